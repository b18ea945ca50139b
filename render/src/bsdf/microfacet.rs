//! GGX / Trowbridge–Reitz microfacet distribution (Walter et al., "Microfacet Models for
//! Refraction through Rough Surfaces", EGSR 2007) with separable Smith shadowing-masking and
//! sampling of the distribution of visible normals (Heitz, "Sampling the GGX Distribution of
//! Visible Normals", JCGT 7(4), 2018). Directions are in the local frame (normal = +Z).
use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// An (optionally anisotropic) GGX distribution with roughness αu, αv.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ggx {
    /// Roughness along the first tangent.
    pub alpha_u: f32,
    /// Roughness along the second tangent.
    pub alpha_v: f32,
}

impl Ggx {
    /// Isotropic distribution.
    pub fn new(alpha: f32) -> Self {
        let a = alpha.max(1e-4);
        Ggx {
            alpha_u: a,
            alpha_v: a,
        }
    }

    /// D(m): microfacet normal density (per steradian, projected: ∫ D(m) cos θm dm = 1).
    #[inline]
    pub fn d(&self, m: Vec3) -> f32 {
        if m.z <= 0.0 {
            return 0.0;
        }
        let (au, av) = (self.alpha_u, self.alpha_v);
        let x = m.x / au;
        let y = m.y / av;
        let t = x * x + y * y + m.z * m.z;
        1.0 / (PI * au * av * t * t)
    }

    /// Smith G1(v, m) for GGX: 2 / (1 + √(1 + α²tan²θ)), 0 when v sees the back of m.
    #[inline]
    pub fn g1(&self, v: Vec3, m: Vec3) -> f32 {
        if v.dot(m) * v.z <= 0.0 {
            return 0.0;
        }
        let z2 = v.z * v.z;
        if z2 <= 0.0 {
            return 0.0;
        }
        let a2tan2 = (self.alpha_u * self.alpha_u * v.x * v.x
            + self.alpha_v * self.alpha_v * v.y * v.y)
            / z2;
        2.0 / (1.0 + (1.0 + a2tan2).sqrt())
    }

    /// Separable shadowing-masking G(wi, wo, m) = G1(wi, m) G1(wo, m).
    #[inline]
    pub fn g(&self, wi: Vec3, wo: Vec3, m: Vec3) -> f32 {
        self.g1(wi, m) * self.g1(wo, m)
    }

    /// Density of visible normals D_wi(m) = G1(wi, m) max(0, wi·m) D(m) / cos θi (wi.z > 0).
    #[inline]
    pub fn pdf_visible(&self, wi: Vec3, m: Vec3) -> f32 {
        if wi.z <= 0.0 {
            return 0.0;
        }
        self.g1(wi, m) * wi.dot(m).max(0.0) * self.d(m) / wi.z
    }

    /// Sample a visible normal for wi (wi.z > 0) (Heitz 2018, Listing 1).
    #[inline]
    pub fn sample_visible(&self, wi: Vec3, u: Vec2) -> Vec3 {
        let vh = Vec3::new(self.alpha_u * wi.x, self.alpha_v * wi.y, wi.z).normalize();
        let lensq = vh.x * vh.x + vh.y * vh.y;
        let t1 = if lensq > 0.0 {
            Vec3::new(-vh.y, vh.x, 0.0) / lensq.sqrt()
        } else {
            Vec3::X
        };
        let t2 = vh.cross(t1);
        let r = u.x.sqrt();
        let phi = 2.0 * PI * u.y;
        let p1 = r * phi.cos();
        let mut p2 = r * phi.sin();
        let s = 0.5 * (1.0 + vh.z);
        p2 = (1.0 - s) * (1.0 - p1 * p1).max(0.0).sqrt() + s * p2;
        let nh = t1 * p1 + t2 * p2 + vh * (1.0 - p1 * p1 - p2 * p2).max(0.0).sqrt();
        Vec3::new(self.alpha_u * nh.x, self.alpha_v * nh.y, nh.z.max(1e-6)).normalize()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// ∫ D(m) cos θm dω = 1 (projected-area normalisation), by a midpoint rule in (cos θ, φ).
    #[test]
    fn ggx_is_normalised() {
        for alpha in [0.05f32, 0.3, 0.8] {
            let g = Ggx::new(alpha);
            let (nt, np) = (4000, 16);
            let mut s = 0.0f64;
            for i in 0..nt {
                // substitute cos θ = 1 − x² to resolve the peak at small α
                let x = (i as f64 + 0.5) / nt as f64;
                let c = 1.0 - x * x;
                let jac = 2.0 * x / nt as f64;
                for j in 0..np {
                    let phi = 2.0 * std::f64::consts::PI * (j as f64 + 0.5) / np as f64;
                    let st = (1.0 - c * c).max(0.0).sqrt();
                    let m = Vec3::new((st * phi.cos()) as f32, (st * phi.sin()) as f32, c as f32);
                    s += g.d(m) as f64 * c * jac * 2.0 * std::f64::consts::PI / np as f64;
                }
            }
            assert!((s - 1.0).abs() < 2e-3, "alpha {alpha}: {s}");
        }
    }
}
