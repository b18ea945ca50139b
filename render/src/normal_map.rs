//! Tangent-space normal mapping (glTF 2.0 §3.9.3 `normalTexture`): the texel's RGB c ∈ \[0,1\]³
//! gives n_t = normalize((2c_r − 1)·s, (2c_g − 1)·s, 2c_b − 1), s the texture's `scale`, in the
//! frame (T, B, N) with B = w·(N × T) (w the tangent's handedness), +X right and +Y up in the
//! image.
//!
//! Tangents come from the glTF `TANGENT` attribute or, when absent, are generated per
//! triangle from the texture coordinates: T = ∂p/∂u and B = ∂p/∂v′ with v′ = −v (glTF's v
//! runs down the image, the map's +Y up), w = sign((N × T)·B) — the per-triangle core of
//! MikkTSpace (Mikkelsen 2008, "Simulation of wrinkled surfaces revisited"), without its
//! averaging over the triangles that share a vertex.
//!
//! Leaks: a perturbed normal n′ is kept in the hemisphere of the geometric normal on the side
//! of the interpolated normal N (n′ is pushed towards it until n′·N_g ≥ 0.01; the "clamp"
//! adjustment), and light transport through a normal-mapped hit is zero unless the geometric
//! and the shading normal agree on whether the incident and outgoing directions are on the
//! same side (Veach 1997, §5.3: for reflection both sides, for transmission opposite sides).
use glam::{Vec2, Vec3, Vec4};

/// A tangent-space normal map (nearest texel).
#[derive(Debug, Clone)]
pub struct NormalMap {
    /// Width (texels).
    pub width: u32,
    /// Height (texels).
    pub height: u32,
    /// Decoded unit tangent-space normals (scale applied), row-major, row 0 = image top.
    pub normals: Vec<Vec3>,
    /// Repeat (true) or clamp along u and v.
    pub repeat: [bool; 2],
}

/// Decode one 8-bit texel (r, g, b) with the glTF `scale`: ((2c − 1)·s, (2c − 1)·s, 2c − 1),
/// normalised. 8 bits cannot encode 0.5: components within one quantisation step of zero
/// (|2c − 1| ≤ 1/255, i.e. the bytes 127 and 128) are taken as 0, so that a flat map
/// (128, 128, 255) is exactly the unperturbed normal.
pub fn decode_texel(rgb: [u8; 3], scale: f32) -> Vec3 {
    let d = |b: u8| {
        let v = 2.0 * b as f32 / 255.0 - 1.0;
        if v.abs() <= 1.0 / 255.0 + 1e-7 {
            0.0
        } else {
            v
        }
    };
    let n = Vec3::new(d(rgb[0]) * scale, d(rgb[1]) * scale, d(rgb[2]));
    let l = n.length();
    if l > 0.0 && l.is_finite() {
        n / l
    } else {
        Vec3::Z
    }
}

impl NormalMap {
    /// The tangent-space normal at texture coordinates `uv`.
    #[inline]
    pub fn eval(&self, uv: Vec2) -> Vec3 {
        let wrap = crate::scene::texel_coord;
        let i = wrap(uv.x, self.width, self.repeat[0]);
        let j = wrap(uv.y, self.height, self.repeat[1]);
        self.normals[j * self.width as usize + i]
    }
}

/// Per-triangle tangent from positions and texture coordinates (see the module docs); None
/// when the UV mapping is degenerate. `ng` is the triangle's unit normal on the side its
/// vertex normals face, so that w matches the shading frame B = w·(N × T).
pub fn triangle_tangent(p: [Vec3; 3], uv: [Vec2; 3], ng: Vec3) -> Option<Vec4> {
    let (e1, e2) = (p[1] - p[0], p[2] - p[0]);
    // v′ = −v: the image's +Y
    let (du1, dv1) = (uv[1].x - uv[0].x, -(uv[1].y - uv[0].y));
    let (du2, dv2) = (uv[2].x - uv[0].x, -(uv[2].y - uv[0].y));
    let det = du1 * dv2 - du2 * dv1;
    if !(det.abs() > 1e-12) {
        return None;
    }
    let r = 1.0 / det;
    let t = (e1 * dv2 - e2 * dv1) * r;
    let b = (e2 * du1 - e1 * du2) * r;
    let t = (t - ng * ng.dot(t)).normalize_or_zero();
    if t == Vec3::ZERO || !t.is_finite() {
        return None;
    }
    let w = if ng.cross(t).dot(b) < 0.0 { -1.0 } else { 1.0 };
    Some(t.extend(w))
}

/// The perturbed shading normal: tangent-space normal `n_t` in the frame of the interpolated
/// normal `ns` and tangent `tan` (xyz, w handedness), kept in the hemisphere of the geometric
/// normal `ng` on `ns`'s side.
#[inline]
pub fn perturb(ns: Vec3, ng: Vec3, tan: Vec4, n_t: Vec3) -> Vec3 {
    if n_t == Vec3::Z {
        return ns;
    }
    let t = tan.truncate();
    let t = (t - ns * ns.dot(t)).normalize_or_zero();
    if t == Vec3::ZERO {
        return ns;
    }
    let b = ns.cross(t) * tan.w;
    let n = (t * n_t.x + b * n_t.y + ns * n_t.z).normalize_or_zero();
    if n == Vec3::ZERO {
        return ns;
    }
    // the geometric normal on the side of ns
    let g = if ns.dot(ng) >= 0.0 { ng } else { -ng };
    const MIN_COS: f32 = 0.01;
    let c = n.dot(g);
    if c >= MIN_COS {
        return n;
    }
    // push n towards g along g until its cosine with g is MIN_COS
    let tperp = (n - g * c).normalize_or_zero();
    if tperp == Vec3::ZERO {
        return g;
    }
    g * MIN_COS + tperp * (1.0 - MIN_COS * MIN_COS).sqrt()
}

/// True when the geometric normal `ng` and the shading normal `ns` agree on whether world
/// directions `wi` and `wo` are on the same side of the surface.
#[inline]
pub fn sides_agree(ng: Vec3, ns: Vec3, wi: Vec3, wo: Vec3) -> bool {
    let geo = (ng.dot(wi) > 0.0) == (ng.dot(wo) > 0.0);
    let sh = (ns.dot(wi) > 0.0) == (ns.dot(wo) > 0.0);
    geo == sh
}
