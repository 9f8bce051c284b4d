//! `Odometry::from_micrometres` divides by constants through reciprocals and the 32-bit divide (no
//! 64-bit division on the F103): this keeps the formula it replaced, as it was written, and compares
//! the two over the edge values and sweeps of x, y and the heading.
use amiro_can::Odometry;

/// One turn in picoradians, as the library's.
const TURN_PICORAD: i128 = 6_283_185_307_180;
const TURN_COUNTS: i128 = 65_536;

fn round_div(n: i128, d: i128) -> i128 {
    if n >= 0 {
        (n + d / 2) / d
    } else {
        (n - d / 2) / d
    }
}

/// The heading's reduction as it was: three 64-bit divisions.
fn heading_counts_before(heading_urad: i64) -> u16 {
    const M: u64 = (TURN_PICORAD / 20) as u64;
    let r = heading_urad.rem_euclid(M as i64) as u64;
    let u = r * 50_000 % M;
    ((u * 2 * TURN_COUNTS as u64 + M) / (2 * M)) as u16
}

/// The exact formula in 128 bits: the count nearest `heading × 65536 × 10⁶ / TURN_PICORAD`,
/// wrapped into one turn.
fn heading_counts_exact(heading_urad: i64) -> u16 {
    round_div(
        i128::from(heading_urad) * TURN_COUNTS * 1_000_000,
        TURN_PICORAD,
    )
    .rem_euclid(TURN_COUNTS) as u16
}

/// `from_micrometres` as it was.
fn before(x_um: i64, y_um: i64, heading_urad: i64) -> Option<Odometry> {
    let x = i32::try_from(round_div(i128::from(x_um), 100)).ok()?;
    let y = i32::try_from(round_div(i128::from(y_um), 100)).ok()?;
    Odometry::new(x, y, heading_counts_before(heading_urad))
}

/// A small deterministic generator (SplitMix64), so a failure names its input.
struct Mix(u64);

impl Mix {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
}

/// Values around the places the formulas could differ: zero, the extremes, the wire's range and its
/// rounding halves, and multiples of one turn (and of `M`, 50 000 turns) on either side.
fn edge_values() -> Vec<i64> {
    const M: i64 = (TURN_PICORAD / 20) as i64;
    let mut values = vec![
        0, 1, -1, 49, 50, 51, -49, -50, -51, 99, 100, 101, -99, -100, -101,
    ];
    values.extend([i64::MIN, i64::MIN + 1, i64::MAX, i64::MAX - 1]);
    for centre in [
        838_860_700i64,
        838_860_749,
        838_860_750,
        838_860_800,
        838_860_850,
        -838_860_800,
        -838_860_849,
        -838_860_850,
        -838_860_900,
        i64::from(i32::MAX),
        i64::from(i32::MIN),
        i64::from(u32::MAX) - 50,
        i64::from(u32::MAX) - 49,
        i64::from(u32::MAX),
        -i64::from(u32::MAX) + 50,
        -i64::from(u32::MAX) + 49,
        214_748_364_750,
        6_283_185,
        3_141_593,
        M,
        2 * M,
        M / 2,
        M * 29_000_000,
        i64::MAX / M * M,
        i64::MIN / M * M,
    ] {
        for delta in -3..=3 {
            values.push(centre.saturating_add(delta));
            values.push(centre.saturating_neg().saturating_add(delta));
        }
    }
    // The µrad nearest each count's half-way point, for a few turns either side of zero.
    for turn in -3i64..=3 {
        for count in (0..65_536i128).step_by(97) {
            let half = (2 * count + 1) * TURN_PICORAD / (2 * TURN_COUNTS * 1_000_000);
            let at = i64::try_from(half).unwrap() + turn * 6_283_185;
            values.extend([at - 1, at, at + 1]);
        }
    }
    values
}

#[test]
fn the_old_formula_is_the_exact_one() {
    // The reference itself against the 128-bit formula: the comparisons below are with the truth.
    for h in edge_values() {
        assert_eq!(
            heading_counts_before(h),
            heading_counts_exact(h),
            "heading {h}"
        );
    }
}

#[test]
fn edge_values_give_the_same_odometry() {
    let values = edge_values();
    for &v in &values {
        assert_eq!(
            Odometry::from_micrometres(v, 0, v),
            before(v, 0, v),
            "x and heading {v}"
        );
        assert_eq!(
            Odometry::from_micrometres(0, v, v.wrapping_neg()),
            before(0, v, v.wrapping_neg()),
            "y {v}, heading {}",
            v.wrapping_neg()
        );
    }
    // Some of the edges must reach each outcome: in range, refused, and each heading half.
    assert!(values
        .iter()
        .any(|&v| Odometry::from_micrometres(v, 0, 0).is_none()));
    assert!(values
        .iter()
        .any(|&v| v > 800_000_000 && Odometry::from_micrometres(v, 0, 0).is_some()));
}

#[test]
fn every_heading_over_several_turns_and_positions_in_range() {
    // Every µrad of a turn around zero, either way.
    for h in -6_283_186i64..=6_283_186 {
        assert_eq!(
            Odometry::from_micrometres(0, 0, h).map(|o| o.heading()),
            Some(heading_counts_before(h)),
            "heading {h}"
        );
    }
    // Every 1 009 µm across the wire's range and beyond it.
    for x in (-840_000_000i64..=840_000_000).step_by(1_009) {
        assert_eq!(
            Odometry::from_micrometres(x, -x, 0),
            before(x, -x, 0),
            "x {x}"
        );
    }
}

#[test]
fn random_sweep_gives_the_same_odometry() {
    let mut mix = Mix(0x0D0_3E7E);
    for _ in 0..300_000 {
        let bits = mix.next();
        // Spread the magnitudes: full-width values, and ones cut to a random number of bits.
        let cut = |v: u64, m: &mut Mix| (v >> (m.next() % 64)) as i64;
        let (x, y, h) = (
            cut(bits, &mut mix),
            cut(mix.next(), &mut mix),
            cut(mix.next(), &mut mix),
        );
        let (x, y, h) = if bits & 1 == 0 {
            (x, y, h)
        } else {
            (x.wrapping_neg(), y, h.wrapping_neg())
        };
        assert_eq!(
            Odometry::from_micrometres(x, y, h),
            before(x, y, h),
            "({x}, {y}, {h})"
        );
    }
}
