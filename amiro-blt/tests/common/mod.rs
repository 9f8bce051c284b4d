//! Test support: the simulated robot as a [`Transport`] in virtual time, and firmware-like images.
#![allow(dead_code)]

use std::time::Duration;

use amiro_blt::target::{robot, IdSet};
use amiro_blt::{Image, Segment, Target, Transport};
use amiro_blt_sim::{BoardSpec, Faults, Flash, Robot, Timing};

/// The robot on the far side of a virtual serial line.
pub struct SimLink {
    pub robot: Robot,
    now: u64,
    byte_ns: u64,
}

impl SimLink {
    pub fn new(robot: Robot, baud: u32) -> Self {
        let byte_ns = if baud == 0 {
            0
        } else {
            10_000_000_000 / u64::from(baud)
        };
        let now = robot.now();
        SimLink {
            robot,
            now,
            byte_ns,
        }
    }
}

impl Transport for SimLink {
    fn send(&mut self, bytes: &[u8]) -> std::io::Result<()> {
        for &b in bytes {
            self.now += self.byte_ns.max(1);
            self.robot.host_byte(self.now, b);
        }
        Ok(())
    }

    fn receive(&mut self, buf: &mut [u8], timeout: Duration) -> std::io::Result<usize> {
        let deadline = self.now + timeout.as_nanos() as u64;
        match self.robot.next_output_at() {
            Some(t) if t <= deadline => {
                self.now = self.now.max(t);
                let mut n = 0;
                while n < buf.len() {
                    match self.robot.take_output(self.now) {
                        Some(b) => {
                            buf[n] = b;
                            n += 1;
                        }
                        None => break,
                    }
                }
                Ok(n)
            }
            _ => {
                self.now = deadline;
                self.robot.advance(self.now);
                Ok(0)
            }
        }
    }

    fn clock(&self) -> Duration {
        Duration::from_nanos(self.now)
    }

    fn pause(&mut self, duration: Duration) {
        self.now += duration.as_nanos() as u64;
        self.robot.advance(self.now);
    }

    fn pulse_reset(&mut self) -> std::io::Result<bool> {
        Ok(self.robot.rts_pulse())
    }
}

/// A firmware-like image for a target: vector table, the reserved checksum word, code after a
/// gap, and a `.data` image behind it.
pub fn firmware(target: &Target, code_len: usize, seed: u32) -> Image {
    let origin = target.app_origin;
    let sp: u32 = match target.name.as_str() {
        "powermgmt" => 0x2002_0000,
        _ => 0x2001_0000,
    };
    let mut vectors = sp.to_le_bytes().to_vec();
    for i in 0..40u32 {
        vectors.extend_from_slice(&(origin + 0x201 + 8 * i).to_le_bytes());
    }
    let mut x = seed | 1;
    let mut code = Vec::with_capacity(code_len);
    for _ in 0..code_len {
        x ^= x << 13;
        x ^= x >> 17;
        x ^= x << 5;
        code.push(x as u8);
    }
    let code_at = origin + 0x200;
    let data_at = code_at + code_len as u32;
    Image::new(vec![
        Segment {
            address: origin,
            data: vectors,
        },
        Segment {
            address: origin + target.checksum_offset,
            data: vec![0xFF; 4],
        },
        Segment {
            address: code_at,
            data: code,
        },
        Segment {
            address: data_at,
            data: (0..77u8).collect(),
        },
    ])
    .expect("image")
}

pub fn targets() -> [Target; 3] {
    robot(IdSet::Rev12)
}

pub fn sim_robot(faults: Faults) -> Robot {
    Robot::new(BoardSpec::robot_1_2(), Timing::robot(), faults)
}

/// The flash contents the image must leave, with the checksum computed here (not by the host
/// library): the first seven vector words plus the slot sum to zero.
pub fn expected_bytes(target: &Target, image: &Image) -> Vec<(u32, u8)> {
    let word = |a: u32| {
        u32::from_le_bytes([
            image.byte_at(a).unwrap(),
            image.byte_at(a + 1).unwrap(),
            image.byte_at(a + 2).unwrap(),
            image.byte_at(a + 3).unwrap(),
        ])
    };
    let sum = (0..7).fold(0u32, |s, i| s.wrapping_add(word(target.app_origin + 4 * i)));
    let slot = target.app_origin + target.checksum_offset;
    let checksum = 0u32.wrapping_sub(sum).to_le_bytes();
    let mut bytes = Vec::new();
    for s in image.segments() {
        for (i, &b) in s.data.iter().enumerate() {
            let a = s.address + i as u32;
            let b = if (slot..slot + 4).contains(&a) {
                checksum[(a - slot) as usize]
            } else {
                b
            };
            bytes.push((a, b));
        }
    }
    bytes
}

/// Whether the board's flash holds exactly the image (checksum included).
pub fn holds(flash: &Flash, target: &Target, image: &Image) -> bool {
    expected_bytes(target, image)
        .iter()
        .all(|&(a, b)| flash.read(a, 1)[0] == b)
}

/// The invariant of every fault test: a board is either complete and valid, or it does not
/// pass the bootloader's checksum (it stays in its bootloader).
pub fn never_half_written(flash: &Flash, target: &Target, image: &Image) -> bool {
    holds(flash, target, image) || !flash.app_valid()
}
