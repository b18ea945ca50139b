//! White balance and colour correction for any number of channels (RGB, RGBW, RCCB, RCCC,
//! mono, multispectral): per-channel gains, then a 3 × K matrix to linear output RGB fitted by
//! least squares on a calibration capture (§2.D of Farrell, Catrysse & Wandell 2012, with the
//! matrix generalised from 3 × 3 to 3 × K). For an RGB camera (K = 3, channels r, g, b) this is
//! exactly [`crate::WhiteBalance`] followed by [`crate::fit_color_correction`].
use crate::cfa_generic::ChannelPlanes;
use crate::mosaic::{rgb_index_of_name, RgbImage};
use crate::IspError;
use camsim_core::{data, Spectrum};
use nalgebra::DMatrix;
use rayon::prelude::*;

/// The channel the gains are normalised to (gain 1): `g` if present, else `w`, `c` or `y`
/// (clear/white/yellow pixels), else channel 0.
pub fn reference_channel(names: &[String]) -> usize {
    for want in ["g", "w", "c", "y"] {
        if let Some(k) = names.iter().position(|n| {
            n.trim().eq_ignore_ascii_case(want) || (want == "g" && rgb_index_of_name(n) == Some(1))
        }) {
            return k;
        }
    }
    0
}

/// How per-channel white-balance gains are chosen (gain of the reference channel = 1).
#[derive(Debug, Clone, PartialEq)]
pub enum ChannelBalance {
    /// All gains 1.
    None,
    /// Grey world (Buchsbaum 1980): the channel means become equal.
    GreyWorld,
    /// White patch / max-RGB (Land's retinex): the channel maxima become equal.
    WhitePatch,
    /// Explicit gains, one per channel (e.g. [`illuminant_channel_gains`] or a DNG's
    /// AsShotNeutral).
    Gains(Vec<f64>),
}

impl ChannelBalance {
    /// The configuration name.
    pub fn name(&self) -> &'static str {
        match self {
            ChannelBalance::None => "none",
            ChannelBalance::GreyWorld => "grey_world",
            ChannelBalance::WhitePatch => "white_patch",
            ChannelBalance::Gains(_) => "gains",
        }
    }

    /// The gains this rule chooses for an image.
    pub fn gains(&self, img: &ChannelPlanes) -> Result<Vec<f64>, IspError> {
        let k = img.channels();
        let reference = reference_channel(&img.names);
        let from_stat = |stat: Vec<f64>, what: &str| -> Result<Vec<f64>, IspError> {
            if let Some(c) = (0..k).find(|&c| !(stat[c] > 0.0 && stat[c].is_finite())) {
                return Err(IspError::InvalidParameter {
                    name: format!("white balance {what} of channel '{}'", img.names[c]),
                    value: format!("{}", stat[c]),
                    reason: "must be positive to compute a gain".into(),
                });
            }
            Ok(stat.iter().map(|s| stat[reference] / s).collect())
        };
        match self {
            ChannelBalance::None => Ok(vec![1.0; k]),
            ChannelBalance::GreyWorld => {
                let n = (img.rows * img.cols).max(1) as f64;
                from_stat(
                    img.planes
                        .iter()
                        .map(|p| p.iter().map(|&x| x as f64).sum::<f64>() / n)
                        .collect(),
                    "mean",
                )
            }
            ChannelBalance::WhitePatch => from_stat(
                img.planes
                    .iter()
                    .map(|p| {
                        p.iter()
                            .map(|&x| x as f64)
                            .fold(f64::NEG_INFINITY, f64::max)
                    })
                    .collect(),
                "maximum",
            ),
            ChannelBalance::Gains(g) => {
                if g.len() != k {
                    return Err(IspError::InvalidParameter {
                        name: "white balance gains".into(),
                        value: format!("{} values", g.len()),
                        reason: format!("need one per channel ({k})"),
                    });
                }
                if let Some(c) = (0..k).find(|&c| !(g[c] > 0.0 && g[c].is_finite())) {
                    return Err(IspError::InvalidParameter {
                        name: format!("white balance gain of channel '{}'", img.names[c]),
                        value: format!("{}", g[c]),
                        reason: "must be a positive finite number".into(),
                    });
                }
                Ok(g.clone())
            }
        }
    }

    /// Multiply each channel by its gain; returns the gains.
    pub fn apply(&self, img: &mut ChannelPlanes) -> Result<Vec<f64>, IspError> {
        let g = self.gains(img)?;
        for (p, &gk) in img.planes.iter_mut().zip(&g) {
            let g32 = gk as f32;
            p.par_iter_mut().for_each(|x| *x *= g32);
        }
        Ok(g)
    }
}

fn integral(a: &Spectrum, b: &Spectrum) -> Result<f64, IspError> {
    Spectrum::integrate_product(a, b)
        .ok_or_else(|| IspError::Data("integral of two unbounded (affine) spectra".into()))
}

/// Known-illuminant gains for any channels: the gains that make the response to the
/// illuminant itself equal in every channel, `gain_k = c_ref / c_k` with
/// `c_k = ∫ QE_k(λ) I(λ) dλ` (illuminant in photon units).
pub fn illuminant_channel_gains(
    channel_qe: &[Spectrum],
    names: &[String],
    illuminant_photons: &Spectrum,
) -> Result<Vec<f64>, IspError> {
    let resp: Vec<f64> = channel_qe
        .iter()
        .map(|q| integral(q, illuminant_photons))
        .collect::<Result<_, _>>()?;
    if let Some(c) = (0..resp.len()).find(|&c| !(resp[c] > 0.0)) {
        return Err(IspError::InvalidParameter {
            name: format!(
                "response of channel '{}' to the illuminant",
                names.get(c).map_or("?", |s| s.as_str())
            ),
            value: format!("{}", resp[c]),
            reason: "must be positive to compute a gain".into(),
        });
    }
    let r = resp[reference_channel(names)];
    Ok(resp.iter().map(|x| r / x).collect())
}

/// Channel responses to the 24 Macbeth patches (row-major chart order):
/// `∫ QE_k(λ) R_i(λ) I(λ) dλ`, illuminant in photon units — a noise-free calibration capture.
pub fn macbeth_channel_responses(
    channel_qe: &[Spectrum],
    illuminant_photons: &Spectrum,
) -> Result<Vec<Vec<f64>>, IspError> {
    data::macbeth_reflectances_row_major()?
        .iter()
        .map(|refl| {
            let radiance = Spectrum::multiply(refl, illuminant_photons);
            channel_qe.iter().map(|q| integral(&radiance, q)).collect()
        })
        .collect()
}

/// A 3 × K matrix from K channel values to linear output RGB: `rgb_i = Σ_k m[i][k] · x_k`.
#[derive(Debug, Clone, PartialEq)]
pub struct ChannelMatrix {
    /// Three rows of K coefficients.
    pub m: [Vec<f64>; 3],
}

impl ChannelMatrix {
    /// The matrix that picks the channels named r, g, b (None when a colour is missing).
    pub fn select_rgb(names: &[String]) -> Option<Self> {
        let k = names.len();
        let mut m = [vec![0.0; k], vec![0.0; k], vec![0.0; k]];
        let mut found = [false; 3];
        for (c, n) in names.iter().enumerate() {
            if let Some(i) = rgb_index_of_name(n) {
                m[i][c] = 1.0;
                found[i] = true;
            }
        }
        found.iter().all(|&f| f).then_some(ChannelMatrix { m })
    }

    /// Number of input channels.
    pub fn inputs(&self) -> usize {
        self.m[0].len()
    }

    /// `m · x`.
    pub fn apply(&self, x: &[f64]) -> [f64; 3] {
        [0, 1, 2].map(|i| self.m[i].iter().zip(x).map(|(a, b)| a * b).sum())
    }

    /// Every element times `k`.
    pub fn scaled(&self, k: f64) -> Self {
        ChannelMatrix {
            m: self.m.clone().map(|r| r.iter().map(|x| x * k).collect()),
        }
    }

    /// Apply to every pixel of the planes.
    pub fn apply_planes(&self, img: &ChannelPlanes) -> Result<RgbImage, IspError> {
        if self.inputs() != img.channels() || self.m.iter().any(|r| r.len() != img.channels()) {
            return Err(IspError::InvalidParameter {
                name: "colour matrix".into(),
                value: format!("3 × {}", self.inputs()),
                reason: format!("must be 3 × {} (one column per channel)", img.channels()),
            });
        }
        let data = (0..img.rows * img.cols)
            .into_par_iter()
            .map(|i| {
                let mut o = [0f64; 3];
                for (k, p) in img.planes.iter().enumerate() {
                    let v = p[i] as f64;
                    for (j, oj) in o.iter_mut().enumerate() {
                        *oj += self.m[j][k] * v;
                    }
                }
                o.map(|x| x as f32)
            })
            .collect();
        Ok(RgbImage {
            rows: img.rows,
            cols: img.cols,
            data,
        })
    }
}

/// The 3 × K matrix `M` minimising `Σ_i ‖M · x_i − t_i‖²` (least squares by SVD). Needs at
/// least K samples. When the samples do not span K dimensions (e.g. a W channel that is exactly
/// R + G + B, or narrow bands sampling smooth reflectances), directions whose singular value is
/// below [`FIT_RELATIVE_TOLERANCE`] of the largest are dropped: the minimum-norm solution
/// (Golub & Van Loan, *Matrix Computations*, §5.5), which does not amplify noise along
/// directions the calibration capture never exercised.
pub const FIT_RELATIVE_TOLERANCE: f64 = 1e-4;

/// Fit the 3 × K matrix (see [`FIT_RELATIVE_TOLERANCE`] for rank-deficient samples).
pub fn fit_channel_matrix(
    samples: &[Vec<f64>],
    targets: &[[f64; 3]],
) -> Result<ChannelMatrix, IspError> {
    if samples.len() != targets.len() {
        return Err(IspError::Fit(format!(
            "{} samples but {} targets",
            samples.len(),
            targets.len()
        )));
    }
    let n = samples.len();
    let k = samples.first().map_or(0, |s| s.len());
    if k == 0 || samples.iter().any(|s| s.len() != k) {
        return Err(IspError::Fit(
            "samples have different or zero channel counts".into(),
        ));
    }
    if n < k {
        return Err(IspError::Fit(format!(
            "{n} samples for {k} channels; at least {k} are needed"
        )));
    }
    let a = DMatrix::from_fn(n, k, |i, j| samples[i][j]);
    let b = DMatrix::from_fn(n, 3, |i, j| targets[i][j]);
    if a.iter().chain(b.iter()).any(|x| !x.is_finite()) {
        return Err(IspError::Fit("non-finite sample value".into()));
    }
    let svd = a.svd(true, true);
    let smax = svd.singular_values.max();
    if !(smax > 0.0) {
        return Err(IspError::Fit("all samples are zero".into()));
    }
    let x = svd
        .solve(&b, smax * FIT_RELATIVE_TOLERANCE)
        .map_err(|e| IspError::Fit(e.to_string()))?;
    Ok(ChannelMatrix {
        m: [0, 1, 2].map(|i| (0..k).map(|j| x[(j, i)]).collect()),
    })
}
