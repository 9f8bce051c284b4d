//! The report in four forms: a terminal table, markdown, JSON for tools and an SVG chart (every task's and
//! message's worst-case response against its deadline).

use std::collections::BTreeMap;
use std::fmt::Write as _;

use serde_json::{json, Value};

use crate::admission_host::{CheckCost, OwnedRobot};
use crate::analysis::{
    analyse_with_progress, Analysis, BoardResult, MessageResult, Options, TaskResult, TopicResult,
};
use crate::model::{FrameCostSpec, System, TaskKind};
use crate::sensitivity::{self, Sensitivity};
use crate::time::Time;

/// Everything one run found.
#[derive(Debug, Clone, PartialEq)]
pub struct Report {
    /// What was analysed (scenario name or model file).
    pub title: String,
    /// Where the boards' task lists came from.
    pub sources: Vec<String>,
    /// Things the reader should know.
    pub warnings: Vec<String>,
    /// The analysis that decides the verdict.
    pub primary: Analysis,
    /// The other frame-cost model, for comparison.
    pub comparison: Option<Analysis>,
    /// Shortest periods per publisher.
    pub sensitivity: Option<Sensitivity>,
    /// The on-chip admission check's cost per board (empty unless [`Report::with_admission_cost`] added it).
    pub admission: Vec<(String, CheckCost)>,
    /// Per board and task, where its budget came from (`bound`: the machine code's, `stated`: the timing
    /// file's), when the model was built from timing files ([`Report::with_budget_sources`]).
    pub budget_from: BTreeMap<(String, String), String>,
    /// The scenario analysed again with every held bound used ([`Report::with_on_bounds`]); it does not change
    /// the verdict.
    pub on_bounds: Option<crate::scenario::OnBounds>,
    /// The failures the scenario expects (its `expected_failures`, [`Report::with_expected_failures`]); empty:
    /// none, everything must pass.
    pub expected_failures: Vec<String>,
}

/// Publishers beyond this many skip the sensitivity search (each costs about twenty whole-system analyses).
pub const MAX_SENSITIVITY_PUBLISHERS: usize = 64;

impl Report {
    /// Analyses `system` and assembles the report. `chosen` is the frame-cost model asked for on the command
    /// line: with it only that model is analysed; without it the model file's own decides the verdict and the
    /// other one (`exact` ↔ `thesis`; `exact` for a fixed cost) is shown beside it.
    pub fn build(
        system: &System,
        title: String,
        sources: Vec<String>,
        warnings: Vec<String>,
        chosen: Option<FrameCostSpec>,
    ) -> Report {
        Report::build_with_progress(system, title, sources, warnings, chosen, &mut |_| {})
    }

    /// [`Report::build`], telling `progress` each step it starts (analyses per board and bus, the sensitivity
    /// search), for a front end that shows progress on large models.
    pub fn build_with_progress(
        system: &System,
        title: String,
        sources: Vec<String>,
        warnings: Vec<String>,
        chosen: Option<FrameCostSpec>,
        progress: &mut dyn FnMut(&str),
    ) -> Report {
        let own = system
            .bus
            .as_ref()
            .map_or(FrameCostSpec::Exact, |b| b.frame_cost);
        let primary_cost = chosen.unwrap_or(own);
        let options = Options {
            frame_cost: primary_cost,
            horizon: None,
        };
        let primary = analyse_with_progress(system, &options, progress);
        let comparison = match (chosen, &system.bus) {
            (None, Some(_)) => {
                let other = match primary_cost {
                    FrameCostSpec::Exact => FrameCostSpec::Thesis,
                    FrameCostSpec::Thesis | FrameCostSpec::Micros(_) => FrameCostSpec::Exact,
                };
                Some(analyse_with_progress(
                    system,
                    &Options {
                        frame_cost: other,
                        horizon: None,
                    },
                    progress,
                ))
            }
            _ => None,
        };
        progress("sensitivity search");
        let sensitivity = Some(sensitivity::sensitivity(
            system,
            &options,
            MAX_SENSITIVITY_PUBLISHERS,
        ));
        Report {
            title,
            sources,
            warnings,
            primary,
            comparison,
            sensitivity,
            admission: Vec::new(),
            budget_from: BTreeMap::new(),
            on_bounds: None,
            expected_failures: Vec::new(),
        }
    }

    /// Adds the worst-case cost of the on-chip admission check of every board of `robot` (its tasks plus the
    /// protocol's limit of running publishers on the bus), in fixed-point iterations.
    pub fn with_admission_cost(mut self, robot: &OwnedRobot) -> Report {
        self.admission = robot
            .boards
            .iter()
            .enumerate()
            .filter_map(|(i, b)| Some((b.name.clone(), robot.worst_case_cost(i)?)))
            .collect();
        self
    }

    /// Records where each task's budget came from (the built model's [`crate::scenario::Built::budget_from`]),
    /// for the JSON report's `budget_from`.
    pub fn with_budget_sources(mut self, built: &crate::scenario::Built) -> Report {
        for b in &self.primary.boards {
            for t in &b.tasks {
                if let Some(from) = built.budget_from(&b.name, &t.name) {
                    self.budget_from
                        .insert((b.name.clone(), t.name.clone()), from.label().to_string());
                }
            }
        }
        self
    }

    /// Adds the second run's findings, on every held bound ([`crate::scenario::on_held_bounds`]); printed
    /// before the verdict, which stays the first run's.
    pub fn with_on_bounds(mut self, on_bounds: Option<crate::scenario::OnBounds>) -> Report {
        self.on_bounds = on_bounds;
        self
    }

    /// The verdict: everything bounded, every deadline and jitter budget met under the primary frame-cost model.
    pub fn all_ok(&self) -> bool {
        self.primary.all_ok()
    }

    /// Records the failures the scenario expects (its `expected_failures`): the set is a checked refusal.
    pub fn with_expected_failures(mut self, expected: &[String]) -> Report {
        self.expected_failures = expected.to_vec();
        self
    }

    /// What `--check` decides: with no expected failures, the verdict ([`Report::all_ok`]); with some, whether
    /// exactly those fail under the primary frame-cost model (each once, in any order).
    pub fn check_passes(&self) -> bool {
        let (unexpected, missing) = self.unexpected();
        unexpected.is_empty() && missing.is_empty()
    }

    /// The failures the scenario does not expect, and the expected ones that do not fail.
    fn unexpected(&self) -> (Vec<String>, Vec<String>) {
        let failures = self.primary.failures();
        let unexpected = failures
            .iter()
            .filter(|f| !self.expected_failures.contains(f))
            .cloned()
            .collect();
        let missing = self
            .expected_failures
            .iter()
            .filter(|e| !failures.contains(e))
            .cloned()
            .collect();
        (unexpected, missing)
    }

    /// The report's line after the VERDICT for a scenario with expected failures: whether exactly those fail.
    fn expected_line(&self) -> Option<String> {
        if self.expected_failures.is_empty() {
            return None;
        }
        let (unexpected, missing) = self.unexpected();
        let head = "Expected failures (the scenario's `expected_failures`, a checked refusal)";
        Some(if unexpected.is_empty() && missing.is_empty() {
            format!(
                "{head}: exactly these fail, as expected — {} (`--check` passes; the scenario's description says \
                 why)",
                self.primary.failure_figures().join(", ")
            )
        } else {
            let mut parts = Vec::new();
            if !unexpected.is_empty() {
                parts.push(format!("failing unexpectedly: {}", unexpected.join(", ")));
            }
            if !missing.is_empty() {
                parts.push(format!("expected but not failing: {}", missing.join(", ")));
            }
            format!(
                "{head}: NOT as expected — {} (`--check` fails)",
                parts.join("; ")
            )
        })
    }
}

/// Output form.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// Aligned text for a terminal.
    Table,
    /// GitHub-flavoured markdown.
    Markdown,
    /// JSON for tools.
    Json,
    /// An SVG chart.
    Svg,
}

impl Format {
    /// Parses `table`, `markdown`, `json` or `svg`.
    pub fn parse(text: &str) -> Option<Format> {
        match text {
            "table" | "text" => Some(Format::Table),
            "markdown" | "md" => Some(Format::Markdown),
            "json" => Some(Format::Json),
            "svg" => Some(Format::Svg),
            _ => None,
        }
    }
}

/// Renders the report.
pub fn render(report: &Report, format: Format) -> String {
    match format {
        Format::Table => text(report, false),
        Format::Markdown => text(report, true),
        Format::Json => serde_json::to_string_pretty(&to_json(report)).unwrap_or_default() + "\n",
        Format::Svg => svg(report),
    }
}

fn us(t: Time) -> String {
    t.to_string()
}

fn us_f(v: f64) -> String {
    let t = Time::from_us_up(v.abs());
    if v < 0.0 {
        format!("-{t}")
    } else {
        t.to_string()
    }
}

fn percent(u: f64) -> String {
    format!("{:.1} %", u * 100.0)
}

fn kind_label(kind: TaskKind) -> &'static str {
    match kind {
        TaskKind::Plain => "-",
        TaskKind::Hardware => "isr",
        TaskKind::Software => "task",
    }
}

fn period_label(period: Time, sporadic: bool) -> String {
    if sporadic {
        format!("≥{}", us(period))
    } else {
        us(period)
    }
}

fn task_verdict(t: &TaskResult) -> String {
    match &t.bound {
        Err(why) => format!("UNBOUNDED ({why})"),
        Ok(_) if t.schedulable() => "ok".into(),
        Ok(_) => "MISSED".into(),
    }
}

fn message_verdict(m: &MessageResult) -> String {
    match &m.bound {
        Err(why) => format!("UNBOUNDED ({why})"),
        Ok(_) if m.schedulable() => "ok".into(),
        Ok(_) => "MISSED".into(),
    }
}

fn topic_verdict(t: &TopicResult) -> String {
    match (t.worst, t.deadline_met(), t.budget_met()) {
        (None, _, _) => "UNBOUNDED".into(),
        (Some(_), true, true) => "ok".into(),
        (Some(_), false, true) => "MISSED".into(),
        (Some(_), true, false) => "JITTER OVER BUDGET".into(),
        (Some(_), false, false) => "MISSED, JITTER OVER BUDGET".into(),
    }
}

fn opt(t: Option<Time>) -> String {
    t.map_or_else(|| "∞".into(), us)
}

/// A table both text forms print.
struct Table {
    headers: Vec<&'static str>,
    right: Vec<bool>,
    rows: Vec<Vec<String>>,
}

impl Table {
    fn new(columns: &[(&'static str, bool)]) -> Table {
        Table {
            headers: columns.iter().map(|c| c.0).collect(),
            right: columns.iter().map(|c| c.1).collect(),
            rows: Vec::new(),
        }
    }

    fn render(&self, markdown: bool, out: &mut String) {
        if markdown {
            let _ = writeln!(out, "| {} |", self.headers.join(" | "));
            let rule: Vec<&str> = self
                .right
                .iter()
                .map(|&r| if r { "---:" } else { ":---" })
                .collect();
            let _ = writeln!(out, "| {} |", rule.join(" | "));
            for row in &self.rows {
                let cells: Vec<String> = row.iter().map(|c| c.replace('|', "\\|")).collect();
                let _ = writeln!(out, "| {} |", cells.join(" | "));
            }
            out.push('\n');
            return;
        }
        let width = |i: usize| {
            self.rows
                .iter()
                .map(|r| r.get(i).map_or(0, |c| c.chars().count()))
                .chain(std::iter::once(
                    self.headers.get(i).map_or(0, |h| h.chars().count()),
                ))
                .max()
                .unwrap_or(0)
        };
        let widths: Vec<usize> = (0..self.headers.len()).map(width).collect();
        let line = |cells: Vec<&str>| -> String {
            let mut s = String::from(" ");
            for (i, cell) in cells.iter().enumerate() {
                let w = widths.get(i).copied().unwrap_or(0);
                let pad = w.saturating_sub(cell.chars().count());
                let last = i + 1 == cells.len();
                if self.right.get(i).copied().unwrap_or(false) {
                    s.push_str(&" ".repeat(pad));
                    s.push_str(cell);
                } else {
                    s.push_str(cell);
                    if !last {
                        s.push_str(&" ".repeat(pad));
                    }
                }
                if !last {
                    s.push_str("  ");
                }
            }
            s
        };
        let _ = writeln!(out, "{}", line(self.headers.clone()));
        for row in &self.rows {
            let _ = writeln!(out, "{}", line(row.iter().map(String::as_str).collect()));
        }
        out.push('\n');
    }
}

fn heading(out: &mut String, markdown: bool, level: usize, title: &str) {
    if markdown {
        let _ = writeln!(out, "{} {title}\n", "#".repeat(level));
    } else if level <= 1 {
        let _ = writeln!(out, "{title}\n{}", "=".repeat(title.chars().count()));
    } else {
        let _ = writeln!(out, "{title}");
    }
}

/// The entity with the least slack relative to its deadline, as "name (slack x %)".
fn tightest<'a>(items: impl Iterator<Item = (&'a str, Option<Time>, Time)>) -> Option<String> {
    items
        .filter_map(|(name, wcrt, deadline)| {
            let w = wcrt?;
            let d = deadline.as_ns().max(1) as f64;
            Some((name, (d - w.as_ns() as f64) / d))
        })
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(name, slack)| format!("{name} (slack {:.1} % of its deadline)", slack * 100.0))
}

fn board_table(board: &BoardResult) -> Table {
    let mut table = Table::new(&[
        ("task", false),
        ("prio", true),
        ("kind", false),
        ("period µs", true),
        ("WCET µs", true),
        ("block µs", true),
        ("rel. jitter µs", true),
        ("WCRT µs", true),
        ("deadline µs", true),
        ("slack µs", true),
        ("verdict", false),
    ]);
    let mut order: Vec<&TaskResult> = board.tasks.iter().collect();
    order.sort_by_key(|t| std::cmp::Reverse(t.priority));
    for t in order {
        table.rows.push(vec![
            t.name.clone(),
            t.priority.to_string(),
            kind_label(t.kind).into(),
            period_label(t.period, t.sporadic),
            us(t.wcet),
            us(t.blocking),
            us(t.jitter),
            opt(t.wcrt()),
            // A row whose deadline is not checked (the transmit task, a script's engine row) shows none.
            if t.deadline_checked {
                us(t.deadline)
            } else {
                "-".into()
            },
            t.slack_us().map_or_else(|| "-".into(), us_f),
            task_verdict(t),
        ]);
    }
    table
}

fn bus_table(primary: &Analysis, comparison: Option<&Analysis>) -> Option<Table> {
    let bus = primary.bus.as_ref()?;
    let other = comparison.and_then(|c| c.bus.as_ref());
    let mut columns: Vec<(&'static str, bool)> = vec![
        ("message", false),
        ("id", true),
        ("dlc×n", true),
        ("period µs", true),
        ("deadline µs", true),
        ("queue jitter µs", true),
        ("frame µs", true),
        ("block µs", true),
        ("WCRT µs", true),
        ("verdict", false),
    ];
    if other.is_some() {
        columns.extend([
            ("frame µs (alt)", true),
            ("WCRT µs (alt)", true),
            ("verdict (alt)", false),
        ]);
    }
    let mut table = Table::new(&columns);
    let mut order: Vec<usize> = (0..bus.messages.len()).collect();
    order.sort_by_key(|&i| {
        bus.messages
            .get(i)
            .map_or(u32::MAX, |m| crate::can::arbitration_key(m.id, m.extended))
    });
    for i in order {
        let Some(m) = bus.messages.get(i) else {
            continue;
        };
        let mut row = vec![
            m.name.clone(),
            format!("{:#05x}", m.id),
            format!("{}×{}", m.dlc, m.frames),
            us(m.period),
            us(m.deadline),
            us(m.jitter),
            us(m.frame_time),
            us(m.blocking),
            opt(m.wcrt()),
            message_verdict(m),
        ];
        if let Some(o) = other.and_then(|o| o.messages.get(i)) {
            row.extend([us(o.frame_time), opt(o.wcrt()), message_verdict(o)]);
        }
        table.rows.push(row);
    }
    Some(table)
}

fn topic_table(primary: &Analysis, comparison: Option<&Analysis>) -> Table {
    let mut columns: Vec<(&'static str, bool)> = vec![
        ("topic", false),
        ("path", false),
        ("period µs", true),
        ("best µs", true),
        ("worst µs", true),
        ("jitter µs", true),
        ("budget µs", true),
        ("left µs", true),
        ("deadline µs", true),
        ("slack µs", true),
        ("verdict", false),
    ];
    if comparison.is_some() {
        columns.extend([
            ("worst µs (alt)", true),
            ("jitter µs (alt)", true),
            ("verdict (alt)", false),
        ]);
    }
    let mut table = Table::new(&columns);
    for (i, t) in primary.topics.iter().enumerate() {
        let path = match (&t.sender, &t.receiver) {
            (Some(s), None) => format!("{s} → bus"),
            (None, Some(r)) => format!("bus → {r}"),
            (Some(s), Some(r)) => format!("{s} → bus → {r}"),
            (None, None) => "bus".into(),
        };
        let mut row = vec![
            t.name.clone(),
            path,
            us(t.period),
            us(t.best),
            opt(t.worst),
            opt(t.jitter()),
            t.jitter_budget.map_or_else(|| "-".into(), us),
            t.budget_left_us().map_or_else(|| "-".into(), us_f),
            us(t.deadline),
            t.slack_us().map_or_else(|| "-".into(), us_f),
            topic_verdict(t),
        ];
        if let Some(o) = comparison.and_then(|c| c.topics.get(i)) {
            row.extend([opt(o.worst), opt(o.jitter()), topic_verdict(o)]);
        }
        table.rows.push(row);
    }
    table
}

fn text(report: &Report, markdown: bool) -> String {
    let mut out = String::new();
    text_header(report, markdown, &mut out);
    text_boards(&report.primary, markdown, &mut out);
    text_bus(
        &report.primary,
        report.comparison.as_ref(),
        markdown,
        &mut out,
    );
    text_sensitivity(report, markdown, &mut out);
    text_admission(report, markdown, &mut out);
    text_on_bounds(report, markdown, &mut out);
    text_verdict(report, markdown, &mut out);
    out
}

/// The second run's findings, on every held bound: its heading line, then a line per board and per miss.
fn text_on_bounds(report: &Report, markdown: bool, out: &mut String) {
    let Some(o) = &report.on_bounds else {
        return;
    };
    let lines = o.lines();
    let Some((head, rest)) = lines.split_first() else {
        return;
    };
    heading(out, markdown, 2, "The verdict on the bounds");
    let _ = writeln!(out, "{head}{}", if markdown { "\n" } else { "" });
    for l in rest {
        if markdown {
            let depth = l.len() - l.trim_start().len();
            let _ = writeln!(out, "{}- {}", " ".repeat(depth), l.trim_start());
        } else {
            let _ = writeln!(out, "  {l}");
        }
    }
    out.push('\n');
}

/// The title, the frame costs, the sources and the warnings.
fn text_header(report: &Report, markdown: bool, out: &mut String) {
    let primary = &report.primary;
    let comparison = report.comparison.as_ref();
    let cost_line = match comparison {
        Some(c) => format!(
            "frame cost {} (verdict); {} shown as (alt)",
            primary.frame_cost.label(),
            c.frame_cost.label()
        ),
        None => format!("frame cost {}", primary.frame_cost.label()),
    };
    heading(
        out,
        markdown,
        1,
        &format!("Schedule analysis: {}", report.title),
    );
    let _ = writeln!(
        out,
        "{cost_line}; times in µs; WCRT and jitter measured from the activation{}",
        if markdown { "\n" } else { "" }
    );
    for s in &report.sources {
        let _ = writeln!(out, "{}source: {s}", if markdown { "- " } else { "  " });
    }
    for w in &report.warnings {
        let _ = writeln!(out, "{}warning: {w}", if markdown { "- " } else { "  " });
    }
    out.push('\n');
}

/// One table per board: its tasks' response times.
fn text_boards(primary: &Analysis, markdown: bool, out: &mut String) {
    for board in &primary.boards {
        let tight = tightest(
            board
                .tasks
                .iter()
                .filter(|t| t.deadline_checked)
                .map(|t| (t.name.as_str(), t.wcrt(), t.deadline)),
        );
        heading(
            out,
            markdown,
            2,
            &format!(
                "Board {} — CPU utilisation {}{}",
                board.name,
                percent(board.utilisation),
                tight.map_or_else(String::new, |t| format!("; tightest: {t}"))
            ),
        );
        board_table(board).render(markdown, out);
        for bus in &board.sensor_buses {
            text_sensor_bus(bus, markdown, out);
        }
    }
}

/// A sensor bus's scripts ([`crate::sensor_bus`]): each script's bus time, its response on the bus, and the
/// suspension its job is charged; the engine's per-event figure says whether it is an estimate or a bound.
fn text_sensor_bus(bus: &crate::sensor_bus::SensorBusResult, markdown: bool, out: &mut String) {
    heading(
        out,
        markdown,
        3,
        &format!(
            "Sensor bus {} — {} kbit/s, bus utilisation {}; engine interrupt at priority {}, {} µs per event \
             (with entry and exit; {}: {}){}{}, an event's response {} µs",
            bus.name,
            us_f(f64::from(bus.bitrate) / 1000.0),
            percent(bus.utilisation),
            bus.engine_priority,
            us(bus.per_event),
            bus.per_event_from.label(),
            bus.source,
            engine_part(", ", "per script", bus.per_script.as_ref()),
            engine_part(
                ", ",
                "condition wait per START",
                bus.condition_wait.as_ref()
            ),
            opt(bus.event_response),
        ),
    );
    let mut table = Table::new(&[
        ("script of", false),
        ("prio", true),
        ("wire µs", true),
        ("stretch µs", true),
        ("events", true),
        ("settle µs", true),
        ("bus time µs", true),
        ("block µs", true),
        ("jitter µs", true),
        ("bus WCRT µs", true),
        ("suspension µs", true),
    ]);
    for script in &bus.scripts {
        table.rows.push(vec![
            script.task.clone(),
            script.priority.to_string(),
            us(script.wire),
            us(script.stretch),
            script.events.to_string(),
            us(script.settle),
            us(script.bus_time),
            us(script.blocking),
            us(script.jitter),
            match &script.bound {
                Ok(r) => us(r.wcrt),
                Err(why) => format!("∞ ({why})"),
            },
            opt(script.suspension),
        ]);
    }
    table.render(markdown, out);
}

/// The bus's messages and the end-to-end paths per topic.
fn text_bus(primary: &Analysis, comparison: Option<&Analysis>, markdown: bool, out: &mut String) {
    if let (Some(bus), Some(table)) = (&primary.bus, bus_table(primary, comparison)) {
        let alt = comparison.and_then(|c| {
            c.bus
                .as_ref()
                .map(|b| (c.frame_cost.label(), b.utilisation))
        });
        let tight = tightest(
            bus.messages
                .iter()
                .map(|m| (m.name.as_str(), m.wcrt(), m.deadline)),
        );
        heading(
            out,
            markdown,
            2,
            &format!(
                "CAN bus {} kbit/s — utilisation {} ({}){}{}",
                bus.bitrate / 1000,
                percent(bus.utilisation),
                primary.frame_cost.label(),
                alt.map_or_else(String::new, |(label, u)| format!(
                    ", {} ({label}, alt)",
                    percent(u)
                )),
                tight.map_or_else(String::new, |t| format!("; tightest: {t}"))
            ),
        );
        table.render(markdown, out);
        heading(
            out,
            markdown,
            2,
            "End to end per topic (sample due → last frame delivered → receiver done)",
        );
        topic_table(primary, comparison).render(markdown, out);
    }
}

/// The shortest period each publisher could have.
fn text_sensitivity(report: &Report, markdown: bool, out: &mut String) {
    let primary = &report.primary;
    if let Some(s) = &report.sensitivity {
        heading(
            out,
            markdown,
            2,
            &format!(
                "Sensitivity ({}): shortest period that keeps everything schedulable",
                primary.frame_cost.label()
            ),
        );
        if let Some(why) = &s.skipped {
            let _ = writeln!(out, "{why}\n");
        } else {
            let mut table = Table::new(&[
                ("publisher", false),
                ("messages", false),
                ("period µs", true),
                ("shortest µs", true),
                ("limited by", false),
            ]);
            for p in &s.publishers {
                table.rows.push(vec![
                    p.name.clone(),
                    p.messages.join(", "),
                    us(p.period),
                    match (p.shortest, p.fails_now) {
                        (Some(t), false) => us(t),
                        (Some(t), true) => format!("needs ≥ {}", us(t)),
                        (None, _) => "none passes".into(),
                    },
                    p.limited_by.join(", "),
                ]);
            }
            table.render(markdown, out);
        }
    }
}

/// What the on-chip admission check costs per decision.
fn text_admission(report: &Report, markdown: bool, out: &mut String) {
    if !report.admission.is_empty() {
        heading(
            out,
            markdown,
            2,
            "On-chip admission check: worst-case cost per decision (fixed-point iterations)",
        );
        let mut table = Table::new(&[
            ("board", false),
            ("jobs ≤", true),
            ("publishers on the bus", true),
            ("iterations, one analysis", true),
            ("iterations, refusal with suggestions", true),
            ("analyses", true),
        ]);
        for (board, cost) in &report.admission {
            table.rows.push(vec![
                board.clone(),
                cost.tasks.to_string(),
                cost.publishers.to_string(),
                cost.iterations_per_analysis.to_string(),
                cost.iterations_with_search.to_string(),
                cost.analyses_with_search.to_string(),
            ]);
        }
        table.render(markdown, out);
    }
}

/// The verdict, and the comparison's.
fn text_verdict(report: &Report, markdown: bool, out: &mut String) {
    let primary = &report.primary;
    let comparison = report.comparison.as_ref();
    let failures = primary.failures();
    let verdict = if failures.is_empty() {
        format!(
            "VERDICT: schedulable — every deadline and jitter budget met ({} frame costs)",
            primary.frame_cost.label()
        )
    } else {
        format!(
            "VERDICT: NOT schedulable ({} frame costs) — {}",
            primary.frame_cost.label(),
            failures.join(", ")
        )
    };
    let _ = writeln!(
        out,
        "{}{verdict}{}",
        if markdown { "**" } else { "" },
        if markdown { "**" } else { "" }
    );
    if let Some(line) = report.expected_line() {
        let _ = writeln!(out, "{}{line}", if markdown { "\n" } else { "" });
    }
    if let Some(line) = report.on_bounds.as_ref().and_then(on_bounds_verdict) {
        let _ = writeln!(out, "{}{line}", if markdown { "\n" } else { "" });
    }
    if let Some(c) = comparison {
        let f = c.failures();
        let _ = writeln!(
            out,
            "{}({} frame costs, for comparison: {})",
            if markdown { "\n" } else { "" },
            c.frame_cost.label(),
            if f.is_empty() {
                "schedulable".to_string()
            } else {
                format!("not schedulable — {}", f.join(", "))
            }
        );
    }
}

/// The verdict's second line where bounds are held: the VERDICT rests on stated estimates kept where the machine
/// code has a bound, so it says so, and what the verdict is on those bounds (`None` when nothing is held).
fn on_bounds_verdict(o: &crate::scenario::OnBounds) -> Option<String> {
    let held: usize = o.boards.iter().map(|b| b.held.len()).sum();
    if held == 0 {
        return None;
    }
    let rests = format!(
        "the VERDICT above rests on {held} stated estimate{} held where the machine code has a bound",
        if held == 1 { "" } else { "s" }
    );
    if o.all_ok {
        return Some(format!(
            "On the machine code's bounds: schedulable too ({rests}; \"The verdict on the bounds\")"
        ));
    }
    let mut failing: Vec<String> = o
        .boards
        .iter()
        .filter(|b| !b.misses.is_empty())
        .map(|b| format!("{} ({} of {} jobs miss)", b.board, b.misses.len(), b.jobs))
        .collect();
    if !o.bus.is_empty() {
        failing.push(format!(
            "the bus and end to end ({} line{})",
            o.bus.len(),
            if o.bus.len() == 1 { "" } else { "s" }
        ));
    }
    if failing.is_empty() {
        failing.push("a budget".to_string());
    }
    Some(format!(
        "On the machine code's bounds: NOT schedulable — {} ({rests}; what breaks and why: \"The verdict on the bounds\")",
        failing.join(", ")
    ))
}

fn json_time(t: Option<Time>) -> Value {
    t.map_or(Value::Null, |t| json!(t.as_us_f64()))
}

fn messages_json(a: &Analysis) -> Value {
    let Some(bus) = &a.bus else { return json!([]) };
    Value::Array(
        bus.messages
            .iter()
            .map(|m| {
                json!({
                    "name": m.name, "id": m.id, "extended": m.extended, "dlc": m.dlc, "frames": m.frames,
                    "sender": m.sender, "period_us": m.period.as_us_f64(), "deadline_us": m.deadline.as_us_f64(),
                    "frame_us": m.frame_time.as_us_f64(), "blocking_us": m.blocking.as_us_f64(),
                    "jitter_us": m.jitter.as_us_f64(), "wcrt_us": json_time(m.wcrt()), "bcrt_us": m.bcrt.as_us_f64(),
                    "slack_us": m.slack_us(), "unbounded": m.bound.as_ref().err().map(|e| e.to_string()),
                    "schedulable": m.schedulable(),
                })
            })
            .collect(),
    )
}

fn topics_json(a: &Analysis) -> Value {
    Value::Array(
        a.topics
            .iter()
            .map(|t| {
                json!({
                    "name": t.name, "sender": t.sender, "receiver": t.receiver, "period_us": t.period.as_us_f64(),
                    "best_us": t.best.as_us_f64(), "worst_us": json_time(t.worst), "jitter_us": json_time(t.jitter()),
                    "deadline_us": t.deadline.as_us_f64(), "slack_us": t.slack_us(),
                    "jitter_budget_us": json_time(t.jitter_budget), "budget_left_us": t.budget_left_us(),
                    "deadline_met": t.deadline_met(), "budget_met": t.budget_met(), "schedulable": t.ok(),
                })
            })
            .collect(),
    )
}

fn sensor_buses_json(buses: &[crate::sensor_bus::SensorBusResult]) -> Value {
    let buses: Vec<Value> = buses
        .iter()
        .map(|bus| {
            let scripts: Vec<Value> = bus
                .scripts
                .iter()
                .map(|s| {
                    json!({
                        "task": s.task, "priority": s.priority, "wire_us": s.wire.as_us_f64(),
                        "stretch_us": s.stretch.as_us_f64(), "events": s.events,
                        "settle_us": s.settle.as_us_f64(),
                        "bus_time_us": s.bus_time.as_us_f64(), "blocking_us": s.blocking.as_us_f64(),
                        "jitter_us": s.jitter.as_us_f64(),
                        "bus_wcrt_us": json_time(s.bound.as_ref().ok().map(|r| r.wcrt)),
                        "unbounded": s.bound.as_ref().err().map(|e| e.to_string()),
                        "suspension_us": json_time(s.suspension),
                    })
                })
                .collect();
            let mut out = json!({
                "name": bus.name, "bitrate": bus.bitrate, "utilisation": bus.utilisation,
                "engine_priority": bus.engine_priority, "per_event_us": bus.per_event.as_us_f64(),
                "per_event_from": bus.per_event_from.label(), "per_event_source": bus.source,
                "event_response_us": json_time(bus.event_response), "scripts": scripts,
            });
            // The parts beside the per-event one, only where the engine states them.
            for (key, part) in [("per_script", &bus.per_script), ("condition_wait", &bus.condition_wait)] {
                if let (Some(part), Some(map)) = (part, out.as_object_mut()) {
                    map.insert(key.into(), json_part(part));
                }
            }
            out
        })
        .collect();
    Value::Array(buses)
}

/// A stated part of a sensor bus's engine charge as the heading says it (`, 12.74 µs per script (machine-code
/// bound: …)`), or nothing.
fn engine_part(lead: &str, what: &str, part: Option<&crate::sensor_bus::Part>) -> String {
    part.map_or(String::new(), |p| {
        format!(
            "{lead}{} µs {what} ({}: {})",
            us(p.time),
            p.from.label(),
            p.source
        )
    })
}

/// A stated part of a sensor bus's engine charge in the JSON report.
fn json_part(p: &crate::sensor_bus::Part) -> Value {
    json!({ "us": p.time.as_us_f64(), "from": p.from.label(), "source": p.source })
}

fn to_json(report: &Report) -> Value {
    let a = &report.primary;
    let tasks: Vec<Value> = a
        .boards
        .iter()
        .flat_map(|b| {
            b.tasks.iter().map(move |t| {
                let budget_from = report.budget_from.get(&(b.name.clone(), t.name.clone()));
                json!({
                    "board": b.name, "name": t.name, "job_of": t.job_of, "priority": t.priority,
                    "budget_from": budget_from,
                    "kind": kind_label(t.kind), "sporadic": t.sporadic, "period_us": t.period.as_us_f64(),
                    "deadline_us": t.deadline_checked.then(|| t.deadline.as_us_f64()),
                    "wcet_us": t.wcet.as_us_f64(),
                    "overhead_us": t.overhead.as_us_f64(), "bcrt_us": t.bcrt.as_us_f64(),
                    "blocking_us": t.blocking.as_us_f64(), "jitter_us": t.jitter.as_us_f64(),
                    "wcrt_us": json_time(t.wcrt()), "slack_us": t.slack_us(),
                    "busy_window_jobs": t.bound.as_ref().ok().map(|r| r.instances),
                    "unbounded": t.bound.as_ref().err().map(|e| e.to_string()), "schedulable": t.schedulable(),
                })
            })
        })
        .collect();
    let boards: Vec<Value> = a
        .boards
        .iter()
        .map(|b| {
            let mut board = json!({"name": b.name, "utilisation": b.utilisation});
            // Only a board with scripts has the key, so that the others' reports stay as they were.
            if let (false, Some(fields)) = (b.sensor_buses.is_empty(), board.as_object_mut()) {
                fields.insert("sensor_buses".into(), sensor_buses_json(&b.sensor_buses));
            }
            board
        })
        .collect();
    let mut out = json!({
        "title": report.title,
        "frame_cost": a.frame_cost.label(),
        "schedulable": report.all_ok(),
        "failures": a.failures(),
        "sources": report.sources,
        "warnings": report.warnings,
        "boards": boards,
        "bus": a.bus.as_ref().map(|b| json!({"bitrate": b.bitrate, "utilisation": b.utilisation})),
        "tasks": tasks,
        "messages": messages_json(a),
        "topics": topics_json(a),
    });
    if let (Some(c), Value::Object(map)) = (&report.comparison, &mut out) {
        map.insert(
            "comparison".into(),
            json!({
                "frame_cost": c.frame_cost.label(),
                "schedulable": c.all_ok(),
                "failures": c.failures(),
                "bus": c.bus.as_ref().map(|b| json!({"bitrate": b.bitrate, "utilisation": b.utilisation})),
                "messages": messages_json(c),
                "topics": topics_json(c),
            }),
        );
    }
    if let (Some(o), Value::Object(map)) = (&report.on_bounds, &mut out) {
        map.insert(
            "on_bounds".into(),
            serde_json::to_value(o).unwrap_or(Value::Null),
        );
    }
    if let (false, Value::Object(map)) = (report.expected_failures.is_empty(), &mut out) {
        map.insert(
            "expected_failures".into(),
            json!({ "expected": report.expected_failures, "as_expected": report.check_passes() }),
        );
    }
    if let (Some(s), Value::Object(map)) = (&report.sensitivity, &mut out) {
        let publishers: Vec<Value> = s
            .publishers
            .iter()
            .map(|p| {
                json!({
                    "name": p.name, "messages": p.messages, "period_us": p.period.as_us_f64(),
                    "shortest_period_us": json_time(p.shortest), "fails_now": p.fails_now, "limited_by": p.limited_by,
                })
            })
            .collect();
        map.insert(
            "sensitivity".into(),
            json!({"skipped": s.skipped, "publishers": publishers}),
        );
    }
    if let (false, Value::Object(map)) = (report.admission.is_empty(), &mut out) {
        let boards: Vec<Value> = report
            .admission
            .iter()
            .map(|(board, c)| {
                json!({
                    "board": board, "jobs": c.tasks, "publishers": c.publishers,
                    "iterations_per_analysis": c.iterations_per_analysis,
                    "iterations_with_search": c.iterations_with_search,
                    "analyses_with_search": c.analyses_with_search,
                })
            })
            .collect();
        map.insert("admission".into(), Value::Array(boards));
    }
    out
}

// ---- SVG ----------------------------------------------------------------------------------------------------

const SVG_WIDTH: f64 = 1100.0;
const LABEL_X: f64 = 16.0;
const BAR_X: f64 = 330.0;
const BAR_W: f64 = 500.0;
const ROW_H: f64 = 22.0;
const COLOR_JITTER: &str = "#a7b1bd";
const COLOR_BLOCKING: &str = "#f2a541";
const COLOR_OWN: &str = "#2f6fd0";
const COLOR_INTERFERENCE: &str = "#93bff2";
const COLOR_OFFSET: &str = "#c9d7c3";
const COLOR_MISS: &str = "#d1342f";

/// Keeps a label inside the label column: the start and the end, an ellipsis between.
fn shorten(label: &str, max: usize) -> String {
    let chars: Vec<char> = label.chars().collect();
    if chars.len() <= max {
        return label.to_string();
    }
    let head: String = chars.iter().take(max / 2 - 1).collect();
    let tail: String = chars.iter().skip(chars.len() - (max - max / 2)).collect();
    format!("{head}…{tail}")
}

fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// One bar: segments (value, colour) in µs against a deadline.
struct Bar {
    label: String,
    segments: Vec<(f64, &'static str)>,
    deadline: f64,
    total: Option<f64>,
    ok: bool,
    note: String,
    /// Extra tick (the other frame-cost model's WCRT, or the jitter budget).
    tick: Option<(f64, &'static str)>,
}

fn svg(report: &Report) -> String {
    let a = &report.primary;
    let mut sections: Vec<(String, Vec<Bar>)> = Vec::new();
    for board in &a.boards {
        sections.push((
            format!("Board {} — CPU {}", board.name, percent(board.utilisation)),
            board_bars(board),
        ));
    }
    if let Some(bus) = &a.bus {
        sections.push(bus_section(report, bus));
        sections.push((
            "End to end: best (green) to worst (blue); orange tick: best + jitter budget".into(),
            topic_bars(a),
        ));
    }

    // Scale: percent of each row's own deadline, so 3 µs interrupts and 1 s publishers share one chart.
    let max_ratio = sections
        .iter()
        .flat_map(|(_, bars)| bars.iter())
        .filter_map(|b| b.total.map(|t| t / b.deadline.max(1e-9)))
        .fold(1.0f64, f64::max);
    let scale_max = if max_ratio <= 1.0 {
        1.25
    } else {
        (max_ratio * 1.1).min(3.0)
    };
    let scale = Scale { max: scale_max };
    let rows: usize = sections.iter().map(|(_, b)| b.len() + 2).sum();
    let height = 110.0 + rows as f64 * ROW_H + 20.0;
    let mut s = String::new();
    svg_header(report, height, &mut s);
    let mut y = 110.0;
    for (title, bars) in &sections {
        let _ = writeln!(
            s,
            r#"<text x="{LABEL_X}" y="{}" font-size="14" font-weight="bold">{}</text>"#,
            y + 14.0,
            esc(title)
        );
        y += ROW_H + 4.0;
        let top = y;
        for (row, bar) in bars.iter().enumerate() {
            svg_row(bar, row, y, scale, &mut s);
            y += ROW_H;
        }
        svg_axis(top, y, scale, &mut s);
        y += ROW_H;
    }
    s.push_str("</svg>\n");
    s
}

/// A chart's horizontal scale: a ratio of a row's deadline to its x coordinate.
#[derive(Clone, Copy)]
struct Scale {
    /// The largest ratio shown.
    max: f64,
}

impl Scale {
    fn x_of(self, ratio: f64) -> f64 {
        BAR_X + BAR_W * (ratio / self.max).clamp(0.0, 1.0)
    }
}

/// A board's tasks, highest priority first.
fn board_bars(board: &BoardResult) -> Vec<Bar> {
    let mut tasks: Vec<&TaskResult> = board.tasks.iter().collect();
    tasks.sort_by_key(|t| std::cmp::Reverse(t.priority));
    tasks
        .iter()
        .map(|t| {
            let (j, b, c) = (
                t.jitter.as_us_f64(),
                t.blocking.as_us_f64(),
                t.wcet.as_us_f64(),
            );
            let total = t.wcrt().map(Time::as_us_f64);
            let rest = total.map_or(0.0, |r| (r - j - b - c).max(0.0));
            Bar {
                label: format!("{} (p{})", t.name, t.priority),
                segments: vec![
                    (j, COLOR_JITTER),
                    (b, COLOR_BLOCKING),
                    (c, COLOR_OWN),
                    (rest, COLOR_INTERFERENCE),
                ],
                deadline: t.deadline.as_us_f64(),
                total,
                ok: t.schedulable(),
                note: match &t.bound {
                    Ok(r) => format!("{} / {} µs", us(r.wcrt), us(t.deadline)),
                    Err(why) => format!("unbounded: {why}"),
                },
                tick: None,
            }
        })
        .collect()
}

/// The bus's messages in arbitration order, with the comparison's WCRT as a tick.
fn bus_section(report: &Report, bus: &crate::analysis::BusResult) -> (String, Vec<Bar>) {
    let a = &report.primary;
    let other = report
        .comparison
        .as_ref()
        .and_then(|c| c.bus.as_ref().map(|b| (c.frame_cost.label(), b)));
    let mut order: Vec<usize> = (0..bus.messages.len()).collect();
    order.sort_by_key(|&i| {
        bus.messages
            .get(i)
            .map_or(u32::MAX, |m| crate::can::arbitration_key(m.id, m.extended))
    });
    let bars = order
        .iter()
        .filter_map(|&i| bus.messages.get(i).map(|m| (i, m)))
        .map(|(i, m)| {
            let total = m.wcrt().map(Time::as_us_f64);
            let (o, j, b) = (
                m.offset.as_us_f64(),
                m.jitter.as_us_f64(),
                m.blocking.as_us_f64(),
            );
            let own = m.frame_time.as_us_f64() * f64::from(m.frames);
            let rest = total.map_or(0.0, |r| (r - o - j - b - own).max(0.0));
            Bar {
                label: format!("{} ({:#05x})", m.name, m.id),
                segments: vec![
                    (o, COLOR_OFFSET),
                    (j, COLOR_JITTER),
                    (b, COLOR_BLOCKING),
                    (own, COLOR_OWN),
                    (rest, COLOR_INTERFERENCE),
                ],
                deadline: m.deadline.as_us_f64(),
                total,
                ok: m.schedulable(),
                note: match m.wcrt() {
                    Some(w) => format!("{} / {} µs", us(w), us(m.deadline)),
                    None => "unbounded".into(),
                },
                tick: other
                    .as_ref()
                    .and_then(|(_, ob)| ob.messages.get(i))
                    .map(|om| (om.wcrt().map_or(f64::INFINITY, Time::as_us_f64), "#222222")),
            }
        })
        .collect();
    let alt = other.map_or_else(String::new, |(label, b)| {
        format!("; black tick: {label} ({})", percent(b.utilisation))
    });
    (
        format!(
            "CAN bus — {} ({}){alt}",
            percent(bus.utilisation),
            a.frame_cost.label()
        ),
        bars,
    )
}

/// The end-to-end paths per topic, best to worst, with the jitter budget as a tick.
fn topic_bars(a: &Analysis) -> Vec<Bar> {
    a.topics
        .iter()
        .map(|t| {
            let best = t.best.as_us_f64();
            let worst = t.worst.map(Time::as_us_f64);
            Bar {
                label: format!("{} end to end", t.name),
                segments: vec![
                    (best, COLOR_OFFSET),
                    (worst.map_or(0.0, |w| w - best), COLOR_OWN),
                ],
                deadline: t.deadline.as_us_f64(),
                total: worst,
                ok: t.ok(),
                note: match (t.worst, t.jitter_budget) {
                    (Some(w), Some(b)) => format!(
                        "{} / {} µs · jitter {} / {}",
                        us(w),
                        us(t.deadline),
                        opt(t.jitter()),
                        us(b)
                    ),
                    (Some(w), None) => format!(
                        "{} / {} µs · jitter {}",
                        us(w),
                        us(t.deadline),
                        opt(t.jitter())
                    ),
                    (None, _) => "unbounded".into(),
                },
                tick: t
                    .jitter_budget
                    .map(|b| (best + b.as_us_f64(), COLOR_BLOCKING)),
            }
        })
        .collect()
}

/// The SVG's opening, its title and verdict, and the legend.
fn svg_header(report: &Report, height: f64, s: &mut String) {
    let a = &report.primary;
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{SVG_WIDTH}" height="{height}" viewBox="0 0 {SVG_WIDTH} {height}" font-family="DejaVu Sans, Helvetica, Arial, sans-serif" font-size="12">"#
    );
    let _ = writeln!(
        s,
        r#"<defs><pattern id="hatch" width="8" height="8" patternUnits="userSpaceOnUse" patternTransform="rotate(45)"><rect width="4" height="8" fill="{COLOR_MISS}" opacity="0.55"/></pattern></defs>"#
    );
    let _ = writeln!(s, r##"<rect width="100%" height="100%" fill="#ffffff"/>"##);
    let verdict = if report.all_ok() {
        ("schedulable", "#1d7f3a")
    } else {
        ("NOT schedulable", COLOR_MISS)
    };
    let _ = writeln!(
        s,
        r#"<text x="{LABEL_X}" y="28" font-size="18" font-weight="bold">Worst-case response vs deadline — {}</text>"#,
        esc(&report.title)
    );
    let _ = writeln!(
        s,
        r#"<text x="{LABEL_X}" y="50" font-size="13" fill="{}" font-weight="bold">{} ({} frame costs)</text>"#,
        verdict.1,
        verdict.0,
        esc(&a.frame_cost.label())
    );
    // Legend.
    let legend = [
        (COLOR_OFFSET, "sender best case"),
        (COLOR_JITTER, "release / queuing jitter"),
        (COLOR_BLOCKING, "blocking"),
        (COLOR_OWN, "own execution / frames"),
        (COLOR_INTERFERENCE, "interference"),
    ];
    let mut lx = LABEL_X;
    for (color, name) in legend {
        let _ = writeln!(
            s,
            r#"<rect x="{lx}" y="62" width="12" height="12" fill="{color}"/><text x="{}" y="72">{name}</text>"#,
            lx + 16.0
        );
        lx += 30.0 + name.len() as f64 * 6.6;
    }
    let _ = writeln!(
        s,
        r##"<text x="{LABEL_X}" y="92" fill="#555555">Bars in % of each row's own deadline (dashed line = 100 %); right: WCRT / deadline.</text>"##
    );
}

/// One bar's row (`row` counts from 0 within its section) at `y`.
fn svg_row(bar: &Bar, row: usize, y: f64, scale: Scale, s: &mut String) {
    let x_of = |ratio: f64| scale.x_of(ratio);
    let scale_max = scale.max;
    if row.is_multiple_of(2) {
        let _ = writeln!(
            s,
            r##"<rect x="{LABEL_X}" y="{y}" width="{}" height="{ROW_H}" fill="#f4f6f8"/>"##,
            SVG_WIDTH - 2.0 * LABEL_X
        );
    }
    let _ = writeln!(
        s,
        r#"<text x="{}" y="{}">{}</text>"#,
        LABEL_X + 4.0,
        y + 15.0,
        esc(&shorten(&bar.label, 46))
    );
    let d = bar.deadline.max(1e-9);
    match bar.total {
        Some(_) => {
            let mut at = 0.0;
            for &(value, color) in &bar.segments {
                if value <= 0.0 {
                    continue;
                }
                let (x0, x1) = (x_of(at / d), x_of((at + value) / d));
                let _ = writeln!(
                    s,
                    r#"<rect x="{x0:.1}" y="{:.1}" width="{:.1}" height="14" fill="{color}"/>"#,
                    y + 4.0,
                    (x1 - x0).max(0.8)
                );
                at += value;
            }
            if !bar.ok {
                let _ = writeln!(
                    s,
                    r#"<rect x="{BAR_X}" y="{:.1}" width="{:.1}" height="14" fill="none" stroke="{COLOR_MISS}" stroke-width="2"/>"#,
                    y + 4.0,
                    x_of(at / d) - BAR_X
                );
            }
            if at / d > scale_max {
                let _ = writeln!(
                    s,
                    r#"<text x="{:.1}" y="{}" fill="{COLOR_MISS}" font-weight="bold">»</text>"#,
                    BAR_X + BAR_W + 2.0,
                    y + 15.0
                );
            }
        }
        None => {
            let _ = writeln!(
                s,
                r#"<rect x="{BAR_X}" y="{:.1}" width="{BAR_W}" height="14" fill="url(#hatch)" stroke="{COLOR_MISS}"/>"#,
                y + 4.0
            );
        }
    }
    if let Some((value, color)) = bar.tick {
        if value.is_finite() {
            let x = x_of(value / d);
            let _ = writeln!(
                s,
                r#"<line x1="{x:.1}" x2="{x:.1}" y1="{:.1}" y2="{:.1}" stroke="{color}" stroke-width="2"/>"#,
                y + 1.0,
                y + ROW_H - 1.0
            );
        }
    }
    let color = if bar.ok { "#333333" } else { COLOR_MISS };
    let _ = writeln!(
        s,
        r#"<text x="{:.1}" y="{}" fill="{color}" font-size="11">{}</text>"#,
        BAR_X + BAR_W + 14.0,
        y + 15.0,
        esc(&bar.note)
    );
}

/// A section's deadline line and its axis, from `top` to `y`.
fn svg_axis(top: f64, y: f64, scale: Scale, s: &mut String) {
    let x_of = |ratio: f64| scale.x_of(ratio);
    let scale_max = scale.max;
    let x100 = x_of(1.0);
    let _ = writeln!(
        s,
        r##"<line x1="{x100:.1}" x2="{x100:.1}" y1="{top}" y2="{y}" stroke="#444444" stroke-dasharray="4 3"/>"##
    );
    let _ = writeln!(
        s,
        r##"<line x1="{BAR_X}" x2="{}" y1="{y}" y2="{y}" stroke="#999999"/>"##,
        BAR_X + BAR_W
    );
    let mut tick = 0.0;
    while tick <= scale_max + 1e-9 {
        let x = x_of(tick);
        let _ = writeln!(
            s,
            r##"<line x1="{x:.1}" x2="{x:.1}" y1="{y}" y2="{}" stroke="#999999"/><text x="{x:.1}" y="{}" font-size="10" text-anchor="middle" fill="#666666">{:.0} %</text>"##,
            y + 4.0,
            y + 14.0,
            tick * 100.0
        );
        tick += if scale_max > 2.0 { 0.5 } else { 0.25 };
    }
}
