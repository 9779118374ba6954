//! Direct lighting: next-event estimation on quad and sphere lights, MIS-weighted
//! (power heuristic) against the Lambertian lobe's cosine sampling.

use std::f32::consts::PI;

use crate::geometry::shape::{sample_sphere_cone, sphere_cone_pdf, Prim};
use crate::geometry::vec3::V3;
use crate::geometry::RAY_OFFSET;
use crate::materials::scattering::sample_cosine;
use crate::materials::Material;
use crate::rng::Rng;
use crate::scene::{Hit, Scene};
use crate::spectral::spectrum::Spectrum;
use crate::spectral::wavelengths::{mul, Lanes, Wavelengths, LANES};

/// The Lambertian lobe (of diffuse surfaces and of plastic's base): one light sample,
/// then a cosine-weighted bounce. Updates `beta` and returns the new direction and its
/// solid-angle density (for MIS on the next emitter hit).
pub(super) fn diffuse_bounce(
    scene: &Scene,
    hit: &Hit,
    rgb: [f32; 3],
    wl: &Wavelengths,
    beta: &mut Lanes,
    rng: &mut Rng,
    radiance: &mut Lanes,
) -> (V3, f32) {
    let rho = Spectrum::Rgb(rgb).sample(wl);
    next_event(scene, hit, mul(*beta, rho), wl, rng, radiance);
    let (wi, pdf) = sample_cosine(hit.n, rng.uniform(), rng.uniform());
    *beta = mul(*beta, rho);
    (wi, pdf)
}

/// Solid-angle density with which next-event estimation picks the point `hit` on light
/// primitive `prim`, seen from `from` along `d` (before dividing by the light count).
pub(super) fn light_pdf(scene: &Scene, prim: usize, from: V3, hit: &Hit, d: V3) -> f32 {
    match scene.prims[prim] {
        Prim::Quad { .. } => {
            let cos_l = hit.n.dot(-d).abs().max(1e-6);
            hit.t * hit.t / (cos_l * scene.prims[prim].area())
        }
        Prim::Sphere { c, r } => sphere_cone_pdf(from, c, r),
        Prim::Triangle { .. } => 0.0, // never sampled by next-event estimation
    }
}

/// One light sample for a diffuse lobe with per-lane reflectance-weighted throughput
/// `beta_rho`, MIS-weighted against cosine sampling.
fn next_event(
    scene: &Scene,
    hit: &Hit,
    beta_rho: Lanes,
    wl: &Wavelengths,
    rng: &mut Rng,
    radiance: &mut Lanes,
) {
    let lights = scene.lights();
    if lights.is_empty() {
        return;
    }
    let n = lights.len() as f32;
    let li = lights[((rng.uniform() * n) as usize).min(lights.len() - 1)];
    let (u1, u2) = (rng.uniform(), rng.uniform());
    let x = hit.p + hit.n * RAY_OFFSET;
    let (wi, dist, pdf) = match scene.prims[li] {
        Prim::Quad { p, e1, e2 } => {
            let q = p + e1 * u1 + e2 * u2;
            let to = q - x;
            let dist = to.len();
            let wi = to / dist;
            let cos_l = e1.cross(e2).norm().dot(-wi).abs();
            if cos_l < 1e-6 {
                return;
            }
            (wi, dist, dist * dist / (cos_l * scene.prims[li].area()))
        }
        Prim::Sphere { c, r } => {
            let Some((wi, pdf)) = sample_sphere_cone(x, c, r, u1, u2) else {
                return;
            };
            let Some(h) = scene.prims[li].intersect(x, wi, 0.0, f32::INFINITY) else {
                return;
            };
            (wi, h.t, pdf)
        }
        Prim::Triangle { .. } => return,
    };
    let cos = hit.n.dot(wi);
    if cos <= 0.0 || scene.occluded(x, wi, dist * (1.0 - 1e-4), li) {
        return;
    }
    let Material::Emitter { radiance: s, scale } = &scene.materials[scene.prim_material[li]] else {
        return;
    };
    let light = pdf / n;
    let bsdf = cos / PI;
    let w = light * light / (light * light + bsdf * bsdf);
    let le = s.sample(wl);
    let f = cos / PI / light * w * scale;
    for i in 0..LANES {
        radiance[i] += beta_rho[i] * le[i] * f;
    }
}
