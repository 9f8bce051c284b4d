//! The QEMU platform every board's QEMU build shares: the same app, with what the chip does
//! replaced by what QEMU can run.
//!
//! QEMU emulates neither the STM32 clock tree nor bxCAN, so a QEMU build sets up no clock and no
//! CAN hardware. Instead:
//! - the monotonic is SysTick with a 10 µs tick ([`timer`]; `mono::QemuClock` is the tasks'
//!   clock over it), in deterministic virtual time under `-icount`, tickless in a robot run;
//! - the CAN controller is a register-level bxCAN model ([`can`]) under the robot's driver: its
//!   receive FIFO 0 (`bxcan::Fifo0`) is filled from a stimulus log replayed from the host (read
//!   through semihosting) and raises the board's real CAN receive interrupt; its transmit side is
//!   virtual mailboxes that print every frame in `candump -l` format with its virtual-time stamp
//!   (in a robot run, the driver's `bxcan::Mailboxes` over the model);
//! - SYS_PD_N is a stimulus signal; SYS_SYNC_N edges are printed;
//! - the free RAM is painted at boot so the end-of-run line reports the stack's high-water mark.
//!
//! Trace events and the human log are printed as lines starting with `#`; the run ends with one
//! `# qemu: … at N us; …` line (see [`finish`]).
//!
//! Run by `cargo xtask robot`, the board is instead one of three on the host's bus model, in
//! lock-step ([`robot`]).
use core::sync::atomic::{AtomicBool, Ordering};

use cortex_m::interrupt::InterruptNumber;
use cortex_m_semihosting::{debug, hprintln, syscall};

use amiro_trace::stimulus;

use crate::can::{CanRx, CanTx, Completion, RxEvent, Transmit};
use crate::signals::SystemSignals;

pub mod can;
pub mod robot;
pub mod timer;

/// SysTick's clock: the core clock of the QEMU machine (netduino2's STM32F205 for the F1 boards,
/// netduinoplus2's STM32F405 for the F4 board).
#[cfg(feature = "f1")]
pub const CORE_CLOCK_HZ: u32 = 120_000_000;
/// SysTick's clock on the F4 board's QEMU machine (netduinoplus2).
#[cfg(feature = "f4")]
pub const CORE_CLOCK_HZ: u32 = 168_000_000;

/// SysTick ticks every 10 µs: a 1 µs tick would interrupt the emulated CPU every microsecond.
pub const TICK_US: u64 = 10;

/// Microseconds of virtual time since the monotonic started (the platform's own reading, without
/// the trace hooks of `mono::QemuClock`).
pub fn now_us() -> u64 {
    timer::now_ticks().saturating_mul(TICK_US)
}

static SYS_PD_LOW: AtomicBool = AtomicBool::new(false);

const STACK_PAINT: u32 = 0x5A5A_A5A5;

extern "C" {
    static mut __sheap: u32;
    static _stack_start: u32;
}

/// Paints the free RAM, starts the SysTick monotonic and, unless the board runs as part of the
/// robot, opens `trace.bin`. Called by
/// `mono::start_qemu`, which starts the trace clock over it (the platform is the layer below
/// tracing: it calls nothing of it).
pub fn init(syst: cortex_m::peripheral::SYST) {
    paint_stack();
    timer::start(syst);
    can::init();
    // A robot run's boards write no `trace.bin`: nothing reads it there (the robot's checks read
    // the bus log and the console's `# T` lines), and each record was a semihosting write into a
    // file, 5-6 per exchange on DiWheelDrive in the thesis demo (docs/qemu.md, "Speed"). Nor are
    // they stamped or encoded (`tracing::write` asks `trace_file`): a stamp is a clock
    // reading, a trip out of QEMU's translated code, for a record nothing keeps.
    if robot::connect() {
        return;
    }
    if let Some(file) = HostFile::create(b"trace.bin\0") {
        TRACE_FILE.store(file.0, Ordering::Relaxed);
    }
    // The clock's busy ticks, stamped as runs of their own (`timer`'s `SysTick`).
    timer::stamp_busy_ticks(HostFile::create(b"clock.bin\0").map(|file| file.0));
}

/// The host file the trace records go to (`usize::MAX`: none).
static TRACE_FILE: core::sync::atomic::AtomicUsize =
    core::sync::atomic::AtomicUsize::new(usize::MAX);

/// The host file trace records go to (`trace.bin`): single-board runs; `None` in a robot run.
pub fn trace_file() -> Option<usize> {
    let fd = TRACE_FILE.load(Ordering::Relaxed);
    (fd != usize::MAX).then_some(fd)
}

/// Writes trace record bytes to `trace.bin` (the QEMU build's trace channel); `false` if not all.
pub fn write_trace_file(bytes: &[u8]) -> bool {
    trace_file().is_some_and(|fd| write_trace_to(fd, bytes))
}

/// Writes trace record bytes to the host file `fd` ([`trace_file`]); `false` if not all.
pub fn write_trace_to(fd: usize, bytes: &[u8]) -> bool {
    // SAFETY: semihosting WRITE from a buffer we own; it returns the number of bytes NOT written.
    let left = unsafe { syscall!(WRITE, fd, bytes.as_ptr(), bytes.len()) };
    left == 0
}

/// Fills the free stack below the current stack pointer with a pattern, so the end of the run can
/// tell how deep the stack ever went.
fn paint_stack() {
    let sp = cortex_m::register::msp::read() as usize;
    // SAFETY: `__sheap` marks the end of .bss/.uninit; everything from there up to a margin below
    // the live stack pointer is unused memory nobody else writes to.
    unsafe {
        let mut p = core::ptr::addr_of_mut!(__sheap) as usize;
        while p + 64 < sp {
            core::ptr::write_volatile(p as *mut u32, STACK_PAINT);
            p += 4;
        }
    }
}

/// The deepest the stack has been, in bytes (from the top of RAM to the lowest overwritten word).
pub fn stack_high_water() -> usize {
    // SAFETY: reads the painted region back; see `paint_stack`.
    unsafe {
        let bottom = core::ptr::addr_of_mut!(__sheap) as usize;
        let top = core::ptr::addr_of!(_stack_start) as usize;
        let mut p = bottom;
        while p < top && core::ptr::read_volatile(p as *const u32) == STACK_PAINT {
            p += 4;
        }
        top - p
    }
}

/// Static RAM (.data + .bss + .uninit), in bytes.
pub fn static_ram() -> usize {
    // Only the address of a linker symbol is taken.
    core::ptr::addr_of_mut!(__sheap) as usize - crate::layout::RAM_BASE as usize
}

/// Virtual transmit mailboxes: a frame is on the bus the moment it is offered. Like bxCAN's three,
/// they take at most three frames per transmit interrupt; the next interrupt follows at once (as
/// the first transmit-complete would), so one job of the transmit task is as long as the robot's.
pub struct CanTxPort;

static TX_THIS_JOB: core::sync::atomic::AtomicU8 = core::sync::atomic::AtomicU8::new(0);

impl CanTx for CanTxPort {
    fn transmit(&mut self, frame: &amiro_can::Frame) -> Transmit {
        if robot::active() {
            return can::transmit(frame);
        }
        if TX_THIS_JOB.fetch_add(1, Ordering::Relaxed) >= 3 {
            // The mailboxes are full: pend this interrupt again (the transmit-complete).
            const ICSR: *const u32 = 0xE000_ED04 as *const u32;
            const NVIC_ISPR: *mut u32 = 0xE000_E200 as *mut u32;
            // SAFETY: reads the active exception number; writing a set-pending bit of the NVIC
            // only pends that interrupt (the one running: the board's CAN transmit interrupt).
            unsafe {
                let active = core::ptr::read_volatile(ICSR) & 0x1FF;
                if let Some(irq) = active.checked_sub(16) {
                    core::ptr::write_volatile(NVIC_ISPR.add((irq / 32) as usize), 1 << (irq % 32));
                }
            }
            return Transmit::Busy;
        }
        // `(s.micros) can0 ID#DATA`, `amiro_can::candump`'s encoder: digits by hand, so the
        // emulated transmit task does not cost core::fmt's thousands of instructions.
        use amiro_can::candump::{encode_log_line, FrameId, RawFrame, Timestamp, MAX_LOG_LINE};
        let mut line = [0u8; MAX_LOG_LINE];
        let at = RawFrame::data_frame(FrameId::Standard(frame.id().raw()), frame.data())
            .map_or(0, |raw| {
                encode_log_line(Timestamp::from_micros(now_us()), "can0", &raw, &mut line)
            });
        console_write(&line[..at]);
        // On this bus a frame is acknowledged the moment it is offered: the frame line is its
        // acknowledgement (the host reads it from there; no second record costs the task time).
        Transmit::Queued
    }

    fn completed(&mut self, on_completion: &mut dyn FnMut(Completion)) {
        if robot::active() {
            can::completed(on_completion);
            return;
        }
        // A new transmit interrupt: the three mailboxes are free again.
        TX_THIS_JOB.store(0, Ordering::Relaxed);
    }
}

/// The receive FIFO: the driver's `bxcan::Fifo0` over the controller model.
pub struct CanRxPort;

impl CanRx for CanRxPort {
    fn receive(&mut self) -> Option<RxEvent> {
        can::receive()
    }
}

/// The identifier of the QEMU-only control frames (`0x3F0`: a low-priority command to topic 0xF0,
/// which the protocol leaves free; on a robot it would be rejected as `unknown-topic`): a stimulus
/// changes a board's simulated world with them.
pub const SIM_CONTROL_ID: u16 = 0x3F0;

/// The receive FIFO with the QEMU-only control frames ([`SIM_CONTROL_ID`]) taken out before the
/// command queue: each one's data goes to the board's `apply`, the app never sees them.
pub struct ControlledRxPort {
    apply: fn(&[u8]),
}

impl ControlledRxPort {
    /// A receive port that hands the control frames' data to `apply`.
    pub const fn new(apply: fn(&[u8])) -> Self {
        Self { apply }
    }
}

impl CanRx for ControlledRxPort {
    fn receive(&mut self) -> Option<RxEvent> {
        loop {
            match can::receive()? {
                RxEvent::Frame(frame) if frame.id == SIM_CONTROL_ID => {
                    (self.apply)(frame.payload())
                }
                other => return Some(other),
            }
        }
    }
}

/// The CAN error monitor of the QEMU build: the driver's over the controller model (whose bus
/// side reports no errors, so it stays error-active).
pub type CanErrors = crate::bxcan::ErrorMonitor<can::Controller>;

/// A CAN error monitor for the QEMU build.
pub const fn can_errors() -> CanErrors {
    crate::bxcan::ErrorMonitor::new(can::Controller)
}

/// Simulated system signals: SYS_PD_N as the stimulus drives it, SYS_SYNC_N edges printed.
pub struct Signals;

impl SystemSignals for Signals {
    fn release_sync(&mut self) {
        robot::drive_sync(false);
        print_line("# qemu: SYS_SYNC_N released");
    }

    fn pull_sync_low(&mut self) {
        robot::drive_sync(true);
        print_line("# qemu: SYS_SYNC_N pulled low");
    }

    fn shutdown_requested(&self) -> bool {
        SYS_PD_LOW.load(Ordering::SeqCst)
    }

    fn clear_shutdown_interrupt(&mut self) {}
}

/// Replays `stimulus.bin` from the host into the receive FIFO (pending the board's CAN
/// receive interrupt `rx_irq`, and `shutdown_irq` for a SYS_PD_N record), then ends the run.
/// In a robot run the board trades with the host's bus instead ([`robot`]). It waits for each
/// record with `delay_until_us` (the board's traced clock, `mono::QemuClock::delay_until_us`:
/// passed in, the platform being below the tracing).
pub async fn replay_stimulus<W: core::future::Future<Output = ()>>(
    rx_irq: impl InterruptNumber,
    shutdown_irq: impl InterruptNumber,
    delay_until_us: impl Fn(u64) -> W,
) {
    if robot::active() {
        robot::run(rx_irq, shutdown_irq).await;
        return;
    }
    let Some(file) = HostFile::open(b"stimulus.bin\0") else {
        hprintln!("# qemu: cannot open stimulus.bin");
        exit(false);
        return;
    };
    // The records are `amiro_trace::stimulus`'s, which the host encodes.
    let mut header = [0u8; stimulus::HEADER_LEN];
    let decoded = if file.read_exact(&mut header) {
        stimulus::decode_header(&header)
    } else {
        Err(stimulus::StimulusError::NoHeader)
    };
    let duration = match decoded {
        Ok(duration) => duration,
        Err(e) => {
            stimulus_failed(e);
            return;
        }
    };
    let mut bytes = [0u8; stimulus::RECORD_LEN];
    while file.read_exact(&mut bytes) {
        let record = match stimulus::Record::decode(&bytes) {
            Ok(record) => record,
            Err(e) => {
                stimulus_failed(e);
                return;
            }
        };
        if record.at_us > duration {
            break;
        }
        delay_until_us(record.at_us).await;
        match record.event {
            stimulus::Event::ShutdownRequest => {
                // SYS_PD_N falls: the same interrupt the real pin raises.
                SYS_PD_LOW.store(true, Ordering::SeqCst);
                cortex_m::peripheral::NVIC::pend(shutdown_irq);
            }
            stimulus::Event::Frame { id, len, data } => {
                can::stimulus_frame(id, id == stimulus::UNCARRIED_ID, len, data, rx_irq)
            }
        }
    }
    delay_until_us(duration).await;
    finish("end of run");
}

/// Prints why the stimulus cannot be read and ends the run as failed. Not inlined: the error's
/// `Display` is a function address the formatting stores as data, and in the replay task's
/// dispatcher, which builds the task's wakers, the execution-time bound would take it for a
/// waker's target (`machine_code::wcet::stored`; docs/bench.md, "The traced QEMU image's own bound").
#[inline(never)]
fn stimulus_failed(e: stimulus::StimulusError) {
    hprintln!("# qemu: stimulus.bin: {}", e);
    exit(false);
}

/// Prints the run's last line (receive losses, static RAM, the stack's high-water mark) and ends
/// the run successfully.
pub fn finish(why: &str) {
    hprintln!(
        "# qemu: {} at {} us; rx dropped {}; rx overruns {}; admission refused {}; admission busy {}; ram static {} stack {}",
        why,
        now_us(),
        crate::health::rx_dropped(),
        crate::health::rx_overruns(),
        crate::health::admission_refused(),
        crate::health::admission_busy(),
        static_ram(),
        stack_high_water()
    );
    exit(true);
}

/// Prints one line on the console (a board's simulated device reporting what it saw): the text and
/// its end written as they are, under one critical section so no other line splits it. Without
/// `core::fmt` (whose loops over the format's pieces and the text's characters have no bound the
/// execution-time analysis can state): the receive interrupt prints a control frame's line with it,
/// and the traced QEMU image's own bound holds that interrupt (docs/bench.md).
pub fn print_line(line: &str) {
    critical_section::with(|_| {
        console_write(line.as_bytes());
        console_write(b"\n");
    });
}

/// Prints one line of three parts (`before`, `value`, `after`: a number between two texts), under
/// one critical section so no other line splits it, without `core::fmt` and without a buffer: each
/// part written as it is, by direct calls (a receive interrupt's control-frame line; its
/// execution-time bound follows every call, where `print_line_pieces`' sink is a call through a
/// register).
pub fn print_line_around(before: &[u8], value: &[u8], after: &[u8]) {
    critical_section::with(|_| {
        console_write(before);
        console_write(value);
        console_write(after);
        console_write(b"\n");
    });
}

/// Prints one line given in pieces (`pieces` calls its sink once per piece), under one critical
/// section so no other line splits it, without a buffer for the whole line: a device report longer
/// than is worth holding on the stack (LightRing 1-2's 72 channels). Keep the pieces cheap to make:
/// interrupts are off meanwhile.
pub fn print_line_pieces(pieces: impl FnOnce(&mut dyn FnMut(&[u8]))) {
    critical_section::with(|_| {
        let mut sink = |bytes: &[u8]| {
            console_write(bytes);
        };
        pieces(&mut sink);
        console_write(b"\n");
    });
}

/// The console's semihosting handle, opened at the first write (`usize::MAX`: not yet).
/// `cortex_m_semihosting::hio::hstdout` opens a new one at every call, which QEMU never frees: its
/// table of handles grew by one per printed line and was searched at each open.
static CONSOLE: core::sync::atomic::AtomicUsize = core::sync::atomic::AtomicUsize::new(usize::MAX);

/// Writes `bytes` to the console (semihosting's `:tt`, QEMU's stdout); `false` if not all.
pub fn console_write(bytes: &[u8]) -> bool {
    let mut fd = CONSOLE.load(Ordering::Relaxed);
    if fd == usize::MAX {
        // SAFETY: semihosting OPEN of the console with a NUL-terminated name, mode 4 ("w"),
        // length without the NUL. Two contexts racing here open two handles; one is kept.
        let opened = unsafe { syscall!(OPEN, c":tt".as_ptr(), 4, 3) };
        if opened as isize == -1 {
            return false;
        }
        fd = opened;
        CONSOLE.store(fd, Ordering::Relaxed);
    }
    // SAFETY: semihosting WRITE from a buffer we own; it returns the number of bytes NOT written.
    let left = unsafe { syscall!(WRITE, fd, bytes.as_ptr(), bytes.len()) };
    left == 0
}

/// Ends the QEMU run.
pub fn exit(success: bool) {
    debug::exit(if success {
        debug::EXIT_SUCCESS
    } else {
        debug::EXIT_FAILURE
    });
}

struct HostFile(usize);

impl HostFile {
    fn open(name_nul: &[u8]) -> Option<Self> {
        // SAFETY: semihosting OPEN with a NUL-terminated name, mode 1 ("rb"), length without the NUL.
        let fd = unsafe { syscall!(OPEN, name_nul.as_ptr(), 1, name_nul.len() - 1) };
        (fd as isize >= 0).then_some(Self(fd))
    }

    fn create(name_nul: &[u8]) -> Option<Self> {
        // SAFETY: semihosting OPEN with a NUL-terminated name, mode 5 ("wb"), length without the NUL.
        let fd = unsafe { syscall!(OPEN, name_nul.as_ptr(), 5, name_nul.len() - 1) };
        (fd as isize >= 0).then_some(Self(fd))
    }

    /// Reads all of `buf`; a pipe may hand it over in parts.
    fn read_exact(&self, buf: &mut [u8]) -> bool {
        let mut at = 0;
        while at < buf.len() {
            let want = buf.len() - at;
            // SAFETY: semihosting READ into a buffer we own; it returns the number of bytes NOT read.
            let left = unsafe { syscall!(READ, self.0, buf[at..].as_mut_ptr(), want) };
            if left >= want {
                return false;
            }
            at += want - left;
        }
        true
    }

    fn write_all(&self, bytes: &[u8]) -> bool {
        // SAFETY: semihosting WRITE from a buffer we own; it returns the number of bytes NOT written.
        let left = unsafe { syscall!(WRITE, self.0, bytes.as_ptr(), bytes.len()) };
        left == 0
    }
}
