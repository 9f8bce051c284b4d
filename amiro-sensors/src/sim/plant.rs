//! Simulated motors, gears and encoders: duty in, wheel speed and 16-bit encoder counts out.
//!
//! Each wheel is a first-order system: with motor power on, the speed heads for
//! `speed_at_full_duty × (|duty| − deadband) / (10 000 − deadband)` (zero inside the deadband, the
//! static friction a small DC motor has) with time constant `time_constant_us`; with power off the
//! target is zero (the wheel coasts down). Travel accumulates in picometres and is counted in
//! encoder ticks of the geometry's size. Time only moves when the caller says so
//! ([`WheelPlant::advance_to`]), in 1 ms sub-steps, so a run is the same on every machine.

use crate::motion::{DriveGeometry, Duty, MotorPwm, QuadratureCounter};

/// Integration sub-step, µs.
const SUB_STEP_US: u64 = 1_000;

/// One motor's behaviour.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MotorModel {
    /// Steady wheel speed at 100 % duty, µm/s.
    pub speed_at_full_duty_um_s: i32,
    /// Mechanical time constant, µs.
    pub time_constant_us: u32,
    /// Duty below which the wheel does not turn (1/10 000).
    pub deadband: i16,
}

impl MotorModel {
    /// A plausible AMiRo drive (the real motor's constants are unknown): 0.6 m/s at full duty,
    /// 50 ms time constant, 3 % deadband.
    pub const AMIRO: MotorModel = MotorModel {
        speed_at_full_duty_um_s: 600_000,
        time_constant_us: 50_000,
        deadband: 300,
    };

    /// Steady speed for a duty, nm/s.
    const fn steady_speed_nm_s(&self, duty: i16) -> i64 {
        let magnitude = duty.unsigned_abs() as i64;
        let deadband = self.deadband.unsigned_abs() as i64;
        let span = Duty::FULL_SCALE as i64 - deadband;
        if magnitude <= deadband || span <= 0 {
            return 0;
        }
        let speed = self.speed_at_full_duty_um_s as i64 * 1000 * (magnitude - deadband) / span;
        if duty < 0 {
            -speed
        } else {
            speed
        }
    }
}

impl Default for MotorModel {
    fn default() -> Self {
        Self::AMIRO
    }
}

/// One simulated wheel with its encoder.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SimWheel {
    model: MotorModel,
    duty: i16,
    speed_nm_s: i64,
    travel_pm: i64,
    pm_per_tick: i64,
}

impl SimWheel {
    const fn new(model: MotorModel, pm_per_tick: i64) -> Self {
        Self {
            model,
            duty: 0,
            speed_nm_s: 0,
            travel_pm: 0,
            pm_per_tick,
        }
    }

    /// Current speed in µm/s.
    pub const fn speed_um_s(&self) -> i64 {
        self.speed_nm_s / 1000
    }

    /// Distance travelled in µm.
    pub const fn travel_um(&self) -> i64 {
        self.travel_pm / 1_000_000
    }

    /// The duty last applied.
    pub const fn duty(&self) -> i16 {
        self.duty
    }

    /// Whole ticks travelled (signed, not wrapped).
    pub const fn ticks(&self) -> i64 {
        if self.pm_per_tick == 0 {
            0
        } else {
            self.travel_pm.div_euclid(self.pm_per_tick)
        }
    }

    fn step(&mut self, powered: bool, dt_us: u64) {
        let target = if powered {
            self.model.steady_speed_nm_s(self.duty)
        } else {
            0
        };
        let tau = u64::from(self.model.time_constant_us.max(1));
        // Explicit Euler on the first-order lag; dt ≤ 1 ms ≪ τ keeps it stable.
        let dt = dt_us.min(tau) as i64;
        self.speed_nm_s += (target - self.speed_nm_s) * dt / tau as i64;
        // nm/s × µs = 1e-15 m = 1e-3 pm.
        self.travel_pm += self.speed_nm_s * dt_us as i64 / 1000;
    }
}

impl QuadratureCounter for SimWheel {
    fn count(&self) -> u16 {
        // The timer counter wraps at 16 bits; two's-complement truncation is that wrap.
        self.ticks() as u16
    }
}

/// The DiWheelDrive's two motors and encoders.
#[derive(Debug, Clone)]
pub struct WheelPlant {
    /// Left wheel.
    pub left: SimWheel,
    /// Right wheel.
    pub right: SimWheel,
    powered: bool,
    time_us: Option<u64>,
}

impl WheelPlant {
    /// The AMiRo's geometry with [`MotorModel::AMIRO`] on both sides, at rest, power off.
    pub const fn new() -> Self {
        Self::with(DriveGeometry::AMIRO, MotorModel::AMIRO, MotorModel::AMIRO)
    }

    /// A plant with its own geometry and a model per motor (e.g. a weaker right motor).
    pub const fn with(geometry: DriveGeometry, left: MotorModel, right: MotorModel) -> Self {
        let pm = geometry.pm_per_tick();
        Self {
            left: SimWheel::new(left, pm),
            right: SimWheel::new(right, pm),
            powered: false,
            time_us: None,
        }
    }

    /// Switches motor power (POWER_EN).
    pub fn set_power(&mut self, on: bool) {
        self.powered = on;
    }

    /// Whether motor power is on.
    pub const fn is_powered(&self) -> bool {
        self.powered
    }

    /// Runs the plant up to `now_us` (the first call only sets the clock).
    pub fn advance_to(&mut self, now_us: u64) {
        let Some(mut t) = self.time_us else {
            self.time_us = Some(now_us);
            return;
        };
        while t < now_us {
            let dt = (now_us - t).min(SUB_STEP_US);
            self.left.step(self.powered, dt);
            self.right.step(self.powered, dt);
            t += dt;
        }
        self.time_us = Some(t);
    }

    /// Advances to `now_us` and returns the encoder counts (left, right).
    pub fn counts(&mut self, now_us: u64) -> (u16, u16) {
        self.advance_to(now_us);
        (self.left.count(), self.right.count())
    }
}

impl Default for WheelPlant {
    fn default() -> Self {
        Self::new()
    }
}

impl MotorPwm for WheelPlant {
    fn set_duty(&mut self, left: Duty, right: Duty) {
        self.left.duty = left.get();
        self.right.duty = right.get();
    }
}
