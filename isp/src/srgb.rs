//! sRGB encoding (IEC 61966-2-1:1999): the piecewise transfer curve and quantisation of
//! linear values to 8- and 16-bit codes. PNG writing is left to the caller.
use crate::mosaic::RgbImage;
use rayon::prelude::*;

/// Linear → sRGB-encoded value: `12.92 v` for `v ≤ 0.0031308`, else `1.055 v^(1/2.4) − 0.055`
/// (IEC 61966-2-1). Negative inputs are mirrored (odd extension), so the curve is invertible on
/// the whole line; quantisation clips to [0, 1].
pub fn srgb_encode(v: f64) -> f64 {
    if v < 0.0 {
        -srgb_encode(-v)
    } else if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// sRGB-encoded → linear: `e / 12.92` for `e ≤ 0.04045`, else `((e + 0.055) / 1.055)^2.4`.
pub fn srgb_decode(e: f64) -> f64 {
    if e < 0.0 {
        -srgb_decode(-e)
    } else if e <= 0.040_45 {
        e / 12.92
    } else {
        ((e + 0.055) / 1.055).powf(2.4)
    }
}

fn quantise(img: &RgbImage, max_code: f64) -> Vec<f64> {
    img.data
        .par_iter()
        .flat_map_iter(|p| {
            p.map(|v| {
                let v = if v.is_nan() {
                    0.0
                } else {
                    (v as f64).clamp(0.0, 1.0)
                };
                (srgb_encode(v) * max_code).round()
            })
        })
        .collect()
}

/// Interleaved R, G, B 8-bit sRGB codes (`rows × cols × 3`, row-major) of a linear image:
/// clip to [0, 1], encode, `round(e · 255)`.
pub fn to_srgb8(img: &RgbImage) -> Vec<u8> {
    quantise(img, 255.0).into_iter().map(|x| x as u8).collect()
}

/// Interleaved R, G, B 16-bit sRGB codes: clip to [0, 1], encode, `round(e · 65535)`.
pub fn to_srgb16(img: &RgbImage) -> Vec<u16> {
    quantise(img, 65535.0)
        .into_iter()
        .map(|x| x as u16)
        .collect()
}
