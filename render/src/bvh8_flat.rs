//! Ray casting for small scenes (≤ 64 triangles, the flat case of [`crate::bvh4`]) with
//! 8-wide AVX2 + FMA, chosen at run time when the CPU has both (the portable 4-wide code
//! runs otherwise).
//!
//! * Triangles come in packs of 8 (BVH order, so spatially coherent). Each triangle stores
//!   the affine map from world space to its own barycentric frame (Baldwin & Weber, "Fast
//!   Ray-Triangle Intersections by Coordinate Transformation", JCGT 5(3), 2016): with
//!   A = [e₁ e₂ n], n = e₁ × e₂, the rows of A⁻¹ map x − v₀ to (b₁, b₂, w), and the ray
//!   crosses the plane w = 0 at t = −w(o)/w(d), where (b₁, b₂) = (b₁, b₂)(o) + t·(b₁, b₂)(d).
//!   That is 21 FMAs and one division for 8 triangles, with the same barycentric tolerance
//!   as the scalar Möller–Trumbore test ([`crate::scene::TriGeom::intersect`]).
//! * There is no box test: with ≤ 8 packs, testing every pack was measured faster than culling
//!   them by a slab test of their boxes first (Cornell box, 36 triangles: −8 % CPU time).
#![cfg(target_arch = "x86_64")]

use glam::{Vec2, Vec3};
use std::arch::x86_64::*;

/// Barycentric tolerance (closes cracks along shared edges; [`crate::scene::BARY_EPS`]).
use crate::scene::BARY_EPS;

/// 8 triangles: rows of the world → (b₁, b₂, w) maps, one lane per triangle.
#[repr(C, align(32))]
#[derive(Debug, Clone, Copy)]
struct Pack8 {
    /// Row r of lane k: m[4r..4r+4][k] = (a_x, a_y, a_z, c) with value a·x + c; rows b₁, b₂, w.
    /// Unused or degenerate lanes hold NaN (every comparison fails: never hit).
    m: [[f32; 8]; 12],
    /// Triangle index (BVH order) per lane.
    prim: [u32; 8],
}

/// All packs of a small scene and their boxes.
#[repr(C, align(32))]
#[derive(Debug, Clone)]
pub struct Flat8 {
    /// Lanes that hold a pack.
    valid: u32,
    packs: Vec<Pack8>,
}

/// The closest hit: (t, triangle in BVH order, barycentrics).
pub type Hit8 = (f32, u32, Vec2);

impl Flat8 {
    /// True when this CPU runs the 8-wide code.
    pub fn supported() -> bool {
        is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma")
    }

    /// Build from triangles already in BVH order (`prims[i]` is the index reported for
    /// triangle i); at most 64 triangles.
    pub fn build(tris: &[[Vec3; 3]], prims: &[u32]) -> Flat8 {
        assert!(tris.len() <= 64 && tris.len() == prims.len());
        let mut f = Flat8 {
            valid: 0,
            packs: Vec::new(),
        };
        for (k, chunk) in tris.chunks(8).enumerate() {
            let mut p = Pack8 {
                m: [[f32::NAN; 8]; 12],
                prim: [u32::MAX; 8],
            };
            for (l, t) in chunk.iter().enumerate() {
                p.prim[l] = prims[k * 8 + l];
                if let Some(rows) = barycentric_map(t) {
                    for (r, row) in rows.iter().enumerate() {
                        for (c, v) in row.iter().enumerate() {
                            p.m[4 * r + c][l] = *v;
                        }
                    }
                }
            }
            f.valid |= 1 << k;
            f.packs.push(p);
        }
        f
    }

    /// Closest hit along o + t·d, t ∈ [tmin, tmax].
    ///
    /// # Safety
    /// The CPU must support AVX2 and FMA ([`Flat8::supported`]).
    #[target_feature(enable = "avx2,fma")]
    pub unsafe fn intersect(&self, o: Vec3, d: Vec3, tmin: f32, tmax: f32) -> Option<Hit8> {
        let r = Ray8::new(o, d, tmin);
        let mut tmax = tmax;
        let mut best: Option<Hit8> = None;
        for p in &self.packs {
            let (t, u, v, ok) = r.tris(p, tmax);
            let mut m = _mm256_movemask_ps(ok) as u32;
            if m != 0 {
                let (mut ta, mut ua, mut va) = ([0f32; 8], [0f32; 8], [0f32; 8]);
                _mm256_storeu_ps(ta.as_mut_ptr(), t);
                _mm256_storeu_ps(ua.as_mut_ptr(), u);
                _mm256_storeu_ps(va.as_mut_ptr(), v);
                while m != 0 {
                    let i = m.trailing_zeros() as usize;
                    m &= m - 1;
                    if ta[i] <= tmax {
                        tmax = ta[i];
                        best = Some((ta[i], p.prim[i], Vec2::new(ua[i], va[i])));
                    }
                }
            }
        }
        best
    }

    /// True when nothing lies along o + t·d for t ∈ [tmin, tmax] (the first hit ends it).
    ///
    /// # Safety
    /// The CPU must support AVX2 and FMA ([`Flat8::supported`]).
    #[target_feature(enable = "avx2,fma")]
    pub unsafe fn unoccluded(&self, o: Vec3, d: Vec3, tmin: f32, tmax: f32) -> bool {
        let r = Ray8::new(o, d, tmin);
        let mut mask = self.valid;
        while mask != 0 {
            let k = mask.trailing_zeros() as usize;
            mask &= mask - 1;
            if _mm256_movemask_ps(r.tris(&self.packs[k], tmax).3) != 0 {
                return false;
            }
        }
        true
    }
}

/// The map x ↦ (b₁, b₂, w) = A⁻¹(x − v₀), A = [e₁ e₂ n], as 3 rows (a_x, a_y, a_z, c);
/// None for a degenerate triangle. Rows of A⁻¹: (e₂ × n, n × e₁, n)/|n|² (computed in f64).
fn barycentric_map(t: &[Vec3; 3]) -> Option<[[f32; 4]; 3]> {
    let v = |p: Vec3| glam::DVec3::new(p.x as f64, p.y as f64, p.z as f64);
    let (v0, v1, v2) = (v(t[0]), v(t[1]), v(t[2]));
    let (e1, e2) = (v1 - v0, v2 - v0);
    let n = e1.cross(e2);
    let n2 = n.length_squared();
    if !(n2 > 0.0) || !n2.is_finite() {
        return None;
    }
    let rows = [e2.cross(n) / n2, n.cross(e1) / n2, n / n2];
    Some(rows.map(|a| [a.x as f32, a.y as f32, a.z as f32, -a.dot(v0) as f32]))
}

/// A ray splatted over 8 lanes.
struct Ray8 {
    o: [__m256; 3],
    d: [__m256; 3],
    tmin: __m256,
}

impl Ray8 {
    #[inline]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn new(o: Vec3, d: Vec3, tmin: f32) -> Ray8 {
        Ray8 {
            o: [
                _mm256_set1_ps(o.x),
                _mm256_set1_ps(o.y),
                _mm256_set1_ps(o.z),
            ],
            d: [
                _mm256_set1_ps(d.x),
                _mm256_set1_ps(d.y),
                _mm256_set1_ps(d.z),
            ],
            tmin: _mm256_set1_ps(tmin),
        }
    }

    /// The 8 triangles of a pack: (t, b₁, b₂, lane mask of the hits with t ∈ [tmin, tmax]).
    #[inline]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn tris(&self, p: &Pack8, tmax: f32) -> (__m256, __m256, __m256, __m256) {
        macro_rules! m {
            ($i:expr) => {
                _mm256_load_ps(p.m[$i].as_ptr())
            };
        }
        let [ox, oy, oz] = self.o;
        let [dx, dy, dz] = self.d;
        // row value at the origin (affine) and along the direction (linear)
        macro_rules! at_o {
            ($r:expr) => {
                _mm256_fmadd_ps(
                    m!(4 * $r),
                    ox,
                    _mm256_fmadd_ps(
                        m!(4 * $r + 1),
                        oy,
                        _mm256_fmadd_ps(m!(4 * $r + 2), oz, m!(4 * $r + 3)),
                    ),
                )
            };
        }
        macro_rules! along_d {
            ($r:expr) => {
                _mm256_fmadd_ps(
                    m!(4 * $r),
                    dx,
                    _mm256_fmadd_ps(m!(4 * $r + 1), dy, _mm256_mul_ps(m!(4 * $r + 2), dz)),
                )
            };
        }
        let w_o = at_o!(2);
        let w_d = along_d!(2);
        let t = _mm256_div_ps(_mm256_xor_ps(w_o, _mm256_set1_ps(-0.0)), w_d);
        let u = _mm256_fmadd_ps(t, along_d!(0), at_o!(0));
        let v = _mm256_fmadd_ps(t, along_d!(1), at_o!(1));
        let lo = _mm256_set1_ps(-BARY_EPS);
        let hi = _mm256_set1_ps(1.0 + BARY_EPS);
        let ok = _mm256_and_ps(
            _mm256_and_ps(
                _mm256_cmp_ps::<_CMP_GE_OQ>(u, lo),
                _mm256_cmp_ps::<_CMP_GE_OQ>(v, lo),
            ),
            _mm256_and_ps(
                _mm256_cmp_ps::<_CMP_LE_OQ>(_mm256_add_ps(u, v), hi),
                _mm256_and_ps(
                    _mm256_cmp_ps::<_CMP_GE_OQ>(t, self.tmin),
                    _mm256_cmp_ps::<_CMP_LE_OQ>(t, _mm256_set1_ps(tmax)),
                ),
            ),
        );
        (t, u, v, ok)
    }
}
