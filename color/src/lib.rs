//! The colour science that temc (the denoiser) and temc-render (the tracer) share, so a
//! render and the denoiser that reads it convert spectra with the same numbers.
//!
//! - [`cie`]: the CIE 1931 colour matching functions (interpolated from the CIE's table),
//!   their integrals, XYZ -> linear sRGB.
//! - [`cie1931`]: the CIE 1931 2-degree observer's 1 nm table.
//! - [`layers`]: the channels of temc-render's multi-layer EXR, spectral bands included.
//!
//! No dependencies: the tracer's library builds without the denoiser (and without tract).
//! `temc::color::spectral` re-exports [`cie`] and `temc::color::layers` re-exports
//! [`layers`], so the denoiser's paths stay as they were.
//!
//! ```
//! let xyz = temc_color::cie::cmf_tabulated(555.0);
//! assert_eq!(xyz[1], 1.0);
//! ```

#![warn(missing_docs)]

pub mod cie;
pub mod cie1931;
pub mod layers;
