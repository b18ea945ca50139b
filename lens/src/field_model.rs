//! Field model: the ISET ray-trace lens representation (the "field model" of §2.B.3 of the
//! camera-simulation paper): point-spread functions, distortion and relative illumination
//! tabulated over image height × wavelength × **object distance** for a lens at one focus
//! setting, with interpolation between tabulated heights, wavelengths and distances and
//! rotation of a PSF to any field azimuth.
//!
//! ## Conventions
//! * The lens is at one focus setting: its image plane is the paraxial image (primary
//!   wavelength) of an object at the **focus distance** (default: the prescription's own
//!   object distance). Every tabulated object distance is imaged on that same plane, so objects
//!   away from the focus distance are defocused.
//! * Image heights: one grid h_k of **paraxial** chief-ray heights on the image plane, evenly
//!   spaced from 0 to the maximum, shared by every distance; at each distance the object-space
//!   field angle θ_k of h_k is stored (the paraxial height is linear in tan θ). Look-ups are by
//!   paraxial image height in mm (the ideal, undistorted position of the image point).
//! * Field angles of a finite object are measured at the paraxial entrance pupil: the object
//!   point of θ lies at height (d + z_ep)·tan θ (see `trace::FieldAim`).
//! * Every PSF is computed for a field point on **+y** (the meridional plane is y–z) and stored
//!   on a `psf_n` × `psf_n` grid (odd `psf_n`) of pitch `psf_pitch_um` µm, row-major
//!   `[iy·n + ix]`, sample (n/2, n/2) at the real chief ray's image point, x = (ix − n/2)·pitch,
//!   y = (iy − n/2)·pitch, values summing to 1.
//! * A field point at azimuth φ (measured from +x towards +y, so +y is φ = 90°) has the +y
//!   PSF rotated by φ − 90° about its centre (each sample moved and spread by `splat_quadratic`, renormalised).
//! * Distortion: `real_height_mm[field][wavelength]` is the real chief-ray height (chief ray
//!   aimed at the stop centre at that wavelength), `paraxial_height_mm[field]` the paraxial
//!   one at the primary wavelength; distortion % = 100 (real − paraxial)/paraxial.
//! * Relative illumination `[field][wavelength]`, per distance: the film irradiance of a
//!   uniform-radiance scene where the field's real chief ray lands at that wavelength over the
//!   axial one at the same wavelength, traced from the film through the lens with its physical
//!   stop ([`crate::pupil::film_relative_illumination`], the integral the path tracer's
//!   real-lens camera samples: vignetting, cos⁴ and the pupil's aberrations, all by
//!   wavelength). For a lens that cannot be traced from the sensor (mirrors) the entrance-pupil
//!   estimate [`LensPrescription::relative_illumination`] (vignetting × cos⁴ of the image-space
//!   chief-ray angle) at each wavelength.
//! * Wave PSFs come from [`LensPrescription::wave_optics`] (FFT of the pupil function) and are
//!   point-sampled bilinearly onto the common grid, then renormalised; geometric PSFs spread
//!   the rays of a square pupil grid (clipped at the semi-diameters) about the chief ray with
//!   quadratic weights that keep their centroid and second moments (`splat_quadratic`), and
//!   rotations to other azimuths move the samples the same way.
//! * Interpolation: bilinear in paraxial height × wavelength within a distance, and linear in
//!   the object-space **vergence** 1/d (0 for an object at infinity) between the two tabulated
//!   distances that bracket the one asked for; defocus, magnification and the image-space
//!   quantities vary smoothly in 1/d (the Gauss equation is linear in it). Outside the
//!   tabulated range the nearest distance is used.
//!
//! ## File format (`FieldModel::save` / `load`), version 2
//! A JSON object whose keys carry their units; `null` distances are infinity:
//! ```json
//! {"format": "camsim-lens field model", "version": 2,
//!  "lens_name": "...", "psf_kind": "wave" | "geometric",
//!  "focus_distance_mm": null, "image_distance_mm": 41.6, "efl_mm": 49.4, "f_number": 4.5,
//!  "primary_nm": 587.56, "wavelengths_nm": [486.1, 587.6, 656.3],
//!  "paraxial_height_mm": [0, 7.0, 14.1], "psf_n": 33, "psf_pitch_um": 1.0,
//!  "distances": [                                   // increasing vergence 1/d (∞ first)
//!    {"object_distance_mm": null, "working_f_number": 4.5, "magnification": 0.0,
//!     "field_angles_deg": [0, 8.1, 16.0],                          // [field]
//!     "real_height_mm": [[0, 0, 0], [7.01, 7.02, 7.03], ...],     // [field][wavelength]
//!     "relative_illumination": [1.0, 0.93, 0.78],                 // [field], at primary_nm
//!     "relative_illumination_by_wavelength": [[1, 1, 1], [0.93, 0.93, 0.94], ...],
//!                                                    // [field][wavelength]; optional
//!     "psf": [[[...n² values...], ...], ...]},                    // [field][wavelength]
//!    {"object_distance_mm": 2000.0, ...}],
//!  "axial_irradiance_sr": [0.0392, 0.0390, 0.0389]}   // [wavelength] (sr); optional
//! ```
//! `axial_irradiance_sr` (written since it exists; absent = unknown, the paraxial camera
//! equation then applies) is [`FieldModel::axial_irradiance_sr`].
//! `relative_illumination_by_wavelength` (written since it exists) is
//! [`FieldTable::relative_illumination`]; `relative_illumination` is its value at the primary
//! wavelength (linear between the tabulated wavelengths), kept for earlier readers. A file
//! without the per-wavelength key (written before it, or version 1) uses its per-field
//! `relative_illumination` at every wavelength.
//! Version 1 files (one distance: `object_distance_mm`, `field_angles_deg`,
//! `real_height_mm`, `relative_illumination` and `psf` at the top level, the lens focused on
//! that distance) are still read, as a model with that single distance.
use crate::analysis::pupil_grid;
use crate::error::LensError;
use crate::prescription::LensPrescription;
use crate::trace::Clipping;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use serde_json::Value;
use std::path::Path;

/// The `format` string of field-model files.
pub const FORMAT: &str = "camsim-lens field model";
/// The version written by [`FieldModel::save`].
pub const VERSION: u32 = 2;

/// Which PSF the model holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum PsfKind {
    /// Diffraction PSF from the OPD map (FFT).
    Wave,
    /// Ray-density (spot) PSF.
    Geometric,
}

/// Where the lens is focused when a [`FieldModel`] is built.
#[derive(Debug, Clone, PartialEq, Default)]
pub enum Focus {
    /// On the prescription's own object distance (its `object_distance_mm`), paraxially.
    #[default]
    Prescription,
    /// On an object at this distance from the first vertex (mm; `None` = infinity),
    /// paraxially by unit motion.
    At(Option<f64>),
    /// By the focus model ([`crate::focus_model`]): distance, criterion and motion.
    Spec(crate::focus_model::FocusSpec),
    /// A lens already focused by the focus model (its prescription is used as it stands).
    Focused(Box<crate::focus_model::FocusedLens>),
}

/// Largest pupil grid per side a wave-PSF entry of [`FieldModel::compute`] is given.
pub const MAX_WAVE_PUPIL_N: usize = 512;

/// How to build a [`FieldModel`].
#[derive(Debug, Clone, PartialEq)]
pub struct FieldModelOptions {
    /// Number of tabulated field heights (≥ 2), evenly spaced in paraxial image height (unless
    /// `paraxial_heights_mm` is given).
    pub n_fields: usize,
    /// Explicit paraxial image heights (mm; finite, ≥ 0, strictly increasing, at least one) to
    /// tabulate instead of `n_fields` evenly spaced up to `max_field_deg` (which are then
    /// ignored): e.g. exactly the positions a caller evaluates, so that no PSF is interpolated
    /// between heights.
    pub paraxial_heights_mm: Option<Vec<f64>>,
    /// Maximum field angle (degrees) **of the first tabulated distance**; default the largest
    /// of the lens's `fields_deg`. It fixes the maximum paraxial image height shared by all
    /// distances.
    pub max_field_deg: Option<f64>,
    /// Wavelengths (nm); default the lens's.
    pub wavelengths_nm: Option<Vec<f64>>,
    /// PSF kind.
    pub kind: PsfKind,
    /// Samples per side of the stored PSFs (made odd).
    pub psf_n: usize,
    /// Pitch of the stored PSFs (µm).
    pub psf_pitch_um: f64,
    /// Pupil samples per side (OPD grid for wave PSFs, ray grid for geometric ones). For wave
    /// PSFs this is the minimum: an entry whose OPD slope needs more gets more, up to
    /// [`MAX_WAVE_PUPIL_N`] ([`crate::focus`]); [`FieldModel::aliased_entries`] counts those
    /// that needed more still.
    pub pupil_n: usize,
    /// Zero-padding factor of the FFT (wave PSFs).
    pub pad: usize,
    /// Grid per side for relative illumination: on the rear plane for the film-side integral
    /// ([`crate::pupil::film_relative_illumination`]; its quadrature error is about 0.2 % at
    /// 128, the default, and 0.3–0.4 % at 64 for the double Gauss at f/2 12–14 mm off the
    /// axis), on the entrance pupil for the fallback.
    pub ri_grid_n: usize,
    /// Focus setting (image plane).
    pub focus: Focus,
    /// Object distances to tabulate (mm from the first vertex, `None` = infinity); empty = the
    /// focus distance only.
    pub object_distances_mm: Vec<Option<f64>>,
}

impl Default for FieldModelOptions {
    fn default() -> Self {
        FieldModelOptions {
            n_fields: 5,
            paraxial_heights_mm: None,
            max_field_deg: None,
            wavelengths_nm: None,
            kind: PsfKind::Wave,
            psf_n: 33,
            psf_pitch_um: 1.0,
            pupil_n: 64,
            pad: 4,
            ri_grid_n: 128,
            focus: Focus::Prescription,
            object_distances_mm: Vec::new(),
        }
    }
}

/// The tables of one object distance, with the grids they are tabulated on (see the module
/// docs). This is what image formation looks PSFs, distortion and illumination up in.
#[derive(Debug, Clone, PartialEq)]
pub struct FieldTable {
    /// Object distance (mm from the first vertex), `None` = infinity.
    pub object_distance_mm: Option<f64>,
    /// Working F-number at this conjugate (paraxial, primary wavelength).
    pub working_f_number: f64,
    /// Paraxial magnification (0 for an object at infinity).
    pub magnification: f64,
    /// Tabulated wavelengths (nm, increasing).
    pub wavelengths_nm: Vec<f64>,
    /// Paraxial image height of each tabulated field (mm, increasing from 0).
    pub paraxial_height_mm: Vec<f64>,
    /// Object-space field angle of each tabulated field (degrees).
    pub field_angles_deg: Vec<f64>,
    /// Real chief-ray image height, `[field][wavelength]` (mm).
    pub real_height_mm: Vec<Vec<f64>>,
    /// Relative illumination `[field][wavelength]` (1 on axis; see the module docs).
    pub relative_illumination: Vec<Vec<f64>>,
    /// PSF samples per side (odd).
    pub psf_n: usize,
    /// PSF sample pitch (µm).
    pub psf_pitch_um: f64,
    /// PSFs `[field][wavelength][iy·n + ix]`, field on +y, centred on the chief ray, sum 1.
    pub psf: Vec<Vec<Vec<f64>>>,
}

/// The tabulated field model (see the module docs for conventions and the file format).
#[derive(Debug, Clone, PartialEq)]
pub struct FieldModel {
    /// Lens name.
    pub lens_name: String,
    /// PSF kind.
    pub psf_kind: PsfKind,
    /// Object distance the lens is focused on (mm; `None` = infinity).
    pub focus_distance_mm: Option<f64>,
    /// Last vertex → image plane (mm) at the focus setting (the paraxial image of the focus
    /// distance for [`Focus::Prescription`] / [`Focus::At`]).
    pub image_distance_mm: f64,
    /// EFL at the primary wavelength (mm).
    pub efl_mm: f64,
    /// Infinite-conjugate F-number.
    pub f_number: f64,
    /// Primary wavelength (nm).
    pub primary_nm: f64,
    /// Tabulated wavelengths (nm, increasing).
    pub wavelengths_nm: Vec<f64>,
    /// Paraxial image heights of the tabulated fields (mm, increasing from 0).
    pub paraxial_height_mm: Vec<f64>,
    /// PSF samples per side (odd).
    pub psf_n: usize,
    /// PSF sample pitch (µm).
    pub psf_pitch_um: f64,
    /// One table per object distance, by increasing vergence 1/d (infinity first).
    pub tables: Vec<FieldTable>,
    /// Film irradiance on the axis per unit scene radiance (sr) at each tabulated wavelength,
    /// traced from the film through the lens with its physical stop
    /// ([`crate::pupil::axial_irradiance_per_radiance_sr`]): the real lens's camera-equation
    /// factor, for any object distance (a film-side integral). Empty when unknown (a lens that
    /// cannot be traced from the sensor, a file without it): the paraxial π/(4N_w²) applies.
    pub axial_irradiance_sr: Vec<f64>,
    /// Wave-PSF entries whose OPD slope needed a pupil grid finer than [`MAX_WAVE_PUPIL_N`]
    /// (their PSFs alias; callers should warn). Not saved; 0 for a loaded model.
    pub aliased_entries: usize,
}

/// One distance of a version-2 file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct DistanceFile {
    object_distance_mm: Option<f64>,
    working_f_number: f64,
    magnification: f64,
    field_angles_deg: Vec<f64>,
    real_height_mm: Vec<Vec<f64>>,
    /// At the primary wavelength (for readers before the per-wavelength key).
    relative_illumination: Vec<f64>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    relative_illumination_by_wavelength: Vec<Vec<f64>>,
    psf: Vec<Vec<Vec<f64>>>,
}

/// A version-2 file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct FileV2 {
    format: String,
    version: u32,
    lens_name: String,
    psf_kind: PsfKind,
    focus_distance_mm: Option<f64>,
    image_distance_mm: f64,
    efl_mm: f64,
    f_number: f64,
    primary_nm: f64,
    wavelengths_nm: Vec<f64>,
    paraxial_height_mm: Vec<f64>,
    psf_n: usize,
    psf_pitch_um: f64,
    distances: Vec<DistanceFile>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    axial_irradiance_sr: Vec<f64>,
}

/// A version-1 file (one distance, the lens focused on it).
#[derive(Debug, Clone, PartialEq, Deserialize)]
struct FileV1 {
    lens_name: String,
    psf_kind: PsfKind,
    object_distance_mm: Option<f64>,
    image_distance_mm: f64,
    efl_mm: f64,
    f_number: f64,
    primary_nm: f64,
    wavelengths_nm: Vec<f64>,
    field_angles_deg: Vec<f64>,
    paraxial_height_mm: Vec<f64>,
    real_height_mm: Vec<Vec<f64>>,
    relative_illumination: Vec<f64>,
    psf_n: usize,
    psf_pitch_um: f64,
    psf: Vec<Vec<Vec<f64>>>,
}

/// A per-field relative illumination (a file without the per-wavelength key) repeated at each
/// of `nw` wavelengths.
fn per_field_at_every_wavelength(ri: &[f64], nw: usize) -> Vec<Vec<f64>> {
    ri.iter().map(|&v| vec![v; nw]).collect()
}

/// Bilinear sample of an n×n row-major image at fractional index (fx, fy); 0 outside.
fn bilinear(img: &[f64], n: usize, fx: f64, fy: f64) -> f64 {
    if !(fx > -1.0 && fy > -1.0 && fx < n as f64 && fy < n as f64) {
        return 0.0;
    }
    let x0 = fx.floor();
    let y0 = fy.floor();
    let (tx, ty) = (fx - x0, fy - y0);
    let get = |x: f64, y: f64| -> f64 {
        if x < 0.0 || y < 0.0 || x >= n as f64 || y >= n as f64 {
            0.0
        } else {
            img[y as usize * n + x as usize]
        }
    };
    get(x0, y0) * (1.0 - tx) * (1.0 - ty)
        + get(x0 + 1.0, y0) * tx * (1.0 - ty)
        + get(x0, y0 + 1.0) * (1.0 - tx) * ty
        + get(x0 + 1.0, y0 + 1.0) * tx * ty
}

/// Add `v` at the fractional index (`fx`, `fy`) of an n×n row-major grid, spread over the 3 × 3
/// samples around the nearest one with the quadratic Lagrange weights of the offset f ∈
/// [−½, ½] along each axis, w₋₁ = f(f − 1)/2, w₀ = 1 − f², w₊₁ = f(f + 1)/2. They reproduce
/// 1, f and f² exactly, so the grid keeps the mean and the second moments of the points it
/// receives; a nearest-bin histogram adds the bin's box (1/12 sample² per axis) and bilinear
/// resampling up to ¼ sample² more — blur that a PSF of about a sample cannot afford, since it is
/// applied to images whose samples are already pixel averages (the pixel's box counted twice).
/// The weights can be negative (down to −⅛), as for any interpolation of order > 1; weight that
/// would land outside the grid is dropped.
pub fn splat_quadratic(img: &mut [f64], n: usize, fx: f64, fy: f64, v: f64) {
    if !(fx.is_finite() && fy.is_finite()) {
        return;
    }
    let (kx, ky) = (fx.round(), fy.round());
    let w = |f: f64| [0.5 * f * (f - 1.0), 1.0 - f * f, 0.5 * f * (f + 1.0)];
    let (wx, wy) = (w(fx - kx), w(fy - ky));
    for (dy, wy) in (-1..=1).zip(wy) {
        let y = ky + dy as f64;
        if y < 0.0 || y >= n as f64 {
            continue;
        }
        for (dx, wx) in (-1..=1).zip(wx) {
            let x = kx + dx as f64;
            if x < 0.0 || x >= n as f64 {
                continue;
            }
            img[y as usize * n + x as usize] += v * wx * wy;
        }
    }
}

fn normalise(v: &mut [f64]) {
    let s: f64 = v.iter().sum();
    if s > 0.0 {
        v.iter_mut().for_each(|x| *x /= s);
    }
}

/// Index i and weight t with x = (1 − t)·xs[i] + t·xs[i+1], clamped to the table.
fn bracket(xs: &[f64], x: f64) -> (usize, f64) {
    if xs.len() < 2 || x <= xs[0] {
        return (0, 0.0);
    }
    let last = xs.len() - 1;
    if x >= xs[last] {
        return (last - 1, 1.0);
    }
    let i = xs.partition_point(|&a| a <= x) - 1;
    (i, (x - xs[i]) / (xs[i + 1] - xs[i]))
}

/// Object-space vergence 1/d (mm⁻¹) of an object distance (0 at infinity).
pub fn vergence_per_mm(object_distance_mm: Option<f64>) -> f64 {
    match object_distance_mm {
        None => 0.0,
        Some(d) => 1.0 / d,
    }
}

/// Rotate an n×n PSF (centre n/2) by `angle_deg` counter-clockwise (+x towards +y) about its
/// centre: every sample is moved to its rotated position and spread there by
/// [`splat_quadratic`], so the rotated PSF has the rotated centroid and covariance of the
/// samples exactly (bilinear resampling would widen it by up to ¼ sample² per axis);
/// renormalised to sum 1.
pub fn rotate_psf(psf: &[f64], n: usize, angle_deg: f64) -> Vec<f64> {
    let (s, c) = angle_deg.to_radians().sin_cos();
    let c0 = (n / 2) as f64;
    let mut out = vec![0.0; n * n];
    for iy in 0..n {
        for ix in 0..n {
            let v = psf[iy * n + ix];
            if v == 0.0 {
                continue;
            }
            let (u, w) = (ix as f64 - c0, iy as f64 - c0);
            // target point = R(angle)·(u, w)
            let (x, y) = (c * u - s * w, s * u + c * w);
            splat_quadratic(&mut out, n, x + c0, y + c0, v);
        }
    }
    normalise(&mut out);
    out
}

/// One (field, wavelength) entry: chief-ray height and PSF.
struct Entry {
    real_height_mm: f64,
    psf: Vec<f64>,
    aliased: bool,
}

/// The PSF and chief-ray height of field `th` at `w` for `lens` (own object distance and image
/// plane) on the common grid.
fn entry(
    lens: &LensPrescription,
    th: f64,
    w: f64,
    opts: &FieldModelOptions,
    psf_n: usize,
) -> Result<Entry, LensError> {
    let pitch_mm = opts.psf_pitch_um * 1e-3;
    let c0 = (psf_n / 2) as f64;
    let fo_w = lens.first_order(w)?;
    let aim = lens.aim_field(th, w, &fo_w)?;
    let chief = lens
        .trace(&aim.ray(0.0, 0.0), w, Clipping::None)
        .ok_or_else(|| LensError::Aiming {
            field_deg: th,
            msg: format!("chief ray lost at {w} nm"),
        })?;
    let mut img = vec![0.0; psf_n * psf_n];
    let mut aliased = false;
    match opts.kind {
        PsfKind::Wave => {
            let s = lens.pupil_sampling(th, w, opts.pupil_n, opts.pupil_n.max(MAX_WAVE_PUPIL_N))?;
            aliased = !s.alias_free;
            let wo = lens.wave_optics(th, w, s.samples, opts.pad, &[])?;
            let m = wo.psf.n;
            let cm = (m / 2) as f64;
            // The FFT PSF is point-reflected with respect to the image plane (its energy
            // centroid sits on the opposite side of the chief ray from the traced spot
            // centroid); sample it at (−x, −y) so wave and geometric PSFs share the
            // image-plane orientation.
            for iy in 0..psf_n {
                for ix in 0..psf_n {
                    let x = cm - (ix as f64 - c0) * pitch_mm / wo.psf.sample_mm;
                    let y = cm - (iy as f64 - c0) * pitch_mm / wo.psf.sample_mm;
                    img[iy * psf_n + ix] = bilinear(&wo.psf.values, m, x, y);
                }
            }
        }
        PsfKind::Geometric => {
            img = bin_geometric_psf(
                lens,
                &aim,
                chief.image_mm,
                w,
                opts.pupil_n,
                pitch_mm,
                psf_n,
                |_| true,
            );
        }
    }
    normalise(&mut img);
    Ok(Entry {
        real_height_mm: chief.image_mm[1],
        psf: img,
        aliased,
    })
}

/// The geometric PSF (ray counts, not normalised) of the rays of the `pupil_n`² entrance-pupil
/// grid ([`pupil_grid`], normalised pupil coordinates) that `keep` accepts, traced through
/// `lens` at wavelength `w` for the field of `aim` and spread ([`splat_quadratic`]: the rays'
/// centroid and second moments exactly) on a `psf_n`² grid of pitch `pitch_mm` centred (sample
/// centre) on the chief ray's image point `chief_mm`: the one binning of
/// [`FieldModel`]'s geometric PSFs and of [`geometric_pupil_half_psfs`].
#[allow(clippy::too_many_arguments)]
fn bin_geometric_psf(
    lens: &LensPrescription,
    aim: &crate::trace::FieldAim,
    chief_mm: crate::trace::Vec3,
    w: f64,
    pupil_n: usize,
    pitch_mm: f64,
    psf_n: usize,
    keep: impl Fn(&[f64; 2]) -> bool,
) -> Vec<f64> {
    let c0 = (psf_n / 2) as f64;
    let grid = pupil_grid(pupil_n);
    let b = lens
        .trace_system(w)
        .trace_pupil(aim, &grid, Clipping::SemiDiameters);
    let mut img = vec![0.0; psf_n * psf_n];
    for (i, p) in grid.iter().enumerate() {
        let Some(r) = b.get(i).filter(|_| keep(p)) else {
            continue;
        };
        let fx = (r.image_mm[0] - chief_mm[0]) / pitch_mm + c0;
        let fy = (r.image_mm[1] - chief_mm[1]) / pitch_mm + c0;
        splat_quadratic(&mut img, psf_n, fx, fy, 1.0);
    }
    img
}

/// The on-axis geometric PSFs of the two halves of the entrance pupil
/// ([`geometric_pupil_half_psfs`]): the dual-pixel sensor's left and right half-photodiode
/// PSFs (a microlens images the exit pupil, hence each pupil half, onto one half-photodiode).
#[derive(Debug, Clone, PartialEq)]
pub struct PupilHalfPsfs {
    /// Samples per side (odd); the chief ray's image point is the centre bin.
    pub n: usize,
    /// Pitch (mm).
    pub pitch_mm: f64,
    /// Rays through the pupil half x < 0, as a fraction of all the rays that got through
    /// (row-major `n²`).
    pub left: Vec<f64>,
    /// Rays through the half x > 0, the same normalisation: `left + right` is the full
    /// geometric PSF of [`FieldModel`] (sum 1).
    pub right: Vec<f64>,
}

/// The geometric PSFs of `lens` (as it stands: focus setting and object distance) on axis at
/// `wavelength_nm` from the rays through the left (pupil x < 0) and the right (x > 0) half of
/// the entrance pupil only, with [`FieldModel`]'s binning (`pupil_n`² pupil grid, made even so
/// that no ray lies on the split line and the halves partition the full PSF's rays; `psf_n`²
/// bins of `pitch_mm`, made odd). Rays outside the grid are dropped from both halves.
pub fn geometric_pupil_half_psfs(
    lens: &LensPrescription,
    wavelength_nm: f64,
    pupil_n: usize,
    psf_n: usize,
    pitch_mm: f64,
) -> Result<PupilHalfPsfs, LensError> {
    if !(pitch_mm > 0.0) || psf_n == 0 || pupil_n < 2 {
        return Err(LensError::Prescription(
            "pupil-half PSFs: pitch, psf_n and pupil_n must be positive".into(),
        ));
    }
    let (pupil_n, psf_n) = (pupil_n + pupil_n % 2, psf_n | 1);
    let fo = lens.first_order(wavelength_nm)?;
    let aim = lens.aim_field(0.0, wavelength_nm, &fo)?;
    let chief = lens
        .trace(&aim.ray(0.0, 0.0), wavelength_nm, Clipping::None)
        .ok_or_else(|| LensError::Aiming {
            field_deg: 0.0,
            msg: format!("chief ray lost at {wavelength_nm} nm"),
        })?;
    let bin = |left: bool| {
        bin_geometric_psf(
            lens,
            &aim,
            chief.image_mm,
            wavelength_nm,
            pupil_n,
            pitch_mm,
            psf_n,
            |p| (p[0] < 0.0) == left,
        )
    };
    let (mut left, mut right) = (bin(true), bin(false));
    let total: f64 = left.iter().chain(&right).sum();
    if total > 0.0 {
        left.iter_mut()
            .chain(right.iter_mut())
            .for_each(|v| *v /= total);
    }
    Ok(PupilHalfPsfs {
        n: psf_n,
        pitch_mm,
        left,
        right,
    })
}

impl FieldModel {
    /// Build the field model of `lens` at the focus and object distances of `opts` (see the
    /// module docs). Entries are computed in parallel; the result does not depend on the
    /// thread count.
    pub fn compute(lens: &LensPrescription, opts: &FieldModelOptions) -> Result<Self, LensError> {
        let bad = |m: String| LensError::Prescription(format!("field model: {m}"));
        if let Some(hs) = &opts.paraxial_heights_mm {
            let increasing = hs.windows(2).all(|w| w[1] > w[0]);
            if hs.is_empty() || !increasing || hs.iter().any(|h| !(h.is_finite() && *h >= 0.0)) {
                return Err(bad(format!(
                    "paraxial_heights_mm = {hs:?} (need at least one finite height ≥ 0 mm, strictly increasing)"
                )));
            }
        } else if opts.n_fields < 2 {
            return Err(bad(format!("n_fields = {} (need ≥ 2)", opts.n_fields)));
        }
        if !(opts.psf_pitch_um > 0.0) || opts.psf_n == 0 || opts.pupil_n < 2 {
            return Err(bad(
                "psf_pitch_um, psf_n and pupil_n must be positive".into()
            ));
        }
        let psf_n = opts.psf_n | 1;
        let focus_distance_mm = match &opts.focus {
            Focus::Prescription => lens.object_distance_mm,
            Focus::At(d) => *d,
            Focus::Spec(s) => s.focus_distance_mm,
            Focus::Focused(f) => f.focus_distance_mm,
        };
        for d in std::iter::once(&focus_distance_mm)
            .chain(&opts.object_distances_mm)
            .flatten()
        {
            if !(d.is_finite() && *d > 0.0) {
                return Err(bad(format!(
                    "object distance {d} mm must be > 0 (None = infinity)"
                )));
            }
        }
        let focused = match &opts.focus {
            Focus::Prescription | Focus::At(_) => lens.focus_at(focus_distance_mm)?,
            Focus::Spec(s) => lens.focus(s)?.lens,
            Focus::Focused(f) => f.lens.clone(),
        };
        let image_distance_mm = focused.image_distance_mm();
        if !image_distance_mm.is_finite() {
            return Err(bad("the focus distance has no real paraxial image".into()));
        }
        let fo = focused.first_order(lens.primary_nm)?;
        let mut wls = opts
            .wavelengths_nm
            .clone()
            .unwrap_or_else(|| lens.wavelengths_nm.clone());
        wls.sort_by(|a, b| a.partial_cmp(b).unwrap());
        let mut distances = if opts.object_distances_mm.is_empty() {
            vec![focus_distance_mm]
        } else {
            opts.object_distances_mm.clone()
        };
        distances.sort_by(|a, b| {
            vergence_per_mm(*a)
                .partial_cmp(&vergence_per_mm(*b))
                .unwrap()
        });
        distances.dedup();
        let lenses: Vec<LensPrescription> = distances
            .iter()
            .map(|d| focused.with_object_distance(*d))
            .collect();
        let max_deg = opts
            .max_field_deg
            .unwrap_or_else(|| lens.fields_deg.iter().cloned().fold(0.0, f64::max));
        if opts.paraxial_heights_mm.is_none() && !(max_deg > 0.0) {
            return Err(bad(format!("maximum field {max_deg}° must be > 0")));
        }
        // Paraxial height is linear in tan θ at every distance.
        let per_tan: Vec<f64> = lenses
            .iter()
            .map(|l| l.paraxial_image_mm_per_tan(lens.primary_nm))
            .collect::<Result<_, _>>()?;
        let paraxial_height_mm: Vec<f64> = match &opts.paraxial_heights_mm {
            Some(hs) => hs.clone(),
            None => {
                let hmax = per_tan[0] * max_deg.to_radians().tan();
                (0..opts.n_fields)
                    .map(|k| hmax * k as f64 / (opts.n_fields - 1) as f64)
                    .collect()
            }
        };
        let angles: Vec<Vec<f64>> = per_tan
            .iter()
            .map(|pt| {
                paraxial_height_mm
                    .iter()
                    .map(|h| (h / pt).atan().to_degrees())
                    .collect()
            })
            .collect();
        let (nd, nf, nw) = (distances.len(), paraxial_height_mm.len(), wls.len());
        // Every (distance, field, wavelength) entry in parallel.
        let entries: Vec<Entry> = (0..nd * nf * nw)
            .into_par_iter()
            .map(|i| {
                let (d, f, w) = (i / (nf * nw), (i / nw) % nf, i % nw);
                entry(&lenses[d], angles[d][f], wls[w], opts, psf_n)
            })
            .collect::<Result<_, _>>()?;
        // Relative illumination of every (distance, field, wavelength) entry where its real
        // chief ray lands: film-side, or the entrance-pupil estimate for a lens with mirrors.
        let points: Vec<(f64, f64)> = entries
            .iter()
            .enumerate()
            .map(|(i, e)| (e.real_height_mm.abs(), wls[i % nw]))
            .collect();
        let ri: Vec<f64> =
            match crate::pupil::film_relative_illumination(&focused, &points, opts.ri_grid_n) {
                Ok(v) => v,
                Err(_) => (0..nd * nf * nw)
                    .into_par_iter()
                    .map(|i| {
                        let (d, f, w) = (i / (nf * nw), (i / nw) % nf, i % nw);
                        lenses[d]
                            .relative_illumination(angles[d][f], wls[w], opts.ri_grid_n)
                            .map(|r| r.relative_illumination)
                    })
                    .collect::<Result<_, _>>()?,
            };
        // the film-side camera-equation factor (refused lenses, e.g. with mirrors: unknown)
        let axial_irradiance_sr =
            crate::pupil::axial_irradiance_per_radiance_sr(&focused, &wls).unwrap_or_default();
        let aliased_entries = entries.iter().filter(|e| e.aliased).count();
        let mut entries = entries.into_iter();
        let mut tables = Vec::with_capacity(nd);
        for (d, l) in lenses.iter().enumerate() {
            let fo_d = l.first_order(lens.primary_nm)?;
            let mut real_height_mm = Vec::with_capacity(nf);
            let mut psf = Vec::with_capacity(nf);
            for _ in 0..nf {
                let mut hs = Vec::with_capacity(nw);
                let mut ps = Vec::with_capacity(nw);
                for _ in 0..nw {
                    let e = entries.next().unwrap();
                    hs.push(e.real_height_mm);
                    ps.push(e.psf);
                }
                real_height_mm.push(hs);
                psf.push(ps);
            }
            tables.push(FieldTable {
                object_distance_mm: distances[d],
                working_f_number: fo_d.working_f_number,
                magnification: fo_d.magnification,
                wavelengths_nm: wls.clone(),
                paraxial_height_mm: paraxial_height_mm.clone(),
                field_angles_deg: angles[d].clone(),
                real_height_mm,
                relative_illumination: (0..nf)
                    .map(|f| ri[(d * nf + f) * nw..(d * nf + f + 1) * nw].to_vec())
                    .collect(),
                psf_n,
                psf_pitch_um: opts.psf_pitch_um,
                psf,
            });
        }
        Ok(FieldModel {
            lens_name: lens.name.clone(),
            psf_kind: opts.kind,
            focus_distance_mm,
            image_distance_mm,
            efl_mm: fo.efl_mm,
            f_number: fo.f_number,
            primary_nm: lens.primary_nm,
            wavelengths_nm: wls,
            paraxial_height_mm,
            psf_n,
            psf_pitch_um: opts.psf_pitch_um,
            tables,
            axial_irradiance_sr,
            aliased_entries,
        })
    }

    /// [`FieldModel::axial_irradiance_sr`] at `wavelength_nm`, linear between the tabulated
    /// wavelengths (the end values outside); `None` when unknown.
    pub fn axial_irradiance_sr_at(&self, wavelength_nm: f64) -> Option<f64> {
        let (w, e) = (&self.wavelengths_nm, &self.axial_irradiance_sr);
        if e.is_empty() || e.len() != w.len() || e.iter().any(|x| !(x.is_finite() && *x > 0.0)) {
            return None;
        }
        let (i, t) = bracket(w, wavelength_nm);
        Some(if i + 1 < e.len() {
            (1.0 - t) * e[i] + t * e[i + 1]
        } else {
            e[i]
        })
    }

    /// Object distances of the tables (mm, `None` = infinity), by increasing vergence.
    pub fn object_distances_mm(&self) -> Vec<Option<f64>> {
        self.tables.iter().map(|t| t.object_distance_mm).collect()
    }

    /// The table of an object at `object_distance_mm` (`None` = infinity): the tabulated one
    /// if present, else the two bracketing tables blended linearly in vergence 1/d (PSFs
    /// renormalised), the nearest one outside the tabulated range (see the module docs).
    pub fn at_distance(&self, object_distance_mm: Option<f64>) -> FieldTable {
        let v = vergence_per_mm(object_distance_mm);
        let vs: Vec<f64> = self
            .tables
            .iter()
            .map(|t| vergence_per_mm(t.object_distance_mm))
            .collect();
        if let Some(i) = vs.iter().position(|&x| x == v) {
            return self.tables[i].clone();
        }
        let (i, t) = bracket(&vs, v);
        if t == 0.0 || self.tables.len() == 1 {
            return self.tables[i].clone();
        }
        if t == 1.0 {
            return self.tables[i + 1].clone();
        }
        let (a, b) = (&self.tables[i], &self.tables[i + 1]);
        let lin = |x: f64, y: f64| (1.0 - t) * x + t * y;
        let lin_v = |x: &[f64], y: &[f64]| -> Vec<f64> {
            x.iter().zip(y).map(|(p, q)| lin(*p, *q)).collect()
        };
        FieldTable {
            object_distance_mm,
            working_f_number: lin(a.working_f_number, b.working_f_number),
            magnification: lin(a.magnification, b.magnification),
            wavelengths_nm: a.wavelengths_nm.clone(),
            paraxial_height_mm: a.paraxial_height_mm.clone(),
            field_angles_deg: lin_v(&a.field_angles_deg, &b.field_angles_deg),
            real_height_mm: a
                .real_height_mm
                .iter()
                .zip(&b.real_height_mm)
                .map(|(x, y)| lin_v(x, y))
                .collect(),
            relative_illumination: a
                .relative_illumination
                .iter()
                .zip(&b.relative_illumination)
                .map(|(x, y)| lin_v(x, y))
                .collect(),
            psf_n: a.psf_n,
            psf_pitch_um: a.psf_pitch_um,
            psf: a
                .psf
                .iter()
                .zip(&b.psf)
                .map(|(fa, fb)| {
                    fa.iter()
                        .zip(fb)
                        .map(|(x, y)| {
                            let mut p = lin_v(x, y);
                            normalise(&mut p);
                            p
                        })
                        .collect()
                })
                .collect(),
        }
    }

    /// Write the model as JSON, format version 2 (see the module docs).
    pub fn save(&self, path: impl AsRef<Path>) -> Result<(), LensError> {
        let p = path.as_ref();
        let f = FileV2 {
            format: FORMAT.into(),
            version: VERSION,
            lens_name: self.lens_name.clone(),
            psf_kind: self.psf_kind,
            focus_distance_mm: self.focus_distance_mm,
            image_distance_mm: self.image_distance_mm,
            efl_mm: self.efl_mm,
            f_number: self.f_number,
            primary_nm: self.primary_nm,
            wavelengths_nm: self.wavelengths_nm.clone(),
            paraxial_height_mm: self.paraxial_height_mm.clone(),
            psf_n: self.psf_n,
            psf_pitch_um: self.psf_pitch_um,
            distances: self
                .tables
                .iter()
                .map(|t| DistanceFile {
                    object_distance_mm: t.object_distance_mm,
                    working_f_number: t.working_f_number,
                    magnification: t.magnification,
                    field_angles_deg: t.field_angles_deg.clone(),
                    real_height_mm: t.real_height_mm.clone(),
                    relative_illumination: (0..t.relative_illumination.len())
                        .map(|k| t.relative_illumination_at_field(k, self.primary_nm))
                        .collect(),
                    relative_illumination_by_wavelength: t.relative_illumination.clone(),
                    psf: t.psf.clone(),
                })
                .collect(),
            axial_irradiance_sr: self.axial_irradiance_sr.clone(),
        };
        let text = serde_json::to_string(&f)?;
        std::fs::write(p, text).map_err(|e| LensError::Io {
            path: p.display().to_string(),
            msg: e.to_string(),
        })
    }

    /// Read a model written by [`FieldModel::save`] (version 2) or by an earlier camsim
    /// (version 1), checking the table shapes.
    pub fn load(path: impl AsRef<Path>) -> Result<Self, LensError> {
        let p = path.as_ref();
        let bad = |msg: String| LensError::Io {
            path: p.display().to_string(),
            msg,
        };
        let text = std::fs::read_to_string(p).map_err(|e| bad(e.to_string()))?;
        let v: Value =
            serde_json::from_str(&text).map_err(|e| bad(format!("not valid JSON: {e}")))?;
        let format = v.get("format").and_then(Value::as_str).unwrap_or("");
        let version = v.get("version").and_then(Value::as_u64);
        if format != FORMAT {
            return Err(bad(format!(
                "\"format\" = {:?} (expected \"{FORMAT}\")",
                v.get("format")
            )));
        }
        let m = match version {
            Some(2) => {
                let f: FileV2 = serde_json::from_value(v).map_err(|e| bad(e.to_string()))?;
                let nw = f.wavelengths_nm.len();
                let tables = f
                    .distances
                    .into_iter()
                    .map(|d| FieldTable {
                        object_distance_mm: d.object_distance_mm,
                        working_f_number: d.working_f_number,
                        magnification: d.magnification,
                        wavelengths_nm: f.wavelengths_nm.clone(),
                        paraxial_height_mm: f.paraxial_height_mm.clone(),
                        field_angles_deg: d.field_angles_deg,
                        real_height_mm: d.real_height_mm,
                        relative_illumination: if d.relative_illumination_by_wavelength.is_empty() {
                            per_field_at_every_wavelength(&d.relative_illumination, nw)
                        } else {
                            d.relative_illumination_by_wavelength
                        },
                        psf_n: f.psf_n,
                        psf_pitch_um: f.psf_pitch_um,
                        psf: d.psf,
                    })
                    .collect();
                FieldModel {
                    lens_name: f.lens_name,
                    psf_kind: f.psf_kind,
                    focus_distance_mm: f.focus_distance_mm,
                    image_distance_mm: f.image_distance_mm,
                    efl_mm: f.efl_mm,
                    f_number: f.f_number,
                    primary_nm: f.primary_nm,
                    wavelengths_nm: f.wavelengths_nm,
                    paraxial_height_mm: f.paraxial_height_mm,
                    psf_n: f.psf_n,
                    psf_pitch_um: f.psf_pitch_um,
                    tables,
                    axial_irradiance_sr: f.axial_irradiance_sr,
                    aliased_entries: 0,
                }
            }
            Some(1) => {
                let f: FileV1 = serde_json::from_value(v).map_err(|e| bad(e.to_string()))?;
                // Version 1 did not store the working F-number; the infinite-conjugate value
                // is exact for an object at infinity, (1 − m)·N otherwise is not recoverable
                // without the lens, so the F-number is kept (as version 1 readers used it).
                let table = FieldTable {
                    object_distance_mm: f.object_distance_mm,
                    working_f_number: f.f_number,
                    magnification: 0.0,
                    wavelengths_nm: f.wavelengths_nm.clone(),
                    paraxial_height_mm: f.paraxial_height_mm.clone(),
                    field_angles_deg: f.field_angles_deg,
                    real_height_mm: f.real_height_mm,
                    relative_illumination: per_field_at_every_wavelength(
                        &f.relative_illumination,
                        f.wavelengths_nm.len(),
                    ),
                    psf_n: f.psf_n,
                    psf_pitch_um: f.psf_pitch_um,
                    psf: f.psf,
                };
                FieldModel {
                    lens_name: f.lens_name,
                    psf_kind: f.psf_kind,
                    focus_distance_mm: f.object_distance_mm,
                    image_distance_mm: f.image_distance_mm,
                    efl_mm: f.efl_mm,
                    f_number: f.f_number,
                    primary_nm: f.primary_nm,
                    wavelengths_nm: f.wavelengths_nm,
                    paraxial_height_mm: f.paraxial_height_mm,
                    psf_n: f.psf_n,
                    psf_pitch_um: f.psf_pitch_um,
                    tables: vec![table],
                    axial_irradiance_sr: Vec::new(),
                    aliased_entries: 0,
                }
            }
            _ => {
                return Err(bad(format!(
                    "\"version\" = {:?} (this camsim reads versions 1 and 2)",
                    v.get("version")
                )))
            }
        };
        m.check_shapes().map_err(bad)?;
        Ok(m)
    }

    /// Check that every table matches the field / wavelength / PSF grids.
    fn check_shapes(&self) -> Result<(), String> {
        let (nf, nw, nn) = (
            self.paraxial_height_mm.len(),
            self.wavelengths_nm.len(),
            self.psf_n * self.psf_n,
        );
        if nf == 0 || nw == 0 || self.tables.is_empty() || self.psf_n == 0 {
            return Err("empty field, wavelength, distance or PSF grid".into());
        }
        for (i, t) in self.tables.iter().enumerate() {
            let ok = t.field_angles_deg.len() == nf
                && t.relative_illumination.len() == nf
                && t.relative_illumination.iter().all(|r| r.len() == nw)
                && t.real_height_mm.len() == nf
                && t.real_height_mm.iter().all(|r| r.len() == nw)
                && t.psf.len() == nf
                && t.psf
                    .iter()
                    .all(|f| f.len() == nw && f.iter().all(|p| p.len() == nn));
            if !ok {
                return Err(format!(
                    "distance {i}: table shapes do not match {nf} fields × {nw} wavelengths × {}² PSF samples",
                    self.psf_n
                ));
            }
        }
        Ok(())
    }
}

impl FieldTable {
    /// PSF of a field on +y at paraxial image height `height_mm` and `wavelength_nm`,
    /// bilinearly interpolated between the tabulated heights and wavelengths (clamped at the
    /// table ends), renormalised to sum 1.
    pub fn psf_on_y(&self, height_mm: f64, wavelength_nm: f64) -> Vec<f64> {
        let (i, s) = bracket(&self.paraxial_height_mm, height_mm.abs());
        let (j, t) = bracket(&self.wavelengths_nm, wavelength_nm);
        let nn = self.psf_n * self.psf_n;
        if (s == 0.0 || s == 1.0) && (t == 0.0 || t == 1.0) {
            // Exactly on a tabulated point: the table entry itself.
            let fi = if s == 1.0 { i + 1 } else { i };
            let wj = if t == 1.0 { j + 1 } else { j };
            return self.psf[fi][wj].clone();
        }
        let mut out = vec![0.0; nn];
        let i1 = (i + 1).min(self.paraxial_height_mm.len() - 1);
        let j1 = (j + 1).min(self.wavelengths_nm.len() - 1);
        for (fi, fw) in [(i, 1.0 - s), (i1, s)] {
            for (wj, ww) in [(j, 1.0 - t), (j1, t)] {
                let w = fw * ww;
                if w == 0.0 {
                    continue;
                }
                for (o, v) in out.iter_mut().zip(&self.psf[fi][wj]) {
                    *o += w * v;
                }
            }
        }
        normalise(&mut out);
        out
    }

    /// PSF of the image point (x, y) mm (paraxial image-plane position) at `wavelength_nm`:
    /// the interpolated +y PSF at r = √(x² + y²) rotated by its azimuth − 90°.
    pub fn psf_at(&self, x_mm: f64, y_mm: f64, wavelength_nm: f64) -> Vec<f64> {
        let r = x_mm.hypot(y_mm);
        let p = self.psf_on_y(r, wavelength_nm);
        if r == 0.0 {
            return p;
        }
        let az = y_mm.atan2(x_mm).to_degrees();
        rotate_psf(&p, self.psf_n, az - 90.0)
    }

    /// Real chief-ray height (mm) at paraxial height `height_mm` and `wavelength_nm`
    /// (bilinear in the tables).
    pub fn real_height_mm_at(&self, height_mm: f64, wavelength_nm: f64) -> f64 {
        let (i, s) = bracket(&self.paraxial_height_mm, height_mm.abs());
        let (j, t) = bracket(&self.wavelengths_nm, wavelength_nm);
        let i1 = (i + 1).min(self.paraxial_height_mm.len() - 1);
        let j1 = (j + 1).min(self.wavelengths_nm.len() - 1);
        let r = &self.real_height_mm;
        (1.0 - s) * ((1.0 - t) * r[i][j] + t * r[i][j1])
            + s * ((1.0 - t) * r[i1][j] + t * r[i1][j1])
    }

    /// Distortion % at tabulated field `k` and wavelength index `j` (0 on axis, where both
    /// heights vanish).
    pub fn distortion_pct(&self, k: usize, j: usize) -> f64 {
        let p = self.paraxial_height_mm[k];
        if p == 0.0 {
            0.0
        } else {
            100.0 * (self.real_height_mm[k][j].abs() - p) / p
        }
    }

    /// Relative illumination at paraxial height `height_mm` and `wavelength_nm` (bilinear in
    /// the table, clamped at its ends).
    pub fn relative_illumination_at(&self, height_mm: f64, wavelength_nm: f64) -> f64 {
        let (i, s) = bracket(&self.paraxial_height_mm, height_mm.abs());
        let i1 = (i + 1).min(self.paraxial_height_mm.len() - 1);
        (1.0 - s) * self.relative_illumination_at_field(i, wavelength_nm)
            + s * self.relative_illumination_at_field(i1, wavelength_nm)
    }

    /// Relative illumination of tabulated field `k` at `wavelength_nm` (linear between the
    /// tabulated wavelengths, clamped at the ends).
    pub fn relative_illumination_at_field(&self, k: usize, wavelength_nm: f64) -> f64 {
        let (j, t) = bracket(&self.wavelengths_nm, wavelength_nm);
        let j1 = (j + 1).min(self.wavelengths_nm.len() - 1);
        let r = &self.relative_illumination[k];
        (1.0 - t) * r[j] + t * r[j1]
    }
}
