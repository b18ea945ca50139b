//! # Mismatch diagnosis (`camsim diagnose`)
//!
//! Given a recording reduced to per-pixel statistics ([`DataSet`]), the camera as believed
//! ([`ModelState`]) and the forward model's photo-electron rates ([`Forward`]), find the
//! physics the model left out:
//!
//! 1. **fit check** — χ²/dof of every frame against the model's per-pixel mean and variance
//!    (temporal and fixed pattern separated with repeated frames; clipping as censoring);
//! 2. **locate** — the residuals by shot and channel, signal level, exposure, field height,
//!    rows and columns, spatial frequency, temporal vs fixed ([`Located`]);
//! 3. **candidates** — a model with fit parameters for every effect id of effects.md;
//! 4. **fit and select** — ML fit of each, greedy acceptance by BIC, joint refit, until
//!    nothing improves significantly; alike effects the set cannot separate are reported as
//!    undecided;
//! 5. **explain** — per finding, where it shows, what physics, its magnitude, fit before and
//!    after; the fitted [`ModelState`] for fitted_camera.json.
mod candidates;
pub mod data;
pub mod effects;
pub mod identify;
mod like;
pub mod locate;
mod memo;
pub mod model;
pub mod num;
mod select;

pub use candidates::magnitude;
pub use data::{DataSet, ShotAccumulator, ShotData, TargetClass};
pub use effects::{alike, AlikePair, Effect, ALIKE};
pub use identify::{Identifiability, MAX_VARIANCE_INFLATION};
pub use like::{prof, Eval, ScStat};
pub use locate::{EdgeMtf, Located, ShotChannel, ShotMaps, ShotProfiles};
pub use model::{Forward, ModelState, RateSpec};
pub use select::{CandidateRow, Finding, SelectOptions, Selection, Undecided};

use like::Ctx;

/// Settings of a diagnosis.
#[derive(Debug, Clone)]
pub struct DiagnoseOptions {
    /// Selection settings.
    pub select: SelectOptions,
    /// Largest number of pixels used while fitting (larger sensors fit on evenly spread
    /// rows; the reported fit always uses every pixel).
    pub max_fit_pixels: usize,
    /// Residual maps for at most this many shots (those with the worst fit before).
    pub max_maps: usize,
}

impl Default for DiagnoseOptions {
    fn default() -> Self {
        DiagnoseOptions {
            select: SelectOptions::default(),
            // 32768 pixels × every shot: per-parameter statistical error far below the
            // effects' sizes, and 4× less work per likelihood than 2^17 on a 1 MP set
            // (docs/benchmarks/diagnose.md).
            max_fit_pixels: 1 << 15,
            max_maps: 4,
        }
    }
}

/// A reported finding with its words.
#[derive(Debug, Clone)]
pub struct FindingReport {
    /// The effect.
    pub effect: Effect,
    /// Magnitude in the final model (effects.md units).
    pub magnitude: f64,
    /// Where it shows.
    pub where_: String,
    /// What physics, how large.
    pub explanation: String,
    /// ΔBIC at acceptance.
    pub delta_bic: f64,
    /// Δ log-likelihood at acceptance.
    pub delta_logl: f64,
    /// Parameters.
    pub k: usize,
    /// χ²/dof after it was accepted.
    pub chi2_after: f64,
    /// χ²/dof before it was accepted.
    pub chi2_before: f64,
    /// The best other candidates of its round (effect, ΔBIC).
    pub alternatives: Vec<(Effect, f64)>,
}

/// The outcome of a diagnosis.
#[derive(Debug, Clone)]
pub struct Diagnosis {
    /// The believed model.
    pub believed: ModelState,
    /// The fitted model.
    pub fitted: ModelState,
    /// Locate, believed model.
    pub before: Located,
    /// Locate, fitted model.
    pub after: Located,
    /// Degrees of freedom of the final fit (data terms − fitted parameters).
    pub dof_after: f64,
    /// The selection.
    pub selection: Selection,
    /// Reported findings.
    pub findings: Vec<FindingReport>,
    /// Residual maps (shot index, before, after).
    pub maps: Vec<(usize, ShotMaps, ShotMaps)>,
    /// Pixels used while fitting.
    pub fit_pixels: usize,
    /// Sensor rows used while fitting, ascending (every row when the fits are not
    /// subsampled).
    pub fit_rows: Vec<usize>,
    /// The ΔBIC acceptance threshold used.
    pub bic_threshold: f64,
    /// Wall time per stage of this diagnosis (not deterministic: kept out of report.json).
    pub timing: Vec<StageTime>,
}

/// Wall time of one stage of a diagnosis.
#[derive(Debug, Clone, PartialEq)]
pub struct StageTime {
    /// The stage.
    pub stage: String,
    /// Seconds.
    pub seconds: f64,
    /// Calls (likelihood evaluations, forward-model runs), where counted.
    pub calls: Option<u64>,
}

/// Runs the diagnosis.
pub fn diagnose(
    data: &DataSet,
    forward: &dyn Forward,
    believed: &ModelState,
    opts: &DiagnoseOptions,
    progress: &(dyn Fn(&str) + Sync),
) -> Result<Diagnosis, String> {
    if data.shots.is_empty() {
        return Err("the capture set has no usable shots".into());
    }
    let prof0 = prof::snapshot();
    let mut timing: Vec<StageTime> = Vec::new();
    let mut clock = std::time::Instant::now();
    let mut lap = |stage: &str, timing: &mut Vec<StageTime>| {
        timing.push(StageTime {
            stage: stage.to_string(),
            seconds: clock.elapsed().as_secs_f64(),
            calls: None,
        });
        clock = std::time::Instant::now();
    };
    let ctx = Ctx::new(data, forward, opts.max_fit_pixels);
    lap("set-up (fit rows, outlier mask)", &mut timing);
    progress("fit check (believed camera)");
    // The believed camera's rates on every pixel, held for the residual maps: the rate cache
    // is least-recently-used, and at 12 MP the fits' entries evict these long before the maps
    // are drawn (a second whole-sensor forward run: renders and optics of every target).
    let rb = ctx.rates(believed)?;
    let (before, ev_before) = ctx.locate(believed)?;
    lap("fit check and locate, believed camera", &mut timing);
    let selection = select::select(&ctx, believed, &opts.select, progress)?;
    lap(
        "candidates: identifiability, fits and selection",
        &mut timing,
    );
    progress("fit check (fitted camera)");
    let (after, _) = ctx.locate(&selection.state)?;
    lap("fit check and locate, fitted camera", &mut timing);
    let k_total: usize = selection.findings.iter().map(|f| f.k).sum();
    let mut findings = Vec::new();
    let mut prev = ev_before.clone();
    for f in &selection.findings {
        if !f.undecided {
            findings.push(report_finding(&ctx, f, &prev, believed, &selection.state));
        }
        prev = f.after.clone();
    }
    // residual maps of the worst shots before
    let mut worst: Vec<(f64, usize)> = (0..data.shots.len())
        .map(|s| {
            let (c, d) = before
                .shot_channels
                .iter()
                .filter(|x| x.shot == s)
                .fold((0.0, 0.0), |a, x| {
                    (a.0 + x.chi2_per_dof * x.dof, a.1 + x.dof)
                });
            (c / d.max(1.0), s)
        })
        .collect();
    worst.sort_by(|a, b| b.0.total_cmp(&a.0));
    let ra = ctx.rates(&selection.state)?;
    let maps = worst
        .iter()
        .take(opts.max_maps)
        .map(|&(_, s)| {
            (
                s,
                ctx.shot_maps(believed, &rb, s),
                ctx.shot_maps(&selection.state, &ra, s),
            )
        })
        .collect();
    lap("residual maps", &mut timing);
    timing.extend(prof::since(&prof0));
    Ok(Diagnosis {
        believed: believed.clone(),
        fitted: selection.state.clone(),
        dof_after: after.dof - k_total as f64,
        before,
        after,
        selection,
        findings,
        maps,
        fit_pixels: ctx.fit_rows.len() * data.cols,
        fit_rows: ctx.fit_rows.clone(),
        bic_threshold: opts.select.bic_threshold,
        timing,
    })
}

fn report_finding(
    ctx: &Ctx,
    f: &Finding,
    prev: &Eval,
    believed: &ModelState,
    final_state: &ModelState,
) -> FindingReport {
    let d = ctx.data;
    let nch = d.channels();
    let mag = magnitude(f.effect, final_state, believed);
    // where: the (shot, channel)s whose χ² dropped most
    let mut gains: Vec<(f64, usize, usize)> = Vec::new();
    for s in 0..d.shots.len() {
        for c in 0..nch {
            let i = s * nch + c;
            let g = prev.per_sc[i].chi2 - f.after.per_sc[i].chi2;
            gains.push((g, s, c));
        }
    }
    let total: f64 = gains.iter().map(|g| g.0.max(0.0)).sum();
    gains.sort_by(|a, b| b.0.total_cmp(&a.0));
    let mut shots: Vec<usize> = Vec::new();
    let mut chans: Vec<usize> = Vec::new();
    let mut acc = 0.0;
    for &(g, s, c) in &gains {
        if g <= 0.0 || acc > 0.8 * total {
            break;
        }
        acc += g;
        if !shots.contains(&s) {
            shots.push(s);
        }
        if !chans.contains(&c) {
            chans.push(c);
        }
    }
    let shot_txt = if shots.is_empty() {
        "no shot in particular".to_string()
    } else if shots.len() == d.shots.len() && d.shots.len() > 2 {
        "every shot".to_string()
    } else {
        let names: Vec<&str> = shots
            .iter()
            .take(6)
            .map(|&s| d.shots[s].id.as_str())
            .collect();
        let more = if shots.len() > 6 {
            format!(" and {} more", shots.len() - 6)
        } else {
            String::new()
        };
        format!("shots {}{more}", names.join(", "))
    };
    let chan_txt = if chans.len() == nch || chans.is_empty() {
        "all channels".to_string()
    } else {
        let mut c = chans.clone();
        c.sort();
        format!(
            "channel{} {}",
            if c.len() > 1 { "s" } else { "" },
            c.iter()
                .map(|&i| d.channel_names[i].as_str())
                .collect::<Vec<_>>()
                .join(", ")
        )
    };
    let st = final_state;
    let b = &believed.sensor;
    let s = &st.sensor;
    let pct = |x: f64| format!("{:.1}%", 100.0 * x);
    let (pattern, expl) = match f.effect {
        Effect::ExposureScale => (
            "in proportion to the signal".to_string(),
            format!(
                "the photo-signal is {:.4}× the model's ({} {} light reaches the sensor)",
                mag,
                pct((mag - 1.0).abs()),
                if mag > 1.0 { "more" } else { "less" }
            ),
        ),
        Effect::ConversionGain => (
            "in the signal and in the photon-transfer slope (temporal variance against mean)".into(),
            format!(
                "conversion gain is {:.4}× the model's: {:.4e} V/e- instead of {:.4e}",
                mag, s.conversion_gain_v_per_e, b.conversion_gain_v_per_e
            ),
        ),
        Effect::BlackLevel => (
            "as the same offset in every pixel and shot".into(),
            format!(
                "the pedestal is {:+.3} DN off: {:.3} DN instead of {:.3}",
                mag, s.black_level_dn, b.black_level_dn
            ),
        ),
        Effect::DarkCurrent => (
            "as an offset that grows with exposure time".into(),
            format!(
                "dark voltage is {:.4e} V/s instead of {:.4e}",
                mag, b.dark_voltage_v_per_s
            ),
        ),
        Effect::ReadNoise => (
            "in the frame-to-frame noise floor, also in the dark".into(),
            format!("read noise σ is {:.4e} V instead of {:.4e}", mag, b.read_noise_v),
        ),
        Effect::Dsnu => (
            "as fixed per-pixel offsets, the same in every shot and in the dark".into(),
            format!("DSNU σ is {:.4e} V instead of {:.4e}", mag, b.dsnu_sigma_v),
        ),
        Effect::Prnu => (
            "as fixed per-pixel deviations in proportion to the signal".into(),
            format!(
                "PRNU σ is {:.4}% instead of {:.4}%",
                mag, b.prnu_sigma_percent
            ),
        ),
        Effect::ColumnFpn => (
            "as offsets shared by whole columns, the same in every shot".into(),
            format!(
                "column offsets have σ = {:.4e} V (model: {:.4e})",
                mag,
                b.column_fpn.map_or(0.0, |c| c.offset_sigma_v)
            ),
        ),
        Effect::HotPixels => {
            let h = s.effects.hot_pixels;
            (
                format!(
                    "in about {} isolated pixels whose excess grows with exposure",
                    (mag * d.pixels() as f64).round()
                ),
                format!(
                    "{} of the pixels are hot, with an extra dark voltage of about {:.3e} V/s (log-spread {:.2})",
                    pct(mag),
                    h.map_or(0.0, |h| h.dark_voltage_v_per_s),
                    h.map_or(0.0, |h| h.log_sigma)
                ),
            )
        }
        Effect::Nonlinearity => (
            "in the brightest pixels: the response bends below the line".into(),
            format!(
                "at the exposure where the low-signal line reaches 80% of full scale the signal is {} below it",
                pct(mag)
            ),
        ),
        Effect::FullWell => (
            "where pixels saturate".into(),
            format!(
                "pixels saturate at {:.0} e- instead of {:.0}",
                mag, b.well_capacity_e
            ),
        ),
        Effect::RelativeIllumination => (
            "growing with field height towards the corners".into(),
            format!(
                "irradiance at the corners (h = 1) is {} {} the model's relative illumination",
                pct(mag.abs()),
                if mag > 0.0 { "below" } else { "above" }
            ),
        ),
        Effect::VeilingGlare => (
            "as light added evenly, most visible in dark regions".into(),
            format!(
                "stray light adds {} of the mean image irradiance everywhere",
                pct(mag)
            ),
        ),
        Effect::Defocus => (
            "at edges and fine detail (lower MTF)".into(),
            format!("extra blur equivalent to a Gaussian of σ = {mag:.3} µm"),
        ),
        Effect::Crosstalk => (
            "in the balance between neighbouring channels and along the array border".into(),
            format!(
                "{} of each pixel's photo-signal is collected by its 4 neighbours",
                pct(mag)
            ),
        ),
        Effect::IrLeakage => (
            "in shots with light beyond 700 nm".into(),
            format!("the channels collect up to {mag:.4} electrons/photon more over 700–1000 nm"),
        ),
        Effect::QeShift => (
            "in the balance of the channels across illuminants".into(),
            format!(
                "a channel's QE curve sits {:+.2} nm {} the model's",
                mag,
                if mag > 0.0 { "to the red of" } else { "to the blue of" }
            ),
        ),
        Effect::Distortion => (
            "in the positions of structure, growing towards the corners".into(),
            format!(
                "points at h = 1 land {} of the half-diagonal {} ({})",
                pct(mag.abs()),
                if mag > 0.0 { "outwards" } else { "inwards" },
                if mag > 0.0 { "pincushion" } else { "barrel" }
            ),
        ),
        Effect::LateralColor => (
            "as colour fringes at structure, growing towards the corners".into(),
            format!("the 650 nm image sits {mag:+.3} µm from the 450 nm image at h = 1"),
        ),
        Effect::RowNoise => (
            "as offsets shared by whole rows, new in every frame".into(),
            format!(
                "row noise σ is {:.4e} V (model: {:.4e})",
                mag,
                b.effects.row_noise.map_or(0.0, |r| r.sigma_v)
            ),
        ),
        Effect::Rtn => {
            let r = s.effects.rtn;
            (
                format!(
                    "in about {} pixels whose level jumps between two values from frame to frame",
                    (mag * d.pixels() as f64).round()
                ),
                format!(
                    "{} of the pixels show random telegraph noise with a step of about {:.3e} V",
                    pct(mag),
                    r.map_or(0.0, |r| r.amplitude_v)
                ),
            )
        }
        Effect::BlackLevelDrift => (
            "as frame means that move with the frame order".into(),
            format!(
                "the pedestal drifts by {:+.4} DN per frame, {:+.3} DN over the {} frames of the set",
                s.effects.black_level_drift.map_or(0.0, |x| x.dn_per_frame),
                mag,
                st.frames_in_set
            ),
        ),
        Effect::DarkTemperature => (
            "in darks taken at different sensor temperatures".into(),
            format!(
                "the dark current doubles every {:.2} °C (reference {:.1} °C)",
                mag,
                s.effects
                    .dark_temperature
                    .map_or(f64::NAN, |x| x.reference_temperature_c)
            ),
        ),
    };
    let chi2_after = f.after.chi2 / f.after.dof.max(1.0);
    let chi2_before = prev.chi2 / prev.dof.max(1.0);
    FindingReport {
        effect: f.effect,
        magnitude: mag,
        where_: format!("{shot_txt} ({chan_txt}); {pattern}"),
        explanation: format!("{}: {}", f.effect.physics(), expl),
        delta_bic: f.delta_bic,
        delta_logl: f.delta_logl,
        k: f.k,
        chi2_after,
        chi2_before,
        alternatives: f.alternatives.clone(),
    }
}

/// Evaluates the fit of a model (all pixels) — the "fit check" alone.
pub fn fit_check(
    data: &DataSet,
    forward: &dyn Forward,
    state: &ModelState,
) -> Result<Located, String> {
    let ctx = Ctx::new(data, forward, usize::MAX);
    Ok(ctx.locate(state)?.0)
}
