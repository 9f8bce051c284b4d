//! Exact 64-bit division from the Cortex-M3's 32-bit divide instruction.
//!
//! The motion math divides 64-bit values (lengths in nm, angles in nrad, the integrator in
//! 10⁻¹² duty). The STM32F103 divides only 32 by 32 bits in hardware (`UDIV`, at most 12 cycles),
//! so a plain `/` on `i64` calls the compiler's `__aeabi_ldivmod`, a shift-and-subtract loop whose
//! worst case is about 1 800 cycles; the drive controller's step made some thirty of them and was
//! the DiWheelDrive's costliest task. The functions here give exactly the quotient `/` gives, for
//! every dividend and every non-zero divisor ([`div_u64`]), in a fixed sequence of at most three
//! `UDIV`s, a few multiplies and two corrections each, with no loop: schoolbook long division (Knuth, TAOCP vol. 2,
//! 4.3.1, algorithm D) in base 2¹⁶ digits, where the divisor normalised to 32 bits is two digits,
//! so each quotient digit's estimate from its leading digit is corrected with the second digit to
//! the exact one.
//!
//! A value divided by often — a constant, the axle width, a velocity window's time — is a
//! [`Divisor`]: its reciprocal is taken once (by the compiler, for a constant), and each quotient
//! is then a 64 × 64-bit multiply-high and one correction, cheaper still.
//!
//! The divisor is a [`NonZeroU64`]: a division by zero cannot be written, and every divisor the
//! motion math uses is positive (lengths, time steps, constants).

use core::num::NonZeroU64;

/// A divisor from a constant, for `const` items: a zero is a build error.
pub const fn constant(divisor: u64) -> NonZeroU64 {
    match NonZeroU64::new(divisor) {
        Some(divisor) => divisor,
        None => panic!("a constant divisor of zero"),
    }
}

/// `n / d`, exactly as `u64`'s `/`.
pub const fn div_u64(n: u64, d: NonZeroU64) -> u64 {
    let d = d.get();
    if d >> 32 == 0 {
        // A 32-bit divisor: the high word by the hardware, the rest (its remainder below the
        // divisor, then the low word) by long division.
        let d = d as u32;
        let high = (n >> 32) as u32;
        let (q_high, r_high) = (high / d, high % d);
        let (q_low, _) = div_64_32(r_high, n as u32, d);
        ((q_high as u64) << 32) | q_low as u64
    } else {
        // A divisor of 33 bits or more: the quotient fits 32 bits. Estimate it from the divisor's
        // leading 32 bits (normalised) against half the dividend (so the high word stays below
        // them), which gives the quotient or one more; take one off and correct upwards once.
        let shift = ((d >> 32) as u32).leading_zeros(); // 0..=31
        let leading = ((d << shift) >> 32) as u32; // top bit set
        let half = n >> 1; // its high word < 2³¹ ≤ `leading`
        let (estimate, _) = div_64_32((half >> 32) as u32, half as u32, leading);
        let mut q = ((estimate >> (31 - shift)) as u64).saturating_sub(1);
        // q ≤ n / d here, so q·d ≤ n: neither the product nor the difference overflows.
        if n - q * d >= d {
            q += 1;
        }
        q
    }
}

/// A divisor with its reciprocal, for a value divided by often (a constant, the geometry's axle
/// width, a window's time): a quotient is then one 64 × 64-bit multiply-high (four `UMULL`s) and
/// one correction, where [`div_u64`] normalises and estimates two digits. The quotient is inlined
/// at each use: it is short, a constant's reciprocal folds into it, and a function called from
/// many places in one task is what the size-optimising build reaches through a register moved
/// into an outlined helper, a call the bound cannot follow.
///
/// The reciprocal is m = ⌊(2⁶⁴ − 1) / d⌋. For n < 2⁶⁴, m·d > 2⁶⁴ − 1 − d, so n·m / 2⁶⁴ lies in
/// (n/d − 1, n/d): its floor is ⌊n/d⌋ or one less, and the remainder it leaves, n − q·d, tells which.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Divisor {
    divisor: u64,
    reciprocal: u64,
}

impl Divisor {
    /// `d` with its reciprocal (one [`div_u64`]).
    pub const fn new(d: NonZeroU64) -> Self {
        Self {
            divisor: d.get(),
            reciprocal: div_u64(u64::MAX, d),
        }
    }

    /// A divisor from a constant, for `const` items (the reciprocal is computed by the compiler):
    /// a zero is a build error.
    pub const fn constant(d: u64) -> Self {
        Self::new(constant(d))
    }

    /// The divisor.
    pub const fn get(&self) -> u64 {
        self.divisor
    }

    /// `n / d`, exactly as `u64`'s `/`.
    #[inline(always)]
    pub const fn div_u64(&self, n: u64) -> u64 {
        let q = mul_high(n, self.reciprocal);
        // q ≤ n / d, so q·d ≤ n: no overflow.
        if n - q * self.divisor >= self.divisor {
            q + 1
        } else {
            q
        }
    }

    /// `n / d`, exactly as `i64`'s `/` by `d as i64` (rounding towards zero).
    #[inline(always)]
    pub const fn div_i64(&self, n: i64) -> i64 {
        let q = self.div_u64(n.unsigned_abs()) as i64;
        if n < 0 {
            q.wrapping_neg()
        } else {
            q
        }
    }

    /// `n.rem_euclid(d as i64)`, exactly: the remainder in `0..d`.
    #[inline(always)]
    pub const fn rem_euclid_i64(&self, n: i64) -> i64 {
        let magnitude = n.unsigned_abs();
        let r = magnitude - self.div_u64(magnitude) * self.divisor;
        if n < 0 && r != 0 {
            (self.divisor - r) as i64
        } else {
            r as i64
        }
    }
}

/// The high 64 bits of `a · b`, from four 32 × 32-bit products.
#[inline(always)]
const fn mul_high(a: u64, b: u64) -> u64 {
    let (a1, a0) = (a >> 32, a & 0xffff_ffff);
    let (b1, b0) = (b >> 32, b & 0xffff_ffff);
    let low = a0 * b0;
    let cross_a = a1 * b0;
    let cross_b = a0 * b1;
    // The middle column: each term below 2³², their sum below 3·2³².
    let middle = (low >> 32) + (cross_a & 0xffff_ffff) + (cross_b & 0xffff_ffff);
    a1 * b1 + (cross_a >> 32) + (cross_b >> 32) + (middle >> 32)
}

/// `(high·2³² + low) / d` and its remainder, for `high < d`: the quotient fits 32 bits.
const fn div_64_32(high: u32, low: u32, d: u32) -> (u32, u32) {
    // Normalise: shift the divisor's top bit into bit 31 and the dividend with it (the shifted
    // dividend's high word stays below the shifted divisor, as `high < d`).
    let shift = d.leading_zeros();
    let d = d << shift;
    let top = if shift == 0 {
        high
    } else {
        (high << shift) | (low >> (32 - shift))
    };
    let low = low << shift;
    let q1 = quotient_digit(top, low >> 16, d);
    let r1 = ((top << 16) | (low >> 16)).wrapping_sub(q1.wrapping_mul(d));
    let q0 = quotient_digit(r1, low & 0xffff, d);
    let r0 = ((r1 << 16) | (low & 0xffff)).wrapping_sub(q0.wrapping_mul(d));
    ((q1 << 16) | q0, r0 >> shift)
}

/// The base-2¹⁶ digit `(top·2¹⁶ + next) / d` for a normalised `d` (bit 31 set), `top < d` and
/// `next < 2¹⁶`. The estimate from `d`'s leading digit is at most two too large (algorithm D's
/// theorem B); as `d` has only two digits, comparing the estimate times its second digit with what
/// is left of the dividend tells exactly whether it is too large, so two corrections end on the
/// digit. The caller's remainder, `top·2¹⁶ + next − digit·d`, is below `d` and is computed modulo
/// 2³² (the product and the shifted `top` wrap alike).
const fn quotient_digit(top: u32, next: u32, d: u32) -> u32 {
    // ≥ 2¹⁵: bit 31 of the normalised `d`, set again so that the compiler sees a divisor that is
    // never zero (no panic path for the images' panic check; the value is the same).
    let d_high = (d >> 16) | (1 << 15);
    let d_low = d & 0xffff;
    let mut q = top / d_high;
    let mut r = top - q * d_high; // < d_high < 2¹⁶
                                  // `q > 0xffff` first: then `q * d_low` is not formed (it could overflow).
    if q > 0xffff || q * d_low > ((r << 16) | next) {
        q -= 1;
        r += d_high;
        if r <= 0xffff && (q > 0xffff || q * d_low > ((r << 16) | next)) {
            q -= 1;
        }
    }
    q
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check(n: u64, d: u64) {
        let nz = NonZeroU64::new(d).unwrap();
        assert_eq!(div_u64(n, nz), n / d, "{n} / {d}");
        let divisor = Divisor::new(nz);
        assert_eq!(divisor.div_u64(n), n / d, "{n} / {d} by its reciprocal");
        let signed = n as i64;
        if d <= i64::MAX as u64 {
            assert_eq!(divisor.div_i64(signed), signed / d as i64, "{signed} / {d}");
            assert_eq!(
                divisor.rem_euclid_i64(signed),
                signed.rem_euclid(d as i64),
                "{signed} rem {d} by its reciprocal"
            );
        }
    }

    /// A small deterministic generator (xorshift64*), so the sweep is the same on every run.
    struct Sweep(u64);

    impl Sweep {
        fn next(&mut self) -> u64 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
        }
    }

    /// Values at the edges that matter: around every power of two, and near their multiples.
    fn edges() -> Vec<u64> {
        let mut v = vec![0, 1, 2, 3, u64::MAX, u64::MAX - 1, i64::MAX as u64, 1 << 63];
        for bit in 0..64 {
            let p = 1u64 << bit;
            for delta in [0u64, 1, 2, 0xffff, 0x1_0000] {
                v.push(p.wrapping_add(delta));
                v.push(p.wrapping_sub(delta));
            }
            v.push(p | (p >> 1));
            v.push(p.wrapping_mul(3));
        }
        v
    }

    #[test]
    fn every_edge_pair_divides_exactly() {
        let values = edges();
        for &d in values.iter().filter(|&&d| d != 0) {
            for &n in &values {
                check(n, d);
            }
        }
    }

    #[test]
    fn random_dividends_and_divisors_of_every_width_divide_exactly() {
        let mut rng = Sweep(0x9e37_79b9_7f4a_7c15);
        for _ in 0..2_000_000 {
            let n = rng.next() >> (rng.next() % 64);
            let d = rng.next() >> (rng.next() % 64);
            if d != 0 {
                check(n, d);
            }
        }
    }

    #[test]
    fn dividends_next_to_multiples_divide_exactly() {
        // Where a quotient digit's estimate is most often too large: n = q·d + r with r near 0 or d.
        let mut rng = Sweep(0x1234_5678_9abc_def1);
        for _ in 0..500_000 {
            let d = (rng.next() >> (rng.next() % 64)).max(1);
            let q = rng.next() >> (rng.next() % 64);
            let base = q.wrapping_mul(d);
            for r in [0, 1, d - 1, d, d.wrapping_add(1)] {
                check(base.wrapping_add(r), d);
                check(base.wrapping_sub(r), d);
            }
        }
    }

    #[test]
    fn the_motion_constants_divide_exactly_near_their_multiples() {
        for d in [
            2u64,
            1000,
            1_000_000,
            2_000_000,
            1_000_000_000,
            1_000_000_000_000,
            1_570_796_327,
            6_283_185_307,
            77_000,
        ] {
            let nz = NonZeroU64::new(d).unwrap();
            let divisor = Divisor::constant(d);
            for q in (0..200_000u64).chain((1u64 << 40)..(1u64 << 40) + 1000) {
                let base = q.saturating_mul(d);
                for n in [base, base.saturating_add(1), base.saturating_sub(1)] {
                    assert_eq!(div_u64(n, nz), n / d, "{n} / {d}");
                    assert_eq!(divisor.div_u64(n), n / d, "{n} / {d} by its reciprocal");
                }
            }
        }
    }

    #[test]
    fn signed_extremes_round_towards_zero() {
        let one = Divisor::constant(1);
        assert_eq!(one.div_i64(i64::MIN), i64::MIN);
        assert_eq!(Divisor::constant(2).div_i64(i64::MIN), i64::MIN / 2);
        assert_eq!(Divisor::constant(2).div_i64(-7), -3);
        assert_eq!(Divisor::constant(3).rem_euclid_i64(-7), 2);
        let turn = Divisor::constant(6_283_185_307);
        assert_eq!(
            turn.rem_euclid_i64(i64::MIN),
            i64::MIN.rem_euclid(6_283_185_307)
        );
        assert_eq!(Divisor::constant(u64::MAX).div_i64(i64::MIN), 0);
        assert_eq!(div_u64(u64::MAX, constant(u64::MAX)), 1);
        assert_eq!(Divisor::constant(u64::MAX).div_u64(u64::MAX), 1);
    }

    #[test]
    fn the_multiply_high_is_the_wide_product_s_high_half() {
        let mut rng = Sweep(0x5555_aaaa_1234_4321);
        for _ in 0..1_000_000 {
            let (a, b) = (rng.next(), rng.next() >> (rng.next() % 64));
            assert_eq!(
                mul_high(a, b),
                ((u128::from(a) * u128::from(b)) >> 64) as u64
            );
        }
        assert_eq!(mul_high(u64::MAX, u64::MAX), u64::MAX - 1);
    }
}
