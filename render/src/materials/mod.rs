//! Materials: Lambertian, conductors with spectral eta/k (smooth or GGX-rough),
//! dielectrics with dispersion (smooth or rough), and plastic (a dielectric coat over a
//! diffuse base); the scattering functions and textures they are built from.

pub mod ior;
pub mod scattering;
pub mod texture;

use crate::spectral::spectrum::Spectrum;
use crate::spectral::uplift;
use crate::spectral::wavelengths::{Lanes, Wavelengths};
use ior::Ior;
use scattering::{fresnel_conductor, Distribution};
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

/// A surface's reflectance: an RGB texture uplifted to a spectrum at each hit, or a
/// measured spectrum (uniform over the surface).
#[derive(Clone, Debug)]
pub enum Reflectance {
    /// Linear RGB in [0, 1], uplifted per hit.
    Texture(Texture),
    /// A texture that only ever takes two colours (uniform, checker, stripes, fine
    /// lines), both uplifted once ([`Reflectance::texture`]): the table lookup per hit
    /// was 7 % of a render's time.
    TwoTone {
        /// The pattern.
        texture: Texture,
        /// The spectrum and RGB where the pattern's weight is 0, and where it is 1.
        ends: [(uplift::SigmoidPoly, [f32; 3]); 2],
    },
    /// Values in [0, 1] by wavelength.
    Spectral {
        /// The reflectance.
        spectrum: Spectrum,
        /// Its colour under D65 as linear sRGB, for the albedo buffer.
        rgb: [f32; 3],
    },
}

impl Reflectance {
    /// A measured reflectance; its albedo-buffer colour is computed here.
    pub fn spectral(spectrum: Spectrum) -> Self {
        let rgb = spectral_albedo(|l| spectrum.eval(l));
        Reflectance::Spectral { spectrum, rgb }
    }

    /// An RGB texture's reflectance: [`Reflectance::TwoTone`] where the pattern allows.
    pub fn texture(t: Texture) -> Self {
        if !t.pattern.two_tone() {
            return Reflectance::Texture(t);
        }
        // The colours `Texture::eval` gives at weights 0 and 1, to the bit.
        let end = |w: f32| {
            let rgb: [f32; 3] = std::array::from_fn(|i| t.a[i] + (t.b[i] - t.a[i]) * w);
            (uplift::reflectance(rgb), rgb)
        };
        Reflectance::TwoTone {
            texture: t,
            ends: [end(0.0), end(1.0)],
        }
    }

    /// The reflectance at a path's wavelengths and the albedo buffer's RGB, at (u, v).
    pub fn at(&self, u: f32, v: f32, wl: &Wavelengths) -> (Lanes, [f32; 3]) {
        match self {
            Reflectance::Texture(t) => {
                let rgb = t.eval(u, v);
                let r = uplift::reflectance(rgb);
                (wl.lambda.map(|l| r.eval(l)), rgb)
            }
            Reflectance::TwoTone { texture, ends } => {
                let (r, rgb) = &ends[(texture.weight(u, v) > 0.5) as usize];
                (wl.lambda.map(|l| r.eval(l)), *rgb)
            }
            Reflectance::Spectral { spectrum, rgb } => (spectrum.sample(wl), *rgb),
        }
    }
}

/// A surface material.
#[derive(Clone, Debug)]
pub enum Material {
    /// Lambertian reflection; the texture's RGB is uplifted to a spectrum at each hit.
    Diffuse {
        /// Reflectance in [0, 1].
        reflectance: Reflectance,
    },
    /// A metal: complex Fresnel per wavelength, mirror or GGX/Beckmann microfacets.
    Conductor {
        /// Optical constants.
        metal: Metal,
        /// The microfacet alpha (0 = mirror).
        roughness: Texture,
        /// GGX or Beckmann.
        distribution: Distribution,
        /// Normal-incidence reflectance as linear RGB, for the albedo buffer.
        albedo: [f32; 3],
    },
    /// Glass: Fresnel-weighted reflection and refraction, smooth or microfacet-rough.
    Dielectric {
        /// Index of refraction.
        ior: Ior,
        /// The microfacet alpha (0 = smooth).
        roughness: Texture,
        /// GGX or Beckmann.
        distribution: Distribution,
    },
    /// A smooth or rough dielectric coat (index `ior`) over a Lambertian base.
    Plastic {
        /// Base reflectance.
        reflectance: Reflectance,
        /// Coat index.
        ior: f32,
        /// Coat GGX alpha (0 = smooth).
        roughness: Texture,
    },
    /// An emitter (black): `radiance` times `scale`, from its front side only unless
    /// `two_sided` (a quad's or triangle's front faces along `e1 x e2`, a sphere's outwards).
    Emitter {
        /// Spectral shape.
        radiance: Spectrum,
        /// Multiplier; scenes divide by the shape's luminance so `scale` means brightness.
        scale: f32,
        /// Emits from both sides.
        two_sided: bool,
    },
}

/// Below this GGX alpha a surface is treated as perfectly smooth.
pub const SMOOTH: f32 = 1e-3;

/// Normal-incidence reflectance of a metal as linear sRGB (for the albedo buffer):
/// Fresnel at 0 degrees seen under D65 and converted like the film does.
pub fn metal_albedo(m: &Metal) -> [f32; 3] {
    spectral_albedo(|l| fresnel_conductor(1.0, m.eta.eval(l), m.k.eval(l)))
}

/// A reflectance spectrum's colour under D65 (sRGB's white) as linear sRGB clamped to
/// [0, 1], for the albedo buffer: a flat reflectance gives grey.
fn spectral_albedo(r: impl Fn(f32) -> f32) -> [f32; 3] {
    let d65 = Spectrum::d65();
    let mut xyz = [0.0f64; 3];
    let mut ysum = 0.0;
    for l in 380..=780 {
        let (v, e) = (r(l as f32) as f64, d65.eval(l as f32) as f64);
        let c = temc_color::cie::cmf_tabulated(l as f64);
        for i in 0..3 {
            xyz[i] += c[i] * v * e;
        }
        ysum += c[1] * e;
    }
    let rgb = temc_color::cie::xyz_to_linear_srgb(xyz.map(|v| v / ysum));
    rgb.map(|v| v.clamp(0.0, 1.0))
}
