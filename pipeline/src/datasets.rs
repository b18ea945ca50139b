//! Capture sets that describe public real datasets in the spec's format (plus camsim's
//! documented extensions), so `camsim calibrate` / `validate` run on them unchanged. The data
//! are read in place: frames and label images are linked (symbolic links), never copied.
//!
//! * [`llanos_flea3_bandpass`]: B. Llanos (2019/2020), "chromatic-aberration" demo data
//!   (Boost Software License 1.0): a Point Grey Flea3 FL3-GE-50S5C photographing an X-Rite
//!   ColorChecker Classic lit by a projector through seven 10 nm bandpass filters, each at
//!   seven exposures, with spectrometer measurements of the filters and patches
//!   (docs/real_data_flea3.md).
use crate::error::CliError;
use camsim_core::exr_io::write_atomically;
use serde_json::{json, Value};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The 24 ColorChecker patch columns of `spectra_averaged.csv`, row-major chart order.
pub const FLEA3_PATCH_COLUMNS: [&str; 24] = [
    "dark skin",
    "light skin",
    "blue sky",
    "foliage",
    "blue flower",
    "bluish green",
    "orange",
    "purplish blue",
    "moderate red",
    "purple",
    "yellow green",
    "orange yellow",
    "blue",
    "green",
    "red",
    "yellow",
    "magenta",
    "cyan",
    "white 9.5 (.05 D)",
    "neutral 8 (.23 D)",
    "neutral 6.5 (.44 D)",
    "neutral 5 (.70 D)",
    "neutral 3.5 (1.05 D)",
    "black 2 (1.5 D)",
];

/// Bandpass filter named in the image file names (nm) → its column in the spectrometer file
/// (the "450 nm" filter is the 442 nm one of the kit).
pub const FLEA3_FILTER_COLUMNS: [(u32, &str); 7] = [
    (400, "400 nm"),
    (450, "442 nm"),
    (500, "500 nm"),
    (550, "550 nm"),
    (600, "600 nm"),
    (650, "650 nm"),
    (700, "700 nm"),
];

/// Wavelength range kept from the spectrometer data (nm): the camera's response and the
/// filters' passbands lie inside; outside it the ratios to the projector's white reference
/// are noise.
pub const FLEA3_RANGE_NM: (f64, f64) = (380.0, 720.0);

/// The camera as believed for the down-sampled ColorChecker images (session 2): the
/// 2448 × 2048 Sony ICX655 (3.45 µm) was demosaicked, resized by 1/6 to 408 × 342 and
/// re-mosaicked as GBRG (upstream `DemoDataPreprocessing.m`), so one pixel is 20.7 µm;
/// reduced to 8 bits. Conversion gain and swing are assumptions (8-bit full scale = 1 V,
/// 1e-4 V/e⁻): efficiencies come out in relative units anyway (the projector's spectrum is
/// not in the data).
pub fn flea3_bandpass_camera() -> Value {
    let qe = json!({"wavelength_nm": [400, 700], "values": [0.3, 0.3]});
    json!({"name": "flea3-fl3-ge-50s5c, 1/6 down-sampled (believed)",
        "optics": {"f_number": 4.0, "focal_length_mm": 8.0, "relative_illumination": "cos4"},
        "sensor": {"rows": 342, "cols": 408, "pixel_pitch_um": 20.7, "cfa": ["gb", "rg"],
                   "channels": {"r": qe, "g": qe, "b": qe},
                   "well_capacity_e": 10000, "conversion_gain_v_per_e": 1.0e-4, "voltage_swing_v": 1.0,
                   "adc_bits": 8}})
}

/// Columns of a CSV of spectra: the wavelengths (first column) and every named column.
fn read_spectra_csv(path: &Path) -> Result<(Vec<f64>, BTreeMap<String, Vec<f64>>), CliError> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| CliError::input(path, format!("cannot read: {e}")))?;
    let mut lines = text.lines();
    let header: Vec<String> = lines
        .next()
        .ok_or_else(|| CliError::input(path, "empty file"))?
        .split(',')
        .map(|s| s.trim().trim_matches('"').to_string())
        .collect();
    let mut wl = Vec::new();
    let mut cols: Vec<Vec<f64>> = vec![Vec::new(); header.len()];
    for (i, line) in lines.enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let v: Vec<&str> = line.split(',').collect();
        if v.len() != header.len() {
            return Err(CliError::input(
                path,
                format!(
                    "line {} has {} fields, the header {}",
                    i + 2,
                    v.len(),
                    header.len()
                ),
            ));
        }
        for (j, x) in v.iter().enumerate() {
            let x: f64 = x.trim().parse().map_err(|_| {
                CliError::input(path, format!("line {}: \"{x}\" is not a number", i + 2))
            })?;
            if j == 0 {
                wl.push(x);
            } else {
                cols[j].push(x);
            }
        }
    }
    let map = header.into_iter().zip(cols).skip(1).collect();
    Ok((wl, map))
}

fn link(src: &Path, dst: &Path) -> Result<(), CliError> {
    if dst.symlink_metadata().is_ok() {
        std::fs::remove_file(dst).map_err(|e| CliError::output(dst, e))?;
    }
    #[cfg(unix)]
    let r = std::os::unix::fs::symlink(src, dst);
    #[cfg(not(unix))]
    let r = std::fs::copy(src, dst).map(|_| ());
    r.map_err(|e| CliError::output(dst, e))
}

/// Round to 6 significant digits (keeps the JSON small; far below the data's precision).
fn sig6(x: f64) -> f64 {
    if x == 0.0 || !x.is_finite() {
        return 0.0;
    }
    let p = 10f64.powi(5 - x.abs().log10().floor() as i32);
    (x * p).round() / p
}

/// Write `out/camera.json`, `out/captures.json`, `out/raw/*.tif` (links) and
/// `out/labels.png` (link) for the Llanos Flea3 ColorChecker-through-bandpass-filters series
/// and the session's dark frames; returns the captures file.
///
/// Each shot is a `patches` target (4 × 6) with the camsim `labels` extension (the upstream
/// 550 nm label image) and patch radiance `T_filter(λ) · R_patch(λ)` in relative photon
/// units over 380–720 nm: the filter's transmittance (measured against the projector's
/// unfiltered light) times the patch reflectance (against Spectralon), i.e. the projector's
/// own spectrum taken as flat.
pub fn llanos_flea3_bandpass(data_dir: &Path, out: &Path) -> Result<PathBuf, CliError> {
    let csv = data_dir.join("spectral_measurements/spectra_averaged.csv");
    let (wl, cols) = read_spectra_csv(&csv)?;
    let column = |name: &str| -> Result<&Vec<f64>, CliError> {
        cols.get(name)
            .ok_or_else(|| CliError::input(&csv, format!("no column \"{name}\"")))
    };
    let keep: Vec<usize> = (0..wl.len())
        .filter(|&i| wl[i] >= FLEA3_RANGE_NM.0 && wl[i] <= FLEA3_RANGE_NM.1)
        .collect();
    let wl_kept: Vec<f64> = keep.iter().map(|&i| wl[i]).collect();
    let mut patch_cols = Vec::new();
    for n in FLEA3_PATCH_COLUMNS {
        patch_cols.push(column(n)?);
    }
    let mut targets: BTreeMap<u32, Value> = BTreeMap::new();
    for (nm, name) in FLEA3_FILTER_COLUMNS {
        let t = column(name)?;
        let patches: Vec<Value> = patch_cols
            .iter()
            .map(|r| {
                // negative ratios are spectrometer noise around 0
                let v: Vec<f64> = keep.iter().map(|&i| sig6((t[i] * r[i]).max(0.0))).collect();
                json!({"wavelength_nm": wl_kept, "values": v})
            })
            .collect();
        targets.insert(
            nm,
            json!({"kind": "patches", "rows": 4, "cols": 6, "patch_fraction": 1.0,
                   "radiance_unit": "photons", "labels": "labels.png", "patches": patches}),
        );
    }
    std::fs::create_dir_all(out.join("raw")).map_err(|e| CliError::output(out, e))?;
    link(
        &data_dir.join("d2_colorChecker30cm_550nm_labels.png"),
        &out.join("labels.png"),
    )?;
    let list = |sub: &str| -> Result<Vec<String>, CliError> {
        let d = data_dir.join(sub);
        let mut v: Vec<String> = std::fs::read_dir(&d)
            .map_err(|e| CliError::input(&d, format!("cannot list: {e}")))?
            .filter_map(|e| e.ok())
            .map(|e| e.file_name().to_string_lossy().to_string())
            .filter(|n| n.ends_with(".tif"))
            .collect();
        v.sort();
        Ok(v)
    };
    // d2_colorChecker30cm_550nm_25ms_2019-02-18-113606-0004.tif
    let ms_of = |s: &str| s.trim_end_matches("ms").parse::<u32>().ok();
    let mut chart: BTreeMap<(u32, u32), Vec<String>> = BTreeMap::new();
    for n in list("colorchecker_bandpass")? {
        let p: Vec<&str> = n.split('_').collect();
        let (Some(nm), Some(ms)) = (
            p.get(2)
                .and_then(|s| s.trim_end_matches("nm").parse::<u32>().ok()),
            p.get(3).and_then(|s| ms_of(s)),
        ) else {
            continue;
        };
        if p[0] != "d2" || !targets.contains_key(&nm) {
            continue;
        }
        link(
            &data_dir.join("colorchecker_bandpass").join(&n),
            &out.join("raw").join(&n),
        )?;
        chart.entry((nm, ms)).or_default().push(format!("raw/{n}"));
    }
    let mut darks: BTreeMap<u32, Vec<String>> = BTreeMap::new();
    for n in list("dark_frames")? {
        let p: Vec<&str> = n.split('_').collect();
        // session 2 only: the same down-sampled geometry as the chart images
        let Some(ms) = p.get(2).and_then(|s| ms_of(s)) else {
            continue;
        };
        if p[0] != "d2" {
            continue;
        }
        link(
            &data_dir.join("dark_frames").join(&n),
            &out.join("raw").join(&n),
        )?;
        darks.entry(ms).or_default().push(format!("raw/{n}"));
    }
    if chart.is_empty() {
        return Err(CliError::input(
            data_dir,
            "no d2_colorChecker30cm_<nm>nm_<ms>ms_*.tif frames in colorchecker_bandpass/",
        ));
    }
    let mut shots: Vec<Value> = darks
        .into_iter()
        .map(|(ms, frames)| {
            json!({"id": format!("dark-{ms}ms"), "target": {"kind": "dark"},
                   "exposure_s": ms as f64 / 1000.0, "frames": frames})
        })
        .collect();
    for ((nm, ms), frames) in chart {
        shots.push(
            json!({"id": format!("cc-{nm}nm-{ms}ms"), "target": targets[&nm],
                          "exposure_s": ms as f64 / 1000.0, "frames": frames}),
        );
    }
    let write = |p: &Path, text: String| {
        write_atomically(p, |tmp| std::fs::write(tmp, &text)).map_err(|e| CliError::output(p, e))
    };
    write(
        &out.join("camera.json"),
        serde_json::to_string_pretty(&flea3_bandpass_camera()).expect("json"),
    )?;
    let caps = out.join("captures.json");
    write(
        &caps,
        serde_json::to_string(&json!({"camera": "camera.json", "shots": shots})).expect("json"),
    )?;
    Ok(caps)
}
