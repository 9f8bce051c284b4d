//! The machine-code bounds in place of stated budgets: a board's generated bounds file ([`crate::bounds`]) read
//! beside its timing file, each bound (plus its stated bus waits) made the job's budget where one exists, the
//! stated estimate (or a bench measurement) kept only where the bound was declined or absent, and a record of
//! which budget came from where for the report.

use std::collections::BTreeMap;
use std::path::Path;

use super::{display, fail, BuildError, Timing, MODELS_DIR};
use crate::bounds::{self, BoundsFile, TaskBound};
use crate::model::{TaskModel, GLOBAL_CRITICAL_SECTION};

/// What a build does with the bounds the bounds files hold back ([`crate::bounds::TaskBound::held`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Held<'a> {
    /// Held back: the stated budget and sections stand (the analysis the boards admit on).
    Kept,
    /// Used in place of the stated ones (docs/analysis.md, "The verdict on the bounds").
    Used,
    /// Used for these rows of this board only, every other held back: which held bound breaks a set alone.
    Only {
        /// The board.
        board: &'a str,
        /// Its rows.
        rows: &'a [String],
    },
}

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
    /// Where the blocking terms (each job's critical sections) came from.
    pub blocking: Blocking,
}

/// Where a board's blocking terms came from: each job's critical section per ceiling bounded from the machine
/// code, or the timing file's stated section kept.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Blocking {
    /// Job × ceiling terms bounded from the machine code (`<job> at <ceiling> <µs> µs`).
    pub bounded: Vec<String>,
    /// Stated terms kept, each with why in short (`<job>/<resource> (declined at priority 5)`); the sections'
    /// own reasons are in the bounds file and `cargo xtask wcet`.
    pub stated: Vec<String>,
    /// The reason behind each short one that is not a declined section (`no sections` → which file lacks them).
    pub why: BTreeMap<String, String>,
    /// Ceilings a job's machine code raises to where its section is declined and the timing file states none at
    /// that ceiling: not in the analysis (as before the machine code was read), named for the report.
    pub unstated: Vec<String>,
}

/// The resource a job's bounded section at `ceiling` stands as in the model: the global critical section for
/// interrupts off, else one resource per ceiling, its static ceiling that priority.
pub fn ceiling_resource(ceiling: Option<u32>) -> String {
    match ceiling {
        None => GLOBAL_CRITICAL_SECTION.to_string(),
        Some(p) => format!("machine code: priority {p}"),
    }
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
    held: Held<'_>,
    warnings: &mut Vec<String>,
) -> Result<(Timing, BoardBudgets), BuildError> {
    let (name, read) = bounds_file(root, timing)?;
    let read = match held {
        Held::Kept => read,
        Held::Used => read.map(|b| b.with_held_used(|_| true)),
        Held::Only { board, rows } if board == timing.board => {
            read.map(|b| b.with_held_used(|row| rows.iter().any(|r| r == row)))
        }
        Held::Only { .. } => read,
    };
    let mut out = timing.clone();
    let mut rows = BTreeMap::new();
    let stated = |why: String| BudgetFrom::Stated { why };
    let absent = |row: &str| match &read {
        None => "no bounds file".to_string(),
        Some(_) => format!("no row `{row}` in {name}"),
    };
    // Rows the timing file has no budget for are not used; say so, they may be misnamed. The buses' engine handlers
    // have no budget of their own (their engine rows charge them, per script): their rows are the engine's.
    if let Some(b) = &read {
        for t in &b.tasks {
            let known = timing.tasks.contains_key(&t.task)
                || bounds::OVERHEAD_ROWS.contains(&t.task.as_str())
                || timing
                    .sensor_buses
                    .iter()
                    .any(|bus| bus.engine.handlers.contains(&t.task))
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
            blocking: Blocking::default(),
        },
    ))
}

/// The blocking terms from the machine code: every job of `tasks` whose row in the bounds file lists its
/// sections completely gets, per ceiling its code raises to, the bounded section (a resource of that ceiling,
/// [`ceiling_resource`]) in place of the timing file's stated sections at that ceiling; where the section at a
/// ceiling is declined, the stated ones at it are kept; a stated section at a ceiling the code never raises to
/// is dropped (the job never masks there). A job without such a row keeps its stated sections. `ceilings` (the
/// static ceilings) gains each new resource's, and each stated resource's as resolved before any was dropped,
/// so that a resource keeps its ceiling when the holder that raised it is now a bounded term. SRP's blocking of a
/// task stays the longest section of a lower-priority job whose ceiling is at least its priority, computed where
/// it always was.
pub(super) fn apply_sections(
    budgets: &mut BoardBudgets,
    tasks: &mut [TaskModel],
    ceilings: &mut BTreeMap<String, u32>,
) {
    let mut blocking = Blocking::default();
    let mut resolved = ceilings.clone();
    for t in tasks.iter() {
        for r in t.critical_sections_us.keys() {
            let c = resolved.entry(r.clone()).or_insert(0);
            *c = (*c).max(t.priority);
        }
    }
    let ceiling_of = |r: &str| {
        if r == GLOBAL_CRITICAL_SECTION {
            None
        } else {
            Some(resolved.get(r).copied().unwrap_or(0))
        }
    };
    if let Some(file) = &budgets.bounds {
        for row in &file.tasks {
            for c in row.sections.iter().flat_map(|s| &s.ceilings) {
                if let Some(p) = c.ceiling {
                    ceilings.insert(ceiling_resource(Some(p)), p);
                }
            }
        }
    }
    for (r, c) in &resolved {
        if r != GLOBAL_CRITICAL_SECTION {
            ceilings.insert(r.clone(), *c);
        }
    }
    // A job no other job can preempt blocks nobody: its sections are no terms.
    let top = tasks.iter().map(|t| t.priority).max().unwrap_or(0);
    for t in tasks.iter_mut() {
        if t.priority >= top {
            continue;
        }
        let row = budgets.row_of_job(&t.name).map(str::to_string);
        let sections = budgets
            .bounds
            .as_ref()
            .zip(row.as_deref())
            .and_then(|(file, row)| file.task(row))
            .and_then(|r| r.sections.as_ref());
        let why = match (sections, &budgets.bounds) {
            (Some(s), _) => s.incomplete.as_ref().cloned(),
            (None, None) => Some("no bounds file".to_string()),
            (None, Some(_)) => Some(format!(
                "no sections in {} for `{}`",
                budgets.file,
                row.as_deref().unwrap_or(&t.name)
            )),
        };
        let (Some(sections), None) = (sections, &why) else {
            let why = why.unwrap_or_default();
            let short = if sections.is_some() {
                "sections incomplete"
            } else {
                "no sections"
            };
            for r in t.critical_sections_us.keys() {
                blocking.stated.push(format!("{}/{r} ({short})", t.name));
            }
            blocking.why.entry(short.to_string()).or_insert(why);
            // An incomplete list still holds sections of the job (a thread-mode task's: those of the functions
            // its bounds file names): each bounded one is a term too, beside the stated ones (at a resource
            // stated already, the longer of the two).
            for s in sections.iter().flat_map(|s| &s.ceilings) {
                let (Some(length), false) =
                    (s.length_us(), s.ceiling.is_some_and(|c| c <= t.priority))
                else {
                    continue;
                };
                let term = t
                    .critical_sections_us
                    .entry(ceiling_resource(s.ceiling))
                    .or_insert(0.0);
                *term = term.max(length);
                blocking
                    .bounded
                    .push(format!("{} at {} {length} µs", t.name, s.ceiling_name()));
            }
            continue;
        };
        let mut out = BTreeMap::new();
        for (r, &length) in &t.critical_sections_us {
            let at = ceiling_of(r);
            if let Some(s) = sections.ceilings.iter().find(|s| s.ceiling == at) {
                if s.declined.is_some() {
                    out.insert(r.clone(), length);
                    blocking.stated.push(format!(
                        "{}/{r} (declined at {})",
                        t.name,
                        s.ceiling_name()
                    ));
                }
            }
        }
        for s in &sections.ceilings {
            // A raise to the job's own priority or below holds off nobody that could preempt it.
            if s.ceiling.is_some_and(|c| c <= t.priority) {
                continue;
            }
            match (s.length_us(), &s.declined) {
                (Some(length), _) => {
                    out.insert(ceiling_resource(s.ceiling), length);
                    blocking.bounded.push(format!(
                        "{} at {} {length} µs",
                        t.name,
                        s.ceiling_name()
                    ));
                }
                (None, _) => {
                    if !t
                        .critical_sections_us
                        .keys()
                        .any(|r| ceiling_of(r) == s.ceiling)
                    {
                        blocking
                            .unstated
                            .push(format!("{} at {}", t.name, s.ceiling_name()));
                    }
                }
            }
        }
        t.critical_sections_us = out;
    }
    budgets.blocking = blocking;
}

/// The report's line about a board's blocking terms: how many bounded from the machine code, how many stated.
pub(super) fn blocking_line(b: &BoardBudgets) -> String {
    let k = &b.blocking;
    let mut line = format!(
        "{}: blocking terms: {} bounded from the machine code (each job's longest critical section per ceiling, \
         raise to restore",
        b.board,
        k.bounded.len(),
    );
    if !k.bounded.is_empty() {
        line.push_str(&format!(": {}", k.bounded.join(", ")));
    }
    line.push_str(&format!("), {} stated", k.stated.len()));
    if !k.stated.is_empty() {
        line.push_str(&format!(" ({})", k.stated.join(", ")));
    }
    if !k.unstated.is_empty() {
        line.push_str(&format!(
            "; {} ceilings raised in the machine code with the section declined and nothing stated at them (not \
             counted): {}",
            k.unstated.len(),
            k.unstated.join(", ")
        ));
    }
    for (short, why) in &k.why {
        line.push_str(&format!("; {short}: {why}"));
    }
    line
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

/// `why` as the report prints it: where it ends with the row's held reason (the bounds file's `held.reason`) and
/// an earlier row printed the same reason, the reason is replaced by that row's name, so rows sharing one reason
/// (a publisher task's topics) do not repeat it.
fn shared_reason_once<'a>(
    told: &mut Vec<(&'a str, &'a str)>,
    row: &'a str,
    why: &'a str,
    held: Option<&'a str>,
) -> String {
    let Some(reason) = held.filter(|r| !r.is_empty() && why.ends_with(*r)) else {
        return why.to_string();
    };
    if let Some((first, _)) = told.iter().find(|(_, r)| *r == reason) {
        let before = &why[..why.len() - reason.len()];
        return format!("{before}the reason given for {first} above");
    }
    told.push((row, reason));
    why.to_string()
}

/// The report's lines about a board's budgets: the first says how many are bounded from the machine code (on which
/// chip, clock and wait states) and how many stated; where a bounds file exists, one line follows per stated budget
/// with why (`<board>: stated budget of <row>: <why>`), so a long reason reads on its own line.
pub(super) fn budgets_lines(b: &BoardBudgets, measured: &[String]) -> Vec<String> {
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
    let mut each = Vec::new();
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
        // A reason several rows share (the publisher rows of one task) is printed in full once; the
        // rows after it name the row that carries it.
        let mut told: Vec<(&str, &str)> = Vec::new();
        each = stated
            .iter()
            .map(|(row, why)| {
                let m = measured.iter().find(|m| {
                    m.split(' ').next().is_some_and(|name| {
                        name == row.as_str() || bounds::publisher_row(name) == **row
                    })
                });
                let held = b
                    .bounds
                    .as_ref()
                    .and_then(|f| f.task(row))
                    .and_then(|t| t.held.as_ref())
                    .map(|h| h.reason.as_str());
                let why = shared_reason_once(&mut told, row, why, held);
                match m {
                    Some(m) => format!("{}: stated budget of {row}: {why}; measured {m}", b.board),
                    None => format!("{}: stated budget of {row}: {why}", b.board),
                }
            })
            .collect();
        // Grouped by why: rows this image's file holds back (bounded, not used: `held`, per revision), rows
        // whose bound is declined (thread mode, a loop without a bound), rows the file has none for.
        let kind = |row: &str, why: &str| {
            let held = b
                .bounds
                .as_ref()
                .and_then(|f| f.task(row))
                .is_some_and(|t| t.held.is_some());
            if held {
                "held on this image"
            } else if why.starts_with("bound declined") {
                "declined"
            } else {
                "no bound"
            }
        };
        let mut groups: Vec<(&str, Vec<&str>)> = Vec::new();
        for (row, why) in &stated {
            let k = kind(row, why);
            match groups.iter_mut().find(|(g, _)| *g == k) {
                Some((_, rows)) => rows.push(row.as_str()),
                None => groups.push((k, vec![row.as_str()])),
            }
        }
        groups.sort_by_key(|(k, _)| *k != "held on this image");
        let parts: Vec<String> = groups
            .iter()
            .map(|(k, rows)| format!("{} {k}: {}", rows.len(), rows.join(", ")))
            .collect();
        format!(" ({}; why, each below)", parts.join("; "))
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
    let mut lines = vec![format!(
        "{}: budgets: {bounded} bounded from the machine code ({facts}), {} stated{why}{note}",
        b.board,
        total - bounded
    )];
    lines.extend(each);
    // An overhead whose bound the file declines or holds back (the monotonic's interrupt): its stated figure
    // stands, and why, on a line of its own.
    lines.extend(
        b.rows
            .iter()
            .filter(|(r, _)| bounds::OVERHEAD_ROWS.contains(&r.as_str()))
            .filter_map(|(row, f)| match f {
                BudgetFrom::Stated { why } if why.starts_with("bound declined") => {
                    Some(format!("{}: stated overhead of {row}: {why}", b.board))
                }
                _ => None,
            }),
    );
    lines
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_shared_held_reason_is_printed_once() {
        let mut told = Vec::new();
        let a = "bound declined: publisher[a]: bounded at 1 cycles, held back as its budget: the samples";
        let b = "bound declined: publisher[b]: bounded at 2 cycles, held back as its budget: the samples";
        let c =
            "bound declined: publisher[c]: bounded at 3 cycles, held back as its budget: another";
        let d = "bound declined: thread mode";
        let held = Some("the samples");
        assert_eq!(shared_reason_once(&mut told, "publisher[a]", a, held), a);
        assert_eq!(
            shared_reason_once(&mut told, "publisher[b]", b, held),
            "bound declined: publisher[b]: bounded at 2 cycles, held back as its budget: the reason given \
             for publisher[a] above"
        );
        assert_eq!(
            shared_reason_once(&mut told, "publisher[c]", c, Some("another")),
            c
        );
        assert_eq!(shared_reason_once(&mut told, "admit", d, None), d);
    }
    use crate::bounds::{CeilingSection, CeilingSections, Chip, ImageIdentity};
    use crate::model::TaskKind;

    fn job(name: &str, priority: u32, sections: &[(&str, f64)]) -> TaskModel {
        TaskModel {
            name: name.into(),
            priority,
            wcet_us: 50.0,
            period_us: 1000.0,
            deadline_us: None,
            jitter_us: 0.0,
            critical_sections_us: sections.iter().map(|(r, l)| (r.to_string(), *l)).collect(),
            blocking_us: None,
            bcet_us: None,
            kind: TaskKind::Hardware,
            released_by: None,
            sporadic: false,
            job_of: None,
            script: None,
            scripts: None,
        }
    }

    fn section(ceiling: Option<u32>, cycles: Option<u64>) -> CeilingSection {
        CeilingSection {
            ceiling,
            at: "f at src/f.rs:1".into(),
            cycles,
            us: cycles.map(|c| c as f64 / 72.0),
            bus_wait_us: 0.0,
            declined: cycles
                .is_none()
                .then(|| "the loop in f at src/f.rs:2 has no bound".into()),
        }
    }

    fn row(task: &str, sections: Option<CeilingSections>) -> TaskBound {
        TaskBound {
            task: task.into(),
            cycles: None,
            us: None,
            instructions: None,
            bus_wait_us: 0.0,
            declined: Some("a loop".into()),
            critical_sections: BTreeMap::new(),
            sections,
            job: None,
            held: None,
            release: None,
        }
    }

    fn budgets(rows: Vec<TaskBound>) -> BoardBudgets {
        let from = rows
            .iter()
            .map(|r| {
                (
                    r.task.clone(),
                    BudgetFrom::Stated {
                        why: "bound declined: a loop".into(),
                    },
                )
            })
            .collect();
        BoardBudgets {
            board: "b".into(),
            file: "models/b.wcet.json".into(),
            bounds: Some(BoundsFile {
                generated: bounds::GENERATED_PREFIX.into(),
                board: "b".into(),
                revision: None,
                chip: Chip::Stm32f103,
                clock_hz: 72_000_000,
                wait_states: 2,
                image: ImageIdentity {
                    code_sha256: "0".repeat(64),
                    code_bytes: 4,
                },
                tasks: rows,
                idle_critical_sections: BTreeMap::new(),
            }),
            rows: from,
            blocking: Blocking::default(),
        }
    }

    #[test]
    fn the_budgets_line_groups_the_stated_rows_by_why() {
        // publisher[a] held on this image, admit declined (thread mode), can_rx without a row of its own.
        let mut held = row("publisher[a]", None);
        held.held = Some(bounds::HeldBound {
            cycles: Some(72),
            us: Some(1.0),
            instructions: Some(30),
            bus_wait_us: 0.0,
            reason: "polled on this revision".into(),
            sections: None,
            job: None,
        });
        let mut b = budgets(vec![held, row("admit", None)]);
        b.rows.insert(
            "can_rx".into(),
            BudgetFrom::Stated {
                why: "no row `can_rx` in models/b.wcet.json".into(),
            },
        );
        let lines = budgets_lines(&b, &[]);
        assert_eq!(
            lines[0],
            "b: budgets: 0 bounded from the machine code (F103, 72 MHz, 2 wait states; models/b.wcet.json), 3 stated \
             (1 held on this image: publisher[a]; 1 declined: admit; 1 no bound: can_rx; why, each below)"
        );
    }

    #[test]
    fn a_suspending_releases_row_is_its_jobs_whole_cpu() {
        // A topic stating scripts: its row is the release, 9 polls of 720 cycles (10 µs) and 0.5 µs of waits. The
        // analysis's C of the suspending job (its CPU alone, the suspension apart) is the release's 94.5 µs, not
        // one poll's 10.5 or the stated 20.
        let release = TaskBound {
            cycles: Some(6_480),
            us: Some(90.0),
            instructions: Some(3_240),
            bus_wait_us: 4.5,
            declined: None,
            release: Some(bounds::ReleaseBound {
                polls: 9,
                poll_cycles: 720,
                poll_us: 10.0,
                poll_instructions: 360,
                poll_bus_wait_us: 0.5,
                reason: "3 scripts stated (topics.gyro), 1 with a settle before it: …".into(),
            }),
            ..row("publisher[gyro]", None)
        };
        let file = budgets(vec![release.clone()]);
        assert!(BoundsFile::from_json("b.wcet.json", &file.bounds.unwrap().to_json()).is_ok());
        let (mut wcet, mut sections) = (None, BTreeMap::new());
        let from = take(&release, 20.0, &mut wcet, &mut sections);
        assert_eq!(wcet, Some(94.5));
        assert!(matches!(from, BudgetFrom::Bound { us, .. } if us == 94.5));
    }

    #[test]
    fn bounded_sections_replace_the_stated_ones_at_their_ceiling_and_declined_ones_keep_them() {
        // `low` (priority 1) shares `queue` with `mid` (3) and `bus` with `high` (5): stated 2 and 4 µs, and
        // interrupts off 1 µs. Its code raises to 3 (bounded: 720 cycles, 10 µs), to 5 (declined) and turns
        // interrupts off (bounded: 72 cycles, 1 µs); it never raises to 4, where nothing is stated.
        let sections = CeilingSections {
            incomplete: None,
            ceilings: vec![
                section(None, Some(72)),
                section(Some(5), None),
                section(Some(3), Some(720)),
            ],
        };
        let mut b = budgets(vec![row("low", Some(sections)), row("mid", None)]);
        let mut tasks = vec![
            job(
                "low",
                1,
                &[("queue", 2.0), ("bus", 4.0), (GLOBAL_CRITICAL_SECTION, 1.0)],
            ),
            job("mid", 3, &[("queue", 1.0)]),
            job("high", 5, &[("bus", 1.0)]),
        ];
        let mut ceilings = BTreeMap::new();
        apply_sections(&mut b, &mut tasks, &mut ceilings);
        let low: Vec<(&str, f64)> = tasks[0]
            .critical_sections_us
            .iter()
            .map(|(r, l)| (r.as_str(), *l))
            .collect();
        assert_eq!(
            low,
            [
                ("bus", 4.0),
                (GLOBAL_CRITICAL_SECTION, 1.0),
                ("machine code: priority 3", 10.0),
            ]
        );
        // `mid` has no sections in the file: its stated one stands.
        assert_eq!(tasks[1].critical_sections_us["queue"], 1.0);
        // Every resource keeps the ceiling its users gave it, and the bounded one has its own.
        assert_eq!(ceilings["queue"], 3);
        assert_eq!(ceilings["bus"], 5);
        assert_eq!(ceilings["machine code: priority 3"], 3);
        assert_eq!(b.blocking.bounded.len(), 2);
        assert_eq!(
            b.blocking.stated,
            [
                "low/bus (declined at priority 5)",
                "mid/queue (no sections)"
            ]
        );
        assert!(b.blocking.unstated.is_empty());
        let line = blocking_line(&b);
        assert!(line.contains("blocking terms: 2 bounded"), "{line}");
        assert!(line.contains("low at priority 3 10 µs"), "{line}");
        // SRP on the result: `mid` is blocked by `low`'s 10 µs section at ceiling 3, `high` by the stated 4 µs at
        // 5 (the interrupts-off 1 µs is shorter).
        let model = crate::model::Model {
            name: None,
            boards: vec![crate::model::BoardModel {
                name: "b".into(),
                source: None,
                overheads: Default::default(),
                idle_critical_sections_us: BTreeMap::new(),
                can_tx_task: None,
                ceilings: ceilings.clone(),
                tasks: tasks.clone(),
                sensor_buses: Vec::new(),
            }],
            can: None,
        };
        let system = model.validate().expect("valid");
        let result = crate::analysis::analyse(
            &system,
            &crate::analysis::Options {
                frame_cost: Default::default(),
                horizon: None,
            },
        );
        let blocking = |name: &str| {
            result.boards[0]
                .tasks
                .iter()
                .find(|t| t.name == name)
                .map(|t| t.blocking.as_us_f64())
        };
        assert_eq!(blocking("mid"), Some(10.0));
        assert_eq!(blocking("high"), Some(4.0));
    }

    #[test]
    fn an_incomplete_list_adds_its_bounded_sections_beside_the_stated_ones_a_top_job_none_and_a_gap_is_named(
    ) {
        // `a`'s list holds only some of its job's sections (a thread-mode task's named functions): priority 3
        // for 72 cycles (1 µs) and interrupts off for 144 (2 µs), where 1 µs is stated; `b`'s the same, where
        // 3 µs is stated with interrupts off.
        let incomplete = CeilingSections {
            incomplete: Some("a raise of no constant".into()),
            ceilings: vec![section(Some(3), Some(72)), section(None, Some(144))],
        };
        let gap = CeilingSections {
            incomplete: None,
            ceilings: vec![section(Some(4), None)],
        };
        let mut b = budgets(vec![
            row("a", Some(incomplete.clone())),
            row("b", Some(incomplete)),
            row("c", Some(gap.clone())),
            row("top", Some(gap)),
        ]);
        let mut tasks = vec![
            job("a", 1, &[("r", 2.0), (GLOBAL_CRITICAL_SECTION, 1.0)]),
            job("b", 1, &[(GLOBAL_CRITICAL_SECTION, 3.0)]),
            job("c", 2, &[]),
            job("other", 3, &[("r", 1.0)]),
            job("top", 6, &[("s", 1.0)]),
        ];
        apply_sections(&mut b, &mut tasks, &mut BTreeMap::new());
        // The stated sections stay; the bounded ones are added, the longer one where both name a resource.
        let a: Vec<(&str, f64)> = tasks[0]
            .critical_sections_us
            .iter()
            .map(|(r, l)| (r.as_str(), *l))
            .collect();
        assert_eq!(
            a,
            [
                (GLOBAL_CRITICAL_SECTION, 2.0),
                ("machine code: priority 3", 1.0),
                ("r", 2.0),
            ]
        );
        assert_eq!(tasks[1].critical_sections_us[GLOBAL_CRITICAL_SECTION], 3.0);
        assert_eq!(tasks[4].critical_sections_us["s"], 1.0);
        assert_eq!(
            b.blocking.bounded,
            [
                "a at priority 3 1 µs",
                "a at interrupts off 2 µs",
                "b at priority 3 1 µs",
                "b at interrupts off 2 µs"
            ]
        );
        assert_eq!(
            b.blocking.stated,
            [
                "a/critical_section (sections incomplete)",
                "a/r (sections incomplete)",
                "b/critical_section (sections incomplete)",
                "other/r (no sections)"
            ]
        );
        assert_eq!(b.blocking.unstated, ["c at priority 4"]);
    }
}
