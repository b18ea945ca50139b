//! The hot-pixel term: a two-component mixture per pixel, normal or an extra dark rate V
//! whose logarithm is N(ln V_h, σ_h²) across hot pixels, integrated by Laplace's method (by
//! Gauss–Hermite quadrature over that prior when every shot of the pixel is censored); and
//! the per-pixel scan for start values.
use super::column::ColView;
use super::{Ctx, PixShot, Rates, RowSel, BLOCK_ROWS};
use crate::mismatch::model::{ModelState, Pred, ShotConst};
use rayon::prelude::*;

/// Hot-pixel mixture parameters.
#[derive(Debug, Clone, Copy)]
pub(super) struct Hot {
    pub(super) fraction: f64,
    pub(super) ln_rate: f64,
    pub(super) log_sigma: f64,
}

impl Ctx<'_> {
    /// Log-likelihood of one pixel as a hot pixel (Laplace integral over its rate, or
    /// quadrature over the rate's prior when every shot is censored: the Laplace step's
    /// linearised rate uses uncensored shots only); its predictions at the most probable
    /// rate go to `hp`.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn hot_ll<'c>(
        &self,
        px: &[PixShot],
        preds: &[Pred],
        es: &[f64],
        consts: &[ShotConst],
        col: Option<ColView<'c>>,
        sig_d: f64,
        sig_p: f64,
        sig_c: f64,
        use_cols: bool,
        h: &Hot,
        hp: &mut [Pred],
    ) -> f64 {
        // Linearised response to an extra dark rate V: h_s = c_s V, c_s = DN/e · t/g.
        let (mut srr, mut scc) = (0.0, 0.0);
        for (sidx, x) in px.iter().enumerate() {
            if x.censored {
                continue;
            }
            let p = &preds[sidx];
            let c = &consts[sidx];
            let cs = p.dn_per_e * c.t / c.g;
            let mut r = x.mean as f64 - p.mean;
            if let Some(x) = col.and_then(|v| v.get(sidx)) {
                r -= x.c_hat;
            }
            let a = c.var_mean(p);
            srr += r * cs / a;
            scc += cs * cs / a;
        }
        let mu = h.ln_rate;
        // The pixel's predictions with an extra dark rate v (V/s), and its likelihood then.
        let predict_at = |v: f64, hp: &mut [Pred]| {
            for ((o, c), &e) in hp.iter_mut().zip(consts).zip(es) {
                *o = c.predict(e, c.t * v / c.g);
            }
        };
        let ll_at = |v: f64, hp: &mut [Pred]| -> f64 {
            predict_at(v, hp);
            let sig_c_pixel = if use_cols { 0.0 } else { sig_c };
            self.pixel_ll(px, hp, consts, col, sig_d, sig_p, sig_c_pixel)
        };
        if h.log_sigma > 1e-6 && scc == 0.0 {
            // Every shot censored: the rail counts alone carry the rate; the Laplace step
            // has no data curvature to work with, so integrate over the prior of ln V
            // (Gauss–Hermite) with the full (rail) likelihood.
            let gh = crate::mismatch::num::gauss_hermite_24();
            let mut terms = [0.0f64; 24];
            let (mut best, mut v_best) = (f64::NEG_INFINITY, mu.exp());
            for (k, &(z, w)) in gh.iter().enumerate() {
                let v = (mu + h.log_sigma * z).exp();
                terms[k] = ll_at(v, hp) + w.ln();
                if terms[k] > best {
                    best = terms[k];
                    v_best = v;
                }
            }
            let sum: f64 = terms.iter().map(|t| (t - best).exp()).sum();
            predict_at(v_best, hp);
            return best + sum.ln();
        }
        let (x_star, log_prior_term) = if h.log_sigma > 1e-6 && scc > 0.0 {
            let v_hat = srr / scc;
            let s2 = h.log_sigma * h.log_sigma;
            // Newton on x = ln V of  −½ I (e^x − V̂)² − (x − μ)²/(2σ²).
            let mut x = mu;
            for _ in 0..30 {
                let ex = x.exp();
                let g = -scc * (ex - v_hat) * ex - (x - mu) / s2;
                let hh = -scc * (2.0 * ex * ex - v_hat * ex) - 1.0 / s2;
                let step = if hh < 0.0 { -g / hh } else { g.signum() * 0.5 };
                let step = step.clamp(-2.0, 2.0);
                x += step;
                if step.abs() < 1e-8 {
                    break;
                }
            }
            let ex = x.exp();
            let curv = scc * ex * ex + 1.0 / s2;
            let lp = -0.5 * (x - mu) * (x - mu) / s2 - 0.5 * (2.0 * std::f64::consts::PI * s2).ln()
                + 0.5 * (2.0 * std::f64::consts::PI / curv).ln();
            (x, lp)
        } else {
            (mu, 0.0)
        };
        ll_at(x_star.exp(), hp) + log_prior_term
    }

    /// Pixels whose residuals over the shots are best explained by an extra dark rate: per
    /// pixel the least-squares rate V̂ and its significance z = V̂·√I (I: Fisher information);
    /// returns (pixel, V̂, z) for z > `z_min`. With `rail_free`, censored pixel-shots with no
    /// frame at a rail (censored by their neighbourhood only) count too: start values for
    /// data censored everywhere (the frame mean is then biased near a rail, which a start
    /// value tolerates).
    pub(crate) fn hot_scan(
        &self,
        state: &ModelState,
        rates: &Rates,
        z_min: f64,
        sel: RowSel,
        rail_free: bool,
    ) -> Vec<(usize, f64, f64)> {
        let d = self.data;
        let (ns, cols) = (d.shots.len(), d.cols);
        let consts = self.consts(state);
        let blocks: Vec<Vec<(usize, f64, f64)>> = self
            .rows(sel)
            .par_chunks(BLOCK_ROWS)
            .map(|blk| {
                let mut out = Vec::new();
                for &r in blk {
                    for j in 0..cols {
                        let i = r * cols + j;
                        let (mut srr, mut scc) = (0.0, 0.0);
                        for sidx in 0..ns {
                            let sh = &d.shots[sidx];
                            if sh.censored[i]
                                && !(rail_free && sh.n_low[i] == 0 && sh.n_high[i] == 0)
                            {
                                continue;
                            }
                            let c = &consts[sidx];
                            let p = c.predict(rates[sidx][i] as f64 * c.t, 0.0);
                            let cs = p.dn_per_e * c.t / c.g;
                            let a = c.var_mean(&p) + (state.sensor.dsnu_sigma_v * p.u).powi(2);
                            srr += (sh.mean_dn[i] as f64 - p.mean) * cs / a;
                            scc += cs * cs / a;
                        }
                        if scc > 0.0 {
                            let v = srr / scc;
                            let z = v * scc.sqrt();
                            if z > z_min {
                                out.push((i, v, z));
                            }
                        }
                    }
                }
                out
            })
            .collect();
        blocks.into_iter().flatten().collect()
    }
}
