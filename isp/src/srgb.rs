//! sRGB encoding (IEC 61966-2-1:1999): the piecewise transfer curve and quantisation of
//! linear values to 8- and 16-bit codes. PNG writing is left to the caller.
use crate::mosaic::RgbImage;
use rayon::prelude::*;

pub use camsim_core::colorimetry::{srgb_decode, srgb_encode};

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

/// The linear image that interleaved 8-bit sRGB codes stand for (the inverse of [`to_srgb8`]
/// up to quantisation): `decode(code / 255)` per channel.
pub fn from_srgb8(codes: &[u8], rows: usize, cols: usize) -> RgbImage {
    RgbImage {
        rows,
        cols,
        data: codes
            .chunks_exact(3)
            .map(|c| [0, 1, 2].map(|k| srgb_decode(c[k] as f64 / 255.0) as f32))
            .collect(),
    }
}

/// Interleaved R, G, B 16-bit sRGB codes: clip to [0, 1], encode, `round(e · 65535)`.
pub fn to_srgb16(img: &RgbImage) -> Vec<u16> {
    quantise(img, 65535.0)
        .into_iter()
        .map(|x| x as u16)
        .collect()
}
