//! The clock-tree steps against a model RCC: a working tree, and each way a boot used to hang
//! (issue 12: the HSE wait and the clock-reset loops had no bound).
use std::cell::{Cell, RefCell};
use std::collections::HashMap;

use amiro_firmware::bxcan::Registers;
use amiro_firmware::clock_tree::{self, ClockFault, PllSetup, CLOCK_POLLS};

const CR: usize = 0x00;
const CFGR_F1: usize = 0x04;

/// An RCC whose ready flags follow their enable bits after `settle` reads, unless stuck.
#[derive(Default)]
struct Rcc {
    regs: RefCell<HashMap<usize, u32>>,
    reads: Cell<u32>,
    /// The crystal never oscillates.
    dead_crystal: bool,
    /// The PLL keeps reporting ready.
    pll_stuck: bool,
    /// SYSCLK stays on the PLL.
    switch_stuck: bool,
    /// The PLL never locks.
    pll_never_locks: bool,
}

impl Rcc {
    fn handed_over_by_bootloader() -> Self {
        let rcc = Rcc::default();
        // PLL on and locked, SYSCLK from the PLL (SW = SWS = 0b10), HSE on and ready.
        rcc.regs
            .borrow_mut()
            .insert(CR, 1 << 24 | 1 << 25 | 1 << 16 | 1 << 17 | 1 | 1 << 1);
        rcc.regs.borrow_mut().insert(CFGR_F1, 0b10 | 0b10 << 2);
        rcc
    }
}

impl Registers for &Rcc {
    fn read(&self, offset: usize) -> u32 {
        self.reads.set(self.reads.get() + 1);
        self.regs.borrow().get(&offset).copied().unwrap_or(0)
    }

    fn write(&self, offset: usize, value: u32) {
        let mut value = value;
        if offset == CR {
            // Ready flags follow the enables (HSI bit 0 → 1, HSE 16 → 17, PLL 24 → 25).
            for (on, ready) in [(0, 1), (16, 17), (24, 25)] {
                value = value & !(1 << ready) | ((value >> on) & 1) << ready;
            }
            if self.dead_crystal {
                value &= !(1 << 17);
            }
            if self.pll_stuck {
                value |= 1 << 25;
            }
            if self.pll_never_locks {
                value &= !(1 << 25);
            }
        }
        if offset == CFGR_F1 && !self.switch_stuck {
            // SWS follows SW.
            value = value & !(0b11 << 2) | (value & 0b11) << 2;
        }
        self.regs.borrow_mut().insert(offset, value);
    }
}

#[test]
fn a_handed_over_tree_returns_to_the_internal_oscillator() {
    let rcc = Rcc::handed_over_by_bootloader();
    assert_eq!(clock_tree::to_reset_state(&&rcc, CFGR_F1), Ok(()));
    let cr = rcc.regs.borrow()[&CR];
    assert_eq!(cr & (1 << 24 | 1 << 25), 0, "PLL off");
    assert_eq!(rcc.regs.borrow()[&CFGR_F1] & 0b1111, 0, "SYSCLK from HSI");
    assert_eq!(clock_tree::start_crystal(&&rcc), Ok(()));
}

#[test]
fn a_dead_crystal_is_a_fault_after_a_bounded_wait() {
    let rcc = Rcc {
        dead_crystal: true,
        ..Rcc::default()
    };
    assert_eq!(
        clock_tree::start_crystal(&&rcc),
        Err(ClockFault::HseNotReady)
    );
    // One read to set HSEON, then exactly the bound.
    assert_eq!(rcc.reads.get(), 1 + CLOCK_POLLS);
}

#[test]
fn a_pll_that_never_stops_or_a_switch_that_never_happens_is_a_fault() {
    let rcc = Rcc {
        pll_stuck: true,
        ..Rcc::handed_over_by_bootloader()
    };
    assert_eq!(
        clock_tree::to_reset_state(&&rcc, CFGR_F1),
        Err(ClockFault::PllStillRunning)
    );
    let rcc = Rcc {
        switch_stuck: true,
        ..Rcc::handed_over_by_bootloader()
    };
    assert_eq!(
        clock_tree::to_reset_state(&&rcc, CFGR_F1),
        Err(ClockFault::SwitchToHsi)
    );
    assert!(rcc.reads.get() <= 3 + 2 * CLOCK_POLLS);
}

/// A flash interface whose latency field takes what is written, unless it is stuck.
#[derive(Default)]
struct Flash {
    acr: Cell<u32>,
    stuck: bool,
}

impl Registers for &Flash {
    fn read(&self, _offset: usize) -> u32 {
        self.acr.get()
    }

    fn write(&self, _offset: usize, value: u32) {
        if !self.stuck {
            self.acr.set(value);
        }
    }
}

/// The F103's plan: HSE × 9, APB1 and APB2 / 2, two wait states.
const F1_PLL: PllSetup = PllSetup {
    pll_register: CFGR_F1,
    pll: (0x003F_0000, 1 << 16 | 0b0111 << 18),
    prescalers: (0x3FF0, 0b100 << 8 | 0b100 << 11),
    flash_acr: 0,
    latency: (0b111, 2),
};

fn started_from_reset(rcc: &Rcc) {
    assert_eq!(clock_tree::to_reset_state(&rcc, CFGR_F1), Ok(()));
    assert!(clock_tree::in_reset_state(&rcc, CFGR_F1));
}

#[test]
fn the_pll_starts_and_becomes_sysclk_with_its_factors_prescalers_and_wait_states() {
    let rcc = Rcc::handed_over_by_bootloader();
    started_from_reset(&rcc);
    assert_eq!(clock_tree::start_crystal(&&rcc), Ok(()));
    let flash = Flash::default();
    assert_eq!(
        clock_tree::start_pll(&&rcc, &&flash, CFGR_F1, &F1_PLL),
        Ok(())
    );
    let cfgr = rcc.regs.borrow()[&CFGR_F1];
    assert_eq!(cfgr & 0x003F_0000, 1 << 16 | 0b0111 << 18, "HSE × 9");
    assert_eq!(cfgr & 0x3FF0, 0b100 << 8 | 0b100 << 11, "APBs / 2");
    assert_eq!(cfgr & 0b1111, 0b1010, "SW = SWS = PLL");
    assert_eq!(flash.acr.get() & 0b111, 2);
    assert!(clock_tree::running_on_crystal_pll(&&rcc, CFGR_F1));
}

#[test]
fn a_pll_that_never_locks_leaves_the_internal_oscillator_with_undivided_buses() {
    let rcc = Rcc {
        pll_never_locks: true,
        ..Rcc::handed_over_by_bootloader()
    };
    started_from_reset(&rcc);
    let flash = Flash::default();
    let before = rcc.reads.get();
    assert_eq!(
        clock_tree::start_pll(&&rcc, &&flash, CFGR_F1, &F1_PLL),
        Err(ClockFault::PllNotReady)
    );
    assert!(rcc.reads.get() - before <= 8 + 2 * CLOCK_POLLS, "bounded");
    let cr = rcc.regs.borrow()[&CR];
    let cfgr = rcc.regs.borrow()[&CFGR_F1];
    assert_eq!(cr & 1 << 24, 0, "PLL off again");
    assert_eq!(cfgr & 0b1111, 0, "SYSCLK from HSI");
    assert_eq!(cfgr & 0x3FF0, 0, "every bus at the oscillator's frequency");
    assert!(clock_tree::in_reset_state(&&rcc, CFGR_F1));
}

#[test]
fn flash_that_keeps_its_wait_states_or_a_switch_that_never_happens_is_a_fault() {
    let rcc = Rcc::default();
    let flash = Flash {
        stuck: true,
        ..Flash::default()
    };
    assert_eq!(
        clock_tree::start_pll(&&rcc, &&flash, CFGR_F1, &F1_PLL),
        Err(ClockFault::FlashLatency)
    );
    assert_eq!(rcc.regs.borrow()[&CR] & 1 << 24, 0, "the PLL never started");
    let rcc = Rcc {
        switch_stuck: true,
        ..Rcc::default()
    };
    assert_eq!(
        clock_tree::start_pll(&&rcc, &&Flash::default(), CFGR_F1, &F1_PLL),
        Err(ClockFault::SwitchToPll)
    );
}

#[test]
fn a_running_pll_is_never_reconfigured_and_an_unreadable_tree_is_recognised() {
    let rcc = Rcc::handed_over_by_bootloader();
    assert!(clock_tree::running_on_crystal_pll(&&rcc, CFGR_F1));
    assert!(!clock_tree::in_reset_state(&&rcc, CFGR_F1));
    assert_eq!(
        clock_tree::start_pll(&&rcc, &&Flash::default(), CFGR_F1, &F1_PLL),
        Err(ClockFault::PllStillRunning)
    );
    // An RCC that reads zero everywhere (QEMU): the reset step fails, but the tree reads as reset.
    let zero = Rcc {
        dead_crystal: true,
        pll_never_locks: true,
        ..Rcc::default()
    };
    assert!(clock_tree::in_reset_state(&&zero, CFGR_F1));
    assert!(!clock_tree::running_on_crystal_pll(&&zero, CFGR_F1));
}
