//! Known answers for a task charged per activation ([`bounds::PerActivation`]) and for a transmit interrupt
//! charged by its parts ([`bounds::PerFrame`], at the end): a hand-assembled receive
//! handler that drains a FIFO, its job bounded with the drain at its stated 6 passes and its charge per frame
//! with the drain at 2 (one frame and the pass that finds the FIFO empty), and a timer queue's interrupt, its
//! job at 19 passes and its charge per expiry at 3 (a pop, a `continue`, the last pass), each worked out from the Cortex-M3
//! TRM's cycle table as in [`super::tests`] (ARM DDI 0337, table 18-1: data processing 1, LDR 2, PUSH 1 + N,
//! POP with the PC 1 + N + P, a taken branch 1 + P, P = 3; a load from a peripheral whose base the code does not
//! fix 5 more, APB1's; flash at 0 wait states; exception entry 12 and exit 10).
use super::*;
use crate::testelf::{elf_with_lines, Sym};
use crate::thumb;

const F103_0WS: Chip = Chip::Stm32f103 { wait_states: 0 };

/// `RX`: `push {r4, lr}`, a drain loop at src/rx.rs:12 that reads a status word and counts a frame per pass
/// until it reads 0, `pop {r4, pc}`.
fn receive_handler() -> Image {
    let code = thumb(&[
        0xb510, // 0x00 push {r4, lr}: 1 + 2
        0x2400, // 0x02 movs r4, #0: 1
        0x6801, // 0x04 ldr r1, [r0]: 2 + 5 (the loop's header, line 12)
        0x2900, // 0x06 cmp r1, #0: 1
        0xd002, // 0x08 beq 0x10: 1, taken 1 + P
        0x3401, // 0x0a adds r4, #1: 1
        0x3401, // 0x0c adds r4, #1: 1
        0xe7f9, // 0x0e b 0x04: 1 + P
        0xbd10, // 0x10 pop {r4, pc}: 1 + 2 + P
    ]);
    let bytes = elf_with_lines(
        &code,
        &[Sym::function("RX", 0, 18)],
        "firmware/src/rx.rs",
        &[(0, 10), (4, 12), (0x10, 14)],
    );
    Image::parse(&bytes).expect("the test image parses")
}

fn drain(per_activation: &str) -> BoundsFile {
    BoundsFile::parse(&format!(
        r#"{{"loops":[{{"function":"RX","file":"src/rx.rs","line":12,"bound":6,"reason":"3 frames, an overrun, one more, the empty check"}}]{per_activation}}}"#
    ))
    .expect("the bounds file parses")
}

const PER_FRAME: &str = r#","per_activation":[{"task":"rx","function":"RX","file":"src/rx.rs","line":12,"passes":2,"reason":"a job that drains k frames costs at most k charges"}]"#;

fn rx_task() -> Task {
    Task {
        name: "rx".into(),
        entry: TaskEntry::Symbol("RX".into()),
        handler: true,
    }
}

#[test]
fn a_task_charged_per_activation_has_its_job_and_its_charge() {
    let img = receive_handler();
    let rows = bound_tasks(&img, &[rx_task()], F103_0WS, &drain(PER_FRAME));
    let rx = &rows[0];
    // A pass with a frame: ldr 7, cmp 1, beq not taken 1, two adds 2, b 1 + P = 4: 15 cycles, 6
    // instructions. The pass that ends: ldr 7, cmp 1, beq taken 4: 12 cycles, 3 instructions. Around the loop:
    // push 3, movs 1, pop 6: 10 cycles, 3 instructions. The handler's entry and exit: 12 + 10.
    // The job, the header run 6 times: 5 × 15 + 12 + 10 + 22 = 119 cycles; 5 × 6 + 3 + 3 = 36 instructions.
    assert_eq!(
        (rx.cycles, rx.instructions, rx.declined.as_deref()),
        (119, 36, None)
    );
    assert_eq!(rx.loops[0].bound, 6);
    // Per activation, the header run twice: 15 + 12 + 10 + 22 = 59 cycles; 6 + 3 + 3 = 12 instructions.
    let charge = rx.per_activation.as_ref().expect("charged per activation");
    assert_eq!(
        (
            charge.cycles,
            charge.instructions,
            charge.declined.as_deref()
        ),
        (59, 12, None)
    );
    assert_eq!(charge.passes, 2);
    assert_eq!(charge.at, "RX at src/rx.rs:12");
    // Sound per frame: a job that drains k frames (1 ≤ k ≤ 5) costs 15 k + 44 ≤ 59 k.
    for k in 1..=5u64 {
        assert!(15 * k + 44 <= k * charge.cycles);
    }
    assert!(rx.cycles <= 5 * charge.cycles);
    // 72 MHz: 59 cycles are 0.820 µs (rounded up to the ns).
    assert_eq!(charge.us, 0.82);
    // Without the statement, no charge.
    let rows = bound_tasks(&img, &[rx_task()], F103_0WS, &drain(""));
    assert!(rows[0].per_activation.is_none());
    assert_eq!(rows[0].cycles, 119);
}

#[test]
fn a_charge_whose_loop_is_not_on_the_task_path_is_declined() {
    let img = receive_handler();
    let other = Task {
        name: "rx".into(),
        entry: TaskEntry::Symbol("RX".into()),
        handler: true,
    };
    // The file states a loop of another function for the charge.
    let bounds = BoundsFile::parse(
        r#"{"loops":[{"function":"RX","file":"src/rx.rs","line":12,"bound":6,"reason":"r"},
                     {"function":"TX","file":"src/tx.rs","line":3,"bound":4,"reason":"r"}],
            "per_activation":[{"task":"rx","function":"TX","file":"src/tx.rs","line":3,"passes":2,"reason":"r"}]}"#,
    )
    .unwrap();
    let rows = bound_tasks(&img, &[other], F103_0WS, &bounds);
    assert_eq!(rows[0].cycles, 119);
    let charge = rows[0].per_activation.as_ref().unwrap();
    assert!(charge
        .declined
        .as_deref()
        .is_some_and(|r| r.contains("TX at src/tx.rs:3 is not on the task's path")));
}

#[test]
fn a_charge_needs_a_stated_loop_passes_within_its_bound_and_a_reason() {
    let refused = |entry: &str| {
        matches!(
            BoundsFile::parse(&format!(
                r#"{{"loops":[{{"function":"RX","file":"src/rx.rs","line":12,"bound":6,"reason":"r"}}],"per_activation":[{entry}]}}"#
            )),
            Err(crate::Error::Bounds(_))
        )
    };
    assert!(refused(
        r#"{"task":"rx","function":"RX","file":"src/rx.rs","line":12,"passes":7,"reason":"r"}"#
    ));
    assert!(refused(
        r#"{"task":"rx","function":"RX","file":"src/rx.rs","line":13,"passes":2,"reason":"r"}"#
    ));
    assert!(refused(
        r#"{"task":"rx","function":"RX","file":"src/rx.rs","line":12,"passes":0,"reason":"r"}"#
    ));
    assert!(refused(
        r#"{"task":"rx","function":"RX","file":"src/rx.rs","line":12,"passes":2,"reason":" "}"#
    ));
    assert!(!refused(
        r#"{"task":"rx","function":"RX","file":"src/rx.rs","line":12,"passes":2,"reason":"r"}"#
    ));
}

/// `TQ`: a timer queue's interrupt as rtic-time's `on_monotonic_interrupt` runs it: `push {r4, lr}`, a loop at
/// src/tq.rs:20 whose pass reads the head (none: the queue is empty, the loop ends), reads whether it is due
/// (due: a pop, counted, and round again) and, not due, whether the time passed it meanwhile (round again: the
/// `continue`; else the loop ends), `pop {r4, pc}`.
fn timer_queue_handler() -> Image {
    let code = thumb(&[
        0xb510, // 0x00 push {r4, lr}: 1 + 2
        0x2400, // 0x02 movs r4, #0: 1
        0x6801, // 0x04 ldr r1, [r0]: 2 + 5 (the head; the loop's header, line 20)
        0xb131, // 0x06 cbz r1, 0x16: 1, taken 1 + P (the queue empty)
        0x680a, // 0x08 ldr r2, [r1]: 2 + 5 (due?)
        0xb10a, // 0x0a cbz r2, 0x10: 1, taken 1 + P (not due)
        0x3401, // 0x0c adds r4, #1: 1 (the pop and its wake)
        0xe7f9, // 0x0e b 0x04: 1 + P
        0x684b, // 0x10 ldr r3, [r1, #4]: 2 + 5 (passed meanwhile?)
        0x2b00, // 0x12 cmp r3, #0: 1
        0xd1f6, // 0x14 bne 0x04: 1, taken 1 + P (the `continue`)
        0xbd10, // 0x16 pop {r4, pc}: 1 + 2 + P
    ]);
    let bytes = elf_with_lines(
        &code,
        &[Sym::function("TQ", 0, 24)],
        "firmware/src/tq.rs",
        &[(0, 10), (4, 20), (0x16, 30)],
    );
    Image::parse(&bytes).expect("the test image parses")
}

#[test]
fn a_timer_interrupt_charged_per_expiry_covers_every_job_and_what_its_continues_leave() {
    let img = timer_queue_handler();
    let bounds = BoundsFile::parse(
        r#"{"loops":[{"function":"TQ","file":"src/tq.rs","line":20,"bound":19,"reason":"9 waiters: a pop each, a continue before each, the last pass"}],
            "per_activation":[{"task":"tq","function":"TQ","file":"src/tq.rs","line":20,"passes":3,"reason":"a job that serves k expiries costs at most k charges"}]}"#,
    )
    .expect("the bounds file parses");
    let task = Task {
        name: "tq".into(),
        entry: TaskEntry::Symbol("TQ".into()),
        handler: true,
    };
    let rows = bound_tasks(&img, &[task], F103_0WS, &bounds);
    let tq = &rows[0];
    // The passes: a pop — ldr 7, cbz 1, ldr 7, cbz 1, adds 1, b 4 — 21 cycles, 6 instructions; a `continue` —
    // ldr 7, cbz 1, ldr 7, cbz taken 4, ldr 7, cmp 1, bne taken 4 — 31 cycles, 7 instructions (the longest,
    // P); the last — the same with bne not taken, 28 cycles, 7 instructions — or the empty queue's, ldr 7,
    // cbz taken 4: 11 cycles. Around the loop: push 3, movs 1, pop 6: 10 cycles, 3 instructions; entry and
    // exit 12 + 10. So F = 32 cycles outside the loop's passes.
    // The job, the header run 19 times: 18 × 31 + 28 + 32 = 618 cycles; 18 × 7 + 7 + 3 = 136 instructions.
    assert_eq!(
        (tq.cycles, tq.instructions, tq.declined.as_deref()),
        (618, 136, None)
    );
    // Per expiry, the header run 3 times: 2 × 31 + 28 + 32 = 122 cycles; 2 × 7 + 7 + 3 = 24 instructions.
    let charge = tq.per_activation.as_ref().expect("charged per expiry");
    assert_eq!(
        (
            charge.cycles,
            charge.instructions,
            charge.declined.as_deref()
        ),
        (122, 24, None)
    );
    // Sound per expiry (the bounds files' argument): a job that pops k expiries with c `continue`s costs
    // F + 21 k + 31 c + 28 (its last pass not a pop), and each `continue` may leave one more job whose first
    // pass pops nothing, charged F + P = 63 to it. A job whose first pass pops has c <= k - 1; in any other
    // job that pops, the first pass is a `continue` too (c + 1 <= k of them), and even with that pass's
    // F + P counted in (the bounds files charge it to what started the job) it stays within k charges.
    let (f, p) = (32, 31);
    for k in 1..=9u64 {
        for c in 0..k {
            let job = f + 21 * k + 31 * c + 28;
            assert!(job + c * (f + p) <= k * charge.cycles, "k {k}, c {c}");
            let other = 21 * k + 31 * c + 28;
            assert!(
                other + (c + 1) * (f + p) <= k * charge.cycles,
                "k {k}, c + 1"
            );
        }
    }
    // And the one job that serves every waiter is within its 9 charges, as it is within its own bound.
    assert!(tq.cycles <= 9 * charge.cycles);
}

/// A `BL` from `at` to `target` (both offsets in the code), its two halfwords.
fn bl(at: u32, target: u32) -> [u16; 2] {
    let imm = target.wrapping_sub(at + 4);
    let s = (imm >> 31) & 1;
    [
        (0xf000 | (s << 10) | ((imm >> 12) & 0x3ff)) as u16,
        (0xf800 | ((imm >> 1) & 0x7ff)) as u16,
    ]
}

/// `TX`: a transmit interrupt as `tasks::transmit_pending` runs it. A completion scan at src/tx.rs:20 over
/// three mailboxes (a counter to 3) reads each mailbox's flag and, set, calls `C`, the completion; then a
/// transmit loop at src/tx.rs:30 reads the queue's head (none: the loop ends), whether a mailbox is free
/// (none: Busy, the loop ends) and fills it. `C` reads whether the frame was sent; not sent (aborted), it calls
/// `Q`, the requeue's search.
fn transmit_handler() -> Image {
    let [c0, c1] = bl(0x0c, 0x22);
    let [q0, q1] = bl(0x28, 0x30);
    let code = thumb(&[
        0xb530, // 0x00 push {r4, r5, lr}: 1 + 3
        0x2400, // 0x02 movs r4, #0: 1
        0x2c03, // 0x04 cmp r4, #3: 1 (the scan's header, line 20)
        0xda05, // 0x06 bge 0x14: 1, taken 1 + P
        0x6801, // 0x08 ldr r1, [r0]: 2 + 5 (the mailbox's completion flag)
        0xb109, // 0x0a cbz r1, 0x10: 1, taken 1 + P
        c0, c1,     // 0x0c bl C: 1 + P
        0x3401, // 0x10 adds r4, #1: 1
        0xe7f7, // 0x12 b 0x04: 1 + P
        0x6841, // 0x14 ldr r1, [r0, #4]: 2 + 5 (the queue's head; the transmit loop's header, line 30)
        0xb119, // 0x16 cbz r1, 0x20: 1, taken 1 + P (empty)
        0x6882, // 0x18 ldr r2, [r0, #8]: 2 + 5 (a free mailbox?)
        0xb10a, // 0x1a cbz r2, 0x20: 1, taken 1 + P (Busy)
        0x3501, // 0x1c adds r5, #1: 1 (the mailbox filled)
        0xe7f9, // 0x1e b 0x14: 1 + P
        0xbd30, // 0x20 pop {r4, r5, pc}: 1 + 3 + P
        0xb510, // 0x22 C: push {r4, lr}: 1 + 2
        0x68c1, // 0x24 ldr r1, [r0, #12]: 2 + 5 (sent?)
        0xb911, // 0x26 cbnz r1, 0x2e: 1, taken 1 + P (sent)
        q0, q1,     // 0x28 bl Q: 1 + P (aborted: requeued)
        0x3401, // 0x2c adds r4, #1: 1
        0xbd10, // 0x2e pop {r4, pc}: 1 + 2 + P
        0x6901, // 0x30 Q: ldr r1, [r0, #16]: 2 + 5
        0x3101, // 0x32 adds r1, #1: 1
        0x4770, // 0x34 bx lr: 1 + P
    ]);
    let bytes = elf_with_lines(
        &code,
        &[
            Sym::function("TX", 0, 0x22),
            Sym::function("C", 0x22, 0x0e),
            Sym::function("Q", 0x30, 0x06),
        ],
        "firmware/src/tx.rs",
        &[
            (0, 10),
            (4, 20),
            (0x14, 30),
            (0x20, 40),
            (0x22, 50),
            (0x30, 60),
        ],
    );
    Image::parse(&bytes).expect("the test image parses")
}

fn transmit_bounds(per_frame: &str) -> BoundsFile {
    BoundsFile::parse(&format!(
        r#"{{"loops":[{{"function":"TX","file":"src/tx.rs","line":20,"bound":4,"reason":"three mailboxes and the test that ends"}},
                     {{"function":"TX","file":"src/tx.rs","line":30,"bound":5,"reason":"four fills and the pass that ends"}}]{per_frame}}}"#
    ))
    .expect("the bounds file parses")
}

fn tx_task() -> Task {
    Task {
        name: "tx".into(),
        entry: TaskEntry::Symbol("TX".into()),
        handler: true,
    }
}

#[test]
fn a_transmit_interrupt_has_its_parts_per_job_frame_and_abort() {
    let img = transmit_handler();
    let per_frame = r#","per_frame":[{"task":"tx","function":"TX","file":"src/tx.rs","line":30,"completion":"C","completions":3,"requeue":"Q","reason":"a job costs at most its parts"}]"#;
    let rows = bound_tasks(&img, &[tx_task()], F103_0WS, &transmit_bounds(per_frame));
    let tx = &rows[0];
    // C: sent — push 3, ldr 7, cbnz taken 4, pop 6: 20 cycles, 4 instructions; aborted — push 3, ldr 7, cbnz 1,
    // bl 4, Q (ldr 7, adds 1, bx 4: 12 cycles, 3 instructions), adds 1, pop 6: 34 cycles, 9 instructions.
    // The scan's passes: nothing collected — cmp 1, bge 1, ldr 7, cbz taken 4, adds 1, b 4: 18 cycles, 6
    // instructions; a completion — cmp 1, bge 1, ldr 7, cbz 1, bl 4, C, adds 1, b 4: 19 + C (39 sent, 11
    // instructions; 53 aborted, 16); its way out: cmp 1, bge taken 4: 5 cycles, 2 instructions.
    // The transmit loop's pass that fills: ldr 7, cbz 1, ldr 7, cbz 1, adds 1, b 4: 21 cycles, 6 instructions;
    // its way out, Busy: ldr 7, cbz 1, ldr 7, cbz taken 4: 19 cycles, 4 instructions (empty: 11).
    // Around the loops: push 4, movs 1, pop 7: 12 cycles, 3 instructions; entry and exit 12 + 10.
    // The job: 12 + 22 + (3 × 53 + 5) + (4 × 21 + 19) = 301 cycles; 3 + (3 × 16 + 2) + (4 × 6 + 4) = 81.
    assert_eq!(
        (tx.cycles, tx.instructions, tx.declined.as_deref()),
        (301, 81, None)
    );
    let parts = tx.per_frame.as_ref().expect("charged by its parts");
    assert_eq!(parts.declined, None);
    // Fixed: C left out, the transmit loop at one pass: 12 + 22 + (3 × 18 + 5) + 19 = 112 cycles;
    // 3 + (3 × 6 + 2) + 4 = 27 instructions.
    assert_eq!((parts.fixed.cycles, parts.fixed.instructions), (112, 27));
    // A pass: 21 cycles, 6 instructions. A completion: 39 − 18 = 21 cycles, 5 instructions. An abort beyond
    // it: 53 − 39 = 14 cycles (C's 34 aborted less its 20 sent), 16 − 11 = 5 instructions.
    assert_eq!((parts.pass.cycles, parts.pass.instructions), (21, 6));
    assert_eq!((parts.sent.cycles, parts.sent.instructions), (21, 5));
    assert_eq!((parts.abort.cycles, parts.abort.instructions), (14, 5));
    assert_eq!(
        (parts.per_frame.cycles, parts.per_frame.instructions),
        (42, 11)
    );
    // The job's bound is its parts at their worst: 4 fills and 3 aborted completions.
    assert_eq!(
        parts.fixed.cycles + 4 * parts.pass.cycles + 3 * (parts.sent.cycles + parts.abort.cycles),
        tx.cycles
    );
    // Every job within its parts: q fills (0..=4), s sent and a aborted completions (s + a <= 3), the
    // transmit loop left Busy (the longer way out), each scan pass as it ran.
    for q in 0..=4u64 {
        for s in 0..=3u64 {
            for a in 0..=(3 - s) {
                let scan = 18 * (3 - s - a) + 39 * s + 53 * a + 5;
                let job = 12 + 22 + scan + 21 * q + 19;
                let charged = parts.fixed.cycles
                    + q * parts.pass.cycles
                    + s * parts.sent.cycles
                    + a * (parts.sent.cycles + parts.abort.cycles);
                assert_eq!(job, charged, "q {q}, s {s}, a {a}");
            }
        }
    }
    // Without the statement, no parts.
    let rows = bound_tasks(&img, &[tx_task()], F103_0WS, &transmit_bounds(""));
    assert!(rows[0].per_frame.is_none());
}

#[test]
fn parts_whose_functions_do_not_fit_the_scan_are_declined() {
    let img = transmit_handler();
    let declined = |completion: &str, completions: u64, requeue: &str| {
        let entry = format!(
            r#","per_frame":[{{"task":"tx","function":"TX","file":"src/tx.rs","line":30,"completion":"{completion}","completions":{completions},"requeue":"{requeue}","reason":"r"}}]"#
        );
        let rows = bound_tasks(&img, &[tx_task()], F103_0WS, &transmit_bounds(&entry));
        assert_eq!(rows[0].cycles, 301);
        rows[0].per_frame.clone().expect("stated").declined
    };
    // A requeue the image does not have (inlined).
    assert!(declined("C", 3, "R").is_some_and(|r| r.contains("R:")));
    // The scan stated at two passes where it makes three: the requeue's share is not twice C's own.
    assert!(declined("C", 2, "Q").is_some_and(|r| r.contains("not 2 times")));
    // The requeue named as the completion: Q calls no Q.
    assert!(declined("Q", 3, "Q").is_some());
    assert_eq!(declined("C", 3, "Q"), None);
    // The file refuses an entry without completions, a reason, or a stated transmit loop.
    let refused = |entry: &str| {
        matches!(
            BoundsFile::parse(&format!(
                r#"{{"loops":[{{"function":"TX","file":"src/tx.rs","line":30,"bound":5,"reason":"r"}}],"per_frame":[{entry}]}}"#
            )),
            Err(crate::Error::Bounds(_))
        )
    };
    assert!(refused(
        r#"{"task":"tx","function":"TX","file":"src/tx.rs","line":30,"completion":"C","completions":0,"requeue":"Q","reason":"r"}"#
    ));
    assert!(refused(
        r#"{"task":"tx","function":"TX","file":"src/tx.rs","line":30,"completion":"C","completions":3,"requeue":"Q","reason":" "}"#
    ));
    assert!(refused(
        r#"{"task":"tx","function":"TX","file":"src/tx.rs","line":31,"completion":"C","completions":3,"requeue":"Q","reason":"r"}"#
    ));
    assert!(!refused(
        r#"{"task":"tx","function":"TX","file":"src/tx.rs","line":30,"completion":"C","completions":3,"requeue":"Q","reason":"r"}"#
    ));
}
