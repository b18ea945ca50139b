//! Locate: the residuals of a model decomposed by shot and channel, signal level (photon
//! transfer), exposure time, field height (radial profile), rows and columns, spatial
//! frequency (slanted-edge MTF), temporal vs fixed pattern and illuminant.
use super::like::{Ctx, Eval, Rates, RowSel};
use super::model::{ModelState, ShotConst};
use rayon::prelude::*;

/// Radial bins of the field-height profile.
pub const RADIAL_BINS: usize = 12;

/// One (shot, channel) summary.
#[derive(Debug, Clone, PartialEq)]
pub struct ShotChannel {
    /// Shot index.
    pub shot: usize,
    /// Channel index.
    pub channel: usize,
    /// χ²/dof.
    pub chi2_per_dof: f64,
    /// Degrees of freedom.
    pub dof: f64,
    /// Mean of the frame means (data), DN.
    pub data_mean_dn: f64,
    /// Mean of the model's frame means, DN.
    pub model_mean_dn: f64,
    /// Mean signal above the zero-signal DN (model pedestal), data.
    pub data_signal_dn: f64,
    /// Mean residual over its standard error.
    pub mean_z: f64,
    /// Mean temporal variance, data (DN²; NaN with one frame).
    pub data_temporal_var: f64,
    /// Mean temporal variance, model (DN²).
    pub model_temporal_var: f64,
    /// Spatial variance of the frame means around the model beyond the temporal part, data
    /// (DN²): fixed pattern + mismatch.
    pub data_fixed_var: f64,
    /// The same predicted by the model (DN²).
    pub model_fixed_var: f64,
    /// Pixel-shots with frames at an ADC rail.
    pub censored: f64,
}

/// Per-shot profiles.
#[derive(Debug, Clone, PartialEq)]
pub struct ShotProfiles {
    /// Shot index.
    pub shot: usize,
    /// Field-height bins: (h centre, data signal ÷ model signal − 1, pixels).
    pub radial: Vec<(f64, f64, f64)>,
    /// Mean residual per column (DN).
    pub column_resid_dn: Vec<f64>,
    /// Mean residual per row (DN).
    pub row_resid_dn: Vec<f64>,
    /// Standard error of a column mean under the model (DN).
    pub column_se_dn: f64,
    /// Standard error of a row mean under the model (DN).
    pub row_se_dn: f64,
}

/// Slanted-edge MTF of one shot (green-most channel): data and model.
#[derive(Debug, Clone, PartialEq)]
pub struct EdgeMtf {
    /// Shot index.
    pub shot: usize,
    /// Frequencies (cycles/pixel).
    pub freq: Vec<f64>,
    /// MTF of the recording.
    pub data: Vec<f64>,
    /// MTF of the model's expected image.
    pub model: Vec<f64>,
    /// Edge-spread functions (distance px, data, model).
    pub esf: Vec<(f64, f64, f64)>,
}

/// Everything "locate" finds for one model.
#[derive(Debug, Clone)]
pub struct Located {
    /// χ²/dof over everything.
    pub chi2_per_dof: f64,
    /// Degrees of freedom.
    pub dof: f64,
    /// Per (shot, channel).
    pub shot_channels: Vec<ShotChannel>,
    /// Per shot.
    pub profiles: Vec<ShotProfiles>,
    /// Edge shots.
    pub mtf: Vec<EdgeMtf>,
    /// Hot pixels by the model's classification.
    pub hot_pixels: usize,
}

/// Per-pixel model of one shot: expected frame mean and normalised residual.
#[derive(Debug, Clone)]
pub struct ShotMaps {
    /// Model mean (DN).
    pub model_mean: Vec<f32>,
    /// (data − model) / σ of the frame mean (marginal).
    pub z: Vec<f32>,
}

impl Ctx<'_> {
    /// Model mean and normalised residual of every pixel of one shot.
    pub(crate) fn shot_maps(&self, state: &ModelState, rates: &Rates, s: usize) -> ShotMaps {
        let d = self.data;
        let sh = &d.shots[s];
        let c = ShotConst::for_shot(&state.sensor, sh);
        let sn = &state.sensor;
        let sig_u2 =
            sn.dsnu_sigma_v.powi(2) + sn.column_fpn.map_or(0.0, |c| c.offset_sigma_v.powi(2));
        let sig_p2 = (sn.prnu_sigma_percent / 100.0).powi(2);
        let rate = &rates[s];
        let (model_mean, z): (Vec<f32>, Vec<f32>) = (0..d.pixels())
            .into_par_iter()
            .map(|i| {
                let p = c.predict(rate[i] as f64 * c.t, 0.0);
                let vm = c.var_mean(&p) + sig_u2 * p.u * p.u + sig_p2 * p.w * p.w;
                let r = sh.mean_dn[i] as f64 - p.mean;
                (p.mean as f32, (r / vm.sqrt()) as f32)
            })
            .unzip();
        ShotMaps { model_mean, z }
    }

    /// The decompositions of "locate" for `state` (all pixels).
    pub(crate) fn locate(&self, state: &ModelState) -> Result<(Located, Eval), String> {
        let rates = self.rates(state)?;
        let ev = self.evaluate_memo(state, &rates, RowSel::All);
        let d = self.data;
        let nch = d.channels();
        let mut shot_channels = Vec::new();
        for (s, sh) in d.shots.iter().enumerate() {
            let c = ShotConst::for_shot(&state.sensor, sh);
            for ch in 0..nch {
                let x = &ev.per_sc[s * nch + ch];
                if x.dof <= 0.0 {
                    continue;
                }
                let n = x.n.max(1.0);
                let temporal_mean = x.sum_model_var / n / c.frames;
                shot_channels.push(ShotChannel {
                    shot: s,
                    channel: ch,
                    chi2_per_dof: x.chi2 / x.dof,
                    dof: x.dof,
                    data_mean_dn: x.sum_data / n,
                    model_mean_dn: x.sum_model / n,
                    data_signal_dn: x.sum_data / n - c.base_dn,
                    mean_z: x.sum_resid / (x.sum_var_mean.max(1e-30)).sqrt(),
                    data_temporal_var: if sh.has_variance() {
                        x.sum_data_var / n
                    } else {
                        f64::NAN
                    },
                    model_temporal_var: x.sum_model_var / n,
                    data_fixed_var: x.sum_r2 / n - temporal_mean,
                    model_fixed_var: x.sum_var_mean / n - temporal_mean,
                    censored: x.censored,
                });
            }
        }
        let mut profiles = Vec::new();
        let mut mtf = Vec::new();
        for s in 0..d.shots.len() {
            let maps = self.shot_maps(state, &rates, s);
            profiles.push(self.profiles(state, s, &maps));
            if let super::data::TargetClass::Edge { angle_deg } = d.shots[s].target {
                if let Some(m) = self.edge_mtf(s, angle_deg, &maps) {
                    mtf.push(m);
                }
            }
        }
        Ok((
            Located {
                chi2_per_dof: ev.chi2 / ev.dof.max(1.0),
                dof: ev.dof,
                shot_channels,
                profiles,
                mtf,
                hot_pixels: ev.hot_pixels,
            },
            ev,
        ))
    }

    fn profiles(&self, state: &ModelState, s: usize, maps: &ShotMaps) -> ShotProfiles {
        let d = self.data;
        let sh = &d.shots[s];
        let c = ShotConst::for_shot(&state.sensor, sh);
        let (rows, cols) = (d.rows, d.cols);
        let mut rad = vec![(0.0f64, 0.0f64, 0.0f64); RADIAL_BINS];
        let mut col_sum = vec![(0.0f64, 0.0f64); cols];
        let mut row_sum = vec![(0.0f64, 0.0f64); rows];
        let mut var_sum = 0.0;
        let mut n_all = 0.0;
        for r in 0..rows {
            for j in 0..cols {
                let i = r * cols + j;
                if sh.censored[i] {
                    continue;
                }
                let m = sh.mean_dn[i] as f64;
                let mu = maps.model_mean[i] as f64;
                let h = d.field_height(r, j);
                let b = ((h * RADIAL_BINS as f64) as usize).min(RADIAL_BINS - 1);
                rad[b].0 += m - c.base_dn;
                rad[b].1 += mu - c.base_dn;
                rad[b].2 += 1.0;
                let res = m - mu;
                col_sum[j].0 += res;
                col_sum[j].1 += 1.0;
                row_sum[r].0 += res;
                row_sum[r].1 += 1.0;
                let z = maps.z[i] as f64;
                if z != 0.0 && z.is_finite() {
                    var_sum += (res / z).powi(2);
                    n_all += 1.0;
                }
            }
        }
        let var_pix = if n_all > 0.0 { var_sum / n_all } else { 0.0 };
        ShotProfiles {
            shot: s,
            radial: rad
                .iter()
                .enumerate()
                .filter(|(_, x)| x.2 > 0.0 && x.1.abs() > 0.0)
                .map(|(b, x)| ((b as f64 + 0.5) / RADIAL_BINS as f64, x.0 / x.1 - 1.0, x.2))
                .collect(),
            column_resid_dn: col_sum.iter().map(|x| x.0 / x.1.max(1.0)).collect(),
            row_resid_dn: row_sum.iter().map(|x| x.0 / x.1.max(1.0)).collect(),
            column_se_dn: (var_pix / rows.max(1) as f64).sqrt(),
            row_se_dn: (var_pix / cols.max(1) as f64).sqrt(),
        }
    }

    /// Slanted-edge MTF (ISO 12233 style: pixel distance to the known edge line binned at a
    /// quarter pixel → edge-spread function → derivative → Hann-windowed DFT), for the channel
    /// with the most pixels, of the data mean and the model mean.
    fn edge_mtf(&self, s: usize, angle_deg: f64, maps: &ShotMaps) -> Option<EdgeMtf> {
        let d = self.data;
        let sh = &d.shots[s];
        let nch = d.channels();
        let mut counts = vec![0usize; nch];
        for &c in &d.channel {
            counts[c as usize] += 1;
        }
        let ch = (0..nch).max_by_key(|&c| counts[c])? as u8;
        let a = angle_deg.to_radians();
        let (ca, sa) = (a.cos(), a.sin());
        let (yc, xc) = ((d.rows as f64 - 1.0) / 2.0, (d.cols as f64 - 1.0) / 2.0);
        const OS: f64 = 4.0;
        let half = 12.0_f64.min(0.25 * d.rows.min(d.cols) as f64).max(4.0);
        let nb = (2.0 * half * OS) as usize;
        let mut acc = vec![(0.0f64, 0.0f64, 0.0f64); nb];
        for r in 0..d.rows {
            for j in 0..d.cols {
                let i = r * d.cols + j;
                if d.channel[i] != ch || sh.censored[i] {
                    continue;
                }
                let dist = (j as f64 - xc) * ca + (r as f64 - yc) * sa;
                if dist.abs() >= half {
                    continue;
                }
                let b = ((dist + half) * OS) as usize;
                if b < nb {
                    acc[b].0 += sh.mean_dn[i] as f64;
                    acc[b].1 += maps.model_mean[i] as f64;
                    acc[b].2 += 1.0;
                }
            }
        }
        // fill empty bins by interpolation from neighbours
        let mut esf: Vec<(f64, f64, f64)> = Vec::with_capacity(nb);
        for b in 0..nb {
            let x = (b as f64 + 0.5) / OS - half;
            if acc[b].2 > 0.0 {
                esf.push((x, acc[b].0 / acc[b].2, acc[b].1 / acc[b].2));
            }
        }
        if esf.len() < nb / 2 {
            return None;
        }
        let resample = |k: usize| -> Vec<f64> {
            (0..nb)
                .map(|b| {
                    let x = (b as f64 + 0.5) / OS - half;
                    let p = esf.partition_point(|e| e.0 < x);
                    let v = |e: &(f64, f64, f64)| if k == 1 { e.1 } else { e.2 };
                    if p == 0 {
                        v(&esf[0])
                    } else if p >= esf.len() {
                        v(&esf[esf.len() - 1])
                    } else {
                        let (e0, e1) = (&esf[p - 1], &esf[p]);
                        let t = (x - e0.0) / (e1.0 - e0.0);
                        v(e0) + t * (v(e1) - v(e0))
                    }
                })
                .collect()
        };
        let mtf_of = |e: &[f64]| -> Vec<f64> {
            let lsf: Vec<f64> = (0..nb)
                .map(|b| {
                    let lo = e[b.saturating_sub(1)];
                    let hi = e[(b + 1).min(nb - 1)];
                    let w = 0.5
                        - 0.5 * (2.0 * std::f64::consts::PI * (b as f64 + 0.5) / nb as f64).cos();
                    0.5 * (hi - lo) * w
                })
                .collect();
            let nf = nb / 2;
            let mut out = Vec::with_capacity(nf);
            let mut dc = 0.0;
            for k in 0..nf {
                let (mut re, mut im) = (0.0, 0.0);
                for (b, &l) in lsf.iter().enumerate() {
                    let ph = -2.0 * std::f64::consts::PI * (k * b) as f64 / nb as f64;
                    re += l * ph.cos();
                    im += l * ph.sin();
                }
                let m = (re * re + im * im).sqrt();
                if k == 0 {
                    dc = m.max(1e-30);
                }
                out.push(m / dc);
            }
            out
        };
        let (ed, em) = (resample(1), resample(2));
        let freq: Vec<f64> = (0..nb / 2).map(|k| k as f64 * OS / nb as f64).collect();
        // keep up to 1 cycle/pixel
        let keep = freq.iter().take_while(|&&f| f <= 1.0).count();
        let data = mtf_of(&ed);
        let model = mtf_of(&em);
        Some(EdgeMtf {
            shot: s,
            freq: freq[..keep].to_vec(),
            data: data[..keep].to_vec(),
            model: model[..keep].to_vec(),
            esf,
        })
    }
}
