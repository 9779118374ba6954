//! Materials: Lambertian, conductors with spectral eta/k (smooth or GGX-rough),
//! dielectrics with dispersion (smooth or rough), and plastic (a dielectric coat over a
//! diffuse base); the scattering functions and textures they are built from.

pub mod ior;
pub mod scattering;
pub mod texture;

use crate::spectral::spectrum::Spectrum;
use ior::Ior;
use scattering::fresnel_conductor;
use texture::Texture;

/// A conductor's measured optical constants.
#[derive(Clone, Debug)]
pub struct Metal {
    /// Real part of the index.
    pub eta: Spectrum,
    /// Extinction coefficient.
    pub k: Spectrum,
}

/// A named metal: "Au", "Ag", "Cu" or "Al".
pub fn metal(name: &str) -> Option<Metal> {
    use crate::spectral::measured::*;
    let (eta, k) = match name {
        "Au" => (&AU_ETA, &AU_K),
        "Ag" => (&AG_ETA, &AG_K),
        "Cu" => (&CU_ETA, &CU_K),
        "Al" => (&AL_ETA, &AL_K),
        _ => return None,
    };
    Some(Metal {
        eta: Spectrum::Tabulated(eta),
        k: Spectrum::Tabulated(k),
    })
}

/// A surface material.
#[derive(Clone, Debug)]
pub enum Material {
    /// Lambertian reflection; the texture's RGB is uplifted to a spectrum at each hit.
    Diffuse {
        /// Reflectance in [0, 1].
        reflectance: Texture,
    },
    /// A metal: complex Fresnel per wavelength, mirror or GGX microfacets.
    Conductor {
        /// Optical constants.
        metal: Metal,
        /// GGX alpha (0 = mirror).
        roughness: Texture,
        /// Normal-incidence reflectance as linear RGB, for the albedo buffer.
        albedo: [f32; 3],
    },
    /// Glass: Fresnel-weighted reflection and refraction, smooth or GGX-rough.
    Dielectric {
        /// Index of refraction.
        ior: Ior,
        /// GGX alpha (0 = smooth).
        roughness: Texture,
    },
    /// A smooth or rough dielectric coat (index `ior`) over a Lambertian base.
    Plastic {
        /// Base reflectance.
        reflectance: Texture,
        /// Coat index.
        ior: f32,
        /// Coat GGX alpha (0 = smooth).
        roughness: Texture,
    },
    /// An emitter (two-sided, black): `radiance` times `scale`.
    Emitter {
        /// Spectral shape.
        radiance: Spectrum,
        /// Multiplier; scenes divide by the shape's luminance so `scale` means brightness.
        scale: f32,
    },
}

/// Below this GGX alpha a surface is treated as perfectly smooth.
pub const SMOOTH: f32 = 1e-3;

/// Normal-incidence reflectance of a metal as linear sRGB (for the albedo buffer):
/// Fresnel at 0 degrees averaged over the CMFs and converted like the film does.
pub fn metal_albedo(m: &Metal) -> [f32; 3] {
    let mut xyz = [0.0f64; 3];
    let mut ysum = 0.0;
    for l in 380..=780 {
        let r = fresnel_conductor(1.0, m.eta.eval(l as f32), m.k.eval(l as f32)) as f64;
        let c = temc_color::cie::cmf(l as f64);
        for i in 0..3 {
            xyz[i] += c[i] * r;
        }
        ysum += c[1];
    }
    let rgb = temc_color::cie::xyz_to_linear_srgb(xyz.map(|v| v / ysum));
    rgb.map(|v| v.clamp(0.0, 1.0))
}
