//! temc: a neural denoiser for images made by spectral Monte Carlo renderers.
//!
//! temc implements TEMC-2 (three encoders for chroma, luma and fused auxiliary buffers, one
//! decoder) and the baselines it is compared with (TEMC-1, DEMC, an autoencoder). The noisy
//! image is converted to PQ-encoded HSV by [`color`], the network (an ONNX graph) runs on the
//! CPU through [`engine`], and the result is converted back.
//!
//! The data flow and the contracts between the parts are in docs/contracts.md.

#![warn(missing_docs)]

pub mod capi;
pub mod color;
pub mod engine;
mod error;
pub mod filter;
pub mod image;
pub mod io;
pub mod tile;

pub use error::{Error, Result};
