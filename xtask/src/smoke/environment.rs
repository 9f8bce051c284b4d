//! How a production image's boot must end in QEMU, given the robot's environment its board's
//! machine can hold (the inputs the boot reads that QEMU has no model for, each board's
//! [`Board::qemu_inputs`]).
use crate::boards::Board;

/// How a board's boot must end in QEMU.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ending {
    /// The tasks run (the watchdog task has started), the monotonic counts `HALF_PERIODS` and
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
    fn a_board_runs_where_its_machine_holds_sys_pd_n_released() {
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
