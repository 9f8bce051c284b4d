//! Reading the scenario: its one-shots as publishers, the timing files, and the scenario's topics checked
//! against the protocol's table and planned onto the boards that own them.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use amiro_can::{Priority, Topic, TopicInfo};

use super::{
    board_folder, display, fail, read_json, BuildError, Scenario, ScenarioPublisher, Timing,
    MODELS_DIR,
};

/// A topic the scenario puts on the bus: its protocol entry, its CAN priority and its index in the scenario's
/// `publishers` or `commands`.
pub(super) struct Planned {
    pub(super) info: &'static TopicInfo,
    pub(super) priority: Priority,
    pub(super) index: usize,
}

/// The scenario's topics: sensors (published) and actuators (commanded).
pub(super) struct Plan {
    pub(super) sensors: Vec<Planned>,
    pub(super) commands: Vec<Planned>,
}

/// The timing files with their names relative to `root`; a second file for one board is an error.
pub(super) fn read_timings(
    root: &Path,
    timing_paths: &[PathBuf],
) -> Result<Vec<(String, Timing)>, BuildError> {
    let mut timings = Vec::new();
    for path in timing_paths {
        let timing: Timing = read_json(root, path)?;
        let file = display(root, path);
        if timings
            .iter()
            .any(|(_, t): &(String, Timing)| t.board == timing.board)
        {
            return Err(fail(
                &file,
                "board",
                format!("a second timing file for board `{}`", timing.board),
            ));
        }
        timings.push((file, timing));
    }
    Ok(timings)
}

/// The scenario's publishers and commands checked against the protocol's topic table (a sensor published, an
/// actuator commanded, each topic once, positive periods) and against the timing files (the topic's board has
/// one).
pub(super) fn plan(
    scenario: &Scenario,
    scenario_file: &str,
    timings: &[(String, Timing)],
) -> Result<Plan, BuildError> {
    let mut sensors: Vec<Planned> = Vec::new();
    let mut seen = BTreeSet::new();
    for (i, p) in scenario.publishers.iter().enumerate() {
        let (info, priority) = topic_and_priority(
            scenario_file,
            &format!("publishers[{i}]"),
            &p.topic,
            &p.priority,
        )?;
        if !info.is_sensor {
            return Err(fail(
                scenario_file,
                format!("publishers[{i}].topic"),
                format!("`{}` is an actuator: list it under `commands`", p.topic),
            ));
        }
        if !seen.insert(info.topic) {
            return Err(fail(
                scenario_file,
                format!("publishers[{i}].topic"),
                format!("`{}` is published twice", p.topic),
            ));
        }
        check_positive(
            scenario_file,
            &format!("publishers[{i}].period_us"),
            p.period_us,
        )?;
        sensors.push(Planned {
            info,
            priority,
            index: i,
        });
    }
    let mut commands: Vec<Planned> = Vec::new();
    for (i, c) in scenario.commands.iter().enumerate() {
        let (info, priority) = topic_and_priority(
            scenario_file,
            &format!("commands[{i}]"),
            &c.topic,
            &c.priority,
        )?;
        if info.is_sensor {
            return Err(fail(
                scenario_file,
                format!("commands[{i}].topic"),
                format!("`{}` is a sensor: list it under `publishers`", c.topic),
            ));
        }
        if !seen.insert(info.topic) {
            return Err(fail(
                scenario_file,
                format!("commands[{i}].topic"),
                format!("`{}` is listed twice", c.topic),
            ));
        }
        check_positive(
            scenario_file,
            &format!("commands[{i}].period_us"),
            c.period_us,
        )?;
        commands.push(Planned {
            info,
            priority,
            index: i,
        });
    }
    for planned in sensors.iter().chain(&commands) {
        let board = board_folder(planned.info.board);
        if !timings.iter().any(|(_, t)| t.board == board) {
            return Err(fail(
                scenario_file,
                "",
                format!(
                    "topic `{}` lives on board `{board}`, which has no timing file in {MODELS_DIR}",
                    planned.info.name
                ),
            ));
        }
    }
    Ok(Plan { sensors, commands })
}

/// The scenario with each one-shot as a publisher of its topic at its priority every
/// [`amiro_can::ONE_SHOT_INTERVAL_MS`], and a note per one-shot saying so. A one-shot of a published topic, of an
/// actuator or listed twice is an error naming its field.
pub(super) fn one_shots_as_publishers(
    mut scenario: Scenario,
    file: &str,
) -> Result<(Scenario, Vec<String>), BuildError> {
    let mut notes = Vec::new();
    let one_shots = core::mem::take(&mut scenario.one_shots);
    for (i, o) in one_shots.iter().enumerate() {
        let path = format!("one_shots[{i}]");
        let (info, _) = topic_and_priority(file, &path, &o.topic, &o.priority)?;
        if !info.is_sensor {
            return Err(fail(
                file,
                format!("{path}.topic"),
                format!(
                    "`{}` is an actuator: a one-shot asks for a sensor sample",
                    o.topic
                ),
            ));
        }
        let listed = |topic: &str| Topic::from_name(topic).is_some_and(|t| t == info.topic);
        if one_shots[..i].iter().any(|earlier| listed(&earlier.topic)) {
            return Err(fail(
                file,
                format!("{path}.topic"),
                format!("`{}` is listed twice", o.topic),
            ));
        }
        if scenario.publishers.iter().any(|p| listed(&p.topic)) {
            return Err(fail(
                file,
                format!("{path}.topic"),
                format!(
                    "`{}` is also published: a one-shot stops the topic's publisher, list it once",
                    o.topic
                ),
            ));
        }
        let interval_us = u64::from(amiro_can::ONE_SHOT_INTERVAL_MS) * 1000;
        notes.push(format!(
            "one-shot {} at {}: analysed as a sample every {interval_us} µs (how often a board takes a one-shot at most; docs/analysis.md)",
            info.name, o.priority
        ));
        scenario.publishers.push(ScenarioPublisher {
            topic: o.topic.clone(),
            priority: o.priority.clone(),
            period_us: interval_us as f64,
            deadline_us: None,
            jitter_budget_us: None,
        });
    }
    Ok((scenario, notes))
}

pub(super) fn check_positive(file: &str, path: &str, value: f64) -> Result<(), BuildError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(fail(
            file,
            path,
            format!("must be a number > 0, got {value}"),
        ))
    }
}

fn topic_and_priority(
    file: &str,
    path: &str,
    topic: &str,
    priority: &str,
) -> Result<(&'static TopicInfo, Priority), BuildError> {
    let t = Topic::from_name(topic).ok_or_else(|| {
        let known: Vec<&str> = amiro_can::TOPICS.iter().map(|i| i.name).collect();
        fail(
            file,
            format!("{path}.topic"),
            format!("unknown topic `{topic}` (known: {})", known.join(", ")),
        )
    })?;
    let p = Priority::from_name(priority).ok_or_else(|| {
        fail(
            file,
            format!("{path}.priority"),
            format!("`{priority}` is not urgent, high, medium or low"),
        )
    })?;
    Ok((t.info(), p))
}
