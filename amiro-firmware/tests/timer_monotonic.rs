//! The monotonic's timer against a model general-purpose timer: the start sequence, the
//! half-period accounting on a chip (compare and update alternate), and on a timer whose compare
//! events never come (QEMU's model), which is counted and reported once.
use std::cell::RefCell;
use std::collections::BTreeMap;

use amiro_firmware::bxcan::Registers;
use amiro_firmware::timer_monotonic::{
    advance, now_from, now_in_interrupt, on_interrupt, set_compare, start, HalfPeriods, Missed,
};

const SR: usize = 0x10;
const UIF: u32 = 1;
const CC1IF: u32 = 2;
const CC2IF: u32 = 4;
const CC3IF: u32 = 8;

/// Registers that keep what is written; the status register clears the bits written as 0.
#[derive(Default)]
struct Timer {
    regs: RefCell<BTreeMap<usize, u32>>,
    writes: RefCell<Vec<(usize, u32)>>,
}

impl Timer {
    fn flag(&self, bits: u32) {
        *self.regs.borrow_mut().entry(SR).or_default() |= bits;
    }
    fn get(&self, offset: usize) -> u32 {
        self.regs.borrow().get(&offset).copied().unwrap_or(0)
    }
}

impl Registers for &Timer {
    fn read(&self, offset: usize) -> u32 {
        self.get(offset)
    }
    fn write(&self, offset: usize, value: u32) {
        self.writes.borrow_mut().push((offset, value));
        let mut regs = self.regs.borrow_mut();
        let reg = regs.entry(offset).or_default();
        if offset == SR {
            *reg &= value;
        } else {
            *reg = value;
        }
    }
}

#[test]
fn start_sets_a_16_bit_microsecond_counter_and_enables_it_last() {
    let timer = Timer::default();
    let counter = HalfPeriods::new();
    start(&&timer, &counter, 72_000_000);
    assert_eq!(timer.get(0x28), 71, "PSC: 72 MHz / 72 = 1 MHz");
    assert_eq!(
        timer.get(0x2C),
        0xFFFF,
        "ARR written, 16 bits on every timer"
    );
    assert_eq!(timer.get(0x34), 0x8000, "CCR1 at the half period");
    assert_eq!(timer.get(0x0C), 0b11, "update and compare-1 interrupts");
    assert_eq!(timer.get(0x24), 1, "CNT");
    assert_eq!(timer.writes.borrow().last(), Some(&(0x00, 1)), "CEN last");
    start(&&timer, &counter, 8_000_000);
    assert_eq!(timer.get(0x28), 7, "the internal-oscillator plan");
}

#[test]
fn on_a_chip_compare_and_update_alternate_and_nothing_is_missed() {
    let timer = Timer::default();
    let counter = HalfPeriods::new();
    start(&&timer, &counter, 8_000_000);
    for i in 0..10u32 {
        timer.flag(if i % 2 == 0 { CC1IF } else { UIF });
        on_interrupt(&&timer, &counter);
        assert_eq!(timer.get(SR), 0, "the flag taken is cleared");
    }
    assert_eq!((counter.count(), counter.missed()), (10, 0));
    // Both pending at once (the interrupt came late but within the period): in their order.
    timer.flag(CC1IF | UIF);
    on_interrupt(&&timer, &counter);
    assert_eq!(counter.count(), 12);
    assert_eq!(
        counter.take_report(),
        None,
        "nothing missed, nothing to report"
    );
}

#[test]
fn a_timer_without_compare_events_counts_whole_periods_and_reports_once() {
    let timer = Timer::default();
    let counter = HalfPeriods::new();
    start(&&timer, &counter, 8_000_000);
    timer.flag(UIF);
    on_interrupt(&&timer, &counter);
    assert_eq!(counter.take_report(), Some(Missed::HalfPeriodCompare));
    for _ in 0..5 {
        timer.flag(UIF);
        on_interrupt(&&timer, &counter);
        assert_eq!(counter.take_report(), None, "reported once");
    }
    assert_eq!(counter.count(), 12, "two half periods per update");
    assert_eq!(counter.count() % 2, 0, "the parity still says: lower half");
    assert_eq!(counter.missed(), 6);
}

#[test]
fn the_accounting_keeps_the_parity_whatever_goes_missing() {
    assert_eq!(advance(0, false, true), (1, None));
    assert_eq!(advance(1, true, false), (2, None));
    assert_eq!(advance(0, true, true), (2, None));
    assert_eq!(advance(1, true, true), (3, None));
    assert_eq!(
        advance(0, true, false),
        (2, Some(Missed::HalfPeriodCompare))
    );
    assert_eq!(advance(1, false, true), (3, Some(Missed::Update)));
    assert_eq!(advance(7, false, false), (7, None));
    assert_eq!(advance(u32::MAX, true, false), (0, None), "wraps");
}

/// The catch-up as it was written first, one event per pass of a loop: `advance` must agree with it.
fn advance_by_passes(count: u32, update: bool, half: bool) -> (u32, Option<Missed>) {
    let (mut count, mut update, mut half) = (count, update, half);
    let mut missed = None;
    while update || half {
        let due_is_half = count.is_multiple_of(2);
        let (due, other) = if due_is_half {
            (&mut half, &mut update)
        } else {
            (&mut update, &mut half)
        };
        if *due {
            *due = false;
            count = count.wrapping_add(1);
        } else {
            *other = false;
            count = count.wrapping_add(2);
            missed.get_or_insert(if due_is_half {
                Missed::HalfPeriodCompare
            } else {
                Missed::Update
            });
        }
    }
    (count, missed)
}

#[test]
fn the_catch_up_without_a_loop_is_the_catch_up_one_event_at_a_time() {
    for count in [0, 1, 2, 3, 0x7FFF_FFFF, u32::MAX - 1, u32::MAX] {
        for update in [false, true] {
            for half in [false, true] {
                assert_eq!(
                    advance(count, update, half),
                    advance_by_passes(count, update, half),
                    "count {count}, update {update}, half {half}"
                );
            }
        }
    }
}

#[test]
fn the_interrupt_clears_the_queue_compare_with_the_events_it_takes_and_nothing_else() {
    let timer = Timer::default();
    let counter = HalfPeriods::new();
    start(&&timer, &counter, 8_000_000);
    // Only the queue's compare: cleared, nothing counted.
    timer.flag(CC2IF | CC3IF);
    on_interrupt(&&timer, &counter);
    assert_eq!(timer.get(SR), CC3IF, "CC2IF cleared, CC3IF left");
    assert_eq!(counter.count(), 0);
    // With the half-period compare: both cleared in one write, the half period counted.
    timer.flag(CC1IF | CC2IF);
    let writes = timer.writes.borrow().len();
    on_interrupt(&&timer, &counter);
    assert_eq!(timer.get(SR), CC3IF);
    assert_eq!(counter.count(), 1);
    assert_eq!(timer.writes.borrow().len(), writes + 1, "one status write");
}

#[test]
fn time_is_the_counter_placed_in_the_half_periods_counted() {
    // The one time whose low 16 bits are the counter's and that lies at most one period beyond the
    // count's half period: the count may lag the counter by up to one half period.
    for count in [0u32, 1, 2, 3, 1000, 1001, u32::MAX - 1, u32::MAX] {
        let base = u64::from(count) << 15;
        for value in 0..=u16::MAX {
            let now = now_from(count, value);
            assert_eq!(
                now & 0xFFFF,
                u64::from(value),
                "count {count}, counter {value}"
            );
            assert!(
                (base..base + 0x1_0000).contains(&now),
                "count {count}, counter {value}: {now:#x}"
            );
        }
    }
    assert_eq!(now_from(0, 5), 5);
    assert_eq!(now_from(1, 0x8005), 0x8005);
    assert_eq!(
        now_from(1, 5),
        0x1_0005,
        "wrapped, its update not yet counted"
    );
    assert_eq!(
        now_from(2, 0x8005),
        0x1_8005,
        "past the half, not yet counted"
    );
}

#[test]
fn the_interrupt_reads_time_from_the_count_and_the_counter() {
    let timer = Timer::default();
    let counter = HalfPeriods::new();
    start(&&timer, &counter, 8_000_000);
    for _ in 0..3 {
        timer.flag(if counter.count().is_multiple_of(2) {
            CC1IF
        } else {
            UIF
        });
        on_interrupt(&&timer, &counter);
    }
    (&timer).write(0x24, 0x0123);
    assert_eq!(now_in_interrupt(&&timer, &counter), 0x1_8000 + 0x8123);
}

#[test]
fn a_compare_beyond_one_period_waits_for_the_wrap() {
    let timer = Timer::default();
    (&timer).write(0x24, 0x0000);
    assert!(!set_compare(&&timer, 0x1_2345, 0x1_0000));
    assert_eq!(timer.get(0x38), 0x2345);
    assert!(!set_compare(&&timer, 0x3_0000, 0x1_0000));
    assert_eq!(timer.get(0x38), 0);
    assert!(
        !set_compare(&&timer, 5, 10),
        "a past instant: the wrap looks again"
    );
    assert_eq!(timer.get(0x38), 0);
}

#[test]
fn a_compare_the_counter_has_reached_asks_for_another_look() {
    let timer = Timer::default();
    // Set at 0x1_0000 for 0x1_0010; the counter, read after the write, says 0x0010 ticks passed.
    (&timer).write(0x24, 0x0010);
    assert!(set_compare(&&timer, 0x1_0010, 0x1_0000), "reached exactly");
    (&timer).write(0x24, 0x0020);
    assert!(set_compare(&&timer, 0x1_0010, 0x1_0000), "passed");
    (&timer).write(0x24, 0x000F);
    assert!(!set_compare(&&timer, 0x1_0010, 0x1_0000), "one tick to go");
    // Across the counter's wrap: set at 0x1_FFF0 for 0x2_0005, the counter at 0x0006.
    (&timer).write(0x24, 0x0006);
    assert!(set_compare(&&timer, 0x2_0005, 0x1_FFF0));
    (&timer).write(0x24, 0xFFFF);
    assert!(!set_compare(&&timer, 0x2_0005, 0x1_FFF0));
}

#[test]
fn each_missing_event_has_its_own_report() {
    assert!(Missed::HalfPeriodCompare
        .report()
        .starts_with("monotonic: "));
    assert_ne!(Missed::HalfPeriodCompare.report(), Missed::Update.report());
}
