//! Denoise an EXR through temc's Rust API.
//!
//! ```sh
//! cargo run --release --example denoise_exr -- MODEL.onnx noisy.exr denoised.exr
//! ```
//!
//! `noisy.exr` may be a plain RGB EXR, a `temc-render` EXR or a Blender multi-layer EXR:
//! albedo, normal and depth layers found in it guide the denoiser. The output is written
//! to a temporary file and renamed, so a failure never leaves half a file.

use std::error::Error;
use std::path::Path;

use temc::engine::Model;
use temc::filter::{Device, Filter};
use temc::image::{Format, Layout};

fn main() -> Result<(), Box<dyn Error>> {
    let args: Vec<String> = std::env::args().collect();
    let [_, model, input, output] = args.as_slice() else {
        return Err("usage: denoise_exr MODEL.onnx IN.exr OUT.exr".into());
    };
    let weights = std::fs::read(model).map_err(|e| format!("{model}: {e}"))?;
    // The filter type must match the model's architecture (TEMC2, TEMC1, DEMC, AE).
    let kind = Model::from_bytes(&weights)?
        .info()
        .architecture
        .to_ascii_uppercase();
    let image = temc::io::read(Path::new(input))?;
    let (w, h) = (image.width, image.height);
    let color = image.color.ok_or("no colour channels in the input")?;

    // One-channel buffers go through the byte-level API with their layout; the filter
    // borrows every input, so they must outlive it.
    let depth_bytes: Option<Vec<u8>> = image
        .depth
        .as_ref()
        .map(|d| d.iter().flat_map(|v| v.to_ne_bytes()).collect());

    let device = Device::new();
    device.commit()?;
    let mut filter = Filter::new(&device, &kind)?;
    filter.set_weights(&weights);
    filter.set_input_f32("color", &color, w, h)?;
    if let Some(albedo) = &image.albedo {
        filter.set_input_f32("albedo", albedo, w, h)?;
    }
    if let Some(normal) = &image.normal {
        filter.set_input_f32("normal", normal, w, h)?;
    }
    if let Some(bytes) = &depth_bytes {
        filter.set_input("depth", bytes, Layout::packed(Format::Float, w, h))?;
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
