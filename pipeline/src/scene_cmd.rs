//! `camsim scene`: write a shot's scene radiance and sensor irradiance as spectral OpenEXR
//! (Fichet 2021 layout, W units), with its luminance and, optionally, the round-trip error of
//! a k-term linear model (§2.A of the paper).
use crate::chain::{shot_scene, wavelength_grid};
use crate::config::CaptureSet;
use crate::error::CliError;
use camsim_core::constants::SI;
use camsim_core::exr_io::{
    bands_energy_to_photons, write_spectral_exr, IRRADIANCE_UNITS, RADIANCE_UNITS,
};
use camsim_core::linear_model::compress;
use camsim_core::scene::mean_luminance;
use serde_json::{json, Value};
use std::path::{Path, PathBuf};

/// What `scene` reports: the scene's size and luminance, and `<id>_scene.json` as written.
#[derive(Debug, Clone)]
pub struct SceneSummary {
    /// The shot.
    pub shot: String,
    /// Scene samples (rows).
    pub rows: usize,
    /// Scene samples (columns).
    pub cols: usize,
    /// Mean luminance over the sensor's window (cd/m²).
    pub mean_luminance_cd_m2: f64,
    /// Files written into `--out` (relative paths).
    pub files: Vec<PathBuf>,
    /// `<id>_scene.json` as written.
    pub json: Value,
}

/// Write `<id>_radiance.exr`, `<id>_irradiance.exr` and `<id>_scene.json` into `out`.
pub fn write_scene(
    set: &CaptureSet,
    shot_id: &str,
    out: &Path,
    basis_terms: Option<usize>,
) -> Result<SceneSummary, CliError> {
    let idx = set
        .shots
        .iter()
        .position(|s| s.id == shot_id)
        .ok_or_else(|| {
            CliError::input(
                &set.path,
                format!(
                    "no shot with id \"{shot_id}\" (have: {})",
                    set.shots
                        .iter()
                        .map(|s| s.id.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            )
        })?;
    let grid = wavelength_grid(set);
    let scene = shot_scene(set, idx, &grid)?;
    let irr = crate::chain::irradiance_of(set, &scene, &grid)?;
    let mut rad_w = scene.radiance.to_bands(&grid);
    bands_energy_to_photons(&mut rad_w, &SI, true);
    let mut irr_w = irr.irradiance.to_bands(&grid);
    bands_energy_to_photons(&mut irr_w, &SI, true);
    let s = &set.camera.sensor;
    let window = (
        s.cols as f64 * s.pixel_pitch_m,
        s.rows as f64 * s.pixel_pitch_m,
    );
    let mean_luminance_cd_m2 = mean_luminance(&scene, Some(window), &SI);
    let mut report = json!({
        "shot": shot_id,
        "rows": scene.radiance.rows, "cols": scene.radiance.cols,
        "sample_pitch_um": scene.sample_pitch_m * 1e6,
        "wavelength_nm": grid.wavelength_nm,
        "mean_luminance_cd_m2": mean_luminance_cd_m2,
    });
    if let Some(k) = basis_terms {
        let c = compress(&scene.radiance, &grid, k);
        report["linear_model"] = json!({
            "basis_terms": k,
            "variance_explained": c.variance_explained,
            "relative_rms_error": c.relative_rms_error,
            "max_abs_error_photons": c.max_abs_error,
        });
    }
    let text = serde_json::to_string_pretty(&report).expect("json");
    let files = crate::staging::with_staging(out, |st| {
        let names: [PathBuf; 3] = [
            format!("{shot_id}_radiance.exr").into(),
            format!("{shot_id}_irradiance.exr").into(),
            format!("{shot_id}_scene.json").into(),
        ];
        let rp = st.join(&names[0]);
        write_spectral_exr(&rp, &rad_w, RADIANCE_UNITS, None)
            .map_err(|e| CliError::output(&rp, e))?;
        let ip = st.join(&names[1]);
        write_spectral_exr(&ip, &irr_w, IRRADIANCE_UNITS, None)
            .map_err(|e| CliError::output(&ip, e))?;
        let jp = st.join(&names[2]);
        std::fs::write(&jp, &text).map_err(|e| CliError::output(&jp, e))?;
        Ok(names.to_vec())
    })?;
    Ok(SceneSummary {
        shot: shot_id.to_string(),
        rows: scene.radiance.rows,
        cols: scene.radiance.cols,
        mean_luminance_cd_m2,
        files,
        json: report,
    })
}
