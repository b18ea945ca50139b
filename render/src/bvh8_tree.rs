//! Ray casting for large scenes (more than 64 triangles, the tree case of [`crate::bvh4`])
//! with 8-wide AVX2 + FMA, chosen at run time when the CPU has both (the portable 4-wide tree
//! runs otherwise).
//!
//! The topology is the same obvhs PLOC binary BVH as the 4-wide tree, collapsed to 8 children
//! per node (the largest child by surface area is opened first, as in Wald et al., "Getting
//! Rid of Packets", 2008): at 10⁶ triangles the tree no longer fits in the L2 cache and each
//! node visit waits on memory, so a wider, shallower tree makes fewer dependent loads per ray
//! (about log₈ instead of log₄ of the triangle count).
//!
//! * A node stores its 8 child boxes as structure-of-arrays (256 bytes, cache-line aligned);
//!   one slab test (Kay & Kajiya 1986) runs on the 8 boxes at once with the same arithmetic
//!   as the 4-wide test, `(bound − o)·(1/d)`, and the hit children are visited nearest first.
//! * Leaves are the 4-wide triangle packs of [`crate::bvh4`] (Möller–Trumbore, the scalar
//!   test's barycentric tolerance), so a hit has the same t, triangle and barycentrics as in
//!   the 4-wide tree.
//! * The children waiting on the traversal stack are prefetched; shadow rays stop at the first
//!   hit.
#![cfg(target_arch = "x86_64")]

use crate::bvh4::{Bvh4Hit, Pack4, PreparedRay, TriBuilder, EMPTY, LEAF};
use glam::{Vec2, Vec3};
use std::arch::x86_64::*;
use std::mem::MaybeUninit;

/// Traversal stack depth (each level pushes ≤ 7 entries).
const STACK: usize = 512;

/// 8 child boxes, structure-of-arrays.
#[repr(C, align(64))]
#[derive(Debug, Clone, Copy)]
struct Node8 {
    /// Child box minima per axis, one lane per child (padded; empty lanes never hit).
    min: [[f32; 8]; 3],
    /// Child box maxima.
    max: [[f32; 8]; 3],
    /// Child references: node index, LEAF | pack index, or EMPTY.
    child: [u32; 8],
    /// Lanes that hold a child.
    valid: u32,
}

/// An 8-wide BVH over triangles in BVH order (the order is returned by [`Bvh8::build`] and
/// kept once, in [`crate::bvh4::Bvh4::order`]).
#[derive(Debug, Clone)]
pub struct Bvh8 {
    nodes: Vec<Node8>,
    packs: Vec<Pack4>,
    root: u32,
}

/// A ray splatted over 8 lanes for the box test.
struct Ray8 {
    o: [__m256; 3],
    inv: [__m256; 3],
    tmin: __m256,
}

impl Bvh8 {
    /// True when this CPU runs the 8-wide code.
    pub fn supported() -> bool {
        is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma")
    }

    /// Build from obvhs's binary BVH over `tris` (`count`: triangles under each binary node);
    /// also returns the BVH order (input index of each triangle in BVH order).
    pub(crate) fn build(
        tris: &[[Vec3; 3]],
        bvh2: &obvhs::bvh2::Bvh2,
        count: &[u32],
    ) -> (Bvh8, Vec<u32>) {
        let mut b = Builder8 {
            tb: TriBuilder {
                tris,
                packs: Vec::new(),
                order: Vec::with_capacity(tris.len()),
            },
            nodes: Vec::new(),
        };
        let root = b.collapse(bvh2, count, 0).0;
        (
            Bvh8 {
                // read at scattered places while tracing: in huge pages (render/src/huge_pages.rs)
                nodes: crate::huge_pages::copy(&b.nodes),
                packs: crate::huge_pages::copy(&b.tb.packs),
                root,
            },
            b.tb.order,
        )
    }

    /// True when every root-to-leaf path fits the fixed traversal stack (each level stacks at
    /// most 7 children); a deeper tree (a pathological obvhs build) is not used, and the
    /// portable 4-wide tree traces instead.
    pub(crate) fn fits_stack(&self) -> bool {
        let max_depth = (STACK - 1) / 7;
        let mut todo = vec![(self.root, 1usize)];
        while let Some((c, depth)) = todo.pop() {
            if depth > max_depth {
                return false;
            }
            if c & LEAF != 0 || c == EMPTY {
                continue;
            }
            let n = &self.nodes[c as usize];
            for (i, ch) in n.child.iter().enumerate() {
                if n.valid & (1 << i) != 0 {
                    todo.push((*ch, depth + 1));
                }
            }
        }
        true
    }

    /// Ask the memory system for child `c` ahead of its visit.
    #[inline(always)]
    fn prefetch(&self, c: u32) {
        let (p, lines) = if c & LEAF != 0 {
            (
                self.packs.as_ptr().wrapping_add((c & !LEAF) as usize) as *const i8,
                3,
            )
        } else {
            (self.nodes.as_ptr().wrapping_add(c as usize) as *const i8, 4)
        };
        for l in 0..lines {
            // SAFETY: a prefetch never faults, whatever the address
            #[allow(unused_unsafe)]
            unsafe {
                _mm_prefetch::<_MM_HINT_T0>(p.wrapping_add(64 * l))
            };
        }
    }

    /// Closest hit along o + t·d with t ∈ [tmin, tmax].
    ///
    /// # Safety
    /// The CPU must support AVX2 and FMA ([`Bvh8::supported`]).
    #[target_feature(enable = "avx2,fma")]
    pub unsafe fn intersect(&self, o: Vec3, d: Vec3, tmin: f32, tmax: f32) -> Option<Bvh4Hit> {
        let r = PreparedRay::new(o, d, tmin);
        let r8 = Ray8::new(&r);
        let mut tmax = tmax;
        let mut best = Bvh4Hit {
            t: f32::INFINITY,
            prim: EMPTY,
            bary: Vec2::ZERO,
        };
        let mut stack = [MaybeUninit::<(u32, f32)>::uninit(); STACK];
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
                let (tnear, mut m) = r8.boxes(n, tmax);
                if m != 0 {
                    let mut tn = [0f32; 8];
                    _mm256_storeu_ps(tn.as_mut_ptr(), tnear);
                    // hit children sorted by entry distance, farthest first onto the stack
                    let mut hits = [(0u32, 0f32); 8];
                    let mut k = 0;
                    while m != 0 {
                        let i = m.trailing_zeros() as usize;
                        m &= m - 1;
                        let mut j = k;
                        while j > 0 && hits[j - 1].1 < tn[i] {
                            hits[j] = hits[j - 1];
                            j -= 1;
                        }
                        hits[j] = (n.child[i], tn[i]);
                        k += 1;
                    }
                    // visit the nearest now, stack (and prefetch) the others
                    for h in &hits[..k - 1] {
                        self.prefetch(h.0);
                        stack[sp] = MaybeUninit::new(*h);
                        sp += 1;
                    }
                    cur = hits[k - 1].0;
                    continue;
                }
            }
            // pop the next child that may still hold a closer hit
            loop {
                if sp == 0 {
                    return (best.prim != EMPTY).then_some(best);
                }
                sp -= 1;
                // SAFETY: entries below sp were written above
                let (c, tn) = stack[sp].assume_init();
                if tn <= tmax {
                    cur = c;
                    break;
                }
            }
        }
    }

    /// True when no triangle lies along o + t·d for t ∈ [tmin, tmax] (first hit ends it).
    ///
    /// # Safety
    /// The CPU must support AVX2 and FMA ([`Bvh8::supported`]).
    #[target_feature(enable = "avx2,fma")]
    pub unsafe fn unoccluded(&self, o: Vec3, d: Vec3, tmin: f32, tmax: f32) -> bool {
        let r = PreparedRay::new(o, d, tmin);
        let r8 = Ray8::new(&r);
        let mut stack = [MaybeUninit::<u32>::uninit(); STACK];
        let mut sp = 0usize;
        let mut cur = self.root;
        loop {
            if cur & LEAF != 0 {
                if r.tris(&self.packs[(cur & !LEAF) as usize], tmax).3 != 0 {
                    return false;
                }
            } else {
                let n = &self.nodes[cur as usize];
                let mut m = r8.boxes(n, tmax).1;
                while m != 0 {
                    let i = m.trailing_zeros() as usize;
                    m &= m - 1;
                    let c = n.child[i];
                    self.prefetch(c);
                    stack[sp] = MaybeUninit::new(c);
                    sp += 1;
                }
            }
            if sp == 0 {
                return true;
            }
            sp -= 1;
            // SAFETY: entries below sp were written above
            cur = stack[sp].assume_init();
        }
    }
}

impl Ray8 {
    #[inline]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn new(r: &PreparedRay) -> Ray8 {
        let s = |v: glam::Vec4| _mm256_set1_ps(v.x);
        Ray8 {
            o: [s(r.o[0]), s(r.o[1]), s(r.o[2])],
            inv: [s(r.inv[0]), s(r.inv[1]), s(r.inv[2])],
            tmin: _mm256_set1_ps(r.tmin),
        }
    }

    /// Entry distance per child and the mask of the (valid) children hit within [tmin, tmax];
    /// the same operations per lane as the 4-wide test.
    #[inline]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn boxes(&self, n: &Node8, tmax: f32) -> (__m256, u32) {
        let ld = |a: &[f32; 8]| _mm256_load_ps(a.as_ptr());
        let slab = |ax: usize| {
            let t0 = _mm256_mul_ps(_mm256_sub_ps(ld(&n.min[ax]), self.o[ax]), self.inv[ax]);
            let t1 = _mm256_mul_ps(_mm256_sub_ps(ld(&n.max[ax]), self.o[ax]), self.inv[ax]);
            (_mm256_min_ps(t0, t1), _mm256_max_ps(t0, t1))
        };
        let (nx, fx) = slab(0);
        let (ny, fy) = slab(1);
        let (nz, fz) = slab(2);
        let tnear = _mm256_max_ps(_mm256_max_ps(nx, ny), _mm256_max_ps(nz, self.tmin));
        let tfar = _mm256_min_ps(
            _mm256_min_ps(fx, fy),
            _mm256_min_ps(fz, _mm256_set1_ps(tmax)),
        );
        let hit = _mm256_cmp_ps::<_CMP_LE_OQ>(tnear, tfar);
        (tnear, _mm256_movemask_ps(hit) as u32 & n.valid)
    }
}

/// A child reference with its box.
type ChildBox = (u32, Vec3, Vec3);

struct Builder8<'a> {
    tb: TriBuilder<'a>,
    nodes: Vec<Node8>,
}

impl Builder8<'_> {
    /// Collapse binary node `i` into an 8-wide child (a pack when ≤ 4 triangles lie below).
    fn collapse(&mut self, bvh: &obvhs::bvh2::Bvh2, count: &[u32], i: usize) -> ChildBox {
        if count[i] <= 4 || bvh.nodes[i].prim_count > 0 {
            let mut prims = Vec::new();
            crate::bvh4::prims_under(bvh, i, &mut prims);
            return self.child_over(&prims);
        }
        let kids = crate::bvh4::open_children(bvh, count, i, 8);
        let idx = self.push_node();
        let children: Vec<ChildBox> = kids.iter().map(|&k| self.collapse(bvh, count, k)).collect();
        self.fill_node(idx, &children)
    }

    fn push_node(&mut self) -> usize {
        self.nodes.push(Node8 {
            min: [[0.0; 8]; 3],
            max: [[0.0; 8]; 3],
            child: [EMPTY; 8],
            valid: 0,
        });
        self.nodes.len() - 1
    }

    /// Store ≤ 8 children in node `idx` (boxes padded as in the 4-wide tree).
    fn fill_node(&mut self, idx: usize, children: &[ChildBox]) -> ChildBox {
        let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        let n = &mut self.nodes[idx];
        for (c, &(r, a, b)) in children.iter().enumerate() {
            let (a, b) = crate::bvh4::pad_box(a, b);
            for ax in 0..3 {
                n.min[ax][c] = a[ax];
                n.max[ax][c] = b[ax];
            }
            n.child[c] = r;
            n.valid |= 1 << c;
            lo = lo.min(a);
            hi = hi.max(b);
        }
        (idx as u32, lo, hi)
    }

    /// A child over a list of input triangles: one pack when ≤ 4, else a node over ≤ 8 groups
    /// (only reached for leaves the binary builder left large).
    fn child_over(&mut self, prims: &[u32]) -> ChildBox {
        if prims.len() <= 4 {
            return self.tb.pack_over(prims);
        }
        let idx = self.push_node();
        let per = prims.len().div_ceil(8);
        let children: Vec<ChildBox> = prims.chunks(per).map(|c| self.child_over(c)).collect();
        self.fill_node(idx, &children)
    }
}
