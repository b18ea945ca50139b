//! Image-based emission: emissive textures on surfaces and the equirectangular environment
//! map, both RGB images upsampled to spectra with the emission convention of
//! [`crate::spectral::rgb_emission`] (Mitsuba 3's spectral variants): with k = 2·max(rgb), the
//! sigmoid-polynomial reflectance fit of rgb/k (Jakob & Hanika 2019, through the loader's
//! coefficient table) times k times the unit-luminance D65.
//!
//! The environment map is looked up bilinearly (as Mitsuba 3's `envmap`) and importance-sampled
//! by a piecewise-constant 2-D distribution over its texels with weights luminance × sin θ
//! (Pharr, Jakob & Humphreys, *Physically Based Rendering*, 4th ed., §12.5 and §A.5.6), the
//! luminance being the largest of the texel's 3 × 3 neighbourhood (the support of the bilinear
//! lookup, so the density is > 0 wherever the radiance is): a texel (i, j) of a W × H map covers
//! u ∈ [i/W, (i+1)/W), v ∈ [j/H, (j+1)/H), θ = π v, φ = 2π u, so the density per steradian of
//! a direction is p(u, v) / (2π² sin θ).
//!
//! Orientation (Mitsuba 3's `envmap` convention, y up): a world direction d is taken to the
//! map's frame by the inverse of `to_world`, then u = atan2(d.x, −d.z)/(2π) (wrapped to
//! [0, 1)), v = acos(d.y)/π. Row 0 of the image (v = 0) is straight up (+y); the middle row is
//! the horizon; the image centre (u = ½) is the direction +z, u = ¼ is +x, the left and right
//! edges (u = 0, 1) are −z ([`EnvMap::dir_of`]).
use crate::sampling::Distribution1D;
use crate::spectral::{d65_normalized, SigmoidPoly, N_WL};
use glam::{Mat3, Vec2, Vec3};
use std::f32::consts::PI;

/// The spectral radiance of one RGB texel: `scale · poly(λ) · D65n(λ)` (W m⁻² sr⁻¹ nm⁻¹ for a
/// linear RGB in those units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RadianceTexel {
    /// Reflectance-like sigmoid polynomial of rgb / scale.
    pub poly: SigmoidPoly,
    /// k = 2·max(rgb) (0 for black).
    pub scale: f32,
}

impl RadianceTexel {
    /// Black.
    pub const BLACK: RadianceTexel = RadianceTexel {
        poly: SigmoidPoly { c: [0.0; 3] },
        scale: 0.0,
    };

    /// The texel of a linear RGB (each component finite, ≥ 0).
    pub fn from_rgb(rgb: [f64; 3]) -> Self {
        let k = 2.0 * rgb.iter().copied().fold(0.0, f64::max);
        if !(k > 0.0) {
            return RadianceTexel::BLACK;
        }
        RadianceTexel {
            poly: crate::gltf_load::rgb_to_poly(rgb.map(|v| v / k)),
            scale: k as f32,
        }
    }

    /// Radiance at the 4 wavelengths.
    #[inline]
    pub fn eval4(&self, wl: &[f32; N_WL]) -> [f32; N_WL] {
        if self.scale == 0.0 {
            return [0.0; N_WL];
        }
        let d = d65_normalized();
        wl.map(|w| self.scale * self.poly.eval(w) * d.eval(w))
    }

    /// Radiance at one wavelength.
    #[inline]
    pub fn eval(&self, nm: f32) -> f32 {
        if self.scale == 0.0 {
            return 0.0;
        }
        self.scale * self.poly.eval(nm) * d65_normalized().eval(nm)
    }
}

/// Luminance (relative, Y) of linear sRGB: the Y row of the core's sRGB → XYZ matrix
/// ([`camsim_core::colorimetry::linear_srgb_to_xyz`], IEC 61966-2-1).
#[inline]
pub fn rgb_luminance(rgb: [f64; 3]) -> f64 {
    camsim_core::colorimetry::linear_srgb_to_xyz(rgb)[1]
}

/// An RGB image as radiance texels (row 0 = top of the image = texture v = 0).
#[derive(Debug, Clone)]
pub struct RadianceImage {
    /// Width (texels).
    pub width: u32,
    /// Height (texels).
    pub height: u32,
    /// Texels, row-major.
    pub texels: Vec<RadianceTexel>,
    /// Luminance of each texel's linear RGB (row-major).
    pub luminance: Vec<f32>,
}

impl RadianceImage {
    /// From linear RGB texels (row-major, row 0 at the top), each finite and ≥ 0.
    pub fn from_rgb(width: u32, height: u32, rgb: &[[f32; 3]]) -> Self {
        use rayon::prelude::*;
        let texels = rgb
            .par_iter()
            .map(|p| RadianceTexel::from_rgb(p.map(|v| v as f64)))
            .collect();
        let luminance = rgb
            .iter()
            .map(|p| rgb_luminance(p.map(|v| v as f64)) as f32)
            .collect();
        RadianceImage {
            width,
            height,
            texels,
            luminance,
        }
    }

    /// Texel index of texture coordinates `uv` (nearest texel; repeat or clamp per axis).
    #[inline]
    pub fn index(&self, uv: Vec2, repeat: [bool; 2]) -> usize {
        let wrap = crate::scene::texel_coord;
        wrap(uv.y, self.height, repeat[1]) * self.width as usize + wrap(uv.x, self.width, repeat[0])
    }
}

/// A glTF emissive texture (emissiveTexture × emissiveFactor × KHR_materials_emissive_strength,
/// sRGB-decoded), nearest texel.
#[derive(Debug, Clone)]
pub struct EmissionTexture {
    /// The radiance texels.
    pub image: RadianceImage,
    /// Repeat (true) or clamp along u and v.
    pub repeat: [bool; 2],
    /// Largest value of any texel's spectrum (for light-selection weights).
    pub max_value: f32,
}

impl EmissionTexture {
    /// From an image (the largest spectral value is found on a 5 nm grid).
    pub fn new(image: RadianceImage, repeat: [bool; 2]) -> Self {
        use rayon::prelude::*;
        // the maximum is exact in any order, so the parallel reduction is deterministic
        let max_value = image
            .texels
            .par_iter()
            .map(|t| {
                (0..=94)
                    .map(|i| t.eval(360.0 + 5.0 * i as f32))
                    .fold(0.0f32, f32::max)
            })
            .reduce(|| 0.0f32, f32::max);
        EmissionTexture {
            image,
            repeat,
            max_value,
        }
    }

    /// Emitted radiance at texture coordinates `uv`.
    #[inline]
    pub fn eval(&self, uv: Vec2, wl: &[f32; N_WL]) -> [f32; N_WL] {
        self.image.texels[self.image.index(uv, self.repeat)].eval4(wl)
    }
}

/// A piecewise-constant distribution on [0,1)² over a `w × h` grid of cells (row j = v).
#[derive(Debug, Clone)]
pub struct Distribution2D {
    w: usize,
    h: usize,
    rows: Distribution1D,
    cols: Vec<Option<Distribution1D>>,
}

/// A sample of [`Distribution2D`].
#[derive(Debug, Clone, Copy)]
pub struct Sample2D {
    /// The point in [0,1)².
    pub uv: Vec2,
    /// Density on [0,1)² at it.
    pub pdf: f32,
}

impl Distribution2D {
    /// From non-negative cell weights (row-major, `h` rows of `w`); None when all are zero.
    pub fn new(w: usize, h: usize, weights: &[f64]) -> Option<Self> {
        let row_sums: Vec<f64> = weights.chunks_exact(w).map(|r| r.iter().sum()).collect();
        let rows = Distribution1D::new(&row_sums)?;
        let cols = weights.chunks_exact(w).map(Distribution1D::new).collect();
        Some(Distribution2D { w, h, rows, cols })
    }

    /// Sample a point: row by the marginal, column by the row's conditional, uniform within.
    #[inline]
    pub fn sample(&self, u: Vec2) -> Option<Sample2D> {
        let (j, pj, vr) = self.rows.sample(u.y);
        let cols = self.cols[j].as_ref()?;
        let (i, pi, ur) = cols.sample(u.x);
        let pdf = pj * pi * (self.w * self.h) as f32;
        if !(pdf > 0.0) {
            return None;
        }
        Some(Sample2D {
            uv: Vec2::new(
                ((i as f32 + ur) / self.w as f32).min(1.0 - f32::EPSILON),
                ((j as f32 + vr) / self.h as f32).min(1.0 - f32::EPSILON),
            ),
            pdf,
        })
    }

    /// Density on [0,1)² of the cell holding `uv`.
    #[inline]
    pub fn pdf(&self, uv: Vec2) -> f32 {
        let i = ((uv.x * self.w as f32) as usize).min(self.w - 1);
        let j = ((uv.y * self.h as f32) as usize).min(self.h - 1);
        match &self.cols[j] {
            Some(c) => self.rows.pmf(j) * c.pmf(i) * (self.w * self.h) as f32,
            None => 0.0,
        }
    }
}

/// An environment sample seen from any point.
#[derive(Debug, Clone, Copy)]
pub struct EnvSample {
    /// Unit world direction towards the environment.
    pub dir: Vec3,
    /// Density per steradian.
    pub pdf: f32,
}

/// An equirectangular (latitude–longitude) environment map: radiance arriving from infinitely
/// far along each direction.
#[derive(Debug, Clone)]
pub struct EnvMap {
    /// The radiance texels (already multiplied by the strength).
    pub image: RadianceImage,
    /// Map frame → world (a rotation).
    pub to_world: Mat3,
    to_local: Mat3,
    distr: Option<Distribution2D>,
    /// Mean luminance over the sphere (∫ Y dω / 4π) of the map's RGB.
    pub mean_luminance: f64,
}

impl EnvMap {
    /// From a radiance image and the map-to-world rotation.
    pub fn new(image: RadianceImage, to_world: Mat3) -> Self {
        let (w, h) = (image.width as usize, image.height as usize);
        let mut weights = vec![0f64; w * h];
        let mut mean = 0.0f64;
        for j in 0..h {
            // ∫ sin θ dθ over the row, exactly: cos θ0 − cos θ1
            let th0 = std::f64::consts::PI * j as f64 / h as f64;
            let th1 = std::f64::consts::PI * (j + 1) as f64 / h as f64;
            let band = th0.cos() - th1.cos();
            let s = (std::f64::consts::PI * (j as f64 + 0.5) / h as f64).sin();
            for i in 0..w {
                // the bilinear lookup of a point in this cell reads the cell's 3 × 3
                // neighbourhood: its largest luminance keeps the density > 0 wherever the
                // interpolated radiance is (unbiased), close to proportional elsewhere
                let mut y = 0.0f64;
                for dj in -1i64..=1 {
                    let jj = (j as i64 + dj).clamp(0, h as i64 - 1) as usize;
                    for di in -1i64..=1 {
                        let ii = (i as i64 + di).rem_euclid(w as i64) as usize;
                        y = y.max(image.luminance[jj * w + ii] as f64);
                    }
                }
                weights[j * w + i] = y * s;
                mean += image.luminance[j * w + i] as f64 * band * 2.0 * std::f64::consts::PI
                    / w as f64;
            }
        }
        let distr = Distribution2D::new(w, h, &weights);
        EnvMap {
            image,
            to_local: to_world.transpose(),
            to_world,
            distr,
            mean_luminance: mean / (4.0 * std::f64::consts::PI),
        }
    }

    /// True when the map has some light to sample.
    pub fn has_power(&self) -> bool {
        self.distr.is_some()
    }

    /// Texture coordinates of a world direction (Mitsuba 3 `envmap`: u = atan2(x, −z)/2π
    /// wrapped to [0,1), v = acos(y)/π in the map frame).
    #[inline]
    pub fn uv_of(&self, d: Vec3) -> Vec2 {
        let l = self.to_local * d;
        let mut u = l.x.atan2(-l.z) * (0.5 / PI);
        u -= u.floor();
        let v = l.y.clamp(-1.0, 1.0).acos() * (1.0 / PI);
        Vec2::new(u.min(1.0 - f32::EPSILON), v.min(1.0 - f32::EPSILON))
    }

    /// The world direction of texture coordinates `uv` (inverse of [`EnvMap::uv_of`]):
    /// map-frame (sin φ sin θ, cos θ, −cos φ sin θ) with φ = 2π u, θ = π v.
    #[inline]
    pub fn dir_of(&self, uv: Vec2) -> Vec3 {
        let (sp, cp) = (2.0 * PI * uv.x).sin_cos();
        let (st, ct) = (PI * uv.y).sin_cos();
        self.to_world * Vec3::new(sp * st, ct, -cp * st)
    }

    /// Radiance arriving along `-d`, i.e. seen looking in world direction `d`: bilinear
    /// interpolation of the 4 nearest texels' spectra (texel centres at ((i+½)/W, (j+½)/H),
    /// repeating in u, clamped in v), as Mitsuba's `envmap`.
    #[inline]
    pub fn eval(&self, d: Vec3, wl: &[f32; N_WL]) -> [f32; N_WL] {
        let uv = self.uv_of(d);
        let (w, h) = (self.image.width as i64, self.image.height as i64);
        let x = uv.x * w as f32 - 0.5;
        let y = uv.y * h as f32 - 0.5;
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let (x0, y0) = (x0 as i64, y0 as i64);
        let mut out = [0.0f32; N_WL];
        for (dy, wy) in [(0, 1.0 - fy), (1, fy)] {
            let j = (y0 + dy).clamp(0, h - 1) as usize;
            for (dx, wx) in [(0, 1.0 - fx), (1, fx)] {
                let wgt = wx * wy;
                if wgt == 0.0 {
                    continue;
                }
                let i = (x0 + dx).rem_euclid(w) as usize;
                let t = &self.image.texels[j * w as usize + i];
                if t.scale == 0.0 {
                    continue;
                }
                let v = t.eval4(wl);
                for k in 0..N_WL {
                    out[k] += wgt * v[k];
                }
            }
        }
        out
    }

    /// Sample a direction by luminance × sin θ.
    #[inline]
    pub fn sample(&self, u: Vec2) -> Option<EnvSample> {
        let s = self.distr.as_ref()?.sample(u)?;
        let st = (PI * s.uv.y).sin();
        if !(st > 0.0) {
            return None;
        }
        let pdf = s.pdf / (2.0 * PI * PI * st);
        if !(pdf > 0.0 && pdf.is_finite()) {
            return None;
        }
        Some(EnvSample {
            dir: self.dir_of(s.uv),
            pdf,
        })
    }

    /// Density per steradian of [`EnvMap::sample`] producing direction `d`.
    #[inline]
    pub fn pdf(&self, d: Vec3) -> f32 {
        let Some(distr) = &self.distr else {
            return 0.0;
        };
        let uv = self.uv_of(d);
        let l = self.to_local * d;
        let st = (1.0 - l.y * l.y).max(0.0).sqrt();
        if !(st > 0.0) {
            return 0.0;
        }
        distr.pdf(uv) / (2.0 * PI * PI * st)
    }
}

/// Where the environment comes from (render settings, or the glTF scene's extras).
#[derive(Debug, Clone, PartialEq)]
pub struct EnvironmentSpec {
    /// An OpenEXR with linear RGB (channels `R`, `G`, `B`, or one `Y`) in W m⁻² sr⁻¹ per unit
    /// of the emission convention (RGB (1,1,1) = D65 of unit luminance).
    pub exr: std::path::PathBuf,
    /// Multiplier of the map's values.
    pub strength: f64,
    /// Rotation of the map about the world +y axis (degrees, right-handed).
    pub rotation_y_deg: f64,
}

/// Largest decoded EXR accepted as an environment map: 1 GiB of pixels, e.g. 2²⁶ texels
/// (16384 × 4096) of four f32 channels. The map then holds about 48 bytes per texel more
/// (radiance texels, luminance, sampling distribution), so this bounds it near 4 GiB.
pub const MAX_ENVIRONMENT_DECODED_BYTES: f64 = (1u64 << 30) as f64;

/// Load an environment map from an EXR file.
pub fn load_environment(spec: &EnvironmentSpec) -> Result<EnvMap, crate::RenderError> {
    let path = &spec.exr;
    let err = |msg: String| crate::RenderError::Scene {
        path: path.display().to_string(),
        msg,
    };
    if !(spec.strength.is_finite() && spec.strength >= 0.0) {
        return Err(err(format!(
            "environment strength {}: expected a finite number ≥ 0",
            spec.strength
        )));
    }
    if !spec.rotation_y_deg.is_finite() {
        return Err(err(format!(
            "environment rotation {}: expected a finite angle in degrees",
            spec.rotation_y_deg
        )));
    }
    let (rows, cols, chans, _) =
        camsim_core::exr_io::read_channels_within(path, MAX_ENVIRONMENT_DECODED_BYTES)
            .map_err(|e| err(format!("{e}")))?;
    if rows == 0 || cols == 0 {
        return Err(err("environment map is empty".into()));
    }
    if let Some((c, v)) = chans.iter().find(|(_, v)| v.len() != rows * cols) {
        return Err(err(format!(
            "environment map channel {c} has {} values: expected {rows} × {cols} (subsampled channels are not supported)",
            v.len()
        )));
    }
    let find = |n: &str| chans.iter().find(|(c, _)| c == n).map(|(_, v)| v);
    let planes: [&Vec<f32>; 3] = match (find("R"), find("G"), find("B"), find("Y")) {
        (Some(r), Some(g), Some(b), _) => [r, g, b],
        (_, _, _, Some(y)) => [y, y, y],
        _ => {
            return Err(err(format!(
                "environment map needs channels R, G, B (or Y); it has {}",
                chans
                    .iter()
                    .map(|(c, _)| c.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            )))
        }
    };
    let k = spec.strength as f32;
    let mut rgb = Vec::with_capacity(rows * cols);
    for i in 0..rows * cols {
        let p = [planes[0][i], planes[1][i], planes[2][i]];
        if p.iter().any(|v| !(v.is_finite() && *v >= 0.0)) {
            return Err(err(format!(
                "environment map pixel (x {}, y {}) = {p:?}: expected finite values ≥ 0",
                i % cols,
                i / cols
            )));
        }
        rgb.push(p.map(|v| v * k));
    }
    let image = RadianceImage::from_rgb(cols as u32, rows as u32, &rgb);
    let rot = Mat3::from_rotation_y((spec.rotation_y_deg as f32).to_radians());
    Ok(EnvMap::new(image, rot))
}
