//! Per-shot pixel statistics over the frames of a shot: per-pixel mean, per-pixel temporal
//! variance (sample variance over frames, exact in integer arithmetic) and clipping counts.
use camsim_core::RawFrame;
use rayon::prelude::*;

/// Statistics of one shot.
#[derive(Debug, Clone)]
pub(crate) struct Stack {
    /// Frames in the shot.
    pub n_frames: usize,
    /// Per-pixel mean over frames (DN).
    pub mean: Vec<f64>,
    /// Per-pixel sample variance over frames (DN², N − 1); None with one frame.
    pub var: Option<Vec<f64>>,
    /// Per channel: fraction of pixel-frames at 0 DN.
    pub clip_lo: Vec<f64>,
    /// Per channel: fraction of pixel-frames at the ADC maximum.
    pub clip_hi: Vec<f64>,
}

impl Stack {
    /// Largest clipped fraction (low or high) of the channels.
    pub fn worst_clip(&self) -> f64 {
        self.clip_lo
            .iter()
            .chain(&self.clip_hi)
            .fold(0.0f64, |a, &b| a.max(b))
    }
}

/// Channel index of every pixel (row-major) and pixel count per channel.
#[derive(Debug, Clone)]
pub(crate) struct ChannelMap {
    pub rows: usize,
    pub cols: usize,
    pub channel: Vec<u8>,
    pub n_channels: usize,
}

impl ChannelMap {
    pub fn new(sensor: &camsim_sensor::SensorModel) -> Self {
        let (rows, cols) = (sensor.rows, sensor.cols);
        let channel = (0..rows * cols)
            .map(|i| sensor.cfa.channel_at(i / cols, i % cols) as u8)
            .collect();
        ChannelMap {
            rows,
            cols,
            channel,
            n_channels: sensor.channel_qe.len().max(1),
        }
    }
}

/// Computes a shot's statistics; the frames must all be `rows × cols` (checked by the caller).
pub(crate) fn stack(frames: &[RawFrame], map: &ChannelMap, max_dn: u16) -> Stack {
    let (rows, cols) = (map.rows, map.cols);
    let n = frames.len();
    let nch = map.n_channels;
    let mut mean = vec![0f64; rows * cols];
    let mut var = vec![0f64; rows * cols];
    let counts = mean
        .par_chunks_mut(cols)
        .zip(var.par_chunks_mut(cols))
        .enumerate()
        .map(|(r, (m_row, v_row))| {
            let mut sum = vec![0u64; cols];
            let mut sumsq = vec![0u64; cols];
            let mut lo = vec![0usize; nch];
            let mut hi = vec![0usize; nch];
            let ch_row = &map.channel[r * cols..(r + 1) * cols];
            for f in frames {
                let src = &f.dn[r * cols..(r + 1) * cols];
                for c in 0..cols {
                    let x = src[c] as u64;
                    sum[c] += x;
                    sumsq[c] += x * x;
                    if src[c] == 0 {
                        lo[ch_row[c] as usize] += 1;
                    } else if src[c] >= max_dn {
                        hi[ch_row[c] as usize] += 1;
                    }
                }
            }
            let nf = n as f64;
            for c in 0..cols {
                m_row[c] = sum[c] as f64 / nf;
            }
            if n >= 2 {
                let nn = n as u128;
                for c in 0..cols {
                    // Exact: N Σx² − (Σx)² in integers.
                    let num = nn * sumsq[c] as u128 - (sum[c] as u128) * (sum[c] as u128);
                    v_row[c] = num as f64 / (nf * (nf - 1.0));
                }
            }
            (lo, hi)
        })
        .reduce(
            || (vec![0usize; nch], vec![0usize; nch]),
            |(mut a, mut b), (c, d)| {
                a.iter_mut().zip(c).for_each(|(x, y)| *x += y);
                b.iter_mut().zip(d).for_each(|(x, y)| *x += y);
                (a, b)
            },
        );
    let mut per_ch = vec![0usize; nch];
    for &c in &map.channel {
        per_ch[c as usize] += 1;
    }
    let frac = |v: Vec<usize>| -> Vec<f64> {
        v.iter()
            .zip(&per_ch)
            .map(|(&k, &p)| {
                if p == 0 {
                    0.0
                } else {
                    k as f64 / (p * n) as f64
                }
            })
            .collect()
    };
    Stack {
        n_frames: n,
        mean,
        var: (n >= 2).then_some(var),
        clip_lo: frac(counts.0),
        clip_hi: frac(counts.1),
    }
}

/// Pixels per chunk of the deterministic parallel sums of [`moments`].
const MOMENT_CHUNK: usize = 4096;

/// Count and the two sums of `g(i)` over the pixel indices where `keep(i)`, in fixed chunks
/// summed in order: the same bits at any thread count (a rayon `reduce` splits by work
/// stealing, so its rounding would depend on the schedule). Generic, not `dyn`, so that `g`
/// inlines into the per-pixel loop.
fn chunk_sums<K, G>(n_pix: usize, keep: &K, g: G) -> (usize, f64, f64)
where
    K: Fn(usize) -> bool + Sync,
    G: Fn(usize) -> (f64, f64) + Sync,
{
    (0..n_pix.div_ceil(MOMENT_CHUNK))
        .into_par_iter()
        .map(|k| {
            let (mut n, mut a, mut b) = (0usize, 0.0f64, 0.0f64);
            for i in k * MOMENT_CHUNK..((k + 1) * MOMENT_CHUNK).min(n_pix) {
                if keep(i) {
                    let (x, y) = g(i);
                    n += 1;
                    a += x;
                    b += y;
                }
            }
            (n, a, b)
        })
        .collect::<Vec<_>>()
        .into_iter()
        .fold((0, 0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1, a.2 + b.2))
}

/// Mean, sample variance and fourth central moment of the values `f(i)` over the pixel
/// indices where `keep(i)` (parallel, two passes).
pub(crate) fn moments(
    n_pix: usize,
    keep: impl Fn(usize) -> bool + Sync,
    f: impl Fn(usize) -> f64 + Sync,
) -> (usize, f64, f64, f64) {
    let (cnt, s, _) = chunk_sums(n_pix, &keep, |i| (f(i), 0.0));
    if cnt < 2 {
        return (cnt, f64::NAN, f64::NAN, f64::NAN);
    }
    let m = s / cnt as f64;
    let (_, s2, s4) = chunk_sums(n_pix, &keep, |i| {
        let d = f(i) - m;
        let d2 = d * d;
        (d2, d2 * d2)
    });
    (cnt, m, s2 / (cnt - 1) as f64, s4 / cnt as f64)
}

/// Per channel, the count and two sums that `g` adds into its channel's slot, over fixed
/// chunks summed in order (as [`chunk_sums`]). Generic so that `g` inlines.
fn channel_chunk_sums<G>(n_pix: usize, n_channels: usize, g: G) -> Vec<(usize, f64, f64)>
where
    G: Fn(usize, &mut [(usize, f64, f64)]) + Sync,
{
    (0..n_pix.div_ceil(MOMENT_CHUNK))
        .into_par_iter()
        .map(|k| {
            let mut acc = vec![(0usize, 0.0f64, 0.0f64); n_channels];
            for i in k * MOMENT_CHUNK..((k + 1) * MOMENT_CHUNK).min(n_pix) {
                g(i, &mut acc);
            }
            acc
        })
        .collect::<Vec<_>>()
        .into_iter()
        .fold(vec![(0usize, 0.0f64, 0.0f64); n_channels], |mut t, c| {
            for (a, b) in t.iter_mut().zip(c) {
                *a = (a.0 + b.0, a.1 + b.1, a.2 + b.2);
            }
            t
        })
}

/// Per channel, [`moments`] with `keep(i) && channel(i) == c`, all channels in one scan of the
/// pixels per pass (the same chunks summed in the same order per channel, so each channel's
/// result has exactly the bits of its own [`moments`] call).
pub(crate) fn moments_by_channel(
    n_pix: usize,
    n_channels: usize,
    channel: impl Fn(usize) -> usize + Sync,
    keep: impl Fn(usize) -> bool + Sync,
    f: impl Fn(usize) -> f64 + Sync,
) -> Vec<(usize, f64, f64, f64)> {
    let first = channel_chunk_sums(n_pix, n_channels, |i, acc| {
        if keep(i) {
            // A channel index out of range matches no channel, as in `moments`.
            if let Some(a) = acc.get_mut(channel(i)) {
                a.0 += 1;
                a.1 += f(i);
            }
        }
    });
    let means: Vec<f64> = first.iter().map(|&(n, s, _)| s / n as f64).collect();
    let second = channel_chunk_sums(n_pix, n_channels, |i, acc| {
        if keep(i) {
            let c = channel(i);
            if let (Some(a), Some(&m)) = (acc.get_mut(c), means.get(c)) {
                let d = f(i) - m;
                let d2 = d * d;
                a.1 += d2;
                a.2 += d2 * d2;
            }
        }
    });
    first
        .iter()
        .zip(&second)
        .zip(&means)
        .map(|((&(cnt, _, _), &(_, s2, s4)), &m)| {
            if cnt < 2 {
                (cnt, f64::NAN, f64::NAN, f64::NAN)
            } else {
                (cnt, m, s2 / (cnt - 1) as f64, s4 / cnt as f64)
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn moments_by_channel_has_the_bits_of_moments_per_channel() {
        let n = 3 * MOMENT_CHUNK + 517;
        let v: Vec<f64> = (0..n)
            .map(|i| ((i * 7919) % 1013) as f64 * 0.37 + (i as f64).sin())
            .collect();
        let ch = |i: usize| (i % 4 + i / 97) % 3;
        let keep = |i: usize| i % 11 != 0;
        let all = moments_by_channel(n, 3, ch, keep, |i| v[i]);
        for (c, got) in all.iter().enumerate() {
            let want = moments(n, |i| keep(i) && ch(i) == c, |i| v[i]);
            assert_eq!(got.0, want.0);
            for (a, b) in [(got.1, want.1), (got.2, want.2), (got.3, want.3)] {
                assert_eq!(a.to_bits(), b.to_bits(), "channel {c}");
            }
        }
    }

    #[test]
    fn stack_is_exact() {
        let map = ChannelMap {
            rows: 1,
            cols: 3,
            channel: vec![0, 0, 0],
            n_channels: 1,
        };
        let fr = |v: [u16; 3]| RawFrame {
            rows: 1,
            cols: 3,
            adc_bits: 12,
            dn: v.to_vec(),
            layout: None,
        };
        let s = stack(&[fr([1, 0, 4095]), fr([3, 0, 4095])], &map, 4095);
        assert_eq!(s.mean, vec![2.0, 0.0, 4095.0]);
        assert_eq!(s.var.unwrap(), vec![2.0, 0.0, 0.0]);
        assert!((s.clip_lo[0] - 1.0 / 3.0).abs() < 1e-12);
        assert!((s.clip_hi[0] - 1.0 / 3.0).abs() < 1e-12);
    }
}
