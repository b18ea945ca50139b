//! The focus model: where a lens camera puts its image plane (or its focusing group) for an
//! object at the focus distance, by a stated criterion. This is the one place every consumer
//! of a lens (lens report, field model, `blur.kind = "lens"`, the real-lens and light-field
//! cameras of the path tracer, the depth path, studies) gets a focused lens from.
//!
//! ## Setting ([`FocusSpec`])
//! * `focus_distance_mm`: object distance from the first vertex (mm); `None` = infinity.
//! * [`FocusCriterion`]:
//!   * `Paraxial`: the paraxial image of the focus distance at the primary wavelength.
//!   * `Best`: the position maximising the polychromatic MTF at one frequency, weighted over
//!     the field (below). Camera consumers pass half the pixel Nyquist frequency, 1/(4p) for a
//!     pitch p; without a pixel the default is a quarter of the incoherent cutoff 1/(λN_w) at
//!     the primary wavelength ([`default_frequency_cyc_per_mm`]).
//! * [`FocusMotion`]: `Unit` — the whole lens moves relative to the sensor, i.e. the last
//!   thickness (image distance) changes, the object distance from the first vertex being the
//!   focus distance; `Group { first_surface, last_surface }` — surfaces `first..=last` move
//!   together by δ (+ = towards the image): the gap before the group (thickness of surface
//!   `first − 1`) grows by δ and the gap after it (thickness of surface `last`) shrinks by δ.
//!   The sensor is then fixed where the same criterion puts it with the lens focused at
//!   infinity by unit motion (δ = 0 at infinity), as an internally focusing lens whose
//!   flange distance was set at infinity.
//!
//! ## Merit
//! The MTF at one frequency ν of an aberrated lens oscillates with defocus (its phase
//! reverses; on the f/2 double Gauss at 62.5 cycles/mm the 588 nm MTF goes 0.34 → 0.17 → 0.03
//! in 25 µm steps around the RMS best focus), so it is not a usable merit on its own: the
//! merit is the MTF *up to* ν, the mean of the polychromatic MTF at ν·k/K, k = 1..=K
//! ([`MERIT_FREQS`] = 4: a discrete area under the MTF curve, as Heynacher's subjective quality
//! factor), which has one clear maximum. The MTF at ν itself is reported too
//! ([`FocusedLens::mtf_at_frequency`]). The polychromatic MTF at a frequency is taken as the
//! wavelength-weighted (equal weights) mean of the monochromatic diffraction MTFs (T + S)/2 (FFT of the pupil function,
//! [`crate::focus`] sets the pupil grid from the OPD slope). This ignores the phase of the OTFs
//! (the lateral-colour shift between wavelengths), so it is an upper bound of the MTF of the
//! summed PSF off axis and exact on axis when the chief rays coincide. The field weighting is
//! the mean over the image disc by three equal-area zones: relative image heights
//! r_k = √((k + ½)/3), k = 0, 1, 2 (in tan θ of the maximum field), equal weights; a maximum
//! field of 0 uses the axis only.
//!
//! ## Search
//! The position is searched on an interval around the paraxial focus that holds the
//! polychromatic RMS-spot best focus of the axis (ray fans, golden section), widened by four
//! diffraction depths of focus (`focus_search_interval_mm`); the merit is scanned at 10 steps
//! and the best step refined by golden section to 0.1 λN_w² ([`maximise_on_interval`]). For a group, the
//! paraxial group shift is solved by the secant method on the paraxial image distance, and the
//! image-side interval is mapped to group shifts by the numerical derivative ∂s'/∂δ.
use crate::error::LensError;
use crate::prescription::LensPrescription;

/// How the lens moves to focus.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum FocusMotion {
    /// The whole lens moves relative to the sensor (the image distance changes).
    #[default]
    Unit,
    /// Surfaces `first_surface..=last_surface` (0-based) move together; the sensor is fixed
    /// at its infinity-focus position (see the module docs).
    Group {
        /// First surface of the group (≥ 1: the gap before it is inside the lens).
        first_surface: usize,
        /// Last surface of the group (≥ `first_surface`, < number of surfaces).
        last_surface: usize,
    },
}

/// The focus criterion.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum FocusCriterion {
    /// Maximum polychromatic MTF at the focus frequency, weighted over the field.
    #[default]
    Best,
    /// Paraxial image of the focus distance (primary wavelength).
    Paraxial,
}

impl FocusCriterion {
    /// The name used in files and reports (`"best"` or `"paraxial"`).
    pub fn name(self) -> &'static str {
        match self {
            FocusCriterion::Best => "best",
            FocusCriterion::Paraxial => "paraxial",
        }
    }

    /// Parse `"best"` / `"paraxial"`.
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "best" => Some(FocusCriterion::Best),
            "paraxial" => Some(FocusCriterion::Paraxial),
            _ => None,
        }
    }
}

/// How to focus (everything but the distance).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct FocusMethod {
    /// Criterion.
    pub criterion: FocusCriterion,
    /// Motion.
    pub motion: FocusMotion,
    /// Merit frequency (cycles/mm); `None` = [`default_frequency_cyc_per_mm`].
    pub frequency_cyc_per_mm: Option<f64>,
    /// Largest field angle of the merit (degrees); `None` = the largest of the lens's
    /// `fields_deg`; 0 = axis only.
    pub max_field_deg: Option<f64>,
    /// Merit wavelengths (nm, equal weights); `None` = the lens's `wavelengths_nm`.
    pub wavelengths_nm: Option<Vec<f64>>,
}

impl FocusMethod {
    /// The method from the keys of a camera or lens configuration (docs/lens.md, "Focus"):
    /// `focus_criterion` (`"best"` default, `"paraxial"`), `focus_frequency_cyc_per_mm`
    /// (> 0; default: the caller's) and `focus_group_surfaces` (`[first, last]`, default unit
    /// motion). The error names the key and the value.
    pub fn from_keys(
        criterion: Option<&str>,
        frequency_cyc_per_mm: Option<f64>,
        group_surfaces: Option<[usize; 2]>,
    ) -> Result<Self, String> {
        let criterion = match criterion {
            None => FocusCriterion::Best,
            Some(c) => FocusCriterion::parse(c).ok_or_else(|| {
                format!(
                    "focus_criterion: unknown value \"{c}\" (expected \"best\" or \"paraxial\")"
                )
            })?,
        };
        if let Some(f) = frequency_cyc_per_mm {
            if !(f.is_finite() && f > 0.0) {
                return Err(format!(
                    "focus_frequency_cyc_per_mm: {f} must be a finite number > 0"
                ));
            }
        }
        let motion = match group_surfaces {
            None => FocusMotion::Unit,
            Some([a, b]) => {
                if a == 0 || a > b {
                    return Err(format!(
                        "focus_group_surfaces: [{a}, {b}] must be [first, last] with 1 ≤ first ≤ last"
                    ));
                }
                FocusMotion::Group {
                    first_surface: a,
                    last_surface: b,
                }
            }
        };
        Ok(FocusMethod {
            criterion,
            motion,
            frequency_cyc_per_mm,
            ..Default::default()
        })
    }

    /// The paraxial focus by unit motion (the lens's own image plane convention before the
    /// focus model existed).
    pub fn paraxial() -> Self {
        FocusMethod {
            criterion: FocusCriterion::Paraxial,
            ..Default::default()
        }
    }
}

/// A focus setting: distance and method.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct FocusSpec {
    /// Focus distance from the first vertex (mm); `None` = infinity.
    pub focus_distance_mm: Option<f64>,
    /// How to focus.
    pub method: FocusMethod,
}

/// A focused lens and how it was focused.
#[derive(Debug, Clone, PartialEq)]
pub struct FocusedLens {
    /// The prescription at the focus setting, its object at the focus distance.
    pub lens: LensPrescription,
    /// Focus distance from the first vertex (mm); `None` = infinity.
    pub focus_distance_mm: Option<f64>,
    /// Criterion used.
    pub criterion: FocusCriterion,
    /// Motion used.
    pub motion: FocusMotion,
    /// The method with every default resolved (frequency, maximum field, wavelengths): focusing
    /// again with it gives the same lens.
    pub method: FocusMethod,
    /// Last vertex → image plane (mm) at the focus setting.
    pub image_distance_mm: f64,
    /// Paraxial image distance of the focus distance by unit motion (mm).
    pub paraxial_image_distance_mm: f64,
    /// Group shift from the prescription's own gaps (mm, + = towards the image; 0 for unit
    /// motion).
    pub group_shift_mm: f64,
    /// Merit frequency (cycles/mm).
    pub frequency_cyc_per_mm: f64,
    /// Field angles (degrees) and weights of the merit.
    pub merit_fields: Vec<(f64, f64)>,
    /// Merit wavelengths (nm).
    pub merit_wavelengths_nm: Vec<f64>,
    /// The merit at the focus setting: polychromatic field-weighted MTF averaged over
    /// ν·k/4, k = 1..=4 (module docs).
    pub mtf: f64,
    /// The same merit at the paraxial focus (unit motion).
    pub mtf_paraxial: f64,
    /// Polychromatic field-weighted MTF at ν itself, at the focus setting.
    pub mtf_at_frequency: f64,
    /// Whether every MTF evaluated was alias free.
    pub alias_free: bool,
}

/// Result of [`maximise_on_interval`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Maximum {
    /// Argument of the maximum.
    pub x: f64,
    /// Value there.
    pub value: f64,
}

/// Maximise `f` on [`lo`, `hi`]: a scan at `steps` steps (the merit of an aberrated lens can
/// have several local maxima), then golden-section refinement of the best step until the
/// bracket is shorter than `tol`.
pub fn maximise_on_interval<E>(
    mut f: impl FnMut(f64) -> Result<f64, E>,
    lo: f64,
    hi: f64,
    steps: usize,
    tol: f64,
) -> Result<Maximum, E> {
    let steps = steps.max(2);
    let h = (hi - lo) / steps as f64;
    let mut best = (lo, f64::MIN);
    for k in 0..=steps {
        let z = lo + h * k as f64;
        let m = f(z)?;
        if m > best.1 {
            best = (z, m);
        }
    }
    let g = (5f64.sqrt() - 1.0) / 2.0;
    let (mut a, mut b) = ((best.0 - h).max(lo), (best.0 + h).min(hi));
    let mut c = b - g * (b - a);
    let mut d = a + g * (b - a);
    let (mut fc, mut fd) = (f(c)?, f(d)?);
    while b - a > tol.max(1e-12 * (hi - lo).abs()) {
        if fc > fd {
            b = d;
            d = c;
            fd = fc;
            c = b - g * (b - a);
            fc = f(c)?;
        } else {
            a = c;
            c = d;
            fc = fd;
            d = a + g * (b - a);
            fd = f(d)?;
        }
    }
    let z = 0.5 * (a + b);
    let mz = f(z)?;
    Ok(if mz >= best.1 {
        Maximum { x: z, value: mz }
    } else {
        Maximum {
            x: best.0,
            value: best.1,
        }
    })
}

/// Default merit frequency without a pixel: a quarter of the incoherent cutoff 1/(λN_w) at the
/// primary wavelength with the object at `focus_distance_mm`.
pub fn default_frequency_cyc_per_mm(
    lens: &LensPrescription,
    focus_distance_mm: Option<f64>,
) -> Result<f64, LensError> {
    let l = lens.focus_at(focus_distance_mm)?;
    let nw = l.first_order(lens.primary_nm)?.working_f_number.abs();
    Ok(0.25 / (lens.primary_nm * 1e-6 * nw))
}

/// Field angles (degrees) and weights of the merit: three equal-area zones of the image disc
/// up to `max_field_deg` (module docs), or the axis when it is 0.
pub fn merit_fields(max_field_deg: f64) -> Vec<(f64, f64)> {
    if !(max_field_deg > 0.0) {
        return vec![(0.0, 1.0)];
    }
    let t = max_field_deg.to_radians().tan();
    (0..3)
        .map(|k| {
            let r = ((k as f64 + 0.5) / 3.0).sqrt();
            ((r * t).atan().to_degrees(), 1.0 / 3.0)
        })
        .collect()
}

/// Smallest and largest pupil grid per side of a merit MTF (larger needs are flagged in
/// [`FocusedLens::alias_free`]).
const MERIT_PUPIL_N: (usize, usize) = (32, 128);

/// Scan steps of the focus search (then golden section to a tenth of λN_w²).
const SCAN_STEPS: usize = 10;

/// Frequencies of the merit: ν·k/K, k = 1..=K (module docs).
pub const MERIT_FREQS: usize = 4;

impl LensPrescription {
    /// The polychromatic field-weighted MTF (module docs) of this lens as it stands, averaged
    /// over `freqs` (cycles/mm); and whether every MTF was alias free.
    pub fn poly_mtf_merit(
        &self,
        fields: &[(f64, f64)],
        wavelengths_nm: &[f64],
        freqs: &[f64],
    ) -> Result<(f64, bool), LensError> {
        use rayon::prelude::*;
        let jobs: Vec<(f64, f64, f64)> = fields
            .iter()
            .flat_map(|&(f, w)| wavelengths_nm.iter().map(move |&l| (f, w, l)))
            .collect();
        let vals: Vec<(f64, f64, bool)> = jobs
            .par_iter()
            .map(|&(field, weight, wl)| {
                let (wo, s) = self.wave_optics_sampled(
                    field,
                    wl,
                    MERIT_PUPIL_N.0,
                    MERIT_PUPIL_N.1,
                    2,
                    &freqs,
                )?;
                let m = wo
                    .mtf
                    .iter()
                    .map(|p| 0.5 * (p.tangential + p.sagittal))
                    .sum::<f64>()
                    / freqs.len() as f64;
                Ok((weight, m, s.alias_free))
            })
            .collect::<Result<_, LensError>>()?;
        let wsum: f64 = vals.iter().map(|v| v.0).sum();
        if !(wsum > 0.0) {
            return Err(LensError::Prescription(
                "MTF merit: field weights must sum to > 0".into(),
            ));
        }
        Ok((
            vals.iter().map(|v| v.0 * v.1).sum::<f64>() / wsum,
            vals.iter().all(|v| v.2),
        ))
    }

    /// A copy with surfaces `first..=last` moved by `shift_mm` towards the image (module docs).
    pub fn with_group_shift(
        &self,
        first_surface: usize,
        last_surface: usize,
        shift_mm: f64,
    ) -> Result<Self, LensError> {
        let n = self.surfaces.len();
        if first_surface == 0 || first_surface > last_surface || last_surface >= n {
            return Err(LensError::Prescription(format!(
                "focus group: surfaces {first_surface}..={last_surface} must satisfy 1 ≤ first ≤ last < {n}"
            )));
        }
        let mut l = self.clone();
        l.surfaces[first_surface - 1].thickness_mm += shift_mm;
        l.surfaces[last_surface].thickness_mm -= shift_mm;
        for k in [first_surface - 1, last_surface] {
            if !(l.surfaces[k].thickness_mm > 0.0) {
                return Err(LensError::Prescription(format!(
                    "focus group: a shift of {shift_mm:.4} mm closes the gap after surface {k}"
                )));
            }
        }
        Ok(l)
    }

    /// Focus this lens per `spec` (module docs).
    pub fn focus(&self, spec: &FocusSpec) -> Result<FocusedLens, LensError> {
        let m = &spec.method;
        if let Some(d) = spec.focus_distance_mm {
            if !(d.is_finite() && d > 0.0) {
                return Err(LensError::Prescription(format!(
                    "focus distance {d} mm must be > 0 (None = infinity)"
                )));
            }
        }
        let paraxial = self.focus_at(spec.focus_distance_mm)?;
        let s0 = paraxial.image_distance_mm();
        if !(s0.is_finite() && s0 > 0.0) {
            return Err(LensError::Paraxial(format!(
                "the focus distance has no real paraxial image (image distance {s0} mm)"
            )));
        }
        let freq = match m.frequency_cyc_per_mm {
            Some(f) if f.is_finite() && f > 0.0 => f,
            Some(f) => {
                return Err(LensError::Prescription(format!(
                    "focus frequency {f} cycles/mm must be > 0"
                )))
            }
            None => default_frequency_cyc_per_mm(self, spec.focus_distance_mm)?,
        };
        let max_field = m
            .max_field_deg
            .unwrap_or_else(|| self.fields_deg.iter().cloned().fold(0.0, f64::max));
        let fields = merit_fields(max_field);
        let wls = m
            .wavelengths_nm
            .clone()
            .unwrap_or_else(|| self.wavelengths_nm.clone());
        if wls.is_empty() {
            return Err(LensError::Prescription(
                "focus: no merit wavelengths".into(),
            ));
        }
        let freqs: Vec<f64> = (1..=MERIT_FREQS)
            .map(|k| freq * k as f64 / MERIT_FREQS as f64)
            .collect();
        let merit = |l: &LensPrescription| l.poly_mtf_merit(&fields, &wls, &freqs);
        // Search resolution: a tenth of the diffraction depth of focus ±λN_w² … ±2λN_w².
        let nw = paraxial
            .first_order(self.primary_nm)?
            .working_f_number
            .abs();
        let tol_mm = 0.1 * self.primary_nm * 1e-6 * nw * nw;
        let (mtf_paraxial, mut alias_free) = merit(&paraxial)?;
        let done = |lens: LensPrescription, shift: f64, mtf: f64, alias_free: bool| {
            let image_distance_mm = lens.image_distance_mm();
            let (mtf_at_frequency, _) = lens.poly_mtf_merit(&fields, &wls, &[freq])?;
            Ok::<FocusedLens, LensError>(FocusedLens {
                lens,
                focus_distance_mm: spec.focus_distance_mm,
                criterion: m.criterion,
                motion: m.motion,
                method: FocusMethod {
                    criterion: m.criterion,
                    motion: m.motion,
                    frequency_cyc_per_mm: Some(freq),
                    max_field_deg: Some(max_field),
                    wavelengths_nm: Some(wls.clone()),
                },
                image_distance_mm,
                paraxial_image_distance_mm: s0,
                group_shift_mm: shift,
                frequency_cyc_per_mm: freq,
                merit_fields: fields.clone(),
                merit_wavelengths_nm: wls.clone(),
                mtf,
                mtf_paraxial,
                mtf_at_frequency,
                alias_free,
            })
        };
        match m.motion {
            FocusMotion::Unit => match m.criterion {
                FocusCriterion::Paraxial => done(paraxial, 0.0, mtf_paraxial, alias_free),
                FocusCriterion::Best => {
                    let (lo, hi) = paraxial.rms_focus_interval_mm(&wls)?;
                    let best = maximise_on_interval(
                        |dz| {
                            let (v, ok) = merit(&paraxial.with_image_distance(s0 + dz))?;
                            alias_free &= ok;
                            Ok::<f64, LensError>(v)
                        },
                        lo,
                        hi,
                        SCAN_STEPS,
                        tol_mm,
                    )?;
                    let (lens, v) = if best.value >= mtf_paraxial {
                        (paraxial.with_image_distance(s0 + best.x), best.value)
                    } else {
                        (paraxial, mtf_paraxial)
                    };
                    done(lens, 0.0, v, alias_free)
                }
            },
            FocusMotion::Group {
                first_surface,
                last_surface,
            } => {
                // The sensor: where the same criterion puts it at infinity by unit motion.
                let inf = if spec.focus_distance_mm.is_none() {
                    None
                } else {
                    Some(self.focus(&FocusSpec {
                        focus_distance_mm: None,
                        method: FocusMethod {
                            motion: FocusMotion::Unit,
                            frequency_cyc_per_mm: Some(freq),
                            max_field_deg: Some(max_field),
                            wavelengths_nm: Some(wls.clone()),
                            criterion: m.criterion,
                        },
                    })?)
                };
                let Some(inf) = inf else {
                    // At infinity the group is at its own position (δ = 0).
                    let u = self.focus(&FocusSpec {
                        focus_distance_mm: None,
                        method: FocusMethod {
                            motion: FocusMotion::Unit,
                            ..m.clone()
                        },
                    })?;
                    return Ok(FocusedLens {
                        motion: m.motion,
                        method: FocusMethod {
                            motion: m.motion,
                            ..u.method.clone()
                        },
                        ..u
                    });
                };
                let base = self
                    .with_object_distance(spec.focus_distance_mm)
                    .with_image_distance(inf.image_distance_mm);
                let shifted = |d: f64| base.with_group_shift(first_surface, last_surface, d);
                let image_of = |d: f64| -> Result<f64, LensError> {
                    Ok(shifted(d)?
                        .first_order(self.primary_nm)?
                        .paraxial_image_distance_mm)
                };
                // Paraxial group shift: s'(δ) = image distance − δ·[last is the final surface].
                let last_is_image = last_surface + 1 == self.surfaces.len();
                let target = |d: f64| -> Result<f64, LensError> {
                    let sensor = inf.image_distance_mm - if last_is_image { d } else { 0.0 };
                    Ok(image_of(d)? - sensor)
                };
                let efl = self.first_order(self.primary_nm)?.efl_mm.abs();
                let (mut x0, mut x1) = (0.0, 1e-3 * efl);
                let (mut f0, mut f1) = (target(x0)?, target(x1)?);
                for _ in 0..60 {
                    if (f1 - f0).abs() < 1e-15 {
                        break;
                    }
                    let x2 = x1 - f1 * (x1 - x0) / (f1 - f0);
                    x0 = x1;
                    f0 = f1;
                    x1 = x2;
                    f1 = target(x1)?;
                    if f1.abs() < 1e-9 {
                        break;
                    }
                }
                if !(f1.abs() < 1e-6) {
                    return Err(LensError::Paraxial(format!(
                        "focus group {first_surface}..={last_surface} cannot focus on {:?} mm",
                        spec.focus_distance_mm
                    )));
                }
                let d_par = x1;
                let par_lens = shifted(d_par)?;
                match m.criterion {
                    FocusCriterion::Paraxial => {
                        let (v, ok) = merit(&par_lens)?;
                        alias_free &= ok;
                        done(par_lens, d_par, v, alias_free)
                    }
                    FocusCriterion::Best => {
                        // Image-side interval → group shifts through ∂s'/∂δ.
                        let (lo, hi) = par_lens.rms_focus_interval_mm(&wls)?;
                        let h = 1e-3 * efl;
                        let slope = (target(d_par + h)? - target(d_par - h)?) / (2.0 * h);
                        if !(slope.abs() > 1e-9) {
                            return Err(LensError::Paraxial(format!(
                                "focus group {first_surface}..={last_surface} does not move the image"
                            )));
                        }
                        // target(δ) = image − sensor; the sensor sees defocus −target.
                        let (a, b) = (-hi / slope, -lo / slope);
                        let (a, b) = (d_par + a.min(b), d_par + a.max(b));
                        let best = maximise_on_interval(
                            |d| {
                                let (v, ok) = merit(&shifted(d)?)?;
                                alias_free &= ok;
                                Ok::<f64, LensError>(v)
                            },
                            a,
                            b,
                            SCAN_STEPS,
                            tol_mm / slope.abs(),
                        )?;
                        done(shifted(best.x)?, best.x, best.value, alias_free)
                    }
                }
            }
        }
    }

    /// The best-focus search interval (image-plane shift, mm, from this lens's own image
    /// plane): around the axial polychromatic RMS-spot best focus (ray fans at `wavelengths_nm`,
    /// aimed at the primary) and the own plane, widened by four diffraction depths of focus.
    fn rms_focus_interval_mm(&self, wavelengths_nm: &[f64]) -> Result<(f64, f64), LensError> {
        let grid = crate::analysis::pupil_grid(33);
        let fans = wavelengths_nm
            .iter()
            .map(|&w| self.ray_fan(0.0, w, self.primary_nm, &grid, crate::trace::Clipping::None))
            .collect::<Result<Vec<_>, _>>()?;
        let efl = self.first_order(self.primary_nm)?.efl_mm.abs();
        let dz = self.best_focus_shift_mm(&fans, 0.02 * efl);
        self.focus_search_interval_mm(self.primary_nm, dz)
    }
}
