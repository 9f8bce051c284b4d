//! `cargo xtask analyze`: the worst-case response times of the boards and the CAN bus, end to end.
//!
//! Argument parsing, file loading and printing only; everything else is `schedule_analysis`
//! (docs/analysis.md explains the model files, the equations and the report).
use std::path::{Path, PathBuf};

use anyhow::{anyhow, Context, Result};
use schedule_analysis::model::{FrameCostSpec, Model};
use schedule_analysis::report::{self, Format, Report};
use schedule_analysis::{admission_host, scenario};

/// Models with at least this many tasks and messages report their progress on stderr.
const LARGE_MODEL: usize = 1_000;

/// Arguments of `cargo xtask analyze`.
#[derive(clap::Args, Debug)]
pub struct AnalyzeArgs {
    /// Scenario to analyse: a name in schedule-analysis/models (`thesis-demo`, the default) or a path to a
    /// `.scenario.json`. The boards' tasks come from their RTIC apps, the budgets from the timing files.
    pub scenario: Option<String>,
    /// Analyse a model file (the JSON model format of docs/analysis.md) instead of a scenario.
    #[arg(long, value_name = "FILE", conflicts_with = "scenario")]
    pub model: Option<PathBuf>,
    /// CAN frame cost: `thesis` (545 µs), `exact` (worst-case stuffing) or a number of µs per frame. Without it
    /// the model's own decides the verdict and the other model is shown beside it.
    #[arg(long, value_name = "thesis|exact|US", value_parser = parse_frame_cost)]
    pub frame_cost: Option<FrameCostSpec>,
    /// Output format: table, markdown, json or svg.
    #[arg(long, value_name = "table|markdown|json|svg", default_value = "table", value_parser = parse_format)]
    pub format: Format,
    /// Write the report to FILE instead of standard output.
    #[arg(long, value_name = "FILE")]
    pub output: Option<PathBuf>,
    /// Exit with failure when any deadline or jitter budget is missed (for CI); for a scenario with
    /// `expected_failures`, unless exactly those fail.
    #[arg(long)]
    pub check: bool,
    /// Also write the combined model (scenario + timing files + apps) in the JSON model format to FILE.
    #[arg(long, value_name = "FILE")]
    pub emit_model: Option<PathBuf>,
    /// The robot revision whose timing files to read (1-2, 1-1; docs/boards.md "Revisions"). Default:
    /// `AMIRO_REVISION` if set, else the models folder's files (1-1 budgets for DiWheelDrive).
    #[arg(long, value_name = "1-2|1-1")]
    pub revision: Option<String>,
}

fn parse_frame_cost(text: &str) -> Result<FrameCostSpec, String> {
    FrameCostSpec::parse(text)
}

fn parse_format(text: &str) -> Result<Format, String> {
    Format::parse(text)
        .ok_or_else(|| format!("unknown format `{text}`: expected table, markdown, json or svg"))
}

/// Runs the analysis and prints (or writes) the report. `Ok(true)`: everything is schedulable and within its
/// jitter budget under the frame-cost model that decides the verdict, or, for a scenario with
/// `expected_failures`, exactly those fail ([`Report::check_passes`]: what `--check` decides).
pub fn run(args: &AnalyzeArgs, root: &Path) -> Result<bool> {
    if let Some(revision) = &args.revision {
        match crate::revision::Choice::parse(Some(revision))? {
            crate::revision::Choice::Robot(robot) => crate::revision::select_models(robot),
            _ => anyhow::bail!("--revision {revision}: analyse one revision at a time"),
        }
    }
    let mut robot = None;
    let mut from_timing = None;
    let (model, title, sources, warnings, origin) = match &args.model {
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("reading {}", path.display()))?;
            let model = Model::from_json(&text).map_err(|e| anyhow!("{}: {e}", path.display()))?;
            let title = model
                .name
                .clone()
                .unwrap_or_else(|| path.display().to_string());
            (
                model,
                title,
                vec![format!("model file {}", path.display())],
                Vec::new(),
                path.display().to_string(),
            )
        }
        None => {
            let name = args
                .scenario
                .as_deref()
                .unwrap_or(scenario::DEFAULT_SCENARIO);
            let path = scenario::find_scenario(root, name);
            let built = scenario::build(root, &path, &scenario::timing_files(root))?;
            // The boards' admission tables, from the same apps and timing files, for the on-chip check's cost.
            robot = Some(admission_host::lower(
                root,
                &scenario::timing_files(root),
                built
                    .model
                    .can
                    .as_ref()
                    .map_or(schedule_analysis::can::DEFAULT_BITRATE, |c| c.bitrate),
                args.frame_cost.unwrap_or(built.frame_cost),
            )?);
            let title = built.model.name.clone().unwrap_or_else(|| name.to_string());
            // A set the machine-code bounds break: which bound, and that the analysis keeps it.
            let mut warnings = built.warnings.clone();
            warnings.extend(scenario::breaking_bounds(
                &built,
                args.frame_cost.unwrap_or(built.frame_cost),
            ));
            let parts = (
                built.model.clone(),
                title,
                built.sources.clone(),
                warnings,
                "the built model".to_string(),
            );
            from_timing = Some((built, path));
            parts
        }
    };
    if let Some(path) = &args.emit_model {
        std::fs::write(path, model.to_json() + "\n")
            .with_context(|| format!("writing {}", path.display()))?;
    }
    let system = model.validate().map_err(|e| anyhow!("{origin}: {e}"))?;
    // Large models take seconds: say what is being analysed on stderr (the report itself goes to stdout).
    let entities = system.boards.iter().map(|b| b.tasks.len()).sum::<usize>()
        + system.bus.as_ref().map_or(0, |b| b.messages.len());
    let started = std::time::Instant::now();
    let mut progress = |step: &str| {
        if entities >= LARGE_MODEL {
            eprintln!(
                "analyze: {:>7.1} s  {step}",
                started.elapsed().as_secs_f64()
            );
        }
    };
    let report = Report::build_with_progress(
        &system,
        title,
        sources,
        warnings,
        args.frame_cost,
        &mut progress,
    );
    let report = match &from_timing {
        Some((built, path)) => {
            // The same scenario again with every held bound used: what the verdict would be on the machine
            // code's bounds (docs/analysis.md, "The verdict on the bounds"); the verdict stays the first run's.
            progress("on every held bound");
            let on_bounds = scenario::on_held_bounds(
                root,
                path,
                &scenario::timing_files(root),
                args.frame_cost.unwrap_or(built.frame_cost),
                &report.primary,
            )?;
            report
                .with_budget_sources(built)
                .with_on_bounds(on_bounds)
                .with_expected_failures(&built.expected_failures)
        }
        None => report,
    };
    let report = match &robot {
        Some(robot) => {
            progress("on-chip admission check cost");
            report.with_admission_cost(robot)
        }
        None => report,
    };
    progress("done");
    let text = report::render(&report, args.format);
    match &args.output {
        Some(path) => {
            std::fs::write(path, &text).with_context(|| format!("writing {}", path.display()))?;
            eprintln!(
                "wrote {} ({})",
                path.display(),
                if report.all_ok() {
                    "schedulable"
                } else {
                    "NOT schedulable"
                }
            );
        }
        None => print!("{text}"),
    }
    Ok(report.check_passes())
}
