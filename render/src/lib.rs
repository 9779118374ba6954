//! temc-render: a spectral Monte Carlo path tracer for temc's data sets and demo scenes.
//!
//! Paths carry four hero wavelengths; the film converts them to CIE XYZ with the CIE 1931
//! observer's own table (`temc_color::cie::cmf_tabulated_f32`, from the `temc-color`
//! crate the denoiser shares; the denoiser's spectral input still uses the crate's
//! analytic fit, see docs/render.md). The renderer
//! inspects each scene ([`scene::Scene::features`]) and runs the cheapest correct kernel
//! ([`integrator::Kernel`]).
//!
//! The modules are the stages of a render, each using only those above it:
//!
//! | module | stage |
//! |---|---|
//! | [`geometry`] | vectors, primitives, the BVH |
//! | [`spectral`] | spectra, the wavelengths a path carries, their sampling |
//! | [`materials`] | materials, their scattering functions, textures |
//! | [`camera`], [`scene`] | the camera; the assembled scene the integrator queries |
//! | [`description`] | scene input: the file format, OBJ, generated and named scenes |
//! | [`rng`], [`integrator`] | random numbers; path tracing with next-event estimation, and the weaker [`Sampling`] modes |
//! | [`film`], [`output`] | pixel sums, output layers, the EXR; atomic file writes |
//! | [`render()`], [`render_progressive`] | the loop over pixels that ties them together |
//!
//! The applications (`dataset`, `demo`, `bench`) are modules of the `temc-render` binary.
//!
//! ```
//! use temc_render::{description::named, render, Settings};
//! let scene = named::scene("cornell-spiky").unwrap();
//! let img = render(&scene, &Settings { width: 16, height: 16, spp: 4, ..Settings::default() });
//! assert_eq!(img.color.len(), 16 * 16);
//! ```

#![warn(missing_docs)]

pub mod camera;
pub mod description;
pub mod film;
pub mod geometry;
pub mod integrator;
pub mod materials;
pub mod output;
mod render;
pub mod rng;
pub mod scene;
pub mod spectral;

pub use integrator::Sampling;
pub use render::{kernel_for, render, render_progressive, Cancelled, Settings};
