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
//! * **Exit-pupil bounds** (the idea of pbrt-v4's RealisticCamera, re-derived here): for film
//!   radii in `pupil_bins` intervals of [0, half-diagonal], the axis-aligned box on the rear
//!   vertex plane that holds every point through which a ray from the film point (on +x) gets
//!   through the lens, found on a coarse-then-fine grid at the shortest, primary and longest
//!   wavelength, at both ends and the middle of the interval, widened by one fine cell. A film
//!   point at azimuth φ samples the box of its interval uniformly and rotates the point by φ
//!   (rotational symmetry).
//! * **Estimator.** Irradiance from radiance L through the rear plane at distance d from the
//!   sensor, both planes perpendicular to the axis (cos θ_film = cos θ_plane = d/|q − p|):
//!   E(p) = ∫ L cos⁴θ / d² dA_q. With q uniform on the box (pdf 1/A) the weight of one ray
//!   is w = cos⁴θ·A/d² (sr), 0 when the ray is vignetted, totally reflected or misses a
//!   surface. Fresnel losses and glass absorption are not modelled (T = 1).
//! * **Dispersion.** The ray is traced at the hero wavelength only; `wavelength_dependent` is
//!   true and the secondary weights are 0 (the integrator terminates the secondaries).
//! * **Centre ray** (depth channel): the chief ray, through the centre of the stop at the
//!   primary wavelength; its rear-plane aim point is solved by secant iteration at the interval
//!   ends and interpolated.
use super::{Camera, CameraRay, OutputQuantity};
use camsim_lens::prescription::{Aperture, Medium, Surface};
use camsim_lens::trace::{intersect, normal, refract, Ray as LensRay};
use camsim_lens::{FocusMethod, FocusSpec, FocusedLens, GlassCatalog, LensError, LensPrescription};
use glam::{Vec2, Vec3};
use rayon::prelude::*;
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

/// Axis-aligned box on the rear plane (mm, film point on +x).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PupilBounds {
    /// Lower x.
    pub x0_mm: f64,
    /// Upper x.
    pub x1_mm: f64,
    /// Lower y.
    pub y0_mm: f64,
    /// Upper y.
    pub y1_mm: f64,
}

impl PupilBounds {
    /// Area (mm²).
    pub fn area_mm2(&self) -> f64 {
        (self.x1_mm - self.x0_mm) * (self.y1_mm - self.y0_mm)
    }
    fn include(b: &mut Option<PupilBounds>, x: f64, y: f64) {
        match b {
            None => {
                *b = Some(PupilBounds {
                    x0_mm: x,
                    x1_mm: x,
                    y0_mm: y,
                    y1_mm: y,
                })
            }
            Some(b) => {
                b.x0_mm = b.x0_mm.min(x);
                b.x1_mm = b.x1_mm.max(x);
                b.y0_mm = b.y0_mm.min(y);
                b.y1_mm = b.y1_mm.max(y);
            }
        }
    }
    fn union(a: Option<PupilBounds>, b: Option<PupilBounds>) -> Option<PupilBounds> {
        match (a, b) {
            (None, x) | (x, None) => x,
            (Some(a), Some(b)) => Some(PupilBounds {
                x0_mm: a.x0_mm.min(b.x0_mm),
                x1_mm: a.x1_mm.max(b.x1_mm),
                y0_mm: a.y0_mm.min(b.y0_mm),
                y1_mm: a.y1_mm.max(b.y1_mm),
            }),
        }
    }
    fn widened(self, d: f64) -> PupilBounds {
        PupilBounds {
            x0_mm: self.x0_mm - d,
            x1_mm: self.x1_mm + d,
            y0_mm: self.y0_mm - d,
            y1_mm: self.y1_mm + d,
        }
    }
}

/// One surface of the mirrored lens.
#[derive(Debug, Clone)]
struct RevSurface {
    surface: Surface,
    /// Vertex z' (mm) in the mirrored frame.
    z_mm: f64,
    /// Squared clear radius (mm²), ∞ without a semi-diameter.
    sd2_mm2: f64,
    /// Row of the index table of the medium after this surface (towards the object).
    medium_after: usize,
}

/// n(λ) of each medium on a 1 nm grid (linear interpolation, clamped at the ends).
#[derive(Debug, Clone)]
struct IndexTable {
    lo_nm: f64,
    n_per_row: usize,
    values: Vec<f64>,
}

impl IndexTable {
    const LO_NM: f64 = 250.0;
    const HI_NM: f64 = 1300.0;

    fn new(media: &[Medium]) -> Self {
        let n_per_row = (Self::HI_NM - Self::LO_NM) as usize + 1;
        let mut values = Vec::with_capacity(media.len() * n_per_row);
        for m in media {
            for i in 0..n_per_row {
                values.push(m.index(Self::LO_NM + i as f64));
            }
        }
        IndexTable {
            lo_nm: Self::LO_NM,
            n_per_row,
            values,
        }
    }

    #[inline]
    fn index(&self, row: usize, wavelength_nm: f64) -> f64 {
        let x = (wavelength_nm - self.lo_nm).clamp(0.0, (self.n_per_row - 1) as f64);
        let i = (x as usize).min(self.n_per_row - 2);
        let t = x - i as f64;
        let r = &self.values[row * self.n_per_row..(row + 1) * self.n_per_row];
        r[i] * (1.0 - t) + r[i + 1] * t
    }
}

/// A ray that left the front of the lens (mirrored frame, mm).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LensExit {
    /// Point on the front surface (mirrored frame: x, y, z').
    pub origin_mm: [f64; 3],
    /// Unit direction (mirrored frame, +z' = towards the object).
    pub direction: [f64; 3],
    /// Where the ray crossed the aperture stop (x, y mm).
    pub stop_mm: [f64; 2],
}

/// The real-lens camera (see the module docs).
#[derive(Debug, Clone)]
pub struct RealLensCamera {
    width_px: u32,
    height_px: u32,
    pixel_pitch_mm: f64,
    surfaces: Vec<RevSurface>,
    stop_rev: usize,
    index: IndexTable,
    /// Rear-vertex plane z' (mm) = last thickness.
    rear_z_mm: f64,
    /// Image plane z in the lens frame (mm).
    z_img_mm: f64,
    /// Entrance pupil z in the lens frame (mm).
    z_ep_mm: f64,
    /// Film half-diagonal (mm) covered by the pupil table.
    r_max_mm: f64,
    bins: Vec<Option<PupilBounds>>,
    /// Chief-ray rear-plane x (mm) at the interval ends k·Δ, k = 0..=bins.
    chief_x_mm: Vec<Option<f64>>,
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
        let per_tan_mm = (paraxial.paraxial_chief_height_mm(1.0, lens.primary_nm)?
            / 1f64.to_radians().tan())
        .abs();
        let pitch_est_mm = match opts.film {
            FilmSize::PixelPitchUm(p) => p * 1e-3,
            FilmSize::VerticalFovRad(fov) => 2.0 * per_tan_mm * (fov / 2.0).tan() / height_px as f64,
        };
        let mut method = opts.focus_method.clone();
        if pitch_est_mm.is_finite() && pitch_est_mm > 0.0 {
            method.frequency_cyc_per_mm = method
                .frequency_cyc_per_mm
                .or(Some(0.25 / pitch_est_mm));
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
        let stop_sd = fo.stop_semi_diameter_mm;
        let s = &mut lens.surfaces[lens.stop_index];
        s.semi_diameter_mm = Some(s.semi_diameter_mm.map_or(stop_sd, |v| v.min(stop_sd)));

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

        // Mirrored surfaces and media (medium 0 = image space, air).
        let z = lens.vertex_z_mm();
        let z_img_mm = z[ns];
        let mut media = vec![Medium::Air];
        let mut surfaces = Vec::with_capacity(ns);
        for i in 0..ns {
            let j = ns - 1 - i;
            let s = &lens.surfaces[j];
            let after = if j == 0 {
                Medium::Air
            } else {
                lens.surfaces[j - 1].medium.clone()
            };
            media.push(after);
            let mut m = s.clone();
            m.curvature_per_mm = -s.curvature_per_mm;
            m.aspheric_coeffs = s.aspheric_coeffs.iter().map(|a| -a).collect();
            surfaces.push(RevSurface {
                surface: m,
                z_mm: z_img_mm - z[j],
                sd2_mm2: s.semi_diameter_mm.map_or(f64::INFINITY, |v| v * v),
                medium_after: i + 1,
            });
        }
        let rear_z_mm = surfaces[0].z_mm;
        if !(rear_z_mm > 0.0) {
            return Err(cfg(format!(
                "the sensor is not behind the last surface (distance {rear_z_mm} mm)"
            )));
        }
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
        let mut cam = RealLensCamera {
            width_px,
            height_px,
            pixel_pitch_mm,
            surfaces,
            stop_rev: ns - 1 - lens.stop_index,
            index: IndexTable::new(&media),
            rear_z_mm,
            z_img_mm,
            z_ep_mm,
            r_max_mm,
            bins: Vec::new(),
            chief_x_mm: Vec::new(),
            info,
        };
        cam.bins = cam.compute_pupil_bounds(opts, 1.5 * max_sd);
        cam.chief_x_mm = cam.compute_chief_rays(lens.primary_nm);
        Ok(cam)
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
        self.z_img_mm - self.info.exit_pupil_z_mm
    }

    /// The exit-pupil table: film-radius interval width (mm) and the bounds per interval.
    pub fn pupil_table(&self) -> (f64, &[Option<PupilBounds>]) {
        (self.r_max_mm / self.bins.len() as f64, &self.bins)
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
        self.trace_surfaces(origin_mm, direction, wavelength_nm, true)
    }

    /// The surface loop of every sensor-side trace: intersect, clip (with `clip`: at the clear
    /// radii, and a backwards step), refract, and record the stop crossing.
    fn trace_surfaces(
        &self,
        origin_mm: [f64; 3],
        direction: [f64; 3],
        wavelength_nm: f64,
        clip: bool,
    ) -> Option<LensExit> {
        let mut r = LensRay {
            origin_mm,
            direction,
            opl_mm: 0.0,
        };
        let mut n1 = 1.0;
        let mut stop = [f64::NAN; 2];
        for (i, s) in self.surfaces.iter().enumerate() {
            let (t, q) = intersect(&s.surface, s.z_mm, &r)?;
            if clip && (t < -1e-9 || q[0] * q[0] + q[1] * q[1] > s.sd2_mm2) {
                return None;
            }
            let nrm = normal(&s.surface, [q[0], q[1], q[2] - s.z_mm])?;
            let n2 = self.index.index(s.medium_after, wavelength_nm);
            let d = refract(r.direction, nrm, n1, n2)?;
            if i == self.stop_rev {
                stop = [q[0], q[1]];
            }
            r = LensRay {
                origin_mm: q,
                direction: d,
                opl_mm: 0.0,
            };
            n1 = n2;
        }
        Some(LensExit {
            origin_mm: r.origin_mm,
            direction: r.direction,
            stop_mm: stop,
        })
    }

    /// Trace from sensor point `p` (mm) towards rear-plane point `q` (mm).
    pub fn trace_through(&self, p: [f64; 2], q: [f64; 2], wavelength_nm: f64) -> Option<LensExit> {
        let d = [q[0] - p[0], q[1] - p[1], self.rear_z_mm];
        let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        self.trace_from_sensor(
            [p[0], p[1], 0.0],
            [d[0] / l, d[1] / l, d[2] / l],
            wavelength_nm,
        )
    }

    /// Bounds of the rear-plane points through which rays from (r, 0) get through, at the
    /// given wavelengths, on a `g`×`g` grid over `b`; `None` when none gets through.
    fn scan(&self, r: f64, b: PupilBounds, g: usize, wls: &[f64]) -> Option<PupilBounds> {
        let mut out = None;
        for iy in 0..g {
            let y = b.y0_mm + (b.y1_mm - b.y0_mm) * (iy as f64 + 0.5) / g as f64;
            for ix in 0..g {
                let x = b.x0_mm + (b.x1_mm - b.x0_mm) * (ix as f64 + 0.5) / g as f64;
                if wls
                    .iter()
                    .any(|&w| self.trace_through([r, 0.0], [x, y], w).is_some())
                {
                    PupilBounds::include(&mut out, x, y);
                }
            }
        }
        out
    }

    fn compute_pupil_bounds(
        &self,
        opts: &RealLensOptions,
        extent0_mm: f64,
    ) -> Vec<Option<PupilBounds>> {
        let nb = opts.pupil_bins;
        let dr = self.r_max_mm / nb as f64;
        let wls = [
            opts.wavelength_range_nm.0,
            self.info.primary_nm,
            opts.wavelength_range_nm.1,
        ];
        let fine = opts.pupil_grid;
        let coarse = (fine / 2).max(8);
        // Bounds at the interval ends and middles r_i = i·Δ/2 (shared by neighbouring
        // intervals), then interval k = union of r_2k, r_2k+1, r_2k+2.
        let at_radius: Vec<Option<PupilBounds>> = (0..=2 * nb)
            .into_par_iter()
            .map(|i| {
                let r = i as f64 * 0.5 * dr;
                // Coarse scan over a square that grows until the pupil is inside it.
                let mut e = extent0_mm;
                let mut found = None;
                for _ in 0..6 {
                    let sq = PupilBounds {
                        x0_mm: -e,
                        x1_mm: e,
                        y0_mm: -e,
                        y1_mm: e,
                    };
                    found = self.scan(r, sq, coarse, &wls);
                    let cell = 2.0 * e / coarse as f64;
                    match found {
                        Some(b)
                            if b.x0_mm < -e + cell
                                || b.x1_mm > e - cell
                                || b.y0_mm < -e + cell
                                || b.y1_mm > e - cell =>
                        {
                            e *= 2.0
                        }
                        _ => break,
                    }
                }
                // Fine scan of the coarse box widened by one coarse cell, widened in turn by
                // one fine cell.
                let b = found?;
                let wide = b.widened(2.0 * e / coarse as f64);
                let c = (wide.x1_mm - wide.x0_mm).max(wide.y1_mm - wide.y0_mm) / fine as f64;
                self.scan(r, wide, fine, &wls).map(|f| f.widened(c))
            })
            .collect();
        (0..nb)
            .map(|k| {
                PupilBounds::union(
                    PupilBounds::union(at_radius[2 * k], at_radius[2 * k + 1]),
                    at_radius[2 * k + 2],
                )
            })
            .collect()
    }

    /// Rear-plane x of the chief ray (through the stop centre) from (r, 0), by secant steps.
    fn solve_chief(&self, r: f64, guess: f64, wavelength_nm: f64) -> Option<f64> {
        let f = |a: f64| {
            self.trace_from_sensor_unclipped([r, 0.0], [a, 0.0], wavelength_nm)
                .map(|e| e.stop_mm[0])
        };
        let mut a0 = guess;
        let mut f0 = f(a0)?;
        if f0.abs() < 1e-10 {
            return Some(a0);
        }
        let mut a1 = guess + 1e-3 * (1.0 + guess.abs());
        let mut f1 = f(a1)?;
        for _ in 0..60 {
            if (f1 - f0).abs() < 1e-300 {
                return None;
            }
            let a2 = a1 - f1 * (a1 - a0) / (f1 - f0);
            a0 = a1;
            f0 = f1;
            a1 = a2;
            f1 = f(a1)?;
            if f1.abs() < 1e-10 {
                return Some(a1);
            }
        }
        None
    }

    /// Like [`Self::trace_through`] without clipping at the clear radii (chief-ray aiming:
    /// the chief ray may be defined where the marginal rays are vignetted).
    fn trace_from_sensor_unclipped(
        &self,
        p: [f64; 2],
        q: [f64; 2],
        wavelength_nm: f64,
    ) -> Option<LensExit> {
        let d = [q[0] - p[0], q[1] - p[1], self.rear_z_mm];
        let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        self.trace_surfaces(
            [p[0], p[1], 0.0],
            [d[0] / l, d[1] / l, d[2] / l],
            wavelength_nm,
            false,
        )
    }

    fn compute_chief_rays(&self, primary_nm: f64) -> Vec<Option<f64>> {
        let nb = self.bins.len();
        let dr = self.r_max_mm / nb as f64;
        // Paraxial guess: the line from the film point to the exit-pupil centre.
        let xp_from_sensor = self.z_img_mm - self.info.exit_pupil_z_mm;
        (0..=nb)
            .into_par_iter()
            .map(|k| {
                let r = k as f64 * dr;
                if k == 0 {
                    return Some(0.0);
                }
                let guess = if xp_from_sensor.abs() > 1e-9 {
                    r * (1.0 - self.rear_z_mm / xp_from_sensor)
                } else {
                    0.0
                };
                self.solve_chief(r, guess, primary_nm).or_else(|| {
                    let b = self.bins[k.min(nb - 1)]?;
                    Some(0.5 * (b.x0_mm + b.x1_mm))
                })
            })
            .collect()
    }

    /// Convert a lens exit (mirrored frame, mm) to a camera-space ray (origin m, unit direction).
    #[inline]
    pub fn to_camera(&self, e: &LensExit) -> (Vec3, Vec3) {
        let z_lens = self.z_img_mm - e.origin_mm[2];
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

    /// Rotation (cos φ, sin φ) of a sensor point and its radius.
    #[inline]
    fn polar(p: [f64; 2]) -> (f64, f64, f64) {
        let r = p[0].hypot(p[1]);
        if r > 0.0 {
            (r, p[0] / r, p[1] / r)
        } else {
            (0.0, 1.0, 0.0)
        }
    }

    /// Sample the exit pupil for sensor point `p` (mm) with `u` ∈ [0,1)²: the rear-plane
    /// point (mm) and the area (mm²) of the box it was drawn from. `None` outside the table
    /// or where the pupil is empty.
    pub fn sample_pupil(&self, p: [f64; 2], u: [f64; 2]) -> Option<([f64; 2], f64)> {
        let (r, c, s) = Self::polar(p);
        let nb = self.bins.len();
        let k = ((r / self.r_max_mm) * nb as f64) as usize;
        let b = (*self.bins.get(k)?)?;
        let x = b.x0_mm + u[0] * (b.x1_mm - b.x0_mm);
        let y = b.y0_mm + u[1] * (b.y1_mm - b.y0_mm);
        Some(([c * x - s * y, s * x + c * y], b.area_mm2()))
    }

    /// The irradiance weight and lens exit of one sample (see the module docs).
    pub fn sample_ray_mm(
        &self,
        p: [f64; 2],
        u: [f64; 2],
        wavelength_nm: f64,
    ) -> Option<(f64, LensExit)> {
        let (q, area) = self.sample_pupil(p, u)?;
        let d = [q[0] - p[0], q[1] - p[1], self.rear_z_mm];
        let l2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
        let l = l2.sqrt();
        let dir = [d[0] / l, d[1] / l, d[2] / l];
        let exit = self.trace_from_sensor([p[0], p[1], 0.0], dir, wavelength_nm)?;
        let cos2 = dir[2] * dir[2];
        let w = cos2 * cos2 * area / (self.rear_z_mm * self.rear_z_mm);
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
        let (r, c, s) = Self::polar(p);
        let nb = self.bins.len();
        let x = r / self.r_max_mm * nb as f64;
        let k = (x as usize).min(nb - 1);
        let t = x - k as f64;
        let a = match (self.chief_x_mm.get(k)?, self.chief_x_mm.get(k + 1)?) {
            (Some(a0), Some(a1)) => a0 * (1.0 - t) + a1 * t,
            (Some(a), None) | (None, Some(a)) => *a,
            (None, None) => return None,
        };
        let exit = self.trace_from_sensor_unclipped(p, [c * a, s * a], self.info.primary_nm)?;
        let (origin_m, direction) = self.to_camera(&exit);
        Some(CameraRay {
            origin_m,
            direction,
            weight: [1.0; 4],
            wavelength_dependent: false,
        })
    }
}
