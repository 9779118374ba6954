//! The channels of temc-render's multi-layer EXR, which temc reads: one list, so the
//! writer, the data set's manifest and the reader agree.
//!
//! ```
//! use temc_color::layers;
//! let names = layers::channel_names();
//! assert_eq!(names.len(), 10 + layers::SPECTRAL_BANDS);
//! assert_eq!(names[10], "spectral.b00");
//! assert_eq!(layers::SPECTRAL_MAX_NM, 780.0);
//! ```

/// Linear sRGB radiance.
pub const COLOR: [&str; 3] = ["color.R", "color.G", "color.B"];
/// Albedo at the first non-specular hit.
pub const ALBEDO: [&str; 3] = ["albedo.R", "albedo.G", "albedo.B"];
/// Normal at the first non-specular hit.
pub const NORMAL: [&str; 3] = ["normal.X", "normal.Y", "normal.Z"];
/// Distance to the first hit.
pub const DEPTH: &str = "depth.Z";

/// Bands of the `spectral` layer, as the paper used: equal bands from
/// [`SPECTRAL_MIN_NM`], each [`SPECTRAL_BAND_NM`] wide.
pub const SPECTRAL_BANDS: usize = 16;
/// Lower edge of the first spectral band, nm.
pub const SPECTRAL_MIN_NM: f32 = 380.0;
/// Width of each spectral band, nm.
pub const SPECTRAL_BAND_NM: f32 = 25.0;
/// Upper edge of the last spectral band, nm.
pub const SPECTRAL_MAX_NM: f32 = SPECTRAL_MIN_NM + SPECTRAL_BANDS as f32 * SPECTRAL_BAND_NM;

/// The channel of spectral band `b` (`spectral.b00` ..), mean radiance over the band.
pub fn spectral_band(b: usize) -> String {
    format!("spectral.b{b:02}")
}

/// Every channel: colour, albedo, normal, depth, then the spectral bands.
pub fn channel_names() -> Vec<String> {
    COLOR
        .iter()
        .chain(&ALBEDO)
        .chain(&NORMAL)
        .chain([&DEPTH])
        .map(|s| s.to_string())
        .chain((0..SPECTRAL_BANDS).map(spectral_band))
        .collect()
}
