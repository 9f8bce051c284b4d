//! The robot scenario with a world (`robot/scenarios/world-ring.log` in
//! `robot/worlds/wall-approach.json`): the firmware drives the robot towards a wall past a post,
//! and every proximity-ring reading on the bus is checked against the distance worked out from the
//! trajectory; run twice, the trajectories and everything printed are identical.
use std::path::Path;

use anyhow::{bail, ensure, Context, Result};

use amiro_robot::world::WorldRun;
use amiro_robot::{Outcome, NODES};
use amiro_world::feed::ImuRevision;
use amiro_world::geometry::Vec2;
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

/// Runs the scenario twice; returns its summary line.
pub fn run(root: &Path, firmware: &[amiro_robot::Firmware; 3]) -> Result<String> {
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
        let work = crate::qemu::target_dir(root)
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
        std::fs::write(work.join("output.log"), &outcome.text)?;
        let mut csv = Vec::new();
        world.trajectory().write_csv(&mut csv)?;
        std::fs::write(work.join("trajectory.csv"), &csv)?;
        std::fs::write(
            work.join("world.svg"),
            world.trajectory().svg(world.world().arena()),
        )?;
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
    let ring = check_ring(outcome, world.world().arena(), world.trajectory())?;
    Ok(format!(
        "{ring}; {summary}; twice, trajectories ({} rows) and {} bytes of output identical",
        world.trajectory().samples.len(),
        outcome.text.len()
    ))
}

/// Every ring reading on the bus against the distance worked out from the pose when its sample
/// was released (the trajectory interpolated), within `ring::tolerance_mm`.
fn check_ring(outcome: &Outcome, arena: &Arena, trajectory: &Trajectory) -> Result<String> {
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
        if (f64::from(mm) - f64::from(expected)).abs() > tolerance {
            outside.push(format!(
                "sensor {index} at {} µs: {mm} mm, expected {expected} ± {tolerance:.1} mm",
                t.released_at
            ));
        }
    }
    ensure!(readings >= 8 * 50, "only {readings} ring readings");
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

/// The obstacle-avoidance example's scenario: `examples/obstacle_avoidance.py` as the controller
/// against the real firmware in `robot/worlds/arena.json`.
pub const AVOIDANCE: &str = "world-avoidance";
/// Its virtual duration.
const AVOIDANCE_US: u64 = 60_000_000;

/// Runs `examples/obstacle_avoidance.py` (python from the interop venv) in lock-step in the arena
/// for [`AVOIDANCE_US`]: no contact and at least 3 m travelled.
pub fn avoidance(root: &Path, firmware: &[amiro_robot::Firmware; 3]) -> Result<String> {
    let python = crate::interop::venv(root, &crate::workspace::target_dir(root).join("interop"))?;
    let work = crate::qemu::target_dir(root)
        .join("scenarios")
        .join("robot")
        .join(AVOIDANCE);
    let _ = std::fs::remove_dir_all(&work);
    let arena = root.join("robot").join("worlds").join("arena.json");
    let mut world = WorldRun::load(&arena, None, ImuRevision::Rev1_1)?;
    let program = format!(
        "{} {}",
        python.display(),
        root.join("examples")
            .join("obstacle_avoidance.py")
            .display()
    );
    world.with_controller(&program, amiro_world::controller::DEFAULT_PERIOD_US)?;
    let started = std::time::Instant::now();
    let mut lines: Vec<String> = Vec::new();
    let outcome = amiro_robot::run_in_world(
        firmware,
        &[],
        AVOIDANCE_US,
        &work,
        &mut lines,
        None,
        Some(&mut world),
    );
    world.finish();
    let outcome = outcome?;
    let wall = started.elapsed().as_secs_f64();
    std::fs::write(work.join("output.log"), &outcome.text)?;
    let mut csv = Vec::new();
    world.trajectory().write_csv(&mut csv)?;
    std::fs::write(work.join("trajectory.csv"), &csv)?;
    std::fs::write(
        work.join("world.svg"),
        world.trajectory().svg(world.world().arena()),
    )?;
    let summary = world.summary();
    ensure!(summary.contacts == 0, "{summary}: a contact");
    ensure!(
        summary.travelled_m >= 3.0,
        "{summary}: less than 3 m in {} s",
        AVOIDANCE_US / 1_000_000
    );
    let motor = outcome
        .transfers
        .iter()
        .filter(|t| t.frame.id == 0x110)
        .count();
    Ok(format!(
        "obstacle_avoidance.py drove the firmware for {} s ({motor} motor commands): {summary}; {wall:.1} s of wall time, the world's hooks {:.1} % of it",
        AVOIDANCE_US / 1_000_000,
        100.0 * world.wall.as_secs_f64() / wall.max(1e-9)
    ))
}
