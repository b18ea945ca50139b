//! Linear rate parameters: the weighted least-squares normal equations of the frame means.
use super::{Ctx, Rates, RowSel, BLOCK_ROWS};
use crate::mismatch::model::ModelState;
use rayon::prelude::*;

/// Weighted least-squares normal equations of the frame means for small changes of linear
/// rate parameters: `d_k = ∂μ/∂θ_k = DN/e · t · basis_k`, weights 1/Var(m) (marginal),
/// residuals r = m − μ. Returns (A, b) with A = Σ w d dᵀ (K×K, row-major), b = Σ w d r.
impl Ctx<'_> {
    pub(crate) fn normal_equations(
        &self,
        state: &ModelState,
        rates: &Rates,
        basis: &[Rates],
        sel: RowSel,
    ) -> (Vec<f64>, Vec<f64>) {
        let d = self.data;
        let (ns, cols) = (d.shots.len(), d.cols);
        let kk = basis.len();
        let consts = self.consts(state);
        let s = &state.sensor;
        let sig_d = if s.noise.dsnu { s.dsnu_sigma_v } else { 0.0 };
        let sig_p = if s.noise.prnu {
            s.prnu_sigma_percent / 100.0
        } else {
            0.0
        };
        let sig_c = s.column_fpn.map_or(0.0, |c| c.offset_sigma_v);
        let blocks: Vec<(Vec<f64>, Vec<f64>)> = self
            .rows(sel)
            .par_chunks(BLOCK_ROWS)
            .map(|blk| {
                let mut a = vec![0.0; kk * kk];
                let mut b = vec![0.0; kk];
                let mut dv = vec![0.0; kk];
                for &r in blk {
                    for j in 0..cols {
                        let i = r * cols + j;
                        for sidx in 0..ns {
                            let sh = &d.shots[sidx];
                            if sh.censored[i] {
                                continue;
                            }
                            let c = &consts[sidx];
                            let p = c.predict(rates[sidx][i] as f64 * c.t, 0.0);
                            let vm = c.var_mean(&p)
                                + (sig_d * sig_d + sig_c * sig_c) * p.u * p.u
                                + sig_p * sig_p * p.w * p.w;
                            let w = 1.0 / vm;
                            let rr = sh.mean_dn[i] as f64 - p.mean;
                            for k in 0..kk {
                                dv[k] = p.dn_per_e * c.t * basis[k][sidx][i] as f64;
                            }
                            for k in 0..kk {
                                b[k] += w * dv[k] * rr;
                                for l in 0..kk {
                                    a[k * kk + l] += w * dv[k] * dv[l];
                                }
                            }
                        }
                    }
                }
                (a, b)
            })
            .collect();
        let mut a = vec![0.0; kk * kk];
        let mut b = vec![0.0; kk];
        for (ba, bb) in &blocks {
            a.iter_mut().zip(ba).for_each(|(x, y)| *x += y);
            b.iter_mut().zip(bb).for_each(|(x, y)| *x += y);
        }
        (a, b)
    }
}
