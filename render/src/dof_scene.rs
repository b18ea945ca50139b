//! The depth-of-field test scene (scenes/dof_tiles.gltf, `camsim study` depth-of-field
//! study): fronto-parallel tiles, each carrying an ISO 12233 style slanted edge (radiance 0.8
//! right of the edge, 0.2 left: 4:1 contrast, tilted by `edge_angle_deg` with its top leaning
//! right), at one planar depth per tile, laid out on a grid of square image cells so that no
//! tile hides another (each tile exactly fills its cell's view frustum). The tiles are
//! self-luminous and non-reflecting (a back-lit transparency), so the scene radiance is known
//! exactly and noise-free. The camera sits at the origin looking down −Z (glTF convention),
//! +Y up.
use crate::gltf_write::{flat_spectrum, quad, GltfBuilder};
use serde_json::json;

/// The layout of the depth-of-field scene.
#[derive(Debug, Clone, PartialEq)]
pub struct DofTiles {
    /// Planar depth of each tile (m), in cell order (row-major from the top left).
    pub depths_m: Vec<f64>,
    /// Cells per row.
    pub cols: usize,
    /// Vertical field of view of the camera (degrees).
    pub yfov_deg: f64,
    /// Edge tilt (degrees from vertical; ISO 12233 ≈ 5°).
    pub edge_angle_deg: f64,
}

/// A cell of the image in pixels: [x0, x1) × [y0, y1) (continuous film coordinates).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CellPx {
    /// Left edge (px).
    pub x0: f64,
    /// Right edge (px).
    pub x1: f64,
    /// Top edge (px).
    pub y0: f64,
    /// Bottom edge (px).
    pub y1: f64,
}

impl DofTiles {
    /// Cell rows.
    pub fn rows(&self) -> usize {
        self.depths_m.len().div_ceil(self.cols.max(1))
    }

    /// Image aspect ratio (width / height) for square cells.
    pub fn aspect(&self) -> f64 {
        self.cols as f64 / self.rows() as f64
    }

    /// Image height (px) for `width_px` (square cells).
    pub fn height_px(&self, width_px: u32) -> u32 {
        ((width_px as f64 / self.aspect()).round() as u32).max(1)
    }

    /// Cell `k` on a `width_px × height_px` film.
    pub fn cell_px(&self, k: usize, width_px: u32, height_px: u32) -> CellPx {
        let (c, r) = (k % self.cols, k / self.cols);
        let cw = width_px as f64 / self.cols as f64;
        let ch = height_px as f64 / self.rows() as f64;
        CellPx {
            x0: c as f64 * cw,
            x1: (c + 1) as f64 * cw,
            y0: r as f64 * ch,
            y1: (r + 1) as f64 * ch,
        }
    }

    /// Check the layout (message names the bad value).
    pub fn validate(&self) -> Result<(), String> {
        if self.depths_m.is_empty() || self.cols == 0 {
            return Err("need at least one depth and cols ≥ 1".into());
        }
        if let Some(z) = self.depths_m.iter().find(|z| !(z.is_finite() && **z > 0.0)) {
            return Err(format!("depth {z} m must be a positive finite number"));
        }
        if !(self.yfov_deg > 0.0 && self.yfov_deg < 90.0) {
            return Err(format!("yfov_deg {} must be in (0, 90)", self.yfov_deg));
        }
        if !(self.edge_angle_deg.abs() >= 1.0 && self.edge_angle_deg.abs() <= 20.0) {
            return Err(format!(
                "edge_angle_deg {} must be 1–20° in magnitude",
                self.edge_angle_deg
            ));
        }
        Ok(())
    }

    /// The glTF scene.
    pub fn builder(&self) -> GltfBuilder {
        let mut b = GltfBuilder::new();
        // self-luminous tiles (no reflection): the radiance is exactly the emission, so the
        // only Monte Carlo noise is that of the camera's own (pupil, pixel) sampling
        let mat = |b: &mut GltfBuilder, name: &str, le: f64| {
            b.material(json!({"name": name, "doubleSided": true,
                "pbrMetallicRoughness": {"baseColorFactor": [0.0, 0.0, 0.0, 1.0], "metallicFactor": 0.0, "roughnessFactor": 1.0},
                "extras": {"spectral_reflectance": flat_spectrum(0.0), "spectral_emission": flat_spectrum(le)}}))
        };
        let white = mat(&mut b, "white", 0.8);
        let black = mat(&mut b, "black", 0.2);
        let th = (0.5 * self.yfov_deg.to_radians()).tan();
        let tw = th * self.aspect();
        let (cols, rows) = (self.cols as f64, self.rows() as f64);
        let t = self.edge_angle_deg.to_radians().tan();
        for (k, &z) in self.depths_m.iter().enumerate() {
            let (c, r) = ((k % self.cols) as f64, (k / self.cols) as f64);
            // cell bounds on the z = −1 plane (y up; row 0 at the top)
            let (xl, xr) = (-tw + 2.0 * tw * c / cols, -tw + 2.0 * tw * (c + 1.0) / cols);
            let (yt, yb) = (th - 2.0 * th * r / rows, th - 2.0 * th * (r + 1.0) / rows);
            let (xc, yc) = (0.5 * (xl + xr), 0.5 * (yt + yb));
            // the edge x = xc + (y − yc)·tan a (top leans right for a > 0)
            let (xe_t, xe_b) = (xc + (yt - yc) * t, xc + (yb - yc) * t);
            let p = |x: f64, y: f64| [(x * z) as f32, (y * z) as f32, -z as f32];
            let right = quad([p(xe_b, yb), p(xr, yb), p(xr, yt), p(xe_t, yt)]);
            let left = quad([p(xl, yb), p(xe_b, yb), p(xe_t, yt), p(xl, yt)]);
            let mw = b.mesh(&format!("tile{k}_white"), &right, white);
            let mb = b.mesh(&format!("tile{k}_black"), &left, black);
            b.node(json!({"name": format!("tile{k}_white"), "mesh": mw}), true);
            b.node(json!({"name": format!("tile{k}_black"), "mesh": mb}), true);
        }
        let cam = b.camera(
            "camera",
            self.yfov_deg.to_radians(),
            Some(self.aspect()),
            0.001,
        );
        b.node(json!({"name": "camera", "camera": cam}), true);
        b
    }
}

/// The shipped layout (scenes/dof_tiles.gltf): 16 tiles at vergences 1/z evenly spaced from
/// 0.12 to 0.88 m⁻¹ (z = 1.14–8.33 m) around a 2 m focus, 4 per row, 2.5° vertical field
/// (a 50 mm lens on a ≈ 2.2 mm high sensor).
pub fn shipped() -> DofTiles {
    DofTiles {
        depths_m: (0..16)
            .map(|k| 1.0 / (0.12 + 0.76 * k as f64 / 15.0))
            .collect(),
        cols: 4,
        yfov_deg: 2.5,
        edge_angle_deg: 5.0,
    }
}

/// Settings of [`render_dof`].
#[derive(Debug, Clone, PartialEq)]
pub struct DofRenderOptions {
    /// Film width (px); the height follows the layout (square cells).
    pub width_px: u32,
    /// Samples per pixel of the real-lens render.
    pub spp_lens: u32,
    /// Samples per pixel of the pinhole render (the depth path's input).
    pub spp_pinhole: u32,
    /// Seed.
    pub seed: u64,
    /// Band range (nm): one band [lo, hi].
    pub band_nm: (f64, f64),
    /// F-number the lens is stopped to.
    pub f_number: f64,
    /// Focus distance from the entrance pupil (m).
    pub focus_distance_m: f64,
    /// Depth-path layers.
    pub layers: usize,
    /// Render the real-lens image (false: depth path only).
    pub real_lens: bool,
    /// How the lens is focused (`camsim_lens::focus_model`); both paths use the real-lens
    /// camera's resolved method, so they share one focus plane.
    pub focus_method: camsim_lens::FocusMethod,
}

/// The images of [`render_dof`] (one band, row-major `width × height`).
#[derive(Debug, Clone)]
pub struct DofRenders {
    /// Film width (px).
    pub width: usize,
    /// Film height (px).
    pub height: usize,
    /// Sensor pixel pitch of the real-lens camera (mm).
    pub pixel_pitch_mm: f64,
    /// Real-lens sensor irradiance (W/(m²·nm)), if rendered.
    pub real_lens: Option<Vec<f32>>,
    /// Its per-pixel variance of the estimate.
    pub real_lens_variance: Option<Vec<f32>>,
    /// Pinhole radiance (W/(m²·sr·nm)).
    pub pinhole: Vec<f32>,
    /// Planar depth (m).
    pub depth_m: Vec<f32>,
    /// Depth path: the pinhole radiance defocused with the lens PSFs.
    pub depth_path: Vec<f32>,
    /// How the lens was focused (both paths).
    pub focus: camsim_lens::FocusedLens,
    /// Entrance-pupil radius of the stopped lens (m).
    pub entrance_pupil_radius_m: f64,
    /// Render times (s): real lens, pinhole, depth path.
    pub times_s: [f64; 3],
}

/// Render the tiles through the real lens (sensor irradiance) and a pinhole at its entrance
/// pupil, and defocus the pinhole image with the lens's PSF per depth (the depth path,
/// [`crate::depth_path::LensDefocus`]). The real-lens film fits the scene camera's field, so
/// both images have the same paraxial geometry.
pub fn render_dof(
    tiles: &DofTiles,
    lens: &camsim_lens::LensPrescription,
    o: &DofRenderOptions,
) -> Result<DofRenders, String> {
    use crate::camera::real_lens::{FilmSize, RealLensCamera, RealLensOptions};
    use crate::camera::Pinhole;
    use crate::depth_path::{
        defocus_layered, slab_inverse_depths, LensDefocus, LensDefocusOptions,
    };
    use crate::{render, Bands, RenderSettings};
    tiles.validate()?;
    static COUNTER: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let dir = std::env::temp_dir().join(format!(
        "camsim_dof_{}_{}",
        std::process::id(),
        COUNTER.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
    ));
    std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let path = dir.join("dof_tiles.gltf");
    tiles
        .builder()
        .write(&path)
        .map_err(|e| format!("{}: {e}", path.display()))?;
    let scene = crate::gltf_load::load_gltf(&path).map_err(|e| e.to_string());
    let _ = std::fs::remove_dir_all(&dir);
    let scene = scene?;
    let sc = crate::gltf_load::pick_camera(&scene, None)?;
    let (w, h) = (o.width_px, tiles.height_px(o.width_px));
    let bands = Bands::new(o.band_nm.0, o.band_nm.1, o.band_nm.1 - o.band_nm.0)
        .map_err(|e| format!("band: {e}"))?;
    let settings = |spp: u32, seed: u64, variance: bool| RenderSettings {
        spp,
        seed,
        bands: bands.clone(),
        variance,
        depth_spp: 0,
        ..Default::default()
    };
    let cam = RealLensCamera::new(
        lens,
        w,
        h,
        &RealLensOptions {
            focus_distance_m: Some(o.focus_distance_m),
            f_number: Some(o.f_number),
            film: FilmSize::VerticalFovRad(sc.yfov_rad as f64),
            pupil_bins: 8,
            pupil_grid: 48,
            wavelength_range_nm: (o.band_nm.0, o.band_nm.1),
            focus_method: {
                // the merit's wavelengths: the rendered band's (as the depth path's PSFs)
                let mut m = o.focus_method.clone();
                let (lo, hi) = o.band_nm;
                m.wavelengths_nm = m.wavelengths_nm.or_else(|| {
                    Some(
                        (0..5)
                            .map(|k| lo + (hi - lo) * (k as f64 + 0.5) / 5.0)
                            .collect(),
                    )
                });
                m
            },
        },
    )
    .map_err(|e| e.to_string())?;
    let pitch = cam.info().pixel_pitch_mm;
    let t0 = std::time::Instant::now();
    let (real, real_var) = if o.real_lens {
        let r = render(
            &scene,
            &cam,
            sc.to_world,
            &settings(o.spp_lens, o.seed, true),
            None,
        );
        (
            Some(r.band_planes[0].clone()),
            r.variance_planes.map(|v| v[0].clone()),
        )
    } else {
        (None, None)
    };
    let t1 = std::time::Instant::now();
    let pin = render(
        &scene,
        &Pinhole {
            perspective: sc.perspective(w, h),
        },
        sc.to_world,
        &settings(o.spp_pinhole, o.seed ^ 0x9e37_79b9, false),
        None,
    );
    let t2 = std::time::Instant::now();
    let (w, h) = (w as usize, h as usize);
    let invs = slab_inverse_depths(&pin.depth_z_m, o.layers);
    let (lo, hi) = o.band_nm;
    let defocus = LensDefocus::new(
        lens,
        &LensDefocusOptions {
            f_number: Some(o.f_number),
            focus_distance_m: Some(o.focus_distance_m),
            pixel_pitch_mm: pitch,
            wavelengths_nm: (0..5)
                .map(|k| lo + (hi - lo) * (k as f64 + 0.5) / 5.0)
                .collect(),
            pupil_n: 128,
            focus_method: cam.info().focus.method.clone(),
        },
        &invs,
    )
    .map_err(|e| e.to_string())?;
    let dp = defocus_layered(&pin.band_planes, &pin.depth_z_m, w, h, o.layers, |iz| {
        defocus.kernel(iz)
    });
    let t3 = std::time::Instant::now();
    Ok(DofRenders {
        width: w,
        height: h,
        pixel_pitch_mm: pitch,
        real_lens: real,
        real_lens_variance: real_var,
        pinhole: pin.band_planes[0].clone(),
        depth_m: pin.depth_z_m.clone(),
        depth_path: dp[0].clone(),
        focus: cam.info().focus.clone(),
        entrance_pupil_radius_m: defocus.entrance_pupil_radius_m,
        times_s: [
            (t1 - t0).as_secs_f64(),
            (t2 - t1).as_secs_f64(),
            (t3 - t2).as_secs_f64(),
        ],
    })
}
