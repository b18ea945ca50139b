//! Light-field (plenoptic) camera: a microlens array in front of the sensor behind a main lens
//! (Ng et al., "Light field photography with a hand-held plenoptic camera", Stanford CTSR
//! 2005-02; Ng 2006), producing the raw light-field **sensor irradiance**, plus sub-aperture
//! views and shift-and-add refocusing of the raw image.
//!
//! ## Geometry (camera space, metres; the main lens at z = 0, looking down −Z)
//! * Main lens: a thin lens (focal length F, F-number N, aperture radius A = F/2N) or a
//!   `camsim-lens` prescription traced exactly (see [`super::real_lens`]), focused at
//!   `focus_distance_m`: the microlens array (MLA) sits in the focused image plane, a distance
//!   b behind the lens (thin lens: 1/b = 1/F − 1/D).
//! * MLA: square grid of square thin microlenses of pitch p_μ and focal length f_μ; the sensor
//!   lies `spacing` s behind it (s = f_μ for the classic plenoptic camera). Each microlens k
//!   covers a cell of `pixels_per_microlens` n × n sensor pixels; the cells are centred on the
//!   chief rays through the main lens's exit pupil (distance b_xp in front of the MLA):
//!   c'_k = c_k (b_xp + s)/b_xp, so the sensor pixel pitch is p = p_μ (b_xp + s)/(n b_xp).
//!   The film is `width × height` pixels, multiples of n. Pixels see only through their own
//!   microlens (baffled cells, no crosstalk).
//! * Film pixel (i, j) → sensor point x = −(i − W/2)·p, y = (j − H/2)·p, as for the real-lens
//!   camera (the raw image is presented upright).
//!
//! ## Estimator
//! A sample picks a point m uniformly on its microlens (pdf 1/p_μ²) and traces sensor → m →
//! microlens → main lens (thin: aperture test; prescription: exact trace) → scene. Sensor
//! irradiance E = ∫ L cos⁴θ / s² dA_m, so the weight is cos⁴θ·p_μ²/s² (0 when vignetted).
//! The microlenses are *aplanatic* thin lenses: a ray through the point h of a microlens of
//! focal length f changes its transverse direction cosines by −h/f. This shear of phase space
//! conserves étendue, hence the flux that reaches each cell, exactly (the slope form
//! σ' = σ + h/f does not: it loses about 2 % at f/4), and is the ideal thin lens to first
//! order. The thin main lens is the ideal imaging lens (slopes σ' = σ + x_L/F, Mitsuba's
//! thinlens): the flux through a microlens depends only on the straight image-side rays from
//! the aperture, so it is not affected, and planes are imaged perfectly.
//!
//! ## Views and refocusing (s = f_μ)
//! Pixel (u, v) of every cell sees (nearly) one position of the main-lens aperture
//! U = −b·δ/f_μ (δ: the pixel's offset from its cell centre): the sub-aperture view (u, v) is
//! the (W/n)×(H/n) image made of that pixel of every cell. A point at depth z moves between
//! neighbouring views by D(z) = −b (1/z − 1/D)(b + s)/(n f_μ) view pixels (thin lens; derived
//! from the MLA crossing of the ray through U towards the point's image); shift-and-add
//! refocusing at depth z samples view (u, v) at (i + D(z)(u − u_c), j + D(z)(v − v_c)) and
//! averages (Ng 2005, Eq. 2 discretised).
use super::real_lens::{FilmSize, RealLensCamera, RealLensError, RealLensOptions};
use super::{Camera, CameraRay, OutputQuantity};
use camsim_lens::{GlassCatalog, LensPrescription};
use glam::{Vec2, Vec3};
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// The main lens of a [`LightFieldCamera`].
#[derive(Debug, Clone)]
pub enum MainLens {
    /// Ideal thin lens.
    Thin {
        /// Focal length (mm).
        focal_length_mm: f64,
        /// F-number (aperture radius F/2N).
        f_number: f64,
    },
    /// A traced prescription (its sensor plane is the MLA).
    Prescription(Box<RealLensCamera>),
}

/// `main_lens` of the configuration: `{"thin": {"focal_length_mm": 50, "f_number": 4}}` or
/// `{"prescription": "lens.json", "f_number": 4}` (F-number optional).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MainLensConfig {
    /// Thin-lens parameters.
    #[serde(default)]
    pub thin: Option<ThinMainLens>,
    /// Prescription file (relative to the config file).
    #[serde(default)]
    pub prescription: Option<PathBuf>,
    /// Stop-down of the prescription.
    #[serde(default)]
    pub f_number: Option<f64>,
}

/// Thin main lens.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ThinMainLens {
    /// Focal length (mm).
    pub focal_length_mm: f64,
    /// F-number.
    pub f_number: f64,
}

/// The `lightfield:CONFIG` JSON.
///
/// ```json
/// {"main_lens": {"thin": {"focal_length_mm": 50, "f_number": 4}},
///  "focus_distance_m": 2.0,
///  "microlens_pitch_um": 100, "microlens_focal_length_um": 410,
///  "microlens_spacing_um": 410,          // optional, default = focal length
///  "pixels_per_microlens": 9}
/// ```
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LightFieldConfig {
    /// Main lens.
    pub main_lens: MainLensConfig,
    /// Distance of the plane conjugate to the MLA (m, from the main lens / entrance pupil).
    pub focus_distance_m: f64,
    /// Microlens pitch (µm).
    pub microlens_pitch_um: f64,
    /// Microlens focal length (µm).
    pub microlens_focal_length_um: f64,
    /// MLA → sensor distance (µm); default the focal length.
    #[serde(default)]
    pub microlens_spacing_um: Option<f64>,
    /// Sensor pixels per microlens along each axis.
    pub pixels_per_microlens: u32,
}

/// First-order facts of a configured light-field camera.
#[derive(Debug, Clone, PartialEq)]
pub struct LightFieldInfo {
    /// Main lens → MLA (mm; for a prescription: last vertex → MLA).
    pub mla_distance_mm: f64,
    /// Exit pupil → MLA (mm), the distance used to centre the cells.
    pub exit_pupil_to_mla_mm: f64,
    /// Microlens pitch (mm).
    pub microlens_pitch_mm: f64,
    /// Microlens focal length (mm).
    pub microlens_focal_mm: f64,
    /// MLA → sensor (mm).
    pub spacing_mm: f64,
    /// Sensor pixel pitch (mm).
    pub pixel_pitch_mm: f64,
    /// Pixels per microlens (per axis).
    pub n: u32,
    /// Microlenses (x, y).
    pub microlenses: (u32, u32),
    /// Focus distance (m).
    pub focus_distance_m: f64,
    /// Thin main lens focal length (mm), `None` for a prescription.
    pub thin_focal_mm: Option<f64>,
}

/// The light-field camera (see the module docs).
#[derive(Debug, Clone)]
pub struct LightFieldCamera {
    width_px: u32,
    height_px: u32,
    main: MainLens,
    info: LightFieldInfo,
    /// Thin lens: aperture radius (mm).
    aperture_mm: f64,
}

impl LightFieldCamera {
    /// Build a light-field camera with a `width_px` × `height_px` raw sensor.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        main: MainLens,
        focus_distance_m: f64,
        microlens_pitch_um: f64,
        microlens_focal_length_um: f64,
        microlens_spacing_um: Option<f64>,
        pixels_per_microlens: u32,
        width_px: u32,
        height_px: u32,
    ) -> Result<Self, RealLensError> {
        let bad = |m: String| RealLensError::Config(format!("light-field camera: {m}"));
        let pos = |name: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(v)
            } else {
                Err(bad(format!("{name} = {v} must be > 0")))
            }
        };
        let p_mu = pos("microlens_pitch_um", microlens_pitch_um)? * 1e-3;
        let f_mu = pos("microlens_focal_length_um", microlens_focal_length_um)? * 1e-3;
        let s = pos(
            "microlens_spacing_um",
            microlens_spacing_um.unwrap_or(microlens_focal_length_um),
        )? * 1e-3;
        let n = pixels_per_microlens;
        if n == 0 {
            return Err(bad("pixels_per_microlens must be ≥ 1".into()));
        }
        if width_px == 0 || height_px == 0 || width_px % n != 0 || height_px % n != 0 {
            return Err(bad(format!(
                "the film {width_px}×{height_px} px must be a non-empty multiple of \
                 pixels_per_microlens = {n}"
            )));
        }
        let d_m = pos("focus_distance_m", focus_distance_m)?;
        let (b, b_xp, aperture_mm, thin_focal) = match &main {
            MainLens::Thin {
                focal_length_mm,
                f_number,
            } => {
                let f = pos("main_lens.thin.focal_length_mm", *focal_length_mm)?;
                let nf = pos("main_lens.thin.f_number", *f_number)?;
                let dmm = d_m * 1e3;
                if dmm <= f {
                    return Err(bad(format!(
                        "focus_distance_m = {d_m} must exceed the focal length {f} mm"
                    )));
                }
                let b = 1.0 / (1.0 / f - 1.0 / dmm);
                (b, b, f / (2.0 * nf), Some(f))
            }
            MainLens::Prescription(cam) => (
                cam.info().image_distance_mm,
                cam.exit_pupil_to_sensor_mm(),
                0.0,
                None,
            ),
        };
        if !(b_xp > 0.0) {
            return Err(bad(format!(
                "the exit pupil lies behind the microlens array ({b_xp} mm)"
            )));
        }
        let pixel_pitch_mm = p_mu * (b_xp + s) / (n as f64 * b_xp);
        let info = LightFieldInfo {
            mla_distance_mm: b,
            exit_pupil_to_mla_mm: b_xp,
            microlens_pitch_mm: p_mu,
            microlens_focal_mm: f_mu,
            spacing_mm: s,
            pixel_pitch_mm,
            n,
            microlenses: (width_px / n, height_px / n),
            focus_distance_m: d_m,
            thin_focal_mm: thin_focal,
        };
        Ok(LightFieldCamera {
            width_px,
            height_px,
            main,
            info,
            aperture_mm,
        })
    }

    /// Build from a `lightfield:CONFIG` file (see [`LightFieldConfig`]).
    pub fn from_file(path: &Path, width_px: u32, height_px: u32) -> Result<Self, RealLensError> {
        let file_err = |msg: String| RealLensError::File {
            path: path.display().to_string(),
            msg,
        };
        let text = std::fs::read_to_string(path).map_err(|e| file_err(e.to_string()))?;
        let cfg: LightFieldConfig =
            serde_json::from_str(&text).map_err(|e| file_err(e.to_string()))?;
        let main = match (&cfg.main_lens.thin, &cfg.main_lens.prescription) {
            (Some(t), None) => {
                if cfg.main_lens.f_number.is_some() {
                    return Err(file_err(
                        "main_lens.f_number applies to a prescription; give thin.f_number".into(),
                    ));
                }
                MainLens::Thin {
                    focal_length_mm: t.focal_length_mm,
                    f_number: t.f_number,
                }
            }
            (None, Some(p)) => {
                let lp = path.parent().unwrap_or(Path::new(".")).join(p);
                let lens = LensPrescription::from_json_file(&lp, &GlassCatalog::bundled())
                    .map_err(|e| file_err(format!("main_lens.prescription: {e}")))?;
                MainLens::Prescription(Box::new(
                    Self::prescription_main_lens(
                        &lens,
                        cfg.focus_distance_m,
                        cfg.main_lens.f_number,
                        cfg.microlens_pitch_um,
                    )
                    .map_err(|e| file_err(e.to_string()))?,
                ))
            }
            _ => {
                return Err(file_err(
                    "main_lens must have exactly one of \"thin\" and \"prescription\"".into(),
                ))
            }
        };
        Self::new(
            main,
            cfg.focus_distance_m,
            cfg.microlens_pitch_um,
            cfg.microlens_focal_length_um,
            cfg.microlens_spacing_um,
            cfg.pixels_per_microlens,
            width_px,
            height_px,
        )
        .map_err(|e| file_err(e.to_string()))
    }

    /// A prescription main lens focused at `focus_distance_m` (its sensor plane = the MLA) by
    /// the focus model (`camsim_lens::focus_model`, default method): best polychromatic MTF on
    /// axis up to half the Nyquist frequency of the microlens grid, 1/(4 p_μ).
    pub fn prescription_main_lens(
        lens: &LensPrescription,
        focus_distance_m: f64,
        f_number: Option<f64>,
        microlens_pitch_um: f64,
    ) -> Result<RealLensCamera, RealLensError> {
        // Only the tracer is used: a one-pixel film (one microlens) keeps the exit-pupil table
        // trivial.
        RealLensCamera::new(
            lens,
            1,
            1,
            &RealLensOptions {
                focus_distance_m: Some(focus_distance_m),
                f_number,
                film: FilmSize::PixelPitchUm(microlens_pitch_um),
                pupil_bins: 1,
                pupil_grid: 8,
                ..Default::default()
            },
        )
    }

    /// First-order facts.
    pub fn info(&self) -> &LightFieldInfo {
        &self.info
    }

    /// Sensor point (mm) of a film position (px).
    pub fn film_mm(&self, film_px: Vec2) -> [f64; 2] {
        let p = self.info.pixel_pitch_mm;
        [
            -(film_px.x as f64 - 0.5 * self.width_px as f64) * p,
            (film_px.y as f64 - 0.5 * self.height_px as f64) * p,
        ]
    }

    /// Centre (mm, MLA plane) of the microlens covering film position `film_px`.
    pub fn microlens_centre_mm(&self, film_px: Vec2) -> Option<[f64; 2]> {
        let n = self.info.n as f64;
        let (kx, ky) = (
            (film_px.x as f64 / n).floor(),
            (film_px.y as f64 / n).floor(),
        );
        let (mx, my) = (
            self.info.microlenses.0 as f64,
            self.info.microlenses.1 as f64,
        );
        if kx < 0.0 || ky < 0.0 || kx >= mx || ky >= my {
            return None;
        }
        let p = self.info.microlens_pitch_mm;
        Some([-(kx + 0.5 - 0.5 * mx) * p, (ky + 0.5 - 0.5 * my) * p])
    }

    /// Trace one sample: sensor point → microlens point (u ∈ [0,1)²) → main lens → scene.
    /// Returns the irradiance weight and the camera-space ray, `None` when vignetted.
    pub fn sample(
        &self,
        film_px: Vec2,
        u: [f64; 2],
        wavelength_nm: f64,
    ) -> Option<(f64, Vec3, Vec3)> {
        let i = &self.info;
        let sp = self.film_mm(film_px);
        let c = self.microlens_centre_mm(film_px)?;
        let m = [
            c[0] + (u[0] - 0.5) * i.microlens_pitch_mm,
            c[1] + (u[1] - 0.5) * i.microlens_pitch_mm,
        ];
        let s = i.spacing_mm;
        let (dx, dy) = (m[0] - sp[0], m[1] - sp[1]);
        let cos2 = s * s / (dx * dx + dy * dy + s * s);
        let w = cos2 * cos2 * i.microlens_pitch_mm * i.microlens_pitch_mm / (s * s);
        // Direction of travel (towards the scene, −z) from the sensor point to m; the
        // microlens refracts it as an aplanatic thin lens: transverse direction cosines
        // q' = q − (m − c)/f_μ (a shear of (position, direction cosine) phase space, so
        // étendue and radiance are conserved; paraxially the ideal thin lens).
        let l = (dx * dx + dy * dy + s * s).sqrt();
        let (qx, qy) = thin_lens_cosines(
            dx / l,
            dy / l,
            m[0] - c[0],
            m[1] - c[1],
            i.microlens_focal_mm,
        )?;
        let qz = (1.0 - qx * qx - qy * qy).sqrt();
        match &self.main {
            MainLens::Thin {
                focal_length_mm, ..
            } => {
                let b = i.mla_distance_mm;
                let t = b / qz;
                let xl = m[0] + qx * t;
                let yl = m[1] + qy * t;
                if xl * xl + yl * yl > self.aperture_mm * self.aperture_mm {
                    return None;
                }
                // ideal thin lens (perfect imaging of planes, as Mitsuba's thinlens): slopes
                // dx/dz change by the height over the focal length, σ' = σ + x_L/F
                let (ox, oy) = (
                    -qx / qz + xl / focal_length_mm,
                    -qy / qz + yl / focal_length_mm,
                );
                let o = Vec3::new((xl * 1e-3) as f32, (yl * 1e-3) as f32, 0.0);
                let d = Vec3::new(-ox as f32, -oy as f32, -1.0).normalize();
                Some((w, o, d))
            }
            MainLens::Prescription(cam) => {
                // mirrored frame of the lens: same x, y; z' towards the object
                let exit = cam.trace_from_sensor([m[0], m[1], 0.0], [qx, qy, qz], wavelength_nm)?;
                let (o, d) = cam.to_camera(&exit);
                Some((w, o, d))
            }
        }
    }

    /// Disparity between neighbouring sub-aperture views (view pixels per view step) of a
    /// point at depth `z_m` (thin main lens, s = f_μ; see the module docs).
    pub fn disparity_per_view(&self, z_m: f64) -> f64 {
        let i = &self.info;
        let b = i.mla_distance_mm;
        -b * (1.0 / (z_m * 1e3) - 1.0 / (i.focus_distance_m * 1e3)) * (b + i.spacing_mm)
            / (i.n as f64 * i.microlens_focal_mm)
    }

    /// Sub-aperture views of a raw image (`width × height`, row-major): n² views, view
    /// (u, v) at index v·n + u, each (width/n) × (height/n).
    pub fn sub_aperture_views(&self, raw: &[f32]) -> Vec<Vec<f32>> {
        sub_aperture_views(
            raw,
            self.width_px as usize,
            self.height_px as usize,
            self.info.n as usize,
        )
    }
}

/// Aplanatic thin lens of focal length `f_mm`: a ray crossing it at (hx, hy) mm from its
/// centre, travelling away from the sensor with transverse direction cosines (qx, qy), leaves
/// with (qx − hx/f, qy − hy/f); `None` past grazing.
#[inline]
fn thin_lens_cosines(qx: f64, qy: f64, hx: f64, hy: f64, f_mm: f64) -> Option<(f64, f64)> {
    let (ox, oy) = (qx - hx / f_mm, qy - hy / f_mm);
    (ox * ox + oy * oy < 1.0).then_some((ox, oy))
}

/// Sub-aperture views of a raw plenoptic image of `width × height` pixels with cells of
/// n × n pixels: view (u, v) (index v·n + u) holds pixel (u, v) of every cell.
pub fn sub_aperture_views(raw: &[f32], width: usize, height: usize, n: usize) -> Vec<Vec<f32>> {
    let (vw, vh) = (width / n, height / n);
    let mut views = vec![vec![0f32; vw * vh]; n * n];
    for v in 0..n {
        for u in 0..n {
            let view = &mut views[v * n + u];
            for j in 0..vh {
                for i in 0..vw {
                    view[j * vw + i] = raw[(j * n + v) * width + i * n + u];
                }
            }
        }
    }
    views
}

/// Shift-and-add refocusing: the mean over views (u, v) of view(u, v) sampled bilinearly
/// (edge-clamped) at (i + shift·(u − u_c), j + shift·(v − v_c)), u_c = v_c = (n − 1)/2.
/// `shift` = [`LightFieldCamera::disparity_per_view`] of the depth to bring into focus.
pub fn refocus(views: &[Vec<f32>], n: usize, vw: usize, vh: usize, shift: f64) -> Vec<f32> {
    let mut out = vec![0f64; vw * vh];
    let c = (n as f64 - 1.0) / 2.0;
    let at = |img: &[f32], x: f64, y: f64| -> f64 {
        let x = x.clamp(0.0, (vw - 1) as f64);
        let y = y.clamp(0.0, (vh - 1) as f64);
        let (x0, y0) = (x.floor() as usize, y.floor() as usize);
        let (x1, y1) = ((x0 + 1).min(vw - 1), (y0 + 1).min(vh - 1));
        let (tx, ty) = (x - x0 as f64, y - y0 as f64);
        let g = |xx: usize, yy: usize| img[yy * vw + xx] as f64;
        g(x0, y0) * (1.0 - tx) * (1.0 - ty)
            + g(x1, y0) * tx * (1.0 - ty)
            + g(x0, y1) * (1.0 - tx) * ty
            + g(x1, y1) * tx * ty
    };
    for v in 0..n {
        for u in 0..n {
            let img = &views[v * n + u];
            let (ox, oy) = (shift * (u as f64 - c), shift * (v as f64 - c));
            for j in 0..vh {
                for i in 0..vw {
                    out[j * vw + i] += at(img, i as f64 + ox, j as f64 + oy);
                }
            }
        }
    }
    let k = 1.0 / (n * n) as f64;
    out.into_iter().map(|v| (v * k) as f32).collect()
}

impl Camera for LightFieldCamera {
    fn film_size_px(&self) -> (u32, u32) {
        (self.width_px, self.height_px)
    }

    fn output_quantity(&self) -> OutputQuantity {
        OutputQuantity::SensorIrradiance
    }

    fn generate_ray(
        &self,
        film_px: Vec2,
        lens_uv: Vec2,
        wavelengths_nm: &[f32; 4],
    ) -> Option<CameraRay> {
        let (w, origin_m, direction) = self.sample(
            film_px,
            [lens_uv.x as f64, lens_uv.y as f64],
            wavelengths_nm[0] as f64,
        )?;
        let dispersive = matches!(self.main, MainLens::Prescription(_));
        Some(CameraRay {
            origin_m,
            direction,
            weight: if dispersive {
                [w as f32, 0.0, 0.0, 0.0]
            } else {
                [w as f32; 4]
            },
            wavelength_dependent: dispersive,
        })
    }

    fn center_ray(&self, film_px: Vec2) -> Option<CameraRay> {
        // the ray through the centre of the pixel's microlens
        let (_, origin_m, direction) = self.sample(film_px, [0.5, 0.5], 587.6)?;
        Some(CameraRay {
            origin_m,
            direction,
            weight: [1.0; 4],
            wavelength_dependent: false,
        })
    }
}
