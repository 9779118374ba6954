//! temc: a neural denoiser for images made by spectral Monte Carlo renderers.
//!
//! temc implements TEMC-2 (three encoders for chroma, luma and fused auxiliary buffers, one
//! decoder) and the baselines it is compared with (TEMC-1, DEMC, an autoencoder). The noisy
//! image is converted to PQ-encoded HSV by [`color`], the network (an ONNX graph) runs on the
//! CPU through [`engine`], and the result is converted back.
//!
//! The data flow and the contracts between the parts are in docs/contracts.md.
//!
//! Quick start (the OIDN-like API of [`filter`]; the trained TEMC-2 models are built in,
//! one per [`filter::Quality`], and `set_weights` takes any other temc ONNX model):
//!
//! ```
//! use temc::filter::{Device, Filter, Quality};
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let (width, height) = (64, 32);
//! let noisy = vec![0.25f32; width * height * 3]; // linear HDR RGB
//! let device = Device::new();
//! device.commit()?;
//! let mut filter = Filter::new(&device, "TEMC2")?;
//! filter.set_quality(Quality::Balanced); // the default
//! filter.set_input_f32("color", &noisy, width, height)?;
//! filter.commit()?;
//! let (denoised, stats) = filter.execute_to_vec()?;
//! assert_eq!(denoised.len(), noisy.len());
//! assert_eq!(stats.tiles, 1);
//! # Ok(())
//! # }
//! ```
//!
//! The C ABI (`capi`, behind the default cargo feature `capi`; `include/temc.h` and the
//! C++ wrapper `include/temc.hpp`) mirrors Intel Open Image Denoise 2.x.

#![warn(missing_docs)]
// Every unsafe block of the library says why it is sound (tests and examples, which hand
// the C ABI buffers they own, are exempt).
#![warn(clippy::undocumented_unsafe_blocks)]

#[cfg(feature = "capi")]
pub mod capi;
pub mod color;
pub mod engine;
mod error;
pub mod filter;
pub mod image;
pub mod io;
pub mod keep_mean;
pub mod prefilter;
/// Applies the network's per-pixel multi-level filters to linear radiance (docs/reconstruction.md).
pub mod reconstruct;
pub mod tile;

pub use error::{Error, Result};
