//! One wheel's speed controller: feed-forward plus PI, with output limits and anti-windup.
//!
//! `duty = kff·target + kp·error + ki·∫error dt`, clamped to ±`max_duty`. Anti-windup clamps the
//! integrator: it integrates only until the output reaches its limit, never past it, moves freely
//! in the direction that leaves saturation, and the integral term alone is bounded by the limit.
//!
//! The wheel speed limit is a limit ([`WheelSpeedController::update_limited`]): the target is
//! clamped to a ceiling 2 % below it, and near the ceiling a speed governor works on the
//! lag-compensated measurement and lets neither the integrator nor the output push the wheel
//! harder outward. Units are chosen so integer gains have a plain meaning: `kff` and `kp` in duty
//! (1/10 000) per m/s, `ki` in duty per metre of accumulated speed error.

use super::divide::Divisor;
use super::Duty;

/// Controller gains and limits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PiGains {
    /// Feed-forward: duty per m/s of target speed (the inverse of the motor's speed per duty).
    pub kff: i32,
    /// Proportional: duty per m/s of speed error.
    pub kp: i32,
    /// Integral: duty per metre of integrated speed error (m/s · s).
    pub ki: i32,
    /// Output limit, 0..=10 000.
    pub max_duty: i16,
}

impl PiGains {
    /// Starting values, tuned against [`crate::sim::WheelPlant`]'s motor model (0.6 m/s at full
    /// duty, 50 ms time constant, 3 % deadband) at a 10 ms control period: a 0.1 m/s step reaches
    /// the target in about 50 ms, overshoots by about 13 % and stays within 3 % from 150 ms on
    /// (pinned by a test). The real motor's constants are unknown (amiro-boards.md lists its part number
    /// and no-load speed as unknown), so expect to retune `kff` first, then `kp`/`ki`, on hardware.
    pub const AMIRO: PiGains = PiGains {
        kff: 15_000,
        kp: 20_000,
        ki: 200_000,
        max_duty: Duty::FULL_SCALE,
    };
}

impl Default for PiGains {
    fn default() -> Self {
        Self::AMIRO
    }
}

/// Speed errors beyond this are clamped (µm/s): keeps every product inside `i64`.
const MAX_ERROR_UM_S: i64 = 10_000_000;
/// The speed governor acts once the measured speed is within this many thousandths of the limit.
pub const LIMIT_GUARD_PER_MILLE: i64 = 20;
/// How many control steps the window-averaged speed measurement lags the wheel (half the default
/// four-step window).
const LAG_STEPS: i64 = 2;
/// One duty in the integrator's unit (duty × 10⁻¹²: ki [duty/m] × error [µm/s] × dt [µs]).
const INTEGRAL_PER_DUTY: i64 = 1_000_000_000_000;
/// [`INTEGRAL_PER_DUTY`] as a divisor.
const PER_DUTY: Divisor = Divisor::constant(INTEGRAL_PER_DUTY as u64);
/// Per mille.
const THOUSAND: Divisor = Divisor::constant(1000);
/// µm/s per m/s (the gains' unit).
const MILLION: Divisor = Divisor::constant(1_000_000);

/// One wheel's controller state.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WheelSpeedController {
    gains: PiGains,
    integral: i64,
    last_output: i64,
    last_measured: i64,
}

impl WheelSpeedController {
    /// A controller at rest.
    pub const fn new(gains: PiGains) -> Self {
        Self {
            gains,
            integral: 0,
            last_output: 0,
            last_measured: 0,
        }
    }

    /// The gains in use.
    pub const fn gains(&self) -> &PiGains {
        &self.gains
    }

    /// Clears the integrator (e.g. when the motors are switched off).
    pub fn reset(&mut self) {
        self.integral = 0;
        self.last_output = 0;
        self.last_measured = 0;
    }

    /// The integral term in duty units.
    pub const fn integral_duty(&self) -> i64 {
        PER_DUTY.div_i64(self.integral)
    }

    /// One control step of `dt_us` towards `target_um_s` given `measured_um_s`, with no speed
    /// limit but the error clamp.
    pub fn update(&mut self, target_um_s: i64, measured_um_s: i64, dt_us: u32) -> Duty {
        self.update_limited(target_um_s, measured_um_s, dt_us, MAX_ERROR_UM_S)
    }

    /// One control step towards `target_um_s`, which is first clamped to ±`limit_um_s`, with
    /// the speed governor: once the measured speed is within [`LIMIT_GUARD_PER_MILLE`] of the
    /// limit, the output may not push the wheel harder in that direction than it did on the last
    /// step, and the integrator may not grow outward. The measurement lags the wheel (it is
    /// averaged over the velocity window), so a PI that keeps pushing until the measurement
    /// reaches the limit has already driven the wheel past it; holding the drive from just below
    /// the limit lets the wheel settle onto it instead.
    pub fn update_limited(
        &mut self,
        target_um_s: i64,
        measured_um_s: i64,
        dt_us: u32,
        limit_um_s: i64,
    ) -> Duty {
        let limit = i64::from(self.gains.max_duty.clamp(0, Duty::FULL_SCALE));
        let speed_limit = limit_um_s.clamp(0, MAX_ERROR_UM_S);
        // Regulate to a ceiling a guard band below the limit: the measurement's resolution and
        // the loop's ripple around its set-point then stay under the limit.
        let guard = THOUSAND.div_i64(speed_limit * LIMIT_GUARD_PER_MILLE);
        let ceiling = speed_limit - guard;
        let target = target_um_s.clamp(-ceiling, ceiling);
        let measured = measured_um_s.clamp(-MAX_ERROR_UM_S, MAX_ERROR_UM_S);
        // Where the wheel is now: the measurement is an average over the velocity window and
        // lags by about half of it, so extrapolate by that many steps of its latest change.
        let predicted = measured
            .saturating_add((measured - self.last_measured).saturating_mul(LAG_STEPS))
            .clamp(-MAX_ERROR_UM_S, MAX_ERROR_UM_S);
        self.last_measured = measured;
        let near_limit = target.abs() >= ceiling
            && predicted.signum() == target.signum()
            && predicted.abs() >= ceiling - 4 * guard;
        let feedback = if near_limit { predicted } else { measured };
        let error = target
            .saturating_sub(feedback)
            .clamp(-MAX_ERROR_UM_S, MAX_ERROR_UM_S);
        let feed_forward = MILLION.div_i64(i64::from(self.gains.kff) * target);
        let proportional = MILLION.div_i64(i64::from(self.gains.kp) * error);
        let mut step = i64::from(self.gains.ki)
            .saturating_mul(error)
            .saturating_mul(i64::from(dt_us));
        if near_limit && step.signum() == target.signum() && predicted.abs() >= ceiling {
            step = 0;
        }
        // Integrate only up to the value that puts the output on its limit: beyond that the
        // integrator would store error the output cannot act on (wind-up). If P and feed-forward
        // already saturate the output, the integrator holds rather than moving further out.
        let at_upper = (limit - feed_forward - proportional).saturating_mul(INTEGRAL_PER_DUTY);
        let at_lower = (-limit - feed_forward - proportional).saturating_mul(INTEGRAL_PER_DUTY);
        let candidate = self.integral.saturating_add(step);
        let integral = if step > 0 {
            candidate.min(at_upper.max(self.integral))
        } else {
            candidate.max(at_lower.min(self.integral))
        };
        let integral_limit = limit.saturating_mul(INTEGRAL_PER_DUTY);
        self.integral = integral.clamp(-integral_limit, integral_limit);
        let mut output =
            (feed_forward + proportional + PER_DUTY.div_i64(self.integral)).clamp(-limit, limit);
        if near_limit && output.signum() == target.signum() && predicted.abs() >= ceiling {
            // Push no harder than last time in the direction the wheel already runs at the limit.
            let held = if self.last_output.signum() == output.signum() {
                self.last_output.abs()
            } else {
                0
            };
            output = output.signum() * output.abs().min(held);
        }
        self.last_output = output;
        Duty::saturating(output)
    }
}
