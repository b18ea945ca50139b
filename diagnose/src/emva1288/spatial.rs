//! Spatial nonuniformity (Rel. 4.0 §8): DSNU₁₂₈₈ and PRNU₁₂₈₈ with their row, column and
//! pixel parts, the horizontal and vertical spectrograms and the histograms, from a stack of
//! L bright frames (about 50 % saturation) and a stack of L dark frames at the same exposure.
use super::{LineFit, Measured};
use rayon::prelude::*;
use rustfft::num_complex::Complex;
use rustfft::FftPlanner;
use serde::Serialize;

/// Per-pixel sums of a stack of frames, filled one frame at a time.
#[derive(Debug, Clone)]
pub struct StackAccumulator {
    /// Rows M.
    pub rows: usize,
    /// Columns N.
    pub cols: usize,
    /// Frames added L.
    pub frames: u32,
    sum: Vec<u64>,
    sum_sq: Vec<u64>,
}

impl StackAccumulator {
    /// An empty stack of `rows × cols` frames.
    pub fn new(rows: usize, cols: usize) -> Self {
        StackAccumulator {
            rows,
            cols,
            frames: 0,
            sum: vec![0; rows * cols],
            sum_sq: vec![0; rows * cols],
        }
    }

    /// Adds one row-major frame; a frame of another size is an error naming both sizes.
    pub fn add(&mut self, dn: &[u16]) -> Result<(), String> {
        self.add_frames(&[dn])
    }

    /// Adds several row-major frames; a frame of another size is an error naming both sizes
    /// (and nothing is added). The sums are integers, so they are the same as adding the
    /// frames one by one in any order; adding them together a tile of pixels at a time loads
    /// and stores each tile of the sums once per call instead of once per frame.
    pub fn add_frames(&mut self, frames: &[&[u16]]) -> Result<(), String> {
        const TILE: usize = 4096;
        if let Some(f) = frames.iter().find(|f| f.len() != self.sum.len()) {
            return Err(format!(
                "frame has {} pixels, the stack is {}×{}",
                f.len(),
                self.rows,
                self.cols
            ));
        }
        self.sum
            .par_chunks_mut(TILE)
            .zip(self.sum_sq.par_chunks_mut(TILE))
            .enumerate()
            .for_each(|(t, (s, q))| {
                let start = t * TILE;
                for f in frames {
                    let d = &f[start..start + s.len()];
                    for ((s, q), &v) in s.iter_mut().zip(q.iter_mut()).zip(d) {
                        // v² < 2³², so the square is exact in u32.
                        let v = v as u32;
                        *s += v as u64;
                        *q += (v * v) as u64;
                    }
                }
            });
        self.frames += frames.len() as u32;
        Ok(())
    }

    /// The average image ⟨y⟩ = (1/L) Σ_l y_l (DN), row-major.
    pub fn average(&self) -> Vec<f64> {
        let l = self.frames as f64;
        self.sum.iter().map(|&s| s as f64 / l).collect()
    }
}

/// Statistics of one stack (Rel. 4.0 §8, evaluation of the spatial variances).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct StackStats {
    /// Rows M.
    pub rows: usize,
    /// Columns N.
    pub cols: usize,
    /// Frames L.
    pub frames: u32,
    /// Spatial mean μ_y of the average image (DN).
    pub mean_dn: f64,
    /// Temporal variance of the stack σ²_y.stack: the mean over pixels of the per-pixel
    /// variance across the L frames (DN²).
    pub var_stack_dn2: f64,
    /// Spatial variance of the average image s²_y.measured (DN², divisor MN − 1).
    pub var_measured_dn2: f64,
    /// Spatial variance corrected for the residual temporal noise, s²_y (DN²).
    pub s2_dn2: f64,
    /// Variance of the column means, corrected (s²_y.cav, DN²).
    pub s2_cav_dn2: f64,
    /// Variance of the row means, corrected (s²_y.rav, DN²).
    pub s2_rav_dn2: f64,
}

/// Stack statistics (Rel. 4.0 §8):
/// `σ²_y.stack = (1/MN) Σ_pixels 1/(L−1) Σ_l (y_l − ⟨y⟩)²`,
/// `s²_y = s²_y.measured − σ²_y.stack / L` (the average image still holds 1/L of the temporal
/// variance), and for the column and row means
/// `s²_y.cav = (1/N) Σ_n (μ_y[n] − μ_y)² − σ²_y.stack/(L M)`,
/// `s²_y.rav = (1/M) Σ_m (μ_y[m] − μ_y)² − σ²_y.stack/(L N)`.
pub fn stack_stats(acc: &StackAccumulator) -> StackStats {
    let (m, n) = (acc.rows, acc.cols);
    let l = acc.frames as f64;
    let avg = acc.average();
    let mn = (m * n) as f64;
    let mean = avg.iter().sum::<f64>() / mn;
    // Per-pixel variance across the stack from the integer sums (exact numerators):
    // (L Σy² − (Σy)²) / (L (L − 1)); their sum is exact too (u128), so it does not depend on
    // the order in which the threads add.
    let var_stack = acc
        .sum
        .par_iter()
        .zip(acc.sum_sq.par_iter())
        .map(|(&s, &q)| {
            let li = acc.frames as u128;
            li * q as u128 - (s as u128) * (s as u128)
        })
        .sum::<u128>() as f64
        / (l * (l - 1.0))
        / mn;
    let var_measured = avg.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (mn - 1.0);
    let col_means: Vec<f64> = (0..n)
        .map(|c| (0..m).map(|r| avg[r * n + c]).sum::<f64>() / m as f64)
        .collect();
    let row_means: Vec<f64> = avg
        .chunks(n)
        .map(|row| row.iter().sum::<f64>() / n as f64)
        .collect();
    let cav = col_means.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n as f64
        - var_stack / (l * m as f64);
    let rav = row_means.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / m as f64
        - var_stack / (l * n as f64);
    StackStats {
        rows: m,
        cols: n,
        frames: acc.frames,
        mean_dn: mean,
        var_stack_dn2: var_stack,
        var_measured_dn2: var_measured,
        s2_dn2: var_measured - var_stack / l,
        s2_cav_dn2: cav,
        s2_rav_dn2: rav,
    }
}

/// The row, column and pixel parts of a spatial variance (DN²).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct VarianceParts {
    /// Total s²_y.
    pub total_dn2: f64,
    /// Row part s²_y.row.
    pub row_dn2: f64,
    /// Column part s²_y.col.
    pub col_dn2: f64,
    /// Pixel part s²_y.pixel.
    pub pixel_dn2: f64,
}

/// Splits s²_y into row, column and pixel variances (Rel. 4.0 §8, the unbiased estimators
/// from the variances of the row and column means):
/// `s²_col = (MN−M)/(MN−M−N) s²_cav − N/(MN−M−N) (s²_y − s²_rav)`,
/// `s²_row = (MN−N)/(MN−M−N) s²_rav − M/(MN−M−N) (s²_y − s²_cav)`,
/// `s²_pixel = MN/(MN−M−N) (s²_y − s²_cav − s²_rav)`.
pub fn variance_parts(s: &StackStats) -> VarianceParts {
    let (m, n) = (s.rows as f64, s.cols as f64);
    let d = m * n - m - n;
    VarianceParts {
        total_dn2: s.s2_dn2,
        col_dn2: (m * n - m) / d * s.s2_cav_dn2 - n / d * (s.s2_dn2 - s.s2_rav_dn2),
        row_dn2: (m * n - n) / d * s.s2_rav_dn2 - m / d * (s.s2_dn2 - s.s2_cav_dn2),
        pixel_dn2: m * n / d * (s.s2_dn2 - s.s2_cav_dn2 - s.s2_rav_dn2),
    }
}

/// DSNU₁₂₈₈ in electrons, `√s²_y.dark / K` (Rel. 4.0 §8); NaN for a negative variance.
pub fn dsnu_electrons(s2_dark_dn2: f64, k: f64) -> f64 {
    if s2_dark_dn2 < 0.0 {
        f64::NAN
    } else {
        s2_dark_dn2.sqrt() / k
    }
}

/// PRNU₁₂₈₈ in percent, `100 √(s²_y − s²_y.dark) / (μ_y − μ_y.dark)` (Rel. 4.0 §8); NaN for
/// a negative difference.
pub fn prnu_percent(s2_dn2: f64, s2_dark_dn2: f64, mean_dn: f64, dark_mean_dn: f64) -> f64 {
    let d = s2_dn2 - s2_dark_dn2;
    if d < 0.0 {
        f64::NAN
    } else {
        100.0 * d.sqrt() / (mean_dn - dark_mean_dn)
    }
}

/// Standard uncertainty of a spatial variance s² from MN pixels under a normal model,
/// `√(2/(MN−1)) · s²_measured` (the sampling error the standard's "uncertainty of the spatial
/// variance" budget is dominated by).
pub fn spatial_variance_uncertainty(s: &StackStats) -> f64 {
    (2.0 / ((s.rows * s.cols) as f64 - 1.0)).sqrt() * s.var_measured_dn2
}

/// A spectrogram: power per spatial frequency, averaged over lines (Rel. 4.0 §8,
/// horizontal and vertical spectrograms).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Spectrogram {
    /// Spatial frequency (cycles/pixel), 0 … 0.5.
    pub frequency_per_px: Vec<f64>,
    /// Power (DN²) per frequency: `(1/L_lines) Σ_lines |DFT(y − μ_y)|² / N`.
    pub power_dn2: Vec<f64>,
}

/// The horizontal (`vertical = false`: a DFT along each row) or vertical spectrogram of an
/// average image: the mean is removed, each line transformed, `|Y(k)|²/N` averaged over
/// the lines; frequencies 0 … N/2 (Rel. 4.0 §8). Its square root is the nonuniformity per
/// frequency; the mean of the full spectrum equals the spatial variance (Parseval).
pub fn spectrogram(avg: &[f64], rows: usize, cols: usize, vertical: bool) -> Spectrogram {
    let mean = avg.iter().sum::<f64>() / avg.len() as f64;
    let (lines, len) = if vertical { (cols, rows) } else { (rows, cols) };
    let fft = FftPlanner::<f64>::new().plan_fft_forward(len);
    let half = len / 2 + 1;
    // Lines are transformed in parallel in fixed groups whose sums are added in group order,
    // so the result does not depend on the thread count or the scheduling.
    const GROUP: usize = 16;
    let partial: Vec<Vec<f64>> = (0..lines.div_ceil(GROUP))
        .into_par_iter()
        .map(|g| {
            let mut acc = vec![0.0; half];
            let mut buf: Vec<Complex<f64>> = Vec::with_capacity(len);
            for i in g * GROUP..((g + 1) * GROUP).min(lines) {
                buf.clear();
                buf.extend((0..len).map(|j| {
                    let v = if vertical {
                        avg[j * cols + i]
                    } else {
                        avg[i * cols + j]
                    };
                    Complex::new(v - mean, 0.0)
                }));
                fft.process(&mut buf);
                for (a, c) in acc.iter_mut().zip(&buf[..half]) {
                    *a += c.norm_sqr() / len as f64;
                }
            }
            acc
        })
        .collect();
    let mut power = vec![0.0; half];
    for p in partial {
        for (x, y) in power.iter_mut().zip(p) {
            *x += y;
        }
    }
    Spectrogram {
        frequency_per_px: (0..half).map(|k| k as f64 / len as f64).collect(),
        power_dn2: power.into_iter().map(|p| p / lines as f64).collect(),
    }
}

/// A histogram with equal bins.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Histogram {
    /// Lower edge of each bin.
    pub bin_lower: Vec<f64>,
    /// Count per bin.
    pub counts: Vec<u64>,
}

/// Histogram of `v` in `bins` equal bins between its minimum and maximum.
pub fn histogram(v: &[f64], bins: usize) -> Histogram {
    let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let w = ((hi - lo) / bins as f64).max(1e-12);
    let mut counts = vec![0u64; bins];
    for x in v {
        counts[(((x - lo) / w) as usize).min(bins - 1)] += 1;
    }
    Histogram {
        bin_lower: (0..bins).map(|i| lo + i as f64 * w).collect(),
        counts,
    }
}

/// The 5 × 5 high-pass filter of Rel. 4.0 §8 (defect pixels, PRNU histogram):
/// `y' = y − R ∗ y` with R the 5 × 5 box average; the two-pixel border is dropped.
pub fn high_pass_5x5(img: &[f64], rows: usize, cols: usize) -> (Vec<f64>, usize, usize) {
    if rows < 5 || cols < 5 {
        return (Vec::new(), 0, 0);
    }
    let (r2, c2) = (rows - 4, cols - 4);
    let out = (0..r2)
        .into_par_iter()
        .flat_map_iter(|r| {
            (0..c2).map(move |c| {
                let mut s = 0.0;
                for dr in 0..5 {
                    for dc in 0..5 {
                        s += img[(r + dr) * cols + c + dc];
                    }
                }
                img[(r + 2) * cols + c + 2] - s / 25.0
            })
        })
        .collect();
    (out, r2, c2)
}

/// The spatial part of the datasheet.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SpatialResult {
    /// Bright stack statistics.
    pub bright: StackStats,
    /// Dark stack statistics.
    pub dark: StackStats,
    /// Row / column / pixel parts of the bright spatial variance.
    pub bright_parts: VarianceParts,
    /// Row / column / pixel parts of the dark spatial variance.
    pub dark_parts: VarianceParts,
    /// DSNU₁₂₈₈ (e⁻).
    pub dsnu_e: Measured,
    /// DSNU row / column / pixel parts (e⁻).
    pub dsnu_row_e: f64,
    /// DSNU column part (e⁻).
    pub dsnu_col_e: f64,
    /// DSNU pixel part (e⁻).
    pub dsnu_pixel_e: f64,
    /// PRNU₁₂₈₈ (%).
    pub prnu_percent: Measured,
    /// PRNU row part (%).
    pub prnu_row_percent: f64,
    /// PRNU column part (%).
    pub prnu_col_percent: f64,
    /// PRNU pixel part (%).
    pub prnu_pixel_percent: f64,
    /// Horizontal spectrogram of the dark average image (DN²).
    pub dsnu_spectrogram_h: Spectrogram,
    /// Vertical spectrogram of the dark average image (DN²).
    pub dsnu_spectrogram_v: Spectrogram,
    /// Horizontal spectrogram of the bright average image (DN²).
    pub prnu_spectrogram_h: Spectrogram,
    /// Vertical spectrogram of the bright average image (DN²).
    pub prnu_spectrogram_v: Spectrogram,
    /// Histogram of the dark average image minus its mean (e⁻).
    pub dsnu_histogram_e: Histogram,
    /// Histogram of the high-pass filtered bright − dark image (% of the mean signal).
    pub prnu_histogram_percent: Histogram,
}

/// The spatial analysis of Rel. 4.0 §8 from the two stacks and the system gain K.
pub fn analyse_spatial(
    bright: &StackAccumulator,
    dark: &StackAccumulator,
    k: &LineFit,
) -> Result<SpatialResult, String> {
    if bright.frames < 2 || dark.frames < 2 {
        return Err(format!(
            "spatial stacks need at least 2 frames each (bright {}, dark {})",
            bright.frames, dark.frames
        ));
    }
    if (bright.rows, bright.cols) != (dark.rows, dark.cols) {
        return Err("bright and dark stacks differ in size".into());
    }
    let b = stack_stats(bright);
    let d = stack_stats(dark);
    let bp = variance_parts(&b);
    let dp = variance_parts(&d);
    let kk = k.slope;
    let dsnu = dsnu_electrons(d.s2_dn2, kk);
    let u_dsnu = dsnu
        * (((spatial_variance_uncertainty(&d) / (2.0 * d.s2_dn2)).powi(2))
            + (k.slope_se / kk).powi(2))
        .sqrt();
    let signal = b.mean_dn - d.mean_dn;
    let prnu = prnu_percent(b.s2_dn2, d.s2_dn2, b.mean_dn, d.mean_dn);
    let u_prnu = {
        let diff = b.s2_dn2 - d.s2_dn2;
        let u = (spatial_variance_uncertainty(&b).powi(2)
            + spatial_variance_uncertainty(&d).powi(2))
        .sqrt();
        prnu * u / (2.0 * diff)
    };
    let (m, n) = (bright.rows, bright.cols);
    let avg_b = bright.average();
    let avg_d = dark.average();
    let dark_centered_e: Vec<f64> = avg_d.iter().map(|v| (v - d.mean_dn) / kk).collect();
    let diff: Vec<f64> = avg_b.iter().zip(&avg_d).map(|(x, y)| x - y).collect();
    let (hp, _, _) = high_pass_5x5(&diff, m, n);
    let hp_percent: Vec<f64> = hp.iter().map(|v| 100.0 * v / signal).collect();
    Ok(SpatialResult {
        bright: b,
        dark: d,
        bright_parts: bp,
        dark_parts: dp,
        dsnu_e: Measured {
            value: dsnu,
            uncertainty: u_dsnu,
        },
        dsnu_row_e: dsnu_electrons(dp.row_dn2, kk),
        dsnu_col_e: dsnu_electrons(dp.col_dn2, kk),
        dsnu_pixel_e: dsnu_electrons(dp.pixel_dn2, kk),
        prnu_percent: Measured {
            value: prnu,
            uncertainty: u_prnu,
        },
        prnu_row_percent: prnu_percent(bp.row_dn2, dp.row_dn2, b.mean_dn, d.mean_dn),
        prnu_col_percent: prnu_percent(bp.col_dn2, dp.col_dn2, b.mean_dn, d.mean_dn),
        prnu_pixel_percent: prnu_percent(bp.pixel_dn2, dp.pixel_dn2, b.mean_dn, d.mean_dn),
        dsnu_spectrogram_h: spectrogram(&avg_d, m, n, false),
        dsnu_spectrogram_v: spectrogram(&avg_d, m, n, true),
        prnu_spectrogram_h: spectrogram(&avg_b, m, n, false),
        prnu_spectrogram_v: spectrogram(&avg_b, m, n, true),
        dsnu_histogram_e: histogram(&dark_centered_e, 256),
        prnu_histogram_percent: histogram(&hp_percent, 256),
    })
}
