//! Colour-difference formulas beyond ΔE*ab (which lives in `camsim_core::colorimetry`).
//!
//! * CIEDE2000 (CIE 142-2001), implemented exactly as written in G. Sharma, W. Wu and
//!   E. N. Dalal, "The CIEDE2000 color-difference formula: implementation notes, supplementary
//!   test data, and mathematical observations", Color Res. Appl. 30(1), 21–30 (2005),
//!   equations (2)–(22) of that paper;
//! * CIE94 (CIE 116-1995), graphic-arts weights.
use camsim_core::colorimetry::Lab;

/// The parametric factors kL, kC, kH of CIEDE2000 (all 1 under the reference conditions).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ciede2000Weights {
    /// kL, lightness.
    pub k_l: f64,
    /// kC, chroma.
    pub k_c: f64,
    /// kH, hue.
    pub k_h: f64,
}

impl Default for Ciede2000Weights {
    fn default() -> Self {
        Ciede2000Weights {
            k_l: 1.0,
            k_c: 1.0,
            k_h: 1.0,
        }
    }
}

/// 25⁷, the constant of the G and R_C terms.
const POW25_7: f64 = 6_103_515_625.0;

/// Hue angle in degrees in [0, 360); 0 for a = b = 0 (Sharma et al. eq. 4).
fn hue_deg(b: f64, a: f64) -> f64 {
    if a == 0.0 && b == 0.0 {
        return 0.0;
    }
    let h = b.atan2(a).to_degrees();
    if h < 0.0 {
        h + 360.0
    } else {
        h
    }
}

/// CIEDE2000 colour difference ΔE00 under reference conditions (kL = kC = kH = 1).
///
/// Symmetric in its arguments. Validated against all 34 pairs of Table 1 of Sharma, Wu &
/// Dalal (2005).
pub fn delta_e_2000(lab1: Lab, lab2: Lab) -> f64 {
    delta_e_2000_weighted(lab1, lab2, Ciede2000Weights::default())
}

/// CIEDE2000 with explicit parametric factors (Sharma et al. 2005, eqs. 2–22).
pub fn delta_e_2000_weighted(lab1: Lab, lab2: Lab, k: Ciede2000Weights) -> f64 {
    // Step 1: C'_i, h'_i (eqs. 2–7)
    let c1_ab = lab1.a.hypot(lab1.b);
    let c2_ab = lab2.a.hypot(lab2.b);
    let c_ab_mean = 0.5 * (c1_ab + c2_ab);
    let c7 = c_ab_mean.powi(7);
    let g = 0.5 * (1.0 - (c7 / (c7 + POW25_7)).sqrt());
    let a1p = (1.0 + g) * lab1.a;
    let a2p = (1.0 + g) * lab2.a;
    let c1p = a1p.hypot(lab1.b);
    let c2p = a2p.hypot(lab2.b);
    let h1p = hue_deg(lab1.b, a1p);
    let h2p = hue_deg(lab2.b, a2p);

    // Step 2: ΔL', ΔC', ΔH' (eqs. 8–11)
    let dl = lab2.l - lab1.l;
    let dc = c2p - c1p;
    let cc = c1p * c2p;
    let dh_deg = if cc == 0.0 {
        0.0
    } else {
        let d = h2p - h1p;
        if d > 180.0 {
            d - 360.0
        } else if d < -180.0 {
            d + 360.0
        } else {
            d
        }
    };
    let dh_big = 2.0 * cc.sqrt() * (0.5 * dh_deg).to_radians().sin();

    // Step 3: weighting functions (eqs. 12–22)
    let l_mean = 0.5 * (lab1.l + lab2.l);
    let cp_mean = 0.5 * (c1p + c2p);
    let hp_mean = if cc == 0.0 {
        h1p + h2p
    } else if (h1p - h2p).abs() <= 180.0 {
        0.5 * (h1p + h2p)
    } else if h1p + h2p < 360.0 {
        0.5 * (h1p + h2p + 360.0)
    } else {
        0.5 * (h1p + h2p - 360.0)
    };
    let t = 1.0 - 0.17 * (hp_mean - 30.0).to_radians().cos()
        + 0.24 * (2.0 * hp_mean).to_radians().cos()
        + 0.32 * (3.0 * hp_mean + 6.0).to_radians().cos()
        - 0.20 * (4.0 * hp_mean - 63.0).to_radians().cos();
    let d_theta_deg = 30.0 * (-((hp_mean - 275.0) / 25.0).powi(2)).exp();
    let cp7 = cp_mean.powi(7);
    let r_c = 2.0 * (cp7 / (cp7 + POW25_7)).sqrt();
    let l50 = (l_mean - 50.0).powi(2);
    let s_l = 1.0 + 0.015 * l50 / (20.0 + l50).sqrt();
    let s_c = 1.0 + 0.045 * cp_mean;
    let s_h = 1.0 + 0.015 * cp_mean * t;
    let r_t = -(2.0 * d_theta_deg).to_radians().sin() * r_c;

    let tl = dl / (k.k_l * s_l);
    let tc = dc / (k.k_c * s_c);
    let th = dh_big / (k.k_h * s_h);
    (tl * tl + tc * tc + th * th + r_t * tc * th)
        .max(0.0)
        .sqrt()
}

/// CIE94 colour difference ΔE*94 with the graphic-arts constants (CIE 116-1995):
/// kL = kC = kH = 1, S_L = 1, S_C = 1 + 0.045 C*₁, S_H = 1 + 0.015 C*₁.
///
/// Not symmetric: `reference` supplies C*₁ of the weighting functions.
pub fn delta_e_94(reference: Lab, sample: Lab) -> f64 {
    let c1 = reference.a.hypot(reference.b);
    let c2 = sample.a.hypot(sample.b);
    let dl = reference.l - sample.l;
    let dc = c1 - c2;
    let da = reference.a - sample.a;
    let db = reference.b - sample.b;
    // ΔH*² = Δa² + Δb² − ΔC², clamped against rounding below zero
    let dh2 = (da * da + db * db - dc * dc).max(0.0);
    let s_c = 1.0 + 0.045 * c1;
    let s_h = 1.0 + 0.015 * c1;
    (dl * dl + (dc / s_c).powi(2) + dh2 / (s_h * s_h)).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lab(l: f64, a: f64, b: f64) -> Lab {
        Lab { l, a, b }
    }

    /// Table 1 of Sharma, Wu & Dalal, Color Res. Appl. 30(1), 2005, p. 24: pairs
    /// (L1, a1, b1, L2, a2, b2, ΔE00), all 34 rows, values exactly as published.
    const SHARMA_2005_TABLE1: [[f64; 7]; 34] = [
        [50.0000, 2.6772, -79.7751, 50.0000, 0.0000, -82.7485, 2.0425],
        [50.0000, 3.1571, -77.2803, 50.0000, 0.0000, -82.7485, 2.8615],
        [50.0000, 2.8361, -74.0200, 50.0000, 0.0000, -82.7485, 3.4412],
        [
            50.0000, -1.3802, -84.2814, 50.0000, 0.0000, -82.7485, 1.0000,
        ],
        [
            50.0000, -1.1848, -84.8006, 50.0000, 0.0000, -82.7485, 1.0000,
        ],
        [
            50.0000, -0.9009, -85.5211, 50.0000, 0.0000, -82.7485, 1.0000,
        ],
        [50.0000, 0.0000, 0.0000, 50.0000, -1.0000, 2.0000, 2.3669],
        [50.0000, -1.0000, 2.0000, 50.0000, 0.0000, 0.0000, 2.3669],
        [50.0000, 2.4900, -0.0010, 50.0000, -2.4900, 0.0009, 7.1792],
        [50.0000, 2.4900, -0.0010, 50.0000, -2.4900, 0.0010, 7.1792],
        [50.0000, 2.4900, -0.0010, 50.0000, -2.4900, 0.0011, 7.2195],
        [50.0000, 2.4900, -0.0010, 50.0000, -2.4900, 0.0012, 7.2195],
        [50.0000, -0.0010, 2.4900, 50.0000, 0.0009, -2.4900, 4.8045],
        [50.0000, -0.0010, 2.4900, 50.0000, 0.0010, -2.4900, 4.8045],
        [50.0000, -0.0010, 2.4900, 50.0000, 0.0011, -2.4900, 4.7461],
        [50.0000, 2.5000, 0.0000, 50.0000, 0.0000, -2.5000, 4.3065],
        [50.0000, 2.5000, 0.0000, 73.0000, 25.0000, -18.0000, 27.1492],
        [50.0000, 2.5000, 0.0000, 61.0000, -5.0000, 29.0000, 22.8977],
        [50.0000, 2.5000, 0.0000, 56.0000, -27.0000, -3.0000, 31.9030],
        [50.0000, 2.5000, 0.0000, 58.0000, 24.0000, 15.0000, 19.4535],
        [50.0000, 2.5000, 0.0000, 50.0000, 3.1736, 0.5854, 1.0000],
        [50.0000, 2.5000, 0.0000, 50.0000, 3.2972, 0.0000, 1.0000],
        [50.0000, 2.5000, 0.0000, 50.0000, 1.8634, 0.5757, 1.0000],
        [50.0000, 2.5000, 0.0000, 50.0000, 3.2592, 0.3350, 1.0000],
        [
            60.2574, -34.0099, 36.2677, 60.4626, -34.1751, 39.4387, 1.2644,
        ],
        [
            63.0109, -31.0961, -5.8663, 62.8187, -29.7946, -4.0864, 1.2630,
        ],
        [61.2901, 3.7196, -5.3901, 61.4292, 2.2480, -4.9620, 1.8731],
        [35.0831, -44.1164, 3.7933, 35.0232, -40.0716, 1.5901, 1.8645],
        [
            22.7233, 20.0904, -46.6940, 23.0331, 14.9730, -42.5619, 2.0373,
        ],
        [36.4612, 47.8580, 18.3852, 36.2715, 50.5065, 21.2231, 1.4146],
        [90.8027, -2.0831, 1.4410, 91.1528, -1.6435, 0.0447, 1.4441],
        [90.9257, -0.5406, -0.9208, 88.6381, -0.8985, -0.7239, 1.5381],
        [6.7747, -0.2908, -2.4247, 5.8714, -0.0985, -2.2286, 0.6377],
        [2.0776, 0.0795, -1.1350, 0.9033, -0.0636, -0.5514, 0.9082],
    ];

    #[test]
    fn ciede2000_matches_all_34_pairs_of_sharma_2005_table1() {
        for (i, r) in SHARMA_2005_TABLE1.iter().enumerate() {
            let (p, q) = (lab(r[0], r[1], r[2]), lab(r[3], r[4], r[5]));
            let d = delta_e_2000(p, q);
            assert!(
                (d - r[6]).abs() < 1e-4,
                "pair {}: got {d:.6}, table {}",
                i + 1,
                r[6]
            );
            // the formula is symmetric (Sharma et al. §"Mathematical observations")
            let d_rev = delta_e_2000(q, p);
            assert!(
                (d_rev - r[6]).abs() < 1e-4,
                "pair {} reversed: got {d_rev:.6}",
                i + 1
            );
        }
    }

    #[test]
    fn ciede2000_identity_and_neutral_axis() {
        let g = lab(50.0, 0.0, 0.0);
        assert_eq!(delta_e_2000(g, g), 0.0);
        // on the neutral axis only the lightness term remains: ΔL / S_L
        let d = delta_e_2000(lab(50.0, 0.0, 0.0), lab(60.0, 0.0, 0.0));
        let l50: f64 = (55.0f64 - 50.0).powi(2);
        let s_l = 1.0 + 0.015 * l50 / (20.0 + l50).sqrt();
        assert!((d - 10.0 / s_l).abs() < 1e-12);
    }

    #[test]
    fn cie94_reduces_to_its_terms() {
        // pure lightness difference: S_L = 1
        assert!((delta_e_94(lab(50.0, 10.0, 10.0), lab(53.0, 10.0, 10.0)) - 3.0).abs() < 1e-12);
        // pure chroma difference at constant hue: ΔC / (1 + 0.045 C1)
        let d = delta_e_94(lab(50.0, 30.0, 40.0), lab(50.0, 36.0, 48.0));
        assert!((d - 10.0 / (1.0 + 0.045 * 50.0)).abs() < 1e-12);
        // pure hue difference at constant chroma: ΔH / (1 + 0.015 C1), ΔH = chord length
        let d = delta_e_94(lab(50.0, 50.0, 0.0), lab(50.0, 0.0, 50.0));
        assert!((d - 50.0 * 2f64.sqrt() / (1.0 + 0.015 * 50.0)).abs() < 1e-9);
    }
}
