//! `camsim scene`: write a shot's scene radiance and sensor irradiance as spectral OpenEXR
//! (Fichet 2021 layout, W units), with its luminance and, optionally, the round-trip error of
//! a k-term linear model (§2.A of the paper).
use crate::chain::{shot_scene, wavelength_grid};
use crate::config::CaptureSet;
use crate::error::CliError;
use camsim_core::constants::SI;
use camsim_core::exr_io::{
    bands_energy_to_photons, write_atomically, write_spectral_exr, IRRADIANCE_UNITS, RADIANCE_UNITS,
};
use camsim_core::linear_model::compress;
use camsim_core::scene::mean_luminance;
use serde_json::json;
use std::path::Path;

/// Write `<id>_radiance.exr`, `<id>_irradiance.exr` and `<id>_scene.json` into `out`.
pub fn write_scene(
    set: &CaptureSet,
    shot_id: &str,
    out: &Path,
    basis_terms: Option<usize>,
) -> Result<serde_json::Value, CliError> {
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
    std::fs::create_dir_all(out).map_err(|e| CliError::output(out, e))?;
    let mut rad_w = scene.radiance.to_bands(&grid);
    bands_energy_to_photons(&mut rad_w, &SI, true);
    let mut irr_w = irr.irradiance.to_bands(&grid);
    bands_energy_to_photons(&mut irr_w, &SI, true);
    let rp = out.join(format!("{shot_id}_radiance.exr"));
    write_spectral_exr(&rp, &rad_w, RADIANCE_UNITS, None).map_err(|e| CliError::output(&rp, e))?;
    let ip = out.join(format!("{shot_id}_irradiance.exr"));
    write_spectral_exr(&ip, &irr_w, IRRADIANCE_UNITS, None)
        .map_err(|e| CliError::output(&ip, e))?;
    let s = &set.camera.sensor;
    let window = (
        s.cols as f64 * s.pixel_pitch_m,
        s.rows as f64 * s.pixel_pitch_m,
    );
    let mut report = json!({
        "shot": shot_id,
        "rows": scene.radiance.rows, "cols": scene.radiance.cols,
        "sample_pitch_um": scene.sample_pitch_m * 1e6,
        "wavelength_nm": grid.wavelength_nm,
        "mean_luminance_cd_m2": mean_luminance(&scene, Some(window), &SI),
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
    let jp = out.join(format!("{shot_id}_scene.json"));
    let text = serde_json::to_string_pretty(&report).expect("json");
    write_atomically(&jp, |tmp| std::fs::write(tmp, &text))
        .map_err(|e| CliError::output(&jp, e))?;
    Ok(report)
}
