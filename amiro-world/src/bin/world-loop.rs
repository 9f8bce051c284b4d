//! `world-loop`: a behaviour in a world without the firmware (amiro_world::kinematic), for
//! trying a behaviour and for the examples' CI checks. Prints the end line and the figures the
//! checks read; writes the trajectory CSV, the arena's SVG and the bus log on request (the last
//! two make a Foxglove recording with `amiro record --world --trajectory`).

use std::path::PathBuf;
use std::time::Duration;

use amiro_world::controller::{Controller, DEFAULT_PERIOD_US};
use amiro_world::{kinematic, Arena, World};
use anyhow::{Context, Result};
use clap::Parser;

/// Runs an operator-side behaviour (the controller protocol on its stdin/stdout) against a world.
#[derive(Parser)]
#[command(name = "world-loop")]
struct Args {
    /// The world file (JSON; docs/world.md).
    world: PathBuf,
    /// The behaviour's command line (split on whitespace).
    #[arg(long)]
    controller: String,
    /// Virtual time to run, seconds.
    #[arg(long, default_value_t = 10.0)]
    duration_s: f64,
    /// Controller period, µs.
    #[arg(long, default_value_t = DEFAULT_PERIOD_US)]
    period_us: u64,
    /// Noise seed (default: the world's).
    #[arg(long)]
    seed: Option<u64>,
    /// How long to wait for the behaviour's `ok`, wall-clock seconds.
    #[arg(long, default_value_t = 10.0)]
    timeout_s: f64,
    /// Write the trajectory here (CSV).
    #[arg(long)]
    trajectory: Option<PathBuf>,
    /// Write the arena with the path here (SVG).
    #[arg(long)]
    svg: Option<PathBuf>,
    /// Write every frame of the loop here (`candump -l`, virtual time), as a robot run's bus log.
    #[arg(long)]
    bus_log: Option<PathBuf>,
}

fn main() -> Result<()> {
    let args = Args::parse();
    let arena = Arena::load(&args.world)?;
    let mut world = match args.seed {
        Some(seed) => World::with_seed(seed, arena),
        None => World::new(arena),
    };
    let timeout = Duration::try_from_secs_f64(args.timeout_s).context("--timeout-s")?;
    let duration_us = (args.duration_s.max(0.0) * 1e6).round() as u64;
    let mut controller = Controller::spawn(&args.controller, timeout)?;
    let outcome = kinematic::run(&mut world, &mut controller, duration_us, args.period_us)?;
    controller.finish();
    if let Some(path) = &args.trajectory {
        let mut file = std::io::BufWriter::new(
            std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?,
        );
        outcome
            .trajectory
            .write_csv(&mut file)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    if let Some(path) = &args.svg {
        std::fs::write(path, outcome.trajectory.svg(world.arena()))
            .with_context(|| format!("writing {}", path.display()))?;
    }
    if let Some(path) = &args.bus_log {
        let mut text = outcome.bus_log.join("\n");
        text.push('\n');
        std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))?;
    }
    let dark = if outcome.ticks == 0 {
        0.0
    } else {
        100.0 * outcome.ticks_over_dark as f64 / outcome.ticks as f64
    };
    println!(
        "world: {} ticks, a floor sensor over dark at {:.1} % of them, {} frames ignored",
        outcome.ticks, dark, outcome.ignored_frames
    );
    let leds: Vec<String> = outcome
        .leds
        .iter()
        .map(|[r, g, b]| format!("{r:02x}{g:02x}{b:02x}"))
        .collect();
    println!("world: leds {}", leds.join(" "));
    println!("{}", outcome.summary);
    Ok(())
}
