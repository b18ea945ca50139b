//! The render scene: world-space triangles in a 4-wide BVH ([`crate::bvh4`], topology from
//! obvhs's PLOC builder), their shading
//! attributes, materials, emitters and cameras.
use crate::bsdf::Bsdf;
use crate::bvh4::Bvh4;
use crate::camera::Perspective;
use crate::envmap::{EmissionTexture, EnvMap};
use crate::normal_map::NormalMap;
use crate::sampling::{square_to_triangle, Distribution1D};
use crate::spectral::{SigmoidPoly, TabulatedSpectrum, N_WL};
use glam::{Mat4, Vec2, Vec3, Vec3A, Vec4};
use obvhs::ray::Ray;

/// Barycentric tolerance of every ray–triangle test (this one, [`crate::bvh4`]'s packs and the
/// AVX2 flat case): a ray exactly on an edge shared by two triangles must hit one of them.
/// In f32 the barycentric u = (s·p)/det, s = o − v₀, p = d × e₂, carries a rounding error of
/// about 4ε·|s|·|p|/|det| ≈ 4ε·L/(a·sin α) (ε = 2⁻²⁴, L the distance from the ray origin to
/// the triangle, a its edge length, α the angle between its edges, face-on): 4·10⁻⁵ for the
/// 4-px checker cells of the depth cross-check (4.2 cm at 5 m), which the former 10⁻⁶ did not
/// cover — 353 of the 98 304 pixel-centre rays of its `steps` scene (357 and 250 of the
/// other two), which lie exactly on the cells' diagonals, missed both triangles
/// (render/tests/depth_crosscheck.rs, `pinhole_depth_is_the_card_depth_at_every_pixel`). 10⁻⁴ closes cracks up to
/// L/(a·sin α) ≈ 400 and grows each triangle by 10⁻⁴ of its size. Not watertight beyond that
/// ratio (a watertight test: Woop, Benthin & Wald, JCGT 2(1), 2013).
pub(crate) const BARY_EPS: f32 = 1e-4;

/// Intersection data of one triangle (Möller & Trumbore 1997): vertex 0 and two edges.
#[derive(Debug, Clone, Copy)]
pub struct TriGeom {
    /// Vertex 0 (m).
    pub v0: Vec3A,
    /// v1 − v0.
    pub e1: Vec3A,
    /// v2 − v0.
    pub e2: Vec3A,
}

impl TriGeom {
    /// Distance along the ray to the hit, ∞ for a miss or outside [tmin, tmax].
    #[inline(always)]
    pub fn intersect(&self, ray: &Ray) -> f32 {
        let p = ray.direction.cross(self.e2);
        let det = self.e1.dot(p);
        if det == 0.0 {
            return f32::INFINITY;
        }
        let inv = 1.0 / det;
        let s = ray.origin - self.v0;
        // the barycentric tolerance closes cracks along shared edges (a ray exactly on an
        // edge may otherwise miss both triangles in floating point)
        const EPS: f32 = BARY_EPS;
        let u = s.dot(p) * inv;
        if !(-EPS..=1.0 + EPS).contains(&u) {
            return f32::INFINITY;
        }
        let q = s.cross(self.e1);
        let v = ray.direction.dot(q) * inv;
        if v < -EPS || u + v > 1.0 + EPS {
            return f32::INFINITY;
        }
        let t = self.e2.dot(q) * inv;
        if t >= ray.tmin && t <= ray.tmax {
            t
        } else {
            f32::INFINITY
        }
    }

    /// Barycentrics (b1, b2) of the point where the ray crosses the triangle's plane.
    #[inline]
    pub fn barycentrics(&self, o: Vec3A, d: Vec3A) -> Vec2 {
        let p = d.cross(self.e2);
        let inv = 1.0 / self.e1.dot(p);
        let s = o - self.v0;
        let q = s.cross(self.e1);
        Vec2::new(s.dot(p) * inv, d.dot(q) * inv)
    }
}

/// Shading attributes of one triangle.
#[derive(Debug, Clone, Copy)]
pub struct TriShading {
    /// Unit geometric normal (right-handed from the CCW winding).
    pub ng: Vec3,
    /// Per-vertex unit normals (equal to `ng` when the mesh has none).
    pub n: [Vec3; 3],
    /// Per-vertex texture coordinates (zero when absent).
    pub uv: [Vec2; 3],
    /// Material index.
    pub material: u32,
    /// Index in the area-light list, or u32::MAX.
    pub light: u32,
    /// Area (m²).
    pub area: f32,
    /// Index in [`Scene::tangents`] (per-vertex tangents for normal mapping), or u32::MAX.
    pub tangent: u32,
}

/// A spectral reflectance that may vary over the surface.
#[derive(Debug, Clone)]
pub enum SpectralTexture {
    /// The same spectrum everywhere.
    Constant(TabulatedSpectrum),
    /// An RGB image upsampled per texel (sigmoid-polynomial coefficients), nearest texel with
    /// repeat/clamp wrapping, sampled at the hit's texture coordinates.
    Image {
        /// Width (texels).
        width: u32,
        /// Height (texels).
        height: u32,
        /// Per-texel coefficients (row 0 = top of the image, v = 0).
        coeffs: Vec<SigmoidPoly>,
        /// Repeat (true) or clamp along u and v.
        repeat: [bool; 2],
        /// Mean reflectance (for sampling weights).
        mean: f32,
    },
}

/// Texel column (or row) of texture coordinate `x` on an axis of `n` texels, nearest texel:
/// repeating (glTF REPEAT; MIRRORED_REPEAT is read as REPEAT) or clamped to the edge.
#[inline]
pub(crate) fn texel_coord(x: f32, n: u32, repeat: bool) -> usize {
    let t = if repeat {
        x - x.floor()
    } else {
        x.clamp(0.0, 1.0)
    };
    ((t * n as f32) as usize).min(n as usize - 1)
}

impl SpectralTexture {
    /// Reflectance at the 4 wavelengths and texture coordinates `uv`.
    #[inline]
    pub fn eval(&self, uv: Vec2, wl: &[f32; N_WL]) -> [f32; N_WL] {
        match self {
            SpectralTexture::Constant(s) => s.eval4(wl),
            SpectralTexture::Image {
                width,
                height,
                coeffs,
                repeat,
                ..
            } => {
                let wrap = texel_coord;
                let i = wrap(uv.x, *width, repeat[0]);
                let j = wrap(uv.y, *height, repeat[1]);
                let c = &coeffs[j * *width as usize + i];
                [c.eval(wl[0]), c.eval(wl[1]), c.eval(wl[2]), c.eval(wl[3])]
            }
        }
    }
    /// Mean value over the visible range (Mitsuba's `mean()`, used for sampling weights).
    pub fn mean(&self) -> f32 {
        match self {
            SpectralTexture::Constant(s) => s.mean_over(360.0, 830.0),
            SpectralTexture::Image { mean, .. } => *mean,
        }
    }
}

/// A material: BSDF, its reflectance, and optional one-sided area emission.
#[derive(Debug, Clone)]
pub struct Material {
    /// Name (glTF material name or index).
    pub name: String,
    /// Scattering.
    pub bsdf: Bsdf,
    /// Diffuse (or specular) reflectance.
    pub reflectance: SpectralTexture,
    /// Emitted spectral radiance (W m⁻² sr⁻¹ nm⁻¹) from the front (CCW) side.
    pub emission: Option<TabulatedSpectrum>,
    /// Emitted radiance varying over the surface (glTF emissiveTexture); replaces `emission`
    /// where present.
    pub emission_texture: Option<EmissionTexture>,
    /// Tangent-space normal map (glTF normalTexture).
    pub normal_map: Option<NormalMap>,
}

impl Material {
    /// True when the material emits light.
    #[inline]
    pub fn emits(&self) -> bool {
        self.emission.is_some() || self.emission_texture.is_some()
    }
}

/// A point-like or directional light (KHR_lights_punctual).
#[derive(Debug, Clone)]
pub enum PunctualLight {
    /// Point or spot light.
    Point {
        /// Position (m).
        position_m: Vec3,
        /// Spectral radiant intensity (W sr⁻¹ nm⁻¹) on the axis.
        intensity: TabulatedSpectrum,
        /// Spot axis (unit, the direction the light points) and cone cosines (inner, outer);
        /// None for an isotropic point light.
        spot: Option<(Vec3, f32, f32)>,
    },
    /// Distant light.
    Directional {
        /// Direction the light travels (unit).
        direction: Vec3,
        /// Spectral irradiance on a surface facing the light (W m⁻² nm⁻¹).
        irradiance: TabulatedSpectrum,
    },
}

impl PunctualLight {
    /// glTF spot falloff: clamp((cos − cos_outer)/(cos_inner − cos_outer), 0, 1)².
    #[inline]
    pub fn spot_factor(&self, dir_from_light: Vec3) -> f32 {
        match self {
            PunctualLight::Point {
                spot: Some((axis, ci, co)),
                ..
            } => {
                let c = axis.dot(dir_from_light);
                let t = ((c - co) / (ci - co).max(1e-4)).clamp(0.0, 1.0);
                t * t
            }
            _ => 1.0,
        }
    }
}

/// A camera found in the scene.
#[derive(Debug, Clone)]
pub struct SceneCamera {
    /// Node or camera name.
    pub name: String,
    /// Camera-to-world transform with the scale removed.
    pub to_world: Mat4,
    /// Vertical field of view (rad).
    pub yfov_rad: f32,
    /// glTF aspectRatio when given.
    pub aspect_ratio: Option<f32>,
    /// Near clip (m).
    pub znear_m: f32,
    /// Far clip (m).
    pub zfar_m: Option<f32>,
    /// `extras.thinlens` of the camera node or camera: (aperture radius, focus distance) (m).
    pub thinlens: Option<(f32, f32)>,
}

impl SceneCamera {
    /// The perspective projection for a film of `width × height` px.
    pub fn perspective(&self, width_px: u32, height_px: u32) -> Perspective {
        Perspective {
            width_px,
            height_px,
            yfov_rad: self.yfov_rad,
            znear_m: self.znear_m,
            zfar_m: self.zfar_m.unwrap_or(f32::INFINITY),
        }
    }
}

/// Everything the integrator needs.
pub struct Scene {
    /// Triangles in BVH order.
    pub tris: Vec<TriGeom>,
    /// Shading attributes in BVH order.
    pub shading: Vec<TriShading>,
    /// The 4-wide BVH over `tris` (primitive i of the BVH is `tris[i]`).
    pub bvh: Option<Bvh4>,
    /// Materials.
    pub materials: Vec<Material>,
    /// Triangle index (BVH order) of each area light.
    pub area_lights: Vec<u32>,
    /// Point, spot and directional lights.
    pub punctual: Vec<PunctualLight>,
    /// Light selection: area lights first, then punctual lights, by power.
    pub light_distr: Option<Distribution1D>,
    /// Cameras in document order.
    pub cameras: Vec<SceneCamera>,
    /// Bounding-sphere centre and radius of the geometry (for directional lights).
    pub bounds_center: Vec3,
    /// Bounding-sphere radius (m).
    pub bounds_radius: f32,
    /// Environment lighting (selected after the punctual lights), if any.
    pub environment: Option<EnvMap>,
    /// Per-vertex tangents (xyz unit, w = ±1 bitangent sign) of normal-mapped triangles,
    /// indexed by [`TriShading::tangent`].
    pub tangents: Vec<[Vec4; 3]>,
}

/// A closest hit.
#[derive(Debug, Clone, Copy)]
pub struct Hit {
    /// Distance along the (unit) ray (m).
    pub t: f32,
    /// Triangle (BVH order).
    pub prim: u32,
    /// Barycentrics (b1, b2) of the hit point.
    pub bary: Vec2,
}

/// A light sample seen from a shading point.
#[derive(Debug, Clone, Copy)]
pub struct LightSample {
    /// Unit direction from the shading point to the light.
    pub dir: Vec3,
    /// Distance to the light point (∞ for a directional light).
    pub dist: f32,
    /// Emitted radiance (area), intensity/d² (point) or irradiance (directional) per wavelength,
    /// already divided by the density of the sample (solid angle × selection).
    pub weight: [f32; N_WL],
    /// Density of the direction per steradian (for MIS; 0 for Dirac lights).
    pub pdf: f32,
    /// True for point and directional lights (no MIS).
    pub delta: bool,
}

impl Scene {
    /// Build the acceleration structure and the light distribution from world-space triangles.
    pub fn build(
        triangles: Vec<[Vec3; 3]>,
        mut shading: Vec<TriShading>,
        materials: Vec<Material>,
        punctual: Vec<PunctualLight>,
        cameras: Vec<SceneCamera>,
    ) -> Scene {
        let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        for t in &triangles {
            for v in t {
                lo = lo.min(*v);
                hi = hi.max(*v);
            }
        }
        let (bounds_center, bounds_radius) = if triangles.is_empty() {
            (Vec3::ZERO, 1.0)
        } else {
            (0.5 * (lo + hi), (0.5 * (hi - lo).length()).max(1e-3))
        };
        let (tris, bvh) = if triangles.is_empty() {
            (Vec::new(), None)
        } else {
            let bvh = Bvh4::build(&triangles);
            // reorder so that BVH primitive i is triangle i (no indirection while tracing)
            let order: Vec<usize> = bvh.order.iter().map(|&i| i as usize).collect();
            // read at scattered places while tracing: in huge pages (render/src/huge_pages.rs)
            let mut tris = crate::huge_pages::with_capacity(order.len());
            tris.extend(order.iter().map(|&i| {
                let t = &triangles[i];
                TriGeom {
                    v0: t[0].into(),
                    e1: (t[1] - t[0]).into(),
                    e2: (t[2] - t[0]).into(),
                }
            }));
            crate::huge_pages::finish(&tris);
            let mut reordered = crate::huge_pages::with_capacity(order.len());
            reordered.extend(order.iter().map(|&i| shading[i]));
            crate::huge_pages::finish(&reordered);
            shading = reordered;
            (tris, Some(bvh))
        };
        // area lights
        let mut area_lights = Vec::new();
        for (i, s) in shading.iter_mut().enumerate() {
            s.light = u32::MAX;
            if area_light_weight(&materials[s.material as usize], s.area) > 0.0 {
                s.light = area_lights.len() as u32;
                area_lights.push(i as u32);
            }
        }
        let mut scene = Scene {
            tris,
            shading,
            bvh,
            materials,
            area_lights,
            punctual,
            light_distr: None,
            cameras,
            bounds_center,
            bounds_radius,
            environment: None,
            tangents: Vec::new(),
        };
        scene.light_distr = scene.light_distribution();
        scene
    }

    /// Set (or remove) the environment lighting and rebuild the light selection.
    pub fn set_environment(&mut self, env: Option<EnvMap>) {
        self.environment = env;
        self.light_distr = self.light_distribution();
    }

    /// True when light index `li` of [`Scene::light_distr`] is the environment.
    #[inline]
    fn is_environment_light(&self, li: usize) -> bool {
        li == self.area_lights.len() + self.punctual.len()
    }

    /// Light selection: area lights (weight ∝ area × peak radiance × π), punctual lights, then
    /// the environment (π R² × π × mean luminance, R the bounding-sphere radius).
    fn light_distribution(&self) -> Option<Distribution1D> {
        let bounds_radius = self.bounds_radius;
        let mut weights: Vec<f64> = self
            .area_lights
            .iter()
            .map(|&i| {
                let s = &self.shading[i as usize];
                area_light_weight(&self.materials[s.material as usize], s.area)
            })
            .collect();
        for l in &self.punctual {
            weights.push(match l {
                PunctualLight::Point { intensity, .. } => {
                    intensity.max_value() as f64 * 4.0 * std::f64::consts::PI
                }
                PunctualLight::Directional { irradiance, .. } => {
                    irradiance.max_value() as f64
                        * std::f64::consts::PI
                        * (bounds_radius as f64).powi(2)
                }
            });
        }
        if let Some(env) = self.environment.as_ref().filter(|e| e.has_power()) {
            weights.push(
                std::f64::consts::PI
                    * std::f64::consts::PI
                    * (bounds_radius as f64).powi(2)
                    * env.mean_luminance,
            );
        }
        Distribution1D::new(&weights)
    }

    /// Density (per steradian) of next-event estimation choosing direction `d` towards the
    /// environment (for MIS when a BSDF-sampled ray escapes).
    #[inline]
    pub fn environment_pdf(&self, d: Vec3) -> f32 {
        match (&self.environment, &self.light_distr) {
            (Some(env), Some(distr)) if env.has_power() => {
                let li = self.area_lights.len() + self.punctual.len();
                if li < distr.len() {
                    distr.pmf(li) * env.pdf(d)
                } else {
                    0.0
                }
            }
            _ => 0.0,
        }
    }

    /// Closest hit along the ray within [tmin, tmax].
    #[inline]
    pub fn intersect(&self, o: Vec3, d: Vec3, tmin: f32, tmax: f32) -> Option<Hit> {
        let h = self.bvh.as_ref()?.intersect(o, d, tmin, tmax)?;
        Some(Hit {
            t: h.t,
            prim: h.prim,
            bary: h.bary,
        })
    }

    /// True when nothing blocks the segment (tmin, tmax) along the ray.
    #[inline]
    pub fn unoccluded(&self, o: Vec3, d: Vec3, tmin: f32, tmax: f32) -> bool {
        match self.bvh.as_ref() {
            Some(bvh) => bvh.unoccluded(o, d, tmin, tmax),
            None => true,
        }
    }

    /// Density (per steradian) of sampling the direction to point `p` on area-light triangle
    /// `prim` from distance `dist` with cos θ at the light `cos_l` (for MIS on emitter hits).
    #[inline]
    pub fn area_light_pdf(&self, prim: u32, dist: f32, cos_l: f32) -> f32 {
        let s = &self.shading[prim as usize];
        let Some(d) = &self.light_distr else {
            return 0.0;
        };
        if s.light == u32::MAX || cos_l <= 0.0 {
            return 0.0;
        }
        d.pmf(s.light as usize) / s.area * dist * dist / cos_l
    }

    /// Sample a light as seen from `p` (next-event estimation). `u` picks the light, `u2` the
    /// point on it. Returns None when the light faces away or has no power.
    #[inline]
    pub fn sample_light(&self, p: Vec3, u: f32, u2: Vec2, wl: &[f32; N_WL]) -> Option<LightSample> {
        self.sample_light_with(p, u, u2, wl, |e, _| e.eval4(wl))
    }

    /// [`Scene::sample_light`] with the emitted radiance of an area light's material at the
    /// sample's wavelengths given by `emission(spectrum, material index)` (the integrator
    /// memoises it per path).
    #[inline(always)]
    pub fn sample_light_with(
        &self,
        p: Vec3,
        u: f32,
        u2: Vec2,
        wl: &[f32; N_WL],
        mut emission: impl FnMut(&TabulatedSpectrum, u32) -> [f32; N_WL],
    ) -> Option<LightSample> {
        let distr = self.light_distr.as_ref()?;
        let (li, pmf, _) = distr.sample(u);
        if pmf <= 0.0 {
            return None;
        }
        if self.is_environment_light(li) {
            let env = self.environment.as_ref()?;
            let es = env.sample(u2)?;
            let inv = 1.0 / (es.pdf * pmf);
            let le = env.eval(es.dir, wl);
            return Some(LightSample {
                dir: es.dir,
                dist: f32::INFINITY,
                weight: le.map(|v| v * inv),
                pdf: es.pdf * pmf,
                delta: false,
            });
        }
        if li < self.area_lights.len() {
            let prim = self.area_lights[li] as usize;
            let g = &self.tris[prim];
            let s = &self.shading[prim];
            let b = square_to_triangle(u2);
            let q: Vec3 = (g.v0 + g.e1 * b.x + g.e2 * b.y).into();
            let to = q - p;
            let d2 = to.length_squared();
            if !(d2 > 0.0) {
                return None;
            }
            let dist = d2.sqrt();
            let dir = to * (1.0 / dist);
            // one-sided emitter: the shading normal decides the front, as in Mitsuba
            let ns = shading_normal(s, b);
            if ns.dot(-dir) <= 0.0 {
                return None;
            }
            let cos_l = s.ng.dot(-dir).abs();
            if cos_l <= 1e-7 {
                return None;
            }
            // solid-angle density pmf·d²/(area·cos θ_l) and its inverse from one division
            let (a, c) = (pmf * d2, s.area * cos_l);
            let r = 1.0 / (a * c);
            let (pdf, inv_pdf) = (a * a * r, c * c * r);
            if !(pdf > 0.0 && pdf.is_finite() && inv_pdf.is_finite()) {
                return None;
            }
            let mat = &self.materials[s.material as usize];
            let le = match &mat.emission_texture {
                Some(t) => t.eval(interpolate_uv(s, b), wl),
                None => emission(mat.emission.as_ref()?, s.material),
            };
            Some(LightSample {
                dir,
                dist,
                weight: le.map(|v| v * inv_pdf),
                pdf,
                delta: false,
            })
        } else {
            match &self.punctual[li - self.area_lights.len()] {
                l @ PunctualLight::Point {
                    position_m,
                    intensity,
                    ..
                } => {
                    let to = *position_m - p;
                    let d2 = to.length_squared();
                    if !(d2 > 0.0) {
                        return None;
                    }
                    let dist = d2.sqrt();
                    let dir = to / dist;
                    let k = l.spot_factor(-dir) / (d2 * pmf);
                    if k <= 0.0 {
                        return None;
                    }
                    Some(LightSample {
                        dir,
                        dist,
                        weight: intensity.eval4(wl).map(|v| v * k),
                        pdf: 0.0,
                        delta: true,
                    })
                }
                PunctualLight::Directional {
                    direction,
                    irradiance,
                } => Some(LightSample {
                    dir: -*direction,
                    dist: f32::INFINITY,
                    weight: irradiance.eval4(wl).map(|v| v / pmf),
                    pdf: 0.0,
                    delta: true,
                }),
            }
        }
    }
}

/// Selection weight of an area-light triangle: area × peak radiance × π (0: not a light).
fn area_light_weight(m: &Material, area: f32) -> f64 {
    let peak = match (&m.emission_texture, &m.emission) {
        (Some(t), _) => t.max_value,
        (None, Some(e)) => e.max_value(),
        (None, None) => 0.0,
    };
    let p = peak as f64 * area as f64 * std::f64::consts::PI;
    if p > 0.0 && area > 0.0 && p.is_finite() {
        p
    } else {
        0.0
    }
}

/// Interpolated texture coordinates at barycentrics b = (b1, b2).
#[inline]
pub fn interpolate_uv(s: &TriShading, b: Vec2) -> Vec2 {
    s.uv[0] * (1.0 - b.x - b.y) + s.uv[1] * b.x + s.uv[2] * b.y
}

/// Interpolated unit shading normal at barycentrics b = (b1, b2).
#[inline]
pub fn shading_normal(s: &TriShading, b: Vec2) -> Vec3 {
    // equal (unit) vertex normals: the interpolation is that normal, no normalisation needed
    if s.n[0] == s.n[1] && s.n[1] == s.n[2] {
        return s.n[0];
    }
    let n = s.n[0] * (1.0 - b.x - b.y) + s.n[1] * b.x + s.n[2] * b.y;
    let l = n.length();
    if l > 0.0 && l.is_finite() {
        n / l
    } else {
        s.ng
    }
}
