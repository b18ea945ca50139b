//! The illuminant of a spectral scene: CIE daylight, illuminant swap that keeps reflectance,
//! and estimation of the illuminant of a scene that came without one.
//!
//! * **Swap** ([`swap_illuminant`]): `L_new(x, λ) = L(x, λ) / E_old(λ) · E_new(λ)`, i.e. the
//!   reflectance `L / E_old` is kept, then (ISETCam `sceneAdjustIlluminant`, `preserveMean`
//!   = true) the result is scaled so the scene's mean luminance is unchanged.
//! * **Daylight** ([`cie_daylight`]): CIE 15:2004 §3.1, the daylight locus
//!   `x_D(T)` (two cubic fits, 4000–7000 K and 7000–25000 K), `y_D = −3 x_D² + 2.87 x_D − 0.275`,
//!   and `S(λ) = S0 + M1 S1 + M2 S2` with
//!   `M1 = (−1.3515 − 1.7703 x + 5.9114 y) / (0.0241 + 0.2562 x − 0.7341 y)`,
//!   `M2 = (0.0300 − 31.4424 x + 30.0717 y) / (0.0241 + 0.2562 x − 0.7341 y)`
//!   (S0, S1, S2 from ISETCam `cieDaylightBasis`).
//! * **Estimation** ([`estimate_illuminant`]): the candidates are Planckian radiators and CIE
//!   daylights on a grid of 5 mired steps (2000–25000 K for blackbodies, 4000–25000 K for
//!   daylight). The evidence is one spectrum `s(λ)` taken from the scene:
//!   - [`EstimateMethod::GreyWorld`]: the mean radiance over the scene — under the grey-world
//!     hypothesis the mean reflectance is spectrally flat, so `s ∝ E` (Buchsbaum, "A spatial
//!     processor model for object colour perception", J. Franklin Inst. 310(1), 1980);
//!   - [`EstimateMethod::Brightest`]: the mean radiance of the brightest 1 % of the pixels
//!     (by luminance) — the white-patch hypothesis of Retinex: the brightest surface is a
//!     white (Land & McCann, "Lightness and retinex theory", JOSA 61(1), 1971).
//!
//!   Each candidate `e(λ)` is fitted with its best scale, `k = Σ s e / Σ e²`, and scored by the
//!   relative residual `Σ (s − k e)² / Σ s²` over the scene's wavelengths (photon units); the
//!   lowest score wins (a discrete search over the set, as in Finlayson, Hordley & Hubel's
//!   "colour by correlation", IEEE PAMI 23(11), 2001, which also picks from a set of
//!   plausible lights). The winner is scaled so that the brightest 1 % of the pixels have
//!   reflectance 1 in the same least-squares sense (the scale is a convention: reflectance
//!   is then `≤ 1` for the brightest surfaces; with it a swap keeps the scene's brightest
//!   white white).
use crate::colorimetry::luminance_weight_for_photons;
use crate::constants::PhysicalConstants;
use crate::error::CoreError;
use crate::image::{ratio_spectrum, SceneRadiance, SpectralImage};
use crate::scene::{blackbody_energy, PLANCK_C1, PLANCK_C2};
use crate::spectrum::{Spectrum, WavelengthGrid};

/// Which spectrum of the scene the estimate is fitted to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EstimateMethod {
    /// The mean radiance of the whole scene (Buchsbaum 1980).
    GreyWorld,
    /// The mean radiance of the brightest 1 % of the pixels (Land & McCann 1971).
    Brightest,
}

/// The family of a candidate illuminant.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum IlluminantFamily {
    /// A Planckian radiator.
    Blackbody,
    /// A CIE daylight.
    Daylight,
}

/// The result of [`estimate_illuminant`].
#[derive(Debug, Clone, PartialEq)]
pub struct IlluminantEstimate {
    /// Family of the winning candidate.
    pub family: IlluminantFamily,
    /// Its (correlated) colour temperature, K.
    pub cct_k: f64,
    /// The illuminant in photons/(s·sr·m²·nm), scaled so the brightest pixels have
    /// reflectance 1.
    pub spectrum_photons: Spectrum,
    /// Relative residual `Σ (s − k e)² / Σ s²` of the winner's fit.
    pub relative_residual: f64,
}

/// CIE daylight of correlated colour temperature `cct_k` (4000–25000 K), energy units, relative
/// (S0 + M1 S1 + M2 S2; S0 is 100 at 560 nm), on the basis' 5 nm grid (CIE 15:2004 §3.1).
pub fn cie_daylight(cct_k: f64) -> Result<Spectrum, CoreError> {
    if !(4000.0..=25000.0).contains(&cct_k) {
        return Err(CoreError::Target(format!(
            "CIE daylight needs 4000–25000 K, got {cct_k}"
        )));
    }
    let t = cct_k;
    let x = if t <= 7000.0 {
        -4.6070e9 / t.powi(3) + 2.9678e6 / t.powi(2) + 0.09911e3 / t + 0.244063
    } else {
        -2.0064e9 / t.powi(3) + 1.9018e6 / t.powi(2) + 0.24748e3 / t + 0.237040
    };
    let y = -3.0 * x * x + 2.870 * x - 0.275;
    let den = 0.0241 + 0.2562 * x - 0.7341 * y;
    let m1 = (-1.3515 - 1.7703 * x + 5.9114 * y) / den;
    let m2 = (0.0300 - 31.4424 * x + 30.0717 * y) / den;
    let b = crate::data::spectral("lights/cieDaylightBasis")?;
    let (s0, s1, s2) = (&b.spectra[0], &b.spectra[1], &b.spectra[2]);
    let wl = match s0 {
        Spectrum::Sampled { wavelength_nm, .. } => wavelength_nm.clone(),
        Spectrum::Affine { .. } => return Err(CoreError::Target("daylight basis".into())),
    };
    let values = wl
        .iter()
        .map(|&w| s0.eval(w) + m1 * s1.eval(w) + m2 * s2.eval(w))
        .collect();
    Spectrum::sampled(wl, values)
}

/// The candidate set of [`estimate_illuminant`]: (family, CCT in K, energy spectrum), 5 mired
/// steps from 40 to 500 mired.
pub fn candidate_illuminants() -> Result<Vec<(IlluminantFamily, f64, Spectrum)>, CoreError> {
    let mut out = Vec::new();
    for mired in (40..=500).step_by(5) {
        let t = 1e6 / mired as f64;
        out.push((
            IlluminantFamily::Blackbody,
            t,
            blackbody_energy(t, 360.0, 830.0, PLANCK_C1, PLANCK_C2),
        ));
        if (4000.0..=25000.0).contains(&t) {
            out.push((IlluminantFamily::Daylight, t, cie_daylight(t)?));
        }
    }
    Ok(out)
}

/// Mean spectra of a scene sampled on `grid`: over every pixel, and over the brightest 1 %
/// (by luminance, at least one pixel).
fn evidence(
    img: &SpectralImage,
    grid: &WavelengthGrid,
    c: &PhysicalConstants,
) -> (Vec<f64>, Vec<f64>) {
    let n = img.rows * img.cols;
    let lum = img.integrate_against(&luminance_weight_for_photons(c));
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| lum[b].total_cmp(&lum[a]).then(a.cmp(&b)));
    let top = (n / 100).max(1);
    let bright = &order[..top];
    let term_samples: Vec<Vec<f64>> = (0..img.terms())
        .map(|k| img.basis_spectrum(k).sample(grid))
        .collect();
    let means = img.plane_means();
    let mut all = vec![0.0; grid.len()];
    let mut br = vec![0.0; grid.len()];
    for (k, samples) in term_samples.iter().enumerate() {
        let bm = bright.iter().map(|&i| img.planes[k][i] as f64).sum::<f64>() / top as f64;
        for (b, s) in samples.iter().enumerate() {
            all[b] += means[k] * s;
            br[b] += bm * s;
        }
    }
    (all, br)
}

/// Estimate the illuminant of `img` (photon units) on the wavelengths of `grid` (see the module
/// documentation for the method, the candidates and the scale). Errors for a black scene.
pub fn estimate_illuminant(
    img: &SpectralImage,
    grid: &WavelengthGrid,
    method: EstimateMethod,
    c: &PhysicalConstants,
) -> Result<IlluminantEstimate, CoreError> {
    let (all, bright) = evidence(img, grid, c);
    let s = match method {
        EstimateMethod::GreyWorld => &all,
        EstimateMethod::Brightest => &bright,
    };
    let ss: f64 = s.iter().map(|v| v * v).sum();
    if !(ss > 0.0 && ss.is_finite()) {
        return Err(CoreError::Target(
            "cannot estimate the illuminant of a scene without light".into(),
        ));
    }
    let mut best: Option<(f64, IlluminantFamily, f64, Spectrum)> = None;
    for (family, t, e_energy) in candidate_illuminants()? {
        let e = e_energy.energy_to_photons(c);
        let es = e.sample(grid);
        let ee: f64 = es.iter().map(|v| v * v).sum();
        if ee <= 0.0 {
            continue;
        }
        let k = s.iter().zip(&es).map(|(a, b)| a * b).sum::<f64>() / ee;
        let r: f64 = s
            .iter()
            .zip(&es)
            .map(|(a, b)| (a - k * b).powi(2))
            .sum::<f64>()
            / ss;
        if best.as_ref().is_none_or(|b| r < b.0) {
            best = Some((r, family, t, e));
        }
    }
    let (r, family, t, e) = best.expect("candidate set is not empty");
    let es = e.sample(grid);
    let ee: f64 = es.iter().map(|v| v * v).sum();
    let k_white = bright.iter().zip(&es).map(|(a, b)| a * b).sum::<f64>() / ee;
    Ok(IlluminantEstimate {
        family,
        cct_k: t,
        spectrum_photons: e.scaled(k_white),
        relative_residual: r,
    })
}

/// Mean luminance (cd/m²) of every pixel of `scene` (photon units, exact spectral integrals).
fn mean_luminance_all(scene: &SceneRadiance, c: &PhysicalConstants) -> f64 {
    crate::scene::mean_luminance(scene, None, c)
}

/// Swap the scene's illuminant for `new_photons`, keeping reflectance and (when
/// `preserve_mean_luminance`) the mean luminance, as ISETCam's `sceneAdjustIlluminant`. Errors
/// when the scene has no illuminant, or when the old illuminant is zero somewhere the scene has
/// light (reflectance undefined there).
pub fn swap_illuminant(
    scene: &mut SceneRadiance,
    new_photons: &Spectrum,
    preserve_mean_luminance: bool,
    c: &PhysicalConstants,
) -> Result<(), CoreError> {
    let before = if preserve_mean_luminance {
        mean_luminance_all(scene, c)
    } else {
        0.0
    };
    if let Some(old) = &scene.illuminant {
        check_invertible(&scene.radiance, old)?;
    }
    scene.swap_illuminant(new_photons.clone())?;
    if preserve_mean_luminance && before > 0.0 {
        let after = mean_luminance_all(scene, c);
        if after > 0.0 {
            scene.scale(before / after);
        }
    }
    Ok(())
}

/// The ratio `new / old` that a swap multiplies the radiance by (0 where `old` is 0).
pub fn swap_factor(new_photons: &Spectrum, old_photons: &Spectrum) -> Spectrum {
    ratio_spectrum(new_photons, old_photons)
}

/// Refuse a swap where the old illuminant is 0 at a wavelength the scene emits at.
fn check_invertible(img: &SpectralImage, old: &Spectrum) -> Result<(), CoreError> {
    for k in 0..img.terms() {
        let b = img.basis_spectrum(k);
        if let Spectrum::Sampled {
            wavelength_nm,
            values,
        } = &b
        {
            let used = img.planes[k].iter().any(|v| *v != 0.0);
            if !used {
                continue;
            }
            if let Some((w, _)) = wavelength_nm
                .iter()
                .zip(values)
                .find(|(w, v)| **v != 0.0 && old.eval(**w) <= 0.0)
            {
                return Err(CoreError::Target(format!(
                    "the scene's illuminant is 0 at {w} nm where the scene has light: \
                     reflectance is undefined there, so the illuminant cannot be swapped"
                )));
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn d65_from_the_daylight_formula() {
        // CIE D65 is the daylight of 6504 K (6500 · 1.4388/1.4380): the formula must give
        // ISETCam's tabulated D65 shape within the table's rounding.
        let d = cie_daylight(6504.0).unwrap();
        let t = crate::data::illuminant("D65").unwrap();
        let k = t.eval(560.0) / d.eval(560.0);
        for w in (400..=700).step_by(10) {
            let (a, b) = (k * d.eval(w as f64), t.eval(w as f64));
            assert!((a - b).abs() / b < 0.01, "{w} nm: formula {a}, table {b}");
        }
    }
}
