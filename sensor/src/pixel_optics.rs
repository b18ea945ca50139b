//! Pixel optics: microlens, chief-ray angle (CRA), angular response, pixel vignetting and
//! angle-dependent optical crosstalk.
//!
//! # Model
//!
//! The geometric phase-space (ray-transfer) analysis of a pixel's optical stack of Catrysse &
//! Wandell, "Optical efficiency of image sensor pixels", *JOSA A* 19(8), 1610–1620 (2002), as
//! ISETCam's microlens toolbox computes it (`mlAnalyzeArrayEtendue`, `mlRadiance`: paraxial
//! ray-transfer matrices of the microlens and the dielectric stack, rays of the exit pupil's
//! cone at each pixel). The microlens shift that compensates the chief-ray angle follows
//! Agranov, Berezin & Tsai, "Crosstalk and microlens study in a color CMOS image sensor",
//! *IEEE Trans. Electron Devices* 50(1), 4–11 (2003).
//!
//! Coordinates: `x`, `y` in the sensor plane, `x` along the columns, `y` along the rows (down);
//! a pixel's position is its centre relative to the sensor's centre. Directions are
//! **tangent vectors** `t = (dx/dz, dy/dz)` of a ray travelling towards the sensor.
//!
//! * **The cone.** The exit pupil (a disk of radius `R` at distance `z_xp` in front of the
//!   sensor, [`ChiefRay::ExitPupil`]) seen from the image point `q` is the set of directions
//!   `t = (q − p)/z_xp`, `p` in the pupil: in tangent space a disk of centre `t_c = q / z_xp`
//!   (the chief ray) and radius `ρ = R / z_xp`. From a CRA table ([`ChiefRay::Table`]),
//!   `t_c = tan θ(|q|) q/|q|` and `ρ = 1/(2N)` (`N` the f-number). A uniform exit pupil fills
//!   the disk uniformly (paraxially: the cos⁴ weighting inside the cone is second order, and
//!   the cos⁴ fall-off across the field belongs to the optics' relative illumination).
//! * **Refraction** into the stack of index `n` (paraxial Snell): `t → t / n`.
//! * **Microlens** (thin, focal length `f` in the stack, square aperture of side `D ≤ p`,
//!   centre shifted by `m` from the pixel centre): a ray entering at `x` (relative to the
//!   microlens centre) leaves with `t' = t/n − x/f` ([`Microlens`]).
//! * **Stack** of height `h` (microlens → photodiode plane): the ray lands at
//!   `s = m + x (1 − h/f) + h t / n` relative to the pixel's photodiode centre.
//!
//! The light of the cone over the microlens lands on the Minkowski sum of the scaled microlens
//! aperture (side `|1 − h/f| D`) and the disk of radius `h ρ / n` centred at `m + h t_c / n`.
//! The fraction of the pixel's light that lands in a rectangle `S` of the photodiode plane
//! (eq. PO-1) is
//!
//! ```text
//! η(S) = (D²/p²) · (1/D²) ∫_{x ∈ aperture} |disk(m + x(1 − h/f) + h t_c/n, hρ/n) ∩ S| / (π (hρ/n)²) dx
//! ```
//!
//! with the disk–rectangle overlap area in closed form ([`disk_rect_overlap_area`]) and the
//! integral over the aperture by Gauss–Legendre quadrature (one point, exact, when the
//! photodiode lies in the microlens's focal plane `h = f`).
//!
//! * **Pixel vignetting / CRA shading**: `η` of the pixel's own photodiode (a square of side
//!   `w` centred on the pixel), a function of position through `t_c` and `m`.
//! * **Optical crosstalk**: `η` of each of the 8 neighbours' photodiodes (centred at
//!   `(±p, 0)`, `(0, ±p)`, `(±p, ±p)`); it grows as the spot walks off-centre with the CRA.
//! * **Étendue limit** (verification): on the axis with `h = f` the spot is the disk of radius
//!   `f ρ / n`, and the accepted fraction equals `min(1, G_pd / G_cone)` whenever the disk and
//!   the photodiode square nest (disk inside: 1; square inside: the ratio), where
//!   `G_pd = n² D² (w/f)²` is the étendue of the photodiode seen through the microlens and
//!   `G_cone = D² π ρ²` that of the incoming cone over the microlens ([`etendue_ratio`]); in
//!   between, étendue conservation makes the ratio an upper bound.
//! * **Microlens shift** ([`MicrolensShift`]): `m = −κ h t_c / n` (a fraction κ of the
//!   CRA-compensating shift; κ = 1 puts the spot's centre back on the photodiode's and restores
//!   the on-axis response exactly) or a linear law `m = −k q` (µm per mm of field height).
//!
//! Not modelled: diffraction at the microlens (pixels near the wavelength), wavelength
//! dependence, reflection losses, light from outside the sensor's edge (border pixels lose
//! their outward crosstalk and receive none from beyond the edge). Electrons: the light
//! filtered by pixel `i`'s colour filter that lands in pixel `j`'s photodiode counts as `j`'s
//! with `i`'s channel response (the photodiodes' own QE taken equal), as for the
//! [`crate::Crosstalk`] block.
use crate::ElectronRate;
use rayon::prelude::*;

/// Gauss–Legendre points per axis of the aperture integral when `h ≠ f`.
pub const APERTURE_QUADRATURE_POINTS: usize = 16;

/// Errors of the pixel-optics model: the field (as written under `sensor.pixel_optics`), the
/// value and what is required.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{field} = {value}: {reason}")]
pub struct PixelOpticsError {
    /// Field name, e.g. `microlens_focal_length_um`.
    pub field: String,
    /// The offending value, formatted.
    pub value: String,
    /// What is required.
    pub reason: String,
}

fn invalid(field: &str, value: impl std::fmt::Display, reason: &str) -> PixelOpticsError {
    PixelOpticsError {
        field: field.to_string(),
        value: value.to_string(),
        reason: reason.to_string(),
    }
}

/// The pixel's optical stack (all lengths µm).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Microlens {
    /// Pixel pitch `p` (µm).
    pub pitch_um: f64,
    /// Side `D` of the microlens's square aperture (µm, `0 < D ≤ p`; light on the gaps is lost).
    pub diameter_um: f64,
    /// Focal length `f` of the microlens inside the stack (µm).
    pub focal_length_um: f64,
    /// Height `h` of the stack from the microlens to the photodiode plane (µm).
    pub stack_height_um: f64,
    /// Side `w` of the square photodiode aperture (µm, `0 < w ≤ p`).
    pub photodiode_width_um: f64,
    /// Refractive index `n ≥ 1` of the stack (paraxial Snell `t → t/n`).
    pub refractive_index: f64,
}

impl Microlens {
    /// Check every field (finite, in range).
    pub fn validate(&self) -> Result<(), PixelOpticsError> {
        let pos = |name: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(invalid(name, v, "must be a positive number"))
            }
        };
        pos("pixel_pitch_um", self.pitch_um)?;
        pos("microlens_diameter_um", self.diameter_um)?;
        pos("microlens_focal_length_um", self.focal_length_um)?;
        pos("stack_height_um", self.stack_height_um)?;
        pos("photodiode_width_um", self.photodiode_width_um)?;
        if self.diameter_um > self.pitch_um * (1.0 + 1e-12) {
            return Err(invalid(
                "microlens_diameter_um",
                self.diameter_um,
                &format!("must not exceed the pixel pitch ({} µm)", self.pitch_um),
            ));
        }
        if self.photodiode_width_um > self.pitch_um * (1.0 + 1e-12) {
            return Err(invalid(
                "photodiode_width_um",
                self.photodiode_width_um,
                &format!("must not exceed the pixel pitch ({} µm)", self.pitch_um),
            ));
        }
        if !(self.refractive_index.is_finite() && self.refractive_index >= 1.0) {
            return Err(invalid(
                "refractive_index",
                self.refractive_index,
                "must be a number ≥ 1",
            ));
        }
        Ok(())
    }

    /// Fraction of the light of `cone` falling on the pixel (area `p²`) that lands in the
    /// rectangle `rect` of the photodiode plane (µm, relative to the pixel's centre), with the
    /// microlens centre shifted by `shift_um` (eq. PO-1 of the module docs). This is the
    /// angular model other pixel layouts (e.g. two photodiodes under one microlens) call with
    /// their own rectangles.
    pub fn fraction_in_rect(&self, cone: &Cone, shift_um: [f64; 2], rect: &RectUm) -> f64 {
        let (n, h, f, d) = (
            self.refractive_index,
            self.stack_height_um,
            self.focal_length_um,
            self.diameter_um,
        );
        let radius = h * cone.radius_tangent / n;
        let centre = [
            shift_um[0] + h * cone.chief_tangent[0] / n,
            shift_um[1] + h * cone.chief_tangent[1] / n,
        ];
        // Spread of the landing point per unit aperture coordinate.
        let spread = 1.0 - h / f;
        let on_rect = |cx: f64, cy: f64| -> f64 {
            if radius <= 0.0 {
                // A collimated beam: the point lands in or out.
                let inside = cx >= rect.x0 && cx < rect.x1 && cy >= rect.y0 && cy < rect.y1;
                return if inside { 1.0 } else { 0.0 };
            }
            disk_rect_overlap_area(
                radius,
                rect.x0 - cx,
                rect.x1 - cx,
                rect.y0 - cy,
                rect.y1 - cy,
            ) / (std::f64::consts::PI * radius * radius)
        };
        let aperture_fill = (d / self.pitch_um).powi(2);
        if (spread * d).abs() <= 1e-12 * d {
            return aperture_fill * on_rect(centre[0], centre[1]);
        }
        let (nodes, weights) = gauss_legendre(APERTURE_QUADRATURE_POINTS);
        let mut sum = 0.0;
        for (u, wu) in nodes.iter().zip(&weights) {
            let x = 0.5 * d * u;
            for (v, wv) in nodes.iter().zip(&weights) {
                let y = 0.5 * d * v;
                sum += wu * wv * on_rect(centre[0] + spread * x, centre[1] + spread * y);
            }
        }
        // Weights sum to 2 per axis: the mean over the aperture is sum / 4.
        aperture_fill * sum / 4.0
    }

    /// The angular response to `cone` with the microlens shifted by `shift_um`: the fraction
    /// reaching the pixel's own photodiode (pixel vignetting) and each neighbour's (optical
    /// crosstalk).
    pub fn response(&self, cone: &Cone, shift_um: [f64; 2]) -> AngularResponse {
        let (p, hw) = (self.pitch_um, 0.5 * self.photodiode_width_um);
        let mut to_pixel = [[0.0; 3]; 3];
        for (iy, row) in to_pixel.iter_mut().enumerate() {
            for (ix, v) in row.iter_mut().enumerate() {
                let (cx, cy) = ((ix as f64 - 1.0) * p, (iy as f64 - 1.0) * p);
                let rect = RectUm {
                    x0: cx - hw,
                    x1: cx + hw,
                    y0: cy - hw,
                    y1: cy + hw,
                };
                *v = self.fraction_in_rect(cone, shift_um, &rect);
            }
        }
        AngularResponse { to_pixel }
    }
}

/// A rectangle of the photodiode plane (µm, relative to the pixel's centre).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RectUm {
    /// Left edge.
    pub x0: f64,
    /// Right edge.
    pub x1: f64,
    /// Top edge.
    pub y0: f64,
    /// Bottom edge.
    pub y1: f64,
}

/// The cone of light from the exit pupil seen from one image point, in tangent space (air).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cone {
    /// Chief-ray direction tangent `(dx/dz, dy/dz)` (its CRA is `atan |t_c|`).
    pub chief_tangent: [f64; 2],
    /// Radius `ρ` of the cone's disk in tangent space (`R / z_xp`, or `1/(2N)`).
    pub radius_tangent: f64,
}

/// The fractions of a pixel's incident light reaching each photodiode of its 3 × 3
/// neighbourhood.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AngularResponse {
    /// `to_pixel[1 + dy][1 + dx]`: into the photodiode of the pixel `dy` rows down and `dx`
    /// columns right; `to_pixel[1][1]` is the pixel's own (its optical efficiency).
    pub to_pixel: [[f64; 3]; 3],
}

impl AngularResponse {
    /// The fraction reaching the pixel's own photodiode.
    pub fn accepted(&self) -> f64 {
        self.to_pixel[1][1]
    }

    /// The fraction reaching the 8 neighbours' photodiodes (optical crosstalk).
    pub fn crosstalk(&self) -> f64 {
        self.to_pixel.iter().flatten().sum::<f64>() - self.accepted()
    }
}

/// Where the chief ray and the cone at each image point come from.
#[derive(Debug, Clone, PartialEq)]
pub enum ChiefRay {
    /// A circular exit pupil of radius `radius_mm` at `distance_mm` in front of the sensor
    /// (negative: behind it, rays converge towards the axis). From a lens: its paraxial exit
    /// pupil, converted by the caller (this crate does not depend on the lens crate).
    ExitPupil {
        /// Distance sensor → exit pupil (mm, non-zero).
        distance_mm: f64,
        /// Exit-pupil radius (mm).
        radius_mm: f64,
    },
    /// A CRA table: field height (mm, increasing, first ≥ 0) → CRA (degrees, positive =
    /// travelling away from the axis), linear between entries and held beyond the ends; the
    /// cone radius `1/(2N)`.
    Table {
        /// Field heights (mm).
        field_mm: Vec<f64>,
        /// Chief-ray angles (degrees).
        cra_deg: Vec<f64>,
        /// F-number `N` of the cone.
        f_number: f64,
    },
}

impl ChiefRay {
    /// Check the fields.
    pub fn validate(&self) -> Result<(), PixelOpticsError> {
        match self {
            ChiefRay::ExitPupil {
                distance_mm,
                radius_mm,
            } => {
                if !(distance_mm.is_finite() && *distance_mm != 0.0) {
                    return Err(invalid(
                        "exit_pupil_distance_mm",
                        distance_mm,
                        "must be a finite non-zero number",
                    ));
                }
                if !(radius_mm.is_finite() && *radius_mm > 0.0) {
                    return Err(invalid(
                        "exit_pupil_radius_mm",
                        radius_mm,
                        "must be a positive number",
                    ));
                }
            }
            ChiefRay::Table {
                field_mm,
                cra_deg,
                f_number,
            } => {
                if field_mm.is_empty() || field_mm.len() != cra_deg.len() {
                    return Err(invalid(
                        "cra_table",
                        format!("{} entries", field_mm.len()),
                        "needs at least one [field_mm, cra_deg] pair",
                    ));
                }
                for (i, (h, a)) in field_mm.iter().zip(cra_deg).enumerate() {
                    let prev_ok = i == 0 || *h > field_mm[i - 1];
                    if !(h.is_finite() && *h >= 0.0 && prev_ok) {
                        return Err(invalid(
                            &format!("cra_table[{i}][0]"),
                            h,
                            "field heights must be finite, ≥ 0 and strictly increasing",
                        ));
                    }
                    if !(a.is_finite() && a.abs() < 90.0) {
                        return Err(invalid(
                            &format!("cra_table[{i}][1]"),
                            a,
                            "must be an angle in (−90, 90) degrees",
                        ));
                    }
                }
                if !(f_number.is_finite() && *f_number > 0.0) {
                    return Err(invalid("f_number", f_number, "must be a positive number"));
                }
            }
        }
        Ok(())
    }

    /// The cone at image point `(x_mm, y_mm)`.
    pub fn cone_at(&self, x_mm: f64, y_mm: f64) -> Cone {
        match self {
            ChiefRay::ExitPupil {
                distance_mm,
                radius_mm,
            } => Cone {
                chief_tangent: [x_mm / distance_mm, y_mm / distance_mm],
                radius_tangent: radius_mm / distance_mm.abs(),
            },
            ChiefRay::Table { f_number, .. } => {
                let r = x_mm.hypot(y_mm);
                let t = self.cra_deg_at(r).to_radians().tan();
                let chief_tangent = if r > 0.0 {
                    [t * x_mm / r, t * y_mm / r]
                } else {
                    [0.0, 0.0]
                };
                Cone {
                    chief_tangent,
                    radius_tangent: 0.5 / f_number,
                }
            }
        }
    }

    /// The chief-ray angle (degrees) at field height `r_mm`.
    pub fn cra_deg_at(&self, r_mm: f64) -> f64 {
        match self {
            ChiefRay::ExitPupil { distance_mm, .. } => (r_mm / distance_mm).atan().to_degrees(),
            ChiefRay::Table {
                field_mm, cra_deg, ..
            } => {
                let n = field_mm.len();
                if r_mm <= field_mm[0] {
                    return cra_deg[0];
                }
                if r_mm >= field_mm[n - 1] {
                    return cra_deg[n - 1];
                }
                let i = field_mm.partition_point(|h| *h <= r_mm);
                let (h0, h1) = (field_mm[i - 1], field_mm[i]);
                let a = (r_mm - h0) / (h1 - h0);
                cra_deg[i - 1] + a * (cra_deg[i] - cra_deg[i - 1])
            }
        }
    }
}

/// The microlens shift across the sensor (a design parameter; positive = towards the axis).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MicrolensShift {
    /// Microlenses centred on their pixels.
    None,
    /// `m = −κ h t_c / n`: the fraction κ of the shift that puts the chief ray's landing
    /// point on the photodiode's centre (κ = 1: full CRA compensation).
    Cra {
        /// κ.
        fraction: f64,
    },
    /// `m = −k q`: linear in field height, `k` µm per mm.
    Linear {
        /// `k` (µm of shift per mm of field height).
        um_per_mm: f64,
    },
}

/// A sensor's pixel optics: the stack, the chief-ray model and the microlens shift law.
#[derive(Debug, Clone, PartialEq)]
pub struct PixelOptics {
    /// The pixel's optical stack.
    pub microlens: Microlens,
    /// The cone at each image point.
    pub chief_ray: ChiefRay,
    /// The microlens shift law.
    pub shift: MicrolensShift,
}

impl PixelOptics {
    /// A validated model.
    pub fn new(
        microlens: Microlens,
        chief_ray: ChiefRay,
        shift: MicrolensShift,
    ) -> Result<Self, PixelOpticsError> {
        microlens.validate()?;
        chief_ray.validate()?;
        match shift {
            MicrolensShift::None => {}
            MicrolensShift::Cra { fraction } if fraction.is_finite() => {}
            MicrolensShift::Linear { um_per_mm } if um_per_mm.is_finite() => {}
            MicrolensShift::Cra { fraction } => {
                return Err(invalid(
                    "microlens_shift.cra_fraction",
                    fraction,
                    "must be a finite number",
                ))
            }
            MicrolensShift::Linear { um_per_mm } => {
                return Err(invalid(
                    "microlens_shift.um_per_mm",
                    um_per_mm,
                    "must be a finite number",
                ))
            }
        }
        Ok(PixelOptics {
            microlens,
            chief_ray,
            shift,
        })
    }

    /// The microlens shift (µm) at image point `(x_mm, y_mm)` with cone `cone`.
    pub fn shift_um_at(&self, x_mm: f64, y_mm: f64, cone: &Cone) -> [f64; 2] {
        let ml = &self.microlens;
        match self.shift {
            MicrolensShift::None => [0.0, 0.0],
            MicrolensShift::Cra { fraction } => {
                let k = -fraction * ml.stack_height_um / ml.refractive_index;
                [k * cone.chief_tangent[0], k * cone.chief_tangent[1]]
            }
            MicrolensShift::Linear { um_per_mm } => [-um_per_mm * x_mm, -um_per_mm * y_mm],
        }
    }

    /// The angular response of the pixel centred at image point `(x_mm, y_mm)`.
    pub fn response_at(&self, x_mm: f64, y_mm: f64) -> AngularResponse {
        let cone = self.chief_ray.cone_at(x_mm, y_mm);
        let shift = self.shift_um_at(x_mm, y_mm, &cone);
        self.microlens.response(&cone, shift)
    }

    /// The response of every pixel of a `rows × cols` sensor (pixel centres at
    /// `((c − (cols−1)/2) p, (r − (rows−1)/2) p)`): exact at each pixel when the sensor has at
    /// most [`MAP_NODES`] pixels per side, else exact on a grid of that many nodes per side
    /// and bilinear between them (the response is smooth in position).
    pub fn response_map(&self, rows: usize, cols: usize) -> ResponseMap {
        let p_mm = self.microlens.pitch_um * 1e-3;
        let axis = |n: usize| -> Vec<f64> {
            let k = n.clamp(1, MAP_NODES);
            (0..k)
                .map(|i| {
                    let idx = if k == 1 {
                        0.0
                    } else {
                        i as f64 * (n as f64 - 1.0) / (k as f64 - 1.0)
                    };
                    (idx - (n as f64 - 1.0) / 2.0) * p_mm
                })
                .collect()
        };
        let (ys, xs) = (axis(rows), axis(cols));
        let nodes: Vec<[[f32; 3]; 3]> = ys
            .par_iter()
            .flat_map_iter(|&y| {
                xs.iter()
                    .map(move |&x| {
                        let r = self.response_at(x, y).to_pixel;
                        r.map(|row| row.map(|v| v as f32))
                    })
                    .collect::<Vec<_>>()
            })
            .collect();
        ResponseMap {
            rows,
            cols,
            node_rows: ys.len(),
            node_cols: xs.len(),
            nodes,
        }
    }
}

/// Nodes per side of [`PixelOptics::response_map`].
pub const MAP_NODES: usize = 65;

/// The angular response of every pixel of a sensor, tabulated ([`PixelOptics::response_map`]).
#[derive(Debug, Clone, PartialEq)]
pub struct ResponseMap {
    /// Sensor rows.
    pub rows: usize,
    /// Sensor columns.
    pub cols: usize,
    /// Node rows (= `rows` when exact per pixel).
    pub node_rows: usize,
    /// Node columns.
    pub node_cols: usize,
    /// Row-major node responses, `to_pixel` layout of [`AngularResponse`].
    pub nodes: Vec<[[f32; 3]; 3]>,
}

impl ResponseMap {
    /// The response of pixel `(r, c)` (bilinear between nodes).
    pub fn at(&self, r: usize, c: usize) -> [[f32; 3]; 3] {
        let pos = |i: usize, n: usize, k: usize| -> (usize, usize, f32) {
            if k <= 1 || n <= 1 {
                return (0, 0, 0.0);
            }
            if k == n {
                return (i, i, 0.0);
            }
            let u = i as f64 * (k as f64 - 1.0) / (n as f64 - 1.0);
            let i0 = (u.floor() as usize).min(k - 2);
            (i0, i0 + 1, (u - i0 as f64) as f32)
        };
        let (r0, r1, a) = pos(r, self.rows, self.node_rows);
        let (c0, c1, b) = pos(c, self.cols, self.node_cols);
        let n = |rr: usize, cc: usize| &self.nodes[rr * self.node_cols + cc];
        let (q00, q01, q10, q11) = (n(r0, c0), n(r0, c1), n(r1, c0), n(r1, c1));
        let mut out = [[0f32; 3]; 3];
        for i in 0..3 {
            for j in 0..3 {
                let top = q00[i][j] + b * (q01[i][j] - q00[i][j]);
                let bot = q10[i][j] + b * (q11[i][j] - q10[i][j]);
                out[i][j] = top + a * (bot - top);
            }
        }
        out
    }

    /// The own-photodiode fraction of every pixel (the pixel-vignetting / CRA shading map),
    /// row-major.
    pub fn accepted_map(&self) -> Vec<f32> {
        (0..self.rows)
            .flat_map(|r| (0..self.cols).map(move |c| (r, c)))
            .map(|(r, c)| self.at(r, c)[1][1])
            .collect()
    }
}

/// Apply pixel optics to a mean electron rate: `rate` holds each pixel's rate as if all the
/// light on the pixel reached its photodiode; the result is
/// `out_j = Σ_{i ∈ 3×3(j)} rate_i · η_i(j − i)` (own fraction and crosstalk from the
/// neighbours; light leaving the sensor's edge is lost). Rows are computed independently and
/// summed in a fixed order: the same bits at any thread count.
pub fn apply_pixel_optics(map: &ResponseMap, rate: &mut ElectronRate) {
    assert_eq!(
        (map.rows, map.cols),
        (rate.rows, rate.cols),
        "response map of another sensor"
    );
    let (rows, cols) = (rate.rows, rate.cols);
    let src = &rate.electrons_per_s;
    let mut out = vec![0f32; rows * cols];
    out.par_chunks_mut(cols).enumerate().for_each(|(r, row)| {
        // Responses of the source rows r−1, r, r+1.
        let kernels: Vec<Option<Vec<[[f32; 3]; 3]>>> = (0..3)
            .map(|k| {
                let sr = r as isize + k as isize - 1;
                (sr >= 0 && (sr as usize) < rows)
                    .then(|| (0..cols).map(|c| map.at(sr as usize, c)).collect())
            })
            .collect();
        for (c, o) in row.iter_mut().enumerate() {
            let mut acc = 0f64;
            for (k, kr) in kernels.iter().enumerate() {
                let Some(kr) = kr else { continue };
                let sr = r + k - 1;
                // Source at row offset dy = k − 1 from r sends to offset −dy.
                let iy = 2 - k;
                for dx in -1isize..=1 {
                    let sc = c as isize + dx;
                    if sc < 0 || sc as usize >= cols {
                        continue;
                    }
                    let ix = (1 - dx) as usize;
                    acc += src[sr * cols + sc as usize] as f64 * kr[sc as usize][iy][ix] as f64;
                }
            }
            *o = acc as f32;
        }
    });
    rate.electrons_per_s = out;
}

/// `min(1, G_pd / G_cone)` with `G_pd = n² D² (w/f)²` (étendue of the photodiode seen through
/// the microlens, paraxial) and `G_cone = D² π ρ²` (étendue of a cone of tangent-space radius
/// `ρ` over the microlens): the closed-form on-axis acceptance of a focal-plane pixel when the
/// spot and the photodiode nest (Catrysse & Wandell 2002, §3; the upper bound otherwise), times
/// the microlens fill `(D/p)²`.
pub fn etendue_ratio(microlens: &Microlens, cone_radius_tangent: f64) -> f64 {
    let ml = microlens;
    let g_pd = (ml.refractive_index * ml.photodiode_width_um / ml.focal_length_um).powi(2);
    let g_cone = std::f64::consts::PI * cone_radius_tangent.powi(2);
    (ml.diameter_um / ml.pitch_um).powi(2) * (g_pd / g_cone).min(1.0)
}

/// Area of the intersection of the disk of radius `r` centred at the origin with the rectangle
/// `[x0, x1] × [y0, y1]`: `∫ |[y0, y1] ∩ [−s(x), s(x)]| dx`, `s = √(r² − x²)`, integrated
/// exactly piece by piece between the abscissae where the chord meets `y0` or `y1`
/// (antiderivative of `s`: `(x s + r² asin(x/r)) / 2`).
pub fn disk_rect_overlap_area(r: f64, x0: f64, x1: f64, y0: f64, y1: f64) -> f64 {
    if r <= 0.0 || y1 <= y0 {
        return 0.0;
    }
    let (a, b) = (x0.max(-r), x1.min(r));
    if a >= b {
        return 0.0;
    }
    let mut cuts = vec![a, b];
    for y in [y0, y1] {
        if y.abs() < r {
            let x = (r * r - y * y).sqrt();
            for xc in [-x, x] {
                if xc > a && xc < b {
                    cuts.push(xc);
                }
            }
        }
    }
    cuts.sort_by(|p, q| p.total_cmp(q));
    let big_s = |x: f64| {
        let x = x.clamp(-r, r);
        0.5 * (x * (r * r - x * x).max(0.0).sqrt() + r * r * (x / r).asin())
    };
    let mut area = 0.0;
    for w in cuts.windows(2) {
        let (u, v) = (w[0], w[1]);
        if v <= u {
            continue;
        }
        let m = 0.5 * (u + v);
        let s = (r * r - m * m).max(0.0).sqrt();
        let (hi_is_chord, lo_is_chord) = (s < y1, -s > y0);
        let (hi, lo) = (s.min(y1), (-s).max(y0));
        if hi <= lo {
            continue;
        }
        let int_s = big_s(v) - big_s(u);
        let len = v - u;
        area += match (hi_is_chord, lo_is_chord) {
            (true, true) => 2.0 * int_s,
            (true, false) => int_s - y0 * len,
            (false, true) => y1 * len + int_s,
            (false, false) => (y1 - y0) * len,
        };
    }
    area
}

/// Gauss–Legendre nodes and weights on [−1, 1], `n ≥ 2` (Newton iteration on the Legendre
/// polynomial `P_n` from the three-term recurrence; Abramowitz & Stegun 25.4.29).
fn gauss_legendre(n: usize) -> (Vec<f64>, Vec<f64>) {
    let mut x = vec![0.0; n];
    let mut w = vec![0.0; n];
    for i in 0..n {
        // Tricomi's initial guess.
        let mut z = (std::f64::consts::PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
        let mut dp = 1.0;
        for _ in 0..100 {
            let (mut p0, mut p1) = (1.0, z);
            for k in 2..=n {
                let p2 = ((2 * k - 1) as f64 * z * p1 - (k - 1) as f64 * p0) / k as f64;
                p0 = p1;
                p1 = p2;
            }
            dp = n as f64 * (z * p1 - p0) / (z * z - 1.0);
            let dz = p1 / dp;
            z -= dz;
            if dz.abs() < 1e-15 {
                break;
            }
        }
        x[i] = z;
        w[i] = 2.0 / ((1.0 - z * z) * dp * dp);
    }
    (x, w)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gauss_legendre_integrates_polynomials_exactly() {
        let (x, w) = gauss_legendre(APERTURE_QUADRATURE_POINTS);
        assert!((w.iter().sum::<f64>() - 2.0).abs() < 1e-13);
        // ∫ x^k over [−1, 1] = 2/(k+1) for even k, exact up to degree 2n − 1.
        for k in (0..2 * APERTURE_QUADRATURE_POINTS).step_by(2) {
            let q: f64 = x.iter().zip(&w).map(|(x, w)| w * x.powi(k as i32)).sum();
            assert!(
                (q - 2.0 / (k as f64 + 1.0)).abs() < 1e-12,
                "degree {k}: {q}"
            );
        }
    }

    #[test]
    fn disk_rect_overlap_known_cases() {
        let pi = std::f64::consts::PI;
        // Rectangle containing the disk: its area.
        assert!((disk_rect_overlap_area(1.0, -2.0, 2.0, -2.0, 2.0) - pi).abs() < 1e-13);
        // Half plane x > 0: half the disk; quadrant: a quarter.
        assert!((disk_rect_overlap_area(1.0, 0.0, 5.0, -5.0, 5.0) - pi / 2.0).abs() < 1e-13);
        assert!((disk_rect_overlap_area(1.0, 0.0, 5.0, 0.0, 5.0) - pi / 4.0).abs() < 1e-13);
        // Disk containing the square: the square's area.
        assert!((disk_rect_overlap_area(2.0, -1.0, 1.0, -1.0, 1.0) - 4.0).abs() < 1e-13);
        // Circular segment beyond x = d: r² acos(d/r) − d √(r² − d²).
        let (r, d) = (1.3_f64, 0.4_f64);
        let seg = r * r * (d / r).acos() - d * (r * r - d * d).sqrt();
        assert!((disk_rect_overlap_area(r, d, 9.0, -9.0, 9.0) - seg).abs() < 1e-13);
        // Disjoint.
        assert_eq!(disk_rect_overlap_area(1.0, 1.5, 2.0, -1.0, 1.0), 0.0);
    }

    #[test]
    fn cra_table_interpolates_and_holds() {
        let c = ChiefRay::Table {
            field_mm: vec![0.0, 2.0, 4.0],
            cra_deg: vec![0.0, 20.0, 30.0],
            f_number: 2.0,
        };
        c.validate().unwrap();
        assert!((c.cra_deg_at(1.0) - 10.0).abs() < 1e-12);
        assert!((c.cra_deg_at(3.0) - 25.0).abs() < 1e-12);
        assert!((c.cra_deg_at(9.0) - 30.0).abs() < 1e-12);
        let cone = c.cone_at(0.0, 3.0);
        assert!((cone.chief_tangent[1] - 25f64.to_radians().tan()).abs() < 1e-12);
        assert_eq!(cone.chief_tangent[0], 0.0);
        assert_eq!(cone.radius_tangent, 0.25);
    }

    #[test]
    fn hostile_parameters_are_refused() {
        let ml = Microlens {
            pitch_um: 1.4,
            diameter_um: 1.5,
            focal_length_um: 3.0,
            stack_height_um: 3.0,
            photodiode_width_um: 0.8,
            refractive_index: 1.5,
        };
        let e = ml.validate().unwrap_err();
        assert_eq!(e.field, "microlens_diameter_um");
        let bad = ChiefRay::Table {
            field_mm: vec![0.0, 0.0],
            cra_deg: vec![0.0, 1.0],
            f_number: 2.0,
        };
        assert_eq!(bad.validate().unwrap_err().field, "cra_table[1][0]");
    }
}
