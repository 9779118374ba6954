//! What commit decides: OIDN's checks (core/unet_filter.cpp, `checkParams` and the choice
//! of weights, in its order, with its messages, as [`Error::InvalidOperation`]), and the
//! execution path the filter then takes.

use super::input::{self, ColorInput};
use super::{Filter, ImageName, Kind};
use crate::color::SpectralBands;
use crate::image::{Format, Layout};
use crate::prefilter::AuxKind;
use crate::Error;

/// The path a committed filter's execution takes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ExecutionPath {
    /// Denoise the colour, made linear by the given input stage.
    Denoise(ColorInput),
    /// "RT" given only one aux image (and an output): denoise that image.
    Prefilter(AuxKind),
    /// Every image is empty (0 pixels): OIDN commits and executes it, doing nothing.
    Empty,
}

fn op(message: impl Into<String>) -> Error {
    Error::InvalidOperation(message.into())
}

/// An image of no pixels (OIDN's 0xN and Nx0 images).
pub(super) fn is_empty(layout: &Layout) -> bool {
    layout.width == 0 || layout.height == 0
}

impl Filter<'_> {
    fn layout(&self, name: ImageName) -> Option<Layout> {
        self.images[name.index()].map(|i| i.layout)
    }

    /// OIDN's checks at commit, so a misconfigured filter fails where it fails with OIDN
    /// rather than at execute. "spectral" counts as colour; "depth" is checked for size
    /// like the aux images.
    pub(super) fn check_params(&self) -> Result<(), Error> {
        let image = |n| self.layout(n);
        let color = image(ImageName::Color).or(image(ImageName::Spectral).map(|l| Layout {
            // The colour temc makes from the bands.
            format: Format::Float3,
            ..l
        }));
        let (albedo, normal) = (image(ImageName::Albedo), image(ImageName::Normal));
        let Some(input) = color.or(albedo).or(normal) else {
            return Err(op("input image not specified"));
        };
        let output = image(ImageName::Output).ok_or_else(|| op("output image not specified"))?;
        // OIDN also takes 1- and 2-channel images; temc's networks need RGB (a fourth
        // channel, as in FLOAT4, is ignored).
        for (name, l) in [("color", color), ("albedo", albedo), ("normal", normal)] {
            if let Some(l) = l.filter(|l| l.format.channels() < 3) {
                return Err(op(format!(
                    "unsupported input image format: {name:?} is {:?}, temc needs 3 channels",
                    l.format
                )));
            }
        }
        if output.format.channels() < 3 {
            return Err(op(format!(
                "unsupported output image format: {:?}, temc needs 3 channels",
                output.format
            )));
        }
        if input.format.channels() != output.format.channels() {
            return Err(op(format!(
                "input/output image channel count mismatch: {} and {}",
                input.format.channels(),
                output.format.channels()
            )));
        }
        for name in [
            ImageName::Color,
            ImageName::Spectral,
            ImageName::Albedo,
            ImageName::Normal,
            ImageName::Depth,
        ] {
            if let Some(l) = image(name) {
                if (l.width, l.height) != (output.width, output.height) {
                    return Err(op(format!(
                        "image size mismatch: {:?} is {}x{}, \"output\" is {}x{}",
                        name.as_str(),
                        l.width,
                        l.height,
                        output.width,
                        output.height
                    )));
                }
            }
        }
        // OIDN's first mode check, "directional and hdr/srgb modes cannot be enabled at
        // the same time", cannot fire: temc refuses "directional" when it is set.
        if self.hdr && self.srgb {
            return Err(op("hdr and srgb modes cannot be enabled at the same time"));
        }
        Ok(())
    }

    /// The execution path for the images set. Without OIDN's checks a filter with no
    /// colour denoises (and execute reports the missing colour).
    pub(super) fn choose_path(&self) -> Result<ExecutionPath, Error> {
        let set: Vec<Layout> = self.images.iter().flatten().map(|i| i.layout).collect();
        if !set.is_empty() && set.iter().all(is_empty) {
            return Ok(ExecutionPath::Empty);
        }
        let has = |n: ImageName| self.images[n.index()].is_some();
        let (color, spectral) = (has(ImageName::Color), has(ImageName::Spectral));
        if color && spectral {
            return Err(Error::InvalidArgument(
                "set \"color\" or \"spectral\", not both".into(),
            ));
        }
        if color || spectral {
            return Ok(ExecutionPath::Denoise(if spectral {
                ColorInput::Spectral
            } else if self.srgb {
                ColorInput::Srgb
            } else {
                ColorInput::Linear
            }));
        }
        // Aux images alone: OIDN's "RT" denoises one of them; nothing else does.
        let aux = (has(ImageName::Albedo), has(ImageName::Normal));
        match (self.kind, aux) {
            (Kind::Rt, (true, false)) if self.hdr => {
                Err(op("hdr mode is not supported for albedo filtering"))
            }
            (Kind::Rt, (true, false)) => Ok(ExecutionPath::Prefilter(AuxKind::Albedo)),
            (Kind::Rt, (false, true)) if self.hdr || self.srgb => Err(op(
                "hdr and srgb modes are not supported for normal filtering",
            )),
            (Kind::Rt, (false, true)) => Ok(ExecutionPath::Prefilter(AuxKind::Normal)),
            _ if self.checked => Err(op(
                "invalid combination of input features (set \"color\", or for \"RT\" only one \
                 of \"albedo\" and \"normal\")",
            )),
            _ => Ok(ExecutionPath::Denoise(ColorInput::Linear)),
        }
    }

    /// The band layout for "spectral" from the band parameters, checked against the image.
    pub(super) fn band_layout(&self) -> Result<SpectralBands, Error> {
        let n = self.spectral.bands;
        if n < 1 {
            return Err(Error::InvalidArgument(
                "image \"spectral\" needs \"spectralBands\" (the number of bands per pixel)".into(),
            ));
        }
        let (lo, hi) = (self.spectral.min_nm, self.spectral.max_nm);
        if hi <= lo {
            return Err(Error::InvalidArgument(format!(
                "spectralMax ({hi}) must exceed spectralMin ({lo})"
            )));
        }
        let img = self.images[ImageName::Spectral.index()]
            .ok_or_else(|| op("image \"spectral\" is not set"))?;
        let span = input::spectral_span(&img.layout, n)?;
        // The band count may have grown since the image was set: check its buffer again.
        if span > img.capacity {
            return Err(Error::InvalidArgument(format!(
                "image \"spectral\": {n} bands span {span} bytes, the buffer has {}",
                img.capacity
            )));
        }
        SpectralBands::uniform(n, lo, hi)
    }
}
