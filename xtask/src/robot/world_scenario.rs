//! The robot scenarios with a world, each run on the three boards' real firmware in lock-step:
//!
//! - `world-ring` (`robot/scenarios/world-ring.log` in `robot/worlds/wall-approach.json`): the
//!   firmware drives the robot towards a wall past a post, and every proximity-ring reading on the
//!   bus is checked against the distance worked out from the trajectory; run twice, the
//!   trajectories and everything printed are identical;
//! - `world-avoidance`: `examples/obstacle_avoidance.py` in `robot/worlds/arena.json` for 60 s,
//!   no contact and at least 3 m travelled;
//! - `world-line`: `examples/line_following.py` round the closed line of
//!   `robot/worlds/line-lap.json`, a whole lap with a floor sensor over the line at ≥ 90 % of the
//!   ticks, worked out from the trajectory and the world.
//!
//! Each leaves `output.log`, `bus.log`, `trajectory.csv` and `world.svg` in its scenario folder.
use std::path::Path;

use anyhow::{bail, ensure, Context, Result};

use amiro_robot::world::WorldRun;
use amiro_robot::{Outcome, NODES};
use amiro_world::feed::ImuRevision;
use amiro_world::file::FloorShape;
use amiro_world::floor;
use amiro_world::geometry::{Segment, Vec2};
use amiro_world::output::Trajectory;
use amiro_world::ring::{expected_mm, tolerance_mm, Response};
use amiro_world::Arena;

/// The scenario's stimulus (`robot/scenarios/`) and world (`robot/worlds/`).
pub const STIMULUS: &str = "world-ring";
/// The world it runs in.
pub const WORLD: &str = "wall-approach";
/// The ring's sample frames (`proximity-ring` at medium: index byte, millimetres little-endian).
const RING_ID: u16 = 0x61F;
/// Readings outside their tolerance allowed (the tolerance is three standard deviations).
const OUTSIDE_PERCENT: f64 = 1.0;

/// How old a ring frame's reading may be, µs: none on the shipped image (its release reads the
/// ring); with `powermgmt/scripted-i2c` its bus owners' latest reading, at most an owner's period
/// (`sensors::scripted::OWNER_PERIOD_US`, 62.5 ms) and its response old (docs/i2c.md, "The
/// readings' age": 39.3 ms on the robot's analysis; in QEMU's lock-step run well under 5 ms).
pub fn ring_age_us(features: &[&str]) -> u64 {
    if features.contains(&"powermgmt/scripted-i2c") {
        62_500 + 5_000
    } else {
        0
    }
}

/// Runs the scenario twice; returns its summary line. A ring reading may be `ring_age_us` old
/// ([`ring_age_us`]).
pub fn run(root: &Path, firmware: &[amiro_robot::Firmware; 3], ring_age_us: u64) -> Result<String> {
    let stimulus = root
        .join("robot")
        .join("scenarios")
        .join(format!("{STIMULUS}.log"));
    let world_path = root
        .join("robot")
        .join("worlds")
        .join(format!("{WORLD}.json"));
    let (actions, duration) = amiro_robot::stimulus::read(&stimulus)?;
    let duration = duration.with_context(|| format!("{}: no `# duration:`", stimulus.display()))?;
    let mut runs = Vec::new();
    for k in 0..2 {
        let work = crate::workspace::qemu_target_dir(root)
            .join("scenarios")
            .join("robot")
            .join(format!("{STIMULUS}-{k}"));
        let _ = std::fs::remove_dir_all(&work);
        let mut world = WorldRun::load(&world_path, None, ImuRevision::Rev1_1)?;
        let mut lines: Vec<String> = Vec::new();
        let outcome = amiro_robot::run_in_world(
            firmware,
            &actions,
            duration,
            &work,
            &mut lines,
            None,
            Some(&mut world),
        )?;
        let csv = write_outputs(&work, &outcome, &world)?;
        runs.push((outcome, world, csv));
    }
    let (outcome, world, csv) = &runs[0];
    ensure!(
        *csv == runs[1].2,
        "the two runs' trajectories differ (same world, seed and stimulus)"
    );
    ensure!(
        outcome.text == runs[1].0.text,
        "the two runs printed different bytes"
    );
    let summary = world.summary();
    ensure!(
        summary.travelled_m > 0.1,
        "the robot travelled {:.3} m, expected more than 0.1 m at 0.1 m/s",
        summary.travelled_m
    );
    let ring = check_ring(
        outcome,
        world.world().arena(),
        world.trajectory(),
        ring_age_us,
    )?;
    Ok(format!(
        "{ring}; {summary}; twice, trajectories ({} rows) and {} bytes of output identical",
        world.trajectory().samples.len(),
        outcome.text.len()
    ))
}

/// Every ring reading on the bus against the distance worked out from the pose when its sample
/// was released (the trajectory interpolated), within `ring::tolerance_mm`; a reading up to
/// `age_us` old matches the pose at any time that long before the release (every millisecond).
fn check_ring(
    outcome: &Outcome,
    arena: &Arena,
    trajectory: &Trajectory,
    age_us: u64,
) -> Result<String> {
    let response = Response::AMIRO;
    let (mut readings, mut outside, mut seen, mut nearest) = (0usize, Vec::new(), 0, u16::MAX);
    for t in outcome
        .transfers
        .iter()
        .filter(|t| t.frame.id == RING_ID && NODES[t.node] == "powermgmt")
    {
        let &[index, lo, hi] = t.frame.payload() else {
            bail!(
                "a ring frame of {} bytes: {:02X?}",
                t.frame.len,
                t.frame.payload()
            );
        };
        let Some((position, heading)) = pose_at(trajectory, t.released_at) else {
            continue;
        };
        let mm = u16::from_le_bytes([lo, hi]);
        let expected = expected_mm(arena, position, heading, &response, usize::from(index));
        let tolerance = tolerance_mm(expected, &response);
        readings += 1;
        if expected < 200 {
            seen += 1;
            nearest = nearest.min(expected);
        }
        let within = |expected: u16| {
            (f64::from(mm) - f64::from(expected)).abs() <= tolerance_mm(expected, &response)
        };
        let earlier = (1..=age_us / 1_000).any(|ms| {
            t.released_at
                .checked_sub(ms * 1_000)
                .and_then(|at| pose_at(trajectory, at))
                .is_some_and(|(position, heading)| {
                    within(expected_mm(
                        arena,
                        position,
                        heading,
                        &response,
                        usize::from(index),
                    ))
                })
        });
        if !within(expected) && !earlier {
            outside.push(format!(
                "sensor {index} at {} µs: {mm} mm, expected {expected} ± {tolerance:.1} mm",
                t.released_at
            ));
        }
    }
    // A sample every 62.5 ms from 10 ms (every 20 ms before 2026-12-06): 31 in 2 s, some cut by the end.
    ensure!(readings >= 8 * 25, "only {readings} ring readings");
    ensure!(
        seen >= 50,
        "only {seen} readings had something within 200 mm (the wall and the post)"
    );
    let percent = 100.0 * outside.len() as f64 / readings as f64;
    if percent > OUTSIDE_PERCENT {
        bail!(
            "{} of {readings} ring readings ({percent:.1} %) outside their tolerance, first: {}",
            outside.len(),
            outside
                .iter()
                .take(5)
                .cloned()
                .collect::<Vec<_>>()
                .join("; ")
        );
    }
    Ok(format!(
        "{readings} ring readings ({seen} seeing the wall or the post, nearest {nearest} mm) match the trajectory's distances, {} ({percent:.2} %) outside 3 σ",
        outside.len()
    ))
}

/// The pose at `t_us`, linear between the trajectory's rows; `None` outside them.
fn pose_at(trajectory: &Trajectory, t_us: u64) -> Option<(Vec2, f64)> {
    let samples = &trajectory.samples;
    let after = samples.iter().position(|s| s.t_us >= t_us)?;
    let b = samples.get(after)?;
    let a = if after == 0 {
        b
    } else {
        samples.get(after - 1)?
    };
    let f = if b.t_us == a.t_us {
        0.0
    } else {
        (t_us - a.t_us) as f64 / (b.t_us - a.t_us) as f64
    };
    let lerp = |p: f64, q: f64| p + (q - p) * f;
    let mut turn = b.pose.heading - a.pose.heading;
    turn = (turn + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI;
    Some((
        Vec2 {
            x: lerp(a.pose.position.x, b.pose.position.x),
            y: lerp(a.pose.position.y, b.pose.position.y),
        },
        a.pose.heading + turn * f,
    ))
}

/// Writes a world run's outputs into `work`: everything printed (`output.log`), the bus log
/// (`bus.log`, candump -l), the trajectory (`trajectory.csv`) and the arena with the path
/// (`world.svg`). Returns the trajectory's bytes.
fn write_outputs(work: &Path, outcome: &Outcome, world: &WorldRun) -> Result<Vec<u8>> {
    std::fs::write(work.join("output.log"), &outcome.text)?;
    let (bus, _) = crate::qemu::split_output(&outcome.text);
    std::fs::write(work.join("bus.log"), bus)?;
    let mut csv = Vec::new();
    world.trajectory().write_csv(&mut csv)?;
    std::fs::write(work.join("trajectory.csv"), &csv)?;
    std::fs::write(
        work.join("world.svg"),
        world.trajectory().svg(world.world().arena()),
    )?;
    Ok(csv)
}

/// A behaviour's run: what it did and the wall time it took.
struct Behaviour {
    outcome: Outcome,
    world: WorldRun,
    wall_s: f64,
}

impl Behaviour {
    /// The motor commands the behaviour sent.
    fn motor_commands(&self) -> usize {
        self.outcome
            .transfers
            .iter()
            .filter(|t| t.frame.id == 0x110)
            .count()
    }
}

/// Runs `examples/EXAMPLE` (python from the interop venv) as the controller in lock-step with
/// the real firmware in `robot/worlds/WORLD` for `duration_us`, its outputs in the scenario
/// folder `name`.
fn behaviour(
    root: &Path,
    firmware: &[amiro_robot::Firmware; 3],
    name: &str,
    world: &str,
    example: &str,
    duration_us: u64,
) -> Result<Behaviour> {
    let python = crate::interop::venv(root, &crate::workspace::target_dir(root).join("interop"))?;
    let work = crate::workspace::qemu_target_dir(root)
        .join("scenarios")
        .join("robot")
        .join(name);
    let _ = std::fs::remove_dir_all(&work);
    let mut world = WorldRun::load(
        &root.join("robot").join("worlds").join(world),
        None,
        ImuRevision::Rev1_1,
    )?;
    let program = format!(
        "{} {}",
        python.display(),
        root.join("examples").join(example).display()
    );
    world.with_controller(&program, amiro_world::controller::DEFAULT_PERIOD_US)?;
    let started = std::time::Instant::now();
    let mut lines: Vec<String> = Vec::new();
    let outcome = amiro_robot::run_in_world(
        firmware,
        &[],
        duration_us,
        &work,
        &mut lines,
        None,
        Some(&mut world),
    );
    world.finish();
    let outcome = outcome?;
    let wall_s = started.elapsed().as_secs_f64();
    write_outputs(&work, &outcome, &world)?;
    Ok(Behaviour {
        outcome,
        world,
        wall_s,
    })
}

/// The obstacle-avoidance example's scenario: `examples/obstacle_avoidance.py` as the controller
/// against the real firmware in `robot/worlds/arena.json`.
pub const AVOIDANCE: &str = "world-avoidance";
/// Its virtual duration.
const AVOIDANCE_US: u64 = 60_000_000;

/// Runs `examples/obstacle_avoidance.py` in lock-step in the arena for [`AVOIDANCE_US`]: no
/// contact and at least 3 m travelled.
pub fn avoidance(root: &Path, firmware: &[amiro_robot::Firmware; 3]) -> Result<String> {
    let run = behaviour(
        root,
        firmware,
        AVOIDANCE,
        "arena.json",
        "obstacle_avoidance.py",
        AVOIDANCE_US,
    )?;
    let summary = run.world.summary();
    ensure!(summary.contacts == 0, "{summary}: a contact");
    ensure!(
        summary.travelled_m >= 3.0,
        "{summary}: less than 3 m in {} s",
        AVOIDANCE_US / 1_000_000
    );
    Ok(format!(
        "obstacle_avoidance.py drove the firmware for {} s ({} motor commands): {summary}; {:.1} s of wall time, the world's hooks {:.1} % of it",
        AVOIDANCE_US / 1_000_000,
        run.motor_commands(),
        run.wall_s,
        100.0 * run.world.wall.as_secs_f64() / run.wall_s.max(1e-9)
    ))
}

/// The line-following example's scenario: `examples/line_following.py` as the controller against
/// the real firmware in `robot/worlds/line-lap.json`.
pub const LINE: &str = "world-line";
/// Its virtual duration: a lap takes the example about 12 s.
const LINE_US: u64 = 14_000_000;
/// The share of the ticks at which a floor sensor must be over the line.
const OVER_LINE_PERCENT: f64 = 90.0;

/// Runs `examples/line_following.py` in lock-step on the lap for [`LINE_US`]: a whole lap of the
/// closed line, and a floor sensor over the line at [`OVER_LINE_PERCENT`] of the ticks, both
/// worked out from the trajectory and the world (not from what the example says).
pub fn line_following(root: &Path, firmware: &[amiro_robot::Firmware; 3]) -> Result<String> {
    let run = behaviour(
        root,
        firmware,
        LINE,
        "line-lap.json",
        "line_following.py",
        LINE_US,
    )?;
    let arena = run.world.world().arena();
    let trajectory = run.world.trajectory();
    let (segments, _) = closed_line(arena)?;
    let lap = lap_time(segments, trajectory);
    let over = over_line_percent(arena, trajectory);
    let summary = run.world.summary();
    let lap_s = lap.with_context(|| {
        format!(
            "{summary}: no whole lap of the line in {} s",
            LINE_US / 1_000_000
        )
    })? as f64
        / 1e6;
    ensure!(
        over >= OVER_LINE_PERCENT,
        "{summary}: a floor sensor over the line at only {over:.1} % of the ticks"
    );
    Ok(format!(
        "line_following.py drove the firmware round the lap in {lap_s:.2} s ({} motor commands), a floor sensor over the line at {over:.1} % of {} ticks: {summary}; {:.1} s of wall time for {} s, the world's hooks {:.1} % of it",
        run.motor_commands(),
        trajectory.samples.len(),
        run.wall_s,
        LINE_US / 1_000_000,
        100.0 * run.world.wall.as_secs_f64() / run.wall_s.max(1e-9)
    ))
}

/// The arena's one closed floor line: its segments in order and its length.
fn closed_line(arena: &Arena) -> Result<(&[Segment], f64)> {
    let mut lines = arena.floor.iter().filter_map(|patch| match &patch.shape {
        FloorShape::Line { segments, .. } => Some(segments.as_slice()),
        FloorShape::Polygon(_) => None,
    });
    let (Some(segments), None) = (lines.next(), lines.next()) else {
        bail!("the lap's world must have exactly one floor line");
    };
    let (Some(first), Some(last)) = (segments.first(), segments.last()) else {
        bail!("the lap's floor line has no segments");
    };
    ensure!(
        first.a.minus(last.b).length() < 1e-9,
        "the lap's floor line is not closed"
    );
    let length = segments.iter().map(|s| s.b.minus(s.a).length()).sum();
    Ok((segments, length))
}

/// How far along the closed line `segments` the point nearest `p` lies (m from its start).
fn along(segments: &[Segment], p: Vec2) -> f64 {
    let (mut best, mut best_s, mut start) = (f64::INFINITY, 0.0, 0.0);
    for s in segments {
        let d = s.distance_to(p);
        if d < best {
            best = d;
            best_s = start + s.nearest_point(p).minus(s.a).length();
        }
        start += s.b.minus(s.a).length();
    }
    best_s
}

/// When the robot has gone once round the closed line (its progress along the line, from the
/// nearest point at each row, summed with the wrap-around), in µs; `None` if it never has.
fn lap_time(segments: &[Segment], trajectory: &Trajectory) -> Option<u64> {
    let length: f64 = segments.iter().map(|s| s.b.minus(s.a).length()).sum();
    let mut samples = trajectory.samples.iter();
    let mut previous = along(segments, samples.next()?.pose.position);
    let mut progress = 0.0f64;
    for sample in samples {
        let now = along(segments, sample.pose.position);
        let step = (now - previous + length / 2.0).rem_euclid(length) - length / 2.0;
        progress += step;
        previous = now;
        if progress.abs() >= length {
            return Some(sample.t_us);
        }
    }
    None
}

/// The share of the trajectory's rows (one per tick) at which at least one floor sensor's
/// centre is over a dark part of the floor (grey below 128), in %.
fn over_line_percent(arena: &Arena, trajectory: &Trajectory) -> f64 {
    let rows = trajectory.samples.len();
    let over = trajectory
        .samples
        .iter()
        .filter(|s| {
            floor::POSITIONS_M.iter().any(|&(x, y)| {
                let p = Vec2::new(x, y).to_world(s.pose.position, s.pose.heading);
                arena.grey_at(p) < 128
            })
        })
        .count();
    100.0 * over as f64 / rows.max(1) as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use amiro_world::Pose;

    /// A square line, 1 m round, the robot at its start heading along it.
    fn square() -> Arena {
        Arena::parse(
            r#"{ "robot": { "x": 0.5, "y": 0.5, "heading_deg": 0 },
                 "floor": [ { "line": [[0.5, 0.5], [0.75, 0.5], [0.75, 0.75], [0.5, 0.75]],
                              "width": 0.03, "grey": 0, "closed": true } ] }"#,
        )
        .expect("the square")
    }

    /// Rows every 10 ms along the square's line from its start for `metres` (negative: the
    /// other way round), `offset` m to the left of it.
    fn along_square(metres: f64, offset: f64) -> Trajectory {
        let corners: [(f64, f64); 4] = [(0.5, 0.5), (0.75, 0.5), (0.75, 0.75), (0.5, 0.75)];
        let mut t = Trajectory::default();
        let rows = (metres.abs() / 0.002).round() as u64;
        for k in 0..=rows {
            let s = (k as f64 * 0.002 * metres.signum()).rem_euclid(1.0);
            let side = ((s / 0.25) as usize).min(3);
            let (a, b) = (corners[side], corners[(side + 1) % 4]);
            let f = (s - side as f64 * 0.25) / 0.25;
            let heading = (b.1 - a.1).atan2(b.0 - a.0);
            let p = Vec2::new(a.0 + (b.0 - a.0) * f, a.1 + (b.1 - a.1) * f);
            let left = Vec2::new(-heading.sin(), heading.cos()).scale(offset);
            t.record(
                k * 10_000,
                Pose {
                    position: p.plus(left),
                    heading,
                },
            );
        }
        t
    }

    #[test]
    fn a_lap_is_once_round_the_line_either_way() {
        let arena = square();
        let (segments, length) = closed_line(&arena).expect("one closed line");
        assert!((length - 1.0).abs() < 1e-9);
        // 1.1 m: the lap ends at 1 m, row 500.
        let lap = lap_time(segments, &along_square(1.1, 0.0)).expect("a lap");
        assert!((4_990_000..=5_010_000).contains(&lap), "{lap}");
        assert!(lap_time(segments, &along_square(-1.1, 0.0)).is_some());
        assert_eq!(lap_time(segments, &along_square(0.9, 0.0)), None);
    }

    #[test]
    fn the_rows_over_the_line_are_counted_from_the_sensors_positions() {
        let arena = square();
        // Centred: the front sensors (12 mm either side) are on the 30 mm line, except just
        // past each corner, where the front pair 40 mm ahead overshoots it.
        let centred = over_line_percent(&arena, &along_square(0.5, 0.0));
        assert!(centred > 90.0, "{centred} %");
        // 60 mm to the side: every sensor (at most 28 mm from the centre) is off it, except
        // round the corners, where the line turns under the body.
        let aside = over_line_percent(&arena, &along_square(0.5, 0.06));
        assert!(aside < 30.0, "{aside} %");
    }

    #[test]
    fn a_world_without_one_closed_line_is_refused() {
        let open = Arena::parse(
            r#"{ "robot": { "x": 0.5, "y": 0.5, "heading_deg": 0 },
                 "floor": [ { "line": [[0.5, 0.5], [0.75, 0.5]], "width": 0.03, "grey": 0 } ] }"#,
        )
        .expect("an open line");
        assert!(closed_line(&open).is_err());
        let none = Arena::parse(r#"{ "robot": { "x": 0.5, "y": 0.5, "heading_deg": 0 } }"#)
            .expect("no line");
        assert!(closed_line(&none).is_err());
    }
}
