//! Known answers for a loop's way out that cannot complete ([`super::path`]): a way out into a
//! block from which no path returns (a panic, a trap, a loop with no exit, a tail whose sample one
//! topic's job leaves out) is no last pass to charge. Hand-assembled Thumb-2, each bound worked out
//! from the Cortex-M3 TRM's cycle table as in [`super::tests`] (data processing 1, LDR 2 and 5 more
//! from a peripheral whose base the code does not fix, APB1's, PUSH/POP 1 + N, a taken branch
//! 1 + P and BL 1 + P with P = 3, `CBZ` 1 and + P when taken; flash at 0 wait states: a line of 8
//! bytes costs 1, hidden by the instructions here).
use super::*;
use crate::testelf::{elf, elf_with_lines, Sym};
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

/// `PUB`, a publisher whose release loop (src/pub.rs:20, stated at 4 runs) reads the next release
/// (0: none), leaves for a release of topic 3 to a tail (src/pub.rs:21) that samples it through
/// `SAMPLE_B` before the return, and otherwise samples through `SAMPLE_A` (1) or `SAMPLE_B`, counts
/// and goes round.
fn publisher() -> Image {
    let code = thumb(&[
        0xb510, // 0x00 push {r4, lr}: 1 + 2
        0x6801, // 0x02 ldr r1, [r0]: 2 + 5, an unknown base (the header, line 20)
        0x2900, // 0x04 cmp r1, #0: 1
        0xd00d, // 0x06 beq 0x24: 1, taken 1 + P (nothing due: to the return)
        0x2903, // 0x08 cmp r1, #3: 1
        0xd008, // 0x0a beq 0x1e: 1, taken 1 + P (the way out from the body, to the tail)
        0x2901, // 0x0c cmp r1, #1: 1
        0xd102, // 0x0e bne 0x16: 1, taken 1 + P
        0xf000, 0xf80c, // 0x10 bl SAMPLE_A: 1 + P
        0xe001, // 0x14 b 0x1a: 1 + P
        0xf000, 0xf80b, // 0x16 bl SAMPLE_B: 1 + P
        0x3401, // 0x1a adds r4, #1: 1
        0xe7f1, // 0x1c b 0x02: 1 + P
        0x3401, // 0x1e adds r4, #1: 1 (the tail, line 21)
        0x3401, // 0x20 adds r4, #1: 1
        0xe000, // 0x22 b 0x26: 1 + P
        0xbd10, // 0x24 pop {r4, pc}: 1 + 2 + P
        0xf000, 0xf803, // 0x26 bl SAMPLE_B: 1 + P
        0xe7fb, // 0x2a b 0x24: 1 + P
        0x2001, // 0x2c SAMPLE_A: movs r0, #1: 1
        0x4770, // 0x2e bx lr: 1 + P
        0x2002, // 0x30 SAMPLE_B: movs r0, #2: 1
        0x4770, // 0x32 bx lr: 1 + P
    ]);
    let bytes = elf_with_lines(
        &code,
        &[
            Sym::function("PUB", 0, 0x2c),
            Sym::function("SAMPLE_A", 0x2c, 4),
            Sym::function("SAMPLE_B", 0x30, 4),
        ],
        "firmware/src/pub.rs",
        &[
            (0, 10),
            (2, 20),
            (0x1e, 21),
            (0x24, 22),
            (0x2c, 30),
            (0x30, 40),
        ],
    );
    Image::parse(&bytes).expect("the test image parses")
}

#[test]
fn a_way_out_into_a_left_out_sample_is_no_last_pass_of_a_topics_job() {
    let file = BoundsFile::parse(
        r#"{"loops":[{"function":"PUB","file":"src/pub.rs","line":20,"bound":4,"reason":"3 releases and the end"}],
        "topics":{"function":"PUB","file":"src/pub.rs","line":20,"reason":"one release per job",
        "groups":[{"name":"a","topics":["alpha"],"functions":["SAMPLE_A"],"reason":"only alpha's arm calls it"},
                  {"name":"b","topics":["beta"],"functions":["SAMPLE_B"],"reason":"only beta's arms call it"}]}}"#,
    )
    .expect("the bounds file parses");
    let task = Task {
        name: "pub".into(),
        entry: TaskEntry::Symbol("PUB".into()),
        handler: false,
    };
    let rows = bound_tasks(&publisher(), &[task], F103_0WS, &file);
    let (a, b) = (&rows[0].topics[0], &rows[0].topics[1]);
    // Each topic's job: the push, the loop's longest way out, one iteration, what follows the way
    // out. The header's way out (ldr 7, cmp 1, beq taken 4) is 12 cycles, 3 instructions, to the
    // pop (6); the body's (ldr 7, cmp 1, beq 1, cmp 1, beq taken 4) 14 cycles, 5 instructions, to
    // the tail (adds 1, adds 1, b 4), the bl (4), SAMPLE_B (5: movs 1, bx lr 4), the b (4) and the
    // pop (6).
    // Group a: an iteration through A (ldr 7, cmp 1, beq 1, cmp 1, beq 1, cmp 1, bne 1, bl 4,
    // SAMPLE_A 5, b 4, adds 1, b 4) is 31 cycles, 13 instructions. With B's calls left out the
    // tail leads nowhere: only the header's way out completes, 3 + 12 + 6 + 31 = 52 cycles,
    // 1 + 3 + 1 + 13 = 18 instructions (charging the body's way out gave 54 and 20).
    assert_eq!(
        (
            a.group.as_str(),
            a.cycles,
            a.instructions,
            a.declined.as_deref()
        ),
        ("a", 52, 18, None)
    );
    // Group b: an iteration through B (ldr 7, cmp 1, beq 1, cmp 1, beq 1, cmp 1, bne taken 4, bl 4,
    // SAMPLE_B 5, adds 1, b 4) is 30 cycles, 12 instructions; the tail samples B and returns, so
    // the body's way out is charged: 3 + 14 + 6 + 4 + 5 + 4 + 6 + 30 = 72 cycles,
    // 1 + 5 + 3 + 1 + 2 + 1 + 1 + 12 = 26 instructions.
    assert_eq!(
        (
            b.group.as_str(),
            b.cycles,
            b.instructions,
            b.declined.as_deref()
        ),
        ("b", 72, 26, None)
    );
}

#[test]
fn a_function_that_returns_is_charged_whatever_its_name() {
    // The callee where the count runs out is named like a panic (`..._failed`, as DiWheelDrive's
    // `floor_failed` is) but returns (`bx lr`): read from its code, the call goes on, so the
    // header's way out is charged as with `helper`: 67 cycles, 39 instructions (taken by its name
    // for a panic, the way out was left out: 51 and 32).
    let named = find(CALL, ("amiro_firmware::sensors::report_failed", RETURN));
    assert_eq!(bound(&named), (67, 39, None));
    // And a firmware function that cannot return, whatever its name, is known from its code: a
    // dead end as a panic is, 51 cycles, 32 instructions.
    let halts = find(CALL, ("amiro_firmware::halt", SPIN));
    assert_eq!(bound(&halts), (51, 32, None));
}

/// `checked`: `if r0 != 0 { if r1 >= 8 { panic } r0 += 2 }` as a predicated call: `cbz r0` past
/// it all, `cmp r1, #8; it hs; blhs core::panicking::panic`, two adds, the return.
fn predicated_panic() -> Image {
    let code = [
        0xb580, // 0x00 push {r7, lr}: 1 + 2
        0xb128, // 0x02 cbz r0, 0x10: 1, taken + P
        0x2908, // 0x04 cmp r1, #8: 1
        0xbf28, // 0x06 it hs: 1
        0xf000, 0xf804, // 0x08 blhs 0x14: 1 + P (charged taken or not)
        0x3001, // 0x0c adds r0, #1: 1
        0x3001, // 0x0e adds r0, #1: 1
        0xbd80, // 0x10 pop {r7, pc}: 1 + 2 + P
        0xbf00, // 0x12
        SPIN,   // 0x14 core::panicking::panic: b .
    ];
    let symbols = [
        Sym::function("checked", 0, 0x12),
        Sym::function("core::panicking::panic", 0x14, 2),
    ];
    Image::parse(&elf(&thumb(&code), &symbols)).expect("the test image parses")
}

#[test]
fn a_conditional_call_of_a_panic_goes_on_when_skipped() {
    // With r0 ≠ 0 and r1 < 8 the `blhs` is skipped and the adds run: push 3, cbz 1, cmp 1, it 1,
    // blhs 4, adds 1, adds 1, pop 6 = 18 cycles, 8 instructions. Ending the path at the call
    // left only the cbz taken: 3 + 1 + 3 + 6 = 13 cycles, 3 instructions.
    let b = bound_function(
        &predicated_panic(),
        "checked",
        F103_0WS,
        &BoundsFile::default(),
    )
    .expect("the function is analysed");
    assert_eq!((b.cycles, b.instructions, b.declined), (18, 8, None));
}

/// `nested`: `for i in 0..3 { for j in 0..4 { if r2 == 7 { return } .. } r3 += 1 }`: the inner
/// loop's count runs out into a block whose only way on is the outer loop's back edge, from whose
/// header the function returns; its body's way out returns at once.
fn nested() -> Image {
    let code = [
        0xb580, // 0x00 push {r7, lr}: 1 + 2
        0x2000, // 0x02 movs r0, #0: 1
        0x2803, // 0x04 cmp r0, #3: 1 (the outer header: 4 runs, 3 on past it)
        0xd00a, // 0x06 beq 0x1e: 1, taken 1 + P
        0x2100, // 0x08 movs r1, #0: 1
        0x2904, // 0x0a cmp r1, #4: 1 (the inner header: 5 runs, 4 on past it)
        0xd004, // 0x0c beq 0x18: 1, taken 1 + P (the count's way out, to the outer latch)
        0x3201, // 0x0e adds r2, #1: 1
        0x2a07, // 0x10 cmp r2, #7: 1
        0xd004, // 0x12 beq 0x1e: 1, taken 1 + P (the body's way out, to the return)
        0x3101, // 0x14 adds r1, #1: 1
        0xe7f8, // 0x16 b 0x0a: 1 + P
        0x3301, // 0x18 adds r3, #1: 1
        0x3001, // 0x1a adds r0, #1: 1
        0xe7f2, // 0x1c b 0x04: 1 + P
        0xbd80, // 0x1e pop {r7, pc}: 1 + 2 + P
    ];
    Image::parse(&elf(&thumb(&code), &[Sym::function("nested", 0, 0x20)]))
        .expect("the test image parses")
}

#[test]
fn an_inner_way_out_that_returns_through_the_outer_back_edge_is_charged() {
    // The inner loop: an iteration (cmp, beq, adds, cmp, beq, adds, b) 10 cycles, 7 instructions;
    // the count's way out (cmp, beq taken) 5 cycles, 2 instructions, after 4 passes: 45 cycles,
    // 30 instructions; the body's (cmp, beq, adds, cmp, beq taken) 8 cycles, 5 instructions,
    // after 3: 38, 26. The count's way out reaches a return only through the outer back edge,
    // and is charged: the outer iteration (cmp, beq, movs, the inner loop's 45, adds, adds, b)
    // 2 + 1 + 45 + 6 = 54 cycles, 2 + 1 + 30 + 3 = 36 instructions; the outer count's way out
    // (cmp, beq taken) 5 cycles, 2 instructions, after 3 passes: 167 cycles, 110 instructions;
    // with the push and movs (4, 2) and the pop (6, 1): 177 cycles, 113 instructions. (Its body's
    // way out, through the inner one, after 2 passes is 108 + 48 = 156.) Were that way out taken
    // for one that cannot return, the inner loop would be its body's way out alone and the outer
    // loop no loop: 51 cycles.
    let b = bound_function(&nested(), "nested", F103_0WS, &BoundsFile::default())
        .expect("the function is analysed");
    assert_eq!((b.cycles, b.instructions, b.declined), (177, 113, None));
}
