//! Time within the exposure: per-row exposure windows (rolling or global shutter), lights
//! modulated by pulse-width modulation (PWM), rigid image motion during the exposure, and the
//! dark-current temperature law.
//!
//! Row r of a rolling-shutter sensor integrates over `[t_r, t_r + T_exp]` with
//! `t_r = r · row_time` (the electronic rolling shutter: rows are reset and read one row time
//! apart; El Gamal & Eltoukhy, "CMOS image sensors", IEEE Circuits & Devices Magazine 21(3),
//! 2005, §"Rolling shutter"; Liang, Chen & Chen, "Analysis and compensation of rolling shutter
//! effect", IEEE TIP 17(8), 2008, eq. 1). A global shutter is the special case `t_r = 0`.
//!
//! Each row collects `(1/T_exp) ∫_{t_r}^{t_r+T_exp} m(t) E(x − v t) dt` electrons per second
//! of the static rate, with `m(t)` the light's modulation normalised to a mean of 1 and `v`
//! the image velocity (pixels/s). For a steady light and no motion this is the static rate, so
//! the default ([`TimeModel::is_static`]) changes nothing.
//!
//! Units live in names: `_s`, `_hz`, `_px`, `_c` (degrees Celsius).
use crate::{ElectronRate, SensorModel};

/// When the rows of a frame start their exposure.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ShutterMode {
    /// Every row exposes over `[0, T_exp]`.
    #[default]
    Global,
    /// Row r exposes over `[r · row_time, r · row_time + T_exp]`.
    Rolling,
}

/// The readout of the sensor: shutter mode and row time.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Readout {
    /// Global or rolling shutter.
    pub mode: ShutterMode,
    /// Time between the exposure starts of consecutive rows (s); unused by a global shutter.
    pub row_time_s: f64,
}

impl Readout {
    /// Start of row `row`'s exposure window (s): `row · row_time_s` (rolling), 0 (global).
    pub fn row_start_s(&self, row: usize) -> f64 {
        match self.mode {
            ShutterMode::Global => 0.0,
            ShutterMode::Rolling => row as f64 * self.row_time_s,
        }
    }
}

/// A pulse-width-modulated light: on while `frac(f·t − phase) < duty_cycle`, off otherwise,
/// with the same mean as the steady light it replaces (its peak is `1 / duty_cycle` times it).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PwmLight {
    /// Modulation frequency f (Hz).
    pub frequency_hz: f64,
    /// Fraction D of each period the light is on, in (0, 1].
    pub duty_cycle: f64,
    /// Start of the on-phase as a fraction of the period, in [0, 1).
    pub phase: f64,
}

impl PwmLight {
    /// Cumulative on-time in period units of the unit pulse train up to `u` (periods):
    /// `G(u) = ⌊u⌋·D + min(u − ⌊u⌋, D)`.
    fn cumulative_on(&self, u: f64) -> f64 {
        let k = u.floor();
        k * self.duty_cycle + (u - k).min(self.duty_cycle)
    }

    /// The fraction of light a window `[start_s, start_s + exposure_s]` collects, relative
    /// to a steady light of the same mean: `[G(f(t₀+T) − φ) − G(f t₀ − φ)] / (f · D · T)`, the
    /// exact overlap of the interval with the periodic pulse train (1 for a steady light,
    /// D = 1, and whenever T is a multiple of 1/f).
    pub fn window_fraction(&self, start_s: f64, exposure_s: f64) -> f64 {
        if exposure_s <= 0.0 {
            // The limit T → 0: the instantaneous normalised level.
            let u = self.frequency_hz * start_s - self.phase;
            return if u - u.floor() < self.duty_cycle {
                1.0 / self.duty_cycle
            } else {
                0.0
            };
        }
        let f = self.frequency_hz;
        let on = self.cumulative_on(f * (start_s + exposure_s) - self.phase)
            - self.cumulative_on(f * start_s - self.phase);
        on / (f * self.duty_cycle * exposure_s)
    }

    /// The on-intervals of the light within `[t0_s, t1_s]` (s), clipped to it, in order.
    pub fn on_intervals_s(&self, t0_s: f64, t1_s: f64) -> Vec<(f64, f64)> {
        let f = self.frequency_hz;
        let (u0, u1) = (f * t0_s - self.phase, f * t1_s - self.phase);
        let mut out = Vec::new();
        let mut k = u0.floor();
        while k <= u1 {
            let a = ((k + self.phase) / f).max(t0_s);
            let b = ((k + self.duty_cycle + self.phase) / f).min(t1_s);
            if b > a {
                out.push((a, b));
            }
            k += 1.0;
        }
        out
    }

    /// Visibility `(max − min) / (max + min)` of the flicker bands of a rolling shutter
    /// (over all window starts) for exposure time T. With `f·T = n + ρ` (n whole, ρ ∈ [0, 1))
    /// the on-time of a window in periods lies between `n·D + max(0, ρ + D − 1)` and
    /// `n·D + min(ρ, D)` (a window of length ρ < 1 period overlaps one pulse of length D at
    /// most by min(ρ, D) and at least by ρ − (1 − D)); 0 when T is a multiple of 1/f.
    pub fn band_visibility(&self, exposure_s: f64) -> f64 {
        let x = self.frequency_hz * exposure_s;
        let (n, rho) = (x.floor(), x - x.floor());
        let d = self.duty_cycle;
        let hi = n * d + rho.min(d);
        let lo = n * d + (rho + d - 1.0).max(0.0);
        if hi + lo <= 0.0 {
            return 0.0;
        }
        (hi - lo) / (hi + lo)
    }
}

/// Period of the flicker bands of a rolling shutter, in rows: `(1 / f) / row_time`.
pub fn flicker_period_rows(light: &PwmLight, readout: &Readout) -> f64 {
    1.0 / (light.frequency_hz * readout.row_time_s)
}

/// Rigid motion of the image on the sensor during the exposure: at time t the irradiance is
/// `E(x − v t)` (x in pixels: column, row).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Motion {
    /// Image velocity `[v_x, v_y]` (pixels per second; x along columns, y along rows).
    pub velocity_px_per_s: [f64; 2],
}

/// The time model of one shot: readout, light modulation and motion.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TimeModel {
    /// The sensor's readout.
    pub readout: Readout,
    /// Light modulation (None: steady light).
    pub light: Option<PwmLight>,
    /// Image motion (None: static).
    pub motion: Option<Motion>,
}

impl TimeModel {
    /// The light-weighted mean time of row `row`'s window (s): `∫ t m(t) dt / ∫ m(t) dt`
    /// over `[t_r, t_r + T]` (`t_r + T/2` for a steady light). Under motion v the centroid
    /// of an edge sits at `e₀ + v · t̄_r`, so the skew of a rolling shutter is the row-to-row
    /// change of `v · t̄_r` (`v · row_time` exactly for a steady light).
    pub fn row_mean_time_s(&self, row: usize, exposure_s: f64) -> f64 {
        let t0 = self.readout.row_start_s(row);
        let pieces = match &self.light {
            Some(l) if exposure_s > 0.0 => l.on_intervals_s(t0, t0 + exposure_s),
            _ => return t0 + exposure_s / 2.0,
        };
        let (mut m1, mut m0) = (0.0, 0.0);
        for (a, b) in pieces {
            m1 += (b * b - a * a) / 2.0;
            m0 += b - a;
        }
        if m0 > 0.0 {
            m1 / m0
        } else {
            t0 + exposure_s / 2.0
        }
    }
}

/// One node of a row's time average: the image shift at that time and its weight.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShiftSample {
    /// Shift `v·t` (pixels, `[x, y]`).
    pub shift_px: [f64; 2],
    /// Weight (the weights of a row sum to the light fraction of its window).
    pub weight: f64,
}

/// `key = value: reason` (the key as written in the JSON files).
fn bad(field: &str, value: f64, reason: &str) -> String {
    format!("{field} = {value}: {reason}")
}

impl TimeModel {
    /// True when the model changes nothing: no light modulation, no motion (the readout
    /// then only shifts each row's window in time, which a steady static scene ignores).
    pub fn is_static(&self) -> bool {
        self.light.is_none() && self.motion.is_none()
    }

    /// Checks every field; the error names the key (as in camera.json / captures.json) and
    /// its value.
    pub fn validate(&self) -> Result<(), String> {
        let rt = self.readout.row_time_s;
        if !(rt.is_finite() && rt >= 0.0) {
            return Err(bad(
                "sensor.readout.row_time_us",
                rt * 1e6,
                "must be a finite number ≥ 0",
            ));
        }
        if let Some(l) = &self.light {
            if !(l.frequency_hz.is_finite() && l.frequency_hz > 0.0) {
                return Err(bad(
                    "light_modulation.frequency_hz",
                    l.frequency_hz,
                    "must be a positive finite number",
                ));
            }
            if !(l.duty_cycle > 0.0 && l.duty_cycle <= 1.0) {
                return Err(bad(
                    "light_modulation.duty_cycle",
                    l.duty_cycle,
                    "must be in (0, 1]",
                ));
            }
            if !(l.phase >= 0.0 && l.phase < 1.0) {
                return Err(bad(
                    "light_modulation.phase",
                    l.phase,
                    "must be a fraction of the period in [0, 1)",
                ));
            }
        }
        if let Some(m) = &self.motion {
            for (i, v) in m.velocity_px_per_s.iter().enumerate() {
                if !v.is_finite() {
                    return Err(bad(
                        &format!("motion.velocity_px_per_s[{i}]"),
                        *v,
                        "must be finite",
                    ));
                }
            }
        }
        Ok(())
    }

    /// The nodes of row `row`'s time average for exposure `exposure_s`, for interpolation on
    /// a lattice of step `stride_px = [columns, rows]` (the CFA tile).
    ///
    /// The window is cut at the light's edges and wherever a shift component crosses a
    /// multiple of the lattice step; inside each piece the light is constant and the
    /// bilinear interpolant along the straight path is a quadratic in t, so Simpson's rule
    /// (nodes at both ends and the middle, weights 1/6, 4/6, 1/6 of the piece) is exact.
    /// Weights include the normalised light level (`1/D` while on) and `1/T_exp`.
    pub fn row_samples(
        &self,
        row: usize,
        exposure_s: f64,
        stride_px: [f64; 2],
    ) -> Vec<ShiftSample> {
        self.row_samples_from(row, exposure_s, stride_px, 0.0)
    }

    /// [`TimeModel::row_samples`] of a frame whose first row starts its exposure at
    /// `frame_start_s` (a frame of a video): row r's window is
    /// `[frame_start + t_r, frame_start + t_r + T]`, the light's phase and the motion carry
    /// on from t = 0.
    pub fn row_samples_from(
        &self,
        row: usize,
        exposure_s: f64,
        stride_px: [f64; 2],
        frame_start_s: f64,
    ) -> Vec<ShiftSample> {
        let t0 = frame_start_s + self.readout.row_start_s(row);
        let t1 = t0 + exposure_s;
        let v = self.motion.map_or([0.0, 0.0], |m| m.velocity_px_per_s);
        if exposure_s <= 0.0 {
            let w = self.light.map_or(1.0, |l| l.window_fraction(t0, 0.0));
            return vec![ShiftSample {
                shift_px: [v[0] * t0, v[1] * t0],
                weight: w,
            }];
        }
        let (pieces, level) = match &self.light {
            Some(l) => (l.on_intervals_s(t0, t1), 1.0 / l.duty_cycle),
            None => (vec![(t0, t1)], 1.0),
        };
        let mut out = Vec::new();
        for (a, b) in pieces {
            // Break points where v_i·t crosses a multiple of the lattice step.
            let mut cuts = vec![a, b];
            for axis in 0..2 {
                if v[axis] == 0.0 {
                    continue;
                }
                let (sa, sb) = (v[axis] * a / stride_px[axis], v[axis] * b / stride_px[axis]);
                let (lo, hi) = (sa.min(sb), sa.max(sb));
                let mut k = lo.floor() + 1.0;
                while k < hi {
                    cuts.push(k * stride_px[axis] / v[axis]);
                    k += 1.0;
                }
            }
            cuts.sort_by(f64::total_cmp);
            cuts.dedup();
            for w in cuts.windows(2) {
                let (p, q) = (w[0], w[1]);
                if q <= p {
                    continue;
                }
                let scale = level * (q - p) / exposure_s / 6.0;
                for (t, k) in [(p, 1.0), (0.5 * (p + q), 4.0), (q, 1.0)] {
                    out.push(ShiftSample {
                        shift_px: [v[0] * t, v[1] * t],
                        weight: k * scale,
                    });
                }
            }
        }
        out
    }
}

/// Bilinear interpolation of `plane` at `(y, x)` on the sub-lattice of step `(sr, sc)`
/// through pixel `(r, c)` (its CFA channel), the lattice clamped to the image (the image
/// continues beyond its border, as in [`crate::box_weights`]).
#[allow(clippy::too_many_arguments)]
fn lattice_bilinear(
    plane: &[f32],
    rows: usize,
    cols: usize,
    (sr, sc): (usize, usize),
    (r, c): (usize, usize),
    y: f64,
    x: f64,
) -> f64 {
    let (pr, pc) = (r % sr, c % sc);
    let nr = (rows - pr).div_ceil(sr); // lattice rows of this phase
    let nc = (cols - pc).div_ceil(sc);
    let uy = ((y - pr as f64) / sr as f64).clamp(0.0, (nr - 1) as f64);
    let ux = ((x - pc as f64) / sc as f64).clamp(0.0, (nc - 1) as f64);
    let (iy, ix) = (uy.floor() as usize, ux.floor() as usize);
    let (fy, fx) = (uy - iy as f64, ux - ix as f64);
    let (iy1, ix1) = ((iy + 1).min(nr - 1), (ix + 1).min(nc - 1));
    let at = |a: usize, b: usize| plane[(pr + a * sr) * cols + pc + b * sc] as f64;
    (1.0 - fy) * ((1.0 - fx) * at(iy, ix) + fx * at(iy, ix1))
        + fy * ((1.0 - fx) * at(iy1, ix) + fx * at(iy1, ix1))
}

/// The electron rate each pixel collects on average over its row's exposure window under
/// `model`: `(1/T) ∫_{t_r}^{t_r+T} m(t) R(x − v t) dt` with R the static rate, m the
/// normalised light level and v the image velocity. R between pixels of one CFA channel is
/// the bilinear interpolant on that channel's lattice, and the time integral is exact for
/// it ([`TimeModel::row_samples`]). Returns a copy of `rate` when the model is static.
pub fn time_averaged_rate(
    sensor: &SensorModel,
    rate: &ElectronRate,
    exposure_s: f64,
    model: &TimeModel,
) -> ElectronRate {
    time_averaged_rate_from(sensor, rate, exposure_s, model, 0.0)
}

/// [`time_averaged_rate`] of a frame starting at `frame_start_s` (frame k of a video at
/// `k / frame_rate`; [`TimeModel::row_samples_from`]).
pub fn time_averaged_rate_from(
    sensor: &SensorModel,
    rate: &ElectronRate,
    exposure_s: f64,
    model: &TimeModel,
    frame_start_s: f64,
) -> ElectronRate {
    if model.is_static() {
        return rate.clone();
    }
    let (rows, cols) = (rate.rows, rate.cols);
    let stride = (sensor.cfa.tile_rows().max(1), sensor.cfa.tile_cols().max(1));
    let mut out = vec![0f32; rows * cols];
    for (r, row_out) in out.chunks_mut(cols).enumerate() {
        let samples = model.row_samples_from(
            r,
            exposure_s,
            [stride.1 as f64, stride.0 as f64],
            frame_start_s,
        );
        if model.motion.is_none() {
            let w: f64 = samples.iter().map(|s| s.weight).sum();
            for (o, i) in row_out.iter_mut().zip(&rate.electrons_per_s[r * cols..]) {
                *o = (*i as f64 * w) as f32;
            }
            continue;
        }
        for (c, o) in row_out.iter_mut().enumerate() {
            let mut acc = 0.0;
            for s in &samples {
                let y = r as f64 - s.shift_px[1];
                let x = c as f64 - s.shift_px[0];
                acc += s.weight
                    * lattice_bilinear(&rate.electrons_per_s, rows, cols, stride, (r, c), y, x);
            }
            *o = acc as f32;
        }
    }
    ElectronRate {
        rows,
        cols,
        electrons_per_s: out,
    }
}

/// Dark current at temperature `temperature_c`: `dark(T_ref) · 2^((T − T_ref)/T_double)`,
/// the empirical doubling law of silicon dark current near room temperature (Janesick,
/// "Scientific Charge-Coupled Devices", SPIE 2001, §5.6: dark current doubles every
/// 5–9 °C; EMVA 1288 Release 4.0, §8.2 "dark current versus temperature").
pub fn dark_at_temperature(
    dark_at_reference: f64,
    temperature_c: f64,
    reference_temperature_c: f64,
    doubling_temperature_c: f64,
) -> f64 {
    dark_at_reference * ((temperature_c - reference_temperature_c) / doubling_temperature_c).exp2()
}
