//! The scattering functions materials are built from: Fresnel terms, mirror reflection and
//! refraction, microfacet distributions (GGX and Beckmann: normals, Smith masking,
//! visible-normal sampling), cosine-weighted sampling.

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
    // t >= a2 in exact arithmetic (cos_m <= 1); a rounded cos_m a hair above 1 took it to
    // 0 at small alpha, D to infinity and the sample's weight to inf / inf = NaN.
    let t = (cos_m * cos_m * (a2 - 1.0) + 1.0).max(a2);
    a2 / (PI * t * t)
}

/// GGX reflection from `wo` into `wi` about the macro normal `n` (all unit, pointing away):
/// the BSDF times cos(wi) without the Fresnel factor, the solid-angle density with which
/// visible-normal sampling picks `wi`, and the cosine between `wo` and the half vector
/// (the Fresnel factor's angle). `None` when either direction is below the surface.
pub fn ggx_reflection(wo: V3, wi: V3, n: V3, alpha: f32) -> Option<(f32, f32, f32)> {
    Distribution::Ggx.reflection(wo, wi, n, alpha)
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
    Distribution::Ggx.sample(wo, n, alpha, u1, u2)
}

/// The microfacet distribution of a rough conductor or dielectric, chosen in the scene
/// file (`distribution ggx|beckmann`). Both are sampled by their visible normals, so the
/// tracer's weights have one form for both: a reflection or refraction through the
/// sampled normal carries Fresnel times [`Distribution::g1`] of the new direction.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Distribution {
    /// Trowbridge-Reitz (GGX): long tails, the default.
    #[default]
    Ggx,
    /// Beckmann-Spizzichino: Gaussian slopes, a tighter highlight for the same alpha.
    Beckmann,
}

impl Distribution {
    /// The name the scene file uses.
    pub fn name(self) -> &'static str {
        match self {
            Distribution::Ggx => "ggx",
            Distribution::Beckmann => "beckmann",
        }
    }

    /// The distribution of normals D(m) at `cos_m` from the macro normal.
    pub fn d(self, cos_m: f32, alpha: f32) -> f32 {
        match self {
            Distribution::Ggx => ggx_d(cos_m, alpha),
            Distribution::Beckmann => beckmann_d(cos_m, alpha),
        }
    }

    /// Smith's masking term G1, `cos` measured from the macro normal.
    pub fn g1(self, cos: f32, alpha: f32) -> f32 {
        match self {
            Distribution::Ggx => ggx_g1(cos, alpha),
            Distribution::Beckmann => beckmann_g1(cos, alpha),
        }
    }

    /// A visible normal for `wo` in the local frame where the macro normal is +z.
    pub fn sample_vndf(self, wo: V3, alpha: f32, u1: f32, u2: f32) -> V3 {
        match self {
            Distribution::Ggx => ggx_sample_vndf(wo, alpha, u1, u2),
            Distribution::Beckmann => beckmann_sample_vndf(wo, alpha, u1, u2),
        }
    }

    /// World-space visible normal around `n` for `wo` (pointing away).
    pub fn sample(self, wo: V3, n: V3, alpha: f32, u1: f32, u2: f32) -> V3 {
        let (t, b) = basis(n);
        let local = V3(wo.dot(t), wo.dot(b), wo.dot(n));
        let m = self.sample_vndf(local, alpha, u1, u2);
        (t * m.0 + b * m.1 + n * m.2).norm()
    }

    /// Microfacet reflection from `wo` into `wi` about the macro normal `n`: the BSDF
    /// times cos(wi) without Fresnel, the solid-angle density of visible-normal sampling
    /// (G1(wo) D / (4 cos_o)), and the cosine between `wo` and the half vector. `None`
    /// when either direction is below the surface.
    pub fn reflection(self, wo: V3, wi: V3, n: V3, alpha: f32) -> Option<(f32, f32, f32)> {
        let (cos_o, cos_i) = (wo.dot(n), wi.dot(n));
        if cos_o <= 0.0 || cos_i <= 0.0 {
            return None;
        }
        let h = (wo + wi).norm();
        let pdf = self.g1(cos_o, alpha) * self.d(h.dot(n), alpha) / (4.0 * cos_o);
        Some((pdf * self.g1(cos_i, alpha), pdf, wo.dot(h).max(0.0)))
    }
}

/// Beckmann's D(m): Gaussian slopes of RMS `alpha`.
pub fn beckmann_d(cos_m: f32, alpha: f32) -> f32 {
    if cos_m <= 0.0 {
        return 0.0;
    }
    let c2 = cos_m * cos_m;
    let tan2 = (1.0 - c2).max(0.0) / c2;
    let a2 = alpha * alpha;
    (-tan2 / a2).exp() / (PI * a2 * c2 * c2)
}

/// Beckmann's exact Smith G1 = 1 / (1 + Lambda), Lambda = (erf(a) - 1) / 2 +
/// exp(-a^2) / (2 a sqrt(pi)) with a = 1 / (alpha tan): the exact form, not the rational
/// fit, since visible-normal sampling is normalised by exactly this term.
pub fn beckmann_g1(cos: f32, alpha: f32) -> f32 {
    let c = (cos as f64).clamp(1e-6, 1.0);
    let tan = (1.0 - c * c).max(0.0).sqrt() / c;
    let a = 1.0 / (alpha as f64 * tan).max(1e-12);
    if a > 6.0 {
        return 1.0; // Lambda < 1e-17
    }
    let lambda = 0.5 * (erf(a) - 1.0) + (-a * a).exp() / (2.0 * a * std::f64::consts::PI.sqrt());
    (1.0 / (1.0 + lambda)) as f32
}

/// A Beckmann visible normal for `wo` (local frame, +z the macro normal): stretch to
/// alpha = 1, sample the visible slopes there, rotate and unstretch (Heitz & d'Eon 2014,
/// with pbrt-v3's numerically inverted slope CDF, which has no discontinuities).
pub fn beckmann_sample_vndf(wo: V3, alpha: f32, u1: f32, u2: f32) -> V3 {
    let ws = V3(alpha * wo.0, alpha * wo.1, wo.2).norm();
    let sin = (ws.0 * ws.0 + ws.1 * ws.1).sqrt();
    let (cos_phi, sin_phi) = if sin > 1e-7 {
        (ws.0 / sin, ws.1 / sin)
    } else {
        (1.0, 0.0)
    };
    let (sx, sy) = beckmann_slopes_unit(ws.2 as f64, u1 as f64, u2 as f64);
    let (sx, sy) = (sx as f32, sy as f32);
    let x = alpha * (cos_phi * sx - sin_phi * sy);
    let y = alpha * (sin_phi * sx + cos_phi * sy);
    V3(-x, -y, 1.0).norm()
}

/// Slopes visible from a direction at `cos_i` on a Beckmann surface of alpha 1, in the
/// frame where that direction lies in the xz plane: x by inverting its CDF in the erf
/// domain (Newton steps guarded by bisection), y an independent Gaussian.
fn beckmann_slopes_unit(cos_i: f64, u1: f64, u2: f64) -> (f64, f64) {
    if cos_i > 0.9999 {
        let r = (-(1.0 - u1).ln()).sqrt();
        let phi = 2.0 * std::f64::consts::PI * u2;
        return (r * phi.cos(), r * phi.sin());
    }
    let sin_i = (1.0 - cos_i * cos_i).max(0.0).sqrt();
    let (tan_i, cot_i) = (sin_i / cos_i, cos_i / sin_i);
    let inv_sqrt_pi = 1.0 / std::f64::consts::PI.sqrt();
    let (mut a, mut c) = (-1.0, erf(cot_i));
    let u = u1.max(1e-6);
    // pbrt-v3's fitted first guess, then Newton on CDF(b) - u.
    let theta = cos_i.acos();
    let fit = 1.0 + theta * (-0.876 + theta * (0.4265 - 0.0594 * theta));
    let mut b = c - (1.0 + c) * (1.0 - u).powf(fit);
    let norm = 1.0 / (1.0 + c + inv_sqrt_pi * tan_i * (-cot_i * cot_i).exp());
    for _ in 0..20 {
        // Out of the bracket (or NaN): bisect instead.
        if !(a..=c).contains(&b) {
            b = 0.5 * (a + c);
        }
        let x = erf_inv(b);
        let value = norm * (1.0 + b + inv_sqrt_pi * tan_i * (-x * x).exp()) - u;
        if value.abs() < 1e-9 {
            break;
        }
        if value > 0.0 {
            c = b;
        } else {
            a = b;
        }
        b -= value / (norm * (1.0 - x * tan_i));
    }
    (erf_inv(b), erf_inv(2.0 * u2.max(1e-6) - 1.0))
}

/// erf, Abramowitz & Stegun 7.1.26 (absolute error below 1.5e-7).
fn erf(x: f64) -> f64 {
    let t = 1.0 / (1.0 + 0.3275911 * x.abs());
    let poly = t
        * (0.254829592
            + t * (-0.284496736 + t * (1.421413741 + t * (-1.453152027 + t * 1.061405429))));
    (1.0 - poly * (-x * x).exp()).copysign(x)
}

/// Inverse erf, Giles 2010's single-precision approximation, refined by two Newton steps
/// on [`erf`] so that the two agree (the CDF inversion above relies on it).
fn erf_inv(x: f64) -> f64 {
    let x = x.clamp(-0.99999, 0.99999);
    let mut w = -((1.0 - x) * (1.0 + x)).ln();
    let p = if w < 5.0 {
        w -= 2.5;
        [
            2.81022636e-08,
            3.43273939e-07,
            -3.5233877e-06,
            -4.39150654e-06,
            0.00021858087,
            -0.00125372503,
            -0.00417768164,
            0.246640727,
            1.50140941,
        ]
        .iter()
        .fold(0.0, |p, c| c + p * w)
    } else {
        w = w.sqrt() - 3.0;
        [
            -0.000200214257,
            0.000100950558,
            0.00134934322,
            -0.00367342844,
            0.00573950773,
            -0.0076224613,
            0.00943887047,
            1.00167406,
            2.83297682,
        ]
        .iter()
        .fold(0.0, |p, c| c + p * w)
    };
    let mut y = p * x;
    for _ in 0..2 {
        y -= (erf(y) - x) / (2.0 / std::f64::consts::PI.sqrt() * (-y * y).exp());
    }
    y
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
        sampling_matches_density(Distribution::Ggx, 0.3, V3(0.4, 0.0, 0.9165).norm());
    }

    #[test]
    fn beckmann_density_matches_visible_normal_sampling() {
        for (alpha, wo) in [
            (0.3, V3(0.4, 0.0, 0.9165)),
            (0.5, V3(0.8, 0.3, 0.3)),
            (0.2, V3(0.0, 0.0, 1.0)),
        ] {
            sampling_matches_density(Distribution::Beckmann, alpha, wo.norm());
        }
        // A grazing view too, where the slope CDF's inversion works hardest.
        sampling_matches_density(Distribution::Ggx, 0.5, V3(0.8, 0.3, 0.3).norm());
    }

    #[test]
    fn distributions_are_normalised() {
        // Projected area of the microsurface: the integral of D(m) cos(m) is 1; and the
        // visible normals' density G1(wo) max(0, wo.m) D(m) / cos(wo) integrates to 1
        // for every view, which holds only with the exact Smith G1 of that D.
        for dist in [Distribution::Ggx, Distribution::Beckmann] {
            for alpha in [0.1f32, 0.3, 0.7] {
                let views = [V3(0.0, 0.0, 1.0), V3(0.6, 0.0, 0.8), V3(0.95, 0.0, 0.312)];
                let (mut proj, mut vis) = (0.0f64, [0.0f64; 3]);
                hemisphere_quadrature(2000, 256, |m, dw| {
                    let dm = dist.d(m.2, alpha) as f64;
                    proj += dm * m.2 as f64 * dw;
                    for (v, wo) in vis.iter_mut().zip(views) {
                        let wo = wo.norm();
                        let g = dist.g1(wo.2, alpha) as f64;
                        *v += g * (wo.dot(m).max(0.0) as f64) * dm / wo.2 as f64 * dw;
                    }
                });
                assert!((proj - 1.0).abs() < 2e-3, "{dist:?} {alpha}: {proj}");
                for v in vis {
                    assert!((v - 1.0).abs() < 3e-3, "{dist:?} {alpha}: visible {vis:?}");
                }
            }
        }
    }

    #[test]
    fn microfacet_reflection_is_reciprocal_and_loses_energy_only_to_masking() {
        let n = V3(0.0, 0.0, 1.0);
        let (a, b) = (V3(0.3, 0.1, 0.9).norm(), V3(-0.5, 0.4, 0.7).norm());
        for dist in [Distribution::Ggx, Distribution::Beckmann] {
            for alpha in [0.05f32, 0.3, 0.8] {
                // f(a, b) = f(b, a): compare f cos(wi) / cos(wi) both ways.
                let fab = dist.reflection(a, b, n, alpha).unwrap().0 / b.2;
                let fba = dist.reflection(b, a, n, alpha).unwrap().0 / a.2;
                assert!(
                    (fab - fba).abs() <= 1e-5 * fab.max(1e-3),
                    "{dist:?} {alpha}"
                );
                // White furnace of the lobe alone (Fresnel 1): the albedo is at most 1,
                // and near 1 when smooth (single scattering loses only the masked share).
                let mut albedo = 0.0f64;
                hemisphere_quadrature(2000, 256, |wi, dw| {
                    albedo += dist.reflection(a, wi, n, alpha).map_or(0.0, |r| r.0) as f64 * dw;
                });
                assert!(albedo <= 1.003, "{dist:?} {alpha}: {albedo}");
                if alpha <= 0.05 {
                    assert!(albedo > 0.99, "{dist:?} {alpha}: {albedo}");
                }
            }
        }
    }

    #[test]
    fn erf_and_its_inverse() {
        for (x, e) in [
            (0.0, 0.0),
            (0.5, 0.5204998778),
            (1.0, 0.8427007929),
            (2.0, 0.995322265),
        ] {
            assert!(
                (erf(x) - e).abs() < 2e-7 && (erf(-x) + e).abs() < 2e-7,
                "{x}"
            );
        }
        for i in -99..=99 {
            let y = i as f64 / 100.0;
            // erf itself is good to 1.5e-7, so that is the scale of agreement asked for.
            assert!((erf(erf_inv(y)) - y).abs() < 1e-6, "{y}");
        }
    }

    /// Midpoint quadrature over the upper hemisphere in (cos, phi): calls `f(direction,
    /// solid angle)` for each cell.
    fn hemisphere_quadrature(n_cos: usize, n_phi: usize, mut f: impl FnMut(V3, f64)) {
        for i in 0..n_cos {
            // cos = (1 - cos(pi t)) / 2: cells crowd towards the horizon and the normal,
            // where grazing views and sharp lobes need them.
            let c = |t: f64| 0.5 * (1.0 - (std::f64::consts::PI * t).cos());
            let (c0, c1) = (c(i as f64 / n_cos as f64), c((i + 1) as f64 / n_cos as f64));
            let c = 0.5 * (c0 + c1);
            let s = (1.0 - c * c).max(0.0).sqrt();
            for j in 0..n_phi {
                let phi = (j as f64 + 0.5) / n_phi as f64 * 2.0 * std::f64::consts::PI;
                let w = V3((s * phi.cos()) as f32, (s * phi.sin()) as f32, c as f32);
                f(w, (c1 - c0) * 2.0 * std::f64::consts::PI / n_phi as f64);
            }
        }
    }

    /// Histograms the reflected directions of `dist`'s visible-normal samples over cells
    /// of (cos, phi) and compares each cell's frequency with the density
    /// [`Distribution::reflection`] gives it; what the density misses is what sampling
    /// sends below the surface, so the two add to 1.
    fn sampling_matches_density(dist: Distribution, alpha: f32, wo: V3) {
        let n = V3(0.0, 0.0, 1.0);
        let (cells, samples) = (8usize, 400_000usize);
        let mut hist = vec![0usize; cells * cells];
        let mut rng = crate::rng::Rng::new(5, 6);
        let mut below = 0;
        for _ in 0..samples {
            let m = dist.sample_vndf(wo, alpha, rng.uniform(), rng.uniform());
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
                        let (_, pdf, _) = dist.reflection(wo, wi, n, alpha).unwrap();
                        mass += pdf / (sub * sub) as f32 / cells as f32 * 2.0 * PI / cells as f32;
                    }
                }
                total += mass;
                let freq = hist[c * cells + p] as f32 / samples as f32;
                // 4 binomial standard deviations, plus 1 % for the midpoint rule.
                let sd = (mass * (1.0 - mass) / samples as f32).max(0.0).sqrt();
                assert!(
                    (freq - mass).abs() < 4.0 * sd + 0.01 * mass + 2e-4,
                    "{dist:?} alpha {alpha} wo {wo:?} cell ({c}, {p}): sampled {freq}, density {mass}"
                );
            }
        }
        let lost = below as f32 / samples as f32;
        assert!(
            (total + lost - 1.0).abs() < 0.01,
            "{dist:?} {alpha}: {total} + {lost}"
        );
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
