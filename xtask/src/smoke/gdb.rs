//! Inputs a QEMU machine has no register for, held at the robot's level through QEMU's gdbstub: a
//! read watchpoint on the input's port register stops the CPU at every load from it (QEMU stops
//! *before* the access on ARM), the load is stepped, and the bits the robot's wiring holds are set
//! in the register it loaded into. Used where the port is a region that reads zero and drops
//! writes (`netduinoplus2`'s GPIO), so the stand-in cannot set it (`docs/faults.md`).
//!
//! The patcher runs on its own thread beside the QMP polling of [`super::run_board`]; both take
//! [`Steering`]'s lock while they hold the guest stopped, and the polling leaves a guest that the
//! gdbstub stopped (run state `debug`) to this thread.
use std::io::{Read, Write};
use std::os::unix::net::UnixStream;
use std::path::Path;
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

use anyhow::{bail, ensure, Context, Result};

/// The lock that the QMP polling and the patcher hold while the guest is stopped for them; its
/// value is whether the run is ending (the polling sets it before QEMU is killed, so a stop the
/// patcher takes after that is not patched: the gdbstub may close under it).
pub type Steering = Arc<Mutex<bool>>;

/// One GDB remote-protocol connection (QEMU 7.2's gdbstub has no no-ack mode: every packet is
/// acknowledged with `+`).
struct Remote {
    stream: UnixStream,
    pending: Vec<u8>,
}

impl Remote {
    fn connect(socket: &Path) -> Result<Self> {
        let mut last = None;
        for _ in 0..50 {
            match UnixStream::connect(socket) {
                Ok(stream) => {
                    return Ok(Self {
                        stream,
                        pending: Vec::new(),
                    });
                }
                Err(error) => last = Some(error),
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        Err(last.context("no gdbstub")?)
            .with_context(|| format!("connecting to QEMU's gdbstub at {}", socket.display()))
    }

    fn send(&mut self, data: &str) -> Result<()> {
        let sum = data.bytes().fold(0u8, |sum, b| sum.wrapping_add(b));
        write!(self.stream, "${data}#{sum:02x}").context("writing to QEMU's gdbstub")?;
        Ok(())
    }

    /// The next packet (acknowledgements and anything outside a packet skipped); `None` when QEMU
    /// has gone.
    fn next(&mut self) -> Result<Option<String>> {
        loop {
            if let Some(start) = self.pending.iter().position(|&b| b == b'$') {
                if let Some(end) = self.pending[start..].iter().position(|&b| b == b'#') {
                    let end = start + end;
                    if self.pending.len() >= end + 3 {
                        let data = String::from_utf8_lossy(&self.pending[start + 1..end]).into();
                        self.pending.drain(..end + 3);
                        self.stream
                            .write_all(b"+")
                            .context("acknowledging to QEMU's gdbstub")?;
                        return Ok(Some(data));
                    }
                }
            }
            let mut chunk = [0u8; 4096];
            let n = self.stream.read(&mut chunk).unwrap_or(0);
            if n == 0 {
                return Ok(None);
            }
            self.pending.extend_from_slice(&chunk[..n]);
        }
    }

    fn receive(&mut self) -> Result<String> {
        self.next()?.context("QEMU's gdbstub closed")
    }

    /// Sends `data` and returns the reply; a gdbstub that does not answer within 10 s ends the
    /// patcher (and with it the lock it holds) instead of hanging the run.
    fn command(&mut self, data: &str) -> Result<String> {
        self.send(data)?;
        self.stream
            .set_read_timeout(Some(Duration::from_secs(10)))?;
        let reply = self.receive();
        self.stream.set_read_timeout(None)?;
        let reply = reply.with_context(|| format!("gdbstub: no answer to `{data}`"))?;
        if reply.starts_with('E') {
            bail!("gdbstub: `{data}` failed: {reply}");
        }
        Ok(reply)
    }

    /// The core registers r0..r15 (`g`: QEMU 7.2 answers `p`/`P` only to a client that read its
    /// target description), as the hex text `G` takes back.
    fn registers(&mut self) -> Result<String> {
        let all = self.command("g")?;
        ensure!(all.len() >= 16 * 8, "gdbstub: short register dump `{all}`");
        Ok(all)
    }
}

/// Register `n` of a `g` dump.
fn register(all: &str, n: usize) -> Result<u32> {
    let bytes = hex_bytes(&all[8 * n..8 * n + 8])?;
    Ok(u32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]))
}

/// A `g` dump with register `n` set to `value`.
fn with_register(all: &str, n: usize, value: u32) -> String {
    let hex: String = value
        .to_le_bytes()
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect();
    format!("{}{hex}{}", &all[..8 * n], &all[8 * n + 8..])
}

fn hex_bytes(text: &str) -> Result<Vec<u8>> {
    (0..text.len() / 2)
        .map(|i| u8::from_str_radix(&text[2 * i..2 * i + 2], 16).context("gdbstub: not hex"))
        .collect()
}

/// The register a Thumb load instruction (first halfword `first`, next `second`) loads into: the
/// 16-bit register- and immediate-offset loads (LDR, LDRH, LDRB, LDRSH, LDRSB; Rt in bits 0..3) and
/// the 32-bit single loads (LDR.W and its byte/halfword kinds; Rt in bits 12..16 of the second
/// halfword). `None` for anything else.
pub fn load_target(first: u16, second: u16) -> Option<u32> {
    let rt16 = u32::from(first & 7);
    // 0101 011 … 0101 111: the register-offset loads (LDRSB, LDR, LDRH, LDRB, LDRSH).
    if (0b010_1011..=0b010_1111).contains(&(first >> 9)) {
        return Some(rt16);
    }
    match first >> 11 {
        0b01101 | 0b01111 | 0b10001 => return Some(rt16), // LDR, LDRB, LDRH (immediate)
        _ => {}
    }
    // 1111 1000 xxx1 nnnn (LDR{B,H}.W / LDRS{B,H}.W are 1111 100x x..1): a single load.
    if first & 0xFE10 == 0xF810 {
        return Some(u32::from(second >> 12));
    }
    None
}

/// Inserts a read watchpoint per `(address, bits)` and starts the guest (QEMU was started with
/// `-S`); then, on every stop at a watched load: steps it and ORs `bits` into the register it
/// loaded. Returns the thread, which ends with the number of loads patched when QEMU goes.
pub fn hold_inputs(
    socket: &Path,
    inputs: Vec<(u32, u32)>,
    steering: Steering,
) -> Result<JoinHandle<Result<u32>>> {
    let mut remote = Remote::connect(socket)?;
    for &(address, _) in &inputs {
        let reply = remote.command(&format!("Z3,{address:x},4"))?;
        ensure!(
            reply == "OK",
            "gdbstub: no read watchpoint at {address:#x}: `{reply}`"
        );
    }
    remote.send("c")?;
    Ok(std::thread::spawn(move || -> Result<u32> {
        let mut patched = 0;
        while let Some(stop) = remote.next()? {
            let held = steering.lock().unwrap_or_else(|poison| poison.into_inner());
            if *held {
                break;
            }
            // Only a watchpoint's stop is this thread's; a pause from the QMP polling is resumed
            // there.
            let Some(watched) = stop
                .split(';')
                .find_map(|field| field.strip_prefix("rwatch:"))
                .and_then(|hex| u32::from_str_radix(hex, 16).ok())
            else {
                continue;
            };
            let &(address, bits) = inputs
                .iter()
                .find(|(address, _)| *address == watched)
                .with_context(|| format!("a watchpoint at {watched:#x} that was not set"))?;
            let pc = register(&remote.registers()?, 15)?;
            let code = hex_bytes(&remote.command(&format!("m{pc:x},4"))?)?;
            ensure!(code.len() == 4, "gdbstub: no code at {pc:#x}");
            let first = u16::from_le_bytes([code[0], code[1]]);
            let second = u16::from_le_bytes([code[2], code[3]]);
            let rt = load_target(first, second).with_context(|| {
                format!("the read of {address:#x} at {pc:#x} is no load this patcher knows ({first:#06x} {second:#06x})")
            })?;
            remote.command(&format!("z3,{address:x},4"))?;
            let stepped = remote.command("s")?;
            ensure!(
                stepped.starts_with('T') || stepped.starts_with('S'),
                "gdbstub: stepping the load at {pc:#x}: `{stepped}`"
            );
            let all = remote.registers()?;
            let rt = rt as usize;
            let set = with_register(&all, rt, register(&all, rt)? | bits);
            remote.command(&format!("G{set}"))?;
            remote.command(&format!("Z3,{address:x},4"))?;
            remote.send("c")?;
            patched += 1;
        }
        Ok(patched)
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_register_dump_is_read_and_patched_in_place() {
        let all = format!("{}{}", "00000000".repeat(15), "88f30008");
        assert_eq!(register(&all, 15).unwrap(), 0x0800_f388);
        let set = with_register(&all, 1, 0x2000);
        assert_eq!(register(&set, 1).unwrap(), 0x2000);
        assert_eq!(register(&set, 15).unwrap(), 0x0800_f388);
        assert_eq!(set.len(), all.len());
    }

    #[test]
    fn load_targets_are_decoded_for_the_loads_a_port_read_compiles_to() {
        assert_eq!(load_target(0x5820, 0), Some(0), "ldr r0, [r4, r0]");
        assert_eq!(load_target(0x6921, 0), Some(1), "ldr r1, [r4, #0x10]");
        assert_eq!(load_target(0x8a0b, 0), Some(3), "ldrh r3, [r1, #0x10]");
        assert_eq!(
            load_target(0xF8D4, 0x5010),
            Some(5),
            "ldr.w r5, [r4, #0x10]"
        );
        assert_eq!(load_target(0xF854, 0xC000), Some(12), "ldr.w r12, [r4, r0]");
        assert_eq!(load_target(0x6021, 0), None, "str r1, [r4]");
        assert_eq!(load_target(0xF8C4, 0x5010), None, "str.w");
        assert_eq!(load_target(0x4770, 0), None, "bx lr");
    }
}
