//! The bench report as a terminal table, markdown and an SVG of response-time histograms.
use std::fmt::Write as _;

use super::{Bench, TaskRow, TopicRow};

/// A figure to one decimal, `-` where there is none.
pub(super) fn opt(v: Option<f64>) -> String {
    v.map(|v| format!("{v:.1}")).unwrap_or_else(|| "-".into())
}

/// Cells in columns: the first left-aligned in its width, the others right-aligned in theirs, the cell after
/// the last width (the verdict) two spaces on, as it is.
pub(super) fn columns<S: AsRef<str>>(cells: &[S], widths: &[usize]) -> String {
    let mut line = String::new();
    for (k, cell) in cells.iter().map(AsRef::as_ref).enumerate() {
        match widths.get(k) {
            Some(&width) if k == 0 => {
                let _ = write!(line, "{cell:<width$}");
            }
            Some(&width) => {
                let _ = write!(line, " {cell:>width$}");
            }
            None => {
                let _ = write!(line, "  {cell}");
            }
        }
    }
    line
}

/// Column names, `|`-separated.
pub(super) fn names(header: &str) -> Vec<&str> {
    header.split('|').collect()
}

/// The cells of a task's row: task, jobs, execution max, p99 and mean, response max (`≥`: from the run's start,
/// a lower bound), WCRT, deadline, verdict.
pub(super) fn task_cells(t: &TaskRow) -> [String; 9] {
    [
        t.task.clone(),
        t.jobs.to_string(),
        format!("{:.1}", t.exec_max_us),
        format!("{:.1}", t.exec_p99_us),
        format!("{:.1}", t.exec_mean_us),
        format!(
            "{}{:.1}",
            if t.from_release { "" } else { "≥" },
            t.response_max_us
        ),
        opt(t.wcrt_us),
        opt(t.deadline_us),
        t.verdict.clone(),
    ]
}

/// The cells of a topic's row: topic, level, samples, period, release → taken max, → queued max, job WCRT,
/// → bus max, message WCRT, delivery jitter, analysed jitter, verdict.
pub(super) fn topic_cells(t: &TopicRow) -> [String; 12] {
    [
        t.topic.clone(),
        t.level.clone(),
        t.samples.to_string(),
        opt(t.period_us),
        format!("{:.1}", t.start_latency_max_us),
        opt(t.queued_max_us),
        opt(t.job_wcrt_us),
        opt(t.bus_max_us),
        opt(t.message_wcrt_us),
        opt(t.delivery_jitter_us),
        opt(t.analysed_jitter_us),
        t.verdict.clone(),
    ]
}

/// A row of a markdown table.
fn markdown_row(cells: &[String]) -> String {
    format!("| {} |", cells.join(" | "))
}

fn header(b: &Bench) -> String {
    format!(
        "{} ({} build) — {}\nbounds: {}\nthe board's own admission (production build, full-rate bus): {}\ntrace clock {} Hz, {:.0} µs traced, {} records, {} damaged stretches skipped, {} lost on the board, {} unbalanced ends\n",
        b.board,
        b.build,
        b.origin,
        b.model,
        if b.admitted {
            "admits this set"
        } else {
            "refuses this set (nothing is promised: a task the bench cannot bound is no failure)"
        },
        b.clock_hz,
        b.span_us,
        b.records,
        b.damaged,
        b.lost,
        b.unbalanced
    )
}

/// The observed executions against the machine-code bounds (docs/bench.md, "Observed against the bounds").
fn machine_table(out: &mut String, b: &Bench) {
    let _ = writeln!(out, "\nmachine-code bounds: {}", b.machine_bounds);
    if b.machine.is_empty() {
        return;
    }
    let _ = writeln!(
        out,
        "{:<20} {:>12} {:>8} {:>14} {:>12} {:>7}  unit, verdict (held: the analysis keeps a stated budget, the \
         job is held to the machine code's bound all the same; loose: bound > {}× the job)",
        "task", "observed", "trace", "pre-empted", "bound", "ratio", super::machine::TIGHT
    );
    for m in &b.machine {
        let _ = writeln!(
            out,
            "{:<20} {:>12} {:>8} {:>14} {:>12} {:>7}  {}, {}{}{}",
            m.task,
            m.observed,
            m.trace_allowance,
            format!("{}× −{}", m.preemptions, m.unstamped),
            m.bound.map_or_else(|| "-".to_string(), |v| v.to_string()),
            m.ratio
                .map_or_else(|| "-".to_string(), |r| format!("{r:.2}")),
            m.unit,
            m.verdict,
            match (m.image, m.held) {
                (super::machine::QEMU_IMAGE, _) =>
                    " (the QEMU image's own bound, its records in it)",
                (_, true) => " (held)",
                _ => "",
            },
            m.loose
                .as_ref()
                .map_or_else(String::new, |why| format!("; loose: {why}"))
        );
    }
}

/// The plain-text table (also what the terminal shows).
pub fn table(b: &Bench) -> String {
    let mut out = header(b);
    const TASK_WIDTHS: [usize; 8] = [20, 6, 9, 9, 9, 10, 9, 9];
    let header = names("task|jobs|exec max|exec p99|exec avg|resp max|WCRT|deadline|verdict");
    let _ = writeln!(out, "\n{}", columns(&header, &TASK_WIDTHS));
    for t in &b.tasks {
        let _ = writeln!(out, "{}", columns(&task_cells(t), &TASK_WIDTHS));
    }
    machine_table(&mut out, b);
    const TOPIC_WIDTHS: [usize; 10] = [26, 6, 7, 9, 10, 9, 10, 9, 9, 9];
    let header =
        names("topic|level|samples|period|start max|→queued|job WCRT|→bus|msg WCRT|jitter|verdict");
    let _ = writeln!(out, "\n{}", columns(&header, &TOPIC_WIDTHS));
    for t in &b.topics {
        let [topic, level, samples, period, taken, queued, job, bus, message, delivery, analysed, verdict] =
            topic_cells(t);
        let jitter = format!("{delivery}/{analysed}");
        let cells = [
            topic, level, samples, period, taken, queued, job, bus, message, jitter, verdict,
        ];
        let _ = writeln!(out, "{}", columns(&cells, &TOPIC_WIDTHS));
    }
    let _ = writeln!(
        out,
        "\nµs; ≥: response from the run's start (no traced release: interrupts, message wake-ups), a lower bound; jitter: observed/analysed"
    );
    out
}

/// Markdown.
pub fn markdown(b: &Bench) -> String {
    let mut out = format!("# Bench: {}\n\n", b.board);
    for line in header(b).lines() {
        let _ = writeln!(out, "- {line}");
    }
    out.push_str("\n| task | jobs | exec max | exec p99 | exec mean | response max | WCRT | deadline | verdict |\n|---|---:|---:|---:|---:|---:|---:|---:|---|\n");
    for t in &b.tasks {
        let _ = writeln!(out, "{}", markdown_row(&task_cells(t)));
    }
    out.push_str("\n| topic | level | samples | period | release → taken max | → queued max | job WCRT | → bus max | message WCRT | delivery jitter | analysed jitter | verdict |\n|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|\n");
    for t in &b.topics {
        let _ = writeln!(out, "{}", markdown_row(&topic_cells(t)));
    }
    out.push_str("\nTimes in µs. ≥: measured from the run's start (no traced release), a lower bound of the response.\n");
    out
}

fn escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

/// One histogram per task: its responses in 40 bins, the analysed WCRT (red) and the deadline
/// (dashed) drawn in, on an axis that holds all three.
pub fn svg(b: &Bench) -> String {
    const W: f64 = 760.0;
    const PANEL: f64 = 96.0;
    const LEFT: f64 = 170.0;
    const BINS: usize = 40;
    let plot_w = W - LEFT - 20.0;
    let height = 40.0 + PANEL * b.tasks.len().max(1) as f64;
    let mut out = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{W}\" height=\"{height}\" font-family=\"sans-serif\" font-size=\"11\">\n\
         <text x=\"8\" y=\"18\" font-size=\"13\">{} ({} build): response times, WCRT (red) and deadline (dashed)</text>\n",
        escape(&b.board),
        escape(&b.build)
    );
    for (i, t) in b.tasks.iter().enumerate() {
        let top = 30.0 + PANEL * i as f64;
        let base = top + PANEL - 22.0;
        let max_resp = t.responses_us.iter().copied().fold(0.0, f64::max);
        let axis = [
            Some(max_resp),
            t.wcrt_us,
            t.deadline_us.filter(|d| d.is_finite()),
        ]
        .into_iter()
        .flatten()
        .fold(1.0_f64, f64::max)
            * 1.05;
        let mut bins = [0usize; BINS];
        for r in &t.responses_us {
            let k = ((r / axis) * BINS as f64) as usize;
            bins[k.min(BINS - 1)] += 1;
        }
        let tallest = bins.iter().copied().max().unwrap_or(1).max(1) as f64;
        let _ = writeln!(
            out,
            "<text x=\"8\" y=\"{:.1}\">{}</text><text x=\"8\" y=\"{:.1}\" fill=\"#555\">{} jobs, max {:.1} µs</text>",
            top + 30.0,
            escape(&t.task),
            top + 44.0,
            t.jobs,
            max_resp
        );
        let _ = writeln!(
            out,
            "<line x1=\"{LEFT}\" y1=\"{base:.1}\" x2=\"{:.1}\" y2=\"{base:.1}\" stroke=\"#000\"/>",
            LEFT + plot_w
        );
        let bar_w = plot_w / BINS as f64;
        for (k, &n) in bins.iter().enumerate() {
            if n == 0 {
                continue;
            }
            let h = (n as f64 / tallest) * (PANEL - 34.0);
            let _ = writeln!(
                out,
                "<rect x=\"{:.1}\" y=\"{:.1}\" width=\"{:.1}\" height=\"{h:.1}\" fill=\"#4a7ebb\"><title>{n}</title></rect>",
                LEFT + bar_w * k as f64,
                base - h,
                bar_w - 1.0
            );
        }
        let x = |v: f64| LEFT + plot_w * v / axis;
        if let Some(w) = t.wcrt_us {
            let _ = writeln!(
                out,
                "<line x1=\"{0:.1}\" y1=\"{1:.1}\" x2=\"{0:.1}\" y2=\"{base:.1}\" stroke=\"#c00\" stroke-width=\"2\"/><text x=\"{0:.1}\" y=\"{1:.1}\" fill=\"#c00\">WCRT {w:.1}</text>",
                x(w),
                top + 8.0
            );
        }
        if let Some(d) = t.deadline_us.filter(|d| d.is_finite()) {
            let _ = writeln!(
                out,
                "<line x1=\"{0:.1}\" y1=\"{1:.1}\" x2=\"{0:.1}\" y2=\"{base:.1}\" stroke=\"#000\" stroke-dasharray=\"4 3\"/><text x=\"{0:.1}\" y=\"{2:.1}\" text-anchor=\"end\">deadline {d:.0}</text>",
                x(d),
                top + 8.0,
                top + 20.0
            );
        }
        let _ = writeln!(
            out,
            "<text x=\"{LEFT}\" y=\"{:.1}\" fill=\"#555\">0</text><text x=\"{:.1}\" y=\"{:.1}\" fill=\"#555\" text-anchor=\"end\">{axis:.1} µs</text>",
            base + 13.0,
            LEFT + plot_w,
            base + 13.0
        );
        if t.verdict.starts_with("EXCEEDS") {
            let _ = writeln!(
                out,
                "<rect x=\"2\" y=\"{:.1}\" width=\"{:.1}\" height=\"{:.1}\" fill=\"none\" stroke=\"#c00\" stroke-width=\"2\"/>",
                top + 2.0,
                W - 4.0,
                PANEL - 4.0
            );
        }
    }
    out.push_str("</svg>\n");
    out
}
