//! The live bench: bytes of the board's two RTT up-channels (the log and the trace) as they
//! arrive, from a probe (`crate::probe`) or a file that is still being written, through one
//! pipeline: the log into lines, the trace into the capture decoder and a raw copy on disk (a
//! capture `--capture` reads again), and a periodically redrawn view of the figures so far.
//! Everything here runs without a probe: the tests feed recorded bytes in random chunks.
use std::fs::File;
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::{Context, Result};

use crate::probe::{Chunk, Source};

use super::capture::{Capture, Stream};
use super::report::{columns, names, task_cells, topic_cells};
use super::Bench;

/// Splits the log channel into lines: a line is complete at its `\n`; a partial one waits.
#[derive(Debug, Default)]
pub struct LineSplitter {
    partial: Vec<u8>,
}

impl LineSplitter {
    /// Takes the next bytes and returns the lines they complete (`\r` and the `\n` dropped,
    /// invalid UTF-8 replaced).
    pub fn push(&mut self, bytes: &[u8], lines: &mut Vec<String>) {
        for &b in bytes {
            if b == b'\n' {
                let line = String::from_utf8_lossy(&self.partial)
                    .trim_end_matches('\r')
                    .to_string();
                lines.push(line);
                self.partial.clear();
            } else {
                self.partial.push(b);
            }
        }
    }

    /// The unfinished last line, if any.
    pub fn rest(&self) -> Option<String> {
        (!self.partial.is_empty()).then(|| String::from_utf8_lossy(&self.partial).into_owned())
    }
}

/// The two channels' bytes, demultiplexed: log lines out, the trace decoded and saved raw.
pub struct Pipeline {
    stream: Stream,
    log: LineSplitter,
    raw: Option<(PathBuf, File)>,
    log_file: Option<File>,
}

impl Pipeline {
    /// A pipeline on the trace clock `default_hz` (unless a boot record says otherwise); with
    /// `save`, the raw trace bytes go to `save/trace.bin` and the log to `save/log.txt`.
    pub fn new(default_hz: u64, save: Option<&Path>) -> Result<Self> {
        let (raw, log_file) = match save {
            Some(dir) => {
                std::fs::create_dir_all(dir)
                    .with_context(|| format!("creating {}", dir.display()))?;
                let raw = dir.join("trace.bin");
                let file =
                    File::create(&raw).with_context(|| format!("creating {}", raw.display()))?;
                let log = dir.join("log.txt");
                let log_file =
                    File::create(&log).with_context(|| format!("creating {}", log.display()))?;
                (Some((raw, file)), Some(log_file))
            }
            None => (None, None),
        };
        Ok(Self {
            stream: Stream::new(default_hz),
            log: LineSplitter::default(),
            raw,
            log_file,
        })
    }

    /// Takes one chunk; complete log lines are appended to `lines`.
    pub fn push(&mut self, chunk: &Chunk, lines: &mut Vec<String>) -> Result<()> {
        match chunk {
            Chunk::Log(bytes) => {
                if let Some(f) = &mut self.log_file {
                    f.write_all(bytes).context("saving the log")?;
                }
                self.log.push(bytes, lines);
            }
            Chunk::Trace(bytes) => {
                if let Some((path, f)) = &mut self.raw {
                    f.write_all(bytes)
                        .with_context(|| format!("saving the capture to {}", path.display()))?;
                }
                self.stream.push(bytes);
            }
        }
        Ok(())
    }

    /// The capture so far.
    pub fn capture(&mut self) -> &Capture {
        self.stream.capture()
    }

    /// Trace bytes taken so far.
    pub fn trace_bytes(&self) -> u64 {
        self.stream.bytes()
    }

    /// Where the raw capture is saved, if it is.
    pub fn saved(&self) -> Option<&Path> {
        self.raw.as_ref().map(|(p, _)| p.as_path())
    }

    /// The whole capture and the log's unfinished last line; the saved files flushed.
    pub fn finish(mut self) -> Result<(Capture, Option<String>)> {
        if let Some((path, f)) = &mut self.raw {
            f.flush()
                .with_context(|| format!("saving the capture to {}", path.display()))?;
        }
        if let Some(f) = &mut self.log_file {
            f.flush().context("saving the log")?;
        }
        Ok((self.stream.finish(), self.log.rest()))
    }
}

/// When a live run stops.
#[derive(Debug, Clone, Copy)]
pub struct Stop {
    /// After this long (wall clock).
    pub after: Option<Duration>,
    /// After this long without a byte (a file that stopped growing).
    pub idle: Option<Duration>,
    /// How often the view is redrawn.
    pub refresh: Duration,
}

/// Streams `source` through `pipeline` until it ends, `stop` says so, or `interrupted` is set
/// (Ctrl-C). `on_lines` gets every complete log line; `on_refresh` is called every
/// `stop.refresh` with the pipeline and the last log lines (at most 8) to redraw the view.
pub fn run<S: Source + ?Sized>(
    source: &mut S,
    pipeline: &mut Pipeline,
    stop: Stop,
    interrupted: &AtomicBool,
    mut on_lines: impl FnMut(&[String]),
    mut on_refresh: impl FnMut(&mut Pipeline, &[String]) -> Result<()>,
) -> Result<()> {
    let started = Instant::now();
    let mut last_byte = Instant::now();
    let mut last_refresh = Instant::now();
    let mut recent: Vec<String> = Vec::new();
    let mut chunks = Vec::new();
    loop {
        chunks.clear();
        let going = source.poll(&mut chunks)?;
        let mut lines = Vec::new();
        for chunk in &chunks {
            pipeline.push(chunk, &mut lines)?;
        }
        if !chunks.is_empty() {
            last_byte = Instant::now();
        }
        if !lines.is_empty() {
            on_lines(&lines);
            recent.extend(lines);
            let excess = recent.len().saturating_sub(8);
            recent.drain(..excess);
        }
        let ended = !going
            || interrupted.load(Ordering::Relaxed)
            || stop.after.is_some_and(|d| started.elapsed() >= d)
            || stop.idle.is_some_and(|d| last_byte.elapsed() >= d);
        if ended || last_refresh.elapsed() >= stop.refresh {
            on_refresh(pipeline, &recent)?;
            last_refresh = Instant::now();
        }
        if ended {
            return Ok(());
        }
        if chunks.is_empty() {
            std::thread::sleep(Duration::from_millis(5));
        }
    }
}

/// A capture file read as it grows (another RTT client writing it): its bytes are the trace
/// channel.
pub struct GrowingFile {
    file: File,
    offset: u64,
}

impl GrowingFile {
    /// Opens `path` from its start.
    pub fn open(path: &Path) -> Result<Self> {
        let file = File::open(path).with_context(|| format!("opening {}", path.display()))?;
        Ok(Self { file, offset: 0 })
    }
}

impl Source for GrowingFile {
    fn poll(&mut self, out: &mut Vec<Chunk>) -> Result<bool> {
        self.file.seek(SeekFrom::Start(self.offset))?;
        let mut buf = vec![0u8; 64 * 1024];
        let n = self.file.read(&mut buf).context("reading the capture")?;
        if n > 0 {
            buf.truncate(n);
            self.offset += n as u64;
            out.push(Chunk::Trace(buf));
        }
        Ok(true)
    }
}

const RED: &str = "\x1b[1;31m";
const RESET: &str = "\x1b[0m";

/// The live view: per task jobs, execution max/p99 and response max against the analysed WCRT,
/// per topic the latencies against their bounds; anything above its bound in red and marked
/// `!!`, with a banner. `color`: ANSI colours (a terminal).
pub fn view(
    bench: &Bench,
    trace_bytes: u64,
    elapsed: Duration,
    log: &[String],
    color: bool,
) -> String {
    use std::fmt::Write as _;
    let (red, reset) = if color { (RED, RESET) } else { ("", "") };
    let mut out = String::new();
    let _ = writeln!(
        out,
        "{} live — {:.1} s, {} trace bytes, {} records, {} lost on the board, {} damaged, {} unbalanced",
        bench.board,
        elapsed.as_secs_f64(),
        trace_bytes,
        bench.records,
        bench.lost,
        bench.damaged,
        bench.unbalanced
    );
    let failures = bench.failures();
    if !failures.is_empty() {
        let _ = writeln!(
            out,
            "{red}!!! OBSERVED ABOVE ANALYSED — the analysis (or a budget) is wrong:{reset}"
        );
        for f in &failures {
            let _ = writeln!(out, "{red}!!!   {f}{reset}");
        }
    }
    // A row above its bound: marked `!!`, in red.
    let row = |cells: &[String], widths: &[usize]| {
        let line = columns(cells, widths);
        if cells.last().is_some_and(|v| v.starts_with("EXCEEDS")) {
            format!("{red}!! {line}{reset}")
        } else {
            format!("   {line}")
        }
    };
    const TASK_WIDTHS: [usize; 6] = [20, 7, 9, 9, 10, 9];
    let header = names("task|jobs|exec max|exec p99|resp max|WCRT|verdict");
    let _ = writeln!(out, "\n   {}", columns(&header, &TASK_WIDTHS));
    for t in &bench.tasks {
        let [task, jobs, exec_max, exec_p99, _, response, wcrt, _, verdict] = task_cells(t);
        let cells = [task, jobs, exec_max, exec_p99, response, wcrt, verdict];
        let _ = writeln!(out, "{}", row(&cells, &TASK_WIDTHS));
    }
    const TOPIC_WIDTHS: [usize; 7] = [26, 7, 9, 9, 9, 9, 13];
    let header = names("topic|samples|→queued|job WCRT|→bus|msg WCRT|jitter/bound|verdict");
    let _ = writeln!(out, "\n   {}", columns(&header, &TOPIC_WIDTHS));
    for t in &bench.topics {
        let [topic, level, samples, _, _, queued, job, bus, message, delivery, analysed, verdict] =
            topic_cells(t);
        let (name, jitter) = (format!("{topic}@{level}"), format!("{delivery}/{analysed}"));
        let cells = [name, samples, queued, job, bus, message, jitter, verdict];
        let _ = writeln!(out, "{}", row(&cells, &TOPIC_WIDTHS));
    }
    if !log.is_empty() {
        let _ = writeln!(out, "\nlog:");
        for line in log {
            let _ = writeln!(out, "  {line}");
        }
    }
    out
}

/// Clears the terminal and puts the cursor home: the next view replaces the last.
pub const REDRAW: &str = "\x1b[H\x1b[2J";

/// A flag the first Ctrl-C sets (a live stream then ends cleanly, its report written); a second
/// Ctrl-C ends the process as usual.
pub fn interrupt_flag() -> Result<std::sync::Arc<std::sync::atomic::AtomicBool>> {
    use signal_hook::consts::SIGINT;
    let flag = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    signal_hook::flag::register_conditional_shutdown(SIGINT, 130, std::sync::Arc::clone(&flag))
        .and_then(|_| signal_hook::flag::register(SIGINT, std::sync::Arc::clone(&flag)))
        .context("installing the Ctrl-C handler")?;
    Ok(flag)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A recorded capture handed out in chunks of random sizes, log bytes in between.
    struct Chunked {
        trace: Vec<u8>,
        log: Vec<u8>,
        at: usize,
        log_at: usize,
        seed: u64,
    }

    impl Chunked {
        fn next(&mut self, bound: usize) -> usize {
            // xorshift: deterministic, different sizes every call.
            self.seed ^= self.seed << 13;
            self.seed ^= self.seed >> 7;
            self.seed ^= self.seed << 17;
            1 + (self.seed % bound as u64) as usize
        }
    }

    impl Source for Chunked {
        fn poll(&mut self, out: &mut Vec<Chunk>) -> Result<bool> {
            if self.log_at < self.log.len() {
                let n = self.next(40).min(self.log.len() - self.log_at);
                out.push(Chunk::Log(self.log[self.log_at..self.log_at + n].to_vec()));
                self.log_at += n;
            }
            if self.at < self.trace.len() {
                let n = self.next(700).min(self.trace.len() - self.at);
                out.push(Chunk::Trace(self.trace[self.at..self.at + n].to_vec()));
                self.at += n;
            }
            Ok(self.at < self.trace.len() || self.log_at < self.log.len())
        }
    }

    fn recorded() -> Vec<u8> {
        std::fs::read(
            Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/diwheeldrive-thesis-60ms.trace"),
        )
        .unwrap()
    }

    fn root() -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .parent()
            .unwrap()
            .to_path_buf()
    }

    #[test]
    fn log_lines_are_split_across_chunks() {
        let mut s = LineSplitter::default();
        let mut lines = Vec::new();
        s.push(b"boot\r\nhel", &mut lines);
        s.push(b"lo\n\nwor", &mut lines);
        assert_eq!(lines, vec!["boot", "hello", ""]);
        assert_eq!(s.rest().as_deref(), Some("wor"));
        s.push(b"ld\n", &mut lines);
        assert_eq!(lines.last().map(String::as_str), Some("world"));
        assert_eq!(s.rest(), None);
    }

    #[test]
    fn the_live_pipeline_ends_where_the_capture_path_does() {
        let board = crate::boards::by_name("diwheeldrive").unwrap();
        let bytes = recorded();
        let hz = super::super::default_clock_hz(board, true);
        let whole = super::super::capture::read(&bytes, hz).unwrap();
        let expected =
            super::super::measure(&root(), board, &whole, "recorded", true, None).unwrap();
        assert!(!expected.tasks.is_empty() && !expected.topics.is_empty());

        let log: Vec<u8> = (0..50)
            .flat_map(|i| format!("line {i} ünïcode\n").into_bytes())
            .collect();
        for seed in [1u64, 0x9E37_79B9_7F4A_7C15, 12345] {
            let dir =
                std::env::temp_dir().join(format!("amiro-live-{}-{seed}", std::process::id()));
            let mut pipeline = Pipeline::new(hz, Some(&dir)).unwrap();
            let mut source = Chunked {
                trace: bytes.clone(),
                log: log.clone(),
                at: 0,
                log_at: 0,
                seed,
            };
            let mut lines = Vec::new();
            let mut refreshes = 0;
            let stop = Stop {
                after: None,
                idle: None,
                refresh: Duration::ZERO,
            };
            run(
                &mut source,
                &mut pipeline,
                stop,
                &AtomicBool::new(false),
                |l| lines.extend_from_slice(l),
                |p, _| {
                    refreshes += 1;
                    let _ = p.capture();
                    Ok(())
                },
            )
            .unwrap();
            assert!(refreshes > 1, "the view was redrawn while streaming");
            assert_eq!(pipeline.trace_bytes(), bytes.len() as u64);
            let saved = pipeline.saved().unwrap().to_path_buf();
            let (capture, rest) = pipeline.finish().unwrap();
            assert_eq!(rest, None);
            assert_eq!(lines.len(), 50);
            assert_eq!(lines[49], "line 49 ünïcode");
            // The raw copy is the capture, byte for byte: `--capture` reads it again.
            assert_eq!(std::fs::read(&saved).unwrap(), bytes);
            assert_eq!(std::fs::read(dir.join("log.txt")).unwrap(), log);
            let live =
                super::super::measure(&root(), board, &capture, "recorded", true, None).unwrap();
            assert_eq!(
                serde_json::to_string(&live).unwrap(),
                serde_json::to_string(&expected).unwrap(),
                "seed {seed}"
            );
            assert_eq!(
                super::super::report::table(&live),
                super::super::report::table(&expected)
            );
            let _ = std::fs::remove_dir_all(&dir);
        }
    }

    #[test]
    fn an_interrupt_stops_the_stream_and_draws_once_more() {
        let bytes = recorded();
        let mut pipeline = Pipeline::new(120_000_000, None).unwrap();
        let mut source = Chunked {
            trace: bytes.clone(),
            log: Vec::new(),
            at: 0,
            log_at: 0,
            seed: 7,
        };
        let interrupted = AtomicBool::new(true);
        let mut refreshes = 0;
        let stop = Stop {
            after: None,
            idle: None,
            refresh: Duration::from_secs(3600),
        };
        run(
            &mut source,
            &mut pipeline,
            stop,
            &interrupted,
            |_| {},
            |_, _| {
                refreshes += 1;
                Ok(())
            },
        )
        .unwrap();
        assert_eq!(refreshes, 1);
        assert!(pipeline.trace_bytes() < bytes.len() as u64);
    }

    /// One chunk, then the probe stops answering.
    struct Failing(bool);

    impl Source for Failing {
        fn poll(&mut self, out: &mut Vec<Chunk>) -> Result<bool> {
            if std::mem::replace(&mut self.0, true) {
                anyhow::bail!("reading RTT up-channel 1: the probe stopped answering");
            }
            out.push(Chunk::Trace(recorded()[..100].to_vec()));
            Ok(true)
        }
    }

    #[test]
    fn a_source_error_ends_the_run_and_keeps_what_arrived() {
        let mut pipeline = Pipeline::new(120_000_000, None).unwrap();
        let stop = Stop {
            after: None,
            idle: None,
            refresh: Duration::from_secs(3600),
        };
        let err = run(
            &mut Failing(false),
            &mut pipeline,
            stop,
            &AtomicBool::new(false),
            |_| {},
            |_, _| Ok(()),
        )
        .unwrap_err();
        assert!(err.to_string().contains("stopped answering"));
        assert_eq!(pipeline.trace_bytes(), 100);
        assert!(pipeline.capture().reader.records > 0);
    }

    #[test]
    fn a_growing_file_is_read_as_it_grows() {
        let path = std::env::temp_dir().join(format!("amiro-growing-{}.trace", std::process::id()));
        let bytes = recorded();
        let (first, second) = bytes.split_at(bytes.len() / 3);
        std::fs::write(&path, first).unwrap();
        let mut source = GrowingFile::open(&path).unwrap();
        let mut out = Vec::new();
        assert!(source.poll(&mut out).unwrap());
        std::fs::OpenOptions::new()
            .append(true)
            .open(&path)
            .unwrap()
            .write_all(second)
            .unwrap();
        while source.poll(&mut out).unwrap() && out.iter().map(len).sum::<usize>() < bytes.len() {}
        let got: Vec<u8> = out
            .iter()
            .flat_map(|c| match c {
                Chunk::Trace(b) => b.clone(),
                Chunk::Log(_) => Vec::new(),
            })
            .collect();
        assert_eq!(got, bytes);
        let _ = std::fs::remove_file(&path);
    }

    fn len(c: &Chunk) -> usize {
        match c {
            Chunk::Trace(b) | Chunk::Log(b) => b.len(),
        }
    }

    #[test]
    fn the_view_flags_an_observed_response_above_its_wcrt() {
        let board = crate::boards::by_name("diwheeldrive").unwrap();
        let capture = super::super::capture::read(&recorded(), 120_000_000).unwrap();
        let mut bench =
            super::super::measure(&root(), board, &capture, "recorded", true, None).unwrap();
        // The recording's can_rx job runs QEMU's bxCAN model, above the release image's (held) bound: the
        // machine-code check is `bench::machine`'s to test; this view's responses are calm.
        bench.machine.clear();
        let calm = view(&bench, 10, Duration::from_secs(1), &["hello".into()], true);
        assert!(!calm.contains("!!"), "{calm}");
        assert!(calm.contains("hello"));
        let task = bench
            .tasks
            .iter_mut()
            .find(|t| t.wcrt_us.is_some())
            .expect("an analysed task");
        let name = task.task.clone();
        task.response_max_us = task.wcrt_us.unwrap() + 1.0;
        task.verdict = "EXCEEDS WCRT".into();
        let loud = view(&bench, 10, Duration::from_secs(1), &[], true);
        assert!(loud.contains("!!! OBSERVED ABOVE ANALYSED"), "{loud}");
        let row = loud
            .lines()
            .find(|l| l.contains(&name) && l.contains("EXCEEDS WCRT") && !l.contains("response"))
            .expect("the task's row");
        assert!(row.starts_with(RED) && row.contains("!!"), "{row:?}");
        let plain = view(&bench, 10, Duration::from_secs(1), &[], false);
        assert!(!plain.contains('\x1b'));
    }
}
