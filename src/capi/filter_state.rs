//! A C filter's state: the core [`Filter`] (which holds OIDN's filter types, checks and
//! execution paths), the buffers its images live in, the "weights" memory that
//! temcUpdateFilterData re-reads, and OIDN's parameter table.
//!
//! OIDN's rules kept here: an unknown parameter or image name is a warning (printed when
//! the device is verbose), not an error; bools and ints are interchangeable; "hdrScale" is
//! "inputScale"; "alignment" and "overlap" (and their old "tile" names) are readable.

use std::collections::BTreeMap;
use std::sync::Arc;

use super::failure::{Failure, Outcome};
use crate::filter::{Device, Filter, ImageName, Kind, MaxMemory, Quality};
use crate::image::Layout;
use crate::Error;

/// What a filter's state needs of its device: the core device, and OIDN's warnings.
pub(crate) trait FilterDevice {
    /// The core device filters run on.
    fn device(&self) -> &Device;
    /// OIDN's warning (printed when the device is verbose), never an error.
    fn warn(&self, message: &str);
}

impl<T: FilterDevice + ?Sized> FilterDevice for Arc<T> {
    fn device(&self) -> &Device {
        (**self).device()
    }

    fn warn(&self, message: &str) {
        (**self).warn(message)
    }
}

/// A buffer an image lives in: held while the image is set.
pub(crate) trait ImageBuffer: Send + Sync {
    /// Its size in bytes.
    fn size(&self) -> usize;
}

impl<T: ImageBuffer + ?Sized> ImageBuffer for Arc<T> {
    fn size(&self) -> usize {
        (**self).size()
    }
}

/// A core error as the C ABI reports it: OIDN's code, the bare message.
fn failure(e: Error) -> Failure {
    match e {
        Error::InvalidOperation(m) => Failure::operation(m),
        Error::InvalidArgument(m) => Failure::invalid(m),
        e => e.into(),
    }
}

type Setter<T> = fn(&mut Filter<'static>, T) -> Result<(), Error>;
type Getter<T> = fn(&Filter<'static>) -> T;

/// How a parameter is read and written: bools and ints alike, or floats; `None`: read-only.
enum Access {
    Int(Getter<i32>, Option<Setter<i32>>),
    Float(Getter<f32>, Option<Setter<f32>>),
}

/// One filter parameter: its names (OIDN's aliases), the filter types that take it
/// (others warn as for an unknown name), and how it maps to the core filter.
struct Param {
    names: &'static [&'static str],
    takes: fn(Kind) -> bool,
    access: Access,
}

fn any(_: Kind) -> bool {
    true
}

fn ldr_capable(k: Kind) -> bool {
    !k.hdr_only()
}

fn positive(name: &str, v: i32) -> Result<usize, Error> {
    usize::try_from(v).map_err(|_| Error::InvalidArgument(format!("{name} must be >= 0, got {v}")))
}

/// The filter parameters of the C ABI (rav1e's `option_match`, as a table): the first
/// entry naming the parameter for the filter's type wins.
const PARAMS: &[Param] = &[
    Param {
        names: &["hdr"],
        takes: ldr_capable,
        access: Access::Int(
            |f| f.hdr() as i32,
            Some(|f, v| {
                f.set_hdr(v != 0);
                Ok(())
            }),
        ),
    },
    // RTLightmap input is always HDR: "hdr" reads 1 and is not set.
    Param {
        names: &["hdr"],
        takes: Kind::hdr_only,
        access: Access::Int(|f| f.hdr() as i32, None),
    },
    Param {
        names: &["srgb"],
        takes: ldr_capable,
        access: Access::Int(
            |f| f.srgb() as i32,
            Some(|f, v| {
                f.set_srgb(v != 0);
                Ok(())
            }),
        ),
    },
    Param {
        names: &["cleanAux"],
        takes: ldr_capable,
        access: Access::Int(
            |f| f.clean_aux() as i32,
            Some(|f, v| {
                f.set_clean_aux(v != 0);
                Ok(())
            }),
        ),
    },
    Param {
        names: &["directional"],
        takes: Kind::hdr_only,
        access: Access::Int(|_| 0, Some(|f, v| f.set_directional(v != 0))),
    },
    Param {
        names: &["quality"],
        takes: any,
        access: Access::Int(
            |f| f.quality() as i32,
            Some(|f, v| {
                let q = Quality::from_raw(v)
                    .ok_or_else(|| Error::InvalidArgument(format!("unknown quality {v}")))?;
                f.set_quality(q);
                Ok(())
            }),
        ),
    },
    Param {
        names: &["maxMemoryMB"],
        takes: any,
        access: Access::Int(
            |f| match f.max_memory() {
                MaxMemory::Auto => -1,
                MaxMemory::Least => 0,
                MaxMemory::Mb(mb) => mb.min(i32::MAX as usize) as i32,
            },
            Some(|f, v| {
                f.set_max_memory(match v {
                    // OIDN's -1: no explicit limit; temc then uses its default budget.
                    ..0 => MaxMemory::Auto,
                    // OIDN's 0: as little memory as possible, so small tiles (oidnTest
                    // sets it to force many).
                    0 => MaxMemory::Least,
                    mb => MaxMemory::Mb(mb as usize),
                });
                Ok(())
            }),
        ),
    },
    Param {
        names: &["tileSize"],
        takes: any,
        access: Access::Int(
            |f| f.tile_size().min(i32::MAX as usize) as i32,
            Some(|f, v| {
                f.set_tile_size(positive("tileSize", v)?);
                Ok(())
            }),
        ),
    },
    Param {
        names: &["passes"],
        takes: any,
        access: Access::Int(
            |f| f.passes().min(i32::MAX as usize) as i32,
            Some(|f, v| f.set_passes(positive("passes", v)?)),
        ),
    },
    Param {
        names: &["spectralBands"],
        takes: any,
        access: Access::Int(
            |f| f.spectral_bands().min(i32::MAX as usize) as i32,
            Some(|f, v| f.set_spectral_bands(usize::try_from(v).unwrap_or(0))),
        ),
    },
    Param {
        names: &["alignment", "tileAlignment"],
        takes: any,
        access: Access::Int(|f| f.alignment().min(i32::MAX as usize) as i32, None),
    },
    Param {
        names: &["overlap", "tileOverlap"],
        takes: any,
        access: Access::Int(|f| f.overlap().min(i32::MAX as usize) as i32, None),
    },
    Param {
        names: &["inputScale", "hdrScale"],
        takes: any,
        access: Access::Float(|f| f.input_scale(), Some(|f, v| f.set_input_scale(v))),
    },
    Param {
        names: &["spectralMin"],
        takes: any,
        access: Access::Float(
            |f| f.spectral_range().0,
            Some(|f, v| f.set_spectral_range(v, f.spectral_range().1)),
        ),
    },
    Param {
        names: &["spectralMax"],
        takes: any,
        access: Access::Float(
            |f| f.spectral_range().1,
            Some(|f, v| f.set_spectral_range(f.spectral_range().0, v)),
        ),
    },
];

/// The state behind a C filter handle.
pub(crate) struct FilterState {
    filter: Filter<'static>,
    /// The buffers of images set from buffers, held while the image is set (OIDN filters
    /// retain their buffers).
    buffers: BTreeMap<ImageName, Arc<dyn ImageBuffer>>,
    /// The caller's "weights" memory, re-read by temcUpdateFilterData.
    weights: Option<(usize, usize)>,
}

// SAFETY: the core filter's raw pointers are the C caller's images, used under
// temcSetSharedFilterImage's contract; the state is only touched under the filter's mutex.
unsafe impl Send for FilterState {}

impl FilterState {
    /// A filter of C type `kind`, with OIDN's checks at commit.
    pub fn new(device: &dyn FilterDevice, kind: &str) -> Outcome<Self> {
        let kind = Kind::parse(kind).map_err(failure)?;
        let mut filter = Filter::new(device.device(), kind).map_err(failure)?;
        filter.set_oidn_checks(true);
        Ok(Self {
            filter,
            buffers: BTreeMap::new(),
            weights: None,
        })
    }

    /// The image `name` names, or a warning for an unknown name.
    fn image(&self, dev: &dyn FilterDevice, name: &str) -> Option<ImageName> {
        let image = ImageName::parse(name).ok();
        if image.is_none() {
            dev.warn(&format!("unknown filter image {name:?} ignored"));
        }
        image
    }

    /// Sets an image; `buffer` is the buffer it lives in, if any (already range-checked).
    ///
    /// # Safety
    /// `ptr` must stay valid for the bytes `layout` spans until the image is unset or the
    /// filter released (temcSetSharedFilterImage's contract).
    pub unsafe fn set_image(
        &mut self,
        dev: &dyn FilterDevice,
        name: &str,
        ptr: *mut u8,
        layout: Layout,
        buffer: Option<Arc<dyn ImageBuffer>>,
    ) -> Outcome<()> {
        let Some(image) = self.image(dev, name) else {
            return Ok(());
        };
        let kind = self.filter.kind();
        if !kind.accepts(image) {
            dev.warn(&format!("{kind} ignores image {name:?}"));
            return Ok(());
        }
        let empty = layout.width == 0 || layout.height == 0;
        if empty && ptr.is_null() && buffer.is_none() {
            // OIDN's empty images: shared memory that is NULL unsets the image; one of a
            // buffer (or non-NULL memory) stays set, with nothing to read.
            return self.unset_image(dev, name);
        }
        let capacity = buffer.as_ref().map_or(usize::MAX, |b| b.size());
        // SAFETY: forwarded contract; a buffer's memory is held below while the image is set.
        unsafe {
            self.filter
                .set_shared_image_in(image, ptr, layout, capacity)
        }
        .map_err(failure)?;
        match buffer {
            Some(b) => self.buffers.insert(image, b),
            None => self.buffers.remove(&image),
        };
        Ok(())
    }

    /// Checks a buffer-backed image against the buffer's size.
    pub fn check_buffer_image(
        &self,
        name: &str,
        layout: &Layout,
        buffer: &dyn ImageBuffer,
    ) -> Outcome<()> {
        let Ok(image) = ImageName::parse(name) else {
            return Ok(()); // set_image warns
        };
        let span = self.filter.image_span(image, layout).map_err(failure)?;
        if span > buffer.size() {
            return Err(Failure::invalid(format!(
                "image {name:?}: layout spans {span} bytes, the buffer has {}",
                buffer.size()
            )));
        }
        Ok(())
    }

    /// Removes an image.
    pub fn unset_image(&mut self, dev: &dyn FilterDevice, name: &str) -> Outcome<()> {
        let Some(image) = self.image(dev, name) else {
            return Ok(());
        };
        self.filter.unset_image(image).map_err(failure)?;
        self.buffers.remove(&image);
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
        dev: &dyn FilterDevice,
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
        Ok(())
    }

    /// Re-reads opaque data the caller changed in place.
    ///
    /// # Safety
    /// As [`Self::set_data`]: the buffer given there is still readable.
    pub unsafe fn update_data(&mut self, dev: &dyn FilterDevice, name: &str) -> Outcome<()> {
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
    pub fn unset_data(&mut self, dev: &dyn FilterDevice, name: &str) -> Outcome<()> {
        if name == "weights" {
            self.filter.unset_weights();
            self.weights = None;
        } else {
            dev.warn(&format!("unknown filter data {name:?}"));
        }
        Ok(())
    }

    /// The parameter `name` names for this filter's type, or a warning.
    fn param(&self, dev: &dyn FilterDevice, name: &str) -> Option<&'static Access> {
        let kind = self.filter.kind();
        let found = PARAMS
            .iter()
            .find(|p| p.names.contains(&name) && (p.takes)(kind));
        if found.is_none() {
            dev.warn(&format!("unknown filter parameter {name:?} ignored"));
        }
        found.map(|p| &p.access)
    }

    /// Sets a bool or int parameter (OIDN treats the two alike).
    pub fn set_int(&mut self, dev: &dyn FilterDevice, name: &str, v: i32) -> Outcome<()> {
        match self.param(dev, name) {
            Some(Access::Int(_, Some(set))) => set(&mut self.filter, v).map_err(failure),
            Some(Access::Int(_, None) | Access::Float(_, None)) => {
                dev.warn(&format!("filter parameter {name:?} is read-only"));
                Ok(())
            }
            Some(Access::Float(..)) => {
                dev.warn(&format!("filter parameter {name:?} is a float"));
                Ok(())
            }
            None => Ok(()),
        }
    }

    /// Reads a bool or int parameter.
    pub fn get_int(&self, dev: &dyn FilterDevice, name: &str) -> Outcome<i32> {
        Ok(match self.param(dev, name) {
            Some(Access::Int(get, _)) => get(&self.filter),
            _ => 0,
        })
    }

    /// Sets a float parameter.
    pub fn set_float(&mut self, dev: &dyn FilterDevice, name: &str, v: f32) -> Outcome<()> {
        match self.param(dev, name) {
            Some(Access::Float(_, Some(set))) => set(&mut self.filter, v).map_err(failure),
            Some(_) => {
                dev.warn(&format!(
                    "filter parameter {name:?} is not a writable float"
                ));
                Ok(())
            }
            None => Ok(()),
        }
    }

    /// Reads a float parameter ("inputScale" is NaN while automatic).
    pub fn get_float(&self, dev: &dyn FilterDevice, name: &str) -> Outcome<f32> {
        Ok(match self.param(dev, name) {
            Some(Access::Float(get, _)) => get(&self.filter),
            _ => 0.0,
        })
    }

    /// The core filter, for the progress monitor.
    pub fn core(&mut self) -> &mut Filter<'static> {
        &mut self.filter
    }

    /// Checks the filter as OIDN does, chooses its path and loads the model.
    pub fn commit(&mut self) -> Outcome<()> {
        self.filter.commit().map_err(failure)
    }

    /// Fails as [`Self::execute`] would on an uncommitted filter (the Async calls check
    /// before they queue).
    pub fn check_committed(&self) -> Outcome<()> {
        match self.filter.execution_path() {
            Some(_) => Ok(()),
            None => Err(Failure::operation(
                "the filter is not committed (call commit after changes)",
            )),
        }
    }

    /// Runs the committed filter. On error the output is untouched.
    pub fn execute(&mut self) -> Outcome<()> {
        self.filter.execute().map(drop).map_err(failure)
    }
}
