//! Fixed-point sine and cosine for the odometry: angles in nanoradians, results scaled by 2³⁰.
//!
//! `core` has no trigonometry and the STM32F103 has no FPU; a Taylor polynomial on a reduced
//! argument in 64-bit integers is exact to a few parts in 10⁹, deterministic, and the same on host
//! and chip.

use core::num::NonZeroU64;

use super::divide::{constant, div_i64, rem_euclid_i64};

/// One, in the 2³⁰ fixed-point scale of [`sin_cos`]'s results.
pub const ONE: i64 = 1 << 30;
/// A full turn, 2π, in nanoradians (rounded; 0.18 nrad short).
pub const TURN_NRAD: i64 = 6_283_185_307;
/// π in nanoradians.
pub const HALF_TURN_NRAD: i64 = 3_141_592_654;
/// π/2 in nanoradians.
pub const QUARTER_TURN_NRAD: i64 = 1_570_796_327;
/// π/4 in nanoradians.
const EIGHTH_TURN_NRAD: i64 = 785_398_163;
/// [`TURN_NRAD`] as a divisor.
const TURN: NonZeroU64 = constant(TURN_NRAD as u64);
/// [`QUARTER_TURN_NRAD`] as a divisor.
const QUARTER_TURN: NonZeroU64 = constant(QUARTER_TURN_NRAD as u64);
/// Nanoradians per radian.
const NANO: NonZeroU64 = constant(1_000_000_000);

/// `angle` wrapped into `0..TURN_NRAD`.
pub const fn wrap_turn(angle_nrad: i64) -> i64 {
    rem_euclid_i64(angle_nrad, TURN)
}

/// `angle` wrapped into `-π..π`.
pub const fn wrap_half_turn(angle_nrad: i64) -> i64 {
    let a = wrap_turn(angle_nrad);
    if a >= HALF_TURN_NRAD {
        a - TURN_NRAD
    } else {
        a
    }
}

/// `(a * b) >> 30`, rounded to nearest.
const fn mul(a: i64, b: i64) -> i64 {
    (a * b + (1 << 29)) >> 30
}

/// One Horner step of the Taylor series: `1 − x² · s / d` (`d` the next term's factorial ratio).
const fn horner(x2: i64, s: i64, d: u64) -> i64 {
    ONE - div_i64(mul(x2, s), constant(d))
}

/// Sine and cosine of `angle_nrad` (any value), each scaled by [`ONE`].
pub const fn sin_cos(angle_nrad: i64) -> (i64, i64) {
    // Reduce to r in [-π/4, π/4] plus a quarter-turn count q.
    let a = wrap_turn(angle_nrad);
    let mut quadrant = div_i64(a, QUARTER_TURN);
    let mut r = a - quadrant * QUARTER_TURN_NRAD;
    if r > EIGHTH_TURN_NRAD {
        r -= QUARTER_TURN_NRAD;
        quadrant += 1;
    }
    // r from nanoradians to the 2^30 scale: |r| ≤ 7.9e8, times 2^30 stays below 2^63.
    let x = div_i64(
        r * ONE + if r >= 0 { 500_000_000 } else { -500_000_000 },
        NANO,
    );
    let x2 = mul(x, x);
    // Horner form of the Taylor series, from the last term in: the sine's divisors are
    // (2k)(2k + 1) for k = 5 … 1, the cosine's (2k − 1)(2k) for k = 6 … 1, written out (constant
    // divisors, no loop). The first omitted terms are below 1e-10 for |x| ≤ π/4.
    let s = horner(x2, ONE, 10 * 11);
    let s = horner(x2, s, 8 * 9);
    let s = horner(x2, s, 6 * 7);
    let s = horner(x2, s, 4 * 5);
    let s = horner(x2, s, 2 * 3);
    let sin = mul(x, s);
    let c = horner(x2, ONE, 11 * 12);
    let c = horner(x2, c, 9 * 10);
    let c = horner(x2, c, 7 * 8);
    let c = horner(x2, c, 5 * 6);
    let c = horner(x2, c, 3 * 4);
    let cos = horner(x2, c, 2);
    match quadrant % 4 {
        0 => (sin, cos),
        1 => (cos, -sin),
        2 => (-sin, -cos),
        _ => (-cos, sin),
    }
}
