//! The camera model the diagnosis fits: the forward model's mean photo-electron rates (from a
//! [`Forward`] implementation, the optics and spectral stages) followed by the sensor chain of
//! capture-format.md steps 3–7 with the effect blocks, evaluated here for the per-pixel mean
//! and variance of the recorded DN (with well, swing and ADC clipping as censoring).
use super::num::censored;
use camsim_sensor::{Crosstalk, Nonlinearity, SensorModel};
use std::sync::Arc;

/// The optics and spectral effects that change the mean photo-electron rates, evaluated by a
/// [`Forward`]. `None` = as in the believed camera; `Some` = this block, in its fitted form
/// (effects contract), replacing the believed camera's.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct RateSpec {
    /// `optics.relative_illumination.falloff` polynomial coefficients a1, a2, a3.
    pub falloff: Option<Vec<f64>>,
    /// `optics.veiling_glare.fraction`.
    pub glare_fraction: Option<f64>,
    /// `optics.defocus` Gaussian σ (µm).
    pub defocus_sigma_um: Option<f64>,
    /// `optics.distortion` polynomial (k1, k2).
    pub distortion: Option<[f64; 2]>,
    /// `optics.lateral_color` linear displacement d (µm).
    pub lateral_color_um: Option<f64>,
    /// `sensor.ir_leakage` constant added QE per channel index.
    pub ir_leakage: Option<Vec<f64>>,
    /// `sensor.qe_shift` shift (nm) per channel index.
    pub qe_shift_nm: Option<Vec<f64>>,
}

impl RateSpec {
    /// A key identifying the spec (for caches).
    pub fn key(&self) -> String {
        format!("{self:?}")
    }
}

/// The optics + pixel-integration stage of the forward model.
pub trait Forward: Sync {
    /// Mean photo-electron rate (e⁻/s) of every pixel (row-major) of every shot, in the order
    /// of the data set's shots, for the believed camera with `spec` applied; no crosstalk (the
    /// diagnosis applies it), no dark current.
    fn rates(&self, spec: &RateSpec) -> Result<Vec<Arc<Vec<f32>>>, String>;

    /// [`Forward::rates`] where only the pixel rows `rows` (ascending) must hold the model's
    /// values, the others may be 0. Default: [`Forward::rates`].
    fn rates_rows(&self, spec: &RateSpec, rows: &[usize]) -> Result<Vec<Arc<Vec<f32>>>, String> {
        let _ = rows;
        self.rates(spec)
    }

    /// Whether [`Forward::rates_rows`] of `rows` costs less than [`Forward::rates`] (it runs
    /// only bands of rows around them). Default: no.
    fn row_window(&self, rows: &[usize]) -> bool {
        let _ = rows;
        false
    }
}

/// Everything the diagnosis can change in the camera.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelState {
    /// The sensor: base parameters and the sensor effect blocks (`column_fpn`,
    /// `effects.hot_pixels`, `effects.nonlinearity`, `effects.crosstalk`).
    pub sensor: SensorModel,
    /// Photo-signal factor relative to the believed camera (`exposure_scale`).
    pub exposure_factor: f64,
    /// Effects evaluated by the forward model.
    pub rates: RateSpec,
    /// Frames in the capture set (the black-level drift's magnitude is the drift over them).
    pub frames_in_set: u64,
}

/// Per-shot constants of the sensor chain.
#[derive(Debug, Clone, Copy)]
pub(crate) struct ShotConst {
    pub t: f64,
    pub dark_e: f64,
    pub well: f64,
    pub g: f64,
    pub nl: Option<Nonlinearity>,
    /// DN per pixel volt: analog gain · (2^bits − 1) / swing.
    pub k: f64,
    /// DN at zero pixel voltage: offset·dn_per_v + black.
    pub base_dn: f64,
    /// Highest DN the chain can output (swing clip, ADC maximum).
    pub hi_dn: f64,
    /// Temporal variance independent of the signal (DN²): read (+ reset) + quantisation.
    pub const_var: f64,
    pub shot_on: bool,
    pub dark_on: bool,
    /// Frames.
    pub frames: f64,
    /// PRNU σ (fraction).
    pub prnu: f64,
    /// The ADC saturates below the well's DN (then the ADC clip alone matters).
    pub adc_first: bool,
    /// Variance of the fixed volt offsets (DSNU² + column σ², V²).
    pub fix_v2: f64,
}

/// The model's prediction for one pixel of one shot.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Pred {
    /// Expected DN of one frame (clipping included).
    pub mean: f64,
    /// Temporal variance of one frame (DN²).
    pub var_t: f64,
    /// Fixed-pattern variance beyond the linear DSNU/PRNU loadings (DN²): how clipping bends
    /// the fixed pattern near the well or an ADC rail (treated as independent per shot).
    pub var_x: f64,
    /// DN per volt of a fixed offset (DSNU, column offset).
    pub u: f64,
    /// DN per unit relative gain error (PRNU P).
    pub w: f64,
    /// DN per extra dark electron (hot pixels).
    pub dn_per_e: f64,
    /// Mean DN before the ADC clip.
    pub y: f64,
    /// Temporal variance before the clip (DN²).
    pub s2_t: f64,
    /// Fixed-pattern variance before the clip (DN²).
    pub s2_f: f64,
    /// Upper clip (DN).
    pub hi: f64,
}

/// Below this many standard deviations from a clip, the clip is treated as censoring.
const CENSOR_SIGMAS: f64 = 8.0;

impl ShotConst {
    pub fn new(sensor: &SensorModel, exposure_s: f64, analog_gain: f64, frames: usize) -> Self {
        let dnpv = sensor.dn_per_output_v();
        let k = analog_gain * dnpv;
        let black = sensor.black_level_dn;
        let base_dn = sensor.analog_offset_v * dnpv + black;
        let read = if sensor.noise.read {
            sensor.read_noise_v
        } else {
            0.0
        };
        let reset = sensor
            .reset_noise
            .filter(|r| !r.cds)
            .map_or(0.0, |r| r.sigma_v);
        let mut c = ShotConst {
            t: exposure_s,
            dark_e: exposure_s * sensor.dark_voltage_v_per_s / sensor.conversion_gain_v_per_e,
            well: sensor.well_capacity_e,
            g: sensor.conversion_gain_v_per_e,
            nl: sensor.effects.nonlinearity,
            k,
            base_dn,
            hi_dn: sensor.max_dn().min(sensor.voltage_swing_v * dnpv + black),
            const_var: k * k * (read * read + reset * reset) + 1.0 / 12.0,
            shot_on: sensor.noise.shot,
            dark_on: sensor.noise.dark,
            frames: frames.max(1) as f64,
            prnu: if sensor.noise.prnu {
                sensor.prnu_sigma_percent / 100.0
            } else {
                0.0
            },
            fix_v2: if sensor.noise.dsnu {
                sensor.dsnu_sigma_v.powi(2)
            } else {
                0.0
            } + sensor.column_fpn.map_or(0.0, |c| c.offset_sigma_v.powi(2)),
            adc_first: false,
        };
        c.adc_first = c.base_dn + c.k * c.nonlinear(c.well * c.g).0
            > c.hi_dn - CENSOR_SIGMAS * c.const_var.sqrt();
        c
    }

    /// [`ShotConst::new`] for a shot of the data set, with the frame-dependent blocks of
    /// `camsim_sensor::line_noise`: the dark voltage at the shot's temperature
    /// (`dark_temperature`), the row-noise variance k²σ_row² in every frame (`row_noise`),
    /// and the black-level drift `rate·j` averaged over the shot's frames
    /// j = first … first + F − 1 (mean `rate·(first + (F−1)/2)`; the ramp adds its sample
    /// variance `rate²·F(F+1)/12` to the temporal variance).
    pub fn for_shot(sensor: &SensorModel, shot: &super::data::ShotData) -> Self {
        let dark = camsim_sensor::dark_voltage_at(sensor, shot.temperature_c);
        let owned;
        let sensor = if dark != sensor.dark_voltage_v_per_s {
            let mut s = sensor.clone();
            s.dark_voltage_v_per_s = dark;
            owned = s;
            &owned
        } else {
            sensor
        };
        let mut c = ShotConst::new(sensor, shot.exposure_s, shot.analog_gain, shot.frames);
        let fx = &sensor.effects;
        if fx.row_noise.is_some() || fx.black_level_drift.is_some() {
            if let Some(r) = fx.row_noise {
                c.const_var += c.k * c.k * r.sigma_v * r.sigma_v;
            }
            if let Some(d) = fx.black_level_drift {
                let f = shot.frames.max(1) as f64;
                c.base_dn += d.dn_per_frame * (shot.first_frame as f64 + 0.5 * (f - 1.0));
                c.const_var += d.dn_per_frame * d.dn_per_frame * f * (f + 1.0) / 12.0;
            }
            c.adc_first = c.base_dn + c.k * c.nonlinear(c.well * c.g).0
                > c.hi_dn - CENSOR_SIGMAS * c.const_var.sqrt();
        }
        c
    }

    /// Pixel voltage after the nonlinearity, and its derivative.
    #[inline]
    fn nonlinear(&self, v: f64) -> (f64, f64) {
        match self.nl {
            None => (v, 1.0),
            Some(Nonlinearity::Quadratic {
                coefficient_per_v: a,
            }) => {
                if a <= 0.0 {
                    (v, 1.0)
                } else if v < 0.5 / a {
                    (v - a * v * v, 1.0 - 2.0 * a * v)
                } else {
                    (0.25 / a, 0.0)
                }
            }
            Some(Nonlinearity::Tanh { saturation_v: s }) => {
                let th = (v / s).tanh();
                (s * th, 1.0 - th * th)
            }
        }
    }

    /// Mean and variance of one frame's DN of a pixel with `e` mean photo-electrons and
    /// `extra_dark_e` extra dark electrons (hot pixel), capture-format.md steps 3–7:
    /// n = min(Poisson(e(1+P) + d), well), v = NL(n g) + D, DN = clamp(round((G v + offset)
    /// /swing·(2^bits−1) + black)) with read noise and quantisation (1/12 DN²) before the clamp.
    ///
    /// Away from the clips everything is linear: the frame mean is the expected image, its
    /// temporal variance the Poisson + read + quantisation variance, and the fixed pattern
    /// enters through the loadings u (DN per volt of offset) and w (DN per unit gain error).
    /// Near the well or an ADC rail the clips are treated as censoring of a Gaussian whose
    /// variance includes the pixel's unknown fixed pattern (moment matching): the mean is the
    /// censored mean over pixels, the loadings are scaled by the unclipped probability and
    /// what the clip bends out of the fixed pattern goes to `var_x`.
    #[inline]
    pub fn predict(&self, e: f64, extra_dark_e: f64) -> Pred {
        let e = e.max(0.0);
        let dark = self.dark_e + extra_dark_e;
        let lam = e + dark;
        let var_n = if self.shot_on { e } else { 0.0 } + if self.dark_on { dark } else { 0.0 };
        let var_p = (self.prnu * e).powi(2);
        let var_ne = var_n + var_p;
        // Step 4: the well, as censoring of the electron count (temporal + PRNU spread) —
        // unless the ADC saturates below the well's DN, when the ADC clip alone matters.
        let adc_first = self.adc_first;
        let (n_mean, n_var_t, n_var_f, rho_w) = if adc_first {
            (lam, var_n, var_p, 1.0)
        } else if var_ne > 0.0 && {
            // well − λ < CENSOR_SIGMAS·σ, without the square root
            let dw = self.well - lam;
            dw < 0.0 || dw * dw < CENSOR_SIGMAS * CENSOR_SIGMAS * var_ne
        } {
            let c = censored(lam, var_ne.sqrt(), f64::NEG_INFINITY, self.well);
            let unsat = 1.0 - c.p_hi;
            let t = var_n * unsat;
            (c.mean, t, (c.var - t).max(0.0), unsat)
        } else if lam >= self.well {
            (self.well, 0.0, 0.0, 0.0)
        } else {
            (lam, var_n, var_p, 1.0)
        };
        // Step 5: v = NL(n g).
        let (v, slope) = self.nonlinear(n_mean * self.g);
        let dn_per_e = self.k * slope * self.g;
        let y = self.base_dn + self.k * v;
        let var_t = dn_per_e * dn_per_e * n_var_t + self.const_var;
        let var_f = dn_per_e * dn_per_e * n_var_f + self.k * self.k * self.fix_v2;
        // linear loadings and what the well bent out of the PRNU pattern
        let w_lin = rho_w * dn_per_e * e;
        let x_well =
            (dn_per_e * dn_per_e * n_var_f - w_lin * w_lin * self.prnu * self.prnu).max(0.0);
        // within CENSOR_SIGMAS·σ of a rail (compared squared: no square root on the fast path)
        let near = y.min(self.hi_dn - y);
        if near < 0.0 || near * near < CENSOR_SIGMAS * CENSOR_SIGMAS * (var_t + var_f) {
            let s_tot = (var_t + var_f).sqrt();
            // Steps 6–7: the ADC rails, censoring the marginal (temporal + fixed) distribution.
            let c = censored(y, s_tot, 0.0, self.hi_dn);
            let rho = (1.0 - c.p_lo - c.p_hi).max(0.0);
            let vt = (var_t * rho).max(1e-6);
            let u = rho * self.k;
            let w = rho * w_lin;
            let lin = u * u * self.fix_v2 + w * w * self.prnu * self.prnu;
            Pred {
                mean: c.mean,
                var_t: vt,
                var_x: (c.var - vt - lin).max(0.0),
                u,
                w,
                dn_per_e: rho * dn_per_e,
                y,
                s2_t: var_t,
                s2_f: var_f,
                hi: self.hi_dn,
            }
        } else {
            Pred {
                mean: y,
                var_t,
                var_x: x_well,
                u: self.k,
                w: w_lin,
                dn_per_e,
                y,
                s2_t: var_t,
                s2_f: var_f,
                hi: self.hi_dn,
            }
        }
    }

    /// Variance of the frame mean (DN²) without the linear fixed-pattern loadings.
    #[inline]
    pub fn var_mean(&self, p: &Pred) -> f64 {
        p.var_t / self.frames + p.var_x
    }
}

/// Applies `sensor.crosstalk` to one rate image (same rule as the simulator's
/// `camsim_sensor::apply_crosstalk`: each pixel keeps 1 − total, neighbours receive their
/// fractions, charge leaving the array is lost).
pub(crate) fn crosstalk_image(ct: &Crosstalk, rows: usize, cols: usize, src: &[f32]) -> Vec<f32> {
    let mut rate = camsim_sensor::ElectronRate {
        rows,
        cols,
        electrons_per_s: src.to_vec(),
    };
    camsim_sensor::apply_crosstalk(ct, &mut rate);
    rate.electrons_per_s
}

#[cfg(test)]
mod tests {
    use super::*;

    pub(crate) fn sensor() -> SensorModel {
        SensorModel::mono_test(4, 4)
    }

    #[test]
    fn prediction_matches_closed_form_away_from_clips() {
        let s = sensor();
        let c = ShotConst::new(&s, 0.1, 2.0, 4);
        let p = c.predict(1000.0, 0.0);
        // DN = black + G·(2^12−1)/swing · g · (e + t·V/g)
        let k = 2.0 * 4095.0;
        let d = 0.1 * 1e-3 / 1e-4;
        let mean = 64.0 + k * 1e-4 * (1000.0 + d);
        assert!((p.mean - mean).abs() < 1e-9);
        let var = (k * 1e-4).powi(2) * (1000.0 + d) + k * k * 1e-6 + 1.0 / 12.0;
        assert!((p.var_t - var).abs() < 1e-9 * var);
        assert!((p.w - k * 1e-4 * 1000.0).abs() < 1e-9);
        assert_eq!(p.var_x, 0.0);
    }

    #[test]
    fn saturated_pixels_have_no_variance_and_full_rail_probability() {
        let s = sensor();
        let c = ShotConst::new(&s, 1.0, 1.0, 2);
        let p = c.predict(1e6, 0.0);
        // well: 10000 e⁻ · 1e-4 V · 4095 DN/V + 64 = 4159 > 4095: ADC clip
        assert!((p.mean - 4095.0).abs() < 1e-6, "{}", p.mean);
        let r = crate::mismatch::like::rail_stats(&p, 2.0, 0.0, 2.0);
        assert!(r.mean > 1.999 && r.ll > -1e-6, "{r:?}");
        assert!(p.u < 1e-6);
    }
}
