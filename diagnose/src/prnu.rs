//! PRNU (Appendix A): per-pixel slopes of flat-field signal vs exposure, per channel, with
//! the temporal-noise contribution to the slope scatter removed.
//!
//! Per pixel i, `y_fi = (DN_fi − P)/k_f` (pixel volts) over every frame f of one radiance
//! group, fitted by ordinary least squares `y = a_i t + b_i` (the offset absorbs DSNU).
//! The naive estimate is `sd(a_i / ā)` (ISETCam's). Its scatter holds the temporal noise of
//! the slope, `Σ_f (t_f − t̄)² σ²_f / Stt²`; σ²_f is modelled as `c0 + c1 t_f` and fitted to the
//! pixel-averaged squared residuals through `E[r_f²] = Σ_g ((I − H)_fg)² σ²_g` (H the hat
//! matrix of the line fit), which works with one frame per exposure. Smooth illumination
//! fall-off is removed by a 2-D polynomial fit of the slope map; dark current, which adds
//! `Vd` to every slope, is removed from the denominator.
use crate::fit::poly_surface;
use crate::stack::moments;
use crate::{Ctx, Estimate, Outcome, ShotKind};
use nalgebra::DMatrix;
use rayon::prelude::*;
use serde::Serialize;

/// PRNU of one channel.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PrnuChannel {
    /// Channel name.
    pub channel: String,
    /// Pixels used.
    pub pixels: usize,
    /// Naive estimate: 100 · sd of the normalised slopes (%), temporal noise included.
    pub naive_percent: f64,
    /// Temporal-noise part of the naive variance, as a standard deviation (%).
    pub noise_percent: f64,
    /// Corrected estimate (%); NaN when the noise explains all the scatter.
    pub corrected_percent: f64,
    /// Corrected variance (%², may be negative when noise dominates).
    pub corrected_variance: f64,
    /// Standard error of the corrected variance (%²).
    pub corrected_variance_se: f64,
}

pub(crate) fn prnu(
    ctx: &Ctx,
    pedestal: f64,
    vd: f64,
    sat_unit: Option<f64>,
) -> (Outcome<Estimate>, Vec<PrnuChannel>) {
    let thr = ctx.opts.max_clipped_fraction;
    let n_pix = ctx.n_pix();
    let ch = &ctx.map.channel;
    let ex = &ctx.excluded;
    let nch = ctx.map.n_channels;
    // Usable flats: unclipped and (when saturation is known) below 70 % of it.
    let mut left_out = Vec::new();
    let mut usable = Vec::new();
    for (i, s) in ctx.shots.iter().enumerate() {
        let ShotKind::Flat { radiance } = &s.kind else {
            continue;
        };
        let st = &ctx.stacks[i];
        let mut ok = st.worst_clip() <= thr;
        if ok {
            if let Some(xs) = sat_unit {
                for c in 0..nch {
                    let (n, m, _, _) =
                        moments(n_pix, |p| ch[p] as usize == c && !ex[p], |p| st.mean[p]);
                    if n > 0 && (m - pedestal) / s.analog_gain > 0.7 * xs {
                        ok = false;
                    }
                }
            }
        }
        if ok {
            usable.push((i, radiance));
        } else {
            left_out.push(s.id.as_str());
        }
    }
    let note = if left_out.is_empty() {
        String::new()
    } else {
        format!(
            "; flats left out as clipped or near saturation: {}",
            left_out.join(", ")
        )
    };
    // Radiance groups with ≥ 2 exposure times; the one with the most frames.
    let mut groups: Vec<Vec<usize>> = Vec::new();
    for &(i, r) in &usable {
        match groups
            .iter_mut()
            .find(|g| usable.iter().any(|&(j, r2)| j == g[0] && r2 == r))
        {
            Some(g) => g.push(i),
            None => groups.push(vec![i]),
        }
    }
    let n_times = |g: &Vec<usize>| {
        let mut t: Vec<f64> = g.iter().map(|&i| ctx.shots[i].exposure_s).collect();
        t.sort_by(f64::total_cmp);
        t.dedup();
        t.len()
    };
    let frames_of = |g: &Vec<usize>| g.iter().map(|&i| ctx.stacks[i].n_frames).sum::<usize>();
    let Some(group) = groups
        .iter()
        .filter(|g| n_times(g) >= 2 && frames_of(g) >= 3)
        .max_by_key(|g| frames_of(g))
    else {
        return (
            Outcome::not(format!(
                "PRNU: needs unclipped uniform flats of one radiance at ≥ 2 exposure times \
                 (≥ 3 frames in all); the set has {} usable flat shot(s) at {} exposure time(s){note}",
                usable.len(),
                groups.iter().map(n_times).max().unwrap_or(0)
            )),
            vec![],
        );
    };
    // Frames: (t, k, shot index).
    let mut fr: Vec<(f64, f64, usize, usize)> = Vec::new();
    for &i in group {
        let s = ctx.shots[i];
        for j in 0..s.frames.len() {
            fr.push((s.exposure_s, ctx.k(s), i, j));
        }
    }
    let nf = fr.len();
    let tbar = fr.iter().map(|f| f.0).sum::<f64>() / nf as f64;
    let stt: f64 = fr.iter().map(|f| (f.0 - tbar).powi(2)).sum();
    // Per-pixel slope and intercept from the shot means.
    let mut a = vec![0f64; n_pix];
    let mut b = vec![0f64; n_pix];
    a.par_iter_mut()
        .zip(b.par_iter_mut())
        .enumerate()
        .for_each(|(p, (ap, bp))| {
            let (mut sty, mut sy) = (0.0, 0.0);
            for &i in group {
                let s = ctx.shots[i];
                let n = ctx.stacks[i].n_frames as f64;
                let y = (ctx.stacks[i].mean[p] - pedestal) / ctx.k(s);
                sty += n * (s.exposure_s - tbar) * y;
                sy += n * y;
            }
            *ap = sty / stt;
            *bp = sy / nf as f64 - *ap * tbar;
        });
    // Pixel-averaged squared residual per frame and channel.
    let mut r2 = vec![vec![0f64; nf]; nch];
    let mut cnt = vec![0usize; nch];
    for p in 0..n_pix {
        if !ex[p] {
            cnt[ch[p] as usize] += 1;
        }
    }
    for (f, &(t, k, i, j)) in fr.iter().enumerate() {
        let dn = &ctx.shots[i].frames[j].dn;
        // Fixed chunks summed in order: the same bits at any thread count.
        const CHUNK: usize = 4096;
        let sums = (0..n_pix.div_ceil(CHUNK))
            .into_par_iter()
            .map(|q| {
                let mut acc = vec![0f64; nch];
                for p in q * CHUNK..((q + 1) * CHUNK).min(n_pix) {
                    if !ex[p] {
                        let r = (dn[p] as f64 - pedestal) / k - a[p] * t - b[p];
                        acc[ch[p] as usize] += r * r;
                    }
                }
                acc
            })
            .collect::<Vec<_>>()
            .into_iter()
            .fold(vec![0f64; nch], |mut x, y| {
                x.iter_mut().zip(y).for_each(|(u, v)| *u += v);
                x
            });
        for c in 0..nch {
            r2[c][f] = sums[c] / cnt[c].max(1) as f64;
        }
    }
    // E[r_f²] = Σ_g M_fg (c0 + c1 t_g), M = (I − H)∘(I − H).
    let x = DMatrix::from_fn(nf, 2, |r, c| if c == 0 { 1.0 } else { fr[r].0 });
    let xtx_inv = (x.transpose() * &x)
        .try_inverse()
        .expect("two distinct times");
    let h = &x * xtx_inv * x.transpose();
    let m = DMatrix::from_fn(nf, nf, |r, c| {
        let v = if r == c { 1.0 } else { 0.0 } - h[(r, c)];
        v * v
    });
    let u: Vec<f64> = (0..nf).map(|r| m.row(r).sum()).collect();
    let v: Vec<f64> = (0..nf)
        .map(|r| (0..nf).map(|c| m[(r, c)] * fr[c].0).sum())
        .collect();
    let cols = ctx.map.cols;
    let mut out = Vec::new();
    for c in 0..nch {
        let idx: Vec<usize> = (0..n_pix)
            .filter(|&p| ch[p] as usize == c && !ex[p])
            .collect();
        if idx.len() < 16 {
            continue;
        }
        // Noise model fit (2×2 normal equations; c1 dropped when not identifiable).
        let (suu, suv, svv) = (
            u.iter().map(|x| x * x).sum::<f64>(),
            u.iter().zip(&v).map(|(x, y)| x * y).sum::<f64>(),
            v.iter().map(|x| x * x).sum::<f64>(),
        );
        let (sur, svr) = (
            u.iter().zip(&r2[c]).map(|(x, y)| x * y).sum::<f64>(),
            v.iter().zip(&r2[c]).map(|(x, y)| x * y).sum::<f64>(),
        );
        let det = suu * svv - suv * suv;
        let (c0, c1) = if det > 1e-9 * suu * svv {
            ((svv * sur - suv * svr) / det, (suu * svr - suv * sur) / det)
        } else if suu > 0.0 {
            (sur / suu, 0.0)
        } else {
            continue;
        };
        let var_noise: f64 = fr
            .iter()
            .map(|f| (f.0 - tbar).powi(2) * (c0 + c1 * f.0).max(0.0))
            .sum::<f64>()
            / (stt * stt);
        // Shading: polynomial surface of the slope map (degree 0 = channel mean).
        let pos: Vec<(usize, usize)> = idx.iter().map(|&p| (p / cols, p % cols)).collect();
        let av: Vec<f64> = idx.iter().map(|&p| a[p]).collect();
        let (sm, nt) = poly_surface(&pos, &av, ctx.map.rows, cols, ctx.opts.shading_degree);
        let z: Vec<f64> = av.iter().zip(&sm).map(|(x, s)| x / s).collect();
        let n = z.len();
        let (_, _, var_z1, m4) = moments(n, |_| true, |k| z[k]);
        let var_z = var_z1 * (n - 1) as f64 / (n - nt).max(1) as f64;
        let inv_f2 = sm.iter().map(|s| 1.0 / (s * s)).sum::<f64>() / n as f64;
        let noise_z = var_noise * inv_f2;
        let fbar = sm.iter().sum::<f64>() / n as f64;
        let rho = if fbar > vd { fbar / (fbar - vd) } else { 1.0 };
        let var_p = (var_z - noise_z) * rho * rho;
        let se = rho
            * rho
            * ((m4 - var_z * var_z).max(0.0) / n as f64
                + (noise_z * (2.0 / (n as f64 * (nf as f64 - 2.0).max(1.0))).sqrt()).powi(2))
            .sqrt();
        out.push(PrnuChannel {
            channel: ctx
                .sensor
                .channel_names
                .get(c)
                .cloned()
                .unwrap_or_else(|| c.to_string()),
            pixels: n,
            naive_percent: 100.0 * var_z.sqrt(),
            noise_percent: 100.0 * noise_z.sqrt(),
            corrected_percent: if var_p > 0.0 {
                100.0 * var_p.sqrt()
            } else {
                f64::NAN
            },
            corrected_variance: 1e4 * var_p,
            corrected_variance_se: 1e4 * se,
        });
    }
    if out.is_empty() {
        return (
            Outcome::not("PRNU: no channel has enough pixels".to_string()),
            out,
        );
    }
    let ntot: usize = out.iter().map(|c| c.pixels).sum();
    let mut var = 0.0;
    let mut se2 = 0.0;
    for c in &out {
        let w = c.pixels as f64 / ntot as f64;
        var += w * c.corrected_variance;
        se2 += (w * c.corrected_variance_se).powi(2);
    }
    let se = se2.sqrt();
    let est = if var > 0.0 {
        let v = var.sqrt();
        Outcome::Estimated(Estimate {
            value: v,
            std_error: if var > se { se / (2.0 * v) } else { se.sqrt() },
            unit: "%".into(),
            method: format!(
                "per-pixel slopes of flat signal vs exposure ({} frames at {} exposure times), \
                 divided by a degree-{} polynomial shading surface per channel, dark voltage \
                 removed; variance minus the temporal-noise variance of the slopes \
                 (σ² = c0 + c1·t fitted to the residuals), pooled over channels{note}",
                nf,
                n_times(group),
                ctx.opts.shading_degree
            ),
            n_used: ntot,
        })
    } else {
        Outcome::not(format!(
            "PRNU: the slope scatter is explained by temporal noise (PRNU² = {var:.3e} ± {se:.1e} %²); \
             use more frames or brighter flats{note}"
        ))
    };
    (est, out)
}
