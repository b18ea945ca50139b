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
        let zeros = vec![0f32; if has_var { 0 } else { cols1 }];
        censored
            .par_chunks_mut(cols1)
            .zip(rail_only.par_chunks_mut(cols1))
            .enumerate()
            .for_each(|(r, (cen, rail))| {
                // The neighbourhood rule (no rail frames) of every pixel of the row: interior
                // pixels LANES at once (same decisions, see neighbourhood_rule_lanes), the
                // rest by censored_pixel on the bounds-checked neighbours.
                let mut by_neighbours = vec![false; cen.len()];
                let mut c = 0;
                if r >= 2 && r + 2 < rows && cols >= 4 + LANES {
                    let row = |dr: usize| (r + dr - 2) * cols;
                    let m_rows = [0, 2, 4].map(|dr| &mean_dn[row(dr)..row(dr) + cols]);
                    let v_rows = [0, 2, 4].map(|dr| {
                        if has_var {
                            &var_dn[row(dr)..row(dr) + cols]
                        } else {
                            &zeros[..]
                        }
                    });
                    c = 2;
                    while c + LANES + 2 <= cols {
                        // the 8 neighbours (rows r−2, r, r+2 × columns c−2, c, c+2 without
                        // the centre) of pixels c..c+LANES, as contiguous runs
                        let mut m = [[0f32; LANES]; 8];
                        let mut v = [[0f32; LANES]; 8];
                        let mut k = 0;
                        for (q, (mr, vr)) in m_rows.iter().zip(&v_rows).enumerate() {
                            for dc in [0, 2, 4] {
                                if q == 1 && dc == 2 {
                                    continue;
                                }
                                let at = c + dc - 2;
                                m[k].copy_from_slice(&mr[at..at + LANES]);
                                v[k].copy_from_slice(&vr[at..at + LANES]);
                                k += 1;
                            }
                        }
                        by_neighbours[c..c + LANES]
                            .copy_from_slice(&neighbourhood_rule_lanes(&m, &v, max));
                        c += LANES;
                    }
                }
                for (cc, n) in by_neighbours.iter_mut().enumerate() {
                    if (2..c).contains(&cc) {
                        continue;
                    }
                    let mut m = [0f64; 8];
                    let mut v = [0f64; 8];
                    let k = neighbours(r, cc, &mut m, &mut v);
                    let own = mean_dn[r * cols + cc] as f64;
                    *n = censored_pixel(0, &mut m[..k], &mut v[..k], own, max);
                }
                for c in 0..cen.len() {
                    let i = r * cols + c;
                    let at_rail = self.n_low[i] + self.n_high[i] > 0;
                    cen[c] = at_rail || by_neighbours[c];
                    rail[c] = at_rail && !by_neighbours[c];
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
    if neighbourhood_clears_rails(neighbour_means, neighbour_vars, max_dn) {
        return false;
    }
    neighbourhood_rule(neighbour_means, neighbour_vars, own_mean, max_dn)
}

/// A quick exit of [`censored_pixel`] without the medians (it runs for every pixel at the
/// sensor's edges; the interior goes through [`neighbourhood_rule_lanes`]): true only when
/// [`neighbourhood_rule`] is false. The level lies within the neighbours' range [lo, hi],
/// the MAD is at most 1.4826 × (hi − lo) and the median variance at most the largest, so a
/// range 6 such upper bounds away from both rails cannot be censored. Rounding is monotone,
/// so the bound holds for the computed values too; a NaN only lowers the rule's spread (its
/// medians sort it last, the `max`es drop it) and ±∞ fails the bound.
fn neighbourhood_clears_rails(
    neighbour_means: &[f64],
    neighbour_vars: &[f64],
    max_dn: f64,
) -> bool {
    if neighbour_means.is_empty() {
        return false;
    }
    let (lo, hi) = neighbour_means
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
            (a.min(x), b.max(x))
        });
    let v_max = neighbour_vars.iter().fold(0f64, |a, &x| a.max(x));
    let s_ub = (v_max + (1.4826 * (hi - lo)).powi(2)).max(9.0).sqrt();
    lo - 6.0 * s_ub > 0.0 && hi + 6.0 * s_ub < max_dn
}

/// The neighbourhood part of [`censored_pixel`] in full (the medians): the level (median of
/// the neighbours' means, the pixel's own mean without neighbours) within 6 local standard
/// deviations √(median temporal variance + (1.4826 · MAD)²), at least 3 DN, of a rail.
fn neighbourhood_rule(
    neighbour_means: &mut [f64],
    neighbour_vars: &mut [f64],
    own_mean: f64,
    max_dn: f64,
) -> bool {
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

/// Pixels per call of [`neighbourhood_rule_lanes`].
const LANES: usize = 8;

/// [`censored_pixel`]'s neighbourhood rule (no rail frames) for `LANES` pixels at once:
/// `m[k][j]`, `v[k][j]` are the mean and temporal variance (0 without one) of the k-th of the
/// 8 same-channel neighbours of pixel j, in any order (the rule uses only their medians).
///
/// For finite values ≥ +0 — what [`ShotAccumulator::finish`] produces: means of integer sums,
/// variances clamped at 0 — the decisions and every intermediate value are those of
/// [`censored_pixel`] (which the pass uses at the sensor's edges and the tests compare with):
/// on such values `<` orders as [`f64::total_cmp`] does, and the f32 → f64 conversion is exact
/// and monotone, so sorting the f32 values lane by lane with the same network ([`SORT8_NETWORK`])
/// gives the same middle pair and hence the same level and median variance. The deviations
/// from the level are two ascending runs, a = |x₃ − L| ≤ |x₂ − L| ≤ … (below the level) and
/// b = |x₄ − L| ≤ |x₅ − L| ≤ … (above it; x₃ ≤ L ≤ x₄, and rounding is monotone), so their
/// 4th and 5th smallest — the MAD's middle pair — are the order statistics of a merge of two
/// sorted runs: min over the splits i of max(a_(i−1), b_(k−i−1)) (Knuth, *The Art of Computer
/// Programming* vol. 3, §5.3.2, merging), the same values the sort gives. Written with
/// fixed-size lane arrays and branch-free selections so that the compiler turns them into
/// vector min/max instructions (SSE2 `minps`/`maxps`).
#[inline(always)]
fn neighbourhood_rule_lanes(
    m: &[[f32; LANES]; 8],
    v: &[[f32; LANES]; 8],
    max_dn: f64,
) -> [bool; LANES] {
    let mut m = *m;
    let mut v = *v;
    sort8_lanes(&mut m);
    sort8_lanes(&mut v);
    let mut out = [false; LANES];
    for j in 0..LANES {
        let x: [f64; 8] = std::array::from_fn(|k| m[k][j] as f64);
        let level = 0.5 * (x[3] + x[4]);
        let a: [f64; 4] = std::array::from_fn(|i| (x[3 - i] - level).abs());
        let b: [f64; 4] = std::array::from_fn(|i| (x[4 + i] - level).abs());
        let (mn, mx) = (lane_min::<f64>, lane_max::<f64>);
        let d3 = mn(
            mn(mn(b[3], a[3]), mx(a[0], b[2])),
            mn(mx(a[1], b[1]), mx(a[2], b[0])),
        );
        let d4 = mn(
            mn(mx(a[0], b[3]), mx(a[1], b[2])),
            mn(mx(a[2], b[1]), mx(a[3], b[0])),
        );
        let mad = 1.4826 * (0.5 * (d3 + d4));
        let var_t = 0.5 * (v[3][j] as f64 + v[4][j] as f64);
        let s = (var_t.max(0.0) + if mad.is_finite() { mad * mad } else { 0.0 })
            .max(9.0)
            .sqrt();
        out[j] = level - 6.0 * s <= 0.0 || level + 6.0 * s >= max_dn;
    }
    out
}

/// The smaller of two values (the first when equal): `minps`/`minpd` for non-NaN values.
#[inline(always)]
fn lane_min<T: PartialOrd>(a: T, b: T) -> T {
    if b < a {
        b
    } else {
        a
    }
}

/// The larger of two values (the second when equal, so that a compare-exchange permutes its
/// pair): `maxps`/`maxpd` for non-NaN values.
#[inline(always)]
fn lane_max<T: PartialOrd>(a: T, b: T) -> T {
    if b < a {
        a
    } else {
        b
    }
}

/// Sorts each lane j of `x[0][j] … x[7][j]` ascending with [`SORT8_NETWORK`] (for values
/// that `<` orders totally: no NaN), unrolled so that the rows stay in registers.
#[inline(always)]
fn sort8_lanes<T: PartialOrd + Copy>(x: &mut [[T; LANES]; 8]) {
    macro_rules! cmp_swap {
        ($($p:literal $q:literal),*) => {$(
            for j in 0..LANES {
                let (a, b) = (x[$p][j], x[$q][j]);
                x[$p][j] = lane_min(a, b);
                x[$q][j] = lane_max(a, b);
            }
        )*};
    }
    // The comparators of SORT8_NETWORK, in its order.
    cmp_swap!(0 2, 1 3, 4 6, 5 7);
    cmp_swap!(0 4, 1 5, 2 6, 3 7);
    cmp_swap!(0 1, 2 3, 4 5, 6 7);
    cmp_swap!(2 4, 3 5);
    cmp_swap!(1 4, 3 6);
    cmp_swap!(1 2, 3 4, 5 6);
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
/// [`sort8_keys`] and [`sort8_lanes`]; the test checks them against it).
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
            // the lanes: input m in lane 0, its complement in lane 1, the rest constant
            let mut lanes = [[0f32; LANES]; 8];
            for (i, row) in lanes.iter_mut().enumerate() {
                row[0] = k[i] as f32;
                row[1] = 1.0 - k[i] as f32;
                row[2] = 7.0;
            }
            sort8_keys(&mut k);
            assert!(k.windows(2).all(|w| w[0] <= w[1]), "input {m:08b} -> {k:?}");
            assert_eq!(k, by_table, "input {m:08b}");
            sort8_lanes(&mut lanes);
            for (i, row) in lanes.iter().enumerate() {
                assert_eq!(row[0], by_table[i] as f32, "lane 0, input {m:08b}");
                assert_eq!(row[2], 7.0);
            }
            assert!(
                lanes.windows(2).all(|w| w[0][1] <= w[1][1]),
                "lane 1, input {m:08b}"
            );
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

    /// The censoring pass (interior pixels LANES at a time by neighbourhood_rule_lanes, the
    /// rest by censored_pixel on the bounds-checked walk) gives, pixel by pixel, what the rule
    /// gives on each pixel's neighbours gathered directly; on frames with levels near both
    /// rails, levels whose neighbourhoods straddle the rule's thresholds, and in between, on
    /// a sensor too narrow for the lanes and on one with lanes, remainder and edge columns.
    #[test]
    fn censoring_pass_matches_the_rule_per_pixel() {
        for (rows, cols) in [(9usize, 11usize), (12, 37)] {
            censoring_pass_matches_the_rule_on(rows, cols);
        }
    }

    fn censoring_pass_matches_the_rule_on(rows: usize, cols: usize) {
        let max = 4095u16;
        let mut state = 7u64;
        let mut next = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 33) as u32
        };
        // levels whose 6-σ neighbourhoods (σ ≥ 3 DN) reach a rail for some noise draws
        const NEAR: [u32; 12] = [14, 17, 19, 21, 23, 26, 30, 4060, 4066, 4070, 4074, 4078];
        for frames in [1usize, 3] {
            let mut a = ShotAccumulator::new(rows, cols, max);
            // dark columns (censored by the neighbourhood), mid-level columns with two dead
            // pixels (censored by their own rail frames only), columns at the top rail
            // and columns near the thresholds with a noise amplitude that changes by row
            let level: Vec<u32> = (0..rows * cols)
                .map(|i| match (i / cols, i % cols) {
                    (4, 5) | (6, 5) => 0,
                    (_, c) if c < 2 => 5,
                    (_, c) if c < 9 => 2000,
                    (_, c) if c < 11 => 4093,
                    (_, c) => NEAR[(c - 11) % NEAR.len()],
                })
                .collect();
            for _ in 0..frames {
                let f: Vec<u16> = level
                    .iter()
                    .enumerate()
                    .map(|(i, &l)| {
                        let amp = if i % cols < 11 {
                            2
                        } else {
                            1 + 3 * (i / cols % 4) as u32
                        };
                        (l + next() % (2 * amp + 1))
                            .saturating_sub(amp)
                            .min(max as u32) as u16
                    })
                    .collect();
                a.add(&f).unwrap();
            }
            let (n_low, n_high) = (a.n_low.clone(), a.n_high.clone());
            let s = a.finish("s".into(), TargetClass::Uniform, "k".into(), 0.1, 1.0);
            let (mut n_cen, mut n_rail_only, mut n_near) = (0, 0, [0usize; 2]);
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
                    if c >= 11 && n_rail == 0 {
                        n_near[cen as usize] += 1;
                    }
                }
            }
            assert!(n_cen > 0 && n_cen < rows * cols, "{n_cen} censored");
            // both outcomes near the thresholds, without rail frames
            assert!(cols <= 11 || n_near.iter().all(|&n| n > 0), "{n_near:?}");
            if frames > 1 {
                assert!(n_rail_only > 0, "no rail-only pixel");
            }
        }
    }

    /// A small deterministic generator for the adversarial tests.
    struct Lcg(u64);
    impl Lcg {
        fn next(&mut self) -> u64 {
            self.0 = self
                .0
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            self.0 >> 11
        }
        /// Uniform in [0, 1).
        fn unit(&mut self) -> f64 {
            self.next() as f64 / (1u64 << 53) as f64
        }
        fn below(&mut self, n: usize) -> usize {
            (self.next() % n as u64) as usize
        }
    }

    /// Neighbourhoods built to sit on the rule's thresholds: means with ties (one value,
    /// two values at ±δ, or spread offsets), variances equal or spread, the level set so that
    /// the lower (or upper) 6-σ limit lies within ±2 % of the rail (σ from the full rule on
    /// the offsets), plus pool values (0, the maximum, subnormals; with `wild`, negative
    /// zero, negative values, NaN of both signs and ±∞). Returns (means, variances).
    fn adversarial(g: &mut Lcg, n: usize, max_dn: f64, wild: bool) -> (Vec<f64>, Vec<f64>) {
        let kind = g.below(4);
        let delta = [0.0, 0.5, 3.0, 40.0][g.below(4)] * g.unit();
        let offs: Vec<f64> = (0..n)
            .map(|k| match kind {
                0 => 0.0,
                1 => {
                    if k % 2 == 0 {
                        -delta
                    } else {
                        delta
                    }
                }
                2 => delta * (2.0 * g.unit() - 1.0),
                _ => (delta * (2.0 * g.unit() - 1.0)).round(),
            })
            .collect();
        let v_level = [0.0, 4.0, 9.0, 30.0, 500.0][g.below(5)];
        let vars: Vec<f64> = (0..n)
            .map(|_| {
                if g.below(2) == 0 {
                    v_level
                } else {
                    v_level * 2.0 * g.unit()
                }
            })
            .collect();
        // σ of the rule on the offsets alone (the MAD and the median variance do not
        // depend on the level but through rounding)
        let (mut m0, mut v0) = (offs.clone(), vars.clone());
        let level0 = if n == 0 { 0.0 } else { median(&mut m0) };
        let mut dev: Vec<f64> = offs.iter().map(|x| (x - level0).abs()).collect();
        let mad = 1.4826 * if n == 0 { 0.0 } else { median(&mut dev) };
        let var_t = if n == 0 { 0.0 } else { median(&mut v0) };
        let s = (var_t.max(0.0) + mad * mad).max(9.0).sqrt();
        let eps = 0.02 * (2.0 * g.unit() - 1.0);
        let level = if g.below(2) == 0 {
            6.0 * s * (1.0 + eps) - level0
        } else {
            max_dn - 6.0 * s * (1.0 + eps) - level0
        };
        let mut means: Vec<f64> = offs.iter().map(|o| level + o).collect();
        let pool = [
            0.0,
            max_dn,
            max_dn - 1e-9,
            5e-324,
            1e-310,
            -0.0,
            -3.0,
            f64::NAN,
            -f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ];
        let n_pool = if wild { pool.len() } else { 5 };
        for x in means.iter_mut() {
            if g.below(8) == 0 {
                *x = pool[g.below(n_pool)];
            }
        }
        let mut vars = vars;
        for x in vars.iter_mut() {
            if g.below(10) == 0 {
                *x = pool[g.below(n_pool)]
                    .abs()
                    .min(if wild { f64::INFINITY } else { 1e6 });
                if wild && g.below(3) == 0 {
                    *x = pool[g.below(n_pool)];
                }
            }
        }
        (means, vars)
    }

    /// The quick exit is exact: whenever the bound clears a neighbourhood, the full rule
    /// (the medians) does not censor it; on neighbourhoods that straddle the thresholds with
    /// ties, NaN, ±∞, saturated and negative values, for every neighbour count 0–8. The
    /// bound must also clear most cleared-by-the-rule neighbourhoods far from the rails
    /// (a quick exit that never fires is exact too but useless).
    #[test]
    fn quick_exit_clears_only_what_the_rule_keeps() {
        let max_dn = 4095.0;
        let mut g = Lcg(0x5eed);
        let (mut cleared, mut kept, mut tight) = (0usize, 0usize, 0usize);
        for trial in 0..400_000 {
            let n = trial % 9;
            let (m, v) = adversarial(&mut g, n, max_dn, true);
            let clears = neighbourhood_clears_rails(&m, &v, max_dn);
            let (mut m2, mut v2) = (m.clone(), v.clone());
            let rule = neighbourhood_rule(&mut m2, &mut v2, 100.0, max_dn);
            assert!(
                !(clears && rule),
                "bound clears a censored neighbourhood: {m:?} {v:?}"
            );
            cleared += clears as usize;
            kept += !rule as usize;
            // cleared although a 6-σ limit lies within 1 % of a rail
            if clears && n > 0 {
                let (lo, hi) = m
                    .iter()
                    .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
                        (a.min(x), b.max(x))
                    });
                let v_max = v.iter().fold(0f64, |a, &x| a.max(x));
                let s_ub = (v_max + (1.4826 * (hi - lo)).powi(2)).max(9.0).sqrt();
                if lo < 6.06 * s_ub || hi + 6.06 * s_ub > max_dn {
                    tight += 1;
                }
            }
        }
        assert!(cleared > kept / 10, "cleared {cleared} of {kept} kept");
        assert!(
            tight > 100,
            "only {tight} cleared neighbourhoods near the bound"
        );
        // far from the rails the bound clears: a flat-field neighbourhood
        let m = [
            2000.0, 2001.5, 1998.0, 2003.0, 1999.0, 2000.5, 2002.0, 1997.5,
        ];
        let v = [30.0, 28.0, 35.0, 31.0, 29.5, 33.0, 30.5, 27.0];
        assert!(neighbourhood_clears_rails(&m, &v, max_dn));
    }

    /// The lane rule gives censored_pixel's decision for every lane, on neighbourhoods of
    /// finite values ≥ 0 (what the accumulator produces) built to straddle the thresholds,
    /// with ties, zeros, saturated values, subnormals and large variances, in random
    /// neighbour order; both outcomes occur, many within 2 % of a threshold.
    #[test]
    fn lane_rule_matches_censored_pixel() {
        let max_dn = 4095.0;
        let mut g = Lcg(0x1a9e5);
        let mut seen = [0usize; 2];
        for _ in 0..60_000 {
            let mut m = [[0f32; LANES]; 8];
            let mut v = [[0f32; LANES]; 8];
            for j in 0..LANES {
                let (mj, vj) = adversarial(&mut g, 8, max_dn, false);
                for k in 0..8 {
                    m[k][j] = mj[k].clamp(0.0, max_dn) as f32;
                    v[k][j] = vj[k].max(0.0) as f32;
                }
            }
            let got = neighbourhood_rule_lanes(&m, &v, max_dn);
            for j in 0..LANES {
                let mut mj: Vec<f64> = (0..8).map(|k| m[k][j] as f64).collect();
                let mut vj: Vec<f64> = (0..8).map(|k| v[k][j] as f64).collect();
                let want = censored_pixel(0, &mut mj, &mut vj, 0.0, max_dn);
                assert_eq!(got[j], want, "lane {j}: means {mj:?} variances {vj:?}");
                seen[want as usize] += 1;
            }
        }
        assert!(seen.iter().all(|&n| n > 50_000), "{seen:?}");
    }
}
