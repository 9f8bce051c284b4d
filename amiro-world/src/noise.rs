//! Seeded noise: SplitMix64 (Steele, Lea and Flood, "Fast splittable pseudorandom number
//! generators", OOPSLA 2014) and a normal deviate from it. No clock, no OS randomness: the same
//! seed gives the same sequence on every machine, and the normal deviate uses only additions
//! (the Irwin–Hall sum of twelve uniforms, minus six: mean 0, variance 1, tails cut at ±6), so
//! it does not even depend on the platform's `ln` or `cos`.

/// A SplitMix64 generator.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Noise {
    state: u64,
}

impl Noise {
    /// A generator for `seed`.
    pub const fn new(seed: u64) -> Noise {
        Noise { state: seed }
    }

    /// An independent stream for one sensor: the seed mixed with the stream's number, so adding
    /// a sensor does not shift the others' noise.
    pub fn stream(seed: u64, stream: u64) -> Noise {
        let mut mix = Noise::new(seed ^ stream.wrapping_mul(0xD1B5_4A32_D192_ED03));
        Noise::new(mix.next_u64())
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1), 53 bits.
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// A standard normal deviate (mean 0, standard deviation 1).
    pub fn normal(&mut self) -> f64 {
        (0..12).map(|_| self.uniform()).sum::<f64>() - 6.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn splitmix64_matches_its_reference_sequence() {
        // The first outputs for seed 0 of the reference implementation (Vigna's splitmix64.c).
        let mut n = Noise::new(0);
        assert_eq!(n.next_u64(), 0xE220_A839_7B1D_CDAF);
        assert_eq!(n.next_u64(), 0x6E78_9E6A_A1B9_65F4);
        assert_eq!(n.next_u64(), 0x06C4_5D18_8009_454F);
    }

    #[test]
    fn normal_deviates_have_unit_spread() {
        let mut n = Noise::new(7);
        let samples: Vec<f64> = (0..20_000).map(|_| n.normal()).collect();
        let mean = samples.iter().sum::<f64>() / samples.len() as f64;
        let var = samples.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / samples.len() as f64;
        assert!(mean.abs() < 0.03, "{mean}");
        assert!((var.sqrt() - 1.0).abs() < 0.03, "{var}");
        assert!(samples.iter().all(|x| x.abs() <= 6.0));
    }

    #[test]
    fn streams_are_repeatable_and_distinct() {
        let a: Vec<u64> = (0..4).map(|_| Noise::stream(1, 3).next_u64()).collect();
        assert!(a.windows(2).all(|w| w[0] == w[1]));
        assert_ne!(
            Noise::stream(1, 3).next_u64(),
            Noise::stream(1, 4).next_u64()
        );
        assert_ne!(
            Noise::stream(1, 3).next_u64(),
            Noise::stream(2, 3).next_u64()
        );
    }
}
