//! The fixed-pattern term of one pixel: its residual vector over all shots is Gaussian with
//! covariance diag(σ_t²/F) + σ_D² u uᵀ + σ_P² w wᵀ (Woodbury form), with the temporal term
//! (`temporal.rs`) folded into the determinant and censored shots replaced by their
//! rail likelihood (`rail.rs`).
use super::column::ColView;
use super::rail::rail_stats;
use super::temporal::temporal_ll;
use super::{Ctx, PixShot};
use crate::mismatch::model::{Pred, ShotConst};
use crate::mismatch::num::Woodbury;

impl Ctx<'_> {
    /// Log-likelihood of one pixel over all shots (normal component).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn pixel_ll<'c>(
        &self,
        px: &[PixShot],
        preds: &[Pred],
        consts: &[ShotConst],
        col: Option<ColView<'c>>,
        sig_d: f64,
        sig_p: f64,
        sig_c_pixel: f64,
    ) -> f64 {
        let d = self.data;
        let mut wb = Woodbury::default();
        let mut ll = 0.0;
        let sig_u = (sig_d * sig_d + sig_c_pixel * sig_c_pixel).sqrt();
        for (sidx, (sh, x)) in d.shots.iter().zip(px).enumerate() {
            let p = &preds[sidx];
            let f = consts[sidx].frames;
            let (nlo, nhi) = (x.n_lo as f64, x.n_hi as f64);
            if x.censored {
                ll += rail_stats(p, f, nlo, nhi).ll;
                continue;
            }
            let mut r = x.mean as f64 - p.mean;
            let (mut kappa, mut sk) = (1.0, 1.0);
            if let Some(c) = col.and_then(|v| v.get(sidx)) {
                r -= c.c_hat;
                kappa = c.kappa;
                sk = c.sqrt_kappa;
            }
            let a = kappa * consts[sidx].var_mean(p);
            wb.add(r, a, [sk * sig_u * p.u, sk * sig_p * p.w]);
            if sh.has_variance() {
                // temporal_ll, with its −(F−1)/2 · ln σ² folded into the determinant
                let k = f as u32 - 1;
                if f == (k + 1) as f64 && k <= 64 {
                    ll += -0.5 * (f - 1.0) * (x.var as f64 / p.var_t);
                    wb.mul_det_pow(p.var_t, k);
                } else {
                    ll += temporal_ll(x.var as f64, p.var_t, f);
                }
            }
        }
        if !wb.is_empty() {
            ll += wb.log_likelihood();
        }
        ll
    }
}
