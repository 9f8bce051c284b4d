//! QEMU steered over QMP, its JSON monitor, on its standard input and output.
use std::io::{BufRead, BufReader, Write};
use std::path::Path;
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::mpsc::{self, Receiver};
use std::time::Duration;

use anyhow::{bail, ensure, Context, Result};

use super::RAM_BASE;

/// How long QEMU's monitor may take to answer one command (wall time).
const MONITOR_WAIT: Duration = Duration::from_secs(60);

/// QEMU steered over QMP on its standard input and output.
pub struct Qmp {
    pub child: Child,
    input: ChildStdin,
    lines: Receiver<String>,
}

impl Qmp {
    pub fn start(command: &mut Command) -> Result<Self> {
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

    pub fn execute(
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
    pub fn words(&mut self, address: u32, count: usize) -> Result<Vec<u32>> {
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
    pub fn pc(&mut self) -> Result<u32> {
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

    pub fn save_ram(&mut self, size: u64, file: &Path) -> Result<Vec<u8>> {
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
