//! Scenes from the world: an RGB picture shown on a calibrated display → spectral radiance,
//! the way ISETCam's `sceneFromFile(I, 'rgb', meanLuminance, display)` builds a scene
//! (ISETCam `sceneFromFile.m` → `vcReadImage.m`, `ieLUTDigital.m`, `displayGet.m`; MIT,
//! Stanford Center for Image Systems Engineering).
//!
//! ## The convention (ISETCam's, stated)
//!
//! * **The file holds DAC codes, not linear values.** A code `d` of a `b`-bit file is looked
//!   up in the display's **gamma table** (DAC level → relative linear intensity, the forward
//!   direction; no inverse gamma is applied). A `b`-bit code sits at table row
//!   `k = round(d · (L − 1) / (2^b − 1))` of an `L`-row table (ISETCam stretches an 8-bit
//!   image over a 10-bit table with `round(d / 255 · (L − 1))`; MATLAB `round`, half away
//!   from zero), and the table entry `g_p[k]` is used as it is (no interpolation).
//!   A one-channel picture drives every primary with the same code; primaries the picture
//!   has no channel for are driven at code 0 (ISETCam pads with 0).
//! * **Radiance is the display's emitted radiance**, `L_e(x, λ) = Σ_p g_p[k_p(x)] spd_p(λ)`
//!   (W/(sr·m²·nm)), without subpixel structure (ISETCam's default `doSub = false`), and in
//!   photons `L_q = L_e · λ / (h c)` (ISETCam `Energy2Quanta`).
//! * **The illuminant is the display white point**, `Σ_p spd_p(λ)` (all primaries at full
//!   drive), for an emissive display (ISETCam sets `illuminant energy = sum(spd, 2)`), so a
//!   full-white pixel has reflectance 1.
//! * **Geometry**: the scene is at the display's viewing distance `D` and its horizontal field
//!   of view is `cols · atan(p / D)` degrees (`p` = display pixel pitch; ISETCam
//!   `displayGet(d, 'deg per dot')`).
//! * **Mean luminance**: the absolute luminance of the display is kept; when a mean luminance
//!   is asked for, the radiance (and the illuminant) is scaled so the mean luminance over the
//!   picture is that value (ISETCam `sceneAdjustLuminance`), which the pipeline does with
//!   [`crate::scene::scale_to_mean_luminance`].
//!
//! ## Where camsim differs, and why
//!
//! * ISETCam decides between "values in [0, 1]", "8-bit" and "deeper than the table" from the
//!   *largest value in the picture*; camsim uses the file's bit depth, which is the same for
//!   every 8-bit picture whose brightest code is above 1 (and for 16-bit pictures, where
//!   ISETCam re-tabulates the gamma table with a spline, camsim keeps the proportional
//!   rounding above).
//! * The radiance is kept as a linear model with the primary SPDs as basis spectra (one plane
//!   per primary, [`SpectralBasis::Spectra`]) rather than a band cube: it is the same function
//!   of wavelength at every wavelength, and costs three planes instead of one per band.
use crate::constants::PhysicalConstants;
use crate::error::CoreError;
use crate::image::{SpectralBasis, SpectralImage};
use crate::spectrum::Spectrum;

/// What a display contributes to [`scene_from_rgb`]: its primaries, gamma table and geometry.
/// (The display crate's `DisplayModel` holds these; core keeps only what it needs.)
#[derive(Debug, Clone, PartialEq)]
pub struct DisplayPrimaries {
    /// Spectral radiance of each primary at full drive, W/(sr·m²·nm).
    pub spd_energy: Vec<Spectrum>,
    /// `gamma[primary][level]`: relative linear intensity for DAC level `0 … L − 1`.
    pub gamma: Vec<Vec<f64>>,
    /// Display pixel pitch (m).
    pub pixel_pitch_m: f64,
    /// Viewing distance (m).
    pub viewing_distance_m: f64,
}

/// An RGB (or grey) picture as stored: DAC codes, interleaved per pixel, row 0 at the top.
#[derive(Debug, Clone, PartialEq)]
pub struct RgbCodes {
    /// Rows.
    pub rows: usize,
    /// Columns.
    pub cols: usize,
    /// Channels per pixel (1 = grey, 3 = RGB).
    pub channels: usize,
    /// Bit depth of the codes (1–16).
    pub bits: u32,
    /// `rows × cols × channels` codes, `codes[(row · cols + col) · channels + channel]`.
    pub codes: Vec<u16>,
}

/// A scene made from an RGB picture on a display ([`scene_from_rgb`]).
#[derive(Debug, Clone)]
pub struct RgbScene {
    /// Spectral radiance, photons/(s·sr·m²·nm): one plane per primary (its linear intensity
    /// `g_p[k_p(x)]`) times the primary's SPD in photons.
    pub radiance: SpectralImage,
    /// The display white point `Σ_p spd_p`, photons/(s·sr·m²·nm).
    pub illuminant_photons: Spectrum,
    /// Horizontal field of view, `cols · atan(pixel pitch / viewing distance)`, degrees.
    pub fov_deg: f64,
    /// The display's viewing distance (m).
    pub distance_m: f64,
}

/// The gamma-table row of code `code` of a `bits`-deep picture in an `levels`-row table:
/// `round(code · (levels − 1) / (2^bits − 1))` (the row itself when the depths agree).
pub fn gamma_row(code: u32, bits: u32, levels: usize) -> usize {
    let max = ((1u64 << bits) - 1) as f64;
    let top = (levels - 1) as f64;
    if max == top {
        return code as usize;
    }
    // f64::round is half away from zero, like MATLAB's round.
    ((code as f64 * top / max).round() as usize).min(levels - 1)
}

/// Horizontal field of view (degrees) of a picture `cols` pixels wide on a display of pixel
/// pitch `pixel_pitch_m` seen from `viewing_distance_m`: `cols · atan(p / D)` (ISETCam
/// `imgSz · displayGet(d, 'deg per dot')`).
pub fn display_fov_deg(cols: usize, pixel_pitch_m: f64, viewing_distance_m: f64) -> f64 {
    cols as f64 * (pixel_pitch_m / viewing_distance_m).atan().to_degrees()
}

/// The spectral radiance of `picture` shown on `display` (the module documentation states the
/// convention). `c` converts energy to photons (use [`crate::constants::ISETCAM`] to match
/// ISETCam's numbers to the last digit, [`crate::constants::SI`] otherwise).
pub fn scene_from_rgb(
    picture: &RgbCodes,
    display: &DisplayPrimaries,
    c: &PhysicalConstants,
) -> Result<RgbScene, CoreError> {
    let np = display.spd_energy.len();
    let bad = |m: String| CoreError::Target(m);
    if np == 0 || display.gamma.len() != np {
        return Err(bad(format!(
            "display has {np} primary SPDs and {} gamma tables",
            display.gamma.len()
        )));
    }
    let levels = display.gamma[0].len();
    if levels < 2 || display.gamma.iter().any(|t| t.len() != levels) {
        return Err(bad("display gamma tables must share ≥ 2 levels".into()));
    }
    let (rows, cols, ch) = (picture.rows, picture.cols, picture.channels);
    if rows == 0 || cols == 0 {
        return Err(bad(format!("empty picture {rows}×{cols}")));
    }
    if !(1..=16).contains(&picture.bits) {
        return Err(bad(format!("bit depth {} (expected 1–16)", picture.bits)));
    }
    if ch == 0 || ch > np {
        return Err(bad(format!(
            "{ch} channels for a display with {np} primaries (expected 1 or up to {np})"
        )));
    }
    if picture.codes.len() != rows * cols * ch {
        return Err(bad(format!(
            "{} codes for {rows}×{cols}×{ch}",
            picture.codes.len()
        )));
    }
    let max_code = (1u32 << picture.bits) - 1;
    if let Some(i) = picture.codes.iter().position(|&d| d as u32 > max_code) {
        return Err(bad(format!(
            "code {} at pixel {} is above the {}-bit maximum {max_code}",
            picture.codes[i],
            i / ch,
            picture.bits
        )));
    }
    // Per primary: a lookup from code to linear intensity (ISETCam ieLUTDigital on the
    // stretched codes).
    let luts: Vec<Vec<f32>> = display
        .gamma
        .iter()
        .map(|t| {
            (0..=max_code)
                .map(|d| t[gamma_row(d, picture.bits, levels)] as f32)
                .collect()
        })
        .collect();
    let n = rows * cols;
    let planes: Vec<Vec<f32>> = (0..np)
        .map(|p| {
            let lut = &luts[p];
            (0..n)
                .map(|i| {
                    let d = match ch {
                        1 => picture.codes[i] as usize,
                        _ if p < ch => picture.codes[i * ch + p] as usize,
                        _ => 0,
                    };
                    lut[d]
                })
                .collect()
        })
        .collect();
    let basis: Vec<Spectrum> = display
        .spd_energy
        .iter()
        .map(|s| s.energy_to_photons(c))
        .collect();
    let white = sum_spectra(&display.spd_energy).energy_to_photons(c);
    Ok(RgbScene {
        radiance: SpectralImage::new(rows, cols, SpectralBasis::Spectra(basis), planes)?,
        illuminant_photons: white,
        fov_deg: display_fov_deg(cols, display.pixel_pitch_m, display.viewing_distance_m),
        distance_m: display.viewing_distance_m,
    })
}

/// `Σ_p s_p(λ)` sampled on the union of the spectra's wavelengths.
fn sum_spectra(s: &[Spectrum]) -> Spectrum {
    let mut wl: Vec<f64> = s
        .iter()
        .flat_map(|x| match x {
            Spectrum::Sampled { wavelength_nm, .. } => wavelength_nm.clone(),
            Spectrum::Affine { .. } => Vec::new(),
        })
        .collect();
    if wl.is_empty() {
        return Spectrum::constant(s.iter().map(|x| x.eval(0.0)).sum());
    }
    wl.sort_by(|a, b| a.total_cmp(b));
    wl.dedup();
    let values = wl
        .iter()
        .map(|&w| s.iter().map(|x| x.eval(w)).sum())
        .collect();
    Spectrum::Sampled {
        wavelength_nm: wl,
        values,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gamma_rows_follow_isetcam_stretch() {
        // 8-bit into a 1024-row table: round(d · 1023 / 255)
        assert_eq!(gamma_row(0, 8, 1024), 0);
        assert_eq!(gamma_row(255, 8, 1024), 1023);
        assert_eq!(gamma_row(1, 8, 1024), 4); // 4.01
        assert_eq!(gamma_row(128, 8, 1024), 514); // 513.5058…
                                                  // same depth: the code itself
        assert_eq!(gamma_row(77, 8, 256), 77);
    }

    #[test]
    fn fov_of_a_display_picture() {
        // 96 dpi at 0.5 m: atan(0.0254/96/0.5) per pixel
        let f = display_fov_deg(100, 0.0254 / 96.0, 0.5);
        assert!((f - 100.0 * (0.0254f64 / 96.0 / 0.5).atan().to_degrees()).abs() < 1e-12);
        assert!((f - 3.0318).abs() < 1e-3, "{f}");
    }
}
