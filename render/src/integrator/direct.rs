//! Direct lighting: next-event estimation on the scene's emitting primitives (picked in
//! proportion to power), MIS-weighted (power heuristic) against the surface's own
//! sampling, and the emission a path finds when it hits a light.

use std::f32::consts::PI;

use crate::geometry::shape::{sample_sphere_cone, sphere_cone_pdf, Prim};
use crate::geometry::vec3::V3;
use crate::materials::scattering::sample_cosine;
use crate::materials::Material;
use crate::rng::Rng;
use crate::scene::{Hit, Scene};
use crate::spectral::spectrum::Spectrum;
use crate::spectral::wavelengths::{mul, Lanes, Wavelengths, LANES};

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
pub(super) fn mis(a: f32, b: f32) -> f32 {
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

/// One light sample for a surface at `hit`: `bsdf(wi)` gives the BSDF times cos(wi) per
/// lane and the density the surface's own sampling gives `wi` (for MIS), or `None` where
/// the surface does not reflect. Adds the weighted contribution to `radiance`.
pub(super) fn next_event(
    scene: &Scene,
    hit: &Hit,
    wl: &Wavelengths,
    beta: &Lanes,
    rng: &mut Rng,
    radiance: &mut Lanes,
    bsdf: impl Fn(V3) -> Option<(Lanes, f32)>,
) {
    let x = hit.p + hit.n * crate::geometry::RAY_OFFSET;
    let Some(ls) = sample_light(scene, x, wl, rng) else {
        return;
    };
    let Some((f_cos, pdf)) = bsdf(ls.wi) else {
        return;
    };
    let w = mis(ls.pdf, pdf) / ls.pdf;
    for i in 0..LANES {
        radiance[i] += beta[i] * f_cos[i] * ls.le[i] * w;
    }
}

/// The Lambertian lobe (of diffuse surfaces and of plastic's base) with weight `lobe`
/// (the share of light the base gets): one light sample, then a cosine-weighted bounce.
/// Updates `beta` and returns the new direction and the solid-angle density MIS must use
/// for it on the next emitter hit.
#[allow(clippy::too_many_arguments)] // the path state the lobe updates, as in `trace_kernel`
pub(super) fn diffuse_bounce(
    scene: &Scene,
    hit: &Hit,
    rho: Lanes,
    lobe: f32,
    wl: &Wavelengths,
    beta: &mut Lanes,
    rng: &mut Rng,
    radiance: &mut Lanes,
) -> (V3, f32) {
    next_event(scene, hit, wl, beta, rng, radiance, |wi| {
        let cos = hit.n.dot(wi);
        (cos > 0.0).then(|| (rho.map(|r| r * cos / PI), lobe * cos / PI))
    });
    let (wi, pdf) = sample_cosine(hit.n, rng.uniform(), rng.uniform());
    *beta = mul(*beta, rho);
    (wi, lobe * pdf)
}

/// Picks a light by power and a point on it, as seen from `x`; `None` when nothing emits,
/// the point faces away (one-sided emitters) or something blocks it.
pub(super) fn sample_light(
    scene: &Scene,
    x: V3,
    wl: &Wavelengths,
    rng: &mut Rng,
) -> Option<LightSample> {
    let (li, pick) = scene.pick_light(rng.uniform())?;
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
    let le = s.sample(wl).map(|v| v * scale);
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
pub(super) fn light_pdf(scene: &Scene, prim: usize, from: V3, hit: &Hit, d: V3) -> f32 {
    let pick = scene.light_probability(prim);
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
