//! The whole robot in emulation: the QEMU builds of DiWheelDrive, PowerManagement and LightRing on
//! one simulated CAN bus (`amiro-bus-sim`), with the system lines between them, in lock-step
//! virtual time — the host side of `cargo xtask robot` (docs/qemu.md, "The whole robot").
//!
//! - [`board`]: one board's QEMU process, its two named pipes and its console: the one place a
//!   board's exchange happens ([`amiro_trace::robot_link`] is the message both sides encode).
//! - [`run()`]: the coordinator — steps from boundary to boundary, runs the bus model, answers the
//!   boards, with lookahead (a sleeping board is left waiting, a busy board is sent ahead — in the
//!   steady state several together — and a board's own frame is answered when it starts).
//! - [`report`]: the bus report (observed responses against the Davis bound).
//! - [`slcan`]: the operator's adapter as a pseudo-terminal that speaks SLCAN (live runs), paced
//!   to the wall clock by [`pace`].
//! - [`stimulus`]: what a robot run's stimulus may say; [`log`]: `candump -l` lines, durations, the
//!   boards' console records.
//!
//! Each board's QEMU trades with the coordinator at boundaries [`QUANTUM_US`] apart in virtual
//! time (`amiro-firmware/src/qemu/robot.rs` is the other side). A board blocked in that read
//! stands still in virtual time, so the coordinator decides when each quantum ends: once every
//! board that can have queued a frame before the boundary has handed it over, the bus model runs
//! every transmission that starts before it, and each board that needs it gets the frame that
//! completes in its next quantum (at most one: a frame takes at least 44 bit times) with the
//! levels of SYS_SYNC_N (wired-AND) and SYS_PD_N. Everything happens at fixed virtual times, so a
//! run is a function of its stimulus: two runs print the same bytes.
//!
//! The output is the single-board runner's: every frame on the bus as a `candump -l` line stamped
//! with the virtual time it completed, each board's `#` lines behind its name, and the bus's own
//! notes (error frames, line levels) behind `bus:`.
use std::path::PathBuf;

use amiro_bus_sim::Frame;

pub mod board;
pub mod cost;
pub mod log;
pub mod pace;
pub mod report;
mod run;
pub mod slcan;
pub mod stimulus;
pub mod warm;
pub mod world;

pub use amiro_trace::robot_link::QUANTUM_US;
pub use run::{run, run_in_world, Work};

/// The operator's adapter: the fourth node, after the boards.
pub const OPERATOR: usize = 3;
/// Names of the bus's nodes, in order.
pub const NODES: [&str; 4] = ["diwheeldrive", "powermgmt", "lightring", "operator"];

/// A board's QEMU build and machine.
#[derive(Debug, Clone)]
pub struct Firmware {
    /// The ELF.
    pub elf: PathBuf,
    /// The QEMU machine.
    pub machine: &'static str,
}

/// A frame as it went over the bus.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Transfer {
    /// The transmitter (an index into [`NODES`]).
    pub node: usize,
    /// Its mailbox.
    pub mailbox: usize,
    /// The frame.
    pub frame: Frame,
    /// When its node queued it (put it into a mailbox).
    pub queued_at: u64,
    /// When it entered its node's transmit queue (a board's driver gives one frame of an
    /// identifier a mailbox at a time, so a sample's later frames wait there): where its response
    /// starts. The adapter's and a babbling controller's frames: when queued.
    pub released_at: u64,
    /// Start of frame of the attempt that succeeded.
    pub start: u64,
    /// Completion.
    pub end: u64,
}

/// What a robot run produced.
///
/// A run in virtual time keeps everything it printed and every frame (the robot scenarios check
/// them; its length bounds them). A live run has no end: it is [`Outcome::bounded`], keeps neither,
/// and what it printed is in its [`Sink`] (`cargo xtask robot` writes the run's `output.log` and
/// `bus.log` as the lines come, [`log::RunFiles`]); its bus report comes from [`Outcome::traffic`].
#[derive(Debug, Default)]
pub struct Outcome {
    /// Everything printed, in order (a bounded run's: empty).
    pub text: String,
    /// Every frame that went over the bus, in order (a bounded run's: empty).
    pub transfers: Vec<Transfer>,
    /// The bus report's figures, kept as frames go over the bus in a bounded space (every run's).
    pub traffic: report::Traffic,
    /// Keeps neither [`Outcome::text`] nor [`Outcome::transfers`]: a live run's.
    pub bounded: bool,
    /// Error frames on the bus.
    pub error_frames: usize,
    /// The virtual time the run ended at (µs).
    pub ended_at: u64,
    /// What the run cost: boundaries, exchanges, waits.
    pub work: Work,
    /// A live run's pacing: its real-time factor and lag.
    pub pace: Option<pace::Summary>,
}

impl Outcome {
    /// An outcome that keeps only running figures, however long its run (a live run's).
    pub fn bounded() -> Self {
        Self {
            bounded: true,
            ..Self::default()
        }
    }

    /// Takes an output line: to `sink` as it comes, and into [`Outcome::text`] unless bounded.
    pub fn emit(&mut self, sink: &mut dyn Sink, line: &str) {
        crate::pace::timed(crate::pace::Io::Sink, || sink.line(line));
        if !self.bounded {
            self.text.push_str(line);
            self.text.push('\n');
        }
    }

    /// Takes a frame that went over the bus: into the running figures, and into
    /// [`Outcome::transfers`] unless bounded.
    pub fn transfer(&mut self, t: Transfer) {
        self.traffic.push(&t);
        if !self.bounded {
            self.transfers.push(t);
        }
    }

    /// Forgets the frames taken so far (a live run's warm-up: the bus report covers the live run).
    pub fn forget_transfers(&mut self) {
        self.transfers.clear();
        self.traffic.clear();
    }

    /// About how many bytes it holds of what the run produced (text, frames, running figures).
    pub fn retained_bytes(&self) -> usize {
        self.text.capacity()
            + self.transfers.capacity() * std::mem::size_of::<Transfer>()
            + self.traffic.retained_bytes()
    }
}

/// Formats a completed frame as a `candump -l` line.
pub fn candump_line(end: u64, frame: &Frame) -> String {
    use amiro_can::candump::{encode_log_line, FrameId, RawFrame, Timestamp, MAX_LOG_LINE};
    let Some(raw) = RawFrame::data_frame(FrameId::Standard(frame.id), frame.payload()) else {
        // The bus model's frames are standard data frames of at most 8 bytes.
        return format!("# no frame: {frame:?}");
    };
    let mut out = [0u8; MAX_LOG_LINE];
    let n = encode_log_line(Timestamp::from_micros(end), "can0", &raw, &mut out);
    String::from_utf8_lossy(&out[..n.saturating_sub(1)]).into_owned()
}

pub(crate) fn stamp(t: u64) -> String {
    format!("({})", amiro_can::candump::Timestamp::from_micros(t))
}

/// What the coordinator's output goes to as it is produced.
pub trait Sink {
    /// One output line (without its newline).
    fn line(&mut self, line: &str);
}

impl Sink for Vec<String> {
    fn line(&mut self, line: &str) {
        self.push(line.to_string());
    }
}

/// Both sinks, each line to the first and then the second (the terminal and the run's files).
impl<A: Sink, B: Sink> Sink for (A, B) {
    fn line(&mut self, line: &str) {
        self.0.line(line);
        self.1.line(line);
    }
}

/// A live run (`--slcan`): paced to the wall clock, the adapter a client drives, stopped by Ctrl-C.
pub struct Live {
    /// The SLCAN pseudo-terminal.
    pub slcan: slcan::Slcan,
    /// Set by Ctrl-C.
    pub stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
    /// Warm the boards up before the wall clock starts ([`warm`]; not in a world, whose time and
    /// state the warm-up would move).
    pub warm_up: bool,
    /// Called once, when the wall clock starts (the boards have booted, after the warm-up): the
    /// robot is ready for a client (`cargo xtask robot` prints the port then).
    pub ready: Option<Box<dyn FnOnce()>>,
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Counts the lines it is given, keeps none.
    #[derive(Default)]
    struct Count(usize, usize);

    impl Sink for Count {
        fn line(&mut self, line: &str) {
            self.0 += 1;
            self.1 += line.len() + 1;
        }
    }

    /// `seconds` of virtual time at about the thesis demo's output into `outcome`: per
    /// millisecond two boards' trace lines, and a frame (magnetometer-x at 900 µs, its burst of
    /// three, the proximity ring every 10 ms) with its `candump -l` line.
    fn run_for(outcome: &mut Outcome, sink: &mut dyn Sink, seconds: u64) {
        let mut next_mag = 0;
        for ms in 0..seconds * 1000 {
            let t = ms * 1000;
            outcome.emit(
                sink,
                &format!("diwheeldrive: # {} trace sample-start 205 at {t}", stamp(t)),
            );
            outcome.emit(
                sink,
                &format!("powermgmt: # {} trace publish 21F ring at {t}", stamp(t)),
            );
            let mut frames = Vec::new();
            while next_mag < t + 1000 {
                frames.push((0x605, 6, next_mag, 0));
                next_mag += 900;
            }
            if ms % 10 == 0 {
                frames.extend((0..3).map(|j| (0x61F, 8, t + 200, j)));
            }
            for (id, len, released_at, j) in frames {
                let end = released_at + 150 + j * 140;
                let frame = Frame::new(id, &[0x5A; 8][..len]).unwrap();
                outcome.transfer(Transfer {
                    node: 0,
                    mailbox: 0,
                    frame,
                    queued_at: released_at + j * 140,
                    released_at,
                    start: end - 130,
                    end,
                });
                outcome.emit(sink, &candump_line(end, &frame));
            }
        }
    }

    #[test]
    fn a_live_run_keeps_a_bounded_space_however_long_it_runs() {
        // Two minutes of virtual time: a bounded outcome holds what it held after ten seconds,
        // under 64 KiB; its sink got every line and its report is the whole one's.
        let (mut ten, mut long) = (Outcome::bounded(), Outcome::bounded());
        let (mut sink_ten, mut sink_long) = (Count::default(), Count::default());
        run_for(&mut ten, &mut sink_ten, 10);
        run_for(&mut long, &mut sink_long, 120);
        assert!(long.text.is_empty() && long.transfers.is_empty());
        assert!(sink_long.0 > 12 * sink_ten.0 - 1_000, "{}", sink_long.0);
        assert!(sink_long.1 > 16 << 20, "{} B printed", sink_long.1);
        assert!(
            long.retained_bytes() <= ten.retained_bytes().max(1),
            "{} B after 120 s, {} B after 10 s",
            long.retained_bytes(),
            ten.retained_bytes()
        );
        assert!(
            long.retained_bytes() < 64 * 1024,
            "{} B",
            long.retained_bytes()
        );
        // A run in virtual time keeps the whole: the same two minutes hold megabytes.
        let mut whole = Outcome::default();
        run_for(&mut whole, &mut Count::default(), 120);
        assert!(
            whole.retained_bytes() > 16 << 20,
            "{} B",
            whole.retained_bytes()
        );
        assert_eq!(whole.text.len(), sink_long.1);
        assert_eq!(
            long.traffic.report(120_000_000),
            report::analyse(&whole.transfers, 120_000_000)
        );
    }
}
