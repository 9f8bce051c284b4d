//! LightRing 1-2's QEMU scenarios (`lightring/qemu/rev-1-2/*.log`, and the board's shared `led3`,
//! `malformed`, `flood` and `shutdown` logs): the eight LED topics on 24 RGB LEDs, three chained
//! TLC5947 latched as one 72-channel chain. The checks are 1-0's with the chain of three, and each
//! scenario also states the channels it expects itself (docs/protocol.md's table), so the run checks
//! the driver's mapping, not only agreement with it.
use amiro_sensors::drivers::tlc5947::gamma;
use anyhow::{ensure, Context, Result};

use super::lightring::{self, latches, led_sets};
use super::{Bounds, RunOutput, Scenario};

/// Three TLC5947 on the 1-2 ring.
const CHIPS: usize = 3;

/// Every scenario CI runs on the 1-2 build.
pub const SCENARIOS: &[Scenario] = &[
    Scenario {
        name: "all-eight",
        about: "all eight LED topics, each its own colour, on their groups of three of the 24 LEDs",
        check: all_eight,
    },
    Scenario {
        name: "led3",
        about: "the thesis's LED 3 on its three LEDs (chain channels 18..26), latched within the analysed bound",
        check: led3,
    },
    Scenario {
        name: "malformed",
        about: "malformed LED frames rejected with their reasons, the 72 channels unchanged (the shared log)",
        check: malformed,
    },
    Scenario {
        name: "flood",
        about: "LED commands at 50 µs: a queued burst applied in order, the excess counted, one latch per 3 ms",
        check: flood,
    },
    Scenario {
        name: "admission",
        about: "the admission check on a 1-2 robot (the shared log): diagnostics at 1 µs refused, at 21 ms accepted (a 1-2 robot admits 7 ms, 2 to 6 ms are refused), at urgent refused for DiWheelDrive's odometry, then warned; each verdict as the host decides; LED 3 on its three LEDs",
        check: admission,
    },
    Scenario {
        name: "shutdown",
        about: "SYS_PD_N falls: LEDs dark, SYS_SYNC_N low, hand-over, nothing after (the shared log)",
        check: lightring::shutdown,
    },
];

/// The channels protocol LED `led` must light on the 1-2 ring, written out from docs/protocol.md
/// (not from the driver): chain channels 9(n − 1) .. 9n − 1, red on every third from the first.
fn documented_channels(led: u8) -> [usize; 9] {
    let first = 9 * usize::from(led - 1);
    core::array::from_fn(|k| first + k)
}

/// Protocol LED `led` (1-based) in `colour`, the other seven dark.
fn only_led(led: usize, colour: [u8; 3]) -> [[u8; 3]; 8] {
    let mut colours = [[0u8; 3]; 8];
    if let Some(slot) = colours.get_mut(led.wrapping_sub(1)) {
        *slot = colour;
    }
    colours
}

/// Checks the run's last latch against colours per protocol LED with the documented table.
fn last_latch_shows(out: &RunOutput, colours: &[[u8; 3]; 8]) -> Result<()> {
    let last = latches(out, CHIPS)?.pop().context("no latch at all")?;
    shows_as_documented(&last.outputs, colours)
}

/// Checks a latch against colours per protocol LED with the documented table.
fn shows_as_documented(outputs: &[u16], colours: &[[u8; 3]; 8]) -> Result<()> {
    ensure!(
        outputs.len() == 72,
        "{} channels latched, expected 72",
        outputs.len()
    );
    let mut want = [0u16; 72];
    for (led, rgb) in (1u8..=8).zip(colours) {
        for (k, channel) in documented_channels(led).into_iter().enumerate() {
            want[channel] = gamma(rgb[k % 3]);
        }
    }
    for (channel, (got, want)) in outputs.iter().zip(want).enumerate() {
        ensure!(
            *got == want,
            "channel {channel} (part {}, OUT{}) latched {got:03X}, the table says {want:03X}",
            channel / 24,
            channel % 24
        );
    }
    Ok(())
}

fn all_eight(out: &RunOutput, bounds: &Bounds) -> Result<String> {
    // lightring/qemu/rev-1-2/all-eight.log
    let blues = [0x10, 0x80, 0x00, 0xFF, 0x40, 0xC0, 0x20, 0xA0];
    let commands: [(u64, [u8; 3]); 8] = core::array::from_fn(|i| {
        let step = 0x20 * i as u32;
        (
            10_000 + 1_250 * i as u64,
            [(step + 0x1F) as u8, (0xFF - step) as u8, blues[i]],
        )
    });
    let summary = lightring::all_eight_on(out, bounds, CHIPS, &commands)?;
    last_latch_shows(out, &commands.map(|(_, rgb)| rgb))?;
    Ok(format!(
        "{summary}; the 72 channels as docs/protocol.md's table says (LED n on channels 9(n-1)..9n-1)"
    ))
}

fn led3(out: &RunOutput, bounds: &Bounds) -> Result<String> {
    let summary = lightring::led3_on(out, bounds, CHIPS)?;
    last_latch_shows(out, &only_led(3, [0xFF, 0x80, 0x20]))?;
    Ok(summary)
}

fn malformed(out: &RunOutput, bounds: &Bounds) -> Result<String> {
    let summary = lightring::malformed_on(out, bounds, CHIPS)?;
    last_latch_shows(out, &only_led(5, [0x10, 0x20, 0x30]))?;
    Ok(format!("{summary}; LED 5 on channels 36..44 only"))
}

fn admission(out: &RunOutput, bounds: &Bounds) -> Result<String> {
    // A 1-2 robot admits the diagnostics at medium every 7 ms and more (6 ms: its frames 0x61C at 7 633 µs).
    let summary =
        lightring::admission_on(out, bounds, CHIPS, lightring::ADMITTED_DIAGNOSTICS_MS, 7)?;
    last_latch_shows(out, &only_led(3, [0xFF, 0x80, 0x20]))?;
    Ok(summary)
}

fn flood(out: &RunOutput, bounds: &Bounds) -> Result<String> {
    let summary = lightring::flood_on(out, bounds, CHIPS)?;
    // The latches keep the 3 ms interval start to start. A latch's trace is stamped at its end,
    // and the flood stretches some latches (the receive interrupt and the handler pre-empt them),
    // so n latches end within (n − 1) intervals minus the longest a latch may take (its analysed
    // WCRT bounds that) — the count, not each gap, is what the interval promises.
    let times: Vec<u64> = latches(out, CHIPS)?.iter().map(|l| l.at_us).collect();
    let interval = lightring::latch_interval_us(CHIPS);
    let stretch = bounds.led_latency_us(CHIPS)?;
    for (i, a) in times.iter().enumerate() {
        for (k, b) in times[i + 1..].iter().enumerate() {
            let n = k as u64 + 1;
            ensure!(
                b - a + stretch >= n * interval,
                "{n} latches after the one at {a} µs ended by {b} µs: more than one per {interval} µs"
            );
        }
    }
    let applied = led_sets(out)?.len();
    Ok(format!(
        "{summary}; {} latches for {applied} applied commands, at most one per {interval} µs",
        times.len()
    ))
}
