//! The render loop: rows of pixels in parallel, camera rays through each pixel, the
//! integrator's paths, and the film's sums read out at each checkpoint.

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use rayon::prelude::*;

use crate::film::{Layers, Pixel};
use crate::integrator::{self, Kernel, Sampling};
use crate::rng::Rng;
use crate::scene::Scene;
use crate::spectral::sampler::LambdaSampler;

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
    /// Longest path, in scattering events (pbrt-v4's convention: 0 = emitters seen
    /// directly, 1 = direct lighting).
    pub max_depth: u32,
    /// The kernel to run; `None`: the cheapest the scene allows.
    pub kernel: Option<Kernel>,
    /// Which sampling strategies to weaken, to imitate other renderers' noise; the
    /// default is the tracer's own sampler.
    pub sampling: Sampling,
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            width: 256,
            height: 256,
            spp: 16,
            seed: 1,
            max_depth: 12,
            kernel: None,
            sampling: Sampling::DEFAULT,
        }
    }
}

/// The render was cancelled (Ctrl-C); nothing was written.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Cancelled;

/// The kernel `settings` select for `scene`.
pub fn kernel_for(scene: &Scene, settings: &Settings) -> Kernel {
    settings
        .kernel
        .unwrap_or_else(|| Kernel::for_features(&scene.features()))
}

/// Renders `scene` at `settings.spp`.
///
/// # Panics
/// Never in practice: nothing can cancel this render, and it has one checkpoint.
pub fn render(scene: &Scene, settings: &Settings) -> Layers {
    render_progressive(
        scene,
        settings,
        &[settings.spp],
        &|_| {},
        &AtomicBool::new(false),
    )
    .expect("not cancelled")
    .pop()
    .expect("one checkpoint")
}

/// Renders `scene` once up to the largest of `checkpoints` and returns the image as it
/// stood at each checkpoint (ascending), so noisy images at several spp cost one render.
/// `progress` gets the number of finished rows; setting `cancel` stops the render.
pub fn render_progressive(
    scene: &Scene,
    s: &Settings,
    checkpoints: &[u32],
    progress: &(dyn Fn(usize) + Sync),
    cancel: &AtomicBool,
) -> Result<Vec<Layers>, Cancelled> {
    let mut cps: Vec<u32> = checkpoints.iter().copied().filter(|&c| c > 0).collect();
    cps.sort_unstable();
    cps.dedup();
    let max = *cps.last().unwrap_or(&s.spp);
    let kernel = kernel_for(scene, s);
    let sampler = if s.sampling.uniform_wavelength {
        LambdaSampler::Uniform
    } else {
        LambdaSampler::for_emitters(&scene.emitter_spectra())
    };
    let y_norm = temc_color::cie::cmf_tabulated_integral(360.0, 830.0)[1];
    let camera = scene.camera.pinhole(s.width, s.height);
    let done = AtomicUsize::new(0);
    let rows: Vec<Option<Vec<Vec<Pixel>>>> = (0..s.height)
        .into_par_iter()
        .map(|y| {
            if cancel.load(Ordering::Relaxed) {
                return None;
            }
            // One row of pixels per checkpoint.
            let mut out = vec![Vec::with_capacity(s.width); cps.len()];
            for x in 0..s.width {
                let mut px = Pixel::default();
                let mut rng = Rng::new(s.seed, (y * s.width + x) as u64);
                let mut next = 0;
                for k in 1..=max {
                    let ray = camera.ray(x, y, &mut rng);
                    let wl = sampler.sample(rng.uniform());
                    let path = integrator::trace(
                        kernel,
                        s.sampling,
                        scene,
                        wl,
                        ray,
                        &mut rng,
                        s.max_depth,
                    );
                    px.add(&path, y_norm);
                    if next < cps.len() && k == cps[next] {
                        out[next].push(px.clone());
                        next += 1;
                    }
                }
            }
            progress(done.fetch_add(1, Ordering::Relaxed) + 1);
            Some(out)
        })
        .collect();
    if cancel.load(Ordering::Relaxed) {
        return Err(Cancelled);
    }
    let mut per_cp: Vec<Vec<Pixel>> = vec![Vec::with_capacity(s.width * s.height); cps.len()];
    for row in rows {
        for (c, r) in row.ok_or(Cancelled)?.into_iter().enumerate() {
            per_cp[c].extend(r);
        }
    }
    Ok(per_cp
        .iter()
        .map(|px| Layers::from_pixels(s.width, s.height, px))
        .collect())
}
