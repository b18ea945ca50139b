//! Scene targets and their spectral radiance.
//!
//! Geometry follows ../spec/capture-format.md: a target **fills the sensor exactly**, scene
//! coordinates are image-plane coordinates with x to the right and y down from the sensor
//! centre, and outside the sensor the target continues (so blur near the border is defined).
//! A target is rendered on a [`SamplingGrid`] of square cells centred on the optical axis;
//! each cell holds the exact area average of the target over the cell where that is
//! available in closed form (patches, edges, lines, ramps), otherwise a 4×4 supersample; or,
//! with [`SampleAperture::CubicBSpline`] (uniform, dark, patches, edges, points and grid
//! lines), the target exactly filtered by the cubic B-spline of the cell pitch.
use crate::colorimetry::luminance_weight_for_photons;
use crate::constants::PhysicalConstants;
use crate::error::CoreError;
use crate::image::{SceneRadiance, SpectralBasis, SpectralImage};
use crate::sample_aperture::{half_plane_weight, interval_weight, periodic_weight, SampleAperture};
use crate::spectrum::Spectrum;
use rayon::prelude::*;
use std::ops::Range;

/// Where a target is sampled: `rows × cols` square cells of side `pitch_m`, centred on the
/// optical axis, for a sensor of `sensor_width_m × sensor_height_m` (the target's extent).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SamplingGrid {
    /// Cell rows.
    pub rows: usize,
    /// Cell columns.
    pub cols: usize,
    /// Cell side (m).
    pub pitch_m: f64,
    /// Width of the area the target fills (the sensor), m.
    pub sensor_width_m: f64,
    /// Height of the area the target fills (the sensor), m.
    pub sensor_height_m: f64,
    /// What a sample stands for ([`SampleAperture`]); targets without a closed form for the
    /// B-spline ([`rendered_aperture`]) are rendered as cell averages whatever it says.
    pub aperture: SampleAperture,
}

impl SamplingGrid {
    /// A grid for a sensor of `rows × cols` pixels of pitch `pixel_pitch_m`, with `oversample`
    /// cells per pixel side and `margin_px` extra pixels of scene on every side.
    pub fn for_sensor(
        rows: usize,
        cols: usize,
        pixel_pitch_m: f64,
        oversample: usize,
        margin_px: usize,
    ) -> Self {
        let os = oversample.max(1);
        SamplingGrid {
            rows: (rows + 2 * margin_px) * os,
            cols: (cols + 2 * margin_px) * os,
            pitch_m: pixel_pitch_m / os as f64,
            sensor_width_m: cols as f64 * pixel_pitch_m,
            sensor_height_m: rows as f64 * pixel_pitch_m,
            aperture: SampleAperture::Cell,
        }
    }

    /// The same grid with samples of `aperture`.
    pub fn with_aperture(self, aperture: SampleAperture) -> Self {
        SamplingGrid { aperture, ..self }
    }

    /// x (m) of the left edge of column `c`.
    fn x0(&self, c: usize) -> f64 {
        (c as f64 - self.cols as f64 / 2.0) * self.pitch_m
    }
    /// y (m) of the top edge of row `r`.
    fn y0(&self, r: usize) -> f64 {
        (r as f64 - self.rows as f64 / 2.0) * self.pitch_m
    }
}

/// A test target with its spectra in photon units (photons/(s·sr·m²·nm)).
#[derive(Debug, Clone, PartialEq)]
pub enum Target {
    /// No light.
    Dark,
    /// One spectrum everywhere.
    Uniform {
        /// radiance
        radiance: Spectrum,
    },
    /// A `rows × cols` chart tiling the sensor (spec `patches`).
    Patches {
        /// chart rows
        rows: usize,
        /// chart columns
        cols: usize,
        /// side of a patch as a fraction of its cell's side
        patch_fraction: f64,
        /// radiance between patches
        background: Spectrum,
        /// rows·cols radiances, row-major
        patches: Vec<Spectrum>,
    },
    /// Two half-planes; the light side is x·cos a + y·sin a > 0 (spec `slanted_edge`).
    SlantedEdge {
        /// dark side radiance
        dark: Spectrum,
        /// light side radiance
        light: Spectrum,
        /// edge angle (degrees), clockwise as displayed
        angle_deg: f64,
    },
    /// A band cube resampled to fill the sensor (spec `image`); borders repeat outside.
    Image {
        /// the radiance cube (any basis), its own rows × cols
        radiance: SpectralImage,
    },
    /// Horizontal intensity ramp from `min` at the left edge to `max` at the right edge.
    Ramp {
        /// spectrum at intensity 1
        radiance: Spectrum,
        /// intensity at the left edge
        min: f64,
        /// intensity at the right edge
        max: f64,
    },
    /// Sinusoidal grating whose frequency grows linearly from 0 at the left edge to
    /// `max_cycles_per_pixel` at the right edge: 0.5 (1 + contrast cos φ(x)).
    FrequencySweep {
        /// spectrum at intensity 1
        radiance: Spectrum,
        /// highest frequency at the right edge (cycles per pixel; 0.5 = Nyquist)
        max_cycles_per_pixel: f64,
        /// pixel pitch (m) the frequency refers to
        pixel_pitch_m: f64,
        /// Michelson contrast
        contrast: f64,
    },
    /// Square points of side `point_size_m` on a regular grid of spacing `spacing_m`, the
    /// central point on the optical axis.
    PointArray {
        /// point radiance
        radiance: Spectrum,
        /// background radiance
        background: Spectrum,
        /// point spacing (m)
        spacing_m: f64,
        /// point side (m)
        point_size_m: f64,
    },
    /// Horizontal and vertical lines of width `line_width_m` every `spacing_m`, one pair
    /// through the optical axis.
    GridLines {
        /// line radiance
        radiance: Spectrum,
        /// background radiance
        background: Spectrum,
        /// line spacing (m)
        spacing_m: f64,
        /// line width (m)
        line_width_m: f64,
    },
    /// A scene the pipeline renders itself (a glTF scene path-traced on the sampling grid,
    /// with depth): [`render_target`] refuses it; the pipeline's shot scene renders it.
    Rendered {
        /// What is rendered (for messages), e.g. the scene file.
        description: String,
    },
}

/// Length of the overlap of [a0, a1] and [b0, b1].
fn overlap(a0: f64, a1: f64, b0: f64, b1: f64) -> f64 {
    (a1.min(b1) - a0.max(b0)).max(0.0)
}

/// Fraction of each cell along one axis covered by the union of intervals `k·spacing + [lo, hi]`.
fn periodic_coverage(c0: f64, c1: f64, spacing: f64, lo: f64, hi: f64) -> f64 {
    let k0 = ((c0 - hi) / spacing).floor() as i64;
    let k1 = ((c1 - lo) / spacing).ceil() as i64;
    let mut s = 0.0;
    for k in k0..=k1 {
        let o = k as f64 * spacing;
        s += overlap(c0, c1, o + lo, o + hi);
    }
    (s / (c1 - c0)).min(1.0)
}

/// [`periodic_coverage`] of the intervals `k·spacing + [−half, half]` for the cell `[c0, c1]`
/// under `ap` (pitch `d`).
fn periodic_cover(ap: SampleAperture, d: f64, c0: f64, c1: f64, spacing: f64, half: f64) -> f64 {
    match ap {
        SampleAperture::Cell => periodic_coverage(c0, c1, spacing, -half, half),
        _ => {
            let c = 0.5 * (c0 + c1);
            // shift the pattern so that the period containing the centre is k = 0
            let k = (c / spacing).round();
            let off = c - k * spacing;
            periodic_weight(ap, spacing / d, (-half - off) / d, (half - off) / d)
        }
    }
}

/// Area of the part of the axis-aligned square [x0,x1]×[y0,y1] where n·p > 0
/// (Sutherland–Hodgman clip of the square by the half-plane, then the shoelace formula).
fn half_plane_area(x0: f64, x1: f64, y0: f64, y1: f64, nx: f64, ny: f64) -> f64 {
    let poly = [(x0, y0), (x1, y0), (x1, y1), (x0, y1)];
    let mut out: Vec<(f64, f64)> = Vec::with_capacity(6);
    for i in 0..4 {
        let p = poly[i];
        let q = poly[(i + 1) % 4];
        let dp = nx * p.0 + ny * p.1;
        let dq = nx * q.0 + ny * q.1;
        if dp > 0.0 {
            out.push(p);
        }
        if (dp > 0.0) != (dq > 0.0) {
            let t = dp / (dp - dq);
            out.push((p.0 + t * (q.0 - p.0), p.1 + t * (q.1 - p.1)));
        }
    }
    let n = out.len();
    if n < 3 {
        return 0.0;
    }
    let mut a = 0.0;
    for i in 0..n {
        let (xa, ya) = out[i];
        let (xb, yb) = out[(i + 1) % n];
        a += xa * yb - xb * ya;
    }
    0.5 * a.abs()
}

/// `wx(x_c) · wy(y_r)` at every sample of the grid rows `rows` (x_c, y_r: the sample
/// centres).
fn separable_plane(
    g: &SamplingGrid,
    rows: Range<usize>,
    wx: impl Fn(f64) -> f64,
    wy: impl Fn(f64) -> f64,
) -> Vec<f32> {
    let cx: Vec<f64> = (0..g.cols)
        .map(|c| wx(0.5 * (g.x0(c) + g.x0(c + 1))))
        .collect();
    let ry: Vec<f64> = rows
        .clone()
        .map(|r| wy(0.5 * (g.y0(r) + g.y0(r + 1))))
        .collect();
    let mut p = vec![0f32; rows.len() * g.cols];
    p.par_chunks_mut(g.cols)
        .zip(ry.par_iter())
        .for_each(|(row, &y)| {
            for (v, &x) in row.iter_mut().zip(&cx) {
                *v = (x * y) as f32;
            }
        });
    p
}

/// `f(x0, x1, y0, y1)` of every cell of the grid rows `rows` (the cell's edges).
fn plane_from_fn(
    g: &SamplingGrid,
    rows: Range<usize>,
    f: impl Fn(f64, f64, f64, f64) -> f32 + Sync,
) -> Vec<f32> {
    let mut p = vec![0f32; rows.len() * g.cols];
    p.par_chunks_mut(g.cols).enumerate().for_each(|(i, row)| {
        let r = rows.start + i;
        let (y0, y1) = (g.y0(r), g.y0(r + 1));
        for (c, v) in row.iter_mut().enumerate() {
            *v = f(g.x0(c), g.x0(c + 1), y0, y1);
        }
    });
    p
}

/// The aperture `render_target` gives `target`'s samples on `g`: the grid's, for targets
/// with a closed form under it (dark, uniform, patches, slanted edge, point array, grid
/// lines), else [`SampleAperture::Cell`].
pub fn rendered_aperture(target: &Target, g: &SamplingGrid) -> SampleAperture {
    match target {
        Target::Dark
        | Target::Uniform { .. }
        | Target::Patches { .. }
        | Target::SlantedEdge { .. }
        | Target::PointArray { .. }
        | Target::GridLines { .. } => g.aperture,
        _ => SampleAperture::Cell,
    }
}

/// Render a target on a sampling grid as a spectral image (photons/(s·sr·m²·nm)); samples
/// stand for [`rendered_aperture`].
pub fn render_target(target: &Target, g: &SamplingGrid) -> Result<SpectralImage, CoreError> {
    render_target_rows(target, g, 0..g.rows)
}

/// The grid rows `row_range` of [`render_target`] by themselves (a row window of the grid:
/// the same samples, bit for bit, as those rows of the whole render, each sample being a
/// function of its own cell alone), without rendering the rest. Refused when `row_range`
/// leaves the grid.
pub fn render_target_rows(
    target: &Target,
    g: &SamplingGrid,
    row_range: Range<usize>,
) -> Result<SpectralImage, CoreError> {
    if row_range.start > row_range.end || row_range.end > g.rows {
        return Err(CoreError::Target(format!(
            "row window {}..{} of a {}-row sampling grid",
            row_range.start, row_range.end, g.rows
        )));
    }
    let (w, h) = (g.sensor_width_m, g.sensor_height_m);
    let ap = rendered_aperture(target, g);
    let d = g.pitch_m;
    let nr = row_range.len();
    let n = nr * g.cols;
    let single = |s: &Spectrum, plane: Vec<f32>| {
        SpectralImage::from_single_spectrum(nr, g.cols, s.clone(), plane)
    };
    Ok(match target {
        Target::Rendered { description } => {
            return Err(CoreError::Target(format!(
                "{description} is a rendered scene: it is path-traced by the pipeline, not \
                 sampled as a target"
            )))
        }
        Target::Dark => single(&Spectrum::constant(0.0), vec![0.0; n]),
        Target::Uniform { radiance } => single(radiance, vec![1.0; n]),
        Target::Patches {
            rows,
            cols,
            patch_fraction,
            background,
            patches,
        } => {
            if patches.len() != rows * cols {
                return Err(CoreError::Target(format!(
                    "patches lists {} spectra, rows·cols = {}",
                    patches.len(),
                    rows * cols
                )));
            }
            let (cw, ch) = (w / *cols as f64, h / *rows as f64);
            let (pw, ph) = (cw * patch_fraction, ch * patch_fraction);
            let mut planes = Vec::with_capacity(patches.len() + 1);
            let mut bg = vec![1f32; n];
            for pr in 0..*rows {
                for pc in 0..*cols {
                    let cx = -w / 2.0 + (pc as f64 + 0.5) * cw;
                    let cy = -h / 2.0 + (pr as f64 + 0.5) * ch;
                    let (px0, px1, py0, py1) =
                        (cx - pw / 2.0, cx + pw / 2.0, cy - ph / 2.0, cy + ph / 2.0);
                    let a = g.pitch_m * g.pitch_m;
                    let plane = match ap {
                        SampleAperture::Cell => {
                            plane_from_fn(g, row_range.clone(), |x0, x1, y0, y1| {
                                (overlap(x0, x1, px0, px1) * overlap(y0, y1, py0, py1) / a) as f32
                            })
                        }
                        // Separable: one weight per column and one per row.
                        _ => separable_plane(
                            g,
                            row_range.clone(),
                            |xc| interval_weight(ap, (px0 - xc) / d, (px1 - xc) / d),
                            |yc| interval_weight(ap, (py0 - yc) / d, (py1 - yc) / d),
                        ),
                    };
                    bg.iter_mut().zip(&plane).for_each(|(b, p)| *b -= p);
                    planes.push(plane);
                }
            }
            bg.iter_mut().for_each(|b| *b = b.max(0.0));
            let mut basis = patches.clone();
            basis.push(background.clone());
            planes.push(bg);
            SpectralImage::new(nr, g.cols, SpectralBasis::Spectra(basis), planes)?
        }
        Target::SlantedEdge {
            dark,
            light,
            angle_deg,
        } => {
            let a = angle_deg.to_radians();
            let (nx, ny) = (a.cos(), a.sin());
            let area = g.pitch_m * g.pitch_m;
            let lightp = plane_from_fn(g, row_range.clone(), |x0, x1, y0, y1| match ap {
                SampleAperture::Cell => {
                    (half_plane_area(x0, x1, y0, y1, nx, ny) / area).clamp(0.0, 1.0) as f32
                }
                _ => {
                    let (xc, yc) = (0.5 * (x0 + x1), 0.5 * (y0 + y1));
                    half_plane_weight(ap, nx, ny, -(nx * xc + ny * yc) / d) as f32
                }
            });
            let darkp = lightp.iter().map(|v| 1.0 - v).collect();
            SpectralImage::new(
                nr,
                g.cols,
                SpectralBasis::Spectra(vec![dark.clone(), light.clone()]),
                vec![darkp, lightp],
            )?
        }
        Target::Image { radiance } => resample_image(radiance, g, row_range.clone()),
        Target::Ramp { radiance, min, max } => {
            let plane = plane_from_fn(g, row_range.clone(), |x0, x1, _, _| {
                // exact cell average of the clamped linear ramp (piecewise linear in x)
                let f = |x: f64| {
                    let t = ((x + w / 2.0) / w).clamp(0.0, 1.0);
                    min + (max - min) * t
                };
                let m = 8;
                (0..m)
                    .map(|k| f(x0 + (x1 - x0) * (k as f64 + 0.5) / m as f64))
                    .sum::<f64>() as f32
                    / m as f32
            });
            single(radiance, plane)
        }
        Target::FrequencySweep {
            radiance,
            max_cycles_per_pixel,
            pixel_pitch_m,
            contrast,
        } => {
            // φ(x) = π f_max u² / p · W with u ∈ [0,1] across the sensor: local frequency
            // f(u) = f_max·u cycles/pixel.
            let fmax = max_cycles_per_pixel / pixel_pitch_m; // cycles per m at the right edge
            let plane = plane_from_fn(g, row_range.clone(), |x0, x1, _, _| {
                let m = 4;
                (0..m)
                    .map(|k| {
                        let x = x0 + (x1 - x0) * (k as f64 + 0.5) / m as f64;
                        let s = (x + w / 2.0).clamp(0.0, w);
                        let phase = std::f64::consts::PI * fmax * s * s / w;
                        0.5 * (1.0 + contrast * (2.0 * phase).cos())
                    })
                    .sum::<f64>() as f32
                    / m as f32
            });
            single(radiance, plane)
        }
        Target::PointArray {
            radiance,
            background,
            spacing_m,
            point_size_m,
        } => {
            let (s, half) = (*spacing_m, point_size_m / 2.0);
            let pts = plane_from_fn(g, row_range.clone(), |x0, x1, y0, y1| {
                (periodic_cover(ap, d, x0, x1, s, half) * periodic_cover(ap, d, y0, y1, s, half))
                    as f32
            });
            let bg = pts.iter().map(|v| 1.0 - v).collect();
            SpectralImage::new(
                nr,
                g.cols,
                SpectralBasis::Spectra(vec![radiance.clone(), background.clone()]),
                vec![pts, bg],
            )?
        }
        Target::GridLines {
            radiance,
            background,
            spacing_m,
            line_width_m,
        } => {
            let (s, half) = (*spacing_m, line_width_m / 2.0);
            let lines = plane_from_fn(g, row_range.clone(), |x0, x1, y0, y1| {
                let cx = periodic_cover(ap, d, x0, x1, s, half);
                let cy = periodic_cover(ap, d, y0, y1, s, half);
                (1.0 - (1.0 - cx) * (1.0 - cy)) as f32
            });
            let bg = lines.iter().map(|v| 1.0 - v).collect();
            SpectralImage::new(
                nr,
                g.cols,
                SpectralBasis::Spectra(vec![radiance.clone(), background.clone()]),
                vec![lines, bg],
            )?
        }
    })
}

/// The basis of `target`'s render ([`render_target_rows`]): its plane k multiplies basis
/// term k. Refused for a [`Target::Rendered`] scene, which is not sampled as a target.
pub fn target_basis(target: &Target) -> Result<SpectralBasis, CoreError> {
    let spectra =
        |v: &[&Spectrum]| SpectralBasis::Spectra(v.iter().map(|s| (*s).clone()).collect());
    Ok(match target {
        Target::Rendered { description } => {
            return Err(CoreError::Target(format!(
                "{description} is a rendered scene: it has no basis before it is path-traced"
            )))
        }
        Target::Dark => SpectralBasis::Spectra(vec![Spectrum::constant(0.0)]),
        Target::Uniform { radiance }
        | Target::Ramp { radiance, .. }
        | Target::FrequencySweep { radiance, .. } => spectra(&[radiance]),
        Target::Patches {
            background,
            patches,
            ..
        } => {
            let mut basis = patches.clone();
            basis.push(background.clone());
            SpectralBasis::Spectra(basis)
        }
        Target::SlantedEdge { dark, light, .. } => spectra(&[dark, light]),
        Target::Image { radiance } => radiance.basis.clone(),
        Target::PointArray {
            radiance,
            background,
            ..
        }
        | Target::GridLines {
            radiance,
            background,
            ..
        } => spectra(&[radiance, background]),
    })
}

/// What [`render_target_projected_rows`] renders: output plane `j` is
/// `Σ_k weights[j][k] · (term_scale · plane_k)`, `plane_k` the render's plane of basis term k
/// ([`target_basis`]), e.g. one row of weights per sensor channel (`∫ QE_c(λ) B_k(λ) dλ`) or
/// the luminance weights.
#[derive(Debug, Clone, PartialEq)]
pub struct PlaneProjection {
    /// One row per output plane, one weight per basis term of the target.
    pub weights: Vec<Vec<f64>>,
    /// Factor applied to every term sample first, in f32 as [`SpectralImage::scale`] does
    /// (a luminance scaling of the scene; 1 for none).
    pub term_scale: f64,
}

/// Samples per row strip of the projected render of targets without a sparse form
/// ([`render_target_projected_rows`]; times the target's basis terms × 4 bytes).
pub const PROJECTION_STRIP_SAMPLES: usize = 1 << 16;

/// The grid rows `row_range` of [`render_target_rows`] projected onto `proj`'s output planes
/// ([`PlaneProjection`]) without the basis-term planes: bit for bit
/// [`SpectralImage::combine`] of each row of weights on the render's rows after
/// [`SpectralImage::scale`]`(term_scale)`. A chart's patch planes are separable boxes, so
/// per cell only the patches that overlap it are evaluated (the others are 0 there and add
/// nothing: the sum runs over the terms in the same order); other targets are rendered by
/// strips of about [`PROJECTION_STRIP_SAMPLES`] samples and combined. Refused when a row of
/// weights does not have one weight per basis term, or as [`render_target_rows`] refuses.
pub fn render_target_projected_rows(
    target: &Target,
    g: &SamplingGrid,
    row_range: Range<usize>,
    proj: &PlaneProjection,
) -> Result<Vec<Vec<f32>>, CoreError> {
    check_projection(&target_basis(target)?, proj)?;
    if row_range.start > row_range.end || row_range.end > g.rows {
        return Err(CoreError::Target(format!(
            "row window {}..{} of a {}-row sampling grid",
            row_range.start, row_range.end, g.rows
        )));
    }
    match target {
        Target::Patches {
            rows,
            cols,
            patch_fraction,
            patches,
            ..
        } if patches.len() == rows * cols => Ok(patches_projected(
            g,
            row_range,
            (*rows, *cols),
            *patch_fraction,
            proj,
        )),
        _ => project_by_strips(row_range, g.cols, proj, |r| {
            render_target_rows(target, g, r)
        }),
    }
}

/// Refuses a projection without one weight per term of `basis` in every row.
pub fn check_projection(basis: &SpectralBasis, proj: &PlaneProjection) -> Result<(), CoreError> {
    let k = basis.len();
    match proj.weights.iter().position(|w| w.len() != k) {
        Some(j) => Err(CoreError::Target(format!(
            "projection row {j} has {} weights for {k} basis terms",
            proj.weights[j].len()
        ))),
        None => Ok(()),
    }
}

/// [`PlaneProjection`] of the rows `row_range` of a render given by `render` (a row window of
/// it, the same samples as the whole render's rows), rendered by strips of about
/// [`PROJECTION_STRIP_SAMPLES`] samples: per strip the render scaled
/// ([`SpectralImage::scale`]) and combined ([`SpectralImage::combine`]).
pub fn project_by_strips(
    row_range: Range<usize>,
    cols: usize,
    proj: &PlaneProjection,
    mut render: impl FnMut(Range<usize>) -> Result<SpectralImage, CoreError>,
) -> Result<Vec<Vec<f32>>, CoreError> {
    let nr = row_range.len();
    let mut out: Vec<Vec<f32>> = proj.weights.iter().map(|_| vec![0f32; nr * cols]).collect();
    let strip = (PROJECTION_STRIP_SAMPLES / cols.max(1)).max(1);
    let mut r0 = row_range.start;
    while r0 < row_range.end {
        let r1 = (r0 + strip).min(row_range.end);
        let mut img = render(r0..r1)?;
        check_projection(&img.basis, proj)?;
        img.scale(proj.term_scale);
        let at = (r0 - row_range.start) * cols;
        for (o, w) in out.iter_mut().zip(&proj.weights) {
            o[at..at + (r1 - r0) * cols].copy_from_slice(&img.combine(w));
        }
        r0 = r1;
    }
    Ok(out)
}

/// The sparse projected render of a `rows × cols` chart ([`render_target_projected_rows`]):
/// the same per-axis patch factors as [`render_target_rows`]' patch planes (cell overlaps,
/// or the aperture's interval weights at the sample centres), kept where nonzero.
fn patches_projected(
    g: &SamplingGrid,
    row_range: Range<usize>,
    (prows, pcols): (usize, usize),
    patch_fraction: f64,
    proj: &PlaneProjection,
) -> Vec<Vec<f32>> {
    let (w, h) = (g.sensor_width_m, g.sensor_height_m);
    let ap = g.aperture;
    let d = g.pitch_m;
    let a = g.pitch_m * g.pitch_m;
    let (cw, ch) = (w / pcols as f64, h / prows as f64);
    let (pw, ph) = (cw * patch_fraction, ch * patch_fraction);
    // the factor of one axis for the cell [c0, c1] and the patch [p0, p1]
    let factor = |c0: f64, c1: f64, p0: f64, p1: f64| match ap {
        SampleAperture::Cell => overlap(c0, c1, p0, p1),
        _ => {
            let cc = 0.5 * (c0 + c1);
            interval_weight(ap, (p0 - cc) / d, (p1 - cc) / d)
        }
    };
    let xs: Vec<(f64, f64)> = (0..pcols)
        .map(|pc| {
            let cx = -w / 2.0 + (pc as f64 + 0.5) * cw;
            (cx - pw / 2.0, cx + pw / 2.0)
        })
        .collect();
    let ys: Vec<(f64, f64)> = (0..prows)
        .map(|pr| {
            let cy = -h / 2.0 + (pr as f64 + 0.5) * ch;
            (cy - ph / 2.0, cy + ph / 2.0)
        })
        .collect();
    let nonzero = |c0: f64, c1: f64, spans: &[(f64, f64)]| -> Vec<(usize, f64)> {
        spans
            .iter()
            .enumerate()
            .map(|(i, &(p0, p1))| (i, factor(c0, c1, p0, p1)))
            .filter(|(_, f)| *f != 0.0)
            .collect()
    };
    let by_col: Vec<Vec<(usize, f64)>> = (0..g.cols)
        .map(|c| nonzero(g.x0(c), g.x0(c + 1), &xs))
        .collect();
    // a patch's sample: its planes' `(ox·oy/a) as f32` or `(wx·wy) as f32`
    let value = |fx: f64, fy: f64| match ap {
        SampleAperture::Cell => (fx * fy / a) as f32,
        _ => (fx * fy) as f32,
    };
    let nr = row_range.len();
    let cols = g.cols;
    let nj = proj.weights.len();
    let mut out: Vec<Vec<f32>> = (0..nj).map(|_| vec![0f32; nr * cols]).collect();
    if nr == 0 || cols == 0 {
        return out;
    }
    let mut dst_rows: Vec<Vec<&mut [f32]>> = (0..nr).map(|_| Vec::with_capacity(nj)).collect();
    for o in out.iter_mut() {
        for (i, chunk) in o.chunks_mut(cols).enumerate() {
            dst_rows[i].push(chunk);
        }
    }
    let s = proj.term_scale as f32;
    let bg_k = prows * pcols;
    dst_rows
        .into_par_iter()
        .enumerate()
        .for_each(|(i, mut dst)| {
            let r = row_range.start + i;
            let by_row = nonzero(g.y0(r), g.y0(r + 1), &ys);
            let mut acc = vec![0f64; nj];
            for (c, xl) in by_col.iter().enumerate() {
                acc.iter_mut().for_each(|v| *v = 0.0);
                // the background plane: 1 minus the patches (in term order), at least 0
                let mut bg = 1f32;
                for &(pr, fy) in &by_row {
                    for &(pc, fx) in xl {
                        let v = value(fx, fy);
                        bg -= v;
                        let vs = (v * s) as f64;
                        let k = pr * pcols + pc;
                        for (a, wj) in acc.iter_mut().zip(&proj.weights) {
                            if wj[k] != 0.0 {
                                *a += wj[k] * vs;
                            }
                        }
                    }
                }
                let bgs = (bg.max(0.0) * s) as f64;
                for ((a, wj), o) in acc.iter_mut().zip(&proj.weights).zip(dst.iter_mut()) {
                    if wj[bg_k] != 0.0 {
                        *a += wj[bg_k] * bgs;
                    }
                    o[c] = *a as f32;
                }
            }
        });
    out
}

/// Bilinear resampling of an image so that it fills the sensor; outside, the border repeats.
/// (Grid rows `rows` only.)
fn resample_image(src: &SpectralImage, g: &SamplingGrid, rows: Range<usize>) -> SpectralImage {
    let (w, h) = (g.sensor_width_m, g.sensor_height_m);
    let (sr, sc) = (src.rows as f64, src.cols as f64);
    let planes = src
        .planes
        .par_iter()
        .map(|p| {
            let mut out = vec![0f32; rows.len() * g.cols];
            for (i, r) in rows.clone().enumerate() {
                let y = (g.y0(r) + 0.5 * g.pitch_m + h / 2.0) / h * sr - 0.5;
                let y = y.clamp(0.0, sr - 1.0);
                let (yi, fy) = (y.floor() as usize, (y - y.floor()) as f32);
                let yj = (yi + 1).min(src.rows - 1);
                for c in 0..g.cols {
                    let x = (g.x0(c) + 0.5 * g.pitch_m + w / 2.0) / w * sc - 0.5;
                    let x = x.clamp(0.0, sc - 1.0);
                    let (xi, fx) = (x.floor() as usize, (x - x.floor()) as f32);
                    let xj = (xi + 1).min(src.cols - 1);
                    let a = p[yi * src.cols + xi] * (1.0 - fx) + p[yi * src.cols + xj] * fx;
                    let b = p[yj * src.cols + xi] * (1.0 - fx) + p[yj * src.cols + xj] * fx;
                    out[i * g.cols + c] = a * (1.0 - fy) + b * fy;
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

/// Mean luminance (cd/m²) of the scene over the cells whose centres lie inside a
/// `width_m × height_m` window centred on the axis (the whole image if None).
pub fn mean_luminance(
    scene: &SceneRadiance,
    window_m: Option<(f64, f64)>,
    c: &PhysicalConstants,
) -> f64 {
    let img = &scene.radiance;
    let mut sum = LuminanceSum::default();
    sum.add_rows(img, 0, img.rows, scene.sample_pitch_m, window_m, c);
    sum.mean()
}

/// [`mean_luminance`] accumulated over row strips of a scene, in the order of the whole
/// scene's sum (rows top to bottom, then columns), so that the strips of a scene rendered by
/// row windows ([`render_target_rows`]) give the whole scene's mean bit for bit without the
/// whole scene in memory.
#[derive(Debug, Clone, Copy, Default)]
pub struct LuminanceSum {
    /// Sum of the luminance (cd/m²) of the cells counted.
    pub sum_cd_m2: f64,
    /// Cells counted.
    pub cells: usize,
}

impl LuminanceSum {
    /// Add the cells of `strip`, the rows `row0..row0 + strip.rows` of a scene of `full_rows`
    /// rows and sample pitch `pitch_m`, whose centres lie inside `window_m` (see
    /// [`mean_luminance`]).
    pub fn add_rows(
        &mut self,
        strip: &SpectralImage,
        row0: usize,
        full_rows: usize,
        pitch_m: f64,
        window_m: Option<(f64, f64)>,
        c: &PhysicalConstants,
    ) {
        let lum = strip.integrate_against(&luminance_weight_for_photons(c));
        self.add_luminance_rows(&lum, strip.cols, row0, full_rows, pitch_m, window_m);
    }

    /// [`LuminanceSum::add_rows`] of a strip's luminance plane (cd/m², `cols` wide): the
    /// strip's [`SpectralImage::integrate_against`] the luminance weights
    /// ([`luminance_weight_for_photons`]), or the same plane from
    /// [`render_target_projected_rows`] with those weights.
    pub fn add_luminance_rows(
        &mut self,
        lum: &[f32],
        cols: usize,
        row0: usize,
        full_rows: usize,
        pitch_m: f64,
        window_m: Option<(f64, f64)>,
    ) {
        let p = pitch_m;
        let rows = if cols == 0 { 0 } else { lum.len() / cols };
        // The window test per cell, |x| ≤ W/2 and |y| ≤ H/2 at the cell centre, evaluated once
        // per column and once per row: the cells counted and their order (rows top to bottom,
        // then columns) are those of the test at every cell, so the sum has the same bits.
        let inside_col: Vec<bool> = (0..cols)
            .map(|col| {
                let x = (col as f64 + 0.5 - cols as f64 / 2.0) * p;
                window_m.is_none_or(|(ww, _)| x.abs() <= ww / 2.0)
            })
            .collect();
        // (the columns inside a window centred on the axis are one run)
        let first = inside_col.iter().position(|&b| b).unwrap_or(cols);
        let last = inside_col.iter().rposition(|&b| b).map_or(first, |l| l + 1);
        let run_is_whole = inside_col[first..last].iter().all(|&b| b);
        let (mut s, mut n) = (self.sum_cd_m2, self.cells);
        for i in 0..rows {
            let r = row0 + i;
            let y = (r as f64 + 0.5 - full_rows as f64 / 2.0) * p;
            if window_m.is_some_and(|(_, hh)| y.abs() > hh / 2.0) {
                continue;
            }
            let row = &lum[i * cols..(i + 1) * cols];
            if run_is_whole {
                for &v in &row[first..last] {
                    s += v as f64;
                }
                n += last - first;
            } else {
                for (&v, _) in row.iter().zip(&inside_col).filter(|(_, &b)| b) {
                    s += v as f64;
                    n += 1;
                }
            }
        }
        self.sum_cd_m2 = s;
        self.cells = n;
    }

    /// The mean (0 when no cell was counted).
    pub fn mean(&self) -> f64 {
        if self.cells == 0 {
            0.0
        } else {
            self.sum_cd_m2 / self.cells as f64
        }
    }
}

/// Scale the scene so its mean luminance (over `window_m`) is `target_cd_m2`; returns the
/// factor applied. A black scene is left unchanged.
pub fn scale_to_mean_luminance(
    scene: &mut SceneRadiance,
    target_cd_m2: f64,
    window_m: Option<(f64, f64)>,
    c: &PhysicalConstants,
) -> f64 {
    let now = mean_luminance(scene, window_m, c);
    if now <= 0.0 {
        return 1.0;
    }
    let k = target_cd_m2 / now;
    scene.scale(k);
    k
}

/// Blackbody spectral radiance (W/(sr·m²·nm)) at temperature `kelvin`, sampled at 1 nm over
/// `[lo_nm, hi_nm]`: Planck's law L = c1 / (π λ⁵ (exp(c2/(λT)) − 1)) · 1e-9 with
/// c1 = 2πhc², c2 = hc/k.
pub fn blackbody_energy(kelvin: f64, lo_nm: f64, hi_nm: f64, c1: f64, c2: f64) -> Spectrum {
    let n = (hi_nm - lo_nm).round().max(1.0) as usize;
    let w: Vec<f64> = (0..=n)
        .map(|i| lo_nm + (hi_nm - lo_nm) * i as f64 / n as f64)
        .collect();
    let v = w
        .iter()
        .map(|&nm| blackbody_value(kelvin, nm, c1, c2))
        .collect();
    Spectrum::Sampled {
        wavelength_nm: w,
        values: v,
    }
}

/// One value of [`blackbody_energy`].
pub fn blackbody_value(kelvin: f64, nm: f64, c1: f64, c2: f64) -> f64 {
    let l = nm * 1e-9;
    c1 / (l.powi(5) * ((c2 / (l * kelvin)).exp() - 1.0)) * 1e-9 / std::f64::consts::PI
}

/// Planck radiation constants (c1 = 2πhc² W·m², c2 = hc/k m·K), CODATA 2018.
pub const PLANCK_C1: f64 = 3.741_771_852e-16;
/// Second radiation constant (m·K).
pub const PLANCK_C2: f64 = 1.438_776_877e-2;

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use approx::assert_relative_eq;

    /// [`LuminanceSum::add_luminance_rows`] counts the cells whose centres lie in the window
    /// and adds them rows top to bottom, then columns, bit for bit as the test at every cell
    /// does: strips of a scene, windows narrower and wider than it, one cell wide, none.
    #[test]
    fn luminance_sum_adds_the_window_cells_in_order() {
        let (rows, cols, p) = (11usize, 13usize, 1e-6);
        let lum: Vec<f32> = (0..rows * cols)
            .map(|i| ((i as u32).wrapping_mul(2_654_435_761) % 10_007) as f32 * 0.013 + 0.1)
            .collect();
        let per_cell = |window: Option<(f64, f64)>| {
            let (mut s, mut n) = (0.0f64, 0usize);
            for r in 0..rows {
                let y = (r as f64 + 0.5 - rows as f64 / 2.0) * p;
                for c in 0..cols {
                    let x = (c as f64 + 0.5 - cols as f64 / 2.0) * p;
                    if let Some((ww, hh)) = window {
                        if x.abs() > ww / 2.0 || y.abs() > hh / 2.0 {
                            continue;
                        }
                    }
                    s += lum[r * cols + c] as f64;
                    n += 1;
                }
            }
            (s, n)
        };
        for window in [
            None,
            Some((7e-6, 5e-6)),
            Some((13e-6, 11e-6)),
            Some((40e-6, 3e-6)),
            Some((1e-6, 40e-6)),
            Some((0.2e-6, 0.2e-6)),
        ] {
            let mut sum = LuminanceSum::default();
            for (r0, r1) in [(0, 4), (4, 5), (5, 11)] {
                sum.add_luminance_rows(&lum[r0 * cols..r1 * cols], cols, r0, rows, p, window);
            }
            let (s, n) = per_cell(window);
            assert_eq!(
                (sum.sum_cd_m2.to_bits(), sum.cells),
                (s.to_bits(), n),
                "{window:?}"
            );
        }
    }

    #[test]
    fn half_plane_area_is_exact() {
        // vertical edge through the middle of a unit square
        assert_relative_eq!(
            half_plane_area(-0.5, 0.5, -0.5, 0.5, 1.0, 0.0),
            0.5,
            epsilon = 1e-12
        );
        // 45° diagonal through the centre: half
        let a = std::f64::consts::FRAC_1_SQRT_2;
        assert_relative_eq!(
            half_plane_area(-0.5, 0.5, -0.5, 0.5, a, a),
            0.5,
            epsilon = 1e-12
        );
        // x + y > 0 over [-0.25, 0.75]²: all but the corner triangle of legs 0.5 → 1 - 0.125
        let tri = half_plane_area(-0.25, 0.75, -0.25, 0.75, a, a);
        assert_relative_eq!(tri, 0.875, epsilon = 1e-12);
        assert_relative_eq!(
            half_plane_area(0.0, 1.0, 0.0, 1.0, 1.0, 0.0),
            1.0,
            epsilon = 1e-12
        );
    }

    #[test]
    fn patches_cover_cells_exactly() {
        let g = SamplingGrid::for_sensor(40, 60, 1e-6, 1, 0);
        let t = Target::Patches {
            rows: 4,
            cols: 6,
            patch_fraction: 0.5,
            background: Spectrum::constant(0.0),
            patches: (0..24).map(|i| Spectrum::constant(i as f64)).collect(),
        };
        let img = render_target(&t, &g).unwrap();
        // each patch covers 5×5 = 25 px² of its 10×10 cell
        for k in 0..24 {
            let s: f32 = img.planes[k].iter().sum();
            assert_relative_eq!(s, 25.0, epsilon = 1e-4);
        }
        // partition of unity
        for i in 0..g.rows * g.cols {
            let s: f32 = img.planes.iter().map(|p| p[i]).sum();
            assert_relative_eq!(s, 1.0, epsilon = 1e-5);
        }
    }

    #[test]
    fn slanted_edge_orientation_matches_spec() {
        // at 0°, light on the right; at +10°, the top leans right: at the top row the edge is
        // at x > 0 ... light side x cos a + y sin a > 0, y negative at the top → x > -y tan a
        let g = SamplingGrid::for_sensor(20, 20, 1e-6, 1, 0);
        let light = Spectrum::constant(1.0);
        let dark = Spectrum::constant(0.0);
        let img = render_target(
            &Target::SlantedEdge {
                dark: dark.clone(),
                light: light.clone(),
                angle_deg: 0.0,
            },
            &g,
        )
        .unwrap();
        assert_eq!(img.planes[1][5 * 20 + 15], 1.0);
        assert_eq!(img.planes[1][5 * 20 + 4], 0.0);
        let img = render_target(
            &Target::SlantedEdge {
                dark,
                light,
                angle_deg: 10.0,
            },
            &g,
        )
        .unwrap();
        let first_light = |r: usize| {
            (0..20)
                .position(|c| img.planes[1][r * 20 + c] > 0.5)
                .unwrap()
        };
        assert!(first_light(0) > first_light(19), "top of edge leans right");
    }

    /// Every kind of target, rendered by row windows of a grid with a margin, gives the rows
    /// of the whole render bit for bit, and the strips' [`LuminanceSum`] the whole scene's
    /// [`mean_luminance`] bit for bit (the diagnosis renders 12 MP scenes by bands this way).
    #[test]
    fn row_windows_are_the_whole_render_rows() {
        let s = |v: f64| Spectrum::Affine {
            offset: v,
            slope_per_nm: 1e-3,
        };
        let targets = every_kind_of_target();
        let window = Some((14e-6, 9e-6));
        for ap in [SampleAperture::Cell, SampleAperture::CubicBSpline] {
            // 9 × 14 pixels, 2 px margin, 2× oversampling: 26 × 36 cells
            let g = SamplingGrid::for_sensor(9, 14, 1e-6, 2, 2).with_aperture(ap);
            for t in &targets {
                let whole = render_target(t, &g).unwrap();
                let mut lum = LuminanceSum::default();
                let scene_of = |radiance: SpectralImage| SceneRadiance {
                    radiance,
                    sample_pitch_m: g.pitch_m,
                    object_distance_m: None,
                    illuminant: None,
                    depth_m: None,
                    sample_aperture: ap,
                };
                for (r0, r1) in [(0, 3), (3, 11), (11, 12), (12, 26)] {
                    let w = render_target_rows(t, &g, r0..r1).unwrap();
                    assert_eq!((w.rows, w.cols), (r1 - r0, g.cols));
                    assert_eq!(w.planes.len(), whole.planes.len());
                    for (a, b) in w.planes.iter().zip(&whole.planes) {
                        let crop = &b[r0 * g.cols..r1 * g.cols];
                        assert!(
                            a.iter().zip(crop).all(|(x, y)| x.to_bits() == y.to_bits()),
                            "{t:?} {ap:?} rows {r0}..{r1}"
                        );
                    }
                    lum.add_rows(&w, r0, g.rows, g.pitch_m, window, &crate::constants::SI);
                }
                let m = mean_luminance(&scene_of(whole), window, &crate::constants::SI);
                assert_eq!(lum.mean().to_bits(), m.to_bits(), "{t:?} {ap:?}");
            }
            // where the window lies, absolutely: a horizontal edge (light below the axis)
            // turns light at the grid's middle row, 13 of 26 (cell averages)
            let g = g.with_aperture(SampleAperture::Cell);
            let edge = Target::SlantedEdge {
                dark: s(0.0),
                light: s(1.0),
                angle_deg: 90.0,
            };
            let w = render_target_rows(&edge, &g, 12..14).unwrap();
            let light = &w.planes[1];
            assert!(light[..g.cols].iter().all(|v| *v < 1e-6));
            assert!(light[g.cols..].iter().all(|v| *v > 1.0 - 1e-6));
            let uniform = &targets[1];
            assert!(render_target_rows(uniform, &g, 20..27).is_err());
            assert_eq!(render_target_rows(uniform, &g, 3..3).unwrap().rows, 0);
        }
    }

    /// One target of every kind (the picture has 1 term, the others their own bases).
    pub(crate) fn every_kind_of_target() -> Vec<Target> {
        let s = |v: f64| Spectrum::Affine {
            offset: v,
            slope_per_nm: 1e-3,
        };
        let picture = SpectralImage::from_single_spectrum(
            5,
            7,
            s(1.0),
            (0..35).map(|i| (i % 11) as f32 * 0.3).collect(),
        );
        vec![
            Target::Dark,
            Target::Uniform { radiance: s(2.0) },
            Target::Patches {
                rows: 3,
                cols: 4,
                patch_fraction: 0.7,
                background: s(0.2),
                patches: (0..12).map(|i| s(i as f64)).collect(),
            },
            // patches smaller than a cell apart: cells overlap several patches
            Target::Patches {
                rows: 6,
                cols: 9,
                patch_fraction: 0.9,
                background: s(0.3),
                patches: (0..54).map(|i| s(0.1 * i as f64)).collect(),
            },
            Target::SlantedEdge {
                dark: s(0.1),
                light: s(1.0),
                angle_deg: 5.0,
            },
            Target::Image { radiance: picture },
            Target::Ramp {
                radiance: s(1.0),
                min: 0.1,
                max: 0.9,
            },
            Target::FrequencySweep {
                radiance: s(1.0),
                max_cycles_per_pixel: 0.4,
                pixel_pitch_m: 1e-6,
                contrast: 0.8,
            },
            Target::PointArray {
                radiance: s(1.0),
                background: s(0.1),
                spacing_m: 5e-6,
                point_size_m: 1.5e-6,
            },
            Target::GridLines {
                radiance: s(1.0),
                background: s(0.1),
                spacing_m: 6e-6,
                line_width_m: 1e-6,
            },
        ]
    }

    /// Weights of `outputs` projections of `terms` basis terms: some 0, some negative.
    pub(crate) fn test_projection(
        outputs: usize,
        terms: usize,
        term_scale: f64,
    ) -> PlaneProjection {
        PlaneProjection {
            weights: (0..outputs)
                .map(|j| {
                    (0..terms)
                        .map(|k| match (k + 2 * j) % 5 {
                            0 => 0.0,
                            m => (m as f64 * 0.37 - 0.6) * (1.0 + 0.01 * k as f64),
                        })
                        .collect()
                })
                .collect(),
            term_scale,
        }
    }

    /// The projected render of every kind of target (the charts by their sparse form, the
    /// rest by strips) is bit for bit the combination of the scaled term render, on row
    /// windows too, for both sample apertures and for cells smaller and larger than the gaps
    /// between a chart's patches; and the basis it takes is the render's.
    #[test]
    fn projected_render_is_the_combined_term_render() {
        for ap in [SampleAperture::Cell, SampleAperture::CubicBSpline] {
            for os in [1, 2] {
                let g = SamplingGrid::for_sensor(9, 14, 1e-6, os, 2).with_aperture(ap);
                for t in &every_kind_of_target() {
                    let basis = target_basis(t).unwrap();
                    let whole = render_target(t, &g).unwrap();
                    assert_eq!(whole.basis, basis, "{t:?}");
                    let proj = test_projection(3, basis.len(), 1.37);
                    let mut scaled = whole.clone();
                    scaled.scale(proj.term_scale);
                    let want: Vec<Vec<f32>> =
                        proj.weights.iter().map(|w| scaled.combine(w)).collect();
                    let mid = g.rows / 2;
                    for (r0, r1) in [
                        (0, g.rows),
                        (0, 3),
                        (3, mid),
                        (mid, mid + 1),
                        (mid, g.rows),
                        (4, 4),
                    ] {
                        let got = render_target_projected_rows(t, &g, r0..r1, &proj).unwrap();
                        assert_eq!(got.len(), 3);
                        for (a, b) in got.iter().zip(&want) {
                            let crop = &b[r0 * g.cols..r1 * g.cols];
                            assert_eq!(a.len(), crop.len());
                            assert!(
                                a.iter().zip(crop).all(|(x, y)| x.to_bits() == y.to_bits()),
                                "{t:?} {ap:?} os {os} rows {r0}..{r1}"
                            );
                        }
                    }
                }
            }
        }
        let g = SamplingGrid::for_sensor(9, 14, 1e-6, 1, 0);
        let chart = &every_kind_of_target()[2];
        // one weight short, a window off the grid, a rendered scene: refused
        assert!(
            render_target_projected_rows(chart, &g, 0..9, &test_projection(2, 12, 1.0)).is_err()
        );
        assert!(
            render_target_projected_rows(chart, &g, 0..10, &test_projection(2, 13, 1.0)).is_err()
        );
        let rendered = Target::Rendered {
            description: "x".into(),
        };
        assert!(target_basis(&rendered).is_err());
    }

    #[test]
    fn grid_lines_and_points_coverage() {
        let g = SamplingGrid::for_sensor(20, 20, 1e-6, 1, 0);
        let t = Target::GridLines {
            radiance: Spectrum::constant(1.0),
            background: Spectrum::constant(0.0),
            spacing_m: 10e-6,
            line_width_m: 1e-6,
        };
        let img = render_target(&t, &g).unwrap();
        // the line through the axis at x ∈ [-0.5, 0.5] µm covers half of columns 9 and 10
        assert_relative_eq!(img.planes[0][3 * 20 + 9], 0.5, epsilon = 1e-6);
        assert_relative_eq!(img.planes[0][3 * 20 + 10], 0.5, epsilon = 1e-6);
        assert_relative_eq!(img.planes[0][3 * 20 + 5], 0.0, epsilon = 1e-6);
    }
}

/// ISETCam-compatible mean luminance: the image expanded to bands on `grid`, energy per band
/// = photons·hc/λ, and 683 Σ_λ E ȳ Δλ (Riemann sum on a regular grid), averaged over pixels.
pub fn mean_luminance_riemann(
    scene: &SceneRadiance,
    grid: &crate::spectrum::WavelengthGrid,
    c: &PhysicalConstants,
) -> f64 {
    let cmf = crate::data::cie1931_xyz().expect("embedded CIE XYZ");
    let step = grid.step_nm().unwrap_or(1.0);
    let weights: Vec<f64> = grid
        .wavelength_nm
        .iter()
        .map(|&w| {
            crate::constants::LUMINOUS_EFFICACY_LM_PER_W * cmf[1].eval(w) * step
                / c.photons_per_joule(w)
        })
        .collect();
    let bands = scene.radiance.to_bands(grid);
    let lum = bands.combine(&weights);
    lum.iter().map(|v| *v as f64).sum::<f64>() / lum.len() as f64
}
