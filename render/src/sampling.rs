//! Sample warps (Shirley & Chiu 1997 concentric disc; Malley's method for the cosine
//! hemisphere) and a 1-D discrete distribution. Each warp has its density next to it so the
//! chi-square tests can check one against the other.
use glam::{Vec2, Vec3};
use std::f32::consts::{FRAC_PI_4, PI};

/// Concentric map of the unit square onto the unit disc (Shirley & Chiu 1997); uniform density.
#[inline]
pub fn square_to_disk_concentric(u: Vec2) -> Vec2 {
    let a = 2.0 * u - Vec2::ONE;
    if a.x == 0.0 && a.y == 0.0 {
        return Vec2::ZERO;
    }
    // φ = π/4·(y/x) on the wedges |x| > |y|, else π/2 − π/4·(x/y); the angle ψ = π/4·ratio
    // lies in [−π/4, π/4] where short Taylor series give cos and sin to f32 precision
    // (selects, no branch: the wedge is random)
    let swap = a.x.abs() <= a.y.abs();
    let (r, q) = if swap { (a.y, a.x) } else { (a.x, a.y) };
    let (c, s) = cos_sin_quarter(FRAC_PI_4 * (q / r));
    // cos(π/2 − ψ) = sin ψ, sin(π/2 − ψ) = cos ψ
    let (c, s) = if swap { (s, c) } else { (c, s) };
    Vec2::new(r * c, r * s)
}

/// (cos ψ, sin ψ) for |ψ| ≤ π/4 by Taylor series to ψ¹⁰ and ψ⁹ (truncation error below
/// 2·10⁻⁹, under half an f32 ulp of the results).
#[inline(always)]
fn cos_sin_quarter(x: f32) -> (f32, f32) {
    let x2 = x * x;
    let c = 1.0
        + x2 * (-1.0 / 2.0
            + x2 * (1.0 / 24.0
                + x2 * (-1.0 / 720.0 + x2 * (1.0 / 40320.0 - x2 * (1.0 / 3628800.0)))));
    let s = x
        * (1.0
            + x2 * (-1.0 / 6.0
                + x2 * (1.0 / 120.0 + x2 * (-1.0 / 5040.0 + x2 * (1.0 / 362880.0)))));
    (c, s)
}

/// Cosine-weighted hemisphere about +Z (Malley's method); density cos θ / π.
#[inline]
pub fn square_to_cosine_hemisphere(u: Vec2) -> Vec3 {
    let d = square_to_disk_concentric(u);
    let z = (1.0 - d.length_squared()).max(0.0).sqrt();
    Vec3::new(d.x, d.y, z)
}

/// Density of [`square_to_cosine_hemisphere`] (per steradian).
#[inline]
pub fn cosine_hemisphere_pdf(w: Vec3) -> f32 {
    if w.z > 0.0 {
        w.z / PI
    } else {
        0.0
    }
}

/// Uniform direction on the unit sphere; density 1/(4π).
pub fn square_to_uniform_sphere(u: Vec2) -> Vec3 {
    let z = 1.0 - 2.0 * u.x;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = 2.0 * PI * u.y;
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// Uniform point on a triangle as barycentrics (b1, b2) (square-root parametrisation,
/// Turk 1990); density 1/area.
#[inline]
pub fn square_to_triangle(u: Vec2) -> Vec2 {
    let s = u.x.sqrt();
    Vec2::new(1.0 - s, u.y * s)
}

/// Uniform direction inside the cone of half-angle acos(cos_max) about +Z; density
/// 1/(2π(1−cos_max)).
pub fn square_to_uniform_cone(u: Vec2, cos_max: f32) -> Vec3 {
    let z = 1.0 - u.x * (1.0 - cos_max);
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = 2.0 * PI * u.y;
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// An orthonormal basis with `n` as its third axis (Duff et al. 2017, "Building an
/// orthonormal basis, revisited").
#[derive(Debug, Clone, Copy)]
pub struct Frame {
    /// First tangent.
    pub s: Vec3,
    /// Second tangent.
    pub t: Vec3,
    /// Normal.
    pub n: Vec3,
}

impl Frame {
    /// The frame around unit vector `n`.
    #[inline]
    pub fn from_normal(n: Vec3) -> Self {
        let sign = 1.0f32.copysign(n.z);
        let a = -1.0 / (sign + n.z);
        let b = n.x * n.y * a;
        Frame {
            s: Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x),
            t: Vec3::new(b, sign + n.y * n.y * a, -n.y),
            n,
        }
    }
    /// World → local.
    #[inline]
    pub fn to_local(&self, v: Vec3) -> Vec3 {
        Vec3::new(v.dot(self.s), v.dot(self.t), v.dot(self.n))
    }
    /// Local → world.
    #[inline]
    pub fn to_world(&self, v: Vec3) -> Vec3 {
        self.s * v.x + self.t * v.y + self.n * v.z
    }
}

/// A discrete distribution over `n` items (weights ≥ 0), sampled by inverting the CDF.
#[derive(Debug, Clone)]
pub struct Distribution1D {
    cdf: Vec<f32>,
    pmf: Vec<f32>,
    total: f64,
}

impl Distribution1D {
    /// From non-negative weights; None when they sum to zero.
    pub fn new(weights: &[f64]) -> Option<Self> {
        let total: f64 = weights.iter().map(|w| w.max(0.0)).sum();
        if !(total > 0.0) || !total.is_finite() {
            return None;
        }
        let mut acc = 0.0f64;
        let mut cdf = Vec::with_capacity(weights.len());
        let mut pmf = Vec::with_capacity(weights.len());
        for w in weights {
            let p = w.max(0.0) / total;
            acc += p;
            cdf.push(acc as f32);
            pmf.push(p as f32);
        }
        if let Some(last) = cdf.last_mut() {
            *last = 1.0;
        }
        Some(Distribution1D { cdf, pmf, total })
    }
    /// Number of items.
    pub fn len(&self) -> usize {
        self.pmf.len()
    }
    /// True when there are no items (never, for a constructed distribution).
    pub fn is_empty(&self) -> bool {
        self.pmf.is_empty()
    }
    /// Sum of the weights.
    pub fn total(&self) -> f64 {
        self.total
    }
    /// Probability of item `i`.
    #[inline]
    pub fn pmf(&self, i: usize) -> f32 {
        self.pmf[i]
    }
    /// Sample an item with `u` ∈ [0,1): (index, probability, `u` rescaled to [0,1) within it).
    #[inline]
    pub fn sample(&self, u: f32) -> (usize, f32, f32) {
        let i = self
            .cdf
            .partition_point(|&c| c <= u)
            .min(self.cdf.len() - 1);
        let lo = if i == 0 { 0.0 } else { self.cdf[i - 1] };
        let p = self.pmf[i];
        let ur = if p > 0.0 {
            ((u - lo) / p).clamp(0.0, 1.0 - f32::EPSILON)
        } else {
            0.0
        };
        (i, p, ur)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn disk_and_hemisphere_stay_in_range() {
        for i in 0..50 {
            for j in 0..50 {
                let u = Vec2::new(i as f32 / 49.0, j as f32 / 49.0);
                assert!(square_to_disk_concentric(u).length() <= 1.0 + 1e-6);
                let w = square_to_cosine_hemisphere(u);
                assert!((w.length() - 1.0).abs() < 1e-5 && w.z >= 0.0);
            }
        }
    }

    #[test]
    fn quarter_cos_sin_match_libm() {
        for i in 0..=1000 {
            let x = (i as f32 / 1000.0 * 2.0 - 1.0) * FRAC_PI_4;
            let (c, s) = cos_sin_quarter(x);
            assert!((c - x.cos()).abs() <= 2.0 * f32::EPSILON, "cos {x}");
            assert!((s - x.sin()).abs() <= 2.0 * f32::EPSILON, "sin {x}");
        }
        // the disc map agrees with the polar form r·(cos φ, sin φ)
        for i in 1..50 {
            for j in 1..50 {
                let u = Vec2::new(i as f32 / 50.0, j as f32 / 50.0);
                let a = 2.0 * u - Vec2::ONE;
                if a == Vec2::ZERO {
                    assert_eq!(square_to_disk_concentric(u), Vec2::ZERO);
                    continue;
                }
                let (r, phi) = if a.x.abs() > a.y.abs() {
                    (a.x, FRAC_PI_4 * (a.y / a.x))
                } else {
                    (a.y, 0.5 * PI - FRAC_PI_4 * (a.x / a.y))
                };
                let want = Vec2::new(r * phi.cos(), r * phi.sin());
                assert!(
                    (square_to_disk_concentric(u) - want).length() < 1e-6,
                    "{u:?}"
                );
            }
        }
    }

    #[test]
    fn frame_is_orthonormal() {
        for n in [Vec3::Z, -Vec3::Z, Vec3::new(0.3, -0.5, 0.8).normalize()] {
            let f = Frame::from_normal(n);
            assert!(f.s.dot(f.t).abs() < 1e-6 && f.s.dot(n).abs() < 1e-6);
            assert!((f.s.cross(f.t) - n).length() < 1e-5);
            let v = Vec3::new(0.1, 0.7, -0.2);
            assert!((f.to_world(f.to_local(v)) - v).length() < 1e-6);
        }
    }

    #[test]
    fn discrete_distribution_inverts_its_cdf() {
        let d = Distribution1D::new(&[1.0, 0.0, 3.0]).unwrap();
        assert_eq!(d.sample(0.1).0, 0);
        assert_eq!(d.sample(0.3).0, 2);
        assert!((d.pmf(2) - 0.75).abs() < 1e-6);
        assert!(Distribution1D::new(&[0.0, 0.0]).is_none());
    }
}
