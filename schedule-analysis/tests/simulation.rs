//! The analyses against the simulators on many random sets:
//!
//! * any release pattern (offsets, sporadic gaps, release jitter, shorter executions, SRP locks): no simulated
//!   response exceeds the analysed bound;
//! * synchronous release, no jitter, no blocking, full execution times: the simulated worst *equals* the bound
//!   (distinct priorities on the board; on the bus for every message simulated with the higher-priority messages
//!   only, against the analysis without its blocking term, and for the lowest-priority message in the whole set
//!   against the full analysis).

use proptest::prelude::*;
use schedule_analysis::board::{self, CriticalSection, TaskTiming};
use schedule_analysis::busy_window::{AnalysisError, Counter, Limits, Response};
use schedule_analysis::can::{self, FrameCost, MessageTiming};
use schedule_analysis::time::Time;

mod sim;

use sim::{Activation, Job, Segment, SimMessage};

const US: u64 = 1000;

/// A random board task before scaling: priority, period (µs), utilisation share, jitter (fraction of the
/// period, %), which of two resources it locks, and how long (fraction of its WCET, %).
type RawTask = (u32, u64, u64, u64, (bool, bool), (u64, u64));

struct BoardSet {
    timings: Vec<TaskTiming>, // ordered by descending priority
    sections: Vec<Vec<(usize, u64)>>,
    ceilings: Vec<u32>,
}

fn board_set(
    raw: &[RawTask],
    total_utilisation: u64,
    with_jitter: bool,
    with_locks: bool,
    distinct: bool,
) -> BoardSet {
    let shares: u64 = raw.iter().map(|t| t.2).sum::<u64>().max(1);
    let mut tasks: Vec<(TaskTiming, Vec<(usize, u64)>)> = raw
        .iter()
        .enumerate()
        .map(
            |(i, &(priority, period_us, share, jitter_pct, (use0, use1), (len0, len1)))| {
                let period = period_us * US;
                // Utilisation per task in per mille of the total, WCET rounded down to whole µs, at least 1 µs.
                let wcet =
                    ((period * total_utilisation * share) / (shares * 1000) / US).max(1) * US;
                let jitter = if with_jitter {
                    period * jitter_pct / 100 / US * US
                } else {
                    0
                };
                let priority = if distinct { 100 - i as u32 } else { priority };
                let mut sections = Vec::new();
                if with_locks && use0 {
                    sections.push((0, (wcet * len0 / 100 / US).max(1) * US));
                }
                if with_locks && use1 {
                    sections.push((1, (wcet * len1 / 100 / US).max(1) * US));
                }
                let timing = TaskTiming {
                    priority,
                    wcet: Time::from_ns(wcet),
                    period: Time::from_ns(period),
                    jitter: Time::from_ns(jitter),
                };
                (timing, sections)
            },
        )
        .collect();
    tasks.sort_by_key(|t| std::cmp::Reverse(t.0.priority));
    let ceilings = (0..2)
        .map(|r| {
            board::resource_ceiling(
                tasks
                    .iter()
                    .filter(|t| t.1.iter().any(|s| s.0 == r))
                    .map(|t| t.0.priority),
            )
        })
        .collect();
    BoardSet {
        timings: tasks.iter().map(|t| t.0).collect(),
        sections: tasks.into_iter().map(|t| t.1).collect(),
        ceilings,
    }
}

fn analyse_board(set: &BoardSet, with_blocking: bool) -> Vec<Option<Response>> {
    let sections: Vec<CriticalSection> = set
        .timings
        .iter()
        .zip(&set.sections)
        .flat_map(|(t, s)| {
            s.iter().map(|&(r, len)| CriticalSection {
                holder_priority: t.priority,
                ceiling: set.ceilings[r],
                length: Time::from_ns(len),
            })
        })
        .collect();
    let mut scratch = vec![Counter::default(); set.timings.len()];
    responses(
        set.timings.len(),
        with_blocking.then_some(|i: usize| board::srp_blocking(set.timings[i].priority, &sections)),
        |i, b| board::response_time(&set.timings, i, b, &limits(), &mut scratch),
    )
}

/// The analyses' limits here: a 10 s horizon.
fn limits() -> Limits {
    Limits {
        horizon: Time::from_us(10_000_000),
        ..Limits::default()
    }
}

/// The response of each of `n` elements with its `blocking` (none without), `None` where the analysis finds no
/// bound.
fn responses(
    n: usize,
    blocking: Option<impl Fn(usize) -> Time>,
    mut analyse: impl FnMut(usize, Time) -> Result<Response, AnalysisError>,
) -> Vec<Option<Response>> {
    (0..n)
        .map(|i| analyse(i, blocking.as_ref().map_or(Time::ZERO, |b| b(i))).ok())
        .collect()
}

/// A simple deterministic generator for the release patterns (proptest chooses its seed).
struct Lcg(u64);

impl Lcg {
    fn next(&mut self) -> u64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        self.0 >> 33
    }
    fn below(&mut self, n: u64) -> u64 {
        if n == 0 {
            0
        } else {
            self.next() % n
        }
    }
}

/// Random jobs: random offset, strictly periodic or with sporadic gaps, release jitter, execution up to the WCET,
/// the task's critical sections at random places.
fn random_jobs(set: &BoardSet, seed: u64, horizon: u64) -> Vec<Job> {
    let mut rng = Lcg(seed);
    let mut jobs = Vec::new();
    for (task, t) in set.timings.iter().enumerate() {
        let period = t.period.as_ns();
        let mut arrival = rng.below(period / US) * US;
        let sporadic = rng.below(3) == 0;
        let mut last_release = 0;
        while arrival <= horizon {
            let jitter = rng.below(t.jitter.as_ns() / US + 1) * US;
            // One task's jobs stay in order (a timer cannot wake them out of order).
            let release = (arrival + jitter).max(last_release);
            last_release = release;
            let wcet = t.wcet.as_ns();
            let exec = if rng.below(4) == 0 {
                (rng.below(wcet / US) + 1) * US
            } else {
                wcet
            };
            let mut segments = Vec::new();
            let mut used = 0;
            for &(resource, len) in &set.sections[task] {
                let len = len.min(exec - used);
                if len == 0 {
                    continue;
                }
                let before = rng.below((exec - used - len) / US + 1) * US;
                if before > 0 {
                    segments.push(Segment {
                        length: before,
                        lock: None,
                    });
                }
                segments.push(Segment {
                    length: len,
                    lock: Some(resource),
                });
                used += before + len;
            }
            if exec > used {
                segments.push(Segment {
                    length: exec - used,
                    lock: None,
                });
            }
            jobs.push(Job {
                task,
                arrival,
                release,
                segments,
            });
            arrival += period
                + if sporadic {
                    rng.below(period / US) * US
                } else {
                    0
                };
        }
    }
    jobs
}

fn raw_tasks() -> impl Strategy<Value = Vec<RawTask>> {
    prop::collection::vec(
        (
            1u32..=4,
            20u64..=240,
            1u64..=10,
            0u64..=150,
            (any::<bool>(), any::<bool>()),
            (10u64..=100, 10u64..=100),
        ),
        1..=5,
    )
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 300, ..ProptestConfig::default() })]

    #[test]
    fn board_simulation_never_exceeds_the_analysis(
        raw in raw_tasks(),
        utilisation in 300u64..=950,
        seed in any::<u64>(),
    ) {
        let set = board_set(&raw, utilisation, true, true, false);
        let bounds = analyse_board(&set, true);
        let longest = set.timings.iter().map(|t| t.period.as_ns()).max().unwrap_or(0);
        let jobs = random_jobs(&set, seed, 40 * longest);
        let priorities: Vec<u32> = set.timings.iter().map(|t| t.priority).collect();
        let responses = sim::board_run(&priorities, &set.ceilings, &jobs);
        for (job, r) in jobs.iter().zip(responses) {
            if let Some(bound) = bounds[job.task] {
                prop_assert!(r <= bound.wcrt.as_ns(), "task {} job at {}: simulated {} > analysed {}", job.task, job.arrival, r, bound.wcrt.as_ns());
            }
        }
    }

    #[test]
    fn board_synchronous_release_meets_the_analysis_exactly(
        raw in raw_tasks(),
        utilisation in 300u64..=980,
    ) {
        let set = board_set(&raw, utilisation, false, false, true);
        let bounds = analyse_board(&set, false);
        prop_assume!(bounds.iter().all(Option::is_some));
        let horizon = bounds.iter().flatten().map(|b| b.busy_window.as_ns()).max().unwrap_or(0);
        let priorities: Vec<u32> = set.timings.iter().map(|t| t.priority).collect();
        let wcets: Vec<u64> = set.timings.iter().map(|t| t.wcet.as_ns()).collect();
        let periods: Vec<u64> = set.timings.iter().map(|t| t.period.as_ns()).collect();
        let worst = sim::board_synchronous_worst(&priorities, &wcets, &periods, horizon);
        for (i, bound) in bounds.iter().enumerate() {
            prop_assert_eq!(worst[i], bound.map_or(0, |b| b.wcrt.as_ns()), "task {}", i);
        }
    }
}

/// A random message before scaling: DLC, frames per activation (1 = most), period (µs), utilisation share,
/// jitter (% of the period).
type RawMessage = (u8, u32, u64, u64, u64);

fn message_set(
    raw: &[RawMessage],
    total_utilisation: u64,
    with_jitter: bool,
    ids: &[u32],
) -> Vec<MessageTiming> {
    let bit = can::bit_time(1_000_000);
    let shares: u64 = raw.iter().map(|m| m.3).sum::<u64>().max(1);
    let mut set: Vec<MessageTiming> = raw
        .iter()
        .zip(ids)
        .map(|(&(dlc, frames, min_period_us, share, jitter_pct), &id)| {
            let frames = if frames > 3 { 1 } else { frames };
            let frame_time = can::frame_time(FrameCost::Exact, dlc, false, bit);
            let cost = frame_time.as_ns() * u64::from(frames);
            // Period from the utilisation share, on the 1 µs grid, never below the activation's own length.
            let period = (cost * shares * 1000 / (total_utilisation * share.max(1)) / US * US)
                .max(min_period_us * US)
                .max(cost);
            let jitter = if with_jitter {
                period * jitter_pct / 100 / US * US
            } else {
                0
            };
            MessageTiming {
                key: can::arbitration_key(id, false),
                frame_time,
                frames,
                period: Time::from_ns(period),
                jitter: Time::from_ns(jitter),
            }
        })
        .collect();
    set.sort_by_key(|m| m.key);
    set
}

fn sim_messages(set: &[MessageTiming]) -> Vec<SimMessage> {
    set.iter()
        .map(|m| SimMessage {
            key: m.key,
            frame_time: m.frame_time.as_ns(),
            frames: m.frames,
            period: m.period.as_ns(),
            jitter: m.jitter.as_ns(),
        })
        .collect()
}

fn analyse_bus(set: &[MessageTiming], with_blocking: bool) -> Vec<Option<Response>> {
    let bit = can::bit_time(1_000_000);
    let mut scratch = vec![Counter::default(); set.len()];
    responses(
        set.len(),
        with_blocking.then_some(|i: usize| can::blocking(set, i)),
        |i, b| can::response_time(set, i, b, bit, &limits(), &mut scratch),
    )
}

fn raw_messages() -> impl Strategy<Value = (Vec<RawMessage>, Vec<u32>)> {
    prop::collection::vec(
        (0u8..=8, 1u32..=8, 100u64..=3000, 1u64..=10, 0u64..=150),
        1..=6,
    )
    .prop_flat_map(|raw| {
        let n = raw.len();
        (
            Just(raw),
            Just((0u32..0x800).collect::<Vec<_>>())
                .prop_shuffle()
                .prop_map(move |ids| ids[..n].to_vec()),
        )
    })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 300, ..ProptestConfig::default() })]

    #[test]
    fn bus_simulation_never_exceeds_the_analysis(
        (raw, ids) in raw_messages(),
        utilisation in 300u64..=950,
        seed in any::<u64>(),
    ) {
        let set = message_set(&raw, utilisation, true, &ids);
        let bounds = analyse_bus(&set, true);
        let longest = set.iter().map(|m| m.period.as_ns()).max().unwrap_or(0);
        let mut rng = Lcg(seed);
        let mut activations = Vec::new();
        for (m, msg) in set.iter().enumerate() {
            let period = msg.period.as_ns();
            let mut arrival = rng.below(period);
            let sporadic = rng.below(3) == 0;
            let mut last = 0;
            while arrival <= 30 * longest {
                // Any nanosecond, not only bit boundaries: the analysis must hold for all of them.
                let queued = (arrival + rng.below(msg.jitter.as_ns() + 1)).max(last);
                last = queued;
                activations.push(Activation { message: m, arrival, queued });
                arrival += period + if sporadic { rng.below(period) } else { 0 };
            }
        }
        let responses = sim::can_run(&sim_messages(&set), &activations);
        for (a, r) in activations.iter().zip(responses) {
            if let Some(bound) = bounds[a.message] {
                prop_assert!(r <= bound.wcrt.as_ns(), "message {} at {}: simulated {} > analysed {}", a.message, a.arrival, r, bound.wcrt.as_ns());
            }
        }
    }

    #[test]
    fn bus_synchronous_release_meets_the_analysis_exactly(
        (raw, ids) in raw_messages(),
        utilisation in 300u64..=980,
    ) {
        let set = message_set(&raw, utilisation, false, &ids);
        let unblocked = analyse_bus(&set, false);
        prop_assume!(unblocked.iter().all(Option::is_some));
        let horizon = unblocked.iter().flatten().map(|b| b.busy_window.as_ns()).max().unwrap_or(0);
        // Message i with the higher-priority messages only: no lower-priority frame can ever be in progress.
        for (i, bound) in unblocked.iter().enumerate() {
            let worst = sim::can_synchronous_worst(&sim_messages(&set[..=i]), horizon);
            prop_assert_eq!(worst[i], bound.map_or(0, |b| b.wcrt.as_ns()), "message {}", i);
        }
        // The lowest-priority message has nothing to be blocked by: with the whole set, the full analysis is exact.
        let full = analyse_bus(&set, true);
        let worst = sim::can_synchronous_worst(&sim_messages(&set), horizon);
        let last = set.len() - 1;
        prop_assert_eq!(full[last].map(|b| b.wcrt.as_ns()), Some(worst[last]));
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 300, ..ProptestConfig::default() })]

    /// The batched analyses start each iteration from a higher-priority stream's window; they must give exactly
    /// what the one-by-one analyses give.
    #[test]
    fn batched_analyses_equal_one_by_one(
        raw in raw_tasks(),
        (raw_m, ids) in raw_messages(),
        utilisation in 300u64..=990,
    ) {
        let set = board_set(&raw, utilisation, true, true, false);
        let sections: Vec<CriticalSection> = set
            .timings
            .iter()
            .zip(&set.sections)
            .flat_map(|(t, s)| {
                s.iter().map(|&(r, len)| CriticalSection { holder_priority: t.priority, ceiling: set.ceilings[r], length: Time::from_ns(len) })
            })
            .collect();
        let blockings: Vec<Time> = set.timings.iter().map(|t| board::srp_blocking(t.priority, &sections)).collect();
        let limits = limits();
        let mut scratch = vec![Counter::default(); set.timings.len()];
        let mut batched = vec![Err(schedule_analysis::AnalysisError::NoSuchIndex); set.timings.len()];
        board::response_times(&set.timings, &blockings, &limits, &mut scratch, &mut batched);
        for (i, b) in batched.iter().enumerate() {
            let single = board::response_time(&set.timings, i, blockings[i], &limits, &mut scratch);
            prop_assert_eq!(single.map(|r| (r.wcrt, r.worst_instance, r.instances, r.busy_window)), b.map(|r| (r.wcrt, r.worst_instance, r.instances, r.busy_window)));
        }

        let messages = message_set(&raw_m, utilisation, true, &ids);
        let bit = can::bit_time(1_000_000);
        let mut blockings = vec![Time::ZERO; messages.len()];
        can::blockings(&messages, &mut blockings);
        let mut scratch = vec![Counter::default(); messages.len()];
        let mut batched = vec![Err(schedule_analysis::AnalysisError::NoSuchIndex); messages.len()];
        can::response_times(&messages, &blockings, bit, &limits, &mut scratch, &mut batched);
        for (i, b) in batched.iter().enumerate() {
            prop_assert_eq!(blockings[i], can::blocking(&messages, i));
            let single = can::response_time(&messages, i, blockings[i], bit, &limits, &mut scratch);
            prop_assert_eq!(single.map(|r| (r.wcrt, r.worst_instance, r.instances, r.busy_window)), b.map(|r| (r.wcrt, r.worst_instance, r.instances, r.busy_window)));
        }
    }
}

/// Jobs of the critical instant with release jitter: every task's jobs whose nominal arrival is at or before `o`
/// are released together at `o` (each as late as its jitter allows), later ones exactly on time.
fn critical_instant_jobs(set: &BoardSet, o: u64, horizon: u64) -> Vec<Job> {
    let mut jobs = Vec::new();
    for (task, t) in set.timings.iter().enumerate() {
        let (period, jitter, wcet) = (t.period.as_ns(), t.jitter.as_ns(), t.wcet.as_ns());
        let mut arrival = o - jitter;
        while arrival <= o + horizon {
            let release = arrival.max(o);
            jobs.push(Job {
                task,
                arrival,
                release,
                segments: vec![Segment {
                    length: wcet,
                    lock: None,
                }],
            });
            arrival += period;
        }
    }
    jobs
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 300, ..ProptestConfig::default() })]

    /// Release jitter is exact too: replaying the critical instant of the jitter analysis reproduces every bound.
    #[test]
    fn board_critical_instant_with_jitter_meets_the_analysis_exactly(
        raw in raw_tasks(),
        utilisation in 300u64..=950,
    ) {
        let set = board_set(&raw, utilisation, true, false, true);
        let bounds = analyse_board(&set, false);
        prop_assume!(bounds.iter().all(Option::is_some));
        let o = set.timings.iter().map(|t| t.jitter.as_ns()).max().unwrap_or(0) + 1000;
        let horizon = bounds.iter().flatten().map(|b| b.busy_window.as_ns()).max().unwrap_or(0);
        let jobs = critical_instant_jobs(&set, o, horizon);
        let priorities: Vec<u32> = set.timings.iter().map(|t| t.priority).collect();
        let responses = sim::board_run(&priorities, &set.ceilings, &jobs);
        let mut worst = vec![0u64; set.timings.len()];
        for (job, r) in jobs.iter().zip(responses) {
            worst[job.task] = worst[job.task].max(r);
        }
        for (i, bound) in bounds.iter().enumerate() {
            prop_assert_eq!(worst[i], bound.map_or(0, |b| b.wcrt.as_ns()), "task {}", i);
        }
    }

    /// The same on the bus: queuing jitter at its critical instant, each message with the more urgent ones.
    #[test]
    fn bus_critical_instant_with_jitter_meets_the_analysis_exactly(
        (raw, ids) in raw_messages(),
        utilisation in 300u64..=950,
    ) {
        let set = message_set(&raw, utilisation, true, &ids);
        let unblocked = analyse_bus(&set, false);
        prop_assume!(unblocked.iter().all(Option::is_some));
        let o = set.iter().map(|m| m.jitter.as_ns()).max().unwrap_or(0) + 1000;
        let horizon = unblocked.iter().flatten().map(|b| b.busy_window.as_ns()).max().unwrap_or(0);
        for (i, bound) in unblocked.iter().enumerate() {
            let mut activations = Vec::new();
            for (m, msg) in set[..=i].iter().enumerate() {
                let mut arrival = o - msg.jitter.as_ns();
                while arrival <= o + horizon {
                    activations.push(Activation { message: m, arrival, queued: arrival.max(o) });
                    arrival += msg.period.as_ns();
                }
            }
            let responses = sim::can_run(&sim_messages(&set[..=i]), &activations);
            let worst = activations.iter().zip(responses).filter(|(a, _)| a.message == i).map(|(_, r)| r).max().unwrap_or(0);
            prop_assert_eq!(worst, bound.map_or(0, |b| b.wcrt.as_ns()), "message {}", i);
        }
    }
}

/// The bus analysis (`bus_analysis::analyse`, the one the report and the chip's check run) of one board's messages
/// (`own`: identifier, DLC, period, own jitter; sent by a job whose response does not vary, through a transmit
/// interrupt of response `tx`) beside other nodes' (`others`: identifier, DLC, period, jitter): each message's
/// response from its earliest queuing, in the order given (own first), `None` where it has no bound. With
/// `charged`, a frame's abort refill is charged as the host's charged model does (`abort_refill::refill_delay` in
/// its own queuing jitter); without, the uncharged model the verdict and the boards' admission run: the board's
/// frames queued within one transmit response.
fn node_bounds(
    own: &[(u32, u8, u64, u64)],
    others: &[(u32, u8, u64, u64)],
    tx: u64,
    charged: bool,
) -> Vec<Option<u64>> {
    use schedule_analysis::bus_analysis::{self, BusWork, Message, Sender};
    let bit = can::bit_time(1_000_000);
    let tx = Time::from_ns(tx);
    let refill = if charged {
        schedule_analysis::abort_refill::refill_delay(tx, FrameCost::Exact, bit)
    } else {
        Time::ZERO
    };
    let messages: Vec<Message> = own
        .iter()
        .map(|&(id, dlc, period, jitter)| Message {
            id,
            extended: false,
            dlc,
            frames: 1,
            period: Time::from_ns(period),
            jitter: Time::from_ns(jitter).plus(refill),
            sender: Sender::Bounded {
                worst: Time::ZERO,
                best: Time::ZERO,
                tx,
            },
        })
        .chain(others.iter().map(|&(id, dlc, period, jitter)| Message {
            id,
            extended: false,
            dlc,
            frames: 1,
            period: Time::from_ns(period),
            jitter: Time::from_ns(jitter),
            sender: Sender::Outside,
        }))
        .collect();
    let n = messages.len();
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by_key(|&i| can::arbitration_key(messages[i].id, false));
    let empty = MessageTiming {
        key: 0,
        frame_time: Time::ZERO,
        frames: 1,
        period: Time::ZERO,
        jitter: Time::ZERO,
    };
    let mut timings = vec![empty; n];
    let mut offsets = vec![None; n];
    let mut blockings = vec![Time::ZERO; n];
    let mut scratch = vec![Counter::default(); n];
    let mut out: Vec<Result<Response, AnalysisError>> = vec![Err(AnalysisError::NoSuchIndex); n];
    let work = BusWork {
        order: &order,
        timings: &mut timings,
        offsets: &mut offsets,
        blockings: &mut blockings,
        scratch: &mut scratch,
    };
    bus_analysis::analyse(
        |i| messages.get(i).copied(),
        work,
        FrameCost::Exact,
        bit,
        &limits(),
        out.as_mut_slice(),
    );
    let mut bounds = vec![None; n];
    for (position, &i) in order.iter().enumerate() {
        bounds[i] = out[position].as_ref().ok().map(|r| r.wcrt.as_ns());
    }
    bounds
}

fn node_messages(set: &[(u32, u8, u64, u64)]) -> Vec<SimMessage> {
    set.iter()
        .map(|&(id, dlc, period, jitter)| SimMessage {
            key: can::arbitration_key(id, false),
            frame_time: can::frame_time(FrameCost::Exact, dlc, false, can::bit_time(1_000_000))
                .as_ns(),
            frames: 1,
            period,
            jitter,
        })
        .collect()
}

/// A frame that needs an abort whose frame is on the bus, replayed on the board's transmit path
/// (`sim::node_run`), every transmit job acting as late as it may (20 µs after its pend); the board's four
/// frames of eight bytes (135 µs at 1 Mbit/s), `m` 0x010 the most urgent, `v1` 0x030, `v2` 0x031, `v3` 0x032:
///
/// * `v3` queued at 0: in a mailbox at 20, on the bus 20–155 (nothing else pending).
/// * `v1` and `v2` queued at 30: in the two other mailboxes at 50.
/// * `m` queued at 60: at 80 the three mailboxes are taken, `m` beats the least urgent, `v3`, whose abort is
///   asked for; but `v3` is on the bus, so it runs to its end, 155, and completes sent.
/// * At 155 the bus falls idle without `m`: `v1` wins, 155–290. The job `v3`'s completion pended puts `m` in the
///   freed mailbox at 175. At 290 `m` wins over `v2`: 290–425. Its response: 425 − 60 = 365 µs.
///
/// The uncharged model, the verdict's and the boards' (queuing jitter 20, one transmit response; blocking 135):
/// 20 + 135 + 135 = 290 µs, beaten by 75. With the abort refill charged (jitter 20 + 20 + 135 = 175): 445 µs.
#[test]
fn an_abort_whose_frame_is_on_the_bus_beats_the_uncharged_model_not_the_charged() {
    let tx = 20 * US;
    let own = [
        (0x010, 8, 10_000 * US, 0),
        (0x030, 8, 10_000 * US, 0),
        (0x031, 8, 10_000 * US, 0),
        (0x032, 8, 10_000 * US, 0),
    ];
    let queued = [60 * US, 30 * US, 30 * US, 0];
    let activations: Vec<Activation> = queued
        .iter()
        .enumerate()
        .map(|(message, &at)| Activation {
            message,
            arrival: at,
            queued: at,
        })
        .collect();
    let responses = sim::node_run(&node_messages(&own), &[], &activations, tx, &mut |latest| {
        latest
    });
    assert_eq!(responses[0], 365 * US);
    assert_eq!(node_bounds(&own, &[], tx, false)[0], Some(290 * US));
    assert_eq!(node_bounds(&own, &[], tx, true)[0], Some(445 * US));
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 200, ..ProptestConfig::default() })]

    /// The board's transmit path (queue, three mailboxes, aborts, jobs acting up to the transmit interrupt's
    /// response after their pends) beside other nodes' frames: no simulated response exceeds the charged model's
    /// bound (the uncharged one is beaten: above). The board's frames come in bursts, as a publisher job queues
    /// them: every period a multiple of one base period, the first arrivals within 300 µs of each other, so that
    /// the mailboxes fill and more urgent frames come after less urgent ones (the aborts, on and off the bus).
    #[test]
    fn the_transmit_path_never_exceeds_the_analysis(
        ids in Just((0u32..0x800).collect::<Vec<_>>()).prop_shuffle(),
        own_n in 4usize..=6,
        others_n in 0usize..=3,
        raw in proptest::collection::vec((0u8..=8, 1u64..=3, 0u64..=300, 0u64..=300), 9),
        base_us in 800u64..=4_000,
        tx_us in 5u64..=200,
        seed in any::<u64>(),
    ) {
        let set: Vec<(u32, u8, u64, u64)> = raw
            .iter()
            .zip(&ids)
            .map(|(&(dlc, k, _, jitter_us), &id)| (id, dlc, k * base_us * US, jitter_us * US))
            .collect();
        let (own, others) = (&set[..own_n], &set[own_n..own_n + others_n]);
        let tx = tx_us * US;
        let bounds = node_bounds(own, others, tx, true);
        // Each message's frame done before its next is queued: a frame waiting for a mailbox that holds its own
        // identifier is a case the analysis does not charge yet (docs/analysis.md, "Not charged yet").
        let all_periods = own.iter().chain(others).map(|m| m.2);
        prop_assume!(bounds.iter().zip(all_periods).all(|(b, period)| b.is_some_and(|b| b <= period)));
        let all: Vec<(u32, u8, u64, u64)> = own.iter().chain(others).copied().collect();
        let longest = all.iter().map(|m| m.2).max().unwrap_or(0);
        let mut rng = Lcg(seed);
        let mut activations = Vec::new();
        for (m, &(_, _, period, jitter)) in all.iter().enumerate() {
            // The board's own in bursts; the other nodes' anywhere in their periods.
            let mut arrival = if m < own_n { raw[m].2 * US } else { rng.below(period) };
            let mut last = 0;
            while arrival <= 30 * longest {
                let queued = (arrival + rng.below(jitter + 1)).max(last);
                last = queued;
                activations.push(Activation { message: m, arrival, queued });
                arrival += period;
            }
        }
        // Half the jobs act as late as they may, the rest anywhere before.
        let mut jobs = Lcg(seed ^ 0x5eed);
        let mut delay = |latest: u64| if jobs.below(2) == 0 { latest } else { jobs.below(latest + 1) };
        let responses = sim::node_run(&node_messages(own), &node_messages(others), &activations, tx, &mut delay);
        for (a, r) in activations.iter().zip(responses) {
            if let Some(bound) = bounds[a.message] {
                prop_assert!(r <= bound, "message {} at {}: simulated {} > analysed {}", a.message, a.arrival, r, bound);
            }
        }
    }
}
