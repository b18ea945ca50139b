//! Spectral machinery of the renderer: output bands, hero-wavelength sampling, fast tabulated
//! spectra, and RGB → spectrum upsampling by the sigmoid-polynomial model of Jakob & Hanika
//! ("A Low-Dimensional Function Space for Efficient Spectral Upsampling", Computer Graphics
//! Forum 38(2), 2019), fitted at load time by Gauss–Newton in CIELAB.
use camsim_core::spectrum::Spectrum;
use std::sync::OnceLock;

/// Number of wavelengths carried by one path (hero wavelength + 3 rotations; Wilkie et al.
/// 2014, "Hero Wavelength Spectral Sampling").
pub const N_WL: usize = 4;

/// The output bands: `count` contiguous bands of `step_nm` from `lo_nm` (edges
/// lo, lo+step, …, hi). Each output channel is the band-averaged spectral radiance
/// (1/(H−L))·∫_L^H L(λ) dλ, as the Mitsuba harness's box spectral response functions.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bands {
    /// First edge (nm).
    pub lo_nm: f32,
    /// Band width (nm).
    pub step_nm: f32,
    /// Number of bands.
    pub count: usize,
}

impl Bands {
    /// Parse `LO:HI:STEP` (nm); HI − LO must be a positive multiple of STEP.
    pub fn parse(text: &str) -> Result<Bands, String> {
        let parts: Vec<&str> = text.split(':').collect();
        let bad = || format!("--bands \"{text}\": expected LO:HI:STEP in nm, e.g. 380:780:10");
        if parts.len() != 3 {
            return Err(bad());
        }
        let v: Vec<f64> = parts
            .iter()
            .map(|p| p.trim().parse::<f64>().map_err(|_| bad()))
            .collect::<Result<_, _>>()?;
        Bands::new(v[0], v[1], v[2]).map_err(|e| format!("--bands \"{text}\": {e}"))
    }

    /// Bands from edges `lo..hi` in steps of `step` (nm).
    pub fn new(lo: f64, hi: f64, step: f64) -> Result<Bands, String> {
        if !(lo > 0.0 && hi > lo && step > 0.0 && lo.is_finite() && hi.is_finite()) {
            return Err(format!(
                "need 0 < LO < HI and STEP > 0, got {lo}:{hi}:{step}"
            ));
        }
        let n = (hi - lo) / step;
        let count = n.round();
        if (n - count).abs() > 1e-6 * n.max(1.0) || count < 1.0 {
            return Err(format!(
                "HI − LO = {} nm is not a whole multiple of STEP = {step} nm",
                hi - lo
            ));
        }
        if count > 4096.0 {
            return Err(format!("{count} bands is too many (at most 4096)"));
        }
        Ok(Bands {
            lo_nm: lo as f32,
            step_nm: step as f32,
            count: count as usize,
        })
    }

    /// Upper edge of the last band (nm).
    pub fn hi_nm(&self) -> f32 {
        self.lo_nm + self.step_nm * self.count as f32
    }
    /// Edges (lo, hi) of band `b` (nm).
    pub fn edges(&self, b: usize) -> (f64, f64) {
        let lo = self.lo_nm as f64 + self.step_nm as f64 * b as f64;
        (lo, lo + self.step_nm as f64)
    }
    /// Centre of band `b` (nm).
    pub fn center_nm(&self, b: usize) -> f64 {
        let (l, h) = self.edges(b);
        0.5 * (l + h)
    }
    /// The band holding wavelength `nm` (clamped to the range).
    #[inline]
    pub fn index(&self, nm: f32) -> usize {
        let i = ((nm - self.lo_nm) / self.step_nm) as isize;
        i.clamp(0, self.count as isize - 1) as usize
    }
    /// The harness channel name `band_LLLL_HHHH` of band `b`.
    pub fn mitsuba_name(&self, b: usize) -> String {
        let (l, h) = self.edges(b);
        format!("band_{:04}_{:04}", l.round() as i64, h.round() as i64)
    }

    /// The 4 wavelengths of one sample: the hero λ₀ = LO + (HI−LO)·u and its rotations by
    /// (HI−LO)/4 (stratified, Wilkie et al. 2014). The density of each is uniform,
    /// 1/(HI−LO), which is also the sum of the bands' box response functions (each of height
    /// 1/STEP on its band) normalised — the same importance the Mitsuba harness uses.
    #[inline]
    pub fn sample_wavelengths(&self, u: f32) -> [f32; N_WL] {
        let span = self.hi_nm() - self.lo_nm;
        let mut out = [0.0; N_WL];
        for (i, o) in out.iter_mut().enumerate() {
            let mut v = u + i as f32 / N_WL as f32;
            if v >= 1.0 {
                v -= 1.0;
            }
            *o = self.lo_nm + span * v;
        }
        out
    }

    /// 1 / density of each sampled wavelength (nm).
    #[inline]
    pub fn inv_pdf_nm(&self) -> f32 {
        self.hi_nm() - self.lo_nm
    }
}

/// A spectrum tabulated on a regular 1 nm grid for fast evaluation in the hot loop (linear
/// interpolation; exact for piecewise-linear input whose breakpoints are whole nanometres),
/// zero outside its support (the capture-format convention).
#[derive(Debug, Clone, PartialEq)]
pub struct TabulatedSpectrum {
    start_nm: f32,
    values: Vec<f32>,
    /// Constant value when the source is a constant (values is then empty).
    constant: Option<f32>,
}

impl TabulatedSpectrum {
    /// A constant spectrum.
    pub fn constant(v: f32) -> Self {
        TabulatedSpectrum {
            start_nm: 0.0,
            values: Vec::new(),
            constant: Some(v),
        }
    }

    /// Tabulate a core spectrum over `[lo, hi]` nm (at least the part where it is defined).
    pub fn from_spectrum(s: &Spectrum) -> Self {
        match s {
            Spectrum::Affine {
                offset,
                slope_per_nm,
            } if *slope_per_nm == 0.0 => TabulatedSpectrum::constant(*offset as f32),
            _ => {
                let (lo, hi) = s.support_nm();
                let (lo, hi) = (lo.max(200.0), hi.min(3000.0));
                let start = lo.floor();
                let n = ((hi.ceil() - start) as usize) + 1;
                let values = (0..n)
                    .map(|i| {
                        let w = start + i as f64;
                        if w < lo || w > hi {
                            0.0
                        } else {
                            s.eval(w) as f32
                        }
                    })
                    .collect();
                TabulatedSpectrum {
                    start_nm: start as f32,
                    values,
                    constant: None,
                }
            }
        }
    }

    /// Tabulate a function on `[lo, hi]` nm at 1 nm.
    pub fn from_fn(lo: f32, hi: f32, f: impl Fn(f64) -> f64) -> Self {
        let start = lo.floor();
        let n = (hi.ceil() - start) as usize + 1;
        TabulatedSpectrum {
            start_nm: start,
            values: (0..n).map(|i| f(start as f64 + i as f64) as f32).collect(),
            constant: None,
        }
    }

    /// Value at `nm`.
    #[inline(always)]
    pub fn eval(&self, nm: f32) -> f32 {
        if let Some(c) = self.constant {
            return c;
        }
        let x = nm - self.start_nm;
        let i = x as usize; // saturates: 0 for x < 0
        if x >= 0.0 && i + 1 < self.values.len() {
            let t = x - i as f32;
            return self.values[i] * (1.0 - t) + self.values[i + 1] * t;
        }
        // the last sample itself, else 0 outside the support
        if x >= 0.0 && i + 1 == self.values.len() && x == i as f32 {
            self.values[i]
        } else {
            0.0
        }
    }

    /// Values at the 4 wavelengths of a sample.
    #[inline(always)]
    pub fn eval4(&self, wl: &[f32; N_WL]) -> [f32; N_WL] {
        [
            self.eval(wl[0]),
            self.eval(wl[1]),
            self.eval(wl[2]),
            self.eval(wl[3]),
        ]
    }

    /// Largest value (used for light selection and sampling weights).
    pub fn max_value(&self) -> f32 {
        self.constant
            .unwrap_or_else(|| self.values.iter().copied().fold(0.0, f32::max))
    }

    /// Mean over `[lo, hi]` nm (1 nm Riemann sum).
    pub fn mean_over(&self, lo: f32, hi: f32) -> f32 {
        let n = ((hi - lo).max(1.0)) as usize;
        (0..n).map(|i| self.eval(lo + i as f32 + 0.5)).sum::<f32>() / n as f32
    }
}

/// Sigmoid-polynomial spectrum s(λ) = S(c₀t² + c₁t + c₂), S(x) = ½ + x/(2√(1+x²)), with
/// t = (λ − 360)/470 the normalised wavelength (Jakob & Hanika 2019, Eq. 3 and 5).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SigmoidPoly {
    /// Coefficients (c₀, c₁, c₂) of the polynomial in t.
    pub c: [f32; 3],
}

const FIT_LO: f64 = 360.0;
const FIT_SPAN: f64 = 470.0;

#[inline]
fn sigmoid(x: f64) -> f64 {
    0.5 + x / (2.0 * (1.0 + x * x).sqrt())
}

impl SigmoidPoly {
    /// Value at `nm`.
    #[inline]
    pub fn eval(&self, nm: f32) -> f32 {
        let t = (nm - FIT_LO as f32) / FIT_SPAN as f32;
        let x = (self.c[0] * t + self.c[1]) * t + self.c[2];
        if !x.is_finite() {
            return if x > 0.0 { 1.0 } else { 0.0 };
        }
        0.5 + x / (2.0 * (1.0 + x * x).sqrt())
    }
}

/// Tables the RGB fit needs (built once): wavelengths, D65 × CMF weights, normalised D65.
struct FitTables {
    wl: Vec<f64>,
    /// D65(λ)·x̄,ȳ,z̄(λ)·Δλ / ∫D65 ȳ (so a perfect white reflector has Y = 1).
    w_xyz: Vec<[f64; 3]>,
    /// XYZ of the D65 white (for CIELAB).
    white: [f64; 3],
    /// D65 normalised to unit luminance: D65(λ)·∫ȳ / ∫D65 ȳ.
    d65_norm: TabulatedSpectrum,
}

pub use camsim_core::colorimetry::{
    LINEAR_SRGB_TO_XYZ as SRGB_TO_XYZ, XYZ_TO_LINEAR_SRGB as XYZ_TO_SRGB,
};

fn fit_tables() -> &'static FitTables {
    static T: OnceLock<FitTables> = OnceLock::new();
    T.get_or_init(|| {
        let d65 = camsim_core::data::illuminant("D65").expect("embedded D65");
        let cmf = camsim_core::data::cie1931_xyz().expect("embedded CIE 1931");
        let (lo, hi) = cmf[1].support_nm();
        let step = 2.0;
        let n = ((hi - lo) / step).round() as usize + 1;
        let wl: Vec<f64> = (0..n).map(|i| lo + step * i as f64).collect();
        let ybar_int: f64 = wl.iter().map(|&w| cmf[1].eval(w) * step).sum();
        let d65y: f64 = wl
            .iter()
            .map(|&w| d65.eval(w) * cmf[1].eval(w) * step)
            .sum();
        let w_xyz: Vec<[f64; 3]> = wl
            .iter()
            .map(|&w| {
                let e = d65.eval(w) * step / d65y;
                [cmf[0].eval(w) * e, cmf[1].eval(w) * e, cmf[2].eval(w) * e]
            })
            .collect();
        let mut white = [0.0; 3];
        for w in &w_xyz {
            for k in 0..3 {
                white[k] += w[k];
            }
        }
        let k = ybar_int / d65y;
        let d65_norm = TabulatedSpectrum::from_fn(300.0, 830.0, |w| d65.eval(w) * k);
        FitTables {
            wl,
            w_xyz,
            white,
            d65_norm,
        }
    })
}

/// D65 normalised to unit luminance (∫ D65n ȳ = ∫ ȳ), the illuminant factor of RGB emission.
pub fn d65_normalized() -> &'static TabulatedSpectrum {
    &fit_tables().d65_norm
}

/// CIELAB of `xyz` under `white` ([`camsim_core::colorimetry::xyz_to_lab`]) as an array.
fn lab(xyz: [f64; 3], white: [f64; 3]) -> [f64; 3] {
    use camsim_core::colorimetry::{xyz_to_lab, Xyz};
    let v = |a: [f64; 3]| Xyz {
        x: a[0],
        y: a[1],
        z: a[2],
    };
    let l = xyz_to_lab(v(xyz), v(white));
    [l.l, l.a, l.b]
}

fn poly_xyz(t: &FitTables, c: [f64; 3]) -> [f64; 3] {
    let mut xyz = [0.0; 3];
    for (w, wx) in t.wl.iter().zip(&t.w_xyz) {
        let x = (w - FIT_LO) / FIT_SPAN;
        let s = sigmoid((c[0] * x + c[1]) * x + c[2]);
        for k in 0..3 {
            xyz[k] += s * wx[k];
        }
    }
    xyz
}

fn mat3(m: &[[f64; 3]; 3], v: [f64; 3]) -> [f64; 3] {
    [
        m[0][0] * v[0] + m[0][1] * v[1] + m[0][2] * v[2],
        m[1][0] * v[0] + m[1][1] * v[1] + m[1][2] * v[2],
        m[2][0] * v[0] + m[2][1] * v[1] + m[2][2] * v[2],
    ]
}

fn solve3(a: [[f64; 3]; 3], b: [f64; 3]) -> Option<[f64; 3]> {
    let det = a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1])
        - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
        + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0]);
    if det.abs() < 1e-300 || !det.is_finite() {
        return None;
    }
    let mut x = [0.0; 3];
    for (i, xi) in x.iter_mut().enumerate() {
        let mut m = a;
        for r in 0..3 {
            m[r][i] = b[r];
        }
        *xi = (m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]))
            / det;
    }
    Some(x)
}

/// Gauss–Newton steps on the CIELAB residual between `target` (linear sRGB) and the sRGB of
/// the sigmoid-polynomial reflectance under D65, starting at `c`.
fn gauss_newton(t: &FitTables, target_xyz: [f64; 3], mut c: [f64; 3], iters: usize) -> [f64; 3] {
    let target = lab(target_xyz, t.white);
    for _ in 0..iters {
        let r0 = lab(poly_xyz(t, c), t.white);
        let res = [r0[0] - target[0], r0[1] - target[1], r0[2] - target[2]];
        if res.iter().map(|r| r * r).sum::<f64>() < 1e-12 {
            break;
        }
        let mut j = [[0.0; 3]; 3];
        for k in 0..3 {
            let h = 1e-5 * (1.0 + c[k].abs());
            let mut cp = c;
            cp[k] += h;
            let rp = lab(poly_xyz(t, cp), t.white);
            for r in 0..3 {
                j[r][k] = (rp[r] - r0[r]) / h;
            }
        }
        let Some(d) = solve3(j, res) else { break };
        // damped update keeps the polynomial from jumping far on the steep sigmoid tails
        let norm = d.iter().map(|x| x * x).sum::<f64>().sqrt();
        let s = if norm > 20.0 { 20.0 / norm } else { 1.0 };
        for k in 0..3 {
            c[k] -= s * d[k];
        }
        if !c.iter().all(|x| x.is_finite()) {
            return [0.0; 3];
        }
    }
    c
}

/// Fit the sigmoid polynomial whose reflectance under D65 has linear sRGB `rgb` (each
/// component clamped to [0, 1]). Continuation from the grey of the same mean, as Jakob &
/// Hanika fit their table outward from the centre.
pub fn fit_rgb(rgb: [f64; 3]) -> SigmoidPoly {
    let t = fit_tables();
    let rgb = rgb.map(|v| v.clamp(0.0, 1.0));
    // pure black/white: the sigmoid saturates; use a large constant argument instead
    let m = (rgb[0] + rgb[1] + rgb[2]) / 3.0;
    if rgb.iter().all(|&v| (v - m).abs() < 1e-9) {
        let v = m.clamp(1e-4, 1.0 - 1e-4);
        // S(x) = v ⇔ x = (2v − 1)/(2√(v(1−v)))
        let x = (2.0 * v - 1.0) / (2.0 * (v * (1.0 - v)).sqrt());
        return SigmoidPoly {
            c: [0.0, 0.0, x as f32],
        };
    }
    let grey = m.clamp(1e-3, 1.0 - 1e-3);
    let x0 = (2.0 * grey - 1.0) / (2.0 * (grey * (1.0 - grey)).sqrt());
    let mut c = [0.0, 0.0, x0];
    let steps = 8;
    for s in 1..=steps {
        let a = s as f64 / steps as f64;
        let target_rgb = [
            grey + a * (rgb[0] - grey),
            grey + a * (rgb[1] - grey),
            grey + a * (rgb[2] - grey),
        ];
        let xyz = mat3(&SRGB_TO_XYZ, target_rgb.map(|v| v.max(1e-6)));
        c = gauss_newton(t, xyz, c, if s == steps { 40 } else { 12 });
    }
    SigmoidPoly {
        c: c.map(|v| v as f32),
    }
}

/// Linear sRGB of reflectance `f(λ)` under D65 (for tests and previews).
pub fn reflectance_to_srgb(f: impl Fn(f32) -> f32) -> [f64; 3] {
    let t = fit_tables();
    let mut xyz = [0.0; 3];
    for (w, wx) in t.wl.iter().zip(&t.w_xyz) {
        let s = f(*w as f32) as f64;
        for k in 0..3 {
            xyz[k] += s * wx[k];
        }
    }
    mat3(&XYZ_TO_SRGB, xyz)
}

/// CIE XYZ weights (x̄, ȳ, z̄ sampled on the CMF support) for previews: returns (λ, x̄, ȳ, z̄).
pub fn cmf_table() -> Vec<(f64, [f64; 3])> {
    let cmf = camsim_core::data::cie1931_xyz().expect("embedded CIE 1931");
    let (lo, hi) = cmf[1].support_nm();
    let n = (hi - lo).round() as usize;
    (0..=n)
        .map(|i| {
            let w = lo + i as f64;
            (w, [cmf[0].eval(w), cmf[1].eval(w), cmf[2].eval(w)])
        })
        .collect()
}

/// A reflectance from RGB: the fitted sigmoid polynomial tabulated at 1 nm.
pub fn rgb_reflectance(rgb: [f64; 3]) -> TabulatedSpectrum {
    let p = fit_rgb(rgb);
    TabulatedSpectrum::from_fn(300.0, 830.0, |w| p.eval(w as f32) as f64)
}

/// An emission spectrum from RGB (Mitsuba's convention for spectral variants): with
/// k = 2·max(rgb), the reflectance fit of rgb/k times k times the unit-luminance D65, so that
/// RGB (1,1,1) gives D65 of luminance 1 and the result's sRGB is ≈ rgb.
pub fn rgb_emission(rgb: [f64; 3]) -> TabulatedSpectrum {
    let k = 2.0 * rgb.iter().copied().fold(0.0, f64::max);
    if !(k > 0.0) {
        return TabulatedSpectrum::constant(0.0);
    }
    let p = fit_rgb(rgb.map(|v| v / k));
    let d = d65_normalized();
    TabulatedSpectrum::from_fn(300.0, 830.0, |w| {
        k * p.eval(w as f32) as f64 * d.eval(w as f32) as f64
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bands_parse_and_index() {
        let b = Bands::parse("380:780:10").unwrap();
        assert_eq!(b.count, 40);
        assert_eq!(b.index(384.9), 0);
        assert_eq!(b.index(779.9), 39);
        assert_eq!(b.mitsuba_name(17), "band_0550_0560");
        assert!(Bands::parse("380:785:10").is_err());
        assert!(Bands::parse("780:380:10").is_err());
        assert!(Bands::parse("a:b").is_err());
        let wl = b.sample_wavelengths(0.9);
        assert!(wl.iter().all(|&w| (380.0..780.0).contains(&w)));
        assert!((wl[1] - (380.0 + 400.0 * 0.15)).abs() < 1e-3);
    }

    #[test]
    fn tabulated_matches_piecewise_linear() {
        let s = Spectrum::sampled(vec![400.0, 500.0, 600.0], vec![1.0, 3.0, 2.0]).unwrap();
        let t = TabulatedSpectrum::from_spectrum(&s);
        for w in [400.0, 433.3, 500.0, 555.5, 600.0] {
            assert!((t.eval(w as f32) as f64 - s.eval(w)).abs() < 1e-5, "{w}");
        }
        assert_eq!(t.eval(399.0), 0.0);
        assert_eq!(t.eval(600.5), 0.0);
    }

    #[test]
    fn rgb_fit_reproduces_the_colour() {
        for rgb in [
            [0.8, 0.2, 0.1],
            [0.1, 0.6, 0.2],
            [0.2, 0.3, 0.9],
            [0.5, 0.5, 0.5],
            [0.95, 0.9, 0.3],
        ] {
            let p = fit_rgb(rgb);
            let back = reflectance_to_srgb(|w| p.eval(w));
            for k in 0..3 {
                assert!((back[k] - rgb[k]).abs() < 0.01, "{rgb:?} -> {back:?}");
            }
            // a reflectance stays in [0, 1]
            for w in (360..830).step_by(10) {
                let v = p.eval(w as f32);
                assert!((0.0..=1.0).contains(&v));
            }
        }
    }

    #[test]
    fn white_emission_has_unit_luminance() {
        let e = rgb_emission([1.0, 1.0, 1.0]);
        let cmf = cmf_table();
        let num: f64 = cmf
            .iter()
            .map(|(w, c)| e.eval(*w as f32) as f64 * c[1])
            .sum();
        let den: f64 = cmf.iter().map(|(_, c)| c[1]).sum();
        assert!((num / den - 1.0).abs() < 0.01, "{}", num / den);
    }
}
