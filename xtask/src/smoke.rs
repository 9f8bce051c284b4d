//! `cargo xtask smoke [BOARD…]`: the production images, booted on emulated silicon.
//!
//! Every other QEMU run uses the `qemu` builds (no clock tree, no bxCAN). This one boots the image
//! a robot runs — byte for byte what `cargo xtask flash` writes: the release ELF's load segments
//! with the AMiRo-BLT checksum word filled in — behind a stand-in for AMiRo-BLT at `0x0800_0000`
//! that does what the bootloader's hand-over does (VTOR = application base, MSP from its first
//! word, jump to its reset vector), on the QEMU machine nearest the board's chip: `netduinoplus2`
//! (STM32F405) for PowerManagement, `netduino2` (STM32F205, whose TIM2..TIM5 and SPI1 sit where
//! the F103's do) for DiWheelDrive and LightRing. QEMU emulates neither RCC nor bxCAN nor flash
//! interface nor IWDG nor GPIO on these machines (their registers read as zero), which is what a
//! chip whose clocks never come up looks like: the run shows that the boot's waits on them end
//! and are reported. Before booting, each ELF is scanned for unbounded waits ([`waits`]).
//!
//! The run is steered over QMP (QEMU's JSON monitor) on QEMU's standard input and output: every
//! [`POLL`] the guest is stopped, its program counter read and its RAM saved (`pmemsave`); the
//! RTT log channel is read out of the RAM image at the `_SEGGER_RTT` control block (found by
//! symbol as `cargo xtask bench` finds it on a probe, or by scanning RAM for its ID), the
//! monotonic's half-period counter (`amiro_firmware::timer_monotonic`, every board's) at its
//! symbol. The inputs the boot reads and QEMU has no GPIO for are held at the robot's level
//! ([`environment`]): by the stand-in, or through QEMU's gdbstub ([`gdb`]). It fails when the board halts (a panic or a HardFault parks the CPU in `fault::halt`),
//! when the monotonic's counter stops while QEMU runs, and when the log misses a step of the boot
//! ([`check_log`]).
//!
//! [`run_board`] takes one board and its ELF, so a caller can run it once per board revision.
use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::mpsc::{self, Receiver};
use std::time::{Duration, Instant};

use anyhow::{bail, ensure, Context, Result};
use object::{Object, ObjectSymbol};

mod gdb;

use crate::boards::Board;
use crate::qemu::ICOUNT_SHIFT;

/// Where the stand-in for AMiRo-BLT goes: where the chip starts.
pub const STANDIN_BASE: u32 = 0x0800_0000;
/// Both chips' SRAM.
const RAM_BASE: u32 = 0x2000_0000;
/// How often the guest is stopped and looked at (wall time).
const POLL: Duration = Duration::from_millis(250);
/// How many half periods of the monotonic make a run: QEMU's timer model has no compare events,
/// so each of its update interrupts counts two (`timer_monotonic::advance`): 32 interrupts.
pub const HALF_PERIODS: u32 = 64;
/// How long the monotonic's counter may stand still, counted in CPU time QEMU got meanwhile (not
/// wall time: on a loaded machine a correct image's QEMU may wait for a core far longer than it
/// runs; issue 34).
const STALL: Duration = Duration::from_secs(15);
/// The CPU-time guard of one board's run (QEMU's own CPU time, as [`STALL`]).
const CPU_LIMIT: Duration = Duration::from_secs(120);
/// The wall-time guard of last resort (a QEMU that gets no CPU at all for this long is not
/// waited for): far beyond any correct run on a busy 2-core machine.
const WALL_LIMIT: Duration = Duration::from_secs(900);
/// How long QEMU's monitor may take to answer one command (wall time).
const MONITOR_WAIT: Duration = Duration::from_secs(60);

/// The CPU time (user + system) process `pid` has had so far, from `/proc/PID/stat`; `None`
/// where that cannot be read (then the wall-time guards alone apply).
fn cpu_time(pid: u32) -> Option<Duration> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // The command name (field 2) is in parentheses and may hold spaces: count from after it.
    let fields: Vec<&str> = stat.rsplit_once(')')?.1.split_whitespace().collect();
    let ticks = fields.get(11)?.parse::<u64>().ok()? + fields.get(12)?.parse::<u64>().ok()?;
    // SAFETY: sysconf has no preconditions.
    let per_second = unsafe { libc::sysconf(libc::_SC_CLK_TCK) };
    let per_second = u64::try_from(per_second).ok().filter(|&n| n > 0)?;
    Some(Duration::from_millis(ticks * 1000 / per_second))
}

/// Where the stand-in's callbacks start (one `b .` each), right behind its vector table.
const CALLBACK_CODE: u32 = STANDIN_BASE + 8;
/// Where its start-up code starts.
const STARTUP_CODE: u32 = STANDIN_BASE + 0x14;
/// AMiRo-BLT's callback table (`amiro_firmware::bootloader::CALLBACK_TABLE`).
const CALLBACK_TABLE: u32 = STANDIN_BASE + 0x1C0;
/// The callbacks in table order (`amiro_firmware::bootloader::Callback`, offsets 16..32).
pub const CALLBACKS: [&str; 5] = [
    "hibernate",
    "deep sleep",
    "transportation",
    "restart",
    "handle a shutdown request",
];

/// The stand-in for AMiRo-BLT: a two-word vector table (stack in low RAM, reset vector to the
/// start-up code); one `b .` per callback; the start-up code — for each `(address, value)` of
/// `environment` `ldr r2, =address; ldr r3, =value; str r3, [r2]`, then AMiRo-BLT's hand-over
/// `ldr r0, =app; ldr r1, =VTOR; str r0, [r1]; ldr r1, [r0]; msr msp, r1; ldr r1, [r0, #4];
/// bx r1` — and its literals; and at [`CALLBACK_TABLE`] the table the application looks for
/// (magic "A-BL", three version words, the five callbacks, seven reserved words), so a hand-over
/// parks the CPU where the run sees which callback the board chose.
pub fn standin(app_base: u32, environment: &[(u32, u32)]) -> Vec<u8> {
    const VTOR: u32 = 0xE000_ED08;
    // Instructions: a plain halfword, or `ldr rt, [pc, #…]` of a literal.
    enum Op {
        Half(u16),
        Literal(u16, u32),
    }
    let mut ops = Vec::new();
    for &(address, value) in environment {
        ops.extend([
            Op::Literal(2, address),
            Op::Literal(3, value),
            Op::Half(0x6013),
        ]); // str r3, [r2]
    }
    ops.extend([
        Op::Literal(0, app_base),
        Op::Literal(1, VTOR),
        Op::Half(0x6008), // str r0, [r1]
        Op::Half(0x6801), // ldr r1, [r0]: the application's initial stack pointer
        Op::Half(0xF381), // msr msp, r1
        Op::Half(0x8808),
        Op::Half(0x6841), // ldr r1, [r0, #4]: its reset vector
        Op::Half(0x4708), // bx r1
    ]);
    let start = (STARTUP_CODE - STANDIN_BASE) as usize;
    let pool = (start + 2 * ops.len()).next_multiple_of(4);
    let mut out = Vec::with_capacity(0x200);
    out.extend_from_slice(&(RAM_BASE + 0x1000).to_le_bytes());
    out.extend_from_slice(&(STARTUP_CODE + 1).to_le_bytes());
    for _ in CALLBACKS {
        out.extend_from_slice(&0xE7FEu16.to_le_bytes()); // b .
    }
    out.resize(start, 0xFF);
    let mut literals = Vec::new();
    for (i, op) in ops.iter().enumerate() {
        let half = match *op {
            Op::Half(half) => half,
            Op::Literal(rt, value) => {
                let at = pool + 4 * literals.len();
                literals.push(value);
                let pc = (start + 2 * i + 4) & !3;
                0x4800 | rt << 8 | ((at - pc) / 4) as u16
            }
        };
        out.extend_from_slice(&half.to_le_bytes());
    }
    out.resize(pool, 0xFF);
    for value in literals {
        out.extend_from_slice(&value.to_le_bytes());
    }
    assert!(
        out.len() <= (CALLBACK_TABLE - STANDIN_BASE) as usize,
        "stand-in too long"
    );
    out.resize((CALLBACK_TABLE - STANDIN_BASE) as usize, 0xFF);
    out.extend_from_slice(&0x412D_424Cu32.to_le_bytes());
    out.extend_from_slice(&[0; 12]);
    for i in 0..CALLBACKS.len() as u32 {
        out.extend_from_slice(&(CALLBACK_CODE + 2 * i + 1).to_le_bytes());
    }
    out.extend_from_slice(&[0; 28]);
    out
}

/// Which callback of the stand-in the CPU sits in, if any.
pub fn callback_at(pc: u32) -> Option<&'static str> {
    let offset = (pc & !1).checked_sub(CALLBACK_CODE)?;
    CALLBACKS.get((offset / 2) as usize).copied()
}

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
    /// ([`gdb::hold_inputs`]): the port reads zero and drops writes.
    Watchpoint,
}

/// The F103's GPIOC (RM0008 §9): its input data register is at offset 8.
const F103_GPIOC_IDR: u32 = 0x4001_1000 + 0x08;
/// The F205's USART1 on `netduino2` (QEMU's `stm32f205_soc.c`) and its baud-rate register
/// (offset 8), which QEMU's USART model stores and reads back without side effects.
const F205_USART1_BRR: u32 = 0x4001_1000 + 0x08;

/// The F405's GPIOC input data register (RM0090 §8.4.5), PowerManagement's SYS_PD_N port.
const F405_GPIOC_IDR: u32 = 0x4002_0800 + 0x10;

/// The environment set up around the image on `machine` (the robot's, not the firmware's
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
pub fn environment(machine: &str) -> &'static [Input] {
    const _: () = assert!(F103_GPIOC_IDR == F205_USART1_BRR);
    match machine {
        "netduino2" => &[Input {
            address: F103_GPIOC_IDR,
            value: 1 << 8 | 1 << 14,
            stands_for: "SYS_PD_N released (PC8 / PC14 held high by the robot's pull-ups)",
            through: "netduino2's USART1_BRR, which reads back, at the F103's GPIOC_IDR",
            via: Via::StandIn,
        }],
        "netduinoplus2" => &[Input {
            address: F405_GPIOC_IDR,
            value: 1 << 13,
            stands_for: "SYS_PD_N released (PC13 held high by the robot's pull-up)",
            through: "a gdbstub read watchpoint on GPIOC_IDR, PC13 set in each load's result",
            via: Via::Watchpoint,
        }],
        _ => &[],
    }
}

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
pub fn expected_ending(machine: &str) -> Ending {
    if environment(machine).is_empty() {
        Ending::HandOver("handle a shutdown request")
    } else {
        Ending::Running
    }
}

/// The flash contents from `base` on: every load segment at its address, gaps erased (0xFF).
pub fn flash_image(segments: &[(u64, Vec<u8>)], base: u64) -> Result<Vec<u8>> {
    let end = segments
        .iter()
        .map(|(at, bytes)| at + bytes.len() as u64)
        .max()
        .context("no load segments")?;
    ensure!(end > base, "the image ends before its base {base:#x}");
    let mut image = vec![0xFF; (end - base) as usize];
    for (at, bytes) in segments {
        ensure!(
            *at >= base,
            "a load segment at {at:#x} lies below the application base {base:#x}"
        );
        let from = (at - base) as usize;
        image[from..from + bytes.len()].copy_from_slice(bytes);
    }
    Ok(image)
}

/// The up-channel `channel`'s bytes in a RAM image (`ram` starts at [`RAM_BASE`]), from the RTT
/// control block at `control` (or, if `None`, wherever RAM holds its ID), read from the channel's
/// read to its write offset (nothing on the host reads it, so that is everything written, up to
/// the channel's size).
pub fn rtt_up_channel(ram: &[u8], control: Option<u32>, channel: u32) -> Result<Vec<u8>> {
    const ID: &[u8] = b"SEGGER RTT";
    let word = |addr: u32| -> Result<u32> {
        let at = addr
            .checked_sub(RAM_BASE)
            .context("an RTT address below RAM")? as usize;
        let bytes = ram
            .get(at..at + 4)
            .with_context(|| format!("RTT address {addr:#x} beyond the saved RAM"))?;
        Ok(u32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]))
    };
    let control = match control {
        Some(at) => at,
        None => {
            let at = ram
                .windows(ID.len())
                .position(|w| w == ID)
                .context("no RTT control block in RAM (did the firmware set up its log?)")?;
            RAM_BASE + at as u32
        }
    };
    let at = control
        .checked_sub(RAM_BASE)
        .context("the RTT control block lies below RAM")? as usize;
    ensure!(
        ram.get(at..at + ID.len()) == Some(ID),
        "no RTT control block at {control:#x} yet (the firmware has not set up its log)"
    );
    let max_up = word(control + 16)?;
    ensure!(
        channel < max_up,
        "the firmware has {max_up} RTT up-channels, not {}",
        channel + 1
    );
    let desc = control + 24 + 24 * channel;
    let (buffer, size, write, read) = (
        word(desc + 4)?,
        word(desc + 8)?,
        word(desc + 12)?,
        word(desc + 16)?,
    );
    ensure!(
        size > 0 && write < size && read < size,
        "RTT up-channel {channel} is damaged (size {size}, write {write}, read {read})"
    );
    let byte = |offset: u32| -> Result<u8> {
        let at = (buffer + offset)
            .checked_sub(RAM_BASE)
            .context("RTT buffer below RAM")? as usize;
        ram.get(at)
            .copied()
            .context("RTT buffer beyond the saved RAM")
    };
    let mut out = Vec::new();
    let mut offset = read;
    while offset != write {
        out.push(byte(offset)?);
        offset = (offset + 1) % size;
    }
    Ok(out)
}

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
        ("init: done", "the end of init"),
    ];
    match ending {
        Ending::Running => steps.push((
            "watchdog: reset after 500 ms",
            "the watchdog task's start (RTIC runs the tasks)",
        )),
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
    // The monotonic's interrupt ran and its event accounting saw what QEMU's timer lacks (its
    // first interrupt may come before or after the watchdog task's start).
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

/// A board's monotonic timer (its `board.rs` / `mono.rs`: `amiro_firmware::timer_monotonic!`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MonotonicTimer {
    /// Its name on the chip.
    pub name: &'static str,
    /// Its registers' base address (the same on the chip and on the board's QEMU machine).
    pub base: u32,
}

/// Which timer each board's monotonic runs on: DiWheelDrive TIM5 (TIM2–TIM4 drive its motors and
/// count its encoders), LightRing TIM3, PowerManagement TIM2 — all where QEMU's machines model
/// them (TIM2–TIM5 at the F103's and the F405's addresses).
pub fn monotonic_timer(board: &str) -> MonotonicTimer {
    match board {
        "diwheeldrive" => MonotonicTimer {
            name: "TIM5",
            base: 0x4000_0C00,
        },
        "lightring" => MonotonicTimer {
            name: "TIM3",
            base: 0x4000_0400,
        },
        _ => MonotonicTimer {
            name: "TIM2",
            base: 0x4000_0000,
        },
    }
}

/// The internal oscillator of the chip a machine stands for: the clock the boards fall back to
/// in QEMU, whose RCC reads as reset (F103 8 MHz, F405 16 MHz; every bus undivided, so the timers'
/// input too).
pub fn internal_oscillator_hz(machine: &str) -> u32 {
    if machine == "netduinoplus2" {
        16_000_000
    } else {
        8_000_000
    }
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

/// The symbols the run needs from the ELF.
struct Symbols {
    rtt: Option<u32>,
    /// The monotonic's half-period counter (`timer_monotonic::HalfPeriods`, its count first).
    counter: u32,
    /// `amiro_firmware::fault::halt`, where a panic or a HardFault parks the CPU.
    halt: std::ops::Range<u32>,
}

fn symbols(elf: &[u8]) -> Result<Symbols> {
    let file = object::File::parse(elf).context("parsing the firmware ELF")?;
    let find = |pred: &dyn Fn(&str) -> bool| {
        file.symbols()
            .find(|s| !s.is_undefined() && s.name().map(pred).unwrap_or(false) && s.address() != 0)
    };
    let counter = find(&|n| n.contains("HALF_PERIODS"))
        .context("no monotonic half-period counter (HALF_PERIODS) in the ELF")?;
    let halt = find(&|n| n.contains("14amiro_firmware5fault4halt"))
        .context("no amiro_firmware::fault::halt in the ELF")?;
    let start = (halt.address() & !1) as u32;
    Ok(Symbols {
        rtt: crate::elf::rtt_control_block(elf).map(|a| a as u32),
        counter: counter.address() as u32,
        halt: start..start + halt.size().max(2) as u32,
    })
}

/// QEMU steered over QMP on its standard input and output.
struct Qmp {
    child: Child,
    input: ChildStdin,
    lines: Receiver<String>,
}

impl Qmp {
    fn start(command: &mut Command) -> Result<Self> {
        let mut child = command
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .context("starting qemu-system-arm (install it: apt-get install qemu-system-arm)")?;
        let input = child.stdin.take().context("QEMU stdin")?;
        let output = child.stdout.take().context("QEMU stdout")?;
        let (tx, lines) = mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(output).lines() {
                let Ok(line) = line else { break };
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        let mut qmp = Self {
            child,
            input,
            lines,
        };
        qmp.reply(None)?; // the greeting
        qmp.execute("qmp_capabilities", None)?;
        Ok(qmp)
    }

    /// The next reply (skipping events); `None` sends nothing first.
    fn reply(&mut self, send: Option<&serde_json::Value>) -> Result<serde_json::Value> {
        if let Some(message) = send {
            writeln!(self.input, "{message}").context("writing to QEMU's monitor")?;
            self.input.flush()?;
        }
        loop {
            let line = self.lines.recv_timeout(MONITOR_WAIT).with_context(|| {
                format!(
                    "QEMU's monitor did not answer {} within {MONITOR_WAIT:?} of wall time (did QEMU exit?)",
                    send.map_or_else(|| "its greeting".to_string(), |m| format!("`{m}`"))
                )
            })?;
            let Ok(value) = serde_json::from_str::<serde_json::Value>(&line) else {
                continue;
            };
            if value.get("event").is_some() {
                continue;
            }
            if let Some(error) = value.get("error") {
                bail!("QEMU's monitor: {error}");
            }
            return Ok(value);
        }
    }

    fn execute(
        &mut self,
        command: &str,
        arguments: Option<serde_json::Value>,
    ) -> Result<serde_json::Value> {
        let mut message = serde_json::json!({ "execute": command });
        if let Some(arguments) = arguments {
            message["arguments"] = arguments;
        }
        let reply = self.reply(Some(&message))?;
        Ok(reply.get("return").cloned().unwrap_or_default())
    }

    /// `count` words of the guest's physical memory from `address` (device registers too: the
    /// human monitor's `xp` reads through the machine's bus).
    fn words(&mut self, address: u32, count: usize) -> Result<Vec<u32>> {
        let dump = self.execute(
            "human-monitor-command",
            Some(serde_json::json!({ "command-line": format!("xp /{count}wx {address:#x}") })),
        )?;
        let words: Vec<u32> = dump
            .as_str()
            .unwrap_or_default()
            .lines()
            .filter_map(|line| line.split_once(": ").map(|(_, rest)| rest))
            .flat_map(|rest| rest.split_whitespace())
            .map(|word| u32::from_str_radix(word.trim_start_matches("0x"), 16))
            .collect::<Result<_, _>>()
            .context("QEMU's `xp` answered something other than hex words")?;
        ensure!(
            words.len() == count,
            "QEMU's `xp` gave {} words, not {count}",
            words.len()
        );
        Ok(words)
    }

    /// The guest's program counter, from the human monitor's register dump.
    fn pc(&mut self) -> Result<u32> {
        let dump = self.execute(
            "human-monitor-command",
            Some(serde_json::json!({ "command-line": "info registers" })),
        )?;
        let text = dump.as_str().unwrap_or_default();
        let hex = text
            .split_once("R15=")
            .map(|(_, rest)| rest.chars().take(8).collect::<String>())
            .context("no R15 in QEMU's register dump")?;
        u32::from_str_radix(&hex, 16).context("R15 is not hex")
    }

    fn save_ram(&mut self, size: u64, file: &Path) -> Result<Vec<u8>> {
        self.execute(
            "pmemsave",
            Some(serde_json::json!({
                "val": RAM_BASE,
                "size": size,
                "filename": file.to_string_lossy(),
            })),
        )?;
        std::fs::read(file).with_context(|| format!("reading {}", file.display()))
    }
}

impl Drop for Qmp {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// One board's smoke run: its log, and what failed.
pub struct Outcome {
    /// The board's RTT log at the end of the run.
    pub log: String,
    /// The AMiRo-BLT callback the board handed over to, if it did.
    pub handed_over: Option<&'static str>,
    /// The monotonic's half periods counted during the run.
    pub half_periods: u32,
    /// Loads of a watched input set to the robot's level ([`Via::Watchpoint`]), if any.
    pub patched_loads: Option<u32>,
    /// Everything that went wrong (empty: passed).
    pub failures: Vec<String>,
}

/// Boots `board`'s production image (built and checked by `cargo xtask build`) in QEMU and checks
/// its boot. `work` holds the images, the RAM snapshots and QEMU's stderr.
pub fn run_board(board: &Board, elf_path: &Path, work: &Path) -> Result<Outcome> {
    std::fs::create_dir_all(work)?;
    // The bytes `cargo xtask flash` writes: the ELF with its AMiRo-BLT checksum word, its segments.
    let patched = work.join(format!("{}.blt.elf", board.name));
    crate::elf::write_checksum(elf_path, &patched)?;
    let elf = std::fs::read(&patched)?;
    let image = flash_image(&crate::elf::load_segments(&elf)?, board.app_base)?;
    let image_path = work.join("application.bin");
    std::fs::write(&image_path, &image)?;
    let standin_path = work.join("amiro-blt-standin.bin");
    std::fs::write(
        &standin_path,
        standin(
            board.app_base as u32,
            &environment(board.qemu_machine)
                .iter()
                .filter(|input| input.via == Via::StandIn)
                .map(|input| (input.address, input.value))
                .collect::<Vec<_>>(),
        ),
    )?;
    let symbols = symbols(&elf)?;
    let stderr_path = work.join("qemu-stderr.log");

    let mut qemu = Command::new("qemu-system-arm");
    qemu.args(["-machine", board.qemu_machine, "-display", "none"])
        .args(["-monitor", "none", "-serial", "null"])
        .args([
            "-chardev",
            "stdio,id=qmp",
            "-mon",
            "chardev=qmp,mode=control",
        ])
        .args([
            "-icount",
            &format!("shift={ICOUNT_SHIFT},align=off,sleep=off"),
        ])
        .args(["-device", &loader(&standin_path, STANDIN_BASE.into())])
        .args(["-device", &loader(&image_path, board.app_base)])
        .current_dir(work);
    let watched: Vec<(u32, u32)> = environment(board.qemu_machine)
        .iter()
        .filter(|input| input.via == Via::Watchpoint)
        .map(|input| (input.address, input.value))
        .collect();
    let gdb_socket = work.join("gdb.sock");
    if !watched.is_empty() {
        let _ = std::fs::remove_file(&gdb_socket);
        // Held at reset until the watchpoints are in; the gdbstub starts the guest.
        qemu.arg("-chardev")
            .arg(format!(
                "socket,id=gdb,path={},server=on,wait=off",
                gdb_socket.display()
            ))
            .args(["-gdb", "chardev:gdb", "-S"]);
    }

    let mut qmp = Qmp::start(&mut qemu)?;
    let steering = gdb::Steering::default();
    let patcher = if watched.is_empty() {
        None
    } else {
        Some(gdb::hold_inputs(&gdb_socket, watched, steering.clone())?)
    };
    let stderr = qmp.child.stderr.take();
    let stderr_file = std::fs::File::create(&stderr_path)?;
    if let Some(mut stderr) = stderr {
        let mut stderr_file = stderr_file;
        std::thread::spawn(move || std::io::copy(&mut stderr, &mut stderr_file));
    }

    let snapshot = work.join("ram.bin");
    let started = Instant::now();
    let mut first: Option<u32> = None;
    let pid = qmp.child.id();
    let cpu = || cpu_time(pid).unwrap_or_default();
    // The counter's last change: its value, the wall time and QEMU's CPU time then.
    let mut last = (0u32, Instant::now(), cpu());
    let mut log = String::new();
    let mut failures = Vec::new();
    let mut handed_over = None;
    let ending = expected_ending(board.qemu_machine);
    loop {
        std::thread::sleep(POLL);
        if let Some(status) = qmp.child.try_wait()? {
            failures.push(format!("QEMU exited ({status})"));
            break;
        }
        if started.elapsed() > WALL_LIMIT {
            failures.push(format!(
                "the run did not end within the wall-time guard of {WALL_LIMIT:?} (QEMU had \
                 {:.1} s of CPU; the guest stayed stopped at a watched input?)",
                cpu().as_secs_f64()
            ));
            break;
        }
        let held = steering.lock().unwrap_or_else(|poison| poison.into_inner());
        qmp.execute("stop", None)?;
        let status = qmp.execute("query-status", None)?;
        if status.get("status").and_then(|s| s.as_str()) == Some("debug") {
            // Stopped at a watched input: the patcher's to resume.
            drop(held);
            continue;
        }
        let pc = qmp.pc()?;
        let ram = qmp.save_ram(board.ram_bytes, &snapshot)?;
        qmp.execute("cont", None)?;
        drop(held);
        if let Ok(bytes) = rtt_up_channel(&ram, symbols.rtt, 0) {
            log = String::from_utf8_lossy(&bytes).into_owned();
        }
        let at = (symbols.counter - RAM_BASE) as usize;
        let counter = ram
            .get(at..at + 4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .unwrap_or_default();
        if let Some(callback) = callback_at(pc) {
            handed_over = Some(callback);
            break;
        }
        if symbols.halt.contains(&(pc & !1)) {
            failures.push(format!(
                "the board halted in fault::halt (a panic or a HardFault; pc {pc:#010x})"
            ));
            break;
        }
        let base = *first.get_or_insert(counter);
        if counter != last.0 {
            last = (counter, Instant::now(), cpu());
        }
        if ending == Ending::Running && counter.wrapping_sub(base) >= HALF_PERIODS {
            break;
        }
        let stalled_cpu = cpu().saturating_sub(last.2);
        if stalled_cpu > STALL {
            failures.push(format!(
                "no progress: the monotonic's half-period counter stayed at {counter} while QEMU \
                 ran {:.1} s of CPU (the stall guard is {STALL:?} of QEMU's CPU; {:.1} s of wall \
                 time; pc {pc:#010x})",
                stalled_cpu.as_secs_f64(),
                last.1.elapsed().as_secs_f64()
            ));
            break;
        }
        if cpu() > CPU_LIMIT || started.elapsed() > WALL_LIMIT {
            failures.push(format!(
                "only {} of {HALF_PERIODS} half periods of the monotonic when the run's guard \
                 ended it: {:.1} s of QEMU's CPU (guard {CPU_LIMIT:?}), {:.1} s of wall time \
                 (guard {WALL_LIMIT:?})",
                counter.wrapping_sub(base),
                cpu().as_secs_f64(),
                started.elapsed().as_secs_f64()
            ));
            break;
        }
    }
    let half_periods = last.0.wrapping_sub(first.unwrap_or(last.0));
    // The monotonic's timer as the board left it (after a hand-over too: AMiRo-BLT's hand-over
    // masks the interrupts, it does not stop the timer).
    let timer = monotonic_timer(board.name);
    let timer_state = (|| -> Result<_> {
        let before = qmp.words(timer.base, 16)?;
        std::thread::sleep(Duration::from_millis(20));
        Ok((before, qmp.words(timer.base, 16)?))
    })();
    drop(qmp);
    let mut patched_loads = None;
    if let Some(patcher) = patcher {
        match patcher.join() {
            Ok(Ok(patched)) => patched_loads = Some(patched),
            Ok(Err(error)) => failures.push(format!("holding the inputs: {error:#}")),
            Err(_) => failures.push("the input patcher panicked".into()),
        }
    }
    match timer_state {
        Ok((before, after)) => failures.extend(check_timer(
            &timer,
            &before,
            &after,
            internal_oscillator_hz(board.qemu_machine),
        )),
        Err(error) => failures.push(format!(
            "could not read the monotonic's timer {} at {:#010x}: {error:#}",
            timer.name, timer.base
        )),
    }
    match (ending, handed_over) {
        (Ending::Running, Some(callback)) => failures.push(format!(
            "the board handed over to AMiRo-BLT's `{callback}` callback instead of running on"
        )),
        (Ending::HandOver(expected), None) => failures.push(format!(
            "the board did not hand over to AMiRo-BLT's `{expected}` callback"
        )),
        (Ending::HandOver(expected), Some(callback)) if callback != expected => failures.push(
            format!("the board handed over to `{callback}`, not `{expected}`"),
        ),
        _ => {}
    }
    failures.extend(check_log(&log, ending));
    Ok(Outcome {
        log,
        handed_over,
        half_periods,
        patched_loads,
        failures,
    })
}

fn loader(file: &Path, addr: u64) -> String {
    format!("loader,file={},addr={addr:#x},force-raw=on", file.display())
}

/// `cargo xtask smoke`: boots the production image of each board revision in `builds` in QEMU
/// (built here unless `built` says the caller built them: then their kept ELFs are booted, nothing
/// is rebuilt); fails unless every one passes.
pub fn run(root: &Path, builds: &[crate::revision::Build], built: bool) -> Result<()> {
    crate::workspace::ensure_qemu()?;
    if !built {
        crate::workspace::build_boards(root, builds, false)?;
    }
    let mut failed = Vec::new();
    for build in builds {
        let board = build.board;
        let elf = crate::revision::kept_elf(root, build, false);
        let name = format!("{} {}", board.name, build.revision.name);
        // Every wait on the boot path and after it bounded: the machine code says so.
        let found = machine_code::waits::scan_elf(&elf)?;
        let (known, new): (Vec<_>, Vec<_>) = found.iter().partition(|w| w.known().is_some());
        println!(
            "waits {}: {} unbounded-looking poll loop(s), {} with a stated bound",
            name,
            found.len(),
            known.len()
        );
        for wait in &known {
            println!(
                "waits {}: bounded by design: {} at {:#x} ({})",
                name,
                wait.function,
                wait.branch,
                wait.lines.first().map(String::as_str).unwrap_or("?")
            );
        }
        for wait in &new {
            println!(
                "waits {}: UNBOUNDED: {} at {:#x}: {}",
                name,
                wait.function,
                wait.branch,
                wait.lines.join(" | ")
            );
        }
        if !new.is_empty() {
            failed.push(name.clone());
        }
        let work = work_dir(root, &build.stem());
        let outcome =
            run_board(board, &elf, &work).with_context(|| format!("smoke run of {name}"))?;
        println!(
            "── {} on {} (production image behind an AMiRo-BLT stand-in) ──",
            name, board.qemu_machine
        );
        for input in environment(board.qemu_machine) {
            println!(
                "  [{}: {} at {:#010x}, through {}]",
                match input.via {
                    Via::StandIn => "stand-in",
                    Via::Watchpoint => "gdbstub",
                },
                input.stands_for,
                input.address,
                input.through
            );
        }
        if let Some(patched) = outcome.patched_loads {
            println!("  [{patched} load(s) of the watched input given the robot's level]");
        }
        for line in outcome.log.lines() {
            println!("  {line}");
        }
        if outcome.failures.is_empty() {
            let timer = monotonic_timer(board.name);
            println!(
                "  [monotonic: {} at {:#010x} counts 1 MHz of the internal oscillator, 16-bit \
                 period, half-period compare set, interrupts enabled]",
                timer.name, timer.base
            );
            match outcome.handed_over {
                Some(callback) => println!(
                    "smoke {}: ok (handed over to AMiRo-BLT's `{callback}` callback: SYS_PD_N \
                     reads low on {}, where nothing holds it released)",
                    name, board.qemu_machine
                ),
                None => println!(
                    "smoke {}: ok ({} half periods of the monotonic)",
                    name, outcome.half_periods
                ),
            }
        } else {
            for failure in &outcome.failures {
                println!("smoke {name}: FAILED: {failure}");
            }
            println!(
                "  (images, RAM snapshot and QEMU's stderr: {})",
                work.display()
            );
            failed.push(name.clone());
        }
    }
    ensure!(failed.is_empty(), "smoke run failed: {}", failed.join(", "));
    Ok(())
}

fn work_dir(root: &Path, board: &str) -> PathBuf {
    crate::workspace::target_dir(root).join("smoke").join(board)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_guards_read_a_process_cpu_time() {
        // This process has run (it is running this test); a process that does not exist has none.
        let mine = cpu_time(std::process::id()).expect("own /proc/PID/stat");
        let spin = Instant::now();
        let mut x = 0u64;
        while spin.elapsed() < Duration::from_millis(60) {
            x = x.wrapping_add(std::hint::black_box(1));
        }
        assert!(x > 0);
        assert!(cpu_time(std::process::id()).expect("again") >= mine);
        assert_eq!(cpu_time(u32::MAX), None);
    }

    #[test]
    fn the_standin_loads_vtor_stack_and_reset_vector_of_the_application() {
        let code = standin(0x0800_6000, &[(0x4001_1008, 0x4100)]);
        let word = |i: usize| u32::from_le_bytes(code[i..i + 4].try_into().unwrap());
        let half = |i: usize| u16::from_le_bytes(code[i..i + 2].try_into().unwrap());
        assert_eq!(word(0), 0x2000_1000);
        assert_eq!(
            word(4),
            STARTUP_CODE + 1,
            "reset vector: the start-up code, Thumb"
        );
        // Decode the start-up code: each `ldr rt, [pc, #…]` loads its literal into a register.
        let mut regs = [0u32; 4];
        let mut stores = Vec::new();
        let mut at = (STARTUP_CODE - STANDIN_BASE) as usize;
        loop {
            let insn = half(at);
            match insn {
                0x4800..=0x4BFF => {
                    let pc = (at + 4) & !3;
                    regs[usize::from(insn >> 8 & 7)] = word(pc + 4 * usize::from(insn & 0xFF));
                }
                0x6013 => stores.push((regs[2], regs[3])),
                0x6008 => stores.push((regs[1], regs[0])),
                0x4708 => break,
                _ => {}
            }
            at += 2;
        }
        assert_eq!(stores, [(0x4001_1008, 0x4100), (0xE000_ED08, 0x0800_6000)]);
        assert_eq!(
            regs[0], 0x0800_6000,
            "MSP and the reset vector come from the application"
        );
        assert_eq!(
            word(0x1C0),
            0x412D_424C,
            "the callback table's magic at 0x080001C0"
        );
        for (i, name) in CALLBACKS.iter().enumerate() {
            let pointer = word(0x1C0 + 16 + 4 * i);
            assert_eq!(pointer & 1, 1, "Thumb");
            assert_eq!(callback_at(pointer), Some(*name));
            let at = (pointer & !1) as usize - 0x0800_0000;
            assert_eq!(&code[at..at + 2], &[0xFE, 0xE7], "b .");
        }
        assert_eq!(callback_at(STARTUP_CODE), None);
    }

    #[test]
    fn the_flash_image_places_segments_and_erases_gaps() {
        let image = flash_image(&[(0x100, vec![1, 2]), (0x104, vec![3])], 0x100).unwrap();
        assert_eq!(image, vec![1, 2, 0xFF, 0xFF, 3]);
        assert!(flash_image(&[(0xF0, vec![1])], 0x100).is_err());
    }

    fn ram_with_log(text: &[u8], read: u32) -> Vec<u8> {
        let mut ram = vec![0u8; 0x400];
        ram[0x10..0x1A].copy_from_slice(b"SEGGER RTT");
        let put = |ram: &mut Vec<u8>, at: usize, v: u32| {
            ram[at..at + 4].copy_from_slice(&v.to_le_bytes())
        };
        put(&mut ram, 0x10 + 16, 2);
        put(&mut ram, 0x10 + 20, 0);
        let desc = 0x10 + 24;
        put(&mut ram, desc + 4, RAM_BASE + 0x200);
        put(&mut ram, desc + 8, 16);
        let write = (read + text.len() as u32) % 16;
        put(&mut ram, desc + 12, write);
        put(&mut ram, desc + 16, read);
        for (i, b) in text.iter().enumerate() {
            ram[0x200 + (read as usize + i) % 16] = *b;
        }
        ram
    }

    #[test]
    fn the_rtt_log_is_read_by_symbol_or_by_scan_and_wraps() {
        let ram = ram_with_log(b"boot: x\n", 0);
        assert_eq!(
            rtt_up_channel(&ram, Some(RAM_BASE + 0x10), 0).unwrap(),
            b"boot: x\n"
        );
        assert_eq!(rtt_up_channel(&ram, None, 0).unwrap(), b"boot: x\n");
        let wrapped = ram_with_log(b"0123456789", 10);
        assert_eq!(rtt_up_channel(&wrapped, None, 0).unwrap(), b"0123456789");
        assert!(rtt_up_channel(&ram, None, 2).is_err(), "only two channels");
        assert!(rtt_up_channel(&[0u8; 64], None, 0).is_err());
    }

    const GOOD: &str = "boot: LightRing, watchdog running\n\
        clock: reset: the internal oscillator never got ready\n\
        clock: the crystal did not start\n\
        clock: the flash did not take its wait states\n\
        clock: running on internal oscillator without PLL\n\
        power lines: SYS_SYNC_N held low\n\
        CAN: silent: the controller did not enter initialisation mode\n\
        init: done; RTIC starts the tasks\n\
        watchdog: reset after 500 ms without a feed\n\
        monotonic: a half-period compare event went missing; time goes on from the updates\n\
        watchdog: first feed (the tasks and the monotonic run)\n";

    #[test]
    fn a_complete_boot_log_passes() {
        assert_eq!(check_log(GOOD, Ending::Running), Vec::<String>::new());
        let handed_over = GOOD
            .replace(
                "watchdog: reset after 500 ms without a feed\n",
                "shutdown requested from outside: publishers stopped\n\
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
    }

    #[test]
    fn each_machine_states_how_sys_pd_n_reads_released() {
        let inputs = environment("netduino2");
        assert_eq!(inputs.len(), 1);
        assert_eq!(inputs[0].address, 0x4001_1008, "the F103's GPIOC_IDR");
        assert_eq!(inputs[0].value, 1 << 8 | 1 << 14, "PC8 and PC14");
        assert_eq!(inputs[0].via, Via::StandIn);
        assert!(inputs[0].through.contains("USART1_BRR"));
        let inputs = environment("netduinoplus2");
        assert_eq!(inputs.len(), 1);
        assert_eq!(inputs[0].address, 0x4002_0810, "the F405's GPIOC_IDR");
        assert_eq!(inputs[0].value, 1 << 13, "PC13");
        assert_eq!(inputs[0].via, Via::Watchpoint);
        assert_eq!(expected_ending("netduino2"), Ending::Running);
        assert_eq!(expected_ending("netduinoplus2"), Ending::Running);
        assert_eq!(
            expected_ending("stm32vldiscovery"),
            Ending::HandOver("handle a shutdown request")
        );
    }

    #[test]
    fn the_monotonic_timer_must_be_set_up_and_counting() {
        let timer = monotonic_timer("powermgmt");
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
        assert_eq!(monotonic_timer("lightring").base, 0x4000_0400);
        assert_eq!(monotonic_timer("diwheeldrive").base, 0x4000_0C00);
    }
}
