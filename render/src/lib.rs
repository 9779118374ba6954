//! temc-render: a spectral Monte Carlo path tracer for temc's data sets and demo scenes.
//!
//! Paths carry four hero wavelengths; the film converts them to CIE XYZ with the same
//! colour matching functions as the denoiser (`temc::color`), so training data and
//! inference agree. Work in progress: diffuse surfaces, spectral area lights (including a
//! spiky fluorescent lamp), a constant environment, NEE with MIS, Russian roulette, and
//! multi-layer EXR output (colour, 16 spectral bands, albedo, normal, depth).

#![warn(missing_docs)]

pub mod film;
pub mod integrator;
pub mod scene;
pub mod spectrum;
pub mod vec3;

use rayon::prelude::*;

use film::{Layers, Pixel};
use scene::Scene;
use vec3::V3;

/// Render settings.
#[derive(Clone, Copy, Debug)]
pub struct Settings {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Paths per pixel.
    pub spp: u32,
    /// Seed: the same seed gives the same image.
    pub seed: u64,
    /// Longest path, in bounces.
    pub max_depth: u32,
}

/// Renders `scene`; `progress` is called with the number of finished rows.
pub fn render(scene: &Scene, s: Settings, progress: &(dyn Fn(usize) + Sync)) -> Layers {
    let lights = scene.lights();
    let y_norm = temc::color::spectral::cmf_integral(360.0, 830.0)[1];
    let cam = &scene.camera;
    let fwd = (cam.target - cam.eye).norm();
    let right = V3(0.0, 1.0, 0.0).cross(fwd).norm();
    let up = fwd.cross(right);
    let tan = (cam.fov_deg.to_radians() * 0.5).tan();
    let aspect = s.width as f32 / s.height as f32;
    let done = std::sync::atomic::AtomicUsize::new(0);
    let rows: Vec<Vec<Pixel>> = (0..s.height)
        .into_par_iter()
        .map(|y| {
            let row = (0..s.width)
                .map(|x| {
                    let mut px = Pixel::default();
                    let mut rng = integrator::Rng::new(s.seed, (y * s.width + x) as u64);
                    for _ in 0..s.spp {
                        let sx = (2.0 * (x as f32 + rng.uniform()) / s.width as f32 - 1.0)
                            * tan
                            * aspect;
                        let sy = (1.0 - 2.0 * (y as f32 + rng.uniform()) / s.height as f32) * tan;
                        let d = (fwd + right * sx + up * sy).norm();
                        let path =
                            integrator::trace(scene, &lights, cam.eye, d, &mut rng, s.max_depth);
                        px.add(&path, y_norm);
                    }
                    px
                })
                .collect();
            progress(done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1);
            row
        })
        .collect();
    let px: Vec<Pixel> = rows.into_iter().flatten().collect();
    Layers::from_pixels(s.width, s.height, &px)
}
