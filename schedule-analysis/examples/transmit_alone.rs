//! The transmit interrupt's bound used alone, every other held bound held back: per scenario and revision the
//! jobs and bus paths that miss, and `can_tx`'s rows with their WCRTs (docs/analysis.md, "The transmit interrupt's
//! parts"). `cargo run -p schedule-analysis --example transmit_alone -- [ROOT] [SCENARIO REVISION]...`; without
//! pairs: thesis-demo on each board's newest revision, thesis-demo on 1-2 and thesis-magnetometer-900us on 1-1.
//! `SHOW=row,row` names the rows printed with their WCRTs (default `can_tx`); `TOPIC=name` prints where that topic's
//! jitter comes from (its message's terms, its sender's row, the interference at the sender's priority).
use std::path::PathBuf;

use schedule_analysis::analysis::{analyse, Options};
use schedule_analysis::model::FrameCostSpec;
use schedule_analysis::scenario::{self, Held};

fn main() {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let root = PathBuf::from(if args.is_empty() {
        ".".to_string()
    } else {
        args.remove(0)
    });
    let mut runs: Vec<(String, Option<String>)> = args
        .chunks(2)
        .map(|c| {
            (
                c[0].clone(),
                c.get(1).filter(|r| r.as_str() != "-").cloned(),
            )
        })
        .collect();
    if runs.is_empty() {
        runs = vec![
            ("thesis-demo".into(), None),
            ("thesis-demo".into(), Some("1-2".into())),
            ("thesis-magnetometer-900us".into(), Some("1-1".into())),
        ];
    }
    // Other held rows (with or instead of can_tx): `ROWS=can_tx,can_rx`, used together on each board that holds them.
    let rows: Vec<String> = std::env::var("ROWS")
        .unwrap_or_else(|_| "can_tx".into())
        .split(',')
        .map(str::to_string)
        .collect();
    // The rows printed with their WCRTs (prefixes of the board's job names): `SHOW=handle_commands,latch_leds`.
    let show: Vec<String> = std::env::var("SHOW")
        .unwrap_or_else(|_| "can_tx".into())
        .split(',')
        .map(str::to_string)
        .collect();
    for (name, revision) in runs {
        let path = scenario::find_scenario(&root, &name);
        let timings = scenario::timing_files_for(&root, revision.as_deref());
        for board in ["diwheeldrive", "powermgmt", "lightring"] {
            let held = Held::Only { board, rows: &rows };
            let built = match scenario::build_held(&root, &path, &timings, held) {
                Ok(b) => b,
                Err(e) => {
                    println!("{name} {revision:?} {board}: cannot build: {e}");
                    continue;
                }
            };
            let system = built.model.validate().expect("the model validates");
            let analysis = analyse(
                &system,
                &Options {
                    frame_cost: FrameCostSpec::Exact,
                    horizon: None,
                },
            );
            let mut misses = Vec::new();
            for b in &analysis.boards {
                for t in &b.tasks {
                    let wcrt = t
                        .wcrt()
                        .map_or("unbounded".to_string(), |r| format!("{:.1}", r.as_us_f64()));
                    if b.name == board && show.iter().any(|s| t.name.starts_with(s.as_str())) {
                        let deadline = if t.deadline_checked {
                            format!("{:.0} µs", t.deadline.as_us_f64())
                        } else {
                            "none of its own".to_string()
                        };
                        println!(
                            "{name} {} {board}: {} wcet {:.2} µs, jitter {:.1}, WCRT {wcrt} µs, deadline {deadline}{}",
                            revision.as_deref().unwrap_or("newest"),
                            t.name,
                            t.wcet.as_us_f64(),
                            t.jitter.as_us_f64(),
                            if t.schedulable() { "" } else { "  MISS" }
                        );
                    }
                    if !t.schedulable() {
                        misses.push(format!(
                            "{}/{} WCRT {wcrt} > {:.0}",
                            b.name,
                            t.name,
                            t.deadline.as_us_f64()
                        ));
                    }
                }
                println!(
                    "{name} {} {board}: board {} utilisation {:.1} %",
                    revision.as_deref().unwrap_or("newest"),
                    b.name,
                    b.utilisation * 100.0
                );
            }
            if let Some(bus) = &analysis.bus {
                for m in bus.messages.iter().filter(|m| !m.schedulable()) {
                    misses.push(format!("message {}", m.name));
                }
            }
            // `TOPIC=gyroscope`: where the topic's jitter comes from — its message's terms, its sender's row and
            // the board's rows at or above the sender's priority with the standard interference term
            // ⌈(R + J)/T⌉·C at the sender's WCRT R (a reading aid: the analysis' own busy window is the verdict).
            if let Ok(topic) = std::env::var("TOPIC") {
                let us = |t: schedule_analysis::time::Time| t.as_us_f64();
                if let (Some(t), Some(m)) = (
                    analysis.topics.iter().find(|t| t.name == topic),
                    analysis
                        .bus
                        .as_ref()
                        .and_then(|b| b.messages.iter().find(|m| m.name == topic)),
                ) {
                    if !m
                        .sender
                        .as_deref()
                        .is_some_and(|s| s.starts_with(&format!("{board}/")))
                    {
                        continue;
                    }
                    println!(
                        "{name} {board}: topic {topic} best {:.1} worst {:?} jitter {:?}; message jitter {:.1} (own, sender, transmit path), blocking {:.1}, {} frame(s) of {:.1}, WCRT {:?}, best {:.1}",
                        us(t.best),
                        t.worst.map(us),
                        t.jitter().map(us),
                        us(m.jitter),
                        us(m.blocking),
                        m.frames,
                        us(m.frame_time),
                        m.wcrt().map(us),
                        us(m.bcrt)
                    );
                    let sender = m.sender.clone().unwrap_or_default();
                    // The sender's board only: the run whose rows are used there.
                    for b in analysis
                        .boards
                        .iter()
                        .filter(|b| sender.starts_with(&format!("{board}/")) && b.name == board)
                    {
                        let Some(s) = b.tasks.iter().find(|x| {
                            sender.ends_with(&format!("/{}", x.name)) || sender == x.name
                        }) else {
                            continue;
                        };
                        let r = s.wcrt().unwrap_or(s.deadline);
                        println!(
                            "{name} {board}:   sender {}/{}: wcet {:.1}, blocking {:.1}, jitter {:.1}, bcrt {:.1}, WCRT {:.1}",
                            b.name, s.name, us(s.wcet), us(s.blocking), us(s.jitter), us(s.bcrt), us(r)
                        );
                        for x in b
                            .tasks
                            .iter()
                            .filter(|x| x.priority >= s.priority && x.name != s.name)
                        {
                            let n = (us(r) + us(x.jitter)) / us(x.period).max(1e-9);
                            println!(
                                "{name} {board}:     {} (priority {}): wcet {:.1}, period {:.0}, jitter {:.1}: {:.0} × wcet = {:.1}",
                                x.name, x.priority, us(x.wcet), us(x.period), us(x.jitter), n.ceil(), n.ceil() * us(x.wcet)
                            );
                        }
                    }
                }
            }
            for t in &analysis.topics {
                if !t.deadline_met() {
                    misses.push(format!("topic {} end to end", t.name));
                }
                if !t.budget_met() {
                    misses.push(format!(
                        "topic {} jitter {:?} µs > budget {:?} µs",
                        t.name,
                        t.jitter(),
                        t.jitter_budget
                    ));
                }
            }
            println!(
                "{name} {} {board}: {}",
                revision.as_deref().unwrap_or("newest"),
                if misses.is_empty() {
                    "passes".to_string()
                } else {
                    format!("misses: {}", misses.join("; "))
                }
            );
        }
    }
}
