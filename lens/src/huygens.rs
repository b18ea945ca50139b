//! Wave-optics PSF by direct Huygens–Fresnel integration over the exit-pupil reference sphere.
//!
//! The FFT PSF of [`LensPrescription::wave_optics`] ties its sample pitch to the pupil grid,
//! λN_w(n − 1)/m for an n-sample pupil zero-padded to m, and assumes the paraxial pupil →
//! image-angle scaling; a fine pitch needs large padding and an off-centre window a large
//! transform. The Huygens PSF evaluates the diffraction integral directly at any image points:
//!
//! * real rays on the linspace(−1, 1, n)² entrance-pupil grid (as for the OPD map) are traced
//!   to the image plane and back along themselves to the reference sphere of radius R centred on
//!   the chief ray's image point p through the paraxial exit pupil (the OPD map's sphere); ray j
//!   meets it at Q_j with optical path L_j;
//! * every Q_j radiates a secondary spherical wavelet (Huygens–Fresnel principle, Born & Wolf
//!   §8.2–8.3; Goodman, "Introduction to Fourier Optics" §3.5), so at an image-plane point P
//!
//!   U(P) = Σ_j exp(i k₀ [L_j − L_c + n'(|P − Q_j| − R)]) · (R/|P − Q_j|) · (1 + cos χ_j)/2,
//!
//!   with k₀ = 2π/λ₀, n' the image-space index, L_c the chief ray's path and χ_j the angle
//!   between the ray direction and P − Q_j (the Fresnel–Kirchhoff obliquity factor);
//! * each ray carries equal flux (uniform illumination of the entrance pupil, as for the FFT
//!   PSF); the PSF is |U|² normalised to sum 1 over the requested window.
//!
//! Because Q_j are the rays' real positions on the reference sphere, the pupil distortion and
//! the exact (non-paraxial) distances are included. The pupil sum is still a discrete sampling:
//! as for the FFT, an n-sample pupil describes the PSF without aliasing only within a window of
//! width ≈ λN_w(n − 1) about p ([`LensPrescription::huygens_pupil_samples`] gives the n needed
//! for a window).
//!
//! The Strehl ratio reported is the intensity at p relative to an aberration-free pupil,
//! |Σ_j exp(2πi W_j)|²/N² with W_j the OPD in waves (Born & Wolf §9.1).
use crate::analysis::Psf;
use crate::error::LensError;
use crate::prescription::LensPrescription;
use crate::trace::AimedChief;
use crate::trace::Clipping;
use rayon::prelude::*;

/// A Huygens PSF.
#[derive(Debug, Clone, PartialEq)]
pub struct HuygensPsf {
    /// The PSF: `n`² samples of pitch `sample_mm` centred (index n/2, n/2) on `centre_mm`,
    /// row index along +y and column index along +x of the image plane, summing to 1.
    pub psf: Psf,
    /// Image-plane point (x, y) of the centre sample (mm): the chief ray's image point plus the
    /// requested offset.
    pub centre_mm: [f64; 2],
    /// The chief ray's image point (mm).
    pub chief_mm: [f64; 2],
    /// Strehl ratio at the chief ray's image point (see the module docs).
    pub strehl_ratio: f64,
    /// Pupil rays that reached the reference sphere.
    pub rays: usize,
    /// Working F-number used for window sizes (paraxial, at this wavelength).
    pub working_f_number: f64,
}

/// Where the Huygens PSF is evaluated.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HuygensWindow {
    /// Samples per side (the centre sample is n/2).
    pub n: usize,
    /// Sample pitch (mm).
    pub sample_mm: f64,
    /// Offset (x, y) of the window centre from the chief ray's image point (mm).
    pub offset_mm: [f64; 2],
}

impl LensPrescription {
    /// Pupil samples per side that describe a window of half-width `half_width_mm` about the
    /// chief ray without aliasing (the pupil-sum period λN_w(n − 1) must exceed the window).
    pub fn huygens_pupil_samples(
        &self,
        wavelength_nm: f64,
        half_width_mm: f64,
    ) -> Result<usize, LensError> {
        let nw = self.first_order(wavelength_nm)?.working_f_number;
        Ok((2.0 * half_width_mm / (wavelength_nm * 1e-6 * nw)).ceil() as usize + 2)
    }

    /// The Huygens PSF of `field_deg` at `wavelength_nm` from a `pupil_n`² pupil grid, on
    /// `window` (see the module docs). The chief ray is aimed at `wavelength_nm`; rays are
    /// clipped at the semi-diameters when `clipping` says so.
    pub fn huygens_psf(
        &self,
        field_deg: f64,
        wavelength_nm: f64,
        pupil_n: usize,
        window: &HuygensWindow,
        clipping: Clipping,
    ) -> Result<HuygensPsf, LensError> {
        if pupil_n < 2 || window.n == 0 || !(window.sample_mm > 0.0) {
            return Err(LensError::Prescription(format!(
                "Huygens PSF: pupil_n = {pupil_n} (need ≥ 2), n = {}, sample_mm = {} (need > 0)",
                window.n, window.sample_mm
            )));
        }
        let AimedChief {
            first_order: fo,
            aim,
            chief,
        } = self.aimed_chief_ray(field_deg, wavelength_nm)?;
        let n_img = self.surfaces.last().unwrap().medium.index(wavelength_nm);
        let p = chief.image_mm;
        let radius = (p[2] - fo.exit_pupil_z_mm) / chief.direction[2];
        if !(radius.is_finite() && radius.abs() > 1e-9) {
            return Err(LensError::Paraxial(format!(
                "Huygens PSF: exit pupil at the image plane (reference radius {radius} mm)"
            )));
        }
        // Point of a traced ray on the reference sphere and its optical path there.
        let on_sphere = |img: [f64; 3], d: [f64; 3], opl: f64| -> ([f64; 3], f64) {
            let w = [img[0] - p[0], img[1] - p[1], img[2] - p[2]];
            let wd = w[0] * d[0] + w[1] * d[1] + w[2] * d[2];
            let ww = w[0] * w[0] + w[1] * w[1] + w[2] * w[2];
            let disc = (wd * wd - ww + radius * radius).max(0.0);
            let s = if radius >= 0.0 {
                wd + disc.sqrt()
            } else {
                wd - disc.sqrt()
            };
            (
                [img[0] - s * d[0], img[1] - s * d[1], img[2] - s * d[2]],
                opl - n_img * s,
            )
        };
        let (_, l_chief) = on_sphere(chief.image_mm, chief.direction, chief.opl_mm);
        let v: Vec<f64> = (0..pupil_n)
            .map(|i| -1.0 + 2.0 * i as f64 / (pupil_n - 1) as f64)
            .collect();
        // Secondary sources: Q (relative to p), path difference L − L_c, direction.
        let pts: Vec<[f64; 2]> = (0..pupil_n * pupil_n)
            .map(|k| [v[k % pupil_n], v[k / pupil_n]])
            .filter(|q| q[0] * q[0] + q[1] * q[1] <= 1.0)
            .collect();
        let batch = self
            .trace_system(wavelength_nm)
            .trace_pupil(&aim, &pts, clipping);
        let sources: Vec<([f64; 3], f64, [f64; 3])> = (0..batch.len())
            .filter_map(|i| {
                let r = batch.get(i)?;
                let (q, l) = on_sphere(r.image_mm, r.direction, r.opl_mm);
                Some((
                    [q[0] - p[0], q[1] - p[1], q[2] - p[2]],
                    l - l_chief,
                    r.direction,
                ))
            })
            .collect();
        if sources.is_empty() {
            return Err(LensError::Aiming {
                field_deg,
                msg: "no pupil ray reaches the image".into(),
            });
        }
        let k0 = 2.0 * std::f64::consts::PI / (wavelength_nm * 1e-6);
        let strehl = {
            let (mut re, mut im) = (0.0, 0.0);
            for (_, dl, _) in &sources {
                let (s, c) = (k0 * dl).sin_cos();
                re += c;
                im += s;
            }
            (re * re + im * im) / (sources.len() as f64).powi(2)
        };
        let n = window.n;
        let c0 = (n / 2) as f64;
        let centre = [p[0] + window.offset_mm[0], p[1] + window.offset_mm[1]];
        let r2 = radius * radius;
        let mut values: Vec<f64> = (0..n * n)
            .into_par_iter()
            .map(|idx| {
                let (ix, iy) = (idx % n, idx / n);
                // P − p (P on the image plane).
                let pp = [
                    window.offset_mm[0] + (ix as f64 - c0) * window.sample_mm,
                    window.offset_mm[1] + (iy as f64 - c0) * window.sample_mm,
                    0.0,
                ];
                let (mut re, mut im) = (0.0, 0.0);
                for (q, dl, d) in &sources {
                    let w = [pp[0] - q[0], pp[1] - q[1], pp[2] - q[2]];
                    let dist2 = w[0] * w[0] + w[1] * w[1] + w[2] * w[2];
                    let dist = dist2.sqrt();
                    // |P − Q| − R without cancellation.
                    let excess = (dist2 - r2) / (dist + radius.abs());
                    let cos_chi = (w[0] * d[0] + w[1] * d[1] + w[2] * d[2]) / dist;
                    let amp = radius.abs() / dist * 0.5 * (1.0 + cos_chi);
                    let (s, c) = (k0 * (dl + n_img * excess)).sin_cos();
                    re += amp * c;
                    im += amp * s;
                }
                re * re + im * im
            })
            .collect();
        let sum: f64 = values.iter().sum();
        if sum > 0.0 {
            values.iter_mut().for_each(|x| *x /= sum);
        }
        Ok(HuygensPsf {
            psf: Psf {
                n,
                sample_mm: window.sample_mm,
                values,
            },
            centre_mm: centre,
            chief_mm: [p[0], p[1]],
            strehl_ratio: strehl,
            rays: sources.len(),
            working_f_number: fo.working_f_number,
        })
    }
}
