//! Mirrors and coordinate breaks in sequential tracing (folded and off-axis systems).
//!
//! Conventions are those of Zemax OpticStudio sequential mode (OpticStudio manual, "Sequential
//! surfaces: coordinate break" and "Mirrors"), which the `.zmx` reader reads unchanged:
//!
//! * A **mirror** is a surface whose material is `"mirror"` (Zemax `GLAS MIRROR`). It reflects,
//!   d' = d − 2 (d·N) N (Welford, "Aberrations of Optical Systems" §4.4, the vector law of
//!   reflection), and the medium after it is the medium before it. Coordinate axes do not turn
//!   at a mirror: light travels towards −z after it, so the thicknesses that follow are
//!   negative (and positive again after a second mirror).
//! * A **coordinate break** at surface j ([`CoordinateBreak`]) moves the local frame at the
//!   vertex of surface j: decentre by (dx, dy) along the current x, y axes, then tilt by
//!   right-handed rotations about the current x, then y, then z axes (order 0), or tilt z, y,
//!   x then decentre (order ≠ 0, the reverse, so a break followed by its reverse-order inverse
//!   undoes it). The surface itself has no optical effect; its thickness is measured along the
//!   new z axis. A plane fold mirror is: break (tilt α), flat mirror, break (tilt α), then a
//!   negative thickness.
//!
//! **Unfolded coordinates.** Paraxial optics and every result in image space use the unfolded
//! equivalent system: the propagation sign s flips at each mirror, unfolded thicknesses are
//! s·t (so [`LensPrescription::vertex_z_mm`] grows monotonically through a folded system), the
//! curvature seen by the light is s·c, and a mirror has power −2 n s c (Smith, "Modern Optical
//! Engineering" §2.6: a mirror is a refraction into index −n). Traced rays are reported in the
//! image frame: x, y along its local axes, z = (unfolded image z) + s·z_local and direction
//! (L, M, s·N), so light in image space always travels towards +z as in a refracting lens. A
//! plane mirror therefore leaves every image-space quantity of the unfolded system unchanged.
use crate::prescription::{LensPrescription, MaterialFile, Surface};
use crate::trace::{intersect, surface_step, Clipping, Ray, Vec3};
use serde::{Deserialize, Serialize};

/// A coordinate break at one surface (Zemax `TYPE COORDBRK`, `PARM 1`–`6`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CoordinateBreak {
    /// Index of the surface (0 = first surface after the object) that is the break.
    pub surface: usize,
    /// Decentre along the current x axis (mm).
    #[serde(default)]
    pub decenter_x_mm: f64,
    /// Decentre along the current y axis (mm).
    #[serde(default)]
    pub decenter_y_mm: f64,
    /// Right-handed tilt about the current x axis (degrees).
    #[serde(default)]
    pub tilt_x_deg: f64,
    /// Right-handed tilt about the (tilted) y axis (degrees).
    #[serde(default)]
    pub tilt_y_deg: f64,
    /// Right-handed tilt about the (tilted) z axis (degrees).
    #[serde(default)]
    pub tilt_z_deg: f64,
    /// Zemax order flag: false = decentre then tilt x, y, z; true = tilt z, y, x then decentre.
    #[serde(default)]
    pub tilt_first: bool,
}

/// 3×3 matrix, rows.
type Mat3 = [[f64; 3]; 3];

const IDENTITY: Mat3 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

fn mat_mul(a: &Mat3, b: &Mat3) -> Mat3 {
    let mut m = [[0.0; 3]; 3];
    for (i, row) in m.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j];
        }
    }
    m
}

fn mat_vec(a: &Mat3, v: Vec3) -> Vec3 {
    [
        a[0][0] * v[0] + a[0][1] * v[1] + a[0][2] * v[2],
        a[1][0] * v[0] + a[1][1] * v[1] + a[1][2] * v[2],
        a[2][0] * v[0] + a[2][1] * v[1] + a[2][2] * v[2],
    ]
}

fn mat_t_vec(a: &Mat3, v: Vec3) -> Vec3 {
    [
        a[0][0] * v[0] + a[1][0] * v[1] + a[2][0] * v[2],
        a[0][1] * v[0] + a[1][1] * v[1] + a[2][1] * v[2],
        a[0][2] * v[0] + a[1][2] * v[1] + a[2][2] * v[2],
    ]
}

/// Right-handed rotation by `deg` about axis `axis` (0 = x, 1 = y, 2 = z).
fn rotation(axis: usize, deg: f64) -> Mat3 {
    let (s, c) = deg.to_radians().sin_cos();
    match axis {
        0 => [[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]],
        1 => [[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]],
        _ => [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]],
    }
}

/// A local coordinate frame: global = origin + axes · local.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frame {
    /// Origin (the surface vertex) in global coordinates (mm).
    pub origin_mm: Vec3,
    /// Columns are the local x, y, z axes in global coordinates.
    axes: Mat3,
}

impl Frame {
    /// The local z axis in global coordinates.
    pub fn z_axis(&self) -> Vec3 {
        [self.axes[0][2], self.axes[1][2], self.axes[2][2]]
    }
    /// A global point in local coordinates.
    pub fn to_local(&self, p: Vec3) -> Vec3 {
        mat_t_vec(
            &self.axes,
            [
                p[0] - self.origin_mm[0],
                p[1] - self.origin_mm[1],
                p[2] - self.origin_mm[2],
            ],
        )
    }
    /// A global direction in local coordinates.
    pub fn dir_to_local(&self, d: Vec3) -> Vec3 {
        mat_t_vec(&self.axes, d)
    }
    /// A local point in global coordinates.
    pub fn to_global(&self, p: Vec3) -> Vec3 {
        let g = mat_vec(&self.axes, p);
        [
            g[0] + self.origin_mm[0],
            g[1] + self.origin_mm[1],
            g[2] + self.origin_mm[2],
        ]
    }
    /// A local direction in global coordinates.
    pub fn dir_to_global(&self, d: Vec3) -> Vec3 {
        mat_vec(&self.axes, d)
    }
}

/// The global layout of a folded system: one frame per surface, the image frame, and the
/// propagation sign after each surface.
#[derive(Debug, Clone, PartialEq)]
pub struct Layout {
    /// Frame of each surface (for a coordinate break: the frame after the break).
    pub surfaces: Vec<Frame>,
    /// Frame of the image plane.
    pub image: Frame,
    /// Propagation sign (+1 towards local +z) after each surface.
    pub sign_after: Vec<f64>,
}

/// Vector law of reflection d' = d − 2 (d·N) N (Welford §4.4), for any orientation of N.
pub fn reflect(d: Vec3, nrm: Vec3) -> Vec3 {
    let k = 2.0 * (d[0] * nrm[0] + d[1] * nrm[1] + d[2] * nrm[2]);
    [d[0] - k * nrm[0], d[1] - k * nrm[1], d[2] - k * nrm[2]]
}

impl Surface {
    /// True if the surface is a mirror (material `"mirror"`, Zemax `GLAS MIRROR`).
    pub fn is_mirror(&self) -> bool {
        matches!(&self.material, MaterialFile::Name(n) if n.eq_ignore_ascii_case("mirror"))
    }
}

impl LensPrescription {
    /// True if the lens has a mirror or a coordinate break (traced by [`crate::fold`]).
    pub fn has_folds(&self) -> bool {
        !self.coordinate_breaks.is_empty() || self.surfaces.iter().any(Surface::is_mirror)
    }

    /// The coordinate break at surface `j`, if it is one.
    pub fn coordinate_break(&self, j: usize) -> Option<&CoordinateBreak> {
        self.coordinate_breaks.iter().find(|c| c.surface == j)
    }

    /// Propagation sign after each surface: +1, flipped by every mirror (see the module docs).
    pub fn propagation_signs(&self) -> Vec<f64> {
        let mut s = 1.0;
        self.surfaces
            .iter()
            .map(|x| {
                if x.is_mirror() {
                    s = -s;
                }
                s
            })
            .collect()
    }

    /// The global frames of the surfaces and of the image (see the module docs).
    pub fn layout(&self) -> Layout {
        let mut origin = [0.0; 3];
        let mut axes = IDENTITY;
        let mut frames = Vec::with_capacity(self.surfaces.len());
        for (j, s) in self.surfaces.iter().enumerate() {
            if let Some(cb) = self.coordinate_break(j) {
                let tilt = |order: [usize; 3]| {
                    let ang = [cb.tilt_x_deg, cb.tilt_y_deg, cb.tilt_z_deg];
                    order
                        .iter()
                        .fold(IDENTITY, |m, &a| mat_mul(&m, &rotation(a, ang[a])))
                };
                let shift = |axes: &Mat3, o: Vec3| {
                    let d = mat_vec(axes, [cb.decenter_x_mm, cb.decenter_y_mm, 0.0]);
                    [o[0] + d[0], o[1] + d[1], o[2] + d[2]]
                };
                if cb.tilt_first {
                    axes = mat_mul(&axes, &tilt([2, 1, 0]));
                    origin = shift(&axes, origin);
                } else {
                    origin = shift(&axes, origin);
                    axes = mat_mul(&axes, &tilt([0, 1, 2]));
                }
            }
            let f = Frame {
                origin_mm: origin,
                axes,
            };
            frames.push(f);
            let z = f.z_axis();
            for k in 0..3 {
                origin[k] += s.thickness_mm * z[k];
            }
        }
        Layout {
            surfaces: frames,
            image: Frame {
                origin_mm: origin,
                axes,
            },
            sign_after: self.propagation_signs(),
        }
    }
}

/// Intersection in a surface's local frame (vertex at the origin) for a ray travelling either
/// way along z: a ray towards −z meets the surface z = sag(r) where the mirrored ray meets
/// z = −sag(r), i.e. the surface with c, A_i negated.
fn intersect_local(s: &Surface, p: Vec3, d: Vec3) -> Option<(f64, Vec3)> {
    if d[2] >= 0.0 {
        return intersect(
            s,
            0.0,
            &Ray {
                origin_mm: p,
                direction: d,
                opl_mm: 0.0,
            },
        );
    }
    let mut m = s.clone();
    m.curvature_per_mm = -s.curvature_per_mm;
    m.aspheric_coeffs = s.aspheric_coeffs.iter().map(|a| -a).collect();
    m.odd_aspheric_coeffs = s.odd_aspheric_coeffs.iter().map(|b| -b).collect();
    let (t, q) = intersect(
        &m,
        0.0,
        &Ray {
            origin_mm: [p[0], p[1], -p[2]],
            direction: [d[0], d[1], -d[2]],
            opl_mm: 0.0,
        },
    )?;
    Some((t, [q[0], q[1], -q[2]]))
}

/// Trace through a lens with mirrors or coordinate breaks up to surface `upto` (exclusive;
/// `surfaces.len()` = the image plane): the point there (unfolded coordinates, see the module
/// docs), direction, optical path and stop point. Same contract as the coaxial trace.
pub(crate) fn trace_folded(
    lens: &LensPrescription,
    ray: &Ray,
    wavelength_nm: f64,
    clipping: Clipping,
    upto: usize,
) -> Option<(Vec3, Vec3, f64, Vec3)> {
    let lay = lens.layout();
    let zu = lens.vertex_z_mm();
    let mut o = ray.origin_mm;
    let mut d = ray.direction;
    let mut opl = ray.opl_mm;
    let mut n_prev = 1.0;
    let mut sign = 1.0; // propagation sign before the current surface
    let mut stop_pt = [f64::NAN; 3];
    // Point in unfolded coordinates of the local point q of frame j.
    let unfold = |q: Vec3, j: usize, sign: f64| [q[0], q[1], zu[j] + sign * q[2]];
    for (j, s) in lens.surfaces.iter().enumerate().take(upto) {
        if lens.coordinate_break(j).is_some() {
            continue; // no optical effect: only the frame moves
        }
        let f = &lay.surfaces[j];
        let (p, dl) = (f.to_local(o), f.dir_to_local(d));
        let (t, q) = intersect_local(s, p, dl)?;
        opl += n_prev * t;
        let n2 = s.medium.index(wavelength_nm);
        let d2 = surface_step(s, j, t, q, dl, n_prev, n2, clipping)?;
        if j == lens.stop_index {
            stop_pt = unfold(q, j, sign);
        }
        o = f.to_global(q);
        d = f.dir_to_global(d2);
        n_prev = n2;
        if s.is_mirror() {
            sign = -sign;
        }
    }
    let ns = lens.surfaces.len();
    if upto < ns {
        let f = &lay.surfaces[upto];
        let (t, q) = intersect_local(&lens.surfaces[upto], f.to_local(o), f.dir_to_local(d))?;
        let dl = f.dir_to_local(d);
        return Some((
            unfold(q, upto, sign),
            [dl[0], dl[1], sign * dl[2]],
            opl + n_prev * t,
            stop_pt,
        ));
    }
    let f = &lay.image;
    let (p, dl) = (f.to_local(o), f.dir_to_local(d));
    if sign * dl[2] <= 0.0 {
        return None;
    }
    let t = -p[2] / dl[2];
    let q = [p[0] + t * dl[0], p[1] + t * dl[1], 0.0];
    Some((
        unfold(q, ns, sign),
        [dl[0], dl[1], sign * dl[2]],
        opl + n_prev * t,
        stop_pt,
    ))
}
