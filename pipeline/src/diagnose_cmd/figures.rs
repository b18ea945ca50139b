//! Figures and the HTML page of `camsim diagnose`.
use crate::error::CliError;
use crate::plots;
use crate::report::html_escape;
use camsim_diagnose::mismatch::{DataSet, Diagnosis, Located, ShotMaps};
use serde_json::Value;
use std::path::Path;

/// A written figure.
#[derive(Debug, Clone)]
pub struct Figure {
    /// File name (beside report.html).
    pub file: String,
    /// Caption.
    pub caption: String,
    /// Section of the report.
    pub section: &'static str,
}

/// Normalised residuals binned to at most 512 pixels a side (block sum / √n keeps unit
/// variance), drawn blue (model too bright) – white – red (model too dark), ±4 σ.
fn residual_png(path: &Path, z: &[f32], rows: usize, cols: usize) -> Result<(), CliError> {
    let b = rows.max(cols).div_ceil(512).max(1);
    let (r2, c2) = (rows.div_ceil(b), cols.div_ceil(b));
    let mut sum = vec![0f64; r2 * c2];
    let mut n = vec![0f64; r2 * c2];
    for r in 0..rows {
        for c in 0..cols {
            let v = z[r * cols + c] as f64;
            if v.is_finite() {
                let k = (r / b) * c2 + c / b;
                sum[k] += v;
                n[k] += 1.0;
            }
        }
    }
    let v: Vec<f64> = sum
        .iter()
        .zip(&n)
        .map(|(s, n)| if *n > 0.0 { s / n.sqrt() } else { 0.0 })
        .collect();
    // small sensors: enlarge so the map is visible
    let up = (256 / r2.max(c2)).clamp(1, 8);
    let (r3, c3) = (r2 * up, c2 * up);
    let mut rgb = Vec::with_capacity(r3 * c3 * 3);
    for r in 0..r3 {
        for c in 0..c3 {
            let x = (v[(r / up) * c2 + c / up] / 4.0).clamp(-1.0, 1.0);
            let k = (255.0 * (1.0 - x.abs())).round() as u8;
            if x < 0.0 {
                rgb.extend_from_slice(&[k, k, 255]);
            } else {
                rgb.extend_from_slice(&[255, k, k]);
            }
        }
    }
    plots::rgb8_png(path, &rgb, r3, c3)
}

fn sorted(mut v: Vec<(f64, f64)>) -> Vec<(f64, f64)> {
    v.retain(|p| p.0.is_finite() && p.1.is_finite());
    v.sort_by(|a, b| a.0.total_cmp(&b.0));
    v
}

/// Writes every figure into `dir`.
pub fn write_figures(dir: &Path, d: &Diagnosis, data: &DataSet) -> Result<Vec<Figure>, CliError> {
    let mut figs: Vec<Figure> = Vec::new();
    let mut add = |file: String, caption: String, section: &'static str| {
        figs.push(Figure {
            file,
            caption,
            section,
        })
    };
    // 1. residual maps
    for (k, (s, before, after)) in d.maps.iter().enumerate() {
        let id = &data.shots[*s].id;
        for (tag, m) in [("before", before), ("after", after)] {
            let file = format!("residual_{k}_{tag}.png");
            residual_png(&dir.join(&file), &m.z, data.rows, data.cols)?;
            add(
                file,
                format!(
                    "Shot {id}: residual of the frame mean ÷ its σ, {tag} (blue: model too bright, red: model too dark, ±4σ)"
                ),
                "Residual maps",
            );
        }
        let _: &ShotMaps = before;
    }
    // 2. photon transfer per channel
    for (c, name) in data.channel_names.iter().enumerate() {
        let pts = |l: &Located, model: bool| -> Vec<(f64, f64)> {
            sorted(
                l.shot_channels
                    .iter()
                    .filter(|x| x.channel == c && data.shots[x.shot].has_variance())
                    .map(|x| {
                        (
                            x.data_signal_dn,
                            if model {
                                x.model_temporal_var
                            } else {
                                x.data_temporal_var
                            },
                        )
                    })
                    .collect(),
            )
        };
        let data_pts = pts(&d.before, false);
        if data_pts.len() < 2 {
            continue;
        }
        let file = format!("ptc_{c}.png");
        plots::line_plot(
            &dir.join(&file),
            &format!("Photon transfer, channel {name}"),
            &[
                ("recording".into(), data_pts),
                ("believed model".into(), pts(&d.before, true)),
                ("fitted model".into(), pts(&d.after, true)),
            ],
            ("mean signal above pedestal (DN)", "temporal variance (DN²)"),
        )?;
        add(
            file,
            format!("Photon-transfer curve of channel {name}: temporal variance against mean signal, per shot"),
            "Photon transfer",
        );
    }
    // 3. radial profiles
    let light: Vec<usize> = (0..data.shots.len())
        .filter(|&s| data.shots[s].target.is_light())
        .take(6)
        .collect();
    if !light.is_empty() {
        for (tag, l) in [("before", &d.before), ("after", &d.after)] {
            let series: Vec<(String, Vec<(f64, f64)>)> = light
                .iter()
                .map(|&s| {
                    (
                        data.shots[s].id.clone(),
                        l.profiles[s].radial.iter().map(|x| (x.0, x.1)).collect(),
                    )
                })
                .collect();
            let file = format!("radial_{tag}.png");
            plots::line_plot(
                &dir.join(&file),
                &format!("Radial profile, {tag}"),
                &series,
                ("field height h", "recording ÷ model signal − 1"),
            )?;
            add(
                file,
                format!("Field-height profile of the signal mismatch, {tag}: relative illumination, glare and distortion show here"),
                "Field height",
            );
        }
    }
    // 4. columns and rows: the shot with the largest column structure before
    let col_score = |s: usize| -> f64 {
        let p = &d.before.profiles[s];
        let se = p.column_se_dn.max(1e-12);
        p.column_resid_dn
            .iter()
            .map(|x| (x / se).powi(2))
            .sum::<f64>()
            / p.column_resid_dn.len().max(1) as f64
    };
    if let Some(s) = (0..data.shots.len()).max_by(|&a, &b| col_score(a).total_cmp(&col_score(b))) {
        for (what, get) in [("columns", true), ("rows", false)] {
            let series: Vec<(String, Vec<(f64, f64)>)> =
                [("believed model", &d.before), ("fitted model", &d.after)]
                    .iter()
                    .map(|(n, l)| {
                        let p = &l.profiles[s];
                        let (v, se) = if get {
                            (&p.column_resid_dn, p.column_se_dn)
                        } else {
                            (&p.row_resid_dn, p.row_se_dn)
                        };
                        (
                            n.to_string(),
                            v.iter()
                                .enumerate()
                                .map(|(i, x)| (i as f64, x / se.max(1e-12)))
                                .collect(),
                        )
                    })
                    .collect();
            let file = format!("{what}.png");
            plots::line_plot(
                &dir.join(&file),
                &format!(
                    "Mean residual per {} (shot {})",
                    &what[..what.len() - 1],
                    data.shots[s].id
                ),
                &series,
                (if get { "column" } else { "row" }, "mean residual ÷ its σ"),
            )?;
            add(
                file,
                format!("Mean residual of every {} of shot {} in units of its standard error: column offsets and row structure show here", &what[..what.len() - 1], data.shots[s].id),
                "Rows and columns",
            );
        }
    }
    // 5. MTF of edge shots
    for (k, (mb, ma)) in d.before.mtf.iter().zip(&d.after.mtf).enumerate() {
        let file = format!("mtf_{k}.png");
        plots::line_plot(
            &dir.join(&file),
            &format!("Edge MTF, shot {}", data.shots[mb.shot].id),
            &[
                (
                    "recording".into(),
                    mb.freq
                        .iter()
                        .copied()
                        .zip(mb.data.iter().copied())
                        .collect(),
                ),
                (
                    "believed model".into(),
                    mb.freq
                        .iter()
                        .copied()
                        .zip(mb.model.iter().copied())
                        .collect(),
                ),
                (
                    "fitted model".into(),
                    ma.freq
                        .iter()
                        .copied()
                        .zip(ma.model.iter().copied())
                        .collect(),
                ),
            ],
            ("spatial frequency (cycles/pixel)", "MTF"),
        )?;
        add(
            file,
            format!("Slanted-edge MTF of shot {} (most populous channel): defocus and crosstalk show here", data.shots[mb.shot].id),
            "Spatial frequency",
        );
    }
    // 6. exposure: mean residual per shot against exposure time
    let per_shot = |l: &Located| -> Vec<(f64, f64)> {
        sorted(
            (0..data.shots.len())
                .map(|s| {
                    let xs: Vec<f64> = l
                        .shot_channels
                        .iter()
                        .filter(|x| x.shot == s)
                        .map(|x| x.mean_z)
                        .collect();
                    (
                        data.shots[s].exposure_s,
                        xs.iter().sum::<f64>() / xs.len().max(1) as f64,
                    )
                })
                .collect(),
        )
    };
    plots::line_plot(
        &dir.join("exposure.png"),
        "Mean residual against exposure time",
        &[
            ("believed model".into(), per_shot(&d.before)),
            ("fitted model".into(), per_shot(&d.after)),
        ],
        ("exposure (s)", "mean residual ÷ its σ"),
    )?;
    add(
        "exposure.png".into(),
        "Mean residual of each shot (averaged over channels, in standard errors) against exposure time: black level, dark current and exposure errors show here".into(),
        "Exposure",
    );
    // 7. illuminant / spectral: relative signal mismatch per light shot and channel
    for (tag, l) in [("before", &d.before), ("after", &d.after)] {
        let series: Vec<(String, Vec<(f64, f64)>)> = data
            .channel_names
            .iter()
            .enumerate()
            .map(|(c, n)| {
                (
                    n.clone(),
                    l.shot_channels
                        .iter()
                        .filter(|x| x.channel == c && data.shots[x.shot].target.is_light())
                        .filter_map(|x| {
                            let model_signal =
                                x.model_mean_dn - (x.data_mean_dn - x.data_signal_dn);
                            (model_signal.abs() > 1e-9)
                                .then(|| (x.shot as f64, x.data_signal_dn / model_signal - 1.0))
                        })
                        .collect::<Vec<(f64, f64)>>(),
                )
            })
            .filter(|s| !s.1.is_empty())
            .collect();
        if series.is_empty() {
            continue;
        }
        let file = format!("spectral_{tag}.png");
        plots::line_plot(
            &dir.join(&file),
            &format!("Signal mismatch per shot and channel, {tag}"),
            &series,
            ("shot index", "recording ÷ model signal − 1"),
        )?;
        add(
            file,
            format!("Relative signal mismatch of each light shot per channel, {tag}: illuminant-dependent (spectral) errors differ between shots and channels"),
            "Illuminant",
        );
    }
    // 8. temporal vs fixed pattern
    let ratio = |l: &Located, temporal: bool| -> Vec<(f64, f64)> {
        (0..data.shots.len())
            .filter_map(|s| {
                let xs: Vec<_> = l.shot_channels.iter().filter(|x| x.shot == s).collect();
                let (a, b) = xs.iter().fold((0.0, 0.0), |acc, x| {
                    if temporal {
                        (acc.0 + x.data_temporal_var, acc.1 + x.model_temporal_var)
                    } else {
                        (acc.0 + x.data_fixed_var, acc.1 + x.model_fixed_var)
                    }
                });
                (a.is_finite() && b > 0.0).then(|| (s as f64, a / b))
            })
            .collect()
    };
    plots::line_plot(
        &dir.join("temporal_fixed.png"),
        "Noise: recording ÷ model",
        &[
            ("temporal, believed".into(), ratio(&d.before, true)),
            ("fixed pattern, believed".into(), ratio(&d.before, false)),
            ("temporal, fitted".into(), ratio(&d.after, true)),
            ("fixed pattern, fitted".into(), ratio(&d.after, false)),
        ],
        ("shot index", "variance ratio"),
    )?;
    add(
        "temporal_fixed.png".into(),
        "Temporal variance (from repeated frames) and fixed-pattern variance (spread of the frame means beyond the temporal part) of the recording divided by the model's, per shot".into(),
        "Temporal and fixed pattern",
    );
    // 9. candidates of the first round
    if let Some(r) = d.selection.rounds.first() {
        let rows: Vec<_> = r.iter().filter(|x| x.delta_bic.is_some()).collect();
        if !rows.is_empty() {
            let labels: Vec<String> = rows.iter().map(|x| x.effect.id().to_string()).collect();
            let vals: Vec<f64> = rows
                .iter()
                .map(|x| {
                    let v = -x.delta_bic.unwrap_or(0.0);
                    v.signum() * (1.0 + v.abs()).log10()
                })
                .collect();
            plots::bar_chart(
                &dir.join("candidates.png"),
                "Candidates against the believed model",
                &labels,
                &vals,
                "−ΔBIC (signed log10(1+|x|))",
            )?;
            add(
                "candidates.png".into(),
                "Improvement of each candidate fitted alone to the believed model (−ΔBIC, log scale; above log10(11) ≈ 1.04 is accepted)".into(),
                "Candidates",
            );
        }
    }
    Ok(figs)
}

fn fmt(v: &Value) -> String {
    match v.as_f64() {
        Some(x) if x != 0.0 && (x.abs() < 1e-3 || x.abs() >= 1e5) => format!("{x:.4e}"),
        Some(x) => format!("{x:.4}"),
        None => v.as_str().map(str::to_string).unwrap_or_else(|| "–".into()),
    }
}

/// The report page.
pub fn report_html(report: &Value, d: &Diagnosis, data: &DataSet, figs: &[Figure]) -> String {
    let mut h = String::new();
    h.push_str("<!DOCTYPE html><html lang=\"en\"><head><meta charset=\"utf-8\"><title>camsim diagnose</title>");
    h.push_str("<style>body{font-family:sans-serif;max-width:1150px;margin:2em auto;color:#222}figure{display:inline-block;margin:8px;vertical-align:top;max-width:540px}figure img{max-width:520px;border:1px solid #ccc;image-rendering:pixelated}table{border-collapse:collapse;margin:6px 0}td,th{border:1px solid #ccc;padding:3px 8px;text-align:left;vertical-align:top}th{background:#f3f3f3}.num{text-align:right}</style></head><body>");
    h.push_str("<h1>camsim diagnose</h1>");
    h.push_str(&format!(
        "<p>Fit of the believed camera: χ²/dof = <b>{}</b> ({} dof); fitted camera: χ²/dof = <b>{}</b>. χ²/dof compares every frame with the model's per-pixel mean and variance (temporal and fixed pattern separated with repeated frames; clipped pixels as censored counts); close to 1 means the model explains the recording within its noise. The fitted camera is <a href=\"fitted_camera.json\">fitted_camera.json</a>; the machine-readable report is <a href=\"report.json\">report.json</a>.</p>",
        fmt(&report["fit_before"]["chi2_per_dof"]),
        fmt(&report["fit_before"]["dof"]),
        fmt(&report["fit_after"]["chi2_per_dof"]),
    ));
    h.push_str("<h2>Findings</h2>");
    let findings = report["findings"].as_array().cloned().unwrap_or_default();
    if findings.is_empty() {
        h.push_str("<p>No findings: the believed camera explains the recording within its noise (no candidate improved the BIC by more than the threshold).</p>");
    } else {
        h.push_str("<table><tr><th>#</th><th>effect</th><th>magnitude</th><th>where</th><th>explanation</th><th class=num>ΔBIC</th><th class=num>χ²/dof before → after</th></tr>");
        for (i, f) in findings.iter().enumerate() {
            h.push_str(&format!(
                "<tr><td>{}</td><td><b>{}</b></td><td class=num>{} {}</td><td>{}</td><td>{}</td><td class=num>{}</td><td class=num>{} → {}</td></tr>",
                i + 1,
                html_escape(f["effect"].as_str().unwrap_or("")),
                fmt(&f["magnitude"]),
                html_escape(f["unit"].as_str().unwrap_or("")),
                html_escape(f["where"].as_str().unwrap_or("")),
                html_escape(f["explanation"].as_str().unwrap_or("")),
                fmt(&f["evidence"]["delta_bic"]),
                fmt(&f["evidence"]["chi2_per_dof_before"]),
                fmt(&f["fit_after"]["chi2_per_dof"]),
            ));
        }
        h.push_str("</table>");
    }
    if let Some(u) = report["undecided"].as_array().filter(|u| !u.is_empty()) {
        h.push_str("<h2>Cannot tell apart</h2><table><tr><th>effects</th><th>ΔBIC</th><th>magnitudes</th><th>evidence that would separate them</th></tr>");
        for x in u {
            h.push_str(&format!(
                "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
                html_escape(&x["effects"].to_string()),
                html_escape(&x["delta_bic"].to_string()),
                html_escape(&x["magnitudes"].to_string()),
                html_escape(&x["would_separate"].to_string())
            ));
        }
        h.push_str("</table>");
    }
    if let Some(u) = report["cannot_tell"].as_array().filter(|u| !u.is_empty()) {
        h.push_str("<h2>Cannot tell from these shots</h2><p>The Fisher information of the shots cannot separate these candidates from the baseline parameters; they are not fitted and never reported as findings.</p><ul>");
        for x in u {
            h.push_str(&format!(
                "<li><b>{}</b>: {}. Would separate it: {}</li>",
                html_escape(x["effect"].as_str().unwrap_or("")),
                html_escape(x["explanation"].as_str().unwrap_or("")),
                html_escape(x["would_separate"].as_str().unwrap_or(""))
            ));
        }
        h.push_str("</ul>");
    }
    if report["timing"].is_string() {
        h.push_str("<p>Time per stage and what the fit subsampled: <a href=\"timing.json\">timing.json</a>.</p>");
    }
    if let Some(u) = report["not_testable"].as_array().filter(|u| !u.is_empty()) {
        h.push_str("<h2>Not testable with this capture set</h2><ul>");
        for x in u {
            h.push_str(&format!(
                "<li><b>{}</b>: {}</li>",
                html_escape(x["effect"].as_str().unwrap_or("")),
                html_escape(x["reason"].as_str().unwrap_or(""))
            ));
        }
        h.push_str("</ul>");
    }
    h.push_str("<h2>Ranked candidates</h2>");
    for (k, r) in d.selection.rounds.iter().enumerate() {
        h.push_str(&format!("<h3>Round {}</h3><table><tr><th>effect</th><th class=num>ΔBIC</th><th class=num>Δ ln L</th><th class=num>parameters</th><th class=num>magnitude</th></tr>", k + 1));
        for x in r.iter().filter(|x| x.delta_bic.is_some()) {
            h.push_str(&format!(
                "<tr><td>{}</td><td class=num>{:.1}</td><td class=num>{:.1}</td><td class=num>{}</td><td class=num>{:.4e} {}</td></tr>",
                x.effect.id(),
                x.delta_bic.unwrap_or(f64::NAN),
                x.delta_logl,
                x.k,
                x.magnitude,
                html_escape(x.effect.unit())
            ));
        }
        h.push_str("</table>");
    }
    h.push_str("<h2>Fit per shot and channel</h2><table><tr><th>shot</th><th>channel</th><th class=num>χ²/dof before</th><th class=num>χ²/dof after</th><th class=num>mean DN (data)</th><th class=num>mean DN (believed)</th><th class=num>mean DN (fitted)</th></tr>");
    for b in &d.before.shot_channels {
        let a = d
            .after
            .shot_channels
            .iter()
            .find(|x| x.shot == b.shot && x.channel == b.channel);
        h.push_str(&format!(
            "<tr><td>{}</td><td>{}</td><td class=num>{:.3}</td><td class=num>{}</td><td class=num>{:.2}</td><td class=num>{:.2}</td><td class=num>{}</td></tr>",
            html_escape(&data.shots[b.shot].id),
            html_escape(&data.channel_names[b.channel]),
            b.chi2_per_dof,
            a.map_or("–".into(), |a| format!("{:.3}", a.chi2_per_dof)),
            b.data_mean_dn,
            b.model_mean_dn,
            a.map_or("–".into(), |a| format!("{:.2}", a.model_mean_dn)),
        ));
    }
    h.push_str("</table>");
    let mut section = "";
    for f in figs {
        if f.section != section {
            section = f.section;
            h.push_str(&format!("<h2>{}</h2>", html_escape(section)));
        }
        h.push_str(&format!(
            "<figure><img src=\"{}\" alt=\"{}\"><figcaption>{}</figcaption></figure>",
            html_escape(&f.file),
            html_escape(&f.caption),
            html_escape(&f.caption)
        ));
    }
    h.push_str("</body></html>\n");
    h
}
