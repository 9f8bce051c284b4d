//! Fixed-point sine and cosine for the odometry: angles in nanoradians, results scaled by 2³⁰.
//!
//! `core` has no trigonometry and the STM32F103 has no FPU; a Taylor polynomial on a reduced
//! argument in 64-bit integers is exact to a few parts in 10⁹, deterministic, and the same on host
//! and chip.

use super::divide::Divisor;

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
const TURN: Divisor = Divisor::constant(TURN_NRAD as u64);
/// [`QUARTER_TURN_NRAD`] as a divisor.
const QUARTER_TURN: Divisor = Divisor::constant(QUARTER_TURN_NRAD as u64);
/// Nanoradians per radian.
const NANO: Divisor = Divisor::constant(1_000_000_000);
/// The sine series' Horner divisors, (2k)(2k + 1) for k = 5 … 1.
const SINE_DIVISORS: [Divisor; 5] = [
    Divisor::constant(10 * 11),
    Divisor::constant(8 * 9),
    Divisor::constant(6 * 7),
    Divisor::constant(4 * 5),
    Divisor::constant(2 * 3),
];
/// The cosine series' Horner divisors, (2k − 1)(2k) for k = 6 … 1.
const COSINE_DIVISORS: [Divisor; 6] = [
    Divisor::constant(11 * 12),
    Divisor::constant(9 * 10),
    Divisor::constant(7 * 8),
    Divisor::constant(5 * 6),
    Divisor::constant(3 * 4),
    Divisor::constant(2), // 1 × 2
];

/// `angle` wrapped into `0..TURN_NRAD`.
pub const fn wrap_turn(angle_nrad: i64) -> i64 {
    TURN.rem_euclid_i64(angle_nrad)
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

/// Sine and cosine of `angle_nrad` (any value), each scaled by [`ONE`].
pub const fn sin_cos(angle_nrad: i64) -> (i64, i64) {
    // Reduce to r in [-π/4, π/4] plus a quarter-turn count q.
    let a = wrap_turn(angle_nrad);
    let mut quadrant = QUARTER_TURN.div_i64(a);
    let mut r = a - quadrant * QUARTER_TURN_NRAD;
    if r > EIGHTH_TURN_NRAD {
        r -= QUARTER_TURN_NRAD;
        quadrant += 1;
    }
    // r from nanoradians to the 2^30 scale: |r| ≤ 7.9e8, times 2^30 stays below 2^63.
    let x = NANO.div_i64(r * ONE + if r >= 0 { 500_000_000 } else { -500_000_000 });
    let x2 = mul(x, x);
    // Horner form of the Taylor series, from the last term in; the first omitted terms are below
    // 1e-10 for |x| ≤ π/4. One division a pass: an index loop over constant divisors.
    let mut s = ONE;
    let mut k = 0;
    while k < SINE_DIVISORS.len() {
        s = ONE - SINE_DIVISORS[k].div_i64(mul(x2, s));
        k += 1;
    }
    let sin = mul(x, s);
    let mut c = ONE;
    let mut k = 0;
    while k < COSINE_DIVISORS.len() {
        c = ONE - COSINE_DIVISORS[k].div_i64(mul(x2, c));
        k += 1;
    }
    let cos = c;
    match quadrant % 4 {
        0 => (sin, cos),
        1 => (cos, -sin),
        2 => (-sin, -cos),
        _ => (-cos, sin),
    }
}
