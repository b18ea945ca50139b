//! Paraxial (first-order) optics by the y–nu trace of Smith, "Modern Optical Engineering"
//! (4th ed., §2.6 and §5.3): at surface j the reduced angle changes by nu' = nu − y·φ with
//! φ = c (n' − n), and between surfaces y' = y + t·nu'/n'. Two independent rays (the "a" ray,
//! y = 1, nu = 0 and the "b" ray, y = 0, nu = 1 at the first vertex) span every paraxial ray, so
//! focal points, principal planes and pupils follow from linear combinations.
//!
//! Positions `*_z_mm` are axial coordinates with the first vertex at z = 0 and light towards +z
//! (for systems with mirrors: unfolded coordinates, see [`crate::fold`]).
use crate::error::LensError;
use crate::prescription::{Aperture, LensPrescription};

/// Height and reduced angle (n·u) of a paraxial ray after each surface.
#[derive(Debug, Clone, PartialEq)]
pub struct ParaxialRay {
    /// Height y at each surface (mm); the last entry is at the image plane.
    pub y_mm: Vec<f64>,
    /// Reduced angle n·u after each surface (the first entry is the object-space value before
    /// surface 0 is not stored; entry j is after refraction at surface j).
    pub nu: Vec<f64>,
}

/// First-order properties at one wavelength.
#[derive(Debug, Clone, PartialEq)]
pub struct FirstOrder {
    /// Wavelength (nm).
    pub wavelength_nm: f64,
    /// Effective focal length (image-side, in air) 1/φ (mm).
    pub efl_mm: f64,
    /// Back focal length: last vertex → rear focal point (mm).
    pub bfl_mm: f64,
    /// Front focal length: front focal point → first vertex (mm, positive when the focal point
    /// lies in front of the lens).
    pub ffl_mm: f64,
    /// Rear focal point z (mm).
    pub rear_focal_z_mm: f64,
    /// Front focal point z (mm).
    pub front_focal_z_mm: f64,
    /// Front principal plane z (mm).
    pub front_principal_z_mm: f64,
    /// Rear principal plane z (mm).
    pub rear_principal_z_mm: f64,
    /// Entrance-pupil z (mm from the first vertex).
    pub entrance_pupil_z_mm: f64,
    /// Entrance-pupil diameter (mm).
    pub entrance_pupil_diameter_mm: f64,
    /// Exit-pupil z (mm from the first vertex).
    pub exit_pupil_z_mm: f64,
    /// Exit pupil relative to the image plane, z_xp − z_image (mm, negative = before it).
    pub exit_pupil_from_image_mm: f64,
    /// Exit-pupil diameter (mm).
    pub exit_pupil_diameter_mm: f64,
    /// Paraxial semi-diameter of the stop that the aperture specification implies (mm).
    pub stop_semi_diameter_mm: f64,
    /// Infinite-conjugate F-number EFL/EPD.
    pub f_number: f64,
    /// Working F-number 1/(2 n' |u'|) of the image-space marginal ray (Smith §6.3).
    pub working_f_number: f64,
    /// Distance from the last vertex to the paraxial image of the object (mm).
    pub paraxial_image_distance_mm: f64,
    /// Paraxial magnification (0 for an object at infinity).
    pub magnification: f64,
}

/// Trace a paraxial ray starting at the first vertex with height `y0` and reduced angle `nu0`
/// (object space, n = 1) through all surfaces up to the image plane (y–nu trace, Smith §2.6).
pub fn ynu_trace(lens: &LensPrescription, wavelength_nm: f64, y0: f64, nu0: f64) -> ParaxialRay {
    let n = lens.indices(wavelength_nm);
    let mut y = y0;
    let mut nu = nu0;
    let mut n_prev = 1.0;
    let mut ys = Vec::with_capacity(n.len() + 1);
    let mut nus = Vec::with_capacity(n.len());
    // Unfolded (crate::fold): the light sees curvature s·c, a mirror has power −2 n s c
    // (refraction into −n), a coordinate break none, and thicknesses count as s·t.
    let folded = lens.has_folds();
    let mut sign = 1.0;
    for (j, s) in lens.surfaces.iter().enumerate() {
        ys.push(y);
        if !folded {
            nu -= y * s.curvature_per_mm * (n[j] - n_prev);
        } else if s.is_mirror() {
            nu += y * 2.0 * n_prev * sign * s.curvature_per_mm;
            sign = -sign;
        } else if lens.coordinate_break(j).is_none() {
            nu -= y * sign * s.curvature_per_mm * (n[j] - n_prev);
        }
        nus.push(nu);
        y += sign * s.thickness_mm * nu / n[j];
        n_prev = n[j];
    }
    ys.push(y);
    ParaxialRay { y_mm: ys, nu: nus }
}

impl LensPrescription {
    /// First-order properties at `wavelength_nm` (see [`FirstOrder`]).
    ///
    /// With `Aperture::FNumber` the EPD is EFL(primary)/F#, so all wavelengths share one stop.
    pub fn first_order(&self, wavelength_nm: f64) -> Result<FirstOrder, LensError> {
        let ns = self.surfaces.len();
        let n_img = self.surfaces[ns - 1].medium.index(wavelength_nm);
        let z = self.vertex_z_mm();
        let z_last = z[ns - 1];
        let z_img = z[ns];
        let a = ynu_trace(self, wavelength_nm, 1.0, 0.0);
        let b = ynu_trace(self, wavelength_nm, 0.0, 1.0);
        // System matrix from the first to the last vertex: [y', nu'] = [[A, B], [C, D]] [y, nu].
        let (ya, nua) = (a.y_mm[ns - 1], a.nu[ns - 1]);
        let (yb, nub) = (b.y_mm[ns - 1], b.nu[ns - 1]);
        let (aa, cc, dd) = (ya, nua, nub);
        if cc.abs() < 1e-15 {
            return Err(LensError::Paraxial(format!(
                "afocal system (power {cc} mm⁻¹)"
            )));
        }
        let phi = -cc;
        let efl_mm = n_img / phi; // image-side focal length f' = n'/φ (= 1/φ in air)
        let bfl_mm = -aa * n_img / cc;
        let ffl_mm = -dd / cc; // object space n = 1
        let rear_focal_z_mm = z_last + bfl_mm;
        let front_focal_z_mm = -ffl_mm;
        let rear_principal_z_mm = rear_focal_z_mm - efl_mm;
        let front_principal_z_mm = front_focal_z_mm + 1.0 / phi;
        // Stop heights of the a and b rays; the chief ray b + k·a has zero height at the stop.
        let s = self.stop_index;
        let (yas, ybs) = (a.y_mm[s], b.y_mm[s]);
        if yas.abs() < 1e-15 {
            return Err(LensError::Paraxial(
                "the stop is at a focus of the front group (no entrance pupil)".into(),
            ));
        }
        let k = -ybs / yas;
        // Chief ray at the first vertex: y = k, u = 1; it crosses the axis at z = −k.
        let entrance_pupil_z_mm = -k;
        let efl_primary = if (wavelength_nm - self.primary_nm).abs() < 1e-12 {
            efl_mm
        } else {
            self.first_order_efl(self.primary_nm)?
        };
        let epd = match self.aperture {
            Aperture::EntrancePupilDiameter(d) => d,
            Aperture::FNumber(f) => efl_primary.abs() / f,
        };
        // Marginal ray: from the axial object point through the edge of the entrance pupil.
        let (ym0, num0) = match self.object_distance_mm {
            None => (epd / 2.0, 0.0),
            Some(d) => {
                let u = (epd / 2.0) / (d + entrance_pupil_z_mm);
                (d * u, u)
            }
        };
        let m = ynu_trace(self, wavelength_nm, ym0, num0);
        let stop_semi_diameter_mm = m.y_mm[s].abs();
        let num_img = m.nu[ns - 1];
        let paraxial_image_distance_mm = if num_img.abs() < 1e-300 {
            f64::INFINITY
        } else {
            -m.y_mm[ns - 1] * n_img / num_img
        };
        let working_f_number = 1.0 / (2.0 * num_img.abs());
        // Chief ray (unit reduced angle in object space): b + k a.
        let yc_last = yb + k * ya;
        let nuc_last = nub + k * nua;
        let exit_pupil_z_mm = z_last - yc_last * n_img / nuc_last;
        let ym_xp = m.y_mm[ns - 1] + (exit_pupil_z_mm - z_last) * num_img / n_img;
        let magnification = match self.object_distance_mm {
            None => 0.0,
            Some(_) => num0 / num_img, // Lagrange: n u h = n' u' h' → m = (n u)/(n' u')
        };
        Ok(FirstOrder {
            wavelength_nm,
            efl_mm,
            bfl_mm,
            ffl_mm,
            rear_focal_z_mm,
            front_focal_z_mm,
            front_principal_z_mm,
            rear_principal_z_mm,
            entrance_pupil_z_mm,
            entrance_pupil_diameter_mm: epd,
            exit_pupil_z_mm,
            exit_pupil_from_image_mm: exit_pupil_z_mm - z_img,
            exit_pupil_diameter_mm: 2.0 * ym_xp.abs(),
            stop_semi_diameter_mm,
            f_number: efl_mm.abs() / epd,
            working_f_number,
            paraxial_image_distance_mm,
            magnification,
        })
    }

    fn first_order_efl(&self, wavelength_nm: f64) -> Result<f64, LensError> {
        let ns = self.surfaces.len();
        let a = ynu_trace(self, wavelength_nm, 1.0, 0.0);
        let c = a.nu[ns - 1];
        if c.abs() < 1e-15 {
            return Err(LensError::Paraxial("afocal system".into()));
        }
        Ok(-self.surfaces[ns - 1].medium.index(wavelength_nm) / c)
    }

    /// A copy focused (paraxially, at `wavelength_nm`) on its object: the last thickness is set
    /// to the paraxial image distance (= BFL for an object at infinity).
    pub fn focused(&self, wavelength_nm: f64) -> Result<Self, LensError> {
        let fo = self.first_order(wavelength_nm)?;
        Ok(self.with_image_distance(fo.paraxial_image_distance_mm))
    }

    /// A copy focused on an object at `object_distance_mm` (`None` = infinity) at the primary
    /// wavelength, i.e. with the image distance moved to the paraxial image.
    pub fn focus_at(&self, object_distance_mm: Option<f64>) -> Result<Self, LensError> {
        self.with_object_distance(object_distance_mm)
            .focused(self.primary_nm)
    }

    /// Paraxial chief-ray height at the image plane for field angle `field_deg`
    /// (object-space chief-ray angle; the chief ray passes through the paraxial pupil centre).
    pub fn paraxial_chief_height_mm(
        &self,
        field_deg: f64,
        wavelength_nm: f64,
    ) -> Result<f64, LensError> {
        let fo = self.first_order(wavelength_nm)?;
        let u = field_deg.to_radians().tan();
        // At the first vertex the chief ray is at height −z_ep·u… measured from the axis crossing.
        let y0 = -fo.entrance_pupil_z_mm * u;
        let r = ynu_trace(self, wavelength_nm, y0, u);
        Ok(*r.y_mm.last().unwrap())
    }

    /// Image-side scale H (mm of paraxial image height per unit tan θ of the object's chief
    /// ray) at `wavelength_nm`: the paraxial chief-ray height is linear in tan θ, so
    /// H = |y(1°)| / tan 1° (for an infinite object, H is the EFL).
    pub fn paraxial_image_mm_per_tan(&self, wavelength_nm: f64) -> Result<f64, LensError> {
        Ok((self.paraxial_chief_height_mm(1.0, wavelength_nm)? / 1f64.to_radians().tan()).abs())
    }

    /// Full field of view (degrees) whose paraxial image just fills a circle of radius
    /// `image_semi_diagonal_mm` (infinite object: tan θ = h / EFL).
    pub fn paraxial_full_fov_deg(&self, image_semi_diagonal_mm: f64) -> Result<f64, LensError> {
        let t = image_semi_diagonal_mm / self.paraxial_image_mm_per_tan(self.primary_nm)?;
        Ok(2.0 * t.abs().atan().to_degrees())
    }
}

/// Signed paraxial blur-disc radius (mm on the image) of an object point at vergence
/// `inv_z_per_m` for a lens focused at vergence `focus_per_m` (both 1/m, distances from the
/// entrance pupil): `r = A · (1/z − 1/D) · H`, with A the entrance-pupil radius (mm) and H the
/// image-side scale (mm of paraxial image height per unit tan θ). Similar triangles: the rays
/// from the point through the pupil rim meet the plane conjugate to the focus distance A·|1/z −
/// 1/D| (in units of tan θ) off the chief ray, which the lens images at H per unit tan θ (the
/// thin-lens circle of confusion, f/(2N)·v·|1/z − 1/D|, with A = f/(2N) and H = v). Positive
/// for points nearer than the focus.
pub fn paraxial_blur_radius_mm(
    entrance_pupil_radius_mm: f64,
    image_mm_per_tan: f64,
    inv_z_per_m: f64,
    focus_per_m: f64,
) -> f64 {
    entrance_pupil_radius_mm * 1e-3 * (inv_z_per_m - focus_per_m) * image_mm_per_tan
}
