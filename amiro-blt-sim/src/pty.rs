//! Serves a [`Robot`] on a pseudo-terminal in real time: a serial-port client opens the slave
//! side as if it were the robot's USB cable.
use std::fs::File;
use std::io::{Read, Write};
use std::os::fd::{AsFd, AsRawFd, OwnedFd};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Instant;

use nix::poll::{poll, PollFd, PollFlags, PollTimeout};
use nix::pty::openpty;
use nix::sys::termios::{cfmakeraw, tcgetattr, tcsetattr, SetArg};

use crate::robot::Robot;

/// A robot behind a pty, running on its own thread.
pub struct PtyRobot {
    path: PathBuf,
    stop: Arc<AtomicBool>,
    thread: JoinHandle<Robot>,
}

impl PtyRobot {
    /// Opens a pty and starts serving `robot` on it; the robot's clock starts now.
    pub fn serve(robot: Robot) -> std::io::Result<PtyRobot> {
        let pty = openpty(None, None).map_err(std::io::Error::from)?;
        let mut attrs = tcgetattr(&pty.slave).map_err(std::io::Error::from)?;
        cfmakeraw(&mut attrs);
        tcsetattr(&pty.slave, SetArg::TCSANOW, &attrs).map_err(std::io::Error::from)?;
        let path = std::fs::read_link(format!("/proc/self/fd/{}", pty.slave.as_raw_fd()))?;
        let stop = Arc::new(AtomicBool::new(false));
        let flag = stop.clone();
        let master = File::from(pty.master);
        let slave = pty.slave;
        let thread = std::thread::spawn(move || run(robot, master, slave, &flag));
        Ok(PtyRobot { path, stop, thread })
    }

    /// The device path a client opens.
    pub fn path(&self) -> &PathBuf {
        &self.path
    }

    /// Stops serving and hands the robot back for inspection.
    pub fn stop(self) -> Robot {
        self.stop.store(true, Ordering::Relaxed);
        self.thread.join().expect("pty robot thread panicked")
    }
}

fn run(mut robot: Robot, mut master: File, _slave: OwnedFd, stop: &AtomicBool) -> Robot {
    let epoch = Instant::now();
    let base = robot.now();
    let mut buf = [0u8; 1024];
    while !stop.load(Ordering::Relaxed) {
        let now = base + epoch.elapsed().as_nanos() as u64;
        robot.advance(now);
        let mut out = Vec::new();
        while let Some(b) = robot.take_output(now) {
            out.push(b);
        }
        if !out.is_empty() && master.write_all(&out).is_err() {
            break;
        }
        let wait_ms: u8 = match robot.next_output_at() {
            Some(t) if t <= now => 0,
            Some(t) => ((t - now) / 1_000_000).clamp(1, 5) as u8,
            None => 5,
        };
        let mut fds = [PollFd::new(master.as_fd(), PollFlags::POLLIN)];
        match poll(&mut fds, PollTimeout::from(wait_ms)) {
            Ok(n) if n > 0 => {
                let readable = fds[0]
                    .revents()
                    .is_some_and(|r| r.contains(PollFlags::POLLIN));
                if !readable {
                    std::thread::sleep(std::time::Duration::from_millis(1));
                    continue;
                }
                match master.read(&mut buf) {
                    Ok(0) | Err(_) => std::thread::sleep(std::time::Duration::from_millis(1)),
                    Ok(n) => {
                        let now = base + epoch.elapsed().as_nanos() as u64;
                        for &b in &buf[..n] {
                            robot.host_byte(now, b);
                        }
                    }
                }
            }
            _ => {}
        }
    }
    robot
}
