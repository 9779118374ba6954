//! Direct lighting: next-event estimation on the scene's emitting primitives (picked in
//! proportion to power), MIS-weighted (power heuristic) against the surface's own
//! sampling, and the emission a path finds when it hits a light; or, in the weaker
//! [`Sampling`] modes, the same without light sampling, with lights picked uniformly, or
//! without MIS.

use std::f32::consts::PI;

use std::cell::Cell;

use crate::geometry::shape::{sample_sphere_cone, sphere_cone_pdf, Prim};
use crate::geometry::vec3::V3;
use crate::materials::scattering::sample_cosine;
use crate::materials::Material;
use crate::rng::Rng;
use crate::scene::{Hit, Scene};
use crate::spectral::spectrum::Spectrum;
use crate::spectral::wavelengths::{mul, Lanes, Wavelengths, LANES};

use super::Sampling;

/// The scene's lights as the render's sampling mode finds them.
#[derive(Clone, Copy)]
pub(super) struct Direct<'a> {
    /// The scene.
    pub scene: &'a Scene,
    /// Which light strategies are weakened.
    pub sampling: Sampling,
    /// The path's spectra at its wavelengths, evaluated once.
    pub spectra: &'a SpectrumCache,
}

/// A per-path cache of spectra (emitters', measured metals') at the path's wavelengths:
/// a path meets the same lamp and metal at every bounce, and a measured table's lookup
/// is a binary search. Keyed by the spectrum's address and the wavelengths (which change
/// only where dispersion splits the path), so a hit returns exactly what
/// `Spectrum::sample` would.
pub(super) struct SpectrumCache {
    entries: [Cell<(usize, Lanes, Lanes)>; CACHED],
    next: Cell<usize>,
}

const CACHED: usize = 8;

impl SpectrumCache {
    pub fn new() -> Self {
        SpectrumCache {
            entries: std::array::from_fn(|_| Cell::new((0, [0.0; LANES], [0.0; LANES]))),
            next: Cell::new(0),
        }
    }

    /// `s.sample(wl)`, from the cache where it was evaluated at these wavelengths.
    #[inline]
    pub fn sample(&self, s: &Spectrum, wl: &Wavelengths) -> Lanes {
        if matches!(
            s,
            Spectrum::Constant(_) | Spectrum::Dense(_) | Spectrum::RgbReflectance(_)
        ) {
            return s.sample(wl); // already cheaper than a lookup
        }
        let key = s as *const Spectrum as usize;
        for e in &self.entries {
            let (k, l, v) = e.get();
            if k == key && l == wl.lambda {
                return v;
            }
        }
        let v = s.sample(wl);
        let i = self.next.get();
        self.entries[i].set((key, wl.lambda, v));
        self.next.set((i + 1) % CACHED);
        v
    }
}

/// One light sample seen from a surface point, already tested for occlusion.
pub(super) struct LightSample {
    /// Unit direction to the light.
    pub wi: V3,
    /// Emitted radiance at the path's wavelengths (scale included).
    pub le: Lanes,
    /// Solid-angle density of having sampled `wi`, the light's selection included.
    pub pdf: f32,
}

/// The power heuristic's weight of a strategy of density `a` against one of density `b`.
fn mis(a: f32, b: f32) -> f32 {
    let (a2, b2) = (a * a, b * b);
    if a2 + b2 > 0.0 {
        a2 / (a2 + b2)
    } else {
        0.0
    }
}

/// The radiance an emitter sends towards a ray that hit its front (`front`) or back side:
/// its spectrum and scale, or `None` for the unlit back of a one-sided emitter (and for
/// anything that does not emit).
pub(super) fn emission(material: &Material, front: bool) -> Option<(&Spectrum, f32)> {
    match material {
        Material::Emitter {
            radiance,
            scale,
            two_sided,
        } if front || *two_sided => Some((radiance, *scale)),
        _ => None,
    }
}

impl Direct<'_> {
    /// One light sample for a surface at `hit`: `bsdf(wi)` gives the BSDF times cos(wi)
    /// per lane and the density the surface's own sampling gives `wi` (for MIS), or `None`
    /// where the surface does not reflect. Adds the weighted contribution to `radiance`.
    /// Does nothing, and draws no random numbers, without light sampling.
    pub fn next_event(
        &self,
        hit: &Hit,
        wl: &Wavelengths,
        beta: &Lanes,
        rng: &mut Rng,
        radiance: &mut Lanes,
        bsdf: impl Fn(V3) -> Option<(Lanes, f32)>,
    ) {
        if self.sampling.bsdf_only {
            return;
        }
        let x = hit.p + hit.n * crate::geometry::RAY_OFFSET;
        let Some(ls) = sample_light(self.scene, self.sampling, self.spectra, x, wl, rng) else {
            return;
        };
        let Some((f_cos, pdf)) = bsdf(ls.wi) else {
            return;
        };
        // Without MIS the light sample counts in full, and `emitted_weight` gives the hits
        // on emitters after this lobe nothing.
        let w = if self.sampling.no_mis {
            1.0 / ls.pdf
        } else {
            mis(ls.pdf, pdf) / ls.pdf
        };
        for i in 0..LANES {
            radiance[i] += beta[i] * f_cos[i] * ls.le[i] * w;
        }
    }

    /// The weight of the emission a path finds at `hit` (along `d`, from `from`) after a
    /// bounce whose lobe sampled the direction with solid-angle density `prev_pdf`, where 0
    /// marks a bounce next-event estimation did not cover (the camera, specular and
    /// refracted directions): those count in full. So do all hits without light sampling,
    /// and hits on what next-event estimation cannot pick.
    pub fn emitted_weight(&self, prev_pdf: f32, from: V3, hit: &Hit, d: V3) -> f32 {
        if prev_pdf == 0.0 || self.sampling.bsdf_only {
            return 1.0;
        }
        let light = light_pdf(self.scene, self.sampling, hit.prim, from, hit, d);
        if !self.sampling.no_mis {
            mis(prev_pdf, light)
        } else if light == 0.0 {
            1.0
        } else {
            0.0
        }
    }
}

/// The Lambertian lobe (of diffuse surfaces and of plastic's base) with weight `lobe`
/// (the share of light the base gets): one light sample, then a cosine-weighted bounce.
/// Updates `beta` and returns the new direction and the solid-angle density MIS must use
/// for it on the next emitter hit.
#[allow(clippy::too_many_arguments)] // the path state the lobe updates, as in `trace_kernel`
pub(super) fn diffuse_bounce(
    direct: &Direct,
    hit: &Hit,
    rho: Lanes,
    lobe: f32,
    wl: &Wavelengths,
    beta: &mut Lanes,
    rng: &mut Rng,
    radiance: &mut Lanes,
) -> (V3, f32) {
    direct.next_event(hit, wl, beta, rng, radiance, |wi| {
        let cos = hit.n.dot(wi);
        (cos > 0.0).then(|| (rho.map(|r| r * cos / PI), lobe * cos / PI))
    });
    let (wi, pdf) = sample_cosine(hit.n, rng.uniform(), rng.uniform());
    *beta = mul(*beta, rho);
    (wi, lobe * pdf)
}

/// Picks a light (by power, or uniformly in [`Sampling::uniform_lights`]) and a point on
/// it, as seen from `x`; `None` when nothing emits, the point faces away (one-sided
/// emitters) or something blocks it.
fn sample_light(
    scene: &Scene,
    sampling: Sampling,
    spectra: &SpectrumCache,
    x: V3,
    wl: &Wavelengths,
    rng: &mut Rng,
) -> Option<LightSample> {
    let u = rng.uniform();
    let (li, pick) = if sampling.uniform_lights {
        scene.pick_light_uniformly(u)?
    } else {
        scene.pick_light(u)?
    };
    let (u1, u2) = (rng.uniform(), rng.uniform());
    let (wi, dist, area_pdf_to_solid, facing) = match scene.prims[li] {
        Prim::Sphere { c, r } => {
            let (wi, pdf) = sample_sphere_cone(x, c, r, u1, u2)?;
            let t = scene.prims[li].hit_t(x, wi, 0.0, f32::INFINITY)?;
            (wi, t, pdf, true) // seen from outside: the front
        }
        Prim::Quad { p, e1, e2 } => flat_sample(x, p + e1 * u1 + e2 * u2, e1, e2, 1.0)?,
        Prim::Triangle { p0, e1, e2 } => {
            let su = u1.sqrt();
            let q = p0 + e1 * (su * (1.0 - u2)) + e2 * (su * u2);
            flat_sample(x, q, e1, e2, 0.5)?
        }
    };
    let (s, scale) = emission(&scene.materials[scene.prim_material[li]], facing)?;
    if scene.occluded(x, wi, dist * (1.0 - 1e-4), li) {
        return None;
    }
    let le = spectra.sample(s, wl).map(|v| v * scale);
    Some(LightSample {
        wi,
        le,
        pdf: area_pdf_to_solid * pick,
    })
}

/// Direction, distance, solid-angle density and side for a uniformly sampled point `q` of
/// a flat light with edges `e1`, `e2` (`area_share`: 1 for a quad, 1/2 for a triangle).
fn flat_sample(x: V3, q: V3, e1: V3, e2: V3, area_share: f32) -> Option<(V3, f32, f32, bool)> {
    let to = q - x;
    let dist = to.len();
    let wi = to / dist;
    let n = e1.cross(e2);
    let area = n.len() * area_share;
    let cos_l = n.norm().dot(-wi);
    if cos_l.abs() < 1e-6 || area <= 0.0 {
        return None;
    }
    Some((wi, dist, dist * dist / (cos_l.abs() * area), cos_l > 0.0))
}

/// Solid-angle density with which next-event estimation picks the point `hit` on light
/// primitive `prim`, seen from `from` along `d`, the light's selection included.
fn light_pdf(scene: &Scene, sampling: Sampling, prim: usize, from: V3, hit: &Hit, d: V3) -> f32 {
    let pick = if sampling.uniform_lights {
        scene.uniform_light_probability(prim)
    } else {
        scene.light_probability(prim)
    };
    if pick == 0.0 {
        return 0.0;
    }
    let cos_l = hit.n.dot(-d).abs().max(1e-6);
    let solid = match scene.prims[prim] {
        Prim::Sphere { c, r } => sphere_cone_pdf(from, c, r),
        p => hit.t * hit.t / (cos_l * p.area()),
    };
    solid * pick
}
