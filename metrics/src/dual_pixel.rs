//! Dual-pixel disparity of a near-vertical edge: the shift between the left and right
//! half-photodiode images.
//!
//! Each row's edge position in either image is the centroid of its blurred edge
//! ([`crate::rolling_shutter::row_edge_positions_px`]: a blur that conserves signal moves no
//! weight across the centroid), so for a step edge the difference of the right and left
//! positions is the difference of the x-centroids of the right and left pupil-half PSFs
//! exactly, whatever their shape (the pixel's box aperture is symmetric and shifts neither):
//! the dual-pixel disparity `8r/(3π)` of thin-lens geometry (Garg et al., ICCV 2019; see
//! `camsim_optics::dual_pixel`). With a colour filter array of period `p`, every CFA phase is
//! measured on its own sub-lattice (a grey edge is a step on each) and the positions scaled
//! by `p`.
use camsim_core::stats::Rect;

/// The measured disparity of one region.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EdgeDisparity {
    /// Mean over rows of right position − left position (pixels; positive: the right image
    /// lies to the right).
    pub disparity_px: f64,
    /// Standard error of the mean over the rows used (pixels; 0 for noise-free frames).
    pub std_error_px: f64,
    /// Row measurements used (rows × CFA column phases).
    pub rows_used: usize,
}

/// The disparity of the edge in `region` of the row-major `cols`-wide left and right frames
/// (black level removed), measured on every CFA sub-lattice of period `period` (1: mono),
/// each sub-row's reference levels the means of its first and last `ref_cols` samples. Rows
/// whose contrast is below a quarter of the largest are left out. `None` when no row has an
/// edge.
pub fn edge_disparity_px(
    left: &[f64],
    right: &[f64],
    cols: usize,
    region: Rect,
    period: usize,
    ref_cols: usize,
) -> Option<EdgeDisparity> {
    let p = period.max(1);
    let mut diffs = Vec::new();
    for pr in 0..p {
        for pc in 0..p {
            // The sub-lattice of phase (pr, pc) inside the region.
            let rows: Vec<usize> = (region.row0..region.row1).filter(|r| r % p == pr).collect();
            let cs: Vec<usize> = (region.col0..region.col1).filter(|c| c % p == pc).collect();
            if rows.is_empty() || cs.len() < 3 {
                continue;
            }
            let sub = |img: &[f64]| -> Vec<f64> {
                rows.iter()
                    .flat_map(|r| cs.iter().map(move |c| img[r * cols + c]))
                    .collect()
            };
            let (sl, sr) = (sub(left), sub(right));
            let pl = crate::rolling_shutter::row_edge_positions_px(
                &sl,
                rows.len(),
                cs.len(),
                ref_cols,
                0.25,
            );
            let prr = crate::rolling_shutter::row_edge_positions_px(
                &sr,
                rows.len(),
                cs.len(),
                ref_cols,
                0.25,
            );
            diffs.extend(
                pl.iter()
                    .zip(&prr)
                    .filter(|(a, b)| a.is_finite() && b.is_finite())
                    .map(|(a, b)| (b - a) * p as f64),
            );
        }
    }
    if diffs.is_empty() {
        return None;
    }
    let n = diffs.len() as f64;
    let mean = diffs.iter().sum::<f64>() / n;
    let var = if diffs.len() > 1 {
        diffs.iter().map(|d| (d - mean).powi(2)).sum::<f64>() / (n - 1.0)
    } else {
        0.0
    };
    Some(EdgeDisparity {
        disparity_px: mean,
        std_error_px: (var / n).sqrt(),
        rows_used: diffs.len(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A box-blurred step edge at `e` (pixels), exact pixel averages.
    fn edge_row(cols: usize, e: f64, width: f64) -> Vec<f64> {
        // pixel c covers [c − ½, c + ½]; the edge ramps linearly over [e − w/2, e + w/2]
        let ramp = |x: f64| ((x - (e - width / 2.0)) / width).clamp(0.0, 1.0);
        let integ = |x: f64| {
            // ∫ ramp from −∞-ish (0) to x, via the antiderivative of the clamped ramp
            let a = e - width / 2.0;
            let b = e + width / 2.0;
            if x <= a {
                0.0
            } else if x >= b {
                width / 2.0 + (x - b)
            } else {
                (x - a) * ramp(x) / 2.0
            }
        };
        (0..cols)
            .map(|c| integ(c as f64 + 0.5) - integ(c as f64 - 0.5))
            .collect()
    }

    #[test]
    fn shifted_edges_give_their_shift_on_every_cfa_phase() {
        let (rows, cols) = (8, 40);
        for (shift, period) in [(1.37, 1), (-2.6, 2), (0.0, 2)] {
            let l: Vec<f64> = (0..rows).flat_map(|_| edge_row(cols, 19.2, 5.0)).collect();
            let r: Vec<f64> = (0..rows)
                .flat_map(|_| edge_row(cols, 19.2 + shift, 5.0))
                .collect();
            let region = Rect {
                row0: 0,
                row1: rows,
                col0: 0,
                col1: cols,
            };
            let d = edge_disparity_px(&l, &r, cols, region, period, 3).unwrap();
            assert!((d.disparity_px - shift).abs() < 1e-9, "{d:?} vs {shift}");
            assert_eq!(d.rows_used, rows * period);
        }
        let flat = vec![1.0; rows * cols];
        let region = Rect {
            row0: 0,
            row1: rows,
            col0: 0,
            col1: cols,
        };
        assert!(edge_disparity_px(&flat, &flat, cols, region, 1, 3).is_none());
    }
}
