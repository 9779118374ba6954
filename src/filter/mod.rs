//! The OIDN-like filter: devices, filters, images, commit and execute.
//!
//! A [`Device`] holds the thread pool; a [`Filter`] holds a model, its images and its
//! parameters. `commit` resolves the model, `execute` validates the images, computes the
//! per-image statistics (exposure, depth scale) once, runs the network over tiles in
//! parallel, and writes the output only when every tile has succeeded.
//!
//! ```
//! use temc::filter::{Device, Filter, Quality};
//! let device = Device::new();
//! device.commit().unwrap();
//! let (w, h) = (40, 24);
//! let color = vec![0.5f32; w * h * 3];
//! let mut output = vec![0f32; w * h * 3];
//! let mut filter = Filter::new(&device, "TEMC2").unwrap();
//! filter.set_quality(Quality::Fast); // the built-in TEMC-2 models; or set_weights(onnx)
//! filter.set_input_f32("color", &color, w, h).unwrap();
//! filter.set_output_f32(&mut output, w, h).unwrap();
//! filter.commit().unwrap();
//! filter.execute().unwrap();
//! drop(filter); // ends the borrow of `output`
//! assert!(output.iter().all(|v| v.is_finite()));
//! ```

mod builtin;
mod commit;
mod denormals;
mod execute;
mod input;
mod kind;
mod passes;

pub use builtin::builtin_model;
pub use commit::ExecutionPath;
pub use input::ColorInput;
pub use kind::Kind;

use std::marker::PhantomData;
use std::sync::{Arc, Mutex};

use crate::color::layers::{SPECTRAL_MAX_NM, SPECTRAL_MIN_NM};
use crate::color::SpectralBands;
use crate::engine::Model;
use crate::image::{Format, Layout};
use crate::Error;

/// Quality modes, with OIDN's numeric values.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Quality {
    /// The library's choice (balanced, for every filter type).
    Default = 0,
    /// Fastest.
    Fast = 4,
    /// The default trade-off.
    Balanced = 5,
    /// Best quality: balanced's network run twice per tile, on the tile and its half turn,
    /// averaged (src/filter/builtin.rs).
    High = 6,
}

impl Quality {
    /// The names [`Quality::from_name`] accepts, in the order of the numeric values.
    pub const NAMES: [&'static str; 4] = ["default", "fast", "balanced", "high"];

    /// Parses a quality name as the CLI and the demo spell it: "fast", "balanced",
    /// "high" or "default".
    pub fn from_name(name: &str) -> Option<Self> {
        Some(match name {
            "default" => Quality::Default,
            "fast" => Quality::Fast,
            "balanced" => Quality::Balanced,
            "high" => Quality::High,
            _ => return None,
        })
    }

    /// The name [`Quality::from_name`] parses.
    pub fn name(self) -> &'static str {
        match self {
            Quality::Default => "default",
            Quality::Fast => "fast",
            Quality::Balanced => "balanced",
            Quality::High => "high",
        }
    }

    /// The quality that runs: [`Quality::Default`] is balanced, for every filter type
    /// (OIDN's default is high, but temc's high is a two-pass ensemble at twice balanced's
    /// time; balanced runs the network OIDN's types ran as high until 2026-12-06); the
    /// others are themselves. The one place that decides what the default quality is.
    pub fn resolve(self) -> Quality {
        match self {
            Quality::Default => Quality::Balanced,
            q => q,
        }
    }

    /// The quality with this numeric value.
    pub fn from_raw(v: i32) -> Option<Self> {
        Some(match v {
            0 => Quality::Default,
            4 => Quality::Fast,
            5 => Quality::Balanced,
            6 => Quality::High,
            _ => return None,
        })
    }
}

/// The default memory budget in MB (`maxMemoryMB`).
pub const DEFAULT_MAX_MEMORY_MB: usize = 2048;

/// Filter types: the model architectures.
pub const FILTER_TYPES: [&str; 4] = ["TEMC2", "TEMC1", "DEMC", "AE"];

/// The filter type that runs a model of `architecture` (a model's `temc.architecture`,
/// e.g. "temc2" -> "TEMC2"); [`Kind::for_architecture`] by name.
pub fn filter_type_for(architecture: &str) -> Result<&'static str, Error> {
    Kind::for_architecture(architecture).map(Kind::name)
}

/// How much memory one execution may use (OIDN's `maxMemoryMB`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MaxMemory {
    /// No explicit limit (OIDN's -1): the budget is [`DEFAULT_MAX_MEMORY_MB`].
    Auto,
    /// As little as possible (OIDN's 0): tiles whose core is four of the model's overlaps
    /// (at least 64 pixels) per side, unless a tile size is set.
    Least,
    /// A budget in MB: tiles shrink until the estimated peak fits it, down to the smallest
    /// tile the model allows (below that floor, 0 included, the budget is exceeded: like
    /// OIDN's `maxMemoryMB`, it is approximate).
    Mb(usize),
}

impl MaxMemory {
    /// The budget in bytes the tile plan fits.
    fn bytes(self) -> usize {
        match self {
            MaxMemory::Auto => DEFAULT_MAX_MEMORY_MB << 20,
            MaxMemory::Least => 0,
            MaxMemory::Mb(mb) => mb.saturating_mul(1 << 20),
        }
    }
}

/// The tiles a filter running `model` plans for a `width x height` image under a
/// `max_memory_mb` budget with `threads` workers, one tile each, and the estimated peak in
/// bytes: the plan stage of an execution, without running it. `threads` is not capped at
/// this machine's cores (a filter's is), so a benchmark can show a larger host's plan
/// (examples/tract_threads.rs).
pub fn tile_plan(
    model: &Model,
    width: usize,
    height: usize,
    threads: usize,
    max_memory_mb: usize,
) -> Result<(crate::tile::TilePlan, f64), Error> {
    let budget = MaxMemory::Mb(max_memory_mb).bytes();
    let passes = model.info().passes;
    execute::tile_plan(model, (width, height), 0, threads.max(1), budget, 0, passes)
}

/// User weights: ONNX bytes (parsed at commit) or a model parsed already.
#[derive(Clone)]
enum Weights {
    Onnx(Arc<[u8]>),
    Parsed(Arc<Model>),
}

struct DeviceState {
    num_threads: usize,
    verbose: i32,
    pool: Option<Arc<rayon::ThreadPool>>,
}

/// A CPU device: thread count and the thread pool filters run on. Cloning shares it.
#[derive(Clone)]
pub struct Device {
    state: Arc<Mutex<DeviceState>>,
}

impl Default for Device {
    fn default() -> Self {
        Self::new()
    }
}

impl Device {
    /// A device using every available core; call [`Device::commit`] before use.
    pub fn new() -> Self {
        Self {
            state: Arc::new(Mutex::new(DeviceState {
                num_threads: 0,
                verbose: 0,
                pool: None,
            })),
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, DeviceState> {
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Threads to use; 0 (the default) means all available cores, and more than the
    /// cores are capped at them (see [`Device::effective_threads`]).
    pub fn set_num_threads(&self, n: usize) {
        let mut s = self.lock();
        s.num_threads = n;
        s.pool = None;
    }

    /// The thread count set (0 = all cores).
    pub fn num_threads(&self) -> usize {
        self.lock().num_threads
    }

    /// Verbosity: 0 silent, 1 and above print execution details to stderr.
    pub fn set_verbose(&self, v: i32) {
        self.lock().verbose = v;
    }

    /// Verbosity level.
    pub fn verbose(&self) -> i32 {
        self.lock().verbose
    }

    /// The threads the pool gets: the setting, at most one per core. More threads than
    /// cores only add contention to a CPU-bound denoise, and a huge setting (a fuzzer
    /// found 1.66e9) would otherwise spawn threads until memory runs out.
    pub fn effective_threads(&self) -> usize {
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        match self.lock().num_threads {
            0 => cores,
            n => n.min(cores),
        }
    }

    /// Builds the thread pool for the current settings.
    pub fn commit(&self) -> Result<(), Error> {
        let n = self.effective_threads();
        let mut s = self.lock();
        if s.verbose > 0 && s.num_threads > n {
            eprintln!(
                "temc: numThreads {} capped at {n} (the cores)",
                s.num_threads
            );
        }
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .thread_name(|i| format!("temc-{i}"))
            .start_handler(|_| denormals::flush_to_zero())
            .build()
            .map_err(|e| Error::OutOfMemory(format!("thread pool: {e}")))?;
        s.pool = Some(Arc::new(pool));
        Ok(())
    }

    /// Whether [`Self::commit`] has built the thread pool (the C ABI refuses some calls
    /// on an uncommitted device, as OIDN does).
    pub fn is_committed(&self) -> bool {
        self.lock().pool.is_some()
    }

    fn pool(&self) -> Result<Arc<rayon::ThreadPool>, Error> {
        self.lock()
            .pool
            .clone()
            .ok_or_else(|| Error::InvalidOperation("the device is not committed".into()))
    }
}

/// The images a filter knows.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum ImageName {
    /// Noisy colour, linear HDR RGB (or sRGB-encoded with "srgb"); this or `Spectral`.
    Color,
    /// Albedo, RGB in [0, 1].
    Albedo,
    /// Shading normal, any length.
    Normal,
    /// Camera distance, one channel.
    Depth,
    /// Denoised colour (required); may alias `color`.
    Output,
    /// Noisy colour as spectral bands: [`Filter::set_spectral_bands`] values per pixel,
    /// the format that of one band, splitting [`Filter::set_spectral_range`] evenly.
    Spectral,
}

impl ImageName {
    /// Every image name, in index order.
    pub const ALL: [ImageName; 6] = [
        ImageName::Color,
        ImageName::Albedo,
        ImageName::Normal,
        ImageName::Depth,
        ImageName::Output,
        ImageName::Spectral,
    ];

    /// Parses an OIDN-style image name.
    pub fn parse(name: &str) -> Result<Self, Error> {
        Self::ALL
            .into_iter()
            .find(|n| n.as_str() == name)
            .ok_or_else(|| {
                Error::InvalidArgument(format!(
                    "unknown image name {name:?} (expected color, albedo, normal, depth, \
                     output or spectral)"
                ))
            })
    }

    fn index(self) -> usize {
        self as usize
    }

    /// The name as the API spells it.
    pub fn as_str(self) -> &'static str {
        ["color", "albedo", "normal", "depth", "output", "spectral"][self.index()]
    }

    /// Channels of a tightly packed f32 or f16 input: 1 for depth and for one spectral
    /// band, 3 otherwise.
    fn packed_channels(self) -> usize {
        match self {
            ImageName::Depth | ImageName::Spectral => 1,
            _ => 3,
        }
    }
}

impl TryFrom<&str> for ImageName {
    type Error = Error;
    fn try_from(name: &str) -> Result<Self, Error> {
        ImageName::parse(name)
    }
}

impl std::fmt::Display for ImageName {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// An image name, typed or as a string ("color"): what the image setters take.
fn image_name(name: impl TryInto<ImageName, Error: Into<Error>>) -> Result<ImageName, Error> {
    name.try_into().map_err(Into::into)
}

/// An image set on a filter: a raw buffer pointer and its validated layout.
#[derive(Clone, Copy, Debug)]
pub(crate) struct RawImage {
    pub ptr: *mut u8,
    pub layout: Layout,
    /// Bytes from `ptr` that the layout touches (0 for an empty image).
    pub span: usize,
    /// Bytes readable from `ptr` (`usize::MAX` when the caller only promised `span`): a
    /// "spectral" image's band count, checked at commit, must fit it.
    pub capacity: usize,
}

// SAFETY: a RawImage is only dereferenced during execute, under the contract of the setter
// that created it (Rust borrows tied to the filter's lifetime, or the C caller's promise).
unsafe impl Send for RawImage {}
// SAFETY: as for Send.
unsafe impl Sync for RawImage {}

type Monitor<'a> = Box<dyn FnMut(f64) -> bool + Send + 'a>;

/// The "spectral" image's bands.
#[derive(Clone, Copy, Debug)]
struct SpectralParams {
    /// Bands per pixel (0: not set).
    bands: usize,
    min_nm: f32,
    max_nm: f32,
}

/// What a successful commit prepared.
struct Committed {
    path: ExecutionPath,
    /// The bands of a spectral colour input.
    bands: Option<SpectralBands>,
}

/// A denoising filter. The lifetime ties borrowed images to the filter.
pub struct Filter<'a> {
    device: Device,
    kind: Kind,
    images: [Option<RawImage>; 6],
    hdr: bool,
    srgb: bool,
    clean_aux: bool,
    quality: Quality,
    max_memory: MaxMemory,
    tile_size: usize,
    /// Flip-ensemble passes: 1, 2 or 4; 0: the model's own (`temc.passes`).
    passes: usize,
    input_scale: Option<f32>,
    spectral: SpectralParams,
    /// OIDN's checks at commit (see [`Filter::set_oidn_checks`]).
    checked: bool,
    weights: Option<Weights>,
    monitor: Option<Monitor<'a>>,
    /// The loaded model, kept while nothing changes.
    model: Option<Arc<Model>>,
    /// The last model loaded from ONNX bytes, with those bytes: kept across changes, so a
    /// recommit with the same weights (a new frame's images) reuses the parsed graph and
    /// its cached plans instead of parsing again.
    loaded: Option<(Arc<[u8]>, Arc<Model>)>,
    committed: Option<Committed>,
    /// Linear RGB made from sRGB or spectral colour (allocated at commit).
    staged: Vec<f32>,
    _borrows: PhantomData<&'a mut [u8]>,
}

impl<'a> Filter<'a> {
    /// A filter of type `kind` ([`Kind`], or its name: "TEMC2", "TEMC1", "DEMC", "AE",
    /// "RT", "RTLightmap") on `device`, with that type's defaults.
    pub fn new(
        device: &Device,
        kind: impl TryInto<Kind, Error: Into<Error>>,
    ) -> Result<Self, Error> {
        let kind = kind.try_into().map_err(Into::into)?;
        Ok(Self {
            device: device.clone(),
            kind,
            images: [None; 6],
            hdr: kind.default_hdr(),
            srgb: false,
            clean_aux: false,
            quality: Quality::Default,
            max_memory: kind.default_max_memory(),
            tile_size: 0,
            passes: 0,
            input_scale: None,
            spectral: SpectralParams {
                bands: 0,
                min_nm: SPECTRAL_MIN_NM,
                max_nm: SPECTRAL_MAX_NM,
            },
            checked: kind.is_oidn(),
            weights: None,
            monitor: None,
            model: None,
            loaded: None,
            committed: None,
            staged: Vec::new(),
            _borrows: PhantomData,
        })
    }

    /// A filter for a parsed `model`: the filter type comes from the model's architecture,
    /// and commit uses the model as it is (no second parse).
    pub fn with_model(device: &Device, model: Arc<Model>) -> Result<Self, Error> {
        let mut f = Self::new(device, Kind::for_architecture(&model.info().architecture)?)?;
        f.weights = Some(Weights::Parsed(model));
        Ok(f)
    }

    /// The filter type.
    pub fn kind(&self) -> Kind {
        self.kind
    }

    fn changed(&mut self) {
        self.committed = None;
        self.model = None;
    }

    fn set_raw(&mut self, name: ImageName, img: RawImage) -> Result<(), Error> {
        if !self.kind.accepts(name) {
            return Err(Error::InvalidArgument(format!(
                "{} takes no image {:?}",
                self.kind,
                name.as_str()
            )));
        }
        self.images[name.index()] = Some(img);
        self.changed();
        Ok(())
    }

    /// Checks `layout` for image `name` and returns the bytes it spans: for "spectral" the
    /// span of the bands set (at least one); with OIDN's rules ([`Self::set_oidn_checks`])
    /// 0 for an empty image (no pixels), which is refused otherwise.
    pub fn image_span(&self, name: ImageName, layout: &Layout) -> Result<usize, Error> {
        if self.checked && commit::is_empty(layout) {
            Ok(0)
        } else if name == ImageName::Spectral {
            input::check_spectral_layout(layout)?;
            input::spectral_span(layout, self.spectral.bands.max(1))
        } else {
            layout.validate(name.as_str())
        }
    }

    /// Sets an image after checking its layout; `capacity` is the bytes readable at `ptr`.
    fn set_checked(
        &mut self,
        name: ImageName,
        ptr: *mut u8,
        layout: Layout,
        capacity: usize,
    ) -> Result<(), Error> {
        let span = self.image_span(name, &layout)?;
        if span > capacity {
            return Err(Error::InvalidArgument(format!(
                "image {:?}: layout spans {span} bytes, buffer has {capacity}",
                name.as_str()
            )));
        }
        if span > 0 && ptr.is_null() {
            return Err(Error::InvalidArgument(format!(
                "image {:?}: NULL pointer",
                name.as_str()
            )));
        }
        self.set_raw(
            name,
            RawImage {
                ptr,
                layout,
                span,
                capacity,
            },
        )
    }

    /// Sets an input image from a byte buffer with any layout (an image of no pixels is
    /// OIDN's empty image). For "spectral" the format is the type of one band.
    pub fn set_input(
        &mut self,
        name: impl TryInto<ImageName, Error: Into<Error>>,
        data: &'a [u8],
        layout: Layout,
    ) -> Result<(), Error> {
        let name = image_name(name)?;
        if name == ImageName::Output {
            return Err(Error::InvalidArgument(
                "\"output\" must be set with set_output (it is written)".into(),
            ));
        }
        self.set_checked(name, data.as_ptr() as *mut u8, layout, data.len())
    }

    /// Sets a tightly packed f32 input: 3 channels for colour, albedo and normal, 1 for
    /// depth and for each spectral band.
    pub fn set_input_f32(
        &mut self,
        name: impl TryInto<ImageName, Error: Into<Error>>,
        data: &'a [f32],
        width: usize,
        height: usize,
    ) -> Result<(), Error> {
        // SAFETY: f32 is plain bytes; any initialised f32 is valid as bytes.
        unsafe { self.set_packed(name, data, (Format::Float, Format::Float3), width, height) }
    }

    /// Sets a tightly packed half-float input: 3 channels for colour, albedo and normal, 1
    /// for depth and for each spectral band.
    pub fn set_input_f16(
        &mut self,
        name: impl TryInto<ImageName, Error: Into<Error>>,
        data: &'a [half::f16],
        width: usize,
        height: usize,
    ) -> Result<(), Error> {
        // SAFETY: f16 is two plain bytes (a transparent u16); any f16 is valid as bytes.
        unsafe { self.set_packed(name, data, (Format::Half, Format::Half3), width, height) }
    }

    /// Sets a tightly packed input of `T` values in `formats` (one channel, three): the one
    /// for depth and spectral bands, the other for colour, albedo and normal.
    ///
    /// # Safety
    /// `T` must be plain data whose bytes may be read as they are (f32, f16).
    unsafe fn set_packed<T>(
        &mut self,
        name: impl TryInto<ImageName, Error: Into<Error>>,
        data: &'a [T],
        (one, three): (Format, Format),
        width: usize,
        height: usize,
    ) -> Result<(), Error> {
        let name = image_name(name)?;
        let format = if name.packed_channels() == 1 {
            one
        } else {
            three
        };
        // SAFETY: the caller's contract; the slice covers exactly `data`'s bytes.
        let bytes = unsafe {
            std::slice::from_raw_parts(data.as_ptr() as *const u8, std::mem::size_of_val(data))
        };
        self.set_input(name, bytes, Layout::packed(format, width, height))
    }

    /// Sets the output image from a byte buffer with any layout.
    pub fn set_output(&mut self, data: &'a mut [u8], layout: Layout) -> Result<(), Error> {
        let capacity = data.len();
        self.set_checked(ImageName::Output, data.as_mut_ptr(), layout, capacity)
    }

    /// Sets a tightly packed f32 RGB output.
    pub fn set_output_f32(
        &mut self,
        data: &'a mut [f32],
        width: usize,
        height: usize,
    ) -> Result<(), Error> {
        let len = std::mem::size_of_val(data);
        // SAFETY: any byte pattern written through this view is a valid f32.
        let bytes = unsafe { std::slice::from_raw_parts_mut(data.as_mut_ptr() as *mut u8, len) };
        self.set_output(bytes, Layout::packed(Format::Float3, width, height))
    }

    /// Sets an image from a raw pointer (the C ABI's `temcSetSharedFilterImage`); the output
    /// may alias an input (in-place denoising). An image of no pixels may have any pointer.
    ///
    /// # Safety
    /// `ptr` must be valid for reads (and writes, for "output") of the bytes `layout` spans
    /// (for "spectral", with the band count set at commit), from this call until the image
    /// is unset or the filter is dropped.
    pub unsafe fn set_shared_image(
        &mut self,
        name: impl TryInto<ImageName, Error: Into<Error>>,
        ptr: *mut u8,
        layout: Layout,
    ) -> Result<(), Error> {
        // SAFETY: forwarded contract; the caller promised what the layout spans.
        unsafe { self.set_shared_image_in(image_name(name)?, ptr, layout, usize::MAX) }
    }

    /// [`Self::set_shared_image`] for memory of `capacity` readable bytes (a C buffer):
    /// the layout, and at commit a "spectral" image's bands, must fit it.
    ///
    /// # Safety
    /// `ptr` must be valid for reads (and writes, for "output") of `capacity` bytes, from
    /// this call until the image is unset or the filter is dropped.
    pub unsafe fn set_shared_image_in(
        &mut self,
        name: ImageName,
        ptr: *mut u8,
        layout: Layout,
        capacity: usize,
    ) -> Result<(), Error> {
        self.set_checked(name, ptr, layout, capacity)
    }

    /// Removes an image.
    pub fn unset_image(
        &mut self,
        name: impl TryInto<ImageName, Error: Into<Error>>,
    ) -> Result<(), Error> {
        let n = image_name(name)?;
        self.images[n.index()] = None;
        self.changed();
        Ok(())
    }

    /// Whether image `name` is set.
    pub fn has_image(&self, name: ImageName) -> bool {
        self.images[name.index()].is_some()
    }

    /// HDR input: linear radiance of any range (temc's default; "RT" defaults to false, as
    /// in OIDN). With `false` the input is taken as display-referred and clamped to [0, 1],
    /// and so is the output. "RTLightmap" is always HDR: `false` is ignored.
    pub fn set_hdr(&mut self, hdr: bool) {
        self.hdr = hdr || self.kind.hdr_only();
        self.changed();
    }

    /// The "hdr" setting.
    pub fn hdr(&self) -> bool {
        self.hdr
    }

    /// sRGB-encoded colour (OIDN's "srgb", for LDR input): it is decoded before the
    /// denoise and the output encoded. With "hdr" too, OIDN's checks refuse the commit.
    /// "RTLightmap" ignores it.
    pub fn set_srgb(&mut self, srgb: bool) {
        self.srgb = srgb && !self.kind.hdr_only();
        self.changed();
    }

    /// The "srgb" setting.
    pub fn srgb(&self) -> bool {
        self.srgb
    }

    /// OIDN's "cleanAux" (the aux images are noise-free): accepted and reported; temc
    /// uses the aux images as given either way.
    pub fn set_clean_aux(&mut self, clean: bool) {
        self.clean_aux = clean;
        self.changed();
    }

    /// The "cleanAux" setting.
    pub fn clean_aux(&self) -> bool {
        self.clean_aux
    }

    /// OIDN's "directional" ("RTLightmap" spherical-harmonics lightmaps): temc has no
    /// directional model, so `true` is refused.
    pub fn set_directional(&mut self, directional: bool) -> Result<(), Error> {
        if directional {
            return Err(Error::InvalidArgument(
                "RTLightmap: directional lightmaps (spherical-harmonics coefficients) are not \
                 supported by temc's colour models; set \"directional\" to false"
                    .into(),
            ));
        }
        Ok(())
    }

    /// Quality mode: which built-in TEMC-2 model runs (see [`builtin_model`] and
    /// [`Quality::resolve`]); ignored when user weights are set.
    pub fn set_quality(&mut self, q: Quality) {
        self.quality = q;
        self.changed();
    }

    /// The quality set (before [`Quality::resolve`]).
    pub fn quality(&self) -> Quality {
        self.quality
    }

    /// Memory budget in MB for one execution: [`MaxMemory::Mb`].
    pub fn set_max_memory_mb(&mut self, mb: usize) {
        self.set_max_memory(MaxMemory::Mb(mb));
    }

    /// Memory budget for one execution.
    pub fn set_max_memory(&mut self, budget: MaxMemory) {
        self.max_memory = budget;
        self.changed();
    }

    /// The memory budget.
    pub fn max_memory(&self) -> MaxMemory {
        self.max_memory
    }

    /// Pixels each tile writes per side (its core; the network sees the core plus the
    /// model's overlap on each side). 0, the default, picks the largest tiles that fit
    /// the memory budget.
    pub fn set_tile_size(&mut self, pixels: usize) {
        self.tile_size = pixels;
        self.changed();
    }

    /// The tile size set (0: from the memory budget).
    pub fn tile_size(&self) -> usize {
        self.tile_size
    }

    /// Runs of the network per tile, one per orientation of the tile (1: the tile; 2: and
    /// its half turn; 4: and its two mirror images), averaged; 0, the default, takes the
    /// model's own count (`temc.passes`: 2 for the built-in high, 1 otherwise). Each pass
    /// costs about one run's time; averaging the orientations cuts the residual noise a
    /// little (docs/reconstruction.md, "A flip ensemble").
    ///
    /// ```
    /// use temc::filter::{Device, Filter};
    /// let mut filter = Filter::new(&Device::new(), "TEMC2").unwrap();
    /// filter.set_passes(4).unwrap();
    /// assert_eq!(filter.passes(), 4);
    /// assert!(filter.set_passes(3).is_err());
    /// ```
    pub fn set_passes(&mut self, passes: usize) -> Result<(), Error> {
        if passes != 0 && !passes::is_allowed(passes) {
            return Err(Error::InvalidArgument(format!(
                "passes = {passes}: must be 0 (the model's own), 1, 2 or 4"
            )));
        }
        self.passes = passes;
        self.changed();
        Ok(())
    }

    /// The flip-ensemble passes set (0: the model's own).
    pub fn passes(&self) -> usize {
        self.passes
    }

    /// Multiplies the input before PQ encoding; NaN restores automatic exposure.
    pub fn set_input_scale(&mut self, s: f32) -> Result<(), Error> {
        if s.is_nan() {
            self.input_scale = None;
        } else if s.is_finite() && s > 0.0 {
            self.input_scale = Some(s);
        } else {
            return Err(Error::InvalidArgument(format!(
                "inputScale must be positive and finite, got {s}"
            )));
        }
        self.changed();
        Ok(())
    }

    /// The input scale set, NaN while automatic.
    pub fn input_scale(&self) -> f32 {
        self.input_scale.unwrap_or(f32::NAN)
    }

    /// Bands per pixel of the "spectral" image (at least 1).
    pub fn set_spectral_bands(&mut self, bands: usize) -> Result<(), Error> {
        if bands < 1 {
            return Err(Error::InvalidArgument(format!(
                "spectralBands must be at least 1, got {bands}"
            )));
        }
        self.spectral.bands = bands;
        self.changed();
        Ok(())
    }

    /// Bands per pixel of the "spectral" image (0 until set).
    pub fn spectral_bands(&self) -> usize {
        self.spectral.bands
    }

    /// The wavelengths in nm the "spectral" bands split evenly (default 380..780, the
    /// spectral layer of temc-render); each must be positive, and commit checks that
    /// `max_nm` exceeds `min_nm`.
    pub fn set_spectral_range(&mut self, min_nm: f32, max_nm: f32) -> Result<(), Error> {
        for (name, v) in [("spectralMin", min_nm), ("spectralMax", max_nm)] {
            if !(v.is_finite() && v > 0.0) {
                return Err(Error::InvalidArgument(format!(
                    "{name} must be a positive wavelength in nm, got {v}"
                )));
            }
        }
        self.spectral.min_nm = min_nm;
        self.spectral.max_nm = max_nm;
        self.changed();
        Ok(())
    }

    /// The "spectral" bands' range in nm, (min, max).
    pub fn spectral_range(&self) -> (f32, f32) {
        (self.spectral.min_nm, self.spectral.max_nm)
    }

    /// OIDN's rules: empty images (0 pixels) are accepted, and a filter of only empty
    /// images executes as a no-op; commit checks input and output set, formats of three
    /// channels, equal channel counts, images of the output's size, not "hdr" with "srgb",
    /// aux images alone only for "RT", each refused with [`Error::InvalidOperation`] and
    /// OIDN's message, and user weights that do not load are refused the same way. On by
    /// default for OIDN's types (and in the C ABI); temc's types refuse empty images,
    /// check the images at execute, and run [`Self::execute_to_vec`] without an output.
    pub fn set_oidn_checks(&mut self, on: bool) {
        self.checked = on;
        self.changed();
    }

    /// Uses a user ONNX model (with temc metadata) instead of the built-in weights.
    pub fn set_weights(&mut self, onnx: &[u8]) {
        self.weights = Some(Weights::Onnx(Arc::from(onnx)));
        self.changed();
    }

    /// Removes user weights.
    pub fn unset_weights(&mut self) {
        self.weights = None;
        self.changed();
    }

    /// Called with the progress in [0, 1] after each tile; returning false cancels the
    /// execution with [`Error::Cancelled`], leaving the output untouched.
    pub fn set_progress_monitor(&mut self, f: impl FnMut(f64) -> bool + Send + 'a) {
        self.monitor = Some(Box::new(f));
    }

    /// Removes the progress monitor.
    pub fn unset_progress_monitor(&mut self) {
        self.monitor = None;
    }

    /// Checks the parameters and images (OIDN's checks, when on), chooses the execution
    /// path, and for a denoise loads the model (user weights, or the built-in one for the
    /// filter type and quality) and checks it matches the filter type. Required after any
    /// change, before execute; a filter whose commit failed stays uncommitted.
    pub fn commit(&mut self) -> Result<(), Error> {
        self.committed = None;
        self.device.pool()?;
        if self.checked {
            self.check_params()?;
        }
        let path = self.choose_path()?;
        let mut bands = None;
        if let ExecutionPath::Denoise(input) = path {
            if input == ColorInput::Spectral {
                bands = Some(self.band_layout()?);
            }
            self.stage_buffer(input)?;
            self.load_model()?;
        }
        self.committed = Some(Committed { path, bands });
        Ok(())
    }

    /// Allocates the staging buffer a converted colour input needs.
    fn stage_buffer(&mut self, input: ColorInput) -> Result<(), Error> {
        let source = if input == ColorInput::Spectral {
            ImageName::Spectral
        } else {
            ImageName::Color
        };
        let n = match self.images[source.index()] {
            Some(img) if input.staged() => img.layout.width * img.layout.height * 3,
            _ => 0,
        };
        self.staged.clear();
        self.staged
            .try_reserve_exact(n)
            .map_err(|_| Error::OutOfMemory(format!("colour staging of {n} floats")))?;
        self.staged.resize(n, 0.0);
        Ok(())
    }

    fn load_model(&mut self) -> Result<(), Error> {
        let kind = self.kind.runs();
        let weights = match self.weights.clone() {
            Some(w) => w,
            None => Weights::Onnx(
                builtin::shared(kind.name(), self.quality.resolve()).ok_or_else(|| {
                    Error::InvalidOperation(format!(
                        "no built-in weights for {}: the baselines ship as files in \
                             onnx/baselines/; set \"weights\" to a temc ONNX model",
                        self.kind
                    ))
                })?,
            ),
        };
        let user_onnx = matches!(self.weights, Some(Weights::Onnx(_)));
        let model = self.parse(weights.clone()).map_err(|e| match e {
            // As OIDN refuses a weights blob it cannot use: at commit, with
            // INVALID_OPERATION (core/tza.cpp), whatever the parser's reason.
            Error::Model(_) | Error::InvalidArgument(_) if self.checked && user_onnx => {
                Error::InvalidOperation(format!("invalid or corrupted weights blob: {e}"))
            }
            e => e,
        })?;
        if let Weights::Onnx(w) = weights {
            self.loaded = Some((w, model.clone()));
        }
        self.model = Some(model);
        Ok(())
    }

    /// The model of `weights` (the loaded one again if they are the bytes it came from),
    /// checked against the filter type.
    fn parse(&self, weights: Weights) -> Result<Arc<Model>, Error> {
        let model = match weights {
            Weights::Parsed(m) => m,
            Weights::Onnx(w) => match &self.loaded {
                Some((prev, m)) if Arc::ptr_eq(prev, &w) => m.clone(),
                _ => Arc::new(Model::from_bytes(&w)?),
            },
        };
        let arch = &model.info().architecture;
        if !arch.eq_ignore_ascii_case(self.kind.runs().name()) {
            return Err(Error::InvalidArgument(format!(
                "the weights are a {arch:?} model, but the filter type is {}",
                self.kind
            )));
        }
        Ok(model)
    }

    /// The committed model, if any.
    pub fn model(&self) -> Option<&Arc<Model>> {
        self.model.as_ref()
    }

    /// The path the committed filter's execution takes, if committed.
    pub fn execution_path(&self) -> Option<ExecutionPath> {
        self.committed.as_ref().map(|c| c.path)
    }

    /// The committed path's pixel alignment (OIDN's "alignment"): the model's, 1 for a
    /// prefilter, 0 before commit.
    pub fn alignment(&self) -> usize {
        match self.execution_path() {
            Some(ExecutionPath::Prefilter(_)) => 1,
            _ => self.model.as_ref().map_or(0, |m| m.info().alignment),
        }
    }

    /// The committed path's tile overlap in pixels (OIDN's "overlap"): the model's, the
    /// prefilter's reach, 0 before commit.
    pub fn overlap(&self) -> usize {
        match self.execution_path() {
            Some(ExecutionPath::Prefilter(_)) => crate::prefilter::REACH,
            _ => self.model.as_ref().map_or(0, |m| m.info().tile_overlap),
        }
    }

    /// Denoises `color` (with the aux images set) into `output`. On any error, including
    /// cancellation, the output is left untouched.
    pub fn execute(&mut self) -> Result<ExecuteStats, Error> {
        if self.images[ImageName::Output.index()].is_none() {
            return Err(Error::InvalidOperation(
                "image \"output\" is not set".into(),
            ));
        }
        self.run().map(|(stats, _)| stats)
    }

    /// Denoises `color` and returns the result as packed RGB f32 instead of writing an
    /// "output" image (which must not be set); saves a full-size buffer for callers that
    /// would only copy the output elsewhere.
    pub fn execute_to_vec(&mut self) -> Result<(Vec<f32>, ExecuteStats), Error> {
        if self.images[ImageName::Output.index()].is_some() {
            return Err(Error::InvalidOperation(
                "execute_to_vec returns the result itself: unset \"output\" first".into(),
            ));
        }
        let (stats, v) = self.run()?;
        let v = v.ok_or_else(|| Error::InvalidOperation("the execution wrote no result".into()))?;
        Ok((v, stats))
    }

    fn run(&mut self) -> Result<(ExecuteStats, Option<Vec<f32>>), Error> {
        let committed = self.committed.as_ref().ok_or_else(|| {
            Error::InvalidOperation(
                "the filter is not committed (call commit after changes)".into(),
            )
        })?;
        let output = self.images[ImageName::Output.index()];
        let input = match committed.path {
            ExecutionPath::Empty => {
                return Ok((ExecuteStats::default(), output.is_none().then(Vec::new)))
            }
            ExecutionPath::Prefilter(kind) => {
                let name = match kind {
                    crate::prefilter::AuxKind::Albedo => ImageName::Albedo,
                    crate::prefilter::AuxKind::Normal => ImageName::Normal,
                };
                let src = self.images[name.index()].ok_or_else(|| {
                    Error::InvalidOperation(format!("image {:?} is not set", name.as_str()))
                })?;
                let result = execute::prefilter(&src, output.as_ref(), kind);
                return Ok((ExecuteStats::default(), result));
            }
            ExecutionPath::Denoise(input) => input,
        };
        let model = self.model.clone().ok_or_else(|| {
            Error::InvalidOperation(
                "the filter is not committed (call commit after changes)".into(),
            )
        })?;
        let pool = self.device.pool()?;
        let tile_size = match (self.tile_size, self.max_memory) {
            (0, MaxMemory::Least) => {
                // Cores of 4 overlaps: several tiles on any image OIDN would tile, each
                // repeating little of its neighbours' work (the smallest tile, one
                // alignment step inside the overlap, would repeat it some 100-fold).
                (4 * model.info().tile_overlap).max(64)
            }
            (t, _) => t,
        };
        let job = execute::Job {
            model: &model,
            images: self.images,
            color_input: input,
            bands: committed.bands.as_ref(),
            staged: &mut self.staged,
            hdr: self.hdr,
            input_scale: self.input_scale,
            max_memory_bytes: self.max_memory.bytes(),
            tile_size,
            passes: match self.passes {
                0 => model.info().passes,
                n => n,
            },
            verbose: self.device.verbose(),
        };
        execute::run(job, &pool, self.monitor.as_mut())
    }
}

/// What an execution did, for `--json` and benchmarks.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ExecuteStats {
    /// Number of tiles.
    pub tiles: usize,
    /// Network window (w, h) per tile.
    pub window: (usize, usize),
    /// Pixels processed by the network over image pixels.
    pub cost_ratio: f64,
    /// The input scale used (given or automatic).
    pub input_scale: f32,
    /// Threads in the pool.
    pub threads: usize,
    /// Estimated peak bytes (staging buffers + concurrent tiles).
    pub estimated_peak_bytes: f64,
    /// Network runs per tile (the flip ensemble's passes).
    pub passes: usize,
}
