//! The scattering functions materials are built from: Fresnel terms, mirror reflection and
//! refraction, GGX masking and visible-normal sampling, cosine-weighted sampling.

use std::f32::consts::PI;

use crate::geometry::vec3::{basis, V3};

/// Unpolarised Fresnel reflectance of a dielectric interface; `eta` = n_transmitted /
/// n_incident, `cos_i` >= 0. Returns 1 under total internal reflection.
pub fn fresnel_dielectric(cos_i: f32, eta: f32) -> f32 {
    let cos_i = cos_i.clamp(0.0, 1.0);
    let sin2_t = (1.0 - cos_i * cos_i) / (eta * eta);
    if sin2_t >= 1.0 {
        return 1.0;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    let rs = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    let rp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    0.5 * (rs * rs + rp * rp)
}

/// Unpolarised Fresnel reflectance of a conductor with complex index eta + i k, seen from
/// a medium of index 1 (the closed form of Born & Wolf, in real arithmetic).
pub fn fresnel_conductor(cos_i: f32, eta: f32, k: f32) -> f32 {
    let c = cos_i.clamp(0.0, 1.0) as f64;
    let (eta, k) = (eta as f64, k as f64);
    let c2 = c * c;
    let s2 = 1.0 - c2;
    let t0 = eta * eta - k * k - s2;
    let a2b2 = (t0 * t0 + 4.0 * eta * eta * k * k).sqrt();
    let a = (0.5 * (a2b2 + t0)).max(0.0).sqrt();
    let rs = (a2b2 + c2 - 2.0 * a * c) / (a2b2 + c2 + 2.0 * a * c);
    let t1 = a2b2 * c2 + s2 * s2;
    let t2 = 2.0 * a * c * s2;
    let rp = rs * (t1 - t2) / (t1 + t2);
    (0.5 * (rs + rp)) as f32
}

/// Mirror reflection of `wo` (pointing away from the surface) about `n`.
pub fn reflect(wo: V3, n: V3) -> V3 {
    n * (2.0 * wo.dot(n)) - wo
}

/// Refraction of `wo` (pointing away, on `n`'s side) through a surface of relative index
/// `eta` = n_transmitted / n_incident; `None` under total internal reflection.
pub fn refract(wo: V3, n: V3, eta: f32) -> Option<V3> {
    let cos_i = wo.dot(n);
    let sin2_t = (1.0 - cos_i * cos_i).max(0.0) / (eta * eta);
    if sin2_t >= 1.0 {
        return None;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    Some((-wo / eta + n * (cos_i / eta - cos_t)).norm())
}

/// Smith's masking term G1 for GGX with parameter `alpha`, `cos` measured from the
/// macro normal.
pub fn ggx_g1(cos: f32, alpha: f32) -> f32 {
    let c2 = (cos * cos).max(1e-8);
    let tan2 = (1.0 - c2).max(0.0) / c2;
    2.0 / (1.0 + (1.0 + alpha * alpha * tan2).sqrt())
}

/// GGX's distribution of normals D(m) for a microfacet normal at `cos_m` from the macro
/// normal.
pub fn ggx_d(cos_m: f32, alpha: f32) -> f32 {
    if cos_m <= 0.0 {
        return 0.0;
    }
    let a2 = alpha * alpha;
    let t = cos_m * cos_m * (a2 - 1.0) + 1.0;
    a2 / (PI * t * t)
}

/// GGX reflection from `wo` into `wi` about the macro normal `n` (all unit, pointing away):
/// the BSDF times cos(wi) without the Fresnel factor, the solid-angle density with which
/// visible-normal sampling picks `wi`, and the cosine between `wo` and the half vector
/// (the Fresnel factor's angle). `None` when either direction is below the surface.
pub fn ggx_reflection(wo: V3, wi: V3, n: V3, alpha: f32) -> Option<(f32, f32, f32)> {
    let (cos_o, cos_i) = (wo.dot(n), wi.dot(n));
    if cos_o <= 0.0 || cos_i <= 0.0 {
        return None;
    }
    let h = (wo + wi).norm();
    let d = ggx_d(h.dot(n), alpha);
    let g1o = ggx_g1(cos_o, alpha);
    let pdf = g1o * d / (4.0 * cos_o);
    Some((pdf * ggx_g1(cos_i, alpha), pdf, wo.dot(h).max(0.0)))
}

/// A microfacet normal sampled from GGX's distribution of visible normals (Heitz 2018),
/// for `wo` in the local frame where the macro normal is +z.
pub fn ggx_sample_vndf(wo: V3, alpha: f32, u1: f32, u2: f32) -> V3 {
    let vh = V3(alpha * wo.0, alpha * wo.1, wo.2).norm();
    let len2 = vh.0 * vh.0 + vh.1 * vh.1;
    let t1 = if len2 > 0.0 {
        V3(-vh.1, vh.0, 0.0) / len2.sqrt()
    } else {
        V3(1.0, 0.0, 0.0)
    };
    let t2 = vh.cross(t1);
    let r = u1.sqrt();
    let phi = 2.0 * PI * u2;
    let p1 = r * phi.cos();
    let s = 0.5 * (1.0 + vh.2);
    let p2 = (1.0 - s) * (1.0 - p1 * p1).max(0.0).sqrt() + s * r * phi.sin();
    let nh = t1 * p1 + t2 * p2 + vh * (1.0 - p1 * p1 - p2 * p2).max(0.0).sqrt();
    V3(alpha * nh.0, alpha * nh.1, nh.2.max(1e-6)).norm()
}

/// World-space microfacet normal around `n` for a surface of GGX `alpha`.
pub fn sample_microfacet(wo: V3, n: V3, alpha: f32, u1: f32, u2: f32) -> V3 {
    let (t, b) = basis(n);
    let local = V3(wo.dot(t), wo.dot(b), wo.dot(n));
    let m = ggx_sample_vndf(local, alpha, u1, u2);
    (t * m.0 + b * m.1 + n * m.2).norm()
}

/// Cosine-weighted direction around `n`, and its solid-angle density.
pub fn sample_cosine(n: V3, u1: f32, u2: f32) -> (V3, f32) {
    let r = u1.sqrt();
    let phi = 2.0 * PI * u2;
    let z = (1.0 - u1).max(0.0).sqrt();
    let (t, b) = basis(n);
    (
        (t * (r * phi.cos()) + b * (r * phi.sin()) + n * z).norm(),
        z / PI,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dielectric_fresnel_limits() {
        assert!((fresnel_dielectric(1.0, 1.5) - 0.04).abs() < 1e-6);
        assert!(fresnel_dielectric(0.0, 1.5) > 0.999);
        // Inside glass past the critical angle: total internal reflection.
        assert_eq!(fresnel_dielectric(0.5, 1.0 / 1.5), 1.0);
    }

    #[test]
    fn refraction_obeys_snell() {
        let n = V3(0.0, 0.0, 1.0);
        let wo = V3(0.6, 0.0, 0.8);
        let t = refract(wo, n, 1.5).unwrap();
        let sin_i = 0.6;
        let sin_t = (t.0 * t.0 + t.1 * t.1).sqrt();
        assert!((sin_i - 1.5 * sin_t).abs() < 1e-5);
        assert!(t.2 < 0.0);
    }

    #[test]
    fn ggx_density_matches_visible_normal_sampling() {
        // Histogram the reflected directions of VNDF samples over cells of (cos, phi) and
        // compare each cell's frequency with the density `ggx_reflection` gives for it.
        let n = V3(0.0, 0.0, 1.0);
        let (alpha, wo) = (0.3, V3(0.4, 0.0, 0.9165).norm());
        let (cells, samples) = (8usize, 400_000usize);
        let mut hist = vec![0usize; cells * cells];
        let mut rng = crate::rng::Rng::new(5, 6);
        let mut below = 0;
        for _ in 0..samples {
            let m = ggx_sample_vndf(wo, alpha, rng.uniform(), rng.uniform());
            let wi = reflect(wo, m);
            if wi.2 <= 0.0 {
                below += 1;
                continue;
            }
            let c = ((wi.2 * cells as f32) as usize).min(cells - 1);
            let phi = wi.1.atan2(wi.0).rem_euclid(2.0 * PI);
            let p = ((phi / (2.0 * PI) * cells as f32) as usize).min(cells - 1);
            hist[c * cells + p] += 1;
        }
        // The density integrated over each cell (solid angle = dcos dphi) by midpoints.
        let sub = 24;
        let mut total = 0.0;
        for c in 0..cells {
            for p in 0..cells {
                let mut mass = 0.0;
                for i in 0..sub {
                    for j in 0..sub {
                        let cos = (c as f32 + (i as f32 + 0.5) / sub as f32) / cells as f32;
                        let phi = (p as f32 + (j as f32 + 0.5) / sub as f32) / cells as f32;
                        let phi = phi * 2.0 * PI;
                        let sin = (1.0 - cos * cos).sqrt();
                        let wi = V3(sin * phi.cos(), sin * phi.sin(), cos);
                        let (_, pdf, _) = ggx_reflection(wo, wi, n, alpha).unwrap();
                        mass += pdf / (sub * sub) as f32 / cells as f32 * 2.0 * PI / cells as f32;
                    }
                }
                total += mass;
                let freq = hist[c * cells + p] as f32 / samples as f32;
                assert!(
                    (freq - mass).abs() < 0.1 * mass + 2e-3,
                    "cell ({c}, {p}): sampled {freq}, density {mass}"
                );
            }
        }
        // What the density misses is what sampling sends below the surface.
        let lost = below as f32 / samples as f32;
        assert!((total + lost - 1.0).abs() < 0.01, "{total} + {lost}");
    }

    #[test]
    fn vndf_normals_face_the_viewer() {
        let wo = V3(0.5, 0.1, 0.86).norm();
        for k in 0..1000 {
            let m = ggx_sample_vndf(
                wo,
                0.3,
                (k as f32 + 0.5) / 1000.0,
                (k * 61 % 1000) as f32 / 1000.0,
            );
            assert!(m.2 > 0.0 && wo.dot(m) > -1e-4);
            assert!((m.len() - 1.0).abs() < 1e-4);
        }
    }
}
