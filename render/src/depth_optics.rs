//! Depth-aware image formation for the camera chain: a pinhole scene radiance with planar
//! depth (a glTF render, or a spectral EXR with a `Z` channel) is defocused by the camera's
//! lens at every object distance, by the depth-layered compositing of [`crate::depth_path`]
//! (occlusion handled: a blurred foreground spreads over the background, which is continued
//! under it).
//!
//! Two kernel sources ([`DepthKernels`]):
//! * **Thin lens** ([`thin_lens_for_camera`]): a lens of focal length f and F-number N focused
//!   on D, the sensor at the image distance v = 1/(1/f − 1/D) (Gauss). A point at depth z
//!   images at v_z with 1/v_z = 1/f − 1/z, so the cone of half-aperture f/(2N) meets the
//!   sensor in a disc of radius c(z) = (f/(2N))·v·|1/z − 1/D| (the same law as
//!   [`ThinLensDefocus::coc_radius_px`], with v/pitch in place of H/(2 tan(θ_y/2))); its
//!   kernel is the pillbox of that radius, the same at every wavelength and field position.
//! * **Real lens** ([`LensDepthKernels`]): the geometric PSFs of a focused `camsim-lens`
//!   prescription ([`camsim_lens::FocusedLens`], focused by the camera's focus settings) at
//!   every slab's object distance, from the lens field model tabulated over object distance
//!   ([`camsim_lens::field_model::FieldModel`]), per tabulated wavelength (each band uses the
//!   nearest) and per **field node** ([`FieldNodes`]): PSFs are tabulated on a grid of nodes
//!   (positions along x × positions along y), each node's the PSF of its paraxial image
//!   position ([`camsim_lens::field_model::FieldTable::psf_at`]: the +y PSF at that height
//!   rotated to the node's azimuth), the field model being tabulated exactly at the nodes'
//!   distinct radii (no interpolation between heights), and each pixel's PSF is interpolated
//!   bilinearly between the four nodes around it (tent weights on the composited images,
//!   Nagy & O'Leary 1998). The chain's nodes are adaptive ([`ADAPTIVE_FIELD_NODES`]): a probe
//!   of the PSF's centroid and RMS widths at 33 heights out to the corner, at the slab
//!   farthest from focus, places node heights where the shape stops being linear in height
//!   ([`adaptive_node_heights_mm`]), e.g. where the double Gauss starts to vignette at f/2;
//!   uniform tile centres ([`FieldNodes::Uniform`]) are the alternative. The rotated PSF points
//!   the way the real lens's does: the radial skewness of the kernel matches the real-lens
//!   camera's PSF at 10 mm off axis to the right and downwards, where a mirrored kernel would
//!   fail (`render/tests/real_lens_crosscheck.rs`, docs/render_validation.md). Limits: between
//!   nodes the PSF is a mixture of the neighbours' (their moments interpolate; a shape change
//!   that is not captured by the centroid and RMS widths is not seen by the probe); the
//!   geometric PSF omits diffraction; the tables are refused above
//!   [`LENS_DEPTH_MEMORY_BUDGET_BYTES`]. Planar depth is taken from the lens's paraxial entrance pupil (the pinhole
//!   of the render), as by the real-lens camera ([`crate::camera::real_lens`]).
//!
//! Both give, besides the defocused planes, the blur size per pixel: the RMS radius of the PSF
//! applied to the pixel's slab (about the PSF centroid), [`kernel_rms_radius_px`].
use crate::depth_path::{
    defocus_layered_slabs, defocus_layered_with, slabs, trim_kernel, Kernel, ThinLensDefocus,
};

/// The thin-lens defocus of a camera (see the module docs): focal length `focal_length_m`,
/// F-number `f_number`, focused on `focus_distance_m` (`None` = infinity), samples of
/// `sample_pitch_m` on the sensor. Errors when the focus distance is not beyond the focal
/// length (no real image).
pub fn thin_lens_for_camera(
    focal_length_m: f64,
    f_number: f64,
    focus_distance_m: Option<f64>,
    sample_pitch_m: f64,
) -> Result<ThinLensDefocus, String> {
    let inv_d = focus_distance_m.map_or(0.0, |d| 1.0 / d);
    let inv_v = 1.0 / focal_length_m - inv_d;
    if !(focal_length_m > 0.0 && f_number > 0.0 && sample_pitch_m > 0.0 && inv_v > 0.0) {
        return Err(format!(
            "thin lens: focal length {focal_length_m} m, f/{f_number}, focus distance {:?} m and \
             sample pitch {sample_pitch_m} m must be positive, the focus beyond the focal length",
            focus_distance_m
        ));
    }
    let v = 1.0 / inv_v;
    // c = R |Δ(1/z)| · H/(2 tan(θ/2)) with H = 1 px and tan(θ/2) = pitch/(2v): H/(2tan) = v/pitch.
    Ok(ThinLensDefocus {
        aperture_radius_m: focal_length_m / (2.0 * f_number),
        focus_distance_m: focus_distance_m.unwrap_or(f64::INFINITY),
        // one sample of pitch p at image scale v (the ratio is unit-free)
        yfov_rad: pinhole_yfov_rad(v, 1, sample_pitch_m),
        height_px: 1,
    })
}

/// The vertical field of view (rad) of a pinhole image of `rows` samples of pitch
/// `sample_pitch_mm` on the sensor that covers exactly the field a lens of image-side scale
/// `image_mm_per_tan` (mm of paraxial image height per unit tan θ of the object's chief ray,
/// [`camsim_lens::LensPrescription::paraxial_image_mm_per_tan`]; a thin lens: its image
/// distance v) images onto them: the paraxial image height is H·tan θ, so
/// tan(θ_y/2) = rows·p/(2H). The depth-aware optics' PSFs, distortion (real relative to the
/// paraxial H·tan θ) and relative illumination are tabulated by sensor position, so the pinhole
/// radiance they act on must use this mapping.
pub fn pinhole_yfov_rad(image_mm_per_tan: f64, rows: usize, sample_pitch_mm: f64) -> f64 {
    2.0 * (0.5 * rows as f64 * sample_pitch_mm / image_mm_per_tan).atan()
}

/// The image scale (samples per unit tan θ) of a pinhole image of `rows` samples with vertical
/// field of view `yfov_rad`: rows/(2 tan(θ_y/2)), the inverse of [`pinhole_yfov_rad`]
/// (H/p = rows/(2 tan(θ_y/2))).
pub fn pinhole_pixels_per_tan(yfov_rad: f64, rows: usize) -> f64 {
    rows as f64 / (2.0 * (0.5 * yfov_rad).tan())
}

/// RMS radius (px) of a kernel about its centroid: √(Σ w·((x − x̄)² + (y − ȳ)²)) (for a uniform
/// disc of radius c it tends to c/√2).
pub fn kernel_rms_radius_px(k: &Kernel) -> f64 {
    let n = 2 * k.radius + 1;
    let (mut s, mut sx, mut sy) = (0.0, 0.0, 0.0);
    for (i, v) in k.values.iter().enumerate() {
        let (x, y) = ((i % n) as f64, (i / n) as f64);
        s += *v as f64;
        sx += *v as f64 * x;
        sy += *v as f64 * y;
    }
    if !(s > 0.0) {
        return 0.0;
    }
    let (mx, my) = (sx / s, sy / s);
    let m2: f64 = k
        .values
        .iter()
        .enumerate()
        .map(|(i, v)| {
            let (x, y) = ((i % n) as f64 - mx, (i / n) as f64 - my);
            *v as f64 * (x * x + y * y)
        })
        .sum();
    (m2 / s).sqrt()
}

/// Largest memory (bytes) [`LensDepthKernels::new`] may use for its PSF tables: 2 GiB. Its
/// estimate is the field model's tables (distances × field heights × wavelengths × psf_n² f64),
/// twice (the per-distance copies), plus the per-node kernels (nodes × wavelengths × distances ×
/// psf_n² f32); above it the call is refused with one line naming the sizes.
pub const LENS_DEPTH_MEMORY_BUDGET_BYTES: u64 = 2 << 30;

/// Options of [`LensDepthKernels::new`].
#[derive(Debug, Clone, PartialEq)]
pub struct LensDepthOptions {
    /// Scene sample pitch on the sensor (mm): the PSF bin size.
    pub sample_pitch_mm: f64,
    /// Image width (samples).
    pub width: usize,
    /// Image height (samples).
    pub height: usize,
    /// Tabulated wavelengths (nm); each band uses the nearest.
    pub wavelengths_nm: Vec<f64>,
    /// Pupil rays per side of the geometric PSFs.
    pub pupil_n: usize,
    /// Where in the field PSFs are tabulated (each pixel's PSF is interpolated between them).
    pub field_nodes: FieldNodes,
}

/// Where [`LensDepthKernels`] tabulates PSFs in the field: a grid of nodes (columns ×
/// rows, a tensor product of positions along x and along y); each pixel's PSF is interpolated
/// bilinearly between the four nodes around it ([`defocus_by_depth`]).
///
/// | variant | parameters | meaning |
/// |---|---|---|
/// | `Uniform(n)` | n ≥ 1 | the centres of `n × n` equal tiles (1: the axis's PSF everywhere) |
/// | `Adaptive` | `tolerance` (fraction, default 0.01), `min_step_px` (samples, default 0.02), `max_per_side` (default 15) | positions along each axis at the field heights where the PSF's shape changes ([`adaptive_node_heights_mm`]), plus the image's edges |
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FieldNodes {
    /// The centres of `n × n` equal tiles.
    Uniform(usize),
    /// Node heights placed by how fast the PSF changes with field height.
    Adaptive {
        /// Largest error of the linear interpolation of the PSF's centroid and RMS widths
        /// between neighbouring node heights, as a fraction of the RMS width.
        tolerance: f64,
        /// Error always allowed (samples), so that sharp PSFs do not need many nodes.
        min_step_px: f64,
        /// At most this many nodes per image axis (the tolerance is relaxed until it holds).
        max_per_side: usize,
    },
}

/// The default field nodes (the camera chain's): adaptive, 1 % of the RMS width + 0.02 sample,
/// at most 15 per side.
pub const ADAPTIVE_FIELD_NODES: FieldNodes = FieldNodes::Adaptive {
    tolerance: 0.01,
    min_step_px: 0.02,
    max_per_side: 15,
};

impl Default for FieldNodes {
    fn default() -> Self {
        ADAPTIVE_FIELD_NODES
    }
}

/// Pupil rays per side of the probe's PSFs (their RMS widths to about 1 %).
const PROBE_PUPIL_N: usize = 96;

/// Dense field heights of the probe of [`adaptive_node_heights_mm`] (evenly spaced from the
/// axis to the corner).
const PROBE_HEIGHTS: usize = 33;

/// Centroid and RMS widths (samples) of a PSF `n × n` on +y (field direction): (centroid y,
/// RMS width along x (tangential), RMS width along y (radial)).
pub fn psf_shape(psf: &[f64], n: usize) -> [f64; 3] {
    let (mut s, mut sx, mut sy) = (0.0, 0.0, 0.0);
    for (i, v) in psf.iter().enumerate() {
        let (x, y) = ((i % n) as f64, (i / n) as f64);
        s += v;
        sx += v * x;
        sy += v * y;
    }
    if !(s > 0.0) {
        return [0.0; 3];
    }
    let (mx, my) = (sx / s, sy / s);
    let (mut vx, mut vy) = (0.0, 0.0);
    for (i, v) in psf.iter().enumerate() {
        let (x, y) = ((i % n) as f64 - mx, (i / n) as f64 - my);
        vx += v * x * x;
        vy += v * y * y;
    }
    [my - (n / 2) as f64, (vx / s).sqrt(), (vy / s).sqrt()]
}

/// The node heights (mm, from 0) of [`FieldNodes::Adaptive`]: from the PSF shapes
/// ([`psf_shape`]: centroid and the two RMS widths) at evenly spaced heights `heights_mm`,
/// the fewest knots, chosen greedily from the axis outwards, such that the linear
/// interpolation of every shape component between neighbouring knots is within
/// `tolerance` × (the larger RMS width there) + `min_step_px` of its value at every height
/// between them (a piecewise-linear fit with adaptive knots; the largest height is always a
/// knot).
pub fn adaptive_node_heights_mm(
    heights_mm: &[f64],
    shapes: &[[f64; 3]],
    tolerance: f64,
    min_step_px: f64,
) -> Vec<f64> {
    let m = heights_mm.len().min(shapes.len());
    if m == 0 {
        return vec![0.0];
    }
    let fits = |a: usize, b: usize| {
        (a + 1..b).all(|j| {
            let t = (heights_mm[j] - heights_mm[a]) / (heights_mm[b] - heights_mm[a]);
            let allowed = tolerance * shapes[j][1].max(shapes[j][2]) + min_step_px;
            (0..3).all(|c| {
                let lerp = shapes[a][c] + t * (shapes[b][c] - shapes[a][c]);
                (lerp - shapes[j][c]).abs() <= allowed
            })
        })
    };
    let mut knots = vec![0usize];
    let mut a = 0;
    while a + 1 < m {
        let mut b = a + 1;
        while b + 1 < m && fits(a, b + 1) {
            b += 1;
        }
        knots.push(b);
        a = b;
    }
    knots.iter().map(|k| heights_mm[*k]).collect()
}

/// Node positions (samples) along an axis of `len` samples of pitch `pitch_mm`: the centre, the
/// node heights `heights_mm` on both sides, and the two edge samples; a node closer than
/// [`MIN_NODE_SPACING_PX`] to the one inside it or to the edge is dropped.
fn axis_nodes(len: usize, pitch_mm: f64, heights_mm: &[f64]) -> Vec<f64> {
    let c = (len as f64 - 1.0) / 2.0;
    let mut side: Vec<f64> = vec![0.0];
    let mut ds: Vec<f64> = heights_mm.iter().map(|h| h / pitch_mm).collect();
    ds.sort_by(|a, b| a.total_cmp(b));
    for d in ds {
        if d - side[side.len() - 1] >= MIN_NODE_SPACING_PX && c - d >= MIN_NODE_SPACING_PX {
            side.push(d);
        }
    }
    if c > 0.0 {
        side.push(c);
    }
    let mut v: Vec<f64> = side.iter().rev().map(|d| c - d).collect();
    v.extend(side.iter().skip(1).map(|d| c + d));
    v
}

/// Smallest spacing of adaptive field nodes (samples): closer nodes would cost a compositing
/// window each for a PSF change below a sample.
pub const MIN_NODE_SPACING_PX: f64 = 4.0;

/// Real-lens PSFs by field node × wavelength × object distance (see the module docs).
#[derive(Debug, Clone)]
pub struct LensDepthKernels {
    /// Node columns (sample positions along x, increasing).
    pub node_x_px: Vec<f64>,
    /// Node rows (sample positions along y, increasing).
    pub node_y_px: Vec<f64>,
    /// Tabulated wavelengths (nm, increasing).
    pub wavelengths_nm: Vec<f64>,
    /// `[node (row-major: row · columns + column)][wavelength]` → (1/z in 1/m, kernel) by
    /// increasing 1/z.
    table: Vec<Vec<Vec<(f64, Kernel)>>>,
    /// Entrance-pupil radius (m) of the lens.
    pub entrance_pupil_radius_m: f64,
}

impl LensDepthKernels {
    /// Tabulate the PSFs of `focus.lens` (as focused) at the planar inverse depths
    /// `inv_depths_per_m` (1/m from the entrance pupil, 0 = infinity; e.g.
    /// [`crate::depth_path::slab_inverse_depths`]).
    pub fn new(
        focus: &camsim_lens::FocusedLens,
        opts: &LensDepthOptions,
        inv_depths_per_m: &[f64],
    ) -> Result<Self, camsim_lens::LensError> {
        use camsim_lens::field_model::{FieldModel, FieldModelOptions, Focus, PsfKind};
        let bad = |m: String| camsim_lens::LensError::Prescription(format!("depth optics: {m}"));
        if !(opts.sample_pitch_mm > 0.0)
            || opts.wavelengths_nm.is_empty()
            || opts.width == 0
            || opts.height == 0
            || opts.field_nodes == FieldNodes::Uniform(0)
        {
            return Err(bad(
                "sample pitch > 0, an image, one field node and at least one wavelength are needed"
                    .into(),
            ));
        }
        let lens = &focus.lens;
        let fo = lens.first_order(lens.primary_nm)?;
        let z_ep_mm = fo.entrance_pupil_z_mm;
        let r_ep_mm = 0.5 * fo.entrance_pupil_diameter_mm;
        let to_vertex =
            |inv: f64| crate::depth_path::vertex_distance_mm(inv, z_ep_mm, "depth optics");
        let per_tan_mm = lens.paraxial_image_mm_per_tan(lens.primary_nm)?;
        let p = opts.sample_pitch_mm;
        let v_focus = focus.focus_distance_mm.map_or(0.0, |d| 1e3 / (d + z_ep_mm));
        let mut invs: Vec<f64> = inv_depths_per_m.iter().map(|v| v.max(0.0)).collect();
        invs.sort_by(|a, b| a.total_cmp(b));
        invs.dedup();
        if invs.is_empty() {
            invs.push(v_focus);
        }
        let max_dv = invs.iter().map(|v| (v - v_focus).abs()).fold(0.0, f64::max);
        // thin-lens disc radius (samples) + margin for aberrations (off axis too)
        let c_max =
            camsim_lens::paraxial::paraxial_blur_radius_mm(r_ep_mm, per_tan_mm, max_dv, 0.0) / p;
        let psf_n = 2 * ((1.5 * c_max + 8.0).ceil() as usize) + 1;
        let distances = invs
            .iter()
            .map(|v| to_vertex(*v))
            .collect::<Result<Vec<_>, _>>()?;
        let mut wls = opts.wavelengths_nm.clone();
        wls.sort_by(|a, b| a.total_cmp(b));
        wls.dedup();
        // node positions (samples) → paraxial image positions (mm); the field model is
        // tabulated exactly at their distinct radii, so that no node's PSF is interpolated
        // between heights
        let (node_x_px, node_y_px) = match opts.field_nodes {
            FieldNodes::Uniform(n) => {
                let centres = |len: usize| -> Vec<f64> {
                    (0..n)
                        .map(|k| {
                            let (lo, hi) = tile_span(len, n, k);
                            0.5 * (lo + hi) as f64 - 0.5
                        })
                        .collect()
                };
                (centres(opts.width), centres(opts.height))
            }
            FieldNodes::Adaptive {
                tolerance,
                min_step_px,
                max_per_side,
            } => {
                // the probe: PSF shapes at evenly spaced heights out to the corner, at the
                // slab farthest from focus (the largest blur), primary wavelength
                let corner_mm = 0.5 * p * (opts.width as f64 - 1.0).hypot(opts.height as f64 - 1.0);
                let far = invs
                    .iter()
                    .copied()
                    .max_by(|a, b| (a - v_focus).abs().total_cmp(&(b - v_focus).abs()))
                    .unwrap_or(v_focus);
                let heights: Vec<f64> = (0..PROBE_HEIGHTS)
                    .map(|k| corner_mm * k as f64 / (PROBE_HEIGHTS - 1) as f64)
                    .collect();
                let probe_bytes = (PROBE_HEIGHTS as u64)
                    .saturating_mul((psf_n as u64).saturating_pow(2))
                    .saturating_mul(16);
                if probe_bytes > LENS_DEPTH_MEMORY_BUDGET_BYTES {
                    return Err(bad(format!(
                        "the field probe would need {:.1} GiB ({PROBE_HEIGHTS} field heights × {psf_n}² samples), over the {:.0} GiB budget: use a coarser sample pitch or a smaller aperture",
                        probe_bytes as f64 / (1u64 << 30) as f64,
                        LENS_DEPTH_MEMORY_BUDGET_BYTES as f64 / (1u64 << 30) as f64
                    )));
                }
                let probe = if corner_mm > 0.0 {
                    let m = FieldModel::compute(
                        lens,
                        &FieldModelOptions {
                            n_fields: PROBE_HEIGHTS,
                            paraxial_heights_mm: Some(heights.clone()),
                            max_field_deg: None,
                            wavelengths_nm: Some(vec![lens.primary_nm]),
                            kind: PsfKind::Geometric,
                            psf_n,
                            psf_pitch_um: p * 1e3,
                            pupil_n: opts.pupil_n.max(PROBE_PUPIL_N),
                            pad: 1,
                            ri_grid_n: 2,
                            focus: Focus::Focused(Box::new(focus.clone())),
                            object_distances_mm: vec![to_vertex(far)?],
                        },
                    )?;
                    let t = m.at_distance(to_vertex(far)?);
                    heights
                        .iter()
                        .map(|h| psf_shape(&t.psf_on_y(*h, lens.primary_nm), t.psf_n))
                        .collect()
                } else {
                    vec![[0.0; 3]]
                };
                let mut tol = tolerance.max(0.0);
                let mut min_step = min_step_px.max(0.0);
                loop {
                    let knots = adaptive_node_heights_mm(&heights, &probe, tol, min_step);
                    let nodes = (
                        axis_nodes(opts.width, p, &knots),
                        axis_nodes(opts.height, p, &knots),
                    );
                    if nodes.0.len().max(nodes.1.len()) <= max_per_side.max(2) {
                        break nodes;
                    }
                    tol = (2.0 * tol).max(0.01);
                    min_step = (2.0 * min_step).max(0.05);
                }
            }
        };
        let (xc, yc) = (
            (opts.width as f64 - 1.0) / 2.0,
            (opts.height as f64 - 1.0) / 2.0,
        );
        let centres_mm: Vec<(f64, f64)> = node_y_px
            .iter()
            .flat_map(|yi| {
                node_x_px
                    .iter()
                    .map(move |xj| ((xj - xc) * p, (yi - yc) * p))
            })
            .collect();
        let single = centres_mm.len() == 1;
        let mut heights_mm: Vec<f64> = if single {
            vec![0.0]
        } else {
            centres_mm.iter().map(|(x, y)| x.hypot(*y)).collect()
        };
        heights_mm.sort_by(|a, b| a.total_cmp(b));
        heights_mm.dedup();
        let (nd, nf, nw) = (
            distances.len() as u64,
            heights_mm.len() as u64,
            wls.len() as u64,
        );
        let entry_bytes = (psf_n as u64).saturating_pow(2);
        let need = nd
            .saturating_mul(nf)
            .saturating_mul(nw)
            .saturating_mul(entry_bytes)
            .saturating_mul(16)
            .saturating_add(
                (centres_mm.len() as u64)
                    .saturating_mul(nw)
                    .saturating_mul(nd)
                    .saturating_mul(entry_bytes)
                    .saturating_mul(4),
            );
        if need > LENS_DEPTH_MEMORY_BUDGET_BYTES {
            return Err(bad(format!(
                "the PSF tables would need {:.1} GiB ({nd} distances × {nf} field heights × {nw} wavelengths × {psf_n}² samples of {:.4} mm, for up to {max_dv:.3} 1/m of defocus), over the {:.0} GiB budget: use fewer depth layers or wavelengths, a coarser sample pitch or a smaller aperture",
                need as f64 / (1u64 << 30) as f64,
                p,
                LENS_DEPTH_MEMORY_BUDGET_BYTES as f64 / (1u64 << 30) as f64
            )));
        }
        let model = FieldModel::compute(
            lens,
            &FieldModelOptions {
                n_fields: heights_mm.len(),
                paraxial_heights_mm: Some(heights_mm),
                max_field_deg: None,
                wavelengths_nm: Some(wls.clone()),
                kind: PsfKind::Geometric,
                psf_n,
                psf_pitch_um: p * 1e3,
                pupil_n: opts.pupil_n.max(8),
                pad: 1,
                ri_grid_n: 8,
                focus: Focus::Focused(Box::new(focus.clone())),
                object_distances_mm: distances.clone(),
            },
        )?;
        let tables: Vec<_> = distances.iter().map(|d| model.at_distance(*d)).collect();
        let mut table = Vec::with_capacity(centres_mm.len());
        for (x_mm, y_mm) in centres_mm {
            let per_wl = wls
                .iter()
                .map(|wl| {
                    invs.iter()
                        .zip(&tables)
                        .map(|(v, t)| {
                            let psf = if single {
                                t.psf_on_y(0.0, *wl)
                            } else {
                                t.psf_at(x_mm, y_mm, *wl)
                            };
                            (*v, trim_kernel(&psf, t.psf_n))
                        })
                        .collect::<Vec<_>>()
                })
                .collect();
            table.push(per_wl);
        }
        Ok(LensDepthKernels {
            node_x_px,
            node_y_px,
            wavelengths_nm: wls,
            table,
            entrance_pupil_radius_m: r_ep_mm * 1e-3,
        })
    }

    /// Number of field nodes (columns × rows).
    pub fn nodes(&self) -> usize {
        self.table.len()
    }

    /// The tabulated PSF of node `node` (row-major), wavelength index `wl`, nearest in 1/z to
    /// `inv_z`.
    pub fn kernel(&self, node: usize, wl: usize, inv_z: f64) -> Kernel {
        self.table[node][wl]
            .iter()
            .min_by(|a, b| (a.0 - inv_z).abs().total_cmp(&(b.0 - inv_z).abs()))
            .map(|t| t.1.clone())
            .unwrap_or_else(Kernel::delta)
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

/// Rows (or columns) `[lo, hi)` of tile `k` of `n` over `len` samples.
fn tile_span(len: usize, n: usize, k: usize) -> (usize, usize) {
    (k * len / n, (k + 1) * len / n)
}

/// The field nodes along one image axis, for PSFs interpolated between them: node `k`'s
/// weight at sample x is the tent that is 1 at its position and 0 at the neighbouring nodes, 1
/// beyond the outer nodes, so that the weights of every sample sum to 1 (bilinear
/// interpolation of the PSF between the four nodes around a pixel, applied to the composited
/// images: Nagy & O'Leary, "Restoring images degraded by spatially variant blur", SIAM J. Sci.
/// Comput. 19, 1998).
struct NodeAxis {
    len: usize,
    centres: Vec<f64>,
}

impl NodeAxis {
    /// The samples `[lo, hi)` where node `k`'s weight is positive.
    fn span(&self, k: usize) -> (usize, usize) {
        let c = &self.centres;
        let lo = if k == 0 {
            0
        } else {
            ((c[k - 1].floor() + 1.0).max(0.0) as usize).min(self.len)
        };
        let hi = if k + 1 == c.len() {
            self.len
        } else {
            (c[k + 1].ceil().max(0.0) as usize).min(self.len)
        };
        (lo.min(hi), hi)
    }

    /// Node `k`'s weight at sample `x`.
    fn weight(&self, k: usize, x: usize) -> f64 {
        let (c, n, x) = (&self.centres, self.centres.len(), x as f64);
        if x <= c[k] {
            if k == 0 {
                1.0
            } else {
                ((x - c[k - 1]) / (c[k] - c[k - 1])).clamp(0.0, 1.0)
            }
        } else if k + 1 == n {
            1.0
        } else {
            ((c[k + 1] - x) / (c[k + 1] - c[k])).clamp(0.0, 1.0)
        }
    }
}

/// Where the depth-dependent PSFs come from.
#[derive(Debug, Clone)]
pub enum DepthKernels {
    /// A thin lens: pillbox of the circle of confusion ([`thin_lens_for_camera`]).
    Thin(ThinLensDefocus),
    /// A real lens's PSFs by field node × wavelength × distance.
    Lens(LensDepthKernels),
}

/// Result of [`defocus_by_depth`].
#[derive(Debug, Clone)]
pub struct DepthDefocused {
    /// The defocused planes (same order as the input bands).
    pub planes: Vec<Vec<f32>>,
    /// PSF RMS radius (samples) applied to each pixel's depth slab (for a lens: at the
    /// tabulated wavelength nearest 550 nm).
    pub blur_rms_radius_px: Vec<f32>,
}

/// Defocus `planes` (`w × h`, wavelength `band_wavelengths_nm[b]` each) with planar depth
/// `depth_m` (∞ or ≤ 0 = escaped) by depth-layered compositing over `layers` slabs
/// ([`crate::depth_path::defocus_layered`]) with the PSFs of `kernels`: for a lens, per field
/// node (the pixels of the node's interpolation weight plus a margin of the largest kernel
/// radius are composited, and added with that weight: the PSF interpolated between the nodes,
/// tent weights) and per group of bands sharing a tabulated wavelength. The background is continued under blurred foreground edges
/// ([`defocus_layered_with`], `continue_background`).
pub fn defocus_by_depth(
    planes: &[Vec<f32>],
    band_wavelengths_nm: &[f64],
    depth_m: &[f32],
    w: usize,
    h: usize,
    layers: usize,
    kernels: &DepthKernels,
) -> DepthDefocused {
    let layers = layers.max(1);
    match kernels {
        DepthKernels::Thin(t) => {
            let out = defocus_layered_with(planes, depth_m, w, h, layers, true, |iz| t.kernel(iz));
            let sl = slabs(depth_m, layers);
            let rms: Vec<f32> = sl
                .mean_inv_z
                .iter()
                .map(|m| m.map_or(0.0, |v| kernel_rms_radius_px(&t.kernel(v)) as f32))
                .collect();
            DepthDefocused {
                planes: out,
                blur_rms_radius_px: sl.index.iter().map(|k| rms[*k]).collect(),
            }
        }
        DepthKernels::Lens(lk) => {
            let mut out = vec![vec![0f32; w * h]; planes.len()];
            let mut rms_map = vec![0f32; w * h];
            let groups: Vec<usize> = band_wavelengths_nm
                .iter()
                .map(|wl| lk.nearest_wavelength(*wl))
                .collect();
            let wl_ref = lk.nearest_wavelength(550.0);
            // the whole image's slabs: every node composites its window with them (slabs of
            // a window's own depth range would split one plane by its f32 depth jitter where no
            // other depth is in the window)
            let whole = slabs(depth_m, layers);
            // Each pixel's PSF is interpolated between the nodes' (bilinear tent weights that
            // sum to 1): every node composites the pixels its tent covers and adds them with
            // its weight.
            let (ys, xs) = (
                NodeAxis {
                    len: h,
                    centres: lk.node_y_px.clone(),
                },
                NodeAxis {
                    len: w,
                    centres: lk.node_x_px.clone(),
                },
            );
            let nx = xs.centres.len();
            for ty in 0..ys.centres.len() {
                for tx in 0..nx {
                    let node = ty * nx + tx;
                    let (r0, r1) = ys.span(ty);
                    let (c0, c1) = xs.span(tx);
                    if r0 == r1 || c0 == c1 {
                        continue;
                    }
                    let wy: Vec<f32> = (r0..r1).map(|r| ys.weight(ty, r) as f32).collect();
                    let wx: Vec<f32> = (c0..c1).map(|c| xs.weight(tx, c) as f32).collect();
                    let margin = lk.table[node]
                        .iter()
                        .flatten()
                        .map(|(_, k)| k.radius)
                        .max()
                        .unwrap_or(0)
                        + 1;
                    let (er0, er1) = (r0.saturating_sub(margin), (r1 + margin).min(h));
                    let (ec0, ec1) = (c0.saturating_sub(margin), (c1 + margin).min(w));
                    let (cw, ch) = (ec1 - ec0, er1 - er0);
                    let crop = |p: &[f32]| -> Vec<f32> {
                        (er0..er1)
                            .flat_map(|r| p[r * w + ec0..r * w + ec1].iter().copied())
                            .collect()
                    };
                    let wslabs = whole.window(w, (er0, er1), (ec0, ec1));
                    let mut gl: Vec<usize> = groups.clone();
                    gl.sort_unstable();
                    gl.dedup();
                    for g in gl {
                        let idx: Vec<usize> =
                            (0..planes.len()).filter(|b| groups[*b] == g).collect();
                        let sub: Vec<Vec<f32>> = idx.iter().map(|b| crop(&planes[*b])).collect();
                        let res = defocus_layered_slabs(&sub, &wslabs, cw, ch, true, |iz| {
                            lk.kernel(node, g, iz)
                        });
                        for (b, pl) in idx.iter().zip(&res) {
                            for (r, wr) in (r0..r1).zip(&wy) {
                                let src = (r - er0) * cw + (c0 - ec0);
                                let dst = &mut out[*b][r * w + c0..r * w + c1];
                                for ((o, v), wc) in dst.iter_mut().zip(&pl[src..]).zip(&wx) {
                                    *o += wr * wc * v;
                                }
                            }
                        }
                    }
                    let (index, mean) = (&wslabs.index, &wslabs.mean_inv_z);
                    let rms: Vec<f32> = mean
                        .iter()
                        .map(|m| {
                            m.map_or(0.0, |v| {
                                kernel_rms_radius_px(&lk.kernel(node, wl_ref, v)) as f32
                            })
                        })
                        .collect();
                    for (r, wr) in (r0..r1).zip(&wy) {
                        for (c, wc) in (c0..c1).zip(&wx) {
                            rms_map[r * w + c] += wr * wc * rms[index[(r - er0) * cw + (c - ec0)]];
                        }
                    }
                }
            }
            DepthDefocused {
                planes: out,
                blur_rms_radius_px: rms_map,
            }
        }
    }
}
