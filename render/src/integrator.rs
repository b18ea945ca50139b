//! Unidirectional spectral path tracing with next-event estimation and multiple importance
//! sampling (Veach 1997, power heuristic β = 2), Russian roulette and hero-wavelength
//! sampling (Wilkie et al. 2014), following the semantics of Mitsuba 3's `path` integrator:
//! `max_depth` counts path segments (1 = emitters seen directly, 2 = direct lighting, −1 =
//! unlimited), Russian roulette from depth `rr_depth` with continuation probability
//! min(max(throughput)·η², 0.95) (Mitsuba's rule). camsim's default `rr_depth` is 2 (roulette
//! from the second bounce; Mitsuba's default is 5): unbiased, it shortens the mean path and
//! trades per-path variance for paths per second (docs/render.md, Performance).
//!
//! Every pixel has its own random stream derived from (seed, pixel index) (core::rng), and
//! each pixel's samples are taken in order by one thread, so the image does not depend on
//! the number of threads.
use crate::camera::{Camera, CameraRay, OutputQuantity};
use crate::sampling::Frame;
use crate::scene::{interpolate_uv, shading_normal, Scene, SpectralTexture};
use crate::spectral::{Bands, TabulatedSpectrum, N_WL};
use camsim_core::rng::{stream, CamRng};
use glam::{Mat4, Vec2, Vec3};
use rand::Rng;
use rayon::prelude::*;
use std::mem::MaybeUninit;
use std::sync::atomic::{AtomicUsize, Ordering};

/// Render settings.
#[derive(Debug, Clone, PartialEq)]
pub struct RenderSettings {
    /// Samples (camera paths) per pixel.
    pub spp: u32,
    /// Seed of every random stream.
    pub seed: u64,
    /// Output bands.
    pub bands: Bands,
    /// Longest path in segments (Mitsuba `max_depth`); −1 = unlimited.
    pub max_depth: i32,
    /// Depth from which Russian roulette applies (Mitsuba `rr_depth`).
    pub rr_depth: u32,
    /// Also estimate the variance of each pixel's estimate per band.
    pub variance: bool,
    /// Jittered rays per pixel for the mean hit distance `depth.T` (0 = skip).
    pub depth_spp: u32,
    /// Environment lighting (an equirectangular EXR); overrides the glTF scene's own
    /// (`extras.camsim_environment_exr`). Applied by [`crate::job::prepare`].
    pub environment: Option<crate::envmap::EnvironmentSpec>,
}

impl Default for RenderSettings {
    fn default() -> Self {
        RenderSettings {
            spp: 64,
            seed: 0,
            bands: Bands::new(380.0, 780.0, 10.0).expect("valid"),
            max_depth: -1,
            rr_depth: 2,
            variance: false,
            depth_spp: 16,
            environment: None,
        }
    }
}

/// The result of a render.
#[derive(Debug, Clone)]
pub struct RenderOutput {
    /// Film width (px).
    pub width: usize,
    /// Film height (px).
    pub height: usize,
    /// The bands of `bands_data`.
    pub bands: Bands,
    /// What the values are: band-averaged radiance W/(m²·sr·nm) or irradiance W/(m²·nm).
    pub quantity: OutputQuantity,
    /// One row-major plane per band.
    pub band_planes: Vec<Vec<f32>>,
    /// Variance of each pixel's estimate (sample variance / spp), per band, when asked for.
    /// The wavelengths are stratified over a pixel's samples, so this i.i.d. estimate is an
    /// upper bound (conservative) for the true variance of the pixel mean.
    pub variance_planes: Option<Vec<Vec<f32>>>,
    /// Planar depth along the viewing axis of the ray through the pixel centre (m); +∞ where
    /// it escapes (OpenEXR `Z`).
    pub depth_z_m: Vec<f32>,
    /// Distance from the camera-ray origin to the first hit of the central ray (m), 0 where
    /// it escapes (harness `depth_center.T`).
    pub depth_center_m: Vec<f32>,
    /// Mean first-hit distance over `depth_spp` jittered rays (m), 0 counted for escapes
    /// (harness `depth.T`); empty when depth_spp = 0.
    pub depth_mean_m: Vec<f32>,
    /// Samples per pixel used.
    pub spp: u32,
    /// Wall-clock time of the radiance pass (s).
    pub render_s: f64,
}

impl RenderOutput {
    /// Camera paths per second of the radiance pass.
    pub fn samples_per_s(&self) -> f64 {
        (self.width * self.height) as f64 * self.spp as f64 / self.render_s.max(1e-9)
    }
}

/// The largest f32 below 1.
const ONE_MINUS_EPS: f32 = 1.0 - f32::EPSILON / 2.0;

#[inline(always)]
fn next_f32(rng: &mut CamRng) -> f32 {
    (rng.next_u32() >> 8) as f32 * (1.0 / 16_777_216.0)
}

#[inline(always)]
fn next_vec2(rng: &mut CamRng) -> Vec2 {
    // two 24-bit uniforms from the high and low halves of one 64-bit output
    let x = rng.next_u64();
    const K: f32 = 1.0 / 16_777_216.0;
    Vec2::new((x >> 40) as f32 * K, ((x >> 8) & 0xFF_FFFF) as f32 * K)
}

/// Fisher–Yates shuffle of `p` in place (a uniformly random permutation).
#[inline]
fn shuffle(p: &mut [u32], rng: &mut CamRng) {
    for i in (1..p.len()).rev() {
        let j = ((rng.next_u32() as u64 * (i as u64 + 1)) >> 32) as usize;
        p.swap(i, j);
    }
}

/// Power heuristic (β = 2).
#[inline(always)]
fn mis(a: f32, b: f32) -> f32 {
    let (a2, b2) = (a * a, b * b);
    if a2 + b2 > 0.0 {
        a2 / (a2 + b2)
    } else {
        0.0
    }
}

/// Offset a ray origin off the surface along the geometric normal, to the side of `dir`.
#[inline(always)]
fn offset_origin(p: Vec3, ng: Vec3, dir: Vec3) -> Vec3 {
    let eps = 5e-5 * (1.0 + p.abs().max_element());
    if ng.dot(dir) >= 0.0 {
        p + ng * eps
    } else {
        p - ng * eps
    }
}

/// A camera ray moved to world space with its clip range.
#[derive(Debug, Clone, Copy)]
struct WorldRay {
    o: Vec3,
    d: Vec3,
    tmin: f32,
    tmax: f32,
}

#[inline]
fn to_world(r: &CameraRay, m: &Mat4, near: f32, far: f32) -> Option<WorldRay> {
    let dz = -r.direction.z;
    let (tmin, tmax) = if dz > 1e-7 {
        let inv = 1.0 / dz;
        (near * inv, far * inv)
    } else {
        (0.0, f32::INFINITY)
    };
    // the camera-to-world matrix is a rotation (scale removed), so the unit camera direction
    // stays unit to rounding: normalise only when it is not
    let d = m.transform_vector3(r.direction);
    let l2 = d.length_squared();
    let d = if (l2 - 1.0).abs() <= 1e-6 {
        d
    } else {
        d / l2.sqrt()
    };
    if !d.is_finite() {
        return None;
    }
    Some(WorldRay {
        o: m.transform_point3(r.origin_m),
        d,
        tmin,
        tmax,
    })
}

/// Materials whose spectral values a path memoises (the first ones of the scene).
const MEMO: u32 = 16;

/// Spectral values of the (first [`MEMO`]) materials at one path's 4 wavelengths, evaluated
/// on first use: a path meets few materials, but each of them many times (every bounce and
/// every light sample). Slots are written before they are read (the `*_ok` bits), so the
/// arrays are not initialised.
struct PathSpectra {
    refl_ok: u32,
    emit_ok: u32,
    refl: [MaybeUninit<[f32; N_WL]>; MEMO as usize],
    emit: [MaybeUninit<[f32; N_WL]>; MEMO as usize],
}

impl PathSpectra {
    #[inline(always)]
    fn new() -> Self {
        PathSpectra {
            refl_ok: 0,
            emit_ok: 0,
            refl: [MaybeUninit::uninit(); MEMO as usize],
            emit: [MaybeUninit::uninit(); MEMO as usize],
        }
    }

    /// Reflectance of material `m` at the hit (texture coordinate from `uv`).
    #[inline(always)]
    fn reflectance(
        &mut self,
        mat: &crate::scene::Material,
        m: u32,
        uv: impl FnOnce() -> Vec2,
        wl: &[f32; N_WL],
    ) -> [f32; N_WL] {
        match &mat.reflectance {
            SpectralTexture::Constant(s) if m < MEMO => {
                if self.refl_ok & (1 << m) == 0 {
                    self.refl[m as usize] = MaybeUninit::new(s.eval4(wl));
                    self.refl_ok |= 1 << m;
                }
                // SAFETY: slot m was written (its bit is set)
                unsafe { self.refl[m as usize].assume_init() }
            }
            t => t.eval(uv(), wl),
        }
    }

    /// Emitted radiance `e` of material `m`.
    #[inline(always)]
    fn emission(&mut self, e: &TabulatedSpectrum, m: u32, wl: &[f32; N_WL]) -> [f32; N_WL] {
        if m >= MEMO {
            return e.eval4(wl);
        }
        if self.emit_ok & (1 << m) == 0 {
            self.emit[m as usize] = MaybeUninit::new(e.eval4(wl));
            self.emit_ok |= 1 << m;
        }
        // SAFETY: slot m was written (its bit is set)
        unsafe { self.emit[m as usize].assume_init() }
    }
}

/// Trace one path carrying 4 wavelengths; returns the radiance per wavelength slot times
/// `beta0` (the camera weight, with the hero-only factor already applied).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn trace_path(
    scene: &Scene,
    ray: WorldRay,
    wl: &[f32; N_WL],
    beta0: [f32; N_WL],
    hero_only0: bool,
    max_depth: u32,
    rr_depth: u32,
    rng: &mut CamRng,
) -> [f32; N_WL] {
    let mut l = [0.0f32; N_WL];
    let mut beta = beta0;
    let mut hero_only = hero_only0;
    let (mut o, mut d, mut tmin, mut tmax) = (ray.o, ray.d, ray.tmin, ray.tmax);
    let mut prev_pdf = 0.0f32;
    let mut prev_delta = true;
    let mut eta2 = 1.0f32;
    let mut depth = 0u32;
    let mut spectra = PathSpectra::new();
    loop {
        let Some(hit) = scene.intersect(o, d, tmin, tmax) else {
            // escaped: the environment, MIS-weighted against its next-event estimation
            if let Some(env) = &scene.environment {
                let le = env.eval(d, wl);
                let w = if prev_delta {
                    1.0
                } else {
                    mis(prev_pdf, scene.environment_pdf(d))
                };
                for i in 0..N_WL {
                    l[i] += beta[i] * le[i] * w;
                }
            }
            break;
        };
        let prim = hit.prim as usize;
        let sh = &scene.shading[prim];
        let b = hit.bary;
        let p = o + d * hit.t;
        let ns_mesh = shading_normal(sh, b);
        let mut ns = ns_mesh;
        let wi_w = -d;
        let mat = &scene.materials[sh.material as usize];
        // normal mapping (and then the side-consistency check of normal_map.rs)
        let mut bumped = false;
        if let Some(nm) = &mat.normal_map {
            if sh.tangent != u32::MAX {
                let tv = &scene.tangents[sh.tangent as usize];
                let tan = tv[0] * (1.0 - b.x - b.y) + tv[1] * b.x + tv[2] * b.y;
                let tan = tan
                    .truncate()
                    .extend(if tv[0].w < 0.0 { -1.0 } else { 1.0 });
                let n2 = crate::normal_map::perturb(ns, sh.ng, tan, nm.eval(interpolate_uv(sh, b)));
                bumped = n2 != ns;
                ns = n2;
            }
        }
        // emission (one-sided: front = shading normal side, as Mitsuba's area emitter)
        // (the mesh's normal, not the normal map's: the side next-event estimation uses)
        if mat.emits() {
            if ns_mesh.dot(wi_w) > 0.0 {
                let le = match (&mat.emission_texture, &mat.emission) {
                    (Some(t), _) => t.eval(interpolate_uv(sh, b), wl),
                    (None, Some(e)) => spectra.emission(e, sh.material, wl),
                    (None, None) => [0.0; N_WL],
                };
                let w = if prev_delta {
                    1.0
                } else {
                    let lp = scene.area_light_pdf(hit.prim, hit.t, sh.ng.dot(wi_w).abs());
                    mis(prev_pdf, lp)
                };
                for i in 0..N_WL {
                    l[i] += beta[i] * le[i] * w;
                }
            }
        }
        if depth + 1 >= max_depth {
            break;
        }
        let frame = Frame::from_normal(ns);
        let wi = frame.to_local(wi_w);
        let refl = spectra.reflectance(mat, sh.material, || interpolate_uv(sh, b), wl);
        let bsdf = &mat.bsdf;
        // next-event estimation
        let ul = next_f32(rng);
        let ul2 = next_vec2(rng);
        if !bsdf.is_delta() {
            if let Some(ls) = scene
                .sample_light_with(p, ul, ul2, wl, |e, m| spectra.emission(e, m, wl))
                // a leak through the normal map contributes nothing
                .filter(|ls| !bumped || crate::normal_map::sides_agree(sh.ng, ns, wi_w, ls.dir))
            {
                let wo = frame.to_local(ls.dir);
                let (f, pdf_b) = bsdf.eval_pdf(wi, wo, &refl, wl);
                if f.iter().zip(&beta).any(|(x, b)| *x * *b > 0.0) {
                    let so = offset_origin(p, sh.ng, ls.dir);
                    let smax = if ls.dist.is_finite() {
                        ls.dist * (1.0 - 1e-4) - 1e-4 * (1.0 + p.abs().max_element())
                    } else {
                        f32::INFINITY
                    };
                    if smax > 0.0 && scene.unoccluded(so, ls.dir, 0.0, smax) {
                        // one MIS weight when the BSDF density does not depend on λ
                        let w0 = if ls.delta { 1.0 } else { mis(ls.pdf, pdf_b[0]) };
                        for i in 0..N_WL {
                            let w = if ls.delta || pdf_b[i] == pdf_b[0] {
                                w0
                            } else {
                                mis(ls.pdf, pdf_b[i])
                            };
                            l[i] += beta[i] * f[i] * ls.weight[i] * w;
                        }
                    }
                }
            }
        }
        // BSDF sampling
        let u1 = next_f32(rng);
        let u2 = next_vec2(rng);
        let Some(bs) = bsdf.sample(wi, u1, u2, &refl, wl) else {
            break;
        };
        for i in 0..N_WL {
            beta[i] *= bs.weight[i];
        }
        if bs.dispersive && !hero_only {
            // only the hero's direction is valid: drop the secondaries, the hero (marginally
            // uniform in λ) then estimates all 4 slots' worth (pbrt-v4 TerminateSecondary)
            beta[0] *= N_WL as f32;
            for x in beta.iter_mut().skip(1) {
                *x = 0.0;
            }
            hero_only = true;
        }
        let wo_w = frame.to_world(bs.wo);
        if bumped && !crate::normal_map::sides_agree(sh.ng, ns, wi_w, wo_w) {
            break;
        }
        prev_pdf = bs.pdf;
        prev_delta = bs.delta;
        eta2 *= bs.eta * bs.eta;
        depth += 1;
        let tmaxb = beta.iter().copied().fold(0.0f32, f32::max);
        if !(tmaxb > 0.0) {
            break;
        }
        let urr = next_f32(rng);
        if depth >= rr_depth {
            let q = (tmaxb * eta2).min(0.95);
            if !(urr < q) {
                break;
            }
            let inv = 1.0 / q;
            for x in beta.iter_mut() {
                *x *= inv;
            }
        }
        o = offset_origin(p, sh.ng, wo_w);
        d = wo_w;
        tmin = 0.0;
        tmax = f32::INFINITY;
    }
    l
}

/// Everything one film row needs.
struct RowCtx<'a, C: Camera + ?Sized> {
    scene: &'a Scene,
    camera: &'a C,
    camera_to_world: Mat4,
    s: &'a RenderSettings,
    w: usize,
    nb: usize,
    max_depth: u32,
    near: f32,
    far: f32,
    spp: u32,
    slot_scale: f32,
    inv_spp: f32,
}

/// Render film row `y`: per pixel [band] means, then variances (when asked for).
#[inline(always)]
fn render_row<C: Camera + ?Sized>(c: &RowCtx<C>, y: usize) -> (Vec<f32>, Vec<f32>) {
    let RowCtx {
        scene,
        camera,
        camera_to_world,
        s,
        w,
        nb,
        max_depth,
        near,
        far,
        spp,
        slot_scale,
        inv_spp,
    } = *c;
    let mut mean = vec![0f32; w * nb];
    let mut var = if s.variance {
        vec![0f32; w * nb]
    } else {
        Vec::new()
    };
    let mut sum = vec![0f64; nb];
    let mut sum2 = vec![0f64; nb];
    let mut perm_x: Vec<u32> = (0..spp).collect();
    let mut perm_y: Vec<u32> = (0..spp).collect();
    for x in 0..w {
        let pix = (y * w + x) as u64;
        let mut rng = stream(s.seed, &[pix]);
        // Stratification over the pixel's spp samples (Latin hypercube / N-rooks,
        // Shirley 1991): film x and y of sample k lie in strata perm_x[k], perm_y[k]
        // of two random permutations, jittered within them. Wavelengths: the 4·spp
        // slot wavelengths of the pixel fill 4·spp equal strata of the range, one
        // each — sample k's hero sits in stratum k of [0, 1/4), jittered, rotated by
        // a random quarter r_k (its other slots are the other quarters, Wilkie et al.
        // 2014), so every band receives the same share of wavelengths and pixels that
        // see an emitter lose the count noise of independent wavelengths. Averaged
        // over permutations, jitter and k, every sample is uniform over pixel ×
        // spectrum (unbiased, also for hero-only paths); all other dimensions are
        // drawn independently of k.
        shuffle(&mut perm_x, &mut rng);
        shuffle(&mut perm_y, &mut rng);
        for k in 0..spp {
            let j = next_vec2(&mut rng);
            let film = Vec2::new(
                x as f32 + ((perm_x[k as usize] as f32 + j.x) * inv_spp).min(ONE_MINUS_EPS),
                y as f32 + ((perm_y[k as usize] as f32 + j.y) * inv_spp).min(ONE_MINUS_EPS),
            );
            let lens = next_vec2(&mut rng);
            let quarter = (rng.next_u32() >> 30) as f32 * 0.25;
            let u_wl =
                ((k as f32 + next_f32(&mut rng)) * inv_spp * 0.25 + quarter).min(ONE_MINUS_EPS);
            let wl = s.bands.sample_wavelengths(u_wl);
            let Some(cr) = camera.generate_ray(film, lens, &wl) else {
                continue;
            };
            let mut beta0 = cr.weight;
            if cr.wavelength_dependent {
                beta0[0] *= N_WL as f32;
                for v in beta0.iter_mut().skip(1) {
                    *v = 0.0;
                }
            }
            if beta0.iter().all(|v| *v == 0.0) {
                continue;
            }
            let Some(ray) = to_world(&cr, &camera_to_world, near, far) else {
                continue;
            };
            let l = trace_path(
                scene,
                ray,
                &wl,
                beta0,
                cr.wavelength_dependent,
                max_depth,
                s.rr_depth,
                &mut rng,
            );
            if !s.variance {
                // the mean only: each slot adds to its band
                for i in 0..N_WL {
                    let v = (l[i] * slot_scale) as f64;
                    if v.is_finite() {
                        sum[s.bands.index(wl[i])] += v;
                    }
                }
                continue;
            }
            // bands of the 4 slots (merge slots that share a band: the sample's value per band
            // for the variance)
            let mut bi = [usize::MAX; N_WL];
            let mut bv = [0f64; N_WL];
            let mut n = 0;
            for i in 0..N_WL {
                let v = (l[i] * slot_scale) as f64;
                if !v.is_finite() {
                    continue;
                }
                let b = s.bands.index(wl[i]);
                match bi[..n].iter().position(|&q| q == b) {
                    Some(k) => bv[k] += v,
                    None => {
                        bi[n] = b;
                        bv[n] = v;
                        n += 1;
                    }
                }
            }
            for k in 0..n {
                sum[bi[k]] += bv[k];
                sum2[bi[k]] += bv[k] * bv[k];
            }
        }
        let inv = 1.0 / spp as f64;
        for b in 0..nb {
            let m = sum[b] * inv;
            mean[x * nb + b] = m as f32;
            if s.variance {
                // variance of the mean: (E[v²] − E[v]²)/(n − 1)
                let v2 = sum2[b] * inv;
                let sv = if spp > 1 {
                    ((v2 - m * m) * spp as f64 / (spp as f64 - 1.0)).max(0.0) * inv
                } else {
                    0.0
                };
                var[x * nb + b] = sv as f32;
            }
            sum[b] = 0.0;
            sum2[b] = 0.0;
        }
    }
    (mean, var)
}

/// Render `scene` through `camera` placed by `camera_to_world`. `progress` is called with the
/// number of finished rows.
pub fn render(
    scene: &Scene,
    camera: &dyn Camera,
    camera_to_world: Mat4,
    s: &RenderSettings,
    progress: Option<&(dyn Fn(usize) + Sync)>,
) -> RenderOutput {
    // a pinhole or thin lens renders through its prepared, statically dispatched form
    let prepared = camera.prepared();
    let camera: &dyn Camera = match &prepared {
        Some(c) => c,
        None => camera,
    };
    let (w, h) = camera.film_size_px();
    let (w, h) = (w as usize, h as usize);
    let nb = s.bands.count;
    let max_depth = if s.max_depth < 0 {
        u32::MAX
    } else {
        s.max_depth as u32
    };
    let near = camera.near_clip_m();
    let far = camera.far_clip_m();
    let spp = s.spp.max(1);
    // per sample, each of the 4 slots adds L·count/4 to its band: the band-averaged radiance
    // estimator (1/Δ)∫_band L with λ uniform on [LO, HI] (density 1/(HI−LO) = 1/(count·Δ)).
    let slot_scale = nb as f32 / N_WL as f32;
    let inv_spp = 1.0 / spp as f32;
    let done = AtomicUsize::new(0);
    let t0 = std::time::Instant::now();
    // row-parallel; each row is [pixel][band] means followed by variances
    let ctx = RowCtx {
        scene,
        camera,
        camera_to_world,
        s,
        w,
        nb,
        max_depth,
        near,
        far,
        spp,
        slot_scale,
        inv_spp,
    };
    let ctx_prepared = prepared.as_ref().map(|c| RowCtx {
        scene,
        camera: c,
        camera_to_world,
        s,
        w,
        nb,
        max_depth,
        near,
        far,
        spp,
        slot_scale,
        inv_spp,
    });
    let rows: Vec<(Vec<f32>, Vec<f32>)> = (0..h)
        .into_par_iter()
        .map(|y| {
            let row = match &ctx_prepared {
                Some(cp) => render_row(cp, y),
                None => render_row(&ctx, y),
            };
            let k = done.fetch_add(1, Ordering::Relaxed) + 1;
            if let Some(p) = progress {
                p(k);
            }
            row
        })
        .collect();
    let render_s = t0.elapsed().as_secs_f64();
    let mut band_planes = vec![vec![0f32; w * h]; nb];
    let mut variance_planes = if s.variance {
        Some(vec![vec![0f32; w * h]; nb])
    } else {
        None
    };
    for (y, (mean, var)) in rows.iter().enumerate() {
        for x in 0..w {
            for b in 0..nb {
                band_planes[b][y * w + x] = mean[x * nb + b];
                if let Some(vp) = variance_planes.as_mut() {
                    vp[b][y * w + x] = var[x * nb + b];
                }
            }
        }
    }
    // depth: the central ray of every pixel, and jittered rays for the mean distance
    let mut depth_z_m = vec![f32::INFINITY; w * h];
    let mut depth_center_m = vec![0f32; w * h];
    let mut depth_mean_m = if s.depth_spp > 0 {
        vec![0f32; w * h]
    } else {
        Vec::new()
    };
    let depth_rows: Vec<Vec<(f32, f32, f32)>> = (0..h)
        .into_par_iter()
        .map(|y| {
            (0..w)
                .map(|x| {
                    let c = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
                    let (mut z, mut tc) = (f32::INFINITY, 0.0);
                    if let Some(cr) = camera.center_ray(c) {
                        if let Some(r) = to_world(&cr, &camera_to_world, near, far) {
                            if let Some(hit) = scene.intersect(r.o, r.d, r.tmin, r.tmax) {
                                tc = hit.t;
                                z = -(cr.origin_m.z + cr.direction.z * hit.t);
                            }
                        }
                    }
                    let mut tm = 0.0f64;
                    if s.depth_spp > 0 {
                        let mut rng = stream(s.seed ^ 0x00DE_9780, &[(y * w + x) as u64]);
                        for _ in 0..s.depth_spp {
                            let film = Vec2::new(x as f32, y as f32) + next_vec2(&mut rng);
                            let lens = next_vec2(&mut rng);
                            let wl = s.bands.sample_wavelengths(next_f32(&mut rng));
                            if let Some(cr) = camera.generate_ray(film, lens, &wl) {
                                if let Some(r) = to_world(&cr, &camera_to_world, near, far) {
                                    if let Some(hit) = scene.intersect(r.o, r.d, r.tmin, r.tmax) {
                                        tm += hit.t as f64;
                                    }
                                }
                            }
                        }
                        tm /= s.depth_spp as f64;
                    }
                    (z, tc, tm as f32)
                })
                .collect()
        })
        .collect();
    for (y, row) in depth_rows.iter().enumerate() {
        for (x, &(z, tc, tm)) in row.iter().enumerate() {
            depth_z_m[y * w + x] = z;
            depth_center_m[y * w + x] = tc;
            if s.depth_spp > 0 {
                depth_mean_m[y * w + x] = tm;
            }
        }
    }
    RenderOutput {
        width: w,
        height: h,
        bands: s.bands,
        quantity: camera.output_quantity(),
        band_planes,
        variance_planes,
        depth_z_m,
        depth_center_m,
        depth_mean_m,
        spp,
        render_s,
    }
}
