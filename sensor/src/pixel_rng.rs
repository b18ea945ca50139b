//! The generator of the pixel loops: xoshiro256++ (D. Blackman, S. Vigna, "Scrambled linear
//! pseudorandom number generators", ACM TOMS 47(4), 2021) — the algorithm of
//! [`camsim_core::rng::CamRng`] — as a small `Copy` value, seeded from a [`CamRng`] stream.
//!
//! Being a plain value that the hot loops own (slow paths get a copy, see
//! [`crate::normal::standard_normal`]), its state stays in registers across a row instead of
//! being stored and reloaded for every draw.
use camsim_core::rng::CamRng;
use rand::{Rng, TryRng};
use std::convert::Infallible;

/// First stream id of every fixed-pattern stream: `stream(seed, &[FIXED_PATTERN_TAG, kind, …])`
/// with kind 0 = PRNU (per row), 1 = DSNU (per row), 2 = column offsets, 3 = hot pixels.
pub const FIXED_PATTERN_TAG: u64 = 0x4650_4E5F_5441_4721; // "FPN_TAG!"

/// xoshiro256++ state.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PixelRng {
    s: [u64; 4],
}

impl PixelRng {
    /// A generator whose state is the next four outputs of `stream` (a deterministic function
    /// of the stream, so of its seed and ids).
    pub fn from_stream(mut stream: CamRng) -> Self {
        let s = [
            stream.next_u64(),
            stream.next_u64(),
            stream.next_u64(),
            stream.next_u64(),
        ];
        // The all-zero state is the one fixed point of xoshiro (probability 2^-256).
        if s == [0; 4] {
            return PixelRng { s: [1, 2, 3, 4] };
        }
        PixelRng { s }
    }

    /// Next 64 random bits.
    #[inline(always)]
    pub fn next(&mut self) -> u64 {
        let s = &mut self.s;
        let result = s[0].wrapping_add(s[3]).rotate_left(23).wrapping_add(s[0]);
        let t = s[1] << 17;
        s[2] ^= s[0];
        s[3] ^= s[1];
        s[1] ^= s[2];
        s[0] ^= s[3];
        s[2] ^= t;
        s[3] = s[3].rotate_left(45);
        result
    }
}

impl TryRng for PixelRng {
    type Error = Infallible;

    #[inline(always)]
    fn try_next_u32(&mut self) -> Result<u32, Infallible> {
        Ok((self.next() >> 32) as u32)
    }

    #[inline(always)]
    fn try_next_u64(&mut self) -> Result<u64, Infallible> {
        Ok(self.next())
    }

    fn try_fill_bytes(&mut self, dst: &mut [u8]) -> Result<(), Infallible> {
        for chunk in dst.chunks_mut(8) {
            let b = self.next().to_le_bytes();
            chunk.copy_from_slice(&b[..chunk.len()]);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn same_sequence_as_rand_xoshiro256plusplus() {
        // Seeded with the same state (little-endian words), the two generators agree.
        let words = [0x0123_4567_89ab_cdefu64, 42, 7, 0xdead_beef];
        let mut seed = [0u8; 32];
        for (c, w) in seed.chunks_mut(8).zip(words) {
            c.copy_from_slice(&w.to_le_bytes());
        }
        let mut theirs = CamRng::from_seed(seed);
        let mut ours = PixelRng { s: words };
        for _ in 0..1000 {
            assert_eq!(ours.next(), theirs.next_u64());
        }
    }

    #[test]
    fn streams_differ() {
        let a = PixelRng::from_stream(camsim_core::rng::stream(1, &[0]));
        let b = PixelRng::from_stream(camsim_core::rng::stream(1, &[1]));
        assert_ne!(a, b);
    }
}
