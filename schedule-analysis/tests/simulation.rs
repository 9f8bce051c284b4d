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

/// A message of the transmit-path tests: identifier, DLC, frames per activation (one identifier: a ring sample's
/// frames, a verdict's pages), period and its own queuing jitter (ns).
type NodeMessage = (u32, u8, u32, u64, u64);

/// The model that bounds a board's messages in the transmit-path tests.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum TxModel {
    /// The model the verdict and the boards' admission ran until 2026-12-05: the board's frames queued within one
    /// transmit response, nothing more (`bus_analysis::analyse` with the response in the queuing jitter and no
    /// transmit interrupt to charge: the plain analysis).
    Uncharged,
    /// The sound one (`bus_analysis::analyse`, the one the report and the chip's check run; docs/analysis.md, "The
    /// sound transmit path: the design"): the board's frames at C + G (G = the transmit response + the longest
    /// frame), every message below the least urgent page (0x71C) blocked by at least the longest frame.
    Sound,
}

/// Each message's bound under `model` (the board's `own`, sent by a job whose response does not vary, through a
/// transmit interrupt of response `tx`; other nodes' `others`): its response from its earliest queuing, in the order
/// given (own first), `None` where it has no bound.
fn node_bounds(
    own: &[NodeMessage],
    others: &[NodeMessage],
    tx: u64,
    model: TxModel,
) -> Vec<Option<u64>> {
    use schedule_analysis::bus_analysis::{Message, Sender};
    let tx = Time::from_ns(tx);
    // The uncharged model: the transmit response in the queuing jitter, no transmit interrupt to charge.
    let (extra, charged) = match model {
        TxModel::Uncharged => (tx, Time::ZERO),
        TxModel::Sound => (Time::ZERO, tx),
    };
    let messages: Vec<Message> = own
        .iter()
        .map(|&(id, dlc, frames, period, jitter)| Message {
            id,
            extended: false,
            dlc,
            frames,
            period: Time::from_ns(period),
            jitter: Time::from_ns(jitter).plus(extra),
            sender: Sender::Bounded {
                worst: Time::ZERO,
                best: Time::ZERO,
                tx: charged,
            },
        })
        .chain(
            others
                .iter()
                .map(|&(id, dlc, frames, period, jitter)| Message {
                    id,
                    extended: false,
                    dlc,
                    frames,
                    period: Time::from_ns(period),
                    jitter: Time::from_ns(jitter),
                    sender: Sender::Outside,
                }),
        )
        .collect();
    // The host's form; its results come in arbitration order.
    let forms = bus_forms(&messages, false);
    let n = messages.len();
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by_key(|&i| can::arbitration_key(messages[i].id, false));
    let mut bounds = vec![None; n];
    for (position, &i) in order.iter().enumerate() {
        bounds[i] = forms[position].0.as_ref().ok().map(|r| r.0.as_ns());
    }
    bounds
}

fn node_messages(set: &[NodeMessage]) -> Vec<SimMessage> {
    set.iter()
        .map(|&(id, dlc, frames, period, jitter)| SimMessage {
            key: can::arbitration_key(id, false),
            frame_time: can::frame_time(FrameCost::Exact, dlc, false, can::bit_time(1_000_000))
                .as_ns(),
            frames,
            period,
            jitter,
        })
        .collect()
}

/// Activations at the given queuing instants (arrival = queuing), one per message in order.
fn queued_at(queued: &[u64]) -> Vec<Activation> {
    queued
        .iter()
        .enumerate()
        .map(|(message, &at)| Activation {
            message,
            arrival: at,
            queued: at,
        })
        .collect()
}

/// (a) A frame that needs an abort whose frame is on the bus, replayed on the board's transmit path
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
/// 20 + 135 + 135 = 290 µs, beaten by 75. The sound model: jitter 20, blocking 135, its frame 135 + G (G = 20 +
/// 135): 20 + 135 + 290 = 445 µs.
#[test]
fn an_abort_whose_frame_is_on_the_bus_beats_the_uncharged_model_not_the_charged() {
    let tx = 20 * US;
    let own = [
        (0x010, 8, 1, 10_000 * US, 0),
        (0x030, 8, 1, 10_000 * US, 0),
        (0x031, 8, 1, 10_000 * US, 0),
        (0x032, 8, 1, 10_000 * US, 0),
    ];
    let activations = queued_at(&[60 * US, 30 * US, 30 * US, 0]);
    let responses = sim::node_run(&node_messages(&own), &[], &activations, tx, &mut |latest| {
        latest
    });
    assert_eq!(responses[0], 365 * US);
    assert_eq!(
        node_bounds(&own, &[], tx, TxModel::Uncharged)[0],
        Some(290 * US)
    );
    assert_eq!(
        node_bounds(&own, &[], tx, TxModel::Sound)[0],
        Some(445 * US)
    );
}

/// Jobs that act after the scripted delays, in the order the jobs are pended, each at most as late as it may; as
/// late as they may once the script is done.
fn scripted(delays: &[u64]) -> impl FnMut(u64) -> u64 + '_ {
    let mut script = delays.iter();
    move |latest| script.next().map_or(latest, |&d| d.min(latest))
}

/// (b) A frame that waits for a mailbox holding its own identifier, by hand: the board's five messages 0x000–0x004
/// without data (55 µs each at 1 Mbit/s), 0x004 with two frames per activation (one identifier, as a verdict's
/// pages), all queued at 0; every job acts 5 µs (the transmit response) after its pend.
///
/// * At 5: 0x000, 0x001, 0x002 in the mailboxes; 0x003 refused (all taken, and it beats none of them).
/// * On the bus 0x000 5–60, 0x001 60–115, 0x002 115–170; the jobs at 65 and 120 put 0x003 and 0x004's first frame
///   in the freed mailboxes; 0x003 170–225, 0x004's first frame 225–280; its second is refused in every job while
///   the first is pending (at 175 and 230).
/// * At 280 the first frame ends, and the bus is idle until the job it pended puts the second in, at 285: 285–340.
///   The response: 340 µs.
///
/// The uncharged model (queuing jitter 5, no blocking): w(1) = 55 + 4·55 = 275, 5 + 275 + 55 = 335 µs, beaten by
/// the 5 µs the second frame waited for a job. The sound model, each of the board's frames at 55 + G (G = 5 + 135 =
/// 140), blocked by a page (135): w(1) = 135 + 195 + 4·195 = 1 110, 5 + 1 110 + 195 = 1 310 µs.
#[test]
fn a_frame_waiting_for_its_own_identifier_beats_the_uncharged_model_not_the_sound() {
    let tx = 5 * US;
    let own: Vec<NodeMessage> = (0..5)
        .map(|id| (id, 0, if id == 4 { 2 } else { 1 }, 10_000 * US, 0))
        .collect();
    let activations = queued_at(&[0; 5]);
    let responses = sim::node_run(&node_messages(&own), &[], &activations, tx, &mut |latest| {
        latest
    });
    assert_eq!(responses[4], 340 * US);
    assert_eq!(
        node_bounds(&own, &[], tx, TxModel::Uncharged)[4],
        Some(335 * US)
    );
    assert_eq!(
        node_bounds(&own, &[], tx, TxModel::Sound)[4],
        Some(1_310 * US)
    );
}

/// (c) A frame displaced from its mailbox waits for the next completion and the job it pends, by hand: the board's
/// `x1` 0x030 (eight bytes, 135 µs), `x2` 0x031, `v` 0x032 and `u` 0x010 (no data, 55 µs), transmit response 200 µs;
/// another node's `w0` 0x041 and `w` 0x040 (eight bytes). `v`, `x1`, `x2` queued at 0, `w0` at 199, `u` and `w` at
/// 210; the first job acts at 200, the next two at once, the rest as late as they may.
///
/// * `w0` on the bus 199–334. At 200 `x1`, `x2`, `v` go into the mailboxes. At 210 `u` beats the least urgent, `v`,
///   off the bus: its abort completes at once, and the job that completion pends (at 210) puts `u` in its mailbox
///   and `v` back into the queue.
/// * `u` 334–389 (its completion pends a job that acts at 589), `x1` 389–524, `x2` 524–579. At 579 the board has
///   nothing pending: `w` wins, 579–714. The job at 589 puts `v` in; `v` 714–769. Its response: 769 µs.
///
/// The uncharged model (queuing jitter 200, blocking 135): 200 + 135 + 55 + 135 + 55 + 55 = 635 µs, beaten by 134.
/// The sound model (the board's frames at C + 335): 200 + 135 + 390 + 470 + 390 + 390 = 1 975 µs.
#[test]
fn a_displaced_frame_beats_the_uncharged_model_not_the_sound() {
    let tx = 200 * US;
    let own = [
        (0x032, 0, 1, 10_000 * US, 0),
        (0x030, 8, 1, 10_000 * US, 0),
        (0x031, 0, 1, 10_000 * US, 0),
        (0x010, 0, 1, 10_000 * US, 0),
    ];
    let others = [(0x041, 8, 1, 10_000 * US, 0), (0x040, 8, 1, 10_000 * US, 0)];
    let activations = queued_at(&[0, 0, 0, 210 * US, 199 * US, 210 * US]);
    let responses = sim::node_run(
        &node_messages(&own),
        &node_messages(&others),
        &activations,
        tx,
        &mut scripted(&[200 * US, 0, 0]),
    );
    assert_eq!(responses[0], 769 * US);
    assert_eq!(
        node_bounds(&own, &others, tx, TxModel::Uncharged)[0],
        Some(635 * US)
    );
    assert_eq!(
        node_bounds(&own, &others, tx, TxModel::Sound)[0],
        Some(1_975 * US)
    );
}

/// (d) A page outside the model's messages blocks a more urgent frame, by hand: the board's `m` 0x100 and another
/// node's `n` 0x200 (no data, 55 µs), transmit response 1 µs; a verdict's page 0x71C (eight bytes, 135 µs) that is
/// no message of the model, queued at 0, on the bus 0–135; `m` queued at 1, in a mailbox at 2, waits for it,
/// 135–190: 189 µs. The uncharged model blocks `m` by the longest lower frame of the model's messages, `n`: 1 + 55 +
/// 55 = 111 µs. The sound model by the longest frame any node can send below the least urgent page, and its frame at
/// 55 + G (G = 1 + 135): 1 + 135 + 191 = 327 µs.
#[test]
fn a_page_outside_the_model_blocks_longer_than_the_model_s_frames() {
    let own = [(0x100, 0, 1, 10_000 * US, 0)];
    let others = [(0x200, 0, 1, 10_000 * US, 0)];
    let page = [(0x71C, 8, 1, 10_000 * US, 0)];
    let theirs: Vec<NodeMessage> = others.iter().chain(&page).copied().collect();
    let activations = queued_at(&[US, 5_000 * US, 0]);
    let responses = sim::node_run(
        &node_messages(&own),
        &node_messages(&theirs),
        &activations,
        US,
        &mut |latest| latest,
    );
    assert_eq!(responses[0], 189 * US);
    assert_eq!(
        node_bounds(&own, &others, US, TxModel::Uncharged)[0],
        Some(111 * US)
    );
    assert_eq!(
        node_bounds(&own, &others, US, TxModel::Sound)[0],
        Some(327 * US)
    );
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 200, ..ProptestConfig::default() })]

    /// The board's transmit path (queue, three mailboxes, aborts, jobs acting up to the transmit interrupt's
    /// response after their pends) beside other nodes' frames and their 8-byte pages outside the model: no
    /// simulated response exceeds the sound model's bound (the uncharged one is beaten: the tests above). The board's frames come in bursts, as a publisher job queues them: every period
    /// a multiple of one base period, the first arrivals within 300 µs of each other, so that the mailboxes fill
    /// and more urgent frames come after less urgent ones (the aborts, on and off the bus, and the displaced
    /// frames); up to four frames of one identifier per activation (the frames that wait for a mailbox of their own
    /// identifier).
    #[test]
    fn the_transmit_path_never_exceeds_the_analysis(
        ids in Just((0u32..0x700).collect::<Vec<_>>()).prop_shuffle(),
        own_n in 4usize..=6,
        others_n in 0usize..=3,
        pages_n in 0usize..=2,
        raw in proptest::collection::vec((0u8..=8, 1u64..=3, 0u64..=300, 0u64..=300, 1u32..=4), 11),
        base_us in 1_500u64..=8_000,
        tx_us in 5u64..=200,
        seed in any::<u64>(),
    ) {
        let set: Vec<NodeMessage> = raw
            .iter()
            .zip(&ids)
            .enumerate()
            .map(|(i, (&(dlc, k, _, jitter_us, frames), &id))| {
                // The board's own may send several frames per activation; the other nodes' and their pages one.
                let frames = if i < own_n { frames } else { 1 };
                (id, dlc, frames, k * base_us * US, jitter_us * US)
            })
            .collect();
        let (own, others) = (&set[..own_n], &set[own_n..own_n + others_n]);
        // Pages: eight bytes, at least a base period apart, not in the model's messages, below every message (a
        // page above a message would be interference no model here sees: the model's messages are the bus's).
        let pages: Vec<NodeMessage> = set[own_n + others_n..own_n + others_n + pages_n]
            .iter()
            .map(|&(id, _, _, period, _)| (0x700 + id % 0x1D, 8, 1, period, 0))
            .collect();
        let tx = tx_us * US;
        let bounds = node_bounds(own, others, tx, TxModel::Sound);
        prop_assume!(bounds.iter().all(Option::is_some));
        let all: Vec<NodeMessage> = own.iter().chain(others).chain(&pages).copied().collect();
        let longest = all.iter().map(|m| m.3).max().unwrap_or(0);
        let mut rng = Lcg(seed);
        let mut activations = Vec::new();
        for (m, &(_, _, _, period, jitter)) in all.iter().enumerate() {
            // The board's own in bursts; the other nodes' anywhere in their periods, their pages sporadic.
            let mut arrival = if m < own_n { raw[m].2 * US } else { rng.below(period) };
            let mut last = 0;
            while arrival <= 30 * longest {
                let queued = (arrival + rng.below(jitter + 1)).max(last);
                last = queued;
                activations.push(Activation { message: m, arrival, queued });
                arrival += if m >= own_n + others_n { period + rng.below(period) } else { period };
            }
        }
        // Half the jobs act as late as they may, the rest anywhere before.
        let mut jobs = Lcg(seed ^ 0x5eed);
        let mut delay = |latest: u64| if jobs.below(2) == 0 { latest } else { jobs.below(latest + 1) };
        let theirs: Vec<NodeMessage> = others.iter().chain(&pages).copied().collect();
        let responses = sim::node_run(&node_messages(own), &node_messages(&theirs), &activations, tx, &mut delay);
        for (a, r) in activations.iter().zip(responses) {
            if let Some(Some(bound)) = bounds.get(a.message) {
                prop_assert!(r <= *bound, "message {} at {}: simulated {} > analysed {}", a.message, a.arrival, r, bound);
            }
        }
    }
}

/// A message's bound as the forms are compared ((WCRT, worst instance, instances, busy window) or why none), and its
/// blocking.
type FormBound = (Result<(Time, u64, u64, Time), AnalysisError>, Time);

/// One bus through `bus_analysis`'s host form (`analyse`, start hints where no board is charged) or its chip form
/// (`analyse_each`): each message's bound in arbitration order, with its blocking.
fn bus_forms(messages: &[schedule_analysis::bus_analysis::Message], each: bool) -> Vec<FormBound> {
    use schedule_analysis::bus_analysis::{self, BusWork};
    let bit = can::bit_time(1_000_000);
    let n = messages.len();
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by_key(|&i| can::arbitration_key(messages[i].id, messages[i].extended));
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
    let message = |i: usize| messages.get(i).copied();
    if each {
        bus_analysis::analyse_each(
            message,
            work,
            FrameCost::Exact,
            bit,
            &limits(),
            out.as_mut_slice(),
        );
    } else {
        bus_analysis::analyse(
            message,
            work,
            FrameCost::Exact,
            bit,
            &limits(),
            out.as_mut_slice(),
        );
    }
    out.iter()
        .zip(&blockings)
        .map(|(r, &b)| {
            (
                r.map(|r| (r.wcrt, r.worst_instance, r.instances, r.busy_window)),
                b,
            )
        })
        .collect()
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 300, ..ProptestConfig::default() })]

    /// The bus's one engine: the host's form (start hints where no board is charged) and the chip's (every
    /// message by its own fixed point) give the same bounds, charged or not; and a bus with no message sent through
    /// a transmit interrupt (no sender with a transmit response) gives the plain analysis's figures, the verdict's
    /// before the sound transmit path (`can::blockings`, `can::response_times`: no raised frames, no page floor).
    #[test]
    fn the_host_and_chip_forms_agree_and_an_uncharged_bus_is_the_plain_analysis(
        (raw, ids) in raw_messages(),
        senders in proptest::collection::vec((0u8..3, 0u64..=300, 0u64..=200, 0u64..=100), 6),
        utilisation in 300u64..=990,
        charged in any::<bool>(),
    ) {
        use schedule_analysis::bus_analysis::{Message, Sender};
        let set = message_set(&raw, utilisation, true, &ids);
        // `message_set` sorts by arbitration: each raw message's timing found by its identifier.
        let timing = |id: u32| set.iter().find(|m| m.key == can::arbitration_key(id, false)).copied().unwrap();
        let messages: Vec<Message> = ids
            .iter()
            .zip(&raw)
            .zip(&senders)
            .map(|((&id, r), &(kind, worst_us, best_us, tx_us))| (timing(id), id, r, (kind, worst_us, best_us, tx_us)))
            .map(|(m, id, r, (kind, worst_us, best_us, tx_us))| Message {
                id,
                extended: false,
                dlc: r.0,
                frames: m.frames,
                period: m.period,
                jitter: m.jitter,
                sender: match kind {
                    0 => Sender::Outside,
                    _ => Sender::Bounded {
                        worst: Time::from_us(worst_us.max(best_us)),
                        best: Time::from_us(best_us),
                        // A board of two transmit responses where charged (kind 1 or 2), none otherwise.
                        tx: if charged { Time::from_us(tx_us * u64::from(kind)) } else { Time::ZERO },
                    },
                },
            })
            .collect();
        let host = bus_forms(&messages, false);
        let chip = bus_forms(&messages, true);
        prop_assert_eq!(&host, &chip);
        if !charged {
            let bit = can::bit_time(1_000_000);
            let mut plain: Vec<MessageTiming> = messages.iter().map(|m| m.timing(FrameCost::Exact, bit).0).collect();
            plain.sort_by_key(|m| m.key);
            let mut blockings = vec![Time::ZERO; plain.len()];
            can::blockings(&plain, &mut blockings);
            let mut scratch = vec![Counter::default(); plain.len()];
            let mut out = vec![Err(AnalysisError::NoSuchIndex); plain.len()];
            can::response_times(&plain, &blockings, bit, &limits(), &mut scratch, &mut out);
            let expected: Vec<_> = out
                .iter()
                .zip(&blockings)
                .map(|(r, &b)| (r.map(|r| (r.wcrt, r.worst_instance, r.instances, r.busy_window)), b))
                .collect();
            prop_assert_eq!(host, expected);
        }
    }
}
