//! A scene's field of view and distance: what part of the image plane a target covers.
//!
//! Without a field of view a target **fills the sensor** (../spec/capture-format.md). With a
//! horizontal field of view `F` (degrees) the target is an object of angular width `F` on the
//! optical axis; a ray from the scene at angle `θ` from the axis passes the (thin) lens centre
//! undeviated and meets the image plane at `x = s′ tan θ`, `s′` the image distance
//! (`1/s′ = 1/f − 1/d` for an object at distance `d`; `s′ = f` at infinity). So the target
//! covers, in the image plane,
//!
//! ```text
//!     W = 2 s′ tan(F / 2),    H = W · rows / cols   (square scene pixels)
//! ```
//!
//! (for a planar scene of width `2 d tan(F/2)` at distance `d` this is the width times the
//! magnification `s′/d`, ISETCam's `sceneGet(scene, 'width') · |m|`). A sensor `w` wide then
//! sees `2 atan(w / (2 s′))` of it and a target of field of view `F` spans `W / p` pixels of
//! pitch `p` — not a picture stretched over the sensor.
//!
//! Outside its field of view an image (or cube) is black: there is nothing there. The
//! synthetic targets keep the spec's continuation rule (a chart continues as its background,
//! an edge as its half-planes, a ramp or sweep as its end values).
//!
//! Images are resampled by exact area averaging: each sample holds the mean of the picture
//! (piecewise constant over its pixels) over the sample's square, so energy and coverage are
//! exact at any size ratio.
use crate::error::CoreError;
use crate::image::SpectralImage;
use crate::scene::{
    check_projection, render_target_projected_rows, render_target_rows, PlaneProjection,
    SamplingGrid, Target,
};
use rayon::prelude::*;

/// Image-plane extent (m) of a target of horizontal field of view `fov_deg` and aspect
/// `rows / cols`, imaged at image distance `image_distance_m`: `W = 2 s′ tan(F/2)`,
/// `H = W · aspect`.
pub fn extent_in_image_plane_m(fov_deg: f64, aspect: f64, image_distance_m: f64) -> (f64, f64) {
    let w = 2.0 * image_distance_m * (0.5 * fov_deg.to_radians()).tan();
    (w, w * aspect)
}

/// Horizontal field of view (degrees) of an image-plane width `width_m` at image distance
/// `image_distance_m`: `2 atan(w / (2 s′))` (the sensor's, for `w` = its width).
pub fn fov_deg_of_width(width_m: f64, image_distance_m: f64) -> f64 {
    2.0 * (0.5 * width_m / image_distance_m).atan().to_degrees()
}

/// Render `target` on `g` as an object covering `extent_m = (W, H)` of the image plane,
/// centred on the axis (`None`: the target fills the sensor, [`crate::scene::render_target`]). Images are
/// area-averaged and black outside the extent; other targets are laid out over the extent
/// (charts tile it, ramps span it) and continue beyond it as the spec says.
pub fn render_target_in_view(
    target: &Target,
    g: &SamplingGrid,
    extent_m: Option<(f64, f64)>,
) -> Result<SpectralImage, CoreError> {
    render_target_in_view_rows(target, g, extent_m, 0..g.rows)
}

/// The grid rows `rows` of [`render_target_in_view`] by themselves, the same samples bit for
/// bit ([`crate::scene::render_target_rows`]).
pub fn render_target_in_view_rows(
    target: &Target,
    g: &SamplingGrid,
    extent_m: Option<(f64, f64)>,
    rows: std::ops::Range<usize>,
) -> Result<SpectralImage, CoreError> {
    let Some((w, h)) = extent_m else {
        return render_target_rows(target, g, rows);
    };
    if !(w.is_finite() && h.is_finite() && w > 0.0 && h > 0.0) {
        return Err(CoreError::Target(format!(
            "field of view gives an image-plane extent of {w} × {h} m (expected positive)"
        )));
    }
    match target {
        Target::Image { radiance } => {
            if rows.start > rows.end || rows.end > g.rows {
                return Err(CoreError::Target(format!(
                    "row window {}..{} of a {}-row sampling grid",
                    rows.start, rows.end, g.rows
                )));
            }
            Ok(area_resample(radiance, g, w, h, rows))
        }
        other => {
            let gv = SamplingGrid {
                sensor_width_m: w,
                sensor_height_m: h,
                ..*g
            };
            render_target_rows(other, &gv, rows)
        }
    }
}

/// The grid rows `rows` of [`render_target_in_view`] projected onto `proj`'s output planes,
/// bit for bit as [`crate::scene::render_target_projected_rows`] (of which it is the
/// field-of-view form): an image with an extent is resampled on the rows and combined.
pub fn render_target_in_view_projected_rows(
    target: &Target,
    g: &SamplingGrid,
    extent_m: Option<(f64, f64)>,
    rows: std::ops::Range<usize>,
    proj: &PlaneProjection,
) -> Result<Vec<Vec<f32>>, CoreError> {
    match (extent_m, target) {
        (None, _) => render_target_projected_rows(target, g, rows, proj),
        // one strip: the resampling's horizontal pass is over the whole picture
        (Some(_), Target::Image { .. }) => {
            let mut img = render_target_in_view_rows(target, g, extent_m, rows)?;
            check_projection(&img.basis, proj)?;
            img.scale(proj.term_scale);
            Ok(proj.weights.iter().map(|w| img.combine(w)).collect())
        }
        (Some((w, h)), other) => {
            if !(w.is_finite() && h.is_finite() && w > 0.0 && h > 0.0) {
                return Err(CoreError::Target(format!(
                    "field of view gives an image-plane extent of {w} × {h} m (expected positive)"
                )));
            }
            let gv = SamplingGrid {
                sensor_width_m: w,
                sensor_height_m: h,
                ..*g
            };
            render_target_projected_rows(other, &gv, rows, proj)
        }
    }
}

/// For each output cell along one axis (`n` cells of size `pitch`, centred), the source
/// pixels (`m` of size `extent / m`, centred) it overlaps and the overlap as a fraction of
/// the cell.
fn axis_weights(n: usize, pitch: f64, m: usize, extent: f64) -> Vec<Vec<(usize, f32)>> {
    let src = extent / m as f64;
    (0..n)
        .map(|i| {
            let a0 = (i as f64 - n as f64 / 2.0) * pitch;
            let a1 = a0 + pitch;
            // source index range touching [a0, a1)
            let s0 = ((a0 + extent / 2.0) / src).floor().max(0.0);
            let s1 = ((a1 + extent / 2.0) / src).ceil().min(m as f64);
            let mut v = Vec::new();
            let mut j = s0 as usize;
            while (j as f64) < s1 {
                let b0 = -extent / 2.0 + j as f64 * src;
                let o = (a1.min(b0 + src) - a0.max(b0)).max(0.0);
                if o > 0.0 {
                    v.push((j, (o / pitch) as f32));
                }
                j += 1;
            }
            v
        })
        .collect()
}

/// Exact area average of a piecewise-constant picture spanning `w × h` (centred) onto `g`;
/// zero outside; grid rows `rows` only.
fn area_resample(
    src: &SpectralImage,
    g: &SamplingGrid,
    w: f64,
    h: f64,
    rows: std::ops::Range<usize>,
) -> SpectralImage {
    let wx = axis_weights(g.cols, g.pitch_m, src.cols, w);
    let wy = axis_weights(g.rows, g.pitch_m, src.rows, h);
    let wy = &wy[rows.clone()];
    let planes = src
        .planes
        .par_iter()
        .map(|p| {
            // horizontal pass: src.rows × g.cols
            let mut tmp = vec![0f32; src.rows * g.cols];
            for r in 0..src.rows {
                let row = &p[r * src.cols..(r + 1) * src.cols];
                for (c, ws) in wx.iter().enumerate() {
                    tmp[r * g.cols + c] = ws.iter().map(|&(j, k)| row[j] * k).sum();
                }
            }
            // vertical pass
            let mut out = vec![0f32; rows.len() * g.cols];
            for (r, ws) in wy.iter().enumerate() {
                for &(i, k) in ws {
                    let t = &tmp[i * g.cols..(i + 1) * g.cols];
                    for (o, v) in out[r * g.cols..(r + 1) * g.cols].iter_mut().zip(t) {
                        *o += k * v;
                    }
                }
            }
            out
        })
        .collect();
    SpectralImage {
        rows: rows.len(),
        cols: g.cols,
        basis: src.basis.clone(),
        planes,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::spectrum::Spectrum;

    #[test]
    fn area_resampling_conserves_coverage() {
        // a 3×5 white picture covering 7.3 × 4.38 µm on a 1 µm grid of 20×20: total coverage
        // = the picture's area in cells, whatever the alignment
        let img = SpectralImage::from_single_spectrum(3, 5, Spectrum::constant(1.0), vec![1.0; 15]);
        let g = SamplingGrid::for_sensor(20, 20, 1e-6, 1, 0);
        let (w, h) = (7.3e-6, 7.3e-6 * 3.0 / 5.0);
        let out =
            render_target_in_view(&Target::Image { radiance: img }, &g, Some((w, h))).unwrap();
        let total: f64 = out.planes[0].iter().map(|v| *v as f64).sum();
        assert!((total - w * h / 1e-12).abs() < 1e-4, "{total}");
        assert!(out.planes[0].iter().all(|v| (0.0..=1.0 + 1e-6).contains(v)));
        // the centre is inside, the corner outside
        assert_eq!(out.planes[0][10 * 20 + 10], 1.0);
        assert_eq!(out.planes[0][0], 0.0);
    }

    /// With a field of view too, the projected render is the combined scaled term render bit
    /// for bit (a chart laid over the extent, a picture resampled onto it).
    #[test]
    fn projected_render_in_view_is_the_combined_term_render() {
        use crate::scene::target_basis;
        use crate::scene::tests::{every_kind_of_target, test_projection};
        let g = SamplingGrid::for_sensor(9, 14, 1e-6, 2, 1);
        for t in &every_kind_of_target() {
            let extent = Some((11.3e-6, 7.1e-6));
            let terms = target_basis(t).unwrap().len();
            let proj = test_projection(2, terms, 0.83);
            let mut whole = render_target_in_view(t, &g, extent).unwrap();
            whole.scale(proj.term_scale);
            for (r0, r1) in [(0, g.rows), (5, 13)] {
                let got =
                    render_target_in_view_projected_rows(t, &g, extent, r0..r1, &proj).unwrap();
                for (a, w) in got.iter().zip(&proj.weights) {
                    let want = whole.combine(w);
                    let crop = &want[r0 * g.cols..r1 * g.cols];
                    assert!(
                        a.iter().zip(crop).all(|(x, y)| x.to_bits() == y.to_bits()),
                        "{t:?} rows {r0}..{r1}"
                    );
                }
            }
        }
    }

    #[test]
    fn extent_and_fov_are_inverse() {
        let (w, _) = extent_in_image_plane_m(30.0, 0.75, 0.05);
        assert!((fov_deg_of_width(w, 0.05) - 30.0).abs() < 1e-12);
    }
}
