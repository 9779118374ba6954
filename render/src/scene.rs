//! Scenes: shapes, materials, emitters, camera, and the named scenes.

use crate::spectrum::Spectrum;
use crate::vec3::V3;

/// A surface material.
#[derive(Clone, Debug)]
pub enum Material {
    /// Lambertian reflection with a spectral reflectance; `rgb` is its albedo for the
    /// albedo feature buffer.
    Diffuse {
        /// Spectral reflectance in [0, 1].
        reflectance: Spectrum,
        /// The same reflectance as linear RGB, for the albedo buffer.
        rgb: [f32; 3],
    },
    /// A black emitter: `radiance` (luminance-normalised) times `scale`.
    Emitter {
        /// Spectral shape.
        radiance: Spectrum,
        /// Multiplier (luminance-normalised scenes divide by the shape's luminance).
        scale: f32,
    },
}

/// A shape.
#[derive(Clone, Debug)]
pub enum Shape {
    /// Centre and radius.
    Sphere {
        /// Centre.
        c: V3,
        /// Radius.
        r: f32,
    },
    /// A parallelogram: corner and two edges (normal = e1 x e2, normalised).
    Quad {
        /// Corner.
        p: V3,
        /// First edge.
        e1: V3,
        /// Second edge.
        e2: V3,
    },
}

/// A shape with its material.
#[derive(Clone, Debug)]
pub struct Object {
    /// Geometry.
    pub shape: Shape,
    /// Index into [`Scene::materials`].
    pub material: usize,
}

/// A pinhole camera.
#[derive(Clone, Debug)]
pub struct Camera {
    /// Eye position.
    pub eye: V3,
    /// Point looked at.
    pub target: V3,
    /// Vertical field of view, degrees.
    pub fov_deg: f32,
}

/// Everything a render needs.
#[derive(Clone, Debug)]
pub struct Scene {
    /// Named for the data set and the command line.
    pub name: String,
    /// Materials.
    pub materials: Vec<Material>,
    /// Objects.
    pub objects: Vec<Object>,
    /// Radiance of rays that escape (constant over directions).
    pub environment: Option<(Spectrum, f32)>,
    /// Camera.
    pub camera: Camera,
}

/// A ray hit.
#[derive(Clone, Copy, Debug)]
pub struct Hit {
    /// Distance along the ray.
    pub t: f32,
    /// Position.
    pub p: V3,
    /// Geometric normal facing the ray's origin side.
    pub n: V3,
    /// Object index.
    pub object: usize,
}

impl Shape {
    /// Nearest intersection in (t_min, t_max).
    pub fn intersect(&self, o: V3, d: V3, t_min: f32, t_max: f32) -> Option<(f32, V3)> {
        match *self {
            Shape::Sphere { c, r } => {
                let oc = o - c;
                let b = oc.dot(d);
                let cc = oc.dot(oc) - r * r;
                let disc = b * b - cc;
                if disc < 0.0 {
                    return None;
                }
                let s = disc.sqrt();
                for t in [-b - s, -b + s] {
                    if t > t_min && t < t_max {
                        return Some((t, (o + d * t - c) / r));
                    }
                }
                None
            }
            Shape::Quad { p, e1, e2 } => {
                let n = e1.cross(e2);
                let denom = n.dot(d);
                if denom.abs() < 1e-12 {
                    return None;
                }
                let t = n.dot(p - o) / denom;
                if t <= t_min || t >= t_max {
                    return None;
                }
                let q = o + d * t - p;
                let (a, b) = (q.dot(e1) / e1.dot(e1), q.dot(e2) / e2.dot(e2));
                if (0.0..=1.0).contains(&a) && (0.0..=1.0).contains(&b) {
                    Some((t, n.norm()))
                } else {
                    None
                }
            }
        }
    }

    /// Area.
    pub fn area(&self) -> f32 {
        match *self {
            Shape::Sphere { r, .. } => 4.0 * std::f32::consts::PI * r * r,
            Shape::Quad { e1, e2, .. } => e1.cross(e2).len(),
        }
    }
}

impl Scene {
    /// Nearest hit along a ray (linear scan: the named scenes have few objects).
    pub fn intersect(&self, o: V3, d: V3, t_max: f32) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        for (i, obj) in self.objects.iter().enumerate() {
            let limit = best.map_or(t_max, |h| h.t);
            if let Some((t, n)) = obj.shape.intersect(o, d, 1e-4, limit) {
                let n = if n.dot(d) > 0.0 { -n } else { n };
                best = Some(Hit {
                    t,
                    p: o + d * t,
                    n,
                    object: i,
                });
            }
        }
        best
    }

    /// Indices of emissive quads (the lights next-event estimation samples).
    pub fn lights(&self) -> Vec<usize> {
        self.objects
            .iter()
            .enumerate()
            .filter(|(_, o)| {
                matches!(self.materials[o.material], Material::Emitter { .. })
                    && matches!(o.shape, Shape::Quad { .. })
            })
            .map(|(i, _)| i)
            .collect()
    }
}

fn quad(p: V3, e1: V3, e2: V3, material: usize) -> Object {
    Object {
        shape: Shape::Quad { p, e1, e2 },
        material,
    }
}

/// A synthetic fluorescent lamp: mercury lines and narrow phosphor bands over a low floor,
/// balanced to a cool white (chromaticity about x 0.361, y 0.357, near 4500 K).
pub fn spiky_lamp() -> Spectrum {
    Spectrum::Lines {
        floor: 0.03,
        lines: vec![
            (404.7, 1.5, 0.5),
            (435.8, 1.5, 1.3),
            (487.0, 4.0, 0.5),
            (546.1, 1.5, 2.1),
            (578.0, 2.0, 0.5),
            (611.0, 3.0, 1.1),
        ],
    }
}

/// The names [`named`] knows.
pub const NAMES: [&str; 3] = ["cornell-spiky", "cornell-warm", "furnace"];

/// A named scene.
pub fn named(name: &str) -> Option<Scene> {
    match name {
        "cornell-spiky" => Some(cornell(spiky_lamp())),
        "cornell-warm" => Some(Scene {
            name: "cornell-warm".into(),
            ..cornell(Spectrum::Blackbody(3200.0))
        }),
        "furnace" => Some(furnace()),
        _ => None,
    }
}

/// The Cornell box (unit cube, open front) lit by a ceiling lamp with the given spectrum.
pub fn cornell(lamp: Spectrum) -> Scene {
    let diffuse = |c: [f32; 3]| Material::Diffuse {
        reflectance: Spectrum::Rgb(c),
        rgb: c,
    };
    let materials = vec![
        diffuse([0.73, 0.73, 0.73]),
        diffuse([0.65, 0.05, 0.05]),
        diffuse([0.12, 0.45, 0.15]),
        Material::Emitter {
            scale: 15.0 / lamp.luminance(),
            radiance: lamp,
        },
    ];
    let (w, r, g, l) = (0, 1, 2, 3);
    let objects = vec![
        quad(V3(0.0, 0.0, 0.0), V3(1.0, 0.0, 0.0), V3(0.0, 0.0, 1.0), w), // floor
        quad(V3(0.0, 1.0, 0.0), V3(0.0, 0.0, 1.0), V3(1.0, 0.0, 0.0), w), // ceiling
        quad(V3(0.0, 0.0, 1.0), V3(1.0, 0.0, 0.0), V3(0.0, 1.0, 0.0), w), // back
        quad(V3(0.0, 0.0, 0.0), V3(0.0, 1.0, 0.0), V3(0.0, 0.0, 1.0), r), // left
        quad(V3(1.0, 0.0, 0.0), V3(0.0, 0.0, 1.0), V3(0.0, 1.0, 0.0), g), // right
        quad(
            V3(0.38, 0.999, 0.4),
            V3(0.24, 0.0, 0.0),
            V3(0.0, 0.0, 0.2),
            l,
        ), // lamp
        Object {
            shape: Shape::Sphere {
                c: V3(0.3, 0.18, 0.55),
                r: 0.18,
            },
            material: w,
        },
        Object {
            shape: Shape::Sphere {
                c: V3(0.7, 0.25, 0.35),
                r: 0.25,
            },
            material: w,
        },
    ];
    Scene {
        name: "cornell-spiky".into(),
        materials,
        objects,
        environment: None,
        camera: Camera {
            eye: V3(0.5, 0.5, -1.4),
            target: V3(0.5, 0.5, 0.0),
            fov_deg: 38.0,
        },
    }
}

/// White furnace: a white diffuse sphere under a uniform environment of radiance 1.
/// Energy conservation means every pixel, sphere or not, has luminance 1.
pub fn furnace() -> Scene {
    Scene {
        name: "furnace".into(),
        materials: vec![Material::Diffuse {
            reflectance: Spectrum::Constant(1.0),
            rgb: [1.0; 3],
        }],
        objects: vec![Object {
            shape: Shape::Sphere {
                c: V3(0.0, 0.0, 0.0),
                r: 1.0,
            },
            material: 0,
        }],
        environment: Some((Spectrum::Constant(1.0), 1.0)),
        camera: Camera {
            eye: V3(0.0, 0.0, -4.0),
            target: V3(0.0, 0.0, 0.0),
            fov_deg: 40.0,
        },
    }
}
