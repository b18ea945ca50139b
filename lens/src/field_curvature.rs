//! Field curvature and astigmatism: the sagittal and tangential foci of the thin pencils about
//! the real chief ray of a field, as axial distances from the lens's image plane.
//!
//! * [`LensPrescription::field_curvature`] integrates **Coddington's equations** along the
//!   traced real chief ray (Welford, "Aberrations of Optical Systems" §10.2; Kingslake, "Lens
//!   Design Fundamentals" ch. 11): at each surface, with incidence and refraction angles I, I'
//!   between the chief ray and the surface normal and the surface's principal curvatures c_t
//!   (meridional) and c_s (azimuthal) at the hit point,
//!
//!   n' cos²I'/t' = n cos²I/t + (n' cos I' − n cos I)·c_t   (tangential),
//!   n'/s' = n/s + (n' cos I' − n cos I)·c_s                 (sagittal),
//!
//!   where t, s (t', s') are the distances along the chief ray from the hit point to the
//!   tangential and sagittal object (image) points, positive in the direction of light; between
//!   surfaces t₊ = t' − D and s₊ = s' − D with D the chief-ray path between the hit points. An
//!   object at infinity starts with n/t = n/s = 0, a finite object with t = s = −(distance from
//!   the object point to the first surface along the chief ray).
//! * [`LensPrescription::field_curvature_from_ray_pairs`] finds the same foci independently:
//!   two rays at normalised pupil offsets ±ε in the meridional (tangential) or sagittal
//!   direction about the chief ray are intersected after the last surface, and the O(ε²)
//!   aberration of the finite pencil is removed by Richardson extrapolation from ε and 2ε.
//!
//! The chief ray is aimed at the stop centre at the wavelength analysed. The result is the
//! axial (z) distance from the lens's image plane (the last thickness) to each focus; negative
//! values lie on the lens side. For a flat image plane this is what is usually plotted as
//! "field curvature"; their difference t − s is the astigmatism.
use crate::error::LensError;
use crate::prescription::LensPrescription;
use crate::trace::{intersect, normal, refract, Clipping, Ray, Vec3};

/// Sagittal and tangential foci of one field and wavelength.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FieldCurvature {
    /// Field angle (degrees, object space).
    pub field_deg: f64,
    /// Wavelength (nm).
    pub wavelength_nm: f64,
    /// Axial distance (mm) from the image plane to the sagittal focus of the chief ray.
    pub sagittal_mm: f64,
    /// Axial distance (mm) from the image plane to the tangential focus of the chief ray.
    pub tangential_mm: f64,
    /// Chief-ray height on the image plane (mm, y).
    pub chief_height_mm: f64,
}

impl FieldCurvature {
    /// Astigmatism: tangential − sagittal focus (mm).
    pub fn astigmatism_mm(&self) -> f64 {
        self.tangential_mm - self.sagittal_mm
    }
}

fn dot(a: Vec3, b: Vec3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

impl LensPrescription {
    fn chief_ray(&self, field_deg: f64, wavelength_nm: f64) -> Result<Ray, LensError> {
        let fo = self.first_order(wavelength_nm)?;
        Ok(self.aim_field(field_deg, wavelength_nm, &fo)?.ray(0.0, 0.0))
    }

    /// Sagittal and tangential foci by Coddington's equations along the real chief ray (see
    /// the module docs).
    pub fn field_curvature(
        &self,
        field_deg: f64,
        wavelength_nm: f64,
    ) -> Result<FieldCurvature, LensError> {
        let lost = |m: &str| LensError::Aiming {
            field_deg,
            msg: format!("chief ray {m} at {wavelength_nm} nm"),
        };
        if self.has_folds() {
            return Err(LensError::Prescription(
                "Coddington field curvature is not implemented for mirrors / coordinate breaks \
                 (use field_curvature_from_ray_pairs)"
                    .into(),
            ));
        }
        let mut r = self.chief_ray(field_deg, wavelength_nm)?;
        let z = self.vertex_z_mm();
        let mut n1 = 1.0;
        // Distances to the tangential and sagittal object points (∞ for a collimated pencil).
        let (mut t, mut s) = (f64::INFINITY, f64::INFINITY);
        for (j, surf) in self.surfaces.iter().enumerate() {
            let (d_mm, q) = intersect(surf, z[j], &r).ok_or_else(|| lost("misses a surface"))?;
            if j == 0 {
                if self.object_distance_mm.is_some() {
                    // The chief ray starts at the object point.
                    t = -d_mm;
                    s = -d_mm;
                }
            } else {
                t -= d_mm;
                s -= d_mm;
            }
            let n2 = surf.medium.index(wavelength_nm);
            let local = [q[0], q[1], q[2] - z[j]];
            let nrm = normal(surf, local).ok_or_else(|| lost("outside a conic"))?;
            let d2 = refract(r.direction, nrm, n1, n2).ok_or_else(|| lost("is reflected (TIR)"))?;
            let cos_i = dot(r.direction, nrm).abs();
            let cos_r = dot(d2, nrm).abs();
            let [c_t, c_s] = surf
                .principal_curvatures_per_mm(local[0].hypot(local[1]))
                .ok_or_else(|| lost("outside a conic"))?;
            let oblique_power = n2 * cos_r - n1 * cos_i;
            // Coddington (module docs); n/∞ = 0 for a collimated pencil.
            let vt = n1 * cos_i * cos_i / t + oblique_power * c_t;
            let vs = n1 / s + oblique_power * c_s;
            t = n2 * cos_r * cos_r / vt;
            s = n2 / vs;
            r = Ray {
                origin_mm: q,
                direction: d2,
                opl_mm: 0.0,
            };
            n1 = n2;
        }
        let zi = z[self.surfaces.len()];
        if r.direction[2] <= 0.0 {
            return Err(lost("does not reach the image plane"));
        }
        let dz = r.direction[2];
        let to_img = (zi - r.origin_mm[2]) / dz;
        Ok(FieldCurvature {
            field_deg,
            wavelength_nm,
            sagittal_mm: r.origin_mm[2] + s * dz - zi,
            tangential_mm: r.origin_mm[2] + t * dz - zi,
            chief_height_mm: r.origin_mm[1] + to_img * r.direction[1],
        })
    }

    /// The same foci from traced ray pairs at normalised pupil offsets ±`eps` and ±2`eps` about
    /// the chief ray, Richardson-extrapolated to zero aperture (see the module docs).
    pub fn field_curvature_from_ray_pairs(
        &self,
        field_deg: f64,
        wavelength_nm: f64,
        eps: f64,
    ) -> Result<FieldCurvature, LensError> {
        let fo = self.first_order(wavelength_nm)?;
        let aim = self.aim_field(field_deg, wavelength_nm, &fo)?;
        let zi = self.vertex_z_mm()[self.surfaces.len()];
        let tr = |px: f64, py: f64| {
            self.trace(&aim.ray(px, py), wavelength_nm, Clipping::None)
                .ok_or_else(|| LensError::Aiming {
                    field_deg,
                    msg: format!("ray at pupil ({px}, {py}) lost at {wavelength_nm} nm"),
                })
        };
        // Axial distance from the image plane at which two rays cross in the coordinate `k`
        // (1: y, tangential pair; 0: x, sagittal pair).
        let cross = |e: f64, k: usize| -> Result<f64, LensError> {
            let (a, b) = if k == 1 {
                (tr(0.0, e)?, tr(0.0, -e)?)
            } else {
                (tr(e, 0.0)?, tr(-e, 0.0)?)
            };
            let sa = a.direction[k] / a.direction[2];
            let sb = b.direction[k] / b.direction[2];
            Ok(-(a.image_mm[k] - b.image_mm[k]) / (sa - sb))
        };
        let rich = |k: usize| -> Result<f64, LensError> {
            let f1 = cross(eps, k)?;
            let f2 = cross(2.0 * eps, k)?;
            Ok((4.0 * f1 - f2) / 3.0)
        };
        let chief = tr(0.0, 0.0)?;
        debug_assert!((chief.image_mm[2] - zi).abs() < 1e-9);
        Ok(FieldCurvature {
            field_deg,
            wavelength_nm,
            sagittal_mm: rich(0)?,
            tangential_mm: rich(1)?,
            chief_height_mm: chief.image_mm[1],
        })
    }
}
