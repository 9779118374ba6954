//! The `temc` command line.
//!
//! `temc info MODEL.onnx` prints a model's card; `temc denoise` and `temc demo` arrive with
//! the filter and the trained default model.

use std::process::ExitCode;

use clap::{Parser, Subcommand};
use temc::engine::Model;

#[derive(Parser)]
#[command(
    name = "temc",
    version,
    about = "Neural denoiser for spectral Monte Carlo renders"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Print the metadata (model card) of a temc ONNX model.
    Info {
        /// Path to the .onnx file.
        model: std::path::PathBuf,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
    },
}

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("temc: {e}");
            ExitCode::FAILURE
        }
    }
}

fn run(cli: Cli) -> temc::Result<()> {
    match cli.command {
        Command::Info { model, json } => {
            let m = Model::from_path(&model)?;
            let info = m.info();
            if json {
                let text = serde_json::to_string_pretty(&info.raw).expect("string map");
                println!("{text}");
            } else {
                println!("{}", model.display());
                for (k, v) in &info.raw {
                    println!("  {k:<24} {v}");
                }
                if info.is_untrained() {
                    println!("  (untrained weights: for tests and benchmarks only)");
                }
            }
            Ok(())
        }
    }
}
