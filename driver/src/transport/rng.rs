//! Random numbers of one gather sample beyond its Sobol point: the light sample at the hit,
//! the directions and Russian-roulette decisions of a path, each derived from
//! (seed, texel, iteration, sample) so a sample's bits never depend on the thread or shard
//! that baked it (docs/ARCHITECTURE.md, "Invariants").

use guidebake_kernels::sobol::rotation;

/// Salt separating this stream from the Sobol rotations of the same (texel, iteration).
const SAMPLE_SALT: u32 = 0x6869_7421;

/// A SplitMix64 stream keyed by one gather sample.
#[derive(Clone, Debug)]
pub struct SampleRng(u64);

impl SampleRng {
    /// The stream of sample `sample` of iteration `iteration` at texel `texel`. `sample` must
    /// be below 2^20 and `iteration` below 2^12 (the settings guarantee both).
    pub fn new(seed: u32, texel: u64, iteration: u32, sample: u32) -> Self {
        debug_assert!(sample < 1 << 20 && iteration < 1 << 12);
        let r = rotation(seed ^ SAMPLE_SALT, texel, iteration << 20 | sample);
        Self(u64::from(r[0]) | u64::from(r[1]) << 32)
    }

    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// A number in [0, 1): 24 random bits, so never rounded up to 1.
    pub fn unit(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 * (1.0 / (1u32 << 24) as f32)
    }

    /// A point in [0, 1)².
    pub fn pair(&mut self) -> [f32; 2] {
        [self.unit(), self.unit()]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn streams_replay_and_stay_below_one() {
        let mut a = SampleRng::new(3, 17, 2, 99);
        let mut b = SampleRng::new(3, 17, 2, 99);
        let mut c = SampleRng::new(3, 17, 2, 100);
        let (mut same, mut mean) = (0, 0.0f64);
        for _ in 0..10_000 {
            let (x, y, z) = (a.unit(), b.unit(), c.unit());
            assert_eq!(x.to_bits(), y.to_bits());
            assert!((0.0..1.0).contains(&x));
            same += usize::from(x == z);
            mean += f64::from(x);
        }
        assert!(same < 5, "neighbouring samples share a stream");
        assert!((mean / 10_000.0 - 0.5).abs() < 0.01, "mean {mean}");
    }
}
