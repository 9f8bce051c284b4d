//! Fixed-point sine and cosine for the odometry: angles in nanoradians, results scaled by 2³⁰.
//!
//! `core` has no trigonometry and the STM32F103 has no FPU; a Taylor polynomial on a reduced
//! argument in 64-bit integers is exact to a few parts in 10⁹, deterministic, and the same on host
//! and chip.

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

/// `angle` wrapped into `0..TURN_NRAD`.
pub const fn wrap_turn(angle_nrad: i64) -> i64 {
    angle_nrad.rem_euclid(TURN_NRAD)
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
    let mut quadrant = a / QUARTER_TURN_NRAD;
    let mut r = a - quadrant * QUARTER_TURN_NRAD;
    if r > EIGHTH_TURN_NRAD {
        r -= QUARTER_TURN_NRAD;
        quadrant += 1;
    }
    // r from nanoradians to the 2^30 scale: |r| ≤ 7.9e8, times 2^30 stays below 2^63.
    let x = (r * ONE + if r >= 0 { 500_000_000 } else { -500_000_000 }) / 1_000_000_000;
    let x2 = mul(x, x);
    // Horner form of the Taylor series; the first omitted terms are below 1e-10 for |x| ≤ π/4.
    let mut s = ONE;
    let mut k = 5;
    while k > 0 {
        let d = (2 * k) * (2 * k + 1);
        s = ONE - mul(x2, s) / d;
        k -= 1;
    }
    let sin = mul(x, s);
    let mut c = ONE;
    let mut k = 6;
    while k > 0 {
        let d = (2 * k - 1) * (2 * k);
        c = ONE - mul(x2, c) / d;
        k -= 1;
    }
    let cos = c;
    match quadrant % 4 {
        0 => (sin, cos),
        1 => (cos, -sin),
        2 => (-sin, -cos),
        _ => (-cos, sin),
    }
}
