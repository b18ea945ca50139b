//! A small glTF 2.0 writer for generated scenes (the test scenes of scenes/ and the test
//! suite): meshes with positions, normals, texture coordinates and u32 indices in one binary
//! buffer, materials, cameras, lights and nodes given as JSON. Writes `.gltf` + `.bin`, or a
//! single `.gltf` with the buffer as a base64 data URI.
use serde_json::{json, Value};
use std::path::Path;

/// Triangle mesh data (CCW winding = front face).
#[derive(Debug, Clone, Default)]
pub struct MeshData {
    /// Vertex positions.
    pub positions: Vec<[f32; 3]>,
    /// Vertex normals (empty = none).
    pub normals: Vec<[f32; 3]>,
    /// Texture coordinates (empty = none).
    pub uvs: Vec<[f32; 2]>,
    /// Triangle indices.
    pub indices: Vec<u32>,
}

impl MeshData {
    /// Append another mesh.
    pub fn append(&mut self, o: &MeshData) {
        let base = self.positions.len() as u32;
        self.positions.extend_from_slice(&o.positions);
        self.normals.extend_from_slice(&o.normals);
        self.uvs.extend_from_slice(&o.uvs);
        self.indices.extend(o.indices.iter().map(|i| i + base));
    }
}

fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
fn normalize(a: [f32; 3]) -> [f32; 3] {
    let l = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
    [a[0] / l, a[1] / l, a[2] / l]
}

/// A quad p0 p1 p2 p3 (CCW seen from the front), flat normals, uvs (0,0) (1,0) (1,1) (0,1).
pub fn quad(p: [[f32; 3]; 4]) -> MeshData {
    let n = normalize(cross(sub(p[1], p[0]), sub(p[2], p[0])));
    MeshData {
        positions: p.to_vec(),
        normals: vec![n; 4],
        uvs: vec![[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]],
        indices: vec![0, 1, 2, 0, 2, 3],
    }
}

/// A UV sphere of `radius` about `center` with `rings × segments` quads; normals point
/// outward (or inward, with the winding flipped so that the front faces inward).
pub fn sphere(center: [f32; 3], radius: f32, rings: u32, segments: u32, inward: bool) -> MeshData {
    let mut m = MeshData::default();
    for r in 0..=rings {
        let th = std::f32::consts::PI * r as f32 / rings as f32;
        for s in 0..=segments {
            let ph = 2.0 * std::f32::consts::PI * s as f32 / segments as f32;
            let n = [th.sin() * ph.cos(), th.cos(), -th.sin() * ph.sin()];
            m.positions.push([
                center[0] + radius * n[0],
                center[1] + radius * n[1],
                center[2] + radius * n[2],
            ]);
            m.normals
                .push(if inward { [-n[0], -n[1], -n[2]] } else { n });
            m.uvs
                .push([s as f32 / segments as f32, r as f32 / rings as f32]);
        }
    }
    let w = segments + 1;
    for r in 0..rings {
        for s in 0..segments {
            let (a, b, c, d) = (
                r * w + s,
                (r + 1) * w + s,
                (r + 1) * w + s + 1,
                r * w + s + 1,
            );
            // outward CCW: a, b, c / a, c, d (θ down, φ around)
            if inward {
                m.indices.extend_from_slice(&[a, c, b, a, d, c]);
            } else {
                m.indices.extend_from_slice(&[a, b, c, a, c, d]);
            }
        }
    }
    // drop the degenerate pole triangles' zero area automatically (the loader skips them)
    m
}

/// An axis-aligned box [lo, hi] with outward (or inward) flat faces.
pub fn cuboid(lo: [f32; 3], hi: [f32; 3], inward: bool) -> MeshData {
    let c = |x: usize, y: usize, z: usize| {
        [
            if x == 0 { lo[0] } else { hi[0] },
            if y == 0 { lo[1] } else { hi[1] },
            if z == 0 { lo[2] } else { hi[2] },
        ]
    };
    // outward CCW faces
    let faces = [
        [c(0, 0, 0), c(0, 0, 1), c(0, 1, 1), c(0, 1, 0)], // −x
        [c(1, 0, 0), c(1, 1, 0), c(1, 1, 1), c(1, 0, 1)], // +x
        [c(0, 0, 0), c(1, 0, 0), c(1, 0, 1), c(0, 0, 1)], // −y
        [c(0, 1, 0), c(0, 1, 1), c(1, 1, 1), c(1, 1, 0)], // +y
        [c(0, 0, 0), c(0, 1, 0), c(1, 1, 0), c(1, 0, 0)], // −z
        [c(0, 0, 1), c(1, 0, 1), c(1, 1, 1), c(0, 1, 1)], // +z
    ];
    let mut m = MeshData::default();
    for f in faces {
        let q = if inward {
            quad([f[0], f[3], f[2], f[1]])
        } else {
            quad(f)
        };
        m.append(&q);
    }
    m
}

/// A glTF document under construction.
#[derive(Debug, Clone, Default)]
pub struct GltfBuilder {
    animations: Vec<Value>,
    bin: Vec<u8>,
    buffer_views: Vec<Value>,
    accessors: Vec<Value>,
    meshes: Vec<Value>,
    materials: Vec<Value>,
    cameras: Vec<Value>,
    nodes: Vec<Value>,
    lights: Vec<Value>,
    roots: Vec<usize>,
    extensions_used: Vec<String>,
    extensions_required: Vec<String>,
    images: Vec<Value>,
    textures: Vec<Value>,
    scene_extras: Option<Value>,
}

impl GltfBuilder {
    /// An empty document.
    pub fn new() -> Self {
        Self::default()
    }

    fn view(&mut self, bytes: &[u8], target: u32) -> usize {
        while self.bin.len() % 4 != 0 {
            self.bin.push(0);
        }
        let off = self.bin.len();
        self.bin.extend_from_slice(bytes);
        self.buffer_views.push(
            json!({"buffer": 0, "byteOffset": off, "byteLength": bytes.len(), "target": target}),
        );
        self.buffer_views.len() - 1
    }

    fn accessor_f32(&mut self, data: &[f32], n: usize, ty: &str, minmax: bool) -> usize {
        let bytes: Vec<u8> = data.iter().flat_map(|v| v.to_le_bytes()).collect();
        let v = self.view(&bytes, 34962);
        let mut a =
            json!({"bufferView": v, "componentType": 5126, "count": data.len() / n, "type": ty});
        if minmax && !data.is_empty() {
            let mut lo = vec![f32::INFINITY; n];
            let mut hi = vec![f32::NEG_INFINITY; n];
            for c in data.chunks(n) {
                for k in 0..n {
                    lo[k] = lo[k].min(c[k]);
                    hi[k] = hi[k].max(c[k]);
                }
            }
            a["min"] = json!(lo);
            a["max"] = json!(hi);
        }
        self.accessors.push(a);
        self.accessors.len() - 1
    }

    /// Add a material (a glTF material object); returns its index.
    pub fn material(&mut self, m: Value) -> usize {
        self.materials.push(m);
        self.materials.len() - 1
    }

    /// Add a one-primitive mesh; returns its index.
    pub fn mesh(&mut self, name: &str, m: &MeshData, material: usize) -> usize {
        let pos: Vec<f32> = m.positions.iter().flatten().copied().collect();
        let p = self.accessor_f32(&pos, 3, "VEC3", true);
        let mut attrs = json!({"POSITION": p});
        if !m.normals.is_empty() {
            let nor: Vec<f32> = m.normals.iter().flatten().copied().collect();
            attrs["NORMAL"] = json!(self.accessor_f32(&nor, 3, "VEC3", false));
        }
        if !m.uvs.is_empty() {
            let uv: Vec<f32> = m.uvs.iter().flatten().copied().collect();
            attrs["TEXCOORD_0"] = json!(self.accessor_f32(&uv, 2, "VEC2", false));
        }
        let bytes: Vec<u8> = m.indices.iter().flat_map(|v| v.to_le_bytes()).collect();
        let v = self.view(&bytes, 34963);
        self.accessors.push(json!({"bufferView": v, "componentType": 5125, "count": m.indices.len(), "type": "SCALAR"}));
        let idx = self.accessors.len() - 1;
        self.meshes.push(json!({"name": name, "primitives": [{"attributes": attrs, "indices": idx, "material": material, "mode": 4}]}));
        self.meshes.len() - 1
    }

    /// Add a one-primitive mesh with a `TANGENT` attribute (xyz unit tangent, w = ±1 the
    /// bitangent sign; one per vertex); returns its index.
    pub fn mesh_with_tangents(
        &mut self,
        name: &str,
        m: &MeshData,
        tangents: &[[f32; 4]],
        material: usize,
    ) -> usize {
        let i = self.mesh(name, m, material);
        let t: Vec<f32> = tangents.iter().flatten().copied().collect();
        let a = self.accessor_f32(&t, 4, "VEC4", false);
        self.meshes[i]["primitives"][0]["attributes"]["TANGENT"] = json!(a);
        i
    }

    /// Add a perspective camera; returns its index.
    pub fn camera(&mut self, name: &str, yfov_rad: f64, aspect: Option<f64>, znear: f64) -> usize {
        let mut p = json!({"yfov": yfov_rad, "znear": znear});
        if let Some(a) = aspect {
            p["aspectRatio"] = json!(a);
        }
        self.cameras
            .push(json!({"name": name, "type": "perspective", "perspective": p}));
        self.cameras.len() - 1
    }

    /// Add a KHR_lights_punctual light (the light object); returns its index.
    pub fn light(&mut self, l: Value) -> usize {
        if !self
            .extensions_used
            .iter()
            .any(|e| e == "KHR_lights_punctual")
        {
            self.extensions_used.push("KHR_lights_punctual".into());
        }
        self.lights.push(l);
        self.lights.len() - 1
    }

    /// Add a node (any glTF node object); `root` puts it in the scene's root list.
    pub fn node(&mut self, n: Value, root: bool) -> usize {
        self.nodes.push(n);
        let i = self.nodes.len() - 1;
        if root {
            self.roots.push(i);
        }
        i
    }

    /// Add an animation of node `node`'s translation: keyframe `times_s` and `translations_m`,
    /// `interpolation` `"LINEAR"` or `"STEP"` (glTF 2.0 §3.11); returns its index.
    pub fn translation_animation(
        &mut self,
        name: &str,
        node: usize,
        times_s: &[f32],
        translations_m: &[[f32; 3]],
        interpolation: &str,
    ) -> usize {
        let input = self.accessor_f32(times_s, 1, "SCALAR", true);
        let flat: Vec<f32> = translations_m.iter().flatten().copied().collect();
        let output = self.accessor_f32(&flat, 3, "VEC3", false);
        // animation data is not a vertex attribute: no bufferView target
        for a in [input, output] {
            let v = self.accessors[a]["bufferView"].as_u64().expect("view") as usize;
            if let Some(o) = self.buffer_views[v].as_object_mut() {
                o.remove("target");
            }
        }
        self.animations.push(json!({
            "name": name,
            "samplers": [{"input": input, "output": output, "interpolation": interpolation}],
            "channels": [{"sampler": 0, "target": {"node": node, "path": "translation"}}],
        }));
        self.animations.len() - 1
    }

    /// Declare an extension as used (and required).
    pub fn use_extension(&mut self, name: &str, required: bool) {
        if !self.extensions_used.iter().any(|e| e == name) {
            self.extensions_used.push(name.into());
        }
        if required && !self.extensions_required.iter().any(|e| e == name) {
            self.extensions_required.push(name.into());
        }
    }

    /// The JSON document with the buffer at `uri`.
    pub fn document(&self, uri: &str) -> Value {
        let mut d = json!({
            "asset": {"version": "2.0", "generator": "camsim-render gltf_write"},
            "scene": 0,
            "scenes": [{"nodes": self.roots}],
            "nodes": self.nodes,
            "meshes": self.meshes,
            "materials": self.materials,
            "accessors": self.accessors,
            "bufferViews": self.buffer_views,
            "buffers": [{"byteLength": self.bin.len(), "uri": uri}],
        });
        if !self.cameras.is_empty() {
            d["cameras"] = json!(self.cameras);
        }
        if !self.animations.is_empty() {
            d["animations"] = json!(self.animations);
        }
        if !self.images.is_empty() {
            d["images"] = json!(self.images);
            d["textures"] = json!(self.textures);
        }
        if !self.lights.is_empty() {
            d["extensions"] = json!({"KHR_lights_punctual": {"lights": self.lights}});
        }
        if !self.extensions_used.is_empty() {
            d["extensionsUsed"] = json!(self.extensions_used);
        }
        if !self.extensions_required.is_empty() {
            d["extensionsRequired"] = json!(self.extensions_required);
        }
        if let Some(e) = &self.scene_extras {
            d["scenes"][0]["extras"] = e.clone();
        }
        d
    }

    /// Set the `extras` of the scene (e.g. `camsim_environment_exr`).
    pub fn scene_extras(&mut self, extras: Value) {
        self.scene_extras = Some(extras);
    }

    /// Write `path` (.gltf) and its buffer `path` with extension .bin.
    pub fn write(&self, path: &Path) -> std::io::Result<()> {
        let bin_path = path.with_extension("bin");
        let uri = bin_path
            .file_name()
            .map(|n| n.to_string_lossy().to_string())
            .unwrap_or_default();
        std::fs::write(&bin_path, &self.bin)?;
        let text =
            serde_json::to_string_pretty(&self.document(&uri)).map_err(std::io::Error::other)?;
        std::fs::write(path, text)
    }

    /// Write a binary glTF (.glb): JSON chunk + BIN chunk.
    pub fn write_glb(&self, path: &Path) -> std::io::Result<()> {
        let mut doc = self.document("");
        doc["buffers"] = json!([{"byteLength": self.bin.len()}]);
        let mut js = serde_json::to_vec(&doc).map_err(std::io::Error::other)?;
        while js.len() % 4 != 0 {
            js.push(b' ');
        }
        let mut bin = self.bin.clone();
        while bin.len() % 4 != 0 {
            bin.push(0);
        }
        let total = 12 + 8 + js.len() + 8 + bin.len();
        let mut out = Vec::with_capacity(total);
        out.extend_from_slice(b"glTF");
        out.extend_from_slice(&2u32.to_le_bytes());
        out.extend_from_slice(&(total as u32).to_le_bytes());
        out.extend_from_slice(&(js.len() as u32).to_le_bytes());
        out.extend_from_slice(b"JSON");
        out.extend_from_slice(&js);
        out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
        out.extend_from_slice(b"BIN\0");
        out.extend_from_slice(&bin);
        std::fs::write(path, out)
    }

    /// Add an image with an embedded PNG (bytes) in the binary buffer and a texture using
    /// it; returns the texture index.
    pub fn png_texture(&mut self, png: &[u8]) -> usize {
        let v = self.view(png, 0);
        self.buffer_views[v]
            .as_object_mut()
            .map(|o| o.remove("target"));
        self.images
            .push(json!({"bufferView": v, "mimeType": "image/png"}));
        self.textures.push(json!({"source": self.images.len() - 1}));
        self.textures.len() - 1
    }

    /// Write one self-contained .gltf with the buffer as a base64 data URI.
    pub fn write_embedded(&self, path: &Path) -> std::io::Result<()> {
        let uri = format!("data:application/octet-stream;base64,{}", base64(&self.bin));
        let text = serde_json::to_string(&self.document(&uri)).map_err(std::io::Error::other)?;
        std::fs::write(path, text)
    }
}

/// Standard base64 (RFC 4648) with padding.
pub fn base64(data: &[u8]) -> String {
    const T: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::with_capacity(data.len().div_ceil(3) * 4);
    for c in data.chunks(3) {
        let b = [c[0], *c.get(1).unwrap_or(&0), *c.get(2).unwrap_or(&0)];
        let n = ((b[0] as u32) << 16) | ((b[1] as u32) << 8) | b[2] as u32;
        s.push(T[(n >> 18) as usize & 63] as char);
        s.push(T[(n >> 12) as usize & 63] as char);
        s.push(if c.len() > 1 {
            T[(n >> 6) as usize & 63] as char
        } else {
            '='
        });
        s.push(if c.len() > 2 {
            T[n as usize & 63] as char
        } else {
            '='
        });
    }
    s
}

/// `{"wavelength_nm": [...], "values": [...]}` of a constant over 360–830 nm.
pub fn flat_spectrum(v: f64) -> Value {
    json!({"wavelength_nm": [360.0, 830.0], "values": [v, v]})
}

/// `{"wavelength_nm": [...], "values": [...]}` of a core spectrum sampled every `step` nm on
/// 360–830 nm.
pub fn sampled_spectrum(s: &camsim_core::Spectrum, step: f64) -> Value {
    let n = ((830.0 - 360.0) / step).round() as usize;
    let w: Vec<f64> = (0..=n).map(|i| 360.0 + step * i as f64).collect();
    let v: Vec<f64> = w.iter().map(|&x| s.eval(x)).collect();
    json!({"wavelength_nm": w, "values": v})
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_matches_rfc4648_vectors() {
        assert_eq!(base64(b""), "");
        assert_eq!(base64(b"f"), "Zg==");
        assert_eq!(base64(b"fo"), "Zm8=");
        assert_eq!(base64(b"foo"), "Zm9v");
        assert_eq!(base64(b"foobar"), "Zm9vYmFy");
    }
}
