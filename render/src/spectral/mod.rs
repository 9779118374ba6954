//! Spectral quantities: the spectra of emitters and surfaces, the wavelengths a path
//! carries, how a render samples them, and the measured tables behind them.

pub mod measured;
pub mod sampler;
pub mod spectrum;
pub mod wavelengths;
