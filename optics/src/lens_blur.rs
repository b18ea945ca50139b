//! `Blur::Lens`: the ISET ray-trace image-formation method (Farrell, Catrysse & Wandell,
//! "Digital camera simulation", Applied Optics 2012, §2.B.3): a lens prescription is turned
//! into a [`FieldModel`] (PSFs, real vs paraxial chief-ray heights and relative illumination
//! tabulated over field height × wavelength × object distance, see
//! `camsim_lens::field_model`); the table of the scene's object distance (a [`FieldTable`],
//! interpolated in 1/d between tabulated distances) is what
//! [`form_image`](crate::form_image) applies per wavelength band:
//!
//! 1. **Geometric distortion.** The scene is given on the ideal (paraxial) image grid. Each
//!    output sample at image height r takes the (bilinearly sampled) scene value at the
//!    paraxial height r_p with `real_height(r_p, λ) = r`, on the same azimuth. The real/paraxial
//!    ratio q = real/paraxial is interpolated linearly in r_p² between the tabulated fields (exact
//!    for third-order distortion), so the wavelength dependence of the table gives lateral
//!    colour. As in ISET no Jacobian is applied (the irradiance is resampled, not redistributed).
//!    The simulated image is not inverted (as in ISET): a scene point at azimuth φ lands at
//!    azimuth φ.
//! 2. **Relative illumination.** The lens's own relative illumination at r_p and the band's
//!    wavelength **replaces** `OpticsModel::relative_illumination` (which is ignored for this
//!    blur kind: the traced value already contains the cos⁴ fall-off): the film irradiance of a
//!    uniform-radiance scene where the real chief ray of r_p lands over the axial one, traced
//!    from the film through the lens with its physical stop at that wavelength
//!    (`camsim_lens::pupil::film_relative_illumination`: vignetting, cos⁴ and the pupil's
//!    aberrations, which change with wavelength; the entrance-pupil estimate
//!    `LensPrescription::relative_illumination` for a lens with mirrors). Interpolated
//!    linearly in r_p² and in wavelength between the tabulated ones (clamped at the ends), held
//!    constant beyond the table.
//! 3. **Camera equation.** The film irradiance per unit radiance on the axis traced from the
//!    film through the lens with its physical stop, E/L = ∫ cos⁴θ/d² dA over the rear-plane
//!    points whose rays get through, at the band's wavelength
//!    (`FieldModel::axial_irradiance_sr`, `camsim_lens::pupil::axial_irradiance_per_radiance_sr`;
//!    the integral the path tracer's real-lens camera samples). It holds what the paraxial
//!    Eq. 1, π/(4N_w²), leaves out: the real pupil's spherical aberration and its change with
//!    wavelength, and a film the focus model moved from the paraxial image (the double Gauss
//!    50 mm focused on 1.5 m: +1.0 to +2.5 % at f/2–f/8 from 680 to 420 nm). A model without
//!    it (a file written before, a lens with mirrors) uses Eq. 1 with the lens's *working*
//!    F-number at the object distance of the table (paraxial, 1/(2n'u') of the marginal ray;
//!    it carries the (1 + |m|) factor of a finite conjugate). The `OpticsModel` `f_number` and
//!    `focal_length_m` are not used. `CameraEquation::IsetCam` is honoured (Eq. 1 as ISETCam).
//! 4. **Shift-variant PSF.** The image is split into square tiles (32–64 samples); every tile is
//!    convolved (FFT, zero-padded, overlap-add) with the field model's PSF at the tile centre's
//!    paraxial field height and the band's wavelength (bilinear in height × wavelength), oriented
//!    to the tile's azimuth and resampled to the scene pitch (bilinear splatting when the PSF
//!    is finer than the scene, bilinear interpolation otherwise), normalised to sum 1. Each
//!    source sample spreads exactly its own energy, so the total is conserved; with
//!    `Padding::Replicate` the image is continued by edge replication (tiles of the continued
//!    border use the PSF of the nearest image position), so a uniform image stays uniform
//!    wherever the PSF varies slowly. PSFs are centred on the real chief ray (the distortion of
//!    step 1 places the chief ray), so a point source lands on its traced chief ray plus the
//!    PSF's own (e.g. coma) centroid offset.
//!
//! ## Where the field model comes from
//! [`LensBlur::from_prescription`] computes it when the camera is loaded (config `"lens"`
//! kind) for one object distance, `LensBlurOptions::object_distance_mm` (config:
//! `optics.object_distance_m`; default the prescription's own `object_distance_mm`, infinity
//! when null). The lens is focused at the distance `LensBlurOptions::focus` gives (by default
//! on that object, as a camera focused on its subject, or at a fixed distance, in which case
//! the object is defocused) by the focus model `camsim_lens::focus_model` with
//! `LensBlurOptions::focus_method` (default: best polychromatic MTF, weighted over the field
//! the model covers, unit motion). A saved model
//! with several distances is used through [`LensBlur::from_model_at`]. The fields are chosen
//! so that the tabulated **real** heights cover
//! `LensBlurOptions::max_image_height_mm` (config: the sensor's half-diagonal) with 10 %
//! to spare; beyond the table distortion is extrapolated (last segment of q(r_p²)) and PSFs
//! and illumination are those of the last field. The PSF grid is sized from traced spots: its
//! half-width covers the largest ray distance from the chief ray plus 4 λN_w of diffraction
//! tail. Wave (FFT) PSFs are used when a pupil grid of at most `max_wave_pupil_n` samples
//! resolves that window without aliasing, otherwise geometric (ray-bin) PSFs, which is the
//! right limit for spots much larger than the Airy disc.
use crate::error::OpticsError;
use crate::fft::next_smooth;
use crate::{
    camera_equation_factor, camera_equation_factor_isetcam, CameraEquation, OpticsModel, Padding,
};
use camsim_core::{SpectralImage, Spectrum, WavelengthGrid};
use camsim_lens::analysis::pupil_grid;
use camsim_lens::field_model::{FieldTable, Focus};
use camsim_lens::{
    Clipping, FieldModel, FieldModelOptions, FocusMethod, FocusSpec, FocusedLens, LensPrescription,
    PsfKind,
};
use rayon::prelude::*;
use rustfft::num_complex::Complex64;
use rustfft::{Fft, FftPlanner};
use std::sync::Arc;

/// Grid per side of the relative-illumination integrals of [`LensBlur::from_prescription`]
/// (`FieldModelOptions::ri_grid_n`).
const RI_GRID_N: usize = 128;

/// How [`LensBlur::from_prescription`] builds the field model.
#[derive(Debug, Clone, PartialEq)]
pub struct LensBlurOptions {
    /// Largest real image height (mm) the model must cover (e.g. the sensor half-diagonal).
    pub max_image_height_mm: f64,
    /// Tabulated field heights (≥ 2), evenly spaced in paraxial height.
    pub n_fields: usize,
    /// Tabulated wavelengths (nm); bands outside use the nearest end.
    pub wavelengths_nm: Vec<f64>,
    /// PSF kind; `None` = automatic (wave when the pupil grid suffices, see the module docs).
    pub kind: Option<PsfKind>,
    /// Largest pupil grid for wave PSFs in the automatic choice.
    pub max_wave_pupil_n: usize,
    /// Samples per side of the stored PSFs are chosen to be at most about this many.
    pub max_psf_n: usize,
    /// Fields of the dense distortion / relative-illumination table (chief rays only).
    pub n_dense_fields: usize,
    /// Object distance from the first vertex (mm); `None` = the prescription's own
    /// `object_distance_mm` (infinity when that is null).
    pub object_distance_mm: Option<f64>,
    /// Where the lens is focused.
    pub focus: LensFocus,
    /// How it is focused (`camsim_lens::focus_model`): criterion, motion, merit frequency
    /// (camera: half the pixel Nyquist). The merit's maximum field is this model's (covering
    /// `max_image_height_mm`) unless set.
    pub focus_method: FocusMethod,
}

/// The focus distance of a [`LensBlur`] (the method is [`LensBlurOptions::focus_method`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum LensFocus {
    /// On the object.
    #[default]
    OnObject,
    /// On the prescription's own object distance (objects elsewhere are defocused).
    Prescription,
    /// On an object at this distance (mm from the first vertex; `None` = infinity).
    At(Option<f64>),
}

impl LensBlurOptions {
    /// Defaults covering real image heights up to `max_image_height_mm`: 6 fields,
    /// 400–700 nm in 50 nm steps, automatic PSF kind.
    pub fn covering(max_image_height_mm: f64) -> Self {
        LensBlurOptions {
            max_image_height_mm,
            n_fields: 6,
            wavelengths_nm: (0..7).map(|i| 400.0 + 50.0 * i as f64).collect(),
            kind: None,
            max_wave_pupil_n: 160,
            max_psf_n: 97,
            n_dense_fields: 41,
            object_distance_mm: None,
            focus: LensFocus::OnObject,
            focus_method: FocusMethod::default(),
        }
    }
}

/// A lens given by its ray-trace field model (see the module docs).
#[derive(Clone, PartialEq)]
pub struct LensBlur {
    /// The tabulated field model.
    pub model: Arc<FieldModel>,
    /// The model's table at the object distance in use (what image formation looks up).
    pub table: Arc<FieldTable>,
    /// Working F-number of the lens at its conjugates (camera equation).
    pub working_f_number: f64,
    /// Apply the PSFs (false: distortion and relative illumination only, ISET's geometry step).
    pub apply_psf: bool,
    /// A denser table of distortion and relative illumination than the field model's (traced
    /// by [`LensBlur::from_prescription`]); `None`: the field model's tables are used.
    pub radial: Option<Arc<RadialTable>>,
    /// How the lens was focused (`None` for a loaded field model).
    pub focus: Option<Arc<FocusedLens>>,
}

/// Real chief-ray heights and relative illumination on a dense set of fields (same conventions
/// as the field model: evenly spaced paraxial heights, heights `[field][wavelength]`).
#[derive(Debug, Clone, PartialEq)]
pub struct RadialTable {
    /// Paraxial image heights (mm, increasing from 0).
    pub paraxial_height_mm: Vec<f64>,
    /// Wavelengths (nm, increasing).
    pub wavelengths_nm: Vec<f64>,
    /// Real chief-ray heights `[field][wavelength]` (mm, signed as traced).
    pub real_height_mm: Vec<Vec<f64>>,
    /// Relative illumination `[field][wavelength]` (1 on axis; as the field model's).
    pub relative_illumination: Vec<Vec<f64>>,
}

impl std::fmt::Debug for LensBlur {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let m = &self.model;
        f.debug_struct("LensBlur")
            .field("lens", &m.lens_name)
            .field("object_distance_mm", &self.table.object_distance_mm)
            .field("focus_distance_mm", &m.focus_distance_mm)
            .field("psf_kind", &m.psf_kind)
            .field("efl_mm", &m.efl_mm)
            .field("working_f_number", &self.working_f_number)
            .field("max_paraxial_height_mm", &m.paraxial_height_mm.last())
            .field("wavelengths_nm", &m.wavelengths_nm)
            .field("psf_n", &m.psf_n)
            .field("psf_pitch_um", &m.psf_pitch_um)
            .field("apply_psf", &self.apply_psf)
            .finish()
    }
}

fn lens_err(e: impl std::fmt::Display) -> OpticsError {
    OpticsError::Lens(e.to_string())
}

impl LensBlur {
    /// A lens blur from an existing field model (e.g. `FieldModel::load`) for an object at
    /// the model's focus distance (the nearest tabulated distance if that one is absent).
    pub fn from_model(model: FieldModel) -> Self {
        let d = model.focus_distance_mm;
        Self::from_model_at(model, d)
    }

    /// A lens blur from an existing field model for an object at `object_distance_mm` (`None`
    /// = infinity): the model's table there, interpolated in 1/d between tabulated distances
    /// (`FieldModel::at_distance`). The working F-number is the table's.
    pub fn from_model_at(model: FieldModel, object_distance_mm: Option<f64>) -> Self {
        let table = model.at_distance(object_distance_mm);
        LensBlur {
            working_f_number: table.working_f_number,
            table: Arc::new(table),
            model: Arc::new(model),
            apply_psf: true,
            radial: None,
            focus: None,
        }
    }

    /// Compute the field model of `lens` at `opts.object_distance_mm` and focus `opts.focus`,
    /// covering `opts.max_image_height_mm` (see the module docs).
    pub fn from_prescription(
        lens: &LensPrescription,
        opts: &LensBlurOptions,
    ) -> Result<Self, OpticsError> {
        let r = opts.max_image_height_mm;
        if !(r.is_finite() && r > 0.0) {
            return Err(OpticsError::InvalidParameter {
                name: "max_image_height_mm",
                value: r,
                reason: "must be a finite number > 0",
            });
        }
        if opts.wavelengths_nm.is_empty() || opts.n_fields < 2 {
            return Err(lens_err("need at least one wavelength and two fields"));
        }
        let name = if lens.name.is_empty() {
            "lens".to_string()
        } else {
            format!("lens \"{}\"", lens.name)
        };
        let ctx = |e: camsim_lens::LensError| lens_err(format!("{name}: {e}"));
        if let Some(d) = opts.object_distance_mm {
            if !(d.is_finite() && d > 0.0) {
                return Err(OpticsError::InvalidParameter {
                    name: "object_distance_mm",
                    value: d,
                    reason: "must be a finite number > 0",
                });
            }
        }
        let object_mm = opts.object_distance_mm.or(lens.object_distance_mm);
        let focus_mm = match opts.focus {
            LensFocus::OnObject => object_mm,
            LensFocus::Prescription => lens.object_distance_mm,
            LensFocus::At(d) => d,
        };
        // The lens at its focus setting (camsim_lens::focus_model), imaging the object
        // (defocused unless they coincide). The merit covers the field of the model: estimated
        // from the paraxially focused lens (tan θ = 1.1 r / (image height per unit tan θ)).
        let mut method = opts.focus_method.clone();
        if method.max_field_deg.is_none() {
            let p = lens.focus_at(focus_mm).map_err(ctx)?;
            let per_tan = p.paraxial_image_mm_per_tan(lens.primary_nm).map_err(ctx)?;
            method.max_field_deg = Some((1.1 * r / per_tan).atan().to_degrees());
        }
        let focus = lens
            .focus(&FocusSpec {
                focus_distance_mm: focus_mm,
                method,
            })
            .map_err(ctx)?;
        let focused = focus.lens.with_object_distance(object_mm);
        let image_mm = focused.image_distance_mm();
        if !(image_mm.is_finite() && image_mm > 0.0) {
            return Err(lens_err(format!(
                "{name}: focused on {}, the paraxial image is not real (image distance {image_mm} mm)",
                focus_mm.map_or("infinity".to_string(), |d| format!("{d} mm"))
            )));
        }
        let fo = focused.first_order(lens.primary_nm).map_err(ctx)?;
        let nw = fo.working_f_number;
        // Paraxial height is linear in tan θ.
        let per_tan = focused
            .paraxial_image_mm_per_tan(lens.primary_nm)
            .map_err(ctx)?;
        let want = 1.1 * r;
        let mut theta = (want / per_tan).atan().to_degrees();
        // Barrel distortion: the real height falls short of the paraxial one; widen the field.
        for _ in 0..3 {
            let d = focused.distortion(theta).map_err(|e| {
                lens_err(format!(
                    "{name}: cannot trace the field {theta:.2}° needed for image height {want:.3} mm: {e}"
                ))
            })?;
            if d.real_height_mm >= want * 0.999 || d.real_height_mm <= 0.0 {
                break;
            }
            let h = d.paraxial_height_mm * want / d.real_height_mm;
            theta = (h / per_tan).atan().to_degrees();
            if theta >= 89.0 {
                return Err(lens_err(format!(
                    "{name}: image height {want:.3} mm needs a field angle ≥ 89°"
                )));
            }
        }
        // PSF window from traced spots (largest ray distance from the chief ray).
        let mut wls = opts.wavelengths_nm.clone();
        wls.sort_by(|a, b| a.partial_cmp(b).unwrap());
        let (lmin, lmax) = (wls[0], wls[wls.len() - 1]);
        let hmax = per_tan * theta.to_radians().tan();
        let grid = pupil_grid(24);
        let mut extent_mm: f64 = 0.0;
        for k in 0..opts.n_fields {
            let h = hmax * k as f64 / (opts.n_fields - 1) as f64;
            let th = (h / per_tan).atan().to_degrees();
            for &w in &[lmin, lens.primary_nm, lmax] {
                let fan = focused
                    .ray_fan(th, w, w, &grid, Clipping::SemiDiameters)
                    .map_err(ctx)?;
                let Some(chief) = focused.trace(&fan.aim.ray(0.0, 0.0), w, Clipping::None) else {
                    return Err(lens_err(format!(
                        "{name}: chief ray of field {th:.2}° lost at {w} nm"
                    )));
                };
                for p in fan.points_at(0.0) {
                    let d = (p[0] - chief.image_mm[0]).hypot(p[1] - chief.image_mm[1]);
                    extent_mm = extent_mm.max(d);
                }
            }
        }
        let geo_um = extent_mm * 1e3;
        let half_um = geo_um + 4.0 * lmax * 1e-3 * nw;
        let nyquist_um = 0.5 * lmin * 1e-3 * nw;
        // Wave PSF window λ N_w (n − 1) at the shortest wavelength must hold ±half_um.
        let pupil_needed = (2.0 * half_um / (lmin * 1e-3 * nw)).ceil() as usize + 1;
        let kind = opts
            .kind
            .unwrap_or(if pupil_needed <= opts.max_wave_pupil_n {
                PsfKind::Wave
            } else {
                PsfKind::Geometric
            });
        let pitch_um = nyquist_um.max(2.0 * half_um / (opts.max_psf_n.max(9) - 1) as f64);
        let psf_n = 2 * (half_um / pitch_um).ceil() as usize + 1;
        let (pupil_n, pad) = match kind {
            PsfKind::Wave => ((pupil_needed.max(64) + 1) & !1, 2),
            PsfKind::Geometric => (128, 1),
        };
        let fm_opts = FieldModelOptions {
            n_fields: opts.n_fields,
            paraxial_heights_mm: None,
            max_field_deg: Some(theta),
            wavelengths_nm: Some(wls),
            kind,
            psf_n,
            psf_pitch_um: pitch_um,
            pupil_n,
            pad,
            ri_grid_n: RI_GRID_N,
            focus: Focus::Focused(Box::new(focus.clone())),
            object_distances_mm: vec![object_mm],
        };
        let model = FieldModel::compute(lens, &fm_opts).map_err(ctx)?;
        let table = model.at_distance(object_mm);
        // Dense distortion / illumination table (chief rays and pupil grids only: cheap).
        let nd = opts.n_dense_fields.max(opts.n_fields);
        let wls = model.wavelengths_nm.clone();
        let rows: Vec<(f64, Vec<f64>)> = (0..nd)
            .into_par_iter()
            .map(|k| {
                let h = hmax * k as f64 / (nd - 1) as f64;
                let th = (h / per_tan).atan().to_degrees();
                let mut real = Vec::with_capacity(wls.len());
                for &w in &wls {
                    let fo_w = focused.first_order(w).map_err(ctx)?;
                    let aim = focused.aim_field(th, w, &fo_w).map_err(ctx)?;
                    let chief = focused
                        .trace(&aim.ray(0.0, 0.0), w, Clipping::None)
                        .ok_or_else(|| {
                            lens_err(format!(
                                "{name}: chief ray of field {th:.2}° lost at {w} nm"
                            ))
                        })?;
                    real.push(chief.image_mm[1]);
                }
                Ok((h, real))
            })
            .collect::<Result<_, OpticsError>>()?;
        // Relative illumination where each real chief ray lands, per wavelength (as the field
        // model's: film-side, the entrance-pupil estimate for a lens with mirrors).
        let nwl = wls.len();
        let points: Vec<(f64, f64)> = rows
            .iter()
            .flat_map(|(_, real)| real.iter().zip(&wls).map(|(r, w)| (r.abs(), *w)))
            .collect();
        let ri: Vec<f64> =
            match camsim_lens::pupil::film_relative_illumination(&focused, &points, RI_GRID_N) {
                Ok(v) => v,
                Err(_) => (0..points.len())
                    .into_par_iter()
                    .map(|i| {
                        let (k, w) = (i / nwl, wls[i % nwl]);
                        let th = (rows[k].0 / per_tan).atan().to_degrees();
                        focused
                            .relative_illumination(th, w, RI_GRID_N)
                            .map(|r| r.relative_illumination)
                            .map_err(ctx)
                    })
                    .collect::<Result<_, OpticsError>>()?,
            };
        let radial = RadialTable {
            paraxial_height_mm: rows.iter().map(|r| r.0).collect(),
            wavelengths_nm: wls,
            real_height_mm: rows.iter().map(|r| r.1.clone()).collect(),
            relative_illumination: ri.chunks(nwl).map(|c| c.to_vec()).collect(),
        };
        Ok(LensBlur {
            model: Arc::new(model),
            table: Arc::new(table),
            working_f_number: nw,
            apply_psf: true,
            radial: Some(Arc::new(radial)),
            focus: Some(Arc::new(focus)),
        })
    }

    /// Finest detail (µm) the blurred image holds: the PSF pitch or λN_w/2, whichever is larger.
    pub fn detail_um(&self, min_wavelength_nm: f64) -> f64 {
        self.table
            .psf_pitch_um
            .max(0.5 * min_wavelength_nm * 1e-3 * self.working_f_number)
    }

    /// Scene margin (m) needed around an image of half-diagonal `half_diagonal_m`: the PSF
    /// half-width plus the largest inward displacement by distortion (barrel distortion samples
    /// the scene outside the image).
    pub fn margin_m(&self, half_diagonal_m: f64) -> f64 {
        let m = &self.table;
        let psf_half_m = (m.psf_n / 2) as f64 * m.psf_pitch_um * 1e-6 * std::f64::consts::SQRT_2;
        let r_mm = half_diagonal_m * 1e3;
        let shift_mm = m
            .wavelengths_nm
            .iter()
            .map(|&w| Radial::new(self, w).inverse_scalar(r_mm) - r_mm)
            .fold(0.0, f64::max);
        psf_half_m + shift_mm * 1e-3
    }

    /// Real image height (mm) of the paraxial height `paraxial_mm` at `wavelength_nm`, as the
    /// image formation interpolates it.
    pub fn real_height_mm(&self, paraxial_mm: f64, wavelength_nm: f64) -> f64 {
        Radial::new(self, wavelength_nm).forward(paraxial_mm)
    }
}

/// Radial tables of one wavelength: q = real/paraxial and relative illumination (both
/// interpolated linearly in wavelength from the tables), both piecewise linear in the paraxial
/// height squared.
struct Radial {
    u: Vec<f64>,
    q: Vec<f64>,
    uh: Vec<f64>,
    ri: Vec<f64>,
    /// Sign of the real heights (−1: the real image is inverted).
    sign: f64,
}

/// Piecewise-linear interpolation in `xs` (increasing), linear extrapolation at both ends when
/// `extrapolate`, else clamped.
fn interp(xs: &[f64], ys: &[f64], x: f64, extrapolate: bool) -> f64 {
    let n = xs.len();
    if n == 1 {
        return ys[0];
    }
    let i = if x <= xs[0] {
        0
    } else if x >= xs[n - 1] {
        n - 2
    } else {
        xs.partition_point(|&a| a <= x) - 1
    };
    let t = (x - xs[i]) / (xs[i + 1] - xs[i]);
    let t = if extrapolate { t } else { t.clamp(0.0, 1.0) };
    ys[i] + t * (ys[i + 1] - ys[i])
}

impl Radial {
    fn new(lb: &LensBlur, wavelength_nm: f64) -> Self {
        let m = &*lb.table;
        let (h, real, ri) = match &lb.radial {
            Some(t) => {
                let wl = &t.wavelengths_nm;
                let real = t
                    .real_height_mm
                    .iter()
                    .map(|row| interp(wl, row, wavelength_nm, false))
                    .collect();
                let ri = t
                    .relative_illumination
                    .iter()
                    .map(|row| interp(wl, row, wavelength_nm, false))
                    .collect();
                (t.paraxial_height_mm.clone(), real, ri)
            }
            None => (
                m.paraxial_height_mm.clone(),
                m.paraxial_height_mm
                    .iter()
                    .map(|&x| m.real_height_mm_at(x, wavelength_nm))
                    .collect::<Vec<_>>(),
                (0..m.paraxial_height_mm.len())
                    .map(|k| m.relative_illumination_at_field(k, wavelength_nm))
                    .collect(),
            ),
        };
        let nf = h.len();
        let sign = if real[nf - 1] > 0.0 { 1.0 } else { -1.0 };
        let mut u = Vec::with_capacity(nf);
        let mut q = Vec::with_capacity(nf);
        for k in 0..nf {
            if h[k] > 0.0 {
                u.push(h[k] * h[k]);
                q.push(real[k].abs() / h[k]);
            }
        }
        // q on the axis: linear extrapolation in h² from the first two off-axis fields.
        let q0 = if q.len() >= 2 {
            q[0] - (q[1] - q[0]) * u[0] / (u[1] - u[0])
        } else {
            q.first().copied().unwrap_or(1.0)
        };
        u.insert(0, 0.0);
        q.insert(0, q0);
        // Illumination on the full h² grid (including the axis).
        let uh: Vec<f64> = h.iter().map(|x| x * x).collect();
        Radial { u, q, uh, ri, sign }
    }

    fn ratio(&self, paraxial_mm: f64) -> f64 {
        interp(&self.u, &self.q, paraxial_mm * paraxial_mm, true).max(1e-6)
    }

    fn forward(&self, paraxial_mm: f64) -> f64 {
        paraxial_mm * self.ratio(paraxial_mm)
    }

    fn illumination(&self, paraxial_mm: f64) -> f64 {
        interp(&self.uh, &self.ri, paraxial_mm * paraxial_mm, false).max(0.0)
    }

    /// r_p with forward(r_p) = r (bisection; forward made monotone by its running maximum).
    fn inverse_scalar(&self, r: f64) -> f64 {
        let (mut lo, mut hi) = (0.0, r.max(1e-9) / self.ratio(r).max(1e-3));
        let mut n = 0;
        while self.forward(hi) < r && n < 60 {
            hi *= 1.5;
            n += 1;
        }
        for _ in 0..80 {
            let mid = 0.5 * (lo + hi);
            if self.forward(mid) < r {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        0.5 * (lo + hi)
    }

    /// Uniform table of the inverse on [0, r_max] (mm): entry j is r_p at r = j·r_max/(n−1).
    fn inverse_table(&self, r_max: f64, n: usize) -> Vec<f64> {
        (0..n)
            .map(|j| self.inverse_scalar(r_max * j as f64 / (n - 1) as f64))
            .collect()
    }
}

/// Bilinear sample of a `rows × cols` plane at fractional (row, col); outside the plane the
/// edge is replicated (`clamp`) or the value is 0.
fn sample(plane: &[f32], rows: usize, cols: usize, fr: f64, fc: f64, clamp: bool) -> f64 {
    let (r0, c0) = (fr.floor(), fc.floor());
    let (tr, tc) = (fr - r0, fc - c0);
    let get = |r: f64, c: f64| -> f64 {
        let (ri, ci) = (r as isize, c as isize);
        if clamp {
            let ri = ri.clamp(0, rows as isize - 1) as usize;
            let ci = ci.clamp(0, cols as isize - 1) as usize;
            plane[ri * cols + ci] as f64
        } else if ri < 0 || ci < 0 || ri >= rows as isize || ci >= cols as isize {
            0.0
        } else {
            plane[ri as usize * cols + ci as usize] as f64
        }
    };
    get(r0, c0) * (1.0 - tr) * (1.0 - tc)
        + get(r0, c0 + 1.0) * (1.0 - tr) * tc
        + get(r0 + 1.0, c0) * tr * (1.0 - tc)
        + get(r0 + 1.0, c0 + 1.0) * tr * tc
}

/// The stored +y PSF (`n`², pitch `pitch_um`, outward direction `sign`·ŷ) oriented to azimuth
/// `phi` (from the column axis towards the row axis) on a `(2hk+1)²` grid of pitch `dx_um`,
/// normalised to sum 1.
fn oriented_kernel(
    psf: &[f64],
    n: usize,
    pitch_um: f64,
    sign: f64,
    phi: f64,
    dx_um: f64,
    hk: usize,
) -> Vec<f64> {
    let m = 2 * hk + 1;
    let mut k = vec![0.0; m * m];
    let c = (n / 2) as f64;
    let (s, co) = phi.sin_cos();
    let (er, et) = ([co, s], [-s, co]);
    if pitch_um <= dx_um {
        for iy in 0..n {
            for ix in 0..n {
                let v = psf[iy * n + ix];
                if v == 0.0 {
                    continue;
                }
                let tau = (ix as f64 - c) * pitch_um;
                let rho = sign * (iy as f64 - c) * pitch_um;
                let dxp = rho * er[0] + tau * et[0];
                let dyp = rho * er[1] + tau * et[1];
                let (fx, fy) = (dxp / dx_um + hk as f64, dyp / dx_um + hk as f64);
                let (x0, y0) = (fx.floor(), fy.floor());
                let (tx, ty) = (fx - x0, fy - y0);
                for (yy, wy) in [(y0, 1.0 - ty), (y0 + 1.0, ty)] {
                    for (xx, wx) in [(x0, 1.0 - tx), (x0 + 1.0, tx)] {
                        if xx >= 0.0 && yy >= 0.0 && (xx as usize) < m && (yy as usize) < m {
                            k[yy as usize * m + xx as usize] += v * wx * wy;
                        }
                    }
                }
            }
        }
    } else {
        for a in 0..m {
            for b in 0..m {
                let dxp = (b as f64 - hk as f64) * dx_um;
                let dyp = (a as f64 - hk as f64) * dx_um;
                let rho = dxp * er[0] + dyp * er[1];
                let tau = dxp * et[0] + dyp * et[1];
                let ix = tau / pitch_um + c;
                let iy = sign * rho / pitch_um + c;
                let (x0, y0) = (ix.floor(), iy.floor());
                let (tx, ty) = (ix - x0, iy - y0);
                let get = |x: f64, y: f64| {
                    if x < 0.0 || y < 0.0 || x >= n as f64 || y >= n as f64 {
                        0.0
                    } else {
                        psf[y as usize * n + x as usize]
                    }
                };
                k[a * m + b] = get(x0, y0) * (1.0 - tx) * (1.0 - ty)
                    + get(x0 + 1.0, y0) * tx * (1.0 - ty)
                    + get(x0, y0 + 1.0) * (1.0 - tx) * ty
                    + get(x0 + 1.0, y0 + 1.0) * tx * ty;
            }
        }
    }
    let sum: f64 = k.iter().sum();
    if sum > 0.0 {
        k.iter_mut().for_each(|v| *v /= sum);
    } else {
        k[hk * m + hk] = 1.0;
    }
    k
}

/// In-place 2-D FFT of an `l × l` row-major array (rows, then columns).
fn fft2(fft: &dyn Fft<f64>, data: &mut [Complex64], l: usize, col: &mut [Complex64]) {
    for row in data.chunks_mut(l) {
        fft.process(row);
    }
    for x in 0..l {
        for y in 0..l {
            col[y] = data[y * l + x];
        }
        fft.process(col);
        for y in 0..l {
            data[y * l + x] = col[y];
        }
    }
}

/// Image formation for `Blur::Lens` (steps 1–4 of the module docs) of a radiance image;
/// returns the image split into the bands of `bands` ([`crate::split_into_bands`]; irradiance,
/// before any diffuser).
pub(crate) fn form_lens_image(
    optics: &OpticsModel,
    lb: &LensBlur,
    radiance: &SpectralImage,
    bands: &WavelengthGrid,
    dx: f64,
) -> Result<crate::BandSplit, OpticsError> {
    let nw = lb.working_f_number;
    if !(nw.is_finite() && nw > 0.0) {
        return Err(OpticsError::InvalidParameter {
            name: "lens working_f_number",
            value: nw,
            reason: "must be a finite number > 0",
        });
    }
    let mut img = radiance.clone();
    let k_eq = match optics.camera_equation {
        CameraEquation::Baseline => camera_equation_factor(nw, 0.0),
        CameraEquation::IsetCam => camera_equation_factor_isetcam(nw, 0.0),
    };
    let k = k_eq;
    let k = match &optics.transmittance {
        Spectrum::Affine {
            offset,
            slope_per_nm,
        } if *slope_per_nm == 0.0 => k * offset,
        t => {
            img.scale_spectrally(t);
            k
        }
    };
    // Split after the transmittance, as without a lens blur.
    let split = crate::split_into_bands(img, bands, optics.padding == Padding::Zero);
    let (mut img, wl) = (split.image, split.wavelength_nm);
    let (rows, cols) = (img.rows, img.cols);
    let clamp = optics.padding == Padding::Replicate;
    let model = &*lb.table;
    img.planes
        .par_iter_mut()
        .zip(wl.par_iter())
        .for_each(|(plane, &w)| {
            let radial = Radial::new(lb, w);
            // The camera equation of the traced lens: its film irradiance per unit radiance on
            // the axis (`FieldModel::axial_irradiance_sr`, the real pupil and film position)
            // in place of the paraxial π/(4N_w²); ISETCam's form is kept as it is.
            let traced = match optics.camera_equation {
                CameraEquation::Baseline => lb.model.axial_irradiance_sr_at(w),
                CameraEquation::IsetCam => None,
            };
            let k = traced.map_or(k, |e| k / k_eq * e);
            let warped = warp(plane, rows, cols, dx, &radial, k, clamp);
            *plane = if lb.apply_psf {
                shift_variant_blur(&warped, rows, cols, dx, model, &radial, w, clamp)
            } else {
                warped
            };
        });
    Ok(crate::BandSplit {
        image: img,
        wavelength_nm: wl,
    })
}

/// Steps 1–3: distortion (inverse mapping), relative illumination and the scalar factor `k`.
fn warp(
    plane: &[f32],
    rows: usize,
    cols: usize,
    dx: f64,
    radial: &Radial,
    k: f64,
    clamp: bool,
) -> Vec<f32> {
    let yc = (rows as f64 - 1.0) / 2.0;
    let xc = (cols as f64 - 1.0) / 2.0;
    let dx_mm = dx * 1e3;
    let r_max = dx_mm * (yc * yc + xc * xc).sqrt() * 1.001 + 1e-9;
    let nt = 4097;
    let inv = radial.inverse_table(r_max, nt);
    let q0 = radial.q[0].max(1e-6);
    let mut out = vec![0f32; rows * cols];
    out.par_chunks_mut(cols).enumerate().for_each(|(i, row)| {
        let y = (i as f64 - yc) * dx_mm;
        for (j, o) in row.iter_mut().enumerate() {
            let x = (j as f64 - xc) * dx_mm;
            let r = x.hypot(y);
            let t = r / r_max * (nt - 1) as f64;
            let i0 = (t.floor() as usize).min(nt - 2);
            let f = t - i0 as f64;
            let rp = inv[i0] * (1.0 - f) + inv[i0 + 1] * f;
            let g = if r > 0.0 { rp / r } else { 1.0 / q0 };
            let v = sample(
                plane,
                rows,
                cols,
                yc + (i as f64 - yc) * g,
                xc + (j as f64 - xc) * g,
                clamp,
            );
            *o = (v * k * radial.illumination(rp)) as f32;
        }
    });
    out
}

/// Step 4: tiled overlap-add convolution with the PSF of each tile's centre.
#[allow(clippy::too_many_arguments)]
fn shift_variant_blur(
    plane: &[f32],
    rows: usize,
    cols: usize,
    dx: f64,
    model: &FieldTable,
    radial: &Radial,
    wavelength_nm: f64,
    clamp: bool,
) -> Vec<f32> {
    let dx_um = dx * 1e6;
    let n = model.psf_n;
    let c = (n / 2) as f64;
    let hk = ((c * model.psf_pitch_um * std::f64::consts::SQRT_2 / dx_um).ceil() as usize + 1)
        .min(4 * (rows.max(cols)) + 8);
    // Pieces: the source image times bilinear "hat" weights centred on a grid of spacing t
    // (a partition of unity), so the PSF varies piecewise-linearly between piece centres and
    // every source sample spreads exactly its own energy.
    let t = hk.clamp(24, 48);
    let l = next_smooth(2 * t - 1 + 2 * hk);
    let (ext_lo, ext_r, ext_c) = if clamp {
        (-(hk as isize), rows + hk, cols + hk)
    } else {
        (0, rows, cols)
    };
    let yc = (rows as f64 - 1.0) / 2.0;
    let xc = (cols as f64 - 1.0) / 2.0;
    let dx_mm = dx * 1e3;
    let get = |r: isize, c: isize| -> f32 {
        let r = r.clamp(0, rows as isize - 1) as usize;
        let c = c.clamp(0, cols as isize - 1) as usize;
        plane[r * cols + c]
    };
    let centres = |end: usize| -> Vec<isize> {
        let span = (end as isize - 1 - ext_lo).max(0) as usize;
        let a = span.div_ceil(t).max(1);
        (0..=a).map(|i| ext_lo + (i * t) as isize).collect()
    };
    let (cr, cc) = (centres(ext_r), centres(ext_c));
    let mut tiles = Vec::new();
    for &r in &cr {
        for &c in &cc {
            tiles.push((r, c));
        }
    }
    let mut planner = FftPlanner::<f64>::new();
    let fwd = planner.plan_fft_forward(l);
    let inv = planner.plan_fft_inverse(l);
    let norm = 1.0 / (l * l) as f64;
    let min_len = (tiles.len() / (2 * rayon::current_num_threads())).max(1);
    let tf = t as f64;
    tiles
        .par_iter()
        .with_min_len(min_len)
        .fold(
            || {
                (
                    vec![0f64; rows * cols],
                    vec![Complex64::new(0.0, 0.0); l * l],
                    vec![Complex64::new(0.0, 0.0); l * l],
                    vec![Complex64::new(0.0, 0.0); l],
                )
            },
            |(mut acc, mut a, mut b, mut col), &(rc, ccn)| {
                // Piece rows/cols: centre ± (t − 1), inside the (extended) domain.
                let r0 = rc - t as isize + 1;
                let c0 = ccn - t as isize + 1;
                let rlo = r0.max(ext_lo);
                let rhi = (rc + t as isize).min(ext_r as isize);
                let clo = c0.max(ext_lo);
                let chi = (ccn + t as isize).min(ext_c as isize);
                a.iter_mut().for_each(|v| *v = Complex64::new(0.0, 0.0));
                let mut any = false;
                for r in rlo..rhi {
                    let wr = 1.0 - (r - rc).abs() as f64 / tf;
                    for c in clo..chi {
                        let v = get(r, c);
                        if v != 0.0 {
                            any = true;
                            let wc = 1.0 - (c - ccn).abs() as f64 / tf;
                            let (ar, ac) = ((r - r0) as usize + hk, (c - c0) as usize + hk);
                            a[ar * l + ac] = Complex64::new(v as f64 * wr * wc, 0.0);
                        }
                    }
                }
                if !any {
                    return (acc, a, b, col);
                }
                let (r1, c1) = (rc, ccn);
                // PSF at the tile centre (clamped into the image).
                let ic = (r1 as f64).clamp(0.0, rows as f64 - 1.0);
                let jc = (c1 as f64).clamp(0.0, cols as f64 - 1.0);
                let (x, y) = ((jc - xc) * dx_mm, (ic - yc) * dx_mm);
                let rr = x.hypot(y);
                let rp = if rr > 0.0 {
                    radial.inverse_scalar(rr)
                } else {
                    0.0
                };
                let phi = if rr > 0.0 {
                    y.atan2(x)
                } else {
                    std::f64::consts::FRAC_PI_2
                };
                let psf = model.psf_on_y(rp, wavelength_nm);
                let ker = oriented_kernel(&psf, n, model.psf_pitch_um, radial.sign, phi, dx_um, hk);
                let m = 2 * hk + 1;
                b.iter_mut().for_each(|v| *v = Complex64::new(0.0, 0.0));
                for ka in 0..m {
                    for kb in 0..m {
                        let v = ker[ka * m + kb];
                        if v != 0.0 {
                            let ya = (ka + l - hk) % l;
                            let xb = (kb + l - hk) % l;
                            b[ya * l + xb] = Complex64::new(v, 0.0);
                        }
                    }
                }
                fft2(&*fwd, &mut a, l, &mut col);
                fft2(&*fwd, &mut b, l, &mut col);
                for (p, q) in a.iter_mut().zip(b.iter()) {
                    *p *= q;
                }
                fft2(&*inv, &mut a, l, &mut col);
                // a[u][v] is the image sample (r0 − hk + u, c0 − hk + v).
                let span_r = 2 * t - 1 + 2 * hk;
                let span_c = 2 * t - 1 + 2 * hk;
                for u in 0..span_r {
                    let ir = r0 - hk as isize + u as isize;
                    if ir < 0 || ir >= rows as isize {
                        continue;
                    }
                    for v in 0..span_c {
                        let jc = c0 - hk as isize + v as isize;
                        if jc < 0 || jc >= cols as isize {
                            continue;
                        }
                        acc[ir as usize * cols + jc as usize] += a[u * l + v].re * norm;
                    }
                }
                (acc, a, b, col)
            },
        )
        .map(|(acc, ..)| acc)
        .reduce(
            || vec![0f64; rows * cols],
            |mut x, y| {
                x.iter_mut().zip(y).for_each(|(p, q)| *p += q);
                x
            },
        )
        .into_iter()
        .map(|v| v.max(0.0) as f32)
        .collect()
}
