//! Which tasks a board declares: read from its RTIC app (or its fallback), or, for a board without an app,
//! from its timing file; with the drift checks between app and timing file.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use super::{fail, AppSource, BuildError, Built, Timing};
use crate::model::GLOBAL_CRITICAL_SECTION;
use crate::rtic_source::{self, RticApp, RticTaskKind};

/// The declared tasks, `idle`, and every resource's static ceiling.
pub(super) type Declarations = (Vec<Declared>, Option<Declared>, BTreeMap<String, u32>);

/// A task as declared (by the app or the timing file).
pub(super) struct Declared {
    pub(super) name: String,
    pub(super) priority: u32,
    pub(super) hardware: bool,
    pub(super) shared: Vec<String>,
}

/// Reads the app (or its fallback) and returns the declared tasks, idle, every resource's users and a source line.
pub(super) fn declared_tasks(
    root: &Path,
    file: &str,
    timing: &Timing,
    built: &mut Built,
) -> Result<Declarations, BuildError> {
    let handlers = crate::sensor_bus::engine_handlers(&timing.sensor_buses)
        .map_err(|(field, e)| fail(file, field, e.to_string()))?;
    for name in timing.tasks.keys() {
        if let Some((b, _)) = handlers.iter().find(|(_, h)| h == name) {
            return Err(fail(
                file,
                format!("tasks.{name}"),
                format!(
                    "`{name}` is sensor_buses[{b}]'s engine handler: it is charged through the `<bus>_engine[<task>]` \
                     rows, not a budget of its own"
                ),
            ));
        }
    }
    let Some(app_source) = &timing.app else {
        return from_timing_file(file, timing, built);
    };
    let (app, used) = read_app(root, file, timing, app_source, built)?;
    let (mut tasks, idle, ceilings) = from_app(&app);
    // The buses' engine handlers are the engine's: at its priority, charged per script by its rows, no row here.
    for &(b, handler) in &handlers {
        let field = || {
            let h = timing
                .sensor_buses
                .get(b)
                .and_then(|bus| bus.engine.handlers.iter().position(|o| o == handler))
                .unwrap_or(0);
            format!("sensor_buses[{b}].engine.handlers[{h}]")
        };
        let engine = timing
            .sensor_buses
            .get(b)
            .map_or(0, |bus| bus.engine.priority);
        let Some(task) = app.task(handler) else {
            return Err(fail(
                file,
                field(),
                crate::sensor_bus::SensorBusError::UnknownHandler(handler.to_string()).to_string(),
            ));
        };
        if u32::from(task.priority) != engine {
            return Err(fail(
                file,
                field(),
                crate::sensor_bus::SensorBusError::HandlerPriority(
                    handler.to_string(),
                    u32::from(task.priority),
                    engine,
                )
                .to_string(),
            ));
        }
        // Its critical sections are not modelled (it has no row): it may lock only what no task above it uses.
        if let Some((resource, ceiling)) = task
            .shared
            .iter()
            .filter(|r| !app.is_lock_free(r))
            .filter_map(|r| ceilings.get(r).map(|c| (r, *c)))
            .find(|(_, c)| *c > engine)
        {
            return Err(fail(
                file,
                field(),
                crate::sensor_bus::SensorBusError::HandlerLocksAbove(
                    handler.to_string(),
                    resource.clone(),
                    ceiling,
                )
                .to_string(),
            ));
        }
        tasks.retain(|t| t.name != handler);
    }
    let handler_names: BTreeSet<&str> = handlers.iter().map(|&(_, h)| h).collect();
    check_drift(file, timing, &app, &used, &handler_names)?;
    built.sources.push(format!(
        "{}: {} tasks read from {used} (#[rtic::app], dispatchers {})",
        timing.board,
        app.tasks.len(),
        if app.dispatchers.is_empty() {
            "none".to_string()
        } else {
            app.dispatchers.join(", ")
        }
    ));
    Ok((tasks, idle, ceilings))
}

/// A board without an app yet: the timing file declares the tasks (priority, binding, shared resources).
fn from_timing_file(
    file: &str,
    timing: &Timing,
    built: &mut Built,
) -> Result<Declarations, BuildError> {
    let mut tasks = Vec::new();
    for (name, t) in &timing.tasks {
        let priority = t.priority.ok_or_else(|| {
            fail(
                file,
                format!("tasks.{name}.priority"),
                "required while the board has no app (`app` is null)",
            )
        })?;
        let shared = t.shared.clone().unwrap_or_else(|| {
            t.critical_sections_us
                .keys()
                .filter(|k| k.as_str() != GLOBAL_CRITICAL_SECTION)
                .cloned()
                .collect()
        });
        tasks.push(Declared {
            name: name.clone(),
            priority,
            hardware: t.binds.is_some(),
            shared,
        });
    }
    let mut ceilings = BTreeMap::new();
    for t in &tasks {
        for r in &t.shared {
            let c = ceilings.entry(r.clone()).or_insert(0);
            *c = (*c).max(t.priority);
        }
    }
    built.sources.push(format!(
        "{}: no app yet — {} tasks declared in {file}",
        timing.board,
        tasks.len()
    ));
    Ok((tasks, None, ceilings))
}

/// The app with the analysed build's features, or its fallback (with a warning) when the app declares none of the
/// budgeted tasks; and the file actually read.
fn read_app(
    root: &Path,
    file: &str,
    timing: &Timing,
    app_source: &AppSource,
    built: &mut Built,
) -> Result<(RticApp, String), BuildError> {
    let publishers = publisher_tasks(timing);
    let features: Vec<&str> = app_source.features.iter().map(String::as_str).collect();
    let read = |relative: &str| -> Result<RticApp, BuildError> {
        let path = root.join(relative);
        let text = std::fs::read_to_string(&path)
            .map_err(|e| fail(file, "app.source", format!("cannot read {relative}: {e}")))?;
        let app = rtic_source::parse_app(&text).map_err(|e| fail(relative, "", e.to_string()))?;
        Ok(app.with_features(&features))
    };
    let mut used = app_source.source.clone();
    let mut app = read(&app_source.source)?;
    let budgeted = |app: &RticApp| {
        app.tasks
            .iter()
            .any(|t| timing.tasks.contains_key(&t.name) || publishers.contains(t.name.as_str()))
    };
    if !budgeted(&app) {
        match &app_source.fallback {
            Some(fallback) => {
                built.warnings.push(format!(
                    "{}: {} declares none of the budgeted tasks yet (a skeleton?); analysed the fallback app {fallback} \
                     instead — it describes the app the timing file budgets, not the code",
                    timing.board, app_source.source
                ));
                app = read(fallback)?;
                used = fallback.clone();
            }
            None => {
                return Err(fail(
                    file,
                    "app.source",
                    format!(
                        "{} declares none of the tasks this file budgets",
                        app_source.source
                    ),
                ))
            }
        }
    }
    Ok((app, used))
}

/// The tasks, idle and static ceilings an app declares (`#[lock_free]` resources left out: they never block).
fn from_app(app: &RticApp) -> Declarations {
    let mut tasks = Vec::new();
    for t in &app.tasks {
        let shared = t
            .shared
            .iter()
            .filter(|r| !app.is_lock_free(r))
            .cloned()
            .collect();
        tasks.push(Declared {
            name: t.name.clone(),
            priority: u32::from(t.priority),
            hardware: matches!(t.kind, RticTaskKind::Hardware { .. }),
            shared,
        });
    }
    let idle = app.idle.as_ref().map(|t| Declared {
        name: t.name.clone(),
        priority: 0,
        hardware: false,
        shared: t
            .shared
            .iter()
            .filter(|r| !app.is_lock_free(r))
            .cloned()
            .collect(),
    });
    let mut ceilings = BTreeMap::new();
    for r in app.shared.iter().filter(|r| !r.lock_free) {
        let users = app
            .tasks
            .iter()
            .filter(|t| t.shared.contains(&r.name))
            .map(|t| u32::from(t.priority));
        ceilings.insert(r.name.clone(), users.max().unwrap_or(0));
    }
    (tasks, idle, ceilings)
}

/// Drift checks: every declared task budgeted (or one of the buses' engine handlers), every budget declared,
/// nothing the source decides overridden.
fn check_drift(
    file: &str,
    timing: &Timing,
    app: &RticApp,
    used: &str,
    handlers: &BTreeSet<&str>,
) -> Result<(), BuildError> {
    let publishers = publisher_tasks(timing);
    for t in &app.tasks {
        if !timing.tasks.contains_key(&t.name)
            && !publishers.contains(t.name.as_str())
            && !handlers.contains(t.name.as_str())
        {
            return Err(fail(
                file,
                "tasks",
                format!(
                    "task `{}` ({used}:{}) has no budget here: add `tasks.{}`",
                    t.name, t.line, t.name
                ),
            ));
        }
    }
    for (name, t) in &timing.tasks {
        if app.task(name).is_none() {
            return Err(fail(
                file,
                format!("tasks.{name}"),
                format!("budgets a task {used} does not declare"),
            ));
        }
        for (field, given) in [
            ("priority", t.priority.is_some()),
            ("binds", t.binds.is_some()),
            ("shared", t.shared.is_some()),
        ] {
            if given {
                return Err(fail(
                    file,
                    format!("tasks.{name}.{field}"),
                    format!("comes from {used}, not from the timing file"),
                ));
            }
        }
    }
    Ok(())
}

/// The timing file's publisher tasks (budgeted per topic, not as tasks).
fn publisher_tasks(timing: &Timing) -> BTreeSet<&str> {
    timing.publishers.values().map(String::as_str).collect()
}
