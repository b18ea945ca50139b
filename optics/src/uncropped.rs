//! The uncropped optical image of a scene that covers only part of the simulation grid:
//! ISETCam's `oiCompute(…, crop = false)` procedure (issue 17 §4) applied to the scene image
//! (the target's own extent), its result placed back on the grid.
//!
//! ISETCam computes the optical image on the scene's own samples: the scene is zero-padded by
//! `round(rows/8)` rows and `round(cols/8)` columns each side (`oiPad`), blurred by the FFT
//! (whose OTF(0) = 1 conserves power), and with `crop = false` the padded image is kept, so a
//! sensor larger than the scene sees the ring of blurred light around it. Here the scene image
//! is the centred window `rows × cols` of the grid that the target covers;
//! [`crate::form_image_uncropped`] forms its padded image, which is written back centred on
//! the grid. Everything outside the scene image and its ring is zero (ISETCam has no light
//! there), and the ring is cut where it leaves the grid.
use crate::{form_image_uncropped, OpticsError, OpticsModel, Padding};
use camsim_core::image::Plane;
use camsim_core::{SceneRadiance, SensorIrradiance, SpectralImage, WavelengthGrid};

/// The centred window of `n` samples that covers an extent of `extent_samples` samples on an
/// axis of `n` samples: `[c0, n − c0)` with `c0 = floor(n/2 − extent/2)` (cells the extent
/// touches at all, clamped to the axis). Symmetric about the axis centre, so the window's
/// centre is the grid's (the optical axis).
pub fn centred_window(n: usize, extent_samples: f64) -> (usize, usize) {
    let half = 0.5 * extent_samples.max(0.0);
    // 1e-9: an extent of a whole number of samples is not widened by rounding.
    let c0 = (0.5 * n as f64 - half + 1e-9).floor().max(0.0) as usize;
    let c0 = c0.min(n / 2);
    (c0, n - c0)
}

/// Copy rows `r0..r1`, columns `c0..c1` of every plane.
fn window(
    img: &SpectralImage,
    (r0, r1): (usize, usize),
    (c0, c1): (usize, usize),
) -> SpectralImage {
    let (nr, nc) = (r1 - r0, c1 - c0);
    let planes = img
        .planes
        .iter()
        .map(|p| {
            let mut q = Vec::with_capacity(nr * nc);
            for i in r0..r1 {
                q.extend_from_slice(&p[i * img.cols + c0..i * img.cols + c1]);
            }
            q
        })
        .collect();
    SpectralImage {
        rows: nr,
        cols: nc,
        basis: img.basis.clone(),
        planes,
    }
}

/// The optical image of `scene` when the scene image is only its centred window of
/// `window_rows × window_cols` samples (a target whose field of view is smaller than the
/// grid): ISETCam's uncropped optical image of that window ([`crate::form_image_uncropped`],
/// with the ISETCam zero padding whatever `optics.padding` says), written back centred on
/// `scene`'s grid. The result has `scene`'s size and pitch; outside the window and its
/// `round(n/8)` ring it is zero. The window must be centred (see [`centred_window`]): it is
/// `[(rows − window_rows)/2, …)`, so `rows − window_rows` and `cols − window_cols` must be even.
pub fn form_image_uncropped_window(
    optics: &OpticsModel,
    scene: &SceneRadiance,
    bands: &WavelengthGrid,
    window_rows: usize,
    window_cols: usize,
) -> Result<SensorIrradiance, OpticsError> {
    let (rows, cols) = (scene.radiance.rows, scene.radiance.cols);
    if window_rows == 0
        || window_cols == 0
        || window_rows > rows
        || window_cols > cols
        || (rows - window_rows) % 2 != 0
        || (cols - window_cols) % 2 != 0
    {
        return Err(OpticsError::Scene(format!(
            "the scene image ({window_rows} × {window_cols}) must be a centred window of the \
             {rows} × {cols} grid"
        )));
    }
    let (r0, c0) = ((rows - window_rows) / 2, (cols - window_cols) / 2);
    let (rr, cc) = ((r0, r0 + window_rows), (c0, c0 + window_cols));
    let sub = SceneRadiance {
        radiance: window(&scene.radiance, rr, cc),
        sample_pitch_m: scene.sample_pitch_m,
        object_distance_m: scene.object_distance_m,
        illuminant: scene.illuminant.clone(),
        depth_m: scene.depth_m.as_ref().map(|d| {
            let mut data = Vec::with_capacity(window_rows * window_cols);
            for i in rr.0..rr.1 {
                data.extend_from_slice(&d.data[i * d.cols + cc.0..i * d.cols + cc.1]);
            }
            Plane {
                rows: window_rows,
                cols: window_cols,
                data,
            }
        }),
        sample_aperture: scene.sample_aperture,
    };
    let zero = OpticsModel {
        padding: Padding::Zero,
        ..optics.clone()
    };
    let un = form_image_uncropped(&zero, &sub, bands)?;
    let e = &un.irradiance.irradiance;
    // The padded image's top-left sample sits at (r0 − pad_rows, c0 − pad_cols) of the grid.
    let (top, left) = (
        r0 as isize - un.pad_rows as isize,
        c0 as isize - un.pad_cols as isize,
    );
    let planes = e
        .planes
        .iter()
        .map(|p| {
            let mut q = vec![0f32; rows * cols];
            for i in 0..e.rows {
                let gi = top + i as isize;
                if gi < 0 || gi >= rows as isize {
                    continue;
                }
                for j in 0..e.cols {
                    let gj = left + j as isize;
                    if gj >= 0 && gj < cols as isize {
                        q[gi as usize * cols + gj as usize] = p[i * e.cols + j];
                    }
                }
            }
            q
        })
        .collect();
    Ok(SensorIrradiance {
        irradiance: SpectralImage {
            rows,
            cols,
            basis: e.basis.clone(),
            planes,
        },
        sample_pitch_m: un.irradiance.sample_pitch_m,
    })
}
