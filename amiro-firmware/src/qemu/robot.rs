//! The robot mode of the QEMU platform: this board as one of three on a simulated bus that
//! `cargo xtask robot` runs (docs/qemu.md, "The whole robot").
//!
//! When the run's work directory holds the named pipes `robot-down` and `robot-up`, the board
//! trades with the host's bus model every [`QUANTUM_US`] of its virtual time instead of replaying
//! a stimulus: it hands over the frames it put into its three mailboxes since the last exchange
//! (with the time it queued them) and what it drives on the system lines, and gets back the one
//! frame, if any, that completes on the bus in the coming quantum (a frame needs at least 44 bit
//! times, so no two complete within 40 µs) and the levels of SYS_SYNC_N and SYS_PD_N. The read
//! blocks, and a blocked QEMU's virtual clock stands still, so no board runs ahead of the others.
//!
//! The frame is delivered at its completion time: into the 3-frame receive FIFO (an overrun if the
//! board has not emptied it, as on bxCAN), or, for the board's own frame, as a free mailbox and a
//! transmit-complete interrupt.
use core::cell::RefCell;
use core::sync::atomic::{AtomicBool, AtomicU16, AtomicU8, AtomicUsize, Ordering};

use cortex_m::interrupt::InterruptNumber;
use critical_section::Mutex;
use rtic_time::timer_queue::TimerQueueBackend;

use super::{HostFile, TICK_US};
use crate::can::{Completion, RxFrame, Transmit};

/// The exchange period: a multiple of the 10 µs tick below the shortest frame (44 bit times from
/// start of frame to completion at 1 Mbit/s).
pub const QUANTUM_US: u64 = 40;
/// Board → host: `u64` now, `u8` new frames, `u8` lines driven, 6 reserved, three 20-byte records
/// (`u64` queued at, `u16` id, `u8` length, `u8` mailbox, 8 data bytes).
const UP_LEN: usize = 16 + 3 * 20;
/// Host → board: `u64` completion time, `u8` flags, `u8` mailbox, `u16` id, `u8` length, 3
/// reserved, 8 data bytes, 8 reserved.
const DOWN_LEN: usize = 32;

/// Up: this board pulls SYS_SYNC_N low.
const DRIVES_SYNC_LOW: u8 = 1;
/// Up: this board drives SYS_PD_N low.
const DRIVES_PD_LOW: u8 = 2;
/// Down: a frame completes in this quantum.
const DOWN_FRAME: u8 = 1;
/// Down: the frame is this board's own (its mailbox is free at the completion time).
const DOWN_OWN: u8 = 2;
/// Down: SYS_PD_N reads low.
const DOWN_PD_LOW: u8 = 4;
/// Down: SYS_SYNC_N reads low.
const DOWN_SYNC_LOW: u8 = 8;
/// Down: the run is over.
const DOWN_END: u8 = 16;

const NO_FILE: usize = usize::MAX;
static DOWN: AtomicUsize = AtomicUsize::new(NO_FILE);
static UP: AtomicUsize = AtomicUsize::new(NO_FILE);
/// The lines this board drives (a module holds SYS_SYNC_N low until it is initialised).
static DRIVES: AtomicU8 = AtomicU8::new(DRIVES_SYNC_LOW);
static SYNC_READS_LOW: AtomicBool = AtomicBool::new(true);
/// The transmit interrupt (the exception that called [`transmit`]), `u16::MAX` until known.
static TX_IRQ: AtomicU16 = AtomicU16::new(u16::MAX);

#[derive(Clone, Copy)]
struct Mailbox {
    frame: amiro_can::Frame,
    queued_us: u64,
    handed_over: bool,
    done: bool,
}

static MAILBOXES: Mutex<RefCell<[Option<Mailbox>; 3]>> = Mutex::new(RefCell::new([None; 3]));

/// Opens the pipes to the host's bus if this run has them (`init` calls it); `true` in robot mode.
pub(super) fn connect() -> bool {
    // A FIFO the host holds open opens at once; without `robot-down` this is a single-board run.
    let Some(down) = HostFile::open(b"robot-down\0") else {
        return false;
    };
    let Some(up) = HostFile::create(b"robot-up\0") else {
        return false;
    };
    DOWN.store(down.0, Ordering::Relaxed);
    UP.store(up.0, Ordering::Relaxed);
    true
}

/// Whether this board runs as part of the robot.
pub fn active() -> bool {
    UP.load(Ordering::Relaxed) != NO_FILE
}

/// Records what this board drives on SYS_SYNC_N (`true`: pulled low).
pub(super) fn drive_sync(low: bool) {
    if low {
        DRIVES.fetch_or(DRIVES_SYNC_LOW, Ordering::SeqCst);
    } else {
        DRIVES.fetch_and(!DRIVES_SYNC_LOW, Ordering::SeqCst);
    }
}

/// Drives SYS_PD_N low (PowerManagement's shutdown request); it stays low.
pub fn drive_power_down() {
    DRIVES.fetch_or(DRIVES_PD_LOW, Ordering::SeqCst);
}

/// Whether SYS_SYNC_N reads low on the robot's line (the wired-AND of every module), as of the
/// last exchange.
pub fn sync_reads_low() -> bool {
    SYNC_READS_LOW.load(Ordering::SeqCst)
}

/// Puts `frame` into a free mailbox (the host queues it on the bus at the next exchange).
pub(super) fn transmit(frame: &amiro_can::Frame) -> Transmit {
    remember_tx_interrupt();
    let now = super::now_us();
    critical_section::with(|cs| {
        let mut boxes = MAILBOXES.borrow_ref_mut(cs);
        match boxes.iter_mut().find(|m| m.is_none()) {
            Some(slot) => {
                *slot = Some(Mailbox {
                    frame: *frame,
                    queued_us: now,
                    handed_over: false,
                    done: false,
                });
                Transmit::Queued
            }
            // All three hold frames: the transmit-complete interrupt of one of them comes back.
            None => Transmit::Busy,
        }
    })
}

/// Reports the mailboxes whose frame went out and frees them.
pub(super) fn completed(on_completion: &mut dyn FnMut(Completion)) {
    let mut sent: [Option<amiro_can::Frame>; 3] = [None; 3];
    critical_section::with(|cs| {
        for (slot, out) in MAILBOXES.borrow_ref_mut(cs).iter_mut().zip(&mut sent) {
            if slot.is_some_and(|m| m.done) {
                *out = slot.take().map(|m| m.frame);
            }
        }
    });
    for frame in sent.into_iter().flatten() {
        on_completion(Completion::Sent(frame));
    }
}

fn remember_tx_interrupt() {
    const ICSR: *const u32 = 0xE000_ED04 as *const u32;
    // SAFETY: reads the number of the active exception (a read-only field of the SCB).
    let active = unsafe { core::ptr::read_volatile(ICSR) } & 0x1FF;
    if let Some(irq) = active.checked_sub(16) {
        TX_IRQ.store(irq as u16, Ordering::Relaxed);
    }
}

/// The interrupt number the transmit path ran in.
#[derive(Clone, Copy)]
struct Irq(u16);

// SAFETY: the number was read from the NVIC's active exception, so it is a valid interrupt.
unsafe impl InterruptNumber for Irq {
    fn number(self) -> u16 {
        self.0
    }
}

/// Waits for the tick at `at_us` without a trace record: the exchange is the platform's, not a
/// task of the app's.
async fn wait_until(at_us: u64) {
    use rtic_monotonics::systick::SystickBackend;
    SystickBackend::timer_queue()
        .delay_until(at_us.div_ceil(TICK_US))
        .await;
}

/// The exchange loop (in place of the stimulus replay): until the host ends the run.
pub(super) async fn run(rx_irq: impl InterruptNumber, shutdown_irq: impl InterruptNumber) {
    let (up, down) = (
        HostFile(UP.load(Ordering::Relaxed)),
        HostFile(DOWN.load(Ordering::Relaxed)),
    );
    let mut boundary = 0;
    let mut pd_seen = false;
    loop {
        boundary += QUANTUM_US;
        wait_until(boundary).await;
        let mut message = [0u8; UP_LEN];
        message[..8].copy_from_slice(&super::now_us().to_le_bytes());
        let mut count = 0u8;
        critical_section::with(|cs| {
            for (k, slot) in MAILBOXES.borrow_ref_mut(cs).iter_mut().enumerate() {
                let Some(m) = slot.as_mut().filter(|m| !m.handed_over) else {
                    continue;
                };
                m.handed_over = true;
                let at = 16 + 20 * usize::from(count);
                let record = &mut message[at..at + 20];
                record[..8].copy_from_slice(&m.queued_us.to_le_bytes());
                record[8..10].copy_from_slice(&m.frame.id().raw().to_le_bytes());
                let data = m.frame.data();
                record[10] = data.len() as u8;
                record[11] = k as u8;
                record[12..12 + data.len()].copy_from_slice(data);
                count += 1;
            }
        });
        message[8] = count;
        message[9] = DRIVES.load(Ordering::SeqCst);
        let mut answer = [0u8; DOWN_LEN];
        if !up.write_all(&message) || !down.read_exact(&mut answer) {
            super::print_line("# qemu: the robot's bus is gone");
            super::exit(false);
            return;
        }
        let flags = answer[8];
        SYNC_READS_LOW.store(flags & DOWN_SYNC_LOW != 0, Ordering::SeqCst);
        if flags & DOWN_PD_LOW != 0 && !pd_seen {
            // SYS_PD_N falls: the same interrupt the real pin raises.
            pd_seen = true;
            super::SYS_PD_LOW.store(true, Ordering::SeqCst);
            cortex_m::peripheral::NVIC::pend(shutdown_irq);
        }
        if flags & DOWN_END != 0 {
            super::finish("end of run");
            return;
        }
        if flags & DOWN_FRAME == 0 {
            continue;
        }
        let mut at = [0u8; 8];
        at.copy_from_slice(&answer[..8]);
        wait_until(u64::from_le_bytes(at)).await;
        if flags & DOWN_OWN != 0 {
            let mailbox = usize::from(answer[9]);
            critical_section::with(|cs| {
                if let Some(m) = MAILBOXES
                    .borrow_ref_mut(cs)
                    .get_mut(mailbox)
                    .and_then(Option::as_mut)
                {
                    m.done = true;
                }
            });
            let irq = TX_IRQ.load(Ordering::Relaxed);
            if irq != u16::MAX {
                cortex_m::peripheral::NVIC::pend(Irq(irq));
            }
        } else {
            let mut frame = RxFrame {
                id: u16::from_le_bytes([answer[10], answer[11]]),
                len: answer[12].min(8),
                data: [0; 8],
            };
            frame.data.copy_from_slice(&answer[16..24]);
            super::deliver(frame, rx_irq);
        }
    }
}
