//! Dark-frame estimators (Appendix A): hot pixels, pedestal and dark voltage, read noise,
//! DSNU.
use crate::fit::{robust_location_scale, weighted_line};
use crate::stack::moments;
use crate::{Ctx, Estimate, HotPixels, Outcome, ShotKind};
use rayon::prelude::*;

/// Indices (into ctx.shots) of the dark shots usable for means and variances, and a note on
/// the ones left out for clipping.
fn usable_darks(ctx: &Ctx) -> Result<(Vec<usize>, String), String> {
    let all: Vec<usize> = (0..ctx.shots.len())
        .filter(|&i| ctx.shots[i].kind == ShotKind::Dark)
        .collect();
    if all.is_empty() {
        return Err("the set has no dark shots".into());
    }
    let thr = ctx.opts.max_clipped_fraction;
    let (ok, clipped): (Vec<usize>, Vec<usize>) = all
        .iter()
        .partition(|&&i| ctx.stacks[i].worst_clip() <= thr);
    let note = if clipped.is_empty() {
        String::new()
    } else {
        format!(
            "; left out for clipping at 0 DN or the ADC maximum (> {:.2} % of pixel-frames): {}",
            100.0 * thr,
            clipped
                .iter()
                .map(|&i| ctx.shots[i].id.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        )
    };
    if ok.is_empty() {
        return Err(format!(
            "every dark shot clips at 0 DN or the ADC maximum (black level too low?){note}"
        ));
    }
    Ok((ok, note))
}

fn distinct_times(ctx: &Ctx, idx: &[usize]) -> usize {
    let mut t: Vec<f64> = idx.iter().map(|&i| ctx.shots[i].exposure_s).collect();
    t.sort_by(f64::total_cmp);
    t.dedup_by(|a, b| (*a - *b).abs() <= 1e-12 * b.abs().max(1e-300));
    t.len()
}

/// Hot pixels from the per-pixel dark current (shortest vs longest usable dark exposure), or
/// from the dark level with a single exposure; marks them in `ctx.excluded`.
pub(crate) fn hot_pixels(ctx: &mut Ctx) -> Outcome<HotPixels> {
    let (idx, _) = match usable_darks(ctx) {
        Ok(v) => v,
        Err(r) => return Outcome::not(format!("hot pixels: {r}")),
    };
    // Shortest and longest exposures, most frames on ties.
    let key = |i: usize| (ctx.shots[i].exposure_s, ctx.stacks[i].n_frames);
    let short = idx
        .iter()
        .copied()
        .min_by(|&a, &b| key(a).0.total_cmp(&key(b).0).then(key(b).1.cmp(&key(a).1)))
        .unwrap();
    let long = idx
        .iter()
        .copied()
        .max_by(|&a, &b| key(a).0.total_cmp(&key(b).0).then(key(a).1.cmp(&key(b).1)))
        .unwrap();
    let (ss, sl) = (ctx.shots[short], ctx.shots[long]);
    let (ks, kl) = (ctx.k(ss), ctx.k(sl));
    let (ms, ml) = (&ctx.stacks[short].mean, &ctx.stacks[long].mean);
    let two = sl.exposure_s > ss.exposure_s;
    let dt = sl.exposure_s - ss.exposure_s;
    let q: Vec<f64> = if two {
        (0..ctx.n_pix())
            .into_par_iter()
            .map(|i| (ml[i] / kl - ms[i] / ks) / dt)
            .collect()
    } else {
        ml.par_iter().map(|m| m / kl).collect()
    };
    let (med, sig) = robust_location_scale(&q);
    // Floor: a quantisation step in the same unit, so a noiseless sensor flags nothing.
    let floor = if two { 1.0 / (kl * dt) } else { 1.0 / kl };
    let threshold = med + ctx.opts.hot_pixel_sigmas * sig.max(floor);
    let cols = ctx.map.cols;
    let mut pixels = Vec::new();
    for (i, &v) in q.iter().enumerate() {
        if v > threshold {
            ctx.excluded[i] = true;
            pixels.push((i / cols, i % cols, v));
        }
    }
    Outcome::Estimated(HotPixels {
        quantity: if two {
            format!("dark current (V/s) from shots {} and {}", ss.id, sl.id)
        } else {
            format!(
                "dark level (V) of shot {} (one dark exposure: offset outliers)",
                sl.id
            )
        },
        median: med,
        robust_sigma: sig,
        threshold,
        pixels,
    })
}

pub(crate) struct DarkFit {
    pub black: Outcome<Estimate>,
    pub dark_voltage: Outcome<Estimate>,
}

/// Mean dark DN of a shot over the non-excluded pixels, with its standard error from the
/// temporal noise (the fixed pattern is common to all shots and cancels in the slope).
fn shot_dark_mean(ctx: &Ctx, i: usize) -> (f64, f64) {
    let st = &ctx.stacks[i];
    let ex = &ctx.excluded;
    let (n, m, var_sp, _) = moments(ctx.n_pix(), |p| !ex[p], |p| st.mean[p]);
    let var_t = match &st.var {
        Some(v) => moments(ctx.n_pix(), |p| !ex[p], |p| v[p]).1,
        // One frame: spatial variance bounds the temporal one (conservative).
        None => var_sp,
    };
    (m, (var_t / (n * st.n_frames) as f64).sqrt().max(1e-9))
}

/// Pedestal (DN) and dark voltage (V/s): weighted least squares of the mean dark DN against
/// `k · t` (so shots at different analog gains share one line).
pub(crate) fn dark_signal(ctx: &Ctx) -> DarkFit {
    let (idx, note) = match usable_darks(ctx) {
        Ok(v) => v,
        Err(r) => {
            return DarkFit {
                black: Outcome::not(format!("black level: {r}")),
                dark_voltage: Outcome::not(format!("dark voltage: {r}")),
            }
        }
    };
    let pts: Vec<(f64, f64, f64)> = idx
        .iter()
        .map(|&i| {
            let (m, se) = shot_dark_mean(ctx, i);
            (ctx.k(ctx.shots[i]) * ctx.shots[i].exposure_s, m, se)
        })
        .collect();
    let x: Vec<f64> = pts.iter().map(|p| p.0).collect();
    let y: Vec<f64> = pts.iter().map(|p| p.1).collect();
    let se: Vec<f64> = pts.iter().map(|p| p.2).collect();
    if distinct_times(ctx, &idx) >= 2 {
        if let Some(f) = weighted_line(&x, &y, &se) {
            return DarkFit {
                black: Outcome::Estimated(Estimate {
                    value: f.intercept,
                    std_error: f.intercept_se,
                    unit: "DN".into(),
                    method: format!(
                        "intercept of weighted least squares of mean dark DN vs k·t over {} dark shots{note}",
                        f.n
                    ),
                    n_used: f.n,
                }),
                dark_voltage: Outcome::Estimated(Estimate {
                    value: f.slope,
                    std_error: f.slope_se,
                    unit: "V/s".into(),
                    method: format!(
                        "slope of weighted least squares of mean dark DN vs k·t (k = G·(2^bits−1)/swing) over {} dark shots{note}",
                        f.n
                    ),
                    n_used: f.n,
                }),
            };
        }
    }
    // One exposure time: the pedestal with the believed dark voltage subtracted.
    let j = (0..pts.len())
        .min_by(|&a, &b| pts[a].0.total_cmp(&pts[b].0))
        .unwrap();
    let vd = ctx.sensor.dark_voltage_v_per_s;
    DarkFit {
        black: Outcome::Estimated(Estimate {
            value: pts[j].1 - vd * pts[j].0,
            std_error: se[j],
            unit: "DN".into(),
            method: format!(
                "mean of dark shot {} minus the believed dark signal ({} V/s · k · t)",
                ctx.shots[idx[j]].id, vd
            ),
            n_used: 1,
        }),
        dark_voltage: Outcome::not(format!(
            "dark voltage: needs dark shots at ≥ 2 exposure times; the set has one ({} s){note}",
            ctx.shots[idx[j]].exposure_s
        )),
    }
}

/// Temporal variance (DN²) of a shot over non-excluded pixels and its standard error.
fn temporal_var(ctx: &Ctx, i: usize) -> Option<(f64, f64, usize)> {
    let v = ctx.stacks[i].var.as_ref()?;
    let ex = &ctx.excluded;
    let (n, m, var, _) = moments(ctx.n_pix(), |p| !ex[p], |p| v[p]);
    Some((m, (var / n as f64).sqrt(), n))
}

/// Read noise (V): per dark shot, read² = (σ²_t − 1/12)/k² − g·Vd·t (quantisation and dark
/// shot noise removed), combined by inverse variance.
pub(crate) fn read_noise(ctx: &Ctx, g: (f64, f64), vd: (f64, f64)) -> Outcome<Estimate> {
    let (idx, note) = match usable_darks(ctx) {
        Ok(v) => v,
        Err(r) => return Outcome::not(format!("read noise: {r}")),
    };
    let mut est = Vec::new();
    let mut small = None;
    for &i in &idx {
        let Some((v, se, _)) = temporal_var(ctx, i) else {
            continue;
        };
        let s = ctx.shots[i];
        if v < 0.25 {
            small = Some((s.id.clone(), v.sqrt()));
            continue;
        }
        let k = ctx.k(s);
        let dark_shot = g.0 * vd.0 * s.exposure_s;
        let dark_shot_var = (s.exposure_s * (g.0 * vd.1).hypot(vd.0 * g.1)).powi(2);
        let r2 = (v - 1.0 / 12.0) / (k * k) - dark_shot;
        let var_r2 = (se / (k * k)).powi(2) + dark_shot_var;
        est.push((r2, var_r2));
    }
    if est.is_empty() {
        return Outcome::not(match small {
            Some((id, sd)) => format!(
                "read noise: temporal dark noise of shot {id} is {sd:.2} DN, below half a \
                 quantisation step; only an upper limit is possible (raise the analog gain)"
            ),
            None => format!("read noise: needs a dark shot with ≥ 2 frames{note}"),
        });
    }
    let w: f64 = est.iter().map(|e| 1.0 / e.1).sum();
    let r2 = est.iter().map(|e| e.0 / e.1).sum::<f64>() / w;
    let se_r2 = (1.0 / w).sqrt();
    if r2 <= 0.0 {
        return Outcome::not(format!(
            "read noise: temporal dark variance is explained by quantisation and dark shot \
             noise (read² = {r2:.3e} ± {se_r2:.1e} V²)"
        ));
    }
    let r = r2.sqrt();
    Outcome::Estimated(Estimate {
        value: r,
        std_error: se_r2 / (2.0 * r),
        unit: "V".into(),
        method: format!(
            "temporal variance of repeated darks (per-pixel variance over frames, = var(a−b)/2 \
             for two frames), minus 1/12 DN² quantisation and g·Vd·t dark shot noise, \
             inverse-variance mean of {} shots{note}",
            est.len()
        ),
        n_used: est.len(),
    })
}

/// DSNU (V): spatial variance of the frame-averaged dark minus the temporal part
/// σ²_t / N, from the dark shot with the most frames (shortest exposure on ties). Also adds
/// the DSNU-mean uncertainty to the pedestal's standard error.
pub(crate) fn dsnu(ctx: &Ctx, black: Outcome<Estimate>) -> (Outcome<Estimate>, Outcome<Estimate>) {
    let (idx, note) = match usable_darks(ctx) {
        Ok(v) => v,
        Err(r) => return (Outcome::not(format!("DSNU: {r}")), black),
    };
    let best = idx
        .iter()
        .copied()
        .filter(|&i| ctx.stacks[i].n_frames >= 2)
        .max_by(|&a, &b| {
            ctx.stacks[a]
                .n_frames
                .cmp(&ctx.stacks[b].n_frames)
                .then(ctx.shots[b].exposure_s.total_cmp(&ctx.shots[a].exposure_s))
        });
    let Some(i) = best else {
        return (
            Outcome::not(format!(
                "DSNU: needs a dark shot with ≥ 2 frames to separate the temporal noise{note}"
            )),
            black,
        );
    };
    let st = &ctx.stacks[i];
    let ex = &ctx.excluded;
    let (n, _, var_m, m4) = moments(ctx.n_pix(), |p| !ex[p], |p| st.mean[p]);
    let (vt, se_vt, _) = temporal_var(ctx, i).unwrap();
    let nf = st.n_frames as f64;
    let fixed = var_m - vt / nf;
    let se_fixed = ((m4 - var_m * var_m).max(0.0) / n as f64 + (se_vt / nf).powi(2)).sqrt();
    let k = ctx.k(ctx.shots[i]);
    let black = match black {
        Outcome::Estimated(mut e) => {
            // The intercept holds the realised mean of the DSNU pattern: add its spread.
            let kc = ctx.sensor.analog_gain * ctx.sensor.dn_per_output_v();
            let fixed_cam = fixed.max(0.0) * (kc / k).powi(2);
            e.std_error = (e.std_error.powi(2) + fixed_cam / n as f64).sqrt();
            Outcome::Estimated(e)
        }
        o => o,
    };
    if fixed <= 0.0 {
        return (
            Outcome::not(format!(
                "DSNU: the fixed dark pattern is below the temporal noise floor \
                 (σ²_fixed = {fixed:.3e} ± {se_fixed:.1e} DN² in shot {})",
                ctx.shots[i].id
            )),
            black,
        );
    }
    let sd = fixed.sqrt();
    (
        Outcome::Estimated(Estimate {
            value: sd / k,
            std_error: se_fixed / (2.0 * sd) / k,
            unit: "V".into(),
            method: format!(
                "var(frame-averaged dark) − σ²_temporal/N over {n} pixels of shot {} ({} frames){note}",
                ctx.shots[i].id, st.n_frames
            ),
            n_used: n,
        }),
        black,
    )
}
