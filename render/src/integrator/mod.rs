//! Path tracing with hero wavelengths, next-event estimation with MIS, Russian roulette.
//!
//! The tracer is compiled in several kernels (const generic switches) and a scene runs the
//! cheapest one that is correct for it: without dispersive glass the four wavelengths are
//! never split, without any dielectric no refraction code is in the loop. The general
//! kernel, which a scene can be forced onto to check the specialisation, is what a general
//! spectral renderer runs on every scene: four hero wavelengths split only at dispersive
//! refraction, wavelengths sampled from the emitters, every material branch. The
//! one-wavelength kernel (one wavelength per path from the start, the naive way to support
//! dispersion) is kept as a labelled extra baseline.
//!
//! [`Sampling`] weakens strategies at run time, to imitate other renderers' noise (see
//! `sampling.rs`). Those are plain branches, not kernels: each is taken the same way on
//! every path, so it costs next to nothing, and the default path does the same arithmetic
//! in the same order as before the modes existed, so its images did not change.

mod direct;
mod sampling;

use std::f32::consts::PI;

use crate::geometry::vec3::V3;
use crate::geometry::RAY_OFFSET;
use crate::materials::scattering::{
    fresnel_conductor, fresnel_dielectric, ggx_g1, ggx_reflection, reflect, refract, sample_cosine,
    sample_microfacet,
};
use crate::materials::{Material, SMOOTH};
use crate::rng::Rng;
use crate::scene::{Features, Scene};
use crate::spectral::wavelengths::{mul, Lanes, Wavelengths, LANES};
use direct::{diffuse_bounce, emission, Direct, SpectrumCache};
pub use sampling::{Mode, Sampling};

/// Which code paths a render compiles in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Kernel {
    /// Trace only the hero wavelength from the first vertex.
    pub split_always: bool,
    /// Split wavelengths lazily at dispersive refraction (pbrt-v4's rule).
    pub dispersion: bool,
    /// Refraction code present.
    pub transmission: bool,
}

impl Kernel {
    /// Everything on: correct for any scene, cheapest for none; hero wavelengths split
    /// only at dispersion (what a general spectral renderer does).
    pub const GENERAL: Kernel = Kernel {
        split_always: false,
        dispersion: true,
        transmission: true,
    };

    /// [`Kernel::GENERAL`] with one wavelength per path from the first vertex: the naive
    /// support for dispersion, a baseline only.
    pub const ONE_WAVELENGTH: Kernel = Kernel {
        split_always: true,
        ..Kernel::GENERAL
    };

    /// The cheapest correct kernel for a scene with these features. Every kernel samples
    /// wavelengths from the emitters' spectra: on smooth emitters too that beat the
    /// analytic visible density at the same speed (`temc-render bench`, 2026-12-02: the
    /// visible density needed up to 1.3x the time to equal error on the blackbody and D65
    /// scenes, 3.4x in the furnace), so only the code paths are specialised.
    pub fn for_features(f: &Features) -> Kernel {
        Kernel {
            split_always: false,
            dispersion: f.dispersion,
            transmission: f.transmission,
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

/// Traces one path from the camera ray `ray` (origin, unit direction) with the given
/// kernel and sampling mode.
pub fn trace(
    kernel: Kernel,
    sampling: Sampling,
    scene: &Scene,
    wl: Wavelengths,
    ray: (V3, V3),
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
                $(($a, $b, $c) => trace_kernel::<$a, $b, $c>(sampling, scene, wl, ray, rng, max_depth),)*
            }
        };
    }
    dispatch!(
        false false false, false false true, false true false, false true true,
        true false false, true false true, true true false, true true true
    )
}

/// One path, compiled once per kernel. It stays one long function on purpose: it is the
/// hot loop, and every material arm updates the same path state (throughput, radiance,
/// the auxiliary buffers, the MIS density, the wavelengths), which helpers would have to
/// pass around by reference. Splitting it is only worth doing with a render benchmark that
/// shows no slowdown; on the shared 2-core machine of the restructuring (issue 17),
/// identical runs varied by about 10 %, too much to show that, so it was left whole.
fn trace_kernel<const SPLIT: bool, const DISP: bool, const TRANS: bool>(
    sampling: Sampling,
    scene: &Scene,
    mut wl: Wavelengths,
    (origin, d): (V3, V3),
    rng: &mut Rng,
    max_depth: u32,
) -> PathSample {
    if SPLIT {
        wl.terminate_secondary();
    }
    let mut radiance = [0.0f32; LANES];
    let mut aux: Option<([f32; 3], V3)> = None;
    let mut depth0 = 0.0;
    let spectra = SpectrumCache::new();
    let direct = Direct {
        scene,
        sampling,
        spectra: &spectra,
    };
    let roulette_start = sampling.roulette_start();
    let (mut o, mut d) = (origin, d);
    let mut beta = [1.0f32; LANES];
    // Solid-angle density of the last diffuse-lobe sample, for MIS on emitter hits;
    // 0 after the camera or a bounce that next-event estimation did not cover.
    let mut prev_pdf = 0.0f32;
    let mut prev_p = origin;
    // pbrt-v4's depth convention: `depth` counts the scattering events before this
    // vertex, so `max_depth` N gives paths of at most N bounces (0: emitters seen
    // directly; 1: direct lighting). The vertex after the N-th bounce is still
    // intersected, for emission only: the BSDF sample of the last scattering vertex is
    // the partner of its light sample in MIS, and leaving it out biased that bounce low.
    for depth in 0..=max_depth {
        let Some(hit) = scene.intersect(o, d, 0.0, f32::INFINITY) else {
            if let Some((env, scale)) = &scene.environment {
                let le = env.sample(&wl);
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
        if depth == max_depth && !matches!(material, Material::Emitter { .. }) {
            break; // no bounce left: only emission counts here
        }
        let (wi, transmitted) = match material {
            Material::Emitter { .. } => {
                aux.get_or_insert(([1.0; 3], hit.n));
                if let Some((s, scale)) = emission(material, hit.front) {
                    let w = direct.emitted_weight(prev_pdf, prev_p, &hit, d);
                    let le = spectra.sample(s, &wl);
                    for i in 0..LANES {
                        radiance[i] += beta[i] * le[i] * scale * w;
                    }
                }
                break;
            }
            Material::Diffuse { reflectance } => {
                let (rho, rgb) = reflectance.at(u, v, &wl);
                aux.get_or_insert((rgb, hit.n));
                let (wi, pdf) =
                    diffuse_bounce(&direct, &hit, rho, 1.0, &wl, &mut beta, rng, &mut radiance);
                prev_pdf = pdf;
                (wi, false)
            }
            Material::Plastic {
                reflectance,
                ior,
                roughness,
            } => {
                let (rho, rgb) = reflectance.at(u, v, &wl);
                aux.get_or_insert((rgb, hit.n));
                let f = fresnel_dielectric(wo.dot(hit.n), *ior);
                let a = roughness.eval_scalar(u, v);
                // Both lobes as one BSDF for light sampling and MIS: the coat (GGX, or a
                // mirror that light sampling cannot see) chosen with probability f, the
                // Lambertian base with 1 - f.
                let coat = |wi: V3| {
                    (a >= SMOOTH)
                        .then(|| ggx_reflection(wo, wi, hit.n, a))
                        .flatten()
                        .map_or((0.0, 0.0), |(fc, pdf, _)| (f * fc, f * pdf))
                };
                let base_pdf = |wi: V3| (1.0 - f) * hit.n.dot(wi).max(0.0) / PI;
                direct.next_event(&hit, &wl, &beta, rng, &mut radiance, |wi| {
                    let cos = hit.n.dot(wi);
                    let (c, c_pdf) = coat(wi);
                    (cos > 0.0).then(|| {
                        let fd = (1.0 - f) * cos / PI;
                        (rho.map(|r| r * fd + c), base_pdf(wi) + c_pdf)
                    })
                });
                let wi = if rng.uniform() < f {
                    if a < SMOOTH {
                        prev_pdf = 0.0;
                        reflect(wo, hit.n)
                    } else {
                        let m = sample_microfacet(wo, hit.n, a, rng.uniform(), rng.uniform());
                        let wi = reflect(wo, m);
                        if wi.dot(hit.n) <= 0.0 {
                            break;
                        }
                        beta = beta.map(|b| b * ggx_g1(wi.dot(hit.n), a));
                        prev_pdf = base_pdf(wi) + coat(wi).1;
                        wi
                    }
                } else {
                    let (wi, _) = sample_cosine(hit.n, rng.uniform(), rng.uniform());
                    beta = mul(beta, rho);
                    prev_pdf = base_pdf(wi) + coat(wi).1;
                    wi
                };
                (wi, false)
            }
            Material::Conductor {
                metal,
                roughness,
                albedo,
                distribution: mf,
            } => {
                let a = roughness.eval_scalar(u, v);
                let eta = spectra.sample(&metal.eta, &wl);
                let k = spectra.sample(&metal.k, &wl);
                let fresnel =
                    |cos: f32| std::array::from_fn(|i| fresnel_conductor(cos, eta[i], k[i]));
                let (wi, cos_m, g) = if a < SMOOTH {
                    prev_pdf = 0.0;
                    (reflect(wo, hit.n), wo.dot(hit.n), 1.0)
                } else {
                    aux.get_or_insert((*albedo, hit.n));
                    direct.next_event(&hit, &wl, &beta, rng, &mut radiance, |wi| {
                        let (fc, pdf, cos_h) = mf.reflection(wo, wi, hit.n, a)?;
                        let fr: Lanes = fresnel(cos_h);
                        Some((fr.map(|v| v * fc), pdf))
                    });
                    let m = mf.sample(wo, hit.n, a, rng.uniform(), rng.uniform());
                    let wi = reflect(wo, m);
                    if wi.dot(hit.n) <= 0.0 {
                        break;
                    }
                    prev_pdf = mf.reflection(wo, wi, hit.n, a).map_or(0.0, |r| r.1);
                    (wi, wo.dot(m), mf.g1(wi.dot(hit.n), a))
                };
                let fr: Lanes = fresnel(cos_m);
                beta = std::array::from_fn(|i| beta[i] * fr[i] * g);
                (wi, false)
            }
            Material::Dielectric {
                ior,
                roughness,
                distribution: mf,
            } => {
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
                // Light sampling covers the outside reflection lobe of rough glass; lights
                // seen through it are found by the refracted paths alone (weight 1).
                let reflection_pdf = |wi: V3| {
                    let (fc, pdf, cos_h) = mf.reflection(wo, wi, hit.n, a)?;
                    let fr = fresnel_dielectric(cos_h, eta);
                    Some((fr * fc, fr * pdf))
                };
                let lit = a >= SMOOTH && hit.front;
                let m = if a < SMOOTH {
                    hit.n
                } else {
                    aux.get_or_insert(([1.0; 3], hit.n));
                    if lit {
                        direct.next_event(&hit, &wl, &beta, rng, &mut radiance, |wi| {
                            reflection_pdf(wi).map(|(fc, pdf)| ([fc; LANES], pdf))
                        });
                    }
                    mf.sample(wo, hit.n, a, rng.uniform(), rng.uniform())
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
                    beta = beta.map(|b| b * mf.g1(side.abs(), a));
                }
                if lit && !through {
                    prev_pdf = reflection_pdf(wi).map_or(0.0, |r| r.1);
                }
                (wi, through)
            }
        };
        prev_p = hit.p;
        o = hit.p + if transmitted { -hit.n } else { hit.n } * RAY_OFFSET;
        d = wi;
        if depth >= roulette_start {
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
