//! The assembled scene the integrator queries: primitives with materials behind a BVH,
//! the lights, the camera, and the inspection that picks a render kernel.

use crate::camera::Camera;
use crate::geometry::bvh::Bvh;
use crate::geometry::shape::{Prim, PrimHit};
use crate::geometry::vec3::V3;
use crate::materials::Material;
use crate::spectral::spectrum::Spectrum;

/// Everything a render needs.
#[derive(Clone, Debug)]
pub struct Scene {
    /// Named for the data set and the command line.
    pub name: String,
    /// Materials.
    pub materials: Vec<Material>,
    /// Primitives.
    pub prims: Vec<Prim>,
    /// Material index of each primitive.
    pub prim_material: Vec<usize>,
    /// Radiance of rays that escape (constant over directions): shape and scale.
    pub environment: Option<(Spectrum, f32)>,
    /// Camera.
    pub camera: Camera,
    bvh: Bvh,
    lights: Lights,
}

/// The emitting primitives next-event estimation samples, chosen in proportion to their
/// power, so a scene of many dim lamps and one bright one spends its light samples on the
/// bright one.
#[derive(Clone, Debug, Default)]
struct Lights {
    /// Primitive indices.
    prims: Vec<usize>,
    /// Cumulative selection probability (last = 1).
    cdf: Vec<f32>,
    /// Selection probability of every primitive (0 for those that do not emit).
    prob: Vec<f32>,
}

impl Lights {
    fn new(prims: &[Prim], prim_material: &[usize], materials: &[Material]) -> Self {
        // Emitted power per unit area of each material: `scale` is the radiance's
        // luminance, and a side emits pi times its radiance.
        let density: Vec<f64> = materials
            .iter()
            .map(|m| match m {
                Material::Emitter {
                    scale,
                    radiance,
                    two_sided,
                } => {
                    let sides = if *two_sided { 2.0 } else { 1.0 };
                    (scale * radiance.luminance()) as f64 * sides
                }
                _ => 0.0,
            })
            .collect();
        let power = |i: usize| density[prim_material[i]] * prims[i].area() as f64;
        let lit: Vec<(usize, f64)> = (0..prims.len())
            .map(|i| (i, power(i)))
            .filter(|&(_, p)| p > 0.0 && p.is_finite())
            .collect();
        let total: f64 = lit.iter().map(|l| l.1).sum();
        let mut prob = vec![0.0f32; prims.len()];
        let mut cdf = Vec::with_capacity(lit.len());
        let mut acc = 0.0f64;
        for &(i, p) in &lit {
            prob[i] = (p / total) as f32;
            acc += p / total;
            cdf.push(acc as f32);
        }
        if let Some(last) = cdf.last_mut() {
            *last = 1.0;
        }
        Lights {
            prims: lit.iter().map(|l| l.0).collect(),
            cdf,
            prob,
        }
    }
}

/// A ray hit.
#[derive(Clone, Copy, Debug)]
pub struct Hit {
    /// Distance along the ray.
    pub t: f32,
    /// Position.
    pub p: V3,
    /// Geometric normal on the side the ray came from.
    pub n: V3,
    /// Whether the ray hit the front (outside) of the primitive.
    pub front: bool,
    /// Texture coordinates.
    pub uv: (f32, f32),
    /// Primitive index.
    pub prim: usize,
    /// Material index.
    pub material: usize,
}

/// What a scene contains, which decides the cheapest correct render kernel.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Features {
    /// A dielectric whose index depends on wavelength: refraction must split wavelengths.
    pub dispersion: bool,
    /// Any dielectric: the loop needs refraction code.
    pub transmission: bool,
    /// An emitter with narrow lines: wavelengths are sampled from the emitters' spectra.
    pub spiky_emitters: bool,
    /// Any glossy or specular surface (conductor, dielectric, plastic coat).
    pub glossy: bool,
}

impl Scene {
    /// Assembles a scene and builds its BVH. `objects` pairs shapes with material indices.
    pub fn new(
        name: &str,
        materials: Vec<Material>,
        objects: Vec<(Vec<Prim>, usize)>,
        environment: Option<(Spectrum, f32)>,
        camera: Camera,
    ) -> Self {
        let mut prims = Vec::new();
        let mut prim_material = Vec::new();
        for (shape, m) in objects {
            prim_material.extend(std::iter::repeat_n(m, shape.len()));
            prims.extend(shape);
        }
        let bvh = Bvh::build(&prims);
        let mut materials = materials;
        for m in &mut materials {
            if let Material::Emitter { radiance, .. } = m {
                *radiance = radiance.dense();
            }
        }
        let environment = environment.map(|(s, scale)| (s.dense(), scale));
        let lights = Lights::new(&prims, &prim_material, &materials);
        Scene {
            name: name.into(),
            materials,
            prims,
            prim_material,
            environment,
            camera,
            bvh,
            lights,
        }
    }

    /// Nearest hit along a unit ray, with t in (t_min, t_max).
    pub fn intersect(&self, o: V3, d: V3, t_min: f32, t_max: f32) -> Option<Hit> {
        let (prim, PrimHit { t, n, uv }) = self.bvh.intersect(&self.prims, o, d, t_min, t_max)?;
        let front = n.dot(d) < 0.0;
        Some(Hit {
            t,
            p: o + d * t,
            n: if front { n } else { -n },
            front,
            uv,
            prim,
            material: self.prim_material[prim],
        })
    }

    /// Whether anything but primitive `skip` blocks the segment from `o` along `d`.
    pub fn occluded(&self, o: V3, d: V3, t_max: f32, skip: usize) -> bool {
        self.bvh.occluded(o, d, t_max, &[skip])
    }

    /// The emitting primitives: the lights next-event estimation samples.
    pub fn lights(&self) -> &[usize] {
        &self.lights.prims
    }

    /// Picks a light in proportion to its power from a uniform number `u`: the primitive
    /// and the probability of having picked it. `None` when nothing emits.
    pub fn pick_light(&self, u: f32) -> Option<(usize, f32)> {
        let l = &self.lights;
        let k = l
            .cdf
            .partition_point(|&c| c <= u)
            .min(l.prims.len().checked_sub(1)?);
        let prim = l.prims[k];
        Some((prim, l.prob[prim]))
    }

    /// The probability with which [`Scene::pick_light`] picks primitive `prim`.
    pub fn light_probability(&self, prim: usize) -> f32 {
        self.lights.prob[prim]
    }

    /// Picks a light uniformly, every emitting primitive alike, from a uniform number `u`
    /// (what a renderer without power-based selection does): the primitive and the
    /// probability of having picked it. `None` when nothing emits.
    pub fn pick_light_uniformly(&self, u: f32) -> Option<(usize, f32)> {
        let prims = &self.lights.prims;
        let k = ((u * prims.len() as f32) as usize).min(prims.len().checked_sub(1)?);
        Some((prims[k], 1.0 / prims.len() as f32))
    }

    /// The probability with which [`Scene::pick_light_uniformly`] picks primitive `prim`.
    pub fn uniform_light_probability(&self, prim: usize) -> f32 {
        let prims = &self.lights.prims;
        // `Lights::new` lists the lit primitives in index order.
        if prims.binary_search(&prim).is_ok() {
            1.0 / prims.len() as f32
        } else {
            0.0
        }
    }

    /// Spectra of every emitter and of the environment.
    pub fn emitter_spectra(&self) -> Vec<&Spectrum> {
        let mut v: Vec<&Spectrum> = self
            .materials
            .iter()
            .filter_map(|m| match m {
                Material::Emitter { radiance, .. } => Some(radiance),
                _ => None,
            })
            .collect();
        if let Some((s, _)) = &self.environment {
            v.push(s);
        }
        v
    }

    /// Inspects the materials that primitives use.
    pub fn features(&self) -> Features {
        let mut f = Features::default();
        let mut used = vec![false; self.materials.len()];
        for &m in &self.prim_material {
            used[m] = true;
        }
        for (m, _) in self.materials.iter().zip(&used).filter(|(_, u)| **u) {
            match m {
                Material::Dielectric { ior, .. } => {
                    f.transmission = true;
                    f.glossy = true;
                    f.dispersion |= ior.dispersive();
                }
                Material::Conductor { .. } | Material::Plastic { .. } => f.glossy = true,
                Material::Emitter { radiance, .. } => f.spiky_emitters |= radiance.is_spiky(),
                Material::Diffuse { .. } => {}
            }
        }
        if let Some((s, _)) = &self.environment {
            f.spiky_emitters |= s.is_spiky();
        }
        f
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::description::named;

    #[test]
    fn inspection_finds_what_each_scene_calls_for() {
        let f = |n: &str| named::scene(n).unwrap().features();
        assert_eq!(f("cornell-warm"), Features::default());
        assert!(f("cornell-spiky").spiky_emitters && !f("cornell-spiky").transmission);
        assert!(f("prism").dispersion && f("prism").transmission);
        assert!(f("metals").glossy && !f("metals").transmission);
        assert!(f("laser").spiky_emitters);
    }
}
