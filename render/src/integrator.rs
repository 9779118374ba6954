//! Path tracing with hero wavelengths, next-event estimation with MIS, Russian roulette.

use std::f32::consts::PI;

use crate::scene::{Material, Scene, Shape};
use crate::spectrum::{Lanes, Spectrum, Wavelengths, LANES};
use crate::vec3::{basis, V3};

/// A small, fast, seedable generator (PCG32), so renders are deterministic from a seed.
pub struct Rng(u64);

impl Rng {
    /// A stream for one (seed, pixel, sample).
    pub fn new(seed: u64, stream: u64) -> Self {
        let mut r = Rng(seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(stream.wrapping_mul(1442695040888963407) | 1));
        r.uniform();
        r
    }
    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f32 {
        let old = self.0;
        self.0 = old
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let x = (((old >> 18) ^ old) >> 27) as u32;
        let r = (old >> 59) as u32;
        (x.rotate_right(r) >> 8) as f32 / (1u32 << 24) as f32
    }
}

/// What one camera path found.
pub struct PathSample {
    /// Radiance per lane.
    pub radiance: Lanes,
    /// The lanes' wavelengths and densities.
    pub wavelengths: Wavelengths,
    /// First non-emissive hit: albedo RGB, normal, distance (zeros when the ray escaped).
    pub albedo: [f32; 3],
    /// Shading normal at the first hit.
    pub normal: V3,
    /// Distance to the first hit (0 when the ray escaped).
    pub depth: f32,
}

fn mul(a: Lanes, b: Lanes) -> Lanes {
    [a[0] * b[0], a[1] * b[1], a[2] * b[2], a[3] * b[3]]
}

fn emitted(s: &Spectrum, scale: f32, wl: &Wavelengths) -> Lanes {
    s.sample(wl).map(|v| v * scale)
}

/// Traces one path from the camera along `d`.
pub fn trace(
    scene: &Scene,
    lights: &[usize],
    origin: V3,
    d: V3,
    rng: &mut Rng,
    max_depth: u32,
) -> PathSample {
    let wl = Wavelengths::sample(rng.uniform());
    let mut out = PathSample {
        radiance: [0.0; LANES],
        wavelengths: wl,
        albedo: [0.0; 3],
        normal: V3::default(),
        depth: 0.0,
    };
    let (mut o, mut d) = (origin, d);
    let mut beta = [1.0f32; LANES];
    let mut prev_cos_pdf = 0.0f32; // solid-angle pdf of the last BSDF sample; 0 = camera ray
    let n_lights = lights.len() as f32;
    for depth in 0..max_depth {
        let Some(hit) = scene.intersect(o, d, f32::INFINITY) else {
            if let Some((env, scale)) = &scene.environment {
                let le = emitted(env, *scale, &wl);
                out.radiance = std::array::from_fn(|i| out.radiance[i] + beta[i] * le[i]);
            }
            break;
        };
        let obj = &scene.objects[hit.object];
        match &scene.materials[obj.material] {
            Material::Emitter { radiance, scale } => {
                if depth == 0 {
                    out.normal = hit.n;
                    out.depth = hit.t;
                }
                let le = emitted(radiance, *scale, &wl);
                // MIS against next-event estimation, which also found this light.
                let w = if prev_cos_pdf == 0.0 || !matches!(obj.shape, Shape::Quad { .. }) {
                    1.0
                } else {
                    let cos_l = hit.n.dot(-d).abs().max(1e-6);
                    let light_pdf = hit.t * hit.t / (cos_l * obj.shape.area() * n_lights);
                    prev_cos_pdf * prev_cos_pdf
                        / (prev_cos_pdf * prev_cos_pdf + light_pdf * light_pdf)
                };
                out.radiance = std::array::from_fn(|i| out.radiance[i] + beta[i] * le[i] * w);
                break;
            }
            Material::Diffuse { reflectance, rgb } => {
                if depth == 0 {
                    out.albedo = *rgb;
                    out.normal = hit.n;
                    out.depth = hit.t;
                }
                let rho = reflectance.sample(&wl);
                // Next-event estimation: one point on one light.
                if !lights.is_empty() {
                    let li = lights[((rng.uniform() * n_lights) as usize).min(lights.len() - 1)];
                    let lo = &scene.objects[li];
                    if let (Shape::Quad { p, e1, e2 }, Material::Emitter { radiance, scale }) =
                        (&lo.shape, &scene.materials[lo.material])
                    {
                        let q = *p + *e1 * rng.uniform() + *e2 * rng.uniform();
                        let to = q - hit.p;
                        let dist = to.len();
                        let wi = to / dist;
                        let cos = hit.n.dot(wi);
                        let ln = e1.cross(*e2).norm();
                        let cos_l = ln.dot(-wi).abs();
                        if cos > 0.0 && cos_l > 1e-6 {
                            let blocked = scene
                                .intersect(hit.p, wi, dist - 1e-3)
                                .is_some_and(|h| h.object != li);
                            if !blocked {
                                let light_pdf = dist * dist / (cos_l * lo.shape.area() * n_lights);
                                let bsdf_pdf = cos / PI;
                                let w = light_pdf * light_pdf
                                    / (light_pdf * light_pdf + bsdf_pdf * bsdf_pdf);
                                let le = emitted(radiance, *scale, &wl);
                                let f = cos / PI / light_pdf * w;
                                out.radiance = std::array::from_fn(|i| {
                                    out.radiance[i] + beta[i] * rho[i] * le[i] * f
                                });
                            }
                        }
                    }
                }
                // Cosine-weighted bounce: f cos / pdf = reflectance.
                let (u1, u2) = (rng.uniform(), rng.uniform());
                let r = u1.sqrt();
                let phi = 2.0 * PI * u2;
                let z = (1.0 - u1).max(0.0).sqrt();
                let (t, b) = basis(hit.n);
                d = (t * (r * phi.cos()) + b * (r * phi.sin()) + hit.n * z).norm();
                o = hit.p;
                prev_cos_pdf = z / PI;
                beta = mul(beta, rho);
                if depth >= 3 {
                    let p = beta.iter().fold(0.0f32, |m, &v| m.max(v)).min(0.95);
                    if p <= 0.0 || rng.uniform() >= p {
                        break;
                    }
                    beta = beta.map(|v| v / p);
                }
            }
        }
    }
    out
}
