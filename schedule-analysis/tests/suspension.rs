//! The self-suspension analysis (`schedule_analysis::sensor_bus`) against the simulator on many random boards:
//! jobs that run their CPU before, between and after one to three scripts on two sensor buses (each bus
//! non-preemptive, by priority), each script after a settle of the job's own at times, SRP locks, release jitter,
//! sporadic gaps, shorter executions, scripts and settles, the jobs of one RTIC task one at a time: no simulated
//! response exceeds the analysed bound. The engine's interrupt is not simulated (its rows are zero here: a script
//! raises no events).

use proptest::prelude::*;
use proptest::strategy::ValueTree;
use schedule_analysis::analysis;
use schedule_analysis::board::{self, TaskTiming};
use schedule_analysis::busy_window::{Counter, Limits};
use schedule_analysis::model::{BoardSystem, OverheadTimes, TaskKind, TaskSpec};
use schedule_analysis::sensor_bus;
use schedule_analysis::sensor_bus::{BoardBuses, Part, PerEventFrom, Script, SensorBus};
use schedule_analysis::time::Time;

mod sim;

use sim::{Piece, Segment, SuspendingJob};

const US: u64 = 1000;

/// A random task before scaling: priority, period (µs), CPU share, jitter (% of the period), joins the previous
/// task's RTIC task, its scripts' bus time together (% of its period, 0: no script), its critical section (% of its
/// CPU, 0: none), how many scripts its job runs (1 to 3; the `k`th on bus `(task + k) % 2`), each script's settle
/// (‰ of its period, 0: none).
type RawTask = (u32, u64, u64, u64, bool, u64, u64, u64, u64);

/// One script of a random job: its bus, its bus time and its settle (ns).
#[derive(Clone, Copy)]
struct RandomScript {
    bus: usize,
    length: u64,
    settle: u64,
}

struct Set {
    board: BoardSystem,
    /// The RTIC task of each task.
    serial: Vec<usize>,
    /// Per task: its job's scripts in order, the critical section (ns).
    script: Vec<Vec<RandomScript>>,
    section: Vec<Option<u64>>,
    ceiling: u32,
}

fn set(raw: &[RawTask], utilisation: u64) -> Set {
    chained_set(raw, utilisation, &[])
}

/// [`set`] with release chains: task `i` is released by task `i − releases[i]` where that is a task of another RTIC
/// task (0 or out of range: not released), at its releaser's period (one job per releaser's job), its own jitter
/// on top of its releaser's completion. The releaser's priority is random: lower or higher, suspending or not.
fn chained_set(raw: &[RawTask], utilisation: u64, releases: &[u64]) -> Set {
    let shares: u64 = raw.iter().map(|t| t.2).sum::<u64>().max(1);
    let mut tasks = Vec::new();
    let mut serial = Vec::new();
    let mut script = Vec::new();
    let mut section = Vec::new();
    let mut scripts = Vec::new();
    for (
        i,
        &(priority, period_us, share, jitter_pct, joins, script_pct, section_pct, count, settle_pm),
    ) in raw.iter().enumerate()
    {
        let joined = joins && i > 0;
        let released_by = releases
            .get(i)
            .and_then(|&back| i.checked_sub(back as usize).filter(|_| back > 0))
            .filter(|&by| !joined && serial[by] != i);
        let period = released_by.map_or(period_us * US, |by| {
            let releaser: &TaskSpec = &tasks[by];
            releaser.period.as_ns()
        });
        let wcet = ((period * utilisation * share) / (shares * 1000) / US).max(1) * US;
        let (priority, group) = if joined {
            let previous: &TaskSpec = &tasks[i - 1];
            (previous.priority, serial[i - 1])
        } else {
            (priority, i)
        };
        let count = if script_pct > 0 { count.max(1) } else { 0 };
        let job: Vec<RandomScript> = (0..count)
            .map(|k| RandomScript {
                bus: (i + k as usize) % 2,
                length: (period * script_pct / 100 / count / US).max(1) * US,
                settle: period * settle_pm / 1000 / US * US,
            })
            .collect();
        let cs = (section_pct > 0).then(|| (wcet * section_pct / 100 / US).max(1) * US);
        for (k, s) in job.iter().enumerate() {
            scripts.push(Script {
                task: i,
                bus: s.bus,
                wire: Time::from_ns(s.length),
                stretch: Time::ZERO,
                events: 0,
                starts: 0,
                engine_row: usize::MAX,
                position: k,
                of: job.len(),
                settle: Time::from_ns(s.settle),
            });
        }
        tasks.push(TaskSpec {
            name: format!("t{i}"),
            priority,
            wcet: Time::from_ns(wcet),
            bcet: Time::ZERO,
            period: Time::from_ns(period),
            deadline: Time::from_ns(period),
            deadline_follows_period: true,
            jitter: Time::from_ns(period * jitter_pct / 100 / US * US),
            sections: cs
                .map(|l| vec![("r".to_string(), Time::from_ns(l))])
                .unwrap_or_default(),
            blocking: None,
            kind: TaskKind::Plain,
            released_by,
            sporadic: false,
            job_of: Some(format!("rtic{group}")),
        });
        serial.push(group);
        script.push(job);
        section.push(cs);
    }
    let ceiling = tasks
        .iter()
        .filter(|t| !t.sections.is_empty())
        .map(|t| t.priority)
        .max()
        .unwrap_or(0);
    let board = BoardSystem {
        name: "random".into(),
        overheads: OverheadTimes::default(),
        tasks,
        idle_sections: Vec::new(),
        can_tx_task: None,
        static_ceilings: Vec::new(),
        sensor_buses: BoardBuses {
            buses: ["i2c1", "i2c2"]
                .into_iter()
                .map(|name| SensorBus {
                    name: name.into(),
                    bitrate: 400_000,
                    bit_time: Time::from_ns(2500),
                    engine_priority: 10,
                    per_event: Time::ZERO,
                    per_event_from: PerEventFrom::Estimate,
                    source: "not simulated".into(),
                    per_script: None,
                    condition_wait: None,
                })
                .collect(),
            scripts,
        },
    };
    Set {
        board,
        serial,
        script,
        section,
        ceiling,
    }
}

/// A deterministic generator for the release patterns (proptest chooses its seed).
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
    /// 0, `n` or anything between (the extremes are where suspensions hurt most).
    fn split(&mut self, n: u64) -> u64 {
        match self.below(3) {
            0 => 0,
            1 => n,
            _ => self.below(n / US + 1) * US,
        }
    }
}

fn cpu(length: u64, lock: bool) -> Piece {
    Piece::Cpu(Segment {
        length,
        lock: lock.then_some(0),
    })
}

/// A released job's link to the job whose completion releases it: the releaser's index in the jobs and the job's
/// own jitter drawn, on top of that completion.
#[derive(Clone, Copy)]
struct Link {
    job: usize,
    releaser: usize,
    jitter: u64,
}

/// Random jobs: offsets, periodic or sporadic, release jitter, the CPU split at random around the scripts (often all
/// in one part), shorter CPU, scripts and settles at times, the critical section in any one part. A released task
/// has one job per job of its releaser, from the same arrival; its release is set by [`chained_run`].
fn random_jobs(set: &Set, seed: u64, horizon: u64) -> (Vec<SuspendingJob>, Vec<Link>) {
    let mut rng = Lcg(seed);
    let mut jobs: Vec<SuspendingJob> = Vec::new();
    let mut links = Vec::new();
    for (task, t) in set.board.tasks.iter().enumerate() {
        let period = t.period.as_ns();
        let mut arrival = rng.below(period / US) * US;
        let sporadic = rng.below(3) == 0;
        let mut last_release = 0;
        // A released task's jobs: one per job of its releaser (generated before it: its releaser comes first).
        let releasers: Option<Vec<usize>> = t.released_by.map(|by| {
            (0..jobs.len())
                .filter(|&j| jobs[j].task == by)
                .collect::<Vec<usize>>()
        });
        let mut next_releaser = 0;
        loop {
            if let Some(list) = &releasers {
                let Some(&r) = list.get(next_releaser) else {
                    break;
                };
                next_releaser += 1;
                arrival = jobs[r].arrival;
                links.push(Link {
                    job: jobs.len(),
                    releaser: r,
                    jitter: rng.below(t.jitter.as_ns() / US + 1) * US,
                });
            } else if arrival > horizon {
                break;
            }
            let jitter = if releasers.is_some() {
                0
            } else {
                rng.below(t.jitter.as_ns() / US + 1) * US
            };
            let release = (arrival + jitter).max(last_release);
            last_release = release;
            let wcet = t.wcet.as_ns();
            let exec = if rng.below(4) == 0 {
                (rng.below(wcet / US) + 1) * US
            } else {
                wcet
            };
            // The CPU in one part more than the job has scripts.
            let job = &set.script[task];
            let mut parts = Vec::with_capacity(job.len() + 1);
            let mut left = exec;
            for _ in 0..job.len() {
                let part = rng.split(left);
                parts.push(part);
                left -= part;
            }
            parts.push(left);
            // The critical section at the start of the part that can hold it (clipped to that part).
            let section = set.section[task].unwrap_or(0);
            let piece = |length: u64, with_lock: bool| -> Vec<Piece> {
                let locked = if with_lock { section.min(length) } else { 0 };
                let mut out = Vec::new();
                if locked > 0 {
                    out.push(cpu(locked, true));
                }
                if length > locked {
                    out.push(cpu(length - locked, false));
                }
                out
            };
            let locked_part = rng.below(parts.len() as u64) as usize;
            let mut pieces = Vec::new();
            for (k, &part) in parts.iter().enumerate() {
                pieces.extend(piece(part, k == locked_part));
                let Some(s) = job.get(k) else {
                    continue;
                };
                if s.settle > 0 {
                    let settle = if rng.below(4) == 0 {
                        rng.below(s.settle / US + 1) * US
                    } else {
                        s.settle
                    };
                    pieces.push(Piece::Settle(settle));
                }
                let actual = if rng.below(4) == 0 {
                    (rng.below(s.length / US) + 1) * US
                } else {
                    s.length
                };
                pieces.push(Piece::ScriptOn(s.bus, actual));
            }
            jobs.push(SuspendingJob {
                task,
                arrival,
                release,
                pieces,
            });
            arrival += period
                + if sporadic {
                    rng.below(period / US) * US
                } else {
                    0
                };
        }
    }
    (jobs, links)
}

/// [`sim::suspending_run`] with each released job ready at its releaser's completion plus its own jitter (no earlier
/// than its task's previous job): replayed until the releases agree with the completions. The replay is causal
/// (what happens before an instant depends on the releases before it alone), so each replay settles at least one
/// more release in time order: at most one replay per released job and one more. `None` if it did not settle.
fn chained_run(
    priorities: &[u32],
    serial: &[usize],
    ceilings: &[u32],
    jobs: &mut [SuspendingJob],
    links: &[Link],
) -> Option<Vec<u64>> {
    for _ in 0..=links.len() {
        let responses = sim::suspending_run(priorities, serial, ceilings, jobs);
        let mut changed = false;
        let mut last: Vec<u64> = vec![0; priorities.len()];
        for link in links {
            let releaser = &jobs[link.releaser];
            let done = releaser.arrival + responses[link.releaser];
            let task = jobs[link.job].task;
            let release = (done + link.jitter).max(last[task]);
            last[task] = release;
            if jobs[link.job].release != release {
                jobs[link.job].release = release;
                changed = true;
            }
        }
        if !changed {
            return Some(responses);
        }
    }
    None
}

fn raw_tasks() -> impl Strategy<Value = Vec<RawTask>> {
    prop::collection::vec(
        (
            1u32..=4,
            20u64..=240,
            1u64..=10,
            0u64..=60,
            prop::bool::weighted(0.25),
            prop_oneof![Just(0u64), 1u64..=12],
            prop_oneof![Just(0u64), 10u64..=100],
            1u64..=3,
            prop_oneof![Just(0u64), 1u64..=30],
        ),
        2..=5,
    )
}

/// Every job's simulated response against its task's bound; how many jobs had a bound.
fn check(set: &Set, seed: u64) -> Result<usize, String> {
    let result = analysis::analyse_board(&set.board, &Limits::default());
    let longest = set
        .board
        .tasks
        .iter()
        .map(|t| t.period.as_ns())
        .max()
        .unwrap_or(0);
    let (mut jobs, links) = random_jobs(set, seed, 40 * longest);
    let priorities: Vec<u32> = set.board.tasks.iter().map(|t| t.priority).collect();
    let responses = chained_run(&priorities, &set.serial, &[set.ceiling], &mut jobs, &links)
        .ok_or("the releases did not settle")?;
    let mut bounded = 0;
    for (job, r) in jobs.iter().zip(responses) {
        if let Some(bound) = result.tasks[job.task].wcrt() {
            bounded += 1;
            if r > bound.as_ns() {
                return Err(format!(
                    "task {} job at {}: simulated {} > analysed {}",
                    job.task,
                    job.arrival,
                    r,
                    bound.as_ns()
                ));
            }
        }
    }
    Ok(bounded)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 400, ..ProptestConfig::default() })]

    #[test]
    fn suspending_simulation_never_exceeds_the_analysis(
        raw in raw_tasks(),
        utilisation in 100u64..=600,
        seed in any::<u64>(),
    ) {
        let set = set(&raw, utilisation);
        let checked = check(&set, seed);
        prop_assert!(checked.is_ok(), "{}", checked.unwrap_err());
    }
}

/// Per task: how far back its releaser is (0: none), as [`chained_set`] reads it; mostly released.
fn releases() -> impl Strategy<Value = Vec<u64>> {
    prop::collection::vec(prop_oneof![1 => Just(0u64), 2 => 1u64..=4], 5)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 100, ..ProptestConfig::default() })]

    /// Release chains: a lower job releasing a higher one and the reverse, a suspending job releasing a suspending
    /// one or a plain one; the simulator readies each released job at its releaser's completion.
    #[test]
    fn chained_simulation_never_exceeds_the_analysis(
        raw in raw_tasks(),
        releases in releases(),
        utilisation in 100u64..=600,
        seed in any::<u64>(),
    ) {
        let set = chained_set(&raw, utilisation, &releases);
        let checked = check(&set, seed);
        prop_assert!(checked.is_ok(), "{}", checked.unwrap_err());
    }

    /// The same on [`heavy_tasks`]' sets, where the suspending job's segments' bound is often the one taken.
    #[test]
    fn chained_heavy_simulation_never_exceeds_the_analysis(
        raw in heavy_tasks(),
        releases in releases(),
        utilisation in 100u64..=500,
        seed in any::<u64>(),
    ) {
        let set = chained_set(&raw, utilisation, &releases);
        let checked = check(&set, seed);
        prop_assert!(checked.is_ok(), "{}", checked.unwrap_err());
    }
}

/// Release chains where the suspension matters most, each with zero to two short tasks above (priorities 5 and 6):
/// a suspending job (priority 2, its scripts 20 to 60 % of its period) released by a heavy one below it (1); a job
/// above (3) released by a heavy one at the bottom (1) across a suspending one between them (2); a suspending job (3)
/// releasing another (2, a long script) over a heavy plain one (1).
fn chain_templates() -> impl Strategy<Value = (Vec<RawTask>, Vec<u64>)> {
    let above = (
        5u32..=6,
        10u64..=60,
        1u64..=5,
        0u64..=30,
        Just(false),
        Just(0u64),
        prop_oneof![Just(0u64), 10u64..=100],
        Just(1u64),
        Just(0u64),
    );
    let heavy = |priority: u32| {
        (
            Just(priority),
            100u64..=400,
            5u64..=10,
            0u64..=20,
            Just(false),
            Just(0u64),
            prop_oneof![Just(0u64), 10u64..=100],
            Just(1u64),
            Just(0u64),
        )
    };
    let suspending = |priority: u32, script: std::ops::RangeInclusive<u64>| {
        (
            Just(priority),
            100u64..=400,
            1u64..=3,
            0u64..=20,
            Just(false),
            script,
            prop_oneof![Just(0u64), 10u64..=100],
            prop_oneof![3 => Just(1u64), 1 => Just(2u64)],
            prop_oneof![3 => Just(0u64), 1 => 1u64..=20],
        )
    };
    let plain = |priority: u32| {
        (
            Just(priority),
            20u64..=200,
            1u64..=3,
            0u64..=20,
            Just(false),
            Just(0u64),
            Just(0u64),
            Just(1u64),
            Just(0u64),
        )
    };
    let templates = prop_oneof![
        (heavy(1), suspending(2, 20..=60)).prop_map(|(r, p)| (vec![r, p], vec![0, 1])),
        (heavy(1), suspending(2, 20..=60), plain(3))
            .prop_map(|(r, p, x)| (vec![r, p, x], vec![0, 0, 2])),
        (suspending(3, 5..=15), suspending(2, 20..=50), heavy(1))
            .prop_map(|(a, b, l)| (vec![a, b, l], vec![0, 1, 0])),
    ];
    (templates, prop::collection::vec(above, 0..=2)).prop_map(|((mut raw, mut releases), above)| {
        releases.extend(above.iter().map(|_| 0));
        raw.extend(above);
        (raw, releases)
    })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 400, ..ProptestConfig::default() })]

    /// [`chain_templates`]' sets against the simulator.
    #[test]
    fn chain_templates_never_exceed_the_analysis(
        (raw, releases) in chain_templates(),
        utilisation in 300u64..=900,
        seed in any::<u64>(),
    ) {
        let set = chained_set(&raw, utilisation, &releases);
        let checked = check(&set, seed);
        prop_assert!(checked.is_ok(), "{}", checked.unwrap_err());
    }
}

/// The chained properties are not vacuous: on a fixed sweep of [`raw_tasks`]' and [`heavy_tasks`]' sets with
/// releases (128 released tasks, 95 of them bounded, 21 released by a lower one, 11 suspending ones released by a
/// suspending one, 178 530 jobs checked), released tasks are bounded and their jobs checked.
#[test]
fn the_chained_sets_are_checked() {
    let mut runner = proptest::test_runner::TestRunner::deterministic();
    let strategy = (
        prop_oneof![raw_tasks(), heavy_tasks()],
        releases(),
        100u64..=600,
    );
    let (mut released, mut bounded, mut by_lower, mut suspending_pairs, mut jobs) = (0, 0, 0, 0, 0);
    for case in 0..200 {
        let (raw, releases, utilisation) = strategy.new_tree(&mut runner).unwrap().current();
        let set = chained_set(&raw, utilisation, &releases);
        let result = analysis::analyse_board(&set.board, &Limits::default());
        let suspends = |i: usize| !set.script[i].is_empty();
        for (i, t) in set.board.tasks.iter().enumerate() {
            let Some(by) = t.released_by else {
                continue;
            };
            released += 1;
            if result.tasks[i].wcrt().is_some() {
                bounded += 1;
                by_lower += usize::from(set.board.tasks[by].priority < t.priority);
                suspending_pairs += usize::from(suspends(i) && suspends(by));
            }
        }
        jobs += check(&set, case).expect("within the analysis");
    }
    assert!(released > 100, "{released} released tasks");
    assert!(
        bounded * 3 >= released,
        "{bounded} of {released} released tasks bounded"
    );
    assert!(
        by_lower > 20,
        "{by_lower} bounded tasks released by a lower one"
    );
    assert!(
        suspending_pairs > 10,
        "{suspending_pairs} bounded suspending tasks released by a suspending one"
    );
    assert!(jobs > 10_000, "{jobs} jobs checked");
}

/// The property above is not vacuous: on a fixed sweep of sets most tasks with a script are bounded, and their
/// jobs are checked.
#[test]
fn the_random_sets_are_mostly_bounded() {
    let mut rng = Lcg(0x5eed);
    let (mut suspending, mut bounded_suspending, mut jobs, mut several) = (0, 0, 0, 0);
    for case in 0..200 {
        let n = 2 + rng.below(4) as usize;
        let raw: Vec<RawTask> = (0..n)
            .map(|_| {
                (
                    1 + rng.below(4) as u32,
                    20 + rng.below(221),
                    1 + rng.below(10),
                    rng.below(61),
                    rng.below(4) == 0,
                    if rng.below(2) == 0 {
                        0
                    } else {
                        1 + rng.below(12)
                    },
                    if rng.below(2) == 0 {
                        0
                    } else {
                        10 + rng.below(91)
                    },
                    1 + rng.below(3),
                    if rng.below(2) == 0 {
                        0
                    } else {
                        1 + rng.below(30)
                    },
                )
            })
            .collect();
        let set = set(&raw, 100 + rng.below(501));
        let result = analysis::analyse_board(&set.board, &Limits::default());
        for s in set
            .board
            .sensor_buses
            .scripts
            .iter()
            .filter(|s| s.position == 0)
        {
            suspending += 1;
            if result.tasks[s.task].wcrt().is_some() {
                bounded_suspending += 1;
                if s.of > 1 {
                    several += 1;
                }
            }
        }
        jobs += check(&set, case).expect("within the analysis");
    }
    assert!(suspending > 100, "{suspending} suspending tasks");
    assert!(
        bounded_suspending * 10 >= suspending * 7,
        "{bounded_suspending} of {suspending} suspending tasks bounded"
    );
    assert!(jobs > 10_000, "{jobs} jobs checked");
    assert!(several > 50, "{several} bounded jobs of several scripts");
}

/// Sets where a suspending job's suspension is long against the periods above it, so that its bound by its CPU
/// segments (`suspension_analysis`, docs/analysis.md "The suspending job by its segments") is often the one taken:
/// one to three short-period tasks above (priorities 3 and 4, periods 20 to 80 µs), a job at 2 whose scripts take
/// 30 to 75 % of its 150 to 400 µs period, and at times a task below it; release jitter, settles, critical
/// sections and jobs of one RTIC task as in [`raw_tasks`].
fn heavy_tasks() -> impl Strategy<Value = Vec<RawTask>> {
    let above = (
        3u32..=4,
        10u64..=40,
        1u64..=10,
        0u64..=30,
        Just(false),
        Just(0u64),
        prop_oneof![Just(0u64), 10u64..=100],
        Just(1u64),
        Just(0u64),
    );
    let suspending = (
        Just(2u32),
        300u64..=800,
        1u64..=10,
        0u64..=20,
        Just(false),
        40u64..=80,
        prop_oneof![Just(0u64), 10u64..=100],
        prop_oneof![3 => Just(1u64), 1 => 2u64..=3],
        prop_oneof![3 => Just(0u64), 1 => 1u64..=20],
    );
    let below = (
        Just(1u32),
        200u64..=800,
        1u64..=10,
        0u64..=30,
        prop::bool::weighted(0.3),
        prop_oneof![Just(0u64), 1u64..=12],
        prop_oneof![Just(0u64), 10u64..=100],
        1u64..=2,
        Just(0u64),
    );
    (
        prop::collection::vec(above, 1..=3),
        suspending,
        prop::collection::vec(below, 0..=1),
    )
        .prop_map(|(mut above, suspending, below)| {
            above.push(suspending);
            above.extend(below);
            above
        })
}

/// Whether task `i`'s bound is its segments' bound: below its suspension-oblivious bound (its CPU, suspensions,
/// settles and a blocking per resumption as its execution, every other task at or above its priority at its own
/// jitter: in [`heavy_tasks`] no other suspending job is at or above it), or where that has none.
fn by_segments(set: &Set, result: &analysis::BoardResult, i: usize) -> bool {
    let task = &set.board.tasks[i];
    let ours = |s: &&sensor_bus::ScriptResult| {
        s.task == task.name || s.task.starts_with(&format!("{}#", task.name))
    };
    let scripts: Vec<&sensor_bus::ScriptResult> = result
        .sensor_buses
        .iter()
        .flat_map(|bus| &bus.scripts)
        .filter(ours)
        .collect();
    let blocking = result.tasks[i].blocking;
    let executed = scripts.iter().fold(task.wcet, |c, s| {
        let resumptions = if s.settle > Time::ZERO { 2 } else { 1 };
        c.plus(s.suspension.unwrap_or(Time::ZERO))
            .plus(s.settle)
            .plus(blocking.times(resumptions))
    });
    let mut level: Vec<TaskTiming> = set
        .board
        .tasks
        .iter()
        .enumerate()
        .filter(|&(k, t)| k != i && t.priority >= task.priority)
        .map(|(_, t)| TaskTiming {
            priority: t.priority,
            wcet: t.wcet,
            period: t.period,
            jitter: t.jitter,
        })
        .collect();
    level.sort_by_key(|t| std::cmp::Reverse(t.priority));
    level.push(TaskTiming {
        priority: task.priority,
        wcet: executed,
        period: task.period,
        jitter: task.jitter,
    });
    let mut scratch = vec![Counter::default(); level.len()];
    let at = level.len() - 1;
    let oblivious = board::response_time(&level, at, Time::ZERO, &Limits::default(), &mut scratch);
    match (result.tasks[i].wcrt(), oblivious) {
        (Some(r), Ok(o)) => r < o.wcrt,
        (Some(_), Err(_)) => true,
        (None, _) => false,
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 400, ..ProptestConfig::default() })]

    /// The bound by a suspending job's segments never falls below the simulated responses (with a second
    /// resumption's interference left out, or a bound above the period taken, it does: see
    /// `the_segments_bound_is_often_the_one_taken`).
    #[test]
    fn a_suspending_jobs_segments_never_fall_below_the_simulation(
        raw in heavy_tasks(),
        utilisation in 100u64..=500,
        seed in any::<u64>(),
    ) {
        let set = set(&raw, utilisation);
        let checked = check(&set, seed);
        prop_assert!(checked.is_ok(), "{}", checked.unwrap_err());
    }
}

/// The property above is not vacuous: on a fixed sweep of its sets, many suspending jobs' bounds are their segments'
/// (below any suspension-oblivious bound), and their jobs are checked against the simulator.
#[test]
fn the_segments_bound_is_often_the_one_taken() {
    let mut rng = Lcg(0x5e9);
    let (mut taken, mut jobs) = (0, 0);
    let runner_config = proptest::test_runner::Config::default();
    let mut runner = proptest::test_runner::TestRunner::new_with_rng(
        runner_config,
        proptest::test_runner::TestRng::deterministic_rng(
            proptest::test_runner::RngAlgorithm::ChaCha,
        ),
    );
    let strategy = heavy_tasks();
    for case in 0..200 {
        let raw = strategy.new_tree(&mut runner).expect("a set").current();
        let set = set(&raw, 100 + rng.below(401));
        let result = analysis::analyse_board(&set.board, &Limits::default());
        for i in 0..result.tasks.len() {
            if !set.script[i].is_empty() && by_segments(&set, &result, i) {
                taken += 1;
            }
        }
        jobs += check(&set, case).expect("within the analysis");
    }
    assert!(
        taken > 30,
        "{taken} suspending jobs bounded by their segments"
    );
    assert!(jobs > 10_000, "{jobs} jobs checked");
}

/// A task at or above the engine's priority in [`script_board`]: priority (5 to 7), CPU (µs), period (µs), release
/// jitter (µs), whether it locks the resource the task below the engine locks.
type Above = (u32, u64, u64, u64, bool);

/// The engine's figures in [`script_board`] (µs): per event, the condition wait, the per-script part; and the
/// script's events, STARTs, wire time (µs) and the critical section of the task below the engine (µs, 0: none).
type Engine = (u64, u64, u64, u32, u32, u64, u64);

/// The engine's priority in [`script_board`].
const ENGINE: u32 = 5;

/// A board with one bus whose engine runs at priority 5: the tasks `above` (at or above it), a task at 2 whose jobs
/// are one critical section on a resource some of them may lock too, and a client at 1 that runs one script.
fn script_board(above: &[Above], engine: Engine) -> BoardSystem {
    let (per_event, wait, per_script, events, starts, wire, section) = engine;
    let task =
        |name: String, priority, wcet: u64, period: u64, jitter: u64, lock: Option<u64>| TaskSpec {
            name: name.clone(),
            priority,
            wcet: Time::from_us(wcet),
            bcet: Time::ZERO,
            period: Time::from_us(period),
            deadline: Time::from_us(period),
            deadline_follows_period: true,
            jitter: Time::from_us(jitter),
            sections: lock
                .map(|l| vec![("r".to_string(), Time::from_us(l))])
                .unwrap_or_default(),
            blocking: None,
            kind: TaskKind::Plain,
            released_by: None,
            sporadic: false,
            job_of: Some(name),
        };
    let mut tasks: Vec<TaskSpec> = above
        .iter()
        .enumerate()
        .map(|(i, &(priority, wcet, period, jitter, locks))| {
            task(
                format!("a{i}"),
                priority,
                wcet,
                period,
                jitter,
                locks.then_some(1),
            )
        })
        .collect();
    tasks.push(task(
        "lower".into(),
        2,
        section.max(1),
        40,
        0,
        (section > 0).then_some(section),
    ));
    tasks.push(task("client".into(), 1, 1, 1_000_000, 0, None));
    let part = |us: u64| {
        (us > 0).then(|| Part {
            time: Time::from_us(us),
            from: PerEventFrom::Estimate,
            source: "random".into(),
        })
    };
    BoardSystem {
        name: "engine".into(),
        overheads: OverheadTimes::default(),
        sensor_buses: BoardBuses {
            buses: vec![SensorBus {
                name: "i2c1".into(),
                bitrate: 400_000,
                bit_time: Time::from_ns(2500),
                engine_priority: ENGINE,
                per_event: Time::from_us(per_event),
                per_event_from: PerEventFrom::Estimate,
                source: "random".into(),
                per_script: part(per_script),
                condition_wait: part(wait),
            }],
            scripts: vec![Script {
                task: tasks.len() - 1,
                bus: 0,
                wire: Time::from_us(wire),
                stretch: Time::ZERO,
                events,
                starts,
                engine_row: usize::MAX,
                position: 0,
                of: 1,
                settle: Time::ZERO,
            }],
        },
        tasks,
        idle_sections: Vec::new(),
        can_tx_task: None,
        static_ceilings: Vec::new(),
    }
}

/// The script as the engine runs it: from its first START, a stretch of wire (the first, returned apart: the job's
/// release after its arrival, the START, since the wire runs whether the CPU is free or not), an event's handler at
/// the engine's priority, and so on to its ending event (the first `starts` events with the condition wait, the
/// last with the per-script part and the wait); the wire split at random among the gaps.
fn script_pieces(engine: Engine, rng: &mut Lcg) -> (u64, Vec<Piece>) {
    let (per_event, wait, per_script, events, starts, wire, _) = engine;
    let n = u64::from(events);
    let mut left = wire * US;
    let mut first = 0;
    let mut pieces = Vec::new();
    for e in 0..n {
        let gap = if e + 1 == n { left } else { rng.split(left) };
        left -= gap;
        if e == 0 {
            first = gap;
        } else if gap > 0 {
            pieces.push(Piece::Settle(gap));
        }
        let cost = if e + 1 == n {
            per_event + per_script + wait
        } else if e < u64::from(starts) {
            per_event + wait
        } else {
            per_event
        };
        pieces.push(cpu(cost * US, false));
    }
    (first, pieces)
}

/// Simulates the engine running scripts (each from its first START) among random jobs of the tasks at or above
/// it and the task below it; every script's time from its START to its end against the analysed bus time. Returns
/// how many scripts were checked (0 when the analysis left the client unbounded).
fn check_script(above: &[Above], engine: Engine, seed: u64) -> Result<usize, String> {
    let board = script_board(above, engine);
    let result = analysis::analyse_board(&board, &Limits::default());
    let client = board.tasks.len() - 1;
    if result.tasks[client].wcrt().is_none() {
        return Ok(0);
    }
    let bound = result.sensor_buses[0].scripts[0].bus_time.as_ns();
    let mut rng = Lcg(seed);
    let mut jobs = Vec::new();
    let horizon = 30 * bound.max(1000 * US);
    let lower = above.len();
    for (t, spec) in board.tasks.iter().enumerate().take(lower + 1) {
        let period = spec.period.as_ns();
        let mut arrival = rng.below(period / US) * US;
        let mut last = 0;
        while arrival <= horizon {
            let release = (arrival + rng.below(spec.jitter.as_ns() / US + 1) * US).max(last);
            last = release;
            let locks = !spec.sections.is_empty();
            let pieces = if t == lower {
                vec![cpu(spec.wcet.as_ns(), locks)]
            } else if locks {
                vec![cpu(US, true), cpu(spec.wcet.as_ns() - US, false)]
            } else {
                vec![cpu(spec.wcet.as_ns(), false)]
            };
            jobs.push(SuspendingJob {
                task: t,
                arrival,
                release,
                pieces,
            });
            arrival += period
                + if rng.below(3) == 0 {
                    rng.below(period / US) * US
                } else {
                    0
                };
        }
    }
    // The engine's scripts, each started after the previous one's bound has passed (the bus runs one at a time).
    let engine_task = lower + 1;
    let mut start = rng.below(bound / US + 1) * US;
    let mut scripts = 0;
    while start <= horizon {
        let (first, pieces) = script_pieces(engine, &mut rng);
        jobs.push(SuspendingJob {
            task: engine_task,
            arrival: start,
            release: start + first,
            pieces,
        });
        scripts += 1;
        start += bound + rng.below(bound / US + 1) * US;
    }
    let mut priorities: Vec<u32> = board
        .tasks
        .iter()
        .take(lower + 1)
        .map(|t| t.priority)
        .collect();
    priorities.push(ENGINE);
    let serial: Vec<usize> = (0..priorities.len()).collect();
    let ceiling = board
        .tasks
        .iter()
        .filter(|t| !t.sections.is_empty())
        .map(|t| t.priority)
        .max()
        .unwrap_or(0);
    let responses = sim::suspending_run(&priorities, &serial, &[ceiling], &jobs);
    for (job, r) in jobs.iter().zip(responses) {
        if job.task == engine_task && r > bound {
            return Err(format!(
                "script at {}: simulated {} > analysed bus time {}",
                job.arrival, r, bound
            ));
        }
    }
    Ok(scripts)
}

fn above_the_engine() -> impl Strategy<Value = Vec<Above>> {
    prop::collection::vec(
        (ENGINE..=7, 1u64..=20, 40u64..=400, 0u64..=30, any::<bool>()).prop_map(
            |(priority, wcet, period, jitter, locks)| {
                (priority, wcet.min(period / 8).max(1), period, jitter, locks)
            },
        ),
        0..=3,
    )
}

fn engine_figures() -> impl Strategy<Value = Engine> {
    (
        1u64..=10,
        0u64..=6,
        0u64..=13,
        1u32..=24,
        1u32..=4,
        10u64..=600,
        0u64..=8,
    )
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 300, ..ProptestConfig::default() })]

    /// A script's bus time (the lower of its events' own responses and the script as one job) is never below what
    /// the engine, simulated among the tasks at or above it and a lower critical section, takes.
    #[test]
    fn a_scripts_simulated_bus_time_never_exceeds_its_bound(
        above in above_the_engine(),
        engine in engine_figures(),
        seed in any::<u64>(),
    ) {
        let checked = check_script(&above, engine, seed);
        prop_assert!(checked.is_ok(), "{}", checked.unwrap_err());
    }
}

/// The property above is not vacuous: on a fixed sweep most scripts are bounded and checked, and the bound as one
/// job is the one taken in many (below the events' own responses, which are at least `events × R_event`).
#[test]
fn the_scripts_bound_as_one_job_is_often_the_one_taken() {
    let mut rng = Lcg(0xb05);
    let (mut checked, mut taken, mut cases) = (0, 0, 0);
    for case in 0..200 {
        let above: Vec<Above> = (0..rng.below(4))
            .map(|_| {
                let period = 40 + rng.below(361);
                (
                    ENGINE + rng.below(3) as u32,
                    (1 + rng.below(20)).min(period / 8).max(1),
                    period,
                    rng.below(31),
                    rng.below(2) == 0,
                )
            })
            .collect();
        let engine: Engine = (
            1 + rng.below(10),
            rng.below(7),
            rng.below(14),
            1 + rng.below(24) as u32,
            1 + rng.below(4) as u32,
            10 + rng.below(591),
            rng.below(9),
        );
        let scripts = check_script(&above, engine, case).expect("within the bound");
        if scripts > 0 {
            cases += 1;
            checked += scripts;
            let board = script_board(&above, engine);
            let result = analysis::analyse_board(&board, &Limits::default());
            let bus = &result.sensor_buses[0];
            let floor = Time::from_us(engine.5).plus(
                bus.event_response
                    .expect("bounded")
                    .times(u64::from(engine.3)),
            );
            if bus.scripts[0].bus_time < floor {
                taken += 1;
            }
        }
    }
    assert!(cases > 150, "{cases} sets bounded");
    assert!(checked > 3_000, "{checked} scripts simulated");
    assert!(taken > 50, "the bound as one job taken in {taken} sets");
}
