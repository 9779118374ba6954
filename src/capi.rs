//! The C ABI, mirroring Intel Open Image Denoise 2.x with the prefix `temc`/`TEMC_`.
//!
//! A thin shim over [`crate::filter`]: every entry point runs inside `catch_unwind`, turns
//! each failure into an error code with a message stored on the device (OIDN's
//! `oidnGetDeviceError` model: the first error is kept until queried), and never lets a
//! panic cross into C. Handles are checked against a registry of live objects, so NULL,
//! foreign and released handles are reported as errors instead of being dereferenced.
//! `include/temc.h` is generated from this file by cbindgen (`tests/c_header.rs`).

// Handles are dereferenced only after the registry has confirmed they are live, which is
// why the entry points taking them are safe functions for C.
#![allow(
    non_camel_case_types,
    clippy::missing_safety_doc,
    clippy::not_unsafe_ptr_arg_deref
)]

use std::collections::HashSet;
use std::ffi::{c_char, c_void, CStr, CString};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Mutex, OnceLock};

use crate::filter::{Device, Filter};
use crate::image::{Format, Layout};
use crate::Error;

/// Error codes (OIDN's values).
pub type TEMCError = u32;
/// No error.
pub const TEMC_ERROR_NONE: TEMCError = 0;
/// An unknown error (e.g. an internal failure).
pub const TEMC_ERROR_UNKNOWN: TEMCError = 1;
/// A parameter is invalid (NULL handle or pointer, unknown name, bad size or stride, ...).
pub const TEMC_ERROR_INVALID_ARGUMENT: TEMCError = 2;
/// The call is not allowed in the current state (e.g. execute before commit).
pub const TEMC_ERROR_INVALID_OPERATION: TEMCError = 3;
/// Not enough memory.
pub const TEMC_ERROR_OUT_OF_MEMORY: TEMCError = 4;
/// The hardware is not supported.
pub const TEMC_ERROR_UNSUPPORTED_HARDWARE: TEMCError = 5;
/// The progress monitor cancelled the operation.
pub const TEMC_ERROR_CANCELLED: TEMCError = 6;

/// Device types.
pub type TEMCDeviceType = u32;
/// The default device (the CPU).
pub const TEMC_DEVICE_TYPE_DEFAULT: TEMCDeviceType = 0;
/// The CPU.
pub const TEMC_DEVICE_TYPE_CPU: TEMCDeviceType = 1;

/// Pixel formats.
pub type TEMCFormat = u32;
/// No format.
pub const TEMC_FORMAT_UNDEFINED: TEMCFormat = 0;
/// One 32-bit float channel.
pub const TEMC_FORMAT_FLOAT: TEMCFormat = 1;
/// Two 32-bit float channels.
pub const TEMC_FORMAT_FLOAT2: TEMCFormat = 2;
/// Three 32-bit float channels.
pub const TEMC_FORMAT_FLOAT3: TEMCFormat = 3;
/// Four 32-bit float channels (the fourth is ignored).
pub const TEMC_FORMAT_FLOAT4: TEMCFormat = 4;
/// One 16-bit float channel.
pub const TEMC_FORMAT_HALF: TEMCFormat = 257;
/// Two 16-bit float channels.
pub const TEMC_FORMAT_HALF2: TEMCFormat = 258;
/// Three 16-bit float channels.
pub const TEMC_FORMAT_HALF3: TEMCFormat = 259;
/// Four 16-bit float channels (the fourth is ignored).
pub const TEMC_FORMAT_HALF4: TEMCFormat = 260;

/// Quality modes for the filter's "quality" parameter.
pub type TEMCQuality = u32;
/// The library's default (balanced).
pub const TEMC_QUALITY_DEFAULT: TEMCQuality = 0;
/// Fastest.
pub const TEMC_QUALITY_FAST: TEMCQuality = 4;
/// Balanced.
pub const TEMC_QUALITY_BALANCED: TEMCQuality = 5;
/// Highest quality.
pub const TEMC_QUALITY_HIGH: TEMCQuality = 6;

/// Called with each error as it happens: user pointer, code, message.
pub type TEMCErrorFunction =
    Option<unsafe extern "C" fn(user_ptr: *mut c_void, code: TEMCError, message: *const c_char)>;

/// Called with the progress in [0, 1]; return false to cancel.
pub type TEMCProgressMonitorFunction =
    Option<unsafe extern "C" fn(user_ptr: *mut c_void, n: f64) -> bool>;

struct ErrorState {
    first: Option<(TEMCError, CString)>,
    /// The message last handed out by temcGetDeviceError; valid until the next query.
    returned: CString,
    callback: TEMCErrorFunction,
    user_ptr: usize,
}

/// Opaque device handle.
pub struct TEMCDeviceImpl {
    refs: AtomicUsize,
    device: Device,
    errors: Mutex<ErrorState>,
}

/// Opaque filter handle.
pub struct TEMCFilterImpl {
    refs: AtomicUsize,
    device: *mut TEMCDeviceImpl,
    filter: Mutex<Filter<'static>>,
}

/// A device handle.
pub type TEMCDevice = *mut TEMCDeviceImpl;
/// A filter handle.
pub type TEMCFilter = *mut TEMCFilterImpl;

fn live() -> &'static Mutex<HashSet<usize>> {
    static LIVE: OnceLock<Mutex<HashSet<usize>>> = OnceLock::new();
    LIVE.get_or_init(|| Mutex::new(HashSet::new()))
}

fn is_live(p: usize) -> bool {
    live()
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .contains(&p)
}

thread_local! {
    /// Errors with no device to hold them (device creation, NULL device).
    static GLOBAL_ERROR: std::cell::RefCell<(Option<(TEMCError, CString)>, CString)> =
        std::cell::RefCell::new((None, CString::default()));
}

fn code(e: &Error) -> TEMCError {
    match e {
        Error::InvalidArgument(_) | Error::Model(_) | Error::Io { .. } => {
            TEMC_ERROR_INVALID_ARGUMENT
        }
        Error::InvalidOperation(_) => TEMC_ERROR_INVALID_OPERATION,
        Error::Cancelled => TEMC_ERROR_CANCELLED,
        Error::OutOfMemory(_) => TEMC_ERROR_OUT_OF_MEMORY,
        Error::Inference(_) => TEMC_ERROR_UNKNOWN,
    }
}

fn cstring(s: String) -> CString {
    CString::new(s.replace('\0', " ")).unwrap_or_default()
}

fn record(device: Option<&TEMCDeviceImpl>, code: TEMCError, msg: String) {
    let msg = cstring(msg);
    match device {
        Some(d) => {
            let mut st = d.errors.lock().unwrap_or_else(|e| e.into_inner());
            if let Some(cb) = st.callback {
                // SAFETY: the caller registered this function for exactly these arguments.
                unsafe { cb(st.user_ptr as *mut c_void, code, msg.as_ptr()) };
            }
            if st.first.is_none() {
                st.first = Some((code, msg));
            }
        }
        None => GLOBAL_ERROR.with(|g| {
            let mut g = g.borrow_mut();
            if g.0.is_none() {
                g.0 = Some((code, msg));
            }
        }),
    }
}

/// Runs `f` with the live device behind `d`, recording its error (or a panic) on it.
fn with_device<T>(
    d: TEMCDevice,
    fallback: T,
    f: impl FnOnce(&TEMCDeviceImpl) -> Result<T, Error>,
) -> T {
    if d.is_null() || !is_live(d as usize) {
        let what = if d.is_null() {
            "NULL device"
        } else {
            "invalid or released device handle"
        };
        record(None, TEMC_ERROR_INVALID_ARGUMENT, what.into());
        return fallback;
    }
    // SAFETY: registered handles point to live TEMCDeviceImpl values.
    let dev = unsafe { &*d };
    match catch_unwind(AssertUnwindSafe(|| f(dev))) {
        Ok(Ok(v)) => v,
        Ok(Err(e)) => {
            record(Some(dev), code(&e), e.to_string());
            fallback
        }
        Err(_) => {
            record(
                Some(dev),
                TEMC_ERROR_UNKNOWN,
                "internal error (panic)".into(),
            );
            fallback
        }
    }
}

/// Runs `f` with the live filter behind `f_`, recording errors on its device.
fn with_filter<T>(
    fh: TEMCFilter,
    fallback: T,
    f: impl FnOnce(&mut Filter<'static>) -> Result<T, Error>,
) -> T {
    if fh.is_null() || !is_live(fh as usize) {
        let what = if fh.is_null() {
            "NULL filter"
        } else {
            "invalid or released filter handle"
        };
        record(None, TEMC_ERROR_INVALID_ARGUMENT, what.into());
        return fallback;
    }
    // SAFETY: registered handles point to live TEMCFilterImpl values, which keep their
    // device retained.
    let filt = unsafe { &*fh };
    let dev = unsafe { &*filt.device };
    let result = catch_unwind(AssertUnwindSafe(|| {
        let mut guard = filt.filter.lock().unwrap_or_else(|e| e.into_inner());
        f(&mut guard)
    }));
    match result {
        Ok(Ok(v)) => v,
        Ok(Err(e)) => {
            record(Some(dev), code(&e), e.to_string());
            fallback
        }
        Err(_) => {
            record(
                Some(dev),
                TEMC_ERROR_UNKNOWN,
                "internal error (panic)".into(),
            );
            fallback
        }
    }
}

fn name_arg<'a>(name: *const c_char) -> Result<&'a str, Error> {
    if name.is_null() {
        return Err(Error::InvalidArgument("NULL name".into()));
    }
    // SAFETY: the caller passes a NUL-terminated string.
    unsafe { CStr::from_ptr(name) }
        .to_str()
        .map_err(|_| Error::InvalidArgument("name is not UTF-8".into()))
}

/// Creates a device of the given type (TEMC_DEVICE_TYPE_DEFAULT or TEMC_DEVICE_TYPE_CPU).
/// Returns NULL on failure; temcGetDeviceError(NULL, ...) then says why.
#[no_mangle]
pub extern "C" fn temcNewDevice(device_type: TEMCDeviceType) -> TEMCDevice {
    let r = catch_unwind(|| {
        if device_type != TEMC_DEVICE_TYPE_DEFAULT && device_type != TEMC_DEVICE_TYPE_CPU {
            record(
                None,
                TEMC_ERROR_INVALID_ARGUMENT,
                format!("unsupported device type {device_type}"),
            );
            return std::ptr::null_mut();
        }
        let d = Box::into_raw(Box::new(TEMCDeviceImpl {
            refs: AtomicUsize::new(1),
            device: Device::new(),
            errors: Mutex::new(ErrorState {
                first: None,
                returned: CString::default(),
                callback: None,
                user_ptr: 0,
            }),
        }));
        live()
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .insert(d as usize);
        d
    });
    r.unwrap_or_else(|_| {
        record(
            None,
            TEMC_ERROR_UNKNOWN,
            "internal error (panic) creating a device".into(),
        );
        std::ptr::null_mut()
    })
}

/// Commits the device's parameters (builds its thread pool). Required before filters run.
#[no_mangle]
pub extern "C" fn temcCommitDevice(device: TEMCDevice) {
    with_device(device, (), |d| d.device.commit())
}

/// Sets a device parameter: "numThreads" (0 = all cores), "verbose".
#[no_mangle]
pub extern "C" fn temcSetDeviceInt(device: TEMCDevice, name: *const c_char, value: i32) {
    with_device(device, (), |d| match name_arg(name)? {
        "numThreads" if value >= 0 => {
            d.device.set_num_threads(value as usize);
            Ok(())
        }
        "numThreads" => Err(Error::InvalidArgument(format!(
            "numThreads must be >= 0, got {value}"
        ))),
        "verbose" => {
            d.device.set_verbose(value);
            Ok(())
        }
        other => Err(Error::InvalidArgument(format!(
            "unknown device parameter {other:?}"
        ))),
    })
}

/// Reads a device parameter: "numThreads", "verbose", "version" (major*10000+minor*100+patch).
#[no_mangle]
pub extern "C" fn temcGetDeviceInt(device: TEMCDevice, name: *const c_char) -> i32 {
    with_device(device, 0, |d| match name_arg(name)? {
        "numThreads" => Ok(d.device.num_threads() as i32),
        "verbose" => Ok(d.device.verbose()),
        "version" => {
            let v: Vec<i32> = env!("CARGO_PKG_VERSION")
                .split('.')
                .map(|p| p.parse().unwrap_or(0))
                .collect();
            Ok(v[0] * 10000 + v[1] * 100 + v[2])
        }
        other => Err(Error::InvalidArgument(format!(
            "unknown device parameter {other:?}"
        ))),
    })
}

/// Registers a function called with every error of this device (NULL removes it).
#[no_mangle]
pub extern "C" fn temcSetDeviceErrorFunction(
    device: TEMCDevice,
    func: TEMCErrorFunction,
    user_ptr: *mut c_void,
) {
    with_device(device, (), |d| {
        let mut st = d.errors.lock().unwrap_or_else(|e| e.into_inner());
        st.callback = func;
        st.user_ptr = user_ptr as usize;
        Ok(())
    })
}

/// Returns the first error not yet queried and clears it; `out_message` (may be NULL)
/// receives its text, valid until the next call. A NULL device returns errors that had no
/// device (device creation, NULL or released handles) on this thread.
#[no_mangle]
pub unsafe extern "C" fn temcGetDeviceError(
    device: TEMCDevice,
    out_message: *mut *const c_char,
) -> TEMCError {
    let take = |slot: &mut Option<(TEMCError, CString)>, returned: &mut CString| -> TEMCError {
        let (c, m) = slot.take().unwrap_or((TEMC_ERROR_NONE, CString::default()));
        *returned = m;
        if !out_message.is_null() {
            // SAFETY: the caller passes a writable pointer or NULL.
            unsafe {
                *out_message = if c == TEMC_ERROR_NONE {
                    std::ptr::null()
                } else {
                    returned.as_ptr()
                }
            };
        }
        c
    };
    catch_unwind(AssertUnwindSafe(|| {
        if device.is_null() || !is_live(device as usize) {
            if !device.is_null() {
                record(
                    None,
                    TEMC_ERROR_INVALID_ARGUMENT,
                    "invalid or released device handle".into(),
                );
            }
            return GLOBAL_ERROR.with(|g| {
                let mut g = g.borrow_mut();
                let (slot, returned) = &mut *g;
                take(slot, returned)
            });
        }
        // SAFETY: registered handle.
        let d = unsafe { &*device };
        let mut st = d.errors.lock().unwrap_or_else(|e| e.into_inner());
        let st = &mut *st;
        take(&mut st.first, &mut st.returned)
    }))
    .unwrap_or(TEMC_ERROR_UNKNOWN)
}

/// Adds a reference to the device.
#[no_mangle]
pub extern "C" fn temcRetainDevice(device: TEMCDevice) {
    let reg = live().lock().unwrap_or_else(|e| e.into_inner());
    if device.is_null() || !reg.contains(&(device as usize)) {
        drop(reg);
        record(
            None,
            TEMC_ERROR_INVALID_ARGUMENT,
            "invalid or released device handle".into(),
        );
        return;
    }
    // SAFETY: registered handle.
    unsafe { &*device }.refs.fetch_add(1, Ordering::SeqCst);
}

/// Drops a reference; the device is freed with its last reference (filters hold one).
#[no_mangle]
pub extern "C" fn temcReleaseDevice(device: TEMCDevice) {
    with_device(device, (), |d| {
        release_device(d as *const _ as *mut TEMCDeviceImpl);
        Ok(())
    })
}

fn release_device(d: *mut TEMCDeviceImpl) {
    let mut reg = live().lock().unwrap_or_else(|e| e.into_inner());
    // SAFETY: `d` is registered (checked under the same lock by callers' paths).
    if reg.contains(&(d as usize)) && unsafe { &*d }.refs.fetch_sub(1, Ordering::SeqCst) == 1 {
        reg.remove(&(d as usize));
        drop(reg);
        // SAFETY: last reference; created by Box::into_raw in temcNewDevice.
        drop(unsafe { Box::from_raw(d) });
    }
}

/// Creates a filter: "TEMC2" (the default choice), "TEMC1", "DEMC" or "AE".
#[no_mangle]
pub extern "C" fn temcNewFilter(device: TEMCDevice, filter_type: *const c_char) -> TEMCFilter {
    with_device(device, std::ptr::null_mut(), |d| {
        let kind = name_arg(filter_type)?;
        let filter = Filter::new(&d.device, kind)?;
        d.refs.fetch_add(1, Ordering::SeqCst);
        let f = Box::into_raw(Box::new(TEMCFilterImpl {
            refs: AtomicUsize::new(1),
            device: d as *const _ as *mut TEMCDeviceImpl,
            filter: Mutex::new(filter),
        }));
        live()
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .insert(f as usize);
        Ok(f)
    })
}

/// Sets an image shared with the caller ("color", "albedo", "normal", "depth", "output").
/// Strides of 0 mean tightly packed. The buffer must stay valid until the image is unset or
/// the filter released; "output" may be the same buffer as "color" (in-place).
#[no_mangle]
#[allow(clippy::too_many_arguments)]
pub extern "C" fn temcSetSharedFilterImage(
    filter: TEMCFilter,
    name: *const c_char,
    dev_ptr: *mut c_void,
    format: TEMCFormat,
    width: usize,
    height: usize,
    byte_offset: usize,
    pixel_byte_stride: usize,
    row_byte_stride: usize,
) {
    with_filter(filter, (), |f| {
        let name = name_arg(name)?;
        let format = Format::from_raw(format)
            .ok_or_else(|| Error::InvalidArgument(format!("unknown format {format}")))?;
        let layout = Layout {
            format,
            width,
            height,
            byte_offset,
            pixel_stride: pixel_byte_stride,
            row_stride: row_byte_stride,
        };
        // SAFETY: the C caller promises the buffer lives as documented above.
        unsafe { f.set_shared_image(name, dev_ptr as *mut u8, layout) }
    })
}

/// Removes an image from the filter.
#[no_mangle]
pub extern "C" fn temcUnsetFilterImage(filter: TEMCFilter, name: *const c_char) {
    with_filter(filter, (), |f| f.unset_image(name_arg(name)?))
}

/// Sets opaque data: "weights" = a temc ONNX model (copied; the buffer may be freed after).
#[no_mangle]
pub extern "C" fn temcSetSharedFilterData(
    filter: TEMCFilter,
    name: *const c_char,
    host_ptr: *mut c_void,
    byte_size: usize,
) {
    with_filter(filter, (), |f| match name_arg(name)? {
        "weights" => {
            if host_ptr.is_null() || byte_size == 0 {
                return Err(Error::InvalidArgument(
                    "weights: NULL or empty buffer".into(),
                ));
            }
            // SAFETY: the caller passes `byte_size` readable bytes.
            f.set_weights(unsafe { std::slice::from_raw_parts(host_ptr as *const u8, byte_size) });
            Ok(())
        }
        other => Err(Error::InvalidArgument(format!("unknown data {other:?}"))),
    })
}

/// Removes opaque data ("weights").
#[no_mangle]
pub extern "C" fn temcUnsetFilterData(filter: TEMCFilter, name: *const c_char) {
    with_filter(filter, (), |f| match name_arg(name)? {
        "weights" => {
            f.unset_weights();
            Ok(())
        }
        other => Err(Error::InvalidArgument(format!("unknown data {other:?}"))),
    })
}

/// Sets a boolean parameter: "hdr".
#[no_mangle]
pub extern "C" fn temcSetFilterBool(filter: TEMCFilter, name: *const c_char, value: bool) {
    with_filter(filter, (), |f| f.set_bool(name_arg(name)?, value))
}

/// Reads a boolean parameter: "hdr".
#[no_mangle]
pub extern "C" fn temcGetFilterBool(filter: TEMCFilter, name: *const c_char) -> bool {
    with_filter(filter, false, |f| match name_arg(name)? {
        "hdr" => Ok(f.get_int("hdr")? != 0),
        other => Err(Error::InvalidArgument(format!(
            "unknown bool parameter {other:?}"
        ))),
    })
}

/// Sets an integer parameter: "quality" (TEMC_QUALITY_*), "maxMemoryMB".
#[no_mangle]
pub extern "C" fn temcSetFilterInt(filter: TEMCFilter, name: *const c_char, value: i32) {
    with_filter(filter, (), |f| f.set_int(name_arg(name)?, value))
}

/// Reads an integer parameter: "quality", "maxMemoryMB".
#[no_mangle]
pub extern "C" fn temcGetFilterInt(filter: TEMCFilter, name: *const c_char) -> i32 {
    with_filter(filter, 0, |f| f.get_int(name_arg(name)?))
}

/// Sets a float parameter: "inputScale" (NaN = automatic exposure).
#[no_mangle]
pub extern "C" fn temcSetFilterFloat(filter: TEMCFilter, name: *const c_char, value: f32) {
    with_filter(filter, (), |f| f.set_float(name_arg(name)?, value))
}

/// Reads a float parameter: "inputScale" (NaN while automatic).
#[no_mangle]
pub extern "C" fn temcGetFilterFloat(filter: TEMCFilter, name: *const c_char) -> f32 {
    with_filter(filter, f32::NAN, |f| f.get_float(name_arg(name)?))
}

struct SendPtr(*mut c_void);
// SAFETY: the C caller owns the user pointer and promises it may be used from the threads
// temc runs on, as OIDN requires of its progress monitors.
unsafe impl Send for SendPtr {}

/// Sets the progress monitor (NULL removes it); returning false from it cancels execution
/// with TEMC_ERROR_CANCELLED and leaves the output untouched.
#[no_mangle]
pub extern "C" fn temcSetFilterProgressMonitorFunction(
    filter: TEMCFilter,
    func: TEMCProgressMonitorFunction,
    user_ptr: *mut c_void,
) {
    with_filter(filter, (), |f| {
        match func {
            None => f.unset_progress_monitor(),
            Some(cb) => {
                let user = SendPtr(user_ptr);
                f.set_progress_monitor(move |n| {
                    let u = &user;
                    // SAFETY: the caller registered this callback for these arguments.
                    unsafe { cb(u.0, n) }
                });
            }
        }
        Ok(())
    })
}

/// Commits the filter's parameters (loads the model). Required after changes.
#[no_mangle]
pub extern "C" fn temcCommitFilter(filter: TEMCFilter) {
    with_filter(filter, (), |f| f.commit())
}

/// Runs the filter synchronously. On error nothing is written to the output.
#[no_mangle]
pub extern "C" fn temcExecuteFilter(filter: TEMCFilter) {
    with_filter(filter, (), |f| f.execute().map(|_| ()))
}

/// Adds a reference to the filter.
#[no_mangle]
pub extern "C" fn temcRetainFilter(filter: TEMCFilter) {
    // Under the registry lock, so a concurrent release cannot free the handle in between;
    // the filter's own lock is not taken, so retaining never waits for an execution.
    let reg = live().lock().unwrap_or_else(|e| e.into_inner());
    if filter.is_null() || !reg.contains(&(filter as usize)) {
        drop(reg);
        record(
            None,
            TEMC_ERROR_INVALID_ARGUMENT,
            "invalid or released filter handle".into(),
        );
        return;
    }
    // SAFETY: registered handle.
    unsafe { &*filter }.refs.fetch_add(1, Ordering::SeqCst);
}

/// Drops a reference; the filter (and its hold on the device) goes with the last one.
#[no_mangle]
pub extern "C" fn temcReleaseFilter(filter: TEMCFilter) {
    if filter.is_null() || !is_live(filter as usize) {
        record(
            None,
            TEMC_ERROR_INVALID_ARGUMENT,
            "invalid or released filter handle".into(),
        );
        return;
    }
    let _ = catch_unwind(|| {
        let mut reg = live().lock().unwrap_or_else(|e| e.into_inner());
        // SAFETY: registered handle, checked under the registry lock.
        if reg.contains(&(filter as usize))
            && unsafe { &*filter }.refs.fetch_sub(1, Ordering::SeqCst) == 1
        {
            reg.remove(&(filter as usize));
            drop(reg);
            // SAFETY: last reference; created by Box::into_raw in temcNewFilter.
            let f = unsafe { Box::from_raw(filter) };
            let dev = f.device;
            drop(f);
            release_device(dev);
        }
    });
}
