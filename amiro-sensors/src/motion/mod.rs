//! The DiWheelDrive's motion: motors and encoders behind two small traits, and the pure math on
//! top — differential-drive odometry, velocity, the wheel speed PI controller and the
//! [`DriveController`] that ties them together with a dead-man stop.
//!
//! Everything here is integer arithmetic (the STM32F103 has no FPU, and integers give the same
//! result on the host and on the chip): lengths in nanometres inside, micrometres outside; angles in
//! nanoradians inside, microradians outside; time in microseconds. Frame: x forward, y to the left,
//! heading counter-clockwise seen from above, as the protocol defines it.

pub mod divide;
pub mod drive;
pub mod odometry;
pub mod speed;
pub mod trig;

pub use drive::{DriveConfig, DriveController, DriveOutput};
pub use odometry::{DeadReckoning, DriveGeometry, EncoderTracker, Pose};
pub use speed::{PiGains, WheelSpeedController};

/// A motor duty cycle with direction: ±10 000 = ±100 % (the 1.x firmware's scale), positive
/// drives the wheel forward.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
pub struct Duty(i16);

impl Duty {
    /// Full scale: 100 %.
    pub const FULL_SCALE: i16 = 10_000;
    /// Stopped (both H-bridge inputs low).
    pub const ZERO: Duty = Duty(0);
    /// Full forward.
    pub const MAX: Duty = Duty(Self::FULL_SCALE);
    /// Full reverse.
    pub const MIN: Duty = Duty(-Self::FULL_SCALE);

    /// A duty, `None` outside ±10 000.
    pub const fn new(value: i16) -> Option<Duty> {
        if value >= -Self::FULL_SCALE && value <= Self::FULL_SCALE {
            Some(Duty(value))
        } else {
            None
        }
    }

    /// A duty clamped into ±10 000.
    pub const fn saturating(value: i64) -> Duty {
        if value > Self::FULL_SCALE as i64 {
            Self::MAX
        } else if value < -(Self::FULL_SCALE as i64) {
            Self::MIN
        } else {
            Duty(value as i16)
        }
    }

    /// The value in 1/10 000 of full scale.
    pub const fn get(self) -> i16 {
        self.0
    }

    /// The timer compare value for a PWM period of `period` ticks: `|duty| × period / 10 000`.
    /// The direction is [`Duty::is_reverse`]; the DiWheelDrive's A3906 gets the PWM on one input
    /// and 0 on the other.
    pub const fn compare(self, period: u16) -> u16 {
        (self.0.unsigned_abs() as u32 * period as u32 / Self::FULL_SCALE as u32) as u16
    }

    /// Whether the wheel is driven backwards.
    pub const fn is_reverse(self) -> bool {
        self.0 < 0
    }
}

impl From<Duty> for i16 {
    fn from(duty: Duty) -> i16 {
        duty.0
    }
}

/// The two motors' PWM: the firmware implements this on the timer (or the simulated plant does).
pub trait MotorPwm {
    /// Sets both wheels' duty cycles.
    fn set_duty(&mut self, left: Duty, right: Duty);
}

/// One wheel's encoder: the timer counting quadrature edges, wrapping at 16 bits.
pub trait QuadratureCounter {
    /// The current count; differences are taken with wrapping arithmetic.
    fn count(&self) -> u16;
}
