//! LightRing 1-0's QEMU scenarios (`lightring/qemu/*.log`) and what each must show, and the helpers
//! 1-2's (`super::lightring_1_2`) share: every check takes the ring's chain length (`chips`: one
//! TLC5947 on 1-0, three on 1-2).
//!
//! The QEMU build prints what the simulated TLC5947 chain really latched (`tlc5947 latched`
//! followed by its 24 × `chips` output values, chain channel 0 first) right before each
//! `leds-latched` trace event, so these checks see the driver's channel order and gamma table at
//! work, not only the firmware's intentions.
use std::path::Path;

use anyhow::{anyhow, bail, ensure, Context, Result};
use schedule_analysis::analysis::{analyse, Options};
use schedule_analysis::model::FrameCostSpec;
use schedule_analysis::scenario;

use amiro_sensors::drivers::tlc5947::{gamma, led_triples, CHANNELS};

use super::{check_health, trace_time, Bounds, RunOutput, Scenario};

/// Every LightRing scenario CI runs.
pub const SCENARIOS: &[Scenario] = &[
    Scenario {
        name: "led3",
        about: "the thesis's example: LED 3 to an RGB colour, latched within the analysed bound",
        check: led3,
    },
    Scenario {
        name: "all-eight",
        about: "all eight LEDs in one burst",
        check: all_eight,
    },
    Scenario {
        name: "other-boards",
        about: "other boards' commands and sensor data are ignored",
        check: other_boards,
    },
    Scenario {
        name: "malformed",
        about: "malformed LED frames rejected with their reasons, state unchanged",
        check: malformed,
    },
    Scenario {
        name: "flood",
        about: "LED commands at 50 µs: a queued burst applied in order, the excess counted",
        check: flood,
    },
    Scenario {
        name: "shutdown",
        about: "SYS_PD_N falls: LEDs dark, SYS_SYNC_N low, hand-over, nothing after",
        check: shutdown,
    },
    Scenario {
        name: "admission",
        about: "issue 11: diagnostics at 1 µs refused, at 21 ms accepted (20 ms is refused: the latch would miss its 2 ms deadline), at urgent refused for DiWheelDrive's odometry every 2 ms, then started with a warning; each verdict as the host decides; LEDs keep working",
        check: admission,
    },
];

/// The ring's chain length on 1-0.
const CHIPS: usize = 1;

/// The latched outputs of the whole chain, chain channel 0 first.
pub(super) type Outputs = Vec<u16>;

/// One latch: when XLAT rose and what the driver's outputs showed.
pub(super) struct Latch {
    pub(super) at_us: u64,
    pub(super) outputs: Outputs,
}

/// Every output dark.
pub(super) fn dark(chips: usize) -> Outputs {
    vec![0; CHANNELS * chips]
}

/// The latches of a run, in order; each line must carry the whole chain of `chips` parts.
pub(super) fn latches(out: &RunOutput, chips: usize) -> Result<Vec<Latch>> {
    let channels = CHANNELS * chips;
    let mut pending: Option<Outputs> = None;
    let mut latches = Vec::new();
    for note in &out.notes {
        if let Some(values) = note.strip_prefix("tlc5947 latched") {
            let parsed: Vec<u16> = values
                .split_whitespace()
                .map(|v| u16::from_str_radix(v, 16))
                .collect::<Result<_, _>>()
                .with_context(|| format!("bad latch line `{note}`"))?;
            ensure!(
                parsed.len() == channels,
                "`{note}`: {} outputs, expected {channels}",
                parsed.len()
            );
            pending = Some(parsed);
        } else if note.contains("trace leds-latched") {
            let outputs = pending
                .take()
                .with_context(|| format!("`{note}` without the driver's outputs before it"))?;
            latches.push(Latch {
                at_us: trace_time(note)?,
                outputs,
            });
        }
    }
    Ok(latches)
}

/// The LED commands the board applied: (time, LED, colour).
pub(super) fn led_sets(out: &RunOutput) -> Result<Vec<(u64, u8, [u8; 3])>> {
    out.traces("trace led-set")
        .into_iter()
        .map(|line| {
            let led = field(line, "led=")?
                .parse()
                .with_context(|| format!("bad LED in `{line}`"))?;
            let rgb = field(line, "rgb=")?;
            let byte = |i: usize| {
                rgb.get(2 * i..2 * i + 2)
                    .and_then(|h| u8::from_str_radix(h, 16).ok())
                    .with_context(|| format!("bad colour in `{line}`"))
            };
            Ok((trace_time(line)?, led, [byte(0)?, byte(1)?, byte(2)?]))
        })
        .collect()
}

fn field<'a>(line: &'a str, key: &str) -> Result<&'a str> {
    let at = line
        .find(key)
        .with_context(|| format!("no `{key}` in `{line}`"))?
        + key.len();
    Ok(line[at..].split_whitespace().next().unwrap_or(""))
}

/// The chain channels (red, green, blue) of protocol LED `led`'s RGB LEDs on a ring of `chips`.
pub(super) fn led_channels(chips: usize, led: u8) -> Vec<[usize; 3]> {
    led_triples(chips, led)
        .map(|triples| {
            triples
                .map(|t| {
                    let red = 3 * usize::from(t);
                    [red, red + 1, red + 2]
                })
                .collect()
        })
        .unwrap_or_default()
}

/// What the driver's outputs must be for these LED colours (LED n at index n − 1).
pub(super) fn expected(chips: usize, colours: &[[u8; 3]; 8]) -> Outputs {
    let mut outputs = dark(chips);
    for (led, rgb) in (1u8..=8).zip(colours) {
        for outs in led_channels(chips, led) {
            for (out, value) in outs.into_iter().zip(rgb) {
                outputs[out] = gamma(*value);
            }
        }
    }
    outputs
}

/// `LATCH_MIN_INTERVAL_US` of lightring/src/main.rs: a latch may wait this long behind the previous
/// one (1-0: 1 ms; 1-2, whose latch shifts three times the bytes: 3 ms).
pub(super) fn latch_interval_us(chips: usize) -> u64 {
    if chips == 3 {
        3_000
    } else {
        1_000
    }
}

/// Command received → latched, as analysed (the revision's timing files, which `build_qemu`
/// selected): the WCRT of `latch_leds`, whose release jitter is derived from the command path
/// (docs/analysis.md, "LightRing's latch: its release jitter"); the derivation's premises checked
/// here: the jitter is the latch interval plus the handler's own release jitter, the handler is more
/// urgent than the latch and done within its deadline, and that deadline is at most the interval;
/// the timing file's latch interval checked against the firmware's.
pub(super) fn latch_bound_us(root: &Path, chips: usize) -> Result<u64> {
    let models = root.join("schedule-analysis").join("models");
    let built = scenario::build(
        root,
        &models.join("thesis-demo.scenario.json"),
        &scenario::timing_files(root),
    )?;
    let system = built.model.validate().map_err(|e| anyhow!("{e}"))?;
    let analysis = analyse(
        &system,
        &Options {
            frame_cost: FrameCostSpec::default(),
            horizon: None,
        },
    );
    let board = analysis
        .boards
        .iter()
        .find(|b| b.name == "lightring")
        .context("the analysis has no lightring board")?;
    let task = |name: &str| {
        board
            .tasks
            .iter()
            .find(|t| t.name == name)
            .with_context(|| format!("the analysis has no lightring task {name}"))
    };
    let wcrt_us = |name: &str| -> Result<u64> {
        Ok(task(name)?
            .wcrt()
            .with_context(|| format!("{name}: the busy window never closes"))?
            .as_ns()
            .div_ceil(1_000))
    };
    let (handler, latch) = (task("handle_commands")?, task("latch_leds")?);
    let handler_wcrt = wcrt_us("handle_commands")?;
    let latch_wcrt = wcrt_us("latch_leds")?;
    let timing = scenario::timing_files(root)
        .into_iter()
        .find(|p| p.ends_with("lightring.timing.json"))
        .context("no lightring timing file")?;
    let text = std::fs::read_to_string(&timing)
        .with_context(|| format!("reading {}", timing.display()))?;
    let json: serde_json::Value = serde_json::from_str(&text)?;
    let interval = latch_interval_us(chips);
    let stated = |task: &str, field: &str| -> Result<f64> {
        json["tasks"][task][field]
            .as_f64()
            .with_context(|| format!("lightring timing file: tasks.{task}.{field}"))
    };
    let modelled = json["tasks"]["latch_leds"]["arrival"]["sporadic_us"]
        .as_f64()
        .context("lightring timing file: tasks.latch_leds.arrival.sporadic_us")?
        as u64;
    ensure!(
        modelled == interval,
        "{} models a latch per {modelled} µs, the firmware latches at most once per {interval} µs",
        timing.display()
    );
    let latch_jitter = stated("latch_leds", "jitter_us")?;
    let handler_jitter = stated("handle_commands", "jitter_us")?;
    ensure!(
        latch_jitter == interval as f64 + handler_jitter,
        "{} states latch_leds' release jitter as {latch_jitter} µs: it is the {interval} µs latch \
         interval plus handle_commands' own release jitter ({handler_jitter} µs)",
        timing.display()
    );
    ensure!(
        handler.priority > latch.priority,
        "handle_commands (priority {}) must be more urgent than latch_leds ({}): the latch's \
         release jitter rests on it",
        handler.priority,
        latch.priority
    );
    let handler_deadline = handler.deadline.as_ns().div_ceil(1_000);
    ensure!(
        handler_wcrt <= handler_deadline && handler_deadline <= interval,
        "handle_commands' WCRT {handler_wcrt} µs and deadline {handler_deadline} µs must not exceed \
         the {interval} µs latch interval: the latch's release jitter rests on it"
    );
    Ok(latch_wcrt)
}

impl Bounds {
    /// LightRing's command → latched bound (µs) on a ring of `chips`.
    pub(super) fn led_latency_us(&self, chips: usize) -> Result<u64> {
        latch_bound_us(self.root(), chips)
    }
}

/// The first latch at or after `at` that shows `colours`; its latency from `at`.
pub(super) fn latency_until_shown(
    latches: &[Latch],
    at: u64,
    chips: usize,
    colours: &[[u8; 3]; 8],
) -> Result<u64> {
    let want = expected(chips, colours);
    latches
        .iter()
        .filter(|l| l.at_us >= at)
        .find(|l| l.outputs == want)
        .map(|l| l.at_us - at)
        .with_context(|| format!("no latch after {at} µs shows {colours:?}"))
}

fn led3(out: &RunOutput, bounds: &Bounds) -> Result<String> {
    led3_on(out, bounds, CHIPS)
}

/// `led3.log` on a ring of `chips`.
pub(super) fn led3_on(out: &RunOutput, bounds: &Bounds, chips: usize) -> Result<String> {
    const AT: u64 = 10_000;
    let sets = led_sets(out)?;
    ensure!(
        sets.len() == 1 && sets[0].1 == 3 && sets[0].2 == [0xFF, 0x80, 0x20],
        "expected one led-set for LED 3 = FF8020, got {sets:?}"
    );
    let latches = latches(out, chips)?;
    ensure!(
        latches.first().is_some_and(|l| l.outputs == dark(chips)),
        "the first latch must be all dark (BLANK lifts after it)"
    );
    ensure!(
        out.notes.iter().any(|n| n.contains("BLANK low")),
        "BLANK never went low"
    );
    let mut colours = [[0u8; 3]; 8];
    colours[2] = [0xFF, 0x80, 0x20];
    let latency = latency_until_shown(&latches, AT, chips, &colours)?;
    let bound = bounds.led_latency_us(chips)?;
    ensure!(
        latency <= bound,
        "LED 3 latched {latency} µs after the command, above the analysed {bound} µs"
    );
    let after: Vec<&Latch> = latches.iter().filter(|l| l.at_us >= AT + latency).collect();
    ensure!(
        after.iter().all(|l| l.outputs == expected(chips, &colours)),
        "a later refresh lost LED 3's colour"
    );
    Ok(format!(
        "LED 3 (channels {:?}) = FF8020 latched {latency} µs after the command ≤ analysed {bound} µs; {} refreshes keep it",
        led_channels(chips, 3),
        after.len()
    ))
}

fn all_eight(out: &RunOutput, bounds: &Bounds) -> Result<String> {
    let commands: [(u64, [u8; 3]); 8] = [
        (10_000, [0xFF, 0, 0]),
        (11_250, [0, 0xFF, 0]),
        (12_500, [0, 0, 0xFF]),
        (13_750, [0xFF, 0xFF, 0]),
        (15_000, [0, 0xFF, 0xFF]),
        (16_250, [0xFF, 0, 0xFF]),
        (17_500, [0x80, 0x80, 0x80]),
        (18_750, [0xFF, 0xFF, 0xFF]),
    ];
    all_eight_on(out, bounds, CHIPS, &commands)
}

/// The eight LED commands `commands` (LED 1 first: time, colour) on a ring of `chips`: applied in
/// order, each LED's channels latched within the analysed bound, the final latch showing all.
pub(super) fn all_eight_on(
    out: &RunOutput,
    bounds: &Bounds,
    chips: usize,
    commands: &[(u64, [u8; 3]); 8],
) -> Result<String> {
    let sets = led_sets(out)?;
    let got: Vec<(u8, [u8; 3])> = sets.iter().map(|(_, led, rgb)| (*led, *rgb)).collect();
    let want: Vec<(u8, [u8; 3])> = (1u8..=8).zip(commands.iter().map(|c| c.1)).collect();
    ensure!(
        got == want,
        "LED commands applied {got:?}, expected {want:?}"
    );
    let latches = latches(out, chips)?;
    let bound = bounds.led_latency_us(chips)?;
    let mut colours = [[0u8; 3]; 8];
    let mut worst = 0;
    for (i, (at, rgb)) in commands.iter().enumerate() {
        colours[i] = *rgb;
        // Later commands may already be in the same latch: look for this LED's colour only.
        let latch = latches
            .iter()
            .filter(|l| l.at_us >= *at)
            .find(|l| {
                let want = expected(chips, &colours);
                let outs = led_channels(chips, i as u8 + 1);
                !outs.is_empty() && outs.iter().flatten().all(|&o| l.outputs[o] == want[o])
            })
            .with_context(|| format!("LED {} never latched", i + 1))?;
        worst = worst.max(latch.at_us - at);
    }
    ensure!(
        worst <= bound,
        "an LED latched {worst} µs after its command, above the analysed {bound} µs"
    );
    let last = latches.last().context("no latch at all")?;
    ensure!(
        last.outputs == expected(chips, &colours),
        "the final state does not show all eight colours"
    );
    Ok(format!(
        "8 LEDs applied in order, each latched within {worst} µs ≤ analysed {bound} µs; final state shows all eight"
    ))
}

fn other_boards(out: &RunOutput, _bounds: &Bounds) -> Result<String> {
    let chips = CHIPS;
    let ignored = out.traces("command-ignored").len();
    ensure!(ignored == 6, "{ignored} frames ignored, expected all 6");
    ensure!(
        out.traces("command-rejected").is_empty() && out.traces("command-accepted").is_empty(),
        "another board's frame was accepted or rejected"
    );
    ensure!(led_sets(out)?.is_empty(), "an LED changed");
    let latches = latches(out, chips)?;
    ensure!(
        latches.iter().all(|l| l.outputs == dark(chips)),
        "an LED lit up"
    );
    ensure!(out.frames.is_empty(), "LightRing sent frames");
    Ok(format!(
        "6 frames for other boards ignored; {} latches, all dark",
        latches.len()
    ))
}

fn malformed(out: &RunOutput, bounds: &Bounds) -> Result<String> {
    malformed_on(out, bounds, CHIPS)
}

/// `malformed.log` on a ring of `chips`.
pub(super) fn malformed_on(out: &RunOutput, _bounds: &Bounds, chips: usize) -> Result<String> {
    out.expect_rejections(&[
        "dlc-too-short",
        "dlc-too-long",
        "unknown-topic",
        "dlc-too-short",
        "dlc-too-long",
    ])?;
    let sets = led_sets(out)?;
    ensure!(
        sets.len() == 1 && sets[0].1 == 5 && sets[0].2 == [0x10, 0x20, 0x30],
        "only the good LED 5 command may apply, got {sets:?}"
    );
    let latches = latches(out, chips)?;
    ensure!(
        latches
            .iter()
            .filter(|l| l.at_us < 20_000)
            .all(|l| l.outputs == dark(chips)),
        "a malformed frame changed the LEDs"
    );
    let mut colours = [[0u8; 3]; 8];
    colours[4] = [0x10, 0x20, 0x30];
    latency_until_shown(&latches, 20_000, chips, &colours)?;
    let health = check_health(out, amiro_can::Board::LightRing)?;
    ensure!(
        health.rejected == 5,
        "diagnostics count {} rejections, expected 5",
        health.rejected
    );
    Ok(format!(
        "5 malformed frames rejected with their reasons, LEDs unchanged; the good command after them applied; diagnostics: {} accepted, {} rejected",
        health.accepted, health.rejected
    ))
}

fn flood(out: &RunOutput, bounds: &Bounds) -> Result<String> {
    flood_on(out, bounds, CHIPS)
}

/// `flood.log` on a ring of `chips`.
pub(super) fn flood_on(out: &RunOutput, _bounds: &Bounds, chips: usize) -> Result<String> {
    // The flood as the stimulus sends it (lightring/qemu/flood.log).
    let sent: Vec<(u8, [u8; 3])> = (0..120u32)
        .map(|i| {
            (
                1 + (i % 8) as u8,
                [
                    (i * 37 % 256) as u8,
                    (i * 91 % 256) as u8,
                    (i * 53 % 256) as u8,
                ],
            )
        })
        .collect();
    let applied: Vec<(u8, [u8; 3])> = led_sets(out)?
        .iter()
        .map(|(_, led, rgb)| (*led, *rgb))
        .collect();
    let dropped = out.end_field("rx dropped")?;
    ensure!(
        out.end_field("rx overruns")? == 0,
        "receive-FIFO overruns: the receive interrupt fell behind"
    );
    // The flood, and the diagnostics request after it (handled: the queue has drained by then).
    let handled = out.traces("command-").len() as u64;
    ensure!(
        handled == applied.len() as u64 + 1,
        "{handled} commands handled, expected the {} applied LED commands and the diagnostics request",
        applied.len()
    );
    ensure!(
        applied.len() as u64 + dropped == sent.len() as u64,
        "{} applied + {dropped} dropped != {} sent",
        applied.len(),
        sent.len()
    );
    let health = check_health(out, amiro_can::Board::LightRing)?;
    ensure!(
        applied.len() >= 17,
        "only {} commands applied: the 16-deep queue plus the one in hand must all apply",
        applied.len()
    );
    ensure!(
        applied[..17] == sent[..17],
        "the queued burst was not applied in order"
    );
    // Every applied command is a sent one, in sending order (drops only remove, never reorder).
    let mut rest = sent.iter();
    for a in &applied {
        if !rest.any(|s| s == a) {
            bail!("command {a:?} applied out of order");
        }
    }
    let mut colours = [[0u8; 3]; 8];
    for (led, rgb) in &applied {
        colours[usize::from(*led - 1)] = *rgb;
    }
    let last = latches(out, chips)?.pop().context("no latch at all")?;
    ensure!(
        last.outputs == expected(chips, &colours),
        "the final latch does not show the last applied colour of every LED"
    );
    Ok(format!(
        "{} LED commands applied in order (the whole queued burst), {dropped} dropped and counted (diagnostics agree: {}); final state = last applied colours",
        applied.len(),
        health.rx_dropped
    ))
}

pub(super) fn shutdown(out: &RunOutput, _bounds: &Bounds) -> Result<String> {
    const REQUEST: u64 = 30_000;
    let sets = led_sets(out)?;
    ensure!(
        sets.len() == 1 && sets[0].1 == 4,
        "only the LED 4 command before the request may apply, got {sets:?}"
    );
    let dark = out
        .notes
        .iter()
        .position(|n| n.contains("BLANK high"))
        .context("the LEDs never went dark")?;
    let sync = out
        .notes
        .iter()
        .position(|n| n.contains("SYS_SYNC_N pulled low"))
        .context("SYS_SYNC_N was not pulled low")?;
    let end = out.end_line()?;
    ensure!(
        end.starts_with("qemu: shutdown hand-over"),
        "the run did not end in the hand-over: `{end}`"
    );
    let end_at = out.end_field("hand-over at")?;
    ensure!(
        (REQUEST..REQUEST + 1_000).contains(&end_at),
        "hand-over at {end_at} µs, expected within 1 ms of the request"
    );
    ensure!(
        dark < out.notes.len() && sync < out.notes.len(),
        "dark and SYS_SYNC_N low must come before the end"
    );
    ensure!(
        out.traces("command-")
            .iter()
            .all(|l| trace_time(l).is_ok_and(|t| t < REQUEST)),
        "a command was handled after the shutdown request"
    );
    Ok(format!(
        "LEDs dark, SYS_SYNC_N low, hand-over at {end_at} µs; nothing after"
    ))
}

/// `lightring/qemu/admission.log` (issue 11).
fn admission(out: &RunOutput, bounds: &Bounds) -> Result<String> {
    admission_on(
        out,
        bounds,
        CHIPS,
        ADMITTED_DIAGNOSTICS_MS,
        SHORTEST_DIAGNOSTICS_1_0_MS,
    )
}

/// The diagnostics period at medium `admission.log` asks for, ms: the shortest whole one the host admits on a 1-1
/// robot (LightRing 1-0) since DiWheelDrive's transmit jobs are rows (2026-12-06): every 20 ms and shorter the latch
/// misses its 2 000 µs (2 094 µs), every 21 ms (20 456 µs at least) passes. A 1-2 robot admits 7 ms and more (every
/// 6 ms the six frames 0x61C respond in 7 633 µs; 6 543 µs at least). Until 2026-12-06 both admitted 7 ms and refused
/// 6 ms. The same figures on the tables with every machine-code bound used (2026-12-06, main 1233d095).
pub(super) const ADMITTED_DIAGNOSTICS_MS: u64 = 21;

/// The shortest whole milliseconds of the diagnostics at medium the host admits on a 1-1 robot (LightRing 1-0).
const SHORTEST_DIAGNOSTICS_1_0_MS: u64 = 21;

/// DiWheelDrive's odometry request at low that `admission.log` sends LightRing (every 2 ms): admitted on its own,
/// and the reason the diagnostics every 100 ms at urgent is refused (0x701 would respond in 2 660 µs on a 1-1
/// robot's view, 2 662 µs on a 1-2 robot's, against 2 000 µs; 2026-12-06, every machine-code bound used: 2 434 µs on
/// 1-2 while DiWheelDrive 1-2's publisher rows were held). Every 1.5 ms, the request before, is refused on its own
/// now (0x701 in 1 929 µs of 1 500 on 1-1, 1 931 µs on 1-2; at low it needs 1 850 / 1 852 µs).
const ODOMETRY_REQUEST: &str = "301#01D00702";

/// `admission.log` on a ring of `chips`, whose accepted request is the diagnostics every
/// `every_ms` at medium; the host admits every `shortest_ms` and refuses every `shortest_ms` − 1 (docs/qemu.md).
pub(super) fn admission_on(
    out: &RunOutput,
    bounds: &Bounds,
    chips: usize,
    every_ms: u64,
    shortest_ms: u64,
) -> Result<String> {
    use amiro_can::{Topic, Verdict, Violation};
    let verdicts = super::admission_verdicts(out, amiro_can::Board::LightRing);
    ensure!(
        verdicts.len() == 3,
        "{} verdicts, expected two refusals and a warning",
        verdicts.len()
    );
    let root = bounds.root();
    let (_, starved) = &verdicts[0];
    ensure!(
        starved.verdict == Verdict::Refused
            && starved.topic == Topic::LightRingDiagnostics
            && starved.requested.as_micros() == 1,
        "not the refusal at 1 µs: {starved}"
    );
    super::same_refusal(starved, &super::host_admission(root, &[], "01C#01010002")?)?;
    // LED 3 still latched after the refusal.
    let latches = latches(out, chips)?;
    let mut colours = [[0u8; 3]; 8];
    colours[2] = [0xFF, 0x80, 0x20];
    let latency = latency_until_shown(&latches, 50_000, chips, &colours)?;
    // Every `every_ms` at medium: accepted (no verdict), six frames per sample until the stop.
    ensure!(
        super::host_admission(root, &[], &format!("21C#01{every_ms:02X}0000"))?
            .refusal
            .is_none(),
        "the host refuses the diagnostics every {every_ms} ms"
    );
    // The boundary: the shortest admitted, and one ms less refused.
    ensure!(
        super::host_admission(root, &[], &format!("21C#01{shortest_ms:02X}0000"))?
            .refusal
            .is_none(),
        "the host refuses the diagnostics every {shortest_ms} ms"
    );
    ensure!(
        super::host_admission(root, &[], &format!("21C#01{:02X}0000", shortest_ms - 1))?
            .refusal
            .is_some(),
        "the host admits the diagnostics every {} ms: {shortest_ms} ms is not the shortest admitted",
        shortest_ms - 1
    );
    let running = out
        .times(0x61C)
        .into_iter()
        .filter(|t| (60_000..100_000).contains(t))
        .count();
    ensure!(
        running as u64 >= 6 * (40 / every_ms * 3 / 4).max(1),
        "{running} diagnostics frames between the request and the stop, expected every {every_ms} ms × 6"
    );
    ensure!(
        out.times(0x61C).iter().all(|&t| t < 102_000),
        "diagnostics frames after the stop"
    );
    let (_, other) = &verdicts[1];
    ensure!(
        other.verdict == Verdict::Refused
            && matches!(other.violation, Violation::Message { id } if id.raw() == 0x701),
        "not the refusal for DiWheelDrive's odometry frames 0x701: {other}"
    );
    super::same_refusal(
        other,
        &super::host_admission(root, &[ODOMETRY_REQUEST], "01C#01640000")?,
    )?;
    let (_, warned) = &verdicts[2];
    ensure!(
        warned.verdict == Verdict::AcceptedWithWarning && warned.requested.as_micros() == 100_000,
        "not the warning for the diagnostics every 100 ms: {warned}"
    );
    // The health pages (not the verdicts' 0x80/0x81, which share the identifier).
    let started: Vec<u64> = out
        .frames
        .iter()
        .filter(|f| f.id == 0x41C && f.data.first().is_some_and(|p| *p < 0x80))
        .map(|f| f.at_us)
        .collect();
    ensure!(
        started.len() >= 6 && started.iter().all(|&t| t >= 220_000),
        "{} urgent diagnostics frames after the warned request, expected it running",
        started.len()
    );
    Ok(format!(
        "{starved}; LED 3 latched {latency} µs after its command; {every_ms} ms accepted ({running} frames) and stopped; {other}; then warned and started ({} frames)",
        started.len()
    ))
}
