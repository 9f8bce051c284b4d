//! Small examples whose answers are known from the response-time-analysis literature, worked by hand in the
//! comments so a reader can check them without the papers.

use schedule_analysis::analysis;
use schedule_analysis::board::{self, CriticalSection, TaskTiming};
use schedule_analysis::busy_window::{Counter, Limits};
use schedule_analysis::can::{self, FrameCost, MessageTiming};
use schedule_analysis::model::{BoardSystem, OverheadTimes, TaskKind, TaskSpec};
use schedule_analysis::sensor_bus::{BoardBuses, PerEventFrom, Script, SensorBus};
use schedule_analysis::time::Time;

mod sim;

use sim::{Piece, Segment, SuspendingJob};

fn task(priority: u32, wcet: u64, period: u64) -> TaskTiming {
    TaskTiming {
        priority,
        wcet: Time::from_us(wcet),
        period: Time::from_us(period),
        jitter: Time::ZERO,
    }
}

fn wcrts(tasks: &[TaskTiming], blocking: &[u64]) -> Vec<u64> {
    let mut scratch = vec![Counter::default(); tasks.len()];
    (0..tasks.len())
        .map(|i| {
            let b = Time::from_us(blocking.get(i).copied().unwrap_or(0));
            let r = board::response_time(tasks, i, b, &Limits::default(), &mut scratch);
            r.map(|r| r.wcrt.as_ns() / 1000).unwrap_or(u64::MAX)
        })
        .collect()
}

/// Joseph & Pandya (1986) / Audsley et al. (1993), the textbook set (Burns & Wellings): a (T 7, C 3),
/// b (T 12, C 3), c (T 20, C 5). For c: 5 → 11 → 14 → 17 → 20 → 20.
#[test]
fn joseph_pandya_audsley_textbook_set() {
    let tasks = [task(3, 3, 7), task(2, 3, 12), task(1, 5, 20)];
    assert_eq!(wcrts(&tasks, &[]), vec![3, 6, 20]);
}

/// Lehoczky (1990): τ1 (C 26, T 70), τ2 (C 62, T 100), U = 0.991. The level-2 busy period is 694 long and holds
/// seven jobs of τ2 with responses 114, 102, 116, 104, 118, 106, 94: the worst is the fifth job, and it exceeds
/// the period — the first job alone would say 114.
#[test]
fn lehoczky_deadline_beyond_period() {
    let tasks = [task(2, 26, 70), task(1, 62, 100)];
    let mut scratch = vec![Counter::default(); 2];
    let r = board::response_time(&tasks, 1, Time::ZERO, &Limits::default(), &mut scratch)
        .expect("bounded");
    assert_eq!(r.wcrt, Time::from_us(118));
    assert_eq!(r.worst_instance, 4);
    assert_eq!(r.instances, 7);
    assert_eq!(r.busy_window, Time::from_us(694));
}

/// Release jitter (Audsley, Burns, Richardson, Tindell, Wellings 1993): with J the interference term becomes
/// ⌈(w + J_j)/T_j⌉ and the response is measured from the nominal release (+ own J).
/// a (C 1, T 4, J 2) over b (C 2, T 10, J 3): w_b = 2 + ⌈(w+2)/4⌉·1 → 2 → 3 → 4 → 4; R_b = 4 + 3 = 7.
#[test]
fn jitter_terms() {
    let tasks = [
        TaskTiming {
            priority: 2,
            wcet: Time::from_us(1),
            period: Time::from_us(4),
            jitter: Time::from_us(2),
        },
        TaskTiming {
            priority: 1,
            wcet: Time::from_us(2),
            period: Time::from_us(10),
            jitter: Time::from_us(3),
        },
    ];
    assert_eq!(wcrts(&tasks, &[]), vec![3, 7]);
}

/// SRP (Baker 1991) blocking: resource S used by H (prio 3) and L (prio 1), ceiling 3; resource T used by M
/// (prio 2) and L, ceiling 2. H is blocked by L's 4 µs section on S; M by max(L on S 4, L on T 2) = 4; L by none.
/// H (C 2, T 20): R = 2 + 4 = 6. M (C 3, T 30): w = 4 + 3 + 2 = 9. L (C 6, T 60): 6 + 2 + 3 = 11, then
/// ⌈11/20⌉ = 1: 11.
#[test]
fn stack_resource_policy_blocking() {
    let tasks = [task(3, 2, 20), task(2, 3, 30), task(1, 6, 60)];
    let ceiling_s = board::resource_ceiling([3, 1]);
    let ceiling_t = board::resource_ceiling([2, 1]);
    let sections = [
        CriticalSection {
            holder_priority: 3,
            ceiling: ceiling_s,
            length: Time::from_us(1),
        },
        CriticalSection {
            holder_priority: 1,
            ceiling: ceiling_s,
            length: Time::from_us(4),
        },
        CriticalSection {
            holder_priority: 2,
            ceiling: ceiling_t,
            length: Time::from_us(1),
        },
        CriticalSection {
            holder_priority: 1,
            ceiling: ceiling_t,
            length: Time::from_us(2),
        },
    ];
    let blocking: Vec<u64> = tasks
        .iter()
        .map(|t| board::srp_blocking(t.priority, &sections).as_ns() / 1000)
        .collect();
    assert_eq!(blocking, vec![4, 4, 0]);
    assert_eq!(wcrts(&tasks, &blocking), vec![6, 9, 11]);
}

/// The three-message example of Davis, Burns, Bril and Lukkien (2007), at 125 kbit/s with 1 ms per frame:
/// A (T 2.5 ms), B (T 3.5 ms, D 3.25 ms), C (T 3.5 ms, D 3.25 ms), priorities A > B > C.
///
/// The original analysis (Tindell et al. 1994) examines only C's first instance: w = ⌈(w+τ)/2.5⌉ + ⌈(w+τ)/3.5⌉
/// = 2 ms, R = 3 ms ≤ 3.25: "schedulable". But C's busy period is 7 ms long and holds two instances; the second
/// waits behind A at 2.5 and 5 and behind B at 3.5: w = 6 ms, R = 6 + 1 − 3.5 = 3.5 ms > 3.25. The revised
/// analysis finds it, and so does the simulator.
#[test]
fn davis_2007_refutation_example() {
    let bit = can::bit_time(125_000);
    let frame = can::frame_time(FrameCost::Fixed(Time::from_us(1000)), 8, false, bit);
    let m = |id: u32, period_us: u64| MessageTiming {
        key: can::arbitration_key(id, false),
        frame_time: frame,
        frames: 1,
        period: Time::from_us(period_us),
        jitter: Time::ZERO,
    };
    let set = [m(1, 2500), m(2, 3500), m(3, 3500)];
    let mut scratch = vec![Counter::default(); 3];
    let revised: Vec<_> = (0..3)
        .map(|i| {
            let b = can::blocking(&set, i);
            can::response_time(&set, i, b, bit, &Limits::default(), &mut scratch).expect("bounded")
        })
        .collect();
    assert_eq!(revised[0].wcrt, Time::from_us(2000));
    assert_eq!(revised[1].wcrt, Time::from_us(3000));
    assert_eq!(revised[2].wcrt, Time::from_us(3500));
    assert_eq!(revised[2].instances, 2);
    assert_eq!(revised[2].worst_instance, 1);
    let deadline_c = Time::from_us(3250);
    assert!(
        revised[2].wcrt > deadline_c,
        "the revised analysis must catch the miss"
    );

    // The original, flawed test: first instance only.
    let original_c = {
        let hp = &set[..2];
        let mut w = 0u64;
        loop {
            let next: u64 = hp
                .iter()
                .map(|k| (w + bit.as_ns()).div_ceil(k.period.as_ns()) * k.frame_time.as_ns())
                .sum();
            if next == w {
                break w + frame.as_ns();
            }
            w = next;
        }
    };
    assert_eq!(original_c, 3_000_000, "the original analysis says 3 ms");
    assert!(
        Time::from_ns(original_c) <= deadline_c,
        "...and wrongly passes C"
    );

    // The simulator, with all three queued at 0, sees C's second instance finish at 7 ms: 3.5 ms after it queued.
    let sim_set: Vec<sim::SimMessage> = set
        .iter()
        .map(|m| sim::SimMessage {
            key: m.key,
            frame_time: m.frame_time.as_ns(),
            frames: 1,
            period: m.period.as_ns(),
            jitter: 0,
        })
        .collect();
    let worst = sim::can_synchronous_worst(&sim_set, 20_000_000);
    assert_eq!(worst[2], 3_500_000);
}

/// The bus with the thesis's 545 µs per frame: three messages at 1 kHz cannot fit (3 × 545 > 1000 µs), and the
/// report must say unbounded rather than loop.
#[test]
fn thesis_cost_overload_is_unbounded() {
    let bit = can::bit_time(1_000_000);
    let frame = can::frame_time(FrameCost::Thesis, 6, false, bit);
    let set: Vec<MessageTiming> = (0..3)
        .map(|i| MessageTiming {
            key: can::arbitration_key(0x600 + i, false),
            frame_time: frame,
            frames: 1,
            period: Time::from_us(1000),
            jitter: Time::ZERO,
        })
        .collect();
    let mut scratch = vec![Counter::default(); 3];
    let last = can::response_time(&set, 2, Time::ZERO, bit, &Limits::default(), &mut scratch);
    assert!(last.is_err_and(|e| e.is_unbounded()));
    let first = can::response_time(
        &set,
        0,
        can::blocking(&set, 0),
        bit,
        &Limits::default(),
        &mut scratch,
    );
    assert_eq!(
        first.map(|r| r.wcrt),
        Ok(Time::from_us(1090)),
        "blocking 545 + own 545"
    );
}

/// A board task for the self-suspension examples: CPU `wcet` µs, no overheads, released periodically.
fn board_task(name: &str, priority: u32, wcet: u64, period: u64) -> TaskSpec {
    TaskSpec {
        name: name.into(),
        priority,
        wcet: Time::from_us(wcet),
        bcet: Time::ZERO,
        period: Time::from_us(period),
        deadline: Time::from_us(period),
        deadline_follows_period: true,
        jitter: Time::ZERO,
        sections: Vec::new(),
        blocking: None,
        kind: TaskKind::Plain,
        released_by: None,
        sporadic: false,
        job_of: None,
    }
}

/// A board whose tasks `scripts` (task, bus time µs) run scripts on one bus whose engine costs nothing (no
/// engine rows: the examples isolate the suspension and the bus).
fn suspending_board(tasks: Vec<TaskSpec>, scripts: &[(usize, u64)]) -> BoardSystem {
    BoardSystem {
        name: "b".into(),
        overheads: OverheadTimes::default(),
        tasks,
        idle_sections: Vec::new(),
        can_tx_task: None,
        static_ceilings: Vec::new(),
        sensor_buses: BoardBuses {
            buses: vec![SensorBus {
                name: "i2c1".into(),
                bitrate: 400_000,
                bit_time: Time::from_ns(2500),
                engine_priority: 10,
                per_event: Time::ZERO,
                per_event_from: PerEventFrom::Estimate,
                source: "none: the examples have no engine".into(),
                per_script: None,
                condition_wait: None,
            }],
            scripts: scripts
                .iter()
                .map(|&(task, us)| Script {
                    task,
                    bus: 0,
                    wire: Time::from_us(us),
                    stretch: Time::ZERO,
                    events: 0,
                    starts: 0,
                    engine_row: usize::MAX,
                    position: 0,
                    of: 1,
                    settle: Time::ZERO,
                })
                .collect(),
        },
    }
}

fn board_wcrts_us(board: &BoardSystem) -> Vec<Option<u64>> {
    let result = analysis::analyse_board(board, &Limits::default());
    result
        .tasks
        .iter()
        .map(|t| t.wcrt().map(|r| r.as_ns() / 1000))
        .collect()
}

/// A self-suspending task over a plain one: counting the suspending task as its CPU with no jitter is unsound.
/// τ1 (priority 2): CPU 2 µs, a 6 µs script, T 10 µs. τ2 (priority 1): CPU 4 µs, T 100 µs.
///
/// The naive charge: R2 = 4 + ⌈R2/10⌉·2 → 6. The simulator finds 8: τ1's first job runs none of its CPU before
/// its script (the bus 0..6) and all 2 µs after it (6..8); τ2, released at 6, waits; it runs 8..10; τ1's next
/// job runs its 2 µs at once (10..12) and ends without its script this time (a job may be shorter); τ2 runs
/// 12..14: response 14 − 6 = 8.
///
/// The analysis: R1 = 2 + 6 = 8 (suspension-oblivious for itself; its script alone on the bus: 6), and τ1 seen by
/// τ2 as 2 µs released with jitter R1 − C1 = 6: R2 = 4 + ⌈(R2 + 6)/10⌉·2 → 6 → 8 → 8. It covers the 8.
#[test]
fn a_suspending_task_interferes_with_its_response_minus_its_cpu_as_jitter() {
    let cpu = |length_us: u64| {
        Piece::Cpu(Segment {
            length: length_us * 1000,
            lock: None,
        })
    };
    let jobs = vec![
        SuspendingJob {
            task: 0,
            arrival: 0,
            release: 0,
            pieces: vec![cpu(0), Piece::Script(6000), cpu(2)],
        },
        SuspendingJob {
            task: 0,
            arrival: 10_000,
            release: 10_000,
            pieces: vec![cpu(2)],
        },
        SuspendingJob {
            task: 1,
            arrival: 6000,
            release: 6000,
            pieces: vec![cpu(4)],
        },
    ];
    let simulated = sim::suspending_run(&[2, 1], &[0, 1], &[], &jobs);
    assert_eq!(simulated, vec![8000, 2000, 8000]);

    let naive = wcrts(&[task(2, 2, 10), task(1, 4, 100)], &[]);
    assert_eq!(naive, vec![2, 6]);
    assert!(simulated[2] > naive[1] * 1000, "the naive charge misses it");

    let board = suspending_board(
        vec![board_task("t1", 2, 2, 10), board_task("t2", 1, 4, 100)],
        &[(0, 6)],
    );
    assert_eq!(board_wcrts_us(&board), vec![Some(8), Some(8)]);
    let result = analysis::analyse_board(&board, &Limits::default());
    assert_eq!(result.tasks[1].jitter, Time::ZERO, "τ2's own jitter");
    let bus = &result.sensor_buses[0];
    assert_eq!(bus.scripts[0].suspension, Some(Time::from_us(6)));
}

/// Three scripts on one bus, each from its own task: A (priority 3, CPU 10, script 100, T 1000), B (2, 10, 200,
/// 2000), C (1, 10, 300, 5000), all µs. A script's blocking is the longest lower one (A, B: 300; C: 0), its
/// jitter its job's response, its suspension the bus response minus that jitter.
///
/// Round 1 (jitters 0). Bus: A 300 + 100 = 400; B: w = 300 + ⌈(w + 0+)/1000⌉·100 = 400, + 200 = 600;
/// C: w = ⌈(w+)/1000⌉·100 + ⌈(w+)/2000⌉·200 = 300, + 300 = 600. CPU (suspension-oblivious for the job itself,
/// the others at their CPU with jitter response − CPU, still 0): A 10 + 400 = 410; B 610 + ⌈R/1000⌉·10 = 620;
/// C 610 + 10 + 10 = 630.
///
/// Round 2 (jitters 410, 620, 630). Bus: A 410 + 300 + 100 = 810; B: w = 300 + ⌈(w + 410+)/1000⌉·100 = 400,
/// 620 + 400 + 200 = 1220; C: w = ⌈(w + 410+)/1000⌉·100 + ⌈(w + 620+)/2000⌉·200 = 300, 630 + 300 + 300 = 1230:
/// suspensions 400, 600, 600 as before. CPU: A 410; B = 610 + ⌈(R + 400)/1000⌉·10 = 630 (two of A's CPU bursts
/// now fit); C = 610 + ⌈(R + 400)/1000⌉·10 + ⌈(R + 610)/2000⌉·10 = 640.
///
/// Round 3 (jitters 410, 630, 640): the bus responses 810, 1230, 1240, the suspensions unchanged, and the CPU
/// responses 410, 630, 640 again: the fixed point.
#[test]
fn three_scripts_on_one_bus_worked_by_hand() {
    let board = suspending_board(
        vec![
            board_task("a", 3, 10, 1000),
            board_task("b", 2, 10, 2000),
            board_task("c", 1, 10, 5000),
        ],
        &[(0, 100), (1, 200), (2, 300)],
    );
    let result = analysis::analyse_board(&board, &Limits::default());
    let wcrt = |i: usize| result.tasks[i].wcrt().map(|r| r.as_ns() / 1000);
    assert_eq!(
        [wcrt(0), wcrt(1), wcrt(2)],
        [Some(410), Some(630), Some(640)]
    );
    let bus = &result.sensor_buses[0];
    let us = |t: Time| t.as_ns() / 1000;
    let scripts: Vec<(String, u64, u64, u64, u64)> = bus
        .scripts
        .iter()
        .map(|s| {
            (
                s.task.clone(),
                us(s.blocking),
                us(s.jitter),
                s.bound.as_ref().map_or(u64::MAX, |r| us(r.wcrt)),
                s.suspension.map_or(u64::MAX, us),
            )
        })
        .collect();
    assert_eq!(
        scripts,
        vec![
            ("a".into(), 300, 410, 810, 400),
            ("b".into(), 300, 630, 1230, 600),
            ("c".into(), 0, 640, 1240, 600),
        ]
    );
    // The bus's share: 100/1000 + 200/2000 + 300/5000.
    assert!((bus.utilisation - 0.26).abs() < 1e-9);
}

/// A suspending job is blocked again when it resumes: a lower task may lock a resource while it is suspended.
/// τs (priority 3): CPU 2 µs (1 before, 1 after its script), a 5 µs script, T 100; τl and τm (priorities 1 and 2):
/// 4 µs each, all of it holding `r`, whose ceiling is 3.
///
/// The simulator: τl locks `r` at 0; τs arrives at 0.5 and waits until 4, runs 4..5, its script 5..10; τm arrives
/// at 9.5 (the CPU is idle) and locks `r` until 13.5; τs, ready at 10, waits for it and runs 13.5..14.5: response
/// 14. Charging one blocking, as for a job that never suspends, gives 2 + 5 + 4 = 11; the analysis charges a
/// second one for the resumption: 15.
#[test]
fn a_suspending_job_is_blocked_again_when_it_resumes() {
    let locked = |length: u64| {
        Piece::Cpu(Segment {
            length,
            lock: Some(0),
        })
    };
    let free = |length: u64| Piece::Cpu(Segment { length, lock: None });
    let job = |task, arrival, pieces| SuspendingJob {
        task,
        arrival,
        release: arrival,
        pieces,
    };
    let jobs = vec![
        job(0, 500, vec![free(1000), Piece::Script(5000), free(1000)]),
        job(1, 0, vec![locked(4000)]),
        job(2, 9500, vec![locked(4000)]),
    ];
    let simulated = sim::suspending_run(&[3, 1, 2], &[0, 1, 2], &[3], &jobs);
    assert_eq!(simulated[0], 14_000);

    let with_section = |mut t: TaskSpec| {
        t.sections = vec![("r".into(), t.wcet)];
        t
    };
    let mut board = suspending_board(
        vec![
            board_task("s", 3, 2, 100),
            with_section(board_task("l", 1, 4, 100)),
            with_section(board_task("m", 2, 4, 100)),
        ],
        &[(0, 5)],
    );
    board.static_ceilings = vec![("r".into(), 3)];
    let result = analysis::analyse_board(&board, &Limits::default());
    assert_eq!(result.tasks[0].blocking, Time::from_us(4));
    assert_eq!(result.tasks[0].wcrt(), Some(Time::from_us(15)));
    assert!(simulated[0] > 11_000, "one blocking would miss it");
}

/// A board with `buses` sensor buses whose engines cost nothing, and jobs of several scripts: per script (task,
/// bus, bus time µs, settle µs), in each task's order.
fn several_scripts_board(
    tasks: Vec<TaskSpec>,
    buses: usize,
    scripts: &[(usize, usize, u64, u64)],
) -> BoardSystem {
    let mut board = suspending_board(tasks, &[]);
    let bus = board.sensor_buses.buses[0].clone();
    board.sensor_buses.buses = (0..buses)
        .map(|b| SensorBus {
            name: format!("i2c{}", b + 1),
            ..bus.clone()
        })
        .collect();
    board.sensor_buses.scripts = scripts
        .iter()
        .map(|&(task, bus, us, settle)| Script {
            task,
            bus,
            wire: Time::from_us(us),
            stretch: Time::ZERO,
            events: 0,
            starts: 0,
            engine_row: usize::MAX,
            position: 0,
            of: scripts.iter().filter(|s| s.0 == task).count(),
            settle: Time::from_us(settle),
        })
        .collect();
    for (k, s) in board.sensor_buses.scripts.iter_mut().enumerate() {
        s.position = scripts[..k].iter().filter(|o| o.0 == s.task).count();
    }
    board
}

/// A script's figures as the hand-worked examples state them: (task, blocking, jitter, bus WCRT, suspension), µs.
type ScriptRow = (String, u64, u64, u64, u64);

/// A job of two scripts on two buses. τ1 (priority 2, CPU 10, T 1000) runs X on i2c1 (100) then Y on i2c2 (200);
/// τ2 (priority 1, CPU 10, T 2000) runs Z on i2c2 (300); all µs.
///
/// Round 1 (jitters 0). i2c1: X alone, 100. i2c2: Y blocked by Z, 300 + 200 = 500; Z: w = ⌈(w + 0+)/1000⌉·200 =
/// 200, + 300 = 500. τ1 = 10 + 100 + 500 = 610 (its suspensions, one per script, as execution); τ2 = 10 + 500 +
/// ⌈R/1000⌉·10 = 520.
///
/// Round 2 (jitters 610, 610, 520). X: 610 + 100, suspension 100. Y: 610 + 300 + 200 = 1110 (its level's busy
/// period, 700 = 300 + ⌈(700 + 610)/1000⌉·200, holds a second instance, whose response 610 + 500 − 1000 + 200 =
/// 310 is smaller): suspension 500. Z: w = ⌈(w + 610+)/1000⌉·200 = 200, 520 + 200 + 300 = 1020: suspension 500. τ1 = 610; τ2 sees
/// τ1's 10 µs with jitter 610 − 10 = 600: R = 510 + ⌈(R + 600)/1000⌉·10 = 530.
///
/// Round 3 (Z's jitter 530): Z's bus response 1030, every suspension and response unchanged: the fixed point.
/// The simulator's worst placement found below (Z on i2c2 first, τ1's CPU before its scripts) stays within.
#[test]
fn a_job_of_two_scripts_on_two_buses_worked_by_hand() {
    let board = several_scripts_board(
        vec![board_task("t1", 2, 10, 1000), board_task("t2", 1, 10, 2000)],
        2,
        &[(0, 0, 100, 0), (0, 1, 200, 0), (1, 1, 300, 0)],
    );
    let result = analysis::analyse_board(&board, &Limits::default());
    let us = |t: Time| t.as_ns() / 1000;
    assert_eq!(board_wcrts_us(&board), vec![Some(610), Some(530)]);
    let per_script: Vec<Vec<ScriptRow>> = result
        .sensor_buses
        .iter()
        .map(|bus| {
            bus.scripts
                .iter()
                .map(|s| {
                    (
                        s.task.clone(),
                        us(s.blocking),
                        us(s.jitter),
                        s.bound.as_ref().map_or(u64::MAX, |r| us(r.wcrt)),
                        s.suspension.map_or(u64::MAX, us),
                    )
                })
                .collect()
        })
        .collect();
    assert_eq!(
        per_script,
        vec![
            vec![("t1#1".into(), 0, 610, 710, 100)],
            vec![
                ("t1#2".into(), 300, 610, 1110, 500),
                ("t2".into(), 0, 530, 1030, 500)
            ],
        ]
    );

    let cpu = |length_us: u64| {
        Piece::Cpu(Segment {
            length: length_us * 1000,
            lock: None,
        })
    };
    let jobs = vec![
        SuspendingJob {
            task: 1,
            arrival: 0,
            release: 0,
            pieces: vec![cpu(0), Piece::ScriptOn(1, 300_000), cpu(10)],
        },
        SuspendingJob {
            task: 0,
            arrival: 1000,
            release: 1000,
            pieces: vec![
                cpu(10),
                Piece::ScriptOn(0, 100_000),
                Piece::ScriptOn(1, 200_000),
                cpu(0),
            ],
        },
    ];
    let simulated = sim::suspending_run(&[1, 2], &[1, 0], &[], &jobs);
    // τ1: CPU 1..11, X 11..111, Y waits for Z until 300, 300..500: 499 after its arrival. τ2: Z 0..300, CPU
    // 300..310 — τ1's CPU is done by then: 310.
    assert_eq!(simulated, vec![310_000, 499_000]);
    assert!(simulated[1] <= 610_000 && simulated[0] <= 530_000);
}

/// A job with settles: τ1 (priority 2, CPU 10, T 1000) runs two 100 µs scripts on one bus, each after a 66 µs
/// settle of its own (the bq27500's bus-free time); τ2 (priority 1, CPU 20, all of it holding `r`, ceiling 2;
/// T 1000) has no script. τ1's blocking: 20.
///
/// τ1's two scripts are siblings (one job, one after the other): neither interferes with the other on the bus,
/// so each one's suspension is its 100 µs. τ1 for itself: C + Σ (S + settle + 2 B) = 10 + 2 × (100 + 66 + 40) =
/// 422 (a resumption after each settle and after each script, each may meet τ2's section), plus its own
/// blocking 20: 442. τ2: 20 + ⌈(R + 442 − 10)/1000⌉·10 = 30.
///
/// The simulator (τ1's CPU 8 first, then 1 after each settle to submit the script): τ2 takes `r` at 70, in τ1's
/// first settle (8..74), and holds it until 90; τ1 runs 90..91, its script 91..191, its second settle 191..257;
/// τ2's next job takes `r` at 250 until 270; τ1 runs 270..271, its script 271..371: response 371 ≤ 442.
#[test]
fn a_job_with_settles_worked_by_hand() {
    let with_section = |mut t: TaskSpec| {
        t.sections = vec![("r".into(), t.wcet)];
        t
    };
    let mut board = several_scripts_board(
        vec![
            board_task("t1", 2, 10, 1000),
            with_section(board_task("t2", 1, 20, 1000)),
        ],
        1,
        &[(0, 0, 100, 66), (0, 0, 100, 66)],
    );
    board.static_ceilings = vec![("r".into(), 2)];
    let result = analysis::analyse_board(&board, &Limits::default());
    assert_eq!(result.tasks[0].blocking, Time::from_us(20));
    assert_eq!(board_wcrts_us(&board), vec![Some(442), Some(30)]);
    let suspensions: Vec<Option<Time>> = result.sensor_buses[0]
        .scripts
        .iter()
        .map(|s| s.suspension)
        .collect();
    assert_eq!(
        suspensions,
        vec![Some(Time::from_us(100)), Some(Time::from_us(100))]
    );

    let locked = |length_us: u64| {
        Piece::Cpu(Segment {
            length: length_us * 1000,
            lock: Some(0),
        })
    };
    let free = |length_us: u64| {
        Piece::Cpu(Segment {
            length: length_us * 1000,
            lock: None,
        })
    };
    let jobs = vec![
        SuspendingJob {
            task: 0,
            arrival: 0,
            release: 0,
            pieces: vec![
                free(8),
                Piece::Settle(66_000),
                free(1),
                Piece::Script(100_000),
                Piece::Settle(66_000),
                free(1),
                Piece::Script(100_000),
            ],
        },
        SuspendingJob {
            task: 1,
            arrival: 70_000,
            release: 70_000,
            pieces: vec![locked(20)],
        },
        SuspendingJob {
            task: 1,
            arrival: 250_000,
            release: 250_000,
            pieces: vec![locked(20)],
        },
    ];
    let simulated = sim::suspending_run(&[2, 1], &[0, 1], &[2], &jobs);
    assert_eq!(simulated[0], 371_000);
    assert!(simulated[0] <= 442_000);
}

/// Two jobs of one suspending RTIC task `g`: A (priority 2, CPU 1, an 8 µs script, T 20) and B (priority 2, CPU 4,
/// no script, T 20); L (priority 1, CPU 9, T 100); all µs.
///
/// B waits behind A's suspended job (one job of `g` at a time), so B too runs late and then early again: seen by L
/// it needs its own-view response minus its CPU as jitter, as A does. Own view of `g`: A = 1 + 8 + 4 (B) = 13, B =
/// 13. L: R = 9 + ⌈(R + 12)/20⌉·1 + ⌈(R + 9)/20⌉·4 → 14 → 19 → 19. With B's model jitter 0 (only the job with a
/// script given R − C) it was 15.
///
/// The simulator: A's first job suspends 0..8, runs 8..9; B's first job (released at 0) runs 9..13; L, arrived at
/// 8, runs 13..20; A's second job (no script this time) 20..21, B's 21..25; L 25..27: response 19.
#[test]
fn a_suspending_tasks_job_without_a_script_has_its_response_as_jitter_too() {
    let mut a = board_task("a", 2, 1, 20);
    a.job_of = Some("g".into());
    let mut b = board_task("b", 2, 4, 20);
    b.job_of = Some("g".into());
    let board = suspending_board(vec![a, b, board_task("l", 1, 9, 100)], &[(0, 8)]);
    let wcrts = board_wcrts_us(&board);
    assert_eq!(wcrts[2], Some(19));

    let cpu = |length_us: u64| {
        Piece::Cpu(Segment {
            length: length_us * 1000,
            lock: None,
        })
    };
    let jobs = vec![
        SuspendingJob {
            task: 0,
            arrival: 0,
            release: 0,
            pieces: vec![cpu(0), Piece::Script(8000), cpu(1)],
        },
        SuspendingJob {
            task: 1,
            arrival: 0,
            release: 0,
            pieces: vec![cpu(4)],
        },
        SuspendingJob {
            task: 2,
            arrival: 8000,
            release: 8000,
            pieces: vec![cpu(9)],
        },
        SuspendingJob {
            task: 0,
            arrival: 20_000,
            release: 20_000,
            pieces: vec![cpu(1)],
        },
        SuspendingJob {
            task: 1,
            arrival: 20_000,
            release: 20_000,
            pieces: vec![cpu(4)],
        },
    ];
    let simulated = sim::suspending_run(&[2, 2, 1], &[0, 0, 1], &[], &jobs);
    assert_eq!(simulated[2], 19_000);
    assert!(simulated
        .iter()
        .zip([0, 1, 2, 0, 1])
        .all(|(&s, i)| s <= wcrts[i].unwrap() * 1000));
}

/// A failure leaves no unconverged bound behind: τ1 (priority 3, CPU 2, a 6 µs script, T 10), τ2 (priority 2, CPU
/// 4, T 100), τ3 (priority 1, CPU 80, a 1 µs script, T 100; all µs). τ3 overloads, and the iteration stops at its
/// failure in the first round, τ1's response still 0 as τ2's jitter; τ2's bound from that round was 6 µs, while the simulator (τ1's
/// placement of [`a_suspending_task_interferes_with_its_response_minus_its_cpu_as_jitter`]) reaches 8. Only a task
/// above every suspending job and every engine keeps a bound: here none, each says why.
#[test]
fn a_failure_leaves_no_unconverged_bound_behind() {
    let board = suspending_board(
        vec![
            board_task("t1", 3, 2, 10),
            board_task("t2", 2, 4, 100),
            board_task("t3", 1, 80, 100),
        ],
        &[(0, 6), (2, 1)],
    );
    let result = analysis::analyse_board(&board, &Limits::default());
    assert!(result.tasks[2].wcrt().is_none(), "{:?}", result.tasks[2]);
    let why = result.tasks[1]
        .bound
        .as_ref()
        .expect_err("not a fixed point's");
    assert!(why.to_string().contains("t3"), "{why}");
    assert!(result.tasks[0].wcrt().is_none(), "{:?}", result.tasks[0]);

    let cpu = |length_us: u64| {
        Piece::Cpu(Segment {
            length: length_us * 1000,
            lock: None,
        })
    };
    let jobs = vec![
        SuspendingJob {
            task: 0,
            arrival: 0,
            release: 0,
            pieces: vec![cpu(0), Piece::Script(6000), cpu(2)],
        },
        SuspendingJob {
            task: 0,
            arrival: 10_000,
            release: 10_000,
            pieces: vec![cpu(2)],
        },
        SuspendingJob {
            task: 1,
            arrival: 6000,
            release: 6000,
            pieces: vec![cpu(4)],
        },
    ];
    let simulated = sim::suspending_run(&[3, 2, 1], &[0, 1, 2], &[], &jobs);
    assert_eq!(
        simulated[2], 8000,
        "above the 6 µs the failed round gave τ2"
    );
}

/// A script's bus time as one job, worked by hand. The engine at priority 5 takes 10 µs an event (no entry or exit
/// here); a script of 100 µs on the wire raises 4 events; `tick` (priority 6) runs 8 µs every 1 ms; the client
/// (priority 1) runs 1 µs.
///
/// Each event's own worst response: 10 + 8 = 18 µs (its window meets one `tick`), so the events' bound is
/// 100 + 4 × 18 = 172 µs: it counts the one `tick` four times. As one job at priority 5 (the wire executed too):
/// S = 100 + 4 × 10 + ⌈S/1000⌉·8 → 148 µs, the bound taken. The simulator reaches it: the script starts at 0 (the
/// engine's job arrives; the wire runs without the CPU), its first event arrives at 25 with `tick`, which runs
/// 25..33; the events run 33..43, 68..78, 103..113 and 138..148.
/// Without the interference term the bound would be 140 µs, below that. The client: 1 + 148 + `tick`'s 8 = 157 µs.
#[test]
fn a_scripts_bus_time_as_one_job_worked_by_hand() {
    let mut board = suspending_board(
        vec![
            board_task("tick", 6, 8, 1000),
            board_task("client", 1, 1, 100_000),
        ],
        &[(1, 100)],
    );
    board.sensor_buses.buses[0].engine_priority = 5;
    board.sensor_buses.buses[0].per_event = Time::from_us(10);
    board.sensor_buses.scripts[0].events = 4;
    let result = analysis::analyse_board(&board, &Limits::default());
    let bus = &result.sensor_buses[0];
    assert_eq!(bus.event_response, Some(Time::from_us(18)));
    assert_eq!(bus.scripts[0].bus_time, Time::from_us(148));
    assert_eq!(result.tasks[1].wcrt(), Some(Time::from_us(157)));

    let us = 1000;
    let event = Piece::Cpu(Segment {
        length: 10 * us,
        lock: None,
    });
    let wire = Piece::Settle(25 * us);
    let jobs = [
        SuspendingJob {
            task: 1,
            arrival: 0,
            release: 25 * us,
            pieces: vec![event, wire, event, wire, event, wire, event],
        },
        SuspendingJob {
            task: 0,
            arrival: 25 * us,
            release: 25 * us,
            pieces: vec![Piece::Cpu(Segment {
                length: 8 * us,
                lock: None,
            })],
        },
    ];
    let simulated = sim::suspending_run(&[6, 5], &[0, 1], &[], &jobs);
    assert_eq!(simulated[0], 148 * us);
    assert!(Time::from_ns(simulated[0]) <= bus.scripts[0].bus_time);
}

/// The suspending job by its CPU segments: H (priority 2) CPU 10 µs, T 50 µs; J (priority 1) CPU 20 µs, one 70 µs
/// script alone on its bus, T 120 µs.
///
/// Suspension-oblivious for itself, J costs 20 + 70 = 90 µs: R = 90 + ⌈R/50⌉·10 → 100 → 110 → 120 → 120 (H's
/// third job, released at 100 while J is on the bus, counted as if J waited for the CPU then).
///
/// By its segments: its CPU alone, one instance at its place, W = 20 + ⌈W/50⌉·10 = 30; one resumption (after the
/// script), so two segments, each at most its own CPU plus W − C = 10: R = 70 + 30 + 1 · 10 = 110 ≤ 120, its
/// period, so its previous job has ended when it is activated: the bound taken.
///
/// The simulator reaches the 110: H runs 0..10, J half its CPU 10..20, its script 20..90, H's next job (released
/// at 90, 90 µs after its first) 90..100 as J resumes, and J the rest of its CPU 100..110. Leaving out the second
/// segment's `W − C` (the interference a resumption meets) gives 100, below it.
#[test]
fn a_suspending_job_by_its_segments_worked_by_hand() {
    let cpu = |length_us: u64| {
        Piece::Cpu(Segment {
            length: length_us * 1000,
            lock: None,
        })
    };
    let h = |arrival: u64| SuspendingJob {
        task: 0,
        arrival,
        release: arrival,
        pieces: vec![cpu(10)],
    };
    let jobs = vec![
        h(0),
        h(90_000),
        SuspendingJob {
            task: 1,
            arrival: 0,
            release: 0,
            pieces: vec![cpu(10), Piece::Script(70_000), cpu(10)],
        },
    ];
    let simulated = sim::suspending_run(&[2, 1], &[0, 1], &[], &jobs);
    assert_eq!(simulated, vec![10_000, 10_000, 110_000]);

    let board = suspending_board(
        vec![board_task("h", 2, 10, 50), board_task("j", 1, 20, 120)],
        &[(1, 70)],
    );
    assert_eq!(board_wcrts_us(&board), vec![Some(10), Some(110)]);
    let result = analysis::analyse_board(&board, &Limits::default());
    assert_eq!(
        result.sensor_buses[0].scripts[0].suspension,
        Some(Time::from_us(70))
    );

    // Its period shorter than that bound (110 > 100): the segments' bound does not hold (its previous job may
    // not have ended), and suspension-oblivious it overloads (90/100 + 10/50 > 1): no bound.
    let board = suspending_board(
        vec![board_task("h", 2, 10, 50), board_task("j", 1, 20, 100)],
        &[(1, 70)],
    );
    assert_eq!(board_wcrts_us(&board), vec![Some(10), None]);
}

/// A suspending job released by a job that overloads in the suspending job's view: p (priority 2, CPU 20 µs, one
/// 170 µs script alone on its bus, T 400 µs), released by r's completion (priority 1, CPU 300 µs, T 400 µs).
///
/// In p's view it costs 20 + 170 = 190 µs and r overloads below it (190/400 + 300/400 > 1): r has no bound there,
/// so neither has the jitter p inherits from it, and no bound of p (by its segments either) may leave that jitter
/// out. Counting p's CPU alone with no jitter says 190 µs, yet p is ready only when r ends: the simulator, r
/// running 0..300, p 300..310, its script 310..480 and p's rest 480..490, finds 490 µs from p's activation, above
/// its 400 µs period and deadline. Neither has a bound.
#[test]
fn a_suspending_job_whose_releaser_overloads_in_its_view_has_no_bound() {
    let cpu = |length_us: u64| {
        Piece::Cpu(Segment {
            length: length_us * 1000,
            lock: None,
        })
    };
    let jobs = vec![
        SuspendingJob {
            task: 1,
            arrival: 0,
            release: 0,
            pieces: vec![cpu(300)],
        },
        SuspendingJob {
            task: 0,
            arrival: 0,
            release: 300_000,
            pieces: vec![cpu(10), Piece::Script(170_000), cpu(10)],
        },
    ];
    let simulated = sim::suspending_run(&[2, 1], &[0, 1], &[], &jobs);
    assert_eq!(simulated, vec![300_000, 490_000]);

    let mut p = board_task("p", 2, 20, 400);
    p.released_by = Some(1);
    let board = suspending_board(vec![p, board_task("r", 1, 300, 400)], &[(0, 170)]);
    assert_eq!(board_wcrts_us(&board), vec![None, None]);
}

/// A suspending job released by another: a (priority 3, CPU 10 µs, a 50 µs script, T 1000 µs) releases b (2, CPU
/// 10 µs, a 300 µs script, T 1000 µs); l (1, CPU 380 µs, T 1000 µs) has no script.
///
/// a's script waits for b's (non-preemptive): 350 µs, a 360 µs. b's release jitter is a's 360 µs; in its own view
/// it responds in 730 µs from its activation, so its CPU may run anywhere up to 720 µs after it: seen by l, b is
/// 10 µs with jitter 720 (R − C), not the 360 of its release alone. l = 380 + 10 (a, jitter 350) + 2 · 10 (b: the
/// window of 410 µs and the 720 µs jitter reach its second job) = 410 µs. Stating b's 360 µs release jitter as its
/// own instead of the release gives l the same 410 µs.
#[test]
fn a_job_released_by_a_suspending_job_counts_its_own_suspensions() {
    let mut b = board_task("b", 2, 10, 1000);
    b.released_by = Some(0);
    let board = suspending_board(
        vec![
            board_task("a", 3, 10, 1000),
            b,
            board_task("l", 1, 380, 1000),
        ],
        &[(0, 50), (1, 300)],
    );
    assert_eq!(
        board_wcrts_us(&board),
        vec![Some(360), Some(730), Some(410)]
    );
    let mut board = board;
    board.tasks[1].released_by = None;
    board.tasks[1].jitter = Time::from_us(360);
    assert_eq!(
        board_wcrts_us(&board),
        vec![Some(360), Some(730), Some(410)]
    );
}

/// A job above a suspending one, released by a job below it: X (priority 3, CPU 10 µs, T 100 µs) released by R (1,
/// 60 µs, T 100 µs); p (2, CPU 20 µs, one 170 µs script, T 400 µs).
///
/// In the default view R responds in 100 µs, so X's release jitter is 100 µs. In p's view (p costing 190 µs) R
/// overloads below it, yet X above p still comes with that jitter: p = 20 + 170 + ⌈(W + 100)/100⌉ · 10 → 230 µs,
/// as with X's 100 µs stated as its own jitter; its jitter 0 there (R's bound in p's view, none) would give 210.
#[test]
fn a_job_released_across_a_suspending_one_keeps_its_jitter_in_its_view() {
    let mut x = board_task("x", 3, 10, 100);
    x.released_by = Some(1);
    let board = suspending_board(
        vec![x, board_task("r", 1, 60, 100), board_task("p", 2, 20, 400)],
        &[(2, 170)],
    );
    let result = analysis::analyse_board(&board, &Limits::default());
    assert_eq!(
        result.tasks[0].jitter,
        Time::from_us(100),
        "x's inherited jitter"
    );
    let with_release = board_wcrts_us(&board);
    let mut board = board;
    board.tasks[0].released_by = None;
    board.tasks[0].jitter = Time::from_us(100);
    let stated = board_wcrts_us(&board);
    assert_eq!(stated[2], Some(230));
    assert_eq!(with_release[2], stated[2]);
}

/// A script without a bound in the first round: h (priority 3, CPU 10 µs, T 100 µs) above p (2, CPU 10 µs, a
/// 150 µs script, T 100 µs: the bus overloads). p and every job not above it have no bound; h, above every
/// suspending job, keeps its own: 10 µs.
#[test]
fn a_script_without_a_bound_in_the_first_round_leaves_the_jobs_above_bounded() {
    let board = suspending_board(
        vec![
            board_task("h", 3, 10, 100),
            board_task("p", 2, 10, 100),
            board_task("l", 1, 10, 1000),
        ],
        &[(1, 150)],
    );
    assert_eq!(board_wcrts_us(&board), vec![Some(10), None, None]);
}

/// `a_suspending_job_by_its_segments_worked_by_hand`'s J with a release jitter of 5 µs of its own: by its segments
/// 5 + 70 + 30 + 10 = 115 µs, the jitter once (one instance's window from its release does not depend on it; with
/// the jitter in `W` and so in each `W − C` it counts twice: 70 + 35 + 15 = 120).
#[test]
fn a_suspending_jobs_segments_count_its_jitter_once() {
    let mut j = board_task("j", 1, 20, 120);
    j.jitter = Time::from_us(5);
    let board = suspending_board(vec![board_task("h", 2, 10, 50), j], &[(1, 70)]);
    assert_eq!(board_wcrts_us(&board), vec![Some(10), Some(115)]);
}

/// A release chain whose head overloads: a (priority 1, 20 ms every 10 ms) has no bound, so neither has b
/// (priority 3), which a releases, nor c (priority 5), which b releases. c is analysed before b (the more urgent
/// first), so it read b's bound of the round before b lost it; the chain is followed to its end after the last round.
/// Host and chip share this code (`board_analysis`).
#[test]
fn a_job_released_down_a_chain_from_an_overloaded_job_has_no_bound() {
    let mut c = board_task("c", 5, 10, 10_000);
    c.released_by = Some(1);
    let mut b = board_task("b", 3, 10, 10_000);
    b.released_by = Some(2);
    let a = board_task("a", 1, 20_000, 10_000);
    let board = suspending_board(vec![c, b, a], &[]);
    assert_eq!(board_wcrts_us(&board), vec![None, None, None]);
}

/// A model file's system, validated, with `exact` frame costs and the default horizon.
fn exact_system(
    model: &serde_json::Value,
) -> (schedule_analysis::model::System, analysis::Options) {
    let system = schedule_analysis::model::Model::from_json(&model.to_string())
        .expect("parses")
        .validate()
        .expect("valid");
    let options = analysis::Options {
        frame_cost: schedule_analysis::model::FrameCostSpec::Exact,
        horizon: None,
    };
    (system, options)
}

/// The task `name` of a one-board report.
fn only_board_task<'a>(report: &'a analysis::Analysis, name: &str) -> &'a analysis::TaskResult {
    report.boards[0]
        .tasks
        .iter()
        .find(|t| t.name == name)
        .unwrap_or_else(|| panic!("{name}"))
}

/// A frame that needs a mailbox abort whose victim is on the bus (docs/analysis.md, *Why the bounds are safe*, "A
/// frame that needs an abort", and "The sound transmit path: the design"), and the transmit job its publisher
/// releases, worked by hand at 1 Mbit/s, `exact`:
///
/// One board: `can_tx` (its transmit interrupt, priority 3, 20 µs, at least 100 µs apart), its job
/// `can_tx[data]` (priority 3, 10 µs, released by the publisher with the abort latency of its own,
/// `can::transmit_abort_latency` = three 135 µs frames = 405 µs), and the publisher (priority 1, 100 µs, best
/// 50 µs, every 10 ms). On the bus its frame `data` (0x100, 8 bytes, 135 µs) and a command stream `other` (0x200,
/// 8 bytes, from outside).
///
/// * `can_tx`: 20 + its job's 10 once = 30 µs (its window closes at once: 30 ≤ 100).
/// * `can_tx[data]`: 10 + ⌈w/100⌉·20 = 30, plus its jitter.
/// * publisher: 100 + ⌈w/100⌉·20 + 10 → 130 → 150 → 150 µs.
/// * `can_tx[data]`'s jitter: the publisher's 150 + the transmit interrupt's 30 (its abort is asked in a job of
///   the transmit interrupt, within that response after the pend) + 405 = 585 µs (555 without the 30).
/// * `data`'s queuing jitter: the publisher's variation 150 − 50 and the transmit interrupt's response 30 (the
///   frame in a mailbox within it): 130 µs. Blocking: `other`, 135 (and a page's, 135). Uncharged: 130 + 135 + 135
///   = 265 µs from the earliest queuing, delivered 50 + 265 = 450 µs after the publisher's release.
/// * On the sound transmit path its frame costs 135 + G, G = 30 + 135 (one interval in which it is not covered —
///   the three mailboxes full of less urgent frames, the least urgent on the bus: a second transmit response after
///   that frame's end — and the longest frame started in it): 130 + 135 + 300 = 565, delivered by 615 µs.
///
/// The sound model is [`analysis::analyse`]'s (the transmit job's second releaser its transmit interrupt,
/// `board_analysis::Release::also`); the uncharged one, the verdict's until 2026-12-05, gave the figures without it.
#[test]
fn a_frame_needing_a_mailbox_abort_takes_a_second_transmit_response_and_the_aborted_frame() {
    let model = serde_json::json!({
        "boards": [{
            "name": "node",
            "can_tx_task": "can_tx",
            "tasks": [
                { "name": "can_tx", "priority": 3, "wcet_us": 20, "period_us": 100, "sporadic": true },
                { "name": "can_tx[data]", "priority": 3, "wcet_us": 10, "period_us": 10000,
                  "jitter_us": 405, "released_by": "publisher", "job_of": "can_tx" },
                { "name": "publisher", "priority": 1, "wcet_us": 100, "bcet_us": 50, "period_us": 10000,
                  "deadline_us": 10000 }
            ]
        }],
        "can": {
            "bitrate": 1000000,
            "frame_cost": "exact",
            "messages": [
                { "name": "data", "id": 256, "dlc": 8, "period_us": 10000, "deadline_us": 10000,
                  "sender": "node/publisher" },
                { "name": "other", "id": 512, "dlc": 8, "period_us": 10000, "deadline_us": 10000 }
            ]
        }
    });
    assert_eq!(
        can::transmit_abort_latency(can::bit_time(1_000_000)),
        Time::from_us(405)
    );
    let (system, options) = exact_system(&model);
    // (row's jitter, row's WCRT, frame's jitter, frame's WCRT), µs.
    let figures = |report: &analysis::Analysis| {
        let task = |name: &str| only_board_task(report, name);
        assert_eq!(task("can_tx").wcrt(), Some(Time::from_us(30)));
        assert_eq!(task("publisher").wcrt(), Some(Time::from_us(150)));
        let row = task("can_tx[data]");
        let bus = report.bus.as_ref().expect("a bus");
        let data = bus
            .messages
            .iter()
            .find(|m| m.name == "data")
            .expect("data");
        assert_eq!(data.blocking, Time::from_us(135));
        assert_eq!(data.offset, Time::from_us(50));
        (
            row.jitter.as_us_f64(),
            row.wcrt().map(|w| w.as_us_f64()),
            data.jitter.as_us_f64(),
            data.wcrt().map(|w| w.as_us_f64()),
        )
    };
    let charged = analysis::analyse(&system, &options);
    assert_eq!(figures(&charged), (585.0, Some(615.0), 130.0, Some(615.0)));
    // The uncharged model (the verdict's and the boards' until 2026-12-05) gave (555, 585, 130, 450): the transmit
    // job without the transmit response, the frame without the refill.
}

/// The sound model's release-jitter rounds where the transmit interrupt's response grows with them (the transmit
/// job's second releaser, `board_analysis::Release::also`, at its own level),
/// worked by hand at 1 Mbit/s, `exact`. One board: `can_tx` (priority 5, 10 µs, at least 71 µs apart), its job
/// `can_tx[data]` (priority 5, 200 µs, released by the publisher with `can::transmit_abort_latency` = 405 µs of its
/// own), the publisher (priority 9, 100 µs, best 50 µs, every 1 ms); its frame `data` (8 bytes, 135 µs) alone on
/// the bus. `can_tx`'s first instance: 10 + the publisher's 100 + the transmit job's 200 per ⌈(w + J)/1 000⌉ of
/// them, J the job's jitter.
///
/// * Uncharged: J = 100 + 405 = 505, one job: `can_tx` 310 µs; the frame's queuing jitter (100 − 50) + 310 = 360,
///   delivered by 50 + 360 + 135 = 545 µs.
/// * Sound, round 2: J = 505 + 310 = 815, two jobs in the window: 510 µs; round 3: J = 505 + 510 = 1 015, still
///   two: 510, the fixed point. The frame: jitter 50 + 510 = 560, blocked by a page (135), its frame at
///   135 + G (G = 510 + 135) = 780. Its level busy period: 135 + 4·780 = 3 255 (⌈(3 255 + 560)/1 000⌉ = 4); the
///   first of its four frames is the worst: 560 + 135 + 780 = 1 475 (the next: 560 + 915 + 780 − 1 000 = 1 255),
///   delivered by 50 + 1 475 = 1 525 µs.
#[test]
fn the_charged_rounds_grow_the_transmit_response_to_its_fixed_point() {
    let model = serde_json::json!({
        "boards": [{
            "name": "node",
            "can_tx_task": "can_tx",
            "tasks": [
                { "name": "can_tx", "priority": 5, "wcet_us": 10, "period_us": 71, "sporadic": true },
                { "name": "can_tx[data]", "priority": 5, "wcet_us": 200, "period_us": 1000,
                  "jitter_us": 405, "released_by": "publisher", "job_of": "can_tx" },
                { "name": "publisher", "priority": 9, "wcet_us": 100, "bcet_us": 50, "period_us": 1000,
                  "deadline_us": 1000 }
            ]
        }],
        "can": {
            "bitrate": 1000000,
            "frame_cost": "exact",
            "messages": [
                { "name": "data", "id": 256, "dlc": 8, "period_us": 1000, "deadline_us": 10000,
                  "sender": "node/publisher" }
            ]
        }
    });
    let (system, options) = exact_system(&model);
    // (can_tx's WCRT, the transmit job's jitter, the frame's jitter, the frame's WCRT), µs.
    let figures = |report: &analysis::Analysis| {
        let task = |name: &str| only_board_task(report, name);
        let data = &report.bus.as_ref().expect("a bus").messages[0];
        (
            task("can_tx").wcrt().map(|w| w.as_us_f64()),
            task("can_tx[data]").jitter.as_us_f64(),
            data.jitter.as_us_f64(),
            data.wcrt().map(|w| w.as_us_f64()),
        )
    };
    // The uncharged model (until 2026-12-05) gave (310, 505, 360, 545).
    let charged = analysis::analyse(&system, &options);
    assert_eq!(
        figures(&charged),
        (Some(510.0), 1015.0, 560.0, Some(1525.0))
    );
}
