//! The long fuzz run: well over a million deterministic pseudo-random and structured-edge frames through the decoder.
//!
//! Ignored by default (it takes a few seconds in release); run it with
//! `cargo test -p amiro-can --release -- --ignored fuzz_million --nocapture`. Set `AMIRO_FUZZ_CASES` to change
//! the number of random cases (default 10 000 000) and `AMIRO_FUZZ_SEED` to change the seed.

use amiro_can::{
    decode, decode_command, CanId, DecodeError, Kind, Message, Priority, Topic, TOPICS,
};

/// SplitMix64: tiny, deterministic, good enough to spread inputs; no dependency, so runs are reproducible forever.
struct SplitMix64(u64);

impl SplitMix64 {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }

    fn pick<T: Copy>(&mut self, items: &[T]) -> T {
        items[self.below(items.len() as u64) as usize]
    }
}

/// Counts what the decoder said, and checks the invariants that must hold for every input.
#[derive(Default)]
struct Tally {
    inputs: u64,
    accepted: u64,
    rejected: [u64; DecodeError::KINDS.len()],
}

impl Tally {
    fn check(&mut self, id: u16, data: &[u8]) {
        self.inputs += 1;
        let result = decode(id, data);
        let command = decode_command(id, data);
        match result {
            Ok(message) => {
                self.accepted += 1;
                let frame = message.encode();
                assert_eq!(
                    frame.decode(),
                    Ok(message),
                    "{id:03X}#{data:02X?} does not survive re-encoding"
                );
                assert_eq!(frame.id().raw(), id);
                match message {
                    Message::Command(c) => assert_eq!(command, Ok(c)),
                    Message::Sample { .. } => {
                        assert!(matches!(command, Err(DecodeError::ExpectedCommand { .. })))
                    }
                }
            }
            Err(e) => {
                self.rejected[e.kind_index()] += 1;
                assert!(command.is_err());
            }
        }
    }
}

fn env_u64(name: &str, default: u64) -> u64 {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

/// Byte values at the edges of every field: mode and unit limits, sign bits, index and percentage limits.
const EDGE_BYTES: [u8; 14] = [
    0x00, 0x01, 0x02, 0x03, 0x07, 0x08, 0x32, 0x64, 0x65, 0x7F, 0x80, 0xC7, 0xFE, 0xFF,
];

fn edge_ids() -> Vec<u16> {
    let mut ids = vec![0x000, 0x7FF, 0x800, 0x801, 0xFFFF, 0x3FF, 0x400];
    for info in TOPICS {
        for kind in [Kind::Command, Kind::Sensor] {
            for priority in Priority::ALL {
                ids.push(CanId::new(kind, priority, info.topic.byte()).raw());
            }
        }
    }
    // Topic bytes next to known ones.
    for byte in [0x00u8, 0x03, 0x0A, 0x0F, 0x19, 0x1D, 0x20, 0xFF] {
        ids.push(CanId::new(Kind::Command, Priority::Medium, byte).raw());
        ids.push(CanId::new(Kind::Sensor, Priority::Medium, byte).raw());
    }
    ids
}

#[test]
#[ignore = "long run: cargo test -p amiro-can --release -- --ignored"]
fn fuzz_million() {
    let cases = env_u64("AMIRO_FUZZ_CASES", 10_000_000);
    let mut rng = SplitMix64(env_u64("AMIRO_FUZZ_SEED", 0x0A31_B020_2026));
    let mut tally = Tally::default();
    let ids = edge_ids();

    // 1. Exhaustive: every 16-bit identifier below 0x1000 (all 11-bit ones and the next 2048) with no data and
    //    with every single byte: every mode byte on every topic, every priority, both kinds.
    for id in 0..0x1000u16 {
        tally.check(id, &[]);
        for byte in 0..=255u8 {
            tally.check(id, &[byte]);
        }
    }
    let exhaustive = tally.inputs;

    // 2. Random and structured cases.
    for _ in 0..cases {
        let mut data = [0u8; 12];
        let (id, len) = match rng.below(4) {
            // Anything at all, including > 8 bytes and ids beyond 11 bits.
            0 => {
                for b in &mut data {
                    *b = rng.next() as u8;
                }
                (rng.next() as u16, rng.below(13) as usize)
            }
            // A known topic with its own DLC ± 1 and edge bytes.
            1 => {
                let id = rng.pick(&ids);
                let dlc = Topic::from_byte(id as u8).map_or(4, |t| t.info().dlc) as i64;
                let len = (dlc + rng.below(3) as i64 - 1).clamp(0, 9) as usize;
                for b in &mut data {
                    *b = rng.pick(&EDGE_BYTES);
                }
                (id, len)
            }
            // A sensor command shape: mode 0..=3, sample time, unit 0..=3, any length 0..=9.
            2 => {
                let topic = rng.pick(&Topic::ALL);
                let priority = rng.pick(&Priority::ALL);
                data[0] = rng.below(4) as u8;
                let value = if rng.below(4) == 0 {
                    rng.pick(&[0u16, 1, 4294, 4295, u16::MAX])
                } else {
                    rng.next() as u16
                };
                data[1..3].copy_from_slice(&value.to_le_bytes());
                data[3] = rng.below(4) as u8;
                (
                    CanId::new(Kind::Command, priority, topic.byte()).raw(),
                    rng.below(10) as usize,
                )
            }
            // A random valid-length frame on a known topic, random bytes.
            _ => {
                let id = rng.pick(&ids);
                let len = Topic::from_byte(id as u8).map_or(8, |t| t.info().dlc) as usize;
                for b in &mut data {
                    *b = rng.next() as u8;
                }
                (id, len)
            }
        };
        tally.check(id, &data[..len]);
    }

    println!(
        "fuzz_million: {} inputs decoded without a panic ({} exhaustive, {} random/structured), {} accepted",
        tally.inputs,
        exhaustive,
        tally.inputs - exhaustive,
        tally.accepted
    );
    for (name, count) in DecodeError::KINDS.iter().zip(tally.rejected) {
        if count > 0 {
            println!("  rejected {name}: {count}");
        }
    }
    assert!(
        tally.inputs >= 1_000_000,
        "a fuzz run must cover at least a million inputs"
    );
    // Every reason the decoder itself can give was reached.
    for reason in [
        "id-out-of-range",
        "frame-too-long",
        "unknown-topic",
        "sensor-data-on-actuator",
        "dlc-too-short",
        "dlc-too-long",
        "bad-mode",
        "bad-unit",
        "zero-sample-time",
        "period-too-long",
        "sensor-index-out-of-range",
        "bad-charging-flag",
        "state-of-charge-out-of-range",
    ] {
        let i = DecodeError::KINDS
            .iter()
            .position(|k| *k == reason)
            .unwrap();
        assert!(tally.rejected[i] > 0, "the fuzz run never reached {reason}");
    }
}
