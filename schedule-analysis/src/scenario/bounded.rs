//! The machine-code bounds in place of stated budgets: a board's generated bounds file ([`crate::bounds`]) read
//! beside its timing file, each bound (plus its stated bus waits) made the job's budget where one exists, the
//! stated estimate (or a bench measurement) kept only where the bound was declined or absent, and a record of
//! which budget came from where for the report.

use std::collections::BTreeMap;
use std::path::Path;

use super::{display, fail, BuildError, Timing, MODELS_DIR};
use crate::bounds::{self, BoundsFile, TaskBound};

/// Where one budget came from.
#[derive(Debug, Clone, PartialEq)]
pub enum BudgetFrom {
    /// The bound from the machine code (µs, of which `bus_wait_us` are stated peripheral waits); `stated_us` is
    /// the timing file's estimate it replaced.
    Bound {
        /// The budget: the bound plus its bus waits, µs.
        us: f64,
        /// The stated bus waits in it, µs.
        bus_wait_us: f64,
        /// The estimate the timing file states, µs.
        stated_us: f64,
    },
    /// The timing file's budget (an estimate, or a bench measurement where it has one): `why` says why no bound
    /// replaced it.
    Stated {
        /// `bound declined: …`, `no bound in <file>`, `no bounds file`.
        why: String,
    },
}

impl BudgetFrom {
    /// The word the JSON report carries per task: `bound` or `stated`.
    pub fn label(&self) -> &'static str {
        match self {
            BudgetFrom::Bound { .. } => "bound",
            BudgetFrom::Stated { .. } => "stated",
        }
    }
}

/// A board's budgets after its bounds file: the file (if any) and per row where its budget came from.
#[derive(Debug, Clone, PartialEq)]
pub struct BoardBudgets {
    /// The board.
    pub board: String,
    /// The bounds file's path, relative to the workspace root.
    pub file: String,
    /// The file, when there is one.
    pub bounds: Option<BoundsFile>,
    /// Per budget of the timing file — a task's name, `publisher[<topic>]`, or an overhead row — where it came
    /// from.
    pub rows: BTreeMap<String, BudgetFrom>,
}

impl BoardBudgets {
    /// How many of the timing file's task and topic budgets are bounded (overheads not counted).
    pub fn bounded(&self) -> usize {
        self.job_rows()
            .filter(|(_, f)| matches!(f, BudgetFrom::Bound { .. }))
            .count()
    }

    /// The task and topic rows (not the overheads).
    pub fn job_rows(&self) -> impl Iterator<Item = (&String, &BudgetFrom)> {
        self.rows
            .iter()
            .filter(|(r, _)| !bounds::OVERHEAD_ROWS.contains(&r.as_str()))
    }

    /// Where the budget of the model's job `task` came from: a fixed task by its name, a publisher job
    /// (`publish_high[gyroscope]`) by its topic's row, a timer job by the monotonic's, a QEMU transmit job by its
    /// task's.
    pub fn of_job(&self, task: &str) -> Option<&BudgetFrom> {
        self.rows.get(self.row_of_job(task)?)
    }

    /// The row whose budget the model's job `task` has ([`BoardBudgets::of_job`]).
    pub fn row_of_job(&self, task: &str) -> Option<&str> {
        if let Some((row, _)) = self.rows.get_key_value(task) {
            return Some(row);
        }
        if task.starts_with("monotonic[") {
            return self
                .rows
                .get_key_value("monotonic")
                .map(|(r, _)| r.as_str());
        }
        let (base, rest) = task.split_once('[')?;
        let inner = rest.strip_suffix(']')?;
        self.rows
            .get_key_value(&bounds::publisher_row(inner))
            .or_else(|| self.rows.get_key_value(base))
            .map(|(r, _)| r.as_str())
    }
}

/// The bounds file of the image `timing` describes: its path relative to `root`, and the file when there is one
/// (validated, and checked to be for that board and revision).
pub fn bounds_file(
    root: &Path,
    timing: &Timing,
) -> Result<(String, Option<BoundsFile>), BuildError> {
    let revision = timing
        .app
        .as_ref()
        .and_then(|a| bounds::revision_of_features(&a.features));
    let path = bounds::path_for(&root.join(MODELS_DIR), &timing.board, revision);
    let name = display(root, &path);
    let to_build = |e: bounds::BoundsError| fail(&e.file, e.field, e.problem.to_string());
    let read = BoundsFile::read(&path, &name).map_err(to_build)?;
    if let Some(b) = &read {
        b.check_image(&name, &timing.board, revision)
            .map_err(to_build)?;
    }
    Ok((name, read))
}

/// Reads the bounds file of the image `timing` describes (`models/<board>[-<revision>].wcet.json`) and returns
/// the timing with every bounded budget, critical section and overhead in place, and where each came from.
/// A malformed file, or one for another image, is an error naming its field.
pub(super) fn apply(
    root: &Path,
    file: &str,
    timing: &Timing,
    warnings: &mut Vec<String>,
) -> Result<(Timing, BoardBudgets), BuildError> {
    let (name, read) = bounds_file(root, timing)?;
    let mut out = timing.clone();
    let mut rows = BTreeMap::new();
    let stated = |why: String| BudgetFrom::Stated { why };
    let absent = |row: &str| match &read {
        None => "no bounds file".to_string(),
        Some(_) => format!("no row `{row}` in {name}"),
    };
    // Rows the timing file has no budget for are not used; say so, they may be misnamed.
    if let Some(b) = &read {
        for t in &b.tasks {
            let known = timing.tasks.contains_key(&t.task)
                || bounds::OVERHEAD_ROWS.contains(&t.task.as_str())
                || timing
                    .topics
                    .keys()
                    .any(|topic| bounds::publisher_row(topic) == t.task);
            if !known {
                warnings.push(format!(
                    "{name}: row `{}` names no budget of {file}; not used",
                    t.task
                ));
            }
        }
    }
    let row_of = |row: &str| read.as_ref().and_then(|b| b.task(row));
    for (task, t) in &mut out.tasks {
        let Some(stated_us) = t.wcet_us else {
            continue;
        };
        let from = match row_of(task) {
            Some(bound) => take(
                bound,
                stated_us,
                &mut t.wcet_us,
                &mut t.critical_sections_us,
            ),
            None => stated(absent(task)),
        };
        if matches!(from, BudgetFrom::Bound { .. }) {
            t.measured = None;
        }
        rows.insert(task.clone(), from);
    }
    for (topic, t) in &mut out.topics {
        let row = bounds::publisher_row(topic);
        let mut wcet = Some(t.wcet_us);
        let from = match row_of(&row) {
            Some(bound) => take(bound, t.wcet_us, &mut wcet, &mut t.critical_sections_us),
            None => stated(absent(&row)),
        };
        if let (BudgetFrom::Bound { .. }, Some(w)) = (&from, wcet) {
            t.wcet_us = w;
            t.measured = None;
        }
        rows.insert(row, from);
    }
    // The overheads: the monotonic's interrupt, exception entry and exit, the dispatcher.
    let mut overheads: Vec<(&str, &mut f64)> = vec![
        ("exception_entry", &mut out.overheads.isr_entry_us),
        ("exception_exit", &mut out.overheads.isr_exit_us),
        ("dispatcher", &mut out.overheads.dispatcher_us),
    ];
    if let Some(m) = out.monotonic.as_mut() {
        overheads.push(("monotonic", &mut m.timer_isr_us));
    }
    for (row, value) in overheads {
        let from = match row_of(row) {
            Some(bound) => {
                let mut v = Some(*value);
                let from = take(bound, *value, &mut v, &mut BTreeMap::new());
                *value = v.unwrap_or(*value);
                from
            }
            None => stated(absent(row)),
        };
        rows.insert(row.to_string(), from);
    }
    if let Some(b) = &read {
        for (resource, s) in &b.idle_critical_sections {
            if let (Some(length), Some(cs)) = (
                s.length_us(),
                out.idle_critical_sections_us.get_mut(resource),
            ) {
                *cs = length;
            }
        }
    }
    Ok((
        out,
        BoardBudgets {
            board: timing.board.clone(),
            file: name,
            bounds: read,
            rows,
        },
    ))
}

/// A row's bound as the budget (and its bounded critical sections as theirs), or the estimate kept with the
/// reason the bound was declined.
fn take(
    bound: &TaskBound,
    stated_us: f64,
    wcet: &mut Option<f64>,
    sections: &mut BTreeMap<String, f64>,
) -> BudgetFrom {
    let Some(us) = bound.budget_us() else {
        return BudgetFrom::Stated {
            why: format!(
                "bound declined: {}",
                bound.declined.as_deref().unwrap_or("no reason given")
            ),
        };
    };
    *wcet = Some(us);
    for (resource, s) in &bound.critical_sections {
        if let Some(length) = s.length_us() {
            sections.insert(resource.clone(), length);
        }
    }
    BudgetFrom::Bound {
        us,
        bus_wait_us: bound.bus_wait_us,
        stated_us,
    }
}

/// The report's line about a board's budgets: how many are bounded from the machine code (on which chip, clock
/// and wait states), how many stated and why.
pub(super) fn budgets_line(b: &BoardBudgets, measured: &[String]) -> String {
    let total = b.job_rows().count();
    let bounded = b.bounded();
    let facts = match &b.bounds {
        Some(f) => format!(
            "{}, {} MHz, {} wait states; {}",
            f.chip.short(),
            f.clock_hz as f64 / 1e6,
            f.wait_states,
            b.file
        ),
        None => format!(
            "no bounds file {}: `cargo xtask wcet --write` writes it",
            b.file
        ),
    };
    let stated: Vec<(&String, &String)> = b
        .job_rows()
        .filter_map(|(row, f)| match f {
            BudgetFrom::Stated { why } => Some((row, why)),
            BudgetFrom::Bound { .. } => None,
        })
        .collect();
    let why = if stated.is_empty() {
        String::new()
    } else if b.bounds.is_none() {
        if measured.is_empty() {
            " (estimates; none measured)".to_string()
        } else {
            format!(
                " (estimates; measured for {} of them: {})",
                measured.len(),
                measured.join(", ")
            )
        }
    } else {
        let reasons: Vec<String> = stated
            .iter()
            .map(|(row, why)| {
                let m = measured.iter().find(|m| {
                    m.split(' ').next().is_some_and(|name| {
                        name == row.as_str() || bounds::publisher_row(name) == **row
                    })
                });
                match m {
                    Some(m) => format!("{row}: {why}; measured {m}"),
                    None => format!("{row}: {why}"),
                }
            })
            .collect();
        format!(" ({})", reasons.join("; "))
    };
    // A topic's row is bounded by a whole publisher job (docs/analysis.md, "Writing the files"): say so.
    let per_topic = b
        .job_rows()
        .any(|(row, f)| row.starts_with("publisher[") && matches!(f, BudgetFrom::Bound { .. }));
    let note = if per_topic {
        "; each bounded publisher[…] row is one publisher job's bound (its dispatcher's poll of every task of \
         its priority, serving every topic due at its levels), taken for each topic's sample alone"
    } else {
        ""
    };
    format!(
        "{}: budgets: {bounded} bounded from the machine code ({facts}), {} stated{why}{note}",
        b.board,
        total - bounded
    )
}

/// Which machine-code bounds break a set that fails: for each bound above the timing file's stated budget, the set
/// analysed again with that one bound replaced by the stated budget (every job whose budget is that row's); a
/// bound whose replacement makes everything pass breaks the set alone. When none does alone, but all of them
/// replaced together pass, they break it together. One line each, for the report's warnings; empty when the set
/// passes, when no bound is above its estimate, or when the set fails with the estimates too.
pub fn breaking_bounds(
    built: &super::Built,
    frame_cost: crate::model::FrameCostSpec,
) -> Vec<String> {
    use crate::analysis::{analyse, Options};
    let passes = |model: &crate::model::Model| {
        model.validate().is_ok_and(|system| {
            analyse(
                &system,
                &Options {
                    frame_cost,
                    horizon: None,
                },
            )
            .all_ok()
        })
    };
    if passes(&built.model) {
        return Vec::new();
    }
    // (board, row, bound, stated) of every bound above its estimate.
    let above: Vec<(&str, &str, f64, f64)> = built
        .budgets
        .iter()
        .flat_map(|b| {
            b.rows.iter().filter_map(move |(row, from)| match from {
                BudgetFrom::Bound { us, stated_us, .. } if us > stated_us => {
                    Some((b.board.as_str(), row.as_str(), *us, *stated_us))
                }
                _ => None,
            })
        })
        .collect();
    let reverted = |which: &[(&str, &str, f64, f64)]| {
        let mut model = built.model.clone();
        for board in &mut model.boards {
            let Some(budgets) = built.budgets.iter().find(|b| b.board == board.name) else {
                continue;
            };
            for t in &mut board.tasks {
                let row = budgets.row_of_job(&t.name);
                if let Some((_, _, us, stated)) = which
                    .iter()
                    .find(|(b, r, _, _)| *b == board.name && Some(*r) == row)
                {
                    t.wcet_us += stated - us;
                }
            }
        }
        model
    };
    let describe = |(board, row, us, stated): &(&str, &str, f64, f64)| {
        format!("{board}/{row} (bound {us} µs from the machine code, stated {stated} µs)")
    };
    let alone: Vec<String> = above
        .iter()
        .filter(|one| passes(&reverted(std::slice::from_ref(*one))))
        .map(|one| {
            format!(
                "the bound of {} breaks the set: with its stated budget everything passes; the analysis keeps the bound",
                describe(one)
            )
        })
        .collect();
    if !alone.is_empty() {
        return alone;
    }
    if !above.is_empty() && passes(&reverted(&above)) {
        return vec![format!(
            "the bounds of {} break the set together: with their stated budgets everything passes; the analysis keeps the bounds",
            above.iter().map(describe).collect::<Vec<_>>().join(", ")
        )];
    }
    Vec::new()
}
