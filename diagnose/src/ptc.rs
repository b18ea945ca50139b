//! Photon transfer (EMVA 1288 style): conversion gain from the slope of temporal variance vs
//! mean in the linear range, saturation, full well, linearity error.
use crate::fit::weighted_line;
use crate::stack::moments_by_channel;
use crate::{Ctx, Estimate, Outcome, ShotKind};
use serde::Serialize;

/// One photon-transfer point: one channel of one shot with ≥ 2 frames.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PtcPoint {
    /// Shot id.
    pub shot_id: String,
    /// Channel name.
    pub channel: String,
    /// Exposure (s).
    pub exposure_s: f64,
    /// Analog gain.
    pub analog_gain: f64,
    /// Mean DN of the channel (as recorded).
    pub mean_dn: f64,
    /// Mean above the pedestal divided by the analog gain ("unit-gain DN").
    pub unit_gain_mean: f64,
    /// Its standard error from the temporal noise.
    pub unit_gain_mean_se: f64,
    /// Temporal variance minus 1/12 DN² quantisation, divided by G² (unit-gain DN²).
    pub unit_gain_variance: f64,
    /// Its standard error.
    pub unit_gain_variance_se: f64,
    /// Fraction of the channel's pixel-frames at 0 or the ADC maximum.
    pub clipped_fraction: f64,
    /// Used in the conversion-gain fit.
    pub in_fit: bool,
}

pub(crate) struct PtcOut {
    pub points: Vec<PtcPoint>,
    pub conversion_gain: Outcome<Estimate>,
    pub full_well: Outcome<Estimate>,
    pub saturation_dn: Outcome<Estimate>,
    pub linearity: Outcome<Estimate>,
    /// Unit-gain mean of the saturation point, when saturation was reached.
    pub saturation_unit_dn: Option<f64>,
}

pub(crate) fn photon_transfer(ctx: &Ctx, pedestal: f64) -> PtcOut {
    let mut points = Vec::new();
    let mut point_shot = Vec::new();
    let ex = &ctx.excluded;
    for (i, s) in ctx.shots.iter().enumerate() {
        let st = &ctx.stacks[i];
        let Some(var) = &st.var else { continue };
        let g = s.analog_gain;
        let ch = &ctx.map.channel;
        let nch = ctx.map.n_channels;
        let chan = |p: usize| ch[p] as usize;
        let keep = |p: usize| !ex[p];
        let means = moments_by_channel(ctx.n_pix(), nch, chan, keep, |p| st.mean[p]);
        let vars = moments_by_channel(ctx.n_pix(), nch, chan, keep, |p| var[p]);
        for c in 0..nch {
            let (n, m, _, _) = means[c];
            if n < 2 {
                continue;
            }
            let (_, v, vv, _) = vars[c];
            points.push(PtcPoint {
                shot_id: s.id.clone(),
                channel: ctx
                    .sensor
                    .channel_names
                    .get(c)
                    .cloned()
                    .unwrap_or_else(|| c.to_string()),
                exposure_s: s.exposure_s,
                analog_gain: g,
                mean_dn: m,
                unit_gain_mean: (m - pedestal) / g,
                unit_gain_mean_se: (v / (n * st.n_frames) as f64).sqrt() / g,
                unit_gain_variance: (v - 1.0 / 12.0) / (g * g),
                unit_gain_variance_se: (vv / n as f64).sqrt() / (g * g),
                clipped_fraction: st.clip_lo[c].max(st.clip_hi[c]),
                in_fit: false,
            });
            point_shot.push((i, c));
        }
    }
    let none = |r: &str| PtcOut {
        points: points.clone(),
        conversion_gain: Outcome::not(format!("conversion gain: {r}")),
        full_well: Outcome::not(format!("full well: {r}")),
        saturation_dn: Outcome::not(format!("saturation: {r}")),
        linearity: Outcome::not(format!("linearity: {r}")),
        saturation_unit_dn: None,
    };
    if points.is_empty() {
        return none("needs shots with ≥ 2 frames (temporal variance); the set has none");
    }
    let thr = ctx.opts.max_clipped_fraction;
    // Saturation: the point of largest temporal variance; reached when some brighter point
    // has lost at least half of that variance.
    let sat = (0..points.len())
        .max_by(|&a, &b| {
            points[a]
                .unit_gain_variance
                .total_cmp(&points[b].unit_gain_variance)
        })
        .unwrap();
    let (xs, ys) = (points[sat].unit_gain_mean, points[sat].unit_gain_variance);
    let plateau: Vec<usize> = (0..points.len())
        .filter(|&j| {
            points[j].unit_gain_mean >= 0.98 * xs && points[j].unit_gain_variance < 0.5 * ys
        })
        .collect();
    let reached = !plateau.is_empty();
    for p in points.iter_mut() {
        p.in_fit = p.clipped_fraction <= thr && (!reached || p.unit_gain_mean <= 0.7 * xs);
    }
    let fit_idx: Vec<usize> = (0..points.len()).filter(|&j| points[j].in_fit).collect();
    let x: Vec<f64> = fit_idx.iter().map(|&j| points[j].unit_gain_mean).collect();
    let y: Vec<f64> = fit_idx
        .iter()
        .map(|&j| points[j].unit_gain_variance)
        .collect();
    let se: Vec<f64> = fit_idx
        .iter()
        .map(|&j| points[j].unit_gain_variance_se.max(1e-12))
        .collect();
    let dn_per_v = ctx.sensor.dn_per_output_v();
    let fit = weighted_line(&x, &y, &se).filter(|f| f.slope > 0.0);
    let conversion_gain = match fit {
        Some(f) => Outcome::Estimated(Estimate {
            value: f.slope / dn_per_v,
            std_error: f.slope_se / dn_per_v,
            unit: "V/e-".into(),
            method: format!(
                "EMVA 1288 photon transfer: weighted slope of temporal variance vs mean \
                 (unit-gain DN) over {} shot-channel points below 70 % of saturation and \
                 unclipped, DN/e⁻ converted with swing/(2^bits−1)",
                f.n
            ),
            n_used: f.n,
        }),
        None => Outcome::not(format!(
            "conversion gain: needs unclipped points at ≥ 2 signal levels in the linear range \
             (shots with ≥ 2 frames); the set has {} such point(s)",
            fit_idx.len()
        )),
    };
    let kcam = ctx.sensor.analog_gain;
    let (full_well, saturation_dn) = if !reached {
        let r = format!(
            "the flats do not reach saturation (temporal variance still rising at the \
             brightest point, {:.1} DN)",
            points[sat].mean_dn
        );
        (
            Outcome::not(format!("full well: {r}")),
            Outcome::not(format!("saturation: {r}")),
        )
    } else {
        let below = points
            .iter()
            .map(|p| p.unit_gain_mean)
            .filter(|&m| m < xs)
            .fold(f64::NEG_INFINITY, f64::max);
        let res = if below.is_finite() {
            0.5 * (xs - below)
        } else {
            0.0
        };
        let sat_est = Outcome::Estimated(Estimate {
            value: xs * kcam + pedestal,
            std_error: res * kcam,
            unit: "DN".into(),
            method:
                "EMVA 1288: mean at the largest temporal variance, at the camera's analog gain \
                     (standard error: half the gap to the next darker point)"
                    .into(),
            n_used: points.len(),
        });
        let adc = plateau.iter().any(|&j| {
            let (i, c) = point_shot[j];
            ctx.stacks[i].clip_hi[c] >= 0.5
        });
        let fw = match (&fit, adc) {
            (_, true) => {
                let k1 = fit.map(|f| f.slope);
                Outcome::not(format!(
                    "full well: the output clips at the ADC maximum / voltage swing before the \
                     well fills{}",
                    k1.map(|k| format!("; full well ≥ {:.0} e⁻", xs / k))
                        .unwrap_or_default()
                ))
            }
            (None, false) => Outcome::not("full well: needs the conversion gain"),
            (Some(f), false) => {
                let xp: Vec<f64> = plateau.iter().map(|&j| points[j].unit_gain_mean).collect();
                let m = xp.iter().sum::<f64>() / xp.len() as f64;
                let sd = if xp.len() > 1 {
                    (xp.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (xp.len() - 1) as f64).sqrt()
                } else {
                    0.0
                };
                let w = m / f.slope;
                Outcome::Estimated(Estimate {
                    value: w,
                    std_error: w * ((f.slope_se / f.slope).powi(2) + (sd / m).powi(2)).sqrt(),
                    unit: "e-".into(),
                    method: format!(
                        "plateau of the mean signal ({} saturated shot-channel points without \
                         ADC clipping) divided by the photon-transfer gain (DN/e⁻)",
                        xp.len()
                    ),
                    n_used: xp.len(),
                })
            }
        };
        (fw, sat_est)
    };
    let linearity = linearity(
        ctx,
        &points,
        &point_shot,
        if reached { Some(xs) } else { None },
    );
    PtcOut {
        points,
        conversion_gain,
        full_well,
        saturation_dn,
        linearity,
        saturation_unit_dn: reached.then_some(xs),
    }
}

/// EMVA linearity error: per group of uniform shots of one radiance and per channel, a line
/// of unit-gain mean vs exposure over 5–95 % of the range; half the spread of the relative
/// deviations (%), the largest over groups and channels.
fn linearity(
    ctx: &Ctx,
    points: &[PtcPoint],
    point_shot: &[(usize, usize)],
    sat: Option<f64>,
) -> Outcome<Estimate> {
    let radiance = |i: usize| match &ctx.shots[i].kind {
        ShotKind::Flat { radiance } | ShotKind::Narrowband { radiance } => Some(radiance),
        ShotKind::Dark => None,
    };
    let mut groups: Vec<Vec<usize>> = Vec::new();
    for j in 0..points.len() {
        let (i, c) = point_shot[j];
        let Some(r) = radiance(i) else { continue };
        match groups.iter_mut().find(|g| {
            let (i2, c2) = point_shot[g[0]];
            c2 == c && radiance(i2) == Some(r)
        }) {
            Some(g) => g.push(j),
            None => groups.push(vec![j]),
        }
    }
    let thr = ctx.opts.max_clipped_fraction;
    let mut best: Option<(f64, f64, usize)> = None;
    for g in &groups {
        let range = sat.unwrap_or_else(|| {
            g.iter()
                .filter(|&&j| points[j].clipped_fraction <= thr)
                .map(|&j| points[j].unit_gain_mean)
                .fold(0.0, f64::max)
        });
        let sel: Vec<&PtcPoint> = g
            .iter()
            .map(|&j| &points[j])
            .filter(|p| {
                p.clipped_fraction <= thr
                    && p.unit_gain_mean >= 0.05 * range
                    && p.unit_gain_mean <= 0.95 * range
            })
            .collect();
        let mut ts: Vec<f64> = sel.iter().map(|p| p.exposure_s).collect();
        ts.sort_by(f64::total_cmp);
        ts.dedup();
        if ts.len() < 3 {
            continue;
        }
        let x: Vec<f64> = sel.iter().map(|p| p.exposure_s).collect();
        let y: Vec<f64> = sel.iter().map(|p| p.unit_gain_mean).collect();
        let Some(f) = weighted_line(&x, &y, &vec![1.0; x.len()]) else {
            continue;
        };
        let dev: Vec<f64> = x
            .iter()
            .zip(&y)
            .map(|(t, m)| {
                let l = f.intercept + f.slope * t;
                100.0 * (m - l) / l
            })
            .collect();
        let le = 0.5
            * (dev.iter().copied().fold(f64::NEG_INFINITY, f64::max)
                - dev.iter().copied().fold(f64::INFINITY, f64::min));
        let noise = 100.0
            * (sel
                .iter()
                .map(|p| (p.unit_gain_mean_se / p.unit_gain_mean).powi(2))
                .sum::<f64>()
                / sel.len() as f64)
                .sqrt();
        if best.is_none_or(|b| le > b.0) {
            best = Some((le, noise, sel.len()));
        }
    }
    match best {
        Some((le, noise, n)) => Outcome::Estimated(Estimate {
            value: le,
            std_error: noise,
            unit: "%".into(),
            method:
                "EMVA 1288 linearity error: (max δ − min δ)/2 of relative deviations from a \
                     least-squares line of mean vs exposure, 5–95 % of the range; largest over \
                     radiance groups and channels (standard error: rms relative noise of the means)"
                    .into(),
            n_used: n,
        }),
        None => Outcome::not(
            "linearity: needs uniform shots of one radiance at ≥ 3 exposure times with ≥ 2 \
             frames each, within 5–95 % of the range",
        ),
    }
}
