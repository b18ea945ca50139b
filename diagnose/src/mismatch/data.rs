//! The recording reduced once: per shot, the per-pixel mean over its frames, the per-pixel
//! temporal (sample) variance and the number of frames at each ADC rail. Everything the
//! diagnosis compares with the model is computed from these.
use rayon::prelude::*;

/// What a shot's target is, as far as the diagnosis is concerned.
#[derive(Debug, Clone, PartialEq)]
pub enum TargetClass {
    /// No light.
    Dark,
    /// One radiance everywhere.
    Uniform,
    /// A slanted edge at this angle (degrees, capture-format convention).
    Edge {
        /// Edge angle (degrees).
        angle_deg: f64,
    },
    /// Any other structured target (patches, images, ...).
    Structured,
}

impl TargetClass {
    /// True for targets with light.
    pub fn is_light(&self) -> bool {
        !matches!(self, TargetClass::Dark)
    }
    /// True for targets with spatial structure (edges, patches, images).
    pub fn is_structured(&self) -> bool {
        matches!(self, TargetClass::Edge { .. } | TargetClass::Structured)
    }
}

/// One shot reduced to per-pixel statistics.
#[derive(Debug, Clone)]
pub struct ShotData {
    /// Shot id.
    pub id: String,
    /// Target class.
    pub target: TargetClass,
    /// A key naming the target (shots with equal keys look at the same scene).
    pub target_key: String,
    /// Exposure time (s).
    pub exposure_s: f64,
    /// Analog gain.
    pub analog_gain: f64,
    /// Number of frames.
    pub frames: usize,
    /// Per-pixel mean over frames (DN), row-major.
    pub mean_dn: Vec<f32>,
    /// Per-pixel unbiased temporal variance (DN²); empty with one frame.
    pub var_dn: Vec<f32>,
    /// Per-pixel number of frames at 0 DN.
    pub n_low: Vec<u16>,
    /// Per-pixel number of frames at the ADC maximum.
    pub n_high: Vec<u16>,
    /// Pixels treated as censored (see [`censored_pixel`]): compared with the model through
    /// their rail counts only.
    pub censored: Vec<bool>,
    /// Censored pixels that the neighbourhood rule alone would not censor: they are censored
    /// because a frame of their own hit a rail, so their rail counts are seen only given at
    /// least one rail frame (the χ² summary's expected deviance is conditional on that).
    pub rail_only: Vec<bool>,
    /// Sensor temperature during the shot (°C, captures.json `temperature_c`), if given.
    pub temperature_c: Option<f64>,
    /// Global index (capture order over the whole set) of the shot's first frame.
    pub first_frame: u64,
    /// Row means of every frame (DN), frame-major: `row_means_dn[f·rows + r]`.
    pub row_means_dn: Vec<f64>,
}

impl ShotData {
    /// True when the temporal variance is known (≥ 2 frames).
    pub fn has_variance(&self) -> bool {
        self.frames >= 2 && !self.var_dn.is_empty()
    }
}

/// A capture set reduced for the diagnosis.
#[derive(Debug, Clone)]
pub struct DataSet {
    /// Sensor rows.
    pub rows: usize,
    /// Sensor columns.
    pub cols: usize,
    /// Channel index of every pixel, row-major.
    pub channel: Vec<u8>,
    /// Channel names.
    pub channel_names: Vec<String>,
    /// Largest DN (2^bits − 1).
    pub max_dn: f64,
    /// The shots.
    pub shots: Vec<ShotData>,
}

impl DataSet {
    /// Number of pixels.
    pub fn pixels(&self) -> usize {
        self.rows * self.cols
    }
    /// Number of channels.
    pub fn channels(&self) -> usize {
        self.channel_names.len()
    }
    /// Field height h of pixel (r, c): distance of its centre from the sensor centre divided
    /// by the half-diagonal (effects.md).
    #[inline]
    pub fn field_height(&self, r: usize, c: usize) -> f64 {
        let (yc, xc) = (
            (self.rows as f64 - 1.0) / 2.0,
            (self.cols as f64 - 1.0) / 2.0,
        );
        let half_diag = 0.5 * ((self.rows * self.rows + self.cols * self.cols) as f64).sqrt();
        ((r as f64 - yc).powi(2) + (c as f64 - xc).powi(2)).sqrt() / half_diag
    }
}

/// Builds a [`ShotData`] from frames added one at a time (exact integer sums, so the result
/// does not depend on the order of the rows' work or the thread count).
#[derive(Debug, Clone)]
pub struct ShotAccumulator {
    rows: usize,
    cols: usize,
    max_dn: u16,
    frames: usize,
    sum: Vec<u32>,
    sumsq: Vec<u64>,
    n_low: Vec<u16>,
    n_high: Vec<u16>,
    row_means: Vec<f64>,
}

impl ShotAccumulator {
    /// An empty accumulator for `rows × cols` frames of an ADC whose maximum is `max_dn`.
    pub fn new(rows: usize, cols: usize, max_dn: u16) -> Self {
        let n = rows * cols;
        ShotAccumulator {
            rows,
            cols,
            max_dn,
            frames: 0,
            sum: vec![0; n],
            sumsq: vec![0; n],
            n_low: vec![0; n],
            n_high: vec![0; n],
            row_means: Vec::new(),
        }
    }

    /// Adds a frame (row-major DN). Errors on a wrong size or a value above the ADC maximum.
    pub fn add(&mut self, dn: &[u16]) -> Result<(), String> {
        if dn.len() != self.rows * self.cols {
            return Err(format!(
                "frame has {} values but the sensor has {}×{} = {}",
                dn.len(),
                self.rows,
                self.cols,
                self.rows * self.cols
            ));
        }
        if self.frames >= u16::MAX as usize {
            return Err("more than 65535 frames in one shot".into());
        }
        if let Some(v) = dn.iter().find(|&&v| v > self.max_dn) {
            return Err(format!(
                "value {v} DN exceeds the camera's ADC maximum {}",
                self.max_dn
            ));
        }
        let max = self.max_dn;
        let cols = self.cols.max(1);
        self.sum
            .par_chunks_mut(cols)
            .zip(self.sumsq.par_chunks_mut(cols))
            .zip(self.n_low.par_chunks_mut(cols))
            .zip(self.n_high.par_chunks_mut(cols))
            .zip(dn.par_chunks(cols))
            .for_each(|((((s, q), lo), hi), d)| {
                for i in 0..d.len() {
                    let v = d[i];
                    s[i] += v as u32;
                    q[i] += (v as u64) * (v as u64);
                    lo[i] += (v == 0) as u16;
                    hi[i] += (v == max) as u16;
                }
            });
        // Row means of this frame (exact integer sums per row).
        self.row_means.extend(
            dn.chunks(cols)
                .map(|row| row.iter().map(|&v| v as u64).sum::<u64>() as f64 / cols as f64),
        );
        self.frames += 1;
        Ok(())
    }

    /// Frames added so far.
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// The reduced shot.
    pub fn finish(
        self,
        id: String,
        target: TargetClass,
        target_key: String,
        exposure_s: f64,
        analog_gain: f64,
    ) -> ShotData {
        let f = self.frames.max(1) as f64;
        let mean_dn: Vec<f32> = self
            .sum
            .par_iter()
            .map(|&s| (s as f64 / f) as f32)
            .collect();
        let var_dn: Vec<f32> = if self.frames >= 2 {
            self.sum
                .par_iter()
                .zip(self.sumsq.par_iter())
                .map(|(&s, &q)| {
                    let s = s as f64;
                    ((q as f64 - s * s / f) / (f - 1.0)).max(0.0) as f32
                })
                .collect()
        } else {
            Vec::new()
        };
        let max = self.max_dn as f64;
        let (rows, cols) = (self.rows, self.cols);
        let has_var = !var_dn.is_empty();
        let cols1 = cols.max(1);
        // The same-channel neighbours two pixels away (the 3 × 3 grid of offsets −2, 0, +2
        // without the centre, row by row) that lie on the sensor, into `m` (means) and `v`
        // (temporal variances, 0 without them); returns their number.
        let neighbours = |r: usize, c: usize, m: &mut [f64; 8], v: &mut [f64; 8]| -> usize {
            let mut k = 0;
            for dr in [-2i64, 0, 2] {
                for dc in [-2i64, 0, 2] {
                    let (rr, cc) = (r as i64 + dr, c as i64 + dc);
                    if (dr, dc) == (0, 0)
                        || rr < 0
                        || cc < 0
                        || rr >= rows as i64
                        || cc >= cols as i64
                    {
                        continue;
                    }
                    let j = rr as usize * cols + cc as usize;
                    m[k] = mean_dn[j] as f64;
                    v[k] = if has_var { var_dn[j] as f64 } else { 0.0 };
                    k += 1;
                }
            }
            k
        };
        let mut censored = vec![false; mean_dn.len()];
        let mut rail_only = vec![false; mean_dn.len()];
        censored
            .par_chunks_mut(cols1)
            .zip(rail_only.par_chunks_mut(cols1))
            .enumerate()
            .for_each(|(r, (cen, rail))| {
                let interior_row = r >= 2 && r + 2 < rows;
                for c in 0..cen.len() {
                    let i = r * cols + c;
                    let mut m = [0f64; 8];
                    let mut v = [0f64; 8];
                    let k = if interior_row && c >= 2 && c + 2 < cols {
                        // All 8 on the sensor: the same values in the same order, by fixed
                        // offsets.
                        let (up, down) = (i - 2 * cols, i + 2 * cols);
                        let js = [up - 2, up, up + 2, i - 2, i + 2, down - 2, down, down + 2];
                        for (q, &j) in js.iter().enumerate() {
                            m[q] = mean_dn[j] as f64;
                            v[q] = if has_var { var_dn[j] as f64 } else { 0.0 };
                        }
                        8
                    } else {
                        neighbours(r, c, &mut m, &mut v)
                    };
                    let n_rail = self.n_low[i] + self.n_high[i];
                    let own = mean_dn[i] as f64;
                    cen[c] = censored_pixel(n_rail, &mut m[..k], &mut v[..k], own, max);
                    rail[c] = n_rail > 0 && !censored_pixel(0, &mut m[..k], &mut v[..k], own, max);
                }
            });
        ShotData {
            id,
            target,
            target_key,
            exposure_s,
            analog_gain,
            frames: self.frames,
            mean_dn,
            var_dn,
            n_low: self.n_low,
            n_high: self.n_high,
            censored,
            rail_only,
            temperature_c: None,
            first_frame: 0,
            row_means_dn: self.row_means,
        }
    }
}

/// Whether a pixel of a shot is compared through its rail counts rather than its mean and
/// variance: any frame at 0 DN or at the maximum, or a neighbourhood (same-channel
/// neighbours two pixels away) whose level lies within 6 local standard deviations (temporal
/// + spread of the neighbours, at least 3 DN) of a rail. The rule uses the data only, so the
/// censored set does not change with the model, and it looks at the neighbours rather than
/// the pixel's own noise, so keeping a pixel does not truncate its own distribution.
pub fn censored_pixel(
    n_rail: u16,
    neighbour_means: &mut [f64],
    neighbour_vars: &mut [f64],
    own_mean: f64,
    max_dn: f64,
) -> bool {
    if n_rail > 0 {
        return true;
    }
    // Quick exit without the medians (this runs for every pixel of every shot): the level
    // lies within the neighbours' range, the MAD is at most 1.4826 × that range and the
    // median variance at most the largest, so a range 6 such upper bounds away from both
    // rails cannot be censored by the rule below.
    if !neighbour_means.is_empty() {
        let (lo, hi) = neighbour_means
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
                (a.min(x), b.max(x))
            });
        let v_max = neighbour_vars.iter().fold(0f64, |a, &x| a.max(x));
        let s_ub = (v_max + (1.4826 * (hi - lo)).powi(2)).max(9.0).sqrt();
        if lo - 6.0 * s_ub > 0.0 && hi + 6.0 * s_ub < max_dn {
            return false;
        }
    }
    let level = if neighbour_means.is_empty() {
        own_mean
    } else {
        median(neighbour_means)
    };
    let mut dev_buf = [0f64; 8];
    let mad = 1.4826
        * if neighbour_means.len() <= dev_buf.len() {
            let dev = &mut dev_buf[..neighbour_means.len()];
            for (d, x) in dev.iter_mut().zip(neighbour_means.iter()) {
                *d = (x - level).abs();
            }
            median(dev)
        } else {
            let mut dev: Vec<f64> = neighbour_means.iter().map(|x| (x - level).abs()).collect();
            median(&mut dev)
        };
    let var_t = median(neighbour_vars);
    let s = (var_t.max(0.0) + if mad.is_finite() { mad * mad } else { 0.0 })
        .max(9.0)
        .sqrt();
    level - 6.0 * s <= 0.0 || level + 6.0 * s >= max_dn
}

/// The median of `x` in the order of [`f64::total_cmp`]: the middle value, or the mean of the
/// two middle values for an even count; NaN for none. Up to 8 values (a pixel's same-channel
/// neighbours, see [`censored_pixel`]) are ordered by a fixed 19-comparator sorting network
/// (Knuth, *The Art of Computer Programming* vol. 3, §5.3.4) on the values' total-order
/// keys, without touching `x`; the sorted sequence is the one `sort_by(f64::total_cmp)`
/// gives, so the median has the same bits. Longer inputs are sorted in place.
#[inline]
fn median(x: &mut [f64]) -> f64 {
    let n = x.len();
    if n == 0 {
        return f64::NAN;
    }
    if n > 8 {
        x.sort_by(|a, b| a.total_cmp(b));
        return if n % 2 == 1 {
            x[n / 2]
        } else {
            0.5 * (x[n / 2 - 1] + x[n / 2])
        };
    }
    // Padding keys sort after every value's key (ties only with identical bits).
    let mut k = [i64::MAX; 8];
    for (k, &v) in k.iter_mut().zip(x.iter()) {
        *k = total_order_key(v);
    }
    sort8_keys(&mut k);
    if n % 2 == 1 {
        total_order_value(k[n / 2])
    } else {
        0.5 * (total_order_value(k[n / 2 - 1]) + total_order_value(k[n / 2]))
    }
}

/// The integer whose signed order is [`f64::total_cmp`]'s order of `v` (the transform
/// `total_cmp` itself uses: negative values' magnitude bits flipped).
#[inline]
fn total_order_key(v: f64) -> i64 {
    let b = v.to_bits() as i64;
    b ^ ((((b >> 63) as u64) >> 1) as i64)
}

/// The inverse of [`total_order_key`] (the transform is its own inverse).
#[inline]
fn total_order_value(k: i64) -> f64 {
    f64::from_bits((k ^ ((((k >> 63) as u64) >> 1) as i64)) as u64)
}

/// The 19 comparators of the optimal sorting network for 8 inputs, in 6 layers (unrolled in
/// [`sort8_keys`]; the test checks both against each other).
#[cfg_attr(not(test), allow(dead_code))]
const SORT8_NETWORK: [(usize, usize); 19] = [
    (0, 2),
    (1, 3),
    (4, 6),
    (5, 7),
    (0, 4),
    (1, 5),
    (2, 6),
    (3, 7),
    (0, 1),
    (2, 3),
    (4, 5),
    (6, 7),
    (2, 4),
    (3, 5),
    (1, 4),
    (3, 6),
    (1, 2),
    (3, 4),
    (5, 6),
];

/// Sorts 8 keys ascending with [`SORT8_NETWORK`] (branch-free min/max), unrolled so the keys
/// stay in registers.
#[inline(always)]
fn sort8_keys(k: &mut [i64; 8]) {
    let [mut k0, mut k1, mut k2, mut k3, mut k4, mut k5, mut k6, mut k7] = *k;
    macro_rules! cmp_swap {
        ($($a:ident $b:ident),*) => {$(
            let (x, y) = ($a, $b);
            $a = x.min(y);
            $b = x.max(y);
        )*};
    }
    // The comparators of SORT8_NETWORK, in its order.
    cmp_swap!(k0 k2, k1 k3, k4 k6, k5 k7);
    cmp_swap!(k0 k4, k1 k5, k2 k6, k3 k7);
    cmp_swap!(k0 k1, k2 k3, k4 k5, k6 k7);
    cmp_swap!(k2 k4, k3 k5);
    cmp_swap!(k1 k4, k3 k6);
    cmp_swap!(k1 k2, k3 k4, k5 k6);
    *k = [k0, k1, k2, k3, k4, k5, k6, k7];
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn accumulator_mean_variance_and_rails() {
        let mut a = ShotAccumulator::new(1, 3, 10);
        a.add(&[0, 5, 10]).unwrap();
        a.add(&[2, 5, 10]).unwrap();
        a.add(&[4, 8, 9]).unwrap();
        assert!(a.add(&[1, 2]).is_err());
        assert!(a.add(&[1, 2, 11]).unwrap_err().contains("11"));
        let s = a.finish("s".into(), TargetClass::Dark, "k".into(), 0.1, 1.0);
        assert_eq!(s.frames, 3);
        assert_eq!(s.mean_dn, vec![2.0, 6.0, 29.0 / 3.0]);
        assert!((s.var_dn[0] - 4.0).abs() < 1e-6);
        assert!((s.var_dn[1] - 3.0).abs() < 1e-6);
        assert_eq!(s.n_low, vec![1, 0, 0]);
        assert_eq!(s.n_high, vec![0, 0, 2]);
        assert_eq!(s.censored, vec![true, true, true]);
        // A 10-DN range lies within 6 × 3 DN of a rail everywhere: the neighbourhood rule
        // alone censors every pixel.
        assert_eq!(s.rail_only, vec![false, false, false]);
    }

    /// The network sorts every 0/1 input of 8 (the 0-1 principle: then it sorts every input).
    #[test]
    fn sort8_network_sorts_all_zero_one_inputs() {
        for m in 0u32..256 {
            let mut k = [0i64; 8];
            for (i, k) in k.iter_mut().enumerate() {
                *k = ((m >> i) & 1) as i64;
            }
            let mut by_table = k;
            for &(a, b) in SORT8_NETWORK.iter() {
                let (x, y) = (by_table[a], by_table[b]);
                by_table[a] = x.min(y);
                by_table[b] = x.max(y);
            }
            sort8_keys(&mut k);
            assert!(k.windows(2).all(|w| w[0] <= w[1]), "input {m:08b} -> {k:?}");
            assert_eq!(k, by_table, "input {m:08b}");
        }
    }

    /// The median has the bits of the sort-based median it replaces, for every length up
    /// to 9, with ties, signed zeros, negative values and subnormals.
    #[test]
    fn median_matches_sorting_bit_for_bit() {
        fn by_sorting(x: &[f64]) -> f64 {
            let mut x = x.to_vec();
            x.sort_by(|a, b| a.total_cmp(b));
            let n = x.len();
            if n == 0 {
                f64::NAN
            } else if n % 2 == 1 {
                x[n / 2]
            } else {
                0.5 * (x[n / 2 - 1] + x[n / 2])
            }
        }
        let pool = [
            0.0, -0.0, 1.0, -1.0, 2.5, 2.5, 1e-310, -1e-310, 4095.0, 17.25, 3.0, -7.5, 1e300,
        ];
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        for n in 0..=9usize {
            for _ in 0..2000 {
                let x: Vec<f64> = (0..n)
                    .map(|_| {
                        state = state
                            .wrapping_mul(6364136223846793005)
                            .wrapping_add(1442695040888963407);
                        let r = (state >> 33) as usize;
                        if r % 3 == 0 {
                            pool[r % pool.len()]
                        } else {
                            (r % 100_000) as f64 / 7.0 - 5000.0
                        }
                    })
                    .collect();
                let mut y = x.clone();
                let (a, b) = (median(&mut y), by_sorting(&x));
                assert!(
                    a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()),
                    "{x:?}: {a} vs {b}"
                );
            }
        }
    }

    /// The censoring pass (interior pixels by fixed offsets, edge pixels by the bounds-checked
    /// walk) gives, pixel by pixel, what the rule gives on each pixel's neighbours gathered
    /// directly; on frames with levels near both rails and in between, so every branch of the
    /// rule occurs.
    #[test]
    fn censoring_pass_matches_the_rule_per_pixel() {
        let (rows, cols, max) = (9usize, 11usize, 4095u16);
        let mut state = 7u64;
        let mut next = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 33) as u32
        };
        for frames in [1usize, 3] {
            let mut a = ShotAccumulator::new(rows, cols, max);
            // dark columns (censored by the neighbourhood), mid-level columns with two dead
            // pixels (censored by their own rail frames only), columns at the top rail
            let level: Vec<u32> = (0..rows * cols)
                .map(|i| match (i / cols, i % cols) {
                    (4, 5) | (6, 5) => 0,
                    (_, c) if c < 2 => 5,
                    (_, c) if c < 9 => 2000,
                    _ => 4093,
                })
                .collect();
            for _ in 0..frames {
                let f: Vec<u16> = level
                    .iter()
                    .map(|&l| (l + next() % 5).saturating_sub(2).min(max as u32) as u16)
                    .collect();
                a.add(&f).unwrap();
            }
            let (n_low, n_high) = (a.n_low.clone(), a.n_high.clone());
            let s = a.finish("s".into(), TargetClass::Uniform, "k".into(), 0.1, 1.0);
            let (mut n_cen, mut n_rail_only) = (0, 0);
            for r in 0..rows {
                for c in 0..cols {
                    let (mut m, mut v) = (Vec::new(), Vec::new());
                    for dr in [-2i64, 0, 2] {
                        for dc in [-2i64, 0, 2] {
                            let (rr, cc) = (r as i64 + dr, c as i64 + dc);
                            if (dr, dc) != (0, 0)
                                && (0..rows as i64).contains(&rr)
                                && (0..cols as i64).contains(&cc)
                            {
                                let j = rr as usize * cols + cc as usize;
                                m.push(s.mean_dn[j] as f64);
                                v.push(s.var_dn.get(j).map_or(0.0, |&x| x as f64));
                            }
                        }
                    }
                    let i = r * cols + c;
                    let n_rail = n_low[i] + n_high[i];
                    let own = s.mean_dn[i] as f64;
                    let cen = censored_pixel(n_rail, &mut m, &mut v, own, max as f64);
                    let by_rails =
                        n_rail > 0 && !censored_pixel(0, &mut m, &mut v, own, max as f64);
                    assert_eq!(
                        s.censored[i], cen,
                        "censored at ({r}, {c}), {frames} frames"
                    );
                    assert_eq!(s.rail_only[i], by_rails, "rail_only at ({r}, {c})");
                    n_cen += cen as usize;
                    n_rail_only += by_rails as usize;
                }
            }
            assert!(n_cen > 0 && n_cen < rows * cols, "{n_cen} censored");
            if frames > 1 {
                assert!(n_rail_only > 0, "no rail-only pixel");
            }
        }
    }
}
