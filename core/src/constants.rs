//! Physical constants. The baseline uses CODATA 2018 / SI 2019 exact values; ISETCam uses an
//! older Planck constant, offered for oracle compatibility.

/// Planck, light speed and elementary charge in SI units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PhysicalConstants {
    /// Planck constant h (J·s).
    pub planck_j_s: f64,
    /// Speed of light c (m/s).
    pub light_speed_m_per_s: f64,
    /// Elementary charge q (C).
    pub elementary_charge_c: f64,
}

/// SI 2019 exact values (the spec's baseline).
pub const SI: PhysicalConstants = PhysicalConstants {
    planck_j_s: 6.626_070_15e-34,
    light_speed_m_per_s: 299_792_458.0,
    elementary_charge_c: 1.602_176_634e-19,
};

/// The values ISETCam uses (h = 6.626176e-34 J·s, q = 1.602177e-19 C).
pub const ISETCAM: PhysicalConstants = PhysicalConstants {
    planck_j_s: 6.626176e-34,
    light_speed_m_per_s: 2.99792458e8,
    elementary_charge_c: 1.602177e-19,
};

/// Maximum luminous efficacy Km = 683 lm/W (CIE photopic).
pub const LUMINOUS_EFFICACY_LM_PER_W: f64 = 683.0;

impl PhysicalConstants {
    /// Photons per joule at wavelength `wavelength_nm`: λ / (h c).
    pub fn photons_per_joule(&self, wavelength_nm: f64) -> f64 {
        wavelength_nm * 1e-9 / (self.planck_j_s * self.light_speed_m_per_s)
    }
}
