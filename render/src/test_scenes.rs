//! The scenes of scenes/ with known answers, generated in code so that the tests build the
//! same files they check (scenes/README.md states the expected results):
//!
//! * [`furnace`] — a closed sphere of albedo ρ that also emits Le: L = Le/(1 − ρ) everywhere
//!   (with a path-length limit N: Le·(1 − ρᴺ)/(1 − ρ));
//! * [`uniform_emitter`] — a Lambertian plane of albedo ρ under a closed non-reflecting
//!   emitter sphere of radiance Le: L = ρ·Le on the plane (E = π Le);
//! * [`point_source`] — a Lambertian plane under an isotropic point light of intensity I at
//!   height h: L(r) = ρ I h / (π (h² + r²)^{3/2});
//! * [`slanted_edge`] — a white/black plane split by an edge tilted by 5°, under the emitter
//!   sphere (ISO 12233 style target);
//! * [`color_chart`] — the 24 Macbeth ColorChecker reflectances (ISETCam data) under a
//!   D65-shaped emitter sphere: patch radiance = ρ(λ)·Le(λ);
//! * [`moving_bar`] — a bright vertical bar translating sideways (a glTF animation) in front
//!   of a dark wall, facing a camera that looks along −Z: its image moves at
//!   `v · f_px / Z` pixels per second (the rolling-shutter skew study);
//! * [`showcase`] — a Cornell-like room with a dispersive glass sphere, a rough gold sphere, a
//!   rough-plastic block and a thin-lens camera.
use crate::gltf_write::{
    cuboid, flat_spectrum, quad, sampled_spectrum, sphere, GltfBuilder, MeshData,
};
use camsim_core::Spectrum;
use serde_json::{json, Value};

/// Quaternion (x, y, z, w) of a rotation by `deg` about the x axis.
fn rot_x(deg: f64) -> [f64; 4] {
    let h = deg.to_radians() / 2.0;
    [h.sin(), 0.0, 0.0, h.cos()]
}

fn diffuse(name: &str, refl: Value, double_sided: bool) -> Value {
    json!({"name": name, "doubleSided": double_sided,
           "pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.5, 0.5, 1.0], "metallicFactor": 0.0, "roughnessFactor": 1.0},
           "extras": {"spectral_reflectance": refl}})
}

fn emitter_sphere(b: &mut GltfBuilder, radius: f32, le: Value) {
    let m = b.material(json!({"name": "emitter", "doubleSided": false,
        "pbrMetallicRoughness": {"baseColorFactor": [0.0, 0.0, 0.0, 1.0], "metallicFactor": 0.0, "roughnessFactor": 1.0},
        "extras": {"spectral_reflectance": flat_spectrum(0.0), "spectral_emission": le}}));
    let mesh = b.mesh("emitter_sphere", &sphere([0.0; 3], radius, 24, 48, true), m);
    b.node(json!({"name": "emitter_sphere", "mesh": mesh}), true);
}

/// Looking straight down from height `h` (camera −Z = world −Y).
fn camera_down(b: &mut GltfBuilder, h: f64, yfov_deg: f64) {
    let c = b.camera("camera", yfov_deg.to_radians(), Some(1.0), 0.001);
    b.node(json!({"name": "camera", "camera": c, "translation": [0.0, h, 0.0], "rotation": rot_x(-90.0)}), true);
}

fn ground(b: &mut GltfBuilder, half: f32, material: usize) {
    let q = quad([
        [-half, 0.0, half],
        [half, 0.0, half],
        [half, 0.0, -half],
        [-half, 0.0, -half],
    ]);
    let mesh = b.mesh("plane", &q, material);
    b.node(json!({"name": "plane", "mesh": mesh}), true);
}

/// Furnace: camera at the centre of a closed sphere (radius 1 m) of albedo `rho` emitting
/// `le` (both flat spectra).
pub fn furnace(rho: f64, le: f64) -> GltfBuilder {
    let mut b = GltfBuilder::new();
    let m = b.material(json!({"name": "furnace_wall", "doubleSided": false,
        "pbrMetallicRoughness": {"baseColorFactor": [rho, rho, rho, 1.0], "metallicFactor": 0.0, "roughnessFactor": 1.0},
        "extras": {"spectral_reflectance": flat_spectrum(rho), "spectral_emission": flat_spectrum(le)}}));
    // flat facets (no vertex normals): the furnace identity then holds exactly for the mesh
    let mut sp = sphere([0.0; 3], 1.0, 24, 48, true);
    sp.normals.clear();
    let mesh = b.mesh("sphere", &sp, m);
    b.node(json!({"name": "sphere", "mesh": mesh}), true);
    let c = b.camera("camera", 60f64.to_radians(), Some(1.0), 0.001);
    b.node(
        json!({"name": "camera", "camera": c, "rotation": [0.1, 0.2, 0.0, 0.9746794]}),
        true,
    );
    b
}

/// Uniform emitter: a 4 m square plane of albedo `rho` at y = 0 under an emitter sphere of
/// radius 10 m and radiance `le`; camera 1 m above looking down, 60° field.
pub fn uniform_emitter(rho: f64, le: f64) -> GltfBuilder {
    let mut b = GltfBuilder::new();
    emitter_sphere(&mut b, 10.0, flat_spectrum(le));
    let m = b.material(diffuse("plane", flat_spectrum(rho), false));
    ground(&mut b, 2.0, m);
    camera_down(&mut b, 1.0, 60.0);
    b
}

/// Point source: plane of albedo `rho` (8 m square) at y = 0, isotropic point light of
/// `intensity` W sr⁻¹ nm⁻¹ (flat) at height `h`; camera at height 2h looking down, 60°.
pub fn point_source(rho: f64, intensity: f64, h: f64) -> GltfBuilder {
    let mut b = GltfBuilder::new();
    let m = b.material(diffuse("plane", flat_spectrum(rho), false));
    ground(&mut b, 4.0, m);
    let l = b.light(
        json!({"type": "point", "intensity": 1.0, "color": [1.0, 1.0, 1.0],
                           "extras": {"spectral_intensity": flat_spectrum(intensity)}}),
    );
    b.node(json!({"name": "point_light", "translation": [0.0, h, 0.0], "extensions": {"KHR_lights_punctual": {"light": l}}}), true);
    camera_down(&mut b, 2.0 * h, 60.0);
    b
}

/// Slanted edge: white (ρ = 0.8) for x·cos5° + z·sin5° > 0, black (ρ = 0.05) elsewhere, 4 m
/// plane under an emitter sphere of radiance 1; camera 1 m above, 30° field.
pub fn slanted_edge() -> GltfBuilder {
    let mut b = GltfBuilder::new();
    emitter_sphere(&mut b, 10.0, flat_spectrum(1.0));
    let white = b.material(diffuse("white", flat_spectrum(0.8), false));
    let black = b.material(diffuse("black", flat_spectrum(0.05), false));
    let a = 5f32.to_radians();
    // edge through the origin along (−sin a, cos a) in (x, z); the plane is [-2, 2]²
    let h = 2.0f32;
    let t = a.tan();
    // points where the edge meets z = ±h: x = ∓h·t... edge: x cos a + z sin a = 0 → x = −z tan a
    let (xa, xb) = (-h * t, h * t); // at z = h and z = −h
    let right = quad([[xa, 0.0, h], [h, 0.0, h], [h, 0.0, -h], [xb, 0.0, -h]]);
    let left = quad([[-h, 0.0, h], [xa, 0.0, h], [xb, 0.0, -h], [-h, 0.0, -h]]);
    let mw = b.mesh("white_half", &right, white);
    let mb = b.mesh("black_half", &left, black);
    b.node(json!({"name": "white_half", "mesh": mw}), true);
    b.node(json!({"name": "black_half", "mesh": mb}), true);
    camera_down(&mut b, 1.0, 30.0);
    b
}

/// The numbers of [`moving_bar`].
pub mod moving_bar_spec {
    /// Distance of the bar's plane from the camera (m; the bar lies in z = −Z).
    pub const BAR_DISTANCE_M: f64 = 2.0;
    /// Distance of the wall behind it (m).
    pub const WALL_DISTANCE_M: f64 = 4.0;
    /// Bar width (m) and half height (m).
    pub const BAR_WIDTH_M: f64 = 0.1;
    /// Half height of the bar (m): taller than the view.
    pub const BAR_HALF_HEIGHT_M: f64 = 1.0;
    /// Velocity of the bar along +x (m/s), from its two LINEAR keyframes.
    pub const BAR_VELOCITY_M_PER_S: f64 = 8.0;
    /// x of the bar's centre at t = 0 (m).
    pub const BAR_X0_M: f64 = -0.1;
    /// Time of the last keyframe (s).
    pub const LAST_KEYFRAME_S: f64 = 0.1;
    /// Vertical field of view of the camera (degrees).
    pub const YFOV_DEG: f64 = 30.0;
    /// Emitted radiance of the bar and of the wall (W m⁻² sr⁻¹ nm⁻¹, flat spectra).
    pub const BAR_RADIANCE: f64 = 0.01;
    /// Emitted radiance of the wall.
    pub const WALL_RADIANCE: f64 = 0.001;
}

/// Moving bar: a vertical emitting bar ([`moving_bar_spec`]) in the plane z = −Z translating
/// along +x at constant speed (a two-keyframe LINEAR translation animation on node `"bar"`),
/// in front of a dimmer emitting wall; camera at the origin looking along −Z (no aspect
/// ratio: the film's own). Non-reflecting emitters, so a pixel's radiance is the
/// area-weighted mix of the two radiances.
pub fn moving_bar() -> GltfBuilder {
    use moving_bar_spec::*;
    let mut b = GltfBuilder::new();
    let emitter = |name: &str, le: f64| {
        json!({"name": name, "doubleSided": true,
            "pbrMetallicRoughness": {"baseColorFactor": [0.0, 0.0, 0.0, 1.0], "metallicFactor": 0.0, "roughnessFactor": 1.0},
            "extras": {"spectral_reflectance": flat_spectrum(0.0), "spectral_emission": flat_spectrum(le)}})
    };
    let wall_m = b.material(emitter("wall", WALL_RADIANCE));
    let bar_m = b.material(emitter("bar", BAR_RADIANCE));
    let (zw, h) = (-WALL_DISTANCE_M as f32, 4.0f32);
    let wall = quad([[-h, -h, zw], [h, -h, zw], [h, h, zw], [-h, h, zw]]);
    let mw = b.mesh("wall", &wall, wall_m);
    b.node(json!({"name": "wall", "mesh": mw}), true);
    // the bar's mesh is centred on its node; the node carries the position
    let (hw, hh) = ((BAR_WIDTH_M / 2.0) as f32, BAR_HALF_HEIGHT_M as f32);
    let bar = quad([
        [-hw, -hh, 0.0],
        [hw, -hh, 0.0],
        [hw, hh, 0.0],
        [-hw, hh, 0.0],
    ]);
    let mb = b.mesh("bar", &bar, bar_m);
    let z = -BAR_DISTANCE_M;
    let node = b.node(
        json!({"name": "bar", "mesh": mb, "translation": [BAR_X0_M, 0.0, z]}),
        true,
    );
    let x1 = BAR_X0_M + BAR_VELOCITY_M_PER_S * LAST_KEYFRAME_S;
    b.translation_animation(
        "bar_slide",
        node,
        &[0.0, LAST_KEYFRAME_S as f32],
        &[[BAR_X0_M as f32, 0.0, z as f32], [x1 as f32, 0.0, z as f32]],
        "LINEAR",
    );
    let c = b.camera("camera", YFOV_DEG.to_radians(), None, 0.001);
    b.node(json!({"name": "camera", "camera": c}), true);
    b
}

/// D65 (ISETCam) scaled to 1 at 560 nm, 5 nm steps over 360–830 nm.
pub fn d65_unit_at_560() -> Spectrum {
    let d = camsim_core::data::illuminant("D65").expect("embedded D65");
    d.scaled(1.0 / d.eval(560.0))
}

/// Chart geometry: patch `i` (row-major, 4 × 6) centre (x, z) and side (m).
pub fn chart_patch(i: usize) -> ([f32; 2], f32) {
    let (r, c) = (i / 6, i % 6);
    let pitch = 0.25f32;
    let x = (c as f32 - 2.5) * pitch;
    let z = (r as f32 - 1.5) * pitch;
    ([x, z], 0.2)
}

/// Colour chart: the 24 Macbeth patches (0.2 m, pitch 0.25 m) on a black (ρ = 0.02) board at
/// y = 0, lifted by 1 mm, under an emitter sphere with the D65 shape (1 at 560 nm); camera
/// 2 m above, 45° field. Patch i (row-major, top-left = dark skin) is at [`chart_patch`].
pub fn color_chart() -> GltfBuilder {
    let mut b = GltfBuilder::new();
    emitter_sphere(&mut b, 10.0, sampled_spectrum(&d65_unit_at_560(), 5.0));
    let board = b.material(diffuse("board", flat_spectrum(0.02), false));
    ground(&mut b, 1.5, board);
    let refl = camsim_core::data::macbeth_reflectances_row_major().expect("embedded Macbeth");
    for (i, s) in refl.iter().enumerate() {
        let m = b.material(diffuse(
            &format!("patch{i:02}"),
            sampled_spectrum(s, 5.0),
            false,
        ));
        let ([x, z], side) = chart_patch(i);
        let h = side / 2.0;
        let q = quad([
            [x - h, 0.001, z + h],
            [x + h, 0.001, z + h],
            [x + h, 0.001, z - h],
            [x - h, 0.001, z - h],
        ]);
        let mesh = b.mesh(&format!("patch{i:02}"), &q, m);
        b.node(json!({"name": format!("patch{i:02}"), "mesh": mesh}), true);
    }
    camera_down(&mut b, 2.0, 45.0);
    b
}

/// Showcase: a 2 m Cornell-like room (white/red/green walls, ceiling light) with a dispersive
/// glass sphere (N-BK7-like, Abbe 64), a rough gold sphere (Au, α = 0.15), a rough-plastic
/// block and a thin-lens camera focused on the glass sphere.
pub fn showcase() -> GltfBuilder {
    let mut b = GltfBuilder::new();
    let white = b.material(diffuse("white", flat_spectrum(0.75), false));
    let red = b.material(diffuse(
        "red",
        json!({"wavelength_nm": [360.0, 580.0, 610.0, 830.0], "values": [0.06, 0.08, 0.65, 0.7]}),
        false,
    ));
    let green = b.material(diffuse("green", json!({"wavelength_nm": [360.0, 480.0, 530.0, 580.0, 830.0], "values": [0.06, 0.1, 0.5, 0.1, 0.06]}), false));
    let light = b.material(json!({"name": "light", "pbrMetallicRoughness": {"baseColorFactor": [0.0, 0.0, 0.0, 1.0], "metallicFactor": 0.0},
        "emissiveFactor": [1.0, 1.0, 1.0], "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 15.0}}}));
    b.use_extension("KHR_materials_emissive_strength", false);
    let glass = b.material(json!({"name": "glass", "pbrMetallicRoughness": {"baseColorFactor": [1.0, 1.0, 1.0, 1.0], "metallicFactor": 0.0, "roughnessFactor": 0.0},
        "extensions": {"KHR_materials_transmission": {"transmissionFactor": 1.0}, "KHR_materials_ior": {"ior": 1.5168}},
        "extras": {"dispersion": {"abbe_number": 64.17}}}));
    b.use_extension("KHR_materials_transmission", false);
    b.use_extension("KHR_materials_ior", false);
    let gold = b.material(json!({"name": "gold", "pbrMetallicRoughness": {"metallicFactor": 1.0, "roughnessFactor": 0.4},
        "extras": {"mitsuba_bsdf": {"type": "roughconductor", "material": "Au", "alpha": 0.15, "distribution": "ggx"}}}));
    let plastic = b.material(json!({"name": "blue_plastic", "pbrMetallicRoughness": {"metallicFactor": 0.0},
        "extras": {"mitsuba_bsdf": {"type": "roughplastic", "alpha": 0.1, "distribution": "ggx", "int_ior": 1.5,
                    "diffuse_reflectance": {"type": "rgb", "value": [0.1, 0.2, 0.6]}}}}));
    let s = 1.0f32;
    let walls: [(&str, [[f32; 3]; 4], usize); 5] = [
        (
            "floor",
            [[-s, 0.0, s], [s, 0.0, s], [s, 0.0, -s], [-s, 0.0, -s]],
            white,
        ),
        (
            "ceiling",
            [[-s, 2.0, -s], [s, 2.0, -s], [s, 2.0, s], [-s, 2.0, s]],
            white,
        ),
        (
            "back",
            [[-s, 0.0, -s], [s, 0.0, -s], [s, 2.0, -s], [-s, 2.0, -s]],
            white,
        ),
        (
            "left",
            [[-s, 0.0, s], [-s, 0.0, -s], [-s, 2.0, -s], [-s, 2.0, s]],
            red,
        ),
        (
            "right",
            [[s, 0.0, -s], [s, 0.0, s], [s, 2.0, s], [s, 2.0, -s]],
            green,
        ),
    ];
    for (name, q, m) in walls {
        let mesh = b.mesh(name, &quad(q), m);
        b.node(json!({"name": name, "mesh": mesh}), true);
    }
    let l = 0.3f32;
    let lq = quad([[-l, 1.99, -l], [l, 1.99, -l], [l, 1.99, l], [-l, 1.99, l]]);
    let lm = b.mesh("light", &lq, light);
    b.node(json!({"name": "light", "mesh": lm}), true);
    let gs = b.mesh("glass_sphere", &sphere([0.0; 3], 0.3, 32, 64, false), glass);
    b.node(
        json!({"name": "glass_sphere", "mesh": gs, "translation": [0.4, 0.3, 0.2]}),
        true,
    );
    let au = b.mesh("gold_sphere", &sphere([0.0; 3], 0.3, 32, 64, false), gold);
    b.node(
        json!({"name": "gold_sphere", "mesh": au, "translation": [-0.45, 0.3, -0.3]}),
        true,
    );
    let mut blk = MeshData::default();
    blk.append(&cuboid([-0.2, 0.0, -0.2], [0.2, 0.6, 0.2], false));
    let pb = b.mesh("plastic_block", &blk, plastic);
    b.node(json!({"name": "plastic_block", "mesh": pb, "translation": [0.35, 0.0, -0.5], "rotation": [0.0, 0.2588190, 0.0, 0.9659258]}), true);
    let c = b.camera("camera", 40f64.to_radians(), Some(1.0), 0.01);
    b.node(
        json!({"name": "camera", "camera": c, "translation": [0.0, 1.0, 3.9],
                  "extras": {"thinlens": {"aperture_radius": 0.03, "focus_distance": 3.7}}}),
        true,
    );
    b
}

/// Every scene of scenes/ by file stem.
pub fn all() -> Vec<(&'static str, GltfBuilder)> {
    vec![
        ("furnace", furnace(0.5, 1.0)),
        ("uniform_emitter", uniform_emitter(0.6, 1.0)),
        ("point_source", point_source(0.8, 10.0, 1.0)),
        ("slanted_edge", slanted_edge()),
        ("color_chart", color_chart()),
        ("showcase", showcase()),
        ("moving_bar", moving_bar()),
    ]
}
