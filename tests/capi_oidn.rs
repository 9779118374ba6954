//! The C ABI's OIDN 2.x semantics, driven from Rust: what a renderer renamed from OIDN
//! relies on (filter types, defaults, warnings instead of errors, buffers, GPU types), the
//! soundness rules (stale handles, an error callback that queries the error), aux
//! prefiltering and spectral input.

use std::ffi::{c_char, c_void};
use std::sync::atomic::{AtomicUsize, Ordering};

mod common;

use common::c;
use temc::capi::*;
use temc::filter::{Device, Filter, Quality};

fn error(dev: TEMCDevice) -> (TEMCError, String) {
    common::device_error(dev)
}

fn device() -> TEMCDevice {
    let d = temcNewDevice(TEMC_DEVICE_TYPE_CPU);
    temcCommitDevice(d);
    assert_eq!(error(d).0, TEMC_ERROR_NONE);
    d
}

fn geti(f: TEMCFilter, name: &str) -> i32 {
    unsafe { temcGetFilterInt(f, c(name).as_ptr()) }
}

fn seti(f: TEMCFilter, name: &str, v: i32) {
    unsafe { temcSetFilterInt(f, c(name).as_ptr(), v) }
}

fn set_image(f: TEMCFilter, name: &str, p: *const f32, format: TEMCFormat, w: usize, h: usize) {
    unsafe { temcSetSharedFilterImage(f, c(name).as_ptr(), p as *mut _, format, w, h, 0, 0, 0) }
}

/// Smooth colour with a little deterministic noise.
fn image(w: usize, h: usize) -> Vec<f32> {
    (0..w * h * 3)
        .map(|i| {
            0.3 + 0.2 * ((i / 3 % w) as f32 / w as f32) + 0.05 * ((i * 7919 % 13) as f32 / 13.0)
        })
        .collect()
}

#[test]
fn rt_filters_have_oidns_defaults_and_parameter_rules() {
    let d = device();
    let f = unsafe { temcNewFilter(d, c("RT").as_ptr()) };
    assert!(!f.is_null(), "{:?}", error(d));
    assert_eq!(geti(f, "hdr"), 0, "OIDN's hdr default is false");
    // Not OIDN's high: temc's high is a two-pass ensemble, so the default runs balanced.
    assert_eq!(geti(f, "quality"), TEMC_QUALITY_DEFAULT as i32);
    assert_eq!(geti(f, "maxMemoryMB"), -1);
    // Bools through ints and back, OIDN's other names, and unknown names: no errors.
    seti(f, "hdr", 1);
    assert!(unsafe { temcGetFilterBool(f, c("hdr").as_ptr()) });
    unsafe { temcSetFilterBool(f, c("srgb").as_ptr(), true) };
    unsafe { temcSetFilterBool(f, c("cleanAux").as_ptr(), true) };
    assert_eq!(geti(f, "srgb"), 1);
    assert_eq!(geti(f, "cleanAux"), 1);
    unsafe { temcSetFilterFloat(f, c("hdrScale").as_ptr(), 2.0) };
    assert_eq!(
        unsafe { temcGetFilterFloat(f, c("inputScale").as_ptr()) },
        2.0
    );
    seti(f, "noSuchParameter", 3);
    unsafe { temcSetFilterFloat(f, c("noSuchFloat").as_ptr(), 1.0) };
    seti(f, "alignment", 3);
    seti(f, "maxMemoryMB", 512);
    assert_eq!(geti(f, "maxMemoryMB"), 512);
    seti(f, "maxMemoryMB", -1);
    assert_eq!(geti(f, "maxMemoryMB"), -1);
    assert_eq!(error(d).0, TEMC_ERROR_NONE, "OIDN only warns");
    // A real misuse is still an error.
    seti(f, "quality", 3);
    assert_eq!(error(d).0, TEMC_ERROR_INVALID_ARGUMENT);

    // alignment and overlap come from the committed model. (hdr with srgb would fail the
    // commit, as in OIDN.)
    unsafe { temcSetFilterBool(f, c("srgb").as_ptr(), false) };
    let (w, h) = (24, 16);
    let color = image(w, h);
    let mut out = vec![0f32; w * h * 3];
    set_image(f, "color", color.as_ptr(), TEMC_FORMAT_FLOAT3, w, h);
    set_image(f, "output", out.as_mut_ptr(), TEMC_FORMAT_FLOAT3, w, h);
    seti(f, "quality", TEMC_QUALITY_FAST as i32);
    temcCommitFilter(f);
    assert!(geti(f, "alignment") >= 1 && geti(f, "tileAlignment") == geti(f, "alignment"));
    assert!(geti(f, "overlap") > 0 && geti(f, "tileOverlap") == geti(f, "overlap"));
    temcExecuteFilterAsync(f);
    temcSyncDevice(d);
    assert_eq!(error(d).0, TEMC_ERROR_NONE);
    assert!(out.iter().all(|v| v.is_finite()) && out.iter().any(|&v| v > 0.0));

    // RTLightmap: colour only; "directional" refused with a clear message.
    let l = unsafe { temcNewFilter(d, c("RTLightmap").as_ptr()) };
    assert_eq!(geti(l, "hdr"), 1);
    seti(l, "directional", 0);
    assert_eq!(error(d).0, TEMC_ERROR_NONE);
    seti(l, "directional", 1);
    let (code, msg) = error(d);
    assert_eq!(code, TEMC_ERROR_INVALID_ARGUMENT);
    assert!(msg.contains("directional"), "{msg}");
    temcReleaseFilter(l);
    temcReleaseFilter(f);
    temcReleaseDevice(d);
}

#[test]
fn devices_report_oidn_2x_and_refuse_gpus_as_unsupported_hardware() {
    for t in [
        TEMC_DEVICE_TYPE_SYCL,
        TEMC_DEVICE_TYPE_CUDA,
        TEMC_DEVICE_TYPE_HIP,
        TEMC_DEVICE_TYPE_METAL,
    ] {
        assert!(temcNewDevice(t).is_null());
        assert_eq!(
            error(std::ptr::null_mut()).0,
            TEMC_ERROR_UNSUPPORTED_HARDWARE
        );
    }
    assert!(temcNewCUDADevice(std::ptr::null(), std::ptr::null(), 0).is_null());
    assert_eq!(
        error(std::ptr::null_mut()).0,
        TEMC_ERROR_UNSUPPORTED_HARDWARE
    );
    assert_eq!(temcGetNumPhysicalDevices(), 1);
    assert_eq!(
        unsafe { temcGetPhysicalDeviceInt(0, c("type").as_ptr()) },
        TEMC_DEVICE_TYPE_CPU as i32
    );
    assert!(!unsafe { temcGetPhysicalDeviceString(0, c("name").as_ptr()) }.is_null());
    let d = temcNewDeviceByID(0);
    assert!(!d.is_null());
    let get = |n: &str| unsafe { temcGetDeviceInt(d, c(n).as_ptr()) };
    assert_eq!(get("version"), TEMC_VERSION as i32);
    assert_eq!(
        TEMC_VERSION, 20300,
        "OIDN 2.3's API (Cargo.toml's oidn-api-version)"
    );
    assert_eq!(get("versionMajor"), 2);
    assert_eq!(get("type"), TEMC_DEVICE_TYPE_CPU as i32);
    unsafe { temcSetDeviceBool(d, c("setAffinity").as_ptr(), false) };
    assert!(!unsafe { temcGetDeviceBool(d, c("setAffinity").as_ptr()) });
    unsafe { temcSetDeviceInt(d, c("noSuchParameter").as_ptr(), 1) };
    assert_eq!(error(d).0, TEMC_ERROR_NONE);
    temcReleaseDevice(d);
}

static CALLS: AtomicUsize = AtomicUsize::new(0);

/// Queries the error from inside the callback, as some renderers' handlers do: it must
/// not deadlock (no lock is held while the callback runs).
unsafe extern "C" fn query_inside(user: *mut c_void, code: TEMCError, msg: *const c_char) {
    assert_ne!(code, TEMC_ERROR_NONE);
    assert!(!msg.is_null());
    let dev = user as TEMCDevice;
    let got = unsafe { temcGetDeviceError(dev, std::ptr::null_mut()) };
    assert_eq!(got, code, "the error is stored before the callback runs");
    CALLS.fetch_add(1, Ordering::SeqCst);
}

#[test]
fn an_error_callback_may_query_the_error_and_stale_handles_stay_dead() {
    let d = device();
    unsafe { temcSetDeviceErrorFunction(d, Some(query_inside), d as *mut c_void) };
    let f = unsafe { temcNewFilter(d, c("NOPE").as_ptr()) };
    assert!(f.is_null());
    assert_eq!(CALLS.load(Ordering::SeqCst), 1);
    assert_eq!(error(d).0, TEMC_ERROR_NONE, "the callback took it");

    // A released handle stays dead even when its slot is reused.
    let f1 = unsafe { temcNewFilter(d, c("RT").as_ptr()) };
    temcReleaseFilter(f1);
    let f2 = unsafe { temcNewFilter(d, c("RT").as_ptr()) };
    assert_ne!(f1, f2);
    temcCommitFilter(f1);
    assert_eq!(error(std::ptr::null_mut()).0, TEMC_ERROR_INVALID_ARGUMENT);
    // A filter handle is not a device handle.
    temcCommitDevice(f2 as TEMCDevice);
    assert_eq!(error(std::ptr::null_mut()).0, TEMC_ERROR_INVALID_ARGUMENT);
    temcReleaseFilter(f2);
    temcReleaseDevice(d);
}

#[test]
fn buffers_hold_images_and_copy_data() {
    let d = device();
    let (w, h) = (20, 12);
    let bytes = w * h * 3 * 4;
    let color = image(w, h);
    let b = temcNewBuffer(d, bytes);
    assert_eq!(temcGetBufferSize(b), bytes);
    assert_eq!(temcGetBufferStorage(b), TEMC_STORAGE_HOST);
    unsafe { temcWriteBufferAsync(b, 0, bytes, color.as_ptr() as *const c_void) };
    let mut back = vec![0f32; w * h * 3];
    unsafe { temcReadBuffer(b, 0, bytes, back.as_mut_ptr() as *mut c_void) };
    assert_eq!(back, color);
    unsafe { temcReadBuffer(b, 8, bytes, back.as_mut_ptr() as *mut c_void) };
    assert_eq!(error(d).0, TEMC_ERROR_INVALID_ARGUMENT, "read past the end");

    // Denoise in place in the buffer, against the Rust API on the same input.
    let f = unsafe { temcNewFilter(d, c("TEMC2").as_ptr()) };
    seti(f, "quality", TEMC_QUALITY_FAST as i32);
    for name in ["color", "output"] {
        unsafe { temcSetFilterImage(f, c(name).as_ptr(), b, TEMC_FORMAT_FLOAT3, w, h, 0, 0, 0) };
    }
    unsafe {
        temcSetFilterImage(
            f,
            c("albedo").as_ptr(),
            b,
            TEMC_FORMAT_FLOAT3,
            w,
            h + 1,
            0,
            0,
            0,
        )
    };
    assert_eq!(
        error(d).0,
        TEMC_ERROR_INVALID_ARGUMENT,
        "image larger than its buffer"
    );
    // The filter holds the buffer: releasing the handle keeps the memory.
    let data = temcGetBufferData(b) as *const f32;
    temcRetainBuffer(b);
    temcReleaseBuffer(b);
    temcReleaseBuffer(b);
    assert_eq!(temcGetBufferSize(b), 0);
    assert_eq!(error(std::ptr::null_mut()).0, TEMC_ERROR_INVALID_ARGUMENT);
    temcCommitFilter(f);
    temcExecuteFilter(f);
    assert_eq!(error(d).0, TEMC_ERROR_NONE);
    let from_c = unsafe { std::slice::from_raw_parts(data, w * h * 3) }.to_vec();

    let dev = Device::new();
    dev.commit().unwrap();
    let mut rf = Filter::new(&dev, "TEMC2").unwrap();
    rf.set_quality(Quality::Fast);
    rf.set_input_f32("color", &color, w, h).unwrap();
    rf.commit().unwrap();
    assert_eq!(from_c, rf.execute_to_vec().unwrap().0);
    temcReleaseFilter(f);

    // A shared buffer wraps the caller's memory.
    let mut mine = vec![1f32; 16];
    let s = unsafe { temcNewSharedBuffer(d, mine.as_mut_ptr() as *mut c_void, 64) };
    assert_eq!(temcGetBufferData(s), mine.as_mut_ptr() as *mut c_void);
    unsafe { temcWriteBuffer(s, 4, 4, [5f32].as_ptr() as *const c_void) };
    temcReleaseBuffer(s);
    assert_eq!(mine[1], 5.0);
    temcReleaseDevice(d);
}

#[test]
fn an_rt_filter_with_only_albedo_prefilters_it() {
    let (w, h) = (64, 48);
    let clean: Vec<f32> = (0..w * h)
        .flat_map(|i| {
            if i % w < w / 2 {
                [0.8, 0.2, 0.2]
            } else {
                [0.1, 0.5, 0.7]
            }
        })
        .collect();
    let noisy: Vec<f32> = clean
        .iter()
        .enumerate()
        .map(|(i, &v)| v + 0.1 * (((i * 2654435761) % 1000) as f32 / 1000.0 - 0.5))
        .collect();
    let mut out = vec![-1f32; w * h * 3];
    let d = device();
    let f = unsafe { temcNewFilter(d, c("RT").as_ptr()) };
    set_image(f, "albedo", noisy.as_ptr(), TEMC_FORMAT_FLOAT3, w, h);
    set_image(f, "output", out.as_mut_ptr(), TEMC_FORMAT_FLOAT3, w, h);
    temcCommitFilter(f);
    temcExecuteFilter(f);
    assert_eq!(error(d), (TEMC_ERROR_NONE, String::new()));
    let before = temc::prefilter::rel_mse(&noisy, &clean);
    let after = temc::prefilter::rel_mse(&out, &clean);
    eprintln!("RT albedo prefilter: RelMSE {before:.5} -> {after:.5}");
    assert!(after < before / 3.0, "{before} -> {after}");
    // With albedo and normal but no colour, it is the ordinary error.
    let normal = vec![0f32; w * h * 3];
    set_image(f, "normal", normal.as_ptr(), TEMC_FORMAT_FLOAT3, w, h);
    temcCommitFilter(f);
    temcExecuteFilter(f);
    assert_ne!(error(d).0, TEMC_ERROR_NONE);
    temcReleaseFilter(f);
    temcReleaseDevice(d);
}

#[test]
fn spectral_input_equals_its_cmf_conversion_as_colour() {
    let (w, h, n) = (16, 12, 8usize);
    let spectral: Vec<f32> = (0..w * h * n)
        .map(|i| 0.2 + 0.6 * ((i % n) as f32 / n as f32) * ((i / n % w) as f32 / w as f32))
        .collect();
    let edges: Vec<f32> = (0..=n)
        .map(|i| 400.0 + 300.0 * i as f32 / n as f32)
        .collect();
    let bands = temc::color::SpectralBands::new(&edges).unwrap();
    let rgb: Vec<f32> = spectral
        .chunks_exact(n)
        .flat_map(|s| bands.to_linear_srgb(s))
        .collect();

    let d = device();
    let f = unsafe { temcNewFilter(d, c("TEMC2").as_ptr()) };
    seti(f, "quality", TEMC_QUALITY_FAST as i32);
    let mut out = vec![0f32; w * h * 3];
    set_image(f, "spectral", spectral.as_ptr(), TEMC_FORMAT_FLOAT, w, h);
    set_image(f, "output", out.as_mut_ptr(), TEMC_FORMAT_FLOAT3, w, h);
    temcCommitFilter(f);
    let (code, msg) = error(d);
    assert_eq!(code, TEMC_ERROR_INVALID_ARGUMENT);
    assert!(msg.contains("spectralBands"), "{msg}");
    seti(f, "spectralBands", n as i32);
    unsafe { temcSetFilterFloat(f, c("spectralMin").as_ptr(), 400.0) };
    unsafe { temcSetFilterFloat(f, c("spectralMax").as_ptr(), 700.0) };
    temcCommitFilter(f);
    temcExecuteFilter(f);
    assert_eq!(error(d), (TEMC_ERROR_NONE, String::new()));

    let dev = Device::new();
    dev.commit().unwrap();
    let mut rf = Filter::new(&dev, "TEMC2").unwrap();
    rf.set_quality(Quality::Fast);
    rf.set_input_f32("color", &rgb, w, h).unwrap();
    rf.commit().unwrap();
    assert_eq!(out, rf.execute_to_vec().unwrap().0);
    temcReleaseFilter(f);
    temcReleaseDevice(d);
}

fn srgb_to_linear(v: f32) -> f32 {
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

fn linear_to_srgb(v: f32) -> f32 {
    if v <= 0.0031308 {
        v * 12.92
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// OIDN's "srgb" (LDR input): the colour is decoded to linear before denoising and the
/// output encoded again, the same as doing it around the Rust API.
#[test]
fn srgb_ldr_input_is_linearised_and_the_output_encoded() {
    let (w, h) = (20, 14);
    let color: Vec<f32> = image(w, h).iter().map(|v| v.min(1.0)).collect();
    let d = device();
    let f = unsafe { temcNewFilter(d, c("RT").as_ptr()) };
    seti(f, "quality", TEMC_QUALITY_FAST as i32);
    unsafe { temcSetFilterBool(f, c("srgb").as_ptr(), true) };
    let mut out = vec![0f32; w * h * 3];
    set_image(f, "color", color.as_ptr(), TEMC_FORMAT_FLOAT3, w, h);
    set_image(f, "output", out.as_mut_ptr(), TEMC_FORMAT_FLOAT3, w, h);
    temcCommitFilter(f);
    temcExecuteFilter(f);
    assert_eq!(error(d), (TEMC_ERROR_NONE, String::new()));
    temcReleaseFilter(f);
    temcReleaseDevice(d);

    let linear: Vec<f32> = color.iter().map(|&v| srgb_to_linear(v)).collect();
    let dev = Device::new();
    dev.commit().unwrap();
    let mut rf = Filter::new(&dev, "TEMC2").unwrap();
    rf.set_quality(Quality::Fast);
    rf.set_hdr(false);
    rf.set_input_f32("color", &linear, w, h).unwrap();
    rf.commit().unwrap();
    let expected: Vec<f32> = rf
        .execute_to_vec()
        .unwrap()
        .0
        .iter()
        .map(|&v| linear_to_srgb(v))
        .collect();
    assert_eq!(out, expected);
}

/// Many threads create, retain, release and misuse handles at once: stale handles are
/// errors every time (never a crash or another object), live ones keep working.
#[test]
fn concurrent_handle_churn_never_confuses_handles() {
    let d = device();
    let shared = unsafe { temcNewFilter(d, c("RT").as_ptr()) };
    let (dh, sh) = (d as usize, shared as usize);
    let workers: Vec<_> = (0..4)
        .map(|t| {
            std::thread::spawn(move || {
                let (d, shared) = (dh as TEMCDevice, sh as TEMCFilter);
                let mut stale = Vec::new();
                for i in 0..200 {
                    let f = unsafe { temcNewFilter(d, c("RT").as_ptr()) };
                    assert!(!f.is_null());
                    temcRetainFilter(f);
                    seti(f, "quality", TEMC_QUALITY_FAST as i32);
                    temcReleaseFilter(f);
                    assert_eq!(geti(f, "quality"), TEMC_QUALITY_FAST as i32);
                    temcReleaseFilter(f);
                    stale.push(f);
                    // The shared filter stays usable throughout.
                    assert_eq!(geti(shared, "hdr"), 0, "thread {t}, round {i}");
                    let b = temcNewBuffer(d, 64);
                    temcReleaseBuffer(b);
                    stale.push(b as TEMCFilter);
                }
                let mut refused = 0;
                for f in stale {
                    temcCommitFilter(f);
                    let mut msg = std::ptr::null();
                    if unsafe { temcGetDeviceError(std::ptr::null_mut(), &mut msg) }
                        == TEMC_ERROR_INVALID_ARGUMENT
                    {
                        refused += 1;
                    }
                }
                refused
            })
        })
        .collect();
    for w in workers {
        assert_eq!(w.join().unwrap(), 400, "every stale handle is refused");
    }
    temcReleaseFilter(shared);
    temcReleaseDevice(d);
}

/// A device's errors are kept per thread, as in OIDN: a thread sees the errors of its own
/// calls and not another's, and each thread's message pointer stays its own.
#[test]
fn device_errors_are_per_thread() {
    let d = device();
    let addr = d as usize;
    let f = unsafe { temcNewFilter(d, c("NOPE").as_ptr()) };
    assert!(f.is_null());
    let other = std::thread::spawn(move || {
        let d = addr as TEMCDevice;
        let before = error(d).0;
        unsafe { temcSetDeviceInt(d, c("numThreads").as_ptr(), -3) };
        let (code, msg) = error(d);
        (before, code, msg)
    })
    .join()
    .unwrap();
    assert_eq!(
        other.0, TEMC_ERROR_NONE,
        "the other thread does not see this one's error"
    );
    assert_ne!(other.1, TEMC_ERROR_NONE, "{}", other.2);
    let (code, msg) = error(d);
    assert_eq!(code, TEMC_ERROR_INVALID_ARGUMENT);
    assert!(msg.contains("NOPE"), "{msg}");
    assert_eq!(error(d).0, TEMC_ERROR_NONE);
    temcReleaseDevice(d);
}

/// A huge thread count (the `capi` fuzz target's out-of-memory finding of 2026-12-02 set
/// 1.66e9) is capped at the cores: the device commits and denoises, and the setting reads
/// back as given.
#[test]
fn a_huge_thread_count_is_capped_at_the_cores() {
    let d = temcNewDevice(TEMC_DEVICE_TYPE_CPU);
    unsafe { temcSetDeviceInt(d, c("numThreads").as_ptr(), i32::MAX) };
    temcCommitDevice(d);
    assert_eq!(error(d).0, TEMC_ERROR_NONE);
    let got = unsafe { temcGetDeviceInt(d, c("numThreads").as_ptr()) };
    assert_eq!(got, i32::MAX);
    let (w, h) = (16, 12);
    let color = image(w, h);
    let mut out = vec![0f32; w * h * 3];
    let f = unsafe { temcNewFilter(d, c("RT").as_ptr()) };
    set_image(f, "color", color.as_ptr(), TEMC_FORMAT_FLOAT3, w, h);
    set_image(f, "output", out.as_mut_ptr(), TEMC_FORMAT_FLOAT3, w, h);
    temcCommitFilter(f);
    temcExecuteFilter(f);
    let (code, msg) = error(d);
    assert_eq!(code, TEMC_ERROR_NONE, "{msg}");
    assert!(out.iter().all(|v| v.is_finite() && *v > 0.0));
    temcReleaseFilter(f);
    temcReleaseDevice(d);
}

/// OIDN's checks at commit (core/unet_filter.cpp): each misconfigured filter fails
/// `temcCommitFilter` with TEMC_ERROR_INVALID_OPERATION and OIDN's message, execute then
/// refuses it and writes nothing, and the fixed filter commits and runs.
#[test]
fn commit_refuses_what_oidn_refuses() {
    let (w, h) = (24, 16);
    let color = image(w, h);
    let half: Vec<u16> = color
        .iter()
        .map(|&v| half::f16::from_f32(v).to_bits())
        .collect();
    let aux = vec![0.5f32; w * h * 3];
    let d = device();
    type Setup<'a> = &'a dyn Fn(TEMCFilter, *mut f32);
    let cases: [(&str, &str, Setup); 11] = [
        ("RT", "input image not specified", &|f, out| {
            set_image(f, "output", out, TEMC_FORMAT_FLOAT3, w, h)
        }),
        ("RT", "output image not specified", &|f, _| {
            set_image(f, "color", color.as_ptr(), TEMC_FORMAT_FLOAT3, w, h)
        }),
        ("TEMC2", "output image not specified", &|f, _| {
            set_image(f, "color", color.as_ptr(), TEMC_FORMAT_FLOAT3, w, h)
        }),
        ("RT", "unsupported input image format", &|f, out| {
            set_image(f, "color", color.as_ptr(), TEMC_FORMAT_FLOAT3, w, h);
            set_image(f, "normal", aux.as_ptr(), TEMC_FORMAT_FLOAT2, w, h);
            set_image(f, "output", out, TEMC_FORMAT_FLOAT3, w, h);
        }),
        ("RT", "unsupported output image format", &|f, out| {
            set_image(f, "color", color.as_ptr(), TEMC_FORMAT_FLOAT3, w, h);
            set_image(f, "output", out, TEMC_FORMAT_HALF, w, h);
        }),
        (
            "RT",
            "input/output image channel count mismatch",
            &|f, out| {
                set_image(f, "color", color.as_ptr(), TEMC_FORMAT_FLOAT3, w, h);
                set_image(f, "output", out, TEMC_FORMAT_FLOAT4, w, h);
            },
        ),
        ("RT", "image size mismatch", &|f, out| {
            set_image(f, "color", color.as_ptr(), TEMC_FORMAT_FLOAT3, w, h);
            set_image(f, "albedo", aux.as_ptr(), TEMC_FORMAT_FLOAT3, w, h - 1);
            set_image(f, "output", out, TEMC_FORMAT_FLOAT3, w, h);
        }),
        ("TEMC2", "image size mismatch", &|f, out| {
            set_image(f, "color", color.as_ptr(), TEMC_FORMAT_FLOAT3, w, h);
            set_image(f, "depth", aux.as_ptr(), TEMC_FORMAT_FLOAT, w, h);
            set_image(f, "output", out, TEMC_FORMAT_FLOAT3, w - 2, h);
        }),
        (
            "RT",
            "hdr and srgb modes cannot be enabled at the same time",
            &|f, out| {
                set_image(f, "color", color.as_ptr(), TEMC_FORMAT_FLOAT3, w, h);
                set_image(f, "output", out, TEMC_FORMAT_FLOAT3, w, h);
                seti(f, "hdr", 1);
                seti(f, "srgb", 1);
            },
        ),
        ("RT", "invalid combination of input features", &|f, out| {
            set_image(f, "albedo", aux.as_ptr(), TEMC_FORMAT_FLOAT3, w, h);
            set_image(f, "normal", aux.as_ptr(), TEMC_FORMAT_FLOAT3, w, h);
            set_image(f, "output", out, TEMC_FORMAT_FLOAT3, w, h);
        }),
        (
            "RT",
            "hdr and srgb modes are not supported for normal filtering",
            &|f, out| {
                set_image(f, "normal", aux.as_ptr(), TEMC_FORMAT_FLOAT3, w, h);
                set_image(f, "output", out, TEMC_FORMAT_FLOAT3, w, h);
                seti(f, "srgb", 1);
            },
        ),
    ];
    for (kind, message, setup) in cases {
        let f = unsafe { temcNewFilter(d, c(kind).as_ptr()) };
        seti(f, "quality", TEMC_QUALITY_FAST as i32);
        let mut out = vec![-7f32; w * h * 4];
        setup(f, out.as_mut_ptr());
        assert_eq!(
            error(d),
            (TEMC_ERROR_NONE, String::new()),
            "{message}: set-up"
        );
        temcCommitFilter(f);
        let (code, msg) = error(d);
        assert_eq!(
            code, TEMC_ERROR_INVALID_OPERATION,
            "{kind}: {message}: {msg}"
        );
        assert!(
            msg.starts_with(message),
            "{kind}: expected {message:?}, got {msg:?}"
        );
        temcExecuteFilter(f);
        assert_eq!(
            error(d).0,
            TEMC_ERROR_INVALID_OPERATION,
            "{message}: execute"
        );
        assert!(out.iter().all(|&v| v == -7.0), "{message}: output written");
        temcReleaseFilter(f);
    }

    // Fixed: half colour with float output (equal channel counts), sizes that agree.
    let f = unsafe { temcNewFilter(d, c("RT").as_ptr()) };
    seti(f, "quality", TEMC_QUALITY_FAST as i32);
    let mut out = vec![-7f32; w * h * 3];
    let p = out.as_mut_ptr();
    set_image(
        f,
        "color",
        half.as_ptr() as *const f32,
        TEMC_FORMAT_HALF3,
        w,
        h,
    );
    set_image(f, "albedo", aux.as_ptr(), TEMC_FORMAT_FLOAT3, w + 1, h);
    set_image(f, "output", p, TEMC_FORMAT_FLOAT3, w, h);
    temcCommitFilter(f);
    assert_eq!(error(d).0, TEMC_ERROR_INVALID_OPERATION);
    set_image(f, "albedo", aux.as_ptr(), TEMC_FORMAT_FLOAT3, w, h);
    temcCommitFilter(f);
    temcExecuteFilter(f);
    assert_eq!(error(d), (TEMC_ERROR_NONE, String::new()));
    assert!(out.iter().all(|v| v.is_finite() && *v > 0.0));
    temcReleaseFilter(f);

    // "directional" (RTLightmap) cannot be set at all: temc has no directional model, so
    // OIDN's "directional with hdr/srgb" check has nothing to refuse.
    let l = unsafe { temcNewFilter(d, c("RTLightmap").as_ptr()) };
    seti(l, "directional", 1);
    assert_eq!(error(d).0, TEMC_ERROR_INVALID_ARGUMENT);
    assert_eq!(geti(l, "directional"), 0);
    temcReleaseFilter(l);
    temcReleaseDevice(d);
}

/// OIDN 2.5's semaphore calls fail as OIDN 2.5.1's CPU device makes them fail (probed
/// through pip's pyoidn): the same checks in the same order, codes and messages; the
/// device imports no semaphore types, and a file descriptor offered stays the caller's.
#[test]
fn semaphores_fail_as_on_oidns_cpu_device() {
    use std::io::Write;
    use std::os::fd::AsRawFd;

    let d = temcNewDevice(TEMC_DEVICE_TYPE_CPU);
    let get = |n: &str| unsafe { temcGetDeviceInt(d, c(n).as_ptr()) };
    assert!(
        temcNewSharedSemaphoreFromFD(d, TEMC_EXTERNAL_SEMAPHORE_TYPE_FLAG_OPAQUE_FD, 3).is_null()
    );
    assert_eq!(
        error(d),
        (
            TEMC_ERROR_INVALID_OPERATION,
            "changes to the device are not committed".into()
        )
    );
    temcCommitDevice(d);
    assert_eq!(get("externalSemaphoreTypes"), 0);
    assert_eq!(error(d).0, TEMC_ERROR_NONE);

    let mut file = std::fs::OpenOptions::new()
        .write(true)
        .open("/dev/null")
        .unwrap();
    let fd = file.as_raw_fd();
    let unsupported = "external semaphore type not supported by the device";
    for t in [
        TEMC_EXTERNAL_SEMAPHORE_TYPE_FLAG_OPAQUE_FD,
        TEMC_EXTERNAL_SEMAPHORE_TYPE_FLAG_TIMELINE_SEMAPHORE_FD,
        TEMC_EXTERNAL_SEMAPHORE_TYPE_FLAG_OPAQUE_WIN32,
    ] {
        assert!(temcNewSharedSemaphoreFromFD(d, t, fd).is_null());
        let (code, msg) = error(d);
        assert_eq!(code, TEMC_ERROR_INVALID_ARGUMENT, "type {t}");
        assert!(msg.starts_with(unsupported), "{msg}");
    }
    assert!(temcNewSharedSemaphoreFromFD(d, TEMC_EXTERNAL_SEMAPHORE_TYPE_FLAG_NONE, fd).is_null());
    assert_eq!(
        error(d),
        (
            TEMC_ERROR_INVALID_OPERATION,
            "creating a shared semaphore from a POSIX file descriptor is not supported by the device"
                .into()
        )
    );
    file.write_all(b"the descriptor is still open").unwrap();

    // Non-NULL stand-ins for a handle and a name: never dereferenced.
    let h = std::ptr::without_provenance_mut::<c_void>(0x10);
    let n = std::ptr::without_provenance::<c_void>(0x20);
    let none = TEMC_EXTERNAL_SEMAPHORE_TYPE_FLAG_NONE;
    let exactly_one = "exactly one of the external semaphore handle and name must be non-null";
    for (t, handle, name, code, message) in [
        (
            none,
            std::ptr::null_mut(),
            std::ptr::null(),
            TEMC_ERROR_INVALID_ARGUMENT,
            exactly_one,
        ),
        (none, h, n, TEMC_ERROR_INVALID_ARGUMENT, exactly_one),
        (
            none,
            h,
            std::ptr::null(),
            TEMC_ERROR_INVALID_OPERATION,
            "creating a shared semaphore from a Win32 handle is not supported by the device",
        ),
        (
            TEMC_EXTERNAL_SEMAPHORE_TYPE_FLAG_D3D12_FENCE,
            h,
            std::ptr::null(),
            TEMC_ERROR_INVALID_ARGUMENT,
            unsupported,
        ),
    ] {
        assert!(temcNewSharedSemaphoreFromWin32Handle(d, t, handle, name).is_null());
        let (got, msg) = error(d);
        assert_eq!(got, code, "{msg}");
        assert!(msg.starts_with(message), "{msg}");
    }

    let s = [std::ptr::null_mut::<TEMCSemaphoreImpl>()];
    temcSignalSemaphoresAsync(d, s.as_ptr(), std::ptr::null(), 1);
    assert_eq!(
        error(d),
        (
            TEMC_ERROR_INVALID_OPERATION,
            "signaling semaphores is not supported by the device".into()
        )
    );
    temcWaitSemaphoresAsync(d, std::ptr::null(), std::ptr::null(), std::ptr::null(), 0);
    assert_eq!(
        error(d),
        (
            TEMC_ERROR_INVALID_OPERATION,
            "waiting on semaphores is not supported by the device".into()
        )
    );
    // No semaphore handle is valid; these errors have no device.
    temcRetainSemaphore(std::ptr::null_mut());
    assert_eq!(error(std::ptr::null_mut()).0, TEMC_ERROR_INVALID_ARGUMENT);
    temcReleaseSemaphore(std::ptr::without_provenance_mut(0x30));
    assert_eq!(error(std::ptr::null_mut()).0, TEMC_ERROR_INVALID_ARGUMENT);
    temcSignalSemaphoresAsync(std::ptr::null_mut(), std::ptr::null(), std::ptr::null(), 0);
    assert_eq!(error(std::ptr::null_mut()).0, TEMC_ERROR_INVALID_ARGUMENT);
    assert_eq!(error(d).0, TEMC_ERROR_NONE);
    temcReleaseDevice(d);
}

/// OIDN wants a committed device for sync, new buffers and new filters (api.cpp's
/// checkCommitted; oidnTest's "single filter" relies on it): TEMC_ERROR_INVALID_OPERATION
/// before the commit and after a change that needs another, nothing made.
#[test]
fn buffers_and_filters_need_a_committed_device() {
    let not_committed = || {
        (
            TEMC_ERROR_INVALID_OPERATION,
            "changes to the device are not committed".to_string(),
        )
    };
    let d = temcNewDevice(TEMC_DEVICE_TYPE_CPU);
    assert!(unsafe { temcNewFilter(d, c("RT").as_ptr()) }.is_null());
    assert_eq!(error(d), not_committed());
    assert!(temcNewBuffer(d, 64).is_null());
    assert_eq!(error(d), not_committed());
    assert!(temcNewBufferWithStorage(d, 64, TEMC_STORAGE_DEVICE).is_null());
    assert_eq!(error(d), not_committed());
    let mut host = [0f32; 16];
    assert!(unsafe { temcNewSharedBuffer(d, host.as_mut_ptr().cast(), 64) }.is_null());
    assert_eq!(error(d), not_committed());
    temcSyncDevice(d);
    assert_eq!(error(d), not_committed());

    temcCommitDevice(d);
    let f = unsafe { temcNewFilter(d, c("RT").as_ptr()) };
    let b = temcNewBuffer(d, 64);
    temcSyncDevice(d);
    assert!(!f.is_null() && !b.is_null());
    assert_eq!(error(d).0, TEMC_ERROR_NONE);
    // A NULL buffer is an error of the filter's device, as OIDN reports it (oidnTest's
    // "single filter" reads it there).
    unsafe {
        temcSetFilterImage(
            f,
            c("color").as_ptr(),
            std::ptr::null_mut(),
            TEMC_FORMAT_FLOAT3,
            4,
            4,
            0,
            0,
            0,
        )
    };
    assert_eq!(
        error(d),
        (TEMC_ERROR_INVALID_ARGUMENT, "NULL buffer".to_string())
    );

    // A new thread count needs another commit, as any device change does in OIDN.
    unsafe { temcSetDeviceInt(d, c("numThreads").as_ptr(), 1) };
    assert!(unsafe { temcNewFilter(d, c("RT").as_ptr()) }.is_null());
    assert_eq!(error(d), not_committed());
    temcCommitDevice(d);
    let g = unsafe { temcNewFilter(d, c("RT").as_ptr()) };
    assert!(!g.is_null());
    assert_eq!(error(d).0, TEMC_ERROR_NONE);
    temcReleaseFilter(g);
    temcReleaseFilter(f);
    temcReleaseBuffer(b);
    temcReleaseDevice(d);
}

/// OIDN's "weights" rules (oidnTest's "user weights"): NULL with 0 bytes is empty data
/// (no user weights, no error), NULL with a size is INVALID_ARGUMENT, and bytes that are
/// not usable weights are accepted when set and refused by commit with
/// INVALID_OPERATION.
#[test]
fn weights_follow_oidns_data_rules() {
    let d = device();
    let (w, h) = (23, 19);
    let color = image(w, h);
    let mut out = vec![-7f32; w * h * 3];
    let f = unsafe { temcNewFilter(d, c("RT").as_ptr()) };
    set_image(f, "color", color.as_ptr(), TEMC_FORMAT_FLOAT3, w, h);
    set_image(f, "output", out.as_mut_ptr(), TEMC_FORMAT_FLOAT3, w, h);
    seti(f, "quality", TEMC_QUALITY_FAST as i32);
    let weights = c("weights");
    let set =
        |p: *mut c_void, n: usize| unsafe { temcSetSharedFilterData(f, weights.as_ptr(), p, n) };

    set(std::ptr::null_mut(), 0);
    assert_eq!(error(d).0, TEMC_ERROR_NONE, "empty data");
    set(std::ptr::null_mut(), 900);
    assert_eq!(
        error(d).0,
        TEMC_ERROR_INVALID_ARGUMENT,
        "NULL data of 900 bytes"
    );
    temcCommitFilter(f);
    assert_eq!(
        error(d).0,
        TEMC_ERROR_NONE,
        "no user weights: the built-in model"
    );

    let mut garbage: Vec<u8> = (0..900u32).map(|i| (i * 7919 % 251) as u8).collect();
    set(garbage.as_mut_ptr().cast(), garbage.len());
    assert_eq!(error(d).0, TEMC_ERROR_NONE, "set: not parsed yet");
    temcCommitFilter(f);
    let (code, msg) = error(d);
    assert_eq!(code, TEMC_ERROR_INVALID_OPERATION, "{msg}");
    assert!(
        msg.starts_with("invalid or corrupted weights blob"),
        "{msg}"
    );
    temcExecuteFilter(f);
    assert_eq!(
        error(d).0,
        TEMC_ERROR_INVALID_OPERATION,
        "execute after a failed commit"
    );
    assert!(
        out.iter().all(|v| *v == -7.0),
        "output written after a failed commit"
    );

    // Unset by empty data, the filter commits with its built-in model again.
    set(std::ptr::null_mut(), 0);
    temcCommitFilter(f);
    temcExecuteFilter(f);
    let (code, msg) = error(d);
    assert_eq!(code, TEMC_ERROR_NONE, "{msg}");
    assert!(out.iter().all(|v| v.is_finite() && *v > 0.0));
    temcReleaseFilter(f);
    temcReleaseDevice(d);
}

/// OIDN's empty images and zero memory budget (oidnTest's "image size", "filter update"
/// and "inplace filter"): NULL shared memory of no pixels unsets an image, a filter of
/// 0xN or Nx0 images commits and executes as a no-op, and "maxMemoryMB" 0 is accepted
/// (read back as 0) and still denoises.
#[test]
fn empty_images_and_a_zero_memory_budget_follow_oidn() {
    let d = device();
    let f = unsafe { temcNewFilter(d, c("RT").as_ptr()) };
    for (w, h) in [(0, 0), (0, 1), (1, 0)] {
        let color = temcNewBuffer(d, 0);
        let out = temcNewBuffer(d, 0);
        for (name, b) in [("color", color), ("output", out)] {
            unsafe {
                temcSetFilterImage(f, c(name).as_ptr(), b, TEMC_FORMAT_FLOAT3, w, h, 0, 0, 0)
            };
        }
        temcCommitFilter(f);
        temcExecuteFilter(f);
        let (code, msg) = error(d);
        assert_eq!(code, TEMC_ERROR_NONE, "{w}x{h}: {msg}");
        temcReleaseBuffer(color);
        temcReleaseBuffer(out);
    }

    let (w, h) = (40, 24);
    let color = image(w, h);
    let albedo = vec![0.5f32; w * h * 3];
    let mut out = vec![0f32; w * h * 3];
    set_image(f, "color", color.as_ptr(), TEMC_FORMAT_FLOAT3, w, h);
    set_image(f, "albedo", albedo.as_ptr(), TEMC_FORMAT_FLOAT3, w, h);
    set_image(f, "output", out.as_mut_ptr(), TEMC_FORMAT_FLOAT3, w, h);
    seti(f, "quality", TEMC_QUALITY_FAST as i32);
    seti(f, "maxMemoryMB", 0);
    assert_eq!(geti(f, "maxMemoryMB"), 0);
    // Unset by NULL memory of no pixels: the filter no longer needs an albedo-sized image.
    set_image(f, "albedo", std::ptr::null(), TEMC_FORMAT_FLOAT3, 0, 0);
    assert_eq!(error(d).0, TEMC_ERROR_NONE);
    set_image(f, "albedo", std::ptr::null(), TEMC_FORMAT_FLOAT3, w, h);
    assert_eq!(
        error(d).0,
        TEMC_ERROR_INVALID_ARGUMENT,
        "NULL memory of w x h pixels"
    );
    temcCommitFilter(f);
    temcExecuteFilter(f);
    let (code, msg) = error(d);
    assert_eq!(code, TEMC_ERROR_NONE, "{msg}");
    assert!(out.iter().all(|v| v.is_finite() && *v > 0.0));
    seti(f, "maxMemoryMB", 512);
    assert_eq!(geti(f, "maxMemoryMB"), 512);
    assert_eq!(geti(f, "tileSize"), 0, "the budget picks the tiles again");
    // The flip ensemble (a temc parameter): 0 (the model's own), 1, 2 or 4 passes; others
    // refused, the last kept.
    assert_eq!(geti(f, "passes"), 0);
    seti(f, "passes", 4);
    assert_eq!(error(d).0, TEMC_ERROR_NONE);
    seti(f, "passes", 3);
    assert_eq!(error(d).0, TEMC_ERROR_INVALID_ARGUMENT);
    assert_eq!(geti(f, "passes"), 4);
    let single = out.clone();
    temcCommitFilter(f);
    temcExecuteFilter(f);
    assert_eq!(error(d).0, TEMC_ERROR_NONE);
    assert!(out.iter().all(|v| v.is_finite() && *v > 0.0));
    assert_ne!(out, single, "four passes average four runs");
    temcReleaseFilter(f);
    temcReleaseDevice(d);
}

// ---------------------------------------------------------------------------------------
// The device queue: the Async calls queue their work and return; sync points wait for it
// and report its first error, as OIDN's. The tests prove order, not timing: a gate held
// by the test shows that an execution is still queued when its call has returned.

/// A progress monitor that holds every execution until the test opens it (or a minute
/// passes, so a synchronous implementation fails the test instead of hanging it).
#[derive(Default)]
struct Gate {
    open: std::sync::Mutex<bool>,
    opened: std::sync::Condvar,
    /// Progress calls that have returned.
    passed: AtomicUsize,
    /// Whether the monitor lets the execution go on (false: cancel it).
    go_on: bool,
}

impl Gate {
    fn release(&self) {
        *self.open.lock().unwrap() = true;
        self.opened.notify_all();
    }
}

unsafe extern "C" fn gated_progress(user: *mut c_void, _n: f64) -> bool {
    let gate = unsafe { &*(user as *const Gate) };
    let open = gate.open.lock().unwrap();
    let timeout = std::time::Duration::from_secs(60);
    drop(
        gate.opened
            .wait_timeout_while(open, timeout, |o| !*o)
            .unwrap(),
    );
    gate.passed.fetch_add(1, Ordering::SeqCst);
    gate.go_on
}

/// An "RT" HDR filter denoising `w` x `h` images of buffer `color` into buffer `output`.
fn buffer_filter(
    d: TEMCDevice,
    color: TEMCBuffer,
    output: TEMCBuffer,
    w: usize,
    h: usize,
) -> TEMCFilter {
    let f = unsafe { temcNewFilter(d, c("RT").as_ptr()) };
    for (name, b) in [("color", color), ("output", output)] {
        unsafe { temcSetFilterImage(f, c(name).as_ptr(), b, TEMC_FORMAT_FLOAT3, w, h, 0, 0, 0) };
    }
    seti(f, "hdr", 1);
    seti(f, "quality", TEMC_QUALITY_FAST as i32);
    temcCommitFilter(f);
    f
}

#[test]
fn async_calls_queue_their_work_in_order() {
    let d = device();
    let (w, h) = (40, 24);
    let bytes = w * h * 3 * 4;
    let color = image(w, h);
    let (cb, ob) = (temcNewBuffer(d, bytes), temcNewBuffer(d, bytes));
    let f = buffer_filter(d, cb, ob, w, h);
    let gate = Gate {
        go_on: true,
        ..Gate::default()
    };
    let user = &gate as *const Gate as *mut c_void;
    unsafe { temcSetFilterProgressMonitorFunction(f, Some(gated_progress), user) };
    assert_eq!(error(d).0, TEMC_ERROR_NONE);

    // Write the input, denoise it, read the output back: queued, in this order. The
    // buffers are still zero when the calls return (the copy waits behind nothing, but
    // the execution waits at the gate, and the read behind it).
    let mut out = vec![-1f32; w * h * 3];
    unsafe {
        temcWriteBufferAsync(cb, 0, bytes, color.as_ptr() as *const c_void);
        temcExecuteFilterAsync(f);
        temcReadBufferAsync(ob, 0, bytes, out.as_mut_ptr() as *mut c_void);
    }
    let passed_on_return = gate.passed.load(Ordering::SeqCst);
    gate.release();
    temcSyncDevice(d);
    assert_eq!(error(d).0, TEMC_ERROR_NONE);
    assert_eq!(
        passed_on_return, 0,
        "temcExecuteFilterAsync returned only after its execution had got past the gate"
    );
    assert!(gate.passed.load(Ordering::SeqCst) > 0);

    // The same denoise, blocking, from a copy of the input: the queued one equals it.
    let (cb2, ob2) = (temcNewBuffer(d, bytes), temcNewBuffer(d, bytes));
    unsafe { temcWriteBuffer(cb2, 0, bytes, color.as_ptr() as *const c_void) };
    let g = buffer_filter(d, cb2, ob2, w, h);
    temcExecuteFilter(g);
    assert_eq!(error(d).0, TEMC_ERROR_NONE);
    let mut expected = vec![0f32; w * h * 3];
    unsafe { temcReadBuffer(ob2, 0, bytes, expected.as_mut_ptr() as *mut c_void) };
    assert!(expected.iter().any(|&v| v > 0.0));
    assert_eq!(
        out, expected,
        "write, execute and read ran in their queued order"
    );
    for b in [cb, ob, cb2, ob2] {
        temcReleaseBuffer(b);
    }
    temcReleaseFilter(f);
    temcReleaseFilter(g);
    temcReleaseDevice(d);
}

static ASYNC_ERRORS: std::sync::Mutex<Vec<TEMCError>> = std::sync::Mutex::new(Vec::new());

unsafe extern "C" fn collect_error(_user: *mut c_void, code: TEMCError, _message: *const c_char) {
    ASYNC_ERRORS.lock().unwrap().push(code);
}

#[test]
fn errors_of_queued_work_are_reported_at_the_next_sync_point() {
    let d = device();
    unsafe { temcSetDeviceErrorFunction(d, Some(collect_error), std::ptr::null_mut()) };
    let (w, h) = (32, 16);
    let color = image(w, h);
    let mut out = vec![-1f32; w * h * 3];
    let f = unsafe { temcNewFilter(d, c("TEMC2").as_ptr()) };
    set_image(f, "color", color.as_ptr(), TEMC_FORMAT_FLOAT3, w, h);
    set_image(f, "output", out.as_mut_ptr(), TEMC_FORMAT_FLOAT3, w, h);
    seti(f, "quality", TEMC_QUALITY_FAST as i32);
    temcCommitFilter(f);
    // The monitor cancels; the gate keeps the execution queued until the test has looked.
    let gate = Gate::default();
    let user = &gate as *const Gate as *mut c_void;
    unsafe { temcSetFilterProgressMonitorFunction(f, Some(gated_progress), user) };

    temcExecuteFilterAsync(f);
    assert_eq!(error(d).0, TEMC_ERROR_NONE, "queuing it succeeded");
    assert!(ASYNC_ERRORS.lock().unwrap().is_empty());
    gate.release();
    temcSyncDevice(d);
    let (code, message) = error(d);
    assert_eq!(code, TEMC_ERROR_CANCELLED, "{message}");
    assert_eq!(*ASYNC_ERRORS.lock().unwrap(), [TEMC_ERROR_CANCELLED]);
    assert!(
        out.iter().all(|&v| v == -1.0),
        "a cancelled execution writes nothing"
    );
    temcSyncDevice(d);
    assert_eq!(error(d).0, TEMC_ERROR_NONE, "the sync took the error");

    // A blocking execute reports the queued work's error (here, after running itself).
    temcExecuteFilterAsync(f);
    unsafe { temcSetFilterProgressMonitorFunction(f, None, std::ptr::null_mut()) };
    temcExecuteFilter(f);
    assert_eq!(error(d).0, TEMC_ERROR_CANCELLED);
    assert!(
        out.iter().all(|v| v.is_finite() && *v >= 0.0),
        "the blocking one ran"
    );
    temcReleaseFilter(f);
    temcReleaseDevice(d);
}

#[test]
fn releasing_objects_with_queued_work_is_safe() {
    let d = device();
    let (w, h) = (40, 24);
    let bytes = w * h * 3 * 4;
    let color = image(w, h);
    let mut out = vec![-1f32; w * h * 3];
    let cb = temcNewBuffer(d, bytes);
    let f = unsafe { temcNewFilter(d, c("RT").as_ptr()) };
    unsafe {
        temcSetFilterImage(
            f,
            c("color").as_ptr(),
            cb,
            TEMC_FORMAT_FLOAT3,
            w,
            h,
            0,
            0,
            0,
        )
    };
    set_image(f, "output", out.as_mut_ptr(), TEMC_FORMAT_FLOAT3, w, h);
    seti(f, "hdr", 1);
    temcCommitFilter(f);
    let gate = Gate {
        go_on: true,
        ..Gate::default()
    };
    let user = &gate as *const Gate as *mut c_void;
    unsafe { temcSetFilterProgressMonitorFunction(f, Some(gated_progress), user) };

    // Queued: the input's copy and two executions. Every handle is released while they
    // wait at the gate, on another thread, since each last release waits for the queue, as
    // OIDN's: the queued work holds what it uses.
    unsafe { temcWriteBufferAsync(cb, 0, bytes, color.as_ptr() as *const c_void) };
    temcExecuteFilterAsync(f);
    temcExecuteFilterAsync(f);
    let (bh, fh, dh) = (cb as usize, f as usize, d as usize);
    let releaser = std::thread::spawn(move || {
        temcReleaseBuffer(bh as TEMCBuffer);
        temcReleaseDevice(dh as TEMCDevice);
        temcReleaseFilter(fh as TEMCFilter);
    });
    assert_eq!(gate.passed.load(Ordering::SeqCst), 0);
    gate.release();
    releaser.join().unwrap();
    assert!(
        gate.passed.load(Ordering::SeqCst) >= 2,
        "both executions ran"
    );
    assert!(out.iter().all(|v| v.is_finite() && *v >= 0.0));
    assert!(
        out.iter().any(|&v| v > 0.0),
        "the queued copy ran before them"
    );
    temcRetainFilter(f);
    assert_eq!(
        error(std::ptr::null_mut()).0,
        TEMC_ERROR_INVALID_ARGUMENT,
        "released"
    );
}
