//! Spectral quantities: the spectra of emitters and surfaces, the wavelengths a path
//! carries, how a render samples them, the measured tables behind them, and the smooth
//! uplift of RGB colours to spectra.

pub mod measured;
pub mod sampler;
pub mod spectrum;
pub mod uplift;
pub mod wavelengths;
