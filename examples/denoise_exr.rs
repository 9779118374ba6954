//! Denoise an EXR through temc's Rust API.
//!
//! ```sh
//! cargo run --release --example denoise_exr -- noisy.exr denoised.exr [MODEL.onnx]
//! ```
//!
//! Without a model file it runs the built-in TEMC-2 (balanced quality).
//!
//! `noisy.exr` may be a plain RGB EXR, a `temc-render` EXR or a Blender multi-layer EXR:
//! albedo, normal and depth layers found in it guide the denoiser. The output is written
//! to a temporary file and renamed, so a failure never leaves half a file.

use std::error::Error;
use std::path::Path;
use std::sync::Arc;

use temc::engine::Model;
use temc::filter::{Device, Filter, ImageName};

fn main() -> Result<(), Box<dyn Error>> {
    let args: Vec<String> = std::env::args().collect();
    let (input, output, model) = match args.as_slice() {
        [_, i, o] => (i, o, None),
        [_, i, o, m] => (i, o, Some(m)),
        _ => return Err("usage: denoise_exr IN.exr OUT.exr [MODEL.onnx]".into()),
    };
    // A model file is parsed once; the filter takes its type (TEMC2, TEMC1, DEMC, AE)
    // from the model's architecture.
    let model = match model {
        Some(m) => Some(Arc::new(Model::from_path(m)?)),
        None => None,
    };
    let image = temc::io::read(Path::new(input))?;
    let (w, h) = (image.width, image.height);
    let color = image.color.ok_or("no colour channels in the input")?;

    let device = Device::new();
    device.commit()?;
    let mut filter = match model {
        Some(m) => Filter::with_model(&device, m)?,
        None => Filter::new(&device, "TEMC2")?, // the built-in model (balanced by default)
    };
    // The filter borrows every input, so they must outlive it. Depth has one channel.
    filter.set_input_f32(ImageName::Color, &color, w, h)?;
    if let Some(albedo) = &image.albedo {
        filter.set_input_f32(ImageName::Albedo, albedo, w, h)?;
    }
    if let Some(normal) = &image.normal {
        filter.set_input_f32(ImageName::Normal, normal, w, h)?;
    }
    if let Some(depth) = &image.depth {
        filter.set_input_f32(ImageName::Depth, depth, w, h)?;
    }
    filter.set_progress_monitor(|p| {
        eprint!("\rdenoising {:3.0} %", p * 100.0);
        true // returning false would cancel
    });
    filter.commit()?;
    let (denoised, stats) = filter.execute_to_vec()?;
    eprintln!("\r{w}x{h} in {} tile(s)", stats.tiles);
    temc::io::write_rgb(Path::new(output), w, h, &denoised)?;
    Ok(())
}
