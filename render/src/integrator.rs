//! Path tracing with hero wavelengths, next-event estimation with MIS, Russian roulette.
//!
//! The tracer is compiled in several kernels (const generic switches) and a scene runs the
//! cheapest one that is correct for it: without dispersive glass the four wavelengths are
//! never split, without any dielectric no refraction code is in the loop. The general
//! kernel, which a scene can be forced onto to check the specialisation, traces one
//! wavelength per path from the start (the naive way to support dispersion) and keeps
//! every material branch.

use std::f32::consts::PI;

use crate::material::{
    fresnel_conductor, fresnel_dielectric, ggx_g1, mul, reflect, refract, sample_cosine,
    sample_microfacet, Material, SMOOTH,
};
use crate::scene::{Features, Hit, Scene};
use crate::shape::{sample_sphere_cone, sphere_cone_pdf, Prim};
use crate::spectrum::{Lanes, Spectrum, Wavelengths, LANES};
use crate::vec3::V3;

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

/// Which code paths a render compiles in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Kernel {
    /// Trace only the hero wavelength from the first vertex.
    pub split_always: bool,
    /// Split wavelengths lazily at dispersive refraction (pbrt-v4's rule).
    pub dispersion: bool,
    /// Refraction code present.
    pub transmission: bool,
    /// Sample wavelengths from the emitters' spectra (needed for line spectra).
    pub emitter_wavelengths: bool,
}

impl Kernel {
    /// Everything on: correct for any scene, cheapest for none.
    pub const GENERAL: Kernel = Kernel {
        split_always: true,
        dispersion: true,
        transmission: true,
        emitter_wavelengths: true,
    };

    /// The cheapest correct kernel for a scene with these features.
    pub fn for_features(f: &Features) -> Kernel {
        Kernel {
            split_always: false,
            dispersion: f.dispersion,
            transmission: f.transmission,
            emitter_wavelengths: f.spiky_emitters,
        }
    }
}

/// What one camera path found.
pub struct PathSample {
    /// Radiance per lane.
    pub radiance: Lanes,
    /// The lanes' wavelengths and densities (terminated lanes have density 0).
    pub wavelengths: Wavelengths,
    /// Albedo at the first non-specular hit (1 for emitters and the environment).
    pub albedo: [f32; 3],
    /// Normal at the first non-specular hit, facing the ray.
    pub normal: V3,
    /// Distance to the first hit (0 when the camera ray escaped).
    pub depth: f32,
}

/// Traces one path with the given kernel.
pub fn trace(
    kernel: Kernel,
    scene: &Scene,
    wl: Wavelengths,
    origin: V3,
    d: V3,
    rng: &mut Rng,
    max_depth: u32,
) -> PathSample {
    let Kernel {
        split_always: s,
        dispersion: di,
        transmission: t,
        ..
    } = kernel;
    macro_rules! dispatch {
        ($($a:literal $b:literal $c:literal),*) => {
            match (s, di, t) {
                $(($a, $b, $c) => trace_kernel::<$a, $b, $c>(scene, wl, origin, d, rng, max_depth),)*
            }
        };
    }
    dispatch!(
        false false false, false false true, false true false, false true true,
        true false false, true false true, true true false, true true true
    )
}

const EPS: f32 = 1e-4;

fn lanes(s: &Spectrum, wl: &Wavelengths) -> Lanes {
    s.sample(wl)
}

fn trace_kernel<const SPLIT: bool, const DISP: bool, const TRANS: bool>(
    scene: &Scene,
    mut wl: Wavelengths,
    origin: V3,
    d: V3,
    rng: &mut Rng,
    max_depth: u32,
) -> PathSample {
    if SPLIT {
        wl.terminate_secondary();
    }
    let mut radiance = [0.0f32; LANES];
    let mut aux: Option<([f32; 3], V3)> = None;
    let mut depth0 = 0.0;
    let (mut o, mut d) = (origin, d);
    let mut beta = [1.0f32; LANES];
    // Solid-angle density of the last diffuse-lobe sample, for MIS on emitter hits;
    // 0 after the camera or a bounce that next-event estimation did not cover.
    let mut prev_pdf = 0.0f32;
    let mut prev_p = origin;
    let lights = scene.lights();
    let n_lights = lights.len() as f32;
    for depth in 0..max_depth {
        let Some(hit) = scene.intersect(o, d, 0.0, f32::INFINITY) else {
            if let Some((env, scale)) = &scene.environment {
                let le = lanes(env, &wl);
                for i in 0..LANES {
                    radiance[i] += beta[i] * le[i] * scale;
                }
            }
            aux.get_or_insert(([1.0; 3], V3::default()));
            break;
        };
        if depth == 0 {
            depth0 = hit.t;
        }
        let wo = -d;
        let (u, v) = hit.uv;
        let material = &scene.materials[hit.material];
        let (wi, transmitted) = match material {
            Material::Emitter { radiance: s, scale } => {
                aux.get_or_insert(([1.0; 3], hit.n));
                let w = if prev_pdf == 0.0 {
                    1.0
                } else {
                    let lp = light_pdf(scene, hit.prim, prev_p, &hit, d) / n_lights.max(1.0);
                    prev_pdf * prev_pdf / (prev_pdf * prev_pdf + lp * lp)
                };
                let le = lanes(s, &wl);
                for i in 0..LANES {
                    radiance[i] += beta[i] * le[i] * scale * w;
                }
                break;
            }
            Material::Diffuse { reflectance } => {
                let rgb = reflectance.eval(u, v);
                aux.get_or_insert((rgb, hit.n));
                let (wi, pdf) =
                    diffuse_bounce(scene, &hit, rgb, &wl, &mut beta, rng, &mut radiance);
                prev_pdf = pdf;
                (wi, false)
            }
            Material::Plastic {
                reflectance,
                ior,
                roughness,
            } => {
                let rgb = reflectance.eval(u, v);
                aux.get_or_insert((rgb, hit.n));
                let f = fresnel_dielectric(wo.dot(hit.n), *ior);
                if rng.uniform() < f {
                    // The coat: mirror, or GGX by visible-normal sampling.
                    prev_pdf = 0.0;
                    let a = roughness.eval_scalar(u, v);
                    if a < SMOOTH {
                        (reflect(wo, hit.n), false)
                    } else {
                        let m = sample_microfacet(wo, hit.n, a, rng.uniform(), rng.uniform());
                        let wi = reflect(wo, m);
                        if wi.dot(hit.n) <= 0.0 {
                            break;
                        }
                        beta = beta.map(|b| b * ggx_g1(wi.dot(hit.n), a));
                        (wi, false)
                    }
                } else {
                    let (wi, pdf) =
                        diffuse_bounce(scene, &hit, rgb, &wl, &mut beta, rng, &mut radiance);
                    prev_pdf = pdf;
                    (wi, false)
                }
            }
            Material::Conductor {
                metal,
                roughness,
                albedo,
            } => {
                prev_pdf = 0.0;
                let a = roughness.eval_scalar(u, v);
                let (wi, cos_m, g) = if a < SMOOTH {
                    (reflect(wo, hit.n), wo.dot(hit.n), 1.0)
                } else {
                    aux.get_or_insert((*albedo, hit.n));
                    let m = sample_microfacet(wo, hit.n, a, rng.uniform(), rng.uniform());
                    let wi = reflect(wo, m);
                    if wi.dot(hit.n) <= 0.0 {
                        break;
                    }
                    (wi, wo.dot(m), ggx_g1(wi.dot(hit.n), a))
                };
                let eta = metal.eta.sample(&wl);
                let k = metal.k.sample(&wl);
                for i in 0..LANES {
                    beta[i] *= fresnel_conductor(cos_m, eta[i], k[i]) * g;
                }
                (wi, false)
            }
            Material::Dielectric { ior, roughness } => {
                if !TRANS {
                    break; // not compiled in: the kernel was chosen for a scene without glass
                }
                prev_pdf = 0.0;
                if DISP && ior.dispersive() {
                    wl.terminate_secondary();
                }
                let n_mat = ior.eval(wl.lambda[0]);
                let eta = if hit.front { n_mat } else { 1.0 / n_mat };
                let a = roughness.eval_scalar(u, v);
                let m = if a < SMOOTH {
                    hit.n
                } else {
                    aux.get_or_insert(([1.0; 3], hit.n));
                    sample_microfacet(wo, hit.n, a, rng.uniform(), rng.uniform())
                };
                let cos = wo.dot(m);
                if cos <= 0.0 {
                    break;
                }
                let f = fresnel_dielectric(cos, eta);
                let (wi, through) = if rng.uniform() < f {
                    (reflect(wo, m), false)
                } else {
                    match refract(wo, m, eta) {
                        Some(t) => (t, true),
                        None => (reflect(wo, m), false),
                    }
                };
                let side = wi.dot(hit.n);
                if (through && side >= 0.0) || (!through && side <= 0.0) {
                    break;
                }
                if a >= SMOOTH {
                    beta = beta.map(|b| b * ggx_g1(side.abs(), a));
                }
                (wi, through)
            }
        };
        prev_p = hit.p;
        o = hit.p + if transmitted { -hit.n } else { hit.n } * EPS;
        d = wi;
        if depth >= 3 {
            let p = (0..LANES)
                .filter(|&i| wl.pdf[i] > 0.0)
                .fold(0.0f32, |m, i| m.max(beta[i]))
                .min(0.95);
            if p <= 0.0 || rng.uniform() >= p {
                break;
            }
            beta = beta.map(|b| b / p);
        }
    }
    let (albedo, normal) = aux.unwrap_or(([0.0; 3], V3::default()));
    PathSample {
        radiance,
        wavelengths: wl,
        albedo,
        normal,
        depth: depth0,
    }
}

/// The Lambertian lobe (of diffuse surfaces and of plastic's base): one light sample,
/// then a cosine-weighted bounce. Updates `beta` and returns the new direction and its
/// solid-angle density (for MIS on the next emitter hit).
fn diffuse_bounce(
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
fn light_pdf(scene: &Scene, prim: usize, from: V3, hit: &Hit, d: V3) -> f32 {
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
    let x = hit.p + hit.n * EPS;
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
    let le = lanes(s, wl);
    let f = cos / PI / light * w * scale;
    for i in 0..LANES {
        radiance[i] += beta_rho[i] * le[i] * f;
    }
}
