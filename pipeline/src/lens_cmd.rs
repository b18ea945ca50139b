//! `camsim lens …`: lens-prescription analyses on the command line (camsim-lens).
//!
//! * `report`: first-order data, chief rays, distortion, lateral colour, RMS spots per field and
//!   wavelength and the on-axis MTF, as JSON (`--json`) and/or an HTML report with figures;
//! * `spot`: one spot diagram (statistics, optionally the points);
//! * `field-model`: the ISET-style field model file ([`camsim_lens::FieldModel`]);
//! * `psf`: the wave-optics PSF of one field and wavelength as PNG or EXR.
//!
//! A LENS argument is a project prescription (`.json`, see `lens/src/lib.rs`), a Zemax `.zmx`,
//! an ISET/pbrt `.dat` or an ISETCam lens `.json` (told apart from the project format by its
//! surface keys `radius`/`thickness`/`ior`). Every error names the file and is printed on one
//! line.
//!
//! ## Conventions (those of /work/shared/tools/optics_ref/ref_lens.py)
//! * The lens is refocused at the paraxial focus of its primary wavelength (the last thickness
//!   of the file is replaced by the paraxial image distance), for the lens's own object
//!   distance (object at infinity when `object_distance_mm` is null).
//! * Aperture, primary wavelength and fields come from the lens file; a field fraction f means
//!   the object-space chief-ray angle f × (largest |fields_deg| of the file), or f ×
//!   `--max-field-deg` when given.
//! * Chief ray: real ray aimed at the centre of the stop at the primary wavelength.
//!   `chief_ray_height_mm` is |y| of that ray on the image plane, `paraxial_image_height_mm` the
//!   paraxial chief-ray height (= EFL·tan θ for an object at infinity), distortion
//!   % = 100 (real − paraxial)/paraxial.
//! * Lateral colour = |y_chief(486.1 nm)| − |y_chief(656.3 nm)| (F − C, µm), the primary-aimed
//!   chief ray traced at each wavelength.
//! * RMS spot: the n×n square grid ((i + ½)/n·2 − 1) of the paraxial entrance pupil clipped to
//!   the unit disc (shifted by the real chief-ray aim point off axis), RMS radius about the
//!   centroid on the paraxial image plane; no clipping at semi-diameters unless `--clip`.
//! * On-axis MTF: diffraction MTF at the primary wavelength from the OPD map (pupil grid set by
//!   the OPD slope, 64…1024 per side, `camsim_lens::focus`; 2× zero padding), by default on the
//!   best-focus plane (the image-plane shift minimising the on-axis polychromatic RMS spot of
//!   the report wavelengths), as ref_lens.py's `mtf_best_focus_primary`; `--mtf-focus paraxial`
//!   uses the paraxial image plane, `--mtf-focus best-mtf` the plane maximising the MTF.
//!   On axis the tangential and sagittal MTFs coincide; their mean is reported.
use crate::error::CliError;
use crate::plots;
use crate::report::html_escape;
use crate::staging::with_staging;
use camsim_lens::analysis::pupil_grid;
use camsim_lens::focus::MtfMerit;
use camsim_lens::huygens::{HuygensPsf, HuygensWindow};
use camsim_lens::readers::{
    decode_text, read_iset_dat, read_iset_json, read_zmx, zmx_glass_catalog, ZmxOptions,
};
use camsim_lens::{
    Clipping, FieldModel, FieldModelOptions, LensPrescription, PrescriptionFile, PsfKind,
};
use clap::{Subcommand, ValueEnum};
use serde_json::{json, Map, Value};
use std::path::{Path, PathBuf};

/// Wavelengths of the lateral-colour definition (F and C lines, nm).
pub const F_LINE_NM: f64 = 486.1;
/// C line (nm).
pub const C_LINE_NM: f64 = 656.3;

/// Which image plane the on-axis MTF of `lens report` uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum MtfFocus {
    /// The plane minimising the on-axis polychromatic RMS spot.
    Best,
    /// The plane maximising the on-axis MTF at the primary wavelength (mean over the report's
    /// frequencies up to half the cutoff; `camsim_lens::focus`).
    BestMtf,
    /// The paraxial image plane of the primary wavelength.
    Paraxial,
    /// The focus model's plane (`camsim_lens::focus_model`, the report's `focus` section):
    /// best polychromatic MTF weighted over the report's field, the plane every camera uses.
    Model,
}

/// The LENS argument and the glass substitutions for Zemax files.
#[derive(Debug, Clone, clap::Args)]
pub struct LensArg {
    /// The lens: project .json, Zemax .zmx, ISET/pbrt .dat or ISETCam lens .json.
    #[arg(value_name = "LENS")]
    pub path: PathBuf,
    /// Replace a glass that is not in the catalogue (Zemax files; repeatable), e.g.
    /// `--glass-sub J-LAK14=ohara/S-LAL14`.
    #[arg(long = "glass-sub", value_name = "FROM=VENDOR/GLASS")]
    pub glass_sub: Vec<String>,
    /// A Zemax .agf glass catalogue searched before the bundled ones (repeatable). The .agf
    /// files named on a .zmx's GCAT line are also looked for beside the .zmx.
    #[arg(long = "glass-catalog", value_name = "FILE.agf")]
    pub glass_catalog: Vec<PathBuf>,
    /// Sensor diagonal (mm): the maximum field becomes the field whose paraxial chief ray
    /// reaches the sensor corner (tan θ = (d/2)/EFL at infinity), replacing the file's fields
    /// (pbrt .dat and ISET lens files state none). --max-field-deg still overrides it.
    #[arg(long = "sensor-diagonal-mm", value_name = "MM")]
    pub sensor_diagonal_mm: Option<f64>,
}

impl LensArg {
    /// Read the lens (see [`load_lens_with`]).
    pub fn load(&self) -> Result<LensPrescription, CliError> {
        let mut opts = ZmxOptions::default();
        for p in &self.glass_catalog {
            opts.catalog = opts
                .catalog
                .with_agf(p)
                .map_err(|e| CliError::input(p, e))?;
        }
        for s in &self.glass_sub {
            let parsed = s.split_once('=').and_then(|(from, to)| {
                let (vendor, glass) = to.split_once('/')?;
                let ok = |x: &str| !x.trim().is_empty();
                (ok(from) && ok(vendor) && ok(glass))
                    .then(|| (from.trim(), vendor.trim(), glass.trim()))
            });
            let Some((from, vendor, glass)) = parsed else {
                return Err(CliError::Other(format!(
                    "--glass-sub '{s}': expected FROM=VENDOR/GLASS, e.g. J-LAK14=ohara/S-LAL14"
                )));
            };
            opts = opts.substitute(from, glass, vendor);
        }
        let mut lens = load_lens_with(&self.path, &opts)?;
        if let Some(d) = self.sensor_diagonal_mm {
            if !(d.is_finite() && d > 0.0) {
                return Err(CliError::Other(format!(
                    "--sensor-diagonal-mm {d} must be a positive number of mm"
                )));
            }
            let half_fov = lens
                .focused(lens.primary_nm)
                .and_then(|f| f.paraxial_full_fov_deg(d / 2.0))
                .map_err(|e| CliError::input(&self.path, e))?
                / 2.0;
            if !(half_fov > 0.0 && half_fov < 90.0) {
                return Err(CliError::input(
                    &self.path,
                    format!("--sensor-diagonal-mm {d} gives a field of {half_fov}°"),
                ));
            }
            eprintln!(
                "camsim: {}: maximum field {half_fov:.4}° from the sensor diagonal {d} mm \
                 (paraxial chief ray to the corner)",
                self.path.display()
            );
            lens.fields_deg = vec![0.0, half_fov];
        }
        Ok(lens)
    }
}

/// `camsim lens …` subcommands.
#[derive(Debug, Subcommand)]
pub enum LensCommand {
    /// First-order data, chief rays, distortion, lateral colour, RMS spots and the on-axis MTF;
    /// prints JSON (--json) and/or writes DIR/report.html, report.json and figures.
    Report {
        /// The lens and glass substitutions.
        #[command(flatten)]
        lens: LensArg,
        /// Print the report JSON to stdout (no folder is written unless --out is given).
        #[arg(long)]
        json: bool,
        /// Field fractions of the lens's maximum field.
        #[arg(long, value_delimiter = ',', default_value = "0,0.5,0.7,1")]
        field_fraction: Vec<f64>,
        /// Wavelengths of the RMS spots (nm); they key `rms_spot_um` as written.
        #[arg(long, value_delimiter = ',', default_value = "486.1,587.6,656.3")]
        wavelength_nm: Vec<String>,
        /// Output folder for report.html, report.json and the figures (default out/lens
        /// when --json is not given).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Maximum field angle (degrees) instead of the largest of the file's fields_deg.
        #[arg(long)]
        max_field_deg: Option<f64>,
        /// Pupil grid per side of the spot diagrams (33 → 861 rays).
        #[arg(long, default_value_t = 33)]
        grid: usize,
        /// MTF frequencies (cycles/mm).
        #[arg(
            long,
            value_delimiter = ',',
            default_value = "0,10,20,30,40,50,60,70,80,90,100,120,140,160,180,200"
        )]
        mtf_lp_mm: Vec<f64>,
        /// Image plane of the on-axis MTF.
        #[arg(long, value_enum, default_value_t = MtfFocus::Best)]
        mtf_focus: MtfFocus,
        /// Clip rays at the surfaces' semi-diameters (vignetting).
        #[arg(long)]
        clip: bool,
    },
    /// One spot diagram on the paraxial image plane: RMS radius, centroid, rays transmitted.
    Spot {
        /// The lens and glass substitutions.
        #[command(flatten)]
        lens: LensArg,
        /// Field fraction of the lens's maximum field.
        #[arg(long)]
        field_fraction: f64,
        /// Wavelength (nm).
        #[arg(long)]
        wavelength_nm: f64,
        /// At least this many rays (the smallest square pupil grid clipped to the disc that
        /// holds N rays).
        #[arg(long, default_value_t = 861)]
        rays: usize,
        /// Print JSON including the image points.
        #[arg(long)]
        json: bool,
        /// Maximum field angle (degrees) instead of the largest of the file's fields_deg.
        #[arg(long)]
        max_field_deg: Option<f64>,
        /// Shift of the image plane from the paraxial focus (mm).
        #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
        defocus_mm: f64,
        /// Clip rays at the surfaces' semi-diameters (vignetting).
        #[arg(long)]
        clip: bool,
    },
    /// Compute the field model (PSF, distortion, relative illumination over image height ×
    /// wavelength × object distance, the lens at one focus) and save it as JSON (format
    /// version 2, see camsim_lens::field_model).
    FieldModel {
        /// The lens and glass substitutions.
        #[command(flatten)]
        lens: LensArg,
        /// Output file (.json).
        #[arg(long)]
        out: PathBuf,
        /// Number of tabulated field heights (≥ 2).
        #[arg(long, default_value_t = 5)]
        fields: usize,
        /// Wavelengths (nm); default the lens's.
        #[arg(long, value_delimiter = ',')]
        wavelengths_nm: Option<Vec<f64>>,
        /// Maximum field angle (degrees) instead of the largest of the file's fields_deg.
        #[arg(long)]
        max_field_deg: Option<f64>,
        /// Geometric (ray-density) PSFs instead of wave-optics ones.
        #[arg(long)]
        geometric: bool,
        /// Samples per side of the stored PSFs.
        #[arg(long, default_value_t = 33)]
        psf_n: usize,
        /// Pitch of the stored PSFs (µm).
        #[arg(long, default_value_t = 1.0)]
        psf_pitch_um: f64,
        /// Object distances to tabulate (mm from the first vertex; `inf` = infinity), e.g.
        /// `inf,5000,2000,1000`; default the focus distance only.
        #[arg(long, value_delimiter = ',')]
        object_distances_mm: Vec<String>,
        /// Object distance the lens is focused on (mm or `inf`); default the lens file's
        /// `object_distance_mm`.
        #[arg(long)]
        focus_distance_mm: Option<String>,
        /// Pupil samples per side (OPD grid of wave PSFs, ray grid of geometric ones).
        #[arg(long, default_value_t = 64)]
        pupil_samples: usize,
    },
    /// Draw the lens layout (meridional section, surfaces and rays of the axis and the maximum
    /// field at the primary wavelength) as SVG.
    Draw {
        /// The lens and glass substitutions.
        #[command(flatten)]
        lens: LensArg,
        /// Output .svg file.
        #[arg(long)]
        out: PathBuf,
        /// Rays per field across the pupil (meridional fan).
        #[arg(long, default_value_t = 7)]
        rays: usize,
        /// Maximum field angle (degrees) instead of the largest of the file's fields_deg.
        #[arg(long)]
        max_field_deg: Option<f64>,
    },
    /// The wave-optics PSF (sum 1) of one field and wavelength on the paraxial image plane, as
    /// a PNG (normalised to its peak) or a single-channel EXR (channel Y).
    Psf {
        /// The lens and glass substitutions.
        #[command(flatten)]
        lens: LensArg,
        /// Field fraction of the lens's maximum field.
        #[arg(long)]
        field_fraction: f64,
        /// Wavelength (nm).
        #[arg(long)]
        wavelength_nm: f64,
        /// Output: .png or .exr.
        #[arg(long)]
        out: PathBuf,
        /// Maximum field angle (degrees) instead of the largest of the file's fields_deg.
        #[arg(long)]
        max_field_deg: Option<f64>,
        /// Pupil samples per side of the OPD map.
        #[arg(long, default_value_t = 64)]
        pupil_samples: usize,
        /// Zero-padding factor of the FFT (PSF size = pupil samples × pad).
        #[arg(long, default_value_t = 4)]
        pad: usize,
        /// Shift of the image plane from the paraxial focus (mm).
        #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
        defocus_mm: f64,
        /// fft: |FFT of the pupil function|² (pitch λN_w(n − 1)/(n·pad)); huygens: direct
        /// Huygens–Fresnel sum on any grid (--samples, --sample-um), centred on the chief ray.
        #[arg(long, value_enum, default_value_t = PsfMethod::Fft)]
        method: PsfMethod,
        /// Huygens: samples per side (default 129).
        #[arg(long)]
        samples: Option<usize>,
        /// Huygens: sample pitch in µm (default λN_w/4).
        #[arg(long)]
        sample_um: Option<f64>,
    },
}

/// How `lens psf` computes the PSF.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum PsfMethod {
    /// FFT of the pupil function.
    Fft,
    /// Huygens–Fresnel integration over the exit-pupil reference sphere.
    Huygens,
}

/// Read a lens in any supported format (chosen by extension, else by content).
pub fn load_lens(path: &Path) -> Result<LensPrescription, CliError> {
    load_lens_with(path, &ZmxOptions::default())
}

/// [`load_lens`] with explicit Zemax options (glass substitutions).
pub fn load_lens_with(path: &Path, zmx: &ZmxOptions) -> Result<LensPrescription, CliError> {
    crate::guard::guarded(path, || load_lens_unguarded(path, zmx))
}

fn load_lens_unguarded(path: &Path, zmx: &ZmxOptions) -> Result<LensPrescription, CliError> {
    crate::staging::protect_input(path);
    let bad = |e: &dyn std::fmt::Display| CliError::input(path, e);
    let bytes = std::fs::read(path).map_err(|e| bad(&e))?;
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().to_string())
        .unwrap_or_default();
    let kind = match ext.as_str() {
        "zmx" => "zmx",
        "dat" => "dat",
        "json" => "json",
        _ => {
            let text = decode_text(&bytes);
            let t = text.trim_start();
            if t.starts_with('{') {
                "json"
            } else if text.lines().any(|l| {
                let l = l.trim_start();
                l.starts_with("SURF ") || l.starts_with("VERS ") || l.starts_with("UNIT ")
            }) {
                "zmx"
            } else {
                "dat"
            }
        }
    };
    let mut catalog = zmx.catalog.clone();
    let file: PrescriptionFile = match kind {
        "zmx" => {
            let mut zmx = zmx.clone();
            if let Some(dir) = path.parent() {
                zmx.agf_dirs.push(if dir.as_os_str().is_empty() {
                    PathBuf::from(".")
                } else {
                    dir.to_path_buf()
                });
            }
            catalog = zmx_glass_catalog(&bytes, &zmx).map_err(|e| bad(&e))?;
            let f = read_zmx(&bytes, &stem, &zmx).map_err(|e| bad(&e))?;
            if let Some(note) = f.provenance.as_deref() {
                eprintln!("camsim: {}: {note}", path.display());
            }
            f
        }
        "dat" => read_iset_dat(&decode_text(&bytes), &stem).map_err(|e| bad(&e))?,
        _ => {
            let text = decode_text(&bytes);
            let v: Value =
                serde_json::from_str(&text).map_err(|e| bad(&format!("not valid JSON: {e}")))?;
            let first = v
                .get("surfaces")
                .and_then(Value::as_array)
                .and_then(|a| a.first());
            let is_iset = first.is_some_and(|s| {
                s.get("ior").is_some()
                    || s.get("semi_aperture").is_some()
                    || (s.get("radius").is_some() && s.get("radius_mm").is_none())
            });
            if is_iset {
                read_iset_json(&text, &stem).map_err(|e| bad(&e))?
            } else {
                check_lens_keys(&v).map_err(|e| bad(&e))?;
                serde_json::from_value(v)
                    .map_err(|e| bad(&format!("not a lens prescription: {e}")))?
            }
        }
    };
    LensPrescription::from_file_form(&file, &catalog).map_err(|e| bad(&e))
}

/// Refuse unknown keys in a camsim lens JSON (a misspelt `conic` or `semi_diameter_mm` would
/// otherwise be ignored silently). Free-text and reference keys that other tools write
/// (`published`, `notes`, and optics_ref's `psf_fields_deg`, `mtf_freqs_lpmm`) are allowed.
fn check_lens_keys(v: &Value) -> Result<(), String> {
    const TOP: &[&str] = &[
        "name",
        "units",
        "surfaces",
        "object_distance_mm",
        "fields_deg",
        "wavelengths_nm",
        "primary_nm",
        "aperture",
        "provenance",
        "published",
        "notes",
        "psf_fields_deg",
        "mtf_freqs_lpmm",
    ];
    const SURFACE: &[&str] = &[
        "radius_mm",
        "thickness_mm",
        "material",
        "semi_diameter_mm",
        "conic",
        "aspheric_coeffs",
        "odd_aspheric_coeffs",
        "stop",
    ];
    if let Some(m) = v.as_object() {
        if let Some(k) = m.keys().find(|k| !TOP.contains(&k.as_str())) {
            return Err(format!(
                "{k}: unknown key (expected one of {})",
                TOP.join(", ")
            ));
        }
    }
    for (i, s) in v
        .get("surfaces")
        .and_then(Value::as_array)
        .into_iter()
        .flatten()
        .enumerate()
    {
        if let Some(k) = s
            .as_object()
            .and_then(|m| m.keys().find(|k| !SURFACE.contains(&k.as_str())))
        {
            return Err(format!(
                "surfaces[{i}].{k}: unknown key (expected one of {})",
                SURFACE.join(", ")
            ));
        }
    }
    Ok(())
}

/// The lens refocused at the paraxial focus of its primary wavelength.
fn focused(lens: &LensPrescription, path: &Path) -> Result<LensPrescription, CliError> {
    let l = lens
        .focused(lens.primary_nm)
        .map_err(|e| CliError::input(path, e))?;
    let d = l.image_distance_mm();
    if !d.is_finite() {
        return Err(CliError::input(
            path,
            "the paraxial image is at infinity (afocal or object at the front focal point)",
        ));
    }
    Ok(l)
}

/// The maximum field angle (degrees): `override_deg`, else the largest |fields_deg| of the lens,
/// else (pbrt `.dat` and ISET lens files state no field angles) a field stated in the file name
/// as ISETCam names its lenses (`petzval.12deg.50.0mm.dat` → 12°), said on stderr. When none
/// of these gives one and `needed` (an off-axis field is asked for), an error asks for
/// `--max-field-deg`.
fn max_field_deg(
    lens: &LensPrescription,
    override_deg: Option<f64>,
    path: &Path,
    needed: bool,
) -> Result<f64, CliError> {
    match override_deg {
        Some(d) if d.is_finite() && d.abs() < 90.0 => return Ok(d.abs()),
        Some(d) => {
            return Err(CliError::Other(format!(
                "--max-field-deg {d} must be in [0, 90)"
            )))
        }
        None => {}
    }
    let own = lens.fields_deg.iter().fold(0.0, |m: f64, a| m.max(a.abs()));
    if own > 0.0 {
        return Ok(own);
    }
    if let Some(d) = field_deg_from_file_name(path) {
        eprintln!(
            "camsim: {}: the file has no field angles; maximum field {d}° taken from its name",
            path.display()
        );
        return Ok(d);
    }
    if needed {
        return Err(CliError::input(
            path,
            "the lens file states no field angles (pbrt .dat / ISET lens files have none): \
             give the maximum field with --max-field-deg",
        ));
    }
    Ok(0.0)
}

/// A field angle stated in a file name as a dot-separated `<number>deg` part (ISETCam lens
/// names, e.g. `wide.56deg.50.0mm.json` → 56); `None` if there is none or it is not in (0, 90).
pub fn field_deg_from_file_name(path: &Path) -> Option<f64> {
    let name = path.file_name()?.to_string_lossy().to_string();
    name.split(['.', '_'])
        .filter_map(|part| part.strip_suffix("deg")?.parse::<f64>().ok())
        .find(|d| *d > 0.0 && *d < 90.0)
}

fn field_angle(fraction: f64, max_deg: f64) -> Result<f64, CliError> {
    let a = fraction * max_deg;
    if !(fraction.is_finite() && a.abs() < 90.0) {
        return Err(CliError::Other(format!(
            "--field-fraction {fraction} gives a field angle of {a}° (must be below 90°)"
        )));
    }
    Ok(a)
}

fn check_wavelength(w: f64) -> Result<f64, CliError> {
    if w.is_finite() && w > 0.0 {
        Ok(w)
    } else {
        Err(CliError::Other(format!(
            "--wavelength-nm {w} must be a positive number"
        )))
    }
}

/// RGB of a wavelength for plots (rough spectral colour).
fn wavelength_rgb(w: f64) -> [u8; 3] {
    if w < 450.0 {
        [110, 0, 200]
    } else if w < 500.0 {
        [0, 70, 255]
    } else if w < 570.0 {
        [0, 160, 0]
    } else if w < 600.0 {
        [220, 170, 0]
    } else {
        [220, 0, 0]
    }
}

/// Print `text` and a newline on stdout; a closed pipe (e.g. `| head`) is not an error.
fn print_out(text: &str) -> Result<(), CliError> {
    use std::io::Write;
    let mut o = std::io::stdout().lock();
    match writeln!(o, "{text}").and_then(|_| o.flush()) {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => {
            Err(CliError::Other(format!("stdout: {e}")))
        }
        _ => Ok(()),
    }
}

fn finite_or_null(x: f64) -> Value {
    if x.is_finite() {
        json!(x)
    } else {
        Value::Null
    }
}

/// Options of [`lens_report`].
#[derive(Debug, Clone)]
pub struct ReportOptions {
    /// Field fractions.
    pub field_fractions: Vec<f64>,
    /// Wavelengths as written (keys of `rms_spot_um`).
    pub wavelengths: Vec<String>,
    /// Maximum field override (degrees).
    pub max_field_deg: Option<f64>,
    /// Spot pupil grid per side.
    pub grid: usize,
    /// MTF frequencies (cycles/mm).
    pub mtf_lp_mm: Vec<f64>,
    /// MTF image plane.
    pub mtf_focus: MtfFocus,
    /// Clip at semi-diameters.
    pub clip: bool,
}

/// Image points (mm) of one wavelength: (wavelength nm, points).
pub type WavelengthSpot = (f64, Vec<[f64; 2]>);

/// Ray paths (z, y) of one field and their SVG colour.
type RayFanPaths<'a> = (Vec<Vec<(f64, f64)>>, &'a str);

/// What the report figures need besides the JSON.
pub struct ReportData {
    /// The report JSON (schema in the module docs of `lens report`).
    pub json: Value,
    /// Dense distortion curve (field °, %).
    pub distortion_curve: Vec<(f64, f64)>,
    /// Spot points per field: (field °, [(wavelength, points mm)]).
    pub spots: Vec<(f64, Vec<WavelengthSpot>)>,
    /// Best-focus shift used for the MTF (mm).
    pub mtf_focus_shift_mm: f64,
    /// Lens name.
    pub name: String,
    /// Dense field-curvature curves: (wavelength nm, [(field °, sagittal mm, tangential mm)]).
    pub field_curvature_curve: Vec<(f64, Vec<(f64, f64, f64)>)>,
    /// Huygens PSF of each report field at the primary wavelength: (field °, PSF).
    pub huygens: Vec<(f64, HuygensPsf)>,
}

/// Samples per side of the report's Huygens PSFs.
pub const HUYGENS_SAMPLES: usize = 49;
/// Largest pupil grid of the report's Huygens PSFs.
pub const HUYGENS_MAX_PUPIL: usize = 96;

/// The report's Huygens PSF of field `th` at `w`: a `HUYGENS_SAMPLES`² window about the chief
/// ray of half-width max(4 λN_w, |centroid − chief| + 2.5 × RMS spot radius) on the lens's image
/// plane, from the pupil grid whose period λN_w(n − 1) holds every traced ray's landing point
/// (so no ray's wavelet aliases into the window), at most `HUYGENS_MAX_PUPIL` and at least 32.
/// Returns the PSF, the pupil grid used and whether it met that condition.
pub fn report_huygens(
    lens: &LensPrescription,
    th: f64,
    w: f64,
    clipping: Clipping,
) -> Result<(HuygensPsf, usize, bool), camsim_lens::LensError> {
    let fo = lens.first_order(w)?;
    let lam_nw = w * 1e-6 * fo.working_f_number;
    let fan = lens.ray_fan(th, w, w, &pupil_grid(21), clipping)?;
    let spot = fan.spot(0.0);
    let chief = lens
        .trace(&fan.aim.ray(0.0, 0.0), w, Clipping::None)
        .map(|r| [r.image_mm[0], r.image_mm[1]])
        .unwrap_or(spot.centroid_mm);
    let off = (spot.centroid_mm[0] - chief[0]).hypot(spot.centroid_mm[1] - chief[1]);
    let (geo, extent) = if spot.points_mm.is_empty() {
        (0.0, 0.0)
    } else {
        let far = spot
            .points_mm
            .iter()
            .map(|p| (p[0] - chief[0]).hypot(p[1] - chief[1]))
            .fold(0.0, f64::max);
        (off + 2.5 * spot.rms_radius_mm, far)
    };
    let half = geo.max(4.0 * lam_nw);
    let need = lens.huygens_pupil_samples(w, half.max(extent + 2.0 * lam_nw))?;
    let pupil_n = need.clamp(32, HUYGENS_MAX_PUPIL);
    let win = HuygensWindow {
        n: HUYGENS_SAMPLES,
        sample_mm: 2.0 * half / (HUYGENS_SAMPLES - 1) as f64,
        offset_mm: [0.0, 0.0],
    };
    let h = lens.huygens_psf(th, w, pupil_n, &win, clipping)?;
    Ok((h, pupil_n, need <= HUYGENS_MAX_PUPIL))
}

/// Centroid offset from the centre sample and RMS radius about the centroid (mm) of a PSF.
fn psf_moments(p: &camsim_lens::analysis::Psf) -> ([f64; 2], f64) {
    let n = p.n;
    let c = (n / 2) as f64;
    let (mut sx, mut sy, mut t) = (0.0, 0.0, 0.0);
    for (k, v) in p.values.iter().enumerate() {
        sx += (k % n) as f64 * v;
        sy += (k / n) as f64 * v;
        t += v;
    }
    if t <= 0.0 {
        return ([f64::NAN; 2], f64::NAN);
    }
    let (mx, my) = (sx / t, sy / t);
    let r2: f64 = p
        .values
        .iter()
        .enumerate()
        .map(|(k, v)| v * (((k % n) as f64 - mx).powi(2) + ((k / n) as f64 - my).powi(2)))
        .sum::<f64>()
        / t;
    (
        [(mx - c) * p.sample_mm, (my - c) * p.sample_mm],
        r2.sqrt() * p.sample_mm,
    )
}

/// Compute the `lens report` numbers of `lens` (read from `path`, which errors name).
pub fn lens_report(
    lens: &LensPrescription,
    path: &Path,
    opts: &ReportOptions,
) -> Result<ReportData, CliError> {
    let lens = focused(lens, path)?;
    let lerr = |e: camsim_lens::LensError| CliError::input(path, e);
    if opts.grid == 0 {
        return Err(CliError::Other("--grid must be ≥ 1".into()));
    }
    let wls: Vec<f64> = opts
        .wavelengths
        .iter()
        .map(|s| {
            s.trim()
                .parse::<f64>()
                .map_err(|_| CliError::Other(format!("--wavelength-nm: '{s}' is not a number")))
                .and_then(check_wavelength)
        })
        .collect::<Result<_, _>>()?;
    if wls.is_empty() {
        return Err(CliError::Other("--wavelength-nm: no wavelengths".into()));
    }
    let max_deg = max_field_deg(
        &lens,
        opts.max_field_deg,
        path,
        opts.field_fractions.iter().any(|f| *f != 0.0),
    )?;
    let primary = lens.primary_nm;
    let fo = lens.first_order(primary).map_err(lerr)?;
    let clipping = if opts.clip {
        Clipping::SemiDiameters
    } else {
        Clipping::None
    };
    // Distortion / lateral colour: wavelengths [F, C] so that `distortion` returns F − C.
    let mut lc_lens = lens.clone();
    lc_lens.wavelengths_nm = vec![F_LINE_NM, C_LINE_NM];
    let grid = pupil_grid(opts.grid);
    let fig_grid = pupil_grid(opts.grid.min(15));
    let mut fields = Vec::new();
    let mut spots = Vec::new();
    for &frac in &opts.field_fractions {
        let th = field_angle(frac, max_deg)?;
        let d = lc_lens.distortion(th).map_err(lerr)?;
        let mut rms = Map::new();
        let mut pts = Vec::new();
        for (key, &w) in opts.wavelengths.iter().zip(&wls) {
            let fan = lens
                .ray_fan(th, w, primary, &grid, clipping)
                .map_err(lerr)?;
            let s = fan.spot(0.0);
            let v = if s.points_mm.is_empty() {
                f64::NAN
            } else {
                1000.0 * s.rms_radius_mm
            };
            rms.insert(key.trim().to_string(), finite_or_null(v));
            // The figure shows a coarser grid (≤ 15 per side) so the dots stay legible.
            let fig_pts = if opts.grid <= 15 {
                s.points_mm
            } else {
                lens.ray_fan(th, w, primary, &fig_grid, clipping)
                    .map_err(lerr)?
                    .spot(0.0)
                    .points_mm
            };
            pts.push((w, fig_pts));
        }
        // Sagittal / tangential foci (Coddington along the chief ray of each wavelength).
        let mut sag = Map::new();
        let mut tan = Map::new();
        for (key, &w) in opts.wavelengths.iter().zip(&wls) {
            let (a, b) = match lens.field_curvature(th, w) {
                Ok(fc) => (fc.sagittal_mm, fc.tangential_mm),
                Err(_) => (f64::NAN, f64::NAN),
            };
            sag.insert(key.trim().to_string(), finite_or_null(a));
            tan.insert(key.trim().to_string(), finite_or_null(b));
        }
        fields.push(json!({
            "field_fraction": frac,
            "field_deg": th,
            "chief_ray_height_mm": d.real_height_mm,
            "paraxial_image_height_mm": d.paraxial_height_mm,
            "distortion_percent": d.distortion_pct,
            "lateral_color_um": d.lateral_colour_um,
            "rms_spot_um": Value::Object(rms),
            "sagittal_focus_mm": Value::Object(sag),
            "tangential_focus_mm": Value::Object(tan),
        }));
        spots.push((th, pts));
    }
    // Dense distortion curve for the figure.
    let mut distortion_curve = Vec::new();
    if max_deg > 0.0 {
        for k in 0..=20 {
            let th = max_deg * k as f64 / 20.0;
            if let Ok(d) = lens.distortion(th) {
                distortion_curve.push((th, d.distortion_pct));
            }
        }
    }
    // The focus model (camsim_lens::focus_model): the lens as every camera focuses it, on its
    // own object distance, the merit over the report's field and wavelengths.
    let focus = lens
        .focus(&camsim_lens::FocusSpec {
            focus_distance_mm: lens.object_distance_mm,
            method: camsim_lens::FocusMethod {
                max_field_deg: Some(max_deg),
                wavelengths_nm: Some(wls.clone()),
                ..Default::default()
            },
        })
        .map_err(lerr)?;
    let focus_shift_mm = focus.image_distance_mm - focus.paraxial_image_distance_mm;
    let focus_rms_um: Vec<Value> = std::iter::once(0.0)
        .chain([0.5, 0.7, 1.0].map(|f| f * max_deg))
        .map(|th| {
            let fans: Result<Vec<_>, _> = wls
                .iter()
                .map(|&w| focus.lens.ray_fan(th, w, primary, &grid, clipping))
                .collect();
            let rms = fans
                .map(|f| 1e3 * focus.lens.polychromatic_rms_mm(&f, 0.0))
                .unwrap_or(f64::NAN);
            json!({"field_deg": th, "polychromatic_rms_spot_um": finite_or_null(rms)})
        })
        .collect();
    let focus_json = json!({
        "criterion": focus.criterion.name(),
        "motion": "unit",
        "focus_distance_mm": focus.focus_distance_mm,
        "image_distance_mm": focus.image_distance_mm,
        "paraxial_image_distance_mm": focus.paraxial_image_distance_mm,
        "image_shift_mm": focus_shift_mm,
        "group_shift_mm": focus.group_shift_mm,
        "frequency_cyc_per_mm": focus.frequency_cyc_per_mm,
        "merit_fields": focus.merit_fields.iter().map(|f| json!({"field_deg": f.0, "weight": f.1})).collect::<Vec<_>>(),
        "merit_wavelengths_nm": focus.merit_wavelengths_nm,
        "mtf_merit": focus.mtf,
        "mtf_merit_paraxial": focus.mtf_paraxial,
        "mtf_at_frequency": focus.mtf_at_frequency,
        "alias_free": focus.alias_free,
        "rms_spot": focus_rms_um,
    });
    // On-axis MTF.
    let dz = match opts.mtf_focus {
        MtfFocus::Paraxial => 0.0,
        MtfFocus::Model => focus_shift_mm,
        MtfFocus::Best | MtfFocus::BestMtf => {
            let fans: Vec<_> = wls
                .iter()
                .map(|&w| lens.ray_fan(0.0, w, primary, &grid, clipping))
                .collect::<Result<_, _>>()
                .map_err(lerr)?;
            if fans.iter().all(|f| f.rays.iter().all(Option::is_none)) {
                0.0
            } else {
                lens.best_focus_shift_mm(&fans, 0.02 * fo.efl_mm.abs())
            }
        }
    };
    let dz = if opts.mtf_focus == MtfFocus::BestMtf {
        // the plane maximising the on-axis MTF (mean over the report's frequencies ≤ 0.5 ν_cut)
        let nu_cut = 1.0 / (primary * 1e-6 * fo.working_f_number.abs());
        let mut f: Vec<f64> = opts
            .mtf_lp_mm
            .iter()
            .copied()
            .filter(|&f| f > 0.0 && f <= 0.5 * nu_cut)
            .collect();
        if f.is_empty() {
            f.push(0.25 * nu_cut);
        }
        let (lo, hi) = lens.focus_search_interval_mm(primary, dz).map_err(lerr)?;
        lens.best_focus_mtf(&MtfMerit::on_axis(primary, &f), lo, hi)
            .map_err(lerr)?
            .image_shift_mm
    } else {
        dz
    };
    let img_d = lens.image_distance_mm();
    let mtf_lens = lens.with_image_distance(img_d + dz);
    // Pupil grid set by the OPD slope (camsim_lens::focus), 64…1024 per side.
    let (wo, sampling) = mtf_lens
        .wave_optics_sampled(0.0, primary, 64, 1024, 2, &opts.mtf_lp_mm)
        .map_err(lerr)?;
    if !sampling.alias_free {
        eprintln!(
            "camsim: warning: {}: the on-axis MTF needs a {}² pupil grid for its OPD slope \
             ({:.0} waves per pupil radius); computed on {}², so it is aliased (too high)",
            path.display(),
            sampling.needed,
            sampling.max_slope_waves,
            sampling.samples
        );
    }
    let mtf: Vec<Value> = wo
        .mtf
        .iter()
        .map(|p| {
            json!({"lp_per_mm": p.freq_cyc_per_mm,
                   "mtf": finite_or_null(0.5 * (p.tangential + p.sagittal))})
        })
        .collect();
    // Dense field-curvature curves for the figure.
    let field_curvature_curve: Vec<(f64, Vec<(f64, f64, f64)>)> =
        wls.iter()
            .map(|&w| {
                let pts =
                    (0..=20)
                        .filter_map(|k| {
                            let th = max_deg * k as f64 / 20.0;
                            let fc = lens.field_curvature(th, w).ok()?;
                            (fc.sagittal_mm.is_finite() && fc.tangential_mm.is_finite())
                                .then_some((th, fc.sagittal_mm, fc.tangential_mm))
                        })
                        .collect();
                (w, pts)
            })
            .collect();
    // Huygens PSFs of the report fields at the primary wavelength, on the MTF's image plane.
    let mut huygens = Vec::new();
    let mut huygens_json = Vec::new();
    for &frac in &opts.field_fractions {
        let th = field_angle(frac, max_deg)?;
        let (h, pupil_n, alias_free) =
            report_huygens(&mtf_lens, th, primary, clipping).map_err(lerr)?;
        let (c, rms) = psf_moments(&h.psf);
        let n = h.psf.n;
        huygens_json.push(json!({
            "field_fraction": frac,
            "field_deg": th,
            "wavelength_nm": primary,
            "image_plane_shift_mm": dz,
            "samples": n,
            "sample_um": 1000.0 * h.psf.sample_mm,
            "pupil_samples": pupil_n,
            "alias_free": alias_free,
            "strehl_ratio": finite_or_null(h.strehl_ratio),
            "centroid_offset_um": [finite_or_null(1000.0 * c[0]), finite_or_null(1000.0 * c[1])],
            "rms_radius_um": finite_or_null(1000.0 * rms),
        }));
        huygens.push((th, h));
    }
    let json = json!({
        "efl_mm": fo.efl_mm,
        "bfl_mm": fo.bfl_mm,
        "f_number": fo.f_number,
        "entrance_pupil_diameter_mm": fo.entrance_pupil_diameter_mm,
        "primary_wavelength_nm": primary,
        "fields": fields,
        "mtf_on_axis": mtf,
        "mtf_image_shift_mm": dz,
        "focus": focus_json,
        "mtf_pupil_samples": sampling.samples,
        "mtf_alias_free": sampling.alias_free,
        "huygens_psf": huygens_json,
    });
    Ok(ReportData {
        json,
        distortion_curve,
        field_curvature_curve,
        huygens,
        spots,
        mtf_focus_shift_mm: dz,
        name: lens.name.clone(),
    })
}

/// Write report.json, report.html and the figures into `dir` (a staging folder); returns the
/// relative file names.
fn write_report_files(
    dir: &Path,
    lens_path: &Path,
    data: &ReportData,
    opts: &ReportOptions,
) -> Result<Vec<PathBuf>, CliError> {
    let mut files = Vec::new();
    let mut figures: Vec<(String, String)> = Vec::new();
    let j = &data.json;
    let fields = j["fields"].as_array().cloned().unwrap_or_default();
    // Distortion curve.
    let mut curve = data.distortion_curve.clone();
    if curve.is_empty() {
        curve = fields
            .iter()
            .map(|f| {
                (
                    f["field_deg"].as_f64().unwrap_or(0.0),
                    f["distortion_percent"].as_f64().unwrap_or(0.0),
                )
            })
            .collect();
    }
    plots::line_plot(
        &dir.join("distortion.png"),
        "Distortion (primary wavelength)",
        &[("distortion".to_string(), curve)],
        ("field angle (deg)", "distortion (%)"),
    )?;
    figures.push((
        "distortion.png".into(),
        "Distortion vs field angle (real vs paraxial chief-ray height)".into(),
    ));
    // RMS spot vs field per wavelength.
    let series: Vec<(String, Vec<(f64, f64)>)> = opts
        .wavelengths
        .iter()
        .map(|key| {
            let k = key.trim().to_string();
            let pts = fields
                .iter()
                .filter_map(|f| {
                    Some((
                        f["field_deg"].as_f64()?,
                        f["rms_spot_um"][k.as_str()].as_f64()?,
                    ))
                })
                .collect();
            (format!("{k} nm"), pts)
        })
        .collect();
    plots::line_plot(
        &dir.join("rms_spot.png"),
        "RMS spot radius at paraxial focus",
        &series,
        ("field angle (deg)", "RMS spot radius (µm)"),
    )?;
    figures.push((
        "rms_spot.png".into(),
        "RMS spot radius vs field, per wavelength".into(),
    ));
    // MTF.
    let mtf: Vec<(f64, f64)> = j["mtf_on_axis"]
        .as_array()
        .into_iter()
        .flatten()
        .filter_map(|p| Some((p["lp_per_mm"].as_f64()?, p["mtf"].as_f64()?)))
        .collect();
    plots::line_plot(
        &dir.join("mtf.png"),
        "On-axis MTF (primary wavelength)",
        &[("MTF".to_string(), mtf)],
        ("spatial frequency (cycles/mm)", "MTF"),
    )?;
    figures.push((
        "mtf.png".into(),
        format!(
            "On-axis diffraction MTF, image plane shifted {:+.4} mm from paraxial focus",
            data.mtf_focus_shift_mm
        ),
    ));
    // Spot diagrams.
    for (i, (th, per_wl)) in data.spots.iter().enumerate() {
        let all: Vec<[f64; 2]> = per_wl.iter().flat_map(|(_, p)| p.iter().copied()).collect();
        let n = all.len().max(1) as f64;
        let cx = all.iter().map(|p| p[0]).sum::<f64>() / n;
        let cy = all.iter().map(|p| p[1]).sum::<f64>() / n;
        let mut xs = Vec::new();
        let mut ys = Vec::new();
        let mut cs = Vec::new();
        for (w, pts) in per_wl {
            for p in pts {
                xs.push(1000.0 * (p[0] - cx));
                ys.push(1000.0 * (p[1] - cy));
                cs.push(wavelength_rgb(*w));
            }
        }
        let name = format!("spot_{i}.png");
        plots::scatter(
            &dir.join(&name),
            &format!("Spot diagram, field {th:.3}°"),
            &xs,
            &ys,
            Some(&cs),
            ("x − centroid (µm)", "y − centroid (µm)"),
            false,
        )?;
        let wl_list = per_wl
            .iter()
            .map(|(w, _)| format!("{w} nm"))
            .collect::<Vec<_>>()
            .join(", ");
        figures.push((
            name,
            format!(
                "Spot diagram at {th:.3}° ({wl_list}; blue→red by wavelength; {0}×{0} pupil grid)",
                opts.grid.min(15)
            ),
        ));
    }
    // Field curvature.
    let mut fc_series = Vec::new();
    for (w, pts) in &data.field_curvature_curve {
        fc_series.push((
            format!("S {w} nm"),
            pts.iter().map(|p| (p.1, p.0)).collect::<Vec<_>>(),
        ));
        fc_series.push((
            format!("T {w} nm"),
            pts.iter().map(|p| (p.2, p.0)).collect::<Vec<_>>(),
        ));
    }
    if fc_series.iter().any(|s| s.1.len() > 1) {
        plots::line_plot(
            &dir.join("field_curvature.png"),
            "Field curvature (sagittal S, tangential T)",
            &fc_series,
            ("focus − image plane (mm)", "field angle (deg)"),
        )?;
        figures.push((
            "field_curvature.png".into(),
            "Sagittal (S) and tangential (T) focus vs field: axial distance from the paraxial image plane (Coddington along the real chief ray)".into(),
        ));
    }
    // Huygens PSFs.
    for (i, (th, h)) in data.huygens.iter().enumerate() {
        let name = format!("huygens_psf_{i}.png");
        psf_png(&dir.join(&name), &h.psf)?;
        figures.push((
            name,
            format!(
                "Huygens PSF at {th:.3}°, {} nm: {}×{} samples of {:.3} µm about the chief ray (√ intensity, x right, y up), Strehl {:.3}",
                j["primary_wavelength_nm"].as_f64().unwrap_or(f64::NAN),
                h.psf.n,
                h.psf.n,
                1000.0 * h.psf.sample_mm,
                h.strehl_ratio
            ),
        ));
    }
    let json_text = serde_json::to_string_pretty(j).map_err(|e| CliError::Other(e.to_string()))?;
    std::fs::write(dir.join("report.json"), json_text + "\n")
        .map_err(|e| CliError::output(&dir.join("report.json"), e))?;
    // HTML.
    let mut h = String::new();
    h.push_str("<!DOCTYPE html><html lang=\"en\"><head><meta charset=\"utf-8\"><title>camsim lens report</title>");
    h.push_str("<style>body{font-family:sans-serif;max-width:1100px;margin:2em auto;color:#222}figure{display:inline-block;margin:8px;vertical-align:top}figure img{max-width:520px;border:1px solid #ccc}table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:3px 8px;text-align:right}th{background:#f3f3f3}</style></head><body>");
    h.push_str(&format!(
        "<h1>camsim lens report</h1><p>{} — <code>{}</code></p>",
        html_escape(&data.name),
        html_escape(&lens_path.display().to_string())
    ));
    h.push_str("<h2>First order</h2><table>");
    for (k, label) in [
        ("efl_mm", "EFL (mm)"),
        ("bfl_mm", "BFL (mm)"),
        ("f_number", "F-number (EFL/EPD)"),
        ("entrance_pupil_diameter_mm", "entrance-pupil diameter (mm)"),
        ("primary_wavelength_nm", "primary wavelength (nm)"),
    ] {
        h.push_str(&format!(
            "<tr><th style=\"text-align:left\">{label}</th><td>{:.6}</td></tr>",
            j[k].as_f64().unwrap_or(f64::NAN)
        ));
    }
    h.push_str("</table>");
    h.push_str("<h2>Fields</h2><table><tr><th>fraction</th><th>angle (°)</th><th>chief-ray height (mm)</th><th>paraxial height (mm)</th><th>distortion (%)</th><th>lateral colour F−C (µm)</th>");
    for key in &opts.wavelengths {
        h.push_str(&format!(
            "<th>RMS spot {} nm (µm)</th>",
            html_escape(key.trim())
        ));
    }
    h.push_str("</tr>");
    for f in &fields {
        let g = |k: &str, p: usize| {
            f[k].as_f64()
                .map(|x| format!("{x:.p$}"))
                .unwrap_or_else(|| "–".into())
        };
        h.push_str(&format!(
            "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td>",
            g("field_fraction", 3),
            g("field_deg", 4),
            g("chief_ray_height_mm", 6),
            g("paraxial_image_height_mm", 6),
            g("distortion_percent", 4),
            g("lateral_color_um", 3)
        ));
        for key in &opts.wavelengths {
            let v = f["rms_spot_um"][key.trim()]
                .as_f64()
                .map(|x| format!("{x:.3}"))
                .unwrap_or_else(|| "–".into());
            h.push_str(&format!("<td>{v}</td>"));
        }
        h.push_str("</tr>");
    }
    h.push_str("</table>");
    h.push_str("<p>Conventions: lens refocused at the paraxial focus of the primary wavelength; chief ray aimed at the stop centre at the primary wavelength; distortion = 100·(real − paraxial)/paraxial chief-ray height; lateral colour = |y(486.1 nm)| − |y(656.3 nm)| of the primary-aimed chief ray; RMS spot about the centroid, square pupil grid clipped to the unit disc on the paraxial entrance pupil");
    h.push_str(if opts.clip {
        ", rays clipped at the semi-diameters"
    } else {
        ", no clipping at the semi-diameters"
    });
    h.push_str(&format!(
        ". On-axis MTF: FFT of the pupil function ({}² OPD grid set by the OPD slope{}, 2× padding) at the primary wavelength, image plane shifted {:+.5} mm from the paraxial focus ({}).</p>",
        data.json["mtf_pupil_samples"],
        if data.json["mtf_alias_free"].as_bool() == Some(false) {
            "; too coarse for this lens: aliased"
        } else {
            ""
        },
        data.mtf_focus_shift_mm,
        match opts.mtf_focus {
            MtfFocus::Best => "best focus: minimum on-axis polychromatic RMS spot",
            MtfFocus::BestMtf => "best focus: maximum on-axis MTF",
            MtfFocus::Paraxial => "paraxial focus",
            MtfFocus::Model => "the focus model's plane: best polychromatic MTF over the field",
        }
    ));
    h.push_str("<h2>Field curvature</h2><table><tr><th>angle (°)</th>");
    for key in &opts.wavelengths {
        h.push_str(&format!(
            "<th>sagittal {0} nm (mm)</th><th>tangential {0} nm (mm)</th>",
            html_escape(key.trim())
        ));
    }
    h.push_str("</tr>");
    for f in &fields {
        h.push_str(&format!(
            "<tr><td>{:.4}</td>",
            f["field_deg"].as_f64().unwrap_or(f64::NAN)
        ));
        for key in &opts.wavelengths {
            for k in ["sagittal_focus_mm", "tangential_focus_mm"] {
                let v = f[k][key.trim()]
                    .as_f64()
                    .map(|x| format!("{x:.5}"))
                    .unwrap_or_else(|| "–".into());
                h.push_str(&format!("<td>{v}</td>"));
            }
        }
        h.push_str("</tr>");
    }
    h.push_str("</table><p>Axial distance from the paraxial image plane to the sagittal and tangential foci of the thin pencils about the real chief ray of each wavelength (Coddington's equations; negative = towards the lens).</p>");
    h.push_str("<h2>Huygens PSF (primary wavelength)</h2><table><tr><th>angle (°)</th><th>samples</th><th>pitch (µm)</th><th>pupil grid</th><th>alias-free</th><th>Strehl</th><th>centroid offset x, y (µm)</th><th>RMS radius (µm)</th></tr>");
    for p in j["huygens_psf"].as_array().into_iter().flatten() {
        let f = |v: &Value, d: usize| {
            v.as_f64()
                .map(|x| format!("{x:.d$}"))
                .unwrap_or_else(|| "–".into())
        };
        h.push_str(&format!(
            "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}, {}</td><td>{}</td></tr>",
            f(&p["field_deg"], 4),
            p["samples"],
            f(&p["sample_um"], 4),
            p["pupil_samples"],
            p["alias_free"],
            f(&p["strehl_ratio"], 4),
            f(&p["centroid_offset_um"][0], 3),
            f(&p["centroid_offset_um"][1], 3),
            f(&p["rms_radius_um"], 3)
        ));
    }
    h.push_str(&format!("</table><p>Huygens–Fresnel sum of secondary wavelets from the real rays on the exit-pupil reference sphere (camsim_lens::huygens), on the image plane of the MTF below (shifted {:+.5} mm from the paraxial focus), window centred on the chief ray; Strehl ratio at the chief-ray point. Alias-free: the period λN<sub>w</sub>(n − 1) of the n² pupil sum holds every ray's landing point (else n was capped at {}).</p>", data.mtf_focus_shift_mm, HUYGENS_MAX_PUPIL));
    h.push_str("<h2>On-axis MTF</h2><table><tr><th>cycles/mm</th><th>MTF</th></tr>");
    for p in j["mtf_on_axis"].as_array().into_iter().flatten() {
        h.push_str(&format!(
            "<tr><td>{}</td><td>{:.4}</td></tr>",
            p["lp_per_mm"].as_f64().unwrap_or(f64::NAN),
            p["mtf"].as_f64().unwrap_or(f64::NAN)
        ));
    }
    h.push_str("</table><h2>Figures</h2>");
    for (file, caption) in &figures {
        h.push_str(&format!(
            "<figure><img src=\"{0}\" alt=\"{1}\"><figcaption>{1}</figcaption></figure>",
            html_escape(file),
            html_escape(caption)
        ));
    }
    h.push_str(
        "<h2>Files</h2><ul><li><a href=\"report.json\">report.json</a></li></ul></body></html>\n",
    );
    std::fs::write(dir.join("report.html"), h)
        .map_err(|e| CliError::output(&dir.join("report.html"), e))?;
    files.push(PathBuf::from("report.json"));
    files.push(PathBuf::from("report.html"));
    files.extend(figures.iter().map(|(f, _)| PathBuf::from(f)));
    Ok(files)
}

/// A PSF as a colour-mapped PNG (√ of the intensity relative to the peak, so faint structure
/// shows; row 0 at the top is +y), each sample enlarged to at least 320 pixels overall.
fn psf_png(path: &Path, psf: &camsim_lens::analysis::Psf) -> Result<(), CliError> {
    let n = psf.n.max(1);
    let zoom = 320usize.div_ceil(n).max(1);
    let side = n * zoom;
    let peak = psf.values.iter().cloned().fold(0.0, f64::max);
    let mut rgb = vec![255u8; side * side * 3];
    for r in 0..side {
        let iy = n - 1 - r / zoom;
        for c in 0..side {
            let ix = c / zoom;
            let v = if peak > 0.0 {
                (psf.values[iy * n + ix] / peak).max(0.0).sqrt()
            } else {
                0.0
            };
            // Dark blue → red → yellow → white.
            let (cr, cg, cb) = if v < 1.0 / 3.0 {
                let t = 3.0 * v;
                (0.5 * t, 0.0, 0.3 + 0.3 * t)
            } else if v < 2.0 / 3.0 {
                let t = 3.0 * v - 1.0;
                (0.5 + 0.5 * t, 0.6 * t, 0.6 * (1.0 - t))
            } else {
                let t = 3.0 * v - 2.0;
                (1.0, 0.6 + 0.4 * t, t)
            };
            let o = (r * side + c) * 3;
            rgb[o] = (255.0 * cr).round() as u8;
            rgb[o + 1] = (255.0 * cg).round() as u8;
            rgb[o + 2] = (255.0 * cb).round() as u8;
        }
    }
    plots::rgb8_png(path, &rgb, side, side)
}

/// Smallest square pupil grid whose disc-clipped sample holds at least `n` rays.
pub fn grid_for_rays(n: usize) -> usize {
    let mut g = ((4.0 * n as f64 / std::f64::consts::PI).sqrt().floor() as usize).max(1);
    while pupil_grid(g).len() < n {
        g += 1;
    }
    while g > 1 && pupil_grid(g - 1).len() >= n {
        g -= 1;
    }
    g
}

/// Run one `camsim lens` subcommand (results on stdout, progress on stderr).
pub fn run_lens(cmd: LensCommand) -> Result<(), CliError> {
    match cmd {
        LensCommand::Report {
            lens,
            json,
            field_fraction,
            wavelength_nm,
            out,
            max_field_deg,
            grid,
            mtf_lp_mm,
            mtf_focus,
            clip,
        } => {
            if field_fraction.is_empty() {
                return Err(CliError::Other("--field-fraction: no fields".into()));
            }
            if let Some(f) = mtf_lp_mm.iter().find(|f| !(f.is_finite() && **f >= 0.0)) {
                return Err(CliError::Other(format!(
                    "--mtf-lp-mm {f}: must be a finite frequency ≥ 0 (cycles/mm)"
                )));
            }
            // Ray grids: grid² rays per field and wavelength.
            let traces = (grid as f64).powi(2)
                * field_fraction.len() as f64
                * wavelength_nm.len().max(3) as f64;
            crate::budget::check_memory(
                None,
                "--grid",
                (grid as f64).powi(2) * 64.0,
                &format!("{grid}² pupil rays × 64 bytes"),
            )?;
            crate::budget::check_work(
                None,
                "--grid",
                traces,
                &format!("{grid}² rays × fields × wavelengths"),
            )?;
            let opts = ReportOptions {
                field_fractions: field_fraction,
                wavelengths: wavelength_nm,
                max_field_deg,
                grid,
                mtf_lp_mm,
                mtf_focus,
                clip,
            };
            let data = lens_report(&lens.load()?, &lens.path, &opts)?;
            let out = match (out, json) {
                (Some(o), _) => Some(o),
                (None, false) => Some(PathBuf::from("out/lens")),
                (None, true) => None,
            };
            if let Some(out) = &out {
                with_staging(out, |dir| write_report_files(dir, &lens.path, &data, &opts))?;
            }
            if json {
                print_out(
                    &serde_json::to_string_pretty(&data.json)
                        .map_err(|e| CliError::Other(e.to_string()))?,
                )?;
            }
            if let Some(out) = &out {
                eprintln!("camsim: wrote {} (open report.html)", out.display());
            }
            Ok(())
        }
        LensCommand::Spot {
            lens: la,
            field_fraction,
            wavelength_nm,
            rays,
            json,
            max_field_deg: mfd,
            defocus_mm,
            clip,
        } => {
            let w = check_wavelength(wavelength_nm)?;
            if rays == 0 {
                return Err(CliError::Other("--rays must be ≥ 1".into()));
            }
            crate::budget::check_memory(
                None,
                "--rays",
                rays as f64 * 96.0,
                &format!("{rays} rays × 96 bytes (pupil point, spot point)"),
            )?;
            crate::budget::check_work(None, "--rays", rays as f64, "rays traced")?;
            if !defocus_mm.is_finite() {
                return Err(CliError::Other("--defocus-mm must be finite".into()));
            }
            let path = la.path.clone();
            let lens = focused(&la.load()?, &path)?;
            let th = field_angle(
                field_fraction,
                max_field_deg(&lens, mfd, &path, field_fraction != 0.0)?,
            )?;
            let g = grid_for_rays(rays);
            let clipping = if clip {
                Clipping::SemiDiameters
            } else {
                Clipping::None
            };
            let fan = lens
                .ray_fan(th, w, lens.primary_nm, &pupil_grid(g), clipping)
                .map_err(|e| CliError::input(&path, e))?;
            let s = fan.spot(defocus_mm);
            let n_ok = s.points_mm.len();
            let (rms, cx, cy) = if n_ok == 0 {
                (f64::NAN, f64::NAN, f64::NAN)
            } else {
                (1000.0 * s.rms_radius_mm, s.centroid_mm[0], s.centroid_mm[1])
            };
            if json {
                let v = json!({
                    "field_fraction": field_fraction,
                    "field_deg": th,
                    "wavelength_nm": w,
                    "defocus_mm": defocus_mm,
                    "pupil_grid": g,
                    "rays_launched": s.n_launched,
                    "rays_transmitted": n_ok,
                    "rms_radius_um": finite_or_null(rms),
                    "centroid_mm": [finite_or_null(cx), finite_or_null(cy)],
                    "points_mm": s.points_mm,
                });
                print_out(&serde_json::to_string(&v).map_err(|e| CliError::Other(e.to_string()))?)?;
            } else {
                print_out(&format!(
                    "field {th:.4}° at {w} nm: RMS radius {rms:.4} µm, centroid ({cx:.6}, {cy:.6}) mm, {n_ok} of {} rays transmitted",
                    s.n_launched
                ))?;
            }
            Ok(())
        }
        LensCommand::FieldModel {
            lens: la,
            out,
            fields,
            wavelengths_nm,
            max_field_deg: mfd,
            geometric,
            psf_n,
            psf_pitch_um,
            object_distances_mm,
            focus_distance_mm,
            pupil_samples,
        } => {
            let distance = |flag: &str, s: &str| -> Result<Option<f64>, CliError> {
                let t = s.trim();
                if t.eq_ignore_ascii_case("inf") || t.eq_ignore_ascii_case("infinity") {
                    return Ok(None);
                }
                match t.parse::<f64>() {
                    Ok(d) if d.is_finite() && d > 0.0 => Ok(Some(d)),
                    _ => Err(CliError::Other(format!(
                        "{flag} '{s}': expected a distance in mm > 0 or inf"
                    ))),
                }
            };
            let distances: Vec<Option<f64>> = object_distances_mm
                .iter()
                .map(|s| distance("--object-distances-mm", s))
                .collect::<Result<_, _>>()?;
            let focus = match &focus_distance_mm {
                None => camsim_lens::Focus::Prescription,
                Some(s) => camsim_lens::Focus::At(distance("--focus-distance-mm", s)?),
            };
            if pupil_samples < 2 || pupil_samples > 1024 {
                return Err(CliError::Other(format!(
                    "--pupil-samples {pupil_samples} must be in 2..=1024"
                )));
            }
            if let Some(ws) = &wavelengths_nm {
                if ws.is_empty() {
                    return Err(CliError::Other("--wavelengths-nm: no wavelengths".into()));
                }
                for w in ws {
                    check_wavelength(*w)?;
                }
            }
            if fields < 2 {
                return Err(CliError::Other(format!("--fields {fields} must be ≥ 2")));
            }
            {
                // One psf_n² f64 PSF (and its FFT working copy, complex) per field,
                // wavelength and object distance.
                let n_w = wavelengths_nm.as_ref().map_or(31, |w| w.len()) as f64;
                let n_d = distances.len().max(1) as f64;
                let psfs = fields as f64 * n_w * n_d;
                let psf_side = psf_n.max(pupil_samples) as f64;
                crate::budget::check_memory(
                    None,
                    "--psf-n",
                    psfs * psf_side * psf_side * 8.0 + 16.0 * 4.0 * psf_side * psf_side,
                    &format!("{psfs} PSFs of {psf_n}² samples"),
                )?;
                crate::budget::check_work(
                    None,
                    "--psf-n",
                    psfs * (psf_side * psf_side).max((pupil_samples as f64).powi(2) * psf_n as f64),
                    &format!("{psfs} PSFs of {psf_n}² samples"),
                )?;
            }
            let path = la.path.clone();
            let lens = la.load()?;
            let max_deg = max_field_deg(&lens, mfd, &path, true)?;
            if max_deg <= 0.0 {
                return Err(CliError::input(
                    &path,
                    "the lens has no off-axis field (fields_deg); give --max-field-deg",
                ));
            }
            let opts = FieldModelOptions {
                n_fields: fields,
                max_field_deg: Some(max_deg),
                wavelengths_nm,
                kind: if geometric {
                    PsfKind::Geometric
                } else {
                    PsfKind::Wave
                },
                psf_n,
                psf_pitch_um,
                pupil_n: pupil_samples,
                focus,
                object_distances_mm: distances,
                ..FieldModelOptions::default()
            };
            let m = FieldModel::compute(&lens, &opts).map_err(|e| CliError::input(&path, e))?;
            if m.aliased_entries > 0 {
                eprintln!(
                    "camsim: warning: {}: {} PSF entries need a pupil grid finer than {}² for \
                     their OPD slope; they are aliased (use --geometric for such a lens)",
                    path.display(),
                    m.aliased_entries,
                    camsim_lens::field_model::MAX_WAVE_PUPIL_N
                );
            }
            if let Some(parent) = out.parent().filter(|p| !p.as_os_str().is_empty()) {
                camsim_core::cleanup::create_dir_all(parent)
                    .map_err(|e| CliError::output(parent, e))?;
            }
            camsim_core::exr_io::write_atomically(&out, |tmp| {
                m.save(tmp).map_err(|e| CliError::output(&out, e))
            })
            .map_err(|e| match e {
                CliError::Output { .. } => e,
                e => CliError::output(&out, e),
            })?;
            let show = |d: Option<f64>| d.map_or("inf".to_string(), |d| format!("{d}"));
            eprintln!(
                "camsim: wrote {} ({} fields to {:.3}°, {} wavelengths, object distances [{}] mm, focused on {} mm, {}×{} PSFs at {} µm)",
                out.display(),
                m.paraxial_height_mm.len(),
                max_deg,
                m.wavelengths_nm.len(),
                m.object_distances_mm()
                    .iter()
                    .map(|d| show(*d))
                    .collect::<Vec<_>>()
                    .join(", "),
                show(m.focus_distance_mm),
                m.psf_n,
                m.psf_n,
                m.psf_pitch_um
            );
            Ok(())
        }
        LensCommand::Draw {
            lens: la,
            out,
            rays,
            max_field_deg: mfd,
        } => {
            let path = la.path.clone();
            let lens = focused(&la.load()?, &path)?;
            let max_deg = max_field_deg(&lens, mfd, &path, false)?;
            let svg = draw_svg(&lens, max_deg, rays.clamp(1, 101))
                .map_err(|e| CliError::input(&path, e))?;
            if let Some(parent) = out.parent().filter(|p| !p.as_os_str().is_empty()) {
                camsim_core::cleanup::create_dir_all(parent)
                    .map_err(|e| CliError::output(parent, e))?;
            }
            camsim_core::exr_io::write_atomically(&out, |tmp| std::fs::write(tmp, &svg))
                .map_err(|e| CliError::output(&out, e))?;
            eprintln!("camsim: wrote {}", out.display());
            Ok(())
        }
        LensCommand::Psf {
            lens: la,
            field_fraction,
            wavelength_nm,
            out,
            max_field_deg: mfd,
            pupil_samples,
            pad,
            defocus_mm,
            method,
            samples,
            sample_um,
        } => {
            let w = check_wavelength(wavelength_nm)?;
            if method == PsfMethod::Fft && (samples.is_some() || sample_um.is_some()) {
                return Err(CliError::Other(
                    "--samples and --sample-um apply to --method huygens".into(),
                ));
            }
            if let Some(n) = samples {
                if n == 0 || n > 2049 {
                    return Err(CliError::Other(format!(
                        "--samples {n} must be in 1..=2049"
                    )));
                }
            }
            if let Some(p) = sample_um {
                if !(p.is_finite() && p > 0.0) {
                    return Err(CliError::Other(format!("--sample-um {p} must be > 0")));
                }
            }
            let ext = out
                .extension()
                .map(|e| e.to_string_lossy().to_ascii_lowercase())
                .unwrap_or_default();
            if ext != "png" && ext != "exr" {
                return Err(CliError::output(
                    &out,
                    "the output must end in .png or .exr",
                ));
            }
            if pupil_samples < 2 || pad == 0 || pupil_samples * pad > 4096 {
                return Err(CliError::Other(
                    "--pupil-samples must be ≥ 2, --pad ≥ 1 and their product ≤ 4096".into(),
                ));
            }
            if !defocus_mm.is_finite() {
                return Err(CliError::Other("--defocus-mm must be finite".into()));
            }
            let path = la.path.clone();
            let lens = focused(&la.load()?, &path)?;
            let th = field_angle(
                field_fraction,
                max_field_deg(&lens, mfd, &path, field_fraction != 0.0)?,
            )?;
            let d = lens.image_distance_mm();
            let lens = lens.with_image_distance(d + defocus_mm);
            let (m, sample_mm, mut v, extra) = match method {
                PsfMethod::Fft => {
                    let wo = lens
                        .wave_optics(th, w, pupil_samples, pad, &[])
                        .map_err(|e| CliError::input(&path, e))?;
                    let m = wo.psf.n;
                    // The FFT PSF is point-reflected with respect to the image plane (see
                    // camsim_lens::field_model); reflect it about the centre sample (m/2, m/2)
                    // so x, y grow with the column / row index like image-plane coordinates.
                    let mut v = vec![0.0f64; m * m];
                    for iy in 0..m {
                        for ix in 0..m {
                            v[iy * m + ix] = wo.psf.values[((m - iy) % m) * m + (m - ix) % m];
                        }
                    }
                    let extra = json!({"method": "fft", "pad": pad,
                                       "opd_rms_waves": finite_or_null(wo.opd.rms_waves)});
                    (m, wo.psf.sample_mm, v, extra)
                }
                PsfMethod::Huygens => {
                    let nw = lens
                        .first_order(w)
                        .map_err(|e| CliError::input(&path, e))?
                        .working_f_number;
                    let n = samples.unwrap_or(129);
                    let win = HuygensWindow {
                        n,
                        sample_mm: sample_um.map_or(w * 1e-6 * nw / 4.0, |p| p * 1e-3),
                        offset_mm: [0.0, 0.0],
                    };
                    let h = lens
                        .huygens_psf(th, w, pupil_samples, &win, Clipping::None)
                        .map_err(|e| CliError::input(&path, e))?;
                    let extra = json!({"method": "huygens",
                                       "strehl_ratio": finite_or_null(h.strehl_ratio),
                                       "chief_ray_mm": h.chief_mm});
                    (n, win.sample_mm, h.psf.values, extra)
                }
            };
            let sum: f64 = v.iter().sum();
            if !(sum.is_finite() && sum > 0.0) {
                return Err(CliError::input(
                    &path,
                    "no ray reaches the image (empty PSF)",
                ));
            }
            v.iter_mut().for_each(|x| *x /= sum);
            if let Some(parent) = out.parent().filter(|p| !p.as_os_str().is_empty()) {
                camsim_core::cleanup::create_dir_all(parent)
                    .map_err(|e| CliError::output(parent, e))?;
            }
            let peak = v.iter().cloned().fold(0.0, f64::max);
            if ext == "exr" {
                let plane = camsim_core::image::Plane {
                    rows: m,
                    cols: m,
                    data: v.iter().map(|&x| x as f32).collect(),
                };
                camsim_core::exr_io::write_single_channel_exr(&out, "Y", &plane)
                    .map_err(|e| CliError::output(&out, e))?;
            } else {
                let rgb: Vec<u8> = v
                    .iter()
                    .flat_map(|&x| {
                        let g = (255.0 * x / peak).round().clamp(0.0, 255.0) as u8;
                        [g, g, g]
                    })
                    .collect();
                plots::rgb8_png(&out, &rgb, m, m)?;
            }
            let mut summary = json!({
                "file": out.display().to_string(),
                "field_deg": th,
                "wavelength_nm": w,
                "samples": m,
                "sample_pitch_um": 1000.0 * sample_mm,
                "centre_index": m / 2,
                "peak": peak,
                "pupil_samples": pupil_samples,
            });
            if let (Some(o), Some(e)) = (summary.as_object_mut(), extra.as_object()) {
                o.extend(e.clone());
            }
            print_out(
                &serde_json::to_string_pretty(&summary)
                    .map_err(|e| CliError::Other(e.to_string()))?,
            )?;
            Ok(())
        }
    }
}

/// Points (z, y) of a meridional ray at the object-side start, every surface and the image.
fn ray_path(
    lens: &LensPrescription,
    ray: &camsim_lens::Ray,
    wavelength_nm: f64,
) -> Option<Vec<(f64, f64)>> {
    use camsim_lens::trace::{intersect, normal, refract};
    let z = lens.vertex_z_mm();
    let mut r = *ray;
    let mut pts = vec![(r.origin_mm[2], r.origin_mm[1])];
    let mut n1 = 1.0;
    for (j, s) in lens.surfaces.iter().enumerate() {
        let (_, q) = intersect(s, z[j], &r)?;
        pts.push((q[2], q[1]));
        let n2 = s.medium.index(wavelength_nm);
        let nrm = normal(s, [q[0], q[1], q[2] - z[j]])?;
        let d = refract(r.direction, nrm, n1, n2)?;
        r = camsim_lens::Ray {
            origin_mm: q,
            direction: d,
            opl_mm: 0.0,
        };
        n1 = n2;
    }
    let zi = z[lens.surfaces.len()];
    if r.direction[2] <= 0.0 {
        return None;
    }
    let t = (zi - r.origin_mm[2]) / r.direction[2];
    pts.push((zi, r.origin_mm[1] + t * r.direction[1]));
    Some(pts)
}

/// SVG of the meridional section: surfaces (sag profiles over their semi-diameters), element
/// edges, the stop, the image plane and ray fans of the axis and the maximum field.
pub fn draw_svg(
    lens: &LensPrescription,
    max_field_deg: f64,
    rays: usize,
) -> Result<String, camsim_lens::LensError> {
    if lens.has_folds() {
        return Err(camsim_lens::LensError::Prescription(
            "drawing a lens with mirrors or coordinate breaks is not supported".into(),
        ));
    }
    let primary = lens.primary_nm;
    let fo = lens.first_order(primary)?;
    let z = lens.vertex_z_mm();
    let ns = lens.surfaces.len();
    let mut fans: Vec<RayFanPaths> = Vec::new();
    let mut fields = vec![(0.0, "#1f5fd6")];
    if max_field_deg > 0.0 {
        fields.push((max_field_deg, "#d62f1f"));
    }
    for (th, colour) in fields {
        let aim = lens.aim_field(th, primary, &fo)?;
        let mut paths = Vec::new();
        for k in 0..rays {
            let py = if rays == 1 {
                0.0
            } else {
                -1.0 + 2.0 * k as f64 / (rays - 1) as f64
            };
            if let Some(mut p) = ray_path(lens, &aim.ray(0.0, py), primary) {
                // start the drawing one EPD in front of the first vertex
                let z0 = -(fo.entrance_pupil_diameter_mm.max(1.0));
                let (za, ya) = p[0];
                let (zb, yb) = p[1];
                if zb != za && za < z0 {
                    p[0] = (z0, ya + (yb - ya) * (z0 - za) / (zb - za));
                }
                paths.push(p);
            }
        }
        fans.push((paths, colour));
    }
    // Semi-diameters for drawing.
    let sd: Vec<f64> = (0..ns)
        .map(|j| {
            lens.surfaces[j].semi_diameter_mm.unwrap_or_else(|| {
                let m = fans
                    .iter()
                    .flat_map(|(ps, _)| ps.iter().map(move |p| p[j + 1].1.abs()))
                    .fold(fo.entrance_pupil_diameter_mm / 2.0, f64::max);
                1.05 * m
            })
        })
        .collect();
    let profile = |j: usize| -> Vec<(f64, f64)> {
        let s = &lens.surfaces[j];
        let mut h = sd[j];
        // stay inside the conic's domain
        while h > 0.0 && s.sag_mm(h * h).is_none() {
            h *= 0.98;
        }
        (0..=40)
            .map(|i| {
                let y = -h + 2.0 * h * i as f64 / 40.0;
                (z[j] + s.sag_mm(y * y).unwrap_or(0.0), y)
            })
            .collect()
    };
    let profiles: Vec<Vec<(f64, f64)>> = (0..ns).map(profile).collect();
    // Bounds.
    let all = profiles
        .iter()
        .flatten()
        .chain(fans.iter().flat_map(|(ps, _)| ps.iter().flatten()))
        .copied()
        .filter(|p| p.0.is_finite() && p.1.is_finite());
    let (mut zmin, mut zmax, mut ymin, mut ymax) = (0.0f64, z[ns], 0.0f64, 0.0f64);
    for (zz, yy) in all {
        zmin = zmin.min(zz);
        zmax = zmax.max(zz);
        ymin = ymin.min(yy);
        ymax = ymax.max(yy);
    }
    let (w_px, margin) = (1000.0, 30.0);
    let scale = (w_px - 2.0 * margin) / (zmax - zmin).max(1e-9);
    let h_px = (ymax - ymin) * scale + 2.0 * margin + 30.0;
    let tx = |zz: f64| margin + (zz - zmin) * scale;
    let ty = |yy: f64| margin + 20.0 + (ymax - yy) * scale;
    let poly = |pts: &[(f64, f64)]| -> String {
        pts.iter()
            .map(|(a, b)| format!("{:.2},{:.2}", tx(*a), ty(*b)))
            .collect::<Vec<_>>()
            .join(" ")
    };
    let mut o = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{w_px:.0}\" height=\"{h_px:.0}\" viewBox=\"0 0 {w_px:.0} {h_px:.0}\">\n<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n<text x=\"{margin}\" y=\"20\" font-family=\"sans-serif\" font-size=\"14\">{} — EFL {:.3} mm, F/{:.2}, fields 0° and {:.2}° at {} nm</text>\n",
        html_escape(&lens.name),
        fo.efl_mm,
        fo.f_number,
        max_field_deg,
        primary
    );
    // axis
    o.push_str(&format!(
        "<line x1=\"{:.2}\" y1=\"{:.2}\" x2=\"{:.2}\" y2=\"{:.2}\" stroke=\"#999\" stroke-dasharray=\"6 4\"/>\n",
        tx(zmin),
        ty(0.0),
        tx(zmax),
        ty(0.0)
    ));
    // elements: glass after surface j (medium not air) is closed by edges to surface j+1
    for j in 0..ns {
        let glass = !matches!(
            lens.surfaces[j].medium,
            camsim_lens::prescription::Medium::Air
        );
        if glass && j + 1 < ns {
            let (a, b) = (&profiles[j], &profiles[j + 1]);
            let mut pts: Vec<(f64, f64)> = a.clone();
            pts.push(*b.last().unwrap());
            pts.extend(b.iter().rev().copied());
            pts.push(a[0]);
            o.push_str(&format!(
                "<polygon points=\"{}\" fill=\"#cfe3f7\" stroke=\"#234\" stroke-width=\"1.2\"/>\n",
                poly(&pts)
            ));
        } else if j == lens.stop_index {
            let (zs, h) = (z[j], sd[j]);
            for sgn in [1.0, -1.0] {
                o.push_str(&format!(
                    "<line x1=\"{:.2}\" y1=\"{:.2}\" x2=\"{:.2}\" y2=\"{:.2}\" stroke=\"black\" stroke-width=\"3\"/>\n",
                    tx(zs),
                    ty(sgn * h),
                    tx(zs),
                    ty(sgn * h * 1.25)
                ));
            }
        } else if j == 0
            || matches!(
                lens.surfaces[j - 1].medium,
                camsim_lens::prescription::Medium::Air
            )
        {
            o.push_str(&format!(
                "<polyline points=\"{}\" fill=\"none\" stroke=\"#234\" stroke-width=\"1\"/>\n",
                poly(&profiles[j])
            ));
        }
    }
    // image plane
    o.push_str(&format!(
        "<line x1=\"{0:.2}\" y1=\"{1:.2}\" x2=\"{0:.2}\" y2=\"{2:.2}\" stroke=\"black\" stroke-width=\"1.5\"/>\n",
        tx(z[ns]),
        ty(ymax),
        ty(ymin)
    ));
    for (paths, colour) in &fans {
        for p in paths {
            o.push_str(&format!(
                "<polyline points=\"{}\" fill=\"none\" stroke=\"{colour}\" stroke-width=\"0.8\"/>\n",
                poly(p)
            ));
        }
    }
    o.push_str("</svg>\n");
    Ok(o)
}
