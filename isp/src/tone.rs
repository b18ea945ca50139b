//! Optional tone curve and denoiser.
//!
//! * Tone curves act on linear output RGB before sRGB encoding:
//!   - `reinhard`: the global operator of Reinhard, Stark, Shirley & Ferwerda, "Photographic
//!     tone reproduction for digital images", SIGGRAPH 2002, Eq. 4, on luminance
//!     `Y = 0.2126 R + 0.7152 G + 0.0722 B` (sRGB): `Y_d = Y (1 + Y / Y_white²) / (1 + Y)`, every
//!     channel scaled by `Y_d / Y` (hue kept); `Y_white` is the smallest luminance mapped to 1.
//!   - `filmic`: J. Hable's filmic curve ("Filmic tonemapping operators", GDC 2010),
//!     `f(x) = (x(Ax + CB) + DE) / (x(Ax + B) + DF) − E/F` with A = 0.15, B = 0.50, C = 0.10,
//!     D = 0.20, E = 0.02, F = 0.30, per channel, normalised by `f(W)` with the linear white
//!     `W = 11.2`, after an exposure bias of 2 (Hable's values).
//! * The denoiser is a bilateral filter (Tomasi & Manduchi, "Bilateral filtering for gray and
//!   color images", ICCV 1998) per demosaicked channel: weights
//!   `exp(−d²/2σ_s²) · exp(−Δ²/2σ_r²)` over a `(2⌈2σ_s⌉ + 1)²` window (border mirrored);
//!   `σ_r = ∞` gives a plain Gaussian blur.
use crate::cfa_generic::ChannelPlanes;
use crate::mosaic::RgbImage;
use crate::IspError;
use rayon::prelude::*;

/// A global tone curve (module documentation).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ToneCurve {
    /// Linear (no curve).
    None,
    /// Reinhard et al. 2002 Eq. 4 with the given white luminance.
    Reinhard {
        /// Smallest linear luminance mapped to 1.
        white: f64,
    },
    /// Hable's filmic curve.
    Filmic,
}

fn hable(x: f64) -> f64 {
    let (a, b, c, d, e, f) = (0.15, 0.50, 0.10, 0.20, 0.02, 0.30);
    (x * (a * x + c * b) + d * e) / (x * (a * x + b) + d * f) - e / f
}

impl ToneCurve {
    /// Parse "none", "reinhard" (white 4) or "filmic".
    pub fn parse(name: &str, reinhard_white: Option<f64>) -> Result<Self, IspError> {
        match name {
            "none" => Ok(ToneCurve::None),
            "reinhard" => {
                let w = reinhard_white.unwrap_or(4.0);
                if !(w > 0.0 && w.is_finite()) {
                    return Err(IspError::InvalidParameter {
                        name: "tone_white".into(),
                        value: format!("{w}"),
                        reason: "must be a positive finite number".into(),
                    });
                }
                Ok(ToneCurve::Reinhard { white: w })
            }
            "filmic" => Ok(ToneCurve::Filmic),
            _ => Err(IspError::InvalidParameter {
                name: "tone_curve".into(),
                value: name.into(),
                reason: "expected none, reinhard or filmic".into(),
            }),
        }
    }

    /// The configuration name.
    pub fn name(&self) -> &'static str {
        match self {
            ToneCurve::None => "none",
            ToneCurve::Reinhard { .. } => "reinhard",
            ToneCurve::Filmic => "filmic",
        }
    }

    /// The curve applied to one linear RGB value.
    pub fn map(&self, v: [f64; 3]) -> [f64; 3] {
        match *self {
            ToneCurve::None => v,
            ToneCurve::Reinhard { white } => {
                let y = 0.2126 * v[0] + 0.7152 * v[1] + 0.0722 * v[2];
                if y <= 0.0 {
                    return v;
                }
                let yd = y * (1.0 + y / (white * white)) / (1.0 + y);
                v.map(|x| x * yd / y)
            }
            ToneCurve::Filmic => {
                let w = hable(11.2);
                v.map(|x| hable(2.0 * x.max(0.0)) / w)
            }
        }
    }

    /// Apply in place.
    pub fn apply(&self, img: &mut RgbImage) {
        if *self == ToneCurve::None {
            return;
        }
        img.data.par_iter_mut().for_each(|p| {
            let o = self.map([p[0] as f64, p[1] as f64, p[2] as f64]);
            *p = o.map(|x| x as f32);
        });
    }
}

/// Bilateral denoiser settings (module documentation).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bilateral {
    /// Spatial standard deviation (pixels).
    pub sigma_px: f64,
    /// Range standard deviation (linear signal units, 1 = white); infinity = Gaussian blur.
    pub sigma_range: f64,
}

impl Bilateral {
    /// Validate.
    pub fn new(sigma_px: f64, sigma_range: f64) -> Result<Self, IspError> {
        if !(sigma_px > 0.0 && sigma_px <= 20.0) {
            return Err(IspError::InvalidParameter {
                name: "denoise.sigma_px".into(),
                value: format!("{sigma_px}"),
                reason: "must be in (0, 20]".into(),
            });
        }
        if !(sigma_range > 0.0) {
            return Err(IspError::InvalidParameter {
                name: "denoise.sigma_range".into(),
                value: format!("{sigma_range}"),
                reason: "must be positive (infinity for a Gaussian blur)".into(),
            });
        }
        Ok(Bilateral {
            sigma_px,
            sigma_range,
        })
    }

    /// Filter every plane in place.
    pub fn apply(&self, img: &mut ChannelPlanes) {
        let rad = (2.0 * self.sigma_px).ceil() as isize;
        let (rows, cols) = (img.rows, img.cols);
        let ws: Vec<f64> = (-rad..=rad)
            .flat_map(|dr| {
                (-rad..=rad).map(move |dc| {
                    (-((dr * dr + dc * dc) as f64) / (2.0 * self.sigma_px * self.sigma_px)).exp()
                })
            })
            .collect();
        let inv2r = if self.sigma_range.is_finite() {
            1.0 / (2.0 * self.sigma_range * self.sigma_range)
        } else {
            0.0
        };
        let mirror = |i: isize, n: usize| -> usize {
            if n == 1 {
                return 0;
            }
            let p = 2 * (n as isize - 1);
            let m = i.rem_euclid(p);
            if m < n as isize {
                m as usize
            } else {
                (p - m) as usize
            }
        };
        for plane in img.planes.iter_mut() {
            let src = plane.clone();
            plane.par_chunks_mut(cols).enumerate().for_each(|(r, row)| {
                for (c, o) in row.iter_mut().enumerate() {
                    let x0 = src[r * cols + c] as f64;
                    let (mut num, mut den) = (0.0, 0.0);
                    let mut t = 0;
                    for dr in -rad..=rad {
                        let rr = mirror(r as isize + dr, rows);
                        for dc in -rad..=rad {
                            let cc = mirror(c as isize + dc, cols);
                            let x = src[rr * cols + cc] as f64;
                            let w = ws[t] * (-(x - x0) * (x - x0) * inv2r).exp();
                            t += 1;
                            num += w * x;
                            den += w;
                        }
                    }
                    *o = (num / den) as f32;
                }
            });
        }
    }
}
