//! `temc-render`: render a named scene to a multi-layer EXR.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use temc_render::{render, scene, Settings};

#[derive(Parser)]
#[command(
    name = "temc-render",
    version,
    about = "Spectral path tracer for temc's data"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Render a named scene.
    Render {
        /// Scene name (see `temc-render scenes`).
        #[arg(long, default_value = "cornell-spiky")]
        scene: String,
        /// Paths per pixel.
        #[arg(long, default_value_t = 16)]
        spp: u32,
        /// Image size, WxH.
        #[arg(long, default_value = "256x256")]
        size: String,
        /// Seed.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Output EXR.
        #[arg(short, long)]
        output: PathBuf,
    },
    /// List the named scenes.
    Scenes,
}

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("temc-render: {e}");
            ExitCode::FAILURE
        }
    }
}

fn run(cli: Cli) -> Result<(), String> {
    match cli.command {
        Command::Scenes => {
            for n in scene::NAMES {
                println!("{n}");
            }
            Ok(())
        }
        Command::Render {
            scene: name,
            spp,
            size,
            seed,
            output,
        } => {
            let sc = scene::named(&name).ok_or_else(|| {
                format!(
                    "unknown scene {name:?} (known: {})",
                    scene::NAMES.join(", ")
                )
            })?;
            let (w, h) = size
                .split_once('x')
                .and_then(|(w, h)| Some((w.parse::<usize>().ok()?, h.parse::<usize>().ok()?)))
                .filter(|&(w, h)| w > 0 && h > 0 && w <= 16384 && h <= 16384)
                .ok_or_else(|| format!("--size {size:?}: expected WxH, e.g. 256x256"))?;
            if spp == 0 {
                return Err("--spp must be at least 1".into());
            }
            let bar = indicatif::ProgressBar::new(h as u64);
            if !std::io::IsTerminal::is_terminal(&std::io::stderr()) {
                bar.set_draw_target(indicatif::ProgressDrawTarget::hidden());
            }
            let t = std::time::Instant::now();
            let layers = render(
                &sc,
                Settings {
                    width: w,
                    height: h,
                    spp,
                    seed,
                    max_depth: 16,
                },
                &|rows| bar.set_position(rows as u64),
            );
            bar.finish_and_clear();
            layers.write_exr(&output)?;
            eprintln!(
                "temc-render: {name} {w}x{h} at {spp} spp in {:.2} s -> {}",
                t.elapsed().as_secs_f64(),
                output.display()
            );
            Ok(())
        }
    }
}
