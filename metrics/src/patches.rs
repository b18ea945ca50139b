//! Per-patch statistics of test charts (mean, temporal+fixed-pattern noise, SNR), as used in
//! §3 of Farrell, Catrysse & Wandell (2012) to compare simulated and measured chart captures.
//!
//! Geometry follows the capture-format spec, target kind `patches`: with the sensor `W` columns
//! wide and `H` rows high, chart cell (r, c) spans columns [c·W/cols, (c+1)·W/cols) and rows
//! [r·H/rows, (r+1)·H/rows) (continuous pixel coordinates, pixel j covering [j, j+1)); its patch
//! is the centred rectangle whose sides are `patch_fraction` of the cell's sides. Only the inner
//! part of each patch is sampled (a `margin_fraction` of the patch side is dropped on every
//! side) so that blur and misregistration at patch borders do not bias the statistics; a pixel
//! is used only when its whole square lies inside that inner rectangle.
use crate::error::MetricsError;
use camsim_core::stats::{region_stats, Rect};
use serde::Serialize;

/// Layout of a chart that fills the sensor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChartLayout {
    /// Rows of chart cells.
    pub chart_rows: usize,
    /// Columns of chart cells.
    pub chart_cols: usize,
    /// Patch side as a fraction of the cell side, in (0, 1].
    pub patch_fraction: f64,
    /// Fraction of the patch side dropped on each side before sampling, in [0, 0.5).
    pub margin_fraction: f64,
}

/// Statistics of one chart patch for one channel.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PatchStats {
    /// Chart row of the patch.
    pub chart_row: usize,
    /// Chart column of the patch.
    pub chart_col: usize,
    /// First sampled image row.
    pub row0: usize,
    /// One past the last sampled image row.
    pub row1: usize,
    /// First sampled image column.
    pub col0: usize,
    /// One past the last sampled image column.
    pub col1: usize,
    /// Mean value (units of the data, e.g. DN).
    pub mean: f64,
    /// Sample standard deviation (N − 1) over the sampled pixels.
    pub std: f64,
    /// 20 log10(|mean| / std) in dB; infinite for a noise-free patch.
    pub snr_db: f64,
    /// Number of pixels sampled.
    pub count: usize,
}

/// The image rectangle sampled for chart cell (r, c) of a `rows × cols` image.
pub fn patch_sample_rect(
    rows: usize,
    cols: usize,
    layout: &ChartLayout,
    chart_row: usize,
    chart_col: usize,
) -> Rect {
    let axis = |n: usize, cells: usize, i: usize| {
        let cell = n as f64 / cells as f64;
        let centre = (i as f64 + 0.5) * cell;
        let half_patch = 0.5 * layout.patch_fraction * cell;
        let inner = half_patch * (1.0 - 2.0 * layout.margin_fraction);
        // pixel j is inside when j ≥ lo and j + 1 ≤ hi; the tiny tolerance keeps exact
        // boundaries (integer cells) from being lost to rounding
        let lo = ((centre - inner) - 1e-9).ceil().max(0.0) as usize;
        let hi = ((centre + inner) + 1e-9).floor().min(n as f64) as usize;
        (lo, hi.max(lo))
    };
    let (row0, row1) = axis(rows, layout.chart_rows, chart_row);
    let (col0, col1) = axis(cols, layout.chart_cols, chart_col);
    Rect {
        row0,
        row1,
        col0,
        col1,
    }
}

/// Statistics of every patch of the chart (row-major, `chart_rows · chart_cols` entries) over
/// the pixels of `data` (row-major `rows × cols`, a mosaic or a single plane) for which
/// `channel(row, col)` is true; see [`cfa_channel_mask`] for a CFA channel.
pub fn patch_stats(
    data: &[f32],
    rows: usize,
    cols: usize,
    layout: &ChartLayout,
    channel: impl Fn(usize, usize) -> bool,
) -> Result<Vec<PatchStats>, MetricsError> {
    if data.len() != rows * cols {
        return Err(MetricsError::SizeMismatch {
            what: "patch_stats: data",
            expected: rows * cols,
            actual: data.len(),
        });
    }
    if rows == 0 || cols == 0 {
        return Err(MetricsError::Empty("patch_stats: image"));
    }
    if layout.chart_rows == 0 || layout.chart_cols == 0 {
        return Err(MetricsError::InvalidParameter {
            name: "chart_rows/chart_cols",
            value: format!("{}×{}", layout.chart_rows, layout.chart_cols),
            reason: "the chart needs at least one cell",
        });
    }
    if !(layout.patch_fraction > 0.0 && layout.patch_fraction <= 1.0) {
        return Err(MetricsError::InvalidParameter {
            name: "patch_fraction",
            value: layout.patch_fraction.to_string(),
            reason: "must be in (0, 1]",
        });
    }
    if !(layout.margin_fraction >= 0.0 && layout.margin_fraction < 0.5) {
        return Err(MetricsError::InvalidParameter {
            name: "margin_fraction",
            value: layout.margin_fraction.to_string(),
            reason: "must be in [0, 0.5)",
        });
    }
    let mut out = Vec::with_capacity(layout.chart_rows * layout.chart_cols);
    for chart_row in 0..layout.chart_rows {
        for chart_col in 0..layout.chart_cols {
            let rect = patch_sample_rect(rows, cols, layout, chart_row, chart_col);
            let s = region_stats(data, cols, rect, &channel);
            if s.count == 0 {
                return Err(MetricsError::EmptyPatch {
                    chart_row,
                    chart_col,
                });
            }
            out.push(PatchStats {
                chart_row,
                chart_col,
                row0: rect.row0,
                row1: rect.row1,
                col0: rect.col0,
                col1: rect.col1,
                mean: s.mean,
                std: s.std,
                snr_db: s.snr_db,
                count: s.count,
            });
        }
    }
    Ok(out)
}

/// Mask of the pixels of channel `letter` for a repeating CFA tile given one string per row
/// (capture-format spec `sensor.cfa`, e.g. `["gb", "rg"]`).
pub fn cfa_channel_mask(
    cfa: &[&str],
    letter: char,
) -> Result<impl Fn(usize, usize) -> bool, MetricsError> {
    if cfa.is_empty() {
        return Err(MetricsError::Cfa("the tile has no rows".into()));
    }
    let tile: Vec<Vec<char>> = cfa.iter().map(|r| r.chars().collect()).collect();
    let w = tile[0].len();
    if w == 0 || tile.iter().any(|r| r.len() != w) {
        return Err(MetricsError::Cfa(format!(
            "rows of the tile {cfa:?} must have equal, non-zero length"
        )));
    }
    if !tile.iter().flatten().any(|&c| c == letter) {
        return Err(MetricsError::Cfa(format!(
            "channel '{letter}' does not occur in the tile {cfa:?}"
        )));
    }
    let h = tile.len();
    Ok(move |r: usize, c: usize| tile[r % h][c % w] == letter)
}

#[cfg(test)]
mod tests {
    use super::*;
    use camsim_core::rng::splitmix64;

    /// Standard normal deviate from two hashed uniforms (Box–Muller).
    fn normal(seed: u64) -> f64 {
        let u1 = ((splitmix64(seed) >> 11) as f64 + 0.5) / (1u64 << 53) as f64;
        let u2 = ((splitmix64(seed ^ 0xABCD_EF01) >> 11) as f64) / (1u64 << 53) as f64;
        (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
    }

    #[test]
    fn synthetic_bayer_chart_recovers_means_and_noise() {
        // 4×6 chart on a 243×317 mosaic (cells not integer-sized), gb/rg tile. Each patch has a
        // different mean per channel and noise σ = 2 + 0.1·index; background is 1000 (must not
        // leak in). Per-channel means and σ are recovered within 4 standard errors.
        let (rows, cols) = (243usize, 317usize);
        let layout = ChartLayout {
            chart_rows: 4,
            chart_cols: 6,
            patch_fraction: 0.7,
            margin_fraction: 0.15,
        };
        let tile = ["gb", "rg"];
        let chan_of = |r: usize, c: usize| tile[r % 2].as_bytes()[c % 2] as char;
        let mean_of = |k: usize, ch: char| {
            50.0 + 20.0 * k as f64
                + match ch {
                    'r' => 0.0,
                    'g' => 5.0,
                    _ => 11.0,
                }
        };
        let sigma_of = |k: usize| 2.0 + 0.1 * k as f64;
        let (cw, ch) = (cols as f64 / 6.0, rows as f64 / 4.0);
        let mut data = vec![1000f32; rows * cols];
        for r in 0..rows {
            for c in 0..cols {
                let (pr, pc) = (
                    ((r as f64 + 0.5) / ch) as usize,
                    ((c as f64 + 0.5) / cw) as usize,
                );
                let (cx, cy) = ((pc as f64 + 0.5) * cw, (pr as f64 + 0.5) * ch);
                // pixel square fully inside the patch
                let inside = (c as f64) >= cx - 0.35 * cw
                    && (c + 1) as f64 <= cx + 0.35 * cw
                    && (r as f64) >= cy - 0.35 * ch
                    && (r + 1) as f64 <= cy + 0.35 * ch;
                if inside {
                    let k = pr * 6 + pc;
                    data[r * cols + c] = (mean_of(k, chan_of(r, c))
                        + sigma_of(k) * normal((r * cols + c) as u64))
                        as f32;
                }
            }
        }
        for letter in ['r', 'g', 'b'] {
            let mask = cfa_channel_mask(&tile, letter).unwrap();
            let stats = patch_stats(&data, rows, cols, &layout, mask).unwrap();
            assert_eq!(stats.len(), 24);
            for s in &stats {
                let k = s.chart_row * 6 + s.chart_col;
                let (m, sd) = (mean_of(k, letter), sigma_of(k));
                // inner patch 0.7·0.7 = 49 % of the cell side: ≈ 25×37 px, ¼ (r, b) or ½ (g)
                assert!(s.count > 150, "{s:?}");
                assert!(
                    (s.mean - m).abs() < 4.0 * sd / (s.count as f64).sqrt(),
                    "{letter} {s:?} mean {m}"
                );
                // standard error of a sample σ ≈ σ / √(2(n − 1))
                let se_rel = 1.0 / (2.0 * (s.count as f64 - 1.0)).sqrt();
                assert!(
                    (s.std / sd - 1.0).abs() < 4.0 * se_rel,
                    "{letter} {s:?} σ {sd}"
                );
                let snr = 20.0 * (s.mean / s.std).log10();
                assert!((s.snr_db - snr).abs() < 1e-9);
            }
        }
    }

    #[test]
    fn sample_rect_is_centred_and_inside_the_patch() {
        // 60×90 image, 3×3 chart: cells 20×30, patch 0.5 → 10×15 centred; margin 0.2 → 6×9
        let layout = ChartLayout {
            chart_rows: 3,
            chart_cols: 3,
            patch_fraction: 0.5,
            margin_fraction: 0.2,
        };
        let r = patch_sample_rect(60, 90, &layout, 1, 2);
        // row centre 30, inner half-height 3 → rows 27..33; col centre 75, half-width 4.5 → 71..79
        assert_eq!((r.row0, r.row1, r.col0, r.col1), (27, 33, 71, 79));
    }

    #[test]
    fn errors_are_clear() {
        let data = vec![0f32; 100];
        let layout = ChartLayout {
            chart_rows: 2,
            chart_cols: 2,
            patch_fraction: 0.1,
            margin_fraction: 0.4,
        };
        let e = patch_stats(&data, 10, 10, &layout, |_, _| true).unwrap_err();
        assert!(matches!(
            e,
            MetricsError::EmptyPatch {
                chart_row: 0,
                chart_col: 0
            }
        ));
        assert!(e.to_string().contains("margin_fraction"));
        assert!(cfa_channel_mask(&["gb", "rg"], 'x').is_err());
        assert!(cfa_channel_mask(&["gb", "r"], 'g').is_err());
        let bad = ChartLayout {
            patch_fraction: 1.5,
            ..layout
        };
        assert!(patch_stats(&data, 10, 10, &bad, |_, _| true).is_err());
    }
}
