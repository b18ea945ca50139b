//! Wavefront optics beyond defocus: a pupil with arbitrary Zernike aberrations, a Zernike
//! (measurement) pupil separate from the lens's aperture, longitudinal chromatic aberration
//! and polygonal (bladed) apertures. The PSF is `|F{P}|²` of the sampled pupil function, as
//! for [`crate::wavefront_psf`] (Goodman, *Introduction to Fourier Optics*, §6.4).
//!
//! Conventions:
//! * Zernike polynomials follow the OSA/ANSI standard (Thibos, Applegate, Schwiegerling &
//!   Webb, "Standards for reporting the optical aberrations of eyes", J. Refract. Surg. 18,
//!   S652 (2002); ANSI Z80.28): single index `j = (n(n+2) + m)/2`, normalisation
//!   `√((2 − δ_{m0})(n + 1))` so that each polynomial has unit RMS over the unit disk, `cos(mθ)`
//!   for `m > 0`, `sin(|m|θ)` for `m < 0`; coefficients are the RMS wavefront error in µm.
//! * Pupil coordinates as the image: x to the right, y up, θ counter-clockwise from +x. A
//!   wavefront slope moves light the same way: tilt `c·Z₂ = 2cρ cos θ` shifts the PSF by
//!   `+4 N c` along x (the transverse ray aberration `ε = 2N ∂W/∂ρ`).
//! * The lens's aperture has the diameter `D = f / N` (the camera's `f_number` and focal
//!   length: the camera equation and the diffraction scale use N as before). Zernike
//!   coefficients are given over a pupil of diameter `D_z` (the *measurement* pupil, ISETCam's
//!   `measured pupil diameter`; default `D_z = D`). `D_z ≥ D` is required; the aperture samples
//!   the wavefront at `ρ_z = ρ · D / D_z`, so stopping down shrinks the aberrations.
//! * Longitudinal chromatic aberration adds a defocus coefficient `c₄(λ)`: the human eye's
//!   (Thibos, Ye, Zhang & Bradley, "The chromatic eye", Appl. Opt. 31, 3594 (1992), in the
//!   form ISETCam's `wvfLCAFromWavelengthDifference` uses) converted from diopters over the
//!   measurement pupil, or a user table of µm of defocus against wavelength.
//! * A polygonal aperture of `N` blades is the regular N-gon inscribed in the aperture circle
//!   (circumradius `D/2`, one vertex straight up), area `(N/2) R² sin(2π/N)`.
use crate::error::{check_positive, OpticsError};
use crate::kernels::{pupil_psf, SampledPsf};
use rustfft::num_complex::Complex64;
use std::f64::consts::PI;

/// One Zernike term: OSA/ANSI index `j` and coefficient (µm RMS).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ZernikeTerm {
    /// OSA/ANSI single index (0 piston, 1–2 tilt, 3–5 astigmatism/defocus, 6–9 trefoil/coma,
    /// 12 primary spherical, …).
    pub j: usize,
    /// Coefficient = RMS wavefront error of this term (µm).
    pub rms_um: f64,
}

/// Radial order `n` and signed azimuthal frequency `m` of OSA/ANSI index `j`:
/// `n = ⌈(−3 + √(9 + 8j)) / 2⌉`, `m = 2j − n(n + 2)`.
pub fn zernike_osa_nm(j: usize) -> (usize, i64) {
    let mut n = ((-3.0 + (9.0 + 8.0 * j as f64).sqrt()) / 2.0).ceil() as usize;
    // Guard the float rounding at exact triangular numbers.
    while n * (n + 3) / 2 < j {
        n += 1;
    }
    while n > 0 && (n - 1) * (n + 2) / 2 >= j {
        n -= 1;
    }
    let m = 2 * j as i64 - (n * (n + 2)) as i64;
    (n, m)
}

/// The OSA/ANSI Zernike polynomial `Z_j(ρ, θ)` with unit-RMS normalisation over the unit disk
/// (Thibos et al. 2002): `√((2 − δ_{m0})(n+1)) R_n^{|m|}(ρ) · {cos mθ, m ≥ 0; sin |m|θ, m < 0}`,
/// `R_n^k(ρ) = Σ_s (−1)^s (n−s)! / (s! ((n+k)/2 − s)! ((n−k)/2 − s)!) ρ^{n−2s}`.
pub fn zernike_osa(j: usize, rho: f64, theta: f64) -> f64 {
    let (n, m) = zernike_osa_nm(j);
    let k = m.unsigned_abs() as usize;
    let fact = |x: usize| (1..=x).fold(1.0f64, |a, b| a * b as f64);
    let mut r = 0.0;
    for s in 0..=(n - k) / 2 {
        let c = fact(n - s) / (fact(s) * fact((n + k) / 2 - s) * fact((n - k) / 2 - s));
        let sign = if s % 2 == 0 { 1.0 } else { -1.0 };
        r += sign * c * rho.powi((n - 2 * s) as i32);
    }
    let norm = if m == 0 {
        ((n + 1) as f64).sqrt()
    } else {
        (2.0 * (n + 1) as f64).sqrt()
    };
    let ang = if m >= 0 {
        (k as f64 * theta).cos()
    } else {
        (k as f64 * theta).sin()
    };
    norm * r * ang
}

/// Longitudinal chromatic aberration: extra Zernike defocus `c₄(λ)` (µm RMS over the
/// measurement pupil) added to the wavefront at each wavelength.
#[derive(Debug, Clone, PartialEq, Default)]
pub enum ChromaticDefocus {
    /// None.
    #[default]
    None,
    /// The human eye (Thibos et al. 1992, as ISETCam's `wvfLCAFromWavelengthDifference`), in
    /// focus at `reference_nm`: [`human_lca_diopters`] converted by
    /// [`defocus_um_from_diopters`] over the measurement pupil, with ISETCam's sign
    /// (`c₄ = defocus_um_from_diopters(−ΔD)`).
    HumanEye {
        /// Wavelength in focus (nm).
        reference_nm: f64,
    },
    /// A table of defocus (µm RMS, Zernike j = 4) against wavelength, linear between the
    /// entries and constant beyond the ends.
    Table {
        /// Strictly increasing wavelengths (nm).
        wavelength_nm: Vec<f64>,
        /// Defocus at each wavelength (µm RMS).
        defocus_um: Vec<f64>,
    },
}

/// Chromatic difference of refraction of the human eye between `reference_nm` and
/// `wavelength_nm` (diopters; 0 at the reference): `ΔD = q/(λ_ref − c) − q/(λ − c)` with λ in
/// µm, `q = 0.63346`, `c = 0.2141` (Thibos et al. 1992 reduced-eye fit, the form of ISETCam's
/// `wvfLCAFromWavelengthDifference`).
pub fn human_lca_diopters(reference_nm: f64, wavelength_nm: f64) -> f64 {
    const Q: f64 = 0.63346;
    const C: f64 = 0.2141;
    Q / (reference_nm * 1e-3 - C) - Q / (wavelength_nm * 1e-3 - C)
}

/// Zernike defocus coefficient (µm RMS) of a dioptric error over a pupil of diameter
/// `pupil_diameter_mm`: `c₄ = D · d² / (16 √3)` (the paraxial sag `D r²/2` of a spherical
/// wavefront over radius `r = d/2`, written as `c₄ √3 (2ρ² − 1)` plus piston; Thibos et al.
/// 2002; ISETCam's `wvfDefocusDioptersToMicrons`).
pub fn defocus_um_from_diopters(diopters: f64, pupil_diameter_mm: f64) -> f64 {
    diopters * pupil_diameter_mm * pupil_diameter_mm / (16.0 * 3f64.sqrt())
}

impl ChromaticDefocus {
    /// The extra defocus (µm RMS over the measurement pupil of diameter
    /// `zernike_pupil_diameter_m`) at `wavelength_nm`.
    pub fn defocus_um(&self, wavelength_nm: f64, zernike_pupil_diameter_m: f64) -> f64 {
        match self {
            ChromaticDefocus::None => 0.0,
            ChromaticDefocus::HumanEye { reference_nm } => defocus_um_from_diopters(
                -human_lca_diopters(*reference_nm, wavelength_nm),
                zernike_pupil_diameter_m * 1e3,
            ),
            ChromaticDefocus::Table {
                wavelength_nm: w,
                defocus_um: d,
            } => {
                if wavelength_nm <= w[0] {
                    return d[0];
                }
                if wavelength_nm >= w[w.len() - 1] {
                    return d[d.len() - 1];
                }
                let k = w.partition_point(|&x| x <= wavelength_nm);
                let t = (wavelength_nm - w[k - 1]) / (w[k] - w[k - 1]);
                d[k - 1] + t * (d[k] - d[k - 1])
            }
        }
    }
}

/// Area of the regular `n`-gon of circumradius `r`: `(n/2) r² sin(2π/n)`.
pub fn polygon_area(blades: u32, circumradius: f64) -> f64 {
    0.5 * blades as f64 * circumradius * circumradius * (2.0 * PI / blades as f64).sin()
}

/// A pupil with Zernike aberrations, chromatic defocus and an optional polygonal aperture
/// (the `wavefront` blur's options beyond defocus; see the module docs for the conventions).
#[derive(Debug, Clone, PartialEq)]
pub struct WavefrontPupil {
    /// Zernike terms (OSA/ANSI j, µm RMS over the measurement pupil); a j may repeat (summed).
    pub zernike: Vec<ZernikeTerm>,
    /// Measurement-pupil diameter `D_z` (m) of the coefficients; None = the aperture `f/N`.
    pub zernike_pupil_diameter_m: Option<f64>,
    /// Longitudinal chromatic aberration.
    pub chromatic_defocus: ChromaticDefocus,
    /// Aperture blades (≥ 3): a regular polygon; None = a circle.
    pub blades: Option<u32>,
    /// Minimum pupil samples across the diameter (16..=4096); raised automatically until the
    /// wavefront changes by at most 1/8 wave between samples.
    pub pupil_samples: usize,
}

/// The sampled pupil function `P(ξ, η) = t(ξ, η) exp(2πi W(ξ, η)/λ)` on `samples × samples`
/// cells across the aperture diameter (row 0 at the top, y up), with `t` the fraction of each
/// cell inside the aperture (8 × 8 sub-samples near the edge).
#[derive(Debug, Clone, PartialEq)]
pub struct PupilField {
    /// Samples across the diameter.
    pub samples: usize,
    /// Cell-centre coordinates `ξ_k = −1 + (k + ½)·2/samples` (unit radius).
    pub coord: Vec<f64>,
    /// Row-major complex samples (row a at `η = −coord[a]`, column b at `ξ = coord[b]`).
    pub data: Vec<Complex64>,
}

impl PupilField {
    /// Open area `Σ t Δξ²` in units of the squared aperture radius (π for a circle).
    pub fn area(&self) -> f64 {
        let d = 2.0 / self.samples as f64;
        self.data.iter().map(|p| p.norm()).sum::<f64>() * d * d
    }

    /// Transmitted power `Σ |P|² Δξ²` (units of the squared aperture radius): by Parseval,
    /// the integral of [`PupilField::intensity_at`] over the image plane is
    /// `(2λN)² / Δξ⁴` times this (`Δξ = 2 / samples`).
    pub fn power(&self) -> f64 {
        let d = 2.0 / self.samples as f64;
        self.data.iter().map(|p| p.norm_sqr()).sum::<f64>() * d * d
    }

    /// Unnormalised `|Σ P exp(−iπ (x ξ + y η)/(λN))|²` at the image point `(x_m, y_m)` (y up)
    /// for `lambda_n_m` = λN: the PSF at any point, for tests of its symmetry.
    pub fn intensity_at(&self, x_m: f64, y_m: f64, lambda_n_m: f64) -> f64 {
        let np = self.samples;
        let mut acc = Complex64::new(0.0, 0.0);
        for a in 0..np {
            let eta = -self.coord[a];
            for b in 0..np {
                let p = self.data[a * np + b];
                if p.re == 0.0 && p.im == 0.0 {
                    continue;
                }
                let ph = -PI * (x_m * self.coord[b] + y_m * eta) / lambda_n_m;
                acc += p * Complex64::from_polar(1.0, ph);
            }
        }
        acc.norm_sqr()
    }
}

impl WavefrontPupil {
    /// Check every parameter; errors name the offending value.
    pub fn validate(&self) -> Result<(), OpticsError> {
        for t in &self.zernike {
            if !t.rms_um.is_finite() {
                return Err(OpticsError::InvalidParameter {
                    name: "zernike_um",
                    value: t.rms_um,
                    reason: "must be finite",
                });
            }
            if t.j > 65 {
                return Err(OpticsError::InvalidParameter {
                    name: "zernike_um index j",
                    value: t.j as f64,
                    reason: "OSA index must be 0..=65 (radial order ≤ 10)",
                });
            }
        }
        if let Some(d) = self.zernike_pupil_diameter_m {
            check_positive("zernike_pupil_diameter_mm", d * 1e3, false)?;
        }
        if let Some(b) = self.blades {
            if !(3..=64).contains(&b) {
                return Err(OpticsError::InvalidParameter {
                    name: "blades",
                    value: b as f64,
                    reason: "must be between 3 and 64",
                });
            }
        }
        if !(16..=4096).contains(&self.pupil_samples) {
            return Err(OpticsError::InvalidParameter {
                name: "pupil_samples",
                value: self.pupil_samples as f64,
                reason: "must be between 16 and 4096",
            });
        }
        match &self.chromatic_defocus {
            ChromaticDefocus::None => {}
            ChromaticDefocus::HumanEye { reference_nm } => {
                if !(reference_nm.is_finite() && *reference_nm > 300.0) {
                    return Err(OpticsError::InvalidParameter {
                        name: "chromatic_defocus.reference_nm",
                        value: *reference_nm,
                        reason: "must be a wavelength > 300 nm (the fit's pole is at 214 nm)",
                    });
                }
            }
            ChromaticDefocus::Table {
                wavelength_nm,
                defocus_um,
            } => {
                if wavelength_nm.is_empty() || wavelength_nm.len() != defocus_um.len() {
                    return Err(OpticsError::InvalidParameter {
                        name: "chromatic_defocus.defocus_um",
                        value: defocus_um.len() as f64,
                        reason: "needs one value per wavelength_nm entry (at least one)",
                    });
                }
                if wavelength_nm.windows(2).any(|w| !(w[1] > w[0]))
                    || wavelength_nm.iter().any(|w| !w.is_finite())
                {
                    return Err(OpticsError::InvalidParameter {
                        name: "chromatic_defocus.wavelength_nm",
                        value: wavelength_nm[0],
                        reason: "must be finite and strictly increasing",
                    });
                }
                if let Some(v) = defocus_um.iter().find(|v| !v.is_finite()) {
                    return Err(OpticsError::InvalidParameter {
                        name: "chromatic_defocus.defocus_um",
                        value: *v,
                        reason: "must be finite",
                    });
                }
            }
        }
        Ok(())
    }

    /// The measurement-to-aperture scale `s = D / D_z` (≤ 1) for the aperture diameter
    /// `aperture_diameter_m`.
    fn scale(&self, aperture_diameter_m: f64) -> Result<(f64, f64), OpticsError> {
        let dz = self.zernike_pupil_diameter_m.unwrap_or(aperture_diameter_m);
        let s = aperture_diameter_m / dz;
        if s > 1.0 + 1e-9 {
            return Err(OpticsError::InvalidParameter {
                name: "zernike_pupil_diameter_mm",
                value: dz * 1e3,
                reason: "must be at least the aperture diameter focal_length / f_number \
                         (the wavefront is unknown outside the measurement pupil)",
            });
        }
        Ok((s.min(1.0), dz))
    }

    /// Wavefront `W(ξ, η)` (µm) at aperture coordinates (unit radius, y up) for wavelength
    /// `wavelength_nm`, with the measurement scale `s` and measurement diameter `dz_m`.
    fn wavefront_um(&self, xi: f64, eta: f64, s: f64, c4_extra_um: f64) -> f64 {
        let (rho, theta) = ((xi * xi + eta * eta).sqrt() * s, eta.atan2(xi));
        let mut w = c4_extra_um * zernike_osa(4, rho, theta);
        for t in &self.zernike {
            if t.rms_um != 0.0 {
                w += t.rms_um * zernike_osa(t.j, rho, theta);
            }
        }
        w
    }

    /// Signed "outside" measure of the aperture at (ξ, η): < 0 inside, > 0 outside, 0 on the
    /// edge (a distance for the polygon's sides and the circle).
    fn outside(&self, xi: f64, eta: f64) -> f64 {
        match self.blades {
            None => (xi * xi + eta * eta).sqrt() - 1.0,
            Some(n) => {
                let apothem = (PI / n as f64).cos();
                (0..n)
                    .map(|k| {
                        let a = PI / 2.0 + PI / n as f64 + 2.0 * PI * k as f64 / n as f64;
                        xi * a.cos() + eta * a.sin() - apothem
                    })
                    .fold(f64::NEG_INFINITY, f64::max)
            }
        }
    }

    /// The largest wavefront slope |∇W| (µm per unit radius) over the aperture, by finite
    /// differences on a 64² grid (sets the PSF support and the pupil sampling).
    fn max_slope_um(&self, s: f64, c4_um: f64) -> f64 {
        let n = 64;
        let h = 1e-4;
        let mut g: f64 = 0.0;
        for a in 0..=n {
            for b in 0..=n {
                let (x, y) = (
                    -1.0 + 2.0 * b as f64 / n as f64,
                    -1.0 + 2.0 * a as f64 / n as f64,
                );
                if x * x + y * y > 1.0 {
                    continue;
                }
                let gx = (self.wavefront_um(x + h, y, s, c4_um)
                    - self.wavefront_um(x - h, y, s, c4_um))
                    / (2.0 * h);
                let gy = (self.wavefront_um(x, y + h, s, c4_um)
                    - self.wavefront_um(x, y - h, s, c4_um))
                    / (2.0 * h);
                g = g.max(gx.hypot(gy));
            }
        }
        g
    }

    /// The sampled pupil function at `wavelength_nm` for the aperture diameter
    /// `aperture_diameter_m` (= f/N), with `samples` cells across.
    pub fn pupil_field(
        &self,
        wavelength_nm: f64,
        aperture_diameter_m: f64,
        samples: usize,
    ) -> Result<PupilField, OpticsError> {
        self.validate()?;
        check_positive("wavelength_nm", wavelength_nm, false)?;
        let (s, dz) = self.scale(aperture_diameter_m)?;
        let c4 = self.chromatic_defocus.defocus_um(wavelength_nm, dz);
        let lambda_um = wavelength_nm * 1e-3;
        let np = samples;
        let d = 2.0 / np as f64;
        let coord: Vec<f64> = (0..np).map(|k| -1.0 + (k as f64 + 0.5) * d).collect();
        let diag = d * std::f64::consts::FRAC_1_SQRT_2;
        const SUB: usize = 8;
        let mut data = vec![Complex64::new(0.0, 0.0); np * np];
        for a in 0..np {
            let eta = -coord[a];
            for b in 0..np {
                let xi = coord[b];
                let o = self.outside(xi, eta);
                let t = if o < -diag {
                    1.0
                } else if o > diag {
                    0.0
                } else {
                    let mut c = 0usize;
                    for u in 0..SUB {
                        for v in 0..SUB {
                            let y = eta + d * ((u as f64 + 0.5) / SUB as f64 - 0.5);
                            let x = xi + d * ((v as f64 + 0.5) / SUB as f64 - 0.5);
                            if self.outside(x, y) <= 0.0 {
                                c += 1;
                            }
                        }
                    }
                    c as f64 / (SUB * SUB) as f64
                };
                if t > 0.0 {
                    let w = self.wavefront_um(xi, eta, s, c4);
                    data[a * np + b] = Complex64::from_polar(t, 2.0 * PI * w / lambda_um);
                }
            }
        }
        Ok(PupilField {
            samples: np,
            coord,
            data,
        })
    }

    /// The pupil samples used at `wavelength_nm`: `pupil_samples`, raised (up to 4096) until the
    /// wavefront changes by at most 1/8 wave per sample (`8 |∇W|max / λ` per unit radius).
    pub fn samples_for(
        &self,
        wavelength_nm: f64,
        aperture_diameter_m: f64,
    ) -> Result<usize, OpticsError> {
        let (s, dz) = self.scale(aperture_diameter_m)?;
        let c4 = self.chromatic_defocus.defocus_um(wavelength_nm, dz);
        let slope_waves = self.max_slope_um(s, c4) / (wavelength_nm * 1e-3);
        let need = (16.0 * slope_waves).ceil();
        if need > 4096.0 {
            return Err(OpticsError::InvalidParameter {
                name: "zernike_um",
                value: slope_waves,
                reason: "wavefront too steep (waves per pupil radius) for a 4096-sample pupil",
            });
        }
        Ok(self.pupil_samples.max(need as usize))
    }

    /// The PSF at `wavelength_nm` for the working f-number `f_number` (diffraction scale λN)
    /// and the aperture diameter `aperture_diameter_m` (f/N), sampled at `pitch_m`: `|F{P}|²`
    /// by the matrix Fourier transform (as [`crate::wavefront_psf`]) over a radius of
    /// `10 λN + 2N |∇W|max` (the diffraction core plus the geometric ray fan, ≤ the
    /// alias-free 0.45 λN · samples), normalised to sum 1.
    pub fn psf(
        &self,
        wavelength_nm: f64,
        f_number: f64,
        aperture_diameter_m: f64,
        pitch_m: f64,
    ) -> Result<SampledPsf, OpticsError> {
        check_positive("f_number", f_number, false)?;
        check_positive("sample_pitch_m", pitch_m, false)?;
        let np = self.samples_for(wavelength_nm, aperture_diameter_m)?;
        let field = self.pupil_field(wavelength_nm, aperture_diameter_m, np)?;
        let (s, dz) = self.scale(aperture_diameter_m)?;
        let c4 = self.chromatic_defocus.defocus_um(wavelength_nm, dz);
        let ln = wavelength_nm * 1e-9 * f_number;
        let ray_m = 2.0 * f_number * self.max_slope_um(s, c4) * 1e-6;
        Ok(pupil_psf(
            &field.data,
            np,
            &field.coord,
            ln,
            10.0 * ln + ray_m,
            pitch_m,
        ))
    }

    /// Largest PSF half-width (m) over `wavelengths_nm` for the blur margin: `10 λN + 2N |∇W|max`.
    pub fn reach_m(
        &self,
        wavelengths_nm: &[f64],
        f_number: f64,
        aperture_diameter_m: f64,
    ) -> Result<f64, OpticsError> {
        let (s, dz) = self.scale(aperture_diameter_m)?;
        let mut r: f64 = 0.0;
        for &w in wavelengths_nm {
            let c4 = self.chromatic_defocus.defocus_um(w, dz);
            r = r
                .max(10.0 * w * 1e-9 * f_number + 2.0 * f_number * self.max_slope_um(s, c4) * 1e-6);
        }
        Ok(r)
    }
}
