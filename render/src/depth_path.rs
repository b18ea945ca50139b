//! The depth path: pinhole radiance + planar depth → depth-of-field by depth-dependent
//! defocus PSFs, the fast alternative to rendering through a thin or real lens.
//!
//! ## Model
//! * Thin lens (Mitsuba `thinlens` conventions: aperture radius R at the camera centre,
//!   planar focus distance D, vertical field of view θ_y over H pixels): a point at planar
//!   depth z is spread over a uniform disc (pillbox) of radius
//!   c(z) = R·|1/z − 1/D|·H / (2 tan(θ_y/2)) pixels (the rays through the aperture meet the
//!   focal plane's projection on the z = −1 plane with offsets R·(1/z − 1/D)); escaped pixels
//!   (depth ∞) get c = R·H/(2 D tan(θ_y/2)).
//! * Layers (Kraus & Strengert, "Depth-of-field rendering by pyramidal image processing",
//!   EG 2007; the usual layered scatter model): the depth range is cut into `layers` slabs
//!   uniform in 1/z (the CoC is linear in 1/z); each slab's coverage α and premultiplied
//!   radiance α·L are blurred with the PSF of its mid depth and composited back to front with
//!   "over": acc ← acc·(1 − α̃) + (αL)~. Where no farther layer reached a pixel, the layer's
//!   colour is its normalised blur (αL)~/α̃: a background is thereby continued under the
//!   edges of the layers in front of it (hole filling by normalised convolution), so a
//!   blurred foreground edge blends with the background instead of with black. Edges are
//!   replicated outside the image.
//! * Any PSF per depth can be supplied ([`defocus_layered`] takes a kernel function), e.g. a
//!   lens's on-axis geometric PSF at each depth.
//!
//! Known limits (measured in docs/render_validation.md): a pinhole image has no radiance for
//! surfaces hidden behind foreground edges, which a finite aperture partly sees, and blurred
//! foreground edges over a sharp background are approximated by the layer composite.

/// A normalised, odd-sized square kernel (row-major, centre at (r, r)).
#[derive(Debug, Clone, PartialEq)]
pub struct Kernel {
    /// Half-size: the kernel is (2r+1)².
    pub radius: usize,
    /// Values, summing to 1.
    pub values: Vec<f32>,
}

impl Kernel {
    /// The identity kernel.
    pub fn delta() -> Kernel {
        Kernel {
            radius: 0,
            values: vec![1.0],
        }
    }

    /// A uniform disc of radius `r_px` pixels, each pixel weighted by the disc area it covers
    /// (8×8 sub-samples); the identity below 1/16 px.
    pub fn pillbox(r_px: f64) -> Kernel {
        if !(r_px > 1.0 / 16.0) {
            return Kernel::delta();
        }
        let r = r_px.ceil() as usize;
        let n = 2 * r + 1;
        let mut values = vec![0f32; n * n];
        let ss = 8;
        for j in 0..n {
            for i in 0..n {
                let mut c = 0;
                for sy in 0..ss {
                    for sx in 0..ss {
                        let x = i as f64 - r as f64 - 0.5 + (sx as f64 + 0.5) / ss as f64;
                        let y = j as f64 - r as f64 - 0.5 + (sy as f64 + 0.5) / ss as f64;
                        if x * x + y * y <= r_px * r_px {
                            c += 1;
                        }
                    }
                }
                values[j * n + i] = c as f32;
            }
        }
        let s: f32 = values.iter().sum();
        values.iter_mut().for_each(|v| *v /= s);
        Kernel { radius: r, values }
    }
}

/// Thin-lens defocus (Mitsuba `thinlens` conventions).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ThinLensDefocus {
    /// Aperture radius (m).
    pub aperture_radius_m: f64,
    /// Planar focus distance (m).
    pub focus_distance_m: f64,
    /// Vertical field of view (rad).
    pub yfov_rad: f64,
    /// Image height (px).
    pub height_px: usize,
}

impl ThinLensDefocus {
    /// Circle-of-confusion radius (px) of planar depth `z_m` (∞ allowed).
    pub fn coc_radius_px(&self, z_m: f64) -> f64 {
        let inv = if z_m.is_finite() { 1.0 / z_m } else { 0.0 };
        self.aperture_radius_m * (inv - 1.0 / self.focus_distance_m).abs() * self.height_px as f64
            / (2.0 * (0.5 * self.yfov_rad).tan())
    }

    /// The pillbox PSF at inverse depth `inv_z` (1/m).
    pub fn kernel(&self, inv_z: f64) -> Kernel {
        let z = if inv_z > 0.0 {
            1.0 / inv_z
        } else {
            f64::INFINITY
        };
        Kernel::pillbox(self.coc_radius_px(z))
    }
}

/// Convolve a `w × h` plane with `k` (edge replication).
pub fn convolve(img: &[f32], w: usize, h: usize, k: &Kernel) -> Vec<f32> {
    if k.radius == 0 {
        return img.iter().map(|v| v * k.values[0]).collect();
    }
    let r = k.radius as isize;
    let n = 2 * k.radius + 1;
    let mut out = vec![0f32; w * h];
    for y in 0..h as isize {
        for x in 0..w as isize {
            let mut s = 0f32;
            for dy in -r..=r {
                let yy = (y - dy).clamp(0, h as isize - 1) as usize;
                let row = &img[yy * w..(yy + 1) * w];
                let krow = &k.values[((dy + r) as usize) * n..((dy + r) as usize + 1) * n];
                for dx in -r..=r {
                    let xx = (x - dx).clamp(0, w as isize - 1) as usize;
                    s += row[xx] * krow[(dx + r) as usize];
                }
            }
            out[y as usize * w + x as usize] = s;
        }
    }
    out
}

/// Layered depth-of-field: `bands` radiance planes (`w × h`) with planar depth `depth_m`
/// (∞ = escaped) → the defocused planes. `kernel(inv_z)` gives the PSF of inverse depth
/// `inv_z` (1/m, 0 = infinity); `layers` slabs uniform in 1/z between the nearest and the
/// farthest depth.
pub fn defocus_layered(
    bands: &[Vec<f32>],
    depth_m: &[f32],
    w: usize,
    h: usize,
    layers: usize,
    kernel: impl Fn(f64) -> Kernel + Sync,
) -> Vec<Vec<f32>> {
    use rayon::prelude::*;
    let inv: Vec<f64> = depth_m
        .iter()
        .map(|z| {
            if z.is_finite() && *z > 0.0 {
                1.0 / *z as f64
            } else {
                0.0
            }
        })
        .collect();
    let (lo, hi) = inv
        .iter()
        .fold((f64::INFINITY, 0f64), |(a, b), v| (a.min(*v), b.max(*v)));
    let layers = layers.max(1);
    let span = (hi - lo).max(1e-12);
    let slab = |v: f64| (((v - lo) / span * layers as f64) as usize).min(layers - 1);
    // acc: the composite so far as a normalised colour; cover: whether any layer reached the
    // pixel yet
    let mut acc = vec![vec![0f32; w * h]; bands.len()];
    let mut cover = vec![false; w * h];
    // back to front: small 1/z first
    for k in 0..layers {
        let alpha: Vec<f32> = inv
            .iter()
            .map(|v| if slab(*v) == k { 1.0 } else { 0.0 })
            .collect();
        if alpha.iter().all(|a| *a == 0.0) {
            continue;
        }
        let mid = lo + (k as f64 + 0.5) / layers as f64 * span;
        let ker = kernel(mid);
        let a_blur = convolve(&alpha, w, h, &ker);
        acc.par_iter_mut().zip(bands).for_each(|(acc_b, band)| {
            let premul: Vec<f32> = band.iter().zip(&alpha).map(|(l, a)| l * a).collect();
            let c_blur = convolve(&premul, w, h, &ker);
            for (((o, a), c), cov) in acc_b.iter_mut().zip(&a_blur).zip(&c_blur).zip(&cover) {
                if *cov {
                    // "over" the (hole-filled) background
                    *o = *o * (1.0 - a.min(1.0)) + c;
                } else if *a > 1e-6 {
                    // nothing behind: the layer's own colour, normalised by its coverage
                    *o = c / a;
                }
            }
        });
        for (cov, a) in cover.iter_mut().zip(&a_blur) {
            *cov |= *a > 1e-6;
        }
    }
    acc
}
