//! # camsim-optics
//!
//! The optics stage of the ISET pipeline (Farrell, Catrysse & Wandell, "Digital camera
//! simulation", Applied Optics 2012, §2.B): scene spectral radiance
//! ([`SceneRadiance`], photons/(s·sr·m²·nm)) → spectral irradiance at the sensor
//! ([`SensorIrradiance`], photons/(s·m²·nm)) on the same grid, centred on the optical axis.
//!
//! [`form_image`] applies, in order:
//! 1. the camera equation (Eq. 1) `E = π T(λ) L / (4 N² (1+|m|)²)` ([`camera_equation_factor`]);
//! 2. relative illumination (off-axis falloff), e.g. `cos⁴θ`, `tan θ = r/f`;
//! 3. the optical blur: the diffraction-limited OTF (Eq. 3, per wavelength band, by FFT,
//!    Eqs. 4–6), a Gaussian or pillbox PSF (wavelength independent, applied to the planes of
//!    the linear model), sampled per-wavelength PSFs ([`PsfSet`]) or a wavefront PSF with
//!    Zernike defocus, or a general pupil ([`WavefrontPupil`]: any OSA Zernike terms, a
//!    measurement pupil, longitudinal chromatic aberration, polygonal apertures);
//!    or, with [`Blur::Lens`], the ISET ray-trace method (§2.B.3) of a lens prescription, which
//!    replaces steps 1–3 (distortion, traced relative illumination, the lens's working
//!    F-number, shift-variant PSFs; see [`LensBlur`]);
//! 4. an optional Gaussian diffuser (§3.A: FWHM = pixel width);
//! 5. the optional effect blocks of `spec/effects.md` ([`effects`], [`OpticsModel::effects`]):
//!    an extra fall-off with step 2, an exposure scale, a distortion / lateral-colour warp
//!    before the blur, a defocus blur and veiling glare after it.
//!
//! The baseline follows the project spec (capture-format.md, step 1). ISETCam conventions are
//! available as explicit options ([`CameraEquation::IsetCam`],
//! [`RelativeIllumination::IsetCam`], [`Padding::Zero`]) to reproduce its oracles; they are
//! never the default.
#![deny(missing_docs)]

mod band_split;
pub mod dual_pixel;
pub mod effects;
mod error;
mod far_tail;
mod fft;
mod formulas;
mod kernels;
mod lens_blur;
mod psf_set;
mod uncropped;
mod wavefront;

pub use band_split::{split_into_bands, BandSplit};
pub use camsim_core::{SceneRadiance, SensorIrradiance, Spectrum, WavelengthGrid};
pub use dual_pixel::{
    dual_pixel_disparity_m, half_disc_centroid_offset_m, half_pupil_psf, PupilHalf,
};
pub use effects::{
    equivalent_gaussian_sigma_um, two_circle_overlap_fraction, Defocus, Distortion, Falloff,
    GlareSums, LateralColor, LateralColorKind, OpticsEffects, RowWindow,
};
pub use error::OpticsError;
pub use formulas::{
    airy_edge_tail_distance_m, airy_edge_tail_fraction, airy_first_zero_m, airy_first_zero_rad,
    airy_psf, airy_psf_tail_envelope, bessel_j1, camera_equation_factor,
    camera_equation_factor_isetcam, diffraction_otf, magnification, relative_illumination_cos4,
    relative_illumination_cos4_r2, relative_illumination_cos4_row, relative_illumination_isetcam,
    sigma_from_fwhm, thin_lens_image_distance_m,
};
pub use kernels::{gaussian_kernel_1d, pillbox_psf, wavefront_psf, SampledPsf};
pub use lens_blur::{LensBlur, LensBlurOptions, LensFocus};
pub use psf_set::PsfSet;
pub use uncropped::{centred_window, form_image_uncropped_window};
pub use wavefront::{
    defocus_um_from_diopters, human_lca_diopters, polygon_area, zernike_osa, zernike_osa_nm,
    ChromaticDefocus, PupilField, WavefrontPupil, ZernikeTerm,
};

use camsim_core::SpectralImage;
use error::check_positive;
use fft::{FftConvolver, Finish, Transfer};

/// Edge-spread tail of the diffraction PSF (at the longest wavelength) left beyond the region
/// over which the FFT diffraction blur with replicated edges takes the scene's edges as
/// replicated to infinity (instead of the FFT's wrap): a border pixel's irradiance is within
/// `FAR_TAIL_FRACTION · E_max` of blurring the replicated scene, per side of the image
/// ([`crate::airy_edge_tail_fraction`]; issue 17 §5; docs/physics.md).
pub const FAR_TAIL_FRACTION: f64 = 5e-4;
use rayon::prelude::*;

/// Off-axis relative illumination R(x).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum RelativeIllumination {
    /// R = 1.
    None,
    /// R = cos⁴θ with tan θ = r / f (r: distance from the image centre, f: focal length).
    #[default]
    Cos4,
    /// ISETCam's `'cos4th'` formula ([`relative_illumination_isetcam`]) with the focal length
    /// as image distance and the thin-lens magnification. Compatibility only.
    IsetCam,
}

/// Which camera equation (Eq. 1) converts radiance to irradiance.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum CameraEquation {
    /// `π T / (4 N² (1+|m|)²)`; the diffraction cutoff uses the working f-number `N (1+|m|)`.
    /// Exactly `π T / (4N²)` and cutoff `1/(λN)` for an object at infinity.
    #[default]
    Baseline,
    /// ISETCam: `π T / (1 + 4 N² (1+|m|)²)`, cutoff `1/(λN)` (focal length, not image
    /// distance). Compatibility only.
    IsetCam,
}

/// How the image is continued outside its borders before blurring.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Padding {
    /// Edge replication (the target "continues" outside): no dark fringe at the borders, and a
    /// uniform scene stays uniform. FFTs are padded by at least the PSF support and rounded up
    /// to sizes 2^a3^b5^c.
    #[default]
    Replicate,
    /// ISETCam (`oiPad` + `opticsOTF`): zero photons, `round(rows/8)` rows and `round(cols/8)`
    /// columns each side, FFT at exactly that size with ISETCam's `unitFrequencyList`
    /// frequency grid, `abs()` after the inverse FFT. Compatibility only.
    Zero,
}

/// The optical blur.
#[derive(Debug, Clone, PartialEq, Default)]
pub enum Blur {
    /// No blur (pinhole-like ideal imaging).
    None,
    /// Diffraction-limited OTF of the f-number per wavelength band (Eq. 3).
    #[default]
    Diffraction,
    /// Wavelength-independent Gaussian PSF of standard deviation `sigma_um`.
    Gaussian {
        /// σ in µm in the image plane.
        sigma_um: f64,
    },
    /// Wavelength-independent uniform disk ("pillbox") PSF of diameter `width_um`.
    Pillbox {
        /// Disk diameter in µm.
        width_um: f64,
    },
    /// Sampled per-wavelength PSFs ([`PsfSet`]).
    Psf(PsfSet),
    /// Circular pupil with Zernike defocus ([`wavefront_psf`]), per wavelength band.
    Wavefront {
        /// Zernike Z(2,0) coefficient = RMS wavefront error (µm).
        defocus_um: f64,
        /// Pupil samples across the diameter (16..=4096; 128 is ample for |defocus| < λ).
        pupil_samples: usize,
    },
    /// A pupil with arbitrary Zernike aberrations (OSA/ANSI j, µm RMS), a measurement pupil
    /// separate from the aperture `f/N`, longitudinal chromatic aberration and an optional
    /// polygonal (bladed) aperture ([`WavefrontPupil`]), per wavelength band.
    Pupil(WavefrontPupil),
    /// A lens prescription's ray-trace field model (ISET ray-trace method, paper §2.B.3):
    /// distortion, traced relative illumination (replacing `relative_illumination`), the
    /// lens's working F-number in the camera equation and shift-variant, wavelength-dependent
    /// PSFs. See [`LensBlur`] for the details.
    Lens(LensBlur),
}

/// A Gaussian diffuser (e.g. an optical low-pass filter), wavelength independent.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Diffuser {
    /// Full width at half maximum (µm); paper §3.A uses the pixel width.
    pub fwhm_um: f64,
}

/// A lens: f-number, focal length, transmittance, off-axis falloff and blur.
#[derive(Debug, Clone, PartialEq)]
pub struct OpticsModel {
    /// f-number N = f / D.
    pub f_number: f64,
    /// Focal length (m).
    pub focal_length_m: f64,
    /// Lens transmittance T(λ).
    pub transmittance: Spectrum,
    /// Off-axis relative illumination.
    pub relative_illumination: RelativeIllumination,
    /// Camera-equation convention.
    pub camera_equation: CameraEquation,
    /// Optical blur.
    pub blur: Blur,
    /// Optional diffuser applied after the blur.
    pub diffuser: Option<Diffuser>,
    /// Border handling for blurs.
    pub padding: Padding,
    /// Optional effect blocks of effects.md (exposure scale, fall-off, distortion, lateral
    /// colour, defocus, veiling glare); `OpticsEffects::default()` = none.
    pub effects: OpticsEffects,
}

impl OpticsModel {
    /// A diffraction-limited lens with the baseline conventions: T = 1, cos⁴ falloff,
    /// replicate padding, no diffuser.
    pub fn diffraction_limited(f_number: f64, focal_length_m: f64) -> Self {
        OpticsModel {
            f_number,
            focal_length_m,
            transmittance: Spectrum::constant(1.0),
            relative_illumination: RelativeIllumination::Cos4,
            camera_equation: CameraEquation::Baseline,
            blur: Blur::Diffraction,
            diffuser: None,
            padding: Padding::Replicate,
            effects: OpticsEffects::default(),
        }
    }

    /// Check every parameter; errors name the offending value.
    pub fn validate(&self) -> Result<(), OpticsError> {
        check_positive("f_number", self.f_number, false)?;
        check_positive("focal_length_m", self.focal_length_m, false)?;
        if let Some((w, v)) = self.transmittance.first_negative() {
            return Err(OpticsError::InvalidParameter {
                name: "transmittance",
                value: v,
                reason: if w > 0.0 {
                    "must be >= 0 (negative sample)"
                } else {
                    "must be >= 0"
                },
            });
        }
        match &self.blur {
            Blur::None | Blur::Diffraction | Blur::Psf(_) | Blur::Lens(_) => {}
            Blur::Pupil(p) => p.validate()?,
            Blur::Gaussian { sigma_um } => check_positive("blur sigma_um", *sigma_um, true)?,
            Blur::Pillbox { width_um } => check_positive("blur width_um", *width_um, true)?,
            Blur::Wavefront {
                defocus_um,
                pupil_samples,
            } => {
                if !defocus_um.is_finite() {
                    return Err(OpticsError::InvalidParameter {
                        name: "defocus_um",
                        value: *defocus_um,
                        reason: "must be finite",
                    });
                }
                if !(16..=4096).contains(pupil_samples) {
                    return Err(OpticsError::InvalidParameter {
                        name: "pupil_samples",
                        value: *pupil_samples as f64,
                        reason: "must be between 16 and 4096",
                    });
                }
            }
        }
        if let Some(d) = &self.diffuser {
            check_positive("diffuser fwhm_um", d.fwhm_um, true)?;
        }
        self.effects.validate()
    }

    /// Magnification m = −image_distance/d for the object distance (0 at infinity).
    pub fn magnification(&self, object_distance_m: Option<f64>) -> f64 {
        magnification(self.focal_length_m, object_distance_m)
    }
}

/// Form the optical image: radiance → irradiance at the sensor (see the crate docs for the
/// steps). `bands` is the wavelength grid on which wavelength-dependent blurs (diffraction,
/// PSF sets, wavefront) are computed; the result is then a band image on `bands`. With a
/// wavelength-independent blur (or none) the scene's linear model is kept (its planes are
/// filtered directly). The output has the scene's sample pitch.
pub fn form_image(
    optics: &OpticsModel,
    scene: &SceneRadiance,
    bands: &WavelengthGrid,
) -> Result<SensorIrradiance, OpticsError> {
    form_image_with(optics, scene, bands, true, Field::whole(scene)).map(|u| u.irradiance)
}

/// [`form_image`] of a band of rows of a scene: `scene` holds rows `window.row0 ..` of a
/// scene sampling grid of `window.full_rows` rows (same columns and pitch), and the result is
/// the whole grid's optical image on those rows, except within the blur's and the warps'
/// reach of the band's own top and bottom edges (where the band continues the image as
/// `padding` says instead of with the rows beyond it): the caller widens the band by the
/// optics' margin. Every field-dependent step is evaluated at the band's true field
/// coordinates (relative illumination, fall-off, distortion and lateral colour about the
/// whole grid's centre); the veiling glare adds the whole field's mean, `glare`
/// ([`glare_sums`] of the whole scene; required when the block is set). Only the local blurs
/// (none, Gaussian, pillbox; diffuser and defocus blocks) are windowed: a diffraction,
/// wavefront, PSF or lens blur reaches far and is refused, as is the uncropped image.
pub fn form_image_rows(
    optics: &OpticsModel,
    scene: &SceneRadiance,
    bands: &WavelengthGrid,
    window: RowWindow,
    glare: Option<&GlareSums>,
) -> Result<SensorIrradiance, OpticsError> {
    form_image_rows_with(optics, scene, bands, window, glare, None)
}

/// The weights of a spectral projection of an image's planes: given the planes' basis, one
/// row per output plane, one weight per plane (a sensor's channels: `∫ QE_c(λ) B_k(λ) dλ`).
pub type PlaneProjection<'a> = &'a (dyn Fn(&camsim_core::SpectralBasis) -> Vec<Vec<f64>> + Sync);

/// [`form_image_rows`] projected onto `project`'s weights: plane c of the result is
/// `Σ_k w_ck E_k` of [`form_image_rows`]' planes `E_k` (their basis `B_k`, `w = project(B)`),
/// within f32 rounding (test `projected_rows_equal_the_rows_projected`). The projection is
/// taken right after the last step that depends on wavelength (the lateral-colour warp of
/// each wavelength band, which accumulates straight into the projected planes:
/// `effects::warp_planes_projected`); every later step acts alike on every plane (the
/// local blur, the diffuser, defocus; the glare adds `f ·` the projected whole-field sums), so
/// it commutes with the weighted sum (Goodman, *Introduction to Fourier Optics*, 2005, §6.1:
/// incoherent imaging is linear in intensity) and runs on the few projected planes instead of
/// every band's. The result's basis is a placeholder (constant 1: its planes are spectral
/// integrals already); `glare` holds the unprojected planes' sums, as for [`form_image_rows`].
pub fn form_image_rows_projected(
    optics: &OpticsModel,
    scene: &SceneRadiance,
    bands: &WavelengthGrid,
    window: RowWindow,
    glare: Option<&GlareSums>,
    project: PlaneProjection,
) -> Result<SensorIrradiance, OpticsError> {
    form_image_rows_with(optics, scene, bands, window, glare, Some(project))
}

/// [`form_image_rows`], projected when `project` is given ([`form_image_rows_projected`]).
fn form_image_rows_with(
    optics: &OpticsModel,
    scene: &SceneRadiance,
    bands: &WavelengthGrid,
    window: RowWindow,
    glare: Option<&GlareSums>,
    project: Option<PlaneProjection>,
) -> Result<SensorIrradiance, OpticsError> {
    if !matches!(
        optics.blur,
        Blur::None | Blur::Gaussian { .. } | Blur::Pillbox { .. }
    ) {
        return Err(OpticsError::Scene(
            "a row window needs a local blur (none, gaussian, pillbox)".into(),
        ));
    }
    let rows = scene.radiance.rows;
    if window.row0.saturating_add(rows) > window.full_rows {
        return Err(OpticsError::Scene(format!(
            "row window {}..{} beyond the grid's {} rows",
            window.row0,
            window.row0.saturating_add(rows),
            window.full_rows
        )));
    }
    let glare_on = optics.effects.veiling_glare.is_some_and(|f| f > 0.0);
    let glare = match glare {
        Some(g) => g.clone(),
        None if glare_on => {
            return Err(OpticsError::Scene(
                "veiling glare of a row window needs the whole field's sums (glare_sums)".into(),
            ))
        }
        None => GlareSums {
            sums: vec![],
            count: 1.0,
        },
    };
    let field = Field {
        window,
        glare: Some(glare),
        project,
    };
    form_image_with(optics, scene, bands, true, field).map(|u| u.irradiance)
}

/// What the veiling-glare block of `optics` adds to `scene`'s optical image: the sums over the
/// sensor of each plane of the image before the glare ([`GlareSums`]), from [`form_image`]'s
/// steps without the glare on the whole scene; `None` without the block. The input of
/// [`form_image_rows`]'s glare.
pub fn glare_sums(
    optics: &OpticsModel,
    scene: &SceneRadiance,
    bands: &WavelengthGrid,
) -> Result<Option<GlareSums>, OpticsError> {
    if !optics.effects.veiling_glare.is_some_and(|f| f > 0.0) {
        return Ok(None);
    }
    let mut o = optics.clone();
    o.effects.veiling_glare = None;
    let img = form_image_with(&o, scene, bands, true, Field::whole(scene))?.irradiance;
    Ok(Some(effects::veiling_glare_sums(
        &optics.effects,
        &img.irradiance,
        img.sample_pitch_m,
    )))
}

/// [`glare_sums`] of an optical image already formed without the glare (`irradiance`: the
/// whole field through `optics` without the block, e.g. a camera that has none): the same
/// sums (`effects::veiling_glare_sums` over the samples on the sensor of `optics`' effects)
/// without running the optics again.
pub fn glare_sums_of_image(optics: &OpticsModel, irradiance: &SensorIrradiance) -> GlareSums {
    effects::veiling_glare_sums(
        &optics.effects,
        &irradiance.irradiance,
        irradiance.sample_pitch_m,
    )
}

/// Where [`form_image_with`]'s scene lies in the field, the glare's whole-field sums
/// (`None`: from the image itself, which is then the whole field), and the spectral
/// projection of the planes after the wavelength-dependent steps
/// ([`form_image_rows_projected`]; only with a local blur).
#[derive(Clone)]
struct Field<'a> {
    window: RowWindow,
    glare: Option<GlareSums>,
    project: Option<PlaneProjection<'a>>,
}

impl Field<'_> {
    fn whole(scene: &SceneRadiance) -> Self {
        Field {
            window: RowWindow::whole(scene.radiance.rows),
            glare: None,
            project: None,
        }
    }
}

/// The optical image without ISETCam's final crop (`oiCompute` with `crop = false`): the
/// scene is zero-padded by `round(rows/8)` rows and `round(cols/8)` columns each side
/// (`oiPad`), the blur spreads light into that ring, and the whole padded image is returned,
/// so a sensor larger than the scene sees the blurred light around it. The centre
/// `rows × cols` is exactly [`form_image`]'s result. Needs the ISETCam padding
/// ([`Padding::Zero`]), an FFT blur (none, diffraction, PSF set, wavefront) and no effect
/// blocks.
pub fn form_image_uncropped(
    optics: &OpticsModel,
    scene: &SceneRadiance,
    bands: &WavelengthGrid,
) -> Result<UncroppedIrradiance, OpticsError> {
    if optics.padding != Padding::Zero {
        return Err(OpticsError::Scene(
            "an uncropped optical image needs the ISETCam padding (Padding::Zero)".into(),
        ));
    }
    if !matches!(
        optics.blur,
        Blur::None | Blur::Diffraction | Blur::Psf(_) | Blur::Wavefront { .. } | Blur::Pupil(_)
    ) || !optics.effects.is_empty()
    {
        return Err(OpticsError::Scene(
            "an uncropped optical image needs an FFT blur (none, diffraction, psf, wavefront) \
             and no effect blocks"
                .into(),
        ));
    }
    form_image_with(optics, scene, bands, false, Field::whole(scene))
}

/// [`form_image_uncropped`]'s result: the padded irradiance and the ring's width.
#[derive(Debug, Clone)]
pub struct UncroppedIrradiance {
    /// `(rows + 2·pad_rows) × (cols + 2·pad_cols)` irradiance, the scene's pitch.
    pub irradiance: SensorIrradiance,
    /// Rows of the ring above (and below) the scene: `round(rows / 8)`.
    pub pad_rows: usize,
    /// Columns of the ring left (and right) of the scene: `round(cols / 8)`.
    pub pad_cols: usize,
}

/// Zero-pad every plane by `pr` rows and `pc` columns each side.
fn zero_pad_image(img: &SpectralImage, pr: usize, pc: usize) -> SpectralImage {
    let (rows, cols) = (img.rows, img.cols);
    let (nr, nc) = (rows + 2 * pr, cols + 2 * pc);
    let planes = img
        .planes
        .iter()
        .map(|p| {
            let mut q = vec![0f32; nr * nc];
            for i in 0..rows {
                q[(i + pr) * nc + pc..(i + pr) * nc + pc + cols]
                    .copy_from_slice(&p[i * cols..(i + 1) * cols]);
            }
            q
        })
        .collect();
    SpectralImage {
        rows: nr,
        cols: nc,
        basis: img.basis.clone(),
        planes,
    }
}

/// [`form_image`] (`crop`) or [`form_image_uncropped`] (`!crop`, checked by the caller).
fn form_image_with(
    optics: &OpticsModel,
    scene: &SceneRadiance,
    bands: &WavelengthGrid,
    crop: bool,
    field: Field,
) -> Result<UncroppedIrradiance, OpticsError> {
    optics.validate()?;
    let window = field.window;
    let dx = scene.sample_pitch_m;
    check_positive("sample_pitch_m", dx, false)?;
    if let Some(d) = scene.object_distance_m {
        if !(d.is_finite() && d > optics.focal_length_m) {
            return Err(OpticsError::InvalidParameter {
                name: "object_distance_m",
                value: d,
                reason: "must be finite and larger than the focal length (a real image)",
            });
        }
    }
    if bands.is_empty() {
        return Err(OpticsError::Scene("empty wavelength grid".into()));
    }
    let (rows, cols) = (scene.radiance.rows, scene.radiance.cols);
    if rows == 0 || cols == 0 {
        return Err(OpticsError::Scene(format!("empty image {rows}×{cols}")));
    }
    // A scene of B-spline samples: only the FFT blurs undo its aperture (see the blur step).
    let aperture_order = scene.sample_aperture.order();
    if aperture_order > 1
        && !matches!(
            optics.blur,
            Blur::Diffraction
                | Blur::Psf(_)
                | Blur::Wavefront { .. }
                | Blur::Pupil(_)
                | Blur::Pillbox { .. }
        )
    {
        return Err(OpticsError::Scene(format!(
            "the scene's samples have the {:?} aperture, which only the FFT blurs (diffraction, \
             wavefront, psf, pillbox) compensate; render it with cell averages for this blur",
            scene.sample_aperture
        )));
    }
    if let Blur::Lens(lb) = &optics.blur {
        let split = lens_blur::form_lens_image(optics, lb, &scene.radiance, bands, dx)?;
        let (mut img, band_wl) = (split.image, split.wavelength_nm);
        apply_diffuser(optics, &mut img, dx);
        // Effect blocks with a lens: after the lens's own image formation (an approximation
        // for the fall-off and the warp, which ideally act before its PSFs).
        let fx = &optics.effects;
        if !fx.is_empty() {
            let s = fx.exposure_scale.unwrap_or(1.0);
            if fx.falloff.is_some() {
                let map = radial_map(rows, cols, dx, fx, window, |_| s);
                img.scale_spatially(&map);
            } else if s != 1.0 {
                img.scale(s);
            }
            if fx.has_warp() {
                let wl = Some(band_wl.as_slice()).filter(|_| fx.lateral_color.is_some());
                effects::warp_planes(fx, &mut img, dx, wl, window)?;
            }
            apply_defocus_and_glare(optics, &mut img, dx, field.glare.as_ref())?;
        }
        return Ok(UncroppedIrradiance {
            irradiance: SensorIrradiance {
                irradiance: img,
                sample_pitch_m: dx,
            },
            pad_rows: 0,
            pad_cols: 0,
        });
    }
    let n = optics.f_number;
    let m = optics.magnification(scene.object_distance_m);
    let mut img = scene.radiance.clone();

    // 1. Camera equation (Eq. 1) and lens transmittance; the exposure_scale block
    // multiplies the irradiance.
    let (k, n_eff) = match optics.camera_equation {
        CameraEquation::Baseline => (camera_equation_factor(n, m), n * (1.0 + m.abs())),
        CameraEquation::IsetCam => (camera_equation_factor_isetcam(n, m), n),
    };
    let k = k * optics.effects.exposure_scale.unwrap_or(1.0);
    let falloff = optics.effects.falloff.as_ref();
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

    // 2. Relative illumination R(x), folded with the scalar factor into one spatial map.
    let yc = window.centre_row();
    let xc = (cols as f64 - 1.0) / 2.0;
    let f = optics.focal_length_m;
    match optics.relative_illumination {
        RelativeIllumination::None if falloff.is_none() => img.scale(k),
        RelativeIllumination::None => {
            let map = radial_map(rows, cols, dx, &optics.effects, window, |_| k);
            img.scale_spatially(&map);
        }
        ri => {
            // ISETCam evaluates the diagonal on the padded optical image (of the whole field).
            let full_rows = window.full_rows;
            let (pr, pc) = match optics.padding {
                Padding::Zero => (
                    full_rows + 2 * fft::isetcam_pad(full_rows),
                    cols + 2 * fft::isetcam_pad(cols),
                ),
                Padding::Replicate => (full_rows, cols),
            };
            let diag = dx * ((pr * pr + pc * pc) as f64).sqrt();
            let mut map = vec![0f32; rows * cols];
            map.par_chunks_mut(cols).enumerate().for_each(|(i, row)| {
                let y = (window.field_row(i) - yc) * dx;
                for (j, v) in row.iter_mut().enumerate() {
                    let x = (j as f64 - xc) * dx;
                    let r = match ri {
                        RelativeIllumination::Cos4 => {
                            relative_illumination_cos4((x * x + y * y).sqrt(), f)
                        }
                        _ => relative_illumination_isetcam(x, y, f, n, m, diag),
                    };
                    // The relative_illumination block's extra fall-off F(h).
                    let r = match falloff {
                        None => r,
                        Some(fo) => r * fo.factor(x.hypot(y) / optics.effects.half_diagonal_m()),
                    };
                    *v = (k * r) as f32;
                }
            });
            img.scale_spatially(&map);
        }
    }

    // Per-band blurs and lateral colour act on the image split into bands, each band keeping
    // its exact integral of spectrum × response ([`split_into_bands`]); `band_wl` holds the
    // wavelength of each plane once split.
    let per_band = matches!(
        optics.blur,
        Blur::Diffraction | Blur::Psf(_) | Blur::Wavefront { .. } | Blur::Pupil(_)
    ) || optics.effects.lateral_color.is_some();
    let mut band_wl: Option<Vec<f64>> = None;
    if per_band {
        let split = split_into_bands(img, bands, optics.padding == Padding::Zero);
        img = split.image;
        band_wl = Some(split.wavelength_nm);
    }

    // Distortion and lateral colour blocks: geometric warp of every wavelength plane; with a
    // projection (a local blur: the steps after it act alike at every wavelength), the warped
    // planes accumulated straight into the projected ones, and the glare's sums projected.
    let mut glare = field.glare;
    if let Some(project) = field.project {
        let weights = project(&img.basis);
        let planes = if optics.effects.has_warp() {
            let wl = band_wl
                .as_deref()
                .filter(|_| optics.effects.lateral_color.is_some());
            effects::warp_planes_projected(&optics.effects, &img, dx, wl, window, &weights)?
        } else {
            weights.iter().map(|w| img.combine(w)).collect()
        };
        match &mut glare {
            Some(g) if optics.effects.veiling_glare.is_some_and(|f| f > 0.0) => {
                g.sums = project_sums(&g.sums, &weights)?
            }
            _ => {}
        }
        img = SpectralImage {
            rows,
            cols,
            basis: camsim_core::SpectralBasis::Spectra(vec![Spectrum::constant(1.0); planes.len()]),
            planes,
        };
        band_wl = None;
    } else if optics.effects.has_warp() {
        let wl = band_wl
            .as_deref()
            .filter(|_| optics.effects.lateral_color.is_some());
        effects::warp_planes(&optics.effects, &mut img, dx, wl, window)?;
    }
    let band_wl = band_wl.unwrap_or_default();

    // Uncropped (ISETCam crop = false): blur on the zero-padded grid and keep all of it.
    let (pad_rows, pad_cols) = if crop {
        (0, 0)
    } else {
        (fft::isetcam_pad(rows), fft::isetcam_pad(cols))
    };
    if !crop {
        img = zero_pad_image(&img, pad_rows, pad_cols);
    }
    let (rows, cols) = (img.rows, img.cols);

    // 3. Blur. The FFT blurs take samples of the scene's aperture (`aperture_order`) and give
    // cell averages of the blurred irradiance, which the sensor's box average over the pixel
    // turns into the exact pixel mean ([`camsim_core::sample_aperture`]).
    let band_finish = match optics.padding {
        Padding::Zero => Finish::Abs,
        Padding::Replicate => Finish::NonNegative,
    };
    match &optics.blur {
        Blur::None => {}
        Blur::Diffraction => {
            let lmax = band_wl.iter().cloned().fold(0.0, f64::max) * 1e-9;
            // Airy tail: ~1 % of the energy lies beyond 20 λN; with replicated edges, the
            // far-tail correction takes the replicated scene on beyond the pad instead of the
            // FFT's wrap (FAR_TAIL_FRACTION).
            let margin = ((20.0 * lmax * n_eff / dx).ceil() as usize).clamp(2, 1024);
            let mut conv = if crop && optics.padding == Padding::Replicate {
                FftConvolver::new_far_tail(
                    rows,
                    cols,
                    dx,
                    margin,
                    lmax * 1e9,
                    n_eff,
                    FAR_TAIL_FRACTION,
                )
            } else if crop {
                FftConvolver::new(rows, cols, dx, optics.padding, margin, margin)
            } else {
                FftConvolver::prepadded_zero(rows, cols, dx)
            };
            conv.compensate_sample_aperture(aperture_order);
            img.planes
                .par_iter_mut()
                .zip(band_wl.par_iter())
                .for_each_init(
                    || (conv.workspace(), vec![0f32; rows * cols]),
                    |(ws, out), (p, &w)| {
                        let t = Transfer::Diffraction {
                            lambda_n_m: w * 1e-9 * n_eff,
                        };
                        conv.convolve(p, &t, band_finish, ws, out);
                        p.copy_from_slice(out);
                    },
                );
        }
        Blur::Gaussian { sigma_um } => {
            let kern = gaussian_kernel_1d(sigma_um * 1e-6, dx);
            kernels::separable_convolve(&mut img.planes, rows, cols, &kern, optics.padding);
        }
        Blur::Pillbox { width_um } => {
            let psf = pillbox_psf(width_um * 1e-6, dx);
            let pad = optics.padding;
            convolve_planes_with_aperture(&mut img, pad, Finish::Keep, aperture_order, |_| {
                psf.clone()
            })?;
        }
        Blur::Psf(set) => {
            let pad = optics.padding;
            convolve_planes_impl(&mut img, pad, band_finish, aperture_order, !crop, |b| {
                set.resampled(band_wl[b], dx)
            })?;
        }
        Blur::Wavefront {
            defocus_um,
            pupil_samples,
        } => {
            let psfs: Vec<SampledPsf> = band_wl
                .iter()
                .map(|&w| wavefront_psf(w, n_eff, *defocus_um, *pupil_samples, dx))
                .collect::<Result<_, _>>()?;
            let pad = optics.padding;
            convolve_planes_impl(&mut img, pad, band_finish, aperture_order, !crop, |b| {
                psfs[b].clone()
            })?;
        }
        Blur::Pupil(wp) => {
            // The aperture D = f/N (the camera equation's f-number); the PSF scale uses the
            // working f-number.
            let aperture_m = optics.focal_length_m / optics.f_number;
            let psfs: Vec<SampledPsf> = band_wl
                .par_iter()
                .map(|&w| wp.psf(w, n_eff, aperture_m, dx))
                .collect::<Result<_, _>>()?;
            let pad = optics.padding;
            convolve_planes_impl(&mut img, pad, band_finish, aperture_order, !crop, |b| {
                psfs[b].clone()
            })?;
        }
        Blur::Lens(_) => unreachable!("handled above"),
    }

    // 4. Diffuser.
    apply_diffuser(optics, &mut img, dx);

    // 5. Defocus and veiling glare blocks.
    apply_defocus_and_glare(optics, &mut img, dx, glare.as_ref())?;

    Ok(UncroppedIrradiance {
        irradiance: SensorIrradiance {
            irradiance: img,
            sample_pitch_m: dx,
        },
        pad_rows,
        pad_cols,
    })
}

/// The glare sums of projected planes: `Σ_k w_ck · sums_k` per row `w_c` of `weights` (the
/// glare adds `f · sum / count` to each plane, so it commutes with the projection).
fn project_sums(sums: &[f64], weights: &[Vec<f64>]) -> Result<Vec<f64>, OpticsError> {
    weights
        .iter()
        .map(|w| {
            if w.len() != sums.len() {
                return Err(OpticsError::Scene(format!(
                    "veiling glare of a projected row window: {} plane sums for {} weights",
                    sums.len(),
                    w.len()
                )));
            }
            Ok(w.iter().zip(sums).map(|(a, b)| a * b).sum())
        })
        .collect()
}

/// `scalar(h) · F(h)` at every sample (F: the fall-off block, h: field height; the image's
/// rows lie in the field as `window` says).
fn radial_map(
    rows: usize,
    cols: usize,
    dx: f64,
    fx: &OpticsEffects,
    window: RowWindow,
    scalar: impl Fn(f64) -> f64 + Sync,
) -> Vec<f32> {
    let yc = window.centre_row();
    let xc = (cols as f64 - 1.0) / 2.0;
    let hd = fx.half_diagonal_m();
    let mut map = vec![0f32; rows * cols];
    map.par_chunks_mut(cols).enumerate().for_each(|(i, row)| {
        let y = (window.field_row(i) - yc) * dx;
        for (j, v) in row.iter_mut().enumerate() {
            let h = ((j as f64 - xc) * dx).hypot(y) / hd;
            let f = fx.falloff.as_ref().map_or(1.0, |f| f.factor(h));
            *v = (scalar(h) * f) as f32;
        }
    });
    map
}

/// The defocus block's blur, then the veiling-glare block (the means of `glare`, or of the
/// image itself when `None`).
fn apply_defocus_and_glare(
    optics: &OpticsModel,
    img: &mut SpectralImage,
    dx: f64,
    glare: Option<&GlareSums>,
) -> Result<(), OpticsError> {
    let fx = &optics.effects;
    if let Some(d) = &fx.defocus {
        effects::apply_defocus(d, img, dx, optics.padding)?;
    }
    if let Some(f) = fx.veiling_glare {
        if f > 0.0 {
            match glare {
                Some(g) if g.sums.len() != img.planes.len() => {
                    return Err(OpticsError::Scene(format!(
                        "veiling glare of a row window: {} plane sums for {} planes",
                        g.sums.len(),
                        img.planes.len()
                    )))
                }
                Some(g) => effects::apply_veiling_glare(f, img, g),
                None => {
                    let g = effects::veiling_glare_sums(fx, img, dx);
                    effects::apply_veiling_glare(f, img, &g);
                }
            }
        }
    }
    Ok(())
}

/// The optional diffuser (Gaussian, FWHM → σ).
fn apply_diffuser(optics: &OpticsModel, img: &mut SpectralImage, dx: f64) {
    if let Some(d) = &optics.diffuser {
        let kern = gaussian_kernel_1d(sigma_from_fwhm(d.fwhm_um * 1e-6), dx);
        let (rows, cols) = (img.rows, img.cols);
        kernels::separable_convolve(&mut img.planes, rows, cols, &kern, optics.padding);
    }
}

/// Convolve every plane `b` of `img` with `psf_of(b)` by FFT (one padded grid for all).
pub(crate) fn convolve_planes_with(
    img: &mut SpectralImage,
    padding: Padding,
    finish: Finish,
    psf_of: impl Fn(usize) -> SampledPsf + Sync,
) -> Result<(), OpticsError> {
    convolve_planes_with_aperture(img, padding, finish, 1, psf_of)
}

/// [`convolve_planes_with`] for samples of aperture order `aperture_order`
/// ([`fft::FftConvolver::compensate_sample_aperture`]).
pub(crate) fn convolve_planes_with_aperture(
    img: &mut SpectralImage,
    padding: Padding,
    finish: Finish,
    aperture_order: u32,
    psf_of: impl Fn(usize) -> SampledPsf + Sync,
) -> Result<(), OpticsError> {
    convolve_planes_impl(img, padding, finish, aperture_order, false, psf_of)
}

/// [`convolve_planes_with_aperture`]; `prepadded`: the planes are already zero-padded the
/// ISETCam way ([`FftConvolver::prepadded_zero`]).
fn convolve_planes_impl(
    img: &mut SpectralImage,
    padding: Padding,
    finish: Finish,
    aperture_order: u32,
    prepadded: bool,
    psf_of: impl Fn(usize) -> SampledPsf + Sync,
) -> Result<(), OpticsError> {
    let (rows, cols) = (img.rows, img.cols);
    let psfs: Vec<SampledPsf> = (0..img.planes.len()).into_par_iter().map(&psf_of).collect();
    let mr = psfs.iter().map(|p| p.half_rows).max().unwrap_or(0).max(1);
    let mc = psfs.iter().map(|p| p.half_cols).max().unwrap_or(0).max(1);
    let mut conv = if prepadded {
        FftConvolver::prepadded_zero(rows, cols, psfs[0].pitch_m)
    } else {
        FftConvolver::new(rows, cols, psfs[0].pitch_m, padding, mr, mc)
    };
    conv.compensate_sample_aperture(aperture_order);
    img.planes
        .par_iter_mut()
        .zip(psfs.par_iter())
        .for_each_init(
            || (conv.workspace(), vec![0f32; rows * cols]),
            |(ws, out), (p, psf)| {
                let h = conv.kernel_spectrum(psf, ws);
                conv.convolve(p, &Transfer::Spectrum(&h), finish, ws, out);
                p.copy_from_slice(out);
            },
        );
    Ok(())
}

#[cfg(test)]
mod tests;
