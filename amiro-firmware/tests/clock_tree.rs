//! The clock-tree steps against a model RCC: a working tree, and each way a boot used to hang
//! (issue 12: the HSE wait and the clock-reset loops had no bound).
use std::cell::{Cell, RefCell};
use std::collections::HashMap;

use amiro_firmware::bxcan::Registers;
use amiro_firmware::clock_tree::{self, ClockFault, CLOCK_POLLS};

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
