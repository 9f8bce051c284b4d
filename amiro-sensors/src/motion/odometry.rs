//! Differential-drive odometry: encoder ticks to wheel travel, and wheel travel to the robot's pose.
//!
//! Geometry (amiro-boards.md §4b): 1408 ticks per wheel revolution (16-line encoder, both edges of
//! both channels, 22:1 gear), wheel diameter 55.71 mm. The axle width is where the sources
//! disagree: the 1.x firmware used 69 mm and scaled it by a calibration factor, the 2.x firmware
//! derives 2 × (34 + 9/2) = 77 mm from the mechanics (wheel centre to tread centre). This crate
//! defaults to **77 mm**, the geometric value with a stated derivation; it is a field of
//! [`DriveGeometry`] so a calibrated value (e.g. from a UMBmark run) replaces it.
//!
//! Integration is the midpoint rule: with travel `dl`, `dr`, the robot moves `d = (dl + dr) / 2`
//! along the heading halfway through the turn `dθ = (dr - dl) / axle`. Position is kept in
//! nanometres and heading in nanoradians so rounding does not accumulate into anything visible.

use core::num::NonZeroU64;

use super::divide::{div_u64, Divisor};
use super::trig::{sin_cos, wrap_turn};

/// π × 10⁹, for the wheel circumference.
const PI_NANO: u64 = 3_141_592_654;
/// The divisor from pm to nm and from nm to µm.
const THOUSAND: Divisor = Divisor::constant(1000);
/// µrad/s × µm to µm/s of half the wheel speed difference.
const TWO_MILLION: Divisor = Divisor::constant(2_000_000);

/// The drive's mechanical constants.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DriveGeometry {
    /// Encoder ticks per wheel revolution (all four quadrature edges, after the gear).
    pub ticks_per_revolution: u32,
    /// Wheel diameter in µm.
    pub wheel_diameter_um: u32,
    /// Distance between the wheels' contact points in µm.
    pub axle_width_um: u32,
}

impl DriveGeometry {
    /// The AMiRo's values: 1408 ticks, 55.71 mm wheels, 77 mm axle (see the module documentation).
    pub const AMIRO: DriveGeometry = DriveGeometry {
        ticks_per_revolution: 1408,
        wheel_diameter_um: 55_710,
        axle_width_um: 77_000,
    };

    /// The 1.x firmware's uncalibrated axle width, 69 mm.
    pub const AXLE_WIDTH_1X_UM: u32 = 69_000;

    /// Wheel travel per tick in picometres (124 302 647 pm for the AMiRo). Zero ticks per
    /// revolution gives 0 (no motion is ever measured) rather than a division fault.
    pub const fn pm_per_tick(&self) -> i64 {
        // π × 10⁹ × d [µm] is the circumference in fm (at most 1.35e19: fits a u64); shared out
        // over the ticks and divided by 1000 for pm. 64-bit only, so the chip needs no 128-bit
        // division routine.
        let circumference_fm = PI_NANO * self.wheel_diameter_um as u64;
        match NonZeroU64::new(self.ticks_per_revolution as u64 * 1000) {
            Some(denominator) => {
                div_u64(circumference_fm + denominator.get() / 2, denominator) as i64
            }
            None => 0,
        }
    }

    /// Wheel travel for `ticks` in nanometres (saturating far beyond any real travel).
    pub const fn ticks_to_nm(&self, ticks: i64) -> i64 {
        nm_from_pm(ticks.saturating_mul(self.pm_per_tick()))
    }

    /// Wheel speeds (left, right) in µm/s for a body velocity: `v ∓ ω · axle / 2`.
    pub const fn wheel_speeds_um_s(&self, velocity_um_s: i32, angular_urad_s: i32) -> (i64, i64) {
        // µrad/s × µm = 1e-12 m·rad/s; / 2 / 1e6 gives µm/s.
        let half_difference =
            TWO_MILLION.div_i64(angular_urad_s as i64 * self.axle_width_um as i64);
        (
            velocity_um_s as i64 - half_difference,
            velocity_um_s as i64 + half_difference,
        )
    }
}

impl Default for DriveGeometry {
    fn default() -> Self {
        Self::AMIRO
    }
}

/// Turns a wrapping 16-bit encoder count into tick differences.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct EncoderTracker {
    last: Option<u16>,
    inverted: bool,
}

impl EncoderTracker {
    /// A tracker; `inverted` when the count falls as the wheel drives forward.
    pub const fn new(inverted: bool) -> Self {
        Self {
            last: None,
            inverted,
        }
    }

    /// Ticks forward since the previous call (0 on the first). Correct as long as the wheel turns
    /// less than 32 767 ticks (23 revolutions) between calls.
    pub fn delta(&mut self, count: u16) -> i32 {
        let delta = match self.last {
            Some(last) => i32::from(count.wrapping_sub(last) as i16),
            None => 0,
        };
        self.last = Some(count);
        if self.inverted {
            -delta
        } else {
            delta
        }
    }

    /// Forgets the previous count (the next [`delta`](Self::delta) is 0).
    pub fn reset(&mut self) {
        self.last = None;
    }
}

/// The robot's pose in protocol units.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Pose {
    /// x in µm (forward at start).
    pub x_um: i64,
    /// y in µm (left at start).
    pub y_um: i64,
    /// Heading in µrad, 0..2π, counter-clockwise.
    pub heading_urad: i64,
}

/// One odometry step's motion of the robot.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Step {
    /// Left wheel travel in nm.
    pub left_nm: i64,
    /// Right wheel travel in nm.
    pub right_nm: i64,
    /// Forward travel of the robot's centre in nm.
    pub distance_nm: i64,
    /// Rotation in nrad (counter-clockwise positive).
    pub rotation_nrad: i64,
}

/// Pose integration from wheel ticks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DeadReckoning {
    geometry: DriveGeometry,
    /// The geometry's [`DriveGeometry::pm_per_tick`], computed once.
    pm_per_tick: i64,
    /// The axle width (µm) as a divisor; `None` for a zero width (no rotation is measured).
    axle_um: Option<Divisor>,
    x_nm: i64,
    y_nm: i64,
    heading_nrad: i64,
}

impl DeadReckoning {
    /// At the origin, heading 0.
    pub const fn new(geometry: DriveGeometry) -> Self {
        Self {
            geometry,
            pm_per_tick: geometry.pm_per_tick(),
            axle_um: match NonZeroU64::new(geometry.axle_width_um as u64) {
                Some(axle_um) => Some(Divisor::new(axle_um)),
                None => None,
            },
            x_nm: 0,
            y_nm: 0,
            heading_nrad: 0,
        }
    }

    /// The geometry in use.
    pub const fn geometry(&self) -> &DriveGeometry {
        &self.geometry
    }

    /// The wheel and body motion for tick differences, without moving the pose.
    pub const fn step(&self, left_ticks: i32, right_ticks: i32) -> Step {
        // As DriveGeometry::ticks_to_nm, with the travel per tick computed once.
        let left_nm = nm_from_pm((left_ticks as i64).saturating_mul(self.pm_per_tick));
        let right_nm = nm_from_pm((right_ticks as i64).saturating_mul(self.pm_per_tick));
        let distance_nm = half(left_nm + right_nm);
        let rotation_nrad = match &self.axle_um {
            // nm / µm = 1e-3 rad; × 1e6 gives nrad (saturating only for absurd tick counts).
            Some(axle_um) => axle_um.div_i64((right_nm - left_nm).saturating_mul(1_000_000)),
            None => 0,
        };
        Step {
            left_nm,
            right_nm,
            distance_nm,
            rotation_nrad,
        }
    }

    /// Moves the pose by one step of tick differences and returns the step.
    pub fn advance(&mut self, left_ticks: i32, right_ticks: i32) -> Step {
        let step = self.step(left_ticks, right_ticks);
        let (sin, cos) = sin_cos(self.heading_nrad + half(step.rotation_nrad));
        self.x_nm += scale(step.distance_nm, cos);
        self.y_nm += scale(step.distance_nm, sin);
        self.heading_nrad = wrap_turn(self.heading_nrad + step.rotation_nrad);
        step
    }

    /// The pose in µm and µrad (rounded).
    pub const fn pose(&self) -> Pose {
        Pose {
            x_um: round_thousandth(self.x_nm),
            y_um: round_thousandth(self.y_nm),
            heading_urad: round_thousandth(self.heading_nrad),
        }
    }

    /// Heading in nrad, 0..2π.
    pub const fn heading_nrad(&self) -> i64 {
        self.heading_nrad
    }

    /// Position in nm.
    pub const fn position_nm(&self) -> (i64, i64) {
        (self.x_nm, self.y_nm)
    }

    /// Replaces the pose (e.g. from a localisation fix).
    pub fn set_pose(&mut self, pose: Pose) {
        self.x_nm = pose.x_um.saturating_mul(1000);
        self.y_nm = pose.y_um.saturating_mul(1000);
        self.heading_nrad = wrap_turn(pose.heading_urad.saturating_mul(1000));
    }
}

/// `value × fraction / 2^30`, rounded, for a fraction from [`sin_cos`].
fn scale(value: i64, fraction: i64) -> i64 {
    let product = i128::from(value) * i128::from(fraction);
    ((product + (1 << 29)) >> 30) as i64
}

/// `value / 2` (rounding towards zero) by a shift: the size-optimised build calls
/// `__aeabi_ldivmod` for an `i64` divided by 2.
const fn half(value: i64) -> i64 {
    // A negative value gets its odd bit added first, so the flooring shift rounds towards zero.
    (value + ((value >> 63) & 1)) >> 1
}

/// Picometres to nanometres, rounded half away from zero (saturating at the ends).
const fn nm_from_pm(pm: i64) -> i64 {
    if pm >= 0 {
        THOUSAND.div_i64(pm.saturating_add(500))
    } else {
        THOUSAND.div_i64(pm.saturating_sub(500))
    }
}

const fn round_thousandth(value: i64) -> i64 {
    if value >= 0 {
        THOUSAND.div_i64(value + 500)
    } else {
        THOUSAND.div_i64(value - 500)
    }
}
