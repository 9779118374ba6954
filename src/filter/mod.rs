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
mod denormals;
mod execute;

pub use builtin::builtin_model;

use std::marker::PhantomData;
use std::sync::{Arc, Mutex};

use crate::engine::Model;
use crate::image::{Format, Layout};
use crate::Error;

/// Quality modes, with OIDN's numeric values.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Quality {
    /// The library's choice (balanced).
    Default = 0,
    /// Fastest.
    Fast = 4,
    /// The default trade-off.
    Balanced = 5,
    /// Best quality. For now the balanced network, until a high model beats it
    /// (src/filter/builtin.rs).
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
/// e.g. "temc2" -> "TEMC2").
pub fn filter_type_for(architecture: &str) -> Result<&'static str, Error> {
    FILTER_TYPES
        .iter()
        .find(|k| k.eq_ignore_ascii_case(architecture))
        .copied()
        .ok_or_else(|| {
            Error::InvalidArgument(format!(
                "architecture {architecture:?} has no filter type (expected one of {FILTER_TYPES:?})"
            ))
        })
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
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ImageName {
    /// Noisy colour, linear HDR RGB (required).
    Color,
    /// Albedo, RGB in [0, 1].
    Albedo,
    /// Shading normal, any length.
    Normal,
    /// Camera distance, one channel.
    Depth,
    /// Denoised colour (required); may alias `color`.
    Output,
}

impl ImageName {
    /// Parses an OIDN-style image name.
    pub fn parse(name: &str) -> Result<Self, Error> {
        Ok(match name {
            "color" => ImageName::Color,
            "albedo" => ImageName::Albedo,
            "normal" => ImageName::Normal,
            "depth" => ImageName::Depth,
            "output" => ImageName::Output,
            "spectral" => {
                return Err(Error::InvalidArgument(
                    "image \"spectral\" is not supported by the filter yet: convert bands with \
                     temc::color::SpectralBands and pass \"color\""
                        .into(),
                ))
            }
            other => {
                return Err(Error::InvalidArgument(format!(
                    "unknown image name {other:?} (expected color, albedo, normal, depth or output)"
                )))
            }
        })
    }

    fn index(self) -> usize {
        self as usize
    }

    /// The name as the API spells it.
    pub fn as_str(self) -> &'static str {
        ["color", "albedo", "normal", "depth", "output"][self.index()]
    }
}

/// An image set on a filter: a raw buffer pointer and its validated layout.
#[derive(Clone, Copy, Debug)]
pub(crate) struct RawImage {
    pub ptr: *mut u8,
    pub layout: Layout,
    /// Bytes from `ptr` that the layout touches.
    pub span: usize,
}

// SAFETY: a RawImage is only dereferenced during execute, under the contract of the setter
// that created it (Rust borrows tied to the filter's lifetime, or the C caller's promise).
unsafe impl Send for RawImage {}
// SAFETY: as for Send.
unsafe impl Sync for RawImage {}

type Monitor<'a> = Box<dyn FnMut(f64) -> bool + Send + 'a>;

/// A denoising filter. The lifetime ties borrowed images to the filter.
pub struct Filter<'a> {
    device: Device,
    kind: &'static str,
    images: [Option<RawImage>; 5],
    hdr: bool,
    quality: Quality,
    max_memory_mb: usize,
    tile_size: usize,
    input_scale: Option<f32>,
    weights: Option<Weights>,
    monitor: Option<Monitor<'a>>,
    committed: Option<Arc<Model>>,
    /// The weights the committed model was loaded from, to skip reloading.
    loaded_from: Option<Arc<[u8]>>,
    _borrows: PhantomData<&'a mut [u8]>,
}

impl<'a> Filter<'a> {
    /// A filter of type `kind` ("TEMC2", "TEMC1", "DEMC" or "AE") on `device`.
    pub fn new(device: &Device, kind: &str) -> Result<Self, Error> {
        let kind = FILTER_TYPES.iter().find(|k| **k == kind).ok_or_else(|| {
            Error::InvalidArgument(format!(
                "unknown filter type {kind:?} (expected one of {FILTER_TYPES:?})"
            ))
        })?;
        Ok(Self {
            device: device.clone(),
            kind,
            images: [None; 5],
            hdr: true,
            quality: Quality::Default,
            max_memory_mb: DEFAULT_MAX_MEMORY_MB,
            tile_size: 0,
            input_scale: None,
            weights: None,
            monitor: None,
            committed: None,
            loaded_from: None,
            _borrows: PhantomData,
        })
    }

    /// A filter for a parsed `model`: the filter type comes from the model's architecture,
    /// and commit uses the model as it is (no second parse).
    pub fn with_model(device: &Device, model: Arc<Model>) -> Result<Self, Error> {
        let mut f = Self::new(device, filter_type_for(&model.info().architecture)?)?;
        f.weights = Some(Weights::Parsed(model));
        Ok(f)
    }

    /// The filter type.
    pub fn kind(&self) -> &'static str {
        self.kind
    }

    fn changed(&mut self) {
        self.committed = None;
    }

    fn set_raw(&mut self, name: &str, img: RawImage) -> Result<(), Error> {
        let n = ImageName::parse(name)?;
        self.images[n.index()] = Some(img);
        self.changed();
        Ok(())
    }

    /// Sets an input image from a byte buffer with any layout.
    pub fn set_input(&mut self, name: &str, data: &'a [u8], layout: Layout) -> Result<(), Error> {
        if ImageName::parse(name)? == ImageName::Output {
            return Err(Error::InvalidArgument(
                "\"output\" must be set with set_output (it is written)".into(),
            ));
        }
        let span = layout.validate(name)?;
        if span > data.len() {
            return Err(Error::InvalidArgument(format!(
                "image {name:?}: layout spans {span} bytes, buffer has {}",
                data.len()
            )));
        }
        self.set_raw(
            name,
            RawImage {
                ptr: data.as_ptr() as *mut u8,
                layout,
                span,
            },
        )
    }

    /// Sets a tightly packed f32 input: 3 channels for colour, albedo and normal, 1 for depth.
    pub fn set_input_f32(
        &mut self,
        name: &str,
        data: &'a [f32],
        width: usize,
        height: usize,
    ) -> Result<(), Error> {
        let format = if name == "depth" {
            Format::Float
        } else {
            Format::Float3
        };
        // SAFETY: reinterpreting initialised f32s as bytes is always valid.
        let bytes = unsafe {
            std::slice::from_raw_parts(data.as_ptr() as *const u8, std::mem::size_of_val(data))
        };
        self.set_input(name, bytes, Layout::packed(format, width, height))
    }

    /// Sets the output image from a byte buffer with any layout.
    pub fn set_output(&mut self, data: &'a mut [u8], layout: Layout) -> Result<(), Error> {
        let span = layout.validate("output")?;
        if span > data.len() {
            return Err(Error::InvalidArgument(format!(
                "image \"output\": layout spans {span} bytes, buffer has {}",
                data.len()
            )));
        }
        self.set_raw(
            "output",
            RawImage {
                ptr: data.as_mut_ptr(),
                layout,
                span,
            },
        )
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
    /// may alias an input (in-place denoising).
    ///
    /// # Safety
    /// `ptr` must be valid for reads (and writes, for "output") of the bytes `layout` spans,
    /// from this call until the image is unset or the filter is dropped.
    pub unsafe fn set_shared_image(
        &mut self,
        name: &str,
        ptr: *mut u8,
        layout: Layout,
    ) -> Result<(), Error> {
        if ptr.is_null() {
            return Err(Error::InvalidArgument(format!(
                "image {name:?}: NULL pointer"
            )));
        }
        let span = layout.validate(name)?;
        self.set_raw(name, RawImage { ptr, layout, span })
    }

    /// Removes an image.
    pub fn unset_image(&mut self, name: &str) -> Result<(), Error> {
        let n = ImageName::parse(name)?;
        self.images[n.index()] = None;
        self.changed();
        Ok(())
    }

    /// HDR input (the default, and what temc is built for). With `false` the input is
    /// taken as display-referred and clamped to [0, 1], and so is the output.
    pub fn set_hdr(&mut self, hdr: bool) {
        self.hdr = hdr;
        self.changed();
    }

    /// Quality mode: which built-in TEMC-2 model runs (see [`builtin_model`]); ignored
    /// when user weights are set.
    pub fn set_quality(&mut self, q: Quality) {
        self.quality = q;
        self.changed();
    }

    /// Memory budget in MB for one execution: tiles shrink until the estimated peak fits
    /// it, down to the smallest tile the model allows (below that floor the budget is
    /// exceeded: like OIDN's `maxMemoryMB`, it is approximate).
    pub fn set_max_memory_mb(&mut self, mb: usize) {
        self.max_memory_mb = mb;
        self.changed();
    }

    /// Pixels each tile writes per side (its core; the network sees the core plus the
    /// model's overlap on each side). 0, the default, picks the largest tiles that fit
    /// the memory budget.
    pub fn set_tile_size(&mut self, pixels: usize) {
        self.tile_size = pixels;
        self.changed();
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

    /// Sets a boolean parameter by its OIDN name ("hdr").
    pub fn set_bool(&mut self, name: &str, v: bool) -> Result<(), Error> {
        match name {
            "hdr" => self.set_hdr(v),
            _ => {
                return Err(Error::InvalidArgument(format!(
                    "unknown bool parameter {name:?}"
                )))
            }
        }
        Ok(())
    }

    /// Sets an integer parameter by its OIDN name ("quality", "maxMemoryMB"), or temc's
    /// "tileSize".
    pub fn set_int(&mut self, name: &str, v: i32) -> Result<(), Error> {
        match name {
            "quality" => self.set_quality(
                Quality::from_raw(v)
                    .ok_or_else(|| Error::InvalidArgument(format!("unknown quality {v}")))?,
            ),
            "maxMemoryMB" => {
                if v <= 0 {
                    return Err(Error::InvalidArgument(format!(
                        "maxMemoryMB must be positive, got {v}"
                    )));
                }
                self.set_max_memory_mb(v as usize)
            }
            "tileSize" => {
                if v < 0 {
                    return Err(Error::InvalidArgument(format!(
                        "tileSize must be >= 0, got {v}"
                    )));
                }
                self.set_tile_size(v as usize)
            }
            _ => {
                return Err(Error::InvalidArgument(format!(
                    "unknown int parameter {name:?}"
                )))
            }
        }
        Ok(())
    }

    /// Sets a float parameter by its OIDN name ("inputScale").
    pub fn set_float(&mut self, name: &str, v: f32) -> Result<(), Error> {
        match name {
            "inputScale" => self.set_input_scale(v),
            _ => Err(Error::InvalidArgument(format!(
                "unknown float parameter {name:?}"
            ))),
        }
    }

    /// Reads a float parameter back: "inputScale" (NaN while automatic).
    pub fn get_float(&self, name: &str) -> Result<f32, Error> {
        match name {
            "inputScale" => Ok(self.input_scale.unwrap_or(f32::NAN)),
            _ => Err(Error::InvalidArgument(format!(
                "unknown float parameter {name:?}"
            ))),
        }
    }

    /// Reads a parameter back: "hdr" (0/1), "quality", "maxMemoryMB", "tileSize".
    pub fn get_int(&self, name: &str) -> Result<i32, Error> {
        match name {
            "hdr" => Ok(self.hdr as i32),
            "quality" => Ok(self.quality as i32),
            "maxMemoryMB" => Ok(self.max_memory_mb.min(i32::MAX as usize) as i32),
            "tileSize" => Ok(self.tile_size.min(i32::MAX as usize) as i32),
            _ => Err(Error::InvalidArgument(format!(
                "unknown int parameter {name:?}"
            ))),
        }
    }

    /// Loads the model (user weights, or the built-in one for the filter type and quality)
    /// and checks it matches the filter type. Required after any change, before execute.
    pub fn commit(&mut self) -> Result<(), Error> {
        self.device.pool()?;
        let weights = match self.weights.clone() {
            Some(w) => w,
            None => Weights::Onnx(builtin::shared(self.kind, self.quality).ok_or_else(|| {
                Error::InvalidOperation(format!(
                    "no built-in weights for {}: the baselines ship as files in \
                     onnx/baselines/; set \"weights\" to a temc ONNX model",
                    self.kind
                ))
            })?),
        };
        let (model, bytes) = match weights {
            Weights::Parsed(m) => (m, None),
            Weights::Onnx(w) => match (&self.committed, &self.loaded_from) {
                (Some(m), Some(prev)) if Arc::ptr_eq(prev, &w) => (m.clone(), Some(w)),
                _ => (Arc::new(Model::from_bytes(&w)?), Some(w)),
            },
        };
        let arch = &model.info().architecture;
        if !arch.eq_ignore_ascii_case(self.kind) {
            return Err(Error::InvalidArgument(format!(
                "the weights are a {arch:?} model, but the filter type is {}",
                self.kind
            )));
        }
        self.committed = Some(model);
        self.loaded_from = bytes;
        Ok(())
    }

    /// The committed model, if any.
    pub fn model(&self) -> Option<&Arc<Model>> {
        self.committed.as_ref()
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
        let model = self.committed.clone().ok_or_else(|| {
            Error::InvalidOperation(
                "the filter is not committed (call commit after changes)".into(),
            )
        })?;
        let pool = self.device.pool()?;
        let job = execute::Job {
            model: &model,
            images: self.images,
            hdr: self.hdr,
            input_scale: self.input_scale,
            max_memory_bytes: self.max_memory_mb.saturating_mul(1 << 20),
            tile_size: self.tile_size,
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
}
