//! Real (exact) ray tracing in f64.
//!
//! * Intersection with a conic of vertex curvature c and conic constant k: the quadric
//!   c(x² + y² + (1+k)z²) − 2z = 0 solved in the numerically stable form
//!   t = C / (−b + √(b² − A C)) (Spencer & Murty, JOSA 52, 672 (1962); Welford, "Aberrations of
//!   Optical Systems" §4.3), which tends to the plane solution as c → 0.
//! * Even aspheres: Newton iteration on F(t) = z(t) − sag(r²(t)) starting from the conic hit.
//! * Refraction: Snell's law in vector form, d' = μ d + (cos θ' − μ cos θ) N with μ = n/n'
//!   (Welford §4.4); sin²θ' > 1 is total internal reflection and the ray is lost.
//! * Vignetting: optionally a ray is lost when it lands outside a surface's `semi_diameter_mm`.
//! * Optical path length is accumulated as Σ n·(geometric length).
//!
//! Every trace takes the wavelength as an argument.
use crate::error::LensError;
use crate::paraxial::FirstOrder;
use crate::prescription::{LensPrescription, Surface};

/// 3-vector.
pub type Vec3 = [f64; 3];

fn dot(a: Vec3, b: Vec3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn add(a: Vec3, b: Vec3, s: f64) -> Vec3 {
    [a[0] + s * b[0], a[1] + s * b[1], a[2] + s * b[2]]
}
fn normalize(a: Vec3) -> Vec3 {
    let l = dot(a, a).sqrt();
    [a[0] / l, a[1] / l, a[2] / l]
}

/// A ray: a point and a unit direction, in the lens frame (first vertex at z = 0).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ray {
    /// Point (mm).
    pub origin_mm: Vec3,
    /// Unit direction (direction cosines L, M, N).
    pub direction: Vec3,
    /// Optical path already accumulated at `origin_mm` (mm).
    pub opl_mm: f64,
}

/// A ray that reached the image plane.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TracedRay {
    /// Intersection with the image plane (mm).
    pub image_mm: Vec3,
    /// Unit direction in image space.
    pub direction: Vec3,
    /// Optical path length from the start wavefront to the image plane (mm).
    pub opl_mm: f64,
    /// Where the ray crossed the stop surface (mm).
    pub stop_mm: Vec3,
}

/// Whether rays are clipped at the surfaces' semi-diameters.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Clipping {
    /// No clipping (the optics_ref convention: apertures are for drawing only).
    None,
    /// Rays outside any `semi_diameter_mm` are lost (vignetting).
    SemiDiameters,
}

/// Intersection of `ray` with `surf` whose vertex is at `z_vertex`; returns the distance along
/// the ray and the point. `None` if the ray misses.
pub fn intersect(surf: &Surface, z_vertex: f64, ray: &Ray) -> Option<(f64, Vec3)> {
    let p = [
        ray.origin_mm[0],
        ray.origin_mm[1],
        ray.origin_mm[2] - z_vertex,
    ];
    let d = ray.direction;
    let c = surf.curvature_per_mm;
    let k1 = 1.0 + surf.conic;
    // A t² + 2 b t + C = 0
    let a = c * (d[0] * d[0] + d[1] * d[1] + k1 * d[2] * d[2]);
    let b = c * (p[0] * d[0] + p[1] * d[1] + k1 * p[2] * d[2]) - d[2];
    let cc = c * (p[0] * p[0] + p[1] * p[1] + k1 * p[2] * p[2]) - 2.0 * p[2];
    let disc = b * b - a * cc;
    if disc < 0.0 {
        return None;
    }
    let den = -b + disc.sqrt();
    if den == 0.0 {
        return None;
    }
    let mut t = cc / den;
    if !surf.is_conic_only() {
        // Newton on F(t) = z(t) − sag(x(t)² + y(t)²).
        let mut converged = false;
        for _ in 0..50 {
            let q = add(p, d, t);
            let r2 = q[0] * q[0] + q[1] * q[1];
            let sag = surf.sag_mm(r2)?;
            let f = q[2] - sag;
            let dsdr2 = surf.dsag_dr2(r2)?;
            let fp = d[2] - dsdr2 * 2.0 * (q[0] * d[0] + q[1] * d[1]);
            if fp.abs() < 1e-300 {
                return None;
            }
            let dt = f / fp;
            t -= dt;
            if dt.abs() < 1e-13 {
                converged = true;
                break;
            }
        }
        if !converged {
            return None;
        }
    }
    let q = add(p, d, t);
    let r2 = q[0] * q[0] + q[1] * q[1];
    surf.sag_mm(r2)?; // outside the conic's domain → miss
    Some((t, [q[0], q[1], q[2] + z_vertex]))
}

/// Unit surface normal at `point` (lens frame), oriented towards +z.
pub fn normal(surf: &Surface, point: Vec3) -> Option<Vec3> {
    let r2 = point[0] * point[0] + point[1] * point[1];
    let g = surf.dsag_dr2(r2)?;
    Some(normalize([-2.0 * point[0] * g, -2.0 * point[1] * g, 1.0]))
}

/// One surface of a sequential trace, after the intersection, in the surface's local frame
/// (vertex at the origin, axis +z; `q_local` is the hit point, `t_mm` the step length to it,
/// `d_local` the incoming direction): the aperture test, then the vector law at the surface,
/// refraction from `n1` to `n2`, or reflection at a mirror. `None` if the ray is lost: outside
/// the semi-diameter, a backwards step past the first surface (the ray crossed an element edge
/// of negative edge thickness; without clipping such rays are traced on virtually, as Optiland
/// and rayoptics do), or total internal reflection. Shared by the coaxial and the folded
/// traces (`fold.rs`).
#[allow(clippy::too_many_arguments)]
pub fn surface_step(
    s: &Surface,
    j: usize,
    t_mm: f64,
    q_local: Vec3,
    d_local: Vec3,
    n1: f64,
    n2: f64,
    clipping: Clipping,
) -> Option<Vec3> {
    if clipping == Clipping::SemiDiameters {
        if t_mm < -1e-9 && j > 0 {
            return None;
        }
        if let Some(sd) = s.semi_diameter_mm {
            if q_local[0] * q_local[0] + q_local[1] * q_local[1] > sd * sd * (1.0 + 1e-12) {
                return None;
            }
        }
    }
    let nrm = normal(s, q_local)?;
    if s.is_mirror() {
        Some(crate::fold::reflect(d_local, nrm))
    } else {
        refract(d_local, nrm, n1, n2)
    }
}

/// Refract unit direction `d` at unit normal `nrm` from index `n1` to `n2` (vector Snell law).
/// `None` on total internal reflection.
pub fn refract(d: Vec3, nrm: Vec3, n1: f64, n2: f64) -> Option<Vec3> {
    let mut nn = nrm;
    let mut cos_i = dot(d, nn);
    if cos_i < 0.0 {
        nn = [-nn[0], -nn[1], -nn[2]];
        cos_i = -cos_i;
    }
    let mu = n1 / n2;
    let sin2_t = mu * mu * (1.0 - cos_i * cos_i);
    if sin2_t > 1.0 {
        return None;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    Some(normalize(add(
        [mu * d[0], mu * d[1], mu * d[2]],
        nn,
        cos_t - mu * cos_i,
    )))
}

impl LensPrescription {
    /// Trace `ray` (in object space, n = 1, before the first surface) to the image plane at
    /// `wavelength_nm`. `None` if it misses a surface, is totally internally reflected, or
    /// (with [`Clipping::SemiDiameters`]) is vignetted.
    pub fn trace(&self, ray: &Ray, wavelength_nm: f64, clipping: Clipping) -> Option<TracedRay> {
        self.trace_to(ray, wavelength_nm, clipping, self.surfaces.len())
            .map(|(img, dir, opl, stop)| TracedRay {
                image_mm: img,
                direction: dir,
                opl_mm: opl,
                stop_mm: stop,
            })
    }

    /// Trace up to surface `upto` (exclusive; `surfaces.len()` = image plane). Returns the point
    /// on that surface (or image plane), direction before it, OPL, and stop point.
    fn trace_to(
        &self,
        ray: &Ray,
        wavelength_nm: f64,
        clipping: Clipping,
        upto: usize,
    ) -> Option<(Vec3, Vec3, f64, Vec3)> {
        if self.has_folds() {
            return crate::fold::trace_folded(self, ray, wavelength_nm, clipping, upto);
        }
        let z = self.vertex_z_mm();
        let mut r = *ray;
        let mut n_prev = 1.0;
        let mut stop_pt = [f64::NAN; 3];
        for (j, s) in self.surfaces.iter().enumerate().take(upto) {
            let (t, q) = intersect(s, z[j], &r)?;
            let opl = r.opl_mm + n_prev * t;
            let n2 = s.medium.index(wavelength_nm);
            let qv = [q[0], q[1], q[2] - z[j]];
            let d2 = surface_step(s, j, t, qv, r.direction, n_prev, n2, clipping)?;
            if j == self.stop_index {
                stop_pt = q;
            }
            r = Ray {
                origin_mm: q,
                direction: d2,
                opl_mm: opl,
            };
            n_prev = n2;
        }
        if upto < self.surfaces.len() {
            let (t, q) = intersect(&self.surfaces[upto], z[upto], &r)?;
            return Some((q, r.direction, r.opl_mm + n_prev * t, stop_pt));
        }
        // Image plane (flat, at z of the last vertex + last thickness).
        let zi = z[self.surfaces.len()];
        if r.direction[2] <= 0.0 {
            return None;
        }
        let t = (zi - r.origin_mm[2]) / r.direction[2];
        let q = add(r.origin_mm, r.direction, t);
        Some((q, r.direction, r.opl_mm + n_prev * t, stop_pt))
    }

    /// Height (x, y) at which `ray` meets the stop surface.
    pub fn trace_to_stop(&self, ray: &Ray, wavelength_nm: f64) -> Option<[f64; 2]> {
        self.trace_to(ray, wavelength_nm, Clipping::None, self.stop_index)
            .map(|(q, ..)| [q[0], q[1]])
    }
}

/// The first-order data, the ray aim and the traced chief ray of one field at one wavelength
/// ([`LensPrescription::aimed_chief_ray`]).
#[derive(Debug, Clone)]
pub struct AimedChief {
    /// Paraxial data at the wavelength.
    pub first_order: FirstOrder,
    /// The field's aim.
    pub aim: FieldAim,
    /// The chief ray traced to the image plane without clipping.
    pub chief: TracedRay,
}

impl LensPrescription {
    /// Aim field `field_deg` at `wavelength_nm` and trace its chief ray (no clipping): the start
    /// of every per-field analysis (OPD map, Huygens PSF, pupil sampling, vignetting).
    pub fn aimed_chief_ray(
        &self,
        field_deg: f64,
        wavelength_nm: f64,
    ) -> Result<AimedChief, LensError> {
        let first_order = self.first_order(wavelength_nm)?;
        let aim = self.aim_field(field_deg, wavelength_nm, &first_order)?;
        let chief = self
            .trace(&aim.ray(0.0, 0.0), wavelength_nm, Clipping::None)
            .ok_or_else(|| LensError::Aiming {
                field_deg,
                msg: "chief ray lost".into(),
            })?;
        Ok(AimedChief {
            first_order,
            aim,
            chief,
        })
    }
}

/// Where rays of one field enter: the entrance-pupil geometry plus the real-ray aim offset.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FieldAim {
    /// Field angle (degrees, object space, in the y–z plane).
    pub field_deg: f64,
    /// Paraxial entrance-pupil z (mm).
    pub entrance_pupil_z_mm: f64,
    /// Paraxial entrance-pupil radius (mm).
    pub entrance_pupil_radius_mm: f64,
    /// y offset (mm) in the entrance-pupil plane of the ray that meets the stop centre.
    pub aim_y_mm: f64,
    /// Object distance (mm from the first vertex), `None` = infinity.
    pub object_distance_mm: Option<f64>,
    /// z of the start plane for collimated beams (before every surface).
    start_z_mm: f64,
}

impl FieldAim {
    /// z of the start plane of collimated beams (mm).
    pub fn start_z_mm(&self) -> f64 {
        self.start_z_mm
    }

    /// The ray through normalised entrance-pupil coordinates (px, py) ∈ unit disc. The pupil
    /// grid is the paraxial entrance pupil shifted by the real chief-ray aim point (the
    /// rayoptics convention). For an object at infinity the start OPL is measured from the
    /// plane wavefront through the on-axis point at `start_z_mm`, so OPLs of one field are
    /// comparable.
    pub fn ray(&self, px: f64, py: f64) -> Ray {
        let r = self.entrance_pupil_radius_mm;
        let pe = [px * r, self.aim_y_mm + py * r, self.entrance_pupil_z_mm];
        let th = self.field_deg.to_radians();
        match self.object_distance_mm {
            None => {
                let d = [0.0, th.sin(), th.cos()];
                let l = (pe[2] - self.start_z_mm) / d[2];
                let o = add(pe, d, -l);
                let q = [0.0, 0.0, self.start_z_mm];
                let opl0 = dot([o[0] - q[0], o[1] - q[1], o[2] - q[2]], d);
                Ray {
                    origin_mm: o,
                    direction: d,
                    opl_mm: opl0,
                }
            }
            Some(s) => {
                let h = (s + self.entrance_pupil_z_mm) * th.tan();
                let o = [0.0, -h, -s];
                let d = normalize([pe[0] - o[0], pe[1] - o[1], pe[2] - o[2]]);
                Ray {
                    origin_mm: o,
                    direction: d,
                    opl_mm: 0.0,
                }
            }
        }
    }
}

impl LensPrescription {
    /// Aim the chief ray of `field_deg` at the centre of the stop (iterative secant search on
    /// the entrance-pupil y offset, at `wavelength_nm`, converged to 1e-9 mm at the stop).
    pub fn aim_field(
        &self,
        field_deg: f64,
        wavelength_nm: f64,
        fo: &FirstOrder,
    ) -> Result<FieldAim, LensError> {
        let max_sd = self
            .surfaces
            .iter()
            .filter_map(|s| s.semi_diameter_mm)
            .fold(fo.entrance_pupil_diameter_mm, f64::max);
        let mut aim = FieldAim {
            field_deg,
            entrance_pupil_z_mm: fo.entrance_pupil_z_mm,
            entrance_pupil_radius_mm: fo.entrance_pupil_diameter_mm / 2.0,
            aim_y_mm: 0.0,
            object_distance_mm: self.object_distance_mm,
            start_z_mm: fo.entrance_pupil_z_mm.min(0.0) - 4.0 * max_sd - 10.0,
        };
        let err = |m: &str| LensError::Aiming {
            field_deg,
            msg: m.to_string(),
        };
        let f = |a: f64| -> Option<f64> {
            let mut t = aim;
            t.aim_y_mm = a;
            self.trace_to_stop(&t.ray(0.0, 0.0), wavelength_nm)
                .map(|p| p[1])
        };
        // Paraxial start (a = 0): the secant search converges in a few steps for most lenses.
        if let Some(a) = f(0.0)
            .and_then(|f0| aim_secant(&f, 0.0, f0, 1e-3 * aim.entrance_pupil_radius_mm.max(1e-3)))
        {
            aim.aim_y_mm = a;
            return Ok(aim);
        }
        // Wide angles (fisheyes): the paraxial chief ray misses, or the secant steps leave the
        // lens. Real-ray aiming from the stop outward: continue the aim from the axis (where
        // a = 0 is exact) to the field in steps, each started from the previous solution
        // extrapolated in tan θ, with steps halved while a ray is lost.
        let th = field_deg.to_radians();
        let mut prev: (f64, f64) = (0.0, 0.0); // (tan θ, aim) of the last solved field
        let mut done = 0.0f64; // fraction of the field solved
        let mut step = 1.0 / 16.0;
        while done < 1.0 {
            let next = (done + step).min(1.0);
            let t_next = (th * next).tan();
            let mut t = aim;
            t.field_deg = field_deg * next;
            let g = |a: f64| -> Option<f64> {
                let mut u = t;
                u.aim_y_mm = a;
                self.trace_to_stop(&u.ray(0.0, 0.0), wavelength_nm)
                    .map(|p| p[1])
            };
            let guess = if prev.0 != 0.0 {
                prev.1 * t_next / prev.0
            } else {
                0.0
            };
            let solved = g(guess).and_then(|f0| {
                aim_secant(&g, guess, f0, 1e-3 * aim.entrance_pupil_radius_mm.max(1e-3))
            });
            match solved {
                Some(a) => {
                    prev = (t_next, a);
                    done = next;
                    step = (step * 1.5).min(0.25);
                }
                None if step > 1e-4 => step /= 2.0,
                None => {
                    return Err(err(&format!(
                        "no real chief ray through the stop centre beyond {:.3}° (of {field_deg}°)",
                        field_deg * done
                    )))
                }
            }
        }
        aim.aim_y_mm = prev.1;
        Ok(aim)
    }
}

/// Secant search for the root of `f` (stop height of the chief ray as a function of the aim
/// offset), from `a0` (with `f(a0) = f0`) and `a0 + da`, to |f| < 1e-9 mm; a step whose ray is
/// lost is halved back towards the last good point. `None` if it does not converge in 60 steps.
fn aim_secant(f: &dyn Fn(f64) -> Option<f64>, a0: f64, f0: f64, da: f64) -> Option<f64> {
    secant_root(f, a0, f0, da, 1e-9)
}

/// Secant search for a root of `f` from `a0` (with `f(a0) = f0`) and `a0 + da`, to
/// |f| < `tol`; a step where `f` is undefined (a lost ray) is halved back towards the last good
/// point. `None` if it does not converge in 60 steps. The one root finder of the ray-aiming
/// searches (the chief ray from the object side here, from the sensor in [`crate::pupil`]).
pub(crate) fn secant_root(
    f: &dyn Fn(f64) -> Option<f64>,
    a0: f64,
    f0: f64,
    da: f64,
    tol: f64,
) -> Option<f64> {
    if f0.abs() < tol {
        return Some(a0);
    }
    let (mut a0, mut f0) = (a0, f0);
    let mut a1 = a0 + da;
    let mut f1 = f(a1)?;
    for _ in 0..60 {
        if f1.abs() < tol {
            return Some(a1);
        }
        if (f1 - f0).abs() < 1e-300 {
            return None;
        }
        let mut a2 = a1 - f1 * (a1 - a0) / (f1 - f0);
        let mut f2 = f(a2);
        let mut halvings = 0;
        while f2.is_none() && halvings < 30 {
            a2 = 0.5 * (a1 + a2);
            f2 = f(a2);
            halvings += 1;
        }
        let f2 = f2?;
        a0 = a1;
        f0 = f1;
        a1 = a2;
        f1 = f2;
    }
    (f1.abs() < tol).then_some(a1)
}
