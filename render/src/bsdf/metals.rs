//! Spectral complex refractive indices η + iκ of named metals from the Lorentz–Drude model of
//! Rakić, Djurišić, Elazar & Majewski, "Optical properties of metallic films for
//! vertical-cavity optoelectronic devices", Applied Optics 37(22), 5271–5283 (1998), Table 1
//! (LD parameters fitted to measured data, valid over roughly 0.1–5 eV, i.e. the visible):
//!
//! ε(ω) = 1 − f₀ωₚ² / (ω(ω + iΓ₀)) + Σⱼ fⱼωₚ² / ((ωⱼ² − ω²) − iωΓⱼ), η + iκ = √ε, ω = hc/λ in eV.
//!
//! Names follow Mitsuba's conductor presets (Au, Ag, Cu, Al). Values differ from Mitsuba's
//! tabulated presets by a few per cent; for a like-for-like comparison give η and κ
//! explicitly.
use crate::spectral::TabulatedSpectrum;

/// (ωₚ, [(f₀, Γ₀)], [(fⱼ, Γⱼ, ωⱼ)]) in eV.
type Ld = (f64, (f64, f64), &'static [(f64, f64, f64)]);

const AU: Ld = (
    9.03,
    (0.760, 0.053),
    &[
        (0.024, 0.241, 0.415),
        (0.010, 0.345, 0.830),
        (0.071, 0.870, 2.969),
        (0.601, 2.494, 4.304),
        (4.384, 2.214, 13.32),
    ],
);
const AG: Ld = (
    9.01,
    (0.845, 0.048),
    &[
        (0.065, 3.886, 0.816),
        (0.124, 0.452, 4.481),
        (0.011, 0.065, 8.185),
        (0.840, 0.916, 9.083),
        (5.646, 2.419, 20.29),
    ],
);
const CU: Ld = (
    10.83,
    (0.575, 0.030),
    &[
        (0.061, 0.378, 0.291),
        (0.104, 1.056, 2.957),
        (0.723, 3.213, 5.300),
        (0.638, 4.305, 11.18),
    ],
);
const AL: Ld = (
    14.98,
    (0.523, 0.047),
    &[
        (0.227, 0.333, 0.162),
        (0.050, 0.312, 1.544),
        (0.166, 1.351, 1.808),
        (0.030, 3.382, 3.473),
    ],
);

/// The metals known by name.
pub const NAMES: &[&str] = &["Au", "Ag", "Cu", "Al"];

/// η + iκ at `nm` from a Lorentz–Drude parameter set.
fn ld_index(p: &Ld, nm: f64) -> (f64, f64) {
    let (wp, (f0, g0), osc) = *p;
    let w = 1239.841984 / nm;
    // complex as (re, im)
    let inv = |a: f64, b: f64| {
        let d = a * a + b * b;
        (a / d, -b / d)
    };
    // ε = 1 − f0 wp² / (w² + i w g0)
    let (ir, ii) = inv(w * w, w * g0);
    let mut er = 1.0 - f0 * wp * wp * ir;
    let mut ei = -f0 * wp * wp * ii;
    for &(f, g, wj) in osc {
        let (ir, ii) = inv(wj * wj - w * w, -w * g);
        er += f * wp * wp * ir;
        ei += f * wp * wp * ii;
    }
    // principal square root
    let r = (er * er + ei * ei).sqrt();
    let n = (0.5 * (r + er)).max(0.0).sqrt();
    let k = (0.5 * (r - er)).max(0.0).sqrt().copysign(ei);
    (n, k)
}

/// Spectral (η, κ) of a named metal tabulated at 1 nm over 300–830 nm, divided by the
/// exterior index `ext_ior`; None for an unknown name.
pub fn metal(name: &str, ext_ior: f64) -> Option<(TabulatedSpectrum, TabulatedSpectrum)> {
    let p = match name {
        "Au" => &AU,
        "Ag" => &AG,
        "Cu" => &CU,
        "Al" => &AL,
        _ => return None,
    };
    Some((
        TabulatedSpectrum::from_fn(300.0, 830.0, |w| ld_index(p, w).0 / ext_ior),
        TabulatedSpectrum::from_fn(300.0, 830.0, |w| ld_index(p, w).1 / ext_ior),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Spot checks against the measured data the model was fitted to (Johnson & Christy 1972
    /// for Au, Ag, Cu; Rakić 1995 for Al), to ~10 %.
    #[test]
    fn indices_are_close_to_measured_values() {
        let cases = [
            ("Au", 550.0, 0.43, 2.46),
            ("Ag", 550.0, 0.12, 3.34),
            ("Cu", 650.0, 0.21, 3.67),
            ("Al", 550.0, 0.96, 6.69),
        ];
        for (name, nm, n, k) in cases {
            let (e, kk) = metal(name, 1.0).unwrap();
            let (e, kk) = (e.eval(nm as f32) as f64, kk.eval(nm as f32) as f64);
            assert!((kk - k).abs() / k < 0.1, "{name} κ {kk} vs {k}");
            assert!((e - n).abs() < 0.15, "{name} η {e} vs {n}");
        }
        assert!(metal("Unobtainium", 1.0).is_none());
    }
}
