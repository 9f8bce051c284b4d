//! One SLCAN adapter, many `amiro` processes: the first process to open an adapter becomes its owner and serves
//! the others through a unix socket; later ones connect to it instead of opening the serial port.
//!
//! A serial adapter can only have one reader, and SLCAN has no notion of sessions: a second program that opens
//! the port and sends `C` closes the channel under the first (which then hears nothing). So `amiro` never opens a
//! port another `amiro` holds. The owner runs a small hub: one thread talks to the adapter (frames it hears go to
//! every user; frames any user sends are transmitted, confirmed to the sender and shown to the other users, as
//! SocketCAN's local loopback does), one thread accepts connections. When the owner ends, the hub closes the
//! channel and tells every connected process, which report the lost bus and exit non-zero.
//!
//! Rendezvous, race-free: the socket and a lock file live in a per-user directory, named after the device's
//! canonical path. A process first tries to connect; if nobody answers it takes the lock (`flock`) and becomes the
//! owner; if the lock is held, an owner is starting up and it retries the connection for a moment.
//!
//! The socket speaks lines of text. Hub to user: `amiro-relay 1 <owner>` (greeting), `frame <candump -l line>`,
//! `sent`, `refused <reason>`, `closed <reason>`. User to hub: `send <ID#DATA>`.

use std::fs::{File, OpenOptions};
use std::io::{ErrorKind, Read, Write};
use std::os::fd::AsFd;
use std::os::unix::fs::{DirBuilderExt, OpenOptionsExt};
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, Sender};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use anyhow::{anyhow, bail, Context, Result};
use nix::fcntl::{Flock, FlockArg};
use nix::poll::{poll, PollFd, PollFlags, PollTimeout};

use super::slcan::Slcan;
use super::{interrupted, Bus, Reception};
use crate::frame::{parse_compact, parse_line, LoggedFrame, RawFrame, Timestamp};

/// The first line a hub sends; the number changes when the line protocol does.
const GREETING: &str = "amiro-relay 1";
/// How long a user waits for the hub to confirm a transmission (the adapter itself answers within 1 s).
const SEND_TIMEOUT: Duration = Duration::from_secs(3);
/// How long a process waits for an owner that holds the lock but is not listening yet (it is opening the adapter).
const OWNER_STARTUP: Duration = Duration::from_secs(3);
/// Slices in which waits check for Ctrl-C and shutdown.
const SLICE: Duration = Duration::from_millis(20);
/// Interface name of frames received through an adapter (as `slcan.rs` names them).
const INTERFACE: &str = "slcan";

/// Where the socket and lock file of a device live: `$AMIRO_RUNTIME_DIR`, else `$XDG_RUNTIME_DIR/amiro`, else
/// `/tmp/amiro-<uid>`; the names are the device's canonical path with every other character replaced.
pub fn rendezvous(device: &Path) -> Result<(PathBuf, PathBuf)> {
    let dir = match (
        std::env::var_os("AMIRO_RUNTIME_DIR"),
        std::env::var_os("XDG_RUNTIME_DIR"),
    ) {
        (Some(dir), _) => PathBuf::from(dir),
        (None, Some(dir)) => PathBuf::from(dir).join("amiro"),
        (None, None) => PathBuf::from(format!("/tmp/amiro-{}", nix::unistd::getuid())),
    };
    std::fs::DirBuilder::new()
        .recursive(true)
        .mode(0o700)
        .create(&dir)
        .with_context(|| format!("cannot create {}", dir.display()))?;
    let canonical = device
        .canonicalize()
        .with_context(|| format!("cannot open {}", device.display()))?;
    let name: String = canonical
        .to_string_lossy()
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect();
    Ok((
        dir.join(format!("slcan{name}.sock")),
        dir.join(format!("slcan{name}.lock")),
    ))
}

/// Opens an SLCAN adapter, shared: connects to the `amiro` that owns it, or becomes its owner.
pub fn open_shared(device: &Path, baud: Option<u32>) -> Result<Box<dyn Bus>> {
    let (socket, lock) = rendezvous(device)?;
    let give_up = Instant::now() + OWNER_STARTUP;
    loop {
        if let Some(client) = RelayClient::connect(&socket)? {
            if baud.is_some() {
                eprintln!(
                    "note: {} is already open in {}; its baud rate is kept",
                    device.display(),
                    client.owner
                );
            }
            return Ok(Box::new(client));
        }
        let lock_file = OpenOptions::new()
            .create(true)
            .truncate(false)
            .write(true)
            .mode(0o600)
            .open(&lock)
            .with_context(|| format!("cannot open {}", lock.display()))?;
        match Flock::lock(lock_file, FlockArg::LockExclusiveNonblock) {
            Ok(held) => return Ok(Box::new(Hub::start(device, baud, socket, held)?)),
            Err((_, nix::errno::Errno::EWOULDBLOCK)) if Instant::now() < give_up => {
                std::thread::sleep(Duration::from_millis(50));
            }
            Err((_, errno)) => bail!(
                "{} is held by another amiro that does not answer on {} ({errno}); if no amiro is running, \
                 delete {}",
                device.display(),
                socket.display(),
                lock.display()
            ),
        }
    }
}

/// Who owns the adapter, for messages: `amiro monitor (pid 1234)`.
fn describe_this_process() -> String {
    let words: Vec<String> = std::env::args().skip(1).take(1).collect();
    format!("amiro {} (pid {})", words.join(" "), std::process::id())
}

/// What the adapter thread tells every user.
#[derive(Clone, Debug)]
enum HubEvent {
    Frame(LoggedFrame),
    Closed(String),
}

/// A request to the adapter thread.
enum HubRequest {
    Send {
        frame: RawFrame,
        from: u64,
        reply: Sender<std::result::Result<(), String>>,
    },
    Shutdown,
}

/// Somewhere hub events go: the owner's own channel or a connected process's socket.
enum Subscriber {
    Local(Sender<HubEvent>),
    Remote(Arc<Mutex<UnixStream>>),
}

impl Subscriber {
    /// Delivers an event; false if the user is gone.
    fn deliver(&self, event: &HubEvent) -> bool {
        match self {
            Self::Local(sender) => sender.send(event.clone()).is_ok(),
            Self::Remote(stream) => {
                let line = match event {
                    HubEvent::Frame(logged) => format!("frame {}\n", logged.to_log_line()),
                    HubEvent::Closed(reason) => format!("closed {}\n", one_line(reason)),
                };
                write_line(stream, &line)
            }
        }
    }
}

fn one_line(text: &str) -> String {
    text.replace(['\n', '\r'], " ")
}

fn write_line(stream: &Mutex<UnixStream>, line: &str) -> bool {
    match stream.lock() {
        Ok(mut stream) => stream.write_all(line.as_bytes()).is_ok(),
        Err(_) => false,
    }
}

type Subscribers = Arc<Mutex<Vec<(u64, Subscriber)>>>;

fn broadcast(subscribers: &Subscribers, event: &HubEvent, except: Option<u64>) {
    if let Ok(mut subscribers) = subscribers.lock() {
        subscribers.retain(|(id, subscriber)| Some(*id) == except || subscriber.deliver(event));
    }
}

/// The owner's side: the adapter and the threads that share it, seen by the owner as an ordinary bus.
pub struct Hub {
    requests: Sender<HubRequest>,
    events: Receiver<HubEvent>,
    adapter_thread: Option<JoinHandle<Result<()>>>,
    listener_thread: Option<JoinHandle<()>>,
    stop_listening: Arc<AtomicBool>,
    socket: PathBuf,
    device: PathBuf,
    _lock: Flock<File>,
    /// Frames that arrived while a send waited for its confirmation.
    pending: std::collections::VecDeque<LoggedFrame>,
    closed: Option<String>,
}

/// The owner's own subscriber id; connected processes count from 1.
const OWNER: u64 = 0;

impl Hub {
    fn start(device: &Path, baud: Option<u32>, socket: PathBuf, lock: Flock<File>) -> Result<Self> {
        // The lock is ours, so a socket file left behind is from an owner that crashed.
        let _ = std::fs::remove_file(&socket);
        let mut adapter = Slcan::open(device, baud)
            .with_context(|| format!("cannot open the SLCAN adapter {}", device.display()))?;
        adapter.set_interruptible(false);
        let listener = UnixListener::bind(&socket)
            .with_context(|| format!("cannot listen on {}", socket.display()))?;
        listener.set_nonblocking(true)?;

        let (event_sender, events) = mpsc::channel();
        let subscribers: Subscribers =
            Arc::new(Mutex::new(vec![(OWNER, Subscriber::Local(event_sender))]));
        let (requests, request_receiver) = mpsc::channel();
        let owner = describe_this_process();
        let adapter_thread = {
            let subscribers = Arc::clone(&subscribers);
            let owner = owner.clone();
            std::thread::Builder::new()
                .name("slcan-hub".into())
                .spawn(move || serve_adapter(adapter, &request_receiver, &subscribers, &owner))?
        };
        let stop_listening = Arc::new(AtomicBool::new(false));
        let listener_thread = {
            let stop = Arc::clone(&stop_listening);
            let requests = requests.clone();
            std::thread::Builder::new()
                .name("slcan-hub-listener".into())
                .spawn(move || accept_users(&listener, &stop, &subscribers, &requests, &owner))?
        };
        Ok(Self {
            requests,
            events,
            adapter_thread: Some(adapter_thread),
            listener_thread: Some(listener_thread),
            stop_listening,
            socket,
            device: device.to_path_buf(),
            _lock: lock,
            pending: std::collections::VecDeque::new(),
            closed: None,
        })
    }

    fn take_event(&mut self, event: HubEvent) {
        match event {
            HubEvent::Frame(frame) => self.pending.push_back(frame),
            HubEvent::Closed(reason) => self.closed = Some(reason),
        }
    }

    fn shut_down(&mut self) -> Result<()> {
        self.stop_listening.store(true, Ordering::SeqCst);
        let _ = self.requests.send(HubRequest::Shutdown);
        if let Some(listener) = self.listener_thread.take() {
            let _ = listener.join();
        }
        let _ = std::fs::remove_file(&self.socket);
        match self.adapter_thread.take().map(JoinHandle::join) {
            Some(Ok(result)) => result,
            Some(Err(_)) => bail!("the thread serving {} panicked", self.device.display()),
            None => Ok(()),
        }
    }
}

/// The adapter thread: transmits what users send, hands every received frame to every user.
fn serve_adapter(
    mut adapter: Slcan,
    requests: &Receiver<HubRequest>,
    subscribers: &Subscribers,
    owner: &str,
) -> Result<()> {
    let device = adapter.path().display().to_string();
    loop {
        loop {
            match requests.try_recv() {
                Ok(HubRequest::Send { frame, from, reply }) => match adapter.send(&frame) {
                    Ok(()) => {
                        let _ = reply.send(Ok(()));
                        let echo = LoggedFrame {
                            timestamp: Some(Timestamp::now()),
                            interface: Some(INTERFACE.into()),
                            frame,
                        };
                        broadcast(subscribers, &HubEvent::Frame(echo), Some(from));
                    }
                    Err(error) => {
                        let _ = reply.send(Err(format!("{error:#}")));
                    }
                },
                Ok(HubRequest::Shutdown) | Err(mpsc::TryRecvError::Disconnected) => {
                    let reason = format!("{owner}, which held the adapter {device}, ended");
                    broadcast(subscribers, &HubEvent::Closed(reason), Some(OWNER));
                    return adapter.close();
                }
                Err(mpsc::TryRecvError::Empty) => break,
            }
        }
        match adapter.receive(Some(Duration::from_millis(5))) {
            Ok(Reception::Frame(frame)) => broadcast(subscribers, &HubEvent::Frame(frame), None),
            Ok(_) => {}
            Err(error) => {
                let reason = format!("{error:#}");
                broadcast(subscribers, &HubEvent::Closed(reason), None);
                return Err(error);
            }
        }
    }
}

/// The listener thread: greets each connecting process and serves its requests on a thread of its own.
fn accept_users(
    listener: &UnixListener,
    stop: &AtomicBool,
    subscribers: &Subscribers,
    requests: &Sender<HubRequest>,
    owner: &str,
) {
    static NEXT_ID: AtomicU64 = AtomicU64::new(OWNER + 1);
    while !stop.load(Ordering::SeqCst) {
        let stream = match listener.accept() {
            Ok((stream, _)) => stream,
            Err(error) if error.kind() == ErrorKind::WouldBlock => {
                std::thread::sleep(SLICE);
                continue;
            }
            Err(error) => {
                eprintln!("warning: the SLCAN relay stopped accepting users: {error}");
                return;
            }
        };
        let _ = stream.set_nonblocking(false);
        // A user that stops reading must not stall the adapter for everyone: it is dropped instead.
        let _ = stream.set_write_timeout(Some(Duration::from_millis(500)));
        let Ok(reader) = stream.try_clone() else {
            continue;
        };
        let writer = Arc::new(Mutex::new(stream));
        if !write_line(&writer, &format!("{GREETING} {owner}\n")) {
            continue;
        }
        let id = NEXT_ID.fetch_add(1, Ordering::SeqCst);
        if let Ok(mut list) = subscribers.lock() {
            list.push((id, Subscriber::Remote(Arc::clone(&writer))));
        }
        let requests = requests.clone();
        let subscribers = Arc::clone(subscribers);
        let _ = std::thread::Builder::new()
            .name(format!("slcan-hub-user-{id}"))
            .spawn(move || {
                serve_user(reader, &writer, id, &requests);
                if let Ok(mut list) = subscribers.lock() {
                    list.retain(|(other, _)| *other != id);
                }
            });
    }
}

/// Reads `send` requests from one connected process until it disconnects.
fn serve_user(
    reader: UnixStream,
    writer: &Mutex<UnixStream>,
    id: u64,
    requests: &Sender<HubRequest>,
) {
    use std::io::BufRead;
    for line in std::io::BufReader::new(reader).lines() {
        let Ok(line) = line else { return };
        let answer = match line.strip_prefix("send ").map(parse_compact) {
            Some(Ok(frame)) => {
                let (reply, response) = mpsc::channel();
                let request = HubRequest::Send {
                    frame,
                    from: id,
                    reply,
                };
                if requests.send(request).is_err() {
                    return;
                }
                match response.recv() {
                    Ok(Ok(())) => "sent\n".to_string(),
                    Ok(Err(reason)) => format!("refused {}\n", one_line(&reason)),
                    Err(_) => return,
                }
            }
            Some(Err(error)) => format!("refused {error}\n"),
            None => format!("refused unknown request {line:?}\n"),
        };
        if !write_line(writer, &answer) {
            return;
        }
    }
}

impl Bus for Hub {
    fn send(&mut self, frame: &RawFrame) -> Result<()> {
        if let Some(reason) = &self.closed {
            bail!("the bus is closed: {reason}");
        }
        let (reply, response) = mpsc::channel();
        self.requests
            .send(HubRequest::Send {
                frame: *frame,
                from: OWNER,
                reply,
            })
            .map_err(|_| anyhow!("the thread serving {} has stopped", self.device.display()))?;
        match response.recv_timeout(SEND_TIMEOUT) {
            Ok(Ok(())) => Ok(()),
            Ok(Err(reason)) => Err(anyhow!(reason)),
            Err(_) => bail!("the adapter did not confirm {frame} in time"),
        }
    }

    fn receive(&mut self, timeout: Option<Duration>) -> Result<Reception> {
        let deadline = timeout.map(|timeout| Instant::now() + timeout);
        loop {
            if let Some(frame) = self.pending.pop_front() {
                return Ok(Reception::Frame(frame));
            }
            if let Some(reason) = &self.closed {
                bail!("lost the bus: {reason}");
            }
            if interrupted() {
                return Ok(Reception::Interrupted);
            }
            let slice = match deadline {
                Some(deadline) => {
                    let left = deadline.saturating_duration_since(Instant::now());
                    if left.is_zero() {
                        return Ok(Reception::TimedOut);
                    }
                    left.min(SLICE)
                }
                None => SLICE,
            };
            match self.events.recv_timeout(slice) {
                Ok(event) => self.take_event(event),
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => {
                    self.closed = Some(format!(
                        "the thread serving {} stopped",
                        self.device.display()
                    ));
                }
            }
        }
    }

    fn close(&mut self) -> Result<()> {
        self.shut_down()
    }
}

impl Drop for Hub {
    fn drop(&mut self) {
        if self.adapter_thread.is_some() {
            let _ = self.shut_down();
        }
    }
}

/// A process that uses an adapter another `amiro` owns.
pub struct RelayClient {
    stream: UnixStream,
    /// The owner, from its greeting: `amiro monitor (pid 1234)`.
    owner: String,
    /// Bytes received but not yet ending in a newline.
    partial: Vec<u8>,
    /// Lines received but not yet handled.
    lines: std::collections::VecDeque<String>,
    /// Frames that arrived while a send waited for its confirmation.
    pending: std::collections::VecDeque<LoggedFrame>,
}

/// What waiting on the hub produced.
enum Heard {
    Line(String),
    TimedOut,
    Interrupted,
}

impl RelayClient {
    /// Connects to the owner of `socket`; `None` if nobody listens there.
    fn connect(socket: &Path) -> Result<Option<Self>> {
        let stream = match UnixStream::connect(socket) {
            Ok(stream) => stream,
            Err(error)
                if matches!(
                    error.kind(),
                    ErrorKind::NotFound | ErrorKind::ConnectionRefused
                ) =>
            {
                return Ok(None)
            }
            Err(error) => {
                return Err(error)
                    .with_context(|| format!("cannot connect to {}", socket.display()))
            }
        };
        let mut client = Self {
            stream,
            owner: String::new(),
            partial: Vec::new(),
            lines: std::collections::VecDeque::new(),
            pending: std::collections::VecDeque::new(),
        };
        match client.hear(Some(Instant::now() + SEND_TIMEOUT), false)? {
            Heard::Line(line) => match line.strip_prefix(GREETING) {
                Some(owner) => client.owner = owner.trim().to_string(),
                None => bail!(
                    "{} does not speak the amiro relay protocol: {line:?}",
                    socket.display()
                ),
            },
            _ => bail!("the amiro at {} did not answer", socket.display()),
        }
        Ok(Some(client))
    }

    fn lost(&self) -> anyhow::Error {
        anyhow!(
            "lost the bus: the connection to {}, which holds the adapter, broke",
            self.owner
        )
    }

    /// The next line from the hub, until `deadline`.
    fn hear(&mut self, deadline: Option<Instant>, interruptible: bool) -> Result<Heard> {
        loop {
            if let Some(line) = self.lines.pop_front() {
                return Ok(Heard::Line(line));
            }
            if interruptible && interrupted() {
                return Ok(Heard::Interrupted);
            }
            let slice = match deadline {
                Some(deadline) => {
                    let left = deadline.saturating_duration_since(Instant::now());
                    if left.is_zero() {
                        return Ok(Heard::TimedOut);
                    }
                    left.min(SLICE)
                }
                None => SLICE,
            };
            let mut fds = [PollFd::new(self.stream.as_fd(), PollFlags::POLLIN)];
            let timeout = PollTimeout::try_from(slice + Duration::from_micros(999))
                .unwrap_or(PollTimeout::MAX);
            match poll(&mut fds, timeout) {
                Ok(0) | Err(nix::errno::Errno::EINTR) => continue,
                Ok(_) => {}
                Err(error) => return Err(error).context("waiting for the relay"),
            }
            let mut buffer = [0u8; 4096];
            let count = match self.stream.read(&mut buffer) {
                Ok(0) => return Err(self.lost()),
                Ok(count) => count,
                Err(error) if error.kind() == ErrorKind::Interrupted => continue,
                Err(_) => return Err(self.lost()),
            };
            for &byte in &buffer[..count] {
                if byte == b'\n' {
                    let line =
                        String::from_utf8_lossy(&std::mem::take(&mut self.partial)).into_owned();
                    self.lines.push_back(line);
                } else {
                    self.partial.push(byte);
                }
            }
        }
    }

    /// Handles an event line; returns it back if it is an answer to a send.
    fn event(&mut self, line: String) -> Result<Option<String>> {
        if let Some(text) = line.strip_prefix("frame ") {
            match parse_line(text) {
                Ok(Some(frame)) => self.pending.push_back(frame),
                _ => eprintln!("warning: the relay sent an unreadable frame {text:?}"),
            }
            return Ok(None);
        }
        if let Some(reason) = line.strip_prefix("closed ") {
            bail!("lost the bus: {reason}");
        }
        Ok(Some(line))
    }
}

impl Bus for RelayClient {
    fn send(&mut self, frame: &RawFrame) -> Result<()> {
        self.stream
            .write_all(format!("send {frame}\n").as_bytes())
            .map_err(|_| self.lost())?;
        let deadline = Instant::now() + SEND_TIMEOUT;
        loop {
            match self.hear(Some(deadline), false)? {
                Heard::Line(line) => match self.event(line)? {
                    Some(answer) if answer == "sent" => return Ok(()),
                    Some(answer) => match answer.strip_prefix("refused ") {
                        Some(reason) => bail!("{} refused {frame}: {reason}", self.owner),
                        None => bail!("unexpected answer from {}: {answer:?}", self.owner),
                    },
                    None => {}
                },
                Heard::TimedOut | Heard::Interrupted => {
                    bail!("{} did not confirm {frame} in time", self.owner)
                }
            }
        }
    }

    fn receive(&mut self, timeout: Option<Duration>) -> Result<Reception> {
        let deadline = timeout.map(|timeout| Instant::now() + timeout);
        loop {
            if let Some(frame) = self.pending.pop_front() {
                return Ok(Reception::Frame(frame));
            }
            match self.hear(deadline, true)? {
                Heard::Line(line) => {
                    if let Some(answer) = self.event(line)? {
                        eprintln!(
                            "warning: unexpected message from {}: {answer:?}",
                            self.owner
                        );
                    }
                }
                Heard::TimedOut => return Ok(Reception::TimedOut),
                Heard::Interrupted => return Ok(Reception::Interrupted),
            }
        }
    }
}
