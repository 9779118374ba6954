//! A small, fast, seedable generator (PCG32): renders and generated scenes are
//! deterministic from a seed.

/// A PCG32 stream.
pub struct Rng(u64);

impl Rng {
    /// A stream for one (seed, pixel, sample).
    pub fn new(seed: u64, stream: u64) -> Self {
        let mut r = Rng(seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(stream.wrapping_mul(1442695040888963407) | 1));
        r.uniform();
        r
    }
    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f32 {
        let old = self.0;
        self.0 = old
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let x = (((old >> 18) ^ old) >> 27) as u32;
        let r = (old >> 59) as u32;
        (x.rotate_right(r) >> 8) as f32 / (1u32 << 24) as f32
    }
}

/// SplitMix64's finaliser: a stable 64-bit mix whose every output bit depends on every
/// input bit, for choices made by a hash of a seed (a data set's families and samplers).
pub fn splitmix(x: u64) -> u64 {
    let mut z = x.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}
