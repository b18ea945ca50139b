//! Real-lens camera: camera rays traced from the sensor through a `camsim-lens` prescription
//! (exact rays in f64, spheres/conics/even aspheres, vector Snell law, clipping at the clear
//! semi-diameters, dispersion n(λ) of every glass), producing **sensor irradiance**.
//!
//! ## Method
//! * **Frames.** The lens frame of `camsim-lens` has its first vertex at z = 0 and light going
//!   towards +z; the sensor is the image plane z_img (last vertex + last thickness). Rays are
//!   traced from the sensor in the *mirrored* frame z' = z_img − z (sensor at z' = 0, the
//!   surfaces in reverse order with negated curvature and aspheric coefficients), so every
//!   trace step is a forward step of the crate's own `intersect`/`normal`/`refract`. The camera
//!   frame (glTF: looking down −Z, +Y up) has its origin at the paraxial **entrance pupil**, so
//!   the perspective agrees with a pinhole camera at the same node; Z = (z − z_ep)·10⁻³ m.
//! * **Image orientation.** The lens inverts the image; film pixel (i, j) is mapped to the
//!   sensor point x = −(i − W/2)·p, y = (j − H/2)·p, so the output image is upright like a
//!   pinhole camera's (pixel (0,0) top-left).
//! * **Focus** by the focus model (`camsim_lens::focus_model`) on an object at the focus
//!   distance (measured from the entrance pupil): by default the lens moves as a unit to the
//!   best polychromatic MTF up to half the pixel Nyquist frequency over the film's field
//!   (`RealLensOptions::focus_method`; `paraxial` = the paraxial image at the primary
//!   wavelength; a focusing group moves its surfaces instead). The aperture stop's clear radius is set to the paraxial stop radius that the
//!   prescription's aperture (or an `f_number` override) implies.
//! * **Exit-pupil bounds, sensor-side trace and chief rays** come from the lens crate
//!   (`camsim_lens::pupil`: [`SensorSideLens`], [`ExitPupilTable`], in the manner of pbrt-v4's
//!   RealisticCamera and its `ExitPupilSample`); a film point samples the rear-plane box of its
//!   film radius, rotated to its azimuth.
//! * **Estimator.** Irradiance from radiance L through the rear plane at distance d from the
//!   sensor, both planes perpendicular to the axis (cos θ_film = cos θ_plane = d/|q − p|):
//!   E(p) = ∫ L cos⁴θ / d² dA_q. With q uniform on the box (pdf 1/A) the weight of one ray
//!   is w = cos⁴θ·A/d² (sr), 0 when the ray is vignetted, totally reflected or misses a
//!   surface. Fresnel losses and glass absorption are not modelled (T = 1).
//! * **Dispersion.** The ray is traced at the hero wavelength only; `wavelength_dependent` is
//!   true and the secondary weights are 0 (the integrator terminates the secondaries).
//! * **Centre ray** (depth channel): the chief ray, through the centre of the stop at the
//!   primary wavelength ([`ExitPupilTable::chief_aim`]).
use super::{Camera, CameraRay, OutputQuantity};
use camsim_lens::prescription::{Aperture, Medium};
use camsim_lens::pupil::{ExitPupilOptions, ExitPupilTable, SensorSideLens};
pub use camsim_lens::pupil::{PupilBounds, SensorExit as LensExit};
use camsim_lens::{
    Clipping, FocusMethod, FocusSpec, FocusedLens, GlassCatalog, LensError, LensPrescription,
};
use glam::{Vec2, Vec3};
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// Errors building a real-lens camera.
#[derive(Debug, thiserror::Error)]
pub enum RealLensError {
    /// The lens crate rejected the prescription or a paraxial computation failed.
    #[error("lens: {0}")]
    Lens(#[from] LensError),
    /// A configuration value is out of range.
    #[error("real-lens camera: {0}")]
    Config(String),
    /// A configuration file could not be read or parsed.
    #[error("real-lens camera config {path}: {msg}")]
    File {
        /// The file.
        path: String,
        /// What went wrong.
        msg: String,
    },
}

/// How the film (sensor) size is chosen.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FilmSize {
    /// Sensor pixel pitch (µm).
    PixelPitchUm(f64),
    /// The paraxial image of this full vertical field of view (radians) fills the film height
    /// (so the camera sees what a pinhole camera with this `yfov` sees, up to distortion).
    VerticalFovRad(f64),
}

/// Options of [`RealLensCamera::new`].
#[derive(Debug, Clone, PartialEq)]
pub struct RealLensOptions {
    /// Focus distance from the entrance pupil (m); `None` = infinity.
    pub focus_distance_m: Option<f64>,
    /// Stop the lens to this infinite-conjugate F-number (`None` = the prescription's aperture).
    pub f_number: Option<f64>,
    /// Film size.
    pub film: FilmSize,
    /// Film-radius intervals of the exit-pupil table (default 32).
    pub pupil_bins: usize,
    /// Fine grid per side for the exit-pupil bounds (default 64; the coarse grid is half of it).
    pub pupil_grid: usize,
    /// Shortest and longest wavelength the pupil bounds must cover (nm).
    pub wavelength_range_nm: (f64, f64),
    /// How the lens is focused (`camsim_lens::focus_model`); an unset merit frequency is half
    /// the pixel Nyquist frequency, 1/(4p), and an unset merit field the film's half-diagonal.
    pub focus_method: FocusMethod,
}

impl Default for RealLensOptions {
    fn default() -> Self {
        RealLensOptions {
            focus_distance_m: None,
            f_number: None,
            film: FilmSize::VerticalFovRad(40f64.to_radians()),
            pupil_bins: 32,
            pupil_grid: 64,
            wavelength_range_nm: (360.0, 830.0),
            focus_method: FocusMethod::default(),
        }
    }
}

/// The `lens:FILE` camera configuration (JSON). `FILE` may also be a plain prescription
/// (recognised by its `surfaces` key), which means `{"lens": FILE}`.
///
/// ```json
/// {"lens": "../lenses/double_gauss_50mm_f2.json",   // relative to this file
///  "focus_distance_m": 2.5,          // optional; default: the scene camera's extras.thinlens
///                                    // focus_distance, else infinity
///  "f_number": 4.0,                  // optional stop-down
///  "pixel_pitch_um": 5.0,            // optional; default: film fits the glTF camera's yfov
///  "pupil_bins": 32, "pupil_grid": 64,
///  "focus_criterion": "best",        // optional: "best" (default) or "paraxial"
///  "focus_frequency_cyc_per_mm": 60, // optional; default half the pixel Nyquist 1/(4p)
///  "focus_group_surfaces": [6, 10]}  // optional; default the lens moves as a unit
/// ```
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RealLensConfig {
    /// Prescription file (relative paths are relative to the config file).
    pub lens: PathBuf,
    /// Focus distance from the entrance pupil (m).
    #[serde(default)]
    pub focus_distance_m: Option<f64>,
    /// F-number override.
    #[serde(default)]
    pub f_number: Option<f64>,
    /// Sensor pixel pitch (µm).
    #[serde(default)]
    pub pixel_pitch_um: Option<f64>,
    /// Exit-pupil table intervals.
    #[serde(default)]
    pub pupil_bins: Option<usize>,
    /// Exit-pupil grid per side.
    #[serde(default)]
    pub pupil_grid: Option<usize>,
    /// Focus criterion: `"best"` (default) or `"paraxial"` (`camsim_lens::focus_model`).
    #[serde(default)]
    pub focus_criterion: Option<String>,
    /// Merit frequency of the best focus (cycles/mm; default half the pixel Nyquist).
    #[serde(default)]
    pub focus_frequency_cyc_per_mm: Option<f64>,
    /// Focusing group `[first, last]` (surface indices; default: the lens moves as a unit).
    #[serde(default)]
    pub focus_group_surfaces: Option<[usize; 2]>,
}

/// First-order facts about the configured camera (for reports and tests).
#[derive(Debug, Clone, PartialEq)]
pub struct RealLensInfo {
    /// Lens name.
    pub lens_name: String,
    /// Effective focal length at the primary wavelength (mm).
    pub efl_mm: f64,
    /// Infinite-conjugate F-number of the configured aperture.
    pub f_number: f64,
    /// Working F-number at the focus distance.
    pub working_f_number: f64,
    /// Last vertex → sensor (mm).
    pub image_distance_mm: f64,
    /// Entrance pupil z in the lens frame (mm from the first vertex).
    pub entrance_pupil_z_mm: f64,
    /// Entrance-pupil diameter (mm).
    pub entrance_pupil_diameter_mm: f64,
    /// Exit pupil z in the lens frame (mm).
    pub exit_pupil_z_mm: f64,
    /// Sensor pixel pitch (mm).
    pub pixel_pitch_mm: f64,
    /// Object distance from the first vertex (mm), `None` = infinity.
    pub object_distance_mm: Option<f64>,
    /// Primary wavelength (nm).
    pub primary_nm: f64,
    /// Rear-vertex plane → sensor distance (mm).
    pub rear_plane_mm: f64,
    /// How the lens was focused (focus model).
    pub focus: FocusedLens,
}

/// The real-lens camera (see the module docs).
#[derive(Debug, Clone)]
pub struct RealLensCamera {
    width_px: u32,
    height_px: u32,
    pixel_pitch_mm: f64,
    /// The lens as traced from the sensor.
    lens: SensorSideLens,
    /// Exit-pupil bounds and chief rays by film radius.
    pupil: ExitPupilTable,
    /// Entrance pupil z in the lens frame (mm).
    z_ep_mm: f64,
    info: RealLensInfo,
}

impl RealLensCamera {
    /// Build the camera for `lens` (validated prescription) and a `width_px` × `height_px` film.
    pub fn new(
        lens: &LensPrescription,
        width_px: u32,
        height_px: u32,
        opts: &RealLensOptions,
    ) -> Result<Self, RealLensError> {
        let cfg = |m: String| RealLensError::Config(m);
        if width_px == 0 || height_px == 0 {
            return Err(cfg(format!("film {width_px}×{height_px} px is empty")));
        }
        if opts.pupil_bins == 0 || opts.pupil_grid < 8 {
            return Err(cfg(format!(
                "pupil_bins = {} must be ≥ 1 and pupil_grid = {} ≥ 8",
                opts.pupil_bins, opts.pupil_grid
            )));
        }
        if lens.has_folds() {
            return Err(cfg(format!(
                "lens '{}': mirrors and coordinate breaks are not supported by the real-lens \
                 camera",
                lens.name
            )));
        }
        let ns = lens.surfaces.len();
        if !matches!(lens.surfaces[ns - 1].medium, Medium::Air) {
            return Err(cfg(format!(
                "lens '{}': the image space (medium after the last surface) must be air",
                lens.name
            )));
        }
        let mut lens = lens.clone();
        if let Some(n) = opts.f_number {
            if !(n.is_finite() && n > 0.0) {
                return Err(cfg(format!("f_number = {n} must be > 0")));
            }
            lens.aperture = Aperture::FNumber(n);
        }
        let fo_inf = lens.first_order(lens.primary_nm)?;
        let z_ep_mm = fo_inf.entrance_pupil_z_mm;
        let object_distance_mm = match opts.focus_distance_m {
            None => None,
            Some(d) => {
                let od = d * 1e3 - z_ep_mm;
                if !(d.is_finite() && od > 0.0) {
                    return Err(cfg(format!(
                        "focus_distance_m = {d} must lie in front of the lens (> {:.4} m from \
                         the entrance pupil)",
                        z_ep_mm.max(0.0) * 1e-3
                    )));
                }
                Some(od)
            }
        };
        // Focus by the focus model; its merit frequency (half the pixel Nyquist) and field (the
        // film half-diagonal) are estimated on the paraxially focused lens.
        let paraxial = lens.focus_at(object_distance_mm)?;
        let per_tan_mm = paraxial.paraxial_image_mm_per_tan(lens.primary_nm)?;
        let pitch_est_mm = match opts.film {
            FilmSize::PixelPitchUm(p) => p * 1e-3,
            FilmSize::VerticalFovRad(fov) => {
                2.0 * per_tan_mm * (fov / 2.0).tan() / height_px as f64
            }
        };
        let mut method = opts.focus_method.clone();
        if pitch_est_mm.is_finite() && pitch_est_mm > 0.0 {
            method.frequency_cyc_per_mm = method.frequency_cyc_per_mm.or(Some(0.25 / pitch_est_mm));
            let r_mm = 0.5 * (width_px as f64).hypot(height_px as f64) * pitch_est_mm;
            method.max_field_deg = method
                .max_field_deg
                .or(Some((r_mm / per_tan_mm).atan().to_degrees()));
        }
        let focus = lens.focus(&FocusSpec {
            focus_distance_mm: object_distance_mm,
            method,
        })?;
        let mut lens = focus.lens.clone();
        let fo = lens.first_order(lens.primary_nm)?;
        if !(fo.paraxial_image_distance_mm.is_finite() && fo.paraxial_image_distance_mm > 0.0) {
            return Err(cfg(format!(
                "lens '{}' forms no real image of the focus distance (image distance {} mm)",
                lens.name, fo.paraxial_image_distance_mm
            )));
        }
        // The aperture stop's clear radius: the paraxial value the aperture spec implies.
        lens = lens.with_aperture_stop_clear()?;

        let pixel_pitch_mm = match opts.film {
            FilmSize::PixelPitchUm(p) => {
                if !(p.is_finite() && p > 0.0) {
                    return Err(cfg(format!("pixel_pitch_um = {p} must be > 0")));
                }
                p * 1e-3
            }
            FilmSize::VerticalFovRad(fov) => {
                if !(fov.is_finite() && fov > 0.0 && fov < std::f64::consts::PI) {
                    return Err(cfg(format!(
                        "vertical field of view {fov} rad out of (0, π)"
                    )));
                }
                let h = lens
                    .paraxial_chief_height_mm((fov / 2.0).to_degrees(), lens.primary_nm)?
                    .abs();
                2.0 * h / height_px as f64
            }
        };

        let side = SensorSideLens::new(&lens)?;
        let rear_z_mm = side.rear_plane_mm();
        let half_w = 0.5 * width_px as f64 * pixel_pitch_mm;
        let half_h = 0.5 * height_px as f64 * pixel_pitch_mm;
        let r_max_mm = half_w.hypot(half_h) * (1.0 + 1e-9);
        let max_sd = lens
            .surfaces
            .iter()
            .filter_map(|s| s.semi_diameter_mm)
            .fold(0.5 * fo.exit_pupil_diameter_mm.abs(), f64::max)
            .max(0.5 * fo.entrance_pupil_diameter_mm);
        let info = RealLensInfo {
            lens_name: lens.name.clone(),
            efl_mm: fo.efl_mm,
            f_number: fo.f_number,
            working_f_number: fo.working_f_number,
            image_distance_mm: rear_z_mm,
            entrance_pupil_z_mm: z_ep_mm,
            entrance_pupil_diameter_mm: fo.entrance_pupil_diameter_mm,
            exit_pupil_z_mm: fo.exit_pupil_z_mm,
            pixel_pitch_mm,
            object_distance_mm,
            primary_nm: lens.primary_nm,
            rear_plane_mm: rear_z_mm,
            focus,
        };
        let pupil = ExitPupilTable::new(
            &side,
            r_max_mm,
            &ExitPupilOptions {
                bins: opts.pupil_bins,
                grid: opts.pupil_grid,
                wavelengths_nm: [
                    opts.wavelength_range_nm.0,
                    lens.primary_nm,
                    opts.wavelength_range_nm.1,
                ],
                search_half_width_mm: 1.5 * max_sd,
                exit_pupil_to_image_mm: side.image_z_mm() - fo.exit_pupil_z_mm,
            },
        )?;
        Ok(RealLensCamera {
            width_px,
            height_px,
            pixel_pitch_mm,
            lens: side,
            pupil,
            z_ep_mm,
            info,
        })
    }

    /// Build from a `lens:FILE` argument: a [`RealLensConfig`] JSON or a plain prescription.
    /// `yfov_rad` (the scene camera's) sets the film size when the config gives no pixel
    /// pitch; `scene_focus_m` (the scene camera's thin-lens focus distance) is the default
    /// focus.
    pub fn from_file(
        path: &Path,
        width_px: u32,
        height_px: u32,
        yfov_rad: f64,
        scene_focus_m: Option<f64>,
    ) -> Result<Self, RealLensError> {
        let file_err = |msg: String| RealLensError::File {
            path: path.display().to_string(),
            msg,
        };
        let text = std::fs::read_to_string(path).map_err(|e| file_err(e.to_string()))?;
        let value: serde_json::Value =
            serde_json::from_str(&text).map_err(|e| file_err(e.to_string()))?;
        let catalog = GlassCatalog::bundled();
        let (lens, cfg) = if value.get("surfaces").is_some() {
            let lens = LensPrescription::from_json_str(&text, &catalog)
                .map_err(|e| file_err(e.to_string()))?;
            (
                lens,
                RealLensConfig {
                    lens: path.to_path_buf(),
                    focus_distance_m: None,
                    f_number: None,
                    pixel_pitch_um: None,
                    pupil_bins: None,
                    pupil_grid: None,
                    focus_criterion: None,
                    focus_frequency_cyc_per_mm: None,
                    focus_group_surfaces: None,
                },
            )
        } else {
            let cfg: RealLensConfig =
                serde_json::from_value(value).map_err(|e| file_err(e.to_string()))?;
            let lens_path = path.parent().unwrap_or(Path::new(".")).join(&cfg.lens);
            let lens = LensPrescription::from_json_file(&lens_path, &catalog)
                .map_err(|e| file_err(format!("key \"lens\": {e}")))?;
            (lens, cfg)
        };
        let d = RealLensOptions::default();
        let opts = RealLensOptions {
            focus_distance_m: cfg.focus_distance_m.or(scene_focus_m),
            f_number: cfg.f_number,
            film: match cfg.pixel_pitch_um {
                Some(p) => FilmSize::PixelPitchUm(p),
                None => FilmSize::VerticalFovRad(yfov_rad),
            },
            pupil_bins: cfg.pupil_bins.unwrap_or(d.pupil_bins),
            pupil_grid: cfg.pupil_grid.unwrap_or(d.pupil_grid),
            wavelength_range_nm: d.wavelength_range_nm,
            focus_method: FocusMethod::from_keys(
                cfg.focus_criterion.as_deref(),
                cfg.focus_frequency_cyc_per_mm,
                cfg.focus_group_surfaces,
            )
            .map_err(file_err)?,
        };
        Self::new(&lens, width_px, height_px, &opts).map_err(|e| file_err(e.to_string()))
    }

    /// First-order facts.
    pub fn info(&self) -> &RealLensInfo {
        &self.info
    }

    /// Paraxial exit pupil → sensor distance (mm).
    pub fn exit_pupil_to_sensor_mm(&self) -> f64 {
        self.lens.image_z_mm() - self.info.exit_pupil_z_mm
    }

    /// The exit-pupil table: film-radius interval width (mm) and the bounds per interval.
    pub fn pupil_table(&self) -> (f64, &[Option<PupilBounds>]) {
        self.pupil.bounds()
    }

    /// Sensor point (x, y) mm (lens frame) of a continuous film position in pixels.
    pub fn film_mm(&self, film_px: Vec2) -> [f64; 2] {
        [
            -(film_px.x as f64 - 0.5 * self.width_px as f64) * self.pixel_pitch_mm,
            (film_px.y as f64 - 0.5 * self.height_px as f64) * self.pixel_pitch_mm,
        ]
    }

    /// Continuous film position (pixels) of a sensor point (x, y) mm.
    pub fn film_px(&self, sensor_mm: [f64; 2]) -> Vec2 {
        Vec2::new(
            (0.5 * self.width_px as f64 - sensor_mm[0] / self.pixel_pitch_mm) as f32,
            (0.5 * self.height_px as f64 + sensor_mm[1] / self.pixel_pitch_mm) as f32,
        )
    }

    /// Trace a ray from the sensor side (mirrored frame) through the lens at `wavelength_nm`.
    /// `None` if it misses a surface, is totally reflected, steps backwards or is vignetted.
    pub fn trace_from_sensor(
        &self,
        origin_mm: [f64; 3],
        direction: [f64; 3],
        wavelength_nm: f64,
    ) -> Option<LensExit> {
        self.lens
            .trace(origin_mm, direction, wavelength_nm, Clipping::SemiDiameters)
    }

    /// Trace from sensor point `p` (mm) towards rear-plane point `q` (mm).
    pub fn trace_through(&self, p: [f64; 2], q: [f64; 2], wavelength_nm: f64) -> Option<LensExit> {
        self.lens
            .trace_through(p, q, wavelength_nm, Clipping::SemiDiameters)
    }

    /// Convert a lens exit (mirrored frame, mm) to a camera-space ray (origin m, unit direction).
    #[inline]
    pub fn to_camera(&self, e: &LensExit) -> (Vec3, Vec3) {
        let z_lens = self.lens.image_z_mm() - e.origin_mm[2];
        let o = Vec3::new(
            (e.origin_mm[0] * 1e-3) as f32,
            (e.origin_mm[1] * 1e-3) as f32,
            ((z_lens - self.z_ep_mm) * 1e-3) as f32,
        );
        let d = Vec3::new(
            e.direction[0] as f32,
            e.direction[1] as f32,
            -e.direction[2] as f32,
        )
        .normalize();
        (o, d)
    }

    /// Sample the exit pupil for sensor point `p` (mm) with `u` ∈ [0,1)²: the rear-plane
    /// point (mm) and the area (mm²) of the box it was drawn from (1 / its pdf). `None`
    /// outside the table or where the pupil is empty.
    pub fn sample_pupil(&self, p: [f64; 2], u: [f64; 2]) -> Option<([f64; 2], f64)> {
        let s = self.pupil.sample(p, u)?;
        Some((s.rear_point_mm, s.box_area_mm2))
    }

    /// The irradiance weight and lens exit of one sample (see the module docs).
    pub fn sample_ray_mm(
        &self,
        p: [f64; 2],
        u: [f64; 2],
        wavelength_nm: f64,
    ) -> Option<(f64, LensExit)> {
        let s = self.pupil.sample(p, u)?;
        let dir = self.lens.direction_to(p, s.rear_point_mm);
        let exit = self.trace_from_sensor([p[0], p[1], 0.0], dir, wavelength_nm)?;
        let cos2 = dir[2] * dir[2];
        let d = self.lens.rear_plane_mm();
        let w = cos2 * cos2 * s.box_area_mm2 / (d * d);
        Some((w, exit))
    }
}

impl Camera for RealLensCamera {
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
        let p = self.film_mm(film_px);
        let (w, exit) = self.sample_ray_mm(
            p,
            [lens_uv.x as f64, lens_uv.y as f64],
            wavelengths_nm[0] as f64,
        )?;
        let (origin_m, direction) = self.to_camera(&exit);
        Some(CameraRay {
            origin_m,
            direction,
            weight: [w as f32, 0.0, 0.0, 0.0],
            wavelength_dependent: true,
        })
    }

    fn center_ray(&self, film_px: Vec2) -> Option<CameraRay> {
        let p = self.film_mm(film_px);
        let q = self.pupil.chief_aim(p)?;
        let exit = self
            .lens
            .trace_through(p, q, self.info.primary_nm, Clipping::None)?;
        let (origin_m, direction) = self.to_camera(&exit);
        Some(CameraRay {
            origin_m,
            direction,
            weight: [1.0; 4],
            wavelength_dependent: false,
        })
    }
}
