//! Batch real-ray tracing: the same exact trace as [`crate::trace`] for many rays at once, in a
//! structure-of-arrays layout processed [`LANES`] rays at a time so the compiler vectorises
//! every step (AVX-512 / AVX2 code paths with fused multiply-adds are selected at run time on
//! x86-64, a portable path without them elsewhere; a given machine always takes the same path,
//! so results do not depend on the thread count, and paths differ by rounding only).
//!
//! Per wavelength a [`TraceSystem`] holds what the hot loop needs: vertex positions,
//! curvatures, conic factors, the index ratios (glass dispersion is evaluated once, not per
//! ray) and squared clear apertures. Per surface:
//! * intersection with the quadric c(x² + y² + (1+k)z²) − 2z = 0 in the stable form
//!   t = C/(−b + √(b² − A C)) (Spencer & Murty 1962), flat surfaces included (c = 0);
//!   even aspheres fall back to the scalar Newton iteration of [`crate::trace::intersect`];
//! * the unit normal of a sphere, (−c x, −c y, 1 − c z), needs no square root (it is unit on
//!   the sphere); a conic's (−c x, −c y, 1 − (1+k) c z) is normalised;
//! * vector Snell law d' = μ d + (cos θ' − μ cos θ) N (Welford §4.4); total internal
//!   reflection, a miss, leaving a conic's domain, or (with clipping) a semi-diameter or a
//!   backwards step kills the lane;
//! * surfaces with the same medium on both sides (e.g. a stop in air) do not refract.
//!
//! Lost rays are marked, not removed; the arithmetic of a dead lane is discarded.
// The per-lane loops index several parallel arrays on purpose (they vectorise).
#![allow(clippy::needless_range_loop)]
use crate::prescription::LensPrescription;
use crate::trace::{intersect, Clipping, FieldAim, Ray, TracedRay};
use rayon::prelude::*;

/// Rays per vectorised step.
pub const LANES: usize = 32;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Shape {
    /// c = 0.
    Plane,
    /// k = 0.
    Sphere,
    /// k ≠ 0, no aspheric terms.
    Conic,
    /// Aspheric terms: scalar Newton intersection.
    Asphere,
}

/// One surface of a [`TraceSystem`].
#[derive(Debug, Clone, Copy, PartialEq)]
struct Surf {
    z_mm: f64,
    c: f64,
    k1: f64,
    shape: Shape,
    /// Index before / after.
    n1: f64,
    n2: f64,
    mu: f64,
    refracts: bool,
    /// Squared semi-diameter (∞ when none).
    sd2: f64,
}

/// A lens prepared for batch tracing at one wavelength.
#[derive(Debug, Clone)]
pub struct TraceSystem<'a> {
    lens: &'a LensPrescription,
    wavelength_nm: f64,
    surfs: Vec<Surf>,
    z_image_mm: f64,
    stop_index: usize,
}

/// Rays in structure-of-arrays form (lens frame, mm; unit directions).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RayBatch {
    /// Position x.
    pub x: Vec<f64>,
    /// Position y.
    pub y: Vec<f64>,
    /// Position z.
    pub z: Vec<f64>,
    /// Direction cosine L.
    pub l: Vec<f64>,
    /// Direction cosine M.
    pub m: Vec<f64>,
    /// Direction cosine N.
    pub n: Vec<f64>,
    /// Optical path accumulated (mm).
    pub opl: Vec<f64>,
    /// The ray is still alive.
    pub alive: Vec<bool>,
    /// Where the ray crossed the stop surface (x, y); NaN until it does.
    pub stop_x: Vec<f64>,
    /// See `stop_x`.
    pub stop_y: Vec<f64>,
    /// See `stop_x` (z).
    pub stop_z: Vec<f64>,
}

impl RayBatch {
    /// An empty batch with room for `n` rays.
    pub fn with_capacity(n: usize) -> Self {
        let v = || Vec::with_capacity(n);
        RayBatch {
            x: v(),
            y: v(),
            z: v(),
            l: v(),
            m: v(),
            n: v(),
            opl: v(),
            alive: Vec::with_capacity(n),
            stop_x: v(),
            stop_y: v(),
            stop_z: v(),
        }
    }

    /// Number of rays.
    pub fn len(&self) -> usize {
        self.x.len()
    }

    /// True if the batch holds no ray.
    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }

    /// Append a ray.
    pub fn push(&mut self, r: &Ray) {
        self.x.push(r.origin_mm[0]);
        self.y.push(r.origin_mm[1]);
        self.z.push(r.origin_mm[2]);
        self.l.push(r.direction[0]);
        self.m.push(r.direction[1]);
        self.n.push(r.direction[2]);
        self.opl.push(r.opl_mm);
        self.alive.push(true);
        self.stop_x.push(f64::NAN);
        self.stop_y.push(f64::NAN);
        self.stop_z.push(f64::NAN);
    }

    /// The batch of `aim`'s rays through the normalised pupil points `pupil` (the same rays
    /// as [`FieldAim::ray`]; built in parallel).
    pub fn from_pupil(aim: &FieldAim, pupil: &[[f64; 2]]) -> Self {
        let mut b = RayBatch::with_capacity(pupil.len());
        b.fill_from_pupil(aim, pupil);
        b
    }

    /// Refill this batch with `aim`'s rays through `pupil` (as [`RayBatch::from_pupil`]),
    /// reusing its buffers: a streaming caller that keeps one batch per thread allocates
    /// nothing per block. Large batches are filled in parallel.
    pub fn fill_from_pupil(&mut self, aim: &FieldAim, pupil: &[[f64; 2]]) {
        let n = pupil.len();
        for v in [
            &mut self.x,
            &mut self.y,
            &mut self.z,
            &mut self.l,
            &mut self.m,
            &mut self.n,
            &mut self.opl,
        ] {
            // Every element is overwritten by the generation below.
            v.truncate(n);
            v.resize(n, 0.0);
        }
        for v in [&mut self.stop_x, &mut self.stop_y, &mut self.stop_z] {
            v.clear();
            v.resize(n, f64::NAN);
        }
        self.alive.clear();
        self.alive.resize(n, true);
        const BLOCK: usize = 4096;
        let gen = GenParams::new(aim);
        if n <= BLOCK {
            gen.fill(
                aim,
                pupil,
                &mut self.x,
                &mut self.y,
                &mut self.z,
                &mut self.l,
                &mut self.m,
                &mut self.n,
                &mut self.opl,
            );
            return;
        }
        self.x
            .par_chunks_mut(BLOCK)
            .zip(self.y.par_chunks_mut(BLOCK))
            .zip(self.z.par_chunks_mut(BLOCK))
            .zip(self.l.par_chunks_mut(BLOCK))
            .zip(self.m.par_chunks_mut(BLOCK))
            .zip(self.n.par_chunks_mut(BLOCK))
            .zip(self.opl.par_chunks_mut(BLOCK))
            .zip(pupil.par_chunks(BLOCK))
            .for_each(|(((((((x, y), z), l), m), nn), opl), pp)| {
                gen.fill(aim, pp, x, y, z, l, m, nn, opl);
            });
    }

    /// Ray `i` as a [`TracedRay`] (`None` if lost).
    pub fn get(&self, i: usize) -> Option<TracedRay> {
        self.alive[i].then(|| TracedRay {
            image_mm: [self.x[i], self.y[i], self.z[i]],
            direction: [self.l[i], self.m[i], self.n[i]],
            opl_mm: self.opl[i],
            stop_mm: [self.stop_x[i], self.stop_y[i], self.stop_z[i]],
        })
    }

    /// Rays that reached the image.
    pub fn count_alive(&self) -> usize {
        self.alive.iter().filter(|a| **a).count()
    }
}

/// Per-field constants of ray generation from normalised pupil points.
struct GenParams {
    r: f64,
    st: f64,
    ct: f64,
    zs: f64,
    ze: f64,
    ay: f64,
}

impl GenParams {
    fn new(aim: &FieldAim) -> Self {
        let (st, ct) = aim.field_deg.to_radians().sin_cos();
        GenParams {
            r: aim.entrance_pupil_radius_mm,
            st,
            ct,
            zs: aim.start_z_mm(),
            ze: aim.entrance_pupil_z_mm,
            ay: aim.aim_y_mm,
        }
    }

    /// Rays through the pupil points `pp` into the given slices (all of `pp`'s length).
    #[allow(clippy::too_many_arguments)]
    fn fill(
        &self,
        aim: &FieldAim,
        pp: &[[f64; 2]],
        x: &mut [f64],
        y: &mut [f64],
        z: &mut [f64],
        l: &mut [f64],
        m: &mut [f64],
        nn: &mut [f64],
        opl: &mut [f64],
    ) {
        let GenParams {
            r, st, ct, zs, ze, ..
        } = *self;
        if aim.object_distance_mm.is_some() {
            for (i, p) in pp.iter().enumerate() {
                let ray = aim.ray(p[0], p[1]);
                x[i] = ray.origin_mm[0];
                y[i] = ray.origin_mm[1];
                z[i] = ray.origin_mm[2];
                l[i] = ray.direction[0];
                m[i] = ray.direction[1];
                nn[i] = ray.direction[2];
                opl[i] = ray.opl_mm;
            }
            return;
        }
        // Collimated: the direction is the field's; the start point lies on the plane
        // z = start_z (as `FieldAim::ray`). Branch-free, so it vectorises.
        let s = (ze - zs) / ct;
        let n = pp.len();
        let (x, y, z) = (&mut x[..n], &mut y[..n], &mut z[..n]);
        let (l, m, nn, opl) = (&mut l[..n], &mut m[..n], &mut nn[..n], &mut opl[..n]);
        for (i, p) in pp.iter().enumerate() {
            let (ex, ey) = (p[0] * r, aim.aim_y_mm + p[1] * r);
            x[i] = ex;
            y[i] = ey - s * st;
            z[i] = ze - s * ct;
            l[i] = 0.0;
            m[i] = st;
            nn[i] = ct;
            opl[i] = ey * st + (ze - zs) * ct - s;
        }
    }
}

/// Rays to generate from pupil points instead of loading them (collimated fields only).
type Src<'p> = Option<(&'p GenParams, &'p [[f64; 2]])>;

/// Mutable views of one chunk of a batch.
struct Chunk<'b> {
    x: &'b mut [f64],
    y: &'b mut [f64],
    z: &'b mut [f64],
    l: &'b mut [f64],
    m: &'b mut [f64],
    n: &'b mut [f64],
    opl: &'b mut [f64],
    alive: &'b mut [bool],
    sx: &'b mut [f64],
    sy: &'b mut [f64],
    sz: &'b mut [f64],
}

impl<'a> TraceSystem<'a> {
    /// Prepare `lens` for tracing at `wavelength_nm`.
    pub fn new(lens: &'a LensPrescription, wavelength_nm: f64) -> Self {
        let zs = lens.vertex_z_mm();
        let mut n1 = 1.0;
        let surfs = lens
            .surfaces
            .iter()
            .enumerate()
            .map(|(j, s)| {
                let n2 = s.medium.index(wavelength_nm);
                let shape = if !s.is_conic_only() {
                    Shape::Asphere
                } else if s.curvature_per_mm == 0.0 {
                    Shape::Plane
                } else if s.conic == 0.0 {
                    Shape::Sphere
                } else {
                    Shape::Conic
                };
                let out = Surf {
                    z_mm: zs[j],
                    c: s.curvature_per_mm,
                    k1: 1.0 + s.conic,
                    shape,
                    n1,
                    n2,
                    mu: n1 / n2,
                    refracts: n1 != n2,
                    sd2: s.semi_diameter_mm.map_or(f64::INFINITY, |d| d * d),
                };
                n1 = n2;
                out
            })
            .collect();
        TraceSystem {
            lens,
            wavelength_nm,
            surfs,
            z_image_mm: zs[lens.surfaces.len()],
            stop_index: lens.stop_index,
        }
    }

    /// The wavelength (nm).
    pub fn wavelength_nm(&self) -> f64 {
        self.wavelength_nm
    }

    /// Trace every ray of `batch` to the image plane in place (rayon over blocks of rays;
    /// the result does not depend on the thread count).
    pub fn trace(&self, batch: &mut RayBatch, clipping: Clipping) {
        const BLOCK: usize = 64 * LANES;
        let clip = clipping == Clipping::SemiDiameters;
        let RayBatch {
            x,
            y,
            z,
            l,
            m,
            n,
            opl,
            alive,
            stop_x,
            stop_y,
            stop_z,
        } = batch;
        if x.len() <= BLOCK {
            // One block: trace it on this thread (no task overhead for streaming callers).
            let mut c = Chunk {
                x,
                y,
                z,
                l,
                m,
                n,
                opl,
                alive,
                sx: stop_x,
                sy: stop_y,
                sz: stop_z,
            };
            self.trace_block(&mut c, clip, None);
            return;
        }
        x.par_chunks_mut(BLOCK)
            .zip(y.par_chunks_mut(BLOCK))
            .zip(z.par_chunks_mut(BLOCK))
            .zip(l.par_chunks_mut(BLOCK))
            .zip(m.par_chunks_mut(BLOCK))
            .zip(n.par_chunks_mut(BLOCK))
            .zip(opl.par_chunks_mut(BLOCK))
            .zip(alive.par_chunks_mut(BLOCK))
            .zip(stop_x.par_chunks_mut(BLOCK))
            .zip(stop_y.par_chunks_mut(BLOCK))
            .zip(stop_z.par_chunks_mut(BLOCK))
            .for_each(
                |((((((((((x, y), z), l), m), n), opl), alive), sx), sy), sz)| {
                    let mut c = Chunk {
                        x,
                        y,
                        z,
                        l,
                        m,
                        n,
                        opl,
                        alive,
                        sx,
                        sy,
                        sz,
                    };
                    self.trace_block(&mut c, clip, None);
                },
            );
    }

    /// Trace `aim`'s rays through the normalised pupil points `pupil`.
    pub fn trace_pupil(&self, aim: &FieldAim, pupil: &[[f64; 2]], clipping: Clipping) -> RayBatch {
        let mut b = RayBatch::from_pupil(aim, pupil);
        self.trace(&mut b, clipping);
        b
    }

    /// As [`TraceSystem::trace_pupil`], into a reused batch (no allocation once its buffers
    /// have grown to the block size).
    pub fn trace_pupil_into(
        &self,
        aim: &FieldAim,
        pupil: &[[f64; 2]],
        clipping: Clipping,
        batch: &mut RayBatch,
    ) {
        const BLOCK: usize = 64 * LANES;
        let n = pupil.len();
        if aim.object_distance_mm.is_some() || n > BLOCK {
            batch.fill_from_pupil(aim, pupil);
            self.trace(batch, clipping);
            return;
        }
        // Collimated block: rays are generated straight into the lane vectors and traced
        // while in registers / L1 (the same rays as `fill_from_pupil`; every element of the
        // batch is written by the store).
        let RayBatch {
            x,
            y,
            z,
            l,
            m,
            n: nn,
            opl,
            alive,
            stop_x,
            stop_y,
            stop_z,
        } = batch;
        for v in [x, y, z, l, m, nn, opl, stop_x, stop_y, stop_z] {
            v.truncate(n);
            v.resize(n, 0.0);
        }
        alive.truncate(n);
        alive.resize(n, false);
        let gen = GenParams::new(aim);
        let mut c = Chunk {
            x: &mut batch.x,
            y: &mut batch.y,
            z: &mut batch.z,
            l: &mut batch.l,
            m: &mut batch.m,
            n: &mut batch.n,
            opl: &mut batch.opl,
            alive: &mut batch.alive,
            sx: &mut batch.stop_x,
            sy: &mut batch.stop_y,
            sz: &mut batch.stop_z,
        };
        self.trace_block(
            &mut c,
            clipping == Clipping::SemiDiameters,
            Some((&gen, pupil)),
        );
    }

    fn trace_block(&self, c: &mut Chunk<'_>, clip: bool, src: Src<'_>) {
        if self.lens.has_folds() {
            self.trace_block_folded(c, clip, src);
            return;
        }
        #[cfg(target_arch = "x86_64")]
        {
            let fma = std::arch::is_x86_feature_detected!("fma");
            if fma && std::arch::is_x86_feature_detected!("avx512f") {
                // SAFETY: the CPU supports AVX-512F and FMA (checked above).
                unsafe { self.trace_block_avx512(c, clip, src) };
                return;
            }
            if fma && std::arch::is_x86_feature_detected!("avx2") {
                // SAFETY: the CPU supports AVX2 and FMA (checked above).
                unsafe { self.trace_block_avx2(c, clip, src) };
                return;
            }
        }
        self.trace_block_generic::<false>(c, clip, src);
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f,fma")]
    unsafe fn trace_block_avx512(&self, c: &mut Chunk<'_>, clip: bool, src: Src<'_>) {
        self.trace_block_generic::<true>(c, clip, src);
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn trace_block_avx2(&self, c: &mut Chunk<'_>, clip: bool, src: Src<'_>) {
        self.trace_block_generic::<true>(c, clip, src);
    }

    /// Lenses with mirrors or coordinate breaks: the rays of the block one by one through
    /// [`LensPrescription::trace`] (the folded trace of [`crate::fold`]).
    fn trace_block_folded(&self, c: &mut Chunk<'_>, clip: bool, src: Src<'_>) {
        let len = c.x.len();
        if let Some((g, pp)) = src {
            let mut i = 0;
            while i < len {
                let k = (len - i).min(LANES);
                Lanes::generate(g, &pp[i..i + k]).store(c, i, k);
                i += k;
            }
        }
        let clipping = if clip {
            Clipping::SemiDiameters
        } else {
            Clipping::None
        };
        for i in 0..len {
            if !c.alive[i] {
                continue;
            }
            let ray = Ray {
                origin_mm: [c.x[i], c.y[i], c.z[i]],
                direction: [c.l[i], c.m[i], c.n[i]],
                opl_mm: c.opl[i],
            };
            match self.lens.trace(&ray, self.wavelength_nm, clipping) {
                Some(t) => {
                    [c.x[i], c.y[i], c.z[i]] = t.image_mm;
                    [c.l[i], c.m[i], c.n[i]] = t.direction;
                    c.opl[i] = t.opl_mm;
                    [c.sx[i], c.sy[i], c.sz[i]] = t.stop_mm;
                }
                None => c.alive[i] = false,
            }
        }
    }

    #[inline(always)]
    fn trace_block_generic<const FMA: bool>(&self, c: &mut Chunk<'_>, clip: bool, src: Src<'_>) {
        let len = c.x.len();
        let mut i = 0;
        while i < len {
            let k = (len - i).min(LANES);
            let mut v = match src {
                Some((g, pp)) => Lanes::generate(g, &pp[i..i + k]),
                None => Lanes::load(c, i, k),
            };
            self.trace_lanes::<FMA>(&mut v, clip);
            v.store(c, i, k);
            i += k;
        }
    }

    #[inline(always)]
    fn trace_lanes<const FMA: bool>(&self, v: &mut Lanes, clip: bool) {
        // One fused loop per surface, specialised at compile time for the surface's shape,
        // refraction and clipping (a sphere carries no conic terms, a stop in air no Snell
        // step); the loop over LANES lanes is unrolled into LANES/8 (AVX-512) independent
        // vectors that overlap in the pipeline.
        for (j, s) in self.surfs.iter().enumerate() {
            match (s.shape, s.refracts, clip) {
                (Shape::Asphere, _, _) => self.asphere_lanes(v, j, clip),
                (Shape::Plane, false, false) => surf_lanes::<FMA, 0, false, false>(s, v, j),
                (Shape::Plane, false, true) => surf_lanes::<FMA, 0, false, true>(s, v, j),
                (Shape::Plane, true, false) => surf_lanes::<FMA, 0, true, false>(s, v, j),
                (Shape::Plane, true, true) => surf_lanes::<FMA, 0, true, true>(s, v, j),
                (Shape::Sphere, false, false) => surf_lanes::<FMA, 1, false, false>(s, v, j),
                (Shape::Sphere, false, true) => surf_lanes::<FMA, 1, false, true>(s, v, j),
                (Shape::Sphere, true, false) => surf_lanes::<FMA, 1, true, false>(s, v, j),
                (Shape::Sphere, true, true) => surf_lanes::<FMA, 1, true, true>(s, v, j),
                (Shape::Conic, false, false) => surf_lanes::<FMA, 2, false, false>(s, v, j),
                (Shape::Conic, false, true) => surf_lanes::<FMA, 2, false, true>(s, v, j),
                (Shape::Conic, true, false) => surf_lanes::<FMA, 2, true, false>(s, v, j),
                (Shape::Conic, true, true) => surf_lanes::<FMA, 2, true, true>(s, v, j),
            }
            if j == self.stop_index && s.shape != Shape::Asphere {
                // Every lane's position on the stop (dead lanes' values are discarded).
                v.sx = v.x;
                v.sy = v.y;
                v.sz = v.z;
            }
        }
        // Image plane.
        let n_img = self.surfs.last().map_or(1.0, |s| s.n2);
        for i in 0..LANES {
            v.alive[i] &= mask(v.n[i] > 0.0);
            let t = (self.z_image_mm - v.z[i]) / v.n[i];
            v.x[i] += t * v.l[i];
            v.y[i] += t * v.m[i];
            v.z[i] = self.z_image_mm;
            v.opl[i] += n_img * t;
        }
    }

    /// An even-asphere surface: the scalar Newton intersection and normal per lane.
    fn asphere_lanes(&self, v: &mut Lanes, j: usize, clip: bool) {
        let s = &self.surfs[j];
        let surf = &self.lens.surfaces[j];
        let lim = s.sd2 * (1.0 + 1e-12);
        for i in 0..LANES {
            let r = Ray {
                origin_mm: [v.x[i], v.y[i], v.z[i]],
                direction: [v.l[i], v.m[i], v.n[i]],
                opl_mm: 0.0,
            };
            let hit = if v.alive[i] != 0 {
                intersect(surf, s.z_mm, &r)
            } else {
                None
            };
            let Some((t, q)) = hit else {
                v.alive[i] = 0;
                continue;
            };
            let local = [q[0], q[1], q[2] - s.z_mm];
            let r2 = q[0] * q[0] + q[1] * q[1];
            if clip && ((t < -1e-9 && j > 0) || r2 > lim) {
                v.alive[i] = 0;
            }
            v.opl[i] += s.n1 * t;
            v.x[i] = q[0];
            v.y[i] = q[1];
            v.z[i] = q[2];
            if j == self.stop_index {
                v.sx[i] = q[0];
                v.sy[i] = q[1];
                v.sz[i] = q[2];
            }
            if s.refracts {
                match crate::trace::normal(surf, local) {
                    Some(nn) => {
                        let (l, m, n, good) = refract_lane::<false>(
                            s.mu,
                            r.direction[0],
                            r.direction[1],
                            r.direction[2],
                            nn[0],
                            nn[1],
                            nn[2],
                        );
                        v.alive[i] &= good;
                        v.l[i] = l;
                        v.m[i] = m;
                        v.n[i] = n;
                    }
                    None => v.alive[i] = 0,
                }
            }
        }
    }
}

/// One plane (`SHAPE` 0), sphere (1) or conic (2) surface for every lane of `v` (surface `j`):
/// intersection, domain / clipping tests, transfer and (when `REFR`) refraction, in one loop.
#[inline(always)]
fn surf_lanes<const FMA: bool, const SHAPE: u8, const REFR: bool, const CLIP: bool>(
    s: &Surf,
    v: &mut Lanes,
    j: usize,
) {
    let fma = madd::<FMA>;
    let back_ok = j == 0;
    let lim = s.sd2 * (1.0 + 1e-12);
    let kc2 = s.k1 * s.c * s.c;
    let ck = s.c * s.k1;
    // Two loops (intersection + transfer, then refraction): each has one long dependency
    // chain through the divider, and a loop this short is unrolled into independent
    // vectors; a single fused loop was latency-bound.
    let mut qz_lanes = [0.0f64; LANES];
    for i in 0..LANES {
        let px = v.x[i];
        let py = v.y[i];
        let pz = v.z[i] - s.z_mm;
        let (dx, dy, dz) = (v.l[i], v.m[i], v.n[i]);
        let (t, mut ok) = if SHAPE == 0 {
            (-pz / dz, mask(dz != 0.0))
        } else {
            // c(x² + y² + (1+k)z²) − 2z = 0 along p + t d: t = C/(−B + √(B² − A C))
            // (Spencer & Murty 1962); a sphere has k1 = 1.
            let k1 = if SHAPE == 1 { 1.0 } else { s.k1 };
            let a = s.c * fma(dx, dx, fma(dy, dy, k1 * dz * dz));
            let b = fma(s.c, fma(px, dx, fma(py, dy, k1 * pz * dz)), -dz);
            let cc = fma(s.c, fma(px, px, fma(py, py, k1 * pz * pz)), -2.0 * pz);
            let disc = fma(b, b, -(a * cc));
            let den = -b + pos(disc).sqrt();
            (cc / den, mask(disc >= 0.0) & mask(den != 0.0))
        };
        let qx = fma(t, dx, px);
        let qy = fma(t, dy, py);
        let qz = fma(t, dz, pz);
        if SHAPE != 0 {
            // Stay inside the conic's domain 1 − (1+k)c²r² ≥ 0 (as the scalar trace).
            let r2 = qx * qx + qy * qy;
            ok &= mask(1.0 - kc2 * r2 >= 0.0);
        }
        if CLIP {
            let r2 = qx * qx + qy * qy;
            ok &= mask(back_ok | (t >= -1e-9)) & mask(r2 <= lim);
        }
        v.opl[i] += s.n1 * t;
        v.x[i] = qx;
        v.y[i] = qy;
        v.z[i] = qz + s.z_mm;
        qz_lanes[i] = qz;
        v.alive[i] &= ok;
    }
    if !REFR {
        return;
    }
    for i in 0..LANES {
        let (qx, qy, qz) = (v.x[i], v.y[i], qz_lanes[i]);
        let (dx, dy, dz) = (v.l[i], v.m[i], v.n[i]);
        {
            // Unit normal oriented towards +z: (−c x, −c y, 1 − (1+k) c z), unit on a
            // sphere, normalised for a conic; (0, 0, 1) on a plane.
            let (nx, ny, nz) = match SHAPE {
                0 => (0.0, 0.0, 1.0),
                1 => (-s.c * qx, -s.c * qy, 1.0 - s.c * qz),
                _ => {
                    let (nx, ny, nz) = (-s.c * qx, -s.c * qy, 1.0 - ck * qz);
                    let inv = 1.0 / (nx * nx + ny * ny + nz * nz).sqrt();
                    (nx * inv, ny * inv, nz * inv)
                }
            };
            let (l, m, n, good) = refract_lane::<FMA>(s.mu, dx, dy, dz, nx, ny, nz);
            v.alive[i] &= good;
            v.l[i] = l;
            v.m[i] = m;
            v.n[i] = n;
        }
    }
}

/// a·b + c: fused (one rounding) on the FMA code paths, separately rounded otherwise.
#[inline(always)]
fn madd<const FMA: bool>(a: f64, b: f64, c: f64) -> f64 {
    if FMA {
        a.mul_add(b, c)
    } else {
        a * b + c
    }
}

/// Lane mask: all ones when `b`.
#[inline(always)]
fn mask(b: bool) -> u64 {
    (b as u64).wrapping_neg()
}

/// max(x, 0) written as a select (vectorises; NaN → 0).
#[inline(always)]
fn pos(x: f64) -> f64 {
    if x > 0.0 {
        x
    } else {
        0.0
    }
}

/// Vector Snell law for a unit direction d and unit normal N with μ = n/n': the refracted
/// direction μ d + (cos θ' − μ cos θ) N (N flipped to the side of d) and the mask of "no
/// total internal reflection".
#[inline(always)]
fn refract_lane<const FMA: bool>(
    mu: f64,
    dx: f64,
    dy: f64,
    dz: f64,
    nx: f64,
    ny: f64,
    nz: f64,
) -> (f64, f64, f64, u64) {
    let fma = madd::<FMA>;
    let c0 = fma(dx, nx, fma(dy, ny, dz * nz));
    let sgn = if c0 < 0.0 { -1.0 } else { 1.0 };
    let cos_i = c0 * sgn;
    let sin2_t = mu * mu * fma(-cos_i, cos_i, 1.0);
    let cos_t = pos(1.0 - sin2_t).sqrt();
    let g = fma(-mu, cos_i, cos_t) * sgn;
    (
        fma(mu, dx, g * nx),
        fma(mu, dy, g * ny),
        fma(mu, dz, g * nz),
        mask(sin2_t <= 1.0),
    )
}

/// One vector of rays.
struct Lanes {
    x: [f64; LANES],
    y: [f64; LANES],
    z: [f64; LANES],
    l: [f64; LANES],
    m: [f64; LANES],
    n: [f64; LANES],
    opl: [f64; LANES],
    /// All ones = alive.
    alive: [u64; LANES],
    sx: [f64; LANES],
    sy: [f64; LANES],
    sz: [f64; LANES],
}

/// `k ≤ LANES` values of `src[i..]` in a vector padded with `pad`.
#[inline(always)]
fn ld(src: &[f64], i: usize, k: usize, pad: f64) -> [f64; LANES] {
    if k == LANES {
        src[i..i + LANES].try_into().unwrap()
    } else {
        let mut a = [pad; LANES];
        a[..k].copy_from_slice(&src[i..i + k]);
        a
    }
}

#[inline(always)]
fn st(dst: &mut [f64], i: usize, k: usize, a: &[f64; LANES]) {
    if k == LANES {
        dst[i..i + LANES].copy_from_slice(a);
    } else {
        dst[i..i + k].copy_from_slice(&a[..k]);
    }
}

impl Lanes {
    /// The collimated rays of `g` through the pupil points `pp` (≤ LANES; as
    /// `GenParams::fill`); unused lanes trace a harmless axial ray and are discarded.
    #[inline(always)]
    fn generate(g: &GenParams, pp: &[[f64; 2]]) -> Self {
        let GenParams {
            r,
            st,
            ct,
            zs,
            ze,
            ay,
        } = *g;
        let s = (ze - zs) / ct;
        let mut v = Lanes {
            x: [0.0; LANES],
            y: [0.0; LANES],
            z: [0.0; LANES],
            l: [0.0; LANES],
            m: [0.0; LANES],
            n: [1.0; LANES],
            opl: [0.0; LANES],
            alive: [0; LANES],
            sx: [f64::NAN; LANES],
            sy: [f64::NAN; LANES],
            sz: [f64::NAN; LANES],
        };
        for (i, p) in pp.iter().enumerate().take(LANES) {
            let (ex, ey) = (p[0] * r, ay + p[1] * r);
            v.x[i] = ex;
            v.y[i] = ey - s * st;
            v.z[i] = ze - s * ct;
            v.m[i] = st;
            v.n[i] = ct;
            v.opl[i] = ey * st + (ze - zs) * ct - s;
            v.alive[i] = u64::MAX;
        }
        v
    }

    /// Unused lanes of a partial vector trace a harmless axial ray and are discarded.
    #[inline(always)]
    fn load(c: &Chunk<'_>, i: usize, k: usize) -> Self {
        let mut alive = [0u64; LANES];
        for (a, b) in alive.iter_mut().zip(&c.alive[i..i + k]) {
            *a = (*b as u64).wrapping_neg();
        }
        Lanes {
            x: ld(c.x, i, k, 0.0),
            y: ld(c.y, i, k, 0.0),
            z: ld(c.z, i, k, 0.0),
            l: ld(c.l, i, k, 0.0),
            m: ld(c.m, i, k, 0.0),
            n: ld(c.n, i, k, 1.0),
            opl: ld(c.opl, i, k, 0.0),
            alive,
            sx: ld(c.sx, i, k, f64::NAN),
            sy: ld(c.sy, i, k, f64::NAN),
            sz: ld(c.sz, i, k, f64::NAN),
        }
    }

    #[inline(always)]
    fn store(&self, c: &mut Chunk<'_>, i: usize, k: usize) {
        st(c.x, i, k, &self.x);
        st(c.y, i, k, &self.y);
        st(c.z, i, k, &self.z);
        st(c.l, i, k, &self.l);
        st(c.m, i, k, &self.m);
        st(c.n, i, k, &self.n);
        st(c.opl, i, k, &self.opl);
        st(c.sx, i, k, &self.sx);
        st(c.sy, i, k, &self.sy);
        st(c.sz, i, k, &self.sz);
        for (b, a) in c.alive[i..i + k].iter_mut().zip(&self.alive) {
            *b = *a != 0;
        }
    }
}

impl LensPrescription {
    /// A [`TraceSystem`] of this lens at `wavelength_nm`.
    pub fn trace_system(&self, wavelength_nm: f64) -> TraceSystem<'_> {
        TraceSystem::new(self, wavelength_nm)
    }
}
