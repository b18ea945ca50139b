//! Optional optics effect blocks of `spec/effects.md` (the JSON contract is docs/effects.md):
//! exposure scale, extra relative-illumination fall-off, distortion, lateral colour, defocus
//! and veiling glare. Every block is absent by default and then costs nothing.
//!
//! Field height `h` is the distance from the sensor centre divided by the sensor's
//! half-diagonal ([`OpticsEffects::half_diagonal_m`]). [`crate::form_image`] applies, after the
//! camera equation: relative illumination × [`Falloff`] → [`OpticsEffects::exposure_scale`] →
//! [`Distortion`] and [`LateralColor`] (one geometric warp per wavelength plane) → the base blur
//! (and diffuser) → [`Defocus`] → veiling glare.
use crate::error::OpticsError;
use crate::kernels::{self, gaussian_kernel_1d, pillbox_psf};
use crate::Padding;
use camsim_core::SpectralImage;
use rayon::prelude::*;
use std::f64::consts::PI;

/// The optional optics effect blocks and the sensor geometry they refer to.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct OpticsEffects {
    /// Width of the sensor (m): field heights and the glare mean refer to it (0 = the image).
    pub sensor_width_m: f64,
    /// Height of the sensor (m).
    pub sensor_height_m: f64,
    /// `exposure_scale`: factor multiplying the sensor irradiance.
    pub exposure_scale: Option<f64>,
    /// `relative_illumination`: extra fall-off F(h) multiplying the irradiance.
    pub falloff: Option<Falloff>,
    /// `veiling_glare`: fraction f of the mean irradiance added uniformly.
    pub veiling_glare: Option<f64>,
    /// `defocus`: extra blur after the base blur.
    pub defocus: Option<Defocus>,
    /// `distortion`: radial remapping of image height.
    pub distortion: Option<Distortion>,
    /// `lateral_color`: wavelength-dependent magnification.
    pub lateral_color: Option<LateralColor>,
}

/// Extra relative illumination F(h) multiplying the model's (cos⁴, none, isetcam).
#[derive(Debug, Clone, PartialEq)]
pub enum Falloff {
    /// Fitted form: `1 + a1·h² + a2·h⁴ + a3·h⁶ + …` (coefficient i multiplies h^(2i+2)).
    Polynomial {
        /// a1, a2, …
        coefficients: Vec<f64>,
    },
    /// Generator form, mechanical vignetting: the overlap area of two unit circles whose
    /// centres are `s·h` apart, divided by π (entrance pupil clipped by a second stop).
    TwoCircle {
        /// Centre separation s at h = 1 (in units of the circles' radius), in [0, 2].
        separation_at_h1: f64,
    },
}

/// Overlap area of two unit circles with centres `d` apart, divided by π:
/// `(2 acos(d/2) − (d/2)√(4 − d²)) / π` for `d < 2`, else 0.
pub fn two_circle_overlap_fraction(d: f64) -> f64 {
    let d = d.abs();
    if d >= 2.0 {
        return 0.0;
    }
    let a = d / 2.0;
    (2.0 * a.acos() - 2.0 * a * (1.0 - a * a).sqrt()) / PI
}

impl Falloff {
    /// F(h).
    pub fn factor(&self, h: f64) -> f64 {
        match self {
            Falloff::Polynomial { coefficients } => {
                let h2 = h * h;
                let mut p = h2;
                let mut f = 1.0;
                for a in coefficients {
                    f += a * p;
                    p *= h2;
                }
                f.max(0.0)
            }
            Falloff::TwoCircle { separation_at_h1 } => {
                two_circle_overlap_fraction(separation_at_h1 * h)
            }
        }
    }
    /// Magnitude of effects.md: `1 − F(1)`.
    pub fn magnitude(&self) -> f64 {
        1.0 - self.factor(1.0)
    }
}

/// Extra blur, identical for every wavelength plane.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Defocus {
    /// Fitted form: Gaussian PSF of standard deviation σ; MTF `exp(−2π²σ²f²)`.
    Gaussian {
        /// σ (µm).
        sigma_um: f64,
    },
    /// Generator form: uniform disk (geometric defocus) of radius r; MTF `2 J₁(2πrf)/(2πrf)`.
    Pillbox {
        /// r (µm).
        radius_um: f64,
    },
}

impl Defocus {
    /// The MTF at spatial frequency `f` (cycles/µm).
    pub fn mtf(&self, f_per_um: f64) -> f64 {
        match *self {
            Defocus::Gaussian { sigma_um } => {
                (-2.0 * PI * PI * sigma_um * sigma_um * f_per_um * f_per_um).exp()
            }
            Defocus::Pillbox { radius_um } => {
                let x = 2.0 * PI * radius_um * f_per_um;
                if x.abs() < 1e-8 {
                    1.0
                } else {
                    2.0 * crate::formulas::bessel_j1(x) / x
                }
            }
        }
    }

    /// Magnitude of effects.md: σ (µm) of the Gaussian whose MTF best fits this blur's MTF in
    /// least squares over 0 … the pixel Nyquist frequency `1/(2p)` (256 equally spaced
    /// frequencies; the Gaussian kind returns its own σ).
    pub fn equivalent_sigma_um(&self, pixel_pitch_um: f64) -> f64 {
        match *self {
            Defocus::Gaussian { sigma_um } => sigma_um,
            Defocus::Pillbox { radius_um } => {
                equivalent_gaussian_sigma_um(|f| self.mtf(f), pixel_pitch_um, 2.0 * radius_um)
            }
        }
    }

    /// Margin (µm) the blur needs around the image.
    fn reach_um(&self) -> f64 {
        match *self {
            Defocus::Gaussian { sigma_um } => 4.0 * sigma_um,
            Defocus::Pillbox { radius_um } => radius_um,
        }
    }
}

/// σ (µm) of the Gaussian MTF `exp(−2π²σ²f²)` closest in least squares to `mtf` on 256
/// frequencies from 0 to `1/(2·pixel_pitch)`; searched on [0, `sigma_max_um`] (a scan of 400
/// values, then golden-section refinement of the best bracket).
pub fn equivalent_gaussian_sigma_um(
    mtf: impl Fn(f64) -> f64,
    pixel_pitch_um: f64,
    sigma_max_um: f64,
) -> f64 {
    let nyquist = 0.5 / pixel_pitch_um;
    let n = 256;
    let fs: Vec<f64> = (0..n)
        .map(|k| nyquist * k as f64 / (n - 1) as f64)
        .collect();
    let target: Vec<f64> = fs.iter().map(|&f| mtf(f)).collect();
    let cost = |s: f64| -> f64 {
        fs.iter()
            .zip(&target)
            .map(|(&f, &m)| ((-2.0 * PI * PI * s * s * f * f).exp() - m).powi(2))
            .sum()
    };
    let hi = sigma_max_um.max(pixel_pitch_um);
    let m = 400;
    let step = hi / m as f64;
    let best = (0..=m)
        .map(|i| i as f64 * step)
        .min_by(|a, b| cost(*a).total_cmp(&cost(*b)))
        .unwrap_or(0.0);
    let (mut a, mut b) = ((best - step).max(0.0), best + step);
    let g = (5f64.sqrt() - 1.0) / 2.0;
    for _ in 0..80 {
        let c = b - g * (b - a);
        let d = a + g * (b - a);
        if cost(c) < cost(d) {
            b = d;
        } else {
            a = c;
        }
    }
    0.5 * (a + b)
}

/// Radial distortion: a scene point at normalised height h lands at `h·D(h)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Distortion {
    /// Fitted form: `D = 1 + k1·h² + k2·h⁴`.
    Polynomial {
        /// k1.
        k1: f64,
        /// k2.
        k2: f64,
    },
    /// Generator form (division model, Fitzgibbon 2001): `D = 1 / (1 − k·h²)` (k > 0
    /// pincushion).
    Division {
        /// k.
        k: f64,
    },
}

impl Distortion {
    /// D(h).
    pub fn d(&self, h: f64) -> f64 {
        match *self {
            Distortion::Polynomial { k1, k2 } => {
                let h2 = h * h;
                1.0 + k1 * h2 + k2 * h2 * h2
            }
            Distortion::Division { k } => 1.0 / (1.0 - k * h * h),
        }
    }
    /// Magnitude of effects.md: `D(1) − 1` (+ pincushion, − barrel).
    pub fn magnitude(&self) -> f64 {
        self.d(1.0) - 1.0
    }
    /// Largest h where the model is defined (the division model's pole).
    fn h_limit(&self) -> f64 {
        match *self {
            Distortion::Division { k } if k > 0.0 => 1.0 / k.sqrt(),
            _ => f64::INFINITY,
        }
    }
}

/// The shape w(λ) of the lateral-colour displacement.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LateralColorKind {
    /// Fitted form: `w = (λ − 550)/200`.
    Linear,
    /// Generator form (Cauchy dispersion): `w = (1/550² − 1/λ²) / (1/450² − 1/650²)`.
    Cauchy,
}

/// Lateral colour: at wavelength λ a point at height h moves radially by `h·d·w(λ)` µm, with
/// `w(650) − w(450) = 1` and `w(550) = 0`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LateralColor {
    /// Shape of w(λ).
    pub kind: LateralColorKind,
    /// d (µm): displacement of the 650 nm image relative to the 450 nm image at h = 1.
    pub displacement_um: f64,
}

impl LateralColor {
    /// w(λ).
    pub fn w(&self, wavelength_nm: f64) -> f64 {
        match self.kind {
            LateralColorKind::Linear => (wavelength_nm - 550.0) / 200.0,
            LateralColorKind::Cauchy => {
                (1.0 / (550.0 * 550.0) - 1.0 / (wavelength_nm * wavelength_nm))
                    / (1.0 / (450.0 * 450.0) - 1.0 / (650.0 * 650.0))
            }
        }
    }
    /// Radial displacement (µm) at wavelength λ of a point at height h.
    pub fn displacement_um(&self, wavelength_nm: f64, h: f64) -> f64 {
        h * self.displacement_um * self.w(wavelength_nm)
    }
    /// Magnitude of effects.md: d (µm).
    pub fn magnitude(&self) -> f64 {
        self.displacement_um
    }
}

impl OpticsEffects {
    /// No block present.
    pub fn is_empty(&self) -> bool {
        self.exposure_scale.is_none()
            && self.falloff.is_none()
            && self.veiling_glare.is_none()
            && self.defocus.is_none()
            && self.distortion.is_none()
            && self.lateral_color.is_none()
    }

    /// Half-diagonal of the sensor (m); field height h = r / this.
    pub fn half_diagonal_m(&self) -> f64 {
        0.5 * self.sensor_width_m.hypot(self.sensor_height_m)
    }

    /// Whether a geometric warp (distortion or lateral colour) is present.
    pub fn has_warp(&self) -> bool {
        self.distortion.is_some() || self.lateral_color.is_some()
    }

    /// Check every block; errors name the block's key and value.
    pub fn validate(&self) -> Result<(), OpticsError> {
        let err = |m: String| Err(OpticsError::Effect(m));
        let needs_geometry =
            self.falloff.is_some() || self.distortion.is_some() || self.lateral_color.is_some();
        if needs_geometry && !(self.half_diagonal_m().is_finite() && self.half_diagonal_m() > 0.0) {
            return err("optics effects: field-height blocks need the sensor size".into());
        }
        if let Some(s) = self.exposure_scale {
            if !(s.is_finite() && s > 0.0) {
                return err(format!("optics.exposure_scale.factor = {s}: must be > 0"));
            }
        }
        match &self.falloff {
            Some(Falloff::Polynomial { coefficients }) => {
                if let Some(a) = coefficients.iter().find(|a| !a.is_finite()) {
                    return err(format!(
                        "optics.relative_illumination.falloff.coefficients: {a} is not finite"
                    ));
                }
            }
            Some(Falloff::TwoCircle { separation_at_h1 }) => {
                if !(separation_at_h1.is_finite() && (0.0..=2.0).contains(separation_at_h1)) {
                    return err(format!(
                        "optics.relative_illumination.falloff.separation_at_h1 = {separation_at_h1}: must be in [0, 2]"
                    ));
                }
            }
            None => {}
        }
        if let Some(f) = self.veiling_glare {
            if !(f.is_finite() && f >= 0.0) {
                return err(format!("optics.veiling_glare.fraction = {f}: must be ≥ 0"));
            }
        }
        match self.defocus {
            Some(Defocus::Gaussian { sigma_um }) if !(sigma_um.is_finite() && sigma_um >= 0.0) => {
                return err(format!("optics.defocus.sigma_um = {sigma_um}: must be ≥ 0"));
            }
            Some(Defocus::Pillbox { radius_um })
                if !(radius_um.is_finite() && radius_um >= 0.0) =>
            {
                return err(format!(
                    "optics.defocus.radius_um = {radius_um}: must be ≥ 0"
                ));
            }
            _ => {}
        }
        match self.distortion {
            Some(Distortion::Polynomial { k1, k2 }) if !(k1.is_finite() && k2.is_finite()) => {
                return err(format!(
                    "optics.distortion: k1 = {k1}, k2 = {k2} must be finite"
                ));
            }
            Some(Distortion::Division { k }) if !(k.is_finite() && k < 1.0) => {
                return err(format!(
                    "optics.distortion.k = {k}: must be < 1 (the division model has a pole at h = 1/√k)"
                ));
            }
            _ => {}
        }
        if let Some(l) = &self.lateral_color {
            if !l.displacement_um.is_finite() {
                return err(format!(
                    "optics.lateral_color.displacement_um = {}: must be finite",
                    l.displacement_um
                ));
            }
        }
        Ok(())
    }

    /// Forward radial map of the warp at wavelength λ (None: without lateral colour): image
    /// radius of a scene point at radius `r_s_m`, `r_s·D(h_s) + h_s·d·w(λ)` (h_s = r_s / H).
    pub fn warp_forward_m(&self, r_s_m: f64, wavelength_nm: Option<f64>) -> f64 {
        let hd = self.half_diagonal_m();
        let h = r_s_m / hd;
        let mut r = r_s_m * self.distortion.map_or(1.0, |d| d.d(h));
        if let (Some(l), Some(w)) = (&self.lateral_color, wavelength_nm) {
            r += l.displacement_um(w, h) * 1e-6;
        }
        r
    }

    /// The largest radial displacement |r − r_s| of the warp (m) over the image radii up to
    /// `r_max_m`, at every wavelength of `wavelengths_nm` (lateral colour; `None` without
    /// it): how far a warped sample's source lies from it, so how much a row window
    /// ([`RowWindow`]) must be widened to hold every source of its rows (inward ones too,
    /// which an image's outer margin does not need). Sampled at 4 097 scene radii from 0 to
    /// the one imaged at `r_max_m` ([`OpticsEffects::warp_forward_m`]).
    pub fn max_warp_displacement_m(&self, r_max_m: f64, wavelengths_nm: Option<&[f64]>) -> f64 {
        let lams: Vec<Option<f64>> = match wavelengths_nm {
            Some(w) if self.lateral_color.is_some() => w.iter().map(|&l| Some(l)).collect(),
            _ => vec![None],
        };
        let r_lim = self.distortion.map_or(f64::INFINITY, |d| d.h_limit()) * self.half_diagonal_m();
        let mut worst = 0f64;
        for l in lams {
            let fwd = |r: f64| self.warp_forward_m(r, l);
            let mut r_hi = r_max_m.min(0.999 * r_lim);
            let mut tries = 0;
            while fwd(r_hi) < r_max_m && tries < 200 {
                let next = (r_hi * 1.1).min(0.999 * r_lim + 0.001 * r_hi);
                if next <= r_hi {
                    break;
                }
                r_hi = next;
                tries += 1;
            }
            for i in 0..=4096 {
                let r = r_hi * i as f64 / 4096.0;
                worst = worst.max((fwd(r) - r).abs());
            }
        }
        worst
    }

    /// The range `[g_lo, g_hi]` of the warp's ratio `g = r_s / r` (scene radius over image
    /// radius: a sample at field offset (x, y) from the centre takes the scene value at
    /// (g·x, g·y), `warp_planes`) over the image radii `[r_lo_m, r_hi_m]`, at every
    /// wavelength of `wavelengths_nm` (lateral colour; `None` without it). What a row window
    /// of the field must hold: its rows' sources lie within `y·[g_lo, g_hi]` of the centre.
    ///
    /// Exact for the models of [`OpticsEffects::warp_forward_m`]: with `u = (r_s / H)²`,
    /// `1/g = r / r_s = D(u) + d·w(λ)·10⁻⁶ / H`, where `D(u)` is monotone for the division model
    /// and for the polynomial one with k2 = 0, and otherwise a parabola in u with its one
    /// extremum at `u* = −k1 / (2·k2)`; so 1/g takes its extremes at the ends of the
    /// scene-radius range (the exact inverse of `[r_lo, r_hi]`, by bisection of the monotone
    /// forward map, widened by 10⁻⁹ relative) and at u* when it lies inside. `None` when the
    /// forward map cannot be inverted there (it folds over, or is not increasing).
    pub fn warp_ratio_range(
        &self,
        r_lo_m: f64,
        r_hi_m: f64,
        wavelengths_nm: Option<&[f64]>,
    ) -> Option<(f64, f64)> {
        let hd = self.half_diagonal_m();
        if !(hd > 0.0 && r_lo_m >= 0.0 && r_hi_m >= r_lo_m && r_hi_m.is_finite()) {
            return None;
        }
        let lams: Vec<Option<f64>> = match wavelengths_nm {
            Some(w) if self.lateral_color.is_some() => w.iter().map(|&l| Some(l)).collect(),
            _ => vec![None],
        };
        let r_lim = self.distortion.map_or(f64::INFINITY, |d| d.h_limit()) * hd;
        let (mut g_lo, mut g_hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for l in lams {
            let fwd = |r: f64| self.warp_forward_m(r, l);
            // the scene radius imaged at r: bisection on a bracket grown as RadialInverse's
            let inverse = |r: f64| -> Option<f64> {
                if r <= 0.0 {
                    return Some(0.0);
                }
                let mut b = grow_bracket(fwd, r, r_lim)?;
                let mut a = 0.0f64;
                for _ in 0..200 {
                    let c = 0.5 * (a + b);
                    if c <= a || c >= b {
                        break;
                    }
                    if fwd(c) < r {
                        a = c;
                    } else {
                        b = c;
                    }
                }
                Some(0.5 * (a + b))
            };
            let s_lo = inverse(r_lo_m)? * (1.0 - 1e-9);
            let s_hi = (inverse(r_hi_m)? * (1.0 + 1e-9)).min(0.999_999 * r_lim);
            // 1/g = fwd(s)/s; at s → 0 its limit, evaluated at 10⁻⁶ of the half-diagonal
            let inv_g = |s: f64| {
                let s = s.max(1e-6 * hd);
                fwd(s) / s
            };
            let mut at = vec![s_lo, s_hi];
            if let Some(Distortion::Polynomial { k1, k2 }) = self.distortion {
                if k2 != 0.0 {
                    let u = -k1 / (2.0 * k2);
                    if u > 0.0 {
                        let s = hd * u.sqrt();
                        if s > s_lo && s < s_hi {
                            at.push(s);
                        }
                    }
                }
            }
            for s in at {
                let q = inv_g(s);
                if !(q.is_finite() && q > 0.0) {
                    return None;
                }
                g_lo = g_lo.min(1.0 / q);
                g_hi = g_hi.max(1.0 / q);
            }
        }
        Some((g_lo, g_hi))
    }

    /// A bound on the rounding error of [`OpticsEffects::warp_forward_m`] (f64) anywhere on
    /// [0, r_hi] at λ: 64 ε times the sum of the magnitudes of its terms (each term has a few
    /// roundings; a division model's `1 − k·h²` loses relative accuracy as `1/(1 − k·h²)`).
    /// Used to decide bisection steps without evaluating the map ([`bisect_guarded`]).
    fn warp_rounding_bound_m(&self, wavelength_nm: Option<f64>, r_hi_m: f64) -> f64 {
        let hd = self.half_diagonal_m();
        let h = r_hi_m / hd;
        let h2 = h * h;
        let radial = match self.distortion {
            None => 1.0,
            Some(Distortion::Polynomial { k1, k2 }) => 1.0 + k1.abs() * h2 + k2.abs() * h2 * h2,
            Some(Distortion::Division { k }) => {
                let den = 1.0 - k.max(0.0) * h2;
                (1.0 + k.abs() * h2) / (den * den).max(1e-300)
            }
        };
        let lateral = match (&self.lateral_color, wavelength_nm) {
            (Some(l), Some(w)) => (h * l.displacement_um * l.w(w)).abs() * 1e-6,
            _ => 0.0,
        };
        64.0 * f64::EPSILON * (r_hi_m * radial + lateral)
    }

    /// Scene samples per pixel side the defocus block needs (1 without it).
    pub fn oversample_hint(&self, pixel_pitch_m: f64) -> usize {
        let p_um = pixel_pitch_m * 1e6;
        match self.defocus {
            Some(Defocus::Gaussian { sigma_um }) if sigma_um > 0.0 => {
                (p_um / sigma_um).ceil() as usize
            }
            Some(Defocus::Pillbox { radius_um }) if radius_um > 0.0 => {
                (p_um / radius_um).ceil() as usize
            }
            _ => 1,
        }
    }

    /// Scene margin (pixels) the blocks need beyond `base_margin_px` (the base blur's): the
    /// defocus reach plus the largest inward displacement of the warp at the corner of the
    /// blurred region, over the wavelengths `wavelengths_nm` (sensor of `rows × cols` pixels).
    pub fn extra_margin_px(
        &self,
        pixel_pitch_m: f64,
        rows: usize,
        cols: usize,
        base_margin_px: usize,
        wavelengths_nm: &[f64],
    ) -> usize {
        let mut m = 0usize;
        if let Some(d) = &self.defocus {
            m += (d.reach_um() * 1e-6 / pixel_pitch_m).ceil() as usize + 1;
        }
        if self.has_warp() && self.half_diagonal_m() > 0.0 {
            let mb = (base_margin_px + m) as f64;
            let r0 = 0.5
                * pixel_pitch_m
                * ((rows as f64 + 2.0 * mb).powi(2) + (cols as f64 + 2.0 * mb).powi(2)).sqrt();
            let lams: Vec<Option<f64>> = if self.lateral_color.is_some() {
                let lo = wavelengths_nm.iter().cloned().fold(f64::INFINITY, f64::min);
                let hi = wavelengths_nm.iter().cloned().fold(0.0, f64::max);
                if lo.is_finite() {
                    vec![Some(lo), Some(hi)]
                } else {
                    vec![Some(400.0), Some(700.0)]
                }
            } else {
                vec![None]
            };
            let mut shift = 0.0f64;
            for l in lams {
                if let Ok(map) = RadialInverse::shared(self, l, r0 * 1.01) {
                    shift = shift.max(map.source_radius(r0) - r0);
                }
            }
            m += (shift / pixel_pitch_m).ceil() as usize + 2;
        }
        m
    }
}

/// Uniform table of the inverse warp: scene radius r_s for image radius r on [0, r_max].
pub(crate) struct RadialInverse {
    r_max_m: f64,
    table: Vec<f64>,
    /// r_s / r as r → 0.
    ratio0: f64,
}

/// Inverse tables already built, by (effects, wavelength, r_max): a forward model warps every
/// target of a capture set with one optics configuration, and each table (4 097 bisections of
/// 64 steps, ≈ 18 map evaluations each with [`bisect_guarded`]) costs more than warping a
/// plane with it. Bounded: cleared beyond
/// [`INVERSE_MEMO_ENTRIES`] tables.
static INVERSE_MEMO: std::sync::Mutex<
    Option<std::collections::HashMap<(String, Option<u64>, u64), std::sync::Arc<RadialInverse>>>,
> = std::sync::Mutex::new(None);

/// Most inverse tables kept (≈ 33 kB each).
const INVERSE_MEMO_ENTRIES: usize = 2048;

/// The upper end of a bracket of the inverse of the increasing radial map `fwd` at `r`: the
/// first of r, 1.1·r, 1.1²·r, … (approaching the model's pole `r_lim` no closer than 0.999 of
/// it) that `fwd` maps to at least `r`; `None` when 200 steps do not get there.
fn grow_bracket(fwd: impl Fn(f64) -> f64, r: f64, r_lim: f64) -> Option<f64> {
    let mut b = r.min(0.999 * r_lim);
    let mut tries = 0;
    while fwd(b) < r {
        let next = (b * 1.1).min(0.999 * r_lim + 0.001 * b);
        tries += 1;
        if tries > 200 || next <= b {
            return None;
        }
        b = next;
    }
    Some(b)
}
impl RadialInverse {
    const N: usize = 4097;

    /// [`RadialInverse::new`], shared: the same inputs give the same table (bit for bit: the
    /// table is a pure function of them), built once while it stays in [`INVERSE_MEMO`].
    pub(crate) fn shared(
        fx: &OpticsEffects,
        wavelength_nm: Option<f64>,
        r_max_m: f64,
    ) -> Result<std::sync::Arc<Self>, OpticsError> {
        // what the table reads: the warp blocks and the sensor size (not fall-off, glare,
        // defocus or exposure, so those candidates share one table)
        let key = (
            format!(
                "{:?}|{:?}|{:x}|{:x}",
                fx.distortion,
                fx.lateral_color,
                fx.sensor_width_m.to_bits(),
                fx.sensor_height_m.to_bits()
            ),
            wavelength_nm.map(f64::to_bits),
            r_max_m.to_bits(),
        );
        if let Some(m) = INVERSE_MEMO
            .lock()
            .ok()
            .and_then(|g| g.as_ref().and_then(|m| m.get(&key).cloned()))
        {
            return Ok(m);
        }
        let map = std::sync::Arc::new(Self::new(fx, wavelength_nm, r_max_m)?);
        if let Ok(mut g) = INVERSE_MEMO.lock() {
            let m = g.get_or_insert_with(Default::default);
            if m.len() >= INVERSE_MEMO_ENTRIES {
                m.clear();
            }
            m.insert(key, map.clone());
        }
        Ok(map)
    }

    /// Inverse of [`OpticsEffects::warp_forward_m`] at λ on [0, r_max]; an error when the map
    /// is not increasing there (fold-over).
    pub(crate) fn new(
        fx: &OpticsEffects,
        wavelength_nm: Option<f64>,
        r_max_m: f64,
    ) -> Result<Self, OpticsError> {
        let hd = fx.half_diagonal_m();
        let fwd = |r: f64| fx.warp_forward_m(r, wavelength_nm);
        let r_lim = fx.distortion.map_or(f64::INFINITY, |d| d.h_limit()) * hd;
        let fold = || {
            OpticsError::Effect(format!(
                "optics distortion / lateral colour: the radial map folds over inside the image \
                 (image height {:.4} mm not reached); reduce the distortion",
                r_max_m * 1e3
            ))
        };
        // Bracket: grow r_hi until it maps beyond r_max, staying below the model's pole.
        let r_hi = grow_bracket(fwd, r_max_m, r_lim).ok_or_else(fold)?;
        // Monotonicity on the bracket.
        let m = 4096;
        let mut prev = fwd(0.0);
        for i in 1..=m {
            let v = fwd(r_hi * i as f64 / m as f64);
            if !(v > prev) {
                return Err(fold());
            }
            prev = v;
        }
        let noise = fx.warp_rounding_bound_m(wavelength_nm, r_hi);
        let mut table: Vec<f64> = Vec::with_capacity(Self::N);
        for j in 0..Self::N {
            let target = r_max_m * j as f64 / (Self::N - 1) as f64;
            // guess: the previous entries extrapolated; slope: their difference quotient
            let (guess, slope) = match j {
                0 => (None, 0.0),
                1 => (
                    Some(target * eps_ratio(&fwd, hd)),
                    1.0 / eps_ratio(&fwd, hd),
                ),
                _ => {
                    let (x1, x2) = (table[j - 1], table[j - 2]);
                    let dt = r_max_m / (Self::N - 1) as f64;
                    (Some(2.0 * x1 - x2), dt / (x1 - x2))
                }
            };
            table.push(bisect_guarded(&fwd, target, r_hi, guess, slope, noise));
        }
        let eps = 1e-6 * hd;
        Ok(RadialInverse {
            r_max_m,
            table,
            ratio0: eps / fwd(eps),
        })
    }

    /// Scene radius for image radius `r_m` (linear interpolation in the table; linear
    /// extrapolation of the last segment beyond r_max).
    pub(crate) fn source_radius(&self, r_m: f64) -> f64 {
        self.source_radius_at(TablePosition::of(r_m, self.r_max_m))
    }

    /// [`RadialInverse::source_radius`] at a [`TablePosition`] of this table's `r_max`.
    #[inline]
    fn source_radius_at(&self, at: TablePosition) -> f64 {
        let (i0, f) = (at.index, at.fraction);
        self.table[i0] * (1.0 - f) + self.table[i0 + 1] * f
    }
}

/// Where image radius `r` falls in a [`RadialInverse`] table of range `r_max` (every table of
/// one range has the same positions: one per sample serves every wavelength's table).
#[derive(Clone, Copy, Default)]
struct TablePosition {
    /// Entry below r.
    index: usize,
    /// Fraction of the way to the next entry (beyond r_max: > 1, linear extrapolation).
    fraction: f64,
}

impl TablePosition {
    #[inline]
    fn of(r_m: f64, r_max_m: f64) -> Self {
        let t = r_m / r_max_m * (RadialInverse::N - 1) as f64;
        // (a float-to-integer cast truncates toward 0 and saturates, NaN → 0: for every t
        // the same index as `t.floor().max(0.0) as usize`, without a call to floor)
        let index = (t as usize).min(RadialInverse::N - 2);
        TablePosition {
            index,
            fraction: t - index as f64,
        }
    }
}

/// `r_s / r` of the forward map as r → 0 (evaluated at r = 10⁻⁶ of the half-diagonal).
fn eps_ratio(fwd: &dyn Fn(f64) -> f64, hd: f64) -> f64 {
    let eps = 1e-6 * hd;
    eps / fwd(eps)
}

/// The bisection `a, b = 0, r_hi; 64 × { c = (a + b)/2; fwd(c) < target ? a = c : b = c };
/// (a + b)/2` — bit for bit the same result — with fewer evaluations of `fwd`:
/// - a midpoint equal to an end already decided is decided the same way (`fwd` is a pure
///   function), so the steps after the bracket has shrunk to adjacent floats cost nothing;
/// - around an approximate root x* (Newton steps from `guess` with the fixed slope `slope`)
///   a band [lo, hi] is verified: with |fwd_float − fwd| ≤ `noise` everywhere on [0, r_hi]
///   and fwd increasing (which [`RadialInverse::new`] checks at its table's sample radii
///   only: a map with a dip narrower than that spacing and deeper than 2·noise, i.e. one
///   at the point of folding over, may get a different last bit), `fwd(lo) + 2·noise < target`
///   gives `fwd(c) < target` for every c ≤ lo, and `fwd(hi) − 2·noise ≥ target` gives
///   `fwd(c) ≥ target` for every c ≥ hi, so the midpoints outside the band are decided without
///   evaluating `fwd`. When no band verifies (or there is no guess) every midpoint inside
///   (0, r_hi) is evaluated, as in the plain bisection.
fn bisect_guarded(
    fwd: &dyn Fn(f64) -> f64,
    target: f64,
    r_hi: f64,
    guess: Option<f64>,
    slope: f64,
    noise: f64,
) -> f64 {
    // (lo, hi): c ≤ lo ⇒ fwd(c) < target, c ≥ hi ⇒ fwd(c) ≥ target (vacuous by default)
    let (mut lo, mut hi) = (f64::NEG_INFINITY, f64::INFINITY);
    if let Some(mut x) = guess.filter(|g| g.is_finite()) {
        if slope.is_finite() && slope > 0.0 {
            for _ in 0..4 {
                let r = fwd(x) - target;
                if !r.is_finite() {
                    break;
                }
                x -= r / slope;
                if r.abs() <= 4.0 * noise {
                    break;
                }
            }
            let mut half = 8.0 * noise / slope;
            for _ in 0..4 {
                let (l, h) = (x - half, x + half);
                if !(l.is_finite() && h.is_finite()) || l >= r_hi || h <= 0.0 {
                    break;
                }
                let low_ok = l <= 0.0 || fwd(l) + 2.0 * noise < target;
                let high_ok = h >= r_hi || fwd(h) - 2.0 * noise >= target;
                if low_ok && high_ok {
                    lo = if l <= 0.0 { f64::NEG_INFINITY } else { l };
                    hi = if h >= r_hi { f64::INFINITY } else { h };
                    break;
                }
                half *= 16.0;
            }
        }
    }
    let (mut a, mut b) = (0.0f64, r_hi);
    // whether fwd(a) < target / fwd(b) ≥ target is established
    let (mut a_known, mut b_known) = (false, false);
    for _ in 0..64 {
        let c = 0.5 * (a + b);
        let below = if c <= lo || (a_known && c == a) {
            true
        } else if c >= hi || (b_known && c == b) {
            false
        } else {
            fwd(c) < target
        };
        if below {
            a = c;
            a_known = true;
        } else {
            b = c;
            b_known = true;
        }
    }
    0.5 * (a + b)
}

/// The four neighbours and weights of a bilinear sample at fractional (row, col) of a
/// `rows × cols` plane, the border continued outside ([`Tap::sample`]).
#[derive(Clone, Copy, Default)]
struct Tap {
    /// Index of (r0, c0).
    i00: usize,
    /// Index of (r0, c1).
    i01: usize,
    /// Index of (r1, c0).
    i10: usize,
    /// Index of (r1, c1).
    i11: usize,
    /// Row weight.
    tr: f64,
    /// Column weight.
    tc: f64,
}

impl Tap {
    fn new(rows: usize, cols: usize, fr: f64, fc: f64) -> Self {
        let fr = fr.clamp(0.0, (rows - 1) as f64);
        let fc = fc.clamp(0.0, (cols - 1) as f64);
        // (non-negative after the clamp, NaN → 0 either way: the cast is the floor)
        let (r0, c0) = (fr as usize, fc as usize);
        let (r1, c1) = ((r0 + 1).min(rows - 1), (c0 + 1).min(cols - 1));
        Tap {
            i00: r0 * cols + c0,
            i01: r0 * cols + c1,
            i10: r1 * cols + c0,
            i11: r1 * cols + c1,
            tr: fr - r0 as f64,
            tc: fc - c0 as f64,
        }
    }

    /// The bilinear sample of `plane`.
    #[inline]
    fn sample(&self, plane: &[f32]) -> f64 {
        let (tr, tc) = (self.tr, self.tc);
        let g = |i: usize| plane[i] as f64;
        (g(self.i00) * (1.0 - tc) + g(self.i01) * tc) * (1.0 - tr)
            + (g(self.i10) * (1.0 - tc) + g(self.i11) * tc) * tr
    }
}

/// Distortion and lateral colour: every output sample at image radius r takes the scene value
/// at the radius r_s that the forward map sends to r (same azimuth), bilinearly sampled.
/// Plane k uses `wavelengths_nm[k]` (None: the planes are a linear model and the warp must
/// not depend on wavelength). As in ISET's geometric step, no Jacobian is applied: the
/// irradiance is resampled (a uniform field stays uniform); a point's centroid moves to
/// `h·D(h)` (+ the lateral-colour shift).
///
/// Most bytes [`warp_planes`] spends on the radius and tap tables it shares between planes
/// (8 + 48 bytes per sample); larger images compute both per sample and plane instead.
pub(crate) const WARP_SHARED_TABLE_BYTES: usize = 256 << 20;

/// The sample radii are computed once for all planes, and with one map (no lateral colour)
/// the bilinear taps too ([`Tap`]), when these tables fit in [`WARP_SHARED_TABLE_BYTES`];
/// each plane's result is the same arithmetic as sampling it alone (so the same bits with
/// or without the tables).
///
/// `window`: where `img`'s rows lie in the field ([`RowWindow::whole`] for the whole image):
/// the radii, the inverse table's range and the taps are those of the whole field's grid, so
/// a window's rows get the whole image's samples wherever their taps fall inside the window.
pub(crate) fn warp_planes(
    fx: &OpticsEffects,
    img: &mut SpectralImage,
    dx: f64,
    wavelengths_nm: Option<&[f64]>,
    window: RowWindow,
) -> Result<(), OpticsError> {
    warp_planes_within(fx, img, dx, wavelengths_nm, WARP_SHARED_TABLE_BYTES, window)
}

/// [`warp_planes`] with `table_budget_bytes` for its shared tables.
fn warp_planes_within(
    fx: &OpticsEffects,
    img: &mut SpectralImage,
    dx: f64,
    wavelengths_nm: Option<&[f64]>,
    table_budget_bytes: usize,
    window: RowWindow,
) -> Result<(), OpticsError> {
    let (rows, cols) = (img.rows, img.cols);
    let (yc, xc, r_max) = warp_frame(window, cols, dx);
    let maps = inverse_tables(fx, wavelengths_nm, r_max)?;
    let radius_at = |i: usize, j: usize| -> f64 {
        let y = (window.field_row(i) - yc) * dx;
        let x = (j as f64 - xc) * dx;
        x.hypot(y)
    };
    let n = rows * cols;
    let radius_bytes = n.saturating_mul(std::mem::size_of::<f64>());
    let tap_bytes = n.saturating_mul(std::mem::size_of::<Tap>());
    // The image radius of every output sample (shared by the planes), within the budget.
    let radius: Option<Vec<f64>> = (radius_bytes <= table_budget_bytes).then(|| {
        let mut radius = vec![0f64; n];
        radius
            .par_chunks_mut(cols.max(1))
            .enumerate()
            .for_each(|(i, row)| {
                for (j, r) in row.iter_mut().enumerate() {
                    *r = radius_at(i, j);
                }
            });
        radius
    });
    let tap_of = |map: &RadialInverse, i: usize, j: usize| -> Tap {
        let r = match &radius {
            Some(v) => v[i * cols + j],
            None => radius_at(i, j),
        };
        let g = source_ratio(map, r, map.source_radius(r));
        warp_tap(rows, cols, window, (yc, xc), i, j, g)
    };
    if maps.len() == 1 && radius_bytes.saturating_add(tap_bytes) <= table_budget_bytes {
        let map = &maps[0];
        let mut taps = vec![Tap::default(); rows * cols];
        taps.par_chunks_mut(cols.max(1))
            .enumerate()
            .for_each(|(i, row)| {
                for (j, t) in row.iter_mut().enumerate() {
                    *t = tap_of(map, i, j);
                }
            });
        img.planes
            .par_iter_mut()
            .for_each_init(Vec::new, |out: &mut Vec<f32>, plane| {
                out.clear();
                out.extend(taps.iter().map(|t| t.sample(plane) as f32));
                plane.copy_from_slice(out);
            });
        return Ok(());
    }
    img.planes.par_iter_mut().enumerate().for_each_init(
        Vec::new,
        |out: &mut Vec<f32>, (k, plane)| {
            let map = &maps[if maps.len() == 1 { 0 } else { k }];
            out.clear();
            out.resize(rows * cols, 0.0);
            for i in 0..rows {
                for j in 0..cols {
                    out[i * cols + j] = tap_of(map, i, j).sample(plane) as f32;
                }
            }
            plane.copy_from_slice(out);
        },
    );
    Ok(())
}

/// The warp's frame for a `window` of `cols`-sample rows at pitch `dx`: the whole field's
/// centre (row, column, in samples) and the largest image radius its inverse tables cover.
fn warp_frame(window: RowWindow, cols: usize, dx: f64) -> (f64, f64, f64) {
    let yc = window.centre_row();
    let xc = (cols as f64 - 1.0) / 2.0;
    let r_max = dx * (yc * yc + xc * xc).sqrt() * 1.001 + 1e-12;
    (yc, xc, r_max)
}

/// The warp's inverse tables up to `r_max`: one per plane's wavelength, or one for every
/// plane without wavelengths (a model that does not depend on wavelength).
fn inverse_tables(
    fx: &OpticsEffects,
    wavelengths_nm: Option<&[f64]>,
    r_max: f64,
) -> Result<Vec<std::sync::Arc<RadialInverse>>, OpticsError> {
    match wavelengths_nm {
        Some(w) => w
            .par_iter()
            .map(|&l| RadialInverse::shared(fx, Some(l), r_max))
            .collect(),
        None => Ok(vec![RadialInverse::shared(fx, None, r_max)?]),
    }
}

/// `g = r_s / r` of the warp at image radius `r` (`r_s`: its source radius in `map`; the
/// ratio as r → 0 at the centre).
#[inline]
fn source_ratio(map: &RadialInverse, r: f64, r_s: f64) -> f64 {
    if r > 0.0 {
        r_s / r
    } else {
        map.ratio0
    }
}

/// The bilinear tap of output sample (i, j) of a `rows × cols` image whose rows lie in the
/// field as `window` says, centre `(yc, xc)` (the whole field's), at source ratio `g`: the
/// scene at `(yc + (y − yc)·g, xc + (x − xc)·g)`.
#[inline]
fn warp_tap(
    rows: usize,
    cols: usize,
    window: RowWindow,
    (yc, xc): (f64, f64),
    i: usize,
    j: usize,
    g: f64,
) -> Tap {
    // (the whole field's source row, then the window's: an integer off a float ≥ it is
    // exact, so a window's taps and weights are the whole image's)
    Tap::new(
        rows,
        cols,
        yc + (window.field_row(i) - yc) * g - window.row0 as f64,
        xc + (j as f64 - xc) * g,
    )
}

/// [`warp_planes`] followed by the projection of the warped planes onto `weights`, without
/// the warped planes: output plane c is `Σ_k weights[c][k] · W_k`, `W_k` plane k warped at
/// `wavelengths_nm[k]` and rounded to f32 as [`warp_planes`] stores it, summed over k
/// ascending in f64 with the zero weights skipped — bit for bit
/// [`SpectralImage::combine`] of [`warp_planes`]' image (test
/// `projected_warp_is_the_warp_then_the_projection_bit_for_bit`). Each output row takes, per
/// plane, the same taps as [`warp_planes`] (one table position per sample serves every
/// wavelength's inverse table), so the planes are read once and nothing of their size is
/// written: the optics after a lateral-colour warp that act alike at every wavelength then
/// run on the few projected planes (a sensor's channels) instead of every wavelength band's
/// ([`crate::form_image_rows_projected`]).
pub(crate) fn warp_planes_projected(
    fx: &OpticsEffects,
    img: &SpectralImage,
    dx: f64,
    wavelengths_nm: Option<&[f64]>,
    window: RowWindow,
    weights: &[Vec<f64>],
) -> Result<Vec<Vec<f32>>, OpticsError> {
    let (rows, cols) = (img.rows, img.cols);
    let n_planes = img.planes.len();
    if let Some(w) = weights.iter().find(|w| w.len() != n_planes) {
        return Err(OpticsError::Scene(format!(
            "projection of {n_planes} warped planes: {} weights in a row",
            w.len()
        )));
    }
    if wavelengths_nm.is_some_and(|w| w.len() != n_planes) {
        return Err(OpticsError::Scene(format!(
            "warp of {n_planes} planes at {} wavelengths",
            wavelengths_nm.map_or(0, <[f64]>::len)
        )));
    }
    let (yc, xc, r_max) = warp_frame(window, cols, dx);
    let maps = inverse_tables(fx, wavelengths_nm, r_max)?;
    // (plane, weight) pairs of each output plane, zero weights skipped as `combine` does
    let active: Vec<Vec<(usize, f64)>> = weights
        .iter()
        .map(|w| {
            w.iter()
                .copied()
                .enumerate()
                .filter(|(_, v)| *v != 0.0)
                .collect()
        })
        .collect();
    let k_out = weights.len();
    let mut out_rows = vec![0f32; k_out * rows * cols];
    out_rows
        .par_chunks_mut((k_out * cols).max(1))
        .enumerate()
        .for_each_init(
            || {
                (
                    vec![TablePosition::default(); cols],
                    vec![0f64; cols],
                    vec![0f32; cols],
                    vec![0f64; k_out * cols],
                )
            },
            |(pos, radius, warped, acc), (i, out)| {
                let y = (window.field_row(i) - yc) * dx;
                for j in 0..cols {
                    let r = ((j as f64 - xc) * dx).hypot(y);
                    radius[j] = r;
                    pos[j] = TablePosition::of(r, r_max);
                }
                acc.iter_mut().for_each(|a| *a = 0.0);
                for (k, plane) in img.planes.iter().enumerate() {
                    if active.iter().all(|a| a.iter().all(|&(p, _)| p != k)) {
                        continue;
                    }
                    let map = &maps[if maps.len() == 1 { 0 } else { k }];
                    for j in 0..cols {
                        let g = source_ratio(map, radius[j], map.source_radius_at(pos[j]));
                        warped[j] =
                            warp_tap(rows, cols, window, (yc, xc), i, j, g).sample(plane) as f32;
                    }
                    for (c, a) in active.iter().enumerate() {
                        if let Some(&(_, w)) = a.iter().find(|&&(p, _)| p == k) {
                            acc[c * cols..(c + 1) * cols]
                                .iter_mut()
                                .zip(warped.iter())
                                .for_each(|(s, &v)| *s += w * v as f64);
                        }
                    }
                }
                out.iter_mut()
                    .zip(acc.iter())
                    .for_each(|(o, &a)| *o = a as f32);
            },
        );
    // row-interleaved → one plane per output
    let mut planes = vec![vec![0f32; rows * cols]; k_out];
    for i in 0..rows {
        for (c, p) in planes.iter_mut().enumerate() {
            p[i * cols..(i + 1) * cols]
                .copy_from_slice(&out_rows[(i * k_out + c) * cols..(i * k_out + c + 1) * cols]);
        }
    }
    Ok(planes)
}

/// The defocus block's blur of every plane (edge continuation as `padding`).
pub(crate) fn apply_defocus(
    d: &Defocus,
    img: &mut SpectralImage,
    dx: f64,
    padding: Padding,
) -> Result<(), OpticsError> {
    let (rows, cols) = (img.rows, img.cols);
    match *d {
        Defocus::Gaussian { sigma_um } => {
            let k = gaussian_kernel_1d(sigma_um * 1e-6, dx);
            kernels::separable_convolve(&mut img.planes, rows, cols, &k, padding);
            Ok(())
        }
        Defocus::Pillbox { radius_um } => {
            let psf = pillbox_psf(2.0 * radius_um * 1e-6, dx);
            if psf.data.len() == 1 {
                return Ok(());
            }
            crate::convolve_planes_with(img, padding, crate::fft::Finish::Keep, |_| psf.clone())
        }
    }
}

/// Where an image's rows lie in the field: rows `row0 .. row0 + rows` of a grid of
/// `full_rows` rows with the same columns (a band of the scene sampling grid). The field's
/// centre, and with it every field coordinate (relative illumination, fall-off, warps), is the
/// whole grid's; [`RowWindow::whole`] is the image itself.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RowWindow {
    /// The whole grid's row of the image's first row.
    pub row0: usize,
    /// Rows of the whole grid.
    pub full_rows: usize,
}

impl RowWindow {
    /// The whole image of `rows` rows.
    pub fn whole(rows: usize) -> Self {
        RowWindow {
            row0: 0,
            full_rows: rows,
        }
    }

    /// The field centre's row, in the whole grid's rows.
    pub fn centre_row(&self) -> f64 {
        (self.full_rows as f64 - 1.0) / 2.0
    }

    /// The whole grid's row of the image's row `i`.
    pub fn field_row(&self, i: usize) -> f64 {
        (i + self.row0) as f64
    }
}

/// What the veiling-glare block adds: the sum over the samples whose centres lie on the
/// sensor of each plane of the image before the glare, and their count (the glare of plane k
/// is `f · sums[k] / count`). A row window takes the whole field's ([`crate::glare_sums`]).
#[derive(Debug, Clone, PartialEq)]
pub struct GlareSums {
    /// Sum per plane.
    pub sums: Vec<f64>,
    /// Samples summed per plane.
    pub count: f64,
}

/// [`GlareSums`] of a whole image.
pub(crate) fn veiling_glare_sums(fx: &OpticsEffects, img: &SpectralImage, dx: f64) -> GlareSums {
    let (rows, cols) = (img.rows, img.cols);
    let yc = (rows as f64 - 1.0) / 2.0;
    let xc = (cols as f64 - 1.0) / 2.0;
    // Samples whose centres lie on the sensor (all of them when the size is unknown).
    let inside = |n: usize, c: f64, size: f64| -> (usize, usize) {
        if size <= 0.0 {
            return (0, n);
        }
        let half = 0.5 * size / dx;
        let lo = (0..n)
            .find(|&i| (i as f64 - c).abs() < half + 1e-9)
            .unwrap_or(0);
        let hi = (0..n)
            .rev()
            .find(|&i| (i as f64 - c).abs() < half + 1e-9)
            .map_or(n, |i| i + 1);
        (lo, hi)
    };
    let (r0, r1) = inside(rows, yc, fx.sensor_height_m);
    let (c0, c1) = inside(cols, xc, fx.sensor_width_m);
    let count = ((r1 - r0) * (c1 - c0)) as f64;
    let sums = img
        .planes
        .par_iter()
        .map(|p| {
            let mut sum = 0.0f64;
            for r in r0..r1 {
                sum += p[r * cols + c0..r * cols + c1]
                    .iter()
                    .map(|&v| v as f64)
                    .sum::<f64>();
            }
            sum
        })
        .collect();
    GlareSums { sums, count }
}

/// Veiling glare: adds `f ×` the mean over the sensor of each plane to that plane (the mean
/// irradiance at every wavelength, since the image is linear in its planes); the means are
/// `glare`'s ([`veiling_glare_sums`] of the whole image before the glare).
pub(crate) fn apply_veiling_glare(f: f64, img: &mut SpectralImage, glare: &GlareSums) {
    img.planes
        .par_iter_mut()
        .zip(glare.sums.par_iter())
        .for_each(|(p, &sum)| {
            let add = (f * sum / glare.count) as f32;
            p.iter_mut().for_each(|v| *v += add);
        });
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn two_circle_overlap_closed_form() {
        assert_relative_eq!(two_circle_overlap_fraction(0.0), 1.0, epsilon = 1e-15);
        assert_eq!(two_circle_overlap_fraction(2.0), 0.0);
        // Lens (vesica) area by direct integration: 4 ∫_{d/2}^{1} √(1 − x²) dx.
        for &d in &[0.1, 0.5, 1.0, 1.5, 1.9] {
            let n = 200_000;
            let a = d / 2.0;
            let h = (1.0 - a) / n as f64;
            let area: f64 = (0..n)
                .map(|i| {
                    let x = a + (i as f64 + 0.5) * h;
                    4.0 * (1.0 - x * x).sqrt() * h
                })
                .sum();
            assert_relative_eq!(
                two_circle_overlap_fraction(d),
                area / PI,
                max_relative = 1e-6
            );
        }
        // Monte Carlo-free check at d = 1: (2π/3 − √3/2)/π.
        assert_relative_eq!(
            two_circle_overlap_fraction(1.0),
            (2.0 * PI / 3.0 - 3f64.sqrt() / 2.0) / PI,
            epsilon = 1e-14
        );
    }

    #[test]
    fn falloff_polynomial_and_magnitude() {
        let f = Falloff::Polynomial {
            coefficients: vec![-0.2, 0.05, -0.01],
        };
        assert_relative_eq!(
            f.factor(0.5),
            1.0 - 0.2 * 0.25 + 0.05 * 0.0625 - 0.01 * 0.015625
        );
        assert_relative_eq!(f.magnitude(), 0.2 - 0.05 + 0.01, epsilon = 1e-15);
        let t = Falloff::TwoCircle {
            separation_at_h1: 0.4,
        };
        assert_relative_eq!(t.magnitude(), 1.0 - two_circle_overlap_fraction(0.4));
    }

    #[test]
    fn distortion_and_lateral_colour_definitions() {
        let d = Distortion::Division { k: 0.05 };
        assert_relative_eq!(d.magnitude(), 1.0 / 0.95 - 1.0, epsilon = 1e-15);
        let p = Distortion::Polynomial {
            k1: -0.03,
            k2: 0.01,
        };
        assert_relative_eq!(p.magnitude(), -0.02, epsilon = 1e-15);
        for kind in [LateralColorKind::Linear, LateralColorKind::Cauchy] {
            let l = LateralColor {
                kind,
                displacement_um: 3.0,
            };
            assert_relative_eq!(l.w(650.0) - l.w(450.0), 1.0, epsilon = 1e-12);
            assert_relative_eq!(l.w(550.0), 0.0, epsilon = 1e-12);
            assert_relative_eq!(
                l.displacement_um(650.0, 1.0) - l.displacement_um(450.0, 1.0),
                3.0,
                epsilon = 1e-12
            );
        }
        // The Cauchy shape is not the linear one (it bends towards the blue).
        let c = LateralColor {
            kind: LateralColorKind::Cauchy,
            displacement_um: 1.0,
        };
        assert!(c.w(500.0) < -0.2 && (c.w(500.0) + 0.25).abs() > 0.01);
    }

    #[test]
    fn equivalent_sigma_of_a_gaussian_is_itself_and_pillbox_fit_is_least_squares() {
        let g = Defocus::Gaussian { sigma_um: 1.3 };
        assert_eq!(g.equivalent_sigma_um(2.0), 1.3);
        // The generic fit recovers a Gaussian's own σ.
        let s = equivalent_gaussian_sigma_um(|f| g.mtf(f), 2.0, 5.0);
        assert_relative_eq!(s, 1.3, max_relative = 1e-6);
        // Pillbox: the fitted σ is a local minimum of the least-squares cost, and for a disk
        // much smaller than a pixel it tends to the second-moment match σ = r/2 (MTF
        // 1 − (πrf)²/2 + … = 1 − 2π²σ²f² + …).
        let p = Defocus::Pillbox { radius_um: 0.2 };
        assert_relative_eq!(p.equivalent_sigma_um(2.0), 0.1, max_relative = 2e-3);
        let p = Defocus::Pillbox { radius_um: 3.0 };
        let s = p.equivalent_sigma_um(2.0);
        let nyq = 0.25;
        let cost = |s: f64| -> f64 {
            (0..256)
                .map(|k| {
                    let f = nyq * k as f64 / 255.0;
                    ((-2.0 * PI * PI * s * s * f * f).exp() - p.mtf(f)).powi(2)
                })
                .sum()
        };
        assert!(cost(s) <= cost(s * 1.01) && cost(s) <= cost(s * 0.99));
        assert!(s > 1.0 && s < 3.0, "{s}");
    }

    #[test]
    fn pillbox_mtf_matches_numerical_hankel_transform() {
        // MTF(f) = (1/(πr²)) ∫_0^r 2π ρ J0(2π f ρ) dρ, J0 by its integral representation.
        let r = 2.5;
        let j0 = |x: f64| -> f64 {
            let n = 400;
            (0..n)
                .map(|i| ((i as f64 + 0.5) * PI / n as f64).sin() * x)
                .map(f64::cos)
                .sum::<f64>()
                / n as f64
        };
        for &f in &[0.05, 0.1, 0.2, 0.3] {
            let n = 2000;
            let h = r / n as f64;
            let v: f64 = (0..n)
                .map(|i| {
                    let rho = (i as f64 + 0.5) * h;
                    2.0 * PI * rho * j0(2.0 * PI * f * rho) * h
                })
                .sum::<f64>()
                / (PI * r * r);
            let m = Defocus::Pillbox { radius_um: r }.mtf(f);
            assert!((v - m).abs() < 1e-5, "f {f}: {v} vs {m}");
        }
    }

    #[test]
    fn radial_inverse_inverts_the_forward_map() {
        let fx = OpticsEffects {
            sensor_width_m: 200e-6,
            sensor_height_m: 150e-6,
            distortion: Some(Distortion::Division { k: 0.08 }),
            lateral_color: Some(LateralColor {
                kind: LateralColorKind::Cauchy,
                displacement_um: 2.0,
            }),
            ..Default::default()
        };
        let r_max = 130e-6;
        for lam in [420.0, 550.0, 690.0] {
            let inv = RadialInverse::new(&fx, Some(lam), r_max).unwrap();
            for k in 1..20 {
                let r = r_max * k as f64 / 20.0;
                let rs = inv.source_radius(r);
                assert_relative_eq!(fx.warp_forward_m(rs, Some(lam)), r, max_relative = 1e-6);
            }
        }
        // Strong barrel distortion folds over: an error, not a wrong image.
        let bad = OpticsEffects {
            distortion: Some(Distortion::Polynomial { k1: -0.6, k2: 0.0 }),
            ..fx
        };
        assert!(RadialInverse::new(&bad, None, 150e-6).is_err());
    }

    /// The guarded bisection of [`RadialInverse::new`] gives the plain 64-step bisection's
    /// table bit for bit (the reference below is that bisection, written out), over
    /// polynomial and division distortion (barrel and pincushion, up to near the fold and
    /// near the division model's pole), lateral colour of both kinds and several λ and r_max.
    #[test]
    fn guarded_bisection_is_the_plain_bisection_bit_for_bit() {
        let plain = |fx: &OpticsEffects, lam: Option<f64>, r_max: f64| -> Vec<u64> {
            let fwd = |r: f64| fx.warp_forward_m(r, lam);
            let hd = fx.half_diagonal_m();
            let r_lim = fx.distortion.map_or(f64::INFINITY, |d| d.h_limit()) * hd;
            let mut r_hi = r_max.min(0.999 * r_lim);
            let mut tries = 0;
            while fwd(r_hi) < r_max {
                let next = (r_hi * 1.1).min(0.999 * r_lim + 0.001 * r_hi);
                tries += 1;
                if tries > 200 || next <= r_hi {
                    break;
                }
                r_hi = next;
            }
            (0..RadialInverse::N)
                .map(|j| {
                    let target = r_max * j as f64 / (RadialInverse::N - 1) as f64;
                    let (mut a, mut b) = (0.0, r_hi);
                    for _ in 0..64 {
                        let c = 0.5 * (a + b);
                        if fwd(c) < target {
                            a = c;
                        } else {
                            b = c;
                        }
                    }
                    (0.5 * (a + b)).to_bits()
                })
                .collect()
        };
        let dists = [
            None,
            Some(Distortion::Polynomial {
                k1: 0.031,
                k2: -0.004,
            }),
            Some(Distortion::Polynomial {
                k1: -0.25,
                k2: 0.02,
            }),
            Some(Distortion::Polynomial {
                k1: -0.3,
                k2: -0.04,
            }),
            Some(Distortion::Polynomial { k1: 0.3, k2: 0.3 }),
            Some(Distortion::Division { k: 0.08 }),
            Some(Distortion::Division { k: 0.9 }),
            Some(Distortion::Division { k: -0.4 }),
        ];
        let lcs = [
            None,
            Some(LateralColor {
                kind: LateralColorKind::Linear,
                displacement_um: 1.37,
            }),
            Some(LateralColor {
                kind: LateralColorKind::Cauchy,
                displacement_um: -6.0,
            }),
        ];
        let mut tables = 0;
        for d in dists {
            for l in lcs {
                if d.is_none() && l.is_none() {
                    continue;
                }
                let fx = OpticsEffects {
                    sensor_width_m: 528e-6,
                    sensor_height_m: 352e-6,
                    distortion: d,
                    lateral_color: l,
                    ..Default::default()
                };
                let lams: Vec<Option<f64>> = if l.is_some() {
                    vec![Some(380.0), Some(551.0), Some(780.0)]
                } else {
                    vec![None]
                };
                for lam in lams {
                    for r_max in [1e-9, 150e-6, 317.3e-6, 335e-6] {
                        let Ok(t) = RadialInverse::new(&fx, lam, r_max) else {
                            continue;
                        };
                        let got: Vec<u64> = t.table.iter().map(|x| x.to_bits()).collect();
                        assert_eq!(got, plain(&fx, lam, r_max), "{d:?} {l:?} {lam:?} {r_max}");
                        tables += 1;
                    }
                }
            }
        }
        // the configurations above build (the fold-over ones are refused by both)
        assert!(tables >= 60, "{tables} tables compared");
    }

    /// The shared inverse tables are the freshly built ones bit for bit, built once per
    /// (effects, wavelength, r_max), and another lateral colour or wavelength is another
    /// table.
    #[test]
    fn shared_radial_inverse_is_the_built_one() {
        let fx = OpticsEffects {
            sensor_width_m: 240e-6,
            sensor_height_m: 160e-6,
            distortion: Some(Distortion::Polynomial {
                k1: 0.031,
                k2: -0.004,
            }),
            lateral_color: Some(LateralColor {
                kind: LateralColorKind::Linear,
                displacement_um: 1.37,
            }),
            ..Default::default()
        };
        let r_max = 150e-6;
        let a = RadialInverse::shared(&fx, Some(551.0), r_max).unwrap();
        let fresh = RadialInverse::new(&fx, Some(551.0), r_max).unwrap();
        let bits = |t: &RadialInverse| {
            let mut v: Vec<u64> = t.table.iter().map(|x| x.to_bits()).collect();
            v.push(t.ratio0.to_bits());
            v.push(t.r_max_m.to_bits());
            v
        };
        assert_eq!(bits(&a), bits(&fresh));
        // blocks the warp does not read share the table (same bits as a fresh build)
        let fx_glare = OpticsEffects {
            veiling_glare: Some(0.03),
            exposure_scale: Some(1.1),
            ..fx.clone()
        };
        let b = RadialInverse::shared(&fx_glare, Some(551.0), r_max).unwrap();
        assert_eq!(
            bits(&b),
            bits(&RadialInverse::new(&fx_glare, Some(551.0), r_max).unwrap())
        );
        assert_eq!(bits(&b), bits(&a));
        let other_lam = RadialInverse::shared(&fx, Some(552.0), r_max).unwrap();
        assert_ne!(bits(&other_lam), bits(&a));
        let fx2 = OpticsEffects {
            lateral_color: Some(LateralColor {
                kind: LateralColorKind::Linear,
                displacement_um: 1.38,
            }),
            ..fx.clone()
        };
        let other_fx = RadialInverse::shared(&fx2, Some(551.0), r_max).unwrap();
        assert_ne!(bits(&other_fx), bits(&a));
        assert_eq!(
            bits(&other_fx),
            bits(&RadialInverse::new(&fx2, Some(551.0), r_max).unwrap())
        );
    }
}

#[cfg(test)]
pub(crate) mod warp_tests {
    use super::*;
    use camsim_core::{SpectralBasis, Spectrum};

    /// A Gaussian spot of σ = `sig` samples at (x0, y0) samples from the image centre.
    pub(crate) fn spot_s(rows: usize, cols: usize, x0: f64, y0: f64, sig: f64) -> SpectralImage {
        let (yc, xc) = ((rows as f64 - 1.0) / 2.0, (cols as f64 - 1.0) / 2.0);
        let plane = (0..rows * cols)
            .map(|i| {
                let (y, x) = ((i / cols) as f64 - yc, (i % cols) as f64 - xc);
                (-((x - x0).powi(2) + (y - y0).powi(2)) / (2.0 * sig * sig)).exp() as f32
            })
            .collect();
        SpectralImage::new(
            rows,
            cols,
            SpectralBasis::Spectra(vec![Spectrum::constant(1.0)]),
            vec![plane],
        )
        .unwrap()
    }

    /// The warp accumulated straight into projected planes ([`warp_planes_projected`]) is,
    /// bit for bit, [`warp_planes`] then [`SpectralImage::combine`] of each weight row, for
    /// lateral colour (one table per wavelength) with distortion, on a row window of the field
    /// (rows 40..77 of 120) and on the whole image, with a zero weight (skipped, as `combine`
    /// skips it) and a plane no output uses.
    #[test]
    fn projected_warp_is_the_warp_then_the_projection_bit_for_bit() {
        let (rows, cols, dx) = (37, 53, 1.1e-6);
        let planes: Vec<Vec<f32>> = (0..4)
            .map(|k| {
                (0..rows * cols)
                    .map(|i| {
                        let v = (i as u64 + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15 ^ (k + 3));
                        (v >> 40) as f32 / (1u64 << 24) as f32
                    })
                    .collect()
            })
            .collect();
        let basis = || SpectralBasis::Spectra((0..4).map(|_| Spectrum::constant(1.0)).collect());
        let fx = OpticsEffects {
            sensor_width_m: 50e-6,
            sensor_height_m: 36e-6,
            distortion: Some(Distortion::Polynomial {
                k1: -0.05,
                k2: 0.01,
            }),
            lateral_color: Some(LateralColor {
                kind: LateralColorKind::Cauchy,
                displacement_um: 4.1,
            }),
            ..Default::default()
        };
        let lams = [430.0, 510.0, 590.0, 680.0];
        let weights = vec![
            vec![0.3, 1.7, 0.0, 0.25],
            vec![1.1, 0.0, 0.0, 2.5],
            vec![0.0, 0.9, 0.0, 1e-3],
        ];
        for window in [
            RowWindow::whole(rows),
            RowWindow {
                row0: 40,
                full_rows: 120,
            },
        ] {
            let mut img = SpectralImage::new(rows, cols, basis(), planes.clone()).unwrap();
            let got = warp_planes_projected(&fx, &img, dx, Some(&lams), window, &weights).unwrap();
            warp_planes(&fx, &mut img, dx, Some(&lams), window).unwrap();
            for (c, w) in weights.iter().enumerate() {
                let want: Vec<u32> = img.combine(w).iter().map(|v| v.to_bits()).collect();
                let got: Vec<u32> = got[c].iter().map(|v| v.to_bits()).collect();
                assert_eq!(got, want, "output {c}, {window:?}");
            }
            // (the warp moved something: the projection of the unwarped planes differs)
            let unwarped = SpectralImage::new(rows, cols, basis(), planes.clone()).unwrap();
            assert_ne!(got[0], unwarped.combine(&weights[0]), "{window:?}");
        }
    }

    /// The warp with shared radii and taps is, bit for bit, the per-sample warp written out
    /// (hypot, the inverse table, the clamped bilinear sample with floor), for one map
    /// (distortion, planes of a linear model) and one map per wavelength (lateral colour).
    #[test]
    fn shared_taps_warp_is_the_per_sample_warp_bit_for_bit() {
        let (rows, cols, dx) = (37, 53, 1.1e-6);
        let plane = |seed: u64| -> Vec<f32> {
            (0..rows * cols)
                .map(|i| {
                    let v = (i as u64 + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15 ^ seed);
                    (v >> 40) as f32 / (1u64 << 24) as f32
                })
                .collect()
        };
        let reference = |fx: &OpticsEffects, p: &[f32], lam: Option<f64>| -> Vec<u32> {
            let (yc, xc) = ((rows as f64 - 1.0) / 2.0, (cols as f64 - 1.0) / 2.0);
            let r_max = dx * (yc * yc + xc * xc).sqrt() * 1.001 + 1e-12;
            let map = RadialInverse::new(fx, lam, r_max).unwrap();
            let mut out = vec![0u32; rows * cols];
            for i in 0..rows {
                for j in 0..cols {
                    let (y, x) = ((i as f64 - yc) * dx, (j as f64 - xc) * dx);
                    let r = x.hypot(y);
                    let g = if r > 0.0 {
                        let t = r / map.r_max_m * (RadialInverse::N - 1) as f64;
                        let i0 = (t.floor().max(0.0) as usize).min(RadialInverse::N - 2);
                        let f = t - i0 as f64;
                        (map.table[i0] * (1.0 - f) + map.table[i0 + 1] * f) / r
                    } else {
                        map.ratio0
                    };
                    let fr = (yc + (i as f64 - yc) * g).clamp(0.0, (rows - 1) as f64);
                    let fc = (xc + (j as f64 - xc) * g).clamp(0.0, (cols - 1) as f64);
                    let (r0, c0) = (fr.floor() as usize, fc.floor() as usize);
                    let (r1, c1) = ((r0 + 1).min(rows - 1), (c0 + 1).min(cols - 1));
                    let (tr, tc) = (fr - r0 as f64, fc - c0 as f64);
                    let v = |r: usize, c: usize| p[r * cols + c] as f64;
                    let s = (v(r0, c0) * (1.0 - tc) + v(r0, c1) * tc) * (1.0 - tr)
                        + (v(r1, c0) * (1.0 - tc) + v(r1, c1) * tc) * tr;
                    out[i * cols + j] = (s as f32).to_bits();
                }
            }
            out
        };
        let basis = || SpectralBasis::Spectra((0..3).map(|_| Spectrum::constant(1.0)).collect());
        let planes: Vec<Vec<f32>> = (0..3).map(|k| plane(k as u64 + 7)).collect();
        // distortion only: one map for the planes of a linear model
        let fx = OpticsEffects {
            sensor_width_m: 50e-6,
            sensor_height_m: 36e-6,
            distortion: Some(Distortion::Polynomial {
                k1: -0.12,
                k2: 0.03,
            }),
            ..Default::default()
        };
        // with the shared radius and tap tables, and without them (over the table budget)
        for budget in [WARP_SHARED_TABLE_BYTES, 0] {
            let mut img = SpectralImage::new(rows, cols, basis(), planes.clone()).unwrap();
            warp_planes_within(&fx, &mut img, dx, None, budget, RowWindow::whole(rows)).unwrap();
            for (k, p) in img.planes.iter().enumerate() {
                let got: Vec<u32> = p.iter().map(|v| v.to_bits()).collect();
                assert_eq!(
                    got,
                    reference(&fx, &planes[k], None),
                    "plane {k}, budget {budget}"
                );
            }
        }
        // lateral colour: one map per plane's wavelength
        let fx = OpticsEffects {
            lateral_color: Some(LateralColor {
                kind: LateralColorKind::Linear,
                displacement_um: 3.3,
            }),
            ..fx
        };
        let lams = [430.0, 550.0, 680.0];
        let mut without = SpectralImage::new(rows, cols, basis(), planes.clone()).unwrap();
        warp_planes_within(
            &fx,
            &mut without,
            dx,
            Some(&lams),
            0,
            RowWindow::whole(rows),
        )
        .unwrap();
        let mut img = SpectralImage::new(rows, cols, basis(), planes.clone()).unwrap();
        warp_planes(&fx, &mut img, dx, Some(&lams), RowWindow::whole(rows)).unwrap();
        assert_eq!(
            img.planes, without.planes,
            "lateral colour without the radius table"
        );
        for (k, p) in img.planes.iter().enumerate() {
            let got: Vec<u32> = p.iter().map(|v| v.to_bits()).collect();
            assert_eq!(got, reference(&fx, &planes[k], Some(lams[k])), "plane {k}");
            // and the warp moved something (the test compares a non-trivial resampling)
            assert_ne!(
                got,
                planes[k].iter().map(|v| v.to_bits()).collect::<Vec<_>>()
            );
        }
    }

    #[test]
    fn warp_resamples_the_scene_at_the_inverse_radial_map() {
        // Output sample x must hold the scene at the radius the forward map sends to |x|:
        // compare with the analytic spot evaluated there (bilinear interpolation error of a
        // σ = 3 sample Gaussian ≤ 2 · |G''|/8 = 1/(4σ²) ≈ 2.8 % of the peak), and the centroids.
        let (rows, cols, dx) = (200, 260, 1e-6);
        let fx = OpticsEffects {
            sensor_width_m: 240e-6,
            sensor_height_m: 180e-6,
            distortion: Some(Distortion::Division { k: 0.12 }),
            lateral_color: Some(LateralColor {
                kind: LateralColorKind::Linear,
                displacement_um: 4.0,
            }),
            ..Default::default()
        };
        let (yc, xc) = ((rows as f64 - 1.0) / 2.0, (cols as f64 - 1.0) / 2.0);
        for lam in [450.0, 650.0] {
            for (x0, y0) in [(60.0, 40.0), (-70.0, 20.0), (0.0, 0.0)] {
                let mut img = spot_s(rows, cols, x0, y0, 3.0);
                warp_planes(&fx, &mut img, dx, Some(&[lam]), RowWindow::whole(rows)).unwrap();
                // Reference: forward-map every output position's inverse by bisection.
                let inv = |r: f64| -> f64 {
                    let (mut a, mut b) = (0.0, 2.0 * r + 1e-6);
                    for _ in 0..80 {
                        let c = 0.5 * (a + b);
                        if fx.warp_forward_m(c, Some(lam)) < r {
                            a = c;
                        } else {
                            b = c;
                        }
                    }
                    0.5 * (a + b)
                };
                let (mut s0, mut sx0, mut sy0) = (0.0, 0.0, 0.0);
                let (mut s1, mut sx1, mut sy1) = (0.0, 0.0, 0.0);
                for i in 0..rows * cols {
                    let (y, x) = ((i / cols) as f64 - yc, (i % cols) as f64 - xc);
                    let r = x.hypot(y) * dx;
                    let g = if r > 0.0 { inv(r) / r } else { 1.0 };
                    let (us, vs) = (x * g, y * g);
                    let want = (-((us - x0).powi(2) + (vs - y0).powi(2)) / 18.0).exp();
                    let got = img.planes[0][i] as f64;
                    assert!(
                        (got - want).abs() < 0.03,
                        "{lam} ({x0},{y0}) at ({x},{y}): {got} vs {want}"
                    );
                    s0 += want;
                    sx0 += want * x;
                    sy0 += want * y;
                    s1 += got;
                    sx1 += got * x;
                    sy1 += got * y;
                }
                assert!((sx1 / s1 - sx0 / s0).abs() < 0.01 && (sy1 / s1 - sy0 / s0).abs() < 0.01);
                // And to first order in the spot's size the centroid is the forward image of
                // its centre (second-order bias ∝ σ²: < 0.1 sample here).
                let r0 = f64::hypot(x0, y0) * dx;
                let k = if r0 > 0.0 {
                    fx.warp_forward_m(r0, Some(lam)) / r0
                } else {
                    1.0
                };
                assert!((sx1 / s1 - x0 * k).abs() < 0.1 && (sy1 / s1 - y0 * k).abs() < 0.1);
            }
        }
    }
}
