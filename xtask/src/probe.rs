//! The debug probe, through probe-rs as a library: open a probe, flash an image, attach to a
//! running board and read its RTT up-channels. Thin on purpose: nothing here can run without a
//! probe, so everything else (demultiplexing, decoding, the live view) lives in `bench::live` and
//! is tested on the host; this module only moves bytes ([`Chunk`]s, a [`Source`] of them).
use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::{bail, Context, Result};
use probe_rs::flashing::DownloadOptions;
use probe_rs::probe::list::Lister;
use probe_rs::probe::DebugProbeSelector;
use probe_rs::rtt::{Rtt, ScanRegion};
use probe_rs::{Permissions, Session};

use crate::boards::Board;

/// RTT up-channel of the human log.
const LOG_CHANNEL: usize = 0;
/// RTT up-channel of the trace records (named `trace` by the firmware).
const TRACE_CHANNEL: usize = 1;

/// Bytes from one up-channel.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Chunk {
    /// Channel 0, the human log.
    Log(Vec<u8>),
    /// Channel 1, the trace records.
    Trace(Vec<u8>),
}

/// Where the channels' bytes come from: a probe's [`RttLink`], or a file still being written
/// (`bench::live`).
pub trait Source {
    /// Appends whatever arrived since the last call to `out` (possibly nothing); `false` once the
    /// source has ended for good.
    fn poll(&mut self, out: &mut Vec<Chunk>) -> Result<bool>;
}

/// Opens the probe `selector` names (`VID:PID` or `VID:PID:SERIAL`), or the only one attached.
fn open_probe(selector: Option<&str>) -> Result<probe_rs::probe::Probe> {
    let lister = Lister::new();
    if let Some(text) = selector {
        let selector: DebugProbeSelector = text
            .parse()
            .with_context(|| format!("--probe {text}: expected VID:PID or VID:PID:SERIAL"))?;
        return lister
            .open(selector)
            .with_context(|| format!("opening the debug probe {text}"));
    }
    let probes = lister.list_all();
    match probes.as_slice() {
        [] => bail!(
            "no debug probe found: connect one (ST-Link, CMSIS-DAP v2, J-Link) to the board's SWD \
             pins; on Linux the user needs access to its USB device (probe-rs's udev rules)"
        ),
        [one] => one
            .open()
            .with_context(|| format!("opening the debug probe {}", one.identifier)),
        several => bail!(
            "{} debug probes attached ({}): name one with --probe VID:PID[:SERIAL]",
            several.len(),
            several
                .iter()
                .map(|p| format!(
                    "{:04x}:{:04x}{}",
                    p.vendor_id,
                    p.product_id,
                    p.serial_number
                        .as_deref()
                        .map(|s| format!(":{s}"))
                        .unwrap_or_default()
                ))
                .collect::<Vec<_>>()
                .join(", ")
        ),
    }
}

/// A session on the board's chip: under reset when flashing (DiWheelDrive's original firmware
/// disables the debug pins), without disturbing it when attaching to a running board.
pub fn session(board: &Board, selector: Option<&str>, under_reset: bool) -> Result<Session> {
    let probe = open_probe(selector)?;
    let session = if under_reset {
        probe.attach_under_reset(board.chip, Permissions::default())
    } else {
        probe.attach(board.chip, Permissions::default())
    };
    session.with_context(|| {
        format!(
            "attaching to the {} ({}) through the probe: is the board powered and the SWD cable on?",
            board.name, board.chip
        )
    })
}

/// Writes `image` (an ELF whose AMiRo-BLT checksum word is already in place) into flash,
/// verifies it and restarts the board. Flash outside the image (AMiRo-BLT) is kept.
pub fn flash(session: &mut Session, image: &Path) -> Result<()> {
    let bytes = std::fs::read(image).with_context(|| format!("reading {}", image.display()))?;
    let segments =
        crate::elf::load_segments(&bytes).with_context(|| format!("{}", image.display()))?;
    let mut loader = session.target().flash_loader();
    for (address, data) in &segments {
        loader.add_data(*address, data).with_context(|| {
            format!(
                "{}: {address:#010x} is not in the chip's flash",
                image.display()
            )
        })?;
    }
    let mut options = DownloadOptions::default();
    options.keep_unwritten_bytes = true;
    options.verify = true;
    loader
        .commit(session, options)
        .context("programming the flash (nothing is started; flash again)")?;
    session
        .core(0)
        .and_then(|mut core| core.reset())
        .context("restarting the board after flashing")?;
    Ok(())
}

/// The board's RTT up-channels, read through the probe.
pub struct RttLink {
    session: Session,
    rtt: Rtt,
    trace: Option<usize>,
}

impl RttLink {
    /// Finds the RTT control block — at `_SEGGER_RTT` of `elf` when the image is known, else by
    /// scanning the chip's RAM — waiting up to 5 s for the firmware to set it up.
    pub fn attach(mut session: Session, elf: Option<&[u8]>) -> Result<Self> {
        let region = match elf.and_then(crate::elf::rtt_control_block) {
            Some(address) => ScanRegion::Exact(address),
            None => ScanRegion::Ram,
        };
        let mut rtt = {
            let mut core = session.core(0).context("the chip's core")?;
            probe_rs::rtt::try_attach_to_rtt(&mut core, Duration::from_secs(5), &region).context(
                "no RTT control block found: is the firmware running, and built from this tree?",
            )?
        };
        let trace = rtt
            .up_channels()
            .iter()
            .find(|c| c.name() == Some("trace"))
            .map(|c| c.number())
            .or_else(|| rtt.up_channel(TRACE_CHANNEL).map(|c| c.number()));
        if trace.is_none() {
            eprintln!("the firmware has no RTT trace channel: only the log is shown");
        }
        Ok(Self {
            session,
            rtt,
            trace,
        })
    }
}

impl Source for RttLink {
    fn poll(&mut self, out: &mut Vec<Chunk>) -> Result<bool> {
        let mut core = self.session.core(0).context("the chip's core")?;
        let mut buf = [0u8; 1024];
        for (number, trace) in [(Some(LOG_CHANNEL), false), (self.trace, true)] {
            let Some(number) = number else { continue };
            let Some(channel) = self.rtt.up_channel(number) else {
                continue;
            };
            let n = channel.read(&mut core, &mut buf).with_context(|| {
                format!("reading RTT up-channel {number}: is the board still powered?")
            })?;
            if n > 0 {
                let bytes = buf[..n].to_vec();
                out.push(if trace {
                    Chunk::Trace(bytes)
                } else {
                    Chunk::Log(bytes)
                });
            }
        }
        Ok(true)
    }
}

/// The image a probe writes: for an ELF linked behind AMiRo-BLT a copy with the bootloader's
/// checksum word written into its slot (else AMiRo-BLT would not start it), else the ELF as built.
pub fn probe_image(board: &Board, elf: &Path) -> Result<PathBuf> {
    let bytes = std::fs::read(elf).with_context(|| format!("reading {}", elf.display()))?;
    let behind_bootloader = object::read::File::parse(&*bytes)
        .map(|f| object::Object::section_by_name(&f, crate::elf::CHECKSUM_SECTION).is_some())
        .unwrap_or(false);
    if behind_bootloader {
        let patched = elf.with_extension("blt.elf");
        let word = crate::elf::write_checksum(elf, &patched)?;
        println!(
            "{}: AMiRo-BLT checksum word {word:#010x} written into {}",
            board.name,
            patched.display()
        );
        Ok(patched)
    } else {
        println!(
            "{}: bare-chip image (no AMiRo-BLT slot), flashed as built",
            board.name
        );
        Ok(elf.to_path_buf())
    }
}
