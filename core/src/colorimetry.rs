//! CIE colorimetry: XYZ, luminance, CIELAB and ΔE*ab (CIE 15:2004), and the sRGB colour space
//! (IEC 61966-2-1:1999): its XYZ ↔ linear-RGB matrices and its transfer curve. Every crate
//! takes these from here; none keeps a copy.
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

/// CIE XYZ → linear sRGB (IEC 61966-2-1:1999, D65 white), applied as `rgb = M · xyz`: the
/// matrix derived from the sRGB primaries and the D65 white point at full precision (the
/// standard prints it rounded to four decimals); the exact inverse of [`LINEAR_SRGB_TO_XYZ`].
pub const XYZ_TO_LINEAR_SRGB: [[f64; 3]; 3] = [
    [3.2404542, -1.5371385, -0.4985314],
    [-0.9692660, 1.8760108, 0.0415560],
    [0.0556434, -0.2040259, 1.0572252],
];

/// Linear sRGB → CIE XYZ (IEC 61966-2-1:1999, D65 white), applied as `xyz = M · rgb`; its
/// middle row is the luminance of the three primaries (sRGB (1, 1, 1) has Y = 1).
pub const LINEAR_SRGB_TO_XYZ: [[f64; 3]; 3] = [
    [0.4124564, 0.3575761, 0.1804375],
    [0.2126729, 0.7151522, 0.0721750],
    [0.0193339, 0.1191920, 0.9503041],
];

/// `m · v` for a row-major 3×3 matrix.
#[inline]
pub fn mat3_apply(m: &[[f64; 3]; 3], v: [f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|i| m[i][0] * v[0] + m[i][1] * v[1] + m[i][2] * v[2])
}

/// Linear sRGB → CIE XYZ ([`LINEAR_SRGB_TO_XYZ`]).
pub fn linear_srgb_to_xyz(rgb: [f64; 3]) -> [f64; 3] {
    mat3_apply(&LINEAR_SRGB_TO_XYZ, rgb)
}

/// CIE XYZ → linear sRGB ([`XYZ_TO_LINEAR_SRGB`]).
pub fn xyz_to_linear_srgb(xyz: [f64; 3]) -> [f64; 3] {
    mat3_apply(&XYZ_TO_LINEAR_SRGB, xyz)
}

/// The sRGB transfer curve, linear → encoded (IEC 61966-2-1:1999 §5.2): `12.92 v` for
/// `v ≤ 0.0031308`, else `1.055 v^(1/2.4) − 0.055`. Negative inputs are mirrored (odd
/// extension), so the curve is invertible on the whole line; quantisation is the caller's.
pub fn srgb_encode(v: f64) -> f64 {
    if v < 0.0 {
        -srgb_encode(-v)
    } else if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// The sRGB transfer curve, encoded → linear (IEC 61966-2-1:1999 §5.2): `e / 12.92` for
/// `e ≤ 0.04045`, else `((e + 0.055) / 1.055)^2.4`; odd extension for negative inputs.
pub fn srgb_decode(e: f64) -> f64 {
    if e < 0.0 {
        -srgb_decode(-e)
    } else if e <= 0.040_45 {
        e / 12.92
    } else {
        ((e + 0.055) / 1.055).powf(2.4)
    }
}

#[cfg(test)]
mod srgb_tests {
    use super::*;

    #[test]
    fn srgb_matrices_invert_and_white_maps_to_d65() {
        for i in 0..3 {
            for j in 0..3 {
                let e: f64 = (0..3)
                    .map(|k| XYZ_TO_LINEAR_SRGB[i][k] * LINEAR_SRGB_TO_XYZ[k][j])
                    .sum();
                assert!(
                    (e - if i == j { 1.0 } else { 0.0 }).abs() < 2e-6,
                    "{i}{j}: {e}"
                );
            }
        }
        // D65 white (x, y) = (0.3127, 0.3290), Y = 1.
        let w = linear_srgb_to_xyz([1.0; 3]);
        let s = w[0] + w[1] + w[2];
        assert!((w[1] - 1.0).abs() < 1e-6);
        assert!((w[0] / s - 0.3127).abs() < 5e-5 && (w[1] / s - 0.3290).abs() < 5e-5);
    }

    #[test]
    fn srgb_curve_round_trips_and_is_continuous_at_the_knee() {
        for k in -100..=100 {
            let v = k as f64 / 80.0;
            assert!((srgb_decode(srgb_encode(v)) - v).abs() < 1e-12);
        }
        let a = 12.92 * 0.003_130_8;
        let b = 1.055 * 0.003_130_8_f64.powf(1.0 / 2.4) - 0.055;
        assert!((a - b).abs() < 1e-6);
    }
}
