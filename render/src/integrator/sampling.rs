//! Sampling modes that imitate weaker renderers. The tracer's own sampler (hero wavelengths
//! drawn from the emitters' spectra, lights picked by power, next-event estimation with
//! MIS, Russian roulette after three bounces) makes one kind of noise; a denoiser meets
//! the noise of renderers that sample worse too. Each mode swaps one strategy for a weaker
//! one that still converges to the same image, so a data set can show a denoiser that
//! noise without changing what the reference is.

use std::fmt;
use std::str::FromStr;

/// Which strategies a render weakens. All off ([`Sampling::DEFAULT`]) is the tracer's own
/// sampler, bit for bit what it was before the modes existed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct Sampling {
    /// No next-event estimation: emitters are found only by hitting them.
    pub bsdf_only: bool,
    /// Next-event estimation picks every light with the same probability, not by power.
    pub uniform_lights: bool,
    /// Next-event estimation without MIS: it alone counts the direct light of the lobes it
    /// covers, and emitters hit after those lobes count nothing.
    pub no_mis: bool,
    /// One wavelength per path, drawn uniformly over 360..830 nm.
    pub uniform_wavelength: bool,
    /// Russian roulette from the first bounce on, not after three.
    pub early_roulette: bool,
}

/// A mode's name in text, its preset, and the renderer it imitates.
pub type Mode = (&'static str, Sampling, &'static str);

impl Sampling {
    /// The tracer's own sampler.
    pub const DEFAULT: Sampling = Sampling {
        bsdf_only: false,
        uniform_lights: false,
        no_mis: false,
        uniform_wavelength: false,
        early_roulette: false,
    };

    /// See [`Sampling::bsdf_only`].
    pub const BSDF_ONLY: Sampling = Sampling {
        bsdf_only: true,
        ..Sampling::DEFAULT
    };

    /// See [`Sampling::uniform_lights`].
    pub const UNIFORM_LIGHTS: Sampling = Sampling {
        uniform_lights: true,
        ..Sampling::DEFAULT
    };

    /// See [`Sampling::no_mis`].
    pub const NO_MIS: Sampling = Sampling {
        no_mis: true,
        ..Sampling::DEFAULT
    };

    /// See [`Sampling::uniform_wavelength`].
    pub const UNIFORM_WAVELENGTH: Sampling = Sampling {
        uniform_wavelength: true,
        ..Sampling::DEFAULT
    };

    /// See [`Sampling::early_roulette`].
    pub const EARLY_ROULETTE: Sampling = Sampling {
        early_roulette: true,
        ..Sampling::DEFAULT
    };

    /// Every mode, in the order [`Sampling`]'s text lists them.
    pub const MODES: [Mode; 5] = [
        (
            "bsdf-only",
            Sampling::BSDF_ONLY,
            "a path tracer without light sampling (emitters found only by hitting them): \
             fireflies from small lights",
        ),
        (
            "uniform-lights",
            Sampling::UNIFORM_LIGHTS,
            "light sampling that picks lights uniformly, not by power: noise under many \
             lights of unequal power",
        ),
        (
            "no-mis",
            Sampling::NO_MIS,
            "light sampling without MIS: fireflies where glossy surfaces reflect large lights",
        ),
        (
            "uniform-wavelength",
            Sampling::UNIFORM_WAVELENGTH,
            "a naive spectral renderer (one uniform wavelength per path): strong colour noise",
        ),
        (
            "early-roulette",
            Sampling::EARLY_ROULETTE,
            "Russian roulette from the first bounce: more variance in indirect light",
        ),
    ];

    /// Whether this is the tracer's own sampler.
    pub fn is_default(&self) -> bool {
        *self == Sampling::DEFAULT
    }

    /// The first path vertex (0: the camera ray's hit) after which Russian roulette may end
    /// a path.
    pub fn roulette_start(&self) -> u32 {
        if self.early_roulette {
            0
        } else {
            3
        }
    }

    /// Parses a comma-separated list of modes (`bsdf-only,uniform-wavelength`), or
    /// `default` for the tracer's own sampler. Refuses unknown or repeated modes, and
    /// `bsdf-only` with a light-sampling mode (it samples no lights, so they would do
    /// nothing).
    pub fn parse(text: &str) -> Result<Sampling, String> {
        let names: Vec<&str> = text.split(',').map(str::trim).collect();
        if names == ["default"] {
            return Ok(Sampling::DEFAULT);
        }
        if names.contains(&"default") {
            return Err(format!(
                "sampling {text:?}: default is the tracer's own sampler; it cannot be \
                 combined with modes"
            ));
        }
        let mut s = Sampling::DEFAULT;
        for name in names {
            let (_, mode, _) = Sampling::MODES
                .iter()
                .find(|m| m.0 == name)
                .ok_or_else(|| unknown(text, name))?;
            if s.union(*mode) == s {
                return Err(format!("sampling {text:?}: {name} is given twice"));
            }
            s = s.union(*mode);
        }
        if s.bsdf_only && (s.uniform_lights || s.no_mis) {
            return Err(format!(
                "sampling {text:?}: bsdf-only samples no lights, so uniform-lights and \
                 no-mis would change nothing with it"
            ));
        }
        Ok(s)
    }

    /// Every combination [`Sampling::parse`] accepts other than the default: one light
    /// strategy (or none weakened), with or without each of the others.
    pub fn weak_combinations() -> Vec<Sampling> {
        (1..1u32 << Sampling::MODES.len())
            .map(|bits| {
                Sampling::MODES
                    .iter()
                    .enumerate()
                    .filter(|(i, _)| bits & (1 << i) != 0)
                    .fold(Sampling::DEFAULT, |s, (_, m)| s.union(m.1))
            })
            .filter(|s| !(s.bsdf_only && (s.uniform_lights || s.no_mis)))
            .collect()
    }

    /// Every mode on in either.
    fn union(self, o: Sampling) -> Sampling {
        Sampling {
            bsdf_only: self.bsdf_only || o.bsdf_only,
            uniform_lights: self.uniform_lights || o.uniform_lights,
            no_mis: self.no_mis || o.no_mis,
            uniform_wavelength: self.uniform_wavelength || o.uniform_wavelength,
            early_roulette: self.early_roulette || o.early_roulette,
        }
    }
}

/// The error for an unknown mode `name` in `text`, listing the known ones.
fn unknown(text: &str, name: &str) -> String {
    let known: Vec<&str> = Sampling::MODES.iter().map(|m| m.0).collect();
    let what = if name.is_empty() {
        "an empty mode".to_string()
    } else {
        format!("unknown mode {name:?}")
    };
    format!(
        "sampling {text:?}: {what} (give \"default\" or a comma-separated list of: {})",
        known.join(", ")
    )
}

/// `default`, or the modes comma-separated in [`Sampling::MODES`]' order: the text
/// [`Sampling::parse`] reads back.
impl fmt::Display for Sampling {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.is_default() {
            return f.write_str("default");
        }
        let on: Vec<&str> = Sampling::MODES
            .iter()
            .filter(|m| self.union(m.1) == *self)
            .map(|m| m.0)
            .collect();
        f.write_str(&on.join(","))
    }
}

impl FromStr for Sampling {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Sampling::parse(s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_round_trips_and_names_each_mode() {
        assert_eq!(Sampling::parse("default"), Ok(Sampling::DEFAULT));
        assert_eq!(Sampling::DEFAULT.to_string(), "default");
        let s = Sampling::parse("uniform-wavelength, no-mis,early-roulette").unwrap();
        assert!(s.no_mis && s.uniform_wavelength && s.early_roulette);
        assert!(!s.bsdf_only && !s.uniform_lights);
        assert_eq!(s.to_string(), "no-mis,uniform-wavelength,early-roulette");
        for (name, preset, _) in Sampling::MODES {
            assert_eq!(Sampling::parse(name), Ok(preset));
            assert_eq!(preset.to_string(), name);
        }
        for s in Sampling::weak_combinations() {
            assert_eq!(s.to_string().parse(), Ok(s));
        }
    }

    #[test]
    fn parse_errors_say_what_is_wrong() {
        let err = |t: &str| Sampling::parse(t).unwrap_err();
        let e = err("bsdf-only,uniform-wavelenght");
        assert!(e.contains("unknown mode \"uniform-wavelenght\""), "{e}");
        assert!(e.contains("bsdf-only, uniform-lights, no-mis"), "{e}");
        assert!(err("").contains("an empty mode"));
        assert!(err("no-mis,").contains("an empty mode"));
        assert!(err("default,no-mis").contains("cannot be combined"));
        assert!(err("no-mis,no-mis").contains("no-mis is given twice"));
        let e = err("bsdf-only,uniform-lights");
        assert!(e.contains("bsdf-only samples no lights"), "{e}");
    }

    #[test]
    fn weak_combinations_are_every_valid_non_default_one() {
        let all = Sampling::weak_combinations();
        // Five light strategies (the tracer's own, bsdf-only, uniform-lights, no-mis, and
        // the last two together) times two of wavelengths times two of roulette, less the
        // default.
        assert_eq!(all.len(), 5 * 2 * 2 - 1);
        assert!(!all.contains(&Sampling::DEFAULT));
        let unique: std::collections::HashSet<_> = all.iter().collect();
        assert_eq!(unique.len(), all.len());
    }
}
