//! The world's two messages on the robot link (docs/world.md, "How the readings reach the
//! boards"): what the DiWheelDrive reports of its wheels ([`Wheels`]) and what the host answers
//! with the sensors' readings from the world ([`Readings`]). Fixed sizes, one encoder and one
//! decoder each, beside [`crate::robot_link`]'s exchange messages; the exchange carries them
//! only in a run with a world.

/// Board → host, [`Wheels`]: `u64` board time, `i64` left ticks, `i64` right ticks.
pub const WHEELS_LEN: usize = 24;
/// Host → board, [`Readings`]: `u64` time, `u8` groups, 3 reserved, eight `u16` ring counts,
/// four `u16` floor counts, nine `i32` IMU values (rate, acceleration, field; x y z each).
pub const READINGS_LEN: usize = 72;

/// [`Readings::groups`]: the ring counts are valid (PowerManagement).
pub const RING: u8 = 1;
/// The floor counts are valid (DiWheelDrive).
pub const FLOOR: u8 = 2;
/// The IMU values are revision 1-1's: rate in mdps (L3G4200D), acceleration in µg (LIS331DLH),
/// field in nT (HMC5883L).
pub const IMU_1_1: u8 = 4;
/// The IMU values are revision 1-2's: rate in 1/16 °/s, acceleration in mg, field in nT (BNO055).
pub const IMU_1_2: u8 = 8;

/// The DiWheelDrive plant's wheels: whole encoder ticks since boot, signed and not wrapped
/// (`amiro_sensors::sim::SimWheel::ticks`), at the board's virtual time.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Wheels {
    /// The board's virtual time, µs.
    pub now_us: u64,
    /// Left wheel, ticks.
    pub left_ticks: i64,
    /// Right wheel, ticks.
    pub right_ticks: i64,
}

impl Wheels {
    /// The message's bytes.
    pub fn encode(&self) -> [u8; WHEELS_LEN] {
        let mut m = [0u8; WHEELS_LEN];
        m[..8].copy_from_slice(&self.now_us.to_le_bytes());
        m[8..16].copy_from_slice(&self.left_ticks.to_le_bytes());
        m[16..24].copy_from_slice(&self.right_ticks.to_le_bytes());
        m
    }

    /// The message in `m`.
    pub fn decode(m: &[u8; WHEELS_LEN]) -> Wheels {
        Wheels {
            now_us: u64::from_le_bytes(eight(&m[..8])),
            left_ticks: i64::from_le_bytes(eight(&m[8..16])),
            right_ticks: i64::from_le_bytes(eight(&m[16..24])),
        }
    }
}

/// The sensors' readings from the world, valid from `at_us` until the next ones. Each board
/// takes the groups it has ([`Readings::groups`]) and hands them to its simulators' setters.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Readings {
    /// The board's virtual time the readings hold from, µs.
    pub at_us: u64,
    /// Which groups are valid: [`RING`], [`FLOOR`], [`IMU_1_1`] or [`IMU_1_2`].
    pub groups: u8,
    /// The ring's VCNL4020 counts by the protocol's sensor index.
    pub ring: [u16; 8],
    /// The floor VCNL4020 counts in the protocol's order (front-right, right-wheel, left-wheel,
    /// front-left).
    pub floor: [u16; 4],
    /// Angular rate x y z (units by the IMU group).
    pub rate: [i32; 3],
    /// Acceleration including gravity x y z (units by the IMU group).
    pub accel: [i32; 3],
    /// Magnetic field x y z, nT.
    pub field_nt: [i32; 3],
}

impl Readings {
    /// Whether `group` is valid.
    pub const fn has(&self, group: u8) -> bool {
        self.groups & group != 0
    }

    /// The message's bytes.
    pub fn encode(&self) -> [u8; READINGS_LEN] {
        let mut m = [0u8; READINGS_LEN];
        m[..8].copy_from_slice(&self.at_us.to_le_bytes());
        m[8] = self.groups;
        for (k, v) in self.ring.iter().enumerate() {
            m[12 + 2 * k..14 + 2 * k].copy_from_slice(&v.to_le_bytes());
        }
        for (k, v) in self.floor.iter().enumerate() {
            m[28 + 2 * k..30 + 2 * k].copy_from_slice(&v.to_le_bytes());
        }
        let imu = self.rate.iter().chain(&self.accel).chain(&self.field_nt);
        for (k, v) in imu.enumerate() {
            m[36 + 4 * k..40 + 4 * k].copy_from_slice(&v.to_le_bytes());
        }
        m
    }

    /// The message in `m` (group bits the format does not define are dropped).
    pub fn decode(m: &[u8; READINGS_LEN]) -> Readings {
        let u16_at = |at: usize| u16::from_le_bytes([m[at], m[at + 1]]);
        let i32_at = |at: usize| i32::from_le_bytes([m[at], m[at + 1], m[at + 2], m[at + 3]]);
        let mut r = Readings {
            at_us: u64::from_le_bytes(eight(&m[..8])),
            groups: m[8] & (RING | FLOOR | IMU_1_1 | IMU_1_2),
            ..Readings::default()
        };
        for (k, v) in r.ring.iter_mut().enumerate() {
            *v = u16_at(12 + 2 * k);
        }
        for (k, v) in r.floor.iter_mut().enumerate() {
            *v = u16_at(28 + 2 * k);
        }
        for axis in 0..3 {
            r.rate[axis] = i32_at(36 + 4 * axis);
            r.accel[axis] = i32_at(48 + 4 * axis);
            r.field_nt[axis] = i32_at(60 + 4 * axis);
        }
        r
    }
}

fn eight(bytes: &[u8]) -> [u8; 8] {
    let mut b = [0u8; 8];
    b.copy_from_slice(&bytes[..8]);
    b
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_wheels_survive_the_link() {
        let w = Wheels {
            now_us: 12_345_678,
            left_ticks: -1_408,
            right_ticks: i64::MAX,
        };
        let bytes = w.encode();
        assert_eq!(Wheels::decode(&bytes), w);
        assert_eq!(&bytes[8..10], &[0x80, 0xFA], "−1408, little-endian");
    }

    #[test]
    fn the_readings_survive_the_link() {
        let r = Readings {
            at_us: 60_000_000,
            groups: RING | FLOOR | IMU_1_1,
            ring: [2000, 2001, 2400, 12_000, 65_535, 0, 7, 8],
            floor: [5_867, 37_643, 37_000, 6_000],
            rate: [0, -1_000, 180_000],
            accel: [200_000, 0, 1_000_000],
            field_nt: [0, 19_146, -45_105],
        };
        let bytes = r.encode();
        assert_eq!(Readings::decode(&bytes), r);
        assert!(r.has(FLOOR) && !r.has(IMU_1_2));
        // The layout a board reads: groups, then the ring from byte 12, the floor from 28, the
        // IMU from 36.
        assert_eq!(bytes[8], 7);
        assert_eq!(&bytes[12..14], &2000u16.to_le_bytes());
        assert_eq!(&bytes[28..30], &5_867u16.to_le_bytes());
        assert_eq!(&bytes[44..48], &180_000i32.to_le_bytes());
        assert_eq!(&bytes[68..72], &(-45_105i32).to_le_bytes());
    }

    #[test]
    fn garbage_decodes_to_defined_groups_only() {
        let r = Readings::decode(&[0xFF; READINGS_LEN]);
        assert_eq!(r.groups, RING | FLOOR | IMU_1_1 | IMU_1_2);
        assert_eq!(r.ring, [u16::MAX; 8]);
        assert_eq!(r.field_nt, [-1; 3]);
        assert_eq!(Wheels::decode(&[0; WHEELS_LEN]), Wheels::default());
    }
}
