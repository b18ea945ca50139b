//! Colour evaluation shared by `camsim run` and `camsim validate` (Farrell, Catrysse & Wandell
//! 2012, Figs. 5–6): chart patch means, linear sRGB → XYZ → CIELAB (white = sRGB white), and
//! ΔE2000 / ΔE*ab of chart patches against their desired (D65 sRGB) values.
use crate::error::CliError;
use camsim_core::colorimetry::{delta_e_76, xyz_to_lab, Lab, Xyz};
use camsim_isp::{srgb_decode, srgb_encode, RgbImage};
use camsim_metrics::{delta_e_2000, delta_e_stats, patch_sample_rect, ChartLayout, DeltaEStats};
use serde_json::{json, Value};

pub use camsim_core::colorimetry::linear_srgb_to_xyz as srgb_to_xyz;

/// CIELAB of a linear sRGB value, the white being sRGB (1, 1, 1).
pub fn linear_srgb_to_lab(v: [f64; 3]) -> Lab {
    let white = srgb_to_xyz([1.0, 1.0, 1.0]);
    let white = Xyz {
        x: white[0],
        y: white[1],
        z: white[2],
    };
    let x = srgb_to_xyz(v);
    xyz_to_lab(
        Xyz {
            x: x[0],
            y: x[1],
            z: x[2],
        },
        white,
    )
}

/// Mean R, G, B over the sampled part of each of the chart's patches (row-major).
pub fn patch_means(img: &RgbImage, layout: &ChartLayout) -> Vec<[f64; 3]> {
    patch_stats(img, layout)
        .into_iter()
        .map(|p| p.mean)
        .collect()
}

/// One chart patch's pixel statistics over its sampled part, per channel R, G, B.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PatchStats {
    /// Mean value.
    pub mean: [f64; 3],
    /// Standard error of the mean, from the spread of the means of the patch's whole
    /// [`SE_BLOCK_PX`]² blocks: `sd(block means) / √blocks` (0 below two blocks). Blocks, not
    /// pixels, because a demosaicked image's pixels are correlated over a few pixels, which
    /// the pixel spread would not see.
    pub standard_error: [f64; 3],
    /// Number of pixels sampled.
    pub pixels: usize,
}

/// Side of the blocks behind [`PatchStats::standard_error`], pixels: wider than the support of
/// the demosaicking kernels (5 × 5 at most), so block means are nearly independent.
pub const SE_BLOCK_PX: usize = 8;

/// [`PatchStats`] of each of the chart's patches (row-major).
pub fn patch_stats(img: &RgbImage, layout: &ChartLayout) -> Vec<PatchStats> {
    let n_patches = layout.chart_rows * layout.chart_cols;
    (0..n_patches)
        .map(|i| {
            let rect = patch_sample_rect(
                img.rows,
                img.cols,
                layout,
                i / layout.chart_cols,
                i % layout.chart_cols,
            );
            let mean_over = |rows: std::ops::Range<usize>, cols: std::ops::Range<usize>| {
                let mut s = [0.0f64; 3];
                let mut n = 0.0f64;
                for y in rows {
                    for x in cols.clone() {
                        let v = img.at(y, x);
                        for c in 0..3 {
                            s[c] += v[c] as f64;
                        }
                        n += 1.0;
                    }
                }
                (s.map(|v| v / n.max(1.0)), n as usize)
            };
            let (mean, pixels) = mean_over(rect.row0..rect.row1, rect.col0..rect.col1);
            let b = SE_BLOCK_PX;
            let (br, bc) = ((rect.row1 - rect.row0) / b, (rect.col1 - rect.col0) / b);
            let blocks: Vec<[f64; 3]> = (0..br * bc)
                .map(|k| {
                    let (y0, x0) = (rect.row0 + (k / bc) * b, rect.col0 + (k % bc) * b);
                    mean_over(y0..y0 + b, x0..x0 + b).0
                })
                .collect();
            let k = blocks.len() as f64;
            let standard_error = [0, 1, 2].map(|c| {
                if blocks.len() < 2 {
                    return 0.0;
                }
                let m = blocks.iter().map(|v| v[c]).sum::<f64>() / k;
                let ss: f64 = blocks.iter().map(|v| (v[c] - m).powi(2)).sum();
                (ss / (k - 1.0) / k).sqrt()
            });
            PatchStats {
                mean,
                standard_error,
                pixels,
            }
        })
        .collect()
}

/// A linear sRGB value as an 8-bit sRGB output shows it: clipped to [0, 1], encoded, rounded
/// to a code (as `camsim_isp::to_srgb8`) and decoded again.
pub fn through_srgb8(v: [f64; 3]) -> [f64; 3] {
    v.map(|x| {
        let x = if x.is_nan() { 0.0 } else { x.clamp(0.0, 1.0) };
        srgb_decode((srgb_encode(x) * 255.0).round() / 255.0)
    })
}

/// Per-patch colour differences between desired and actual linear sRGB values.
#[derive(Debug, Clone)]
pub struct PatchDeltaE {
    /// CIEDE2000 per patch.
    pub de2000: Vec<f64>,
    /// CIE 1976 ΔE*ab per patch.
    pub de76: Vec<f64>,
    /// Distribution of `de2000`.
    pub stats2000: DeltaEStats,
    /// Distribution of `de76`.
    pub stats76: DeltaEStats,
}

impl PatchDeltaE {
    /// `{"mean", "median", "p95", "max", "per_patch"}` of ΔE2000.
    pub fn json_2000(&self) -> Value {
        stats_json(&self.stats2000, &self.de2000)
    }
    /// `{"mean", "median", "p95", "max", "per_patch"}` of ΔE*ab.
    pub fn json_76(&self) -> Value {
        stats_json(&self.stats76, &self.de76)
    }
}

fn stats_json(s: &DeltaEStats, v: &[f64]) -> Value {
    json!({"mean": s.mean, "median": s.median, "p95": s.p95, "max": s.max, "per_patch": v})
}

/// ΔE2000 and ΔE*ab of `actual` against `desired` (linear sRGB, patch by patch).
pub fn patch_delta_e(desired: &[[f64; 3]], actual: &[[f64; 3]]) -> Result<PatchDeltaE, CliError> {
    let n = desired.len().min(actual.len());
    let de2000: Vec<f64> = (0..n)
        .map(|i| {
            delta_e_2000(
                linear_srgb_to_lab(desired[i]),
                linear_srgb_to_lab(actual[i]),
            )
        })
        .collect();
    let de76: Vec<f64> = (0..n)
        .map(|i| {
            delta_e_76(
                linear_srgb_to_lab(desired[i]),
                linear_srgb_to_lab(actual[i]),
            )
        })
        .collect();
    let stats2000 = delta_e_stats(&de2000).map_err(|e| CliError::Other(e.to_string()))?;
    let stats76 = delta_e_stats(&de76).map_err(|e| CliError::Other(e.to_string()))?;
    Ok(PatchDeltaE {
        de2000,
        de76,
        stats2000,
        stats76,
    })
}
