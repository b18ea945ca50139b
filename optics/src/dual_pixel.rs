//! Dual-pixel (phase-detection) optics: the images seen through the two halves of the exit
//! pupil.
//!
//! A dual-pixel sensor splits every pixel's photodiode in two under one microlens; the
//! microlens images the exit pupil onto the photodiodes, so each half-photodiode collects the
//! light that crossed one half of the pupil (Wadhwa et al., "Synthetic depth-of-field with a
//! single-camera mobile phone", ACM TOG 37(4) (SIGGRAPH 2018), §3). In thin-lens geometry a point at depth z seen by
//! a lens of aperture radius A focused on D, the sensor at v = 1/(1/f − 1/D), spreads over a
//! disc whose pupil-to-sensor map is linear: the ray through pupil point `p` meets the sensor
//! at `p · v (1/z − 1/D)` from the point's chief ray (similar triangles, with `1/v_z = 1/f −
//! 1/z`). The disc has the signed radius `r = A v (1/z − 1/D)` (the thin-lens circle of
//! confusion, computed once in `camsim_render::depth_optics::thin_lens_for_camera`, here with
//! its sign: positive for a point nearer than the focus, whose image lies behind the sensor).
//!
//! * **Half-pupil PSF** ([`half_pupil_psf`]): the pupil half `x < 0` ([`PupilHalf::Left`])
//!   maps to the half disc on the side of `−sign(r)`; the right half to the other side. Each
//!   half disc is a uniform half pillbox; their mean is the full pillbox
//!   ([`crate::pillbox_psf`]) sample for sample.
//! * **Centroid** ([`half_disc_centroid_offset_m`]): the centroid of a uniform half disc of
//!   radius R lies `4R/(3π)` from the centre (Pappus; any statics table).
//! * **Disparity** ([`dual_pixel_disparity_m`]): right-half image centroid minus left-half
//!   image centroid, `d = 2 · 4r/(3π) = 8r/(3π)` for the signed radius r. With
//!   `r = A v (1/z − 1/D)` this is Garg et al.'s affine model `d = α (1/z − 1/D)` with
//!   `α = 8 A v / (3π)` (Garg, Wadhwa, Ansari & Barron, "Learning single camera depth
//!   estimation using dual-pixels", ICCV 2019, §3). An imperfect split, where each
//!   half-photodiode also receives the fraction `1 − s` of the other half's light
//!   (`s` = separation, 1 ideal, ½ none; the angular-response overlap of PDAF pixels;
//!   the half-images of masked PDAF pixels are modelled the same way by Śliwiński & Wachel,
//!   "A simple model for on-sensor phase-detection autofocusing algorithm", J. Comput.
//!   Commun. 1 (2013) 11–17), scales it by `2s − 1`.
use crate::kernels::SampledPsf;
use std::f64::consts::PI;

/// One half of the exit pupil (split along the sensor's columns, x).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PupilHalf {
    /// The half at pupil x < 0.
    Left,
    /// The half at pupil x > 0.
    Right,
}

/// Distance of the centroid of a uniform half disc of radius `radius_m` from the disc's
/// centre: `4R/(3π)` (any unit; the name keeps metres).
pub fn half_disc_centroid_offset_m(radius_m: f64) -> f64 {
    4.0 * radius_m / (3.0 * PI)
}

/// Thin-lens dual-pixel disparity (right-half image centroid minus left-half image centroid,
/// along x) for a blur disc of signed radius `signed_coc_radius_m` (positive: the object is
/// nearer than the focus) and the photodiode `separation` s (1 = ideal split):
/// `d = (2s − 1) · 8 r / (3π)` (module docs).
pub fn dual_pixel_disparity_m(signed_coc_radius_m: f64, separation: f64) -> f64 {
    (2.0 * separation - 1.0) * 2.0 * half_disc_centroid_offset_m(signed_coc_radius_m)
}

/// The PSF of the light through one pupil half: a uniform half disc of the signed blur radius
/// `signed_coc_radius_m` (module docs), area-sampled like [`crate::pillbox_psf`] (8×8
/// sub-samples per sample cell, none on the split line x = 0, so the two halves partition the
/// full disc's sub-samples) at `pitch_m`, normalised to sum 1. A disc too small to hold a
/// sub-sample of either half is the identity (the point is in focus: both halves see it at
/// the same place).
///
/// Limit: each cell's sub-samples count at the cell's centre, so the column through the
/// disc's centre puts half its light at x = 0 instead of ±¼ sample; the sampled centroid
/// falls short of `4R/(3π)` by up to ~1/(2πR) samples (a disc within the centre cell, R < ½
/// sample, gives no disparity at all). A moment-preserving (linear in x) deposition would
/// remove the bias at the cost of the exact partition of [`crate::pillbox_psf`].
pub fn half_pupil_psf(signed_coc_radius_m: f64, pitch_m: f64, half: PupilHalf) -> SampledPsf {
    let r = signed_coc_radius_m.abs();
    let h = (r / pitch_m - 0.5 - 1e-9).ceil().max(0.0) as usize;
    let n = 2 * h + 1;
    // Left pupil half → the disc side of −sign(r); right half → +sign(r).
    let side = match half {
        PupilHalf::Left => -signed_coc_radius_m.signum(),
        PupilHalf::Right => signed_coc_radius_m.signum(),
    };
    let mut p = crate::kernels::disc_subsample_counts(r, pitch_m, |x| x * side > 0.0);
    if p.sum() == 0.0 {
        p.data.iter_mut().for_each(|v| *v = 0.0);
        p.data[h * n + h] = 1.0;
    }
    p.normalise();
    p
}

#[cfg(test)]
mod tests {
    use super::*;

    fn centroid_x(p: &SampledPsf) -> f64 {
        let n = p.cols();
        p.data
            .iter()
            .enumerate()
            .map(|(k, v)| v * ((k % n) as f64 - p.half_cols as f64) * p.pitch_m)
            .sum::<f64>()
            / p.sum()
    }

    #[test]
    fn halves_partition_the_pillbox() {
        for r_px in [0.3, 1.0, 2.7, 6.25] {
            let pitch = 1e-6;
            let full = crate::pillbox_psf(2.0 * r_px * pitch, pitch);
            for sign in [1.0, -1.0] {
                let l = half_pupil_psf(sign * r_px * pitch, pitch, PupilHalf::Left);
                let rt = half_pupil_psf(sign * r_px * pitch, pitch, PupilHalf::Right);
                assert_eq!(l.half_cols, full.half_cols);
                for k in 0..full.data.len() {
                    let mean = 0.5 * (l.data[k] + rt.data[k]);
                    assert!((mean - full.data[k]).abs() < 1e-12, "r {r_px} k {k}");
                }
            }
        }
    }

    /// The sampled half-disc centroid converges to 4R/(3π); the error of the area sampling
    /// shrinks with the radius in samples (bound: one sub-sample, 1/8 of a sample, over the
    /// number of boundary cells ~ the radius, generously 0.02 samples + 1 %).
    #[test]
    fn half_disc_centroid_matches_closed_form() {
        let pitch = 1.0;
        for r in [2.0, 5.0, 11.5, 30.0] {
            let l = half_pupil_psf(r, pitch, PupilHalf::Left);
            let rt = half_pupil_psf(r, pitch, PupilHalf::Right);
            let expected = half_disc_centroid_offset_m(r);
            let tol = 0.02 + 0.01 * expected;
            assert!((centroid_x(&l) + expected).abs() < tol, "left r {r}");
            assert!((centroid_x(&rt) - expected).abs() < tol, "right r {r}");
            let d = centroid_x(&rt) - centroid_x(&l);
            assert!((d - dual_pixel_disparity_m(r, 1.0)).abs() < 2.0 * tol);
            // behind focus the halves swap
            let lb = half_pupil_psf(-r, pitch, PupilHalf::Left);
            assert!((centroid_x(&lb) - expected).abs() < tol);
        }
    }

    #[test]
    fn in_focus_is_the_identity_and_separation_scales() {
        let p = half_pupil_psf(0.0, 1e-6, PupilHalf::Left);
        assert_eq!(p.data, vec![1.0]);
        assert_eq!(dual_pixel_disparity_m(1.0, 0.5), 0.0);
        assert!((dual_pixel_disparity_m(3.0 * PI, 0.75) - 4.0).abs() < 1e-12);
    }
}
