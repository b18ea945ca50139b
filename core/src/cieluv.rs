//! CIE 1976 UCS chromaticity (u′, v′), CIELUV and ΔE*uv (CIE 15:2004 §8.1–8.2.2).
use crate::colorimetry::{xyz_to_lab, Xyz};

/// CIE 1976 UCS chromaticity coordinates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UvPrime {
    /// u′
    pub u: f64,
    /// v′
    pub v: f64,
}

/// CIELUV coordinates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Luv {
    /// L* (the same lightness as CIELAB's)
    pub l: f64,
    /// u*
    pub u: f64,
    /// v*
    pub v: f64,
}

/// CIE 1976 UCS chromaticity (CIE 15:2004 Eq. 8.5): `u′ = 4X / (X + 15Y + 3Z)`,
/// `v′ = 9Y / (X + 15Y + 3Z)`; (0, 0) for black (X + 15Y + 3Z = 0), as ISETCam's `xyz2uv`.
pub fn xyz_to_uv_prime(xyz: Xyz) -> UvPrime {
    let d = xyz.x + 15.0 * xyz.y + 3.0 * xyz.z;
    if d == 0.0 {
        return UvPrime { u: 0.0, v: 0.0 };
    }
    UvPrime {
        u: 4.0 * xyz.x / d,
        v: 9.0 * xyz.y / d,
    }
}

/// CIELUV (CIE 15:2004 Eqs. 8.6–8.8): `L*` as in CIELAB, `u* = 13 L* (u′ − u′ₙ)`,
/// `v* = 13 L* (v′ − v′ₙ)` with (u′ₙ, v′ₙ) the white's chromaticity.
pub fn xyz_to_luv(xyz: Xyz, white: Xyz) -> Luv {
    let l = xyz_to_lab(xyz, white).l;
    let (c, n) = (xyz_to_uv_prime(xyz), xyz_to_uv_prime(white));
    Luv {
        l,
        u: 13.0 * l * (c.u - n.u),
        v: 13.0 * l * (c.v - n.v),
    }
}

/// ΔE*uv (CIE 15:2004 Eq. 8.9): Euclidean distance in CIELUV.
pub fn delta_e_uv(a: Luv, b: Luv) -> f64 {
    ((a.l - b.l).powi(2) + (a.u - b.u).powi(2) + (a.v - b.v).powi(2)).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    const D65: Xyz = Xyz {
        x: 95.047,
        y: 100.0,
        z: 108.883,
    };

    /// The D65 white's chromaticity from its xy (0.31271, 0.32902) by the independent
    /// route `u′ = 4x / (−2x + 12y + 3)`, `v′ = 9y / (−2x + 12y + 3)` (CIE 15:2004 Eq. 8.5b).
    #[test]
    fn uv_prime_matches_the_xy_route() {
        let s = D65.x + D65.y + D65.z;
        let (x, y) = (D65.x / s, D65.y / s);
        let d = -2.0 * x + 12.0 * y + 3.0;
        let c = xyz_to_uv_prime(D65);
        assert!((c.u - 4.0 * x / d).abs() < 1e-12, "{}", c.u);
        assert!((c.v - 9.0 * y / d).abs() < 1e-12, "{}", c.v);
        // D65's commonly tabulated u′v′: 0.1978, 0.4683
        assert!(
            (c.u - 0.1978).abs() < 1e-4 && (c.v - 0.4683).abs() < 1e-4,
            "{c:?}"
        );
        assert_eq!(
            xyz_to_uv_prime(Xyz {
                x: 0.0,
                y: 0.0,
                z: 0.0
            }),
            UvPrime { u: 0.0, v: 0.0 }
        );
    }

    /// The white maps to (100, 0, 0); a grey keeps u* = v* = 0; a hand-computed colour.
    #[test]
    fn luv_of_white_grey_and_a_colour() {
        let w = xyz_to_luv(D65, D65);
        assert!((w.l - 100.0).abs() < 1e-9 && w.u.abs() < 1e-9 && w.v.abs() < 1e-9);
        let g = xyz_to_luv(
            Xyz {
                x: 0.2 * D65.x,
                y: 20.0,
                z: 0.2 * D65.z,
            },
            D65,
        );
        assert!(g.u.abs() < 1e-9 && g.v.abs() < 1e-9, "{g:?}");
        // X, Y, Z = 20, 30, 15: d = 20 + 450 + 45 = 515; u′ = 80/515, v′ = 270/515;
        // L* = 116·0.3^(1/3) − 16 = 61.6542222 (the CIELAB oracle's value).
        let c = xyz_to_luv(
            Xyz {
                x: 20.0,
                y: 30.0,
                z: 15.0,
            },
            D65,
        );
        let n = xyz_to_uv_prime(D65);
        let l = 116.0 * 0.3f64.cbrt() - 16.0;
        assert!((c.l - l).abs() < 1e-9);
        assert!((c.u - 13.0 * l * (80.0 / 515.0 - n.u)).abs() < 1e-9);
        assert!((c.v - 13.0 * l * (270.0 / 515.0 - n.v)).abs() < 1e-9);
        let d = delta_e_uv(c, w);
        let want = ((c.l - 100.0).powi(2) + c.u * c.u + c.v * c.v).sqrt();
        assert!((d - want).abs() < 1e-12);
    }
}
