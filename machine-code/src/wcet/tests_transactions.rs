//! Known answers for a bus transaction's cap ([`super::bounds::TransactionCap`]): a hand-assembled
//! transfer of the I2C master's shape — `caller` fixes the length (`movs r3, #n`) and calls `xfer`,
//! which passes it to `send` (a per-element byte loop that polls a flag once per byte) and then polls
//! the flag once more (the transfer's end) — bounded with its flag waits stated one at a time,
//! uncapped and capped. Cycles from the Cortex-M3 TRM's table as in [`super::tests`] (data processing
//! 1, LDR 2, PUSH/POP 1 + N, a taken branch or `BL` 1 + P, `CBZ` 1 and + P when taken, P = 3; a load
//! from an unknown base charged as an APB1 peripheral's, 5 more; flash at 0 wait states, its lines
//! hidden by the instructions).
use super::*;
use crate::testelf::{elf_with_lines, Sym};
use crate::thumb;

const F103_0WS: Chip = Chip::Stm32f103 { wait_states: 0 };

/// The transfer of `n` bytes (see the module documentation); `wait`'s loop is at src/i2c.rs:109.
fn transfer(n: u16) -> Image {
    let code = thumb(&[
        0xb580,     // 0x00 push {r7, lr}: 3          (caller)
        0x2300 | n, // 0x02 movs r3, #n: 1
        0xf000,
        0xf804, // 0x04 bl 0x10 (xfer): 4
        0xbd80, // 0x08 pop {r7, pc}: 6
        0xbf00, // 0x0a (no function)
        0xbf00, // 0x0c
        0xbf00, // 0x0e
        0xb580, // 0x10 push {r7, lr}: 3          (xfer)
        0x461a, // 0x12 mov r2, r3: 1
        0xf000,
        0xf804, // 0x14 bl 0x20 (send): 4
        0xf000,
        0xf80a, // 0x18 bl 0x30 (wait): 4
        0xbd80, // 0x1c pop {r7, pc}: 6
        0xbf00, // 0x1e (no function)
        0xb510, // 0x20 push {r4, lr}: 3          (send)
        0x4614, // 0x22 mov r4, r2: 1
        0xb11c, // 0x24 cbz r4, 0x2e: 1, taken + P (the header)
        0xf000,
        0xf803, // 0x26 bl 0x30 (wait): 4
        0x3c01, // 0x2a subs r4, #1: 1
        0xe7fa, // 0x2c b 0x24: 4
        0xbd10, // 0x2e pop {r4, pc}: 6
        0x6801, // 0x30 ldr r1, [r0]: 2 + 5       (wait: the flag)
        0x2900, // 0x32 cmp r1, #0: 1
        0xd0fc, // 0x34 beq 0x30: 1, taken + P
        0x4770, // 0x36 bx lr: 4
    ]);
    let bytes = elf_with_lines(
        &code,
        &[
            Sym::function("caller", 0, 0x0a),
            Sym::function("xfer", 0x10, 0x0e),
            Sym::function("send", 0x20, 0x10),
            Sym::function("wait", 0x30, 0x08),
        ],
        "firmware/src/i2c.rs",
        &[(0, 1), (0x10, 10), (0x20, 20), (0x30, 109)],
    );
    Image::parse(&bytes).expect("the test image parses")
}

/// The statements every run shares: `send` one pass per byte of r2, `wait`'s flag at 25 µs; and
/// `transactions`, the caps.
fn bounds(transactions: &str) -> BoundsFile {
    BoundsFile::parse(&format!(
        r#"{{"per_element":[{{"function":"send","register":2,"reason":"one pass per byte"}}],
            "waits":[{{"function":"wait","file":"src/i2c.rs","line":109,"wait_us":25,
                       "source":"one byte at 400 kHz, rounded"}}],
            "transactions":[{transactions}]}}"#
    ))
    .expect("the test file parses")
}

/// A cap on `xfer` of `fixed` µs and `per_byte` µs a byte of r3, holding the waits at `line`.
fn cap(fixed: f64, per_byte: f64, line: u32) -> String {
    format!(
        r#"{{"function":"xfer","register":3,"fixed_us":{fixed},"per_byte_us":{per_byte},
            "waits":[{{"function":"wait","file":"src/i2c.rs","line":{line}}}],
            "reason":"the flags wait in sum at most the transfer's wire time"}}"#
    )
}

/// The worked figures of `caller` with `n` bytes, (cycles, instructions).
///
/// * `wait`: one pass out (ldr 7, cmp 1, beq not taken 1) and bx lr 4, so 13 cycles; 3 + 1
///   instructions and at most one a cycle of its 25 µs (1 800).
/// * `send`: push 3, mov 1, n passes (cbz 1, bl 4, wait 13, subs 1, b 4: 23 each), the header's way
///   out (cbz taken 4, pop 6): 14 + 23n cycles; 2 + n (4 + 1 804) + 2 instructions.
/// * `xfer`: push 3, mov 1, bl 4, send, bl 4, wait 13, pop 6: 45 + 23n cycles; 3 + send + 1 +
///   1 804 + 1 instructions.
/// * `caller`: push 3, movs 1, bl 4, xfer, pop 6: 59 + 23n cycles and n + 1 flags; 3 + xfer + 1,
///   so 1 817 + 1 808n instructions.
fn worked(n: u64) -> (u64, u64) {
    (59 + 23 * n, 1817 + 1808 * n)
}

#[test]
fn an_uncapped_transfer_charges_every_flag_its_stated_wait() {
    for n in [1u16, 2, 5] {
        let b = bound_function(&transfer(n), "caller", F103_0WS, &bounds("")).unwrap();
        let n64 = u64::from(n);
        assert_eq!(b.declined, None);
        assert_eq!((b.cycles, b.instructions), worked(n64), "n = {n}");
        assert_eq!(b.bus_wait_ns, (n64 + 1) * 25_000, "n = {n}");
    }
}

#[test]
fn a_capped_transfer_charges_the_smaller_of_its_flags_and_its_cap() {
    // 10 µs + 20 µs a byte: below the n + 1 flags' 25 µs each for every n, so the cap is charged in
    // place of them: n = 1 30 µs (of 50), n = 2 50 µs (of 75), n = 5 110 µs (of 150). The cycles
    // and the instruction count stay the machine code's (the count keeps the flags': the QEMU runs
    // are held to it).
    for (n, capped_us) in [(1u16, 30u64), (2, 50), (5, 110)] {
        let b = bound_function(
            &transfer(n),
            "caller",
            F103_0WS,
            &bounds(&cap(10.0, 20.0, 109)),
        )
        .unwrap();
        assert_eq!(b.declined, None);
        assert_eq!((b.cycles, b.instructions), worked(u64::from(n)), "n = {n}");
        assert_eq!(b.bus_wait_ns, capped_us * 1000, "n = {n}");
        let info = b
            .loops
            .iter()
            .find(|l| l.source.starts_with("transaction cap"))
            .expect("the cap is listed with the loops");
        assert_eq!(info.function, "xfer");
        assert!(
            info.source.contains(&format!("{n} bytes at the call (r3)")),
            "{info:?}"
        );
    }
    // 40 µs + 30 µs a byte is above the flags' sum for n = 1 (70 against 50): the flags' sum stays.
    let b = bound_function(
        &transfer(1),
        "caller",
        F103_0WS,
        &bounds(&cap(40.0, 30.0, 109)),
    )
    .unwrap();
    assert_eq!(b.bus_wait_ns, 50_000);
    assert_eq!((b.cycles, b.instructions), worked(1));
    // A cap without a length register: its fixed figure at every call.
    let fixed = r#"{"function":"xfer","fixed_us":30,
        "waits":[{"function":"wait","file":"src/i2c.rs","line":109}],"reason":"x"}"#;
    let b = bound_function(&transfer(5), "caller", F103_0WS, &bounds(fixed)).unwrap();
    assert_eq!(b.bus_wait_ns, 30_000);
}

#[test]
fn a_cap_holds_only_the_waits_it_names() {
    // The cap names a place no stated wait is at: the flags at src/i2c.rs:109 are not its, so the
    // bound is the uncapped one (the cap would hold nothing: min(75, 75 + 1) µs).
    let b = bound_function(
        &transfer(2),
        "caller",
        F103_0WS,
        &bounds(&cap(1.0, 0.0, 110)),
    )
    .unwrap();
    assert_eq!(b.bus_wait_ns, 75_000);
    assert_eq!((b.cycles, b.instructions), worked(2));
}

#[test]
fn a_cap_applies_to_its_function_only() {
    // Bounded alone, `send` has no length (declined, as before); `wait` alone is one flag, uncapped.
    let stated = bounds(&cap(10.0, 20.0, 109));
    let send = bound_function(&transfer(2), "send", F103_0WS, &stated).unwrap();
    assert!(send.declined.is_some());
    let wait = bound_function(&transfer(2), "wait", F103_0WS, &stated).unwrap();
    assert_eq!((wait.cycles, wait.bus_wait_ns), (13, 25_000));
}

#[test]
fn a_cap_needs_its_figures_its_waits_and_a_reason() {
    for bad in [
        // A per-byte figure without the register that holds the length.
        r#"{"function":"xfer","fixed_us":1,"per_byte_us":2,"waits":[{"function":"wait","file":"a.rs","line":1}],"reason":"x"}"#,
        // No waits.
        r#"{"function":"xfer","fixed_us":1,"waits":[],"reason":"x"}"#,
        // A negative figure.
        r#"{"function":"xfer","fixed_us":-1,"waits":[{"function":"wait","file":"a.rs","line":1}],"reason":"x"}"#,
        // No reason.
        r#"{"function":"xfer","fixed_us":1,"waits":[{"function":"wait","file":"a.rs","line":1}],"reason":" "}"#,
        // A register that is no argument's.
        r#"{"function":"xfer","register":4,"fixed_us":1,"per_byte_us":1,"waits":[{"function":"wait","file":"a.rs","line":1}],"reason":"x"}"#,
    ] {
        let text = format!(r#"{{"transactions":[{bad}]}}"#);
        assert!(
            matches!(BoundsFile::parse(&text), Err(Error::Bounds(_))),
            "{bad}"
        );
    }
}

/// The statements of [`bounds`] and `calls`, the calls in total per job.
fn bounds_with_calls(calls: &str) -> BoundsFile {
    BoundsFile::parse(&format!(
        r#"{{"per_element":[{{"function":"send","register":2,"reason":"one pass per byte"}}],
            "waits":[{{"function":"wait","file":"src/i2c.rs","line":109,"wait_us":25,
                       "source":"one byte at 400 kHz, rounded"}}],
            "calls":[{calls}]}}"#
    ))
    .expect("the test file parses")
}

#[test]
fn a_function_called_at_most_once_per_job_is_charged_once() {
    // `wait` stated as called at most once per job: of the n + 1 calls on the longest path each costs
    // only its `bl` (4 cycles, one instruction) where it is made, and the job's bound adds one call,
    // 13 cycles, 25 µs and 1 804 instructions: 59 + 23n − 13(n + 1) + 13 = 59 + 10n cycles,
    // 1 817 + 1 808n − 1 804n = 1 817 + 4n instructions, 25 µs of waits.
    let once = r#"{"function":"wait","calls":1,"reason":"the test's: at most one flag a job"}"#;
    for n in [1u16, 2, 5] {
        let n64 = u64::from(n);
        let b = bound_function(&transfer(n), "caller", F103_0WS, &bounds_with_calls(once)).unwrap();
        assert_eq!(b.declined, None);
        assert_eq!(
            (b.cycles, b.instructions, b.bus_wait_ns),
            (59 + 10 * n64, 1817 + 4 * n64, 25_000),
            "n = {n}"
        );
        let info = b
            .loops
            .iter()
            .find(|l| l.source.starts_with("bounds file, calls in total per job"))
            .expect("the statement is listed with the loops");
        assert_eq!((info.function.as_str(), info.bound), ("wait", 1));
    }
    // At n + 1 calls or more the bound is the uncapped one.
    let many = r#"{"function":"wait","calls":3,"reason":"the test's"}"#;
    let b = bound_function(&transfer(2), "caller", F103_0WS, &bounds_with_calls(many)).unwrap();
    assert_eq!((b.cycles, b.instructions), worked(2));
    assert_eq!(b.bus_wait_ns, 75_000);
    // A count of 0 or no reason is refused.
    for bad in [
        r#"{"function":"wait","calls":0,"reason":"x"}"#,
        r#"{"function":"wait","calls":1,"reason":" "}"#,
    ] {
        let text = format!(r#"{{"calls":[{bad}]}}"#);
        assert!(
            matches!(BoundsFile::parse(&text), Err(Error::Bounds(_))),
            "{bad}"
        );
    }
}
