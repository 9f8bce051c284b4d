//! The robot's environment around a production image in QEMU: the inputs the boot reads that QEMU
//! has no model for, held at the robot's level, and how the boot must end on each machine.
use crate::boards::Board;

/// One input of the robot's environment that the stand-in sets before the hand-over, through a
/// register QEMU's machine happens to have at the address the firmware reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Input {
    /// The address the firmware reads.
    pub address: u32,
    /// What the stand-in writes there.
    pub value: u32,
    /// What it stands for on the robot.
    pub stands_for: &'static str,
    /// Which of QEMU's registers makes it work (the reliance, stated).
    pub through: &'static str,
    /// Who sets it.
    pub via: Via,
}

/// How an input of the robot's environment is set in QEMU.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Via {
    /// The stand-in writes it before the hand-over (a register that reads back).
    StandIn,
    /// A read watchpoint through QEMU's gdbstub sets the bits in each load's result
    /// (`gdb::hold_inputs`): the port reads zero and drops writes.
    Watchpoint,
}

/// The F103's GPIOC (RM0008 §9): its input data register is at offset 8.
const F103_GPIOC_IDR: u32 = 0x4001_1000 + 0x08;
/// The F205's USART1 on `netduino2` (QEMU's `stm32f205_soc.c`) and its baud-rate register
/// (offset 8), which QEMU's USART model stores and reads back without side effects.
const F205_USART1_BRR: u32 = 0x4001_1000 + 0x08;

/// The F405's GPIOC input data register (RM0090 §8.4.5), PowerManagement's SYS_PD_N port.
const F405_GPIOC_IDR: u32 = 0x4002_0800 + 0x10;

/// `netduino2`'s inputs: the environment set up around the image on the machine (the robot's, not the firmware's
/// doing). The only QEMU register at the address of an input the boot reads that reads back what
/// is written is on `netduino2`, where the F205's USART1 sits where the F103's GPIOC does, and its
/// BRR where GPIOC_IDR is: the stand-in writes it. Bits 8 and 14 make SYS_PD_N (PC8 on DiWheelDrive,
/// PC14 on LightRing) read released, as the robot's pull-ups hold it. The firmware's writes to
/// GPIOC's other registers land in USART1's (`docs/faults.md` says why that is harmless); none
/// writes BRR's offset (IDR is read-only on the F103). The reliance checks itself: if QEMU stopped
/// reading BRR back, SYS_PD_N would read low, the board would hand over, and its run would fail.
/// `netduinoplus2` has no GPIO at all (its GPIOC is an unimplemented-device region that reads
/// zero and drops writes): there a read watchpoint through the gdbstub sets PC13 (SYS_PD_N) in
/// every load from GPIOC_IDR, the other pins reading zero as before. Without it PowerManagement
/// would see SYS_PD_N driven low and, rightly, shut down.
///
/// Each board's [`Board::qemu_inputs`] is its machine's table: [`NETDUINO2`] or [`NETDUINOPLUS2`].
pub const NETDUINO2: &[Input] = {
    const _: () = assert!(F103_GPIOC_IDR == F205_USART1_BRR);
    &[Input {
        address: F103_GPIOC_IDR,
        value: 1 << 8 | 1 << 14,
        stands_for: "SYS_PD_N released (PC8 / PC14 held high by the robot's pull-ups)",
        through: "netduino2's USART1_BRR, which reads back, at the F103's GPIOC_IDR",
        via: Via::StandIn,
    }]
};

/// `netduinoplus2`'s inputs ([`NETDUINO2`] says why).
pub const NETDUINOPLUS2: &[Input] = &[Input {
    address: F405_GPIOC_IDR,
    value: 1 << 13,
    stands_for: "SYS_PD_N released (PC13 held high by the robot's pull-up)",
    through: "a gdbstub read watchpoint on GPIOC_IDR, PC13 set in each load's result",
    via: Via::Watchpoint,
}];

/// How a board's boot must end in QEMU.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ending {
    /// The tasks run (the watchdog task has started), the monotonic counts [`HALF_PERIODS`] and
    /// reports the compare events QEMU's timer lacks, and nothing faults.
    Running,
    /// SYS_PD_N reads low (a machine with no way to hold it released): the board's shutdown task
    /// hands over to AMiRo-BLT's callback, before the monotonic's first interrupt.
    HandOver(&'static str),
}

/// What QEMU lets each board show (`docs/faults.md`): on a machine where the run can hold
/// SYS_PD_N released (stand-in or gdbstub) the board runs, else it takes the line's low level for
/// a shutdown request.
pub fn expected_ending(board: &Board) -> Ending {
    if board.qemu_inputs.is_empty() {
        Ending::HandOver("handle a shutdown request")
    } else {
        Ending::Running
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_machine_states_how_sys_pd_n_reads_released() {
        let inputs = NETDUINO2;
        assert_eq!(inputs.len(), 1);
        assert_eq!(inputs[0].address, 0x4001_1008, "the F103's GPIOC_IDR");
        assert_eq!(inputs[0].value, 1 << 8 | 1 << 14, "PC8 and PC14");
        assert_eq!(inputs[0].via, Via::StandIn);
        assert!(inputs[0].through.contains("USART1_BRR"));
        let inputs = NETDUINOPLUS2;
        assert_eq!(inputs.len(), 1);
        assert_eq!(inputs[0].address, 0x4002_0810, "the F405's GPIOC_IDR");
        assert_eq!(inputs[0].value, 1 << 13, "PC13");
        assert_eq!(inputs[0].via, Via::Watchpoint);
        for board in &crate::boards::BOARDS {
            assert_eq!(expected_ending(board), Ending::Running, "{}", board.name);
        }
        let unheld = Board {
            qemu_inputs: &[],
            ..crate::boards::BOARDS[0]
        };
        assert_eq!(
            expected_ending(&unheld),
            Ending::HandOver("handle a shutdown request")
        );
    }
}
