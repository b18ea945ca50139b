//! Pupil sampling for the FFT PSF / MTF, and focus criteria (paraxial focus, best focus).
//!
//! **Pupil sampling.** The FFT PSF of an `n`² pupil grid over the exit-pupil diameter is
//! periodic in the image plane with period λN_w(n − 1), the same window as the Huygens sum
//! (see [`crate::huygens`]). The local OPD slope dW/dρ (waves per unit normalised pupil
//! coordinate) equals ε/(2λN_w) for a ray landing ε from the reference point (the transverse
//! ray aberration, Welford "Aberrations of Optical Systems" §8.2), so on the grid spacing
//! h = 2/(n − 1) the OPD changes by εh/(2λN_w) between samples. [`LensPrescription::pupil_sampling`]
//! traces the pupil, takes the largest landing distance ε_max (plus [`PSF_TAIL_MARGIN`] λN_w
//! for the diffraction tails) and asks for at most 1/[`SAMPLES_PER_WAVE`] wave per sample:
//! n ≥ q(ε_max + 2λN_w)/(λN_w) + 1 with q = [`SAMPLES_PER_WAVE`]. q = 2 is the Nyquist rate
//! (every ray inside the PSF window); q = 4 is used because the discrete autocorrelation (the
//! OTF) converges more slowly near the pupil rim at low frequencies: on the 14-wave singlet of
//! lens/tests/mtf_sampling.rs the 5 lp/mm MTF is off by 0.045 at q = 2 and by < 0.01 at q = 4
//! against a 1024² grid. A coarse grid folds the PSF back onto itself and inflates the MTF of
//! strongly aberrated lenses (an f/1.4 Petzval with 18 waves p-v read 0.54 instead of 0.09 at
//! 10 lp/mm with 64²).
//!
//! **Focus.** The paraxial focus is the lens's own image plane (after
//! [`LensPrescription::focused`]). The best focus ([`LensPrescription::best_focus_mtf`]) is the
//! image-plane shift that maximises an MTF merit: the weighted mean over fields and frequencies
//! of the mean of the tangential and sagittal MTF at one wavelength.
use crate::analysis::WaveOptics;
use crate::error::LensError;
use crate::prescription::LensPrescription;
use crate::trace::AimedChief;
use crate::trace::Clipping;

/// Diffraction units (λN_w) of margin around the traced spot in [`LensPrescription::pupil_sampling`].
pub const PSF_TAIL_MARGIN: f64 = 2.0;

/// Pupil samples per wave of OPD change required by [`LensPrescription::pupil_sampling`]
/// (2 = Nyquist; see the module docs for why 4).
pub const SAMPLES_PER_WAVE: f64 = 4.0;

/// The pupil grid an FFT PSF / MTF needs (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PupilSampling {
    /// Pupil samples per side used (even, within the caller's [min, max]).
    pub samples: usize,
    /// Samples per side the OPD slope asks for.
    pub needed: usize,
    /// Largest distance of a traced ray from the chief ray on the image plane (mm).
    pub spot_extent_mm: f64,
    /// Largest OPD slope, waves per unit normalised pupil coordinate: ε_max / (2λN_w).
    pub max_slope_waves: f64,
    /// Whether `samples` ≥ `needed` (false: the PSF aliases; the caller should warn).
    pub alias_free: bool,
}

/// An MTF merit for [`LensPrescription::best_focus_mtf`].
#[derive(Debug, Clone, PartialEq)]
pub struct MtfMerit {
    /// Field angles (degrees) and their weights.
    pub fields: Vec<(f64, f64)>,
    /// Frequencies (cycles/mm), equally weighted.
    pub freqs_cyc_per_mm: Vec<f64>,
    /// Wavelength (nm).
    pub wavelength_nm: f64,
    /// Pupil grid limits per side (the OPD slope sets the grid within them).
    pub min_pupil_n: usize,
    /// Upper limit of the pupil grid per side.
    pub max_pupil_n: usize,
    /// FFT zero-padding factor (≥ 2 keeps the autocorrelation free of wrap-around).
    pub pad: usize,
}

impl MtfMerit {
    /// On-axis merit at `wavelength_nm` over `freqs_cyc_per_mm`, pupil 64…1024, pad 2.
    pub fn on_axis(wavelength_nm: f64, freqs_cyc_per_mm: &[f64]) -> Self {
        MtfMerit {
            fields: vec![(0.0, 1.0)],
            freqs_cyc_per_mm: freqs_cyc_per_mm.to_vec(),
            wavelength_nm,
            min_pupil_n: 64,
            max_pupil_n: 1024,
            pad: 2,
        }
    }
}

/// The result of a focus search.
#[derive(Debug, Clone, PartialEq)]
pub struct BestFocus {
    /// Image-plane shift from the lens's own image plane (mm, + = away from the lens).
    pub image_shift_mm: f64,
    /// Merit there (0…1).
    pub merit: f64,
    /// Merit on the lens's own image plane.
    pub merit_at_zero: f64,
    /// Whether every MTF evaluated was alias free.
    pub alias_free: bool,
}

impl LensPrescription {
    /// The pupil grid (samples per side, within [`min_n`, `max_n`]) that the FFT PSF of
    /// `field_deg` at `wavelength_nm` needs on this lens's image plane (see the module docs).
    pub fn pupil_sampling(
        &self,
        field_deg: f64,
        wavelength_nm: f64,
        min_n: usize,
        max_n: usize,
    ) -> Result<PupilSampling, LensError> {
        let AimedChief {
            first_order: fo,
            aim,
            chief,
        } = self.aimed_chief_ray(field_deg, wavelength_nm)?;
        // A 33² grid plus the rim (where the aberrations are largest), as the OPD map traces.
        let mut pts = crate::analysis::pupil_grid(33);
        pts.extend((0..96).map(|k| {
            let a = 2.0 * std::f64::consts::PI * k as f64 / 96.0;
            [a.cos(), a.sin()]
        }));
        let b = self
            .trace_system(wavelength_nm)
            .trace_pupil(&aim, &pts, Clipping::None);
        let c = chief.image_mm;
        let eps = (0..b.len())
            .filter_map(|i| b.get(i))
            .map(|r| (r.image_mm[0] - c[0]).hypot(r.image_mm[1] - c[1]))
            .fold(0.0f64, f64::max);
        let unit_mm = wavelength_nm * 1e-6 * fo.working_f_number.abs();
        let needed =
            (SAMPLES_PER_WAVE * (eps + PSF_TAIL_MARGIN * unit_mm) / unit_mm).ceil() as usize + 1;
        let lo = (min_n.max(8) + 1) & !1;
        let hi = (max_n.max(lo) + 1) & !1;
        let samples = ((needed + 1) & !1).clamp(lo, hi);
        Ok(PupilSampling {
            samples,
            needed,
            spot_extent_mm: eps,
            max_slope_waves: eps / (2.0 * unit_mm),
            alias_free: needed <= samples,
        })
    }

    /// [`LensPrescription::wave_optics`] on the pupil grid [`LensPrescription::pupil_sampling`]
    /// chooses within [`min_n`, `max_n`], zero-padded by `pad`.
    pub fn wave_optics_sampled(
        &self,
        field_deg: f64,
        wavelength_nm: f64,
        min_n: usize,
        max_n: usize,
        pad: usize,
        freqs_cyc_per_mm: &[f64],
    ) -> Result<(WaveOptics, PupilSampling), LensError> {
        let s = self.pupil_sampling(field_deg, wavelength_nm, min_n, max_n)?;
        let wo = self.wave_optics(field_deg, wavelength_nm, s.samples, pad, freqs_cyc_per_mm)?;
        Ok((wo, s))
    }

    /// The MTF merit (see [`MtfMerit`]) of this lens on its own image plane, and whether every
    /// MTF was alias free.
    pub fn mtf_merit(&self, merit: &MtfMerit) -> Result<(f64, bool), LensError> {
        let mut sum = 0.0;
        let mut wsum = 0.0;
        let mut ok = true;
        for &(field_deg, weight) in &merit.fields {
            let (wo, s) = self.wave_optics_sampled(
                field_deg,
                merit.wavelength_nm,
                merit.min_pupil_n,
                merit.max_pupil_n,
                merit.pad.max(2),
                &merit.freqs_cyc_per_mm,
            )?;
            ok &= s.alias_free;
            let m = wo
                .mtf
                .iter()
                .map(|p| 0.5 * (p.tangential + p.sagittal))
                .sum::<f64>()
                / wo.mtf.len().max(1) as f64;
            sum += weight * m;
            wsum += weight;
        }
        if wsum <= 0.0 {
            return Err(LensError::Prescription(
                "MTF merit: field weights must sum to > 0".into(),
            ));
        }
        Ok((sum / wsum, ok))
    }

    /// Best focus: the image-plane shift in [`lo_mm`, `hi_mm`] (from the lens's own image plane)
    /// maximising `merit`. The merit of a strongly aberrated lens can have several local
    /// maxima, so the interval is first scanned at 24 steps, then the best step is refined by
    /// golden-section search to 1e-4 of the interval
    /// ([`crate::focus_model::maximise_on_interval`]).
    pub fn best_focus_mtf(
        &self,
        merit: &MtfMerit,
        lo_mm: f64,
        hi_mm: f64,
    ) -> Result<BestFocus, LensError> {
        if !(lo_mm.is_finite() && hi_mm.is_finite() && lo_mm < hi_mm) {
            return Err(LensError::Prescription(format!(
                "best focus: search interval [{lo_mm}, {hi_mm}] mm is empty"
            )));
        }
        let d0 = self.image_distance_mm();
        let mut alias_free = true;
        let mut eval = |dz: f64| -> Result<f64, LensError> {
            let (m, ok) = self.with_image_distance(d0 + dz).mtf_merit(merit)?;
            alias_free &= ok;
            Ok(m)
        };
        let best = crate::focus_model::maximise_on_interval(
            &mut eval,
            lo_mm,
            hi_mm,
            24,
            1e-4 * (hi_mm - lo_mm),
        )?;
        let (image_shift_mm, merit_best) = (best.x, best.value);
        let merit_at_zero = eval(0.0)?;
        Ok(BestFocus {
            image_shift_mm,
            merit: merit_best,
            merit_at_zero,
            alias_free,
        })
    }

    /// The default best-focus search interval (mm from the own image plane): from the paraxial
    /// plane to `rms_best_shift_mm` (the RMS-spot best focus), widened on both sides by four
    /// diffraction depths of focus, 4 × 2λN_w².
    pub fn focus_search_interval_mm(
        &self,
        wavelength_nm: f64,
        rms_best_shift_mm: f64,
    ) -> Result<(f64, f64), LensError> {
        let nw = self.first_order(wavelength_nm)?.working_f_number;
        let d = 8.0 * wavelength_nm * 1e-6 * nw * nw;
        Ok((
            rms_best_shift_mm.min(0.0) - d,
            rms_best_shift_mm.max(0.0) + d,
        ))
    }
}
