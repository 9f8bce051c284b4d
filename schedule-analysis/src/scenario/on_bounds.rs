//! The verdict on the bounds: the scenario analysed a second time with every bound the bounds files hold back
//! used in place of the stated budget (and the held rows' critical sections as blocking terms), so that the
//! report says what the sets' verdicts would be on the machine code's bounds (docs/analysis.md, "The verdict on
//! the bounds"). The first run's verdict stands: it is the one the boards admit on.

use std::path::{Path, PathBuf};

use serde::Serialize;

use super::{bounded::BudgetFrom, fail, BuildError, Built};
use crate::analysis::{analyse, Analysis, Options};
use crate::model::FrameCostSpec;
use crate::time::Time;

/// Misses listed per board (and on the bus) before the rest is counted.
pub const MAX_LISTED: usize = 10;
/// Failures listed per held bound used alone before the rest is counted.
pub const ALONE_LISTED: usize = 3;

/// The second run's findings.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct OnBounds {
    /// Every deadline and jitter budget met with every held bound used.
    pub all_ok: bool,
    /// Per board: its held bounds used, its misses, its utilisation on both runs.
    pub boards: Vec<BoardOnBounds>,
    /// The bus's messages and the topics' end-to-end paths that miss, one line each.
    pub bus: Vec<String>,
}

/// One board in the second run.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BoardOnBounds {
    /// The board.
    pub board: String,
    /// The rows whose held bound is used (with their critical sections; rows whose machine-code bound is
    /// declined too lend only their sections and are not named).
    pub held: Vec<String>,
    /// How many jobs the board has.
    pub jobs: usize,
    /// The jobs that miss their deadline (or whose response is unbounded).
    pub misses: Vec<Miss>,
    /// CPU utilisation on the bounds.
    pub utilisation: f64,
    /// CPU utilisation on the stated budgets (the first run's), when the board is in it.
    pub stated_utilisation: Option<f64>,
    /// Each held bound used alone (the board's `publisher[…]` rows together: they share one bound), every other
    /// held back: whether the set then fails, and what fails first.
    pub alone: Vec<Alone>,
}

/// One held bound used alone.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Alone {
    /// The row (`can_tx`), or `publisher[…]` for every publisher row of the board.
    pub row: String,
    /// What fails in the set with only this bound used, each with its figure against its limit
    /// (`diwheeldrive/can_tx WCRT 515.6 of 158 µs`); empty when it passes. The report lists at most
    /// [`ALONE_LISTED`], then how many more.
    pub breaks: Vec<String>,
}

/// A job that misses on the bounds.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Miss {
    /// The model's job (`can_tx`, `publish_high[gyroscope]`).
    pub job: String,
    /// Its worst-case response, µs; `None` when unbounded.
    pub wcrt_us: Option<f64>,
    /// Why it is unbounded, if it is.
    pub unbounded: Option<String>,
    /// Its deadline, µs.
    pub deadline_us: f64,
    /// Its execution-time budget in this run, µs.
    pub wcet_us: f64,
    /// The held bound its row takes (plus bus waits), µs; `None` when its own row is not held.
    pub held_us: Option<f64>,
    /// The stated budget the held bound replaced, µs.
    pub stated_us: Option<f64>,
}

impl Miss {
    /// One line: `can_tx WCRT 310.2 µs > 95 µs deadline (bound 194.2 µs, stated 9 µs)`.
    pub fn line(&self) -> String {
        let wcrt = match (self.wcrt_us, &self.unbounded) {
            (Some(w), _) => format!("WCRT {} µs > {} µs deadline", t(w), t(self.deadline_us)),
            (None, why) => format!(
                "WCRT unbounded ({}), deadline {} µs",
                why.as_deref().unwrap_or("no fixed point"),
                t(self.deadline_us)
            ),
        };
        let budget = match (self.held_us, self.stated_us) {
            (Some(b), Some(s)) => format!("bound {} µs, stated {} µs", t(b), t(s)),
            (Some(b), None) => format!("bound {} µs", t(b)),
            _ => format!("its budget {} µs, not held", t(self.wcet_us)),
        };
        format!("{} {wcrt} ({budget})", self.job)
    }
}

fn t(us: f64) -> Time {
    Time::from_us_up(us.max(0.0))
}

impl OnBounds {
    /// The report's lines: a heading line, then per board a line and one per miss (at most `MAX_LISTED`, then
    /// how many more), then the bus's and topics' misses.
    pub fn lines(&self) -> Vec<String> {
        let verdict = if self.all_ok {
            "every deadline and jitter budget met"
        } else {
            "NOT schedulable"
        };
        let mut out = vec![format!(
            "On the machine code's bounds (every held bound used; the verdict above, on the stated budgets, is the \
             one the boards admit on): {verdict}"
        )];
        for b in &self.boards {
            let held = if b.held.is_empty() {
                "no bound held".to_string()
            } else {
                // The publisher rows share one bound (the publisher jobs'): counted, not each named.
                let (topics, rows): (Vec<&String>, Vec<&String>) =
                    b.held.iter().partition(|r| r.starts_with("publisher["));
                let mut names: Vec<String> = rows.into_iter().cloned().collect();
                if !topics.is_empty() {
                    names.push(format!("{} publisher[…] rows", topics.len()));
                }
                let bounds = if b.held.len() == 1 { "bound" } else { "bounds" };
                format!("{} held {bounds} used: {}", b.held.len(), names.join(", "))
            };
            let misses = if b.misses.is_empty() {
                format!("all {} jobs meet their deadlines", b.jobs)
            } else {
                format!("{} of {} jobs miss", b.misses.len(), b.jobs)
            };
            let stated = b.stated_utilisation.map_or_else(String::new, |u| {
                format!(" ({:.1} % on the stated budgets)", u * 100.0)
            });
            out.push(format!(
                "{} ({held}): {misses}; utilisation {:.1} %{stated}",
                b.board,
                b.utilisation * 100.0
            ));
            out.extend(capped(b.misses.iter().map(Miss::line), "  ", MAX_LISTED));
            let (breaks, passes): (Vec<&Alone>, Vec<&Alone>) =
                b.alone.iter().partition(|a| !a.breaks.is_empty());
            if !b.alone.is_empty() {
                let passes: Vec<&str> = passes.iter().map(|a| a.row.as_str()).collect();
                let passes = if passes.is_empty() {
                    "none".to_string()
                } else {
                    passes.join(", ")
                };
                let breaks_word = if breaks.is_empty() {
                    "breaks the set: none"
                } else {
                    "breaks the set:"
                };
                out.push(format!(
                    "  each held bound alone (the others held): passes: {passes}; {breaks_word}"
                ));
                out.extend(breaks.iter().map(|a| {
                    let listed: Vec<String> =
                        capped(a.breaks.iter().cloned(), "", ALONE_LISTED).collect();
                    format!("    {}: {}", a.row, listed.join(", "))
                }));
            }
        }
        out.extend(capped(
            self.bus.iter().map(|l| format!("bus: {l}")),
            "",
            MAX_LISTED,
        ));
        out
    }
}

/// At most `limit` lines, each after `indent`, then `and N more`.
fn capped<'a>(
    lines: impl Iterator<Item = String>,
    indent: &'a str,
    limit: usize,
) -> impl Iterator<Item = String> + 'a {
    let all: Vec<String> = lines.collect();
    let more = all.len().saturating_sub(limit);
    all.into_iter()
        .take(limit)
        .map(move |l| format!("{indent}{l}"))
        .chain((more > 0).then(|| format!("{indent}and {more} more")))
}

/// Builds the scenario at `scenario_path` with every held bound used ([`super::build_on_held_bounds`]) and
/// analyses it under `frame_cost` with the analysis' own entry point; `stated` is the first run's analysis, for
/// the utilisation beside. `None` when no bounds file holds a bound back (the second run would be the first).
pub fn on_held_bounds(
    root: &Path,
    scenario_path: &Path,
    timing_paths: &[PathBuf],
    frame_cost: FrameCostSpec,
    stated: &Analysis,
) -> Result<Option<OnBounds>, BuildError> {
    let built = super::build_on_held_bounds(root, scenario_path, timing_paths)?;
    if !built
        .budgets
        .iter()
        .filter_map(|b| b.bounds.as_ref())
        .any(|f| f.held_rows() > 0)
    {
        return Ok(None);
    }
    let system = built.model.validate().map_err(|e| {
        fail(
            &super::display(root, scenario_path),
            "",
            format!("the model on every held bound: {e}"),
        )
    })?;
    let analysis = analyse(
        &system,
        &Options {
            frame_cost,
            horizon: None,
        },
    );
    let mut on = summarise(&built, &analysis, stated);
    for board in &mut on.boards {
        board.alone = alone(
            root,
            scenario_path,
            timing_paths,
            frame_cost,
            &built,
            &board.board,
        )?;
    }
    Ok(Some(on))
}

/// Each held row of `board` (its publisher rows as one) used alone: the set built with only it used and
/// analysed, and what fails first.
fn alone(
    root: &Path,
    scenario_path: &Path,
    timing_paths: &[PathBuf],
    frame_cost: FrameCostSpec,
    built: &Built,
    board: &str,
) -> Result<Vec<Alone>, BuildError> {
    let Some(file) = built
        .budgets
        .iter()
        .find(|b| b.board == board)
        .and_then(|b| b.bounds.as_ref())
    else {
        return Ok(Vec::new());
    };
    let held: Vec<String> = file
        .tasks
        .iter()
        .filter(|t| t.held.is_some())
        .map(|t| t.task.clone())
        .collect();
    let (topics, rows): (Vec<String>, Vec<String>) =
        held.into_iter().partition(|r| r.starts_with("publisher["));
    let mut groups: Vec<(String, Vec<String>)> =
        rows.into_iter().map(|r| (r.clone(), vec![r])).collect();
    if !topics.is_empty() {
        groups.push(("publisher[…]".to_string(), topics));
    }
    let mut out = Vec::new();
    for (name, rows) in groups {
        let one = super::build_held(
            root,
            scenario_path,
            timing_paths,
            super::Held::Only { board, rows: &rows },
        )?;
        let system = one.model.validate().map_err(|e| {
            fail(
                &super::display(root, scenario_path),
                "",
                format!("the model on the held bound of {board}/{name}: {e}"),
            )
        })?;
        let failures = analyse(
            &system,
            &Options {
                frame_cost,
                horizon: None,
            },
        )
        .failure_figures();
        out.push(Alone {
            row: name,
            breaks: failures,
        });
    }
    Ok(out)
}

/// The findings of `analysis`, the analysis of `built` (a model on the held bounds).
pub(super) fn summarise(built: &Built, analysis: &Analysis, stated: &Analysis) -> OnBounds {
    let boards = analysis
        .boards
        .iter()
        .map(|b| {
            let budgets = built.budgets.iter().find(|x| x.board == b.name);
            let held_row = |row: &str| {
                budgets
                    .and_then(|x| x.bounds.as_ref())
                    .and_then(|f| f.task(row))
                    .and_then(|r| r.held.as_ref())
            };
            let held = budgets
                .map(|x| {
                    x.rows
                        .keys()
                        .filter(|row| held_row(row).is_some_and(|h| h.cycles.is_some()))
                        .cloned()
                        .collect()
                })
                .unwrap_or_default();
            let misses = b
                .tasks
                .iter()
                .filter(|t| !t.schedulable())
                .map(|t| {
                    let row = budgets.and_then(|x| x.row_of_job(&t.name));
                    let held = row.and_then(held_row).and_then(|h| h.budget_us());
                    let stated_us = match row.and_then(|r| budgets?.rows.get(r)) {
                        Some(BudgetFrom::Bound { stated_us, .. }) if held.is_some() => {
                            Some(*stated_us)
                        }
                        _ => None,
                    };
                    Miss {
                        job: t.name.clone(),
                        wcrt_us: t.wcrt().map(|w| w.as_us_f64()),
                        unbounded: t.bound.as_ref().err().map(|e| e.to_string()),
                        deadline_us: t.deadline.as_us_f64(),
                        wcet_us: t.wcet.as_us_f64(),
                        held_us: held,
                        stated_us,
                    }
                })
                .collect();
            BoardOnBounds {
                board: b.name.clone(),
                held,
                jobs: b.tasks.len(),
                misses,
                utilisation: b.utilisation,
                stated_utilisation: stated
                    .boards
                    .iter()
                    .find(|s| s.name == b.name)
                    .map(|s| s.utilisation),
                alone: Vec::new(),
            }
        })
        .collect();
    let mut bus = Vec::new();
    if let Some(messages) = &analysis.bus {
        for m in messages.messages.iter().filter(|m| !m.schedulable()) {
            bus.push(match m.wcrt() {
                Some(w) => format!("{} WCRT {w} µs > {} µs deadline", m.name, m.deadline),
                None => format!("{} WCRT unbounded, deadline {} µs", m.name, m.deadline),
            });
        }
    }
    for topic in &analysis.topics {
        if !topic.deadline_met() {
            bus.push(match topic.worst {
                Some(w) => format!(
                    "topic {} end to end {w} µs > {} µs deadline",
                    topic.name, topic.deadline
                ),
                None => format!("topic {} end to end unbounded", topic.name),
            });
        }
        if let (false, Some(budget), Some(jitter)) =
            (topic.budget_met(), topic.jitter_budget, topic.jitter())
        {
            bus.push(format!(
                "topic {} jitter {jitter} µs > {budget} µs budget",
                topic.name
            ));
        }
    }
    OnBounds {
        all_ok: analysis.all_ok(),
        boards,
        bus,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn miss(job: &str, held: Option<f64>) -> Miss {
        Miss {
            job: job.into(),
            wcrt_us: Some(120.25),
            unbounded: None,
            deadline_us: 95.0,
            wcet_us: 70.0,
            held_us: held,
            stated_us: held.map(|_| 9.0),
        }
    }

    #[test]
    fn a_board_lists_ten_misses_then_counts_the_rest_and_the_bus_follows() {
        let mut misses = vec![miss("can_tx", Some(70.0)), miss("watchdog", None)];
        misses.extend((0..11).map(|i| miss(&format!("job{i}"), None)));
        let on = OnBounds {
            all_ok: false,
            boards: vec![BoardOnBounds {
                board: "b".into(),
                held: vec![
                    "can_tx".into(),
                    "publisher[a]".into(),
                    "publisher[b]".into(),
                ],
                jobs: 20,
                misses,
                utilisation: 0.713,
                stated_utilisation: Some(0.306),
                alone: vec![
                    Alone {
                        row: "can_tx".into(),
                        breaks: vec!["b/can_tx WCRT 120.25 of 95 µs".into()],
                    },
                    Alone {
                        row: "publisher[…]".into(),
                        breaks: Vec::new(),
                    },
                ],
            }],
            bus: vec!["topic t end to end 1200 µs > 1000 µs deadline".into()],
        };
        let lines = on.lines();
        assert_eq!(
            lines[1],
            "b (3 held bounds used: can_tx, 2 publisher[…] rows): 13 of 20 jobs miss; utilisation 71.3 % \
             (30.6 % on the stated budgets)"
        );
        assert_eq!(
            lines[2],
            "  can_tx WCRT 120.25 µs > 95 µs deadline (bound 70 µs, stated 9 µs)"
        );
        assert_eq!(
            lines[3],
            "  watchdog WCRT 120.25 µs > 95 µs deadline (its budget 70 µs, not held)"
        );
        assert_eq!(lines[12], "  and 3 more");
        assert_eq!(
            lines[13],
            "  each held bound alone (the others held): passes: publisher[…]; breaks the set:"
        );
        assert_eq!(lines[14], "    can_tx: b/can_tx WCRT 120.25 of 95 µs");
        assert_eq!(
            lines[15],
            "bus: topic t end to end 1200 µs > 1000 µs deadline"
        );
        assert_eq!(lines.len(), 16);
    }
}
