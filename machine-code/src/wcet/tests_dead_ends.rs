//! Known answers for a loop's way out that cannot complete ([`super::path`]): a way out into a
//! block from which no path returns is no last pass to charge. Hand-assembled Thumb-2, each bound
//! worked out from the Cortex-M3 TRM's cycle table as in [`super::tests`] (data processing 1,
//! PUSH/POP 1 + N, a taken branch 1 + P and BL 1 + P with P = 3, `CBZ` 1 and + P when taken; flash
//! at 0 wait states: a line of 8 bytes costs 1, hidden by the instructions here).
use super::*;
use crate::testelf::{elf, Sym};
use crate::thumb;

const F103_0WS: Chip = Chip::Stm32f103 { wait_states: 0 };

/// `find`: `for _ in 0..4 { ..; if r2 == 7 { return } .. }` then `at_end` (two halfwords at 0x14)
/// where the count runs out, as `iter().position(..).unwrap()` leaves its search: the header
/// tests the count and leaves to `at_end`, the body leaves to the return. `callee` (at 0x1c, two
/// bytes) is what a `bl` in `at_end` calls.
fn find(at_end: [u16; 2], callee: (&str, u16)) -> Image {
    let code = [
        0xb580,    // 0x00 push {r7, lr}: 1 + 2
        0x2000,    // 0x02 movs r0, #0: 1
        0x2804,    // 0x04 cmp r0, #4: 1 (the header: 5 runs)
        0xd005,    // 0x06 beq 0x14: 1, taken 1 + P (the count's way out, to `at_end`)
        0x3201,    // 0x08 adds r2, #1: 1
        0x2a07,    // 0x0a cmp r2, #7: 1
        0xd004,    // 0x0c beq 0x18: 1, taken 1 + P (found: the body's way out, to the return)
        0x3301,    // 0x0e adds r3, #1: 1
        0x3001,    // 0x10 adds r0, #1: 1 (the count's step)
        0xe7f7,    // 0x12 b 0x04: 1 + P
        at_end[0], // 0x14
        at_end[1], // 0x16
        0xbd80,    // 0x18 pop {r7, pc}: 1 + 2 + P
        0xbf00,    // 0x1a
        callee.1,  // 0x1c the callee
    ];
    let symbols = [
        Sym::function("find", 0, 0x1a),
        Sym::function(callee.0, 0x1c, 2),
    ];
    Image::parse(&elf(&thumb(&code), &symbols)).expect("the test image parses")
}

/// `bl 0x1c`.
const CALL: [u16; 2] = [0xf000, 0xf802];
/// `b .`, the callee of a panic: it spins for ever.
const SPIN: u16 = 0xe7fe;
/// `bx lr`.
const RETURN: u16 = 0x4770;
/// `udf #0`: a trap.
const UDF: u16 = 0xde00;
/// `nop`, after a block that does not go on.
const NOP: u16 = 0xbf00;

fn bound(image: &Image) -> (u64, u64, Option<String>) {
    let b = bound_function(image, "find", F103_0WS, &BoundsFile::default())
        .expect("the function is analysed");
    (b.cycles, b.instructions, b.declined)
}

// From the TRM's table at 0 wait states: the push and the movs 4 cycles, 2 instructions; an
// iteration (cmp, beq, adds, cmp, beq, adds, adds, b) 7 + 4 = 11 cycles, 8 instructions; the
// header's way out (cmp, beq taken) 1 + 4 = 5 cycles, 2 instructions; the body's (cmp, beq, adds,
// cmp, beq taken) 4 + 4 = 8 cycles, 5 instructions; the pop 6 cycles, 1 instruction. The count
// lets the header run 5 times, at most 4 passes on past it: 4 iterations and the header's way out
// (49 cycles, 34 instructions) or 3 and the body's (41, 29).

#[test]
fn a_way_out_that_cannot_complete_is_no_last_pass() {
    // Where the count runs out, a panic, a trap or a loop with no exit: only the body's way out
    // ends a path that returns. 4 + 41 + 6 = 51 cycles, 2 + 29 + 1 = 32 instructions; charging
    // the header's way out as the last pass would be 4 + 49 + 6 = 59 cycles, 37 instructions.
    let dead_ends = [
        ("a panic", find(CALL, ("core::panicking::panic", SPIN))),
        ("a trap", find([UDF, NOP], ("unused", RETURN))),
        ("a loop with no exit", find([SPIN, NOP], ("unused", RETURN))),
    ];
    for (what, image) in &dead_ends {
        assert_eq!(bound(image), (51, 32, None), "{what}");
    }
}

#[test]
fn a_way_out_that_may_still_return_is_charged() {
    // The call where the count runs out returns (its callee `bx lr`: 4 cycles): the header's way
    // out is the last pass, then the bl, the callee and the pop: 4 + 49 + 4 + 4 + 6 = 67 cycles,
    // 2 + 34 + 1 + 1 + 1 = 39 instructions.
    assert_eq!(bound(&find(CALL, ("helper", RETURN))), (67, 39, None));
    // `cbz r1, 0x18` then `udf`: the block may trap, but it may go on to the return (cbz taken,
    // 1 + P): 4 + 49 + 4 + 6 = 63 cycles, 2 + 34 + 1 + 1 = 38 instructions.
    assert_eq!(
        bound(&find([0xb101, UDF], ("unused", RETURN))),
        (63, 38, None)
    );
}
