//! `camsim`: physically based digital camera simulation (ISET pipeline).
use camsim::config::load_captures;
use camsim::error::CliError;
use camsim::simulate::{simulate, SimulateOptions};
use clap::{Parser, Subcommand};
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Parser)]
#[command(name = "camsim", version, about = "Physically based digital camera simulator")]
struct Cli {
    /// Worker threads (default: all cores).
    #[arg(long, global = true)]
    threads: Option<usize>,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
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
        /// Write one noise-free expected image per shot, DIR/<shot id>.exr (channel Y, DN).
        #[arg(long)]
        expected: bool,
    },
}

fn run(cli: Cli) -> Result<(), CliError> {
    if let Some(n) = cli.threads {
        rayon::ThreadPoolBuilder::new().num_threads(n.max(1)).build_global().map_err(|e| CliError::Other(e.to_string()))?;
    }
    match cli.command {
        Command::Simulate { captures, camera, out, seed, expected } => {
            let set = load_captures(&captures, camera.as_deref())?;
            let seed = seed.or(set.simulation.seed).unwrap_or(0);
            let opts = SimulateOptions { out_dir: out, seed, expected, progress: true };
            let summary = simulate(&set, &opts)?;
            eprintln!("camsim: wrote {} file(s) to {}", summary.files.len(), opts.out_dir.display());
            Ok(())
        }
    }
}

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("camsim: error: {}", e.one_line());
            ExitCode::from(2)
        }
    }
}
