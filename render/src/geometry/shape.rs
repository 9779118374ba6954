//! Geometric primitives (spheres, quads, triangles), their intersection and sampling, and
//! the shapes built from them (boxes, prisms, tori).

use std::f32::consts::PI;

use crate::geometry::vec3::V3;

/// A primitive the BVH holds.
#[derive(Clone, Copy, Debug)]
pub enum Prim {
    /// Centre and radius.
    Sphere {
        /// Centre.
        c: V3,
        /// Radius.
        r: f32,
    },
    /// A parallelogram: corner and two edges; its front faces along `e1 x e2`.
    Quad {
        /// Corner.
        p: V3,
        /// First edge.
        e1: V3,
        /// Second edge.
        e2: V3,
    },
    /// A triangle: a vertex and the two edges from it; its front faces along `e1 x e2`.
    Triangle {
        /// First vertex.
        p0: V3,
        /// Edge to the second vertex.
        e1: V3,
        /// Edge to the third vertex.
        e2: V3,
    },
}

/// Where a ray met a primitive.
#[derive(Clone, Copy, Debug)]
pub struct PrimHit {
    /// Distance along the (unit) ray.
    pub t: f32,
    /// Outward (front-side) unit normal.
    pub n: V3,
    /// Surface coordinates in scene units, for textures.
    pub uv: (f32, f32),
}

/// An axis-aligned box.
#[derive(Clone, Copy, Debug)]
pub struct Aabb {
    /// Lower corner.
    pub lo: V3,
    /// Upper corner.
    pub hi: V3,
}

impl Aabb {
    /// The empty box.
    pub const EMPTY: Aabb = Aabb {
        lo: V3(f32::INFINITY, f32::INFINITY, f32::INFINITY),
        hi: V3(f32::NEG_INFINITY, f32::NEG_INFINITY, f32::NEG_INFINITY),
    };
    /// Grows to contain a point.
    pub fn grow(self, p: V3) -> Aabb {
        Aabb {
            lo: V3(self.lo.0.min(p.0), self.lo.1.min(p.1), self.lo.2.min(p.2)),
            hi: V3(self.hi.0.max(p.0), self.hi.1.max(p.1), self.hi.2.max(p.2)),
        }
    }
    /// Union.
    pub fn join(self, o: Aabb) -> Aabb {
        self.grow(o.lo).grow(o.hi)
    }
    /// Half the surface area (the SAH's cost measure).
    pub fn half_area(&self) -> f32 {
        let d = self.hi - self.lo;
        if d.0 < 0.0 {
            return 0.0;
        }
        d.0 * d.1 + d.1 * d.2 + d.2 * d.0
    }
    /// Centre.
    pub fn centre(&self) -> V3 {
        (self.lo + self.hi) * 0.5
    }
}

impl Prim {
    /// Bounding box (padded so flat shapes have volume).
    pub fn bounds(&self) -> Aabb {
        let pad = V3(1e-4, 1e-4, 1e-4);
        let b = match *self {
            Prim::Sphere { c, r } => Aabb {
                lo: c - V3(r, r, r),
                hi: c + V3(r, r, r),
            },
            Prim::Quad { p, e1, e2 } => Aabb::EMPTY
                .grow(p)
                .grow(p + e1)
                .grow(p + e2)
                .grow(p + e1 + e2),
            Prim::Triangle { p0, e1, e2 } => Aabb::EMPTY.grow(p0).grow(p0 + e1).grow(p0 + e2),
        };
        Aabb {
            lo: b.lo - pad,
            hi: b.hi + pad,
        }
    }

    /// Nearest intersection with `t` in (t_min, t_max); `d` is a unit vector.
    pub fn intersect(&self, o: V3, d: V3, t_min: f32, t_max: f32) -> Option<PrimHit> {
        let t = self.hit_t(o, d, t_min, t_max)?;
        Some(self.surface(o + d * t, t))
    }

    /// The distance of the nearest intersection with `t` in (t_min, t_max), without the
    /// surface details (the BVH tests its primitives in their packed form directly).
    pub fn hit_t(&self, o: V3, d: V3, t_min: f32, t_max: f32) -> Option<f32> {
        Packed::new(self).hit_t(o, d, t_min, t_max)
    }

    /// The outward normal and texture coordinates at the point `x` (at distance `t`) where
    /// a ray met the primitive.
    pub fn surface(&self, x: V3, t: f32) -> PrimHit {
        match *self {
            Prim::Sphere { c, r } => {
                let n = (x - c) / r;
                let uv = (n.2.atan2(n.0) * r, n.1.clamp(-1.0, 1.0).acos() * r);
                PrimHit { t, n, uv }
            }
            Prim::Quad { p, e1, e2 } => {
                let q = x - p;
                let (l1, l2) = (e1.dot(e1), e2.dot(e2));
                PrimHit {
                    t,
                    n: e1.cross(e2).norm(),
                    uv: (q.dot(e1) / l1.sqrt(), q.dot(e2) / l2.sqrt()),
                }
            }
            Prim::Triangle { e1, e2, .. } => {
                let n = e1.cross(e2).norm();
                PrimHit {
                    t,
                    n,
                    uv: planar_uv(x, n),
                }
            }
        }
    }

    /// Surface area.
    pub fn area(&self) -> f32 {
        match *self {
            Prim::Sphere { r, .. } => 4.0 * PI * r * r,
            Prim::Quad { e1, e2, .. } => e1.cross(e2).len(),
            Prim::Triangle { e1, e2, .. } => 0.5 * e1.cross(e2).len(),
        }
    }
}

/// Texture coordinates for flat shapes without a parameterisation: the position projected
/// on the plane across the normal's dominant axis.
fn planar_uv(p: V3, n: V3) -> (f32, f32) {
    let a = V3(n.0.abs(), n.1.abs(), n.2.abs());
    if a.0 >= a.1 && a.0 >= a.2 {
        (p.2, p.1)
    } else if a.1 >= a.2 {
        (p.0, p.2)
    } else {
        (p.0, p.1)
    }
}

/// Rotation about the y axis, degrees.
pub fn rotate_y(v: V3, deg: f32) -> V3 {
    let (s, c) = deg.to_radians().sin_cos();
    V3(c * v.0 + s * v.2, v.1, -s * v.0 + c * v.2)
}

/// Rotation about the x axis, degrees.
pub fn rotate_x(v: V3, deg: f32) -> V3 {
    let (s, c) = deg.to_radians().sin_cos();
    V3(v.0, c * v.1 - s * v.2, s * v.1 + c * v.2)
}

/// Orients every face of a convex solid outwards (away from `centre`).
fn outward(faces: Vec<Prim>, centre: V3) -> Vec<Prim> {
    faces
        .into_iter()
        .map(|f| match f {
            Prim::Quad { p, e1, e2 } if e1.cross(e2).dot(p + (e1 + e2) * 0.5 - centre) < 0.0 => {
                Prim::Quad { p, e1: e2, e2: e1 }
            }
            Prim::Triangle { p0, e1, e2 }
                if e1.cross(e2).dot(p0 + (e1 + e2) * (1.0 / 3.0) - centre) < 0.0 =>
            {
                Prim::Triangle { p0, e1: e2, e2: e1 }
            }
            f => f,
        })
        .collect()
}

/// A box from its corners, turned `rot_y` degrees about its vertical axis: six quads facing
/// outwards.
pub fn boxed(lo: V3, hi: V3, rot_y: f32) -> Vec<Prim> {
    let c = (lo + hi) * 0.5;
    let h = (hi - lo) * 0.5;
    let corner = |x: f32, y: f32, z: f32| c + rotate_y(V3(x * h.0, y * h.1, z * h.2), rot_y);
    let q = |a: V3, b: V3, d: V3| Prim::Quad {
        p: a,
        e1: b - a,
        e2: d - a,
    };
    let f = vec![
        q(
            corner(-1., -1., -1.),
            corner(1., -1., -1.),
            corner(-1., 1., -1.),
        ),
        q(
            corner(-1., -1., 1.),
            corner(1., -1., 1.),
            corner(-1., 1., 1.),
        ),
        q(
            corner(-1., -1., -1.),
            corner(-1., 1., -1.),
            corner(-1., -1., 1.),
        ),
        q(
            corner(1., -1., -1.),
            corner(1., 1., -1.),
            corner(1., -1., 1.),
        ),
        q(
            corner(-1., -1., -1.),
            corner(1., -1., -1.),
            corner(-1., -1., 1.),
        ),
        q(
            corner(-1., 1., -1.),
            corner(1., 1., -1.),
            corner(-1., 1., 1.),
        ),
    ];
    outward(f, c)
}

/// A triangular prism standing on its base: equilateral cross-section of side `size`
/// extruded `height` along z, apex up, turned `rot_y` degrees.
pub fn prism(centre: V3, size: f32, height: f32, rot_y: f32) -> Vec<Prim> {
    let r = size / 3f32.sqrt();
    let tri: Vec<V3> = (0..3)
        .map(|k| {
            let a = (90.0 + 120.0 * k as f32).to_radians();
            V3(r * a.cos(), r * a.sin() + r * 0.5, 0.0)
        })
        .collect();
    let place = |v: V3, z: f32| centre + rotate_y(V3(v.0, v.1, z), rot_y);
    let (z0, z1) = (-height * 0.5, height * 0.5);
    let mut f = Vec::new();
    let t = |a: V3, b: V3, c: V3| Prim::Triangle {
        p0: a,
        e1: b - a,
        e2: c - a,
    };
    f.push(t(place(tri[0], z0), place(tri[1], z0), place(tri[2], z0)));
    f.push(t(place(tri[0], z1), place(tri[1], z1), place(tri[2], z1)));
    for k in 0..3 {
        let (a, b) = (tri[k], tri[(k + 1) % 3]);
        f.push(Prim::Quad {
            p: place(a, z0),
            e1: place(b, z0) - place(a, z0),
            e2: place(a, z1) - place(a, z0),
        });
    }
    let c = place(V3(0.0, r * 0.5, 0.0), 0.0);
    outward(f, c)
}

/// A torus around the y axis (major radius `big`, tube radius `small`), tilted `tilt_x`
/// degrees, as a triangle mesh (the generator's mesh, so the BVH is exercised).
pub fn torus(centre: V3, big: f32, small: f32, tilt_x: f32) -> Vec<Prim> {
    let (nu, nv) = (48, 16);
    let at = |i: usize, j: usize| {
        let u = 2.0 * PI * i as f32 / nu as f32;
        let v = 2.0 * PI * j as f32 / nv as f32;
        let ring = big + small * v.cos();
        centre + rotate_x(V3(ring * u.cos(), small * v.sin(), ring * u.sin()), tilt_x)
    };
    let mut f = Vec::with_capacity(nu * nv * 2);
    for i in 0..nu {
        for j in 0..nv {
            let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
            // Winding chosen so e1 x e2 points out of the tube.
            f.push(Prim::Triangle {
                p0: a,
                e1: c - a,
                e2: b - a,
            });
            f.push(Prim::Triangle {
                p0: a,
                e1: d - a,
                e2: c - a,
            });
        }
    }
    f
}

/// A uniformly sampled direction inside the cone that a sphere subtends from `p`, with its
/// solid-angle density; `None` when `p` is inside the sphere.
pub fn sample_sphere_cone(p: V3, c: V3, r: f32, u1: f32, u2: f32) -> Option<(V3, f32)> {
    let to = c - p;
    let d2 = to.dot(to);
    if d2 <= r * r {
        return None;
    }
    let cos_max = (1.0 - r * r / d2).max(0.0).sqrt();
    let cos = 1.0 - u1 * (1.0 - cos_max);
    let sin = (1.0 - cos * cos).max(0.0).sqrt();
    let phi = 2.0 * PI * u2;
    let w = to / d2.sqrt();
    let (t, b) = crate::geometry::vec3::basis(w);
    let dir = (t * (sin * phi.cos()) + b * (sin * phi.sin()) + w * cos).norm();
    Some((dir, sphere_cone_pdf(p, c, r)))
}

/// Solid-angle density of [`sample_sphere_cone`].
pub fn sphere_cone_pdf(p: V3, c: V3, r: f32) -> f32 {
    let d2 = (c - p).dot(c - p);
    if d2 <= r * r {
        return 0.0;
    }
    let cos_max = (1.0 - r * r / d2).max(0.0).sqrt();
    1.0 / (2.0 * PI * (1.0 - cos_max)).max(1e-12)
}

/// A primitive prepared for the ray test: quads keep their normal and edges scaled by
/// their inverse squared lengths, so a test needs no cross product or division but one.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Packed {
    Sphere { c: V3, r2: f32 },
    Quad { p: V3, n: V3, e1: V3, e2: V3 },
    Triangle { p0: V3, e1: V3, e2: V3 },
}

impl Packed {
    /// The packed form of `p`.
    pub(crate) fn new(p: &Prim) -> Self {
        match *p {
            Prim::Sphere { c, r } => Packed::Sphere { c, r2: r * r },
            Prim::Quad { p, e1, e2 } => Packed::Quad {
                p,
                n: e1.cross(e2),
                e1: e1 / e1.dot(e1),
                e2: e2 / e2.dot(e2),
            },
            Prim::Triangle { p0, e1, e2 } => Packed::Triangle { p0, e1, e2 },
        }
    }

    /// The distance of the nearest intersection with `t` in (t_min, t_max). Always
    /// inlined: the traversal loops call it per primitive, and a call each cost more
    /// than the test.
    #[inline(always)]
    pub(crate) fn hit_t(&self, o: V3, d: V3, t_min: f32, t_max: f32) -> Option<f32> {
        match *self {
            Packed::Sphere { c, r2 } => {
                let oc = o - c;
                let b = oc.dot(d);
                let disc = b * b - (oc.dot(oc) - r2);
                if disc < 0.0 {
                    return None;
                }
                let s = disc.sqrt();
                [-b - s, -b + s]
                    .into_iter()
                    .find(|&t| t > t_min && t < t_max)
            }
            Packed::Quad { p, n, e1, e2 } => {
                let denom = n.dot(d);
                if denom.abs() < 1e-12 {
                    return None;
                }
                let t = n.dot(p - o) / denom;
                if t <= t_min || t >= t_max {
                    return None;
                }
                let q = o + d * t - p;
                let (a, b) = (q.dot(e1), q.dot(e2));
                ((0.0..=1.0).contains(&a) && (0.0..=1.0).contains(&b)).then_some(t)
            }
            Packed::Triangle { p0, e1, e2 } => {
                // Moeller-Trumbore.
                let pv = d.cross(e2);
                let det = e1.dot(pv);
                if det.abs() < 1e-12 {
                    return None;
                }
                let inv = 1.0 / det;
                let tv = o - p0;
                let u = tv.dot(pv) * inv;
                if !(0.0..=1.0).contains(&u) {
                    return None;
                }
                let qv = tv.cross(e1);
                let v = d.dot(qv) * inv;
                if v < 0.0 || u + v > 1.0 {
                    return None;
                }
                let t = e2.dot(qv) * inv;
                (t > t_min && t < t_max).then_some(t)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn closed_shapes_face_outwards() {
        let solids = [
            (
                boxed(V3(0., 0., 0.), V3(1., 2., 1.), 30.0),
                V3(0.5, 1.0, 0.5),
            ),
            (prism(V3(0., 0., 0.), 1.0, 1.0, 10.0), V3(0.0, 0.2887, 0.0)),
        ];
        for (faces, c) in solids {
            for f in &faces {
                // A ray from the centre towards the face's middle hits its front side.
                let mid = match *f {
                    Prim::Quad { p, e1, e2 } => p + (e1 + e2) * 0.5,
                    Prim::Triangle { p0, e1, e2 } => p0 + (e1 + e2) * (1.0 / 3.0),
                    Prim::Sphere { .. } => unreachable!(),
                };
                let d = (mid - c).norm();
                let h = f.intersect(c, d, 0.0, 1e9).expect("hit");
                assert!(h.n.dot(d) > 0.0);
            }
        }
    }

    #[test]
    fn torus_normals_point_out_of_the_tube() {
        let c = V3(0.0, 0.0, 0.0);
        for f in torus(c, 1.0, 0.3, 0.0) {
            let Prim::Triangle { p0, e1, e2 } = f else {
                unreachable!()
            };
            let mid = p0 + (e1 + e2) * (1.0 / 3.0);
            let ring = V3(mid.0, 0.0, mid.2).norm();
            assert!(e1.cross(e2).dot(mid - ring) > 0.0);
        }
    }

    #[test]
    fn cone_sampling_hits_the_sphere() {
        let (c, r, p) = (V3(0., 0., 5.), 1.0, V3(0., 0., 0.));
        for k in 0..100 {
            let (d, pdf) = sample_sphere_cone(
                p,
                c,
                r,
                (k as f32 + 0.5) / 100.0,
                (k * 37 % 100) as f32 / 100.0,
            )
            .unwrap();
            assert!(pdf > 0.0);
            assert!(Prim::Sphere { c, r }.intersect(p, d, 0.0, 1e9).is_some());
        }
    }
}
