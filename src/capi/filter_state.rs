//! A C filter's state: OIDN's filter types and parameter semantics over [`Filter`], the
//! images C has set (shared or in buffers), spectral and sRGB staging, and aux
//! prefiltering.
//!
//! OIDN's rules kept here: an unknown parameter or image name is a warning (printed when
//! the device is verbose), not an error; bools and ints are interchangeable; "hdrScale" is
//! "inputScale"; "alignment" and "overlap" (and their old "tile" names) are readable.

use std::collections::BTreeMap;
use std::sync::Arc;

use super::objects::{BufferObj, DeviceObj, Failure, Outcome};
use crate::color::SpectralBands;
use crate::filter::{Filter, Quality, DEFAULT_MAX_MEMORY_MB};
use crate::image::{read3, write3, Format, Layout};
use crate::prefilter::{filter_aux, AuxKind};
use crate::Error;

/// The filter types the C ABI knows: OIDN's two and temc's own.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Api {
    /// A temc type ("TEMC2", "TEMC1", "DEMC", "AE"): temc's defaults (HDR, balanced).
    Native,
    /// OIDN's "RT": TEMC-2 with OIDN's defaults (LDR, high quality) and aux prefiltering.
    Rt,
    /// OIDN's "RTLightmap": TEMC-2 on HDR colour only.
    RtLightmap,
}

/// An image C has set.
#[derive(Clone)]
struct SetImage {
    ptr: *mut u8,
    layout: Layout,
    /// Held so the buffer outlives the image (OIDN filters retain their buffers).
    buffer: Option<Arc<BufferObj>>,
}

/// Which path a committed filter takes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Mode {
    /// Denoise colour; `staged`: colour is made from "spectral" or sRGB input first.
    Denoise { spectral: bool, srgb: bool },
    /// "RT" with only one aux image and an output: denoise that image.
    Prefilter(AuxKind),
    /// Every image is empty (0 pixels): OIDN commits and executes it, doing nothing.
    Empty,
}

/// An image of no pixels (OIDN's 0xN and Nx0 images).
fn is_empty(layout: &Layout) -> bool {
    layout.width == 0 || layout.height == 0
}

// Default band range for "spectral": temc-render's spectral layer.
use crate::color::layers::{SPECTRAL_MAX_NM, SPECTRAL_MIN_NM};

/// The state behind a C filter handle.
pub(crate) struct FilterState {
    filter: Filter<'static>,
    api: Api,
    images: BTreeMap<&'static str, SetImage>,
    /// The pointer the core filter's "color" currently reads, to avoid re-setting it.
    pushed_color: Option<(usize, Layout)>,
    /// Linear RGB made from "spectral" or sRGB colour; the core filter reads it as colour.
    staged: Option<Box<[f32]>>,
    bands: Option<SpectralBands>,
    srgb: bool,
    clean_aux: bool,
    directional: bool,
    spectral_bands: i32,
    spectral_min: f32,
    spectral_max: f32,
    /// The caller's "weights" buffer, re-read by temcUpdateFilterData.
    weights: Option<(usize, usize)>,
    max_memory_auto: bool,
    /// "maxMemoryMB" 0: commit sets the core filter's tile size from the model's overlap.
    small_tiles: bool,
    mode: Option<Mode>,
}

// SAFETY: the raw pointers are the C caller's images, used under temcSetSharedFilterImage's
// contract; the state is only touched under the filter's mutex.
unsafe impl Send for FilterState {}

const IMAGE_NAMES: [&str; 6] = ["color", "albedo", "normal", "depth", "output", "spectral"];

impl FilterState {
    /// A filter of C type `kind`.
    pub fn new(device: &DeviceObj, kind: &str) -> Outcome<Self> {
        let (api, core_kind) = match kind {
            "RT" => (Api::Rt, "TEMC2"),
            "RTLightmap" => (Api::RtLightmap, "TEMC2"),
            other => (Api::Native, other),
        };
        let mut filter = Filter::new(&device.device, core_kind).map_err(|e| {
            Failure::invalid(format!(
                "{e}; OIDN's \"RT\" and \"RTLightmap\" are accepted too"
            ))
        })?;
        match api {
            // OIDN's defaults: "hdr" false, quality high (a client that reads them back,
            // or relies on them, sees what it would with OIDN).
            Api::Rt => {
                filter.set_hdr(false);
                filter.set_quality(Quality::High);
            }
            Api::RtLightmap => {
                filter.set_hdr(true);
                filter.set_quality(Quality::High);
            }
            Api::Native => {}
        }
        Ok(Self {
            filter,
            api,
            images: BTreeMap::new(),
            pushed_color: None,
            staged: None,
            bands: None,
            srgb: false,
            clean_aux: false,
            directional: false,
            spectral_bands: 0,
            spectral_min: SPECTRAL_MIN_NM,
            spectral_max: SPECTRAL_MAX_NM,
            weights: None,
            max_memory_auto: api != Api::Native,
            small_tiles: false,
            mode: None,
        })
    }

    fn changed(&mut self) {
        self.mode = None;
    }

    /// Keeps a set image; the filter needs another commit.
    fn store_image(&mut self, name: &'static str, image: SetImage) {
        self.images.insert(name, image);
        self.changed();
    }

    /// Sets an image; `buffer` is the buffer it lives in, if any (already range-checked).
    ///
    /// # Safety
    /// `ptr` must stay valid for the bytes `layout` spans until the image is unset or the
    /// filter released (temcSetSharedFilterImage's contract).
    pub unsafe fn set_image(
        &mut self,
        dev: &DeviceObj,
        name: &str,
        ptr: *mut u8,
        layout: Layout,
        buffer: Option<Arc<BufferObj>>,
    ) -> Outcome<()> {
        let Some(&name) = IMAGE_NAMES.iter().find(|n| **n == name) else {
            dev.warn(&format!("unknown filter image {name:?} ignored"));
            return Ok(());
        };
        if self.api == Api::RtLightmap && !matches!(name, "color" | "output" | "spectral") {
            dev.warn(&format!("RTLightmap ignores image {name:?}"));
            return Ok(());
        }
        if is_empty(&layout) {
            // OIDN's empty images: shared memory that is NULL unsets the image; one of a
            // buffer (or non-NULL memory) stays set, with nothing to read, and a filter
            // whose images are all empty commits and executes as a no-op. The core
            // filter, which needs pixels, never sees it.
            if ptr.is_null() && buffer.is_none() {
                return self.unset_image(dev, name);
            }
            self.store_image(
                name,
                SetImage {
                    ptr,
                    layout,
                    buffer,
                },
            );
            return Ok(());
        }
        if ptr.is_null() {
            return Err(Failure::invalid(format!("image {name:?}: NULL pointer")));
        }
        if name == "spectral" {
            if layout.format.channels() != 1 {
                return Err(Failure::invalid(
                    "image \"spectral\": the format is the type of one band (TEMC_FORMAT_FLOAT \
                     or TEMC_FORMAT_HALF); the band count is the \"spectralBands\" parameter",
                ));
            }
            // Checked against the band count at commit; here only the size limits.
            Layout {
                pixel_stride: 0,
                row_stride: 0,
                ..layout
            }
            .validate(name)?;
        } else {
            // SAFETY: forwarded under this function's contract.
            unsafe { self.filter.set_shared_image(name, ptr, layout) }?;
            if name == "color" {
                self.pushed_color = Some((ptr as usize, layout));
            }
        }
        self.store_image(
            name,
            SetImage {
                ptr,
                layout,
                buffer,
            },
        );
        Ok(())
    }

    /// Checks a buffer-backed image against the buffer's size.
    pub fn check_buffer_image(
        &self,
        name: &str,
        layout: &Layout,
        buffer: &BufferObj,
    ) -> Outcome<()> {
        let span = if is_empty(layout) {
            0 // OIDN's empty image (0 pixels), in a buffer of any size
        } else if name == "spectral" {
            spectral_span(layout, self.spectral_bands.max(1) as usize)?
        } else {
            layout.validate(name)?
        };
        if span > buffer.size {
            return Err(Failure::invalid(format!(
                "image {name:?}: layout spans {span} bytes, the buffer has {}",
                buffer.size
            )));
        }
        Ok(())
    }

    /// Leaves "maxMemoryMB" 0's tiles: the budget picks them again.
    fn end_small_tiles(&mut self) {
        if std::mem::take(&mut self.small_tiles) {
            self.filter.set_tile_size(0);
        }
    }

    /// Removes an image.
    pub fn unset_image(&mut self, dev: &DeviceObj, name: &str) -> Outcome<()> {
        let Some(&name) = IMAGE_NAMES.iter().find(|n| **n == name) else {
            dev.warn(&format!("unknown filter image {name:?}"));
            return Ok(());
        };
        self.images.remove(name);
        let forwarded = match name {
            "spectral" => false,
            "color" | "output" => true,
            _ => self.api != Api::RtLightmap,
        };
        if forwarded {
            self.filter.unset_image(name)?;
        }
        if name == "color" {
            self.pushed_color = None;
        }
        self.changed();
        Ok(())
    }

    /// Sets opaque data: "weights" (a temc ONNX model; re-read by [`Self::update_data`];
    /// a NULL pointer of 0 bytes unsets it, as OIDN's empty data). A model that does not
    /// load fails the next commit, as in OIDN.
    ///
    /// # Safety
    /// `ptr` must be readable for `size` bytes now and at every temcUpdateFilterData.
    pub unsafe fn set_data(
        &mut self,
        dev: &DeviceObj,
        name: &str,
        ptr: *const u8,
        size: usize,
    ) -> Outcome<()> {
        if name != "weights" {
            dev.warn(&format!("unknown filter data {name:?} ignored"));
            return Ok(());
        }
        if ptr.is_null() && size == 0 {
            // OIDN's empty data (a NULL pointer of 0 bytes): no user weights.
            return self.unset_data(dev, name);
        }
        if ptr.is_null() || size == 0 {
            return Err(Failure::invalid("weights: NULL or empty buffer"));
        }
        // SAFETY: the caller passes `size` readable bytes.
        self.filter
            .set_weights(unsafe { std::slice::from_raw_parts(ptr, size) });
        self.weights = Some((ptr as usize, size));
        self.changed();
        Ok(())
    }

    /// Re-reads opaque data the caller changed in place.
    ///
    /// # Safety
    /// As [`Self::set_data`]: the buffer given there is still readable.
    pub unsafe fn update_data(&mut self, dev: &DeviceObj, name: &str) -> Outcome<()> {
        match (name, self.weights) {
            ("weights", Some((p, n))) => {
                // SAFETY: set_data's contract.
                unsafe { self.set_data(dev, name, p as *const u8, n) }
            }
            ("weights", None) => Err(Failure::operation("weights are not set")),
            _ => {
                dev.warn(&format!("unknown filter data {name:?}"));
                Ok(())
            }
        }
    }

    /// Removes opaque data.
    pub fn unset_data(&mut self, dev: &DeviceObj, name: &str) -> Outcome<()> {
        if name == "weights" {
            self.filter.unset_weights();
            self.weights = None;
            self.changed();
        } else {
            dev.warn(&format!("unknown filter data {name:?}"));
        }
        Ok(())
    }

    /// Sets a bool or int parameter (OIDN treats the two alike).
    pub fn set_int(&mut self, dev: &DeviceObj, name: &str, v: i32) -> Outcome<()> {
        let lightmap = self.api == Api::RtLightmap;
        match name {
            "hdr" if lightmap => dev.warn("RTLightmap input is always HDR; \"hdr\" ignored"),
            "hdr" => self.filter.set_hdr(v != 0),
            "srgb" if !lightmap => self.srgb = v != 0,
            "cleanAux" if !lightmap => self.clean_aux = v != 0,
            "directional" if lightmap => {
                if v != 0 {
                    return Err(Failure::invalid(
                        "RTLightmap: directional lightmaps (spherical-harmonics coefficients) \
                         are not supported by temc's colour models; set \"directional\" to false",
                    ));
                }
                self.directional = false;
            }
            "quality" => {
                let q = Quality::from_raw(v)
                    .ok_or_else(|| Failure::invalid(format!("unknown quality {v}")))?;
                // OIDN's default quality is high.
                let q = match (self.api, q) {
                    (Api::Rt | Api::RtLightmap, Quality::Default) => Quality::High,
                    (_, q) => q,
                };
                self.filter.set_quality(q);
            }
            "maxMemoryMB" if v < 0 => {
                // OIDN's -1: no explicit limit; temc then uses its default budget.
                self.filter.set_max_memory_mb(DEFAULT_MAX_MEMORY_MB);
                self.max_memory_auto = true;
                self.end_small_tiles();
            }
            "maxMemoryMB" if v == 0 => {
                // OIDN's 0: as little memory as possible, so small tiles (oidnTest sets it
                // to force many). temc's smallest tile, one alignment step inside the
                // overlap, would repeat its ~100-pixel overlap some 100-fold: commit picks
                // tiles of 4 overlaps instead (see `small_tiles`).
                self.filter.set_max_memory_mb(0);
                self.max_memory_auto = false;
                self.small_tiles = true;
            }
            "maxMemoryMB" => {
                self.filter.set_int(name, v)?;
                self.max_memory_auto = false;
                self.end_small_tiles();
            }
            "tileSize" => {
                self.filter.set_int(name, v)?;
                self.small_tiles = false;
            }
            "spectralBands" => {
                if v < 1 {
                    return Err(Failure::invalid(format!(
                        "spectralBands must be at least 1, got {v}"
                    )));
                }
                self.spectral_bands = v;
            }
            "alignment" | "overlap" | "tileAlignment" | "tileOverlap" => {
                dev.warn(&format!("filter parameter {name:?} is read-only"));
                return Ok(());
            }
            _ => {
                dev.warn(&format!("unknown filter parameter {name:?} ignored"));
                return Ok(());
            }
        }
        self.changed();
        Ok(())
    }

    /// Reads a bool or int parameter.
    pub fn get_int(&self, dev: &DeviceObj, name: &str) -> Outcome<i32> {
        let info = || self.filter.model().map(|m| m.info().clone());
        Ok(match name {
            "hdr" => self.filter.get_int("hdr")?,
            "srgb" => self.srgb as i32,
            "cleanAux" => self.clean_aux as i32,
            "directional" => self.directional as i32,
            "quality" => self.filter.get_int("quality")?,
            "maxMemoryMB" if self.max_memory_auto => -1,
            "maxMemoryMB" | "tileSize" => self.filter.get_int(name)?,
            "spectralBands" => self.spectral_bands,
            "alignment" | "tileAlignment" => match self.mode {
                Some(Mode::Prefilter(_)) => 1,
                _ => info().map_or(0, |i| i.alignment as i32),
            },
            "overlap" | "tileOverlap" => match self.mode {
                Some(Mode::Prefilter(_)) => crate::prefilter::REACH as i32,
                _ => info().map_or(0, |i| i.tile_overlap as i32),
            },
            _ => {
                dev.warn(&format!("unknown filter parameter {name:?}"));
                0
            }
        })
    }

    /// Sets a float parameter.
    pub fn set_float(&mut self, dev: &DeviceObj, name: &str, v: f32) -> Outcome<()> {
        match name {
            "inputScale" | "hdrScale" => self.filter.set_input_scale(v)?,
            "spectralMin" | "spectralMax" => {
                if !(v.is_finite() && v > 0.0) {
                    return Err(Failure::invalid(format!(
                        "{name} must be a positive wavelength in nm, got {v}"
                    )));
                }
                if name == "spectralMin" {
                    self.spectral_min = v;
                } else {
                    self.spectral_max = v;
                }
            }
            _ => {
                dev.warn(&format!("unknown filter parameter {name:?} ignored"));
                return Ok(());
            }
        }
        self.changed();
        Ok(())
    }

    /// Reads a float parameter ("inputScale" is NaN while automatic).
    pub fn get_float(&self, dev: &DeviceObj, name: &str) -> Outcome<f32> {
        Ok(match name {
            "inputScale" | "hdrScale" => self.filter.get_float("inputScale")?,
            "spectralMin" => self.spectral_min,
            "spectralMax" => self.spectral_max,
            _ => {
                dev.warn(&format!("unknown filter parameter {name:?}"));
                0.0
            }
        })
    }

    /// The core filter, for the progress monitor.
    pub fn core(&mut self) -> &mut Filter<'static> {
        &mut self.filter
    }

    /// OIDN's checks at commit (core/unet_filter.cpp, `checkParams` and the choice of
    /// weights), in its order, with its error code (INVALID_OPERATION) and messages, so a
    /// misconfigured filter fails where it fails with OIDN rather than at execute.
    /// "spectral" counts as colour; "depth" is checked for size like the aux images.
    fn check_params(&self, hdr: bool) -> Outcome<()> {
        let image = |n: &str| self.images.get(n).map(|i| i.layout);
        let color = image("color").or(image("spectral").map(|l| Layout {
            // The colour temc makes from the bands.
            format: Format::Float3,
            ..l
        }));
        let (albedo, normal) = (image("albedo"), image("normal"));
        let Some(input) = color.or(albedo).or(normal) else {
            return Err(Failure::operation("input image not specified"));
        };
        let output =
            image("output").ok_or_else(|| Failure::operation("output image not specified"))?;
        // OIDN also takes 1- and 2-channel images; temc's networks need RGB (a fourth
        // channel, as in FLOAT4, is ignored).
        for (name, l) in [("color", color), ("albedo", albedo), ("normal", normal)] {
            if let Some(l) = l.filter(|l| l.format.channels() < 3) {
                return Err(Failure::operation(format!(
                    "unsupported input image format: {name:?} is {:?}, temc needs 3 channels",
                    l.format
                )));
            }
        }
        if output.format.channels() < 3 {
            return Err(Failure::operation(format!(
                "unsupported output image format: {:?}, temc needs 3 channels",
                output.format
            )));
        }
        if input.format.channels() != output.format.channels() {
            return Err(Failure::operation(format!(
                "input/output image channel count mismatch: {} and {}",
                input.format.channels(),
                output.format.channels()
            )));
        }
        for name in ["color", "spectral", "albedo", "normal", "depth"] {
            if let Some(l) = image(name) {
                if (l.width, l.height) != (output.width, output.height) {
                    return Err(Failure::operation(format!(
                        "image size mismatch: {name:?} is {}x{}, \"output\" is {}x{}",
                        l.width, l.height, output.width, output.height
                    )));
                }
            }
        }
        // "directional" cannot be true in temc (setting it is refused), so only the
        // second of OIDN's two mode checks can fire; both are kept in its order.
        if self.directional && (hdr || self.srgb) {
            return Err(Failure::operation(
                "directional and hdr/srgb modes cannot be enabled at the same time",
            ));
        }
        if hdr && self.srgb {
            return Err(Failure::operation(
                "hdr and srgb modes cannot be enabled at the same time",
            ));
        }
        Ok(())
    }

    /// Decides the path, stages colour if needed and loads the model.
    pub fn commit(&mut self) -> Outcome<()> {
        self.mode = None;
        let hdr = self.filter.get_int("hdr")? != 0;
        self.check_params(hdr)?;
        if self
            .images
            .get("output")
            .is_some_and(|o| is_empty(&o.layout))
        {
            // check_params held the inputs to the output's size: all are empty.
            self.mode = Some(Mode::Empty);
            return Ok(());
        }
        let has = |n: &str| self.images.contains_key(n);
        let mode = if !has("color") && !has("spectral") {
            // Aux images alone: OIDN's "RT" denoises one of them; nothing else does.
            match (self.api, has("albedo"), has("normal")) {
                (Api::Rt, true, false) if hdr => {
                    return Err(Failure::operation(
                        "hdr mode is not supported for albedo filtering",
                    ))
                }
                (Api::Rt, true, false) => Mode::Prefilter(AuxKind::Albedo),
                (Api::Rt, false, true) if hdr || self.srgb => {
                    return Err(Failure::operation(
                        "hdr and srgb modes are not supported for normal filtering",
                    ))
                }
                (Api::Rt, false, true) => Mode::Prefilter(AuxKind::Normal),
                _ => {
                    return Err(Failure::operation(
                        "invalid combination of input features (set \"color\", or for \"RT\" \
                         only one of \"albedo\" and \"normal\")",
                    ))
                }
            }
        } else {
            if has("color") && has("spectral") {
                return Err(Failure::invalid("set \"color\" or \"spectral\", not both"));
            }
            Mode::Denoise {
                spectral: has("spectral"),
                srgb: self.srgb && has("color"),
            }
        };
        if let Mode::Denoise { spectral, srgb } = mode {
            if spectral {
                self.bands = Some(self.spectral_layout()?);
            }
            if spectral || srgb {
                let src = if spectral { "spectral" } else { "color" };
                let l = self.images[src].layout;
                let staged = vec![0f32; l.width * l.height * 3].into_boxed_slice();
                let layout = Layout::packed(Format::Float3, l.width, l.height);
                let ptr = staged.as_ptr() as *mut u8;
                // SAFETY: `staged` is owned by this state and is replaced only here, after
                // the core filter has been pointed at the new buffer.
                unsafe { self.filter.set_shared_image("color", ptr, layout) }?;
                self.staged = Some(staged);
                self.pushed_color = Some((ptr as usize, layout));
            } else if let Some(c) = self.images.get("color") {
                if self.pushed_color != Some((c.ptr as usize, c.layout)) {
                    let (ptr, layout) = (c.ptr, c.layout);
                    // SAFETY: the caller's colour, under its setter's contract.
                    unsafe { self.filter.set_shared_image("color", ptr, layout) }?;
                    self.pushed_color = Some((ptr as usize, layout));
                }
            } else if self.pushed_color.take().is_some() {
                // Colour staged from an image that is gone: the core filter must not read
                // the stale staging buffer.
                self.filter.unset_image("color")?;
                self.staged = None;
            }
            let user_weights = self.weights.is_some();
            self.filter.commit().map_err(|e| match e {
                // As OIDN refuses a weights blob it cannot use: at commit, with
                // INVALID_OPERATION (core/tza.cpp), whatever the parser's reason.
                Error::Model(_) | Error::InvalidArgument(_) if user_weights => {
                    Failure::operation(format!("invalid or corrupted weights blob: {e}"))
                }
                e => e.into(),
            })?;
            if self.small_tiles {
                // Cores of 4 overlaps: several tiles on any image OIDN would tile, each
                // repeating little of its neighbours' work. Committing again reuses the
                // loaded model.
                let overlap = self.filter.model().map_or(0, |m| m.info().tile_overlap);
                self.filter.set_tile_size((4 * overlap).max(64));
                self.filter.commit()?;
            }
        }
        self.mode = Some(mode);
        Ok(())
    }

    /// The band layout for "spectral" from the band parameters, checked against the image.
    fn spectral_layout(&self) -> Outcome<SpectralBands> {
        let n = self.spectral_bands;
        if n < 1 {
            return Err(Failure::invalid(
                "image \"spectral\" needs \"spectralBands\" (the number of bands per pixel)",
            ));
        }
        let (lo, hi) = (self.spectral_min, self.spectral_max);
        if hi <= lo {
            return Err(Failure::invalid(format!(
                "spectralMax ({hi}) must exceed spectralMin ({lo})"
            )));
        }
        let img = &self.images["spectral"];
        let span = spectral_span(&img.layout, n as usize)?;
        // The band count may have grown since the image was set: check its buffer again.
        if let Some(b) = &img.buffer {
            if span > b.size {
                return Err(Failure::invalid(format!(
                    "image \"spectral\": {n} bands span {span} bytes, the buffer has {}",
                    b.size
                )));
            }
        }
        Ok(SpectralBands::uniform(n as usize, lo, hi)?)
    }

    /// The committed path; an error if the filter has changed since its last commit.
    fn committed(&self) -> Outcome<Mode> {
        self.mode.ok_or_else(|| {
            Failure::operation("the filter is not committed (call commit after changes)")
        })
    }

    /// Fails as [`Self::execute`] would on an uncommitted filter.
    pub fn check_committed(&self) -> Outcome<()> {
        self.committed().map(|_| ())
    }

    /// Runs the committed filter. On error the output is untouched.
    pub fn execute(&mut self) -> Outcome<()> {
        let mode = self.committed()?;
        match mode {
            Mode::Empty => Ok(()),
            Mode::Prefilter(kind) => self.prefilter(kind),
            Mode::Denoise { spectral, srgb } => {
                if spectral {
                    self.stage_spectral();
                } else if srgb {
                    self.stage_srgb();
                }
                self.filter.execute()?;
                if srgb {
                    self.encode_srgb_output();
                }
                Ok(())
            }
        }
    }

    fn stage_spectral(&mut self) {
        let (Some(bands), Some(staged), Some(img)) = (
            self.bands.as_ref(),
            self.staged.as_mut(),
            self.images.get("spectral"),
        ) else {
            return;
        };
        let l = img.layout;
        let n = bands.len();
        let (cb, px) = (l.format.channel_bytes(), spectral_pixel_stride(&l, n));
        let row = if l.row_stride == 0 {
            px * l.width
        } else {
            l.row_stride
        };
        let mut values = vec![0f32; n];
        for y in 0..l.height {
            for x in 0..l.width {
                let base = l.byte_offset + y * row + x * px;
                for (b, v) in values.iter_mut().enumerate() {
                    // SAFETY: commit checked the span of N bands per pixel; the caller keeps
                    // the image valid (its setter's contract).
                    *v = unsafe { read_channel(img.ptr.add(base + b * cb), l.format) };
                }
                let rgb = bands.to_linear_srgb(&values);
                staged[(y * l.width + x) * 3..][..3].copy_from_slice(&rgb);
            }
        }
    }

    fn stage_srgb(&mut self) {
        let (Some(staged), Some(img)) = (self.staged.as_mut(), self.images.get("color")) else {
            return;
        };
        let l = img.layout;
        for y in 0..l.height {
            for x in 0..l.width {
                // SAFETY: the layout was validated when the image was set.
                let v = unsafe { read3(img.ptr, &l, x, y) };
                staged[(y * l.width + x) * 3..][..3].copy_from_slice(&v.map(srgb_to_linear));
            }
        }
    }

    fn encode_srgb_output(&mut self) {
        let Some(out) = self.images.get("output") else {
            return;
        };
        let l = out.layout;
        for y in 0..l.height {
            for x in 0..l.width {
                // SAFETY: the output layout was validated when set; execute just wrote it.
                unsafe {
                    let v = read3(out.ptr, &l, x, y);
                    write3(out.ptr, &l, x, y, v.map(linear_to_srgb));
                }
            }
        }
    }

    /// Denoises the one aux image into the output.
    fn prefilter(&mut self, kind: AuxKind) -> Outcome<()> {
        let name = if kind == AuxKind::Albedo {
            "albedo"
        } else {
            "normal"
        };
        let (src, out) = (&self.images[name], &self.images["output"]);
        // Sizes were checked at commit, and images cannot change without another commit.
        let (l, o) = (src.layout, out.layout);
        let mut input = Vec::with_capacity(l.width * l.height * 3);
        for y in 0..l.height {
            for x in 0..l.width {
                // SAFETY: validated layout, caller-kept buffer.
                input.extend_from_slice(&unsafe { read3(src.ptr, &l, x, y) });
            }
        }
        let result = filter_aux(&input, l.width, l.height, kind);
        for y in 0..o.height {
            for x in 0..o.width {
                let i = (y * o.width + x) * 3;
                // SAFETY: validated layout; the input was copied first, so in-place works.
                unsafe { write3(out.ptr, &o, x, y, [result[i], result[i + 1], result[i + 2]]) };
            }
        }
        Ok(())
    }
}

fn spectral_pixel_stride(l: &Layout, bands: usize) -> usize {
    if l.pixel_stride == 0 {
        l.format.channel_bytes() * bands
    } else {
        l.pixel_stride
    }
}

/// Bytes a spectral image of `bands` bands spans, after checking its strides.
fn spectral_span(l: &Layout, bands: usize) -> Outcome<usize> {
    let cb = l.format.channel_bytes();
    let px = spectral_pixel_stride(l, bands);
    let pixel = cb.saturating_mul(bands);
    if px < pixel {
        return Err(Failure::invalid(format!(
            "image \"spectral\": pixel stride {px} is smaller than {bands} bands ({pixel} bytes)"
        )));
    }
    let wide = Layout {
        format: l.format,
        pixel_stride: px,
        row_stride: if l.row_stride == 0 {
            px.saturating_mul(l.width)
        } else {
            l.row_stride
        },
        ..*l
    };
    let span = wide.validate("spectral")?;
    span.checked_add(pixel - cb)
        .ok_or_else(|| Failure::invalid("image \"spectral\": the byte span overflows"))
}

/// Reads one f32 or f16 value.
///
/// # Safety
/// `p` must be readable for one channel of `format`.
unsafe fn read_channel(p: *const u8, format: Format) -> f32 {
    if format.channel_bytes() == 4 {
        // SAFETY: the caller's contract.
        f32::from_ne_bytes(unsafe { std::ptr::read_unaligned(p as *const [u8; 4]) })
    } else {
        // SAFETY: the caller's contract.
        half::f16::from_bits(u16::from_ne_bytes(unsafe {
            std::ptr::read_unaligned(p as *const [u8; 2])
        }))
        .to_f32()
    }
}

/// The sRGB transfer function (IEC 61966-2-1), decoding.
fn srgb_to_linear(v: f32) -> f32 {
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// The sRGB transfer function, encoding.
fn linear_to_srgb(v: f32) -> f32 {
    if v <= 0.0031308 {
        v * 12.92
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}
