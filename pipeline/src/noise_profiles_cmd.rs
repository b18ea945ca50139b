//! `camsim noise-profiles`: darktable's measured noise profiles read through the
//! shot-plus-read-noise model (camsim_diagnose::noise_profiles): what each profile implies
//! (electrons at full scale, read noise) and which fits no such sensor can produce (b < 0),
//! with figures. docs/diagnose_real.md.
use crate::error::CliError;
use crate::plots::line_plot;
use camsim_diagnose::noise_profiles::{
    camera, census, implication, read_noise_profiles, ProfileImplication,
};
use serde_json::json;
use std::path::Path;

/// Run the analysis of `file` (darktable `noiseprofiles.json`) into `out`; with `camera_name`
/// also that camera's per-ISO implications and figures. Returns the summary written to
/// `out/noise_profiles.json`.
pub fn run_noise_profiles(
    file: &Path,
    camera_name: Option<&str>,
    out: &Path,
) -> Result<NoiseProfilesSummary, CliError> {
    crate::staging::protect_input(file);
    let all = read_noise_profiles(file).map_err(|e| CliError::Other(e.to_string()))?;
    let mut result = serde_json::Value::Null;
    let files = crate::staging::with_staging(out, |stage| {
        result = analyse_into(file, &all, camera_name, stage)?;
        let mut files = vec![
            std::path::PathBuf::from("noise_negative_b_by_iso.png"),
            "noise_profiles.json".into(),
        ];
        if camera_name.is_some() {
            files.push("noise_camera_full_scale.png".into());
            files.push("noise_camera_read_noise.png".into());
        }
        Ok(files)
    })?;
    Ok(NoiseProfilesSummary {
        census: census(&all),
        files,
        json: result,
    })
}

/// What `noise-profiles` reports: the census of the profiles, and noise_profiles.json as
/// written.
#[derive(Debug, Clone)]
pub struct NoiseProfilesSummary {
    /// How many makers, models, profiles and fits with b < 0 or a ≤ 0.
    pub census: camsim_diagnose::noise_profiles::ProfileCensus,
    /// Files written into `--out` (relative paths).
    pub files: Vec<std::path::PathBuf>,
    /// noise_profiles.json as written.
    pub json: serde_json::Value,
}

/// The analysis and its files, written into `out` (the staging folder).
fn analyse_into(
    file: &Path,
    all: &[camsim_diagnose::noise_profiles::NoiseProfile],
    camera_name: Option<&str>,
    out: &Path,
) -> Result<serde_json::Value, CliError> {
    let all = all.to_vec();
    let c = census(&all);
    // Fraction of green-channel fits with b < 0 per ISO octave (all cameras).
    let mut bins: std::collections::BTreeMap<i32, (usize, usize)> = Default::default();
    for p in &all {
        let k = (p.iso / 100.0).log2().round() as i32;
        let e = bins.entry(k).or_default();
        e.1 += 1;
        if p.b[1] < 0.0 {
            e.0 += 1;
        }
    }
    let frac: Vec<(f64, f64)> = bins
        .iter()
        .filter(|(_, (_, n))| *n >= 10)
        .map(|(k, (neg, n))| ((100.0 * 2f64.powi(*k)).log10(), *neg as f64 / *n as f64))
        .collect();
    line_plot(
        &out.join("noise_negative_b_by_iso.png"),
        "darktable profiles: share of green fits with b < 0",
        &[("all cameras".to_string(), frac.clone())],
        ("log10 ISO", "fraction with b < 0"),
    )?;
    let mut summary = json!({
        "file": file.display().to_string(),
        "model": "var = a·mean + b (normalised raw); shot + read: a = 1/N_fullscale_e, b = (read_e/N)^2",
        "census": c,
        "negative_b_fraction_by_iso": frac.iter().map(|(l, f)| json!({"iso": 10f64.powf(*l).round(), "fraction": f})).collect::<Vec<_>>(),
    });
    if let Some(name) = camera_name {
        let cam = camera(&all, name);
        if cam.is_empty() {
            return Err(CliError::input(
                file,
                format!("--camera \"{name}\": no such model (give the model, e.g. \"ILCE-7M3\", or \"maker model\")"),
            ));
        }
        let imp: Vec<ProfileImplication> = cam.iter().map(|p| implication(p)).collect();
        let series = |f: &dyn Fn(&ProfileImplication, usize) -> Option<f64>| {
            // B, R, G: line_plot's palette is blue, red, green
            [2usize, 0, 1]
                .into_iter()
                .map(|k| {
                    (
                        ["R", "G", "B"][k].to_string(),
                        imp.iter()
                            .filter_map(|i| f(i, k).map(|v| (i.iso.log10(), v)))
                            .collect::<Vec<_>>(),
                    )
                })
                .collect::<Vec<_>>()
        };
        line_plot(
            &out.join("noise_camera_full_scale.png"),
            &format!("{name}: apparent electrons at full scale × ISO/100"),
            &series(&|i, k| i.channels[k].full_scale_e.map(|n| n * i.iso / 100.0)),
            ("log10 ISO", "N_fs · ISO/100 (e⁻)"),
        )?;
        line_plot(
            &out.join("noise_camera_read_noise.png"),
            &format!("{name}: apparent read noise (b ≥ 0 only)"),
            &series(&|i, k| i.channels[k].read_noise_e),
            ("log10 ISO", "read noise (e⁻)"),
        )?;
        summary["camera"] = json!(name);
        summary["profiles"] = json!(imp
            .iter()
            .map(|i| {
                json!({"iso": i.iso, "channels": i.channels.iter().map(|c| json!({
                    "channel": c.channel, "a": c.a, "b": c.b, "full_scale_e": c.full_scale_e,
                    "read_noise_e": c.read_noise_e, "dynamic_range": c.dynamic_range,
                    "impossible": c.impossible,
                    "why": c.impossible.as_ref().map(|x| x.explanation()),
                })).collect::<Vec<_>>()})
            })
            .collect::<Vec<_>>());
    }
    let p = out.join("noise_profiles.json");
    std::fs::write(
        &p,
        serde_json::to_string_pretty(&summary).unwrap_or_default(),
    )
    .map_err(|e| CliError::output(&p, e))?;
    Ok(summary)
}
