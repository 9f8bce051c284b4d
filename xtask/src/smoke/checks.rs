//! What a production boot must show: its log's steps in order, and its monotonic's timer set up and
//! counting.
use crate::boards::MonotonicTimer;

use super::environment::Ending;

/// The monotonic's report of a timer without compare events (`amiro_firmware::timer_monotonic`).
pub const MISSED_COMPARE: &str = "monotonic: a half-period compare event went missing";

/// The watchdog task's first feed: the board's periodic work ran and the watchdog task woke on
/// the monotonic (`amiro_firmware::watchdog::feed`).
pub const FIRST_FEED: &str = "watchdog: first feed";

/// What the production boot must have logged, in this order (`docs/faults.md`, "The production
/// image in QEMU"). QEMU emulates no clock tree and no bxCAN: the log must say so.
pub fn check_log(log: &str, ending: Ending) -> Vec<String> {
    let lines: Vec<&str> = log.lines().collect();
    let find = |what: &str| lines.iter().position(|l| l.starts_with(what));
    let mut failures = Vec::new();
    if let Some(panic) = lines.iter().find(|l| l.starts_with("panic")) {
        failures.push(format!("the board panicked: `{panic}`"));
    }
    match lines.first() {
        Some(first) if first.starts_with("boot: ") && first.ends_with(", watchdog running") => {}
        Some(first) => failures.push(format!(
            "the first line must report the boot with the watchdog already running, not `{first}`"
        )),
        None => failures.push("the log is empty".into()),
    }
    // Each step: a line starting with it, after the step before.
    let running = find("clock: running on ");
    let fault = lines
        .iter()
        .position(|l| l.starts_with("clock: ") && !l.starts_with("clock: running on "));
    if !matches!((fault, running), (Some(f), Some(r)) if f < r) {
        failures
            .push("missing a clock fault before the clock in use (QEMU has no clock tree)".into());
    }
    let mut steps: Vec<(&str, &str)> = vec![
        (
            "clock: running on internal oscillator without PLL",
            "the fallback to the internal oscillator",
        ),
        ("power lines: ", "the power lines in AMiRo-BLT's state"),
        (
            "CAN: silent: ",
            "CAN reported silent (QEMU has no bxCAN at 0x40006400)",
        ),
        (
            "watchdog: reset after 500 ms",
            "the watchdog switched to its run-time timeout at the end of init",
        ),
        ("init: done", "the end of init"),
    ];
    match ending {
        Ending::Running => {}
        Ending::HandOver(_) => steps.extend([
            (
                "shutdown requested from outside",
                "the shutdown task (RTIC runs the tasks)",
            ),
            (
                "watchdog: reset after 26214 ms",
                "the watchdog stretched to its longest before the hand-over",
            ),
        ]),
    }
    let mut after = 0;
    for (prefix, meaning) in steps {
        match lines.iter().skip(after).position(|l| l.starts_with(prefix)) {
            Some(at) => after += at + 1,
            None => {
                let anywhere = find(prefix).is_some();
                failures.push(format!(
                    "missing {meaning}: no line `{prefix}…`{}",
                    if anywhere { " in its place" } else { "" }
                ));
            }
        }
    }
    if let (Some(clock), Some(power)) = (find("clock: running on "), find("power lines: ")) {
        if clock > power {
            failures.push("the power lines were set before the clock tree".into());
        }
    }
    // The monotonic's interrupt ran (after init, which runs with interrupts off) and its event
    // accounting saw what QEMU's timer lacks.
    let init = find("init: done");
    let missed = find(MISSED_COMPARE);
    match ending {
        Ending::Running if !matches!((init, missed), (Some(i), Some(m)) if i < m) => {
            failures.push(format!(
                "missing the monotonic's report of QEMU's missing compare events after init: no \
                 line `{MISSED_COMPARE}…`"
            ))
        }
        Ending::Running if find(FIRST_FEED).is_none() => failures.push(format!(
            "no `{FIRST_FEED}`: the watchdog task never saw its periodic work done, so tasks did \
             not wake on the monotonic (in QEMU a wake can also be lost to its timer model, see \
             docs/faults.md)"
        )),
        Ending::HandOver(_) if missed.is_some() => failures.push(
            "the monotonic ticked before the hand-over (the shutdown path should be immediate)"
                .into(),
        ),
        _ => {}
    }
    failures
}

/// What the monotonic's timer registers (`before`, and `after` a moment of running) must show:
/// counting microseconds of `timer_clock_hz` (PSC), a 16-bit period (ARR), the half-period compare
/// (CCR1 at 0x8000), the update and compare-1 interrupts (DIER), enabled (CR1.CEN), and counting.
pub fn check_timer(
    timer: &MonotonicTimer,
    before: &[u32],
    after: &[u32],
    timer_clock_hz: u32,
) -> Vec<String> {
    const CR1: usize = 0;
    const DIER: usize = 0x0C / 4;
    const CNT: usize = 0x24 / 4;
    const PSC: usize = 0x28 / 4;
    const ARR: usize = 0x2C / 4;
    const CCR1: usize = 0x34 / 4;
    let mut failures = Vec::new();
    if before.len() < 16 || after.len() < 16 {
        return vec![format!("{}: too few registers read", timer.name)];
    }
    let psc = timer_clock_hz / 1_000_000 - 1;
    for (what, index, mask, expected) in [
        ("CR1.CEN (enabled)", CR1, 1, 1),
        ("DIER (update and compare-1 interrupts)", DIER, 0b11, 0b11),
        ("PSC (1 MHz from the clock in use)", PSC, 0xFFFF, psc),
        ("ARR (a 16-bit period)", ARR, 0xFFFF_FFFF, 0xFFFF),
        ("CCR1 (the half-period compare)", CCR1, 0xFFFF_FFFF, 0x8000),
    ] {
        let value = after[index] & mask;
        if value != expected {
            failures.push(format!(
                "the monotonic's {} at {:#010x}: {what} is {value:#x}, not {expected:#x}",
                timer.name, timer.base
            ));
        }
    }
    if before[CNT] == after[CNT] {
        failures.push(format!(
            "the monotonic's {} does not count (CNT stays {:#x})",
            timer.name, after[CNT]
        ));
    }
    failures
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = "boot: LightRing, watchdog running\n\
        clock: reset: the internal oscillator never got ready\n\
        clock: the crystal did not start\n\
        clock: the flash did not take its wait states\n\
        clock: running on internal oscillator without PLL\n\
        power lines: SYS_SYNC_N held low\n\
        CAN: silent: the controller did not enter initialisation mode\n\
        watchdog: reset after 500 ms without a feed\n\
        init: done; RTIC starts the tasks\n\
        monotonic: a half-period compare event went missing; time goes on from the updates\n\
        watchdog: first feed (the tasks and the monotonic run)\n";

    #[test]
    fn a_complete_boot_log_passes() {
        assert_eq!(check_log(GOOD, Ending::Running), Vec::<String>::new());
        let handed_over = GOOD
            .replace(
                "init: done; RTIC starts the tasks\n",
                "init: done; RTIC starts the tasks\n\
                 shutdown requested from outside: publishers stopped\n\
                 watchdog: reset after 26214 ms without a feed\n",
            )
            .replace(
                &format!("{MISSED_COMPARE}; time goes on from the updates\n"),
                "",
            )
            .replace(
                "watchdog: first feed (the tasks and the monotonic run)\n",
                "",
            );
        assert_eq!(
            check_log(&handed_over, Ending::HandOver("restart")),
            Vec::<String>::new()
        );
        let ticked_first = format!("{handed_over}{MISSED_COMPARE}\n");
        assert_eq!(
            check_log(&ticked_first, Ending::HandOver("restart")).len(),
            1
        );
        let without_task = handed_over.replace("shutdown requested from outside", "shutdown");
        assert!(!check_log(&without_task, Ending::HandOver("restart")).is_empty());
        assert!(!check_log(&handed_over, Ending::Running).is_empty());
    }

    #[test]
    fn each_missing_or_misplaced_step_fails() {
        let steps: [&[usize]; 9] = [&[0], &[1, 2, 3], &[4], &[5], &[6], &[7], &[8], &[9], &[10]];
        for drop in steps {
            let log: String = GOOD
                .lines()
                .enumerate()
                .filter(|(i, _)| !drop.contains(i))
                .map(|(_, l)| format!("{l}\n"))
                .collect();
            assert!(
                !check_log(&log, Ending::Running).is_empty(),
                "without lines {drop:?}:\n{log}"
            );
        }
        let late_watchdog = GOOD.replace(", watchdog running", ", watchdog NOT running");
        assert!(!check_log(&late_watchdog, Ending::Running).is_empty());
        let panicked = format!("{GOOD}panic at src/main.rs:12\n");
        assert_eq!(check_log(&panicked, Ending::Running).len(), 1);
        let swapped = GOOD
            .replace("power lines: SYS_SYNC_N held low\n", "")
            .replace(
                "boot: LightRing, watchdog running\n",
                "boot: LightRing, watchdog running\npower lines: early\n",
            );
        assert!(!check_log(&swapped, Ending::Running).is_empty());
        let tick_before_init =
            GOOD.replace("init: done; RTIC starts the tasks\n", "") + "init: done\n";
        assert!(!check_log(&tick_before_init, Ending::Running).is_empty());
        // The run-time timeout set by a task after init (as before `tasks::come_up` set it).
        let watchdog_in_a_task = GOOD
            .replace("watchdog: reset after 500 ms without a feed\n", "")
            .replace(
                "init: done; RTIC starts the tasks\n",
                "init: done; RTIC starts the tasks\nwatchdog: reset after 500 ms without a feed\n",
            );
        assert_eq!(check_log(&watchdog_in_a_task, Ending::Running).len(), 1);
    }

    #[test]
    fn the_monotonic_timer_must_be_set_up_and_counting() {
        let timer = crate::boards::BOARDS[1].monotonic_timer;
        let mut regs = vec![0u32; 16];
        regs[0] = 1;
        regs[3] = 0b11;
        regs[9] = 0x1234;
        regs[10] = 15;
        regs[11] = 0xFFFF;
        regs[13] = 0x8000;
        let mut later = regs.clone();
        later[9] = 0x2345;
        assert_eq!(
            check_timer(&timer, &regs, &later, 16_000_000),
            Vec::<String>::new()
        );
        assert_eq!(check_timer(&timer, &regs, &regs, 16_000_000).len(), 1);
        assert_eq!(check_timer(&timer, &regs, &later, 8_000_000).len(), 1);
        let mut unarmed = later.clone();
        unarmed[11] = 0;
        assert_eq!(check_timer(&timer, &regs, &unarmed, 16_000_000).len(), 1);
        let base = |name| crate::boards::by_name(name).unwrap().monotonic_timer.base;
        assert_eq!(base("lightring"), 0x4000_0400);
        assert_eq!(base("diwheeldrive"), 0x4000_0C00);
        assert_eq!(base("powermgmt"), 0x4000_0000);
    }
}
