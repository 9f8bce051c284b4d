//! The transmit interrupt's bound used alone, every other held bound held back: per scenario and revision the
//! jobs and bus paths that miss, and `can_tx`'s rows with their WCRTs (docs/analysis.md, "The transmit interrupt's
//! parts"). `cargo run -p schedule-analysis --example transmit_alone -- [ROOT] [SCENARIO REVISION]...`; without
//! pairs: thesis-demo on each board's newest revision, thesis-demo on 1-2 and thesis-magnetometer-900us on 1-1.
//! `SHOW=row,row` names the rows printed with their WCRTs (default `can_tx`).
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
