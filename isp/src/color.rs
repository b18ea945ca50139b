//! White balance and colour correction (§2.D of the paper: a 3×3 matrix chosen by least
//! squares so that the sensor responses to a calibration target — the Macbeth chart under a
//! chosen light — map onto the target's values in the output colour space).
use crate::mosaic::RgbImage;
use crate::IspError;
use camsim_core::{data, Spectrum};
use nalgebra::DMatrix;
use rayon::prelude::*;

pub use camsim_core::colorimetry::XYZ_TO_LINEAR_SRGB;

/// Index of the white patch ("white 9.5", row 4 column 1) in the row-major Macbeth order of
/// [`camsim_core::data::macbeth_reflectances_row_major`].
pub const MACBETH_WHITE_INDEX: usize = 18;

/// A 3×3 linear colour transform applied to column vectors: `out = m · in`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ColorMatrix {
    /// Row-major matrix; `out[i] = Σ_j m[i][j] · in[j]`.
    pub m: [[f64; 3]; 3],
}

impl ColorMatrix {
    /// The identity transform.
    pub fn identity() -> Self {
        ColorMatrix {
            m: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        }
    }

    /// `m · v`.
    #[inline]
    pub fn apply(&self, v: [f64; 3]) -> [f64; 3] {
        let m = &self.m;
        [
            m[0][0] * v[0] + m[0][1] * v[1] + m[0][2] * v[2],
            m[1][0] * v[0] + m[1][1] * v[1] + m[1][2] * v[2],
            m[2][0] * v[0] + m[2][1] * v[1] + m[2][2] * v[2],
        ]
    }

    /// Composition `self ∘ other` = matrix product `self · other` (`other` is applied first).
    pub fn after(&self, other: &ColorMatrix) -> ColorMatrix {
        let mut m = [[0.0; 3]; 3];
        for (i, row) in m.iter_mut().enumerate() {
            for (j, x) in row.iter_mut().enumerate() {
                *x = (0..3).map(|k| self.m[i][k] * other.m[k][j]).sum();
            }
        }
        ColorMatrix { m }
    }

    /// Every element times `k`.
    pub fn scaled(&self, k: f64) -> ColorMatrix {
        ColorMatrix {
            m: self.m.map(|r| r.map(|x| x * k)),
        }
    }

    /// The transpose (converts between the column-vector convention used here and the
    /// row-vector convention `out = in · T` of ISETCam).
    pub fn transpose(&self) -> ColorMatrix {
        let m = &self.m;
        ColorMatrix {
            m: [
                [m[0][0], m[1][0], m[2][0]],
                [m[0][1], m[1][1], m[2][1]],
                [m[0][2], m[1][2], m[2][2]],
            ],
        }
    }

    /// Apply to every pixel of an image in place.
    pub fn apply_image(&self, img: &mut RgbImage) {
        img.data.par_iter_mut().for_each(|p| {
            let o = self.apply([p[0] as f64, p[1] as f64, p[2] as f64]);
            *p = [o[0] as f32, o[1] as f32, o[2] as f32];
        });
    }
}

/// The 3×3 matrix `M` minimising `Σ_i ‖M · sensor_i − target_i‖²` (ordinary least squares,
/// solved by SVD). Needs at least 3 samples whose sensor values span three dimensions.
pub fn fit_color_correction(
    sensor_rgb: &[[f64; 3]],
    target_rgb: &[[f64; 3]],
) -> Result<ColorMatrix, IspError> {
    if sensor_rgb.len() != target_rgb.len() {
        return Err(IspError::Fit(format!(
            "{} sensor samples but {} target samples",
            sensor_rgb.len(),
            target_rgb.len()
        )));
    }
    let n = sensor_rgb.len();
    if n < 3 {
        return Err(IspError::Fit(format!("{n} samples; at least 3 are needed")));
    }
    let a = DMatrix::from_fn(n, 3, |i, j| sensor_rgb[i][j]);
    let b = DMatrix::from_fn(n, 3, |i, j| target_rgb[i][j]);
    if a.iter().chain(b.iter()).any(|x| !x.is_finite()) {
        return Err(IspError::Fit("non-finite sample value".into()));
    }
    let svd = a.svd(true, true);
    let sv = &svd.singular_values;
    let (smax, smin) = (sv.max(), sv.min());
    if !(smin > smax * 1e-12) {
        return Err(IspError::Fit(format!(
            "sensor samples do not span three dimensions (singular values {:?})",
            sv.as_slice()
        )));
    }
    // A X = B with X = Mᵀ
    let x = svd
        .solve(&b, 0.0)
        .map_err(|e| IspError::Fit(e.to_string()))?;
    let mut m = [[0.0; 3]; 3];
    for (i, row) in m.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = x[(j, i)];
        }
    }
    Ok(ColorMatrix { m })
}

/// How the channel gains of the white balance are chosen. Gains are normalised so that green
/// has gain 1 (except for explicit gains).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum WhiteBalance {
    /// No gains.
    None,
    /// Grey world (Buchsbaum 1980): the channel means of the image become equal.
    GreyWorld,
    /// White patch / max-RGB (Land's retinex): the channel maxima of the image become equal.
    WhitePatch,
    /// Explicit gains for (R, G, B), e.g. from [`illuminant_gains`].
    Gains([f64; 3]),
}

impl WhiteBalance {
    /// The gains this rule chooses for an image.
    pub fn gains(&self, img: &RgbImage) -> Result<[f64; 3], IspError> {
        let from_stat = |stat: [f64; 3], what: &str| {
            if let Some(k) = (0..3).find(|&k| !(stat[k] > 0.0 && stat[k].is_finite())) {
                return Err(IspError::InvalidParameter {
                    name: format!("white balance {what} of channel {}", ["R", "G", "B"][k]),
                    value: format!("{}", stat[k]),
                    reason: "must be positive to compute a gain".into(),
                });
            }
            Ok([stat[1] / stat[0], 1.0, stat[1] / stat[2]])
        };
        match *self {
            WhiteBalance::None => Ok([1.0; 3]),
            WhiteBalance::GreyWorld => {
                let mut s = [0.0f64; 3];
                for p in &img.data {
                    for k in 0..3 {
                        s[k] += p[k] as f64;
                    }
                }
                let n = img.data.len().max(1) as f64;
                from_stat(s.map(|x| x / n), "mean")
            }
            WhiteBalance::WhitePatch => {
                let mut mx = [f64::NEG_INFINITY; 3];
                for p in &img.data {
                    for k in 0..3 {
                        mx[k] = mx[k].max(p[k] as f64);
                    }
                }
                from_stat(mx, "maximum")
            }
            WhiteBalance::Gains(g) => {
                if let Some(k) = (0..3).find(|&k| !(g[k] > 0.0 && g[k].is_finite())) {
                    return Err(IspError::InvalidParameter {
                        name: format!("white balance gain[{k}]"),
                        value: format!("{}", g[k]),
                        reason: "must be a positive finite number".into(),
                    });
                }
                Ok(g)
            }
        }
    }

    /// Multiply each channel by its gain; returns the gains used.
    pub fn apply(&self, img: &mut RgbImage) -> Result<[f64; 3], IspError> {
        let g = self.gains(img)?;
        let g32 = g.map(|x| x as f32);
        img.data.par_iter_mut().for_each(|p| {
            for k in 0..3 {
                p[k] *= g32[k];
            }
        });
        Ok(g)
    }
}

fn check_three(channel_qe: &[Spectrum]) -> Result<(), IspError> {
    if channel_qe.len() != 3 {
        return Err(IspError::InvalidParameter {
            name: "channel_qe".into(),
            value: format!("{} spectra", channel_qe.len()),
            reason: "exactly three (R, G, B) are needed".into(),
        });
    }
    Ok(())
}

fn integral(a: &Spectrum, b: &Spectrum) -> Result<f64, IspError> {
    Spectrum::integrate_product(a, b)
        .ok_or_else(|| IspError::Data("integral of two unbounded (affine) spectra".into()))
}

/// Known-illuminant white balance: the gains that make the camera response to the illuminant
/// itself neutral. Response `c = ∫ QE_c(λ) I(λ) dλ` (QE in electrons per photon, so the
/// illuminant in photon units), gain `= G / c` (green gain 1).
pub fn illuminant_gains(
    channel_qe: &[Spectrum],
    illuminant_photons: &Spectrum,
) -> Result<[f64; 3], IspError> {
    check_three(channel_qe)?;
    let mut resp = [0.0; 3];
    for k in 0..3 {
        resp[k] = integral(&channel_qe[k], illuminant_photons)?;
        if !(resp[k] > 0.0) {
            return Err(IspError::InvalidParameter {
                name: format!(
                    "response of channel {} to the illuminant",
                    ["R", "G", "B"][k]
                ),
                value: format!("{}", resp[k]),
                reason: "must be positive to compute a gain".into(),
            });
        }
    }
    Ok([resp[1] / resp[0], 1.0, resp[1] / resp[2]])
}

/// CIE 1931 XYZ of the 24 Macbeth patches (row-major chart order) under an illuminant in
/// energy units: `∫ R_i(λ) I(λ) cmf(λ) dλ` (relative scale, no 683 factor).
pub fn macbeth_xyz(illuminant_energy: &Spectrum) -> Result<Vec<[f64; 3]>, IspError> {
    let cmf = data::cie1931_xyz()?;
    data::macbeth_reflectances_row_major()?
        .iter()
        .map(|refl| {
            let radiance = Spectrum::multiply(refl, illuminant_energy);
            Ok([
                integral(&radiance, &cmf[0])?,
                integral(&radiance, &cmf[1])?,
                integral(&radiance, &cmf[2])?,
            ])
        })
        .collect()
}

/// Linear sRGB of the 24 Macbeth patches under an illuminant (energy units): XYZ scaled so
/// that the white patch ([`MACBETH_WHITE_INDEX`]) has `Y = white_y`, then
/// [`XYZ_TO_LINEAR_SRGB`]. Under D65 this is the colour-correction target of the paper.
pub fn macbeth_target_linear_srgb(
    illuminant_energy: &Spectrum,
    white_y: f64,
) -> Result<Vec<[f64; 3]>, IspError> {
    let xyz = macbeth_xyz(illuminant_energy)?;
    let wy = xyz[MACBETH_WHITE_INDEX][1];
    if !(wy > 0.0) {
        return Err(IspError::InvalidParameter {
            name: "white patch Y".into(),
            value: format!("{wy}"),
            reason: "the illuminant gives no luminance".into(),
        });
    }
    let m = ColorMatrix {
        m: XYZ_TO_LINEAR_SRGB,
    };
    Ok(xyz
        .iter()
        .map(|v| m.apply(v.map(|x| x * white_y / wy)))
        .collect())
}

/// Sensor responses (R, G, B) to the 24 Macbeth patches (row-major order):
/// `∫ QE_c(λ) R_i(λ) I(λ) dλ` with the illuminant in photon units.
pub fn macbeth_sensor_rgb(
    channel_qe: &[Spectrum],
    illuminant_photons: &Spectrum,
) -> Result<Vec<[f64; 3]>, IspError> {
    check_three(channel_qe)?;
    data::macbeth_reflectances_row_major()?
        .iter()
        .map(|refl| {
            let radiance = Spectrum::multiply(refl, illuminant_photons);
            Ok([
                integral(&radiance, &channel_qe[0])?,
                integral(&radiance, &channel_qe[1])?,
                integral(&radiance, &channel_qe[2])?,
            ])
        })
        .collect()
}
