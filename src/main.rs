//! `camsim`: physically based digital camera simulation (ISET pipeline).
use camsim_pipeline::config::load_captures;
use camsim_pipeline::error::CliError;
use camsim_pipeline::simulate::{simulate, SimulateOptions};
use clap::{Parser, Subcommand};
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "camsim",
    version,
    about = "Physically based digital camera simulator"
)]
struct Cli {
    /// Worker threads (default: all cores).
    #[arg(long, global = true)]
    threads: Option<usize>,
    /// Memory limit, e.g. 8G or 512M (default: 3/4 of the available memory; docs/limits.md).
    #[arg(long, global = true, value_name = "SIZE")]
    max_memory: Option<String>,
    /// Work limit in samples (rays, path samples, PSF samples; default 1e11; docs/limits.md).
    #[arg(long, global = true, value_name = "SAMPLES")]
    max_work: Option<f64>,
    #[command(subcommand)]
    command: Command,
}

/// `camsim metric …`: image-quality metrics on image pairs.
#[derive(Subcommand)]
enum MetricCommand {
    /// S-CIELAB ΔE between two pictures (PNG/TIFF codes) shown on a display at a viewing
    /// distance (docs/isp.md#s-cielab).
    Scielab {
        /// First picture.
        a: PathBuf,
        /// Second picture (same size).
        b: PathBuf,
        /// Display model name (e.g. lcdExample, crt, OLED-Sony).
        #[arg(long, default_value = "lcdExample")]
        display: String,
        /// Viewing distance (m).
        #[arg(long)]
        viewing_distance_m: f64,
        /// camsim (published 1996 filters, ΔE*ab) or isetcam (ISETCam's scielab parameters).
        #[arg(long, default_value = "camsim")]
        parameters: String,
    },
}

#[derive(Subcommand)]
enum Command {
    /// Image-quality metrics on any image pair (S-CIELAB).
    Metric {
        #[command(subcommand)]
        cmd: MetricCommand,
    },
    /// Run the whole pipeline on one scene and write a report (no CONFIG: the paper's §3
    /// setup — Table 1 camera, Macbeth chart under tungsten at 61 cd/m²).
    Run {
        /// A run configuration (docs/run.md); omit for the embedded default.
        config: Option<PathBuf>,
        /// Output folder.
        #[arg(long, default_value = "out/run")]
        out: PathBuf,
    },
    /// Develop a real raw file (uncompressed DNG, or headerless raw with --layout) to an sRGB
    /// PNG through the same image processor as simulated frames (docs/isp.md).
    Develop {
        /// The raw file (.dng, or .raw/.bin with --layout).
        input: PathBuf,
        /// Output PNG.
        #[arg(long)]
        out: PathBuf,
        /// bilinear | malvar | edge_adaptive | lmmse | quad_binning | quad_remosaic.
        #[arg(long, default_value = "malvar")]
        demosaic: String,
        /// as_shot | grey_world | white_patch | none.
        #[arg(long, default_value = "as_shot")]
        white_balance: String,
        /// 8 or 16.
        #[arg(long, default_value_t = 8)]
        bits: u32,
        /// none | reinhard | filmic.
        #[arg(long, default_value = "none")]
        tone: String,
        /// Bilateral denoiser: SIGMA_PX,SIGMA_RANGE (range in linear units; inf = Gaussian).
        #[arg(long)]
        denoise: Option<String>,
        /// Keep white-balanced values above the white level (no highlight clip).
        #[arg(long)]
        no_highlight_clip: bool,
        /// Headerless raw layout: rows=R,cols=C,cfa=RGGB,black=B,white=W[,bits=16,endian=little,header=0].
        #[arg(long)]
        layout: Option<String>,
        /// Headerless raw: XYZ→camera matrix, nine comma-separated numbers (D65 calibration).
        #[arg(long)]
        color_matrix: Option<String>,
        /// Headerless raw: camera neutral R,G,B.
        #[arg(long)]
        neutral: Option<String>,
        /// White adaptation: bradford (DNG specification) | camera (dcraw/LibRaw convention).
        #[arg(long, default_value = "bradford")]
        adaptation: String,
    },
    /// Simulate every frame of a capture set (or, with --expected, each shot's expected image).
    Simulate {
        /// captures.json
        captures: PathBuf,
        /// Replace the camera named in the capture set.
        #[arg(long)]
        camera: Option<PathBuf>,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
        /// Seed of every random term (default: simulation.seed of the file, else 0).
        #[arg(long)]
        seed: Option<u64>,
        /// Write one noise-free expected image per shot, DIR/SHOT_ID.exr (channel Y, DN).
        #[arg(long)]
        expected: bool,
    },
    /// Estimate the sensor's parameters from a capture set (Appendix A/B, photon transfer);
    /// writes DIR/fitted_camera.json, calibration.json and report.html.
    Calibrate {
        /// captures.json (with --emva1288: an EMVA 1288 descriptor file)
        captures: PathBuf,
        /// Analyse CAPTURES as an EMVA 1288 series (the descriptor file of the reference
        /// implementation `emva1288`); writes DIR/datasheet.json, results.xml, report.html.
        #[arg(long)]
        emva1288: bool,
        /// Replace the camera named in the capture set (the believed camera).
        #[arg(long)]
        camera: Option<PathBuf>,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
    },
    /// EMVA 1288 (Release 4.0 Linear) characterisation of a camera: simulate the standard's
    /// series (DIR/EMVA1288descriptor.txt + images), analyse it, write DIR/datasheet.json,
    /// results.xml and report.html (docs/emva1288.md).
    Emva1288 {
        /// camera.json
        camera: PathBuf,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
        /// Seed of every random term.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Wavelength of the light (nm; default: the channel's QE peak).
        #[arg(long)]
        wavelength_nm: Option<f64>,
        /// Channel to characterise (default: highest QE at the wavelength).
        #[arg(long)]
        channel: Option<String>,
        /// Rows of the simulated region (default: the sensor's).
        #[arg(long)]
        rows: Option<usize>,
        /// Columns of the simulated region (default: the sensor's).
        #[arg(long)]
        cols: Option<usize>,
        /// Photon-transfer points from dark to saturation.
        #[arg(long, default_value_t = 50)]
        steps: usize,
        /// Frames per spatial stack (L).
        #[arg(long, default_value_t = 100)]
        spatial_frames: usize,
        /// Exposure time at which the signal saturates (s).
        #[arg(long, default_value_t = 0.01)]
        saturation_exposure_s: f64,
    },
    /// Simulate every shot with the camera and compare with the recording (paper Figs. 3–6):
    /// per-shot and per-patch means and SNR, colour accuracy, residual images.
    Validate {
        /// captures.json
        captures: PathBuf,
        /// Replace the camera named in the capture set.
        #[arg(long)]
        camera: Option<PathBuf>,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
        /// Seed of the simulated frames (default: simulation.seed of the file, else 0).
        #[arg(long)]
        seed: Option<u64>,
    },
    /// Write one shot's scene radiance and sensor irradiance as spectral EXR (+ a JSON summary).
    Scene {
        /// captures.json
        captures: PathBuf,
        /// The shot id.
        #[arg(long)]
        shot: String,
        /// Replace the camera named in the capture set.
        #[arg(long)]
        camera: Option<PathBuf>,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
        /// Also report the round-trip error of a linear model with this many basis spectra.
        #[arg(long)]
        basis: Option<usize>,
    },
    /// Find the physics the camera model leaves out (fit check, locate, candidate effects,
    /// BIC selection); writes DIR/report.json, DIR/fitted_camera.json and DIR/report.html.
    Diagnose {
        /// captures.json
        captures: PathBuf,
        /// Replace the camera named in the capture set (the believed camera).
        #[arg(long)]
        camera: Option<PathBuf>,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
        /// Accept a candidate effect when its BIC improves by more than this.
        #[arg(long, default_value_t = 10.0)]
        bic_threshold: f64,
        /// Only consider these effect ids (comma-separated; default: all of effects.md).
        #[arg(long, value_delimiter = ',')]
        effects: Vec<String>,
    },
    /// Read darktable noise profiles (var = a·mean + b) through the shot-plus-read model:
    /// implied electrons at full scale and read noise, impossible (b < 0) fits flagged;
    /// writes DIR/noise_profiles.json and figures (docs/diagnose_real.md).
    NoiseProfiles {
        /// darktable noiseprofiles.json
        file: PathBuf,
        /// One camera's per-ISO analysis (model, or "maker model").
        #[arg(long)]
        camera: Option<String>,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
    },
    /// Generated capture sets with concealed effects and their truth (`demo diagnose`).
    Demo {
        #[command(subcommand)]
        cmd: camsim_pipeline::demo::DemoCommand,
    },
    /// Lens prescriptions (.json, .zmx, ISET .dat/.json): report, spot, field-model, psf.
    Lens {
        #[command(subcommand)]
        cmd: camsim_pipeline::lens_cmd::LensCommand,
    },
    /// Run a parameter study (docs/study.md): every point of the sweep evaluated once
    /// (finished points are reused), then DIR/table.csv, table.json and report.html.
    Study {
        /// The study file (JSON).
        spec: PathBuf,
        /// Output folder.
        #[arg(long, default_value = "out/study")]
        out: PathBuf,
        /// Where the points run.
        #[arg(long, value_enum, default_value_t = camsim_pipeline::study::EngineKind::Local)]
        engine: camsim_pipeline::study::EngineKind,
        /// Evaluate at most this many unfinished points, then stop (run again to resume).
        #[arg(long)]
        max_points: Option<usize>,
        /// Ray: address of a running cluster (default RAY_ADDRESS, else a local cluster).
        #[arg(long)]
        ray_address: Option<String>,
        /// Ray: CPUs of the local cluster started for the run.
        #[arg(long)]
        ray_num_cpus: Option<usize>,
        /// Ray: the Python with Ray (default CAMSIM_RAY_PYTHON, else .venv-ray/bin/python).
        #[arg(long)]
        ray_python: Option<PathBuf>,
    },
    /// Evaluate one study point (POINT.json written by `camsim study`) into DIR; used by the
    /// Ray and Slurm launchers.
    #[command(hide = true)]
    StudyPoint {
        /// The point.json.
        point: PathBuf,
        /// The point's folder.
        #[arg(long)]
        out: PathBuf,
    },
    /// Path-trace a glTF 2.0 scene into a spectral EXR (band radiance + Z depth).
    Render(camsim_pipeline::render_cmd::RenderArgs),
}

fn run(cli: Cli) -> Result<(), CliError> {
    camsim_pipeline::budget::configure(cli.threads, cli.max_memory.as_deref(), cli.max_work)?;
    match cli.command {
        Command::Simulate {
            captures,
            camera,
            out,
            seed,
            expected,
        } => {
            let set = load_captures(&captures, camera.as_deref())?;
            let seed = seed.or(set.simulation.seed).unwrap_or(0);
            let opts = SimulateOptions {
                out_dir: out,
                seed,
                expected,
                progress: true,
            };
            let summary = simulate(&set, &opts)?;
            eprintln!(
                "camsim: wrote {} file(s) to {}",
                summary.files.len(),
                opts.out_dir.display()
            );
            Ok(())
        }
        Command::Develop {
            input,
            out,
            demosaic,
            white_balance,
            bits,
            tone,
            denoise,
            no_highlight_clip,
            layout,
            color_matrix,
            neutral,
            adaptation,
        } => {
            let opts = camsim_pipeline::develop_cmd::options_from_args(
                &demosaic,
                &white_balance,
                bits,
                &tone,
                denoise.as_deref(),
                !no_highlight_clip,
                layout,
                color_matrix.as_deref(),
                neutral.as_deref(),
                &adaptation,
            )?;
            let s = camsim_pipeline::develop_cmd::develop(&input, &out, &opts)?;
            eprintln!(
                "camsim: developed {}×{} (CFA {}, black {:.1}, white {:.0} DN, gains {:.3?}, colour: {}) → {}",
                s.rows,
                s.cols,
                s.cfa.join("/"),
                s.black_dn,
                s.white_dn,
                s.gains,
                s.color_source,
                out.display()
            );
            Ok(())
        }
        Command::Run { config, out } => {
            let summary = camsim_pipeline::run::run(config.as_deref(), &out, true)?;
            if let Some(de) = &summary.delta_e_2000 {
                eprintln!("camsim: mean ΔE2000 = {:.2}", de.mean);
            }
            eprintln!("camsim: wrote {} (open report.html)", out.display());
            Ok(())
        }
        Command::Calibrate {
            captures,
            emva1288: true,
            out,
            ..
        } => {
            let r = camsim_pipeline::emva1288_cmd::run_descriptor(&captures, &out)?;
            print_emva1288(&r);
            eprintln!("camsim: wrote {} (open report.html)", out.display());
            Ok(())
        }
        Command::Emva1288 {
            camera,
            out,
            seed,
            wavelength_nm,
            channel,
            rows,
            cols,
            steps,
            spatial_frames,
            saturation_exposure_s,
        } => {
            let mut o = camsim_pipeline::emva1288_cmd::Emva1288Options::new(out.clone());
            o.seed = seed;
            o.wavelength_nm = wavelength_nm;
            o.channel = channel;
            o.rows = rows;
            o.cols = cols;
            o.steps_to_saturation = steps;
            o.spatial_frames = spatial_frames;
            o.saturation_exposure_s = saturation_exposure_s;
            let r = camsim_pipeline::emva1288_cmd::run_emva1288(&camera, &o)?;
            print_emva1288(&r);
            eprintln!("camsim: wrote {} (open report.html)", out.display());
            Ok(())
        }
        Command::Calibrate {
            captures,
            camera,
            out,
            ..
        } => {
            let set = load_captures(&captures, camera.as_deref())?;
            let summary = camsim_pipeline::calibrate_cmd::run_calibrate(&set, &out, true)?;
            let r = &summary.result;
            for (k, v) in [
                ("black_level_dn", &r.black_level_dn),
                ("dark_voltage_v_per_s", &r.dark_voltage_v_per_s),
                ("read_noise_v", &r.read_noise_v),
                ("dsnu_sigma_v", &r.dsnu_sigma_v),
                ("prnu_sigma_percent", &r.prnu_sigma_percent),
                ("conversion_gain_v_per_e", &r.conversion_gain_v_per_e),
                ("full_well_e", &r.full_well_e),
            ] {
                match v.get() {
                    Some(e) => eprintln!("camsim: {k} = {:.5e} ± {:.2e}", e.value, e.std_error),
                    None => eprintln!("camsim: {k}: not estimable: {}", v.reason().unwrap_or("")),
                }
            }
            eprintln!("camsim: wrote {} (open report.html)", out.display());
            Ok(())
        }
        Command::Validate {
            captures,
            camera,
            out,
            seed,
        } => {
            let set = load_captures(&captures, camera.as_deref())?;
            let seed = seed.or(set.simulation.seed).unwrap_or(0);
            camsim_pipeline::validate_cmd::run_validate(&set, &out, seed, true)?;
            eprintln!("camsim: wrote {} (open report.html)", out.display());
            Ok(())
        }
        Command::Scene {
            captures,
            shot,
            camera,
            out,
            basis,
        } => {
            let set = load_captures(&captures, camera.as_deref())?;
            let report = camsim_pipeline::scene_cmd::write_scene(&set, &shot, &out, basis)?;
            println!(
                "{}",
                serde_json::to_string_pretty(&report.json).unwrap_or_default()
            );
            Ok(())
        }
        Command::Diagnose {
            captures,
            camera,
            out,
            bic_threshold,
            effects,
        } => {
            let set = load_captures(&captures, camera.as_deref())?;
            let opts = camsim_pipeline::diagnose_cmd::DiagnoseCmdOptions {
                bic_threshold,
                effects,
                progress: true,
            };
            let report = camsim_pipeline::diagnose_cmd::run_diagnose(&set, &out, &opts)?;
            eprintln!(
                "camsim: chi2/dof {:.3} -> {:.3}, {} finding(s){}; wrote {} (open report.html)",
                report.chi2_per_dof_before,
                report.chi2_per_dof_after,
                report.findings.len(),
                if report.findings.is_empty() {
                    String::new()
                } else {
                    format!(" ({})", report.findings.join(", "))
                },
                out.display()
            );
            Ok(())
        }
        Command::NoiseProfiles { file, camera, out } => {
            let s = camsim_pipeline::noise_profiles_cmd::run_noise_profiles(
                &file,
                camera.as_deref(),
                &out,
            )?;
            eprintln!(
                "camsim: {} profiles, {} with b < 0; wrote {}",
                s.census.profiles,
                s.census.negative_b_profiles,
                out.display()
            );
            Ok(())
        }
        Command::Demo { cmd } => camsim_pipeline::demo::run_demo(cmd),
        Command::Lens { cmd } => camsim_pipeline::lens_cmd::run_lens(cmd),
        Command::Study {
            spec,
            out,
            engine,
            max_points,
            ray_address,
            ray_num_cpus,
            ray_python,
        } => {
            let opts = camsim_pipeline::study::StudyOptions {
                out: out.clone(),
                engine,
                max_points,
                ray: camsim_pipeline::study::ray::RayOptions {
                    address: ray_address,
                    num_cpus: ray_num_cpus,
                    python: ray_python,
                },
                progress: true,
            };
            let s = camsim_pipeline::study::run_study(&spec, &opts)?;
            eprintln!(
                "camsim: study: {} points: {} evaluated, {} reused, {} pending; wrote {} (open report.html)",
                s.points,
                s.evaluated,
                s.reused,
                s.pending,
                out.display()
            );
            Ok(())
        }
        Command::StudyPoint { point, out } => {
            camsim_pipeline::study::run_point_file(&point, &out)?;
            Ok(())
        }
        Command::Metric {
            cmd:
                MetricCommand::Scielab {
                    a,
                    b,
                    display,
                    viewing_distance_m,
                    parameters,
                },
        } => {
            let s = camsim_pipeline::metric_cmd::scielab_pictures(
                &a,
                &b,
                &display,
                viewing_distance_m,
                &parameters,
            )?;
            println!("{s}");
            Ok(())
        }
        Command::Render(a) => {
            let s = camsim_pipeline::render_cmd::run_render(&a, true)?;
            println!("{s}");
            Ok(())
        }
    }
}

fn main() -> ExitCode {
    camsim_pipeline::staging::install_signal_cleanup();
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            camsim_pipeline::staging::wait_if_interrupted();
            eprintln!("camsim: error: {}", e.one_line());
            ExitCode::from(2)
        }
    }
}

/// One line per datasheet number of an EMVA 1288 analysis.
fn print_emva1288(r: &camsim_pipeline::emva1288_cmd::Emva1288Report) {
    for (k, v) in &r.values {
        eprintln!("camsim: {k} = {:.6e} ± {:.2e}", v.value, v.uncertainty);
    }
}
