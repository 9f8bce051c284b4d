//! `cargo bench -p schedule-analysis`: how long the analysis takes for 10 … 10,000 tasks and messages.
//!
//! First, against the `response-time-analysis` crate (crates.io, Brandenburg's Rust transcription of the
//! Coq-verified abstract RTA of Bozhko & Brandenburg, ECRTS 2020): both analyse the same sporadic task sets
//! (distinct deadline-monotonic priorities, constrained deadlines, no jitter or blocking, every job of the busy
//! window), and the bench asserts that every response time agrees before it times them. Ours is the
//! allocation-free core call the on-chip admission check makes (`board::response_times` on prepared arrays); the
//! crate's is `fixed_priority::fully_preemptive::dedicated_uniproc_rta` per task on its prepared request-bound
//! functions. The host's whole `analyse_board` (names, ceilings, blocking, result records) is shown beside them.
//!
//! Board sets: random priorities (with ties), log-uniform periods 1 ms … 1 s, 85 % utilisation, release jitter up
//! to 10 % of the period, every task locking up to two of eight shared resources (SRP ceilings and blocking are
//! part of the timed work). Bus sets: unique identifiers (29-bit beyond 2048 messages), 0 … 8 data bytes,
//! 80 % utilisation under the exact frame-cost model, queuing jitter up to 10 % of the period. Each row is the
//! median of several runs of the whole analysis (no file parsing). Target: 1000 tasks and 1000 messages each well
//! under 20 ms.

use std::hint::black_box;
use std::time::{Duration, Instant};

use schedule_analysis::analysis::{analyse, analyse_board, Options};
use schedule_analysis::board::{self as board_core, TaskTiming};
use schedule_analysis::busy_window::{AnalysisError, Counter, Limits};
use schedule_analysis::can;
use schedule_analysis::model::{
    BoardSystem, BusSystem, FrameCostSpec, MessageSpec, OverheadTimes, System, TaskKind, TaskSpec,
};
use schedule_analysis::rng::Rng;
use schedule_analysis::time::Time;

use response_time_analysis::time as rta_time;
use response_time_analysis::{arrival, demand, fixed_priority, wcet};

/// Priority assignment of a benchmark set.
#[derive(Clone, Copy)]
enum Priorities {
    /// Deadline-monotonic in n/4 levels (ties between neighbours): how RTIC priorities are assigned.
    DeadlineMonotonic,
    /// Random levels, unrelated to the periods: long busy windows with many jobs, the worst case for the
    /// analysis's running time.
    Random,
}

fn board(n: usize, seed: u64, priorities: Priorities) -> BoardSystem {
    let mut rng = Rng::new(seed);
    let shares: Vec<f64> = (0..n).map(|_| rng.unit() + 0.05).collect();
    let total: f64 = shares.iter().sum();
    let levels = (n / 4).max(2) as u64;
    let tasks = shares
        .iter()
        .enumerate()
        .map(|(i, share)| {
            let period_us = rng.log_uniform(1_000.0, 1_000_000.0);
            let wcet_us = (period_us * 0.85 * share / total).max(0.01);
            let mut sections = Vec::new();
            for _ in 0..(rng.next_u64() % 3) {
                let resource = format!("r{}", rng.next_u64() % 8);
                if !sections.iter().any(|(r, _)| *r == resource) {
                    sections.push((resource, Time::from_us_up(wcet_us * rng.unit() * 0.5)));
                }
            }
            let period = Time::from_us_down(period_us);
            TaskSpec {
                name: format!("task{i}"),
                priority: match priorities {
                    Priorities::Random => (1 + rng.next_u64() % levels) as u32,
                    // Shorter period, higher level: 1 µs … 1 s mapped logarithmically onto the levels.
                    Priorities::DeadlineMonotonic => (1.0
                        + (levels as f64 - 1.0)
                            * (1.0 - (period_us / 1_000.0).ln() / 1_000f64.ln()))
                    .round() as u32,
                },
                wcet: Time::from_us_up(wcet_us),
                bcet: Time::ZERO,
                period,
                deadline: period.times(2),
                deadline_follows_period: false,
                jitter: Time::from_us_up(period_us * 0.1 * rng.unit()),
                sections,
                blocking: None,
                kind: TaskKind::Plain,
                released_by: None,
                sporadic: false,
                job_of: None,
            }
        })
        .collect();
    BoardSystem {
        name: "bench".into(),
        overheads: OverheadTimes::default(),
        tasks,
        idle_sections: Vec::new(),
        can_tx_task: None,
        static_ceilings: Vec::new(),
        sensor_buses: Default::default(),
    }
}

fn bus(n: usize, seed: u64) -> System {
    let mut rng = Rng::new(seed);
    let bit = can::bit_time(1_000_000);
    let extended = n > 2048;
    let mut ids: Vec<u32> = (0..n as u32)
        .map(|i| if extended { i * 7919 % 0x1FFF_FFFF } else { i })
        .collect();
    // Shuffle so priority order and period order are unrelated.
    for i in (1..ids.len()).rev() {
        ids.swap(i, (rng.next_u64() % (i as u64 + 1)) as usize);
    }
    let raw: Vec<(u8, f64)> = (0..n)
        .map(|_| ((rng.next_u64() % 9) as u8, rng.log_uniform(1.0, 1000.0)))
        .collect();
    // Scale the periods so the bus runs at 80 %.
    let load: f64 = raw
        .iter()
        .map(|(dlc, p)| can::frame_time(can::FrameCost::Exact, *dlc, extended, bit).as_us_f64() / p)
        .sum();
    let scale = load / 0.8;
    let messages = raw
        .iter()
        .zip(&ids)
        .enumerate()
        .map(|(i, ((dlc, p), &id))| {
            let period_us = p * scale;
            let period = Time::from_us_down(period_us);
            MessageSpec {
                name: format!("m{i}"),
                id,
                extended,
                dlc: *dlc,
                frames: 1,
                period,
                deadline: period.times(2),
                deadline_follows_period: false,
                jitter: Time::from_us_up(period_us * 0.1 * rng.unit()),
                sender: None,
                receiver: None,
                jitter_budget: None,
                e2e_deadline: None,
            }
        })
        .collect();
    System {
        name: None,
        boards: Vec::new(),
        bus: Some(BusSystem {
            bitrate: 1_000_000,
            bit_time: bit,
            frame_cost: FrameCostSpec::Exact,
            messages,
        }),
    }
}

/// The `response-time-analysis` crate's request-bound function of a sporadic task without jitter.
type Rbf = demand::RBF<arrival::Sporadic, wcet::Scalar>;

/// The crate's model of `tasks` (ordered by descending priority, distinct priorities): one RBF per task.
fn crate_model(tasks: &[TaskTiming]) -> Vec<Rbf> {
    tasks
        .iter()
        .map(|t| {
            demand::RBF::new(
                arrival::Sporadic::new_zero_jitter(rta_time::Duration::from(t.period.as_ns())),
                wcet::Scalar::new(rta_time::Service::from(t.wcet.as_ns())),
            )
        })
        .collect()
}

/// The crate's fully-preemptive fixed-priority RTA of every task against the more urgent ones: the response
/// times in ns, `None` where it finds no fixed point below `limit`.
fn crate_response_times(rbfs: &[Rbf], limit: Time, out: &mut Vec<Option<u64>>) {
    out.clear();
    let limit = rta_time::Duration::from(limit.as_ns());
    for (i, tua) in rbfs.iter().enumerate() {
        let bound = fixed_priority::fully_preemptive::dedicated_uniproc_rta(
            tua,
            rbfs.get(..i).unwrap_or(&[]),
            limit,
        );
        out.push(bound.ok().map(u64::from));
    }
}

/// Batches of `batch` calls of `ours` and of `theirs`, alternating so that both see the same load on a shared
/// machine: the median time of one call of each and the median of the per-round ratios.
fn paired(
    mut ours: impl FnMut() -> usize,
    mut theirs: impl FnMut() -> usize,
    batch: usize,
    rounds: usize,
) -> (Duration, Duration, f64) {
    let time = |f: &mut dyn FnMut() -> usize| {
        let start = Instant::now();
        let mut n = 0;
        for _ in 0..batch {
            n += black_box(f());
        }
        black_box(n);
        start.elapsed() / batch as u32
    };
    let mut a = Vec::with_capacity(rounds);
    let mut b = Vec::with_capacity(rounds);
    let mut ratios = Vec::with_capacity(rounds);
    for _ in 0..rounds {
        let x = time(&mut ours);
        let y = time(&mut theirs);
        ratios.push(x.as_secs_f64() / y.as_secs_f64());
        a.push(x);
        b.push(y);
    }
    a.sort();
    b.sort();
    ratios.sort_by(f64::total_cmp);
    (a[rounds / 2], b[rounds / 2], ratios[rounds / 2])
}

/// Median time of one call, from batches of `batch` calls.
fn per_call(mut f: impl FnMut() -> usize, batch: usize) -> Duration {
    let (t, _) = median(
        || {
            let mut n = 0;
            for _ in 0..batch {
                n += black_box(f());
            }
            n
        },
        15,
    );
    t / batch as u32
}

/// A board set as the crate models it: distinct priorities, shortest period most urgent, no jitter or locks,
/// deadline = period.
fn crate_comparable(n: usize) -> BoardSystem {
    let mut system = board(n, 0xC0FFEE + n as u64, Priorities::DeadlineMonotonic);
    system.tasks.sort_by_key(|t| t.period);
    for (i, t) in system.tasks.iter_mut().enumerate() {
        t.priority = (n - i) as u32;
        t.jitter = Time::ZERO;
        t.sections.clear();
        t.deadline = t.period;
    }
    system
}

fn against_crate() {
    println!("against the response-time-analysis crate (median per call, the two alternating; the ratio is the");
    println!("median of the rounds' ratios; DM priorities, distinct levels, D = T,");
    println!("no jitter or blocking; response times asserted equal): the allocation-free core the on-chip check");
    println!("uses, the crate's dedicated_uniproc_rta per task, their ratio, and the host's whole analyse_board");
    println!();
    println!(
        "{:>5}  {:>14}  {:>14}  {:>11}  {:>14}",
        "n", "core", "crate", "core/crate", "analyse_board"
    );
    let limits = Limits::default();
    for n in [10usize, 20, 40, 100, 1_000] {
        let system = crate_comparable(n);
        let timings: Vec<TaskTiming> = system
            .tasks
            .iter()
            .map(|t| TaskTiming {
                priority: t.priority,
                wcet: t.wcet,
                period: t.period,
                jitter: t.jitter,
            })
            .collect();
        let blockings = vec![Time::ZERO; n];
        let mut scratch = vec![Counter::default(); n];
        let mut out = vec![Err(AnalysisError::NoSuchIndex); n];
        let rbfs = crate_model(&timings);
        let mut theirs = Vec::with_capacity(n);

        // The same problem, the same answers: every response time agrees (both bounded, equal), or the
        // comparison is void.
        board_core::response_times(&timings, &blockings, &limits, &mut scratch, &mut out);
        crate_response_times(&rbfs, limits.horizon, &mut theirs);
        for (i, (ours, theirs)) in out.iter().zip(&theirs).enumerate() {
            let ours = ours.as_ref().ok().map(|r| r.wcrt.as_ns());
            assert!(
                ours.is_some() && ours == *theirs,
                "n = {n}, task {i}: ours {ours:?} ns, the crate's {theirs:?} ns"
            );
        }

        let batch = (20_000 / n).clamp(1, 2_000);
        let (core, reference, ratio) = paired(
            || {
                board_core::response_times(
                    black_box(&timings),
                    &blockings,
                    &limits,
                    &mut scratch,
                    &mut out,
                );
                out.iter().filter(|r| r.is_ok()).count()
            },
            || {
                crate_response_times(black_box(&rbfs), limits.horizon, &mut theirs);
                theirs.iter().filter(|r| r.is_some()).count()
            },
            batch,
            if n >= 1_000 { 9 } else { 31 },
        );
        let host = per_call(
            || {
                analyse_board(black_box(&system), &limits)
                    .tasks
                    .iter()
                    .filter(|t| t.bound.is_ok())
                    .count()
            },
            batch,
        );
        println!(
            "{n:>5}  {:>11}  {:>11}  {:>10.2}×  {:>11}",
            micros(core),
            micros(reference),
            ratio,
            micros(host),
        );
    }
    println!();
}

/// A duration in µs, three significant digits' worth.
fn micros(d: Duration) -> String {
    let us = d.as_secs_f64() * 1e6;
    if us < 10.0 {
        format!("{us:.2} µs")
    } else if us < 100.0 {
        format!("{us:.1} µs")
    } else {
        format!("{us:.0} µs")
    }
}

fn median(mut f: impl FnMut() -> usize, runs: usize) -> (Duration, usize) {
    let mut times = Vec::with_capacity(runs);
    let mut bounded = 0;
    for _ in 0..runs {
        let start = Instant::now();
        bounded = black_box(f());
        times.push(start.elapsed());
    }
    times.sort();
    (times[times.len() / 2], bounded)
}

fn main() {
    // `cargo bench` passes `--bench`; a filter argument is accepted and ignored.
    let limits = Limits::default();
    let options = Options {
        frame_cost: FrameCostSpec::Exact,
        horizon: None,
    };
    println!("schedule-analysis benchmark (median of runs; whole analysis, no parsing)");
    println!();
    against_crate();
    println!(
        "{:>7}  {:>20}  {:>11}  {:>20}  {:>11}  {:>20}  {:>11}",
        "n",
        "board, DM prio.",
        "bounded",
        "board, random prio.",
        "bounded",
        "CAN (exact)",
        "bounded"
    );
    for n in [10usize, 100, 1_000, 10_000] {
        let runs = if n >= 10_000 { 3 } else { 15 };
        let dm = board(n, 0x5EED + n as u64, Priorities::DeadlineMonotonic);
        let (board_time, board_bounded) = median(
            || {
                analyse_board(black_box(&dm), &limits)
                    .tasks
                    .iter()
                    .filter(|t| t.bound.is_ok())
                    .count()
            },
            runs,
        );
        let random = board(n, 0x5EED + n as u64, Priorities::Random);
        let (random_time, random_bounded) = if n <= 1_000 {
            median(
                || {
                    analyse_board(black_box(&random), &limits)
                        .tasks
                        .iter()
                        .filter(|t| t.bound.is_ok())
                        .count()
                },
                runs,
            )
        } else {
            (Duration::ZERO, 0)
        };
        let s = bus(n, 0xB05 + n as u64);
        let (bus_time, bus_bounded) = median(
            || {
                analyse(black_box(&s), &options).bus.map_or(0, |bus| {
                    bus.messages.iter().filter(|m| m.bound.is_ok()).count()
                })
            },
            runs,
        );
        let random_cell = if n <= 1_000 {
            format!(
                "{:>17.3} ms  {:>5}/{:<5}",
                random_time.as_secs_f64() * 1e3,
                random_bounded,
                n
            )
        } else {
            format!("{:>20}  {:>11}", "(skipped)", "")
        };
        println!(
            "{n:>7}  {:>17.3} ms  {:>5}/{:<5}  {random_cell}  {:>17.3} ms  {:>5}/{:<5}",
            board_time.as_secs_f64() * 1e3,
            board_bounded,
            n,
            bus_time.as_secs_f64() * 1e3,
            bus_bounded,
            n
        );
    }
}
