//! Spectral BSDFs with sample / eval / pdf, following Mitsuba 3's definitions so that both
//! renderers read a glTF scene the same way (../shared/tools/mitsuba_ref/README.md):
//!
//! * [`Lobe::Diffuse`] — Lambertian, f = ρ/π;
//! * [`Lobe::Conductor`] — smooth or GGX rough conductor, exact unpolarised complex Fresnel
//!   with spectral η, k (or a perfect mirror, Mitsuba's `material: "none"`), times the
//!   specular reflectance;
//! * [`Lobe::Dielectric`] — smooth or GGX rough dielectric (Walter et al. 2007) with an
//!   optionally dispersive index (Cauchy / Sellmeier / Abbe number); a dispersive sample is
//!   only valid for the hero wavelength (the integrator then terminates the secondaries);
//! * [`Lobe::RoughPlastic`] — a Lambertian base under a GGX dielectric coat, the model of
//!   Mitsuba's `roughplastic` (specular term F·D·G/(4 cos θi) plus a diffuse term scaled by the
//!   coat's directional transmittances, η⁻² and the internal-reflection series).
//!
//! Conventions: local shading frame with the normal on +Z; `wi` points back to the previous
//! vertex (the camera side), `wo` to the next one; `eval` returns f·|cos θo| per wavelength,
//! `sample` returns f·|cos θo|/pdf. One-sided BSDFs are black from the back; `two_sided`
//! mirrors the front onto the back (Mitsuba `twosided`).
pub mod metals;
pub mod microfacet;

use crate::sampling::{cosine_hemisphere_pdf, square_to_cosine_hemisphere};
use crate::spectral::{TabulatedSpectrum, N_WL};
use glam::{Vec2, Vec3};
pub use microfacet::Ggx;
use std::f32::consts::FRAC_1_PI;

/// Refractive index of a dielectric as a function of wavelength.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Ior {
    /// Non-dispersive.
    Constant(f32),
    /// Cauchy: n(λ) = A + B/λ² (λ in µm).
    Cauchy {
        /// A
        a: f32,
        /// B (µm²)
        b_um2: f32,
    },
    /// Sellmeier: n² = 1 + Σ Bᵢλ²/(λ² − Cᵢ) (λ in µm).
    Sellmeier {
        /// B₁..B₃
        b: [f32; 3],
        /// C₁..C₃ (µm²)
        c_um2: [f32; 3],
    },
}

impl Ior {
    /// Index at `nm`.
    #[inline]
    pub fn at(&self, nm: f32) -> f32 {
        match *self {
            Ior::Constant(n) => n,
            Ior::Cauchy { a, b_um2 } => {
                let l = nm * 1e-3;
                a + b_um2 / (l * l)
            }
            Ior::Sellmeier { b, c_um2 } => {
                let l2 = (nm * 1e-3) * (nm * 1e-3);
                let mut n2 = 1.0;
                for i in 0..3 {
                    n2 += b[i] * l2 / (l2 - c_um2[i]);
                }
                n2.max(1e-6).sqrt()
            }
        }
    }
    /// True when the index depends on wavelength.
    pub fn is_dispersive(&self) -> bool {
        !matches!(self, Ior::Constant(_))
    }
    /// A Cauchy model through n_d at 587.56 nm with Abbe number V_d = (n_d − 1)/(n_F − n_C)
    /// (F = 486.13 nm, C = 656.27 nm).
    pub fn from_abbe(n_d: f32, abbe: f32) -> Ior {
        let (lf, lc, ld) = (0.48613f32, 0.65627f32, 0.58756f32);
        let b = (n_d - 1.0) / (abbe * (1.0 / (lf * lf) - 1.0 / (lc * lc)));
        Ior::Cauchy {
            a: n_d - b / (ld * ld),
            b_um2: b,
        }
    }
}

/// Unpolarised Fresnel reflectance of a dielectric interface with relative index
/// `eta` = η_inside/η_outside, for `cos_i` measured against the normal that points outside
/// (negative from inside). Returns (F, cos θt (signed like −cos_i), η_it, η_ti) as Mitsuba's
/// `fresnel` does.
#[inline]
pub fn fresnel_dielectric(cos_i: f32, eta: f32) -> (f32, f32, f32, f32) {
    let outside = cos_i >= 0.0;
    let eta_it = if outside { eta } else { 1.0 / eta };
    let eta_ti = 1.0 / eta_it;
    let ci = cos_i.abs();
    let cos_t2 = 1.0 - eta_ti * eta_ti * (1.0 - ci * ci);
    if cos_t2 <= 0.0 {
        return (1.0, 0.0, eta_it, eta_ti);
    }
    let ct = cos_t2.sqrt();
    let rs = (ci - eta_it * ct) / (ci + eta_it * ct);
    let rp = (eta_it * ci - ct) / (eta_it * ci + ct);
    let f = 0.5 * (rs * rs + rp * rp);
    (f, if outside { -ct } else { ct }, eta_it, eta_ti)
}

/// Unpolarised Fresnel reflectance of a conductor with complex index η + iκ (relative to the
/// outside medium) at incidence cosine `cos_i` ≥ 0 (exact complex Snell / Fresnel).
#[inline]
pub fn fresnel_conductor(cos_i: f32, eta: f32, k: f32) -> f32 {
    let c = cos_i.clamp(0.0, 1.0);
    // complex arithmetic with (re, im) pairs
    let mul = |a: (f32, f32), b: (f32, f32)| (a.0 * b.0 - a.1 * b.1, a.0 * b.1 + a.1 * b.0);
    let div = |a: (f32, f32), b: (f32, f32)| {
        let d = b.0 * b.0 + b.1 * b.1;
        ((a.0 * b.0 + a.1 * b.1) / d, (a.1 * b.0 - a.0 * b.1) / d)
    };
    let sqrt = |a: (f32, f32)| {
        let r = (a.0 * a.0 + a.1 * a.1).sqrt();
        let re = (0.5 * (r + a.0)).max(0.0).sqrt();
        let im = (0.5 * (r - a.0)).max(0.0).sqrt().copysign(a.1);
        (re, im)
    };
    let n = (eta, k);
    let n2 = mul(n, n);
    // cos θt = sqrt(1 − sin²θi / n²)
    let s2 = div((1.0 - c * c, 0.0), n2);
    let ct = sqrt((1.0 - s2.0, -s2.1));
    let nct = mul(n, ct);
    let nc = (n.0 * c, n.1 * c);
    let rs = div((c - nct.0, -nct.1), (c + nct.0, nct.1));
    let rp = div((nc.0 - ct.0, nc.1 - ct.1), (nc.0 + ct.0, nc.1 + ct.1));
    let a2 = |z: (f32, f32)| z.0 * z.0 + z.1 * z.1;
    (0.5 * (a2(rs) + a2(rp))).clamp(0.0, 1.0)
}

#[inline]
fn reflect(wi: Vec3, m: Vec3) -> Vec3 {
    2.0 * wi.dot(m) * m - wi
}

/// Refraction of `wi` about microfacet normal `m` with `cos_t` and η_ti from
/// [`fresnel_dielectric`] (Mitsuba's `refract`).
#[inline]
fn refract(wi: Vec3, m: Vec3, cos_t: f32, eta_ti: f32) -> Vec3 {
    m * (wi.dot(m) * eta_ti + cos_t) - wi * eta_ti
}

/// Number of cosine samples of the rough-plastic coat tables (Mitsuba uses the same).
pub const PLASTIC_TABLE_RES: usize = 64;

/// The scattering model of a material.
#[derive(Debug, Clone)]
pub enum Lobe {
    /// Lambertian reflection of the material's reflectance.
    Diffuse,
    /// Smooth (distr None) or rough conductor.
    Conductor {
        /// GGX roughness, None for a smooth mirror.
        distr: Option<Ggx>,
        /// Real part of the index relative to the outside; None = perfect mirror (F = 1).
        eta_k: Option<(TabulatedSpectrum, TabulatedSpectrum)>,
    },
    /// Smooth (distr None) or rough dielectric interface.
    Dielectric {
        /// GGX roughness, None for a smooth interface.
        distr: Option<Ggx>,
        /// Interior index.
        int_ior: Ior,
        /// Exterior index.
        ext_ior: f32,
    },
    /// Diffuse base under a rough dielectric coat (Mitsuba `roughplastic`).
    RoughPlastic {
        /// Coat roughness.
        distr: Ggx,
        /// Relative index of the coat η = int/ext.
        eta: f32,
        /// Probability weight of the specular lobe: s̄/(d̄ + s̄).
        specular_sampling_weight: f32,
        /// 1 − directional albedo of the coat's specular reflection at cos θ = i/(RES−1).
        external_transmittance: Vec<f32>,
        /// Cosine-weighted albedo of the coat seen from inside (1/η).
        internal_reflectance: f32,
        /// Mitsuba `nonlinear`: divide by 1 − ρ·R_int instead of 1 − R_int.
        nonlinear: bool,
    },
}

/// A BSDF: its lobe and sidedness.
#[derive(Debug, Clone)]
pub struct Bsdf {
    /// The scattering model.
    pub lobe: Lobe,
    /// Mirror the front side onto the back (Mitsuba `twosided`); dielectrics are always
    /// two-sided interfaces.
    pub two_sided: bool,
}

/// One sampled direction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BsdfSample {
    /// Sampled direction (local frame).
    pub wo: Vec3,
    /// f·|cos θo| / pdf per wavelength.
    pub weight: [f32; N_WL],
    /// Density of `wo` (per steradian); 0 for a delta lobe.
    pub pdf: f32,
    /// True for a specular (Dirac) event: no MIS, emitters hit are counted fully.
    pub delta: bool,
    /// Relative index crossed (η_t/η_i, 1 for reflection), for Russian roulette.
    pub eta: f32,
    /// True when the sampled direction depends on the wavelength (dispersion): only the hero
    /// wavelength (slot 0) is valid.
    pub dispersive: bool,
}

/// The linear-interpolation lookup of a coat table indexed by cos θ ∈ [0, 1].
#[inline]
fn lerp_table(t: &[f32], x: f32) -> f32 {
    let n = t.len();
    let x = x.clamp(0.0, 1.0) * (n - 1) as f32;
    let i = (x as usize).min(n - 2);
    let w = x - i as f32;
    t[i] * (1.0 - w) + t[i + 1] * w
}

impl Bsdf {
    /// True when the lobe has no continuous part (pure Dirac): light sampling is skipped.
    pub fn is_delta(&self) -> bool {
        match &self.lobe {
            Lobe::Conductor { distr, .. } | Lobe::Dielectric { distr, .. } => distr.is_none(),
            _ => false,
        }
    }

    /// True when sampling or evaluation depends on the wavelength through a dispersive index.
    pub fn is_dispersive(&self) -> bool {
        matches!(&self.lobe, Lobe::Dielectric { int_ior, .. } if int_ior.is_dispersive())
    }

    /// Map (wi, wo) to the front side for a two-sided BSDF; None when a one-sided BSDF is seen
    /// from the back.
    #[inline]
    fn side(&self, wi: Vec3, wo: Vec3) -> Option<(Vec3, Vec3)> {
        if matches!(self.lobe, Lobe::Dielectric { .. }) {
            return Some((wi, wo));
        }
        if wi.z > 0.0 {
            Some((wi, wo))
        } else if self.two_sided && wi.z < 0.0 {
            let f = Vec3::new(1.0, 1.0, -1.0);
            Some((wi * f, wo * f))
        } else {
            None
        }
    }

    /// f·|cos θo| per wavelength and the density of sampling `wo` per wavelength.
    /// `refl` is the material's reflectance at the hit (diffuse reflectance for diffuse and
    /// plastic, specular reflectance for conductors), `wl` the wavelengths (nm).
    #[inline]
    pub fn eval_pdf(
        &self,
        wi: Vec3,
        wo: Vec3,
        refl: &[f32; N_WL],
        wl: &[f32; N_WL],
    ) -> ([f32; N_WL], [f32; N_WL]) {
        if let Lobe::Diffuse = self.lobe {
            // the common Lambertian case inline (as below: one-sided unless two_sided)
            let zero = ([0.0; N_WL], [0.0; N_WL]);
            let woz = if wi.z > 0.0 {
                wo.z
            } else if self.two_sided && wi.z < 0.0 {
                -wo.z
            } else {
                return zero;
            };
            if woz <= 0.0 {
                return zero;
            }
            let k = FRAC_1_PI * woz;
            return (refl.map(|r| r * k), [k; N_WL]);
        }
        self.eval_pdf_general(wi, wo, refl, wl)
    }

    #[inline(never)]
    fn eval_pdf_general(
        &self,
        wi: Vec3,
        wo: Vec3,
        refl: &[f32; N_WL],
        wl: &[f32; N_WL],
    ) -> ([f32; N_WL], [f32; N_WL]) {
        let zero = ([0.0; N_WL], [0.0; N_WL]);
        let Some((wi, wo)) = self.side(wi, wo) else {
            return zero;
        };
        match &self.lobe {
            Lobe::Diffuse => {
                if wo.z <= 0.0 {
                    return zero;
                }
                let k = FRAC_1_PI * wo.z;
                (refl.map(|r| r * k), [cosine_hemisphere_pdf(wo); N_WL])
            }
            Lobe::Conductor { distr, eta_k } => {
                let Some(d) = distr else { return zero };
                if wo.z <= 0.0 {
                    return zero;
                }
                let h = (wi + wo).normalize();
                let dg = d.d(h) * d.g(wi, wo, h) / (4.0 * wi.z);
                let c = wi.dot(h);
                let mut f = [0.0; N_WL];
                for i in 0..N_WL {
                    let fr = match eta_k {
                        Some((e, k)) => fresnel_conductor(c, e.eval(wl[i]), k.eval(wl[i])),
                        None => 1.0,
                    };
                    f[i] = refl[i] * fr * dg;
                }
                let pdf = d.pdf_visible(wi, h) / (4.0 * wo.dot(h));
                (f, [pdf.max(0.0); N_WL])
            }
            Lobe::Dielectric {
                distr,
                int_ior,
                ext_ior,
            } => {
                let Some(d) = distr else { return zero };
                let mut f = [0.0; N_WL];
                let mut p = [0.0; N_WL];
                let dispersive = int_ior.is_dispersive();
                let n_eval = if dispersive { N_WL } else { 1 };
                for i in 0..n_eval {
                    let eta = int_ior.at(wl[i]) / ext_ior;
                    let (fi, pi) = rough_dielectric_eval(d, wi, wo, eta);
                    f[i] = fi;
                    p[i] = pi;
                }
                if !dispersive {
                    f = [f[0]; N_WL];
                    p = [p[0]; N_WL];
                }
                (f, p)
            }
            Lobe::RoughPlastic {
                distr,
                eta,
                specular_sampling_weight,
                external_transmittance,
                internal_reflectance,
                nonlinear,
            } => {
                if wo.z <= 0.0 {
                    return zero;
                }
                let h = (wi + wo).normalize();
                let (fr, _, _, _) = fresnel_dielectric(wi.dot(h), *eta);
                let spec = fr * distr.d(h) * distr.g(wi, wo, h) / (4.0 * wi.z);
                let t_i = lerp_table(external_transmittance, wi.z);
                let t_o = lerp_table(external_transmittance, wo.z);
                let k = FRAC_1_PI / (eta * eta) * wo.z * t_i * t_o;
                let mut f = [0.0; N_WL];
                for i in 0..N_WL {
                    let denom = 1.0
                        - if *nonlinear {
                            refl[i] * internal_reflectance
                        } else {
                            *internal_reflectance
                        };
                    f[i] = spec + refl[i] / denom * k;
                }
                let ps = plastic_specular_prob(t_i, *specular_sampling_weight);
                let pdf = ps * distr.d(h) * distr.g1(wi, h) / (4.0 * wi.z)
                    + (1.0 - ps) * cosine_hemisphere_pdf(wo);
                (f, [pdf; N_WL])
            }
        }
    }

    /// Sample `wo` given `wi`, with `u1` for the lobe choice and `u2` for the direction.
    /// The hero wavelength (slot 0) decides dispersive events.
    #[inline]
    pub fn sample(
        &self,
        wi_in: Vec3,
        u1: f32,
        u2: Vec2,
        refl: &[f32; N_WL],
        wl: &[f32; N_WL],
    ) -> Option<BsdfSample> {
        if let Lobe::Diffuse = self.lobe {
            // the common Lambertian case inline (as below)
            let flip = if wi_in.z > 0.0 {
                false
            } else if self.two_sided && wi_in.z < 0.0 {
                true
            } else {
                return None;
            };
            let wo = square_to_cosine_hemisphere(u2);
            if wo.z <= 0.0 {
                return None;
            }
            return Some(BsdfSample {
                wo: if flip {
                    Vec3::new(wo.x, wo.y, -wo.z)
                } else {
                    wo
                },
                weight: *refl,
                pdf: cosine_hemisphere_pdf(wo),
                delta: false,
                eta: 1.0,
                dispersive: false,
            });
        }
        self.sample_general(wi_in, u1, u2, refl, wl)
    }

    #[inline(never)]
    fn sample_general(
        &self,
        wi_in: Vec3,
        u1: f32,
        u2: Vec2,
        refl: &[f32; N_WL],
        wl: &[f32; N_WL],
    ) -> Option<BsdfSample> {
        let flip = !matches!(self.lobe, Lobe::Dielectric { .. }) && wi_in.z < 0.0;
        let (wi, _) = self.side(wi_in, Vec3::Z)?;
        let unflip = |w: Vec3| if flip { Vec3::new(w.x, w.y, -w.z) } else { w };
        match &self.lobe {
            Lobe::Diffuse => {
                let wo = square_to_cosine_hemisphere(u2);
                if wo.z <= 0.0 {
                    return None;
                }
                Some(BsdfSample {
                    wo: unflip(wo),
                    weight: *refl,
                    pdf: cosine_hemisphere_pdf(wo),
                    delta: false,
                    eta: 1.0,
                    dispersive: false,
                })
            }
            Lobe::Conductor { distr, eta_k } => match distr {
                None => {
                    let wo = Vec3::new(-wi.x, -wi.y, wi.z);
                    let mut w = [0.0; N_WL];
                    for i in 0..N_WL {
                        let fr = match eta_k {
                            Some((e, k)) => fresnel_conductor(wi.z, e.eval(wl[i]), k.eval(wl[i])),
                            None => 1.0,
                        };
                        w[i] = refl[i] * fr;
                    }
                    Some(BsdfSample {
                        wo: unflip(wo),
                        weight: w,
                        pdf: 0.0,
                        delta: true,
                        eta: 1.0,
                        dispersive: false,
                    })
                }
                Some(d) => {
                    let m = d.sample_visible(wi, u2);
                    let wo = reflect(wi, m);
                    if wo.z <= 0.0 {
                        return None;
                    }
                    let pdf = d.pdf_visible(wi, m) / (4.0 * wo.dot(m));
                    if !(pdf > 0.0) {
                        return None;
                    }
                    // VNDF sampling: f cos/pdf = F · G1(wo, m) (Heitz 2018, Eq. 19)
                    let g1 = d.g1(wo, m);
                    let c = wi.dot(m);
                    let mut w = [0.0; N_WL];
                    for i in 0..N_WL {
                        let fr = match eta_k {
                            Some((e, k)) => fresnel_conductor(c, e.eval(wl[i]), k.eval(wl[i])),
                            None => 1.0,
                        };
                        w[i] = refl[i] * fr * g1;
                    }
                    Some(BsdfSample {
                        wo: unflip(wo),
                        weight: w,
                        pdf,
                        delta: false,
                        eta: 1.0,
                        dispersive: false,
                    })
                }
            },
            Lobe::Dielectric {
                distr,
                int_ior,
                ext_ior,
            } => {
                let dispersive = int_ior.is_dispersive();
                let eta = int_ior.at(wl[0]) / ext_ior;
                let s = match distr {
                    None => {
                        let (f, cos_t, _eta_it, eta_ti) = fresnel_dielectric(wi.z, eta);
                        if u1 <= f {
                            BsdfSample {
                                wo: Vec3::new(-wi.x, -wi.y, wi.z),
                                weight: [1.0; N_WL],
                                pdf: 0.0,
                                delta: true,
                                eta: 1.0,
                                dispersive,
                            }
                        } else {
                            let wo = Vec3::new(-eta_ti * wi.x, -eta_ti * wi.y, cos_t);
                            // radiance scaling (η_t/η_i)⁻² across the interface
                            let s = eta_ti * eta_ti;
                            BsdfSample {
                                wo,
                                weight: [s; N_WL],
                                pdf: 0.0,
                                delta: true,
                                eta: 1.0 / eta_ti,
                                dispersive,
                            }
                        }
                    }
                    Some(d) => {
                        // visible normal of the side wi is on, kept in the upper hemisphere
                        // so that the Fresnel term sees from which side the ray arrives
                        let wi_up = if wi.z >= 0.0 { wi } else { -wi };
                        let m = d.sample_visible(wi_up, u2);
                        let (f, cos_t, _eta_it, eta_ti) = fresnel_dielectric(wi.dot(m), eta);
                        let (wo, reflection) = if u1 <= f {
                            (reflect(wi, m), true)
                        } else {
                            (refract(wi, m, cos_t, eta_ti), false)
                        };
                        // f·cos/pdf = G1(wo, m) (× η_ti² for radiance across the interface)
                        let g1 = d.g1(wo, m);
                        let valid = if reflection {
                            wo.z * wi.z > 0.0
                        } else {
                            wo.z * wi.z < 0.0
                        };
                        if !valid || g1 <= 0.0 {
                            return None;
                        }
                        let (_, pdf) = rough_dielectric_eval(d, wi, wo, eta);
                        if !(pdf > 0.0) {
                            return None;
                        }
                        let s = if reflection { 1.0 } else { eta_ti * eta_ti };
                        BsdfSample {
                            wo,
                            weight: [g1 * s; N_WL],
                            pdf,
                            delta: false,
                            eta: if reflection { 1.0 } else { 1.0 / eta_ti },
                            dispersive,
                        }
                    }
                };
                Some(s)
            }
            Lobe::RoughPlastic {
                distr,
                specular_sampling_weight,
                external_transmittance,
                ..
            } => {
                let t_i = lerp_table(external_transmittance, wi.z);
                let ps = plastic_specular_prob(t_i, *specular_sampling_weight);
                let wo = if u1 < ps {
                    reflect(wi, distr.sample_visible(wi, u2))
                } else {
                    square_to_cosine_hemisphere(u2)
                };
                if wo.z <= 0.0 {
                    return None;
                }
                let (f, p) = self.eval_pdf(wi, wo, refl, wl);
                if !(p[0] > 0.0) {
                    return None;
                }
                Some(BsdfSample {
                    wo: unflip(wo),
                    weight: f.map(|v| v / p[0]),
                    pdf: p[0],
                    delta: false,
                    eta: 1.0,
                    dispersive: false,
                })
            }
        }
    }
}

#[inline]
fn plastic_specular_prob(t_i: f32, w: f32) -> f32 {
    let ps = (1.0 - t_i) * w;
    let pd = t_i * (1.0 - w);
    if ps + pd > 0.0 {
        ps / (ps + pd)
    } else {
        0.0
    }
}

/// Rough dielectric f·|cos θo| and sampling density (Walter et al. 2007, Eqs. 20–21 and the
/// half-vector Jacobians; radiance transport, so transmission carries the (η_i/η_t)² factor).
#[inline]
fn rough_dielectric_eval(d: &Ggx, wi: Vec3, wo: Vec3, eta: f32) -> (f32, f32) {
    let (ci, co) = (wi.z, wo.z);
    if ci == 0.0 || co == 0.0 {
        return (0.0, 0.0);
    }
    let reflect = ci * co > 0.0;
    let eta_io = if ci > 0.0 { eta } else { 1.0 / eta }; // η_o/η_i relative across
    let mut m = if reflect {
        (wi + wo).normalize()
    } else {
        (wi + wo * eta_io).normalize()
    };
    if m.z < 0.0 {
        m = -m;
    }
    if !m.is_finite() {
        return (0.0, 0.0);
    }
    // the microfacet must face both directions consistently
    if wi.dot(m) * ci <= 0.0 || wo.dot(m) * co <= 0.0 {
        return (0.0, 0.0);
    }
    let dm = d.d(m);
    let (f, _, _, _) = fresnel_dielectric(wi.dot(m), eta);
    let g = d.g1(wi * ci.signum(), m) * d.g1(wo * co.signum(), m);
    // visible-normal density for the side wi is on
    let wi_up = wi * ci.signum();
    let pm = d.g1(wi_up, m) * wi_up.dot(m).max(0.0) * dm / wi_up.z;
    if reflect {
        let val = f * dm * g / (4.0 * ci.abs());
        let pdf = f * pm / (4.0 * wo.dot(m).abs());
        (val, pdf)
    } else {
        let denom = wi.dot(m) + eta_io * wo.dot(m);
        let denom2 = denom * denom;
        let val = ((1.0 - f) * dm * g * (wi.dot(m) * wo.dot(m)).abs() / (ci.abs() * denom2)).abs();
        let pdf = (1.0 - f) * pm * eta_io * eta_io * wo.dot(m).abs() / denom2;
        (val, pdf)
    }
}

/// Directional albedo of a GGX dielectric reflection lobe with relative index `eta`, at
/// cos θ = `mu`: ∫ F D G /(4 cos θi) dωo, by a deterministic 64×64 stratified quadrature over
/// the visible normals (E[F(wi·m)·G1(wo, m)] under VNDF sampling).
pub fn rough_reflectance(d: &Ggx, mu: f32, eta: f32) -> f32 {
    let mu = mu.max(1e-6);
    let wi = Vec3::new((1.0 - mu * mu).max(0.0).sqrt(), 0.0, mu);
    let n = 64;
    let mut s = 0.0f64;
    for a in 0..n {
        for b in 0..n {
            let u = Vec2::new((a as f32 + 0.5) / n as f32, (b as f32 + 0.5) / n as f32);
            let m = d.sample_visible(wi, u);
            let wo = reflect(wi, m);
            if wo.z <= 0.0 {
                continue;
            }
            let (f, _, _, _) = fresnel_dielectric(wi.dot(m), eta);
            s += (f * d.g1(wo, m)) as f64;
        }
    }
    (s / (n * n) as f64) as f32
}

/// Build Mitsuba's `roughplastic` lobe: coat tables from [`rough_reflectance`] at
/// cos θ = max(1e-6, i/63), i = 0..63; internal reflectance 2·mean(R(μ, 1/η)·μ).
pub fn rough_plastic(alpha: f32, eta: f32, mean_diffuse: f32, nonlinear: bool) -> Lobe {
    let distr = Ggx::new(alpha);
    let n = PLASTIC_TABLE_RES;
    let mus: Vec<f32> = (0..n)
        .map(|i| (i as f32 / (n - 1) as f32).max(1e-6))
        .collect();
    let external_transmittance = mus
        .iter()
        .map(|&m| 1.0 - rough_reflectance(&distr, m, eta))
        .collect();
    let internal_reflectance = 2.0
        * mus
            .iter()
            .map(|&m| rough_reflectance(&distr, m, 1.0 / eta) * m)
            .sum::<f32>()
        / n as f32;
    let s_mean = 1.0;
    Lobe::RoughPlastic {
        distr,
        eta,
        specular_sampling_weight: s_mean / (mean_diffuse + s_mean),
        external_transmittance,
        internal_reflectance,
        nonlinear,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fresnel_limits() {
        // normal incidence: ((n−1)/(n+1))²
        let (f, ct, _, _) = fresnel_dielectric(1.0, 1.5);
        assert!((f - 0.04).abs() < 1e-6 && (ct + 1.0).abs() < 1e-6);
        // total internal reflection from inside beyond the critical angle
        let (f, _, _, _) = fresnel_dielectric(-0.3, 1.5);
        assert_eq!(f, 1.0);
        // conductor with k = 0 equals the dielectric formula
        for c in [0.1f32, 0.5, 0.9] {
            let a = fresnel_conductor(c, 1.5, 0.0);
            let b = fresnel_dielectric(c, 1.5).0;
            assert!((a - b).abs() < 1e-5, "{a} {b}");
        }
        // gold at normal incidence: |(n−1+ik)/(n+1+ik)|²
        let (n, k) = (0.5f32, 2.4f32);
        let r = ((n - 1.0).powi(2) + k * k) / ((n + 1.0).powi(2) + k * k);
        assert!((fresnel_conductor(1.0, n, k) - r).abs() < 1e-5);
    }

    #[test]
    fn abbe_model_hits_nd_and_vd() {
        let ior = Ior::from_abbe(1.5168, 64.17); // N-BK7
        let (nd, nf, nc) = (ior.at(587.56), ior.at(486.13), ior.at(656.27));
        assert!((nd - 1.5168).abs() < 1e-5);
        assert!(((nd - 1.0) / (nf - nc) - 64.17).abs() < 0.01);
    }
}
