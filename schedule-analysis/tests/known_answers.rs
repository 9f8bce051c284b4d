//! Small examples whose answers are known from the response-time-analysis literature, worked by hand in the
//! comments so a reader can check them without the papers.

use schedule_analysis::board::{self, CriticalSection, TaskTiming};
use schedule_analysis::busy_window::{Counter, Limits};
use schedule_analysis::can::{self, FrameCost, MessageTiming};
use schedule_analysis::time::Time;

mod sim;

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
