//! Helpers shared by the integration tests: the untrained test models, a committed
//! device, C strings, and reading the golden .npy tensors.

#![allow(dead_code)]

use std::ffi::CString;
use std::path::{Path, PathBuf};
use std::process::Command;

use temc::filter::Device;

/// Builds libtemc for this test profile, with the same package selection and dev-dependency
/// feature unification as `cargo test --workspace`, so the build reuses that build's
/// libtemc instead of overwriting it with a differently-featured one (which breaks later
/// doctests of crates that link it). Returns the folder holding libtemc.so.
pub fn built_library() -> PathBuf {
    let release = !cfg!(debug_assertions);
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut cargo = Command::new(env!("CARGO"));
    cargo
        .current_dir(root)
        .args(["build", "--workspace", "--lib", "--tests", "--quiet"]);
    if release {
        cargo.arg("--release");
    }
    assert!(
        cargo.status().unwrap().success(),
        "cargo build --lib failed"
    );
    let target =
        std::env::var_os("CARGO_TARGET_DIR").map_or_else(|| root.join("target"), PathBuf::from);
    target.join(if release { "release" } else { "debug" })
}

/// The untrained test model of `arch` ("temc2", "temc1", "demc", "ae") as ONNX bytes:
/// for tests of the machinery, not of denoising quality.
pub fn test_model(arch: &str) -> Vec<u8> {
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/models");
    std::fs::read(format!("{dir}/{arch}_w0.0625.onnx")).unwrap()
}

/// A committed device with `threads` threads (0 = all cores).
pub fn device(threads: usize) -> Device {
    let d = Device::new();
    d.set_num_threads(threads);
    d.commit().unwrap();
    d
}

/// A C string for the C ABI's names.
pub fn c(s: &str) -> CString {
    CString::new(s).unwrap()
}

/// A float32 tensor read from a .npy file.
pub struct Npy {
    pub shape: Vec<usize>,
    pub data: Vec<f32>,
}

/// Reads a little-endian float32, C-order .npy file (format versions 1 to 3); panics with
/// the path on anything else, since goldens are test fixtures.
/// A device's error (temcGetDeviceError, which clears it): its code and message.
#[cfg(feature = "capi")]
pub fn device_error(dev: temc::capi::TEMCDevice) -> (temc::capi::TEMCError, String) {
    let mut msg: *const std::ffi::c_char = std::ptr::null();
    // SAFETY: `msg` is a valid out-pointer; the message stays valid until the next call.
    let code = unsafe { temc::capi::temcGetDeviceError(dev, &mut msg) };
    let text = if msg.is_null() {
        String::new()
    } else {
        // SAFETY: a non-NULL message is a NUL-terminated string the device owns.
        unsafe { std::ffi::CStr::from_ptr(msg) }
            .to_string_lossy()
            .into_owned()
    };
    (code, text)
}

pub fn read_npy(path: &Path) -> Npy {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert!(
        bytes.len() > 10 && &bytes[..6] == b"\x93NUMPY",
        "{}: not .npy",
        path.display()
    );
    let (header_len, start) = match bytes[6] {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        2 | 3 => (
            u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
            12,
        ),
        v => panic!("{}: npy version {v}", path.display()),
    };
    let header = std::str::from_utf8(&bytes[start..start + header_len]).expect("ascii header");
    assert!(
        header.contains("'descr': '<f4'"),
        "{}: {header}",
        path.display()
    );
    assert!(
        header.contains("'fortran_order': False"),
        "{}: {header}",
        path.display()
    );
    let shape_src = header
        .split("'shape': (")
        .nth(1)
        .and_then(|s| s.split(')').next())
        .expect("shape");
    let shape: Vec<usize> = shape_src
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| s.parse().expect("dim"))
        .collect();
    let body = &bytes[start + header_len..];
    let n: usize = shape.iter().product();
    assert_eq!(body.len(), n * 4, "{}: size", path.display());
    let data = body
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    Npy { shape, data }
}

/// A number of a shared vector file: JSON has no NaN or Inf, so they travel as strings.
pub fn json_f32(v: &serde_json::Value) -> f32 {
    match v {
        serde_json::Value::String(s) if s == "nan" => f32::NAN,
        serde_json::Value::String(s) if s == "inf" => f32::INFINITY,
        serde_json::Value::String(s) if s == "-inf" => f32::NEG_INFINITY,
        v => v.as_f64().expect("number") as f32,
    }
}
