//! Filter types and what each brings: the architecture it runs, its defaults, the images
//! and parameters it takes. OIDN's "RT" and "RTLightmap" run TEMC-2 with OIDN's defaults.

use super::ImageName;
use crate::Error;

/// A filter type: one of temc's model architectures, or one of OIDN's two types.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Kind {
    /// TEMC-2, temc's network ("TEMC2"; built-in weights).
    Temc2,
    /// The TEMC-1 baseline ("TEMC1"; weights from onnx/baselines/).
    Temc1,
    /// The DEMC baseline ("DEMC").
    Demc,
    /// The autoencoder baseline ("AE").
    Ae,
    /// OIDN's "RT": TEMC-2 with OIDN's defaults ("hdr" false; the default quality, which
    /// is balanced in temc), OIDN's checks at commit, and the prefiltering of a lone albedo
    /// or normal image.
    Rt,
    /// OIDN's "RTLightmap": TEMC-2 on HDR colour only.
    RtLightmap,
}

impl Kind {
    /// Every filter type, temc's first.
    pub const ALL: [Kind; 6] = [
        Kind::Temc2,
        Kind::Temc1,
        Kind::Demc,
        Kind::Ae,
        Kind::Rt,
        Kind::RtLightmap,
    ];

    /// The name the API spells ("TEMC2", "RT", ...).
    pub fn name(self) -> &'static str {
        match self {
            Kind::Temc2 => "TEMC2",
            Kind::Temc1 => "TEMC1",
            Kind::Demc => "DEMC",
            Kind::Ae => "AE",
            Kind::Rt => "RT",
            Kind::RtLightmap => "RTLightmap",
        }
    }

    /// Parses a filter type name (exact spelling).
    pub fn parse(name: &str) -> Result<Self, Error> {
        Self::ALL
            .into_iter()
            .find(|k| k.name() == name)
            .ok_or_else(|| {
                Error::InvalidArgument(format!(
                    "unknown filter type {name:?} (expected one of {:?})",
                    Self::ALL.map(Kind::name)
                ))
            })
    }

    /// The temc type whose model this type runs: itself, or TEMC-2 for OIDN's types.
    pub fn runs(self) -> Kind {
        match self {
            Kind::Rt | Kind::RtLightmap => Kind::Temc2,
            k => k,
        }
    }

    /// The temc type that runs a model of `architecture` (a model's `temc.architecture`,
    /// e.g. "temc2" -> [`Kind::Temc2`]).
    pub fn for_architecture(architecture: &str) -> Result<Self, Error> {
        Self::ALL
            .into_iter()
            .filter(|k| k.runs() == *k)
            .find(|k| k.name().eq_ignore_ascii_case(architecture))
            .ok_or_else(|| {
                Error::InvalidArgument(format!(
                    "architecture {architecture:?} has no filter type (expected one of {:?})",
                    super::FILTER_TYPES
                ))
            })
    }

    /// Whether this is one of OIDN's types, with OIDN's defaults and commit-time checks.
    pub fn is_oidn(self) -> bool {
        matches!(self, Kind::Rt | Kind::RtLightmap)
    }

    /// The "hdr" a new filter has: false for "RT" (OIDN's default), true otherwise.
    pub fn default_hdr(self) -> bool {
        self != Kind::Rt
    }

    /// Whether the input is always HDR ("RTLightmap": "hdr" and "srgb" do not apply).
    pub fn hdr_only(self) -> bool {
        self == Kind::RtLightmap
    }

    /// The memory budget a new filter has: OIDN's "no explicit limit" for OIDN's types,
    /// [`super::DEFAULT_MAX_MEMORY_MB`] for temc's (the same budget, read back differently).
    pub fn default_max_memory(self) -> super::MaxMemory {
        if self.is_oidn() {
            super::MaxMemory::Auto
        } else {
            super::MaxMemory::Mb(super::DEFAULT_MAX_MEMORY_MB)
        }
    }

    /// Whether the type takes `image` ("RTLightmap" takes colour only).
    pub fn accepts(self, image: ImageName) -> bool {
        self != Kind::RtLightmap
            || matches!(
                image,
                ImageName::Color | ImageName::Output | ImageName::Spectral
            )
    }
}

impl std::fmt::Display for Kind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl TryFrom<&str> for Kind {
    type Error = Error;
    fn try_from(name: &str) -> Result<Self, Error> {
        Kind::parse(name)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_oidn_types_run_temc2() {
        for k in Kind::ALL {
            assert_eq!(Kind::parse(k.name()).unwrap(), k);
        }
        assert!(Kind::parse("OIDN").is_err());
        assert_eq!(Kind::Rt.runs(), Kind::Temc2);
        assert_eq!(Kind::for_architecture("demc").unwrap(), Kind::Demc);
        assert!(Kind::for_architecture("rt").is_err());
        assert!(!Kind::RtLightmap.accepts(ImageName::Albedo));
        assert!(Kind::Rt.accepts(ImageName::Albedo));
    }
}
