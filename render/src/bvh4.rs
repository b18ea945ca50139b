//! The ray-tracing acceleration structure: a 4-wide BVH whose topology comes from obvhs's
//! PLOC binary BVH (Meister & Bittner, "Parallel Locally-Ordered Clustering for Bounding
//! Volume Hierarchy Construction", IEEE TVCG 2018, with reinsertion), collapsed to 4 children
//! per node (the largest child is opened first, as in Wald et al., "Getting Rid of Packets",
//! 2008) and laid out for SIMD:
//!
//! * a node stores its 4 child boxes as structure-of-arrays; one slab test (Kay & Kajiya 1986)
//!   runs on the 4 boxes at once and the hit children are visited nearest first;
//! * a leaf is one pack of ≤ 4 triangles (vertex 0 and two edges, structure-of-arrays) tested
//!   4 at a time with Möller & Trumbore (1997), with the same barycentric tolerance as the
//!   scalar test ([`crate::scene::TriGeom::intersect`]);
//! * shadow rays stop at the first hit.
//!
//! For the few-dozen-triangle scenes of the Mitsuba comparisons this is 2–3× faster than
//! walking the compressed CWBVH one triangle at a time (the traversal was most of the render
//! time; docs/benchmarks/render.md).
use glam::{Vec2, Vec3, Vec4};
use std::mem::MaybeUninit;

/// Child reference flag: the child is a triangle pack.
pub(crate) const LEAF: u32 = 1 << 31;
/// Unused child slot.
pub(crate) const EMPTY: u32 = u32::MAX;
/// Barycentric tolerance (closes cracks along shared edges; [`crate::scene::BARY_EPS`]).
use crate::scene::BARY_EPS;
/// Traversal stack entries kept on the call stack: enough for trees up to 85 levels deep
/// (each level stacks ≤ 3 children); a deeper tree (a pathological obvhs build) traverses with
/// a heap stack sized from its depth ([`Bvh4::stack_len`]).
const STACK: usize = 256;
/// Up to this many triangles there is no tree: full packs of 4 in BVH order, their boxes in
/// groups of 4, and every ray tests every group's boxes, then the packs it hits (at ≤ 16
/// packs that beats the branchy tree walk; measured on the Cornell box, 36 triangles).
const FLAT_MAX_TRIS: usize = 64;

/// 128 bytes aligned to 64: exactly two cache lines (an adjacent pair for the hardware's
/// spatial prefetcher), never three.
#[repr(C, align(64))]
#[derive(Debug, Clone, Copy)]
struct Node4 {
    /// Child box minima (x, y, z), one lane per child.
    min: [Vec4; 3],
    /// Child box maxima.
    max: [Vec4; 3],
    /// Child references: node index, LEAF | pack index, or EMPTY.
    child: [u32; 4],
}

/// 160 bytes aligned to 32: always three cache lines, never four, with no padding.
#[repr(C, align(32))]
#[derive(Debug, Clone, Copy)]
pub(crate) struct Pack4 {
    /// Vertex 0 (x, y, z), one lane per triangle.
    v0: [Vec4; 3],
    /// v1 − v0.
    e1: [Vec4; 3],
    /// v2 − v0.
    e2: [Vec4; 3],
    /// Triangle index (BVH order) per lane; unused lanes are degenerate (never hit).
    pub(crate) prim: [u32; 4],
}

/// The closest hit of a ray.
#[derive(Debug, Clone, Copy)]
pub struct Bvh4Hit {
    /// Distance along the ray.
    pub t: f32,
    /// Triangle index (BVH order).
    pub prim: u32,
    /// Barycentrics (b1, b2) of the hit.
    pub bary: Vec2,
}

/// A 4-wide BVH over triangles; triangle i of the BVH order is `order[i]` of the input.
#[derive(Debug, Clone)]
pub struct Bvh4 {
    nodes: Vec<Node4>,
    packs: Vec<Pack4>,
    root: u32,
    /// Few triangles: test every pack, no node visits (cheaper than any tree walk).
    flat: bool,
    /// Traversal stack entries the tree can need: 3 per level of the deepest path, plus one.
    stack_len: usize,
    /// Input index of each triangle in BVH order.
    pub order: Vec<u32>,
    /// Few triangles on a CPU with AVX2 + FMA: the 8-wide packs that replace `nodes`/`packs`
    /// (render/src/bvh8_flat.rs).
    #[cfg(target_arch = "x86_64")]
    flat8: Option<Box<crate::bvh8_flat::Flat8>>,
    /// More triangles on a CPU with AVX2 + FMA: the 8-wide tree that replaces `nodes`/`packs`
    /// (render/src/bvh8_tree.rs).
    #[cfg(target_arch = "x86_64")]
    wide8: Option<Box<crate::bvh8_tree::Bvh8>>,
}

/// A ray prepared for traversal (splatted origin/direction, safe reciprocal direction).
pub(crate) struct PreparedRay {
    pub(crate) o: [Vec4; 3],
    d: [Vec4; 3],
    pub(crate) inv: [Vec4; 3],
    pub(crate) tmin: f32,
}

impl PreparedRay {
    #[inline(always)]
    pub(crate) fn new(o: Vec3, d: Vec3, tmin: f32) -> Self {
        // a zero direction component gets a tiny one so that 0·∞ never appears in the slabs
        let safe = |x: f32| {
            if x.abs() < 1e-20 {
                1e-20f32.copysign(x)
            } else {
                x
            }
        };
        let inv = Vec3::new(1.0 / safe(d.x), 1.0 / safe(d.y), 1.0 / safe(d.z));
        PreparedRay {
            o: [Vec4::splat(o.x), Vec4::splat(o.y), Vec4::splat(o.z)],
            d: [Vec4::splat(d.x), Vec4::splat(d.y), Vec4::splat(d.z)],
            inv: [Vec4::splat(inv.x), Vec4::splat(inv.y), Vec4::splat(inv.z)],
            tmin,
        }
    }

    /// Entry distance per child and the mask of the children hit within [tmin, tmax].
    #[inline(always)]
    fn boxes(&self, n: &Node4, tmax: f32) -> (Vec4, u32) {
        let tx0 = (n.min[0] - self.o[0]) * self.inv[0];
        let tx1 = (n.max[0] - self.o[0]) * self.inv[0];
        let ty0 = (n.min[1] - self.o[1]) * self.inv[1];
        let ty1 = (n.max[1] - self.o[1]) * self.inv[1];
        let tz0 = (n.min[2] - self.o[2]) * self.inv[2];
        let tz1 = (n.max[2] - self.o[2]) * self.inv[2];
        let tnear = tx0
            .min(tx1)
            .max(ty0.min(ty1))
            .max(tz0.min(tz1).max(Vec4::splat(self.tmin)));
        let tfar = tx0
            .max(tx1)
            .min(ty0.max(ty1))
            .min(tz0.max(tz1).min(Vec4::splat(tmax)));
        (tnear, tnear.cmple(tfar).bitmask())
    }

    /// Möller–Trumbore on the 4 triangles of a pack: (t per lane, b1, b2, mask of hits in
    /// [tmin, tmax]).
    #[inline(always)]
    pub(crate) fn tris(&self, p: &Pack4, tmax: f32) -> (Vec4, Vec4, Vec4, u32) {
        let [dx, dy, dz] = self.d;
        let [e1x, e1y, e1z] = p.e1;
        let [e2x, e2y, e2z] = p.e2;
        // p = d × e2
        let px = dy * e2z - dz * e2y;
        let py = dz * e2x - dx * e2z;
        let pz = dx * e2y - dy * e2x;
        let det = e1x * px + e1y * py + e1z * pz;
        let inv = Vec4::ONE / det;
        let sx = self.o[0] - p.v0[0];
        let sy = self.o[1] - p.v0[1];
        let sz = self.o[2] - p.v0[2];
        let u = (sx * px + sy * py + sz * pz) * inv;
        // q = s × e1
        let qx = sy * e1z - sz * e1y;
        let qy = sz * e1x - sx * e1z;
        let qz = sx * e1y - sy * e1x;
        let v = (dx * qx + dy * qy + dz * qz) * inv;
        let t = (e2x * qx + e2y * qy + e2z * qz) * inv;
        let lo = Vec4::splat(-BARY_EPS);
        let hi = Vec4::splat(1.0 + BARY_EPS);
        let m = det.cmpne(Vec4::ZERO)
            & u.cmpge(lo)
            & u.cmple(hi)
            & v.cmpge(lo)
            & (u + v).cmple(hi)
            & t.cmpge(Vec4::splat(self.tmin))
            & t.cmple(Vec4::splat(tmax));
        (t, u, v, m.bitmask())
    }
}

impl Bvh4 {
    /// Ask the memory system for child `c` (node or pack) ahead of its visit: the children
    /// that wait on the traversal stack load while the nearest one is traversed (at 10⁶
    /// triangles the tree does not fit in the L2 cache and the traversal waits on memory).
    #[inline(always)]
    fn prefetch(&self, c: u32) {
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
            let (p, lines) = if c & LEAF != 0 {
                (
                    self.packs.as_ptr().wrapping_add((c & !LEAF) as usize) as *const i8,
                    3,
                )
            } else {
                (self.nodes.as_ptr().wrapping_add(c as usize) as *const i8, 2)
            };
            for l in 0..lines {
                // SAFETY: a prefetch never faults, whatever the address
                #[allow(unused_unsafe)]
                unsafe {
                    _mm_prefetch::<_MM_HINT_T0>(p.wrapping_add(64 * l))
                };
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        let _ = c;
    }

    /// Build over world-space triangles (none degenerate in a way that matters: degenerate
    /// triangles are kept and simply never hit).
    pub fn build(triangles: &[[Vec3; 3]]) -> Bvh4 {
        Self::build_with(triangles, true)
    }

    /// [`Bvh4::build`]; `simd8` allows the 8-wide AVX2 code when the CPU has it (a flat layout
    /// for small scenes, a tree above; false: the portable 4-wide code only, for tests).
    pub fn build_with(triangles: &[[Vec3; 3]], simd8: bool) -> Bvh4 {
        let mut b = Builder {
            tb: TriBuilder {
                tris: triangles,
                packs: Vec::new(),
                order: Vec::with_capacity(triangles.len()),
            },
            nodes: Vec::new(),
        };
        #[cfg(target_arch = "x86_64")]
        let mut wide8 = None;
        let root = if triangles.len() <= 4 {
            let all: Vec<u32> = (0..triangles.len() as u32).collect();
            b.child_over(&all).0
        } else {
            let obv: Vec<obvhs::triangle::Triangle> = triangles
                .iter()
                .map(|t| obvhs::triangle::Triangle {
                    v0: t[0].into(),
                    v1: t[1].into(),
                    v2: t[2].into(),
                })
                .collect();
            let params = obvhs::BvhBuildParams {
                max_prims_per_leaf: 1,
                ..obvhs::BvhBuildParams::medium_build()
            };
            let bvh2 = obvhs::bvh2::builder::build_bvh2_from_tris(
                &obv,
                params,
                &mut std::time::Duration::default(),
            );
            let mut count = vec![0u32; bvh2.nodes.len()];
            subtree_count(&bvh2, 0, &mut count);
            #[cfg(target_arch = "x86_64")]
            if simd8 && triangles.len() > FLAT_MAX_TRIS && crate::bvh8_tree::Bvh8::supported() {
                let (w, order) = crate::bvh8_tree::Bvh8::build(triangles, &bvh2, &count);
                if w.fits_stack() {
                    wide8 = Some((Box::new(w), order));
                }
            }
            #[cfg(target_arch = "x86_64")]
            if wide8.is_some() {
                0
            } else {
                b.collapse(&bvh2, &count, 0).0
            }
            #[cfg(not(target_arch = "x86_64"))]
            b.collapse(&bvh2, &count, 0).0
        };
        let stack_len = if b.nodes.is_empty() {
            1
        } else {
            3 * tree_depth(&b.nodes, root) + 1
        };
        let mut bvh = Bvh4 {
            // read at scattered places while tracing: in huge pages (render/src/huge_pages.rs)
            nodes: crate::huge_pages::copy(&b.nodes),
            packs: crate::huge_pages::copy(&b.tb.packs),
            root,
            flat: false,
            stack_len,
            order: b.tb.order,
            #[cfg(target_arch = "x86_64")]
            flat8: None,
            #[cfg(target_arch = "x86_64")]
            wide8: None,
        };
        #[cfg(target_arch = "x86_64")]
        if let Some((w, order)) = wide8 {
            bvh.order = order;
            bvh.wide8 = Some(w);
        }
        if triangles.len() <= FLAT_MAX_TRIS {
            // repack full packs of 4 in BVH order (spatially coherent groups)
            let order = std::mem::take(&mut bvh.order);
            let mut fb = Builder {
                tb: TriBuilder {
                    tris: triangles,
                    packs: Vec::new(),
                    order: Vec::with_capacity(triangles.len()),
                },
                nodes: Vec::new(),
            };
            let packs: Vec<ChildBox> = order.chunks(4).map(|c| fb.child_over(c)).collect();
            // one box per pack, 4 per group node, tested before the triangles
            for g in packs.chunks(4) {
                let idx = fb.push_node();
                fb.fill_node(idx, g);
            }
            bvh.packs = fb.tb.packs;
            bvh.order = fb.tb.order;
            bvh.nodes = fb.nodes;
            bvh.flat = true;
            #[cfg(target_arch = "x86_64")]
            if simd8 && crate::bvh8_flat::Flat8::supported() {
                let tris: Vec<[Vec3; 3]> =
                    bvh.order.iter().map(|&i| triangles[i as usize]).collect();
                let prims: Vec<u32> = (0..tris.len() as u32).collect();
                bvh.flat8 = Some(Box::new(crate::bvh8_flat::Flat8::build(&tris, &prims)));
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        let _ = simd8;
        bvh
    }

    /// True when the 8-wide AVX2 code casts the rays.
    pub fn uses_simd8(&self) -> bool {
        #[cfg(target_arch = "x86_64")]
        return self.flat8.is_some() || self.wide8.is_some();
        #[cfg(not(target_arch = "x86_64"))]
        false
    }

    /// Closest hit along o + t·d with t ∈ [tmin, tmax].
    #[inline]
    pub fn intersect(&self, o: Vec3, d: Vec3, tmin: f32, tmax: f32) -> Option<Bvh4Hit> {
        #[cfg(target_arch = "x86_64")]
        if let Some(f) = &self.flat8 {
            // SAFETY: flat8 is only built when the CPU has AVX2 and FMA
            return unsafe { f.intersect(o, d, tmin, tmax) }.map(|(t, prim, bary)| Bvh4Hit {
                t,
                prim,
                bary,
            });
        }
        #[cfg(target_arch = "x86_64")]
        if let Some(w) = &self.wide8 {
            // SAFETY: wide8 is only built when the CPU has AVX2 and FMA
            return unsafe { w.intersect(o, d, tmin, tmax) };
        }
        let r = PreparedRay::new(o, d, tmin);
        let mut tmax = tmax;
        let mut best = Bvh4Hit {
            t: f32::INFINITY,
            prim: EMPTY,
            bary: Vec2::ZERO,
        };
        if self.flat {
            for n in &self.nodes {
                let mut mb = r.boxes(n, tmax).1;
                while mb != 0 {
                    let c = n.child[mb.trailing_zeros() as usize];
                    mb &= mb - 1;
                    if c == EMPTY {
                        continue;
                    }
                    let p = &self.packs[(c & !LEAF) as usize];
                    let (t, u, v, mut m) = r.tris(p, tmax);
                    while m != 0 {
                        let i = m.trailing_zeros() as usize;
                        m &= m - 1;
                        let ta = t.to_array();
                        if ta[i] <= tmax {
                            tmax = ta[i];
                            best = Bvh4Hit {
                                t: ta[i],
                                prim: p.prim[i],
                                bary: Vec2::new(u.to_array()[i], v.to_array()[i]),
                            };
                        }
                    }
                }
            }
            return (best.prim != EMPTY).then_some(best);
        }
        if self.stack_len <= STACK {
            let mut stack = [MaybeUninit::<(u32, f32)>::uninit(); STACK];
            self.intersect_tree(&r, tmax, &mut stack)
        } else {
            let mut stack = vec![MaybeUninit::<(u32, f32)>::uninit(); self.stack_len];
            self.intersect_tree(&r, tmax, &mut stack)
        }
    }

    /// The tree walk of [`Bvh4::intersect`] with a stack of at least `stack_len` entries.
    #[inline(always)]
    fn intersect_tree(
        &self,
        r: &PreparedRay,
        tmax: f32,
        stack: &mut [MaybeUninit<(u32, f32)>],
    ) -> Option<Bvh4Hit> {
        debug_assert!(stack.len() >= self.stack_len);
        let mut tmax = tmax;
        let mut best = Bvh4Hit {
            t: f32::INFINITY,
            prim: EMPTY,
            bary: Vec2::ZERO,
        };
        let mut sp = 0usize;
        let mut cur = self.root;
        loop {
            if cur & LEAF != 0 {
                let p = &self.packs[(cur & !LEAF) as usize];
                let (t, u, v, mut m) = r.tris(p, tmax);
                if m != 0 {
                    let (ta, ua, va) = (t.to_array(), u.to_array(), v.to_array());
                    while m != 0 {
                        let i = m.trailing_zeros() as usize;
                        m &= m - 1;
                        if ta[i] <= tmax {
                            tmax = ta[i];
                            best = Bvh4Hit {
                                t: ta[i],
                                prim: p.prim[i],
                                bary: Vec2::new(ua[i], va[i]),
                            };
                        }
                    }
                }
            } else {
                let n = &self.nodes[cur as usize];
                let (tnear, mut m) = r.boxes(n, tmax);
                if m != 0 {
                    let tn = tnear.to_array();
                    // hit children sorted by entry distance, farthest first onto the stack
                    let mut hits = [(0u32, 0f32); 4];
                    let mut k = 0;
                    while m != 0 {
                        let i = m.trailing_zeros() as usize;
                        m &= m - 1;
                        let c = n.child[i];
                        if c == EMPTY {
                            continue;
                        }
                        let mut j = k;
                        while j > 0 && hits[j - 1].1 < tn[i] {
                            hits[j] = hits[j - 1];
                            j -= 1;
                        }
                        hits[j] = (c, tn[i]);
                        k += 1;
                    }
                    if k > 0 {
                        // visit the nearest now, stack the others
                        for h in &hits[..k - 1] {
                            self.prefetch(h.0);
                            stack[sp] = MaybeUninit::new(*h);
                            sp += 1;
                        }
                        cur = hits[k - 1].0;
                        continue;
                    }
                }
            }
            // pop the next child that may still hold a closer hit
            loop {
                if sp == 0 {
                    return (best.prim != EMPTY).then_some(best);
                }
                sp -= 1;
                // SAFETY: entries below sp were written above
                let (c, tn) = unsafe { stack[sp].assume_init() };
                if tn <= tmax {
                    cur = c;
                    break;
                }
            }
        }
    }

    /// True when no triangle lies along o + t·d for t ∈ [tmin, tmax] (first hit ends it).
    #[inline]
    pub fn unoccluded(&self, o: Vec3, d: Vec3, tmin: f32, tmax: f32) -> bool {
        #[cfg(target_arch = "x86_64")]
        if let Some(f) = &self.flat8 {
            // SAFETY: flat8 is only built when the CPU has AVX2 and FMA
            return unsafe { f.unoccluded(o, d, tmin, tmax) };
        }
        #[cfg(target_arch = "x86_64")]
        if let Some(w) = &self.wide8 {
            // SAFETY: wide8 is only built when the CPU has AVX2 and FMA
            return unsafe { w.unoccluded(o, d, tmin, tmax) };
        }
        let r = PreparedRay::new(o, d, tmin);
        if self.flat {
            for n in &self.nodes {
                let mut mb = r.boxes(n, tmax).1;
                while mb != 0 {
                    let c = n.child[mb.trailing_zeros() as usize];
                    mb &= mb - 1;
                    if c != EMPTY && r.tris(&self.packs[(c & !LEAF) as usize], tmax).3 != 0 {
                        return false;
                    }
                }
            }
            return true;
        }
        if self.stack_len <= STACK {
            let mut stack = [MaybeUninit::<u32>::uninit(); STACK];
            self.unoccluded_tree(&r, tmax, &mut stack)
        } else {
            let mut stack = vec![MaybeUninit::<u32>::uninit(); self.stack_len];
            self.unoccluded_tree(&r, tmax, &mut stack)
        }
    }

    /// The tree walk of [`Bvh4::unoccluded`] with a stack of at least `stack_len` entries.
    #[inline(always)]
    fn unoccluded_tree(&self, r: &PreparedRay, tmax: f32, stack: &mut [MaybeUninit<u32>]) -> bool {
        debug_assert!(stack.len() >= self.stack_len);
        let mut sp = 0usize;
        let mut cur = self.root;
        loop {
            if cur & LEAF != 0 {
                let p = &self.packs[(cur & !LEAF) as usize];
                if r.tris(p, tmax).3 != 0 {
                    return false;
                }
            } else {
                let n = &self.nodes[cur as usize];
                let mut m = r.boxes(n, tmax).1;
                while m != 0 {
                    let i = m.trailing_zeros() as usize;
                    m &= m - 1;
                    let c = n.child[i];
                    if c != EMPTY {
                        self.prefetch(c);
                        stack[sp] = MaybeUninit::new(c);
                        sp += 1;
                    }
                }
            }
            if sp == 0 {
                return true;
            }
            sp -= 1;
            // SAFETY: entries below sp were written above
            cur = unsafe { stack[sp].assume_init() };
        }
    }
}

/// Inner nodes on the deepest root-to-leaf path of a 4-wide tree.
fn tree_depth(nodes: &[Node4], root: u32) -> usize {
    let mut deepest = 0;
    let mut todo = vec![(root, 0usize)];
    while let Some((c, depth)) = todo.pop() {
        if c & LEAF != 0 || c == EMPTY {
            deepest = deepest.max(depth);
            continue;
        }
        for &ch in &nodes[c as usize].child {
            todo.push((ch, depth + 1));
        }
    }
    deepest
}

/// Number of primitives under each node of the binary BVH.
fn subtree_count(bvh: &obvhs::bvh2::Bvh2, i: usize, count: &mut [u32]) -> u32 {
    let n = &bvh.nodes[i];
    let c = if n.prim_count > 0 {
        n.prim_count
    } else {
        let f = n.first_index as usize;
        subtree_count(bvh, f, count) + subtree_count(bvh, f + 1, count)
    };
    count[i] = c;
    c
}

/// Input triangle indices under binary node `i`.
pub(crate) fn prims_under(bvh: &obvhs::bvh2::Bvh2, i: usize, out: &mut Vec<u32>) {
    let n = &bvh.nodes[i];
    if n.prim_count > 0 {
        let f = n.first_index as usize;
        out.extend_from_slice(&bvh.primitive_indices[f..f + n.prim_count as usize]);
    } else {
        let f = n.first_index as usize;
        prims_under(bvh, f, out);
        prims_under(bvh, f + 1, out);
    }
}

/// A child box padded so that float rounding in the slab test never drops a hit the triangle
/// test would accept.
#[inline]
pub(crate) fn pad_box(a: Vec3, b: Vec3) -> (Vec3, Vec3) {
    let pad = 1e-5 * (b - a).max_element() + 1e-6 * a.abs().max(b.abs()).max_element();
    (a - Vec3::splat(pad), b + Vec3::splat(pad))
}

/// The triangle packs and the BVH order they define (shared by the 4- and 8-wide trees).
pub(crate) struct TriBuilder<'a> {
    pub(crate) tris: &'a [[Vec3; 3]],
    pub(crate) packs: Vec<Pack4>,
    pub(crate) order: Vec<u32>,
}

impl TriBuilder<'_> {
    /// One pack over ≤ 4 input triangles (appended to the BVH order); its reference + box.
    pub(crate) fn pack_over(&mut self, prims: &[u32]) -> ChildBox {
        debug_assert!(prims.len() <= 4);
        let mut p = Pack4 {
            v0: [Vec4::ZERO; 3],
            e1: [Vec4::ZERO; 3],
            e2: [Vec4::ZERO; 3],
            prim: [EMPTY; 4],
        };
        let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        let mut a = [[[0f32; 4]; 3]; 3];
        for (l, &ti) in prims.iter().enumerate() {
            let t = &self.tris[ti as usize];
            let (e1, e2) = (t[1] - t[0], t[2] - t[0]);
            for ax in 0..3 {
                a[0][ax][l] = t[0][ax];
                a[1][ax][l] = e1[ax];
                a[2][ax][l] = e2[ax];
            }
            for v in t {
                lo = lo.min(*v);
                hi = hi.max(*v);
            }
            p.prim[l] = self.order.len() as u32;
            self.order.push(ti);
        }
        for ax in 0..3 {
            p.v0[ax] = Vec4::from_array(a[0][ax]);
            p.e1[ax] = Vec4::from_array(a[1][ax]);
            p.e2[ax] = Vec4::from_array(a[2][ax]);
        }
        self.packs.push(p);
        ((self.packs.len() - 1) as u32 | LEAF, lo, hi)
    }
}

struct Builder<'a> {
    tb: TriBuilder<'a>,
    nodes: Vec<Node4>,
}

/// A child reference with its box.
type ChildBox = (u32, Vec3, Vec3);

impl Builder<'_> {
    /// Collapse binary node `i` into a 4-wide child (a pack when ≤ 4 triangles lie below).
    fn collapse(&mut self, bvh: &obvhs::bvh2::Bvh2, count: &[u32], i: usize) -> ChildBox {
        if count[i] <= 4 || bvh.nodes[i].prim_count > 0 {
            let mut prims = Vec::new();
            prims_under(bvh, i, &mut prims);
            return self.child_over(&prims);
        }
        let kids = open_children(bvh, count, i, 4);
        let idx = self.push_node();
        let children: Vec<ChildBox> = kids.iter().map(|&k| self.collapse(bvh, count, k)).collect();
        self.fill_node(idx, &children)
    }

    fn push_node(&mut self) -> usize {
        self.nodes.push(Node4 {
            min: [Vec4::ZERO; 3],
            max: [Vec4::ZERO; 3],
            child: [EMPTY; 4],
        });
        self.nodes.len() - 1
    }

    /// Store ≤ 4 children in node `idx` (boxes padded so that float rounding in the slab test
    /// never drops a hit the triangle test would accept); returns the node's reference + box.
    fn fill_node(&mut self, idx: usize, children: &[ChildBox]) -> ChildBox {
        let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        let mut mn = [[0f32; 4]; 3];
        let mut mx = [[0f32; 4]; 3];
        let n = &mut self.nodes[idx];
        for (c, &(r, a, b)) in children.iter().enumerate() {
            let (a, b) = pad_box(a, b);
            for ax in 0..3 {
                mn[ax][c] = a[ax];
                mx[ax][c] = b[ax];
            }
            n.child[c] = r;
            lo = lo.min(a);
            hi = hi.max(b);
        }
        for c in children.len()..4 {
            // an empty slot: an inverted box (never counted: child is EMPTY)
            for ax in 0..3 {
                mn[ax][c] = f32::INFINITY;
                mx[ax][c] = f32::NEG_INFINITY;
            }
        }
        for ax in 0..3 {
            n.min[ax] = Vec4::from_array(mn[ax]);
            n.max[ax] = Vec4::from_array(mx[ax]);
        }
        (idx as u32, lo, hi)
    }

    /// A child over an arbitrary list of input triangles: one pack when ≤ 4, else a node over
    /// ≤ 4 groups (in list order; only reached for leaves the binary builder left large).
    fn child_over(&mut self, prims: &[u32]) -> ChildBox {
        if prims.len() <= 4 {
            return self.tb.pack_over(prims);
        }
        let idx = self.push_node();
        let per = prims.len().div_ceil(4);
        let children: Vec<ChildBox> = prims.chunks(per).map(|c| self.child_over(c)).collect();
        self.fill_node(idx, &children)
    }
}

/// The binary nodes that become the children of a `width`-wide node collapsed from binary
/// inner node `i`: starting from its two children, open the largest-area inner child with
/// more than 4 triangles below until there are `width` (or none is left to open).
pub(crate) fn open_children(
    bvh: &obvhs::bvh2::Bvh2,
    count: &[u32],
    i: usize,
    width: usize,
) -> Vec<usize> {
    let f = bvh.nodes[i].first_index as usize;
    let mut kids = vec![f, f + 1];
    while kids.len() < width {
        let open = kids
            .iter()
            .enumerate()
            .filter(|(_, &k)| count[k] > 4 && bvh.nodes[k].prim_count == 0)
            .max_by(|a, b| {
                let area = |k: usize| bvh.nodes[k].aabb.half_area();
                area(*a.1).total_cmp(&area(*b.1))
            })
            .map(|(j, _)| j);
        let Some(j) = open else { break };
        let k = kids.swap_remove(j);
        let g = bvh.nodes[k].first_index as usize;
        kids.push(g);
        kids.push(g + 1);
    }
    kids
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::TriGeom;
    use obvhs::ray::Ray;

    fn lcg(s: &mut u64) -> f32 {
        *s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (*s >> 40) as f32 / (1u64 << 24) as f32
    }

    /// A degenerate-depth tree (triangles at x = 1.12^k: the binary BVH is close to a chain,
    /// too deep for the 4-wide tree's fixed traversal stack) is traversed with a heap stack
    /// sized from its depth and finds the right hits: a ray shot down onto a triangle hits it
    /// at the right distance, a ray beside all of them misses (the 8-wide tree, when the CPU
    /// has AVX2, fits its stack here and is checked the same way).
    #[test]
    fn deep_tree_uses_a_heap_stack() {
        let n = 700;
        let tris: Vec<[Vec3; 3]> = (0..n)
            .map(|k| {
                // in the plane z = 0, spanning x ± 0.04 x: no two overlap in x
                let x = 1.12f32.powi(k);
                let s = 0.04 * x;
                [
                    Vec3::new(x - s, -s, 0.0),
                    Vec3::new(x + s, -s, 0.0),
                    Vec3::new(x, s, 0.0),
                ]
            })
            .collect();
        for simd8 in [false, true] {
            let bvh = Bvh4::build_with(&tris, simd8);
            if !bvh.uses_simd8() {
                assert!(
                    bvh.stack_len > STACK,
                    "depth {}: the test does not reach the heap stack",
                    (bvh.stack_len - 1) / 3
                );
            }
            // (beyond x ≈ 10¹⁴ the Möller–Trumbore products, ∝ size³, overflow f32, in the
            // tree as in the scalar test, so no ray aims there)
            for &k in &[0usize, 1, 100, 200, 250] {
                let t = tris[k];
                let c = (t[0] + t[1] + t[2]) / 3.0;
                // straight down onto the centroid from 0.05 x above it
                let o = Vec3::new(c.x, c.y, 0.05 * c.x);
                let d = Vec3::new(0.0, 0.0, -1.0);
                let h = bvh.intersect(o, d, 0.0, f32::INFINITY).expect("a hit");
                assert_eq!(bvh.order[h.prim as usize] as usize, k, "triangle {k}");
                assert!((h.t - 0.05 * c.x).abs() <= 1e-5 * c.x);
                assert!(!bvh.unoccluded(o, d, 0.0, f32::INFINITY));
                // beside the triangle (outside its span in y): nothing in the way
                let o2 = Vec3::new(c.x, 0.5 * c.x, 0.05 * c.x);
                assert!(bvh.intersect(o2, d, 0.0, f32::INFINITY).is_none());
                assert!(bvh.unoccluded(o2, d, 0.0, f32::INFINITY));
            }
        }
    }

    /// The BVH (flat packs up to 64 triangles — 4-wide portable and 8-wide AVX2 when the CPU
    /// has it —, the 4-wide or, with AVX2, 8-wide tree above) agrees with brute force over
    /// every triangle with the scalar test: closest hit t, triangle barycentrics, and occlusion.
    #[test]
    fn bvh4_matches_brute_force() {
        let mut s = 7u64;
        for n in [1usize, 3, 4, 5, 17, 36, 64, 65, 300, 3000] {
            let tris: Vec<[Vec3; 3]> = (0..n)
                .map(|_| {
                    let c = Vec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * 4.0 - 2.0;
                    let mut r = || Vec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) - 0.5;
                    [c + 1.5 * r(), c + 1.5 * r(), c + 1.5 * r()]
                })
                .collect();
            for simd8 in [false, true] {
                let bvh = Bvh4::build_with(&tris, simd8);
                if n <= FLAT_MAX_TRIS {
                    #[cfg(target_arch = "x86_64")]
                    assert_eq!(
                        bvh.uses_simd8(),
                        simd8 && crate::bvh8_flat::Flat8::supported()
                    );
                } else {
                    // the 8-wide AVX2 tree (render/src/bvh8_tree.rs) when the CPU has it
                    #[cfg(target_arch = "x86_64")]
                    assert_eq!(
                        bvh.uses_simd8(),
                        simd8 && crate::bvh8_tree::Bvh8::supported()
                    );
                }
                let mut sorted = bvh.order.clone();
                sorted.sort();
                assert_eq!(sorted, (0..n as u32).collect::<Vec<_>>());
                let geo: Vec<TriGeom> = bvh
                    .order
                    .iter()
                    .map(|&i| {
                        let t = tris[i as usize];
                        TriGeom {
                            v0: t[0].into(),
                            e1: (t[1] - t[0]).into(),
                            e2: (t[2] - t[0]).into(),
                        }
                    })
                    .collect();
                let mut hits = 0;
                for _ in 0..2000 {
                    let o = Vec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * 8.0 - 4.0;
                    // aimed at the triangle cloud so that most rays hit something
                    let aim = Vec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * 4.0 - 2.0;
                    let d = (aim - o).normalize();
                    let tmax = if lcg(&mut s) < 0.5 {
                        f32::INFINITY
                    } else {
                        3.0
                    };
                    let ray = Ray::new(o.into(), d.into(), 0.0, tmax);
                    let (mut bt, mut bp) = (f32::INFINITY, EMPTY);
                    for (i, g) in geo.iter().enumerate() {
                        let t = g.intersect(&ray);
                        if t < bt {
                            bt = t;
                            bp = i as u32;
                        }
                    }
                    let h = bvh.intersect(o, d, 0.0, tmax);
                    match h {
                        Some(h) => {
                            hits += 1;
                            assert!(bp != EMPTY, "n {n}: BVH hit where brute force missed");
                            assert!(
                                (h.t - bt).abs() <= 1e-5 * bt.max(1.0),
                                "n {n}: t {} vs {bt}",
                                h.t
                            );
                            let b = geo[h.prim as usize].barycentrics(o.into(), d.into());
                            assert!((b - h.bary).length() < 1e-4);
                        }
                        None => assert!(bp == EMPTY, "n {n}: BVH missed a hit at t = {bt}"),
                    }
                    assert_eq!(bvh.unoccluded(o, d, 0.0, tmax), bp == EMPTY);
                }
                if n >= 17 {
                    assert!(
                        hits > 150,
                        "n {n}: only {hits} hits: the test is not testing"
                    );
                }
            }
        }
    }
}
