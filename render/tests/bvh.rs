//! The ray-casting structures (render/src/bvh4.rs: flat packs, the portable 4-wide tree, the
//! 8-wide AVX2 tree for large scenes) against brute force: every triangle tested with the
//! scalar Möller–Trumbore test. Random triangle clouds and meshes with shared edges and
//! axis-aligned faces (zero-thickness boxes); rays aimed at random points, exactly at edges
//! and vertices (grazing), parallel to the axes and to the faces. The nearest hit (t,
//! triangle) and the occlusion answer must agree.
use camsim_render::bvh4::Bvh4;
use camsim_render::scene::TriGeom;
use glam::Vec3;
use obvhs::ray::Ray;

struct Lcg(u64);
impl Lcg {
    fn f(&mut self) -> f32 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 40) as f32 / (1u64 << 24) as f32
    }
    fn v(&mut self) -> Vec3 {
        Vec3::new(self.f(), self.f(), self.f())
    }
}

/// `n` random triangles of size ~`size` in the cube [−2, 2]³.
fn cloud(n: usize, size: f32, rng: &mut Lcg) -> Vec<[Vec3; 3]> {
    (0..n)
        .map(|_| {
            let c = rng.v() * 4.0 - 2.0;
            let mut r = || (rng.v() - 0.5) * size;
            [c + r(), c + r(), c + r()]
        })
        .collect()
}

/// A closed axis-aligned box of 2 × `k`² triangles per face plus a bumpy sphere-like grid
/// inside it (shared edges everywhere; the box faces give zero-thickness child boxes).
fn mesh(k: usize, rng: &mut Lcg) -> Vec<[Vec3; 3]> {
    let mut tris = Vec::new();
    let g = |i: usize| -2.0 + 4.0 * i as f32 / k as f32;
    for axis in 0..3 {
        for side in [-2.0f32, 2.0] {
            let p = |a: f32, b: f32| {
                let mut v = [0.0; 3];
                v[axis] = side;
                v[(axis + 1) % 3] = a;
                v[(axis + 2) % 3] = b;
                Vec3::from_array(v)
            };
            for i in 0..k {
                for j in 0..k {
                    let (a0, a1, b0, b1) = (g(i), g(i + 1), g(j), g(j + 1));
                    tris.push([p(a0, b0), p(a1, b0), p(a1, b1)]);
                    tris.push([p(a0, b0), p(a1, b1), p(a0, b1)]);
                }
            }
        }
    }
    // a bumpy sphere (latitude-longitude grid), radius 1 ± 0.05
    let (nu, nv) = (2 * k, k);
    let pt = |i: usize, j: usize, bump: f32| {
        let th = std::f32::consts::PI * i as f32 / nv as f32;
        let ph = 2.0 * std::f32::consts::PI * (j % nu) as f32 / nu as f32;
        let r = 1.0 + bump;
        Vec3::new(
            r * th.sin() * ph.cos(),
            r * th.cos(),
            r * th.sin() * ph.sin(),
        )
    };
    let bumps: Vec<f32> = (0..(nv + 1) * nu).map(|_| 0.05 * rng.f()).collect();
    let at = |i: usize, j: usize| pt(i, j, bumps[i * nu + j % nu]);
    for i in 0..nv {
        for j in 0..nu {
            tris.push([at(i, j), at(i, j + 1), at(i + 1, j)]);
            tris.push([at(i, j + 1), at(i + 1, j + 1), at(i + 1, j)]);
        }
    }
    tris
}

/// The brute-force nearest hit: (t, input triangle) or None.
fn brute(geo: &[TriGeom], o: Vec3, d: Vec3, tmin: f32, tmax: f32) -> Option<(f32, usize)> {
    let ray = Ray::new(o.into(), d.into(), tmin, tmax);
    let mut best: Option<(f32, usize)> = None;
    for (i, g) in geo.iter().enumerate() {
        let t = g.intersect(&ray);
        if t.is_finite() && best.is_none_or(|(bt, _)| t < bt) {
            best = Some((t, i));
        }
    }
    best
}

fn geom(t: &[Vec3; 3]) -> TriGeom {
    TriGeom {
        v0: t[0].into(),
        e1: (t[1] - t[0]).into(),
        e2: (t[2] - t[0]).into(),
    }
}

/// Rays of every kind into a scene of `tris`: random, grazing edges and vertices, and axis-
/// parallel. Returns (origin, direction, tmin, tmax).
fn rays(tris: &[[Vec3; 3]], n: usize, rng: &mut Lcg) -> Vec<(Vec3, Vec3, f32, f32)> {
    let mut out = Vec::with_capacity(n);
    for k in 0..n {
        let o = rng.v() * 6.0 - 3.0;
        let t = &tris[(rng.f() * tris.len() as f32) as usize % tris.len()];
        let d = match k % 5 {
            // at a random point of the cube
            0 => rng.v() * 4.0 - 2.0 - o,
            // exactly at an edge of a triangle (a point on v0–v1)
            1 => {
                let s = rng.f();
                t[0] + (t[1] - t[0]) * s - o
            }
            // exactly at a vertex
            2 => t[2] - o,
            // along an axis (two zero direction components), through a triangle's vertex
            // plane: parallel to the box faces of that axis
            3 => {
                let ax = (rng.f() * 3.0) as usize % 3;
                let mut d = [0.0f32; 3];
                d[ax] = if rng.f() < 0.5 { 1.0 } else { -1.0 };
                let mut oo = t[0].to_array();
                oo[ax] = o[ax];
                return_ray(&mut out, Vec3::from_array(oo), Vec3::from_array(d), rng);
                continue;
            }
            // in a coordinate plane (one zero component), aimed at a triangle's centroid
            _ => {
                let ax = (rng.f() * 3.0) as usize % 3;
                let c = (t[0] + t[1] + t[2]) / 3.0;
                let mut oo = o.to_array();
                oo[ax] = c[ax];
                let oo = Vec3::from_array(oo);
                let mut d = (c - oo).to_array();
                d[ax] = 0.0;
                return_ray(&mut out, oo, Vec3::from_array(d), rng);
                continue;
            }
        };
        return_ray(&mut out, o, d, rng);
    }
    out
}

fn return_ray(out: &mut Vec<(Vec3, Vec3, f32, f32)>, o: Vec3, d: Vec3, rng: &mut Lcg) {
    if d.length_squared() == 0.0 {
        return;
    }
    let d = d.normalize();
    let tmin = if rng.f() < 0.3 { 0.0 } else { 1e-3 };
    let tmax = if rng.f() < 0.5 {
        f32::INFINITY
    } else {
        0.5 + 4.0 * rng.f()
    };
    out.push((o, d, tmin, tmax));
}

/// One structure (`simd8`: the AVX2 code when the CPU has it) against brute force.
fn check(name: &str, tris: &[[Vec3; 3]], simd8: bool, rng: &mut Lcg) {
    let bvh = Bvh4::build_with(tris, simd8);
    let avx2 = cfg!(target_arch = "x86_64") && {
        #[cfg(target_arch = "x86_64")]
        {
            is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma")
        }
        #[cfg(not(target_arch = "x86_64"))]
        false
    };
    assert_eq!(
        bvh.uses_simd8(),
        simd8 && avx2,
        "{name}: 8-wide code choice"
    );
    let mut sorted = bvh.order.clone();
    sorted.sort();
    assert_eq!(
        sorted,
        (0..tris.len() as u32).collect::<Vec<_>>(),
        "{name}: order"
    );
    let geo: Vec<TriGeom> = tris.iter().map(geom).collect();
    let (mut hits, mut misses, mut ties) = (0, 0, 0);
    for (o, d, tmin, tmax) in rays(tris, 3000, rng) {
        let b = brute(&geo, o, d, tmin, tmax);
        let h = bvh.intersect(o, d, tmin, tmax);
        match (h, b) {
            (Some(h), Some((bt, bi))) => {
                hits += 1;
                assert!(
                    (h.t - bt).abs() <= 1e-6 * bt.max(1.0),
                    "{name} simd8 {simd8}: t {} vs brute force {bt} (o {o}, d {d})",
                    h.t
                );
                let hi = bvh.order[h.prim as usize] as usize;
                if hi != bi {
                    // a tie: the ray crosses a shared edge or vertex; the reported triangle
                    // must itself be hit at the same distance
                    let ray = Ray::new(o.into(), d.into(), tmin, tmax);
                    let th = geo[hi].intersect(&ray);
                    assert!(
                        (th - bt).abs() <= 1e-6 * bt.max(1.0),
                        "{name} simd8 {simd8}: triangle {hi} (t {th}) vs brute force {bi} (t {bt})"
                    );
                    ties += 1;
                }
                // the barycentrics belong to the reported triangle
                let bary = geo[hi].barycentrics(o.into(), d.into());
                assert!((bary - h.bary).length() < 1e-4, "{name}: barycentrics");
            }
            (None, None) => misses += 1,
            (h, b) => panic!("{name} simd8 {simd8}: BVH {h:?} vs brute force {b:?} (o {o}, d {d}, t ∈ [{tmin}, {tmax}])"),
        }
        assert_eq!(
            bvh.unoccluded(o, d, tmin, tmax),
            b.is_none(),
            "{name} simd8 {simd8}: occlusion (o {o}, d {d})"
        );
    }
    // the rays exercise both answers, and ties stay the exception
    assert!(
        hits > 500 && misses > 100,
        "{name}: {hits} hits, {misses} misses"
    );
    assert!(ties * 4 < hits, "{name}: {ties} ties in {hits} hits");
}

/// Clouds of 65 to 20 000 random triangles and a closed mesh with shared edges: the 4-wide
/// portable tree and the 8-wide AVX2 tree give brute force's nearest hit and occlusion.
#[test]
fn bvh_trees_match_brute_force() {
    let mut rng = Lcg(2026);
    for (n, size) in [(65usize, 1.5f32), (700, 0.8), (20_000, 0.15)] {
        let tris = cloud(n, size, &mut rng);
        for simd8 in [false, true] {
            check(&format!("cloud {n}"), &tris, simd8, &mut rng);
        }
    }
    let tris = mesh(40, &mut rng);
    for simd8 in [false, true] {
        check(&format!("mesh {}", tris.len()), &tris, simd8, &mut rng);
    }
}
