//! The monotonic's timer against a model general-purpose timer: the start sequence, the
//! half-period accounting on a chip (compare and update alternate), and on a timer whose compare
//! events never come (QEMU's model), which is counted and reported once.
use std::cell::RefCell;
use std::collections::BTreeMap;

use amiro_firmware::bxcan::Registers;
use amiro_firmware::timer_monotonic::{
    advance, on_interrupt, set_compare, start, HalfPeriods, Missed,
};

const SR: usize = 0x10;
const UIF: u32 = 1;
const CC1IF: u32 = 2;

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
        assert_eq!(on_interrupt(&&timer, &counter), None);
        assert_eq!(timer.get(SR), 0, "the flag taken is cleared");
    }
    assert_eq!((counter.count(), counter.missed()), (10, 0));
    // Both pending at once (the interrupt came late but within the period): in their order.
    timer.flag(CC1IF | UIF);
    assert_eq!(on_interrupt(&&timer, &counter), None);
    assert_eq!(counter.count(), 12);
}

#[test]
fn a_timer_without_compare_events_counts_whole_periods_and_reports_once() {
    let timer = Timer::default();
    let counter = HalfPeriods::new();
    start(&&timer, &counter, 8_000_000);
    timer.flag(UIF);
    assert_eq!(
        on_interrupt(&&timer, &counter),
        Some(Missed::HalfPeriodCompare)
    );
    for _ in 0..5 {
        timer.flag(UIF);
        assert_eq!(on_interrupt(&&timer, &counter), None, "reported once");
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

#[test]
fn a_compare_beyond_one_period_waits_for_the_wrap() {
    let timer = Timer::default();
    set_compare(&&timer, 0x1_2345, 0x1_0000);
    assert_eq!(timer.get(0x38), 0x2345);
    set_compare(&&timer, 0x3_0000, 0x1_0000);
    assert_eq!(timer.get(0x38), 0);
    set_compare(&&timer, 5, 10);
    assert_eq!(timer.get(0x38), 0, "a past instant");
}

#[test]
fn each_missing_event_has_its_own_report() {
    assert!(Missed::HalfPeriodCompare
        .report()
        .starts_with("monotonic: "));
    assert_ne!(Missed::HalfPeriodCompare.report(), Missed::Update.report());
}
