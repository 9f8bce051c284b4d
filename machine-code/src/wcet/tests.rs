//! Known answers: hand-assembled Thumb-2 in small ELF images, each bound worked out from the
//! Cortex-M3 TRM's cycle table (ARM DDI 0337, table 18-1: data processing 1, LDR 2, STR 2,
//! LDM/STM/PUSH/POP 1 + N, a taken branch 1 + P with P = 3 here, BL 1 + P, TBB 2 + P) and the memory
//! system of the F103 (flash lines of 8 bytes at `w` wait states: a line costs w + 1 cycles, a data
//! read from flash w more, a taken branch w more for its first line; an AHB peripheral access 1
//! more).
use super::*;
use crate::testelf::{elf, Sym};
use crate::thumb;

const F103_0WS: Chip = Chip::Stm32f103 { wait_states: 0 };
const F103_2WS: Chip = Chip::Stm32f103 { wait_states: 2 };

fn image(code: &[u16], symbols: &[Sym]) -> Image {
    Image::parse(&elf(&thumb(code), symbols)).expect("the test image parses")
}

fn bound(image: &Image, f: &str, chip: Chip) -> Bound {
    bound_function(image, f, chip, &BoundsFile::default()).expect("the function is analysed")
}

/// A bound's cycles, instructions and declined reason, to compare at once.
fn figures(b: &Bound) -> (u64, u64, Option<&str>) {
    (b.cycles, b.instructions, b.declined.as_deref())
}

#[test]
fn straight_line_code() {
    let img = image(
        &[
            0x4801, // 0x00 ldr r0, [pc, #4]: the literal at 0x08, from flash: 2 + w
            0x6801, // 0x02 ldr r1, [r0]: RCC (0x4002_1000, AHB): 2 + 1
            0x9100, // 0x04 str r1, [sp]: the stack, RAM: 2
            0x4770, // 0x06 bx lr: 1 + P + w
            0x1000, 0x4002, // 0x08 .word 0x40021000
        ],
        &[Sym::function("straight", 0, 12), Sym::data(8)],
    );
    // 0 wait states: 2 + 3 + 2 + 4 = 11 (one flash line fetched: 1 cycle, hidden).
    let b = bound(&img, "straight", F103_0WS);
    assert_eq!(figures(&b), (11, 4, None));
    // 2 wait states: (2 + 2) + 3 + 2 + (4 + 2) = 15; the line costs 3, hidden.
    let b = bound(&img, "straight", F103_2WS);
    assert_eq!((b.cycles, b.instructions), (15, 4));
    assert_eq!(b.bus_wait_ns, 0);
}

#[test]
fn a_counted_loop_runs_exactly_its_count() {
    let img = image(
        &[
            0x2000, // 0x00 movs r0, #0: 1
            0x2300, // 0x02 movs r3, #0: 1
            0x18c0, // 0x04 adds r0, r0, r3: 1   (the loop: 8 passes)
            0x3301, // 0x06 adds r3, #1: 1
            0x2b08, // 0x08 cmp r3, #8: 1
            0xd1fb, // 0x0a bne 0x04: 1, taken + P
            0x4770, // 0x0c bx lr: 1 + P
        ],
        &[Sym::function("sum8", 0, 14)],
    );
    let b = bound(&img, "sum8", F103_0WS);
    // Instructions: 2 + 8 × 4 + 1 = 35, exactly what runs.
    assert_eq!(b.instructions, 35);
    // Cycles: 2 before; 8 passes of 4 and 7 branches back of P = 3; bx lr 4: 2 + 32 + 21 + 4 = 59.
    assert_eq!(b.cycles, 59);
    assert_eq!(b.loops.len(), 1);
    assert_eq!(b.loops[0].bound, 8);
    assert!(b.loops[0].source.starts_with("counted"), "{:?}", b.loops[0]);
}

#[test]
fn a_call_adds_the_callee() {
    let img = image(
        &[
            0xb580, // 0x00 push {r7, lr}: 1 + 2
            0xf000, 0xf803, // 0x02 bl 0x0c: 1 + P
            0xbd80, // 0x06 pop {r7, pc}: 1 + 2 + P
            0xbf00, 0xbf00, // 0x08 (no function)
            0x2005, // 0x0c movs r0, #5: 1
            0x4770, // 0x0e bx lr: 1 + P
        ],
        &[
            Sym::function("caller", 0, 8),
            Sym::function("callee", 0x0c, 4),
        ],
    );
    let callee = bound(&img, "callee", F103_0WS);
    assert_eq!((callee.cycles, callee.instructions), (5, 2));
    // 3 + 4 + (callee 5) + 6 = 18 cycles; 3 + 2 instructions.
    let b = bound(&img, "caller", F103_0WS);
    assert_eq!(figures(&b), (18, 5, None));
}

#[test]
fn a_jump_table_takes_its_longest_case() {
    let img = image(
        &[
            0x2802, // 0x00 cmp r0, #2: 1
            0xd80b, // 0x02 bhi 0x1c: 1 (taken: + P)
            0xe8df, 0xf000, // 0x04 tbb [pc, r0]: 2 + P
            0x0402, 0x0008, // 0x08 the table: 2, 4, 8 (and a byte of padding)
            0x200a, // 0x0c case 0: movs r0, #10
            0x4770, // 0x0e bx lr
            0x2014, // 0x10 case 1: movs r0, #20
            0x3001, // 0x12 adds r0, #1
            0x3001, // 0x14 adds r0, #1
            0x4770, // 0x16 bx lr
            0x201e, // 0x18 case 2: movs r0, #30
            0x4770, // 0x1a bx lr
            0x2000, // 0x1c default: movs r0, #0
            0x4770, // 0x1e bx lr
        ],
        &[
            Sym::function("dispatch", 0, 0x20),
            Sym::data(0x08),
            Sym::code(0x0c),
        ],
    );
    let b = bound(&img, "dispatch", F103_0WS);
    // Case 1 is the longest: 2 (cmp, bhi not taken) + 5 (tbb) + 1 + 1 + 1 + 4 = 14 cycles, 7
    // instructions; the default costs 2 + 3 + 1 + 4 = 10.
    assert_eq!(figures(&b), (14, 7, None));
}

#[test]
fn a_jump_table_without_a_bound_check_ends_at_its_first_entry_that_is_no_instruction() {
    // The compiler knew the index's range (a byte-sized discriminant): no `cmp` before the table,
    // whose data runs on into a literal pool.
    let img = image(
        &[
            0x7800, // 0x00 ldrb r0, [r0]
            0xe8df, 0xf000, // 0x02 tbb [pc, r0]
            0x0503, // 0x06 the table: 3, 5 (cases at 0x0c and 0x10)
            0xffff, 0xffff, // 0x08 a literal: entries 0xff, which lead out of the function
            0x200a, // 0x0c case 0: movs r0, #10
            0x4770, // 0x0e bx lr
            0x2014, // 0x10 case 1: movs r0, #20
            0x3001, // 0x12 adds r0, #1
            0x4770, // 0x14 bx lr
        ],
        &[
            Sym::function("unchecked", 0, 0x16),
            Sym::data(0x06),
            Sym::code(0x0c),
        ],
    );
    let b = bound(&img, "unchecked", F103_0WS);
    // Case 1 is the longest: ldrb, tbb, movs, adds, bx lr.
    assert_eq!((b.instructions, b.declined.as_deref()), (5, None));
}

#[test]
fn a_loop_without_a_bound_is_declined_by_name() {
    let img = image(
        &[
            0x6801, // 0x00 ldr r1, [r0]
            0x2900, // 0x02 cmp r1, #0
            0xd1fc, // 0x04 bne 0x00
            0x4770, // 0x06 bx lr
        ],
        &[Sym::function("spin", 0, 8)],
    );
    let b = bound(&img, "spin", F103_2WS);
    let reason = b.declined.expect("declined");
    assert!(
        reason.contains("loop in spin") && reason.contains("no bound"),
        "{reason}"
    );
    assert_eq!((b.cycles, b.instructions), (0, 0));
}

#[test]
fn an_indirect_call_is_declined_and_so_is_its_caller() {
    let img = image(
        &[
            0xb580, // 0x00 push {r7, lr}
            0x4798, // 0x02 blx r3
            0xbd80, // 0x04 pop {r7, pc}
            0xbf00, // 0x06
            0xb580, // 0x08 push {r7, lr}
            0xf7ff, 0xfff9, // 0x0a bl 0x00
            0xbd80, // 0x0e pop {r7, pc}
        ],
        &[
            Sym::function("through_register", 0, 6),
            Sym::function("outer", 8, 8),
        ],
    );
    let b = bound(&img, "through_register", F103_0WS);
    let reason = b.declined.expect("declined");
    assert!(reason.contains("call through a register"), "{reason}");
    let outer = bound(&img, "outer", F103_0WS);
    assert!(outer
        .declined
        .expect("declined")
        .starts_with("via through_register"));
}

#[test]
fn recursion_is_declined() {
    let img = image(
        &[
            0xb580, // 0x00 push {r7, lr}
            0xf7ff, 0xfffd, // 0x02 bl 0x00
            0xbd80, // 0x06 pop {r7, pc}
        ],
        &[Sym::function("again", 0, 8)],
    );
    let reason = bound(&img, "again", F103_0WS).declined.expect("declined");
    assert!(reason.contains("recursion"), "{reason}");
}

#[test]
fn a_path_into_a_panic_does_not_complete_the_job() {
    let img = image(
        &[
            0x2800, // 0x00 cmp r0, #0: 1
            0xd001, // 0x02 beq 0x08: 1 (+ P)
            0xf000, 0xf803, // 0x04 bl 0x0e (the panic)
            0x2001, // 0x08 movs r0, #1: 1
            0x4770, // 0x0a bx lr: 4
            0xbf00, // 0x0c
            0xe7fe, // 0x0e b 0x0e: the panic spins for ever
        ],
        &[
            Sym::function("checked", 0, 0x0c),
            Sym::function("core::panicking::panic_bounds_check", 0x0e, 2),
        ],
    );
    // Only the path that returns: 1 + 1 + P + 1 + 4 = 10.
    let b = bound(&img, "checked", F103_0WS);
    assert_eq!(figures(&b), (10, 4, None));
}

/// `latch` calls `write`, which makes the breakpoint call `bkpt` (`0xBEAB`: a semihosting call, as
/// the QEMU builds write their console; `0xBE00`: a breakpoint) and returns.
fn breakpoint_call(bkpt: u16) -> Image {
    image(
        &[
            0xb580, // 0x00 push {r7, lr}: 3
            0xf000, 0xf802, // 0x02 bl 0x0a: 1 + P
            0xbd80, // 0x06 pop {r7, pc}: 1 + 2 + P
            0xbf00, // 0x08
            0x2005, // 0x0a movs r0, #5: 1
            bkpt,   // 0x0c bkpt: 1
            0x4770, // 0x0e bx lr: 1 + P
        ],
        &[
            Sym::function("latch", 0, 8),
            Sym::function("write", 0x0a, 6),
        ],
    )
}

#[test]
fn a_semihosting_call_returns_and_a_breakpoint_does_not() {
    // The host performs a semihosting call and the code goes on: 3 + 4 + 1 + 1 + 4 + 6 = 19
    // cycles, 6 instructions.
    let b = bound(&breakpoint_call(0xbeab), "latch", F103_0WS);
    assert_eq!(figures(&b), (19, 6, None));
    // Any other breakpoint stops the core: no path of `write`, nor of `latch`, returns.
    let b = bound(&breakpoint_call(0xbe00), "latch", F103_0WS);
    assert!(
        b.declined
            .as_deref()
            .is_some_and(|r| r.contains("never returns")),
        "{b:?}"
    );
}

#[test]
fn bad_input_is_a_typed_error() {
    assert!(matches!(
        Image::parse(b"not an elf"),
        Err(Error::Malformed(_))
    ));
    assert!(matches!(
        Image::parse(&[0x7f, b'E', b'L', b'F', 1, 1, 1]),
        Err(Error::Malformed(_))
    ));
    let img = image(&[0x4770], &[Sym::function("ret", 0, 2)]);
    assert!(matches!(
        bound_function(&img, "missing", F103_0WS, &BoundsFile::default()),
        Err(Error::MissingSymbol(_))
    ));
    // The first half of a BL with nothing behind it.
    let cut = image(&[0x4770, 0xf000], &[Sym::function("cut", 0, 4)]);
    assert!(matches!(
        bound_function(&cut, "cut", F103_0WS, &BoundsFile::default()),
        Err(Error::Undecodable { address: 2, .. })
    ));
    // A table branch without its table.
    let table = image(&[0xe8df, 0xf000, 0x4770], &[Sym::function("tbl", 0, 6)]);
    assert!(matches!(
        bound_function(&table, "tbl", F103_0WS, &BoundsFile::default()),
        Err(Error::Unfollowable { .. })
    ));
    assert!(matches!(Chip::parse("stm32f7", None), Err(Error::Other(_))));
}

#[test]
fn a_stated_wait_is_kept_apart_from_the_cycles() {
    use path::{longest, LoopNodes, Node};
    // A header (3 cycles, 3 instructions) that loops on itself and leaves to a return (4, 1).
    let nodes = vec![
        Node {
            cost: Cost {
                cycles: 3,
                instructions: 3,
                wait_ns: 0,
            },
            succs: vec![
                (
                    0,
                    Cost {
                        cycles: 3,
                        ..Cost::default()
                    },
                ),
                (1, Cost::default()),
            ],
            exit: false,
            exit_cost: Cost::default(),
        },
        Node {
            cost: Cost {
                cycles: 4,
                instructions: 1,
                wait_ns: 0,
            },
            succs: vec![],
            exit: true,
            exit_cost: Cost::default(),
        },
    ];
    let wait = [LoopNodes {
        header: 0,
        body: [0].into(),
        count: LoopCount::Wait {
            ns: 25_000,
            cycles: 1800,
        },
    }];
    let c = longest(nodes.clone(), &wait, &|c: Cost| c.cycles)
        .unwrap()
        .path;
    // One pass out (3) and the return (4); the 25 µs stated apart, at most one instruction per
    // cycle of it.
    assert_eq!(
        c,
        Cost {
            cycles: 7,
            instructions: 1 + 3 + 1800,
            wait_ns: 25_000
        }
    );
    let passes = [LoopNodes {
        header: 0,
        body: [0].into(),
        count: LoopCount::Passes(5),
    }];
    // Four passes back (3 + 3 each) and one out (3), then the return: 24 + 3 + 4.
    let c = longest(nodes, &passes, &|c: Cost| c.cycles).unwrap().path;
    assert_eq!((c.cycles, c.instructions), (31, 16));
}

#[test]
fn passes_on_past_the_header_bound_the_body_apart_from_the_header() {
    use path::{longest, LoopNodes, Node};
    let cycles = |c: u64| Cost {
        cycles: c,
        ..Cost::default()
    };
    let node = |cost: u64, succs: Vec<(usize, Cost)>, exit: bool| Node {
        cost: cycles(cost),
        succs,
        exit,
        exit_cost: Cost::default(),
    };
    // Header 0 (3 cycles): back to itself (+3), into the body 1, or out to 2. Body 1 (10): back (+3)
    // or out (+3). The return 2 (4).
    let nodes = vec![
        node(
            3,
            vec![(0, cycles(3)), (1, cycles(0)), (2, cycles(0))],
            false,
        ),
        node(10, vec![(0, cycles(3)), (2, cycles(3))], false),
        node(4, vec![], true),
    ];
    let path = |count| {
        let l = [LoopNodes {
            header: 0,
            body: [0, 1].into(),
            count,
        }];
        longest(nodes.clone(), &l, &|c: Cost| c.cycles)
            .unwrap()
            .path
            .cycles
    };
    // A pass back through the body 3 + 10 + 3 = 16, one in the header 3 + 3 = 6; the way out from
    // the header 3, from the body 3 + 10 + 3 = 16. 5 header runs, 2 passes on past it: 3 in the
    // header, 1 through the body and the body's way out (18 + 16 + 16 = 50), or 2 through the body,
    // 2 in the header and the header's way out (32 + 12 + 3 = 47); then the return: 54.
    assert_eq!(path(LoopCount::Body { header: 5, body: 2 }), 54);
    // The header's count alone: 4 passes back through the body and its way out, 64 + 16 + 4.
    assert_eq!(path(LoopCount::Passes(5)), 84);
    // No pass on past the header: 4 in the header and its way out, 24 + 3 + 4.
    assert_eq!(path(LoopCount::Body { header: 5, body: 0 }), 31);
}

/// `spin` of [`a_loop_without_a_bound_is_declined_by_name`], its loop at src/spin.rs:7, its
/// return at line 9.
fn spin_with_lines() -> Image {
    let code = thumb(&[
        0x6801, // 0x00 ldr r1, [r0]: 2 + 5 (an unknown base: APB1, the slowest)
        0x2900, // 0x02 cmp r1, #0: 1
        0xd1fc, // 0x04 bne 0x00: 1, taken + P
        0x4770, // 0x06 bx lr: 1 + P
    ]);
    let bytes = crate::testelf::elf_with_lines(
        &code,
        &[Sym::function("spin", 0, 8)],
        "firmware/src/spin.rs",
        &[(0, 7), (6, 9)],
    );
    Image::parse(&bytes).expect("the test image parses")
}

#[test]
fn the_line_table_names_the_loop() {
    let img = spin_with_lines();
    assert_eq!(
        img.line(4),
        Some(("/work/firmware/src/spin.rs".to_string(), 7))
    );
    let reason = bound(&img, "spin", F103_0WS).declined.expect("declined");
    assert!(reason.contains("spin.rs:7"), "{reason}");
}

#[test]
fn a_stated_loop_bound_is_used() {
    let img = spin_with_lines();
    let bounds = BoundsFile::parse(
        r#"{"loops":[{"function":"spin","file":"src/spin.rs","line":7,"bound":10,"reason":"ten polls at most"}]}"#,
    )
    .unwrap();
    let b = bound_function(&img, "spin", F103_0WS, &bounds).unwrap();
    // A pass: 7 + 1 + 1 = 9; 9 passes back (9 + P each) and one out (9), then bx lr (4):
    // 9 × 12 + 9 + 4 = 121 cycles; 10 × 3 + 1 = 31 instructions.
    assert_eq!(figures(&b), (121, 31, None));
    assert_eq!(b.loops[0].bound, 10);
    assert_eq!(b.loops[0].line, Some(7));
    assert_eq!(b.loops[0].source, "bounds file: ten polls at most");
    // A line that is not the loop's is no bound for it.
    let elsewhere = BoundsFile::parse(
        r#"{"loops":[{"function":"spin","file":"src/spin.rs","line":9,"bound":10,"reason":"x"}]}"#,
    )
    .unwrap();
    let b = bound_function(&img, "spin", F103_0WS, &elsewhere).unwrap();
    assert!(b.declined.is_some());
}

#[test]
fn a_stated_peripheral_wait_is_kept_apart() {
    let img = spin_with_lines();
    let bounds = BoundsFile::parse(
        r#"{"waits":[{"function":"spin","file":"src/spin.rs","line":7,"wait_us":22.5,"source":"one I2C byte at 400 kHz"}]}"#,
    )
    .unwrap();
    let b = bound_function(&img, "spin", F103_0WS, &bounds).unwrap();
    // One pass out (9) and the return (4) in cycles; 22.5 µs stated apart; instructions: the pass
    // (3), at most one a cycle of the wait (22.5 µs × 72 MHz = 1620), the return (1).
    assert_eq!(
        (b.cycles, b.bus_wait_ns, b.instructions),
        (13, 22_500, 1624)
    );
    assert!((b.us(F103_0WS) - (13.0 / 72.0 + 22.5)).abs() < 0.01);
}

#[test]
fn stated_targets_resolve_an_indirect_call() {
    let code = thumb(&[
        0xb580, // 0x00 push {r7, lr}: 3
        0x4798, // 0x02 blx r3: 1 + P
        0xbd80, // 0x04 pop {r7, pc}: 1 + 2 + P
        0xbf00, // 0x06
        0x2005, // 0x08 movs r0, #5: 1 (one target)
        0x4770, // 0x0a bx lr: 4
        0x3001, // 0x0c adds r0, #1: 1 (the other, longer)
        0x3001, // 0x0e adds r0, #1: 1
        0x4770, // 0x10 bx lr: 4
    ]);
    let bytes = crate::testelf::elf_with_lines(
        &code,
        &[
            Sym::function("through_register", 0, 6),
            // Two functions of one name (as closures' shims are once the hash is gone).
            Sym::function("handler", 8, 4),
            Sym::function("handler", 0x0c, 6),
        ],
        "firmware/src/call.rs",
        &[(0, 2), (2, 3), (4, 4)],
    );
    let img = Image::parse(&bytes).unwrap();
    let bounds = BoundsFile::parse(
        r#"{"indirect":[{"function":"through_register","file":"src/call.rs","line":3,"targets":["handler"],"reason":"both functions named handler"}]}"#,
    )
    .unwrap();
    let b = bound_function(&img, "through_register", F103_0WS, &bounds).unwrap();
    // A name stands for every function of it: 3 + 4 + (the longer: 6) + 6 = 19 cycles; 3 + 3
    // instructions.
    assert_eq!(figures(&b), (19, 6, None));
    let unknown = BoundsFile::parse(
        r#"{"indirect":[{"function":"through_register","file":"src/call.rs","line":3,"targets":["gone"],"reason":"x"}]}"#,
    )
    .unwrap();
    assert!(matches!(
        bound_function(&img, "through_register", F103_0WS, &unknown),
        Err(Error::Bounds(_))
    ));
}

/// A waker's clone as LLVM's machine outliner leaves it (the boards' QEMU images: `Delay::poll`'s
/// `cx.waker().clone()`): `poll` calls `OUTLINED_FUNCTION_0`, which loads the waker's vtable and
/// data and tail-calls the vtable's first entry through a register. The helper's code has no line
/// (rows of line 0), and neither has the call (LLVM marks it line 0): the call is keyed at the line
/// before it in `poll`, src/poll.rs:10. `VTABLE` holds `clone`.
fn outlined_waker_clone() -> Image {
    let code = thumb(&[
        0xb580, // 0x00 push {r7, lr}: 3                     line 10
        0xf000, 0xf803, // 0x02 bl 0x0c: 1 + P               line 0
        0xbd80, // 0x06 pop {r7, pc}: 1 + 2 + P              line 12
        0x2005, // 0x08 clone: movs r0, #5: 1                line 20
        0x4770, // 0x0a bx lr: 1 + P
        0xe9d6, 0x1000, // 0x0c ldrd r1, r0, [r6]: 1 + 2     line 0
        0x6809, // 0x10 ldr r1, [r1]: 2
        0x4708, // 0x12 bx r1: 1 + P (a tail call through a register)
        0x0009, 0x0000, // 0x14 VTABLE: clone's address, Thumb bit set
    ]);
    let bytes = crate::testelf::elf_with_lines(
        &code,
        &[
            Sym::function("poll", 0, 8),
            Sym::function("clone", 8, 4),
            Sym::function("OUTLINED_FUNCTION_0", 0x0c, 8),
            Sym::data(0x14),
            Sym::object("VTABLE", 0x14, 4),
        ],
        "firmware/src/poll.rs",
        &[(0, 10), (2, 0), (6, 12), (8, 20), (0x0c, 0)],
    );
    Image::parse(&bytes).expect("the test image parses")
}

#[test]
fn an_outlined_helpers_indirect_call_is_keyed_at_its_call_site() {
    let img = outlined_waker_clone();
    // Neither the helper's call through a register nor the call of the helper has a line.
    assert_eq!(img.line(0x12), None);
    assert_eq!(img.line(0x02), None);
    assert_eq!(
        img.line(0x00),
        Some(("/work/firmware/src/poll.rs".into(), 10))
    );
    // Not stated: declined, naming the place a statement would go.
    let plain = bound(&img, "poll", F103_0WS);
    let reason = plain.declined.expect("declined");
    assert!(
        reason.starts_with(
            "via OUTLINED_FUNCTION_0: the call through a register in OUTLINED_FUNCTION_0"
        ) && reason.contains("keyed at its call in poll at /work/firmware/src/poll.rs:10")
            && reason.ends_with("has no stated targets"),
        "{reason}"
    );
    // Stated at the call site: poll 3 + bl 4, the helper's ldrd 3 + ldr 2 + bx 4, clone's movs 1 +
    // bx lr 4, pop 6: 27 cycles on the core; the helper's loads through registers of unknown value
    // each word an APB1 access at worst (the F103's 2 APB cycles at half the clock + 1: 5), 3 words:
    // 15 more: 42 cycles; 8 instructions. Named, or as the vtable's entry 0 (the image gives the
    // function), alike.
    for stated in [
        r#""targets":["clone"]"#,
        r#""vtable_entry":{"objects":["VTABLE"],"entry":0}"#,
    ] {
        let bounds = BoundsFile::parse(&format!(
            r#"{{"indirect":[{{"function":"poll","file":"src/poll.rs","line":10,{stated},"reason":"the only vtable's clone"}}]}}"#
        ))
        .unwrap();
        let b = bound_function(&img, "poll", F103_0WS, &bounds).unwrap();
        assert_eq!(figures(&b), (42, 8, None), "{stated}");
    }
    // Stated at another line of poll (after the call), or for the helper itself: declined as before.
    for (function, line) in [("poll", 12), ("OUTLINED_FUNCTION_0", 10)] {
        let bounds = BoundsFile::parse(&format!(
            r#"{{"indirect":[{{"function":"{function}","file":"src/poll.rs","line":{line},"targets":["clone"],"reason":"x"}}]}}"#
        ))
        .unwrap();
        let b = bound_function(&img, "poll", F103_0WS, &bounds).unwrap();
        assert!(
            b.declined
                .as_deref()
                .is_some_and(|r| r.contains("has no stated targets")),
            "{function}:{line}: {b:?}"
        );
    }
    // The helper bounded alone has no call site: declined.
    let bounds = BoundsFile::parse(
        r#"{"indirect":[{"function":"poll","file":"src/poll.rs","line":10,"targets":["clone"],"reason":"x"}]}"#,
    )
    .unwrap();
    let alone = bound_function(&img, "OUTLINED_FUNCTION_0", F103_0WS, &bounds).unwrap();
    assert!(alone.declined.is_some(), "{alone:?}");
    // A vtable entry that holds no function's address is an error of the bounds file, as a missing
    // target is.
    let bad = BoundsFile::parse(
        r#"{"indirect":[{"function":"poll","file":"src/poll.rs","line":10,"vtable_entry":{"objects":["VTABLE"],"entry":1},"reason":"x"}]}"#,
    )
    .unwrap();
    assert!(matches!(
        bound_function(&img, "poll", F103_0WS, &bad),
        Err(Error::Bounds(_))
    ));
}

#[test]
fn a_stated_target_names_a_function_the_linker_folded_into_another() {
    // `waker_drop` and `pre_init` are one empty function (identical code folded to one address, as
    // the QEMU images' `rtic::export::executor::waker_drop`); its first symbol names it.
    let code = thumb(&[
        0xb580, // 0x00 push {r7, lr}: 3
        0x4798, // 0x02 blx r3: 1 + P
        0xbd80, // 0x04 pop {r7, pc}: 1 + 2 + P
        0xbf00, // 0x06
        0x4770, // 0x08 bx lr: 1 + P
    ]);
    let bytes = crate::testelf::elf_with_lines(
        &code,
        &[
            Sym::function("through_register", 0, 6),
            Sym::function("pre_init", 8, 2),
            Sym::function("waker_drop", 8, 2),
        ],
        "firmware/src/call.rs",
        &[(0, 2), (2, 3), (4, 4)],
    );
    let img = Image::parse(&bytes).unwrap();
    assert_eq!(img.name(8), "pre_init");
    assert_eq!(
        img.starts_named("waker_drop")
            .into_iter()
            .collect::<Vec<_>>(),
        [8]
    );
    let bounds = BoundsFile::parse(
        r#"{"indirect":[{"function":"through_register","file":"src/call.rs","line":3,"targets":["waker_drop"],"reason":"the vtable's drop"}]}"#,
    )
    .unwrap();
    // 3 + 4 + 4 + 6 = 17 cycles, 4 instructions.
    let b = bound_function(&img, "through_register", F103_0WS, &bounds).unwrap();
    assert_eq!(figures(&b), (17, 4, None));
}

#[test]
fn an_exclusive_retry_costs_one_pass_and_one_iteration_per_preemption() {
    let img = image(
        &[
            0xe850, 0x1f00, // 0x00 ldrex r1, [r0]: 2 + 5 (an unknown base: APB1)
            0x3101, // 0x04 adds r1, #1: 1
            0xe840, 0x1200, // 0x06 strex r2, r1, [r0]: 2 + 5
            0x2a00, // 0x0a cmp r2, #0: 1
            0xd1f8, // 0x0c bne 0x00: 1 (+ P back, when the store failed)
            0x4770, // 0x0e bx lr: 4
        ],
        &[Sym::function("fetch_add", 0, 16)],
    );
    let b = bound(&img, "fetch_add", F103_0WS);
    // One pass (17) and the return (4); a preemption inside adds one iteration (17 + P).
    assert_eq!(figures(&b), (21, 6, None));
    assert_eq!((b.retry_cycles, b.retry_instructions), (20, 5));
    assert!(b.loops[0].source.starts_with("exclusive retry"));
    // As a hardware task: entry 12, return 10, and the retry it may cause a preempted job (the
    // largest of any task's: its own here).
    let rows = bound_tasks(
        &img,
        &[Task {
            name: "h".into(),
            entry: TaskEntry::Symbol("fetch_add".into()),
            handler: true,
        }],
        F103_0WS,
        &BoundsFile::default(),
    );
    assert_eq!(
        (
            rows[0].cycles,
            rows[0].instructions,
            rows[0].preemption_retry_cycles
        ),
        (21 + 22 + 20, 6 + 5, 20)
    );
    // A missing handler is a declined row, not an error.
    let rows = bound_tasks(
        &img,
        &[Task {
            name: "gone".into(),
            entry: TaskEntry::Vector(40),
            handler: true,
        }],
        F103_0WS,
        &BoundsFile::default(),
    );
    assert!(rows[0]
        .declined
        .as_deref()
        .is_some_and(|r| r.contains("vector 40")));
}

#[test]
fn cbz_has_both_ways_and_each_figure_its_own_longest_path() {
    let img = image(
        &[
            0xb108, // 0x00 cbz r0, 0x06: 1 (+ P taken)
            0x2001, // 0x02 movs r0, #1: 1
            0x3002, // 0x04 adds r0, #2: 1
            0x4770, // 0x06 bx lr: 1 + P
        ],
        &[Sym::function("maybe", 0, 8)],
    );
    let b = bound(&img, "maybe", F103_0WS);
    // Taken: 1 + P + 4 = 8 cycles (3 instructions); not taken: 1 + 1 + 1 + 4 = 7 cycles (4
    // instructions). Each figure is the largest of any path.
    assert_eq!((b.cycles, b.instructions), (8, 4));
}

#[test]
fn a_conditional_tail_call_pays_its_refill() {
    let img = image(
        &[
            0x2800, // 0x00 cmp r0, #0: 1
            0xd001, // 0x02 beq 0x08 (the other function): 1, + P taken
            0x4770, // 0x04 bx lr: 4
            0xbf00, // 0x06
            0x2005, // 0x08 movs r0, #5: 1
            0x4770, // 0x0a bx lr: 4
        ],
        &[Sym::function("early", 0, 6), Sym::function("late", 8, 4)],
    );
    // Into `late`: 1 + 1 + P + (1 + 4) = 10 cycles, 4 instructions.
    let b = bound(&img, "early", F103_0WS);
    assert_eq!((b.cycles, b.instructions), (10, 4));
}

#[test]
fn a_step_inside_an_it_block_is_no_count() {
    let img = image(
        &[
            0x2300, // 0x00 movs r3, #0
            0x2900, // 0x02 cmp r1, #0   (the loop)
            0xbf18, // 0x04 it ne
            0x3301, // 0x06 addne r3, #1: may not run
            0x2b08, // 0x08 cmp r3, #8
            0xd1fa, // 0x0a bne 0x02
            0x4770, // 0x0c bx lr
        ],
        &[Sym::function("maybe_count", 0, 14)],
    );
    let reason = bound(&img, "maybe_count", F103_0WS)
        .declined
        .expect("declined");
    assert!(reason.contains("no bound"), "{reason}");
}

/// An exclusive-access sequence the machine outliner split into two leaf helpers, as in the boards'
/// dispatchers (`LDREXB; CMP r2, #1; BX LR` and `STREXB; CMP r2, #0; BX LR`): still a retry.
fn outlined_retry(store_compare: u16) -> Image {
    image(
        &[
            0xb580, // 0x00 push {r7, lr}
            0x2100, // 0x02 movs r1, #0
            0xf000,
            0xf808, // 0x04 bl 0x18 (the load helper)
            0xd103, // 0x08 bne 0x12: the flag is not 1, give up
            0xf000,
            0xf809, // 0x0a bl 0x20 (the store helper)
            0xd1f9, // 0x0e bne 0x04: the store failed, again
            0xbd80, // 0x10 pop {r7, pc}
            0xf3bf,
            0x8f2f, // 0x12 clrex
            0xbd80, // 0x16 pop {r7, pc}
            0xe8d0,
            0x2f4f, // 0x18 ldrexb r2, [r0]
            0x2a01, // 0x1c cmp r2, #1
            0x4770, // 0x1e bx lr
            0xe8c0,
            0x1f42,        // 0x20 strexb r2, r1, [r0]
            store_compare, // 0x24 cmp r2, #0 (or another register)
            0x4770,        // 0x26 bx lr
        ],
        &[
            Sym::function("take_flag", 0, 0x18),
            Sym::function("OUTLINED_FUNCTION_0", 0x18, 8),
            Sym::function("OUTLINED_FUNCTION_1", 0x20, 8),
        ],
    )
}

#[test]
fn an_outlined_exclusive_retry_is_still_a_retry() {
    let b = bound(&outlined_retry(0x2a00), "take_flag", F103_0WS);
    assert_eq!(b.declined, None);
    // push, movs; the loop collapsed to one whole pass (bl, 3 of the load helper, bne, bl, 3 of the
    // store helper, bne); then its longest way out (clrex, pop): 2 + 10 + 2.
    assert_eq!(b.instructions, 14);
    assert!(b.loops[0].source.starts_with("exclusive retry"));
    // A preemption inside costs one more iteration: bl, 3, bne, bl, 3, bne.
    assert_eq!(b.retry_instructions, 10);
    // The branch back tests another register than the store's status: not a retry, no bound.
    let other = bound(&outlined_retry(0x2900), "take_flag", F103_0WS);
    assert!(
        other
            .declined
            .as_deref()
            .is_some_and(|d| d.contains("has no bound")),
        "{other:?}"
    );
}

#[test]
fn a_loop_tested_at_its_top_is_counted() {
    // for i in 0..3 as rustc compiles it: the header compares and leaves, the latch steps and
    // branches back unconditionally.
    let img = image(
        &[
            0x2300, // 0x00 movs r3, #0
            0x2b03, // 0x02 cmp r3, #3      (header: 4 passes)
            0xd002, // 0x04 beq 0x0c
            0x3001, // 0x06 adds r0, #1     (3 iterations)
            0x3301, // 0x08 adds r3, #1
            0xe7fa, // 0x0a b 0x02
            0x4770, // 0x0c bx lr
        ],
        &[Sym::function("three", 0, 14)],
    );
    let b = bound(&img, "three", F103_0WS);
    // 1 + 4 × (cmp, beq) + 3 × (adds, adds, b) + bx lr = 1 + 8 + 9 + 1: exactly what runs.
    assert_eq!((b.instructions, b.declined.as_deref()), (19, None));
    assert_eq!(b.loops.len(), 1);
    assert_eq!(b.loops[0].bound, 4);
    assert!(b.loops[0].source.starts_with("counted"), "{:?}", b.loops[0]);
}

/// `for _ in 0..4 { ..; if r2 == 7 { break } .. }` as rustc compiles it: the header tests the count
/// and leaves, the body may leave too, the latch steps the count and branches back. `first` is the
/// instruction at 0x00: `movs r0, #0` (the count fixed), or a `nop` (its start unknown).
fn leaves_mid_body(first: u16) -> Image {
    let code = thumb(&[
        first,  // 0x00 movs r0, #0 | nop: 1
        0x2804, // 0x02 cmp r0, #4: 1 (the header: 5 runs)
        0xd005, // 0x04 beq 0x12: 1, taken 1 + P (the count's way out)
        0x3201, // 0x06 adds r2, #1: 1
        0x2a07, // 0x08 cmp r2, #7: 1
        0xd002, // 0x0a beq 0x12: 1, taken 1 + P (the way out from inside the body)
        0x3301, // 0x0c adds r3, #1: 1
        0x3001, // 0x0e adds r0, #1: 1 (the count's step)
        0xe7f7, // 0x10 b 0x02: 1 + P
        0x4770, // 0x12 bx lr: 1 + P
    ]);
    let bytes = crate::testelf::elf_with_lines(
        &code,
        &[Sym::function("leaves", 0, 0x14)],
        "firmware/src/leaves.rs",
        &[(0, 5), (2, 7), (0x12, 9)],
    );
    Image::parse(&bytes).expect("the test image parses")
}

#[test]
fn a_counted_loop_left_from_inside_its_body_is_charged_its_passes_up_to_the_exit() {
    // From the TRM's table at 0 wait states (P = 3): an iteration is cmp, beq, adds, cmp, beq,
    // adds, adds, b: 7 + 4 = 11 cycles, 8 instructions; the way out at the header cmp, beq taken:
    // 1 + 4 = 5 cycles, 2 instructions; the way out from the body cmp, beq, adds, cmp, beq taken:
    // 4 + 4 = 8 cycles, 5 instructions. The header runs at most 5 times and its test leaves on the
    // fifth, so at most 4 passes go on past it: either 4 iterations and the header's way out (44 +
    // 5 = 49 cycles, 34 instructions) or 3 iterations and the body's (33 + 8 = 41, 29). With the
    // movs before (1) and the bx lr after (4): 54 cycles, 36 instructions, exactly the longest run.
    // Charging 4 iterations before the body's way out (a fifth pass into the body, which the count
    // never lets run) would be 57 cycles, 39 instructions.
    let img = leaves_mid_body(0x2000);
    let b = bound(&img, "leaves", F103_0WS);
    assert_eq!(figures(&b), (54, 36, None));
    assert_eq!(b.loops[0].bound, 5);
    assert!(
        b.loops[0].source.starts_with("counted") && b.loops[0].source.contains("at most 4 passes"),
        "{:?}",
        b.loops[0]
    );
    // The same loop with its count's start unknown, stated: 5 header runs alone charge the body's
    // way out after 4 whole passes; 5 runs of which 4 go on past the header, as the count does.
    let img = leaves_mid_body(0xbf00);
    let stated = |body: &str| {
        let file = format!(
            r#"{{"loops":[{{"function":"leaves","file":"src/leaves.rs","line":7,"bound":5{body},"reason":"four elements"}}]}}"#
        );
        bound_function(&img, "leaves", F103_0WS, &BoundsFile::parse(&file).unwrap()).unwrap()
    };
    assert_eq!(figures(&stated("")), (57, 39, None));
    let b = stated(r#","body":4"#);
    assert_eq!(figures(&b), (54, 36, None));
    assert_eq!(
        b.loops[0].source,
        "bounds file, at most 4 passes on past the header: four elements"
    );
}

#[test]
fn a_loop_tested_at_its_bottom_left_from_inside_on_its_last_pass_is_charged_whole_passes() {
    // `loop { ..; if r2 == 7 { break } r0 += 1; if r0 == 4 { break } }`: every pass goes on past the
    // header's own way out, the last one too.
    let img = image(
        &[
            0x2000, // 0x00 movs r0, #0: 1
            0x3201, // 0x02 adds r2, #1: 1 (the header: 4 runs)
            0x2a07, // 0x04 cmp r2, #7: 1
            0xd002, // 0x06 beq 0x0e: 1, taken 1 + P (a way out on any pass)
            0x3001, // 0x08 adds r0, #1: 1
            0x2804, // 0x0a cmp r0, #4: 1
            0xd1f9, // 0x0c bne 0x02: 1, taken 1 + P (the count's branch back)
            0x4770, // 0x0e bx lr: 1 + P
        ],
        &[Sym::function("bottom", 0, 0x10)],
    );
    let b = bound(&img, "bottom", F103_0WS);
    // An iteration: 5 + 4 = 9 cycles, 6 instructions; the way out at the bottom, the whole fourth
    // pass: 6 cycles, 6 instructions (the header's: 2 + 4 = 6 cycles, 3 instructions). 3 iterations
    // and the longer way out, with the movs and the bx lr: 1 + 27 + 6 + 4 = 38 cycles,
    // 1 + 18 + 6 + 1 = 26 instructions: four whole passes, as run.
    assert_eq!(figures(&b), (38, 26, None));
    assert_eq!(b.loops[0].bound, 4);
    assert!(!b.loops[0].source.contains("passes on"), "{:?}", b.loops[0]);
}

/// `__aeabi_memclr` as a byte loop on its length in r1 (16 bytes of code, its branches relative):
/// `movs r2, #0`; header `cmp r1, #0; beq` out; `strb r2, [r0]; adds r0, #1; subs r1, #1; b` header;
/// `bx lr`.
const MEMCLR_BYTES: [u16; 8] = [
    0x2200, 0x2900, 0xd003, 0x7002, 0x3001, 0x3901, 0xe7f9, 0x4770,
];

/// `caller`'s code followed by [`MEMCLR_BYTES`].
fn with_memclr(caller: &[u16]) -> Vec<u16> {
    [caller, &MEMCLR_BYTES[..]].concat()
}

/// Whether `b` is declined for a memory function's length no call fixes.
fn length_unknown(b: &Bound) -> bool {
    b.declined
        .as_deref()
        .is_some_and(|r| r.contains(length::LENGTH_UNKNOWN))
}

/// A caller that clears `n` bytes through `__aeabi_memclr` (a byte loop on its length in r1).
fn clears(n: u16) -> Image {
    clears_through(n, "__aeabi_memclr")
}

/// [`clears`] through a callee named `callee`.
fn clears_through(n: u16, callee: &str) -> Image {
    image(
        &with_memclr(&[
            0xb580,     // 0x00 push {r7, lr}
            0x2100 | n, // 0x02 movs r1, #n
            0xf000,
            0xf802, // 0x04 bl 0x0c
            0xbd80, // 0x08 pop {r7, pc}
            0xbf00, // 0x0a
        ]), // 0x0c the callee
        &[
            Sym::function("clear_some", 0, 10),
            Sym::function(callee, 0x0c, 0x10),
        ],
    )
}

#[test]
fn a_memory_function_is_bounded_by_the_length_its_call_passes() {
    // Alone, its loop runs once per byte of a length nothing fixes: declined.
    let alone = bound(&clears(16), "__aeabi_memclr", F103_0WS);
    assert!(length_unknown(&alone), "{alone:?}");
    // Called with 16: push, movs, bl; the callee's movs and its way out (cmp, beq, bx lr) and 16
    // iterations of (cmp, beq, strb, adds, subs, b); pop: 3 + 4 + 96 + 1.
    let b = bound(&clears(16), "clear_some", F103_0WS);
    assert_eq!((b.instructions, b.declined.as_deref()), (104, None));
    // Twice the length, sixteen more iterations.
    let b = bound(&clears(32), "clear_some", F103_0WS);
    assert_eq!(b.instructions, 104 + 16 * 6);
}

#[test]
fn a_register_loaded_with_one_function_address_is_a_direct_call() {
    let img = image(
        &[
            0xb580, // 0x00 push {r7, lr}
            0x4b02, // 0x02 ldr r3, [pc, #8]: the literal at 0x0c
            0x4798, // 0x04 blx r3
            0xbd80, // 0x06 pop {r7, pc}
            0x2005, // 0x08 movs r0, #5   (five)
            0x4770, // 0x0a bx lr
            0x0009, 0x0000, // 0x0c .word five | 1
        ],
        &[
            Sym::function("caller", 0, 8),
            Sym::function("five", 8, 4),
            Sym::data(0x0c),
        ],
    );
    let b = bound(&img, "caller", F103_0WS);
    // push, ldr, blx, the callee's movs and bx lr, pop.
    assert_eq!((b.instructions, b.declined.as_deref()), (6, None));
}

#[test]
fn a_function_address_copied_to_another_register_is_a_direct_call() {
    // The compiler keeps a function's address in one register for several calls and moves it to
    // another between them (`mov r12, r3; blx r12`): the copy holds the same address.
    let img = image(
        &[
            0xb580, // 0x00 push {r7, lr}
            0x4b03, // 0x02 ldr r3, [pc, #12]: the literal at 0x10
            0x469c, // 0x04 mov r12, r3
            0x47e0, // 0x06 blx r12
            0xbd80, // 0x08 pop {r7, pc}
            0x2005, // 0x0a movs r0, #5   (five)
            0x4770, // 0x0c bx lr
            0xbf00, // 0x0e (padding)
            0x000b, 0x0000, // 0x10 .word five | 1
        ],
        &[
            Sym::function("caller", 0, 0x0a),
            Sym::function("five", 0x0a, 4),
            Sym::data(0x0e),
        ],
    );
    let b = bound(&img, "caller", F103_0WS);
    // push, ldr, mov, blx, the callee's movs and bx lr, pop.
    assert_eq!((b.instructions, b.declined.as_deref()), (7, None));
    // A copy of an argument register holds no known address: the call stays unresolved.
    let img = image(
        &[
            0xb580, // 0x00 push {r7, lr}
            0x4684, // 0x02 mov r12, r0
            0x47e0, // 0x04 blx r12
            0xbd80, // 0x06 pop {r7, pc}
        ],
        &[Sym::function("caller", 0, 8)],
    );
    let b = bound(&img, "caller", F103_0WS);
    let reason = b.declined.expect("a call through an argument is declined");
    assert!(reason.contains("call through a register"), "{reason}");
}

#[test]
fn a_stated_length_bounds_a_call_the_machine_code_does_not_fix() {
    // The length is read from memory: nothing in the machine code fixes it.
    let code = thumb(&with_memclr(&[
        0xb580, // 0x00 push {r7, lr}           line 10
        0x6801, // 0x02 ldr r1, [r0]
        0xf000, 0xf802, // 0x04 bl 0x0c         line 11
        0xbd80, // 0x08 pop {r7, pc}            line 12
        0xbf00, // 0x0a
    ])); // 0x0c __aeabi_memclr, line 20
    let img = Image::parse(&crate::testelf::elf_with_lines(
        &code,
        &[
            Sym::function("clear_read", 0, 10),
            Sym::function("__aeabi_memclr", 0x0c, 0x10),
        ],
        "firmware/src/c.rs",
        &[(0, 10), (4, 11), (8, 12), (0x0c, 20)],
    ))
    .expect("the test image parses");
    let none = bound_function(&img, "clear_read", F103_0WS, &BoundsFile::default()).unwrap();
    assert!(length_unknown(&none), "{none:?}");
    let stated = BoundsFile::parse(
        r#"{"lengths":[{"function":"clear_read","file":"src/c.rs","line":11,"register":1,"bytes":16,"reason":"a 16-byte record"}]}"#,
    )
    .unwrap();
    let b = bound_function(&img, "clear_read", F103_0WS, &stated).unwrap();
    // push, ldr, bl; the callee as for 16 bytes (100); pop.
    assert_eq!((b.instructions, b.declined.as_deref()), (104, None));
    assert!(
        b.loops.iter().any(
            |l| l.source == "bounds file: a length of at most 16 bytes in r1: a 16-byte record"
        ),
        "{:?}",
        b.loops
    );
    // On another line the statement is no bound for the call.
    let elsewhere = BoundsFile::parse(
        r#"{"lengths":[{"function":"clear_read","file":"src/c.rs","line":12,"register":1,"bytes":16,"reason":"x"}]}"#,
    )
    .unwrap();
    let b = bound_function(&img, "clear_read", F103_0WS, &elsewhere).unwrap();
    assert!(b.declined.is_some());
}

#[test]
fn a_per_element_function_is_bounded_like_a_memory_function() {
    // Not one of the memory functions by name: its loop has no bound of its own.
    let img = clears_through(16, "fill_slice");
    let plain = bound(&img, "clear_some", F103_0WS);
    assert!(plain.declined.is_some(), "{plain:?}");
    let stated = BoundsFile::parse(
        r#"{"per_element":[{"function":"fill_slice","register":1,"reason":"one pass per element"}]}"#,
    )
    .unwrap();
    let b = bound_function(&img, "clear_some", F103_0WS, &stated).unwrap();
    assert_eq!((b.instructions, b.declined.as_deref()), (104, None));
}

/// A caller that clears 16 bytes through `__aeabi_memclr4`, whose loop (from 0x0e: `cmp r1, #0`, a
/// `beq` out, then `body`, then `b 0x0e`) steps r0 and r1 by 4; `out` is the `beq`'s encoding.
fn clears_words(out: u16, body: &[u16]) -> Image {
    let mut code = vec![
        0xb580, // 0x00 push {r7, lr}
        0x2110, // 0x02 movs r1, #16
        0xf000, 0xf802, // 0x04 bl 0x0c
        0xbd80, // 0x08 pop {r7, pc}
        0xbf00, // 0x0a
        0x2200, // 0x0c movs r2, #0   (__aeabi_memclr4)
        0x2900, // 0x0e cmp r1, #0    (header)
        out,    // 0x10 beq past the loop
    ];
    code.extend_from_slice(body);
    code.extend_from_slice(&[
        0x3004,                         // adds r0, #4
        0x3904,                         // subs r1, #4
        0xe7f9 - body.len() as u16 + 1, // b 0x0e
        0x4770,                         // bx lr
    ]);
    let callee_len = 2 * (code.len() as u64) - 0x0c;
    image(
        &code,
        &[
            Sym::function("clear_words", 0, 10),
            Sym::function("__aeabi_memclr4", 0x0c, callee_len),
        ],
    )
}

#[test]
fn a_memory_loop_that_moves_a_word_a_pass_is_charged_per_word() {
    // A word a pass: 16 bytes are 4 passes, not 16.
    let b = bound(&clears_words(0xd003, &[0x6002]), "clear_words", F103_0WS); // str r2, [r0]
                                                                              // What runs: push, movs, bl; movs; 4 × (cmp, beq, str, adds, subs, b); cmp, beq, bx lr; pop = 32.
                                                                              // The bound charges each of the 16 bytes a quarter of the iteration's 6 instructions, rounded
                                                                              // up (2): 3 + 1 + 32 + 3 + 1 = 40 — at least what runs, and a quarter of the byte-wise 104.
    assert_eq!((b.instructions, b.declined.as_deref()), (40, None));
    let l = b
        .loops
        .iter()
        .find(|l| l.function == "__aeabi_memclr4")
        .expect("the loop is listed");
    assert_eq!(l.bound, 5, "{l:?}");
    assert!(l.source.contains("at least 4"), "{l:?}");
    // A store under a condition is no byte a pass can count on: the same loop with `it ne;
    // strne r2, [r0]` is charged per byte, 16 × its 7-instruction iteration: 3 + 1 + 112 + 3 + 1.
    let b = bound(
        &clears_words(0xd004, &[0xbf18, 0x6002]),
        "clear_words",
        F103_0WS,
    );
    assert_eq!((b.instructions, b.declined.as_deref()), (120, None));
}

/// A caller that clears `min(a, 12).saturating_sub(b)` bytes (`a` and `b` read from memory) through
/// `__aeabi_memclr`; with `min` false it clears `a.saturating_sub(b)`.
fn clears_saturated(min: bool) -> Image {
    let (cmp, it, mov) = if min {
        (0x2b0c, 0xbf28, 0x230c) // cmp r3, #12; it cs; movcs r3, #12
    } else {
        (0xbf00, 0xbf00, 0xbf00) // nops
    };
    image(
        &with_memclr(&[
            0xb580, // 0x00 push {r7, lr}
            0x6803, // 0x02 ldr r3, [r0]
            cmp,    // 0x04
            it,     // 0x06
            mov,    // 0x08
            0x6841, // 0x0a ldr r1, [r0, #4]
            0x1a59, // 0x0c subs r1, r3, r1
            0xbf38, // 0x0e it cc
            0x2100, // 0x10 movcc r1, #0
            0xf000, 0xf801, // 0x12 bl 0x18
            0xbd80, // 0x16 pop {r7, pc}
        ]), // 0x18 __aeabi_memclr
        &[
            Sym::function("clear_rest", 0, 0x18),
            Sym::function("__aeabi_memclr", 0x18, 0x10),
        ],
    )
}

#[test]
fn a_length_made_the_smaller_of_itself_and_a_constant_then_saturated_is_bounded() {
    // `min(a, 12)` in a register of its own, then `saturating_sub`: at most 12 bytes.
    let b = bound(&clears_saturated(true), "clear_rest", F103_0WS);
    // The caller's 11 instructions (both ITs counted), the callee's movs, 12 × (cmp, beq, strb,
    // adds, subs, b) and its way out (cmp, beq, bx lr).
    assert_eq!(
        (b.instructions, b.declined.as_deref()),
        (11 + 1 + 72 + 3, None)
    );
    // Without the `min`, the subtraction alone fixes nothing.
    let b = bound(&clears_saturated(false), "clear_rest", F103_0WS);
    assert!(length_unknown(&b), "{b:?}");
}

#[test]
fn a_counter_set_before_a_call_is_found_through_the_blocks_on_the_way() {
    // r4 = 0 set, then a call (which leaves r4 alone, AAPCS) ends the block; the block after it
    // does not write r4, and the loop counts r4 to 3.
    let img = image(
        &[
            0xb510, // 0x00 push {r4, lr}
            0x2400, // 0x02 movs r4, #0
            0xf000, 0xf808, // 0x04 bl 0x18
            0x3002, // 0x08 adds r0, #2     (the block after the call)
            0x2c03, // 0x0a cmp r4, #3      (header: 4 passes)
            0xd002, // 0x0c beq 0x14
            0x3001, // 0x0e adds r0, #1     (3 iterations)
            0x3401, // 0x10 adds r4, #1
            0xe7fa, // 0x12 b 0x0a
            0xbd10, // 0x14 pop {r4, pc}
            0xbf00, // 0x16
            0x4770, // 0x18 bx lr           (leaf)
        ],
        &[
            Sym::function("after_call", 0, 0x18),
            Sym::function("leaf", 0x18, 2),
        ],
    );
    let b = bound(&img, "after_call", F103_0WS);
    // push, movs, bl, bx lr, adds; 4 × (cmp, beq); 3 × (adds, adds, b); pop = 5 + 8 + 9 + 1.
    assert_eq!((b.instructions, b.declined.as_deref()), (23, None));
    assert!(b
        .loops
        .iter()
        .any(|l| l.bound == 4 && l.source.starts_with("counted")));
}

/// An async task's poll as rustc lowers `loop { x += 1; wait.await; y += 1; }`: the state (r0) sends
/// a first poll to the loop's top and every later one to the `await` (r2 = 0: pending, return), so
/// the loop is entered at two blocks (irreducible).
fn async_loop() -> Image {
    let code = thumb(&[
        0xb908, // 0x00 cbnz r0, 0x06     (resumed: to the await)      line 10
        0x2100, // 0x02 movs r1, #0       (first poll)                 line 11
        0x3101, // 0x04 adds r1, #1       (the loop's top)             line 12
        0x2a00, // 0x06 cmp r2, #0        (the await: pending?)        line 13
        0xd001, // 0x08 beq 0x0e
        0x3301, // 0x0a adds r3, #1       (after the await)            line 14
        0xe7fa, // 0x0c b 0x04
        0x4770, // 0x0e bx lr             (pending: the poll returns)  line 15
    ]);
    Image::parse(&crate::testelf::elf_with_lines(
        &code,
        &[Sym::function("poll", 0, 0x10)],
        "firmware/src/task.rs",
        &[(0, 10), (2, 11), (4, 12), (6, 13), (0x0a, 14), (0x0e, 15)],
    ))
    .expect("the test image parses")
}

#[test]
fn an_async_loop_entered_at_its_await_is_split_into_a_natural_loop() {
    let img = async_loop();
    // Made reducible, the loop (entered now at the await, line 13: the loop's top is copied for the
    // first poll) has no bound of its own: declined by name.
    let plain = bound_function(&img, "poll", F103_0WS, &BoundsFile::default()).unwrap();
    assert!(
        plain.declined.as_deref().is_some_and(
            |r| r.contains("the loop in poll at /work/firmware/src/task.rs:13 has no bound")
        ),
        "{plain:?}"
    );
    // One pass per job, stated: the await runs at most twice per poll (resumed, and pending again).
    let stated = BoundsFile::parse(
        r#"{"loops":[{"function":"poll","file":"src/task.rs","line":13,"bound":2,"reason":"one pass of the task's loop per job"}]}"#,
    )
    .unwrap();
    let b = bound_function(&img, "poll", F103_0WS, &stated).unwrap();
    // The longest poll is the first: cbnz, movs, the loop's top (adds, its copy for the way in), then
    // the await twice: one iteration (cmp, beq, adds, b, adds) and the way out (cmp, beq); bx lr
    // = 3 + 5 + 2 + 1. (A resumed poll: cbnz, 5 + 2, bx lr = 9.)
    assert_eq!((b.instructions, b.declined.as_deref()), (11, None));
}

#[test]
fn a_stated_entry_whose_place_the_image_lacks_is_named() {
    let img = async_loop();
    let stated = BoundsFile::parse(
        r#"{"loops":[{"function":"poll","file":"src/task.rs","line":13,"bound":2,"reason":"r"},
                     {"function":"poll","file":"src/task.rs","line":99,"bound":2,"reason":"r"},
                     {"function":"gone","file":"src/task.rs","line":13,"bound":2,"reason":"r"}],
            "per_element":[{"function":"gone_too","register":1,"reason":"r"}],
            "tasks":[{"name":"t","symbol":"poll","handler":true,"reason":"r"}]}"#,
    )
    .unwrap();
    assert_eq!(
        stated.missing_places(&img),
        [
            "loop poll src/task.rs:99",
            "loop gone src/task.rs:13",
            "per-element function gone_too"
        ]
    );
}

/// `code` (function `f`) followed by `OUTLINED_FUNCTION_1`: `movs r4, #0; bx lr`.
fn with_helper(f: &str, code: &[u16]) -> Image {
    let at = 2 * code.len() as u64;
    image(
        &[code, &[0x2400, 0x4770]].concat(),
        &[
            Sym::function(f, 0, at),
            Sym::function("OUTLINED_FUNCTION_1", at, 4),
        ],
    )
}

#[test]
fn an_outlined_helper_is_read_for_the_registers_it_writes() {
    // LLVM's machine outliner moved the counter's `movs r4, #0` into a helper (no calling convention).
    let set_in_helper = with_helper(
        "counts",
        &[
            0xb510, // 0x00 push {r4, lr}
            0xf000, 0xf805, // 0x02 bl 0x10 (the helper)
            0x2c03, // 0x06 cmp r4, #3      (header: 4 passes)
            0xd001, // 0x08 beq 0x0e
            0x3401, // 0x0a adds r4, #1
            0xe7fb, // 0x0c b 0x06
            0xbd10, // 0x0e pop {r4, pc}
        ],
    );
    let b = bound(&set_in_helper, "counts", F103_0WS);
    // push, bl, movs, bx lr; 4 × (cmp, beq); 3 × (adds, b); pop = 4 + 8 + 6 + 1.
    assert_eq!((b.instructions, b.declined.as_deref()), (19, None));
    // A helper called in the loop that writes the counter (here: back to 0, for ever) is a write of
    // it: the loop is no counted loop.
    let reset_in_loop = with_helper(
        "spins",
        &[
            0xb510, // 0x00 push {r4, lr}
            0x2400, // 0x02 movs r4, #0
            0x2c03, // 0x04 cmp r4, #3
            0xd003, // 0x06 beq 0x10
            0x3401, // 0x08 adds r4, #1
            0xf000, 0xf802, // 0x0a bl 0x12 (the helper)
            0xe7f9, // 0x0e b 0x04
            0xbd10, // 0x10 pop {r4, pc}
        ],
    );
    let b = bound(&reset_in_loop, "spins", F103_0WS);
    assert!(
        b.declined
            .as_deref()
            .is_some_and(|r| r.contains("has no bound")),
        "{b:?}"
    );
}

#[test]
fn a_move_in_an_else_slot_is_no_smaller_of() {
    // `cmp r1, #12; ite cs; movcs r0, r0; movcc r1, #12`: r1 becomes 12 only when it was smaller, so
    // nothing bounds it: the call's length stays unknown.
    let img = image(
        &with_memclr(&[
            0xb580, // 0x00 push {r7, lr}
            0x6801, // 0x02 ldr r1, [r0]
            0x290c, // 0x04 cmp r1, #12
            0xbf2c, // 0x06 ite cs
            0x4600, // 0x08 movcs r0, r0
            0x210c, // 0x0a movcc r1, #12
            0xf000, 0xf801, // 0x0c bl 0x12
            0xbd80, // 0x10 pop {r7, pc}
        ]), // 0x12 __aeabi_memclr
        &[
            Sym::function("else_slot", 0, 0x12),
            Sym::function("__aeabi_memclr", 0x12, 0x10),
        ],
    );
    let b = bound(&img, "else_slot", F103_0WS);
    assert!(length_unknown(&b), "{b:?}");
}

/// The critical sections of `f`'s code as one task's (a handler).
fn sections_of(image: &Image, f: &str, chip: Chip) -> TaskSections {
    let task = Task {
        name: f.to_string(),
        entry: TaskEntry::Symbol(f.to_string()),
        handler: true,
    };
    let mut found = task_sections(image, &[task], chip, &BoundsFile::default());
    found.remove(0)
}

#[test]
fn a_basepri_lock_is_a_section_at_its_ceiling() {
    let img = image(
        &[
            0xf3ef, 0x8411, // 0x00 mrs r4, BASEPRI: 2
            0x20b0, // 0x04 movs r0, #0xb0: 1
            0xf380, 0x8812, // 0x06 msr BASEPRI_MAX, r0: 2 (the raise)
            0x2101, // 0x0a movs r1, #1: 1
            0x3101, // 0x0c adds r1, #1: 1
            0xf384, 0x8811, // 0x0e msr BASEPRI, r4: 2 (the restore)
            0x4770, // 0x12 bx lr: 1 + P
        ],
        &[Sym::function("locked", 0, 0x14)],
    );
    let found = sections_of(&img, "locked", F103_0WS);
    assert_eq!(found.incomplete, None);
    assert_eq!(found.ceilings.len(), 1, "{found:?}");
    let c = &found.ceilings[0];
    // 0xb0 with 4 priority bits is level 11: RTIC's logical priority 16 − 11 = 5.
    assert_eq!(
        c.ceiling,
        Ceiling::Basepri {
            hardware: 0xb0,
            priority: 5
        }
    );
    // From the raise to the restore, both in: 2 + 1 + 1 + 2 = 6 cycles, 4 instructions (the three
    // flash lines it spans cost 1 each at 0 wait states, hidden).
    assert_eq!((c.cycles, c.instructions, c.sections), (6, 4, 1));
    assert_eq!(c.declined, None);
    // 6 cycles at 72 MHz, 83.3 ns, rounded up to the nanosecond.
    assert_eq!(c.us, 0.084);
    assert_eq!(
        Ceiling::of_basepri(0x90).and_then(Ceiling::priority),
        Some(7)
    );
    assert_eq!(Ceiling::of_basepri(0), None);
    assert_eq!(Ceiling::of_basepri(0xb8), None);
}

#[test]
fn interrupts_off_runs_to_the_primask_restore_on_its_longest_path() {
    let img = image(
        &[
            0xf3ef, 0x8010, // 0x00 mrs r0, PRIMASK: 2
            0xb672, // 0x04 cpsid i: 1 (the raise)
            0x2900, // 0x06 cmp r1, #0: 1
            0xd001, // 0x08 beq 0x0e: 1, taken + P
            0x3201, // 0x0a adds r2, #1: 1
            0x3201, // 0x0c adds r2, #1: 1
            0xf380, 0x8810, // 0x0e msr PRIMASK, r0: 2 (the restore)
            0x4770, // 0x12 bx lr
        ],
        &[Sym::function("masked", 0, 0x14)],
    );
    let found = sections_of(&img, "masked", F103_0WS);
    assert_eq!(found.ceilings.len(), 1, "{found:?}");
    let c = &found.ceilings[0];
    assert_eq!(c.ceiling, Ceiling::InterruptsOff);
    // Taken: 1 + 1 + 1 + P + 2 = 8 cycles; through the adds: 1 + 1 + 1 + 1 + 1 + 2 = 7 cycles but
    // 6 instructions, the most of any path.
    assert_eq!((c.cycles, c.instructions), (8, 6));
}

#[test]
fn a_section_holds_what_it_calls_and_the_callee_has_its_own() {
    let img = image(
        &[
            0xb510, // 0x00 push {r4, lr}
            0xf3ef, 0x8411, // 0x02 mrs r4, BASEPRI
            0x20c0, // 0x06 movs r0, #0xc0
            0xf380, 0x8812, // 0x08 msr BASEPRI_MAX, r0: 2 (priority 4)
            0xf000, 0xf804, // 0x0c bl 0x18: 1 + P
            0xf384, 0x8811, // 0x10 msr BASEPRI, r4: 2
            0xbd10, // 0x14 pop {r4, pc}
            0xbf00, // 0x16 nop
            0xf3ef, 0x8010, // 0x18 mrs r0, PRIMASK: 2
            0xb672, // 0x1c cpsid i: 1
            0xf380, 0x8810, // 0x1e msr PRIMASK, r0: 2
            0x4770, // 0x22 bx lr: 1 + P
        ],
        &[
            Sym::function("outer", 0, 0x18),
            Sym::function("inner", 0x18, 0x0c),
        ],
    );
    let found = sections_of(&img, "outer", F103_0WS);
    assert_eq!(found.incomplete, None);
    // Highest ceiling first: the callee's interrupts off, then the caller's lock.
    let ceilings: Vec<(Ceiling, u64, u64)> = found
        .ceilings
        .iter()
        .map(|c| (c.ceiling, c.cycles, c.instructions))
        .collect();
    assert_eq!(
        ceilings,
        [
            // cpsid 1 + msr 2.
            (Ceiling::InterruptsOff, 3, 2),
            // msr 2 + bl 4 + the callee (2 + 1 + 2 + 4 = 9) + msr 2 = 17 cycles; 1 + 1 + 4 + 1.
            (
                Ceiling::Basepri {
                    hardware: 0xc0,
                    priority: 4
                },
                17,
                7
            ),
        ]
    );
}

#[test]
fn a_section_with_a_loop_without_a_bound_is_declined_by_name() {
    let img = image(
        &[
            0xf3ef, 0x8411, // 0x00 mrs r4, BASEPRI
            0x20b0, // 0x04 movs r0, #0xb0
            0xf380, 0x8812, // 0x06 msr BASEPRI_MAX, r0
            0x680a, // 0x0a ldr r2, [r1]: a poll of a flag with no bound
            0x2a00, // 0x0c cmp r2, #0
            0xd0fc, // 0x0e beq 0x0a
            0xf384, 0x8811, // 0x10 msr BASEPRI, r4
            0x4770, // 0x14 bx lr
        ],
        &[Sym::function("polls_locked", 0, 0x16)],
    );
    let found = sections_of(&img, "polls_locked", F103_2WS);
    assert_eq!(found.ceilings.len(), 1, "{found:?}");
    let c = &found.ceilings[0];
    assert_eq!(c.ceiling.priority(), Some(5));
    let reason = c.declined.as_deref().expect("declined");
    assert!(
        reason.contains("section raised in polls_locked")
            && reason.contains("loop in polls_locked")
            && reason.contains("no bound"),
        "{reason}"
    );
    assert_eq!((c.cycles, c.us), (0, 0.0));
}

#[test]
fn a_raise_of_no_constant_leaves_the_task_incomplete() {
    let img = image(
        &[
            0xf3ef, 0x8411, // 0x00 mrs r4, BASEPRI
            0xf380, 0x8812, // 0x04 msr BASEPRI_MAX, r0: r0 is the caller's
            0xf384, 0x8811, // 0x08 msr BASEPRI, r4
            0x4770, // 0x0c bx lr
        ],
        &[Sym::function("raises_an_argument", 0, 0x0e)],
    );
    let found = sections_of(&img, "raises_an_argument", F103_0WS);
    let reason = found.incomplete.expect("incomplete");
    assert!(reason.contains("no constant"), "{reason}");
}

#[test]
fn a_conditional_write_is_joined_with_the_value_before_it() {
    let img = image(
        &[
            0x2003, // 0x00 movs r0, #3
            0x2105, // 0x02 movs r1, #5
            0x2a00, // 0x04 cmp r2, #0
            0xbf04, // 0x06 itt eq
            0x2005, // 0x08 moveq r0, #5: 3 or 5
            0x2105, // 0x0a moveq r1, #5: 5 either way
            0x4770, // 0x0c bx lr
        ],
        &[Sym::function("maybe", 0, 0x0e)],
    );
    let insns = img.function_named("maybe").unwrap().instructions().unwrap();
    let after = |conditional| {
        let mut known = [None; 16];
        for insn in &insns[..6] {
            crate::waits::step_constants(&img, insn, &mut known, conditional);
        }
        (known[0], known[1])
    };
    use crate::waits::Conditional;
    assert_eq!(after(Conditional::Joined), (None, Some(5)));
    // The scans of what the code may hold see the value where it is written.
    assert_eq!(after(Conditional::Taken), (Some(5), Some(5)));
}

#[test]
fn a_raise_of_a_value_written_under_a_condition_has_no_ceiling() {
    let code = |before: u16| {
        [
            0xf3ef, 0x8411, // 0x00 mrs r4, BASEPRI
            before, // 0x04 movs r0, #before
            0x2900, // 0x06 cmp r1, #0
            0xbf08, // 0x08 it eq
            0x20a0, // 0x0a moveq r0, #0xa0: only where r1 is 0
            0xf380, 0x8812, // 0x0c msr BASEPRI_MAX, r0: the raise
            0xf384, 0x8811, // 0x10 msr BASEPRI, r4
            0x4770, // 0x14 bx lr
        ]
    };
    // r0 is 0x20 or 0xa0 at the raise: priority 14 or 6, neither on every path.
    let img = image(&code(0x2020), &[Sym::function("raise", 0, 0x16)]);
    let found = sections_of(&img, "raise", F103_0WS);
    let reason = found.incomplete.as_deref().expect("incomplete");
    assert!(reason.contains("no constant"), "{reason}");
    assert!(found.ceilings.is_empty(), "{:?}", found.ceilings);
    // 0xa0 either way: the raise's ceiling stands (0xa0 is level 10, priority 16 − 10 = 6).
    let img = image(&code(0x20a0), &[Sym::function("raise", 0, 0x16)]);
    let found = sections_of(&img, "raise", F103_0WS);
    assert_eq!(found.incomplete, None);
    let ceilings: Vec<Ceiling> = found.ceilings.iter().map(|c| c.ceiling).collect();
    assert_eq!(
        ceilings,
        [Ceiling::Basepri {
            hardware: 0xa0,
            priority: 6
        }]
    );
}

#[test]
fn a_primask_write_that_may_set_it_is_a_raise() {
    let img = image(
        &[
            0xf3ef, 0x8410, // 0x00 mrs r4, PRIMASK: 2
            0x2001, // 0x04 movs r0, #1: 1
            0x2900, // 0x06 cmp r1, #0: 1
            0xbf08, // 0x08 it eq
            0x2000, // 0x0a moveq r0, #0: 1 where r1 is 0 (r0 stays 1 where it is not)
            0xf380, 0x8810, // 0x0c msr PRIMASK, r0: 2 (interrupts off where r1 is not 0)
            0x3201, // 0x10 adds r2, #1: 1
            0xf384, 0x8810, // 0x12 msr PRIMASK, r4: 2 (the restore)
            0x4770, // 0x16 bx lr
        ],
        &[Sym::function("maybe_masked", 0, 0x18)],
    );
    let found = sections_of(&img, "maybe_masked", F103_0WS);
    assert_eq!(found.incomplete, None);
    let ceilings: Vec<(Ceiling, u64, u64)> = found
        .ceilings
        .iter()
        .map(|c| (c.ceiling, c.cycles, c.instructions))
        .collect();
    // From the write to the restore, both in: 2 + 1 + 2 = 5 cycles, 3 instructions.
    assert_eq!(ceilings, [(Ceiling::InterruptsOff, 5, 3)]);
}

#[test]
fn a_section_whose_restore_is_conditional_is_declined() {
    let img = image(
        &[
            0xf3ef, 0x8411, // 0x00 mrs r4, BASEPRI
            0x20b0, // 0x04 movs r0, #0xb0
            0xf380, 0x8812, // 0x06 msr BASEPRI_MAX, r0: the raise
            0x2900, // 0x0a cmp r1, #0
            0xbf08, // 0x0c it eq
            0xf384, 0x8811, // 0x0e msreq BASEPRI, r4: restored only where r1 is 0
            0x3201, // 0x12 adds r2, #1: still masked where r1 is not 0
            0xf384, 0x8811, // 0x14 msr BASEPRI, r4
            0x4770, // 0x18 bx lr
        ],
        &[Sym::function("restores_maybe", 0, 0x1a)],
    );
    let found = sections_of(&img, "restores_maybe", F103_0WS);
    assert_eq!(found.ceilings.len(), 1, "{found:?}");
    let reason = found.ceilings[0].declined.as_deref().expect("declined");
    assert!(reason.contains("restored under a condition"), "{reason}");
}

/// `(ceiling, cycles, instructions)` of each ceiling `found` has.
fn ceiling_figures(found: &TaskSections) -> Vec<(Ceiling, u64, u64)> {
    found
        .ceilings
        .iter()
        .map(|c| (c.ceiling, c.cycles, c.instructions))
        .collect()
}

#[test]
fn a_plain_basepri_write_of_a_nonzero_constant_is_a_raise() {
    let img = image(
        &[
            0xf3ef, 0x8411, // 0x00 mrs r4, BASEPRI
            0x2020, // 0x04 movs r0, #0x20
            0xf380, 0x8811, // 0x06 msr BASEPRI, r0: 2 (raises the mask where it was 0)
            0x3101, // 0x0a adds r1, #1: 1
            0xf384, 0x8811, // 0x0c msr BASEPRI, r4: 2 (the restore, of what the mrs saved)
            0x2000, // 0x10 movs r0, #0
            0xf380, 0x8811, // 0x12 msr BASEPRI, r0: a write of 0 lowers, no raise
            0x4770, // 0x16 bx lr
        ],
        &[Sym::function("plain_write", 0, 0x18)],
    );
    let found = sections_of(&img, "plain_write", F103_0WS);
    assert_eq!(found.incomplete, None);
    // 0x20 with 4 priority bits is level 2: RTIC's logical priority 16 − 2 = 14. From the write to
    // the restore, both in: 2 + 1 + 2 = 5 cycles, 3 instructions.
    assert_eq!(
        ceiling_figures(&found),
        [(
            Ceiling::Basepri {
                hardware: 0x20,
                priority: 14
            },
            5,
            3
        )]
    );
}

#[test]
fn a_primask_write_is_read_through_the_blocks_and_copies_before_it() {
    let img = image(
        &[
            0xf3ef, 0x8410, // 0x00 mrs r4, PRIMASK
            0x2001, // 0x04 movs r0, #1
            0x4605, // 0x06 mov r5, r0: a copy of the 1
            0xb10a, // 0x08 cbz r2, 0x0e
            0x3301, // 0x0a adds r3, #1
            0x3301, // 0x0c adds r3, #1
            0xf385, 0x8810, // 0x0e msr PRIMASK, r5: 2 (sets PRIMASK on both paths: the raise)
            0x3101, // 0x12 adds r1, #1: 1
            0xf384, 0x8810, // 0x14 msr PRIMASK, r4: 2 (the restore)
            0x4770, // 0x18 bx lr
        ],
        &[Sym::function("copied_one", 0, 0x1a)],
    );
    let found = sections_of(&img, "copied_one", F103_0WS);
    assert_eq!(found.incomplete, None);
    // From the write to the restore, both in: 2 + 1 + 2 = 5 cycles, 3 instructions.
    assert_eq!(ceiling_figures(&found), [(Ceiling::InterruptsOff, 5, 3)]);
}

#[test]
fn a_primask_write_of_a_value_no_mrs_saved_makes_the_list_incomplete() {
    let img = image(
        &[
            0xf001, 0x0001, // 0x00 and r0, r1, #1: bit 0 of whatever r1 holds
            0xf380, 0x8810, // 0x04 msr PRIMASK, r0: sets PRIMASK where r1 is odd
            0x3201, // 0x08 adds r2, #1
            0xb662, // 0x0a cpsie i
            0x4770, // 0x0c bx lr
        ],
        &[Sym::function("unfixed", 0, 0x0e)],
    );
    let found = sections_of(&img, "unfixed", F103_0WS);
    let reason = found.incomplete.as_deref().expect("incomplete");
    assert!(
        reason.contains("unfixed: the Primask write at 0x00000004"),
        "{reason}"
    );
}

/// A BASEPRI lock whose saved mask is spilled to the frame, `between` run inside it (at 0x10, two
/// halfwords).
fn spilled_lock(between: [u16; 2]) -> Image {
    image(
        &[
            0xb510, // 0x00 push {r4, lr}
            0xb082, // 0x02 sub sp, #8
            0xf3ef, 0x8011, // 0x04 mrs r0, BASEPRI
            0x9001, // 0x08 str r0, [sp, #4]: the spill
            0x20b0, // 0x0a movs r0, #0xb0
            0xf380, 0x8812,     // 0x0c msr BASEPRI_MAX, r0: 2 (the raise)
            between[0], // 0x10
            between[1], // 0x12
            0x9801,     // 0x14 ldr r0, [sp, #4]: 2
            0xf380, 0x8811, // 0x16 msr BASEPRI, r0: 2 (the restore, of the spilled mask)
            0xb002, // 0x1a add sp, #8
            0xbd10, // 0x1c pop {r4, pc}
        ],
        &[Sym::function("spilled", 0, 0x1e)],
    )
}

#[test]
fn a_mask_spilled_to_the_frame_is_followed_to_its_restore() {
    // adds r1, #1; adds r1, #1 inside.
    let found = sections_of(&spilled_lock([0x3101, 0x3101]), "spilled", F103_0WS);
    assert_eq!(found.incomplete, None);
    // 2 + 1 + 1 + 2 + 2 = 8 cycles, 5 instructions (the load 2 cycles, TRM table 18-1: 1 + 1, not
    // pipelined with the MSR after it).
    assert_eq!(
        ceiling_figures(&found),
        [(
            Ceiling::Basepri {
                hardware: 0xb0,
                priority: 5
            },
            8,
            5
        )]
    );
}

#[test]
fn a_spilled_mask_written_through_a_frame_address_is_unclear() {
    // add r2, sp, #4; str r3, [r2]: the spilled word is overwritten through r2.
    let found = sections_of(&spilled_lock([0xaa01, 0x6013]), "spilled", F103_0WS);
    let reason = found.incomplete.as_deref().expect("incomplete");
    assert!(
        reason.contains("the Basepri write at 0x00000016"),
        "{reason}"
    );
}

#[test]
fn faultmask_set_is_interrupts_off() {
    let img = image(
        &[
            0xb671, // 0x00 cpsid f: 1 (the raise)
            0x3101, // 0x02 adds r1, #1: 1
            0xb661, // 0x04 cpsie f: 1 (the restore)
            0xf3ef, 0x8413, // 0x06 mrs r4, FAULTMASK
            0x2001, // 0x0a movs r0, #1
            0xf380, 0x8813, // 0x0c msr FAULTMASK, r0: 2 (the raise)
            0x3101, // 0x10 adds r1, #1: 1
            0x3101, // 0x12 adds r1, #1: 1
            0xf384, 0x8813, // 0x14 msr FAULTMASK, r4: 2 (the restore)
            0x4770, // 0x18 bx lr
        ],
        &[Sym::function("faults_masked", 0, 0x1a)],
    );
    let found = sections_of(&img, "faults_masked", F103_0WS);
    assert_eq!(found.incomplete, None);
    // Two sections at one ceiling, the longer counts: 2 + 1 + 1 + 2 = 6 cycles, 4 instructions
    // (the cps one: 1 + 1 + 1 = 3 cycles, 3 instructions).
    assert_eq!(ceiling_figures(&found), [(Ceiling::InterruptsOff, 6, 4)]);
    assert_eq!(found.ceilings[0].sections, 2);
}

/// `bounds_file` with the async loop of [`async_loop`] stated as one pass per job.
fn one_job_of_poll() -> BoundsFile {
    BoundsFile::parse(
        r#"{"jobs":[{"function":"poll","file":"src/task.rs","line":13,"reason":"ready at once, the await is the next release"}]}"#,
    )
    .unwrap()
}

#[test]
fn a_stated_job_is_one_pass_of_an_async_loop() {
    let img = async_loop();
    // Without the statement the loop, entered at its await, stays declined by name.
    let plain = bound_function(&img, "poll", F103_0WS, &BoundsFile::default()).unwrap();
    assert!(
        plain.declined.as_deref().is_some_and(
            |r| r.contains("the loop in poll at /work/firmware/src/task.rs:13 has no bound")
        ),
        "{plain:?}"
    );
    let b = bound_function(&img, "poll", F103_0WS, &one_job_of_poll()).unwrap();
    // The split keeps the await (line 13) as the loop's header (copying the loop's top, one block,
    // for the first poll) and a job runs it twice: where the job resumes (ready) and where it parks
    // (pending). The resumed job: cbnz taken (1 + P), cmp, beq (1, 1), adds r3, b (1 + P), the loop's
    // top adds r1, cmp, beq taken (1 + P), bx lr (1 + P) = 4 + 2 + 1 + 4 + 1 + 1 + 4 + 4 = 21 cycles,
    // 9 instructions. The first poll: cbnz, movs, adds (1 each), the await ready at once as one pass
    // (cmp, beq, adds, b: 1 + 1 + 1 + 4, adds 1), cmp, beq taken (1 + 4), bx lr (4) = 20 cycles,
    // 11 instructions. Each figure is its own longest path: 21 cycles, 11 instructions.
    assert_eq!(figures(&b), (21, 11, None));
    assert_eq!(b.loops.len(), 1);
    assert_eq!((b.loops[0].line, b.loops[0].bound), (Some(13), 2));
    assert!(b.loops[0].source.starts_with("job: "), "{:?}", b.loops[0]);
    // Stated for another line, the statement bounds nothing.
    let elsewhere = BoundsFile::parse(
        r#"{"jobs":[{"function":"poll","file":"src/task.rs","line":12,"reason":"r"}]}"#,
    )
    .unwrap();
    let b = bound_function(&img, "poll", F103_0WS, &elsewhere).unwrap();
    assert!(b.declined.is_some());
    // A job needs its reason; its place is checked like a loop's.
    assert!(matches!(
        BoundsFile::parse(r#"{"jobs":[{"function":"poll","file":"a.rs","line":13,"reason":""}]}"#),
        Err(Error::Bounds(_))
    ));
    assert!(one_job_of_poll().missing_places(&img).is_empty());
}

#[test]
fn an_async_loop_with_two_awaits_is_split_where_every_pass_goes() {
    // `loop { if x { a.await } else { b.await }; y += 2 }` with `x` true on the first poll: a first
    // poll (state 0) enters the loop at await a (line 12), a resumed one at a or b (line 13). Every
    // pass goes through the join behind the awaits (line 14), and splitting there copies the fewest
    // blocks (each await's way to it): one natural loop, named at the join's line, entered only
    // through those copies — so a job runs its header once: it polled its await before.
    let code = thumb(&[
        0x2801, // 0x00 cmp r0, #1
        0xd005, // 0x02 beq 0x10: resumed at await a
        0x2802, // 0x04 cmp r0, #2
        0xd007, // 0x06 beq 0x18: resumed at await b
        0x2100, // 0x08 movs r1, #0 (first poll)
        0xe001, // 0x0a b 0x10
        0x2900, // 0x0c cmp r1, #0 (the loop's top)
        0xd103, // 0x0e bne 0x18
        0x2a00, // 0x10 cmp r2, #0 (await a: pending?)
        0xd007, // 0x12 beq 0x24
        0xe003, // 0x14 b 0x1e
        0xbf00, // 0x16 nop
        0x2b00, // 0x18 cmp r3, #0 (await b: pending?)
        0xd003, // 0x1a beq 0x24
        0xbf00, // 0x1c nop
        0x3102, // 0x1e adds r1, #2 (the join behind either await)
        0xe7f4, // 0x20 b 0x0c
        0xbf00, // 0x22 nop
        0x4770, // 0x24 bx lr
    ]);
    let img = Image::parse(&crate::testelf::elf_with_lines(
        &code,
        &[Sym::function("poll2", 0, 0x26)],
        "firmware/src/task.rs",
        &[
            (0, 10),
            (0x0c, 11),
            (0x10, 12),
            (0x18, 13),
            (0x1e, 14),
            (0x24, 15),
        ],
    ))
    .expect("the test image parses");
    let plain = bound_function(&img, "poll2", F103_0WS, &BoundsFile::default()).unwrap();
    assert!(
        plain
            .declined
            .as_deref()
            .is_some_and(|r| r.contains("task.rs:14 has no bound")),
        "{plain:?}"
    );
    let stated = BoundsFile::parse(
        r#"{"jobs":[{"function":"poll2","file":"src/task.rs","line":14,"reason":"r"}]}"#,
    )
    .unwrap();
    let b = bound_function(&img, "poll2", F103_0WS, &stated).unwrap();
    assert_eq!(b.loops.len(), 1);
    assert_eq!((b.loops[0].line, b.loops[0].bound), (Some(14), 1));
    // The longest job is the first poll, with await a ready at once (no pass of the loop yet): cmp,
    // beq, cmp, beq, movs, b (1 + 1 + 1 + 1 + 1 + 4 cycles), a ready (cmp, beq, b: 1 + 1 + 4), the
    // join (adds, b: 1 + 4), the top (cmp, bne taken: 1 + 4), b pending (cmp, beq taken: 1 + 4), bx
    // lr (4) = 34 cycles, 16 instructions. A job resumed at b: cmp, beq, cmp, beq taken (1 + 1 + 1 +
    // 4), b ready (cmp, beq, nop: 3), the join (5), the top (5), b pending (5), bx lr (4) = 29
    // cycles, 14 instructions — the header once: a second pass would be the next release.
    assert_eq!(figures(&b), (34, 16, None));
}

#[test]
fn a_function_that_only_calls_one_that_cannot_return_cannot_either() {
    // `panic_const_async_fn_resumed` is no panic by its name (the panic check leaves it out), but it
    // only calls `panic_fmt`: a path into it completes no job, as a path into a panic does not.
    let img = image(
        &[
            0x2800, // 0x00 cmp r0, #0: 1
            0xd001, // 0x02 beq 0x08: 1 (+ P)
            0xf000, 0xf803, // 0x04 bl 0x0e
            0x2001, // 0x08 movs r0, #1: 1
            0x4770, // 0x0a bx lr: 4
            0xbf00, // 0x0c
            0xb580, // 0x0e push {r7, lr}
            0xf000, 0xf800, // 0x10 bl 0x14
            0xe7fe, // 0x14 b 0x14: the panic spins for ever
        ],
        &[
            Sym::function("resumes", 0, 0x0c),
            Sym::function(
                "core::panicking::panic_const::panic_const_async_fn_resumed",
                0x0e,
                6,
            ),
            Sym::function("core::panicking::panic_fmt", 0x14, 2),
        ],
    );
    // Only the path that returns: 1 + 1 + P + 1 + 4 = 10.
    let b = bound(&img, "resumes", F103_0WS);
    assert_eq!(figures(&b), (10, 4, None));
}

#[test]
fn a_stated_wait_is_taken_before_the_poll_count_it_times_out_at() {
    // `for _ in 0..250 { if read(SR) != 0 { return 1 } } 0`: a flag poll whose count is its timeout.
    let code = thumb(&[
        0x2300, // 0x00 movs r3, #0: 1                                       line 5
        0x6801, // 0x02 ldr r1, [r0]: 2 + 5 (an unknown base: APB1)          line 7
        0xb919, // 0x04 cbnz r1, 0x0e: 1 (+ P)
        0x3301, // 0x06 adds r3, #1: 1
        0x2bfa, // 0x08 cmp r3, #250: 1
        0xd1fa, // 0x0a bne 0x02: 1 (+ P)
        0x4770, // 0x0c bx lr: 4 (the timeout)                               line 9
        0x2001, // 0x0e movs r0, #1: 1                                        line 10
        0x4770, // 0x10 bx lr: 4
    ]);
    let img = Image::parse(&crate::testelf::elf_with_lines(
        &code,
        &[Sym::function("poll_flag", 0, 0x12)],
        "firmware/src/flag.rs",
        &[(0, 5), (2, 7), (0x0c, 9), (0x0e, 10)],
    ))
    .expect("the test image parses");
    // Counted, the loop runs to its timeout: 250 passes.
    let plain = bound_function(&img, "poll_flag", F103_0WS, &BoundsFile::default()).unwrap();
    assert_eq!(plain.loops[0].bound, 250, "{plain:?}");
    assert!(plain.loops[0].source.starts_with("counted"));
    // With the flag's latency stated, the wait is what bounds it: the way out (ldr 7, cbnz 1 + P,
    // movs 1, bx lr 4) after movs (1) = 17 cycles, the 25 µs apart; instructions: movs, the longest
    // way out by count (ldr, cbnz, adds, cmp, bne), then the longest way on from any exit (movs, bx
    // lr: the collapsed loop leaves by either) = 8, and at most one a cycle of the wait (1800 at
    // 72 MHz).
    let stated = BoundsFile::parse(
        r#"{"waits":[{"function":"poll_flag","file":"src/flag.rs","line":7,"wait_us":25.0,"source":"the flag's stated latency"}]}"#,
    )
    .unwrap();
    let b = bound_function(&img, "poll_flag", F103_0WS, &stated).unwrap();
    assert_eq!(figures(&b), (17, 8 + 1800, None));
    assert_eq!(b.bus_wait_ns, 25_000);
    assert!(
        b.loops[0].source.starts_with("wait: 25 µs"),
        "{:?}",
        b.loops
    );
}

#[test]
fn a_down_counter_tested_by_cbz_at_the_top_is_counted() {
    // `let mut k = 4; while k != 0 { x += 1; k -= 1 }` as `CBZ` at the loop's top.
    let img = image(
        &[
            0x2504, // 0x00 movs r5, #4: 1
            0xb11d, // 0x02 cbz r5, 0x0c: 1 (taken: + P)
            0x3001, // 0x04 adds r0, #1: 1
            0x3d01, // 0x06 subs r5, #1: 1
            0xe7fb, // 0x08 b 0x02: 1 + P
            0xbf00, // 0x0a nop
            0x4770, // 0x0c bx lr: 1 + P
        ],
        &[Sym::function("count_down", 0, 0x0e)],
    );
    let b = bound(&img, "count_down", F103_0WS);
    // The header runs 5 times (k = 4, 3, 2, 1, then 0 leaves): movs 1, four passes of cbz, adds,
    // subs, b (1 + 1 + 1 + 4), the cbz that leaves (1 + P), bx lr (4) = 1 + 28 + 4 + 4 = 37 cycles;
    // 1 + 4 × 4 + 1 + 1 = 19 instructions.
    assert_eq!(figures(&b), (37, 19, None));
    assert_eq!(b.loops[0].bound, 5);
    assert!(
        b.loops[0]
            .source
            .contains("by -1, compared with #0 at the loop's top"),
        "{:?}",
        b.loops[0]
    );
}

/// `spin` of [`spin_with_lines`] at 0x10 (its loop at src/spin.rs:7), called three times by `thrice`.
fn spin_called_thrice() -> Image {
    let code = thumb(&[
        0xb580, // 0x00 push {r7, lr}: 1 + 2
        0xf000, 0xf805, // 0x02 bl 0x10: 1 + P
        0xf000, 0xf803, // 0x06 bl 0x10: 1 + P
        0xf000, 0xf801, // 0x0a bl 0x10: 1 + P
        0xbd80, // 0x0e pop {r7, pc}: 1 + 2 + P
        0x6801, // 0x10 ldr r1, [r0]: 2 + 5 (an unknown base: APB1, the slowest)
        0x2900, // 0x12 cmp r1, #0: 1
        0xd1fc, // 0x14 bne 0x10: 1, taken + P
        0x4770, // 0x16 bx lr: 1 + P
    ]);
    let bytes = crate::testelf::elf_with_lines(
        &code,
        &[
            Sym::function("thrice", 0, 0x10),
            Sym::function("spin", 0x10, 8),
        ],
        "firmware/src/spin.rs",
        &[(0, 3), (0x10, 7), (0x16, 9)],
    );
    Image::parse(&bytes).expect("the test image parses")
}

#[test]
fn a_loop_stated_in_total_per_job_is_charged_once_whatever_its_entries() {
    let img = spin_called_thrice();
    let totals = BoundsFile::parse(
        r#"{"totals":[{"function":"spin","file":"src/spin.rs","line":7,"passes":5,"reason":"five polls per job in all"}]}"#,
    )
    .unwrap();
    // `spin` entered once and left at once: ldr 7, cmp 1, bne 1 (not taken), bx lr 4 = 13 cycles, 4
    // instructions. An iteration back: 9 + P = 12 cycles, 3 instructions.
    let alone = bound_function(&img, "spin", F103_0WS, &totals).unwrap();
    // Its way out, and five iterations for the whole job: 13 + 5 × 12 = 73; 4 + 5 × 3 = 19.
    assert_eq!(figures(&alone), (73, 19, None));
    assert_eq!(alone.loops.len(), 1);
    assert_eq!(alone.loops[0].bound, 5);
    assert_eq!(
        alone.loops[0].source,
        "bounds file, passes in total per job: five polls per job in all"
    );
    // Called three times: push 3, three calls of 4 + 13, pop 6 = 60 cycles, 1 + 3 × (1 + 4) + 1 =
    // 17 instructions; the five passes back once more for the whole job, not at each call:
    // 60 + 60 = 120 cycles, 17 + 15 = 32 instructions.
    let b = bound_function(&img, "thrice", F103_0WS, &totals).unwrap();
    assert_eq!(figures(&b), (120, 32, None));
    // The same five stated per entry are five passes at each of the three calls: 60 + 3 × 4 × 12 =
    // 204 cycles (a bound of 5 header runs: 4 passes back), 17 + 3 × 4 × 3 = 53 instructions.
    let per_entry = BoundsFile::parse(
        r#"{"loops":[{"function":"spin","file":"src/spin.rs","line":7,"bound":5,"reason":"five polls per call"}]}"#,
    )
    .unwrap();
    let b = bound_function(&img, "thrice", F103_0WS, &per_entry).unwrap();
    assert_eq!(figures(&b), (204, 53, None));
    // A total needs a reason, and names a place the image must have.
    assert!(BoundsFile::parse(
        r#"{"totals":[{"function":"spin","file":"src/spin.rs","line":7,"passes":5,"reason":" "}]}"#
    )
    .is_err());
    let moved = BoundsFile::parse(
        r#"{"totals":[{"function":"spin","file":"src/spin.rs","line":8,"passes":5,"reason":"x"}]}"#,
    )
    .unwrap();
    assert_eq!(moved.missing_places(&img), vec!["total spin src/spin.rs:8"]);
}

#[test]
fn a_length_no_call_fixes_names_the_call_that_passes_it() {
    // A caller reads the length from memory and passes it to `__aeabi_memclr` at line 11, which
    // passes its own argument on to its loop: the call to state is the caller's.
    let code = thumb(&with_memclr(&[
        0xb580, // 0x00 push {r7, lr}           line 10
        0x6801, // 0x02 ldr r1, [r0]
        0xf000, 0xf802, // 0x04 bl 0x0c         line 11
        0xbd80, // 0x08 pop {r7, pc}            line 12
        0xbf00, // 0x0a
    ])); // 0x0c __aeabi_memclr, line 20
    let img = Image::parse(&crate::testelf::elf_with_lines(
        &code,
        &[
            Sym::function("clear_read", 0, 10),
            Sym::function("__aeabi_memclr", 0x0c, 0x10),
        ],
        "firmware/src/c.rs",
        &[(0, 10), (4, 11), (8, 12), (0x0c, 20)],
    ))
    .expect("the test image parses");
    let b = bound_function(&img, "clear_read", F103_0WS, &BoundsFile::default()).unwrap();
    let reason = b.declined.expect("declined");
    assert!(
        reason.ends_with(
            "(the length comes from the call in clear_read at /work/firmware/src/c.rs:11)"
        ),
        "{reason}"
    );
    // The memory function alone names no call.
    let alone = bound(&img, "__aeabi_memclr", F103_0WS);
    assert!(!alone.declined.expect("declined").contains("the call in"));
    // A memory function given its length (16) that passes another one on, read from memory: its
    // own call is named, not its caller's.
    let code = thumb(&with_memclr(&[
        0xb580, // 0x00 push {r7, lr}           line 10
        0x2110, // 0x02 movs r1, #16
        0xf000, 0xf802, // 0x04 bl 0x0c         line 11
        0xbd80, // 0x08 pop {r7, pc}            line 12
        0xbf00, // 0x0a
        0x6801, // 0x0c ldr r1, [r0]            line 30 (__aeabi_memclr4)
        0xe7ff, // 0x0e b 0x10: a tail call
    ])); // 0x10 __aeabi_memclr, line 20
    let img = Image::parse(&crate::testelf::elf_with_lines(
        &code,
        &[
            Sym::function("clear_wrapped", 0, 10),
            Sym::function("__aeabi_memclr4", 0x0c, 4),
            Sym::function("__aeabi_memclr", 0x10, 0x10),
        ],
        "firmware/src/c.rs",
        &[(0, 10), (4, 11), (8, 12), (0x0c, 30), (0x10, 20)],
    ))
    .expect("the test image parses");
    let b = bound_function(&img, "clear_wrapped", F103_0WS, &BoundsFile::default()).unwrap();
    let reason = b.declined.expect("declined");
    assert!(
        reason.ends_with(
            "(the length comes from the call in __aeabi_memclr4 at /work/firmware/src/c.rs:30)"
        ),
        "{reason}"
    );
}

#[test]
fn loops_named_at_one_place_share_their_stated_total() {
    // Two polling loops one after the other, both at src/spin.rs:7 (as a loop the compiler split
    // is): each a header of ldr 7 (an unknown base: APB1), cmp 1, bne 1; the return at line 9.
    let code = thumb(&[
        0x6801, // 0x00 ldr r1, [r0]
        0x2900, // 0x02 cmp r1, #0
        0xd1fc, // 0x04 bne 0x00: taken + P
        0x6802, // 0x06 ldr r2, [r0]
        0x2a00, // 0x08 cmp r2, #0
        0xd1fc, // 0x0a bne 0x06: taken + P
        0x4770, // 0x0c bx lr: 1 + P
    ]);
    let img = Image::parse(&crate::testelf::elf_with_lines(
        &code,
        &[Sym::function("twice", 0, 0x0e)],
        "firmware/src/spin.rs",
        &[(0, 7), (0x0c, 9)],
    ))
    .expect("the test image parses");
    let shared = BoundsFile::parse(
        r#"{"totals":[{"function":"twice","file":"src/spin.rs","line":7,"passes":5,"reason":"five polls in all"}]}"#,
    )
    .unwrap();
    // Each loop's way out (9 cycles, 3 instructions), the return (4, 1), and five passes back in all
    // of the longer iteration (both 12 cycles, 3 instructions): 9 + 9 + 4 + 60 = 82; 3 + 3 + 1 +
    // 15 = 22. The statement is listed once.
    let b = bound_function(&img, "twice", F103_0WS, &shared).unwrap();
    assert_eq!(figures(&b), (82, 22, None));
    assert_eq!(b.loops.iter().filter(|l| l.bound == 5).count(), 1);
    // Stated per entry instead, five header runs each: 4 passes back each, 9 + 9 + 4 + 8 × 12 = 118.
    let each = BoundsFile::parse(
        r#"{"loops":[{"function":"twice","file":"src/spin.rs","line":7,"bound":5,"reason":"five polls each"}]}"#,
    )
    .unwrap();
    let b = bound_function(&img, "twice", F103_0WS, &each).unwrap();
    assert_eq!(figures(&b), (118, 31, None));
}

/// The I2C driver's shape: a caller fixes a length in r3 (`movs r3, #n`), an intermediate function
/// passes it on in r1 (`mov r1, r3`) to a `per_element` function whose loop runs once per element. The
/// length the outer call fixes bounds the loop two calls down; an outer call that loads the length
/// from memory leaves it declined, naming that call.
fn passes_length_on(set_r3: u16) -> Image {
    image(
        &with_memclr(&[
            0xb580, // 0x00 push {r7, lr}
            set_r3, // 0x02 movs r3, #n (or a load)
            0xf000, 0xf802, // 0x04 bl 0x0c (read)
            0xbd80, // 0x08 pop {r7, pc}
            0xbf00, // 0x0a
            0xb580, // 0x0c push {r7, lr}   (read)
            0x4619, // 0x0e mov r1, r3
            0xf000, 0xf802, // 0x10 bl 0x18 (receive)
            0xbd80, // 0x14 pop {r7, pc}
            0xbf00, // 0x16
        ]), // 0x18 receive: MEMCLR_BYTES, one store a pass, its length in r1
        &[
            Sym::function("transfer", 0, 0x0c),
            Sym::function("read", 0x0c, 0x0c),
            Sym::function("receive", 0x18, 0x10),
        ],
    )
}

#[test]
fn a_length_fixed_at_a_call_bounds_a_per_element_loop_two_calls_down() {
    let stated = BoundsFile::parse(
        r#"{"per_element":[{"function":"receive","register":1,"reason":"one pass per byte"}]}"#,
    )
    .unwrap();
    // movs r3, #6. What runs: transfer's push, movs, bl and pop (4); read's push, mov, bl and pop
    // (4); receive's movs, then 6 passes of (cmp, beq, strb, adds, subs, b) and the way out (cmp,
    // beq, bx lr): 1 + 36 + 3. 48 instructions, all of them what runs.
    let b = bound_function(&passes_length_on(0x2306), "transfer", F103_0WS, &stated).unwrap();
    assert_eq!((b.instructions, b.declined.as_deref()), (48, None));
    let l = b
        .loops
        .iter()
        .find(|l| l.function == "receive")
        .expect("the loop is listed");
    assert_eq!(l.bound, 7, "{l:?}");
    assert!(l.source.contains("at most 6 at the call (r1)"), "{l:?}");
    // Cycles (TRM, 0 wait states): 6 more elements are 6 more passes of cmp 1, beq 1 (not taken),
    // strb 2 and 5 more for a store whose address the analysis does not know (charged as an APB1
    // peripheral's, 2 × 2 + 1 on the F103), adds 1, subs 1, b 1 + P = 4: 15 cycles and 6
    // instructions each.
    let twelve = bound_function(&passes_length_on(0x230c), "transfer", F103_0WS, &stated).unwrap();
    assert_eq!(twelve.instructions, 48 + 6 * 6);
    assert_eq!(twelve.cycles, b.cycles + 6 * 15);
    // ldr r3, [r0]: the length comes from memory, no call fixes it; the reason names the call that
    // passes the unfixed length to the loop's function (read's), where a `lengths` entry would go.
    let unknown = bound_function(&passes_length_on(0x6803), "transfer", F103_0WS, &stated).unwrap();
    let reason = unknown.declined.expect("declined");
    assert!(reason.contains(length::LENGTH_UNKNOWN), "{reason}");
    assert!(reason.contains("the call in read"), "{reason}");
}

/// The I2C driver's byte loop (`Master::send`): `transfer` fixes the length in r2 (`movs r2, #n`) and
/// calls `send`, a `per_element` function (its length in r2) that copies the length to r4, tests it
/// at the loop's top (`cbz r4`), calls `poll` (a flag read) and leaves on a fault (`cmp r0, #7;
/// bne`) from inside the body, then steps r4 and goes back. `count` is the instruction that sets r4
/// (`mov r4, r2`, or `ldr r4, [r0]`: a count the length does not give); `fault` the instructions the
/// way out from the body runs before its `pop` (none: it branches to the common `pop`).
fn byte_loop(n: u16, count: u16, fault: &[u16]) -> Image {
    let k = u16::try_from(fault.len()).expect("a short fault path");
    // The fault path at 0x22, its pop after it; `poll` after that.
    let (bne, poll) = if fault.is_empty() {
        (0xd102, 0x22) // bne 0x20
    } else {
        (0xd103, 0x22 + 2 * k + 2) // bne 0x22
    };
    let mut code = vec![
        0xb580,     // 0x00 push {r7, lr}    (transfer)
        0x2200 | n, // 0x02 movs r2, #n
        0xf000,
        0xf802, // 0x04 bl 0x0c (send)
        0xbd80, // 0x08 pop {r7, pc}
        0xbf00, // 0x0a
        0xb510, // 0x0c push {r4, lr}    (send)
        count,  // 0x0e mov r4, r2 | ldr r4, [r0]
        0xb12c, // 0x10 cbz r4, 0x1e     (the header)
        0xf000,
        0xf800 | ((poll - 0x16) / 2), // 0x12 bl poll
        0x2807,                       // 0x16 cmp r0, #7
        bne,                          // 0x18 bne fault        (the way out from the body)
        0x3c01,                       // 0x1a subs r4, #1
        0xe7f8,                       // 0x1c b 0x10
        0x2007,                       // 0x1e movs r0, #7      (the header's way out)
        0xbd10,                       // 0x20 pop {r4, pc}
    ];
    if !fault.is_empty() {
        code.extend_from_slice(fault); // 0x22 the fault path
        code.push(0xbd10); // pop {r4, pc}
    }
    code.extend_from_slice(&[
        0x6808, // poll: ldr r0, [r1]
        0x4770, // bx lr
    ]);
    image(
        &code,
        &[
            Sym::function("transfer", 0, 0x0c),
            Sym::function("send", 0x0c, u64::from(poll) - 0x0c),
            Sym::function("poll", u64::from(poll), 4),
        ],
    )
}

fn byte_loop_bound(img: &Image) -> Bound {
    let stated = BoundsFile::parse(
        r#"{"per_element":[{"function":"send","register":2,"reason":"one pass per byte"}]}"#,
    )
    .unwrap();
    bound_function(img, "transfer", F103_0WS, &stated).unwrap()
}

/// `ldr r0, [r1]` from an address the analysis does not know, on the F103 at 0 wait states: 2
/// cycles, and 5 more for the access, charged as an APB1 peripheral's (2 × 2 + 1).
const UNKNOWN_LOAD: u64 = 7;

#[test]
fn a_per_element_loop_left_from_its_body_is_charged_its_passes_up_to_the_exit() {
    // Instructions: transfer's push, movs, bl, pop (4); send's push, mov (2). A pass: cbz (not
    // taken), bl, ldr, bx lr, cmp, bne (not taken), subs, b: 8. The header's way out: cbz (taken),
    // then movs, pop: 3. The body's: cbz, bl, ldr, bx lr, cmp, bne (taken), then pop: 7. The header
    // runs at most n + 1 times and its test (r4, the length, stepped by −1 to 0) ends the loop on
    // the last, so at most n passes go into the body: n passes and the header's way out (8n + 3), or
    // n − 1 passes and the body's (8n − 1). The longest run: 6 + 8n + 3 = 8n + 9 instructions.
    // Cycles (TRM, P = 3, L the load): push 3, movs 1, bl 4, pop with pc 6 (transfer 14); push 3,
    // mov 1; a pass 1 + 4 + L + 4 + 1 + 1 + 1 + 4 = 16 + L; the header's way out 4 + 1 + 6 = 11, the
    // body's 1 + 4 + L + 4 + 1 + 4 + 6 = 20 + L, less than a pass and the header's: 29 + n(16 + L).
    // Charging the body's way out after n whole passes (n + 1 polls, as a per-element loop was)
    // would be 8n + 14 instructions and n(16 + L) + 46 cycles (the loop's longest way out, the
    // body's, before its longer exit, movs and pop).
    let l = UNKNOWN_LOAD;
    for n in [1u16, 2, 7] {
        let b = byte_loop_bound(&byte_loop(n, 0x4614, &[]));
        let n64 = u64::from(n);
        assert_eq!(
            figures(&b),
            (29 + n64 * (16 + l), 8 * n64 + 9, None),
            "n = {n}"
        );
        let lp = b.loops.iter().find(|l| l.function == "send").unwrap();
        assert_eq!(lp.bound, n64 + 1, "{lp:?}");
        assert!(
            lp.source.contains("counted") && lp.source.contains(&format!("at most {n} passes")),
            "{lp:?}"
        );
    }
}

#[test]
fn a_per_element_loop_left_from_its_body_on_its_last_pass_is_charged_no_whole_pass_more() {
    // As above, with 8 `adds r0, #1` on the fault path before its own pop (9 instructions, 14
    // cycles). The run whose last pass faults: 6 + 8(n − 1) + 6 + 9 = 8n + 13 instructions, the
    // longest run. The collapsed loop is charged its longest way out before each of its exits (the
    // longer of n passes and the header's cbz, 8n + 1 instructions and n(16 + L) + 4 cycles, and n − 1
    // passes and the body's way out to its bne, 8n − 2 and n(16 + L) + 1): with the fault path,
    // 6 + 8n + 1 + 9 = 8n + 16 instructions and 18 + n(16 + L) + 4 + 14 cycles, 3 instructions above
    // the run (the header's cbz and the body's step and branch back, charged before an exit they
    // do not reach). Charging the body's way out after n whole passes would be 8n + 21 instructions,
    // n(16 + L) + 53 cycles.
    let l = UNKNOWN_LOAD;
    let fault = [0x3001; 8];
    for n in [1u16, 3, 7] {
        let b = byte_loop_bound(&byte_loop(n, 0x4614, &fault));
        let n64 = u64::from(n);
        assert_eq!(
            figures(&b),
            (36 + n64 * (16 + l), 8 * n64 + 16, None),
            "n = {n}"
        );
        assert!(b.instructions >= 8 * n64 + 13);
    }
}

#[test]
fn a_per_element_loop_whose_header_does_not_end_it_by_the_length_is_charged_whole_passes() {
    // `ldr r4, [r0]`: the header tests a count the length does not give, so its test is not known
    // to end the loop after n passes into the body. The statement (one pass per element) charges
    // n whole passes and the loop's longest way out, the body's (6 instructions; 1 + 4 + L + 4 + 1 +
    // 4 = 14 + L cycles, the header's cbz 4), before its longer exit (movs, pop: 2 and 7): 6 + 8n + 6
    // + 2 = 8n + 14 instructions; 14 + 3 + L + n(16 + L) + 14 + L + 7 cycles.
    let l = UNKNOWN_LOAD;
    for n in [1u16, 7] {
        let b = byte_loop_bound(&byte_loop(n, 0x6804, &[]));
        let n64 = u64::from(n);
        assert_eq!(
            figures(&b),
            (38 + 2 * l + n64 * (16 + l), 8 * n64 + 14, None),
            "n = {n}"
        );
        let lp = b.loops.iter().find(|l| l.function == "send").unwrap();
        assert_eq!(lp.bound, n64 + 1, "{lp:?}");
        assert!(
            lp.source.contains("each pass of this one moves at least 1"),
            "{lp:?}"
        );
    }
}

/// `tangle`: four blocks that each branch to every other one (on r1) or return, entered at each (on
/// r0): one strongly connected region with four ways in, and inside what splitting copies, more
/// regions with more than one way in — irreducible flow that node splitting would grow past
/// [`cfg::MAX_SPLIT_GROWTH`] times. Lines 10 (the entry) and 20, 21, 22, 23 (the four blocks).
fn tangle() -> Image {
    let code = thumb(&[
        0x2800, // 0x00 cmp r0, #0
        0xd004, // 0x02 beq 0x0e
        0x2801, // 0x04 cmp r0, #1
        0xd009, // 0x06 beq 0x1c
        0x2802, // 0x08 cmp r0, #2
        0xd00e, // 0x0a beq 0x2a
        0xe014, // 0x0c b 0x38
        0x2901, // 0x0e cmp r1, #1
        0xd004, // 0x10 beq 0x1c
        0x2902, // 0x12 cmp r1, #2
        0xd009, // 0x14 beq 0x2a
        0x2903, // 0x16 cmp r1, #3
        0xd00e, // 0x18 beq 0x38
        0x4770, // 0x1a bx lr
        0x2900, // 0x1c cmp r1, #0
        0xd0f6, // 0x1e beq 0x0e
        0x2902, // 0x20 cmp r1, #2
        0xd002, // 0x22 beq 0x2a
        0x2903, // 0x24 cmp r1, #3
        0xd007, // 0x26 beq 0x38
        0x4770, // 0x28 bx lr
        0x2900, // 0x2a cmp r1, #0
        0xd0ef, // 0x2c beq 0x0e
        0x2901, // 0x2e cmp r1, #1
        0xd0f4, // 0x30 beq 0x1c
        0x2903, // 0x32 cmp r1, #3
        0xd000, // 0x34 beq 0x38
        0x4770, // 0x36 bx lr
        0x2900, // 0x38 cmp r1, #0
        0xd0e8, // 0x3a beq 0x0e
        0x2901, // 0x3c cmp r1, #1
        0xd0ed, // 0x3e beq 0x1c
        0x2902, // 0x40 cmp r1, #2
        0xd0f2, // 0x42 beq 0x2a
        0x4770, // 0x44 bx lr
    ]);
    Image::parse(&crate::testelf::elf_with_lines(
        &code,
        &[Sym::function("tangle", 0, 0x46)],
        "firmware/src/tangle.rs",
        &[(0, 10), (0x0e, 20), (0x1c, 21), (0x2a, 22), (0x38, 23)],
    ))
    .expect("the test image parses")
}

#[test]
fn irreducible_flow_too_big_to_split_is_declined_at_its_place() {
    // The header splitting stops at is a copy, a block the graph as built does not have: named by
    // its instruction, the bound is declined (it was looked up among the built graph's blocks, a
    // panic: issue 33, never a panic).
    let b = bound_function(&tangle(), "tangle", F103_0WS, &BoundsFile::default())
        .expect("the function is analysed");
    let reason = b.declined.unwrap_or_default();
    assert!(
        reason.starts_with("irreducible control flow in tangle at /work/firmware/src/tangle.rs:2")
            && reason.ends_with("would grow the graph more than 4-fold"),
        "{reason}"
    );
}
