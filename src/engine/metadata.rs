//! The model card inside an ONNX file: the `temc.*` metadata_props of docs/contracts.md §2.
//!
//! The core reads alignment, overlap, channel layout and PQ scale from here rather than
//! hard-coding them, so a retrained or resized model needs no code change.

use std::collections::BTreeMap;

use crate::reconstruct::{RangeOpening, Upsample};
use crate::Error;

/// The metadata format this build understands: 2 = the network predicts filters
/// (docs/reconstruction.md); format 1 models (an `hsv` output) are refused.
pub const FORMAT_VERSION: &str = "2";

/// The aux buffers a layout may name, with their channel counts.
pub const AUX_BUFFERS: [(&str, usize); 3] = [("albedo", 3), ("normal", 3), ("depth", 1)];

/// The aux layout every shipped model uses: albedo (3), normal (3), depth (1).
pub const AUX_LAYOUT: &str = "albedo:3,normal:3,depth:1";

/// The flip-ensemble pass counts a model card (`temc.passes`) or a filter may ask for.
pub const PASS_COUNTS: [usize; 3] = [1, 2, 4];

/// What a model says about itself.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelInfo {
    /// `temc2`, `temc1`, `demc` or `ae`.
    pub architecture: String,
    /// Width multiplier; 1.0 is the paper's network.
    pub width: f32,
    /// H and W of every run must be multiples of this.
    pub alignment: usize,
    /// Theoretical receptive field in pixels.
    pub receptive_field: usize,
    /// Overlap the tiler should use, in pixels.
    pub tile_overlap: usize,
    /// How chroma is encoded (`hs`: hue and saturation, 2 channels).
    pub chroma_encoding: String,
    /// Number of chroma channels, from the encoding.
    pub chroma_channels: usize,
    /// The aux buffer layout, e.g. `albedo:3,normal:3,depth:1`.
    pub aux_layout: String,
    /// Number of aux channels, from the layout.
    pub aux_channels: usize,
    /// The aux layout's buffers in plane order, each one of [`AUX_BUFFERS`].
    pub aux_planes: Vec<(String, usize)>,
    /// Pyramid levels of the reconstruction (`temc.levels`).
    pub levels: usize,
    /// Taps per side of every level's kernels (`temc.kernel`, odd).
    pub kernel: usize,
    /// Whether the reconstruction divides by albedo + eps first (`temc.demodulate`).
    pub demodulate: bool,
    /// The demodulation's epsilon (`temc.demod_eps`).
    pub demod_eps: f32,
    /// Whether each level holds two guide channels, the range term's (`temc.guide`;
    /// optional, absent means no).
    pub guide: bool,
    /// Whether the reconstruction adds the fixed range term (`temc.fixed_range`;
    /// optional, absent means no).
    pub fixed_range: bool,
    /// How the level composition upsamples (`temc.upsample`: `nearest`, the default when
    /// absent, or `bilinear`).
    pub upsample: Upsample,
    /// What the fixed range term opens (`temc.range_opening`: `plain`, the default when
    /// absent, or `aux`, the aux-guided opening).
    pub range_opening: RangeOpening,
    /// Whether the level composition caps each coarse correction (`temc.coarse_clamp`).
    pub coarse_clamp: bool,
    /// The coarse clamp's gain (`temc.coarse_gain`; optional, absent means
    /// [`crate::reconstruct::COARSE_GAIN`]).
    pub coarse_gain: f32,
    /// The coarse clamp's window radius (`temc.coarse_radius`; optional, absent means 0:
    /// each pixel's own fine value).
    pub coarse_radius: usize,
    /// The coarse clamp's rise where samples are sparse (`temc.coarse_sparse`; optional,
    /// absent means 0: no rise).
    pub coarse_sparse: f32,
    /// The fixed range term's threshold from local noise, K (`temc.range_noise`; optional,
    /// absent or 0 means the fixed threshold everywhere).
    pub range_noise: f32,
    /// Flip-ensemble passes a filter runs unless told otherwise (`temc.passes`: 1, 2 or 4;
    /// optional, absent means 1).
    pub passes: usize,
    /// Linear 1.0 corresponds to this many cd/m2 before PQ encoding.
    pub pq_nits_per_unit: f32,
    /// Training data set, or `none` for an untrained test model.
    pub dataset: String,
    /// Optimiser steps the weights were trained for.
    pub train_steps: u64,
    /// RelMSE on the project's test set, if measured.
    pub test_relmse: Option<f64>,
    /// Free text.
    pub description: String,
    /// Every `temc.*` entry, as found.
    pub raw: BTreeMap<String, String>,
}

impl ModelInfo {
    /// Parses the `temc.*` entries of an ONNX model's metadata_props (keys and values as
    /// stored; other keys are ignored). Missing or malformed required keys are errors that
    /// name the key.
    pub fn from_props<'a>(
        props: impl IntoIterator<Item = (&'a str, &'a str)>,
    ) -> Result<Self, Error> {
        let raw: BTreeMap<String, String> = props
            .into_iter()
            .filter(|(k, _)| k.starts_with("temc."))
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect();
        let get = |key: &str| -> Result<&str, Error> {
            raw.get(key).map(String::as_str).ok_or_else(|| {
                Error::Model(format!(
                    "metadata key `{key}` is missing; is this a temc model (docs/contracts.md §2)?"
                ))
            })
        };
        fn num<T: std::str::FromStr>(key: &str, v: &str) -> Result<T, Error> {
            v.trim().parse().map_err(|_| {
                Error::Model(format!("metadata `{key}` = {v:?} is not a valid number"))
            })
        }
        let format = get("temc.format")?;
        if format != FORMAT_VERSION {
            return Err(Error::Model(format!(
                "metadata `temc.format` = {format:?} is not supported (this build reads {FORMAT_VERSION:?})"
            )));
        }
        let chroma_encoding = get("temc.chroma_encoding")?.to_string();
        let chroma_channels = match chroma_encoding.as_str() {
            "hs" => 2,
            other => {
                return Err(Error::Model(format!(
                    "metadata `temc.chroma_encoding` = {other:?} is not supported (expected \"hs\")"
                )))
            }
        };
        let aux_layout = get("temc.aux_layout")?.to_string();
        let aux_planes = parse_layout(&aux_layout)?;
        let aux_channels = aux_planes.iter().map(|(_, n)| n).sum();
        let levels: usize = num("temc.levels", get("temc.levels")?)?;
        let kernel: usize = num("temc.kernel", get("temc.kernel")?)?;
        let demodulate = match get("temc.demodulate")? {
            "0" => false,
            "1" => true,
            v => {
                return Err(Error::Model(format!(
                    "metadata `temc.demodulate` = {v:?} must be 0 or 1"
                )))
            }
        };
        let demod_eps: f32 = num("temc.demod_eps", get("temc.demod_eps")?)?;
        let flag = |key: &str| match raw.get(key).map(String::as_str) {
            None | Some("0") => Ok(false),
            Some("1") => Ok(true),
            Some(v) => Err(Error::Model(format!(
                "metadata `{key}` = {v:?} must be 0 or 1"
            ))),
        };
        let guide = flag("temc.guide")?;
        let fixed_range = flag("temc.fixed_range")?;
        let coarse_clamp = flag("temc.coarse_clamp")?;
        let range_noise = range_noise(&raw)?;
        let (coarse_gain, coarse_radius) = coarse_cap(&raw)?;
        let coarse_sparse = coarse_sparse(&raw)?;
        let upsample = named(
            &raw,
            "temc.upsample",
            Upsample::from_name,
            ["nearest", "bilinear"],
        )?;
        let range_opening = named(
            &raw,
            "temc.range_opening",
            RangeOpening::from_name,
            ["plain", "aux"],
        )?;
        let alignment: usize = num("temc.alignment", get("temc.alignment")?)?;
        if alignment == 0 || !alignment.is_power_of_two() {
            return Err(Error::Model(format!(
                "metadata `temc.alignment` = {alignment} must be a power of two"
            )));
        }
        let width: f32 = num("temc.width", get("temc.width")?)?;
        let pq_nits_per_unit: f32 = num("temc.pq_nits_per_unit", get("temc.pq_nits_per_unit")?)?;
        for (key, v) in [
            ("temc.width", width),
            ("temc.pq_nits_per_unit", pq_nits_per_unit),
        ] {
            if !(v > 0.0 && v.is_finite()) {
                return Err(Error::Model(format!(
                    "metadata `{key}` = {v} must be positive"
                )));
            }
        }
        if !(1..=5).contains(&levels) || (1usize << (levels - 1)) > alignment {
            return Err(Error::Model(format!(
                "metadata `temc.levels` = {levels} must be 1..=5 and 2^(levels-1) must divide the alignment"
            )));
        }
        if kernel.is_multiple_of(2) || !(1..=9).contains(&kernel) {
            return Err(Error::Model(format!(
                "metadata `temc.kernel` = {kernel} must be odd, 1..=9"
            )));
        }
        if !(demod_eps > 0.0 && demod_eps.is_finite()) {
            return Err(Error::Model(format!(
                "metadata `temc.demod_eps` = {demod_eps} must be positive"
            )));
        }
        let passes = match raw.get("temc.passes") {
            None => 1,
            Some(v) => num("temc.passes", v)?,
        };
        if !PASS_COUNTS.contains(&passes) {
            return Err(Error::Model(format!(
                "metadata `temc.passes` = {passes} must be 1, 2 or 4"
            )));
        }
        let test_relmse = match get("temc.test_relmse")? {
            "none" | "" => None,
            v => Some(num("temc.test_relmse", v)?),
        };
        Ok(Self {
            architecture: get("temc.architecture")?.to_string(),
            width,
            alignment,
            receptive_field: num("temc.receptive_field", get("temc.receptive_field")?)?,
            tile_overlap: num("temc.tile_overlap", get("temc.tile_overlap")?)?,
            chroma_encoding,
            chroma_channels,
            aux_layout,
            aux_channels,
            aux_planes,
            levels,
            kernel,
            demodulate,
            demod_eps,
            guide,
            fixed_range,
            upsample,
            range_opening,
            coarse_clamp,
            coarse_gain,
            coarse_radius,
            coarse_sparse,
            range_noise,
            passes,
            pq_nits_per_unit,
            dataset: get("temc.dataset")?.to_string(),
            train_steps: num("temc.train_steps", get("temc.train_steps")?)?,
            test_relmse,
            description: raw.get("temc.description").cloned().unwrap_or_default(),
            raw: raw.clone(),
        })
    }

    /// The first plane of aux buffer `name` among the network's aux planes, if the layout
    /// has it.
    pub fn aux_plane(&self, name: &str) -> Option<usize> {
        let i = self.aux_planes.iter().position(|(n, _)| n == name)?;
        Some(self.aux_planes[..i].iter().map(|(_, c)| c).sum())
    }

    /// True when the weights were never trained (test and benchmark models).
    pub fn is_untrained(&self) -> bool {
        self.dataset == "none"
    }

    /// Channels of one level's filter output: luma taps, chroma taps, two blend logits
    /// and, with `guide`, two guides.
    pub fn filter_channels(&self) -> usize {
        crate::reconstruct::channels(self.kernel, self.guide)
    }
}

/// `temc.range_noise`: absent means 0 (the fixed threshold); else a finite number >= 0.
fn range_noise(raw: &BTreeMap<String, String>) -> Result<f32, Error> {
    let ok = |k: &f32| k.is_finite() && *k >= 0.0;
    optional(raw, "temc.range_noise", 0.0, ok, "a finite number >= 0")
}

/// `temc.coarse_gain` (absent: [`crate::reconstruct::COARSE_GAIN`]; else finite, > 0) and
/// `temc.coarse_radius` (absent: 0; else an integer up to
/// [`crate::reconstruct::COARSE_RADIUS_MAX`]).
fn coarse_cap(raw: &BTreeMap<String, String>) -> Result<(f32, usize), Error> {
    use crate::reconstruct::{COARSE_GAIN, COARSE_RADIUS_MAX as MAX};
    let gain_ok = |g: &f32| g.is_finite() && *g > 0.0;
    let gain = optional(
        raw,
        "temc.coarse_gain",
        COARSE_GAIN,
        gain_ok,
        "a finite number > 0",
    )?;
    let within = format!("an integer in 0..={MAX}");
    let radius = optional(raw, "temc.coarse_radius", 0, |r| *r <= MAX, &within)?;
    Ok((gain, radius))
}

/// `temc.coarse_sparse`: absent means 0 (no rise); else a number in [0, 1].
fn coarse_sparse(raw: &BTreeMap<String, String>) -> Result<f32, Error> {
    let ok = |s: &f32| (0.0..=1.0).contains(s);
    optional(raw, "temc.coarse_sparse", 0.0, ok, "a number in [0, 1]")
}

/// An optional numeric key: absent, `default`; else its value if it parses as `T` and is
/// `ok`, or an error saying it must be `what`.
fn optional<T: std::str::FromStr>(
    raw: &BTreeMap<String, String>,
    key: &str,
    default: T,
    ok: impl Fn(&T) -> bool,
    what: &str,
) -> Result<T, Error> {
    let Some(v) = raw.get(key) else {
        return Ok(default);
    };
    v.parse::<T>()
        .ok()
        .filter(ok)
        .ok_or_else(|| Error::Model(format!("metadata `{key}` = {v:?} must be {what}")))
}

/// An optional key naming one of `T`'s values (`from_name`, which knows `names`); absent:
/// `T::default()`.
fn named<T: Default>(
    raw: &BTreeMap<String, String>,
    key: &str,
    from_name: fn(&str) -> Option<T>,
    names: [&str; 2],
) -> Result<T, Error> {
    match raw.get(key) {
        None => Ok(T::default()),
        Some(v) => from_name(v).ok_or_else(|| {
            let [a, b] = names;
            Error::Model(format!("metadata `{key}` = {v:?} must be {a:?} or {b:?}"))
        }),
    }
}

/// The buffers of a layout such as `albedo:3,normal:3,depth:1`, in order. Each must be one
/// of [`AUX_BUFFERS`] with its channel count, at most once.
fn parse_layout(layout: &str) -> Result<Vec<(String, usize)>, Error> {
    let mut planes: Vec<(String, usize)> = Vec::new();
    for part in layout.split(',').filter(|p| !p.is_empty()) {
        let (name, n) = part.split_once(':').ok_or_else(|| {
            Error::Model(format!(
                "metadata `temc.aux_layout`: entry {part:?} is not name:channels"
            ))
        })?;
        let n: usize = n.parse().map_err(|_| {
            Error::Model(format!(
                "metadata `temc.aux_layout`: entry {part:?} has a bad channel count"
            ))
        })?;
        if name.is_empty() || n == 0 {
            return Err(Error::Model(format!(
                "metadata `temc.aux_layout`: entry {part:?} is empty"
            )));
        }
        if !AUX_BUFFERS.contains(&(name, n)) || planes.iter().any(|(p, _)| p == name) {
            return Err(Error::Model(format!(
                "metadata `temc.aux_layout`: entry {part:?} is not one of {AUX_BUFFERS:?} (or repeats)"
            )));
        }
        planes.push((name.to_string(), n));
    }
    Ok(planes)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn card() -> Vec<(&'static str, &'static str)> {
        vec![
            ("temc.format", "2"),
            ("temc.levels", "3"),
            ("temc.kernel", "5"),
            ("temc.demodulate", "0"),
            ("temc.demod_eps", "0.01"),
            ("temc.architecture", "temc2"),
            ("temc.width", "0.0625"),
            ("temc.alignment", "32"),
            ("temc.receptive_field", "404"),
            ("temc.tile_overlap", "224"),
            ("temc.chroma_encoding", "hs"),
            ("temc.aux_layout", AUX_LAYOUT),
            ("temc.pq_nits_per_unit", "100"),
            ("temc.dataset", "none"),
            ("temc.train_steps", "0"),
            ("temc.test_relmse", "none"),
            ("temc.upsample", "nearest"),
            ("temc.range_opening", "aux"),
            ("temc.coarse_clamp", "1"),
            ("temc.range_noise", "6.0"),
            ("temc.coarse_gain", "0.75"),
            ("temc.coarse_radius", "2"),
            ("temc.coarse_sparse", "0.5"),
            ("other.key", "ignored"),
        ]
    }

    #[test]
    fn parses_a_full_card() {
        let m = ModelInfo::from_props(card()).unwrap();
        assert_eq!(m.architecture, "temc2");
        assert_eq!((m.alignment, m.chroma_channels, m.aux_channels), (32, 2, 7));
        assert_eq!((m.levels, m.kernel, m.filter_channels()), (3, 5, 52));
        assert_eq!(m.aux_planes[2], ("depth".to_string(), 1));
        assert_eq!(
            (m.aux_plane("albedo"), m.aux_plane("depth")),
            (Some(0), Some(6))
        );
        assert_eq!(m.test_relmse, None);
        assert!(m.is_untrained());
        assert!(!m.raw.contains_key("other.key"));
        assert_eq!(m.upsample, Upsample::Nearest);
        assert_eq!(m.range_opening, RangeOpening::Aux);
        assert!(m.coarse_clamp);
        assert_eq!(m.range_noise, 6.0);
        assert_eq!((m.coarse_gain, m.coarse_radius), (0.75, 2));
        assert_eq!(m.coarse_sparse, 0.5);
        let optional = [
            "temc.range_opening",
            "temc.range_noise",
            "temc.coarse_gain",
            "temc.coarse_radius",
            "temc.coarse_sparse",
        ];
        let without = card().into_iter().filter(|(k, _)| !optional.contains(k));
        let m = ModelInfo::from_props(without).unwrap();
        assert_eq!(m.range_opening, RangeOpening::Plain);
        assert_eq!(m.range_noise, 0.0);
        assert_eq!((m.coarse_gain, m.coarse_radius), (1.0, 0));
        assert_eq!(m.coarse_sparse, 0.0);
    }

    #[test]
    fn upsample_defaults_to_nearest_and_reads_bilinear() {
        let without = card().into_iter().filter(|(k, _)| *k != "temc.upsample");
        let m = ModelInfo::from_props(without).unwrap();
        assert_eq!(m.upsample, Upsample::Nearest);
        let with = card().into_iter().map(|(k, v)| match k {
            "temc.upsample" => (k, "bilinear"),
            _ => (k, v),
        });
        assert_eq!(
            ModelInfo::from_props(with).unwrap().upsample,
            Upsample::Bilinear
        );
    }

    #[test]
    fn names_the_missing_or_bad_key() {
        for (key, bad) in [
            ("temc.alignment", Some("24")),
            ("temc.alignment", Some("x")),
            ("temc.format", Some("1")),
            ("temc.levels", Some("6")),
            ("temc.kernel", Some("4")),
            ("temc.demodulate", Some("yes")),
            ("temc.aux_layout", Some("albedo:3,albedo:3")),
            ("temc.aux_layout", Some("normals:3")),
            ("temc.chroma_encoding", Some("lab")),
            ("temc.aux_layout", Some("albedo3")),
            ("temc.width", Some("-1")),
            ("temc.upsample", Some("cubic")),
            ("temc.range_opening", Some("closed")),
            ("temc.coarse_clamp", Some("yes")),
            ("temc.range_noise", Some("-1")),
            ("temc.range_noise", Some("inf")),
            ("temc.range_noise", Some("six")),
            ("temc.coarse_gain", Some("0")),
            ("temc.coarse_gain", Some("nan")),
            ("temc.coarse_radius", Some("9")),
            ("temc.coarse_radius", Some("1.5")),
            ("temc.coarse_radius", Some("-1")),
            ("temc.coarse_sparse", Some("1.5")),
            ("temc.coarse_sparse", Some("-0.1")),
            ("temc.coarse_sparse", Some("nan")),
            ("temc.train_steps", None),
        ] {
            let props: Vec<_> = card()
                .into_iter()
                .filter_map(|(k, v)| {
                    if k == key {
                        bad.map(|b| (k, b))
                    } else {
                        Some((k, v))
                    }
                })
                .collect();
            let err = ModelInfo::from_props(props).unwrap_err().to_string();
            assert!(err.contains(key), "{key}: {err}");
        }
    }
}
