//! The frame-sequence terms: what the per-pixel mean and temporal variance cannot show —
//! offsets shared by a whole row in one frame (`row_noise`) and the frame means moving with
//! the frame index (`black_level_drift`). Both come from the row means of every frame
//! ([`crate::mismatch::data::ShotData::row_means_dn`]); the pixels' own temporal noise enters
//! through the data's per-pixel temporal variances, so the terms do not depend on the model's
//! temporal noise (read, shot, RTN, hot pixels) and change only with σ_row and the drift rate.
//!
//! **Rows** (EMVA 1288 R4.0 §8.3): per shot with F ≥ 2 frames and row r, the deviation of the
//! row mean from the frame mean, y_r = a_r − ā, has across frames the variance
//! `V_r = σ²(1 − 1/R) + P_r(1 − 2/R) + ΣP/R²` with σ the row-noise σ (DN), R rows, and
//! `P_r = Σ_{i∈r} v_i / C² − (σ² + D)/C` the row mean's pixel part (v_i the pixel's temporal
//! sample variance, which holds σ² and the drift ramp's D = rate²F(F+1)/12 too). The sample
//! variance S_r of y_r over the frames is `V_r χ²(F−1)/(F−1)`: a Gamma log-likelihood
//! `−(F−1)/2 (ln V_r + S_r/V_r)`.
//!
//! **Frames**: the frame mean m_f of frame f (global index j_f) is the shot's mean plus
//! `rate·j_f` plus noise of variance `W = σ²/R + (Σ_i v_i − N(σ² + D))/N²`; with the shot's
//! average removed, `−½ Σ_f (m_f − m̄ − rate(j_f − j̄))²/W − (F−1)/2 ln W`.
//!
//! Rows with a censored pixel in the shot, and shots with censored pixels, are left out
//! (clipped values are not Gaussian).
use super::Ctx;
use crate::mismatch::model::ModelState;

impl Ctx<'_> {
    /// The log-likelihood of the frame-sequence terms under `state` (constants dropped).
    pub(crate) fn frame_terms_ll(&self, state: &ModelState) -> f64 {
        let d = self.data;
        let (rows, cols) = (d.rows, d.cols);
        if rows < 2 || cols < 2 {
            return 0.0;
        }
        let fx = &state.sensor.effects;
        let sigma_v = fx.row_noise.map_or(0.0, |r| r.sigma_v);
        let rate = fx.black_level_drift.map_or(0.0, |x| x.dn_per_frame);
        let (rf, cf, nf) = (rows as f64, cols as f64, (rows * cols) as f64);
        let mut ll = 0.0;
        let pre = self.frame_pre.get_or_init(|| {
            d.shots
                .iter()
                .map(|sh| {
                    if !sh.has_variance() {
                        return (Vec::new(), Vec::new());
                    }
                    (0..rows)
                        .map(|r| {
                            let px = r * cols..(r + 1) * cols;
                            (
                                sh.var_dn[px.clone()].iter().map(|&v| v as f64).sum::<f64>(),
                                !sh.censored[px].iter().any(|&c| c),
                            )
                        })
                        .unzip()
                })
                .collect()
        });
        for (si, sh) in d.shots.iter().enumerate() {
            let nfr = sh.frames;
            if nfr < 2 || !sh.has_variance() || sh.row_means_dn.len() != nfr * rows {
                continue;
            }
            let k = state.sensor.dn_per_output_v() * sh.analog_gain;
            let s2 = (k * sigma_v).powi(2);
            let f = nfr as f64;
            let dd = rate * rate * f * (f + 1.0) / 12.0;
            // per row: Σ v_i and whether a pixel is censored (data only: computed once)
            let (var_sums, ok_row) = &pre[si];
            let p_row: Vec<f64> = var_sums
                .iter()
                .map(|sv| (sv / (cf * cf) - (s2 + dd) / cf).max(1e-12))
                .collect();
            let frame_mean = |fi: usize| -> f64 {
                sh.row_means_dn[fi * rows..(fi + 1) * rows]
                    .iter()
                    .sum::<f64>()
                    / rf
            };
            let means: Vec<f64> = (0..nfr).map(frame_mean).collect();
            let p_sum: f64 = p_row.iter().sum();
            // rows
            for r in (0..rows).filter(|&r| ok_row[r]) {
                let y: Vec<f64> = (0..nfr)
                    .map(|fi| sh.row_means_dn[fi * rows + r] - means[fi])
                    .collect();
                let ym = y.iter().sum::<f64>() / f;
                let s = y.iter().map(|v| (v - ym).powi(2)).sum::<f64>() / (f - 1.0);
                let v = (s2 * (1.0 - 1.0 / rf) + p_row[r] * (1.0 - 2.0 / rf) + p_sum / (rf * rf))
                    .max(1e-12);
                ll -= 0.5 * (f - 1.0) * (v.ln() + s / v);
            }
            // frames (only shots without censored pixels)
            if ok_row.iter().all(|&x| x) {
                let w = (s2 / rf + p_sum / (rf * rf)).max(1e-12);
                let _ = nf;
                let jm = sh.first_frame as f64 + 0.5 * (f - 1.0);
                let mm = means.iter().sum::<f64>() / f;
                let mut q = 0.0;
                for (fi, m) in means.iter().enumerate() {
                    let j = sh.first_frame as f64 + fi as f64;
                    q += (m - mm - rate * (j - jm)).powi(2);
                }
                ll -= 0.5 * q / w + 0.5 * (f - 1.0) * w.ln();
            }
        }
        ll
    }
}
