//! The column term: the residuals split into per-column means (one "super-pixel" per column,
//! whose covariance adds the column-offset variance σ_c² u uᵀ) and the deviations from them
//! (the within-column part, in `pixel.rs`), the exact decomposition of a Gaussian
//! random-effects model with equal pixel variances; and the data-only outlier mask that keeps
//! hot or dead pixels out of the column means.
use super::{Ctx, Rates, RowSel, BLOCK_ROWS};
use crate::mismatch::data::DataSet;
use crate::mismatch::model::{Pred, ShotConst};
use crate::mismatch::num::Woodbury;
use rayon::prelude::*;

#[derive(Debug, Clone, Copy, Default)]
struct ColAcc {
    n: f64,
    sr: f64,
    sa: f64,
    su: f64,
    sw2: f64,
}

/// Per-(shot, column) column-mean statistics.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct ColStat {
    pub n: f64,
    pub c_hat: f64,
    pub var_diag: f64,
    pub u_bar: f64,
    pub w_rms: f64,
    /// 1 − 1/n: the variance share a pixel keeps once its column mean is removed.
    pub kappa: f64,
    /// √kappa.
    pub sqrt_kappa: f64,
}

/// One column's [`ColStat`]s (shot-major table, column `j`); a shot's entry counts when the
/// column has at least two pixels in it.
#[derive(Clone, Copy)]
pub(super) struct ColView<'c> {
    pub(super) stats: &'c [ColStat],
    pub(super) cols: usize,
    pub(super) j: usize,
}

impl<'c> ColView<'c> {
    #[inline]
    pub(super) fn get(&self, shot: usize) -> Option<&'c ColStat> {
        let x = &self.stats[shot * self.cols + self.j];
        (x.n >= 2.0).then_some(x)
    }
}

impl Ctx<'_> {
    /// With `store`, also every pixel-shot's prediction, at
    /// ((row position in the selection)·cols + column)·shots + shot, for the pixel pass.
    pub(super) fn column_stats_store(
        &self,
        rates: &Rates,
        consts: &[ShotConst],
        sel: RowSel,
        store: Option<&mut [Pred]>,
    ) -> Vec<ColStat> {
        let d = self.data;
        let (ns, cols) = (d.shots.len(), d.cols);
        let rows = self.rows(sel);
        let per_block = BLOCK_ROWS * cols * ns;
        let mut dummy: Vec<Pred> = Vec::new();
        let (stored, buf): (bool, &mut [Pred]) = match store {
            Some(b) => (true, b),
            None => (false, &mut dummy[..]),
        };
        let n_blocks = rows.len().div_ceil(BLOCK_ROWS);
        let mut bufs: Vec<&mut [Pred]> = if stored {
            buf.chunks_mut(per_block).collect()
        } else {
            (0..n_blocks).map(|_| &mut [][..]).collect()
        };
        // Pixel-major data of these rows (the fit rows, or all rows when they are the same).
        let pix = (sel == RowSel::Fit || self.calc_rows.is_empty()).then_some(&self.fit_pix[..]);
        let blocks: Vec<Vec<ColAcc>> = rows
            .par_chunks(BLOCK_ROWS)
            .zip(bufs.par_iter_mut())
            .enumerate()
            .map(|(bi, (blk, pb))| {
                let mut acc = vec![ColAcc::default(); ns * cols];
                match (stored, pix) {
                    (true, Some(pix)) => {
                        // pixel-major: the predictions are written in the order the pixel
                        // pass reads them (the same sums per (shot, column) as below)
                        for (ri, &r) in blk.iter().enumerate() {
                            for j in 0..cols {
                                let i = r * cols + j;
                                let at = (ri * cols + j) * ns;
                                let px = &pix[((bi * BLOCK_ROWS + ri) * cols + j) * ns..][..ns];
                                for s in 0..ns {
                                    let c = &consts[s];
                                    let p = c.predict(rates[s][i] as f64 * c.t, 0.0);
                                    pb[at + s] = p;
                                    if self.col_excluded[i] || px[s].censored {
                                        continue;
                                    }
                                    let a = &mut acc[s * cols + j];
                                    a.n += 1.0;
                                    a.sr += px[s].mean as f64 - p.mean;
                                    a.sa += c.var_mean(&p);
                                    a.su += p.u;
                                    a.sw2 += p.w * p.w;
                                }
                            }
                        }
                    }
                    _ => {
                        for (ri, &r) in blk.iter().enumerate() {
                            for (s, sh) in d.shots.iter().enumerate() {
                                let c = &consts[s];
                                let rate = &rates[s];
                                for j in 0..cols {
                                    let i = r * cols + j;
                                    let skip = self.col_excluded[i] || sh.censored[i];
                                    if skip && !stored {
                                        continue;
                                    }
                                    let p = c.predict(rate[i] as f64 * c.t, 0.0);
                                    if stored {
                                        pb[(ri * cols + j) * ns + s] = p;
                                    }
                                    if skip {
                                        continue;
                                    }
                                    let a = &mut acc[s * cols + j];
                                    a.n += 1.0;
                                    a.sr += sh.mean_dn[i] as f64 - p.mean;
                                    a.sa += c.var_mean(&p);
                                    a.su += p.u;
                                    a.sw2 += p.w * p.w;
                                }
                            }
                        }
                    }
                }
                acc
            })
            .collect();
        let mut tot = vec![ColAcc::default(); ns * cols];
        for b in &blocks {
            for (t, x) in tot.iter_mut().zip(b) {
                t.n += x.n;
                t.sr += x.sr;
                t.sa += x.sa;
                t.su += x.su;
                t.sw2 += x.sw2;
            }
        }
        tot.iter()
            .map(|a| {
                if a.n < 1.0 {
                    ColStat::default()
                } else {
                    ColStat {
                        n: a.n,
                        c_hat: a.sr / a.n,
                        var_diag: a.sa / (a.n * a.n),
                        u_bar: a.su / a.n,
                        w_rms: (a.sw2 / a.n).sqrt(),
                        kappa: 1.0 - 1.0 / a.n,
                        sqrt_kappa: (1.0 - 1.0 / a.n).sqrt(),
                    }
                }
            })
            .collect()
    }

    /// The column term's log-likelihood: per column, the S-vector of column-mean residuals
    /// (Woodbury form with the DSNU, column-offset and PRNU directions).
    pub(super) fn column_logl(&self, col: &[ColStat], sig_d: f64, sig_p: f64, sig_c: f64) -> f64 {
        let (ns, cols) = (self.data.shots.len(), self.data.cols);
        let terms: Vec<f64> = (0..cols)
            .into_par_iter()
            .map(|j| {
                let mut wb = Woodbury::default();
                let n_max = (0..ns).map(|s| col[s * cols + j].n).fold(0.0, f64::max);
                if n_max < 2.0 {
                    return 0.0;
                }
                let b1 = (sig_d * sig_d / n_max + sig_c * sig_c).sqrt();
                let b2 = sig_p / n_max.sqrt();
                for s in 0..ns {
                    let c = &col[s * cols + j];
                    if c.n < 2.0 || c.var_diag <= 0.0 {
                        continue;
                    }
                    wb.add(c.c_hat, c.var_diag, [b1 * c.u_bar, b2 * c.w_rms]);
                }
                if wb.is_empty() {
                    0.0
                } else {
                    wb.log_likelihood()
                }
            })
            .collect();
        terms.iter().sum()
    }
}

/// The median of 1 to 4 values in the order of [`f32::total_cmp`] (the mean of the two middle
/// values for an even count), by the 5-comparator sorting network for 4 inputs (Knuth, *The
/// Art of Computer Programming* vol. 3, §5.3.4) on the values' total-order keys: the sorted
/// sequence `sort_by(f32::total_cmp)` gives, so the same bits, without a sort call.
#[inline]
fn median_of_4(x: &[f32]) -> f32 {
    debug_assert!((1..=4).contains(&x.len()));
    let key = |v: f32| {
        let b = v.to_bits() as i32;
        b ^ ((((b >> 31) as u32) >> 1) as i32)
    };
    // the transform is its own inverse
    let value = |k: i32| f32::from_bits((k ^ ((((k >> 31) as u32) >> 1) as i32)) as u32);
    // padding keys sort after every value's key (ties only with identical bits)
    let mut k = [i32::MAX; 4];
    for (k, &v) in k.iter_mut().zip(x) {
        *k = key(v);
    }
    for (a, b) in [(0, 1), (2, 3), (0, 2), (1, 3), (1, 2)] {
        let (p, q) = (k[a], k[b]);
        k[a] = p.min(q);
        k[b] = p.max(q);
    }
    let n = x.len();
    if n % 2 == 1 {
        value(k[n / 2])
    } else {
        0.5 * (value(k[n / 2 - 1]) + value(k[n / 2]))
    }
}

/// Pixels that stand out from their same-channel neighbours in the same column (±2, ±4
/// rows) by more than 8 robust σ in some shot: excluded from the column means so that a few
/// hot or dead pixels do not masquerade as column offsets. Depends on the data only.
pub(super) fn outlier_pixels(d: &DataSet) -> Vec<bool> {
    let (rows, cols) = (d.rows, d.cols);
    let mut out = vec![false; rows * cols];
    if rows < 9 {
        return out;
    }
    for sh in &d.shots {
        let dev: Vec<f32> = (0..rows * cols)
            .into_par_iter()
            .map(|i| {
                let (r, c) = (i / cols, i % cols);
                let mut nb = [0f32; 4];
                let mut k = 0;
                for dr in [-4i64, -2, 2, 4] {
                    let rr = r as i64 + dr;
                    if rr >= 0 && (rr as usize) < rows {
                        nb[k] = sh.mean_dn[rr as usize * cols + c];
                        k += 1;
                    }
                }
                sh.mean_dn[i] - median_of_4(&nb[..k])
            })
            .collect();
        // robust σ from a strided sample
        let step = (dev.len() / 20000).max(1);
        let sample: Vec<f64> = dev.iter().step_by(step).map(|&x| x as f64).collect();
        let sigma = crate::mismatch::num::robust_sigma(&sample).max(1e-3);
        let med = crate::mismatch::num::median(&sample);
        for (o, &x) in out.iter_mut().zip(&dev) {
            if (x as f64 - med).abs() > 8.0 * sigma {
                *o = true;
            }
        }
    }
    out
}

#[cfg(test)]
mod median_tests {
    use super::median_of_4;

    /// Bit for bit the sort-based median it replaces, for 1 to 4 values (ties, signed zeros,
    /// negative values, subnormals), and every order of 4 distinct values.
    #[test]
    fn median_of_4_matches_sorting() {
        let by_sorting = |x: &[f32]| {
            let mut x = x.to_vec();
            x.sort_by(|a, b| a.total_cmp(b));
            let k = x.len();
            if k % 2 == 1 {
                x[k / 2]
            } else {
                0.5 * (x[k / 2 - 1] + x[k / 2])
            }
        };
        let pool = [
            0.0f32, -0.0, 1.0, -1.0, 2.5, 1e-40, -1e-40, 4095.0, 63.75, 3.0e30,
        ];
        for n in 1..=4usize {
            let mut idx = vec![0usize; n];
            loop {
                let x: Vec<f32> = idx.iter().map(|&i| pool[i]).collect();
                assert_eq!(median_of_4(&x).to_bits(), by_sorting(&x).to_bits(), "{x:?}");
                // next combination with repetition, in odometer order
                let mut p = 0;
                while p < n && idx[p] == pool.len() - 1 {
                    idx[p] = 0;
                    p += 1;
                }
                if p == n {
                    break;
                }
                idx[p] += 1;
            }
        }
    }
}
