//! CIE colorimetry: XYZ, luminance, CIELAB and ΔE*ab (CIE 15:2004).
use crate::constants::LUMINOUS_EFFICACY_LM_PER_W;
use crate::data;
use crate::spectrum::Spectrum;

/// CIE XYZ tristimulus values.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Xyz {
    /// X
    pub x: f64,
    /// Y (luminance when computed from radiance with Km = 683)
    pub y: f64,
    /// Z
    pub z: f64,
}

/// CIELAB coordinates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Lab {
    /// L*
    pub l: f64,
    /// a*
    pub a: f64,
    /// b*
    pub b: f64,
}

/// How spectral integrals are evaluated.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Quadrature {
    /// Exact integral of the piecewise-linear product (camsim default).
    Exact,
    /// Σ_λ f g Δλ on a regular grid (ISETCam convention).
    RiemannOnGrid {
        /// first wavelength
        start_nm: u32,
        /// step
        step_nm: u32,
        /// count
        count: u32,
    },
}

fn integrate(a: &Spectrum, b: &Spectrum, q: Quadrature) -> f64 {
    match q {
        Quadrature::Exact => Spectrum::integrate_product(a, b).unwrap_or(0.0),
        Quadrature::RiemannOnGrid {
            start_nm,
            step_nm,
            count,
        } => {
            (0..count)
                .map(|i| {
                    let w = (start_nm + i * step_nm) as f64;
                    a.eval(w) * b.eval(w)
                })
                .sum::<f64>()
                * step_nm as f64
        }
    }
}

/// XYZ = 683 ∫ E(λ) cmf(λ) dλ of an energy spectrum (W/(sr·m²·nm) radiance → Y in cd/m²).
pub fn xyz_from_energy(energy: &Spectrum, q: Quadrature) -> Xyz {
    let cmf = data::cie1931_xyz().expect("embedded CIE XYZ");
    let k = LUMINOUS_EFFICACY_LM_PER_W;
    Xyz {
        x: k * integrate(energy, &cmf[0], q),
        y: k * integrate(energy, &cmf[1], q),
        z: k * integrate(energy, &cmf[2], q),
    }
}

/// Luminance (cd/m²) of an energy radiance spectrum: 683 ∫ L(λ) ȳ(λ) dλ.
pub fn luminance_from_energy(energy: &Spectrum, q: Quadrature) -> f64 {
    xyz_from_energy(energy, q).y
}

/// The luminance weight ȳ(λ)·683 expressed for photon spectra: 683 · ȳ(λ) · h c / λ, so that
/// `∫ w(λ) L_photons(λ) dλ` is the luminance. Sampled at 1 nm on the CMF support.
pub fn luminance_weight_for_photons(c: &crate::constants::PhysicalConstants) -> Spectrum {
    let cmf = data::cie1931_xyz().expect("embedded CIE XYZ");
    let (lo, hi) = cmf[1].support_nm();
    let n = (hi - lo).round() as usize;
    let w: Vec<f64> = (0..=n).map(|i| lo + i as f64).collect();
    let v = w
        .iter()
        .map(|&x| LUMINOUS_EFFICACY_LM_PER_W * cmf[1].eval(x) / c.photons_per_joule(x))
        .collect();
    Spectrum::sampled(w, v).expect("valid weight")
}

/// CIELAB from XYZ and the white point (CIE 1976; the linear segment below (6/29)³).
pub fn xyz_to_lab(xyz: Xyz, white: Xyz) -> Lab {
    fn f(t: f64) -> f64 {
        if t > 0.008856 {
            t.cbrt()
        } else {
            7.787 * t + 16.0 / 116.0
        }
    }
    let (fx, fy, fz) = (f(xyz.x / white.x), f(xyz.y / white.y), f(xyz.z / white.z));
    let yr = xyz.y / white.y;
    let l = if yr > 0.008856 {
        116.0 * fy - 16.0
    } else {
        903.3 * yr
    };
    Lab {
        l,
        a: 500.0 * (fx - fy),
        b: 200.0 * (fy - fz),
    }
}

/// ΔE*ab (1976): Euclidean distance in CIELAB.
pub fn delta_e_76(a: Lab, b: Lab) -> f64 {
    ((a.l - b.l).powi(2) + (a.a - b.a).powi(2) + (a.b - b.b).powi(2)).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn lab_and_delta_e_oracles() {
        // ../shared/oracles/isetcam/cases/metrics_xyz_to_lab_1d.json, metrics_delta_e_ab_1976_1d.json
        let w = Xyz {
            x: 95.047,
            y: 100.0,
            z: 108.883,
        };
        let lab = xyz_to_lab(
            Xyz {
                x: 20.0,
                y: 30.0,
                z: 15.0,
            },
            w,
        );
        assert_relative_eq!(lab.l, 61.65422221, max_relative = 1e-9);
        assert_relative_eq!(lab.a, -37.32133644, max_relative = 1e-9);
        assert_relative_eq!(lab.b, 30.59291656, max_relative = 1e-9);
        let lab2 = xyz_to_lab(
            Xyz {
                x: 18.0,
                y: 27.0,
                z: 16.5,
            },
            w,
        );
        assert_relative_eq!(
            delta_e_76(lab, lab2),
            8.492362455389074,
            max_relative = 1e-9
        );
    }
}
