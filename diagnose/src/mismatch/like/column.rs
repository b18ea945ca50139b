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
                let nb = &mut nb[..k];
                nb.sort_by(|a, b| a.total_cmp(b));
                let med = if k % 2 == 1 {
                    nb[k / 2]
                } else {
                    0.5 * (nb[k / 2 - 1] + nb[k / 2])
                };
                sh.mean_dn[i] - med
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
