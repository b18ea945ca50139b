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
//! * Any PSF per depth can be supplied ([`defocus_layered`] takes a kernel function). Each
//!   slab is blurred with the PSF of its pixels' mean 1/z, which is exact for planes.
//! * Real lens ([`LensDefocus`]): the lens's on-axis geometric PSF at each slab's object
//!   distance, taken from the `camsim-lens` field model tabulated over object distance and
//!   binned on the pixel grid. It is compared with the real-lens camera in
//!   `render/tests/depth_path.rs` and in docs/study_dof.md: edge rise per depth within
//!   0.3 px + 12 %, DoF within 4 %, pixel error ≤ 3.5 % inside tiles and 5–31 % at
//!   occlusion boundaries.
//!
//! Known limits (measured in docs/render_validation.md): a pinhole image has no radiance for
//! surfaces hidden behind foreground edges, which a finite aperture partly sees, and blurred
//! foreground edges over a sharp background are approximated by the layer composite.

use crate::plane_fft::{convolve_window, grown_support, PlaneConvolver};

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
    /// (8×8 sub-samples); the identity below 1/16 px, and also where the disc is too small to
    /// hold any sub-sample (r < √2/16 px, the nearest sub-sample's distance from the centre:
    /// normalising an empty kernel would give 0/0).
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
        if !(s > 0.0) {
            return Kernel::delta();
        }
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
    /// The image scale (px per unit tan θ) of the camera: H/(2 tan(θ_y/2))
    /// ([`crate::depth_optics::pinhole_pixels_per_tan`]).
    pub fn pixels_per_tan(&self) -> f64 {
        crate::depth_optics::pinhole_pixels_per_tan(self.yfov_rad, self.height_px)
    }

    /// Circle-of-confusion radius (px) of planar depth `z_m` (∞ allowed).
    pub fn coc_radius_px(&self, z_m: f64) -> f64 {
        let inv = if z_m.is_finite() { 1.0 / z_m } else { 0.0 };
        self.aperture_radius_m * (inv - 1.0 / self.focus_distance_m).abs() * self.pixels_per_tan()
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

/// Convolve a `w × h` plane with `k` (edge replication): the direct sum, or the FFT for
/// large kernels ([`crate::plane_fft::PlaneConvolver`]).
pub fn convolve(img: &[f32], w: usize, h: usize, k: &Kernel) -> Vec<f32> {
    PlaneConvolver::new(w, h, k).apply(img)
}

/// Smallest slab span relative to the nearest inverse depth: depths from f32 hit distances
/// differ by a few ulps (relative ~1e-7) on one plane, and slabs thinner than that would split
/// a plane into layers that occlude each other cell by cell (a flat checker whose cells are
/// separate quads). Below this span the depths are one slab.
pub const SLAB_MIN_RELATIVE_SPAN: f64 = 1e-5;

/// The depth slabs of a depth map (result of [`slabs`]).
#[derive(Debug, Clone, PartialEq)]
pub struct DepthSlabs {
    /// The slab (0..layers) of every pixel.
    pub index: Vec<usize>,
    /// The mean inverse depth (1/m) of each slab's pixels (`None` for an empty slab).
    pub mean_inv_z: Vec<Option<f64>>,
}

impl DepthSlabs {
    /// The window rows `r0..r1`, columns `c0..c1` of a `w`-wide map, with the whole map's
    /// slabs: a window is composited with the layers of the whole image, never re-sliced by
    /// its own (narrower) depth range.
    pub fn window(&self, w: usize, (r0, r1): (usize, usize), (c0, c1): (usize, usize)) -> Self {
        DepthSlabs {
            index: (r0..r1)
                .flat_map(|r| self.index[r * w + c0..r * w + c1].iter().copied())
                .collect(),
            mean_inv_z: self.mean_inv_z.clone(),
        }
    }
}

/// The slab (0..`layers`) of every pixel and the mean inverse depth (1/m) of each slab's
/// pixels: slabs are uniform in 1/z between the nearest and the farthest depth of `depth_m`
/// (∞ or non-positive = escaped, 1/z = 0), at least [`SLAB_MIN_RELATIVE_SPAN`] of the nearest
/// 1/z wide together.
pub fn slabs(depth_m: &[f32], layers: usize) -> DepthSlabs {
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
    let span = (hi - lo).max(SLAB_MIN_RELATIVE_SPAN * hi).max(1e-12);
    let index: Vec<usize> = inv
        .iter()
        .map(|v| (((v - lo) / span * layers as f64) as usize).min(layers - 1))
        .collect();
    let mut sum = vec![(0f64, 0usize); layers];
    for (k, v) in index.iter().zip(&inv) {
        sum[*k].0 += v;
        sum[*k].1 += 1;
    }
    let mean = sum
        .iter()
        .map(|(s, n)| if *n > 0 { Some(s / *n as f64) } else { None })
        .collect();
    DepthSlabs {
        index,
        mean_inv_z: mean,
    }
}

/// The inverse depths (1/m) at which [`defocus_layered`] asks for kernels: the mean 1/z of
/// every non-empty slab (a tabulated PSF model can be built at exactly these).
pub fn slab_inverse_depths(depth_m: &[f32], layers: usize) -> Vec<f64> {
    slabs(depth_m, layers)
        .mean_inv_z
        .into_iter()
        .flatten()
        .collect()
}

/// Layered depth-of-field: `bands` radiance planes (`w × h`) with planar depth `depth_m`
/// (∞ = escaped) → the defocused planes. `kernel(inv_z)` gives the PSF of inverse depth
/// `inv_z` (1/m, 0 = infinity); `layers` slabs uniform in 1/z between the nearest and the
/// farthest depth, each blurred with the PSF of its pixels' mean 1/z (exact for planes:
/// a slab holding one plane uses that plane's PSF).
pub fn defocus_layered(
    bands: &[Vec<f32>],
    depth_m: &[f32],
    w: usize,
    h: usize,
    layers: usize,
    kernel: impl Fn(f64) -> Kernel + Sync,
) -> Vec<Vec<f32>> {
    defocus_layered_with(bands, depth_m, w, h, layers, false, kernel)
}

/// [`defocus_layered`], optionally continuing the background under blurred foreground edges
/// across depth jumps (`continue_background`): where a layer's blurred coverage is partial
/// and no farther layer reached the pixel, the rest of the aperture sees the background,
/// taken as the mean of the composite so far over the covered pixels (more than 10 % farther
/// in 1/z) within the layer kernel's support. Exact for a straight occluding edge over a
/// background uniform along it (`render/tests/depth_crosscheck.rs`); without it the near side
/// of such an edge keeps the foreground colour and its blur is too narrow. On the Mitsuba
/// thin-lens scene (lit boxes, floor, wall) it raises the RMS error near depth edges
/// (docs/render_validation.md), so [`defocus_layered`] (the DoF study) does not use it.
pub fn defocus_layered_with(
    bands: &[Vec<f32>],
    depth_m: &[f32],
    w: usize,
    h: usize,
    layers: usize,
    continue_background: bool,
    kernel: impl Fn(f64) -> Kernel + Sync,
) -> Vec<Vec<f32>> {
    let s = slabs(depth_m, layers);
    defocus_layered_slabs(bands, &s, w, h, continue_background, kernel)
}

/// [`defocus_layered_with`] on given slabs (`slabs` of a `w × h` image, e.g. a window of the
/// whole image's [`DepthSlabs`]).
pub fn defocus_layered_slabs(
    bands: &[Vec<f32>],
    slabs: &DepthSlabs,
    w: usize,
    h: usize,
    continue_background: bool,
    kernel: impl Fn(f64) -> Kernel + Sync,
) -> Vec<Vec<f32>> {
    use rayon::prelude::*;
    let (index, mean) = (&slabs.index, &slabs.mean_inv_z);
    // acc: the composite so far as a normalised colour; cover: whether any layer reached the
    // pixel yet
    let mut acc = vec![vec![0f32; w * h]; bands.len()];
    let mut cover = vec![false; w * h];
    // the mean 1/z of the nearest slab that reached each pixel so far
    let mut cover_inv = vec![0f64; w * h];
    // back to front: small 1/z first
    for (k, mean_k) in mean.iter().enumerate() {
        let Some(mid) = *mean_k else { continue };
        let alpha: Vec<f32> = index
            .iter()
            .map(|s| if *s == k { 1.0 } else { 0.0 })
            .collect();
        let ker = kernel(mid);
        // The slab's coverage and premultiplied radiance vanish outside its pixels: convolve
        // only the window of their bounding box grown by the kernel radius (exact).
        let Some(bbox) = grown_support(&alpha, w, h, ker.radius) else {
            continue;
        };
        let conv = PlaneConvolver::new(bbox.3 - bbox.2, bbox.1 - bbox.0, &ker);
        let a_blur = convolve_window(&alpha, w, h, bbox, &conv);
        // Under this layer's blurred edge, pixels no farther layer reached still see the
        // background through the rest of the aperture: continue the composite so far there by
        // its normalised convolution over the disc of the kernel's support (the mean of the
        // background visible within that disc).
        // Only across a depth jump: the background must lie more than 10 % farther in 1/z (a
        // continuous surface crossing slabs keeps the layer's own normalised colour).
        let partial = |q: usize| !cover[q] && a_blur[q] > 1e-6 && a_blur[q] < 1.0 - 1e-6;
        let source = |q: usize| cover[q] && cover_inv[q] < 0.9 * mid;
        if continue_background
            && ker.radius > 0
            && (0..w * h).any(source)
            && (0..w * h).any(partial)
        {
            let fill = PlaneConvolver::new(w, h, &Kernel::pillbox(ker.radius as f64));
            let covf: Vec<f32> = (0..w * h).map(|q| source(q) as u8 as f32).collect();
            let wsum = fill.apply(&covf);
            let filled: Vec<bool> = (0..w * h).map(|k| partial(k) && wsum[k] > 1e-6).collect();
            acc.par_iter_mut().for_each(|acc_b| {
                let masked: Vec<f32> = acc_b.iter().zip(&covf).map(|(v, c)| v * c).collect();
                let num = fill.apply(&masked);
                for k in 0..w * h {
                    if filled[k] {
                        acc_b[k] = num[k] / wsum[k];
                    }
                }
            });
            for (q, f) in filled.iter().enumerate() {
                if *f {
                    cover[q] = true;
                    cover_inv[q] = 0.0;
                }
            }
        }
        acc.par_iter_mut().zip(bands).for_each(|(acc_b, band)| {
            let premul: Vec<f32> = band.iter().zip(&alpha).map(|(l, a)| l * a).collect();
            let c_blur = convolve_window(&premul, w, h, bbox, &conv);
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
        for ((cov, a), ci) in cover.iter_mut().zip(&a_blur).zip(cover_inv.iter_mut()) {
            if *a > 1e-6 {
                *cov = true;
                *ci = mid;
            }
        }
    }
    acc
}

/// Lens defocus for the depth path: the on-axis **geometric** PSF of a `camsim-lens`
/// prescription at each object distance, from the lens field model
/// ([`camsim_lens::field_model::FieldModel`], tabulated over object distance), binned on the
/// sensor's pixel grid and averaged over the given wavelengths.
///
/// Conventions are those of the real-lens camera ([`crate::camera::real_lens`]): the camera
/// frame's origin is the paraxial entrance pupil, so a planar depth z (m) is the object
/// distance z·10³ − z_ep (mm) from the first vertex; the lens is stopped to `f_number` and
/// focused on `focus_distance_m` from the entrance pupil by the focus model
/// (`LensDefocusOptions::focus_method`).
///
/// On-axis PSFs are used for the whole frame (justified for small fields: the study scenes
/// span ≲ 2° off axis, where the real-lens PSF changes little); paraxially, the defocus disc
/// is the thin-lens one of [`ThinLensDefocus`] with the entrance-pupil radius as aperture
/// radius (`render/tests/depth_path.rs` checks this).
#[derive(Debug, Clone)]
pub struct LensDefocus {
    /// (1/z in 1/m, kernel) by increasing 1/z.
    table: Vec<(f64, Kernel)>,
    /// Entrance-pupil radius (m) of the stopped lens.
    pub entrance_pupil_radius_m: f64,
}

/// Options of [`LensDefocus::new`].
#[derive(Debug, Clone, PartialEq)]
pub struct LensDefocusOptions {
    /// Stop the lens to this F-number (`None` = the prescription's aperture).
    pub f_number: Option<f64>,
    /// Focus distance from the entrance pupil (m; `None` = infinity).
    pub focus_distance_m: Option<f64>,
    /// Sensor pixel pitch (mm): the PSF bin size.
    pub pixel_pitch_mm: f64,
    /// Wavelengths whose PSFs are averaged (nm; equal weights).
    pub wavelengths_nm: Vec<f64>,
    /// Pupil rays per side of the geometric PSFs.
    pub pupil_n: usize,
    /// How the lens is focused (`camsim_lens::focus_model`; an unset merit frequency is half
    /// the pixel Nyquist, 1/(4p)). Pass the real-lens camera's resolved method
    /// (`RealLensInfo::focus.method`) to image with the same focus.
    pub focus_method: camsim_lens::FocusMethod,
}

/// The object distance from a lens's first vertex (mm) of a planar inverse depth `inv_z`
/// (1/m) measured from its entrance pupil at `entrance_pupil_z_mm` (the real-lens camera's
/// frame): `1000/inv_z − z_ep`; `None` at infinity (`inv_z ≤ 0`), an error naming `what` for a
/// depth behind the first vertex.
pub(crate) fn vertex_distance_mm(
    inv_z: f64,
    entrance_pupil_z_mm: f64,
    what: &str,
) -> Result<Option<f64>, camsim_lens::LensError> {
    if inv_z <= 0.0 {
        return Ok(None);
    }
    let d = 1e3 / inv_z - entrance_pupil_z_mm;
    if !(d > 0.0) {
        return Err(camsim_lens::LensError::Prescription(format!(
            "{what}: depth {:.4} m lies behind the lens's first vertex",
            1.0 / inv_z
        )));
    }
    Ok(Some(d))
}

impl LensDefocus {
    /// Tabulate the PSFs of the planar inverse depths `inv_depths_per_m` (1/m, 0 = infinity;
    /// e.g. [`slab_inverse_depths`]).
    pub fn new(
        lens: &camsim_lens::LensPrescription,
        opts: &LensDefocusOptions,
        inv_depths_per_m: &[f64],
    ) -> Result<Self, camsim_lens::LensError> {
        use camsim_lens::field_model::{FieldModel, FieldModelOptions, Focus, PsfKind};
        use camsim_lens::prescription::Aperture;
        let bad = |m: String| camsim_lens::LensError::Prescription(format!("depth path: {m}"));
        if !(opts.pixel_pitch_mm > 0.0) || opts.wavelengths_nm.is_empty() {
            return Err(bad(
                "pixel pitch must be > 0 and at least one wavelength given".into(),
            ));
        }
        let mut lens = lens.clone();
        if let Some(n) = opts.f_number {
            lens.aperture = Aperture::FNumber(n);
        }
        let fo = lens.first_order(lens.primary_nm)?;
        let z_ep_mm = fo.entrance_pupil_z_mm;
        let r_ep_mm = 0.5 * fo.entrance_pupil_diameter_mm;
        // planar depth from the entrance pupil → distance from the first vertex
        let to_vertex = |inv: f64| vertex_distance_mm(inv, z_ep_mm, "depth path");
        let focus_mm = to_vertex(opts.focus_distance_m.map_or(0.0, |d| 1.0 / d))?;
        let mut method = opts.focus_method.clone();
        method.frequency_cyc_per_mm = method
            .frequency_cyc_per_mm
            .or(Some(0.25 / opts.pixel_pitch_mm));
        let focus = lens.focus(&camsim_lens::FocusSpec {
            focus_distance_mm: focus_mm,
            method,
        })?;
        let focused = focus.lens.clone();
        // Image-side scale (mm of paraxial image per unit tan θ) → the largest defocus disc.
        let per_tan_mm = focused.paraxial_image_mm_per_tan(lens.primary_nm)?;
        let v_focus = opts.focus_distance_m.map_or(0.0, |d| 1.0 / d);
        let mut invs: Vec<f64> = inv_depths_per_m.iter().map(|v| v.max(0.0)).collect();
        invs.sort_by(|a, b| a.partial_cmp(b).unwrap());
        invs.dedup();
        let max_dv = invs.iter().map(|v| (v - v_focus).abs()).fold(0.0, f64::max);
        // thin-lens disc radius (px) + margin for aberrations
        let c_max_px =
            camsim_lens::paraxial::paraxial_blur_radius_mm(r_ep_mm, per_tan_mm, max_dv, 0.0)
                / opts.pixel_pitch_mm;
        let psf_n = 2 * ((1.3 * c_max_px + 4.0).ceil() as usize) + 1;
        let distances = invs
            .iter()
            .map(|v| to_vertex(*v))
            .collect::<Result<Vec<_>, _>>()?;
        let model = FieldModel::compute(
            &lens,
            &FieldModelOptions {
                n_fields: 2,
                paraxial_heights_mm: None,
                max_field_deg: Some(1.0),
                wavelengths_nm: Some(opts.wavelengths_nm.clone()),
                kind: PsfKind::Geometric,
                psf_n,
                psf_pitch_um: opts.pixel_pitch_mm * 1e3,
                pupil_n: opts.pupil_n.max(8),
                pad: 1,
                ri_grid_n: 8,
                focus: Focus::Focused(Box::new(focus)),
                object_distances_mm: distances.clone(),
            },
        )?;
        let table = invs
            .iter()
            .zip(&distances)
            .map(|(v, d)| {
                let t = model.at_distance(*d);
                let mut acc = vec![0f64; psf_n * psf_n];
                for wl in &opts.wavelengths_nm {
                    for (a, p) in acc.iter_mut().zip(t.psf_on_y(0.0, *wl)) {
                        *a += p;
                    }
                }
                (*v, trim_kernel(&acc, psf_n))
            })
            .collect();
        Ok(LensDefocus {
            table,
            entrance_pupil_radius_m: r_ep_mm * 1e-3,
        })
    }

    /// The tabulated PSF nearest in 1/z to `inv_z` (1/m).
    pub fn kernel(&self, inv_z: f64) -> Kernel {
        self.table
            .iter()
            .min_by(|a, b| {
                (a.0 - inv_z)
                    .abs()
                    .partial_cmp(&(b.0 - inv_z).abs())
                    .unwrap()
            })
            .map(|t| t.1.clone())
            .unwrap_or_else(Kernel::delta)
    }

    /// The tabulated (1/z, kernel) pairs.
    pub fn table(&self) -> &[(f64, Kernel)] {
        &self.table
    }
}

/// An `n × n` PSF (centre at n/2) → a normalised kernel cropped to its non-zero extent.
pub(crate) fn trim_kernel(psf: &[f64], n: usize) -> Kernel {
    let c = n / 2;
    let mut r = 0;
    for j in 0..n {
        for i in 0..n {
            // every non-zero sample (spread PSFs have small negative ones)
            if psf[j * n + i] != 0.0 {
                r = r.max(i.abs_diff(c)).max(j.abs_diff(c));
            }
        }
    }
    let m = 2 * r + 1;
    let mut values = vec![0f32; m * m];
    for j in 0..m {
        for i in 0..m {
            values[j * m + i] = psf[(j + c - r) * n + (i + c - r)] as f32;
        }
    }
    let s: f32 = values.iter().sum();
    if !(s > 0.0) {
        return Kernel::delta();
    }
    values.iter_mut().for_each(|v| *v /= s);
    Kernel { radius: r, values }
}

/// Real-lens dual-pixel defocus: the on-axis geometric PSFs of the left (entrance-pupil
/// x < 0) and the right (x > 0) pupil half of a focused `camsim-lens` prescription at each
/// object distance ([`camsim_lens::geometric_pupil_half_psfs`], the binning of the field
/// model's geometric PSF, so the two halves partition the full PSF of [`LensDefocus`] /
/// [`crate::depth_optics::LensDepthKernels`]), per wavelength. A microlens images the exit
/// pupil onto the two half-photodiodes, so each sees one half (Wadhwa et al., ACM TOG 37(4),
/// 2018, §3; the thin-lens form is `camsim_optics::dual_pixel`). Conventions (planar depth from
/// the paraxial entrance pupil) are those of [`LensDefocus`]. On axis the two halves carry
/// equal shares of the light (the pupil grid is symmetric in x), so each kernel is normalised
/// to 1 and the caller weights each half image by ½. Limits: one (on-axis) PSF per
/// wavelength and depth for the whole frame; geometric (no diffraction).
#[derive(Debug, Clone)]
pub struct LensDualPixelDefocus {
    /// Tabulated wavelengths (nm, increasing).
    pub wavelengths_nm: Vec<f64>,
    /// `[wavelength]` → (1/z in 1/m, left kernel, right kernel) by increasing 1/z.
    table: Vec<Vec<(f64, Kernel, Kernel)>>,
    /// Entrance-pupil radius (m) of the lens.
    pub entrance_pupil_radius_m: f64,
}

impl LensDualPixelDefocus {
    /// Tabulate the half-pupil PSFs of `focus.lens` (as focused) at the planar inverse depths
    /// `inv_depths_per_m` (1/m from the entrance pupil, 0 = infinity) and `wavelengths_nm`,
    /// binned at `sample_pitch_mm` with a `pupil_n`² ray grid.
    pub fn new(
        focus: &camsim_lens::FocusedLens,
        sample_pitch_mm: f64,
        wavelengths_nm: &[f64],
        pupil_n: usize,
        inv_depths_per_m: &[f64],
    ) -> Result<Self, camsim_lens::LensError> {
        if !(sample_pitch_mm > 0.0) || wavelengths_nm.is_empty() {
            return Err(camsim_lens::LensError::Prescription(
                "dual-pixel lens defocus: sample pitch must be > 0 and at least one wavelength given"
                    .into(),
            ));
        }
        let lens = &focus.lens;
        let fo = lens.first_order(lens.primary_nm)?;
        let z_ep_mm = fo.entrance_pupil_z_mm;
        let r_ep_mm = 0.5 * fo.entrance_pupil_diameter_mm;
        let per_tan_mm = lens.paraxial_image_mm_per_tan(lens.primary_nm)?;
        let v_focus = focus.focus_distance_mm.map_or(0.0, |d| 1e3 / (d + z_ep_mm));
        let mut invs: Vec<f64> = inv_depths_per_m.iter().map(|v| v.max(0.0)).collect();
        invs.sort_by(|a, b| a.total_cmp(b));
        invs.dedup();
        if invs.is_empty() {
            invs.push(v_focus);
        }
        let mut wls = wavelengths_nm.to_vec();
        wls.sort_by(|a, b| a.total_cmp(b));
        wls.dedup();
        let table = wls
            .iter()
            .map(|wl| {
                invs.iter()
                    .map(|v| {
                        let d = vertex_distance_mm(*v, z_ep_mm, "dual-pixel lens defocus")?;
                        // thin-lens disc radius (samples) + margin for aberrations
                        let c = camsim_lens::paraxial::paraxial_blur_radius_mm(
                            r_ep_mm, per_tan_mm, *v, v_focus,
                        )
                        .abs()
                            / sample_pitch_mm;
                        let psf_n = 2 * ((1.5 * c + 8.0).ceil() as usize) + 1;
                        let p = camsim_lens::geometric_pupil_half_psfs(
                            &lens.with_object_distance(d),
                            *wl,
                            pupil_n,
                            psf_n,
                            sample_pitch_mm,
                        )?;
                        Ok((*v, trim_kernel(&p.left, p.n), trim_kernel(&p.right, p.n)))
                    })
                    .collect::<Result<Vec<_>, camsim_lens::LensError>>()
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(LensDualPixelDefocus {
            wavelengths_nm: wls,
            table,
            entrance_pupil_radius_m: r_ep_mm * 1e-3,
        })
    }

    /// The tabulated (left, right) kernels of wavelength index `wl`, nearest in 1/z to `inv_z`.
    pub fn kernels(&self, wl: usize, inv_z: f64) -> (Kernel, Kernel) {
        self.table[wl]
            .iter()
            .min_by(|a, b| (a.0 - inv_z).abs().total_cmp(&(b.0 - inv_z).abs()))
            .map(|t| (t.1.clone(), t.2.clone()))
            .unwrap_or_else(|| (Kernel::delta(), Kernel::delta()))
    }

    /// Index of the tabulated wavelength nearest `wavelength_nm`.
    pub fn nearest_wavelength(&self, wavelength_nm: f64) -> usize {
        (0..self.wavelengths_nm.len())
            .min_by(|a, b| {
                (self.wavelengths_nm[*a] - wavelength_nm)
                    .abs()
                    .total_cmp(&(self.wavelengths_nm[*b] - wavelength_nm).abs())
            })
            .unwrap_or(0)
    }
}
