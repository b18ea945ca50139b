//! # camsim-display
//!
//! The display stage of camsim (§2.E and Eq. 8 of Farrell, Catrysse & Wandell, "Digital camera
//! simulation", Applied Optics 2012). A display is described by
//!
//! * the spectral radiance of each primary at full drive, `spd_p(λ)` in **W/(sr·m²·nm)**
//!   (energy units, the spatial average over the screen, as ISETCam stores it);
//! * a gamma table per primary, digital value → relative linear intensity `g_p(d)`
//!   ([`GammaTable`]);
//! * the dixel: the subpixel intensity maps `s_p(x)` of one repeating tile ([`Dixel`]), each
//!   normalised to mean 1;
//! * the resolution in dots per inch (pixel pitch `0.0254 / dpi` m).
//!
//! [`show`] evaluates Eq. 8,
//!
//! ```text
//!     L(x, λ) = Σ_p g_p(d_p(x)) · s_p(x) · spd_p(λ),
//! ```
//!
//! as a linear-model [`SpectralImage`] with one plane `g_p(d_p(x)) · s_p(x)` per primary and the
//! primary SPDs as basis spectra ([`SpectralBasis::Spectra`]), so the radiance costs one plane
//! per primary rather than one per wavelength. The radiance stays in energy units,
//! W/(sr·m²·nm); [`DisplayRadiance::radiance_photons`] converts to photons/(s·sr·m²·nm), the
//! unit of [`camsim_core::SceneRadiance`].
//!
//! The nine ISETCam displays shipped with camsim are embedded; see [`DisplayModel::names`].
#![deny(missing_docs)]

pub mod dixel;
pub mod error;
pub mod gamma;

pub use dixel::{Dixel, SubpixelMap};
pub use error::DisplayError;
pub use gamma::GammaTable;

use camsim_core::colorimetry::{self, Quadrature, Xyz};
use camsim_core::constants::PhysicalConstants;
use camsim_core::{data, SpectralBasis, SpectralImage, Spectrum};
use rayon::prelude::*;
use serde_json::Value;

/// Metres per inch (pixel pitch = `METERS_PER_INCH / dpi`).
pub const METERS_PER_INCH: f64 = 0.0254;

/// A calibrated display: primaries, gamma, subpixel structure and resolution.
#[derive(Debug, Clone, PartialEq)]
pub struct DisplayModel {
    /// The name it was loaded by ([`DisplayModel::load`]) or the JSON `name` field
    /// ([`DisplayModel::from_json`]).
    pub name: String,
    /// Primary names, e.g. `["R", "G", "B"]`.
    pub primary_names: Vec<String>,
    /// Spectral radiance of each primary at full drive (top gamma entry 1), W/(sr·m²·nm),
    /// averaged over the screen.
    pub primary_spd: Vec<Spectrum>,
    /// Digital value ↔ linear intensity per primary.
    pub gamma: GammaTable,
    /// Subpixel intensity maps.
    pub dixel: Dixel,
    /// Resolution, dots (pixels) per inch.
    pub dpi: f64,
    /// Nominal viewing distance (m), 0.5 when the file has none (the ISETCam default).
    pub viewing_distance_m: f64,
    /// Emissive (true) or reflective display.
    pub is_emissive: bool,
}

fn invalid(field: impl Into<String>, message: impl Into<String>) -> DisplayError {
    DisplayError::InvalidData {
        field: field.into(),
        message: message.into(),
    }
}

fn f64_list(v: &Value, field: &str) -> Result<Vec<f64>, DisplayError> {
    let a = v
        .as_array()
        .ok_or_else(|| invalid(field, format!("expected a list, got {v}")))?;
    a.iter()
        .enumerate()
        .map(|(i, x)| {
            x.as_f64()
                .ok_or_else(|| invalid(format!("{field}[{i}]"), format!("{x} is not a number")))
        })
        .collect()
}

fn list<'a>(v: &'a Value, field: &str) -> Result<&'a Vec<Value>, DisplayError> {
    v.as_array()
        .ok_or_else(|| invalid(field, format!("expected a list, got {}", short(v))))
}

fn short(v: &Value) -> String {
    let s = v.to_string();
    if s.len() > 60 {
        format!(
            "{}…",
            &s[..s.char_indices().nth(60).map_or(s.len(), |(i, _)| i)]
        )
    } else {
        s
    }
}

impl DisplayModel {
    /// Names of the embedded displays (files `data/iset/displays/<name>.json`), sorted.
    pub fn names() -> Vec<&'static str> {
        let mut v: Vec<&'static str> = data::names()
            .filter_map(|n| n.strip_prefix("displays/"))
            .collect();
        v.sort_unstable();
        v
    }

    /// Load an embedded display by name (exact, or ignoring ASCII case), e.g. `"lcdExample"`,
    /// `"LCD-Apple"`, `"OLED-Samsung"`. An unknown name is an error that lists the available
    /// ones.
    pub fn load(name: &str) -> Result<DisplayModel, DisplayError> {
        let names = Self::names();
        let found = names
            .iter()
            .find(|n| **n == name)
            .or_else(|| names.iter().find(|n| n.eq_ignore_ascii_case(name)))
            .ok_or_else(|| DisplayError::UnknownDisplay {
                name: name.to_string(),
                available: names.join(", "),
            })?;
        let v = data::json(&format!("displays/{found}"))?;
        let mut d = Self::from_json(&v)?;
        d.name = found.to_string();
        Ok(d)
    }

    /// Build a display from the camsim display JSON layout (data/iset/README.md, "Displays"):
    /// `wavelength_nm`, `spd[primary][wavelength]`, `gamma[level][primary]`, `dpi`,
    /// `dixel.intensitymap[primary][row][col]`, optional `dixel.n_pixels`, `primary_names`,
    /// `gamma_levels` (checked against the table), `viewing_distance_m`, `is_emissive`.
    pub fn from_json(v: &Value) -> Result<DisplayModel, DisplayError> {
        let name = v["name"].as_str().unwrap_or("unnamed display").to_string();
        let wl = f64_list(&v["wavelength_nm"], "wavelength_nm")?;
        let spd_rows = list(&v["spd"], "spd")?;
        if spd_rows.is_empty() {
            return Err(invalid("spd", "no primaries"));
        }
        let n = spd_rows.len();
        let mut primary_spd = Vec::with_capacity(n);
        for (p, row) in spd_rows.iter().enumerate() {
            let field = format!("spd[{p}]");
            let vals = f64_list(row, &field)?;
            if let Some(i) = vals.iter().position(|x| *x < 0.0) {
                return Err(invalid(
                    format!("{field}[{i}]"),
                    format!("{} is negative", vals[i]),
                ));
            }
            let s =
                Spectrum::sampled(wl.clone(), vals).map_err(|e| invalid(field, e.to_string()))?;
            primary_spd.push(s);
        }

        let g_rows = list(&v["gamma"], "gamma")?;
        let mut linear = vec![Vec::with_capacity(g_rows.len()); n];
        for (k, row) in g_rows.iter().enumerate() {
            let field = format!("gamma[{k}]");
            let vals = f64_list(row, &field)?;
            if vals.len() != n {
                return Err(invalid(
                    field,
                    format!("has {} entries for {n} primaries", vals.len()),
                ));
            }
            for (p, x) in vals.into_iter().enumerate() {
                linear[p].push(x);
            }
        }
        let gamma = GammaTable::new(linear)?;
        if let Some(l) = v.get("gamma_levels").filter(|x| !x.is_null()) {
            if l.as_u64() != Some(gamma.levels() as u64) {
                return Err(invalid(
                    "gamma_levels",
                    format!("{l} but the table has {} levels", gamma.levels()),
                ));
            }
        }

        let dpi = v["dpi"]
            .as_f64()
            .ok_or_else(|| invalid("dpi", format!("{} is not a number", v["dpi"])))?;
        if !(dpi.is_finite() && dpi > 0.0) {
            return Err(invalid("dpi", format!("{dpi} must be a positive number")));
        }
        let viewing_distance_m = match v.get("viewing_distance_m") {
            None | Some(Value::Null) => 0.5,
            Some(x) => x
                .as_f64()
                .filter(|d| d.is_finite() && *d > 0.0)
                .ok_or_else(|| {
                    invalid(
                        "viewing_distance_m",
                        format!("{x} must be a positive number"),
                    )
                })?,
        };
        let is_emissive = v["is_emissive"].as_bool().unwrap_or(true);
        let primary_names = match v["primary_names"].as_array() {
            Some(a) if a.len() == n => a
                .iter()
                .enumerate()
                .map(|(i, x)| x.as_str().map_or(format!("P{i}"), str::to_string))
                .collect(),
            Some(a) => {
                return Err(invalid(
                    "primary_names",
                    format!("{} names for {n} primaries", a.len()),
                ))
            }
            None => (0..n).map(|i| format!("P{i}")).collect(),
        };

        let dx = &v["dixel"];
        let maps = list(&dx["intensitymap"], "dixel.intensitymap")?;
        if maps.len() != n {
            return Err(invalid(
                "dixel.intensitymap",
                format!("has {} primaries, the spd has {n}", maps.len()),
            ));
        }
        let mut intensitymap = Vec::with_capacity(n);
        for (p, m) in maps.iter().enumerate() {
            let rows = list(m, &format!("dixel.intensitymap[{p}]"))?;
            let mut rr = Vec::with_capacity(rows.len());
            for (r, row) in rows.iter().enumerate() {
                rr.push(f64_list(row, &format!("dixel.intensitymap[{p}][{r}]"))?);
            }
            intensitymap.push(rr);
        }
        let ppd = match dx.get("n_pixels") {
            None | Some(Value::Null) => [1, 1],
            Some(x) => {
                let a = f64_list(x, "dixel.n_pixels")?;
                match a.as_slice() {
                    [r, c] if *r >= 1.0 && *c >= 1.0 && r.fract() == 0.0 && c.fract() == 0.0 => {
                        [*r as usize, *c as usize]
                    }
                    _ => {
                        return Err(invalid(
                            "dixel.n_pixels",
                            format!("{x} is not two positive integers"),
                        ))
                    }
                }
            }
        };
        let dixel = Dixel::new(intensitymap, ppd)?;

        Ok(DisplayModel {
            name,
            primary_names,
            primary_spd,
            gamma,
            dixel,
            dpi,
            viewing_distance_m,
            is_emissive,
        })
    }

    /// Number of primaries.
    pub fn n_primaries(&self) -> usize {
        self.primary_spd.len()
    }

    /// Display pixel pitch, `0.0254 / dpi` m.
    pub fn pixel_pitch_m(&self) -> f64 {
        METERS_PER_INCH / self.dpi
    }

    /// Spacing of the dixel samples at the file's resolution (m): tile size / samples, with the
    /// tile spanning `pixels_per_dixel` pixels (ISETCam `displayGet(d, 'sample spacing')`).
    pub fn dixel_sample_pitch_m(&self) -> [f64; 2] {
        let s = self.dixel.native_samples_per_pixel();
        [self.pixel_pitch_m() / s[0], self.pixel_pitch_m() / s[1]]
    }

    /// Sum of the primary SPDs at full drive, W/(sr·m²·nm) (ISETCam `white spd`), sampled at the
    /// display's wavelengths.
    pub fn white_spd(&self) -> Spectrum {
        self.combine_spd(&vec![1.0; self.n_primaries()])
    }

    /// Radiance of a black image (all codes 0): `Σ_p g_p(0) spd_p(λ)`, W/(sr·m²·nm).
    pub fn black_spd(&self) -> Spectrum {
        self.combine_spd(&self.gamma.black_level())
    }

    /// `Σ_p w_p spd_p(λ)` on the union of the primaries' wavelengths.
    pub fn combine_spd(&self, weights: &[f64]) -> Spectrum {
        let mut wl: Vec<f64> = self
            .primary_spd
            .iter()
            .flat_map(|s| match s {
                Spectrum::Sampled { wavelength_nm, .. } => wavelength_nm.clone(),
                Spectrum::Affine { .. } => Vec::new(),
            })
            .collect();
        wl.sort_by(|a, b| a.partial_cmp(b).unwrap());
        wl.dedup();
        let vals = wl
            .iter()
            .map(|&w| {
                self.primary_spd
                    .iter()
                    .zip(weights)
                    .map(|(s, k)| k * s.eval(w))
                    .sum()
            })
            .collect();
        Spectrum::Sampled {
            wavelength_nm: wl,
            values: vals,
        }
    }

    /// CIE 1931 XYZ of each primary at full drive (Y in cd/m², exact integration).
    pub fn primaries_xyz(&self) -> Vec<Xyz> {
        self.primary_spd
            .iter()
            .map(|s| colorimetry::xyz_from_energy(s, Quadrature::Exact))
            .collect()
    }

    /// CIE 1931 XYZ of the white (all primaries at full drive).
    pub fn white_xyz(&self) -> Xyz {
        colorimetry::xyz_from_energy(&self.white_spd(), Quadrature::Exact)
    }

    /// Luminance of the white, cd/m².
    pub fn peak_luminance_cd_per_m2(&self) -> f64 {
        self.white_xyz().y
    }

    /// Relative linear intensity (0–1 of full drive) of `primary` at `digital` (`bits` deep).
    pub fn linear_from_digital(
        &self,
        primary: usize,
        digital: u32,
        bits: u32,
    ) -> Result<f64, DisplayError> {
        self.gamma.linear_from_digital(primary, digital, bits)
    }

    /// The `bits`-deep code of `primary` whose intensity is nearest to `linear` (lowest code of a
    /// flat run; see [`gamma`]).
    pub fn digital_from_linear(
        &self,
        primary: usize,
        linear: f64,
        bits: u32,
    ) -> Result<u16, DisplayError> {
        self.gamma.digital_from_linear(primary, linear, bits)
    }
}

/// An image of digital drive values, one channel per display primary, interleaved row-major
/// (`data[(row * cols + col) * channels + primary]`).
#[derive(Debug, Clone, PartialEq)]
pub struct DigitalImage {
    /// Rows (display pixels).
    pub rows: usize,
    /// Columns (display pixels).
    pub cols: usize,
    /// Bit depth of the values (1–16).
    pub bits: u32,
    /// Channels per pixel.
    pub channels: usize,
    /// `rows × cols × channels` digital values.
    pub data: Vec<u16>,
}

impl DigitalImage {
    /// An RGB image from one `[r, g, b]` per pixel, row-major.
    pub fn from_rgb(rows: usize, cols: usize, bits: u32, rgb: &[[u16; 3]]) -> Self {
        DigitalImage {
            rows,
            cols,
            bits,
            channels: 3,
            data: rgb.iter().flatten().copied().collect(),
        }
    }

    /// Every pixel set to `value` (one entry per channel).
    pub fn uniform(rows: usize, cols: usize, bits: u32, value: &[u16]) -> Self {
        let data = (0..rows * cols)
            .flat_map(|_| value.iter().copied())
            .collect();
        DigitalImage {
            rows,
            cols,
            bits,
            channels: value.len(),
            data,
        }
    }

    /// The channel values of pixel (row, col).
    pub fn pixel(&self, row: usize, col: usize) -> &[u16] {
        let i = (row * self.cols + col) * self.channels;
        &self.data[i..i + self.channels]
    }
}

/// Spectral radiance emitted by a display showing an image.
#[derive(Debug, Clone)]
pub struct DisplayRadiance {
    /// Radiance in **W/(sr·m²·nm)** as a linear model: plane `p` (= `g_p(d_p(x)) s_p(x)`)
    /// multiplies the SPD of primary `p` ([`SpectralBasis::Spectra`]). Rows and columns are
    /// `samples_per_pixel` × the image's.
    pub radiance: SpectralImage,
    /// Spacing of the samples on the screen (m): pixel pitch / samples_per_pixel.
    pub sample_pitch_m: f64,
    /// Samples per display pixel along each axis.
    pub samples_per_pixel: usize,
}

impl DisplayRadiance {
    /// The same radiance in photons/(s·sr·m²·nm) (basis spectra converted with λ/(hc)).
    pub fn radiance_photons(&self, c: &PhysicalConstants) -> SpectralImage {
        let mut img = self.radiance.clone();
        if let SpectralBasis::Spectra(b) = &mut img.basis {
            for s in b.iter_mut() {
                *s = s.energy_to_photons(c);
            }
        }
        img
    }
}

/// Eq. 8: the spectral radiance of `display` showing `image`, with `samples_per_pixel ×
/// samples_per_pixel` samples per display pixel.
///
/// The subpixel maps are box-resampled to that resolution ([`Dixel::resampled`], which keeps
/// each primary's mean); with 1 sample per pixel each pixel is the mean of its part of the
/// tile (mean 1 for a one-pixel tile). Pixel `(i, j)` uses the part `(i mod ppd_r, j mod
/// ppd_c)` of a tile spanning `ppd` pixels (OLED-Samsung: 2 × 2), and each pixel drives its own
/// part with its own values (nearest-neighbour rendering). The image needs one channel per
/// primary, or 3 channels on a display with more primaries (the extra primaries are then
/// driven at code 0). Memory: `rows·cols·n²` f32 per primary.
pub fn show(
    display: &DisplayModel,
    image: &DigitalImage,
    samples_per_pixel: usize,
) -> Result<DisplayRadiance, DisplayError> {
    let n = samples_per_pixel;
    let np = display.n_primaries();
    let (rows, cols, ch) = (image.rows, image.cols, image.channels);
    if rows == 0 || cols == 0 {
        return Err(DisplayError::BadImage(format!("empty image {rows}×{cols}")));
    }
    if !(ch == np || (ch == 3 && np > 3)) {
        return Err(DisplayError::BadImage(format!(
            "{ch} channels for a display with {np} primaries ({})",
            display.primary_names.join(", ")
        )));
    }
    if image.data.len() != rows * cols * ch {
        return Err(DisplayError::BadImage(format!(
            "{} values for {rows}×{cols}×{ch}",
            image.data.len()
        )));
    }
    let luts: Vec<Vec<f64>> = (0..np)
        .map(|p| display.gamma.lut_for_bits(p, image.bits))
        .collect::<Result<_, _>>()?;
    let max = luts[0].len() - 1;
    if let Some(i) = image.data.iter().position(|&d| d as usize > max) {
        let px = i / ch;
        return Err(DisplayError::BadImage(format!(
            "pixel ({}, {}) channel {} has value {}, above the {}-bit maximum {max}",
            px / cols,
            px % cols,
            i % ch,
            image.data[i],
            image.bits
        )));
    }
    let tile = display.dixel.resampled(n)?;
    let [pr, pc] = display.dixel.pixels_per_dixel;
    let out_rows = rows.checked_mul(n);
    let out_cols = cols.checked_mul(n);
    let (out_rows, out_cols) = match (out_rows, out_cols) {
        (Some(r), Some(c)) if r.checked_mul(c).is_some() => (r, c),
        _ => return Err(DisplayError::BadSampling(n, "output size overflows".into())),
    };

    let planes: Vec<Vec<f32>> = (0..np)
        .map(|p| {
            let lut = &luts[p];
            let map = &tile.planes[p];
            let mut plane = vec![0f32; out_rows * out_cols];
            plane
                .par_chunks_mut(out_cols)
                .enumerate()
                .for_each(|(y, out)| {
                    let (i, a) = (y / n, y % n);
                    let trow = ((i % pr) * n + a) * tile.cols;
                    for (x, o) in out.iter_mut().enumerate() {
                        let (j, b) = (x / n, x % n);
                        let d = if p < ch {
                            image.data[(i * cols + j) * ch + p] as usize
                        } else {
                            0
                        };
                        *o = (lut[d] * map[trow + (j % pc) * n + b]) as f32;
                    }
                });
            plane
        })
        .collect();
    let radiance = SpectralImage::new(
        out_rows,
        out_cols,
        SpectralBasis::Spectra(display.primary_spd.clone()),
        planes,
    )?;
    Ok(DisplayRadiance {
        radiance,
        sample_pitch_m: display.pixel_pitch_m() / n as f64,
        samples_per_pixel: n,
    })
}
