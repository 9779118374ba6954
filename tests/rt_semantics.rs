//! OIDN's "RT" semantics, one test body run twice: against the Rust API
//! ([`temc::filter::Filter`] of [`Kind::Rt`]) and against the C ABI (`temcNewFilter(d,
//! "RT")`). Defaults, the albedo-only prefilter path, and OIDN's refusals at commit must
//! agree, so the two cannot drift apart.

mod common;

use common::c;
use temc::capi::*;
use temc::filter::{Device, Filter, ImageName, Kind, Quality};
use temc::image::{Format, Layout};
use temc::prefilter::{filter_aux, AuxKind};
use temc::Error;

/// Why a commit or an execution failed, as both APIs can say it.
#[derive(Debug, PartialEq)]
enum Refusal {
    /// INVALID_OPERATION, with its message.
    Operation(String),
    /// Any other error (its text shows in a failed assertion).
    Other(#[allow(dead_code)] String),
}

/// An "RT" filter driven through one of the two APIs. Images are copied into the driver,
/// which keeps them alive as long as the filter.
trait RtFilter {
    fn new_rt() -> Self;
    fn hdr(&self) -> bool;
    fn srgb(&self) -> bool;
    fn quality(&self) -> Quality;
    fn set_hdr(&mut self, on: bool);
    fn set_srgb(&mut self, on: bool);
    fn set_quality(&mut self, q: Quality);
    /// Sets packed RGB f32 image `name` (the output too) over the driver's copy of `data`.
    fn set_image(&mut self, name: ImageName, data: &[f32], w: usize, h: usize);
    fn commit(&mut self) -> Result<(), Refusal>;
    fn execute(&mut self) -> Result<(), Refusal>;
    /// The driver's output image.
    fn output(&self) -> Vec<f32>;
}

/// Images owned by a driver: boxed, so their addresses stay put.
#[derive(Default)]
struct Images(Vec<(ImageName, Box<[f32]>)>);

impl Images {
    /// Keeps a copy of `data` as `name`, returning its address.
    fn keep(&mut self, name: ImageName, data: &[f32]) -> *mut f32 {
        self.0.retain(|(n, _)| *n != name);
        self.0.push((name, data.into()));
        self.0.last_mut().unwrap().1.as_mut_ptr()
    }

    fn output(&self) -> Vec<f32> {
        let (_, v) = self
            .0
            .iter()
            .find(|(n, _)| *n == ImageName::Output)
            .unwrap();
        v.to_vec()
    }
}

struct RustRt {
    filter: Filter<'static>,
    images: Images,
}

impl RtFilter for RustRt {
    fn new_rt() -> Self {
        let device = Device::new();
        device.commit().unwrap();
        RustRt {
            filter: Filter::new(&device, Kind::Rt).unwrap(),
            images: Images::default(),
        }
    }
    fn hdr(&self) -> bool {
        self.filter.hdr()
    }
    fn srgb(&self) -> bool {
        self.filter.srgb()
    }
    fn quality(&self) -> Quality {
        self.filter.quality()
    }
    fn set_hdr(&mut self, on: bool) {
        self.filter.set_hdr(on)
    }
    fn set_srgb(&mut self, on: bool) {
        self.filter.set_srgb(on)
    }
    fn set_quality(&mut self, q: Quality) {
        self.filter.set_quality(q)
    }
    fn set_image(&mut self, name: ImageName, data: &[f32], w: usize, h: usize) {
        let ptr = self.images.keep(name, data) as *mut u8;
        let layout = Layout::packed(Format::Float3, w, h);
        // SAFETY: the boxed copy lives in `self.images` as long as the filter.
        unsafe { self.filter.set_shared_image(name, ptr, layout) }.unwrap();
    }
    fn commit(&mut self) -> Result<(), Refusal> {
        self.filter.commit().map_err(refusal)
    }
    fn execute(&mut self) -> Result<(), Refusal> {
        self.filter.execute().map(drop).map_err(refusal)
    }
    fn output(&self) -> Vec<f32> {
        self.images.output()
    }
}

fn refusal(e: Error) -> Refusal {
    match e {
        Error::InvalidOperation(m) => Refusal::Operation(m),
        e => Refusal::Other(e.to_string()),
    }
}

struct CRt {
    device: TEMCDevice,
    filter: TEMCFilter,
    images: Images,
}

impl CRt {
    fn seti(&self, name: &str, v: i32) {
        unsafe { temcSetFilterInt(self.filter, c(name).as_ptr(), v) };
        assert_eq!(self.error(), Ok(()), "{name} = {v}");
    }

    fn geti(&self, name: &str) -> i32 {
        unsafe { temcGetFilterInt(self.filter, c(name).as_ptr()) }
    }

    fn error(&self) -> Result<(), Refusal> {
        let (code, text) = common::device_error(self.device);
        match code {
            TEMC_ERROR_NONE => Ok(()),
            TEMC_ERROR_INVALID_OPERATION => Err(Refusal::Operation(text)),
            _ => Err(Refusal::Other(text)),
        }
    }
}

impl Drop for CRt {
    fn drop(&mut self) {
        temcReleaseFilter(self.filter);
        temcReleaseDevice(self.device);
    }
}

impl RtFilter for CRt {
    fn new_rt() -> Self {
        let device = temcNewDevice(TEMC_DEVICE_TYPE_CPU);
        temcCommitDevice(device);
        let filter = unsafe { temcNewFilter(device, c("RT").as_ptr()) };
        assert!(!filter.is_null());
        CRt {
            device,
            filter,
            images: Images::default(),
        }
    }
    fn hdr(&self) -> bool {
        unsafe { temcGetFilterBool(self.filter, c("hdr").as_ptr()) }
    }
    fn srgb(&self) -> bool {
        self.geti("srgb") != 0
    }
    fn quality(&self) -> Quality {
        Quality::from_raw(self.geti("quality")).unwrap()
    }
    fn set_hdr(&mut self, on: bool) {
        unsafe { temcSetFilterBool(self.filter, c("hdr").as_ptr(), on) };
    }
    fn set_srgb(&mut self, on: bool) {
        self.seti("srgb", on as i32)
    }
    fn set_quality(&mut self, q: Quality) {
        self.seti("quality", q as i32)
    }
    fn set_image(&mut self, name: ImageName, data: &[f32], w: usize, h: usize) {
        let ptr = self.images.keep(name, data);
        let n = c(name.as_str());
        unsafe {
            temcSetSharedFilterImage(
                self.filter,
                n.as_ptr(),
                ptr.cast(),
                TEMC_FORMAT_FLOAT3,
                w,
                h,
                0,
                0,
                0,
            )
        };
        assert_eq!(self.error(), Ok(()), "{name}");
    }
    fn commit(&mut self) -> Result<(), Refusal> {
        temcCommitFilter(self.filter);
        self.error()
    }
    fn execute(&mut self) -> Result<(), Refusal> {
        temcExecuteFilter(self.filter);
        self.error()
    }
    fn output(&self) -> Vec<f32> {
        self.images.output()
    }
}

/// A noisy two-colour RGB image in [0, 1].
fn image(w: usize, h: usize) -> Vec<f32> {
    (0..w * h * 3)
        .map(|i| {
            let base = if i / 3 % w < w / 2 { 0.7 } else { 0.2 };
            base + 0.1 * (((i * 2654435761) % 1000) as f32 / 1000.0 - 0.5)
        })
        .collect()
}

fn expect_refused<F: RtFilter>(f: &mut F, message: &str) {
    match f.commit() {
        Err(Refusal::Operation(m)) => assert!(m.starts_with(message), "{m:?}, not {message:?}"),
        other => panic!("{message}: commit gave {other:?}"),
    }
    assert!(
        matches!(f.execute(), Err(Refusal::Operation(_))),
        "{message}: executed"
    );
    assert!(
        f.output().iter().all(|&v| v == -7.0),
        "{message}: output written"
    );
}

/// The one body both APIs run.
fn rt_semantics<F: RtFilter>() {
    let (w, h) = (32, 24);
    let color = image(w, h);
    let sentinel = vec![-7f32; w * h * 3];

    // OIDN's defaults.
    let f = F::new_rt();
    assert!(!f.hdr(), "OIDN's hdr default is false");
    assert!(!f.srgb());
    // Not OIDN's high: temc's high is a two-pass ensemble; the default runs balanced.
    assert_eq!(f.quality(), Quality::Default);

    // Colour in, denoised colour out.
    let mut f = F::new_rt();
    f.set_quality(Quality::Fast);
    f.set_image(ImageName::Color, &color, w, h);
    f.set_image(ImageName::Output, &sentinel, w, h);
    f.commit().unwrap();
    f.execute().unwrap();
    let out = f.output();
    assert!(out.iter().all(|v| v.is_finite() && (0.0..=1.0).contains(v)));

    // Albedo alone: the prefilter path, exactly temc's aux filter.
    let mut f = F::new_rt();
    f.set_image(ImageName::Albedo, &color, w, h);
    f.set_image(ImageName::Output, &sentinel, w, h);
    f.commit().unwrap();
    f.execute().unwrap();
    assert!(f.output() == filter_aux(&color, w, h, AuxKind::Albedo));
    // ... which HDR mode refuses.
    f.set_image(ImageName::Output, &sentinel, w, h);
    f.set_hdr(true);
    expect_refused(&mut f, "hdr mode is not supported for albedo filtering");

    // hdr with srgb.
    let mut f = F::new_rt();
    f.set_image(ImageName::Color, &color, w, h);
    f.set_image(ImageName::Output, &sentinel, w, h);
    f.set_hdr(true);
    f.set_srgb(true);
    expect_refused(
        &mut f,
        "hdr and srgb modes cannot be enabled at the same time",
    );

    // An aux image of another size than the output.
    let mut f = F::new_rt();
    f.set_image(ImageName::Color, &color, w, h);
    f.set_image(ImageName::Albedo, &color[..w * (h - 1) * 3], w, h - 1);
    f.set_image(ImageName::Output, &sentinel, w, h);
    expect_refused(&mut f, "image size mismatch");

    // No output.
    let mut f = F::new_rt();
    f.set_image(ImageName::Color, &color, w, h);
    assert!(
        matches!(f.commit(), Err(Refusal::Operation(m)) if m.starts_with("output image not specified"))
    );
}

#[test]
fn rt_semantics_through_the_rust_api() {
    rt_semantics::<RustRt>();
}

#[test]
fn rt_semantics_through_the_c_abi() {
    rt_semantics::<CRt>();
}
