//! Cameras: the fixed interface between the integrator and every camera model.
//!
//! A camera turns a film position (pixels) and a lens sample into a ray in **camera space**
//! (metres; the glTF convention: the camera looks down −Z, +Y is up, +X is right; film pixel
//! (0,0) is the top-left pixel and pixel centres sit at (i+0.5, j+0.5)). The renderer moves
//! the ray to world space with the glTF camera node's world matrix (scale removed).
//!
//! Implemented here: [`Pinhole`] (the glTF perspective camera, Mitsuba `perspective`) and
//! [`ThinLens`] (Mitsuba `thinlens`: aperture radius, planar focus distance). The real-lens and
//! light-field cameras live in their own modules.
use glam::{Vec2, Vec3};

pub mod lightfield;
pub mod real_lens;

/// A ray leaving the camera, in CAMERA space (metres; glTF convention: the camera looks down −Z,
/// +Y up, +X right; film pixel (0,0) top-left, pixel centres at (i+0.5, j+0.5)).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraRay {
    /// Ray origin (m, camera space).
    pub origin_m: Vec3,
    /// Unit direction (camera space).
    pub direction: Vec3,
    /// Weight per hero wavelength that converts the radiance carried back along the ray into the
    /// camera's output quantity for this sample (1 for pinhole/thin lens which output radiance;
    /// for sensor-irradiance cameras: the estimator weight, W/m² per W/(m² sr), including cos⁴,
    /// pupil area / pdf, lens transmission; 0 where vignetted).
    pub weight: [f32; 4],
    /// True when the ray's path depends on wavelength (dispersive real lens): only wavelength 0
    /// (the hero) is valid for this ray; the integrator terminates the secondaries.
    pub wavelength_dependent: bool,
}

/// What a camera's samples estimate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OutputQuantity {
    /// Scene spectral radiance, W/(m²·sr·nm) (pinhole, thin lens).
    Radiance,
    /// Spectral irradiance on the sensor, W/(m²·nm) (real lens, light field).
    SensorIrradiance,
}

/// A camera model. Implementations must be deterministic functions of their arguments (the
/// renderer's output does not depend on the thread count).
pub trait Camera: Send + Sync {
    /// Film size (width, height) in pixels.
    fn film_size_px(&self) -> (u32, u32);
    /// What the samples estimate.
    fn output_quantity(&self) -> OutputQuantity;
    /// film_px: continuous film position in pixels; lens_uv: uniform in [0,1)²;
    /// wavelengths_nm: the 4 hero-sampled wavelengths of this sample.
    fn generate_ray(
        &self,
        film_px: Vec2,
        lens_uv: Vec2,
        wavelengths_nm: &[f32; 4],
    ) -> Option<CameraRay>;
    /// Depth of the central ray through film_px for the Z channel (planar, along −Z), if defined.
    fn center_ray(&self, film_px: Vec2) -> Option<CameraRay>;
    /// Near clipping distance measured along −Z (m): hits closer to the camera plane than
    /// this are ignored (Mitsuba `near_clip`; glTF `znear`). Default 0.
    fn near_clip_m(&self) -> f32 {
        0.0
    }
    /// Far clipping distance along −Z (m) (Mitsuba `far_clip`; glTF `zfar`). Default ∞.
    fn far_clip_m(&self) -> f32 {
        f32::INFINITY
    }
    /// For a pinhole or thin lens: the equivalent camera with its per-render constants
    /// precomputed, which the render loop uses (without dynamic dispatch) for its many rays;
    /// None (the default) to use this camera as it is.
    fn prepared(&self) -> Option<PreparedPerspective> {
        None
    }
}

/// The perspective projection shared by [`Pinhole`] and [`ThinLens`]: a vertical field of view
/// (glTF `yfov`) and a film of `width × height` pixels with square pixels (the horizontal field
/// follows from the aspect ratio, exactly as glTF's projection matrix with
/// `aspectRatio = width / height`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Perspective {
    /// Film width (px).
    pub width_px: u32,
    /// Film height (px).
    pub height_px: u32,
    /// Vertical field of view (radians, full angle).
    pub yfov_rad: f32,
    /// Near clip along −Z (m).
    pub znear_m: f32,
    /// Far clip along −Z (m), ∞ when absent.
    pub zfar_m: f32,
}

impl Perspective {
    /// The point on the plane z = −1 (camera space) seen through film position `film_px`:
    /// x_ndc = 2·px/W − 1, y_ndc = 1 − 2·py/H, x = x_ndc·tan(yfov/2)·W/H, y = y_ndc·tan(yfov/2).
    pub fn film_to_plane(&self, film_px: Vec2) -> Vec3 {
        let t = (0.5 * self.yfov_rad).tan();
        let (w, h) = (self.width_px as f32, self.height_px as f32);
        let x_ndc = 2.0 * film_px.x / w - 1.0;
        let y_ndc = 1.0 - 2.0 * film_px.y / h;
        Vec3::new(x_ndc * t * w / h, y_ndc * t, -1.0)
    }

    /// The film position (px) where camera-space point `p` (z < 0) projects; None behind the
    /// camera. Inverse of [`Perspective::film_to_plane`].
    pub fn project(&self, p: Vec3) -> Option<Vec2> {
        if p.z >= 0.0 {
            return None;
        }
        let t = (0.5 * self.yfov_rad).tan();
        let (w, h) = (self.width_px as f32, self.height_px as f32);
        let x_ndc = (p.x / -p.z) / (t * w / h);
        let y_ndc = (p.y / -p.z) / t;
        Some(Vec2::new((x_ndc + 1.0) * 0.5 * w, (1.0 - y_ndc) * 0.5 * h))
    }
}

/// [`Perspective::film_to_plane`] with its constants precomputed (no `tan` per ray):
/// x = px·2s_x/W − s_x, y = s_y − py·2s_y/H with s_y = tan(yfov/2), s_x = s_y·W/H.
#[derive(Debug, Clone, Copy, PartialEq)]
struct PlaneMap {
    kx: f32,
    sx: f32,
    ky: f32,
    sy: f32,
}

impl PlaneMap {
    fn new(p: &Perspective) -> Self {
        let t = (0.5 * p.yfov_rad).tan();
        let (w, h) = (p.width_px as f32, p.height_px as f32);
        let sx = t * w / h;
        PlaneMap {
            kx: 2.0 * sx / w,
            sx,
            ky: 2.0 * t / h,
            sy: t,
        }
    }
    #[inline]
    fn film_to_plane(&self, film_px: Vec2) -> Vec3 {
        Vec3::new(
            film_px.x * self.kx - self.sx,
            self.sy - film_px.y * self.ky,
            -1.0,
        )
    }
}

/// Thin-lens camera ray through the film point whose pinhole direction meets the plane z = −1
/// at `p_plane`: the ray leaves a point of the aperture disc (concentric map of `lens_uv`) towards
/// that direction's point on the focus plane z = −focus_distance (pbrt-v4 §5.2.3).
#[inline]
fn thin_lens_ray(
    p_plane: Vec3,
    lens_uv: Vec2,
    focus_distance_m: f32,
    aperture_radius_m: f32,
) -> CameraRay {
    let focus = p_plane * focus_distance_m;
    let a = crate::sampling::square_to_disk_concentric(lens_uv) * aperture_radius_m;
    let origin = Vec3::new(a.x, a.y, 0.0);
    CameraRay {
        origin_m: origin,
        direction: (focus - origin).normalize(),
        weight: [1.0; 4],
        wavelength_dependent: false,
    }
}

/// A pinhole or thin lens with its film-to-plane constants precomputed ([`Camera::prepared`]);
/// aperture radius 0 is the pinhole.
#[derive(Debug, Clone, Copy)]
pub struct PreparedPerspective {
    perspective: Perspective,
    map: PlaneMap,
    aperture_radius_m: f32,
    focus_distance_m: f32,
}

impl Camera for PreparedPerspective {
    fn film_size_px(&self) -> (u32, u32) {
        (self.perspective.width_px, self.perspective.height_px)
    }
    fn output_quantity(&self) -> OutputQuantity {
        OutputQuantity::Radiance
    }
    #[inline]
    fn generate_ray(&self, film_px: Vec2, lens_uv: Vec2, _wl: &[f32; 4]) -> Option<CameraRay> {
        let p = self.map.film_to_plane(film_px);
        if self.aperture_radius_m == 0.0 {
            return Some(CameraRay {
                origin_m: Vec3::ZERO,
                direction: p.normalize(),
                weight: [1.0; 4],
                wavelength_dependent: false,
            });
        }
        Some(thin_lens_ray(
            p,
            lens_uv,
            self.focus_distance_m,
            self.aperture_radius_m,
        ))
    }
    fn center_ray(&self, film_px: Vec2) -> Option<CameraRay> {
        Some(CameraRay {
            origin_m: Vec3::ZERO,
            direction: self.map.film_to_plane(film_px).normalize(),
            weight: [1.0; 4],
            wavelength_dependent: false,
        })
    }
    fn near_clip_m(&self) -> f32 {
        self.perspective.znear_m
    }
    fn far_clip_m(&self) -> f32 {
        self.perspective.zfar_m
    }
}

/// Ideal pinhole: every ray starts at the camera centre.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pinhole {
    /// Projection and film.
    pub perspective: Perspective,
}

impl Camera for Pinhole {
    fn film_size_px(&self) -> (u32, u32) {
        (self.perspective.width_px, self.perspective.height_px)
    }
    fn prepared(&self) -> Option<PreparedPerspective> {
        Some(PreparedPerspective {
            perspective: self.perspective,
            map: PlaneMap::new(&self.perspective),
            aperture_radius_m: 0.0,
            focus_distance_m: 1.0,
        })
    }
    fn output_quantity(&self) -> OutputQuantity {
        OutputQuantity::Radiance
    }
    fn generate_ray(&self, film_px: Vec2, _lens_uv: Vec2, _wl: &[f32; 4]) -> Option<CameraRay> {
        self.center_ray(film_px)
    }
    fn center_ray(&self, film_px: Vec2) -> Option<CameraRay> {
        Some(CameraRay {
            origin_m: Vec3::ZERO,
            direction: self.perspective.film_to_plane(film_px).normalize(),
            weight: [1.0; 4],
            wavelength_dependent: false,
        })
    }
    fn near_clip_m(&self) -> f32 {
        self.perspective.znear_m
    }
    fn far_clip_m(&self) -> f32 {
        self.perspective.zfar_m
    }
}

/// Thin lens (Mitsuba `thinlens`): the ray starts at a point of the aperture disc of radius
/// `aperture_radius_m` (concentric mapping of the lens sample, Shirley & Chiu 1997) and passes
/// through the point that the pinhole ray of the same film position reaches on the focal
/// plane z = −`focus_distance_m` (planar focus).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ThinLens {
    /// Projection and film.
    pub perspective: Perspective,
    /// Aperture radius (m).
    pub aperture_radius_m: f32,
    /// Distance of the plane in focus (m, along −Z).
    pub focus_distance_m: f32,
}

impl Camera for ThinLens {
    fn film_size_px(&self) -> (u32, u32) {
        (self.perspective.width_px, self.perspective.height_px)
    }
    fn prepared(&self) -> Option<PreparedPerspective> {
        Some(PreparedPerspective {
            perspective: self.perspective,
            map: PlaneMap::new(&self.perspective),
            aperture_radius_m: self.aperture_radius_m,
            focus_distance_m: self.focus_distance_m,
        })
    }
    fn output_quantity(&self) -> OutputQuantity {
        OutputQuantity::Radiance
    }
    fn generate_ray(&self, film_px: Vec2, lens_uv: Vec2, _wl: &[f32; 4]) -> Option<CameraRay> {
        let p = self.perspective.film_to_plane(film_px); // z = −1
        Some(thin_lens_ray(
            p,
            lens_uv,
            self.focus_distance_m,
            self.aperture_radius_m,
        ))
    }
    fn center_ray(&self, film_px: Vec2) -> Option<CameraRay> {
        Some(CameraRay {
            origin_m: Vec3::ZERO,
            direction: self.perspective.film_to_plane(film_px).normalize(),
            weight: [1.0; 4],
            wavelength_dependent: false,
        })
    }
    fn near_clip_m(&self) -> f32 {
        self.perspective.znear_m
    }
    fn far_clip_m(&self) -> f32 {
        self.perspective.zfar_m
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn persp() -> Perspective {
        Perspective {
            width_px: 320,
            height_px: 200,
            yfov_rad: 0.7,
            znear_m: 0.01,
            zfar_m: f32::INFINITY,
        }
    }

    #[test]
    fn projection_round_trips() {
        let p = persp();
        for &(x, y) in &[(0.5, 0.5), (160.0, 100.0), (319.5, 13.25)] {
            let q = p.film_to_plane(Vec2::new(x, y)) * 3.7;
            let back = p.project(q).unwrap();
            assert!((back - Vec2::new(x, y)).length() < 1e-3, "{back:?}");
        }
        // the film centre looks straight down −Z; the top edge is at yfov/2
        let c = p.film_to_plane(Vec2::new(160.0, 100.0));
        assert!((c - Vec3::new(0.0, 0.0, -1.0)).length() < 1e-6);
        let top = p.film_to_plane(Vec2::new(160.0, 0.0));
        assert!((top.y.atan2(1.0) - 0.35).abs() < 1e-6);
    }

    /// The prepared pinhole and thin lens give the rays of the plain ones (to rounding).
    #[test]
    fn prepared_cameras_match() {
        let pin = Pinhole {
            perspective: persp(),
        };
        let thin = ThinLens {
            perspective: persp(),
            aperture_radius_m: 0.05,
            focus_distance_m: 2.5,
        };
        for cam in [&pin as &dyn Camera, &thin as &dyn Camera] {
            let p = cam.prepared().expect("prepared");
            assert_eq!(p.film_size_px(), cam.film_size_px());
            assert_eq!(p.near_clip_m(), cam.near_clip_m());
            assert_eq!(p.far_clip_m(), cam.far_clip_m());
            for &(x, y, u, v) in &[
                (0.0, 0.0, 0.1, 0.9),
                (160.3, 99.7, 0.5, 0.5),
                (319.9, 199.9, 0.8, 0.3),
            ] {
                let (f, l) = (Vec2::new(x, y), Vec2::new(u, v));
                let (a, b) = (
                    cam.generate_ray(f, l, &[550.0; 4]).unwrap(),
                    p.generate_ray(f, l, &[550.0; 4]).unwrap(),
                );
                assert!((a.origin_m - b.origin_m).length() < 1e-7);
                assert!((a.direction - b.direction).length() < 1e-6, "{a:?} {b:?}");
                let (a, b) = (cam.center_ray(f).unwrap(), p.center_ray(f).unwrap());
                assert!((a.direction - b.direction).length() < 1e-6);
            }
        }
    }

    #[test]
    fn thin_lens_rays_meet_on_the_focal_plane() {
        let cam = ThinLens {
            perspective: persp(),
            aperture_radius_m: 0.05,
            focus_distance_m: 2.5,
        };
        let f = Vec2::new(40.3, 177.9);
        let target = cam.perspective.film_to_plane(f) * 2.5;
        for &(u, v) in &[(0.1, 0.2), (0.9, 0.5), (0.33, 0.77)] {
            let r = cam.generate_ray(f, Vec2::new(u, v), &[550.0; 4]).unwrap();
            assert!(r.origin_m.truncate().length() <= 0.05 + 1e-6);
            let t = (-2.5 - r.origin_m.z) / r.direction.z;
            let hit = r.origin_m + r.direction * t;
            assert!((hit - target).length() < 1e-5, "{hit:?} vs {target:?}");
        }
    }
}
