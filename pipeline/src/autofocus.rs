//! Contrast autofocus (issue 18): as a camera's contrast-detection autofocus, the lens (moving
//! as a unit) is stepped through focus positions and the position whose simulated image is
//! sharpest on a region of the scene is kept. Every image comes from the one chain
//! ([`crate::chain::shot_electron_rate`] → [`crate::chain::expected_frame`]) with the camera's
//! optics replaced by the lens at that position (`camsim_optics::LensBlur`).
//!
//! * **Positions**: the lens position is parametrised by the object distance it images
//!   paraxially (`camsim_lens::FocusCriterion::Paraxial`), i.e. by the vergence 1/d from 0
//!   (infinity) to 1/`near_m`, `steps` evenly spaced, then golden-section refinement between
//!   the neighbours of the best step down to `tolerance_per_m`. The paraxial map from vergence to
//!   image distance is monotonic, so this scans the lens position itself; what is kept is the
//!   position of maximum image contrast, wherever the paraxial image of the object is.
//! * **Contrast metric** (the Tenengrad / gradient-energy focus measure, Krotkov, "Focusing",
//!   IJCV 1 (1987); Groen, Young & Ligthart, Cytometry 6 (1985)): on the region of the noise-free
//!   expected frame, the sum of squared differences between pixels one CFA period apart
//!   (same colour filter) horizontally and vertically, divided by the number of differences
//!   and by the squared mean of the region (so exposure does not change it). A region more than
//!   half clipped at the ADC's full scale is an error (its contrast is flat).
use crate::config::CaptureSet;
use crate::error::CliError;
use camsim_core::stats::Rect;
use camsim_lens::{FocusMethod, LensPrescription};
use camsim_optics::{Blur, LensBlur, LensBlurOptions, LensFocus};

/// What [`contrast_autofocus`] does.
#[derive(Debug, Clone, PartialEq)]
pub struct AutofocusOptions {
    /// Region of the sensor whose contrast is maximised (pixels).
    pub region: Rect,
    /// Nearest focus distance scanned (m from the first vertex).
    pub near_m: f64,
    /// Scan steps in vergence (≥ 3).
    pub steps: usize,
    /// Golden-section refinement stops when the vergence bracket is shorter (1/m, > 0).
    pub tolerance_per_m: f64,
}

/// One evaluated lens position.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AutofocusSample {
    /// Vergence of the object the position images paraxially (1/m; 0 = infinity).
    pub vergence_per_m: f64,
    /// Last vertex → sensor (mm).
    pub image_distance_mm: f64,
    /// Contrast metric (module docs).
    pub contrast: f64,
}

/// The result of [`contrast_autofocus`].
#[derive(Debug, Clone)]
pub struct Autofocus {
    /// The kept position.
    pub best: AutofocusSample,
    /// Every evaluated position, in evaluation order.
    pub samples: Vec<AutofocusSample>,
    /// The lens blur at the kept position (set it as the camera's `optics.blur`).
    pub blur: LensBlur,
}

/// The contrast metric of `region` in a row-major `cols`-wide frame, differences `period`
/// pixels apart (module docs). `None` when the region holds no pair or is black.
pub fn tenengrad_contrast(frame: &[f32], cols: usize, region: Rect, period: usize) -> Option<f64> {
    let p = period.max(1);
    let (mut s, mut n, mut sum, mut m) = (0.0, 0usize, 0.0, 0usize);
    for r in region.row0..region.row1 {
        for c in region.col0..region.col1 {
            let v = frame[r * cols + c] as f64;
            sum += v;
            m += 1;
            if c + p < region.col1 {
                s += (frame[r * cols + c + p] as f64 - v).powi(2);
                n += 1;
            }
            if r + p < region.row1 {
                s += (frame[(r + p) * cols + c] as f64 - v).powi(2);
                n += 1;
            }
        }
    }
    let mean = sum / m.max(1) as f64;
    if n == 0 || !(mean > 0.0) {
        return None;
    }
    Some(s / n as f64 / (mean * mean))
}

/// Contrast autofocus of shot `shot_index` of `set` with `lens` (module docs): `blur_opts` as
/// the camera's `blur.kind = "lens"` uses them (their focus setting is replaced by each scanned
/// position).
pub fn contrast_autofocus(
    set: &CaptureSet,
    shot_index: usize,
    lens: &LensPrescription,
    blur_opts: &LensBlurOptions,
    af: &AutofocusOptions,
) -> Result<Autofocus, CliError> {
    let s = &set.camera.sensor;
    let rg = af.region;
    if !(rg.row0 < rg.row1 && rg.col0 < rg.col1 && rg.row1 <= s.rows && rg.col1 <= s.cols) {
        return Err(CliError::Other(format!(
            "autofocus region rows {}..{}, cols {}..{} is empty or outside the {}×{} sensor",
            rg.row0, rg.row1, rg.col0, rg.col1, s.rows, s.cols
        )));
    }
    if !(af.near_m.is_finite() && af.near_m > 0.0) || af.steps < 3 || !(af.tolerance_per_m > 0.0) {
        return Err(CliError::Other(format!(
            "autofocus: near_m = {} and tolerance_per_m = {} must be > 0 and steps = {} ≥ 3",
            af.near_m, af.tolerance_per_m, af.steps
        )));
    }
    if shot_index >= set.shots.len() {
        return Err(CliError::Other(format!(
            "autofocus: shot {shot_index} does not exist"
        )));
    }
    let period = s.cfa.tile_rows().max(s.cfa.tile_cols());
    let grid = crate::chain::wavelength_grid(set);
    let eval = |v: f64| -> Result<(AutofocusSample, LensBlur), CliError> {
        let mut o = blur_opts.clone();
        o.focus = LensFocus::At(if v > 0.0 { Some(1e3 / v) } else { None });
        o.focus_method = FocusMethod::paraxial();
        let lb = LensBlur::from_prescription(lens, &o)
            .map_err(|e| CliError::Other(format!("autofocus: {e}")))?;
        let mut set_v = set.clone();
        set_v.camera.optics.blur = Blur::Lens(lb.clone());
        let rate = crate::chain::shot_electron_rate(&set_v, shot_index, &grid)?;
        let shot = crate::chain::shot_exposure(&set_v, shot_index, &rate);
        let frame = crate::chain::expected_frame(s, &rate, &shot);
        // A clipped region has no contrast to maximise (the metric is 0 at every position).
        let max_dn = s.max_dn() as f32;
        let clipped = (rg.row0..rg.row1)
            .flat_map(|r| (rg.col0..rg.col1).map(move |c| (r, c)))
            .filter(|&(r, c)| frame.data[r * frame.cols + c] >= max_dn)
            .count();
        if 2 * clipped > (rg.row1 - rg.row0) * (rg.col1 - rg.col0) {
            return Err(CliError::Other(format!(
                "autofocus: {clipped} of the region's pixels are clipped at {max_dn} DN \
                 (1/d = {v:.4}/m): shorten the shot's exposure"
            )));
        }
        let contrast =
            tenengrad_contrast(&frame.data, frame.cols, rg, period).ok_or_else(|| {
                CliError::Other("autofocus: the region is black in the simulated image".into())
            })?;
        let image_distance_mm = lb.focus.as_ref().map_or(f64::NAN, |f| f.image_distance_mm);
        Ok((
            AutofocusSample {
                vergence_per_m: v,
                image_distance_mm,
                contrast,
            },
            lb,
        ))
    };
    let vmax = 1.0 / af.near_m;
    let h = vmax / (af.steps - 1) as f64;
    let mut samples = Vec::new();
    let mut best: Option<(AutofocusSample, LensBlur)> = None;
    let keep = |r: (AutofocusSample, LensBlur),
                samples: &mut Vec<AutofocusSample>,
                best: &mut Option<(AutofocusSample, LensBlur)>| {
        samples.push(r.0);
        if best.as_ref().is_none_or(|b| r.0.contrast > b.0.contrast) {
            *best = Some(r);
        }
    };
    for k in 0..af.steps {
        let r = eval(h * k as f64)?;
        keep(r, &mut samples, &mut best);
    }
    // Golden section between the neighbours of the best step.
    let v0 = best.as_ref().map_or(0.0, |b| b.0.vergence_per_m);
    let (mut a, mut b) = ((v0 - h).max(0.0), (v0 + h).min(vmax));
    let g = (5f64.sqrt() - 1.0) / 2.0;
    let mut c = b - g * (b - a);
    let mut d = a + g * (b - a);
    let rc = eval(c)?;
    let rd = eval(d)?;
    let (mut fc, mut fd) = (rc.0.contrast, rd.0.contrast);
    keep(rc, &mut samples, &mut best);
    keep(rd, &mut samples, &mut best);
    while b - a > af.tolerance_per_m.max(1e-9 * vmax) {
        if fc > fd {
            b = d;
            d = c;
            fd = fc;
            c = b - g * (b - a);
            let r = eval(c)?;
            fc = r.0.contrast;
            keep(r, &mut samples, &mut best);
        } else {
            a = c;
            c = d;
            fc = fd;
            d = a + g * (b - a);
            let r = eval(d)?;
            fd = r.0.contrast;
            keep(r, &mut samples, &mut best);
        }
    }
    let (best, blur) = best.expect("at least three positions evaluated");
    Ok(Autofocus {
        best,
        samples,
        blur,
    })
}
