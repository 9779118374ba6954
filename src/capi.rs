//! The C ABI: Intel Open Image Denoise 2.x's API with the prefix `temc`/`TEMC_`.
//!
//! A client written against `oidn.h` (or `oidn.hpp`, see `include/temc.hpp`) builds against
//! `include/temc.h` after renaming oidn/OIDN to temc/TEMC, with OIDN's semantics on a
//! CPU-only device: buffers live in host memory (shared buffers wrap the caller's), the
//! asynchronous calls queue their work on the device's queue (`queue`: one worker thread
//! per device, in order) and return, there is one physical device (the CPU), and the GPU
//! device types give TEMC_ERROR_UNSUPPORTED_HARDWARE. Filter types are OIDN's
//! "RT" and "RTLightmap" (TEMC-2) and temc's "TEMC2", "TEMC1", "DEMC", "AE".
//!
//! Soundness: handles are generation-tagged ids looked up in a registry (`registry`), so a
//! released or foreign handle is an error, never a dereference, and an object stays alive
//! while any call uses it. Every entry point runs in one guard (`objects::guarded`) that
//! catches panics and records failures; the error function is called with no lock held.
//! Entry points that read or write through caller pointers are `unsafe` and say what they
//! need. `include/temc.h` is generated from this file by cbindgen (`tests/c_header.rs`).

#![allow(non_camel_case_types)]

mod failure;
mod filter_state;
mod objects;
mod queue;
mod registry;

use std::ffi::{c_char, c_void, CString};
use std::sync::atomic::Ordering;
use std::sync::{Arc, OnceLock};

use crate::image::{Format, Layout};
use filter_state::FilterState;
use objects::{
    affinity, guarded, name_arg, take_error, BufferObj, DeviceObj, Failure, FilterObj, Outcome,
    BUFFERS, DEVICES, FILTERS,
};
use registry::Registry;

/// Retain for every handle kind: a dead or foreign handle is an error naming the kind.
fn retain_in<T>(registry: &Registry<T>, handle: usize, kind: &str) -> Result<(), Failure> {
    if registry.retain(handle) {
        Ok(())
    } else {
        Err(Failure::invalid(format!(
            "invalid or released {kind} handle"
        )))
    }
}

/// Release for every handle kind. The last reference's object is dropped here, outside
/// the registry's lock (its destructor may release other objects), after the work queued
/// on its device, as OIDN waits for it (memory shared with the object may then be freed).
fn release_in<T>(
    registry: &Registry<T>,
    handle: usize,
    kind: &str,
    device: impl Fn(&T) -> &DeviceObj,
) -> Result<(), Failure> {
    match registry.release(handle) {
        Some(last) => {
            if let Some(object) = &last {
                device(object).queue.wait_idle();
            }
            drop(last);
            Ok(())
        }
        None => Err(Failure::invalid(format!(
            "invalid or released {kind} handle"
        ))),
    }
}

/// Part `index` (0 major, 1 minor, 2 patch) of the OIDN API level in Cargo.toml's
/// `[package.metadata.temc]`, which build.rs checked to be three numbers.
const fn api_version_part(index: usize) -> u32 {
    let text = env!("TEMC_OIDN_API_VERSION").as_bytes();
    let (mut i, mut part, mut value) = (0, 0, 0u32);
    while i < text.len() {
        if text[i] == b'.' {
            part += 1;
        } else if part == index {
            value = value * 10 + (text[i] - b'0') as u32;
        }
        i += 1;
    }
    value
}

// The version macros live in include/temc_config.h (as OIDN's in config.h), written from
// Cargo.toml and checked by tests/c_header.rs; cbindgen.toml keeps these out of temc.h.

/// The OIDN API version temc implements: a client's `TEMC_VERSION_MAJOR >= 2` checks
/// take their 2.x path. (The temc library's own version is the device parameter
/// "libraryVersion".)
pub const TEMC_VERSION_MAJOR: u32 = api_version_part(0);
/// Minor version of the OIDN API implemented.
pub const TEMC_VERSION_MINOR: u32 = api_version_part(1);
/// Patch version of the OIDN API implemented.
pub const TEMC_VERSION_PATCH: u32 = api_version_part(2);
/// `major * 10000 + minor * 100 + patch`, as OIDN_VERSION.
pub const TEMC_VERSION: u32 =
    TEMC_VERSION_MAJOR * 10000 + TEMC_VERSION_MINOR * 100 + TEMC_VERSION_PATCH;

/// Bytes in a physical device's UUID.
pub const TEMC_UUID_SIZE: usize = 16;
/// Bytes in a physical device's LUID.
pub const TEMC_LUID_SIZE: usize = 8;

/// Error codes (OIDN's values).
pub type TEMCError = u32;
/// No error.
pub const TEMC_ERROR_NONE: TEMCError = 0;
/// An unknown error (e.g. an internal failure).
pub const TEMC_ERROR_UNKNOWN: TEMCError = 1;
/// A parameter is invalid (NULL or released handle, bad size or stride, ...).
pub const TEMC_ERROR_INVALID_ARGUMENT: TEMCError = 2;
/// The call is not allowed in the current state (e.g. execute before commit).
pub const TEMC_ERROR_INVALID_OPERATION: TEMCError = 3;
/// Not enough memory.
pub const TEMC_ERROR_OUT_OF_MEMORY: TEMCError = 4;
/// The hardware is not supported (every GPU device type: temc runs on the CPU).
pub const TEMC_ERROR_UNSUPPORTED_HARDWARE: TEMCError = 5;
/// The progress monitor cancelled the operation.
pub const TEMC_ERROR_CANCELLED: TEMCError = 6;

/// Device types (OIDN's values).
pub type TEMCDeviceType = u32;
/// The default device (the CPU).
pub const TEMC_DEVICE_TYPE_DEFAULT: TEMCDeviceType = 0;
/// The CPU.
pub const TEMC_DEVICE_TYPE_CPU: TEMCDeviceType = 1;
/// SYCL (not supported: TEMC_ERROR_UNSUPPORTED_HARDWARE).
pub const TEMC_DEVICE_TYPE_SYCL: TEMCDeviceType = 2;
/// CUDA (not supported).
pub const TEMC_DEVICE_TYPE_CUDA: TEMCDeviceType = 3;
/// HIP (not supported).
pub const TEMC_DEVICE_TYPE_HIP: TEMCDeviceType = 4;
/// Metal (not supported).
pub const TEMC_DEVICE_TYPE_METAL: TEMCDeviceType = 5;

/// Pixel formats.
pub type TEMCFormat = u32;
/// No format.
pub const TEMC_FORMAT_UNDEFINED: TEMCFormat = 0;
/// One 32-bit float channel (also the band type of a "spectral" image).
pub const TEMC_FORMAT_FLOAT: TEMCFormat = 1;
/// Two 32-bit float channels.
pub const TEMC_FORMAT_FLOAT2: TEMCFormat = 2;
/// Three 32-bit float channels.
pub const TEMC_FORMAT_FLOAT3: TEMCFormat = 3;
/// Four 32-bit float channels (the fourth is ignored).
pub const TEMC_FORMAT_FLOAT4: TEMCFormat = 4;
/// One 16-bit float channel (also a "spectral" band type).
pub const TEMC_FORMAT_HALF: TEMCFormat = 257;
/// Two 16-bit float channels.
pub const TEMC_FORMAT_HALF2: TEMCFormat = 258;
/// Three 16-bit float channels.
pub const TEMC_FORMAT_HALF3: TEMCFormat = 259;
/// Four 16-bit float channels (the fourth is ignored).
pub const TEMC_FORMAT_HALF4: TEMCFormat = 260;

/// Buffer storage modes. On the CPU device all are host memory the host can access.
pub type TEMCStorage = u32;
/// No storage given (host).
pub const TEMC_STORAGE_UNDEFINED: TEMCStorage = 0;
/// Host memory.
pub const TEMC_STORAGE_HOST: TEMCStorage = 1;
/// Device memory (host memory on the CPU device).
pub const TEMC_STORAGE_DEVICE: TEMCStorage = 2;
/// Managed memory (host memory on the CPU device).
pub const TEMC_STORAGE_MANAGED: TEMCStorage = 3;

/// External memory type flags (for the import functions, which the CPU device refuses).
pub type TEMCExternalMemoryTypeFlag = u32;
/// No external memory type.
pub const TEMC_EXTERNAL_MEMORY_TYPE_FLAG_NONE: TEMCExternalMemoryTypeFlag = 0;
/// An opaque POSIX file descriptor.
pub const TEMC_EXTERNAL_MEMORY_TYPE_FLAG_OPAQUE_FD: TEMCExternalMemoryTypeFlag = 1 << 0;
/// A Linux dma_buf file descriptor.
pub const TEMC_EXTERNAL_MEMORY_TYPE_FLAG_DMA_BUF: TEMCExternalMemoryTypeFlag = 1 << 1;
/// An NT handle.
pub const TEMC_EXTERNAL_MEMORY_TYPE_FLAG_OPAQUE_WIN32: TEMCExternalMemoryTypeFlag = 1 << 2;
/// A global share (KMT) handle.
pub const TEMC_EXTERNAL_MEMORY_TYPE_FLAG_OPAQUE_WIN32_KMT: TEMCExternalMemoryTypeFlag = 1 << 3;
/// An NT handle to a Direct3D 11 texture.
pub const TEMC_EXTERNAL_MEMORY_TYPE_FLAG_D3D11_TEXTURE: TEMCExternalMemoryTypeFlag = 1 << 4;
/// A KMT handle to a Direct3D 11 texture.
pub const TEMC_EXTERNAL_MEMORY_TYPE_FLAG_D3D11_TEXTURE_KMT: TEMCExternalMemoryTypeFlag = 1 << 5;
/// An NT handle to a Direct3D 11 resource.
pub const TEMC_EXTERNAL_MEMORY_TYPE_FLAG_D3D11_RESOURCE: TEMCExternalMemoryTypeFlag = 1 << 6;
/// A KMT handle to a Direct3D 11 resource.
pub const TEMC_EXTERNAL_MEMORY_TYPE_FLAG_D3D11_RESOURCE_KMT: TEMCExternalMemoryTypeFlag = 1 << 7;
/// An NT handle to a Direct3D 12 heap.
pub const TEMC_EXTERNAL_MEMORY_TYPE_FLAG_D3D12_HEAP: TEMCExternalMemoryTypeFlag = 1 << 8;
/// An NT handle to a Direct3D 12 committed resource.
pub const TEMC_EXTERNAL_MEMORY_TYPE_FLAG_D3D12_RESOURCE: TEMCExternalMemoryTypeFlag = 1 << 9;

/// External semaphore type flags (OIDN 2.5; for the import functions, which the CPU
/// device refuses: its "externalSemaphoreTypes" is 0).
pub type TEMCExternalSemaphoreTypeFlag = u32;
/// No external semaphore type.
pub const TEMC_EXTERNAL_SEMAPHORE_TYPE_FLAG_NONE: TEMCExternalSemaphoreTypeFlag = 0;
/// An opaque POSIX file descriptor.
pub const TEMC_EXTERNAL_SEMAPHORE_TYPE_FLAG_OPAQUE_FD: TEMCExternalSemaphoreTypeFlag = 1 << 0;
/// An opaque NT handle.
pub const TEMC_EXTERNAL_SEMAPHORE_TYPE_FLAG_OPAQUE_WIN32: TEMCExternalSemaphoreTypeFlag = 1 << 1;
/// An opaque global share (KMT) handle.
pub const TEMC_EXTERNAL_SEMAPHORE_TYPE_FLAG_OPAQUE_WIN32_KMT: TEMCExternalSemaphoreTypeFlag =
    1 << 2;
/// An NT handle to a Direct3D 11 fence.
pub const TEMC_EXTERNAL_SEMAPHORE_TYPE_FLAG_D3D11_FENCE: TEMCExternalSemaphoreTypeFlag = 1 << 3;
/// An NT handle to a Direct3D 12 fence.
pub const TEMC_EXTERNAL_SEMAPHORE_TYPE_FLAG_D3D12_FENCE: TEMCExternalSemaphoreTypeFlag = 1 << 4;
/// An NT handle to a Direct3D 11 keyed mutex.
pub const TEMC_EXTERNAL_SEMAPHORE_TYPE_FLAG_KEYED_MUTEX: TEMCExternalSemaphoreTypeFlag = 1 << 5;
/// A KMT handle to a Direct3D 11 keyed mutex.
pub const TEMC_EXTERNAL_SEMAPHORE_TYPE_FLAG_KEYED_MUTEX_KMT: TEMCExternalSemaphoreTypeFlag = 1 << 6;
/// A POSIX file descriptor of a timeline semaphore.
pub const TEMC_EXTERNAL_SEMAPHORE_TYPE_FLAG_TIMELINE_SEMAPHORE_FD: TEMCExternalSemaphoreTypeFlag =
    1 << 7;
/// An NT handle to a timeline semaphore.
pub const TEMC_EXTERNAL_SEMAPHORE_TYPE_FLAG_TIMELINE_SEMAPHORE_WIN32:
    TEMCExternalSemaphoreTypeFlag = 1 << 8;
/// A set of TEMCExternalSemaphoreTypeFlag values.
pub type TEMCExternalSemaphoreTypeFlags = u32;

/// Quality modes for the filter's "quality" parameter.
pub type TEMCQuality = u32;
/// The library's default: balanced, for every filter type ("RT" and "RTLightmap" too:
/// OIDN's default is high, and balanced runs the network temc's high ran until 2026-12-06).
pub const TEMC_QUALITY_DEFAULT: TEMCQuality = 0;
/// Fastest.
pub const TEMC_QUALITY_FAST: TEMCQuality = 4;
/// Balanced: a network of 3 pyramid levels (their reach cuts the noise one level leaves).
pub const TEMC_QUALITY_BALANCED: TEMCQuality = 5;
/// Highest quality: balanced's network run on each tile and its half turn, averaged (the
/// "passes" parameter; 2-5 % lower error than balanced at about twice its time).
pub const TEMC_QUALITY_HIGH: TEMCQuality = 6;

/// Called with each error as it is reported: user pointer, code, message (valid during
/// the call); an error of queued work at the next sync point, on the thread of that call.
/// No temc lock is held while it runs, so it may call temc functions.
pub type TEMCErrorFunction =
    Option<unsafe extern "C" fn(user_ptr: *mut c_void, code: TEMCError, message: *const c_char)>;

/// Called with the progress in [0, 1]; return false to cancel. It runs while the filter
/// executes (for temcExecuteFilterAsync, on the device's queue thread): it must not call
/// functions on the same filter.
pub type TEMCProgressMonitorFunction =
    Option<unsafe extern "C" fn(user_ptr: *mut c_void, n: f64) -> bool>;

/// Opaque device type (handles are ids, not addresses).
pub struct TEMCDeviceImpl {
    _opaque: [u8; 0],
}

/// Opaque filter type.
pub struct TEMCFilterImpl {
    _opaque: [u8; 0],
}

/// Opaque buffer type.
pub struct TEMCBufferImpl {
    _opaque: [u8; 0],
}

/// Opaque semaphore type (OIDN 2.5).
pub struct TEMCSemaphoreImpl {
    _opaque: [u8; 0],
}

/// A device handle.
pub type TEMCDevice = *mut TEMCDeviceImpl;
/// A filter handle.
pub type TEMCFilter = *mut TEMCFilterImpl;
/// A buffer handle.
pub type TEMCBuffer = *mut TEMCBufferImpl;
/// A semaphore handle (the CPU device imports none, so no valid one exists).
pub type TEMCSemaphore = *mut TEMCSemaphoreImpl;

fn handle<T>(id: usize) -> *mut T {
    std::ptr::without_provenance_mut(id)
}

fn new_device() -> Outcome<TEMCDevice> {
    DEVICES
        .insert(DeviceObj::new())
        .map(handle)
        .ok_or_else(|| Failure::new(TEMC_ERROR_OUT_OF_MEMORY, "too many devices"))
}

fn gpu_unsupported<T>(what: &str) -> Outcome<T> {
    Err(Failure::unsupported(format!(
        "{what} devices are not supported: temc runs on the CPU (use TEMC_DEVICE_TYPE_CPU)"
    )))
}

// ---------------------------------------------------------------------------------------
// Physical devices: one, the CPU.

/// Returns the number of physical devices: 1 (the CPU).
#[no_mangle]
pub extern "C" fn temcGetNumPhysicalDevices() -> i32 {
    1
}

fn physical(id: i32) -> Outcome<()> {
    if id == 0 {
        Ok(())
    } else {
        Err(Failure::invalid(format!(
            "invalid physical device ID {id} (only 0, the CPU)"
        )))
    }
}

fn cpu_name() -> &'static CString {
    static NAME: OnceLock<CString> = OnceLock::new();
    NAME.get_or_init(|| {
        let model = std::fs::read_to_string("/proc/cpuinfo")
            .ok()
            .and_then(|s| {
                s.lines()
                    .find(|l| l.starts_with("model name"))
                    .and_then(|l| l.split(':').nth(1))
                    .map(|m| m.trim().to_string())
            })
            .unwrap_or_else(|| "CPU".into());
        CString::new(model).unwrap_or_default()
    })
}

/// Reads a bool parameter of a physical device: "uuidSupported", "luidSupported",
/// "pciAddressSupported" (all false for the CPU).
///
/// # Safety
/// `name` must be NULL or a NUL-terminated string.
#[no_mangle]
pub unsafe extern "C" fn temcGetPhysicalDeviceBool(id: i32, name: *const c_char) -> bool {
    guarded(false, |_| {
        physical(id)?;
        // SAFETY: the caller's contract.
        match unsafe { name_arg(name) }? {
            "uuidSupported" | "luidSupported" | "pciAddressSupported" => Ok(false),
            other => Err(Failure::invalid(format!(
                "unknown physical device parameter {other:?}"
            ))),
        }
    })
}

/// Reads an int parameter of a physical device: "type" (TEMC_DEVICE_TYPE_CPU).
///
/// # Safety
/// `name` must be NULL or a NUL-terminated string.
#[no_mangle]
pub unsafe extern "C" fn temcGetPhysicalDeviceInt(id: i32, name: *const c_char) -> i32 {
    guarded(0, |_| {
        physical(id)?;
        // SAFETY: the caller's contract.
        match unsafe { name_arg(name) }? {
            "type" => Ok(TEMC_DEVICE_TYPE_CPU as i32),
            other => Err(Failure::invalid(format!(
                "unknown physical device parameter {other:?}"
            ))),
        }
    })
}

/// Reads an unsigned int parameter of a physical device (as temcGetPhysicalDeviceInt).
///
/// # Safety
/// As temcGetPhysicalDeviceInt.
#[no_mangle]
pub unsafe extern "C" fn temcGetPhysicalDeviceUInt(id: i32, name: *const c_char) -> u32 {
    // SAFETY: forwarded contract.
    unsafe { temcGetPhysicalDeviceInt(id, name) as u32 }
}

/// Reads a string parameter of a physical device: "name" (the CPU model). The string lives
/// as long as the process.
///
/// # Safety
/// `name` must be NULL or a NUL-terminated string.
#[no_mangle]
pub unsafe extern "C" fn temcGetPhysicalDeviceString(
    id: i32,
    name: *const c_char,
) -> *const c_char {
    guarded(std::ptr::null(), |_| {
        physical(id)?;
        // SAFETY: the caller's contract.
        match unsafe { name_arg(name) }? {
            "name" => Ok(cpu_name().as_ptr()),
            other => Err(Failure::invalid(format!(
                "unknown physical device parameter {other:?}"
            ))),
        }
    })
}

/// Reads opaque data of a physical device ("uuid", "luid"): the CPU device has none, so
/// this returns NULL with an error, and 0 in `byte_size` (may be NULL).
///
/// # Safety
/// `name` must be NULL or a NUL-terminated string; `byte_size` NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn temcGetPhysicalDeviceData(
    id: i32,
    name: *const c_char,
    byte_size: *mut usize,
) -> *const c_void {
    if !byte_size.is_null() {
        // SAFETY: the caller's contract.
        unsafe { *byte_size = 0 };
    }
    guarded(std::ptr::null(), |_| {
        physical(id)?;
        // SAFETY: the caller's contract.
        let n = unsafe { name_arg(name) }?;
        Err(Failure::invalid(format!(
            "physical device parameter {n:?} is not available on the CPU device"
        )))
    })
}

// ---------------------------------------------------------------------------------------
// Devices.

/// Returns whether the CPU device is supported: true.
#[no_mangle]
pub extern "C" fn temcIsCPUDeviceSupported() -> bool {
    true
}

/// Returns whether a SYCL device is supported: false.
#[no_mangle]
pub extern "C" fn temcIsSYCLDeviceSupported(_device: *const c_void) -> bool {
    false
}

/// Returns whether a CUDA device is supported: false.
#[no_mangle]
pub extern "C" fn temcIsCUDADeviceSupported(_device_id: i32) -> bool {
    false
}

/// Returns whether a HIP device is supported: false.
#[no_mangle]
pub extern "C" fn temcIsHIPDeviceSupported(_device_id: i32) -> bool {
    false
}

/// Returns whether a Metal device is supported: false.
#[no_mangle]
pub extern "C" fn temcIsMetalDeviceSupported(_device: *mut c_void) -> bool {
    false
}

/// Creates a device: TEMC_DEVICE_TYPE_DEFAULT or _CPU. The GPU types give NULL with
/// TEMC_ERROR_UNSUPPORTED_HARDWARE, other values TEMC_ERROR_INVALID_ARGUMENT;
/// temcGetDeviceError(NULL, ...) says why.
#[no_mangle]
pub extern "C" fn temcNewDevice(device_type: TEMCDeviceType) -> TEMCDevice {
    guarded(std::ptr::null_mut(), |_| match device_type {
        TEMC_DEVICE_TYPE_DEFAULT | TEMC_DEVICE_TYPE_CPU => new_device(),
        TEMC_DEVICE_TYPE_SYCL => gpu_unsupported("SYCL"),
        TEMC_DEVICE_TYPE_CUDA => gpu_unsupported("CUDA"),
        TEMC_DEVICE_TYPE_HIP => gpu_unsupported("HIP"),
        TEMC_DEVICE_TYPE_METAL => gpu_unsupported("Metal"),
        other => Err(Failure::invalid(format!("unknown device type {other}"))),
    })
}

/// Creates a device from a physical device ID (0, the CPU).
#[no_mangle]
pub extern "C" fn temcNewDeviceByID(physical_device_id: i32) -> TEMCDevice {
    guarded(std::ptr::null_mut(), |_| {
        physical(physical_device_id)?;
        new_device()
    })
}

/// Creates a device from a physical device's UUID: the CPU has none, so this gives NULL
/// with TEMC_ERROR_INVALID_ARGUMENT.
#[no_mangle]
pub extern "C" fn temcNewDeviceByUUID(_uuid: *const c_void) -> TEMCDevice {
    guarded(std::ptr::null_mut(), |_| {
        Err(Failure::invalid(
            "no physical device with this UUID (temc has only the CPU)",
        ))
    })
}

/// Creates a device from a physical device's LUID: NULL, as temcNewDeviceByUUID.
#[no_mangle]
pub extern "C" fn temcNewDeviceByLUID(_luid: *const c_void) -> TEMCDevice {
    guarded(std::ptr::null_mut(), |_| {
        Err(Failure::invalid(
            "no physical device with this LUID (temc has only the CPU)",
        ))
    })
}

/// Creates a device from a PCI address: NULL, as temcNewDeviceByUUID.
#[no_mangle]
pub extern "C" fn temcNewDeviceByPCIAddress(
    _pci_domain: i32,
    _pci_bus: i32,
    _pci_device: i32,
    _pci_function: i32,
) -> TEMCDevice {
    guarded(std::ptr::null_mut(), |_| {
        Err(Failure::invalid(
            "no physical device at this PCI address (temc has only the CPU)",
        ))
    })
}

/// Creates a SYCL device: NULL with TEMC_ERROR_UNSUPPORTED_HARDWARE.
#[no_mangle]
pub extern "C" fn temcNewSYCLDevice(_queues: *const c_void, _num_queues: i32) -> TEMCDevice {
    guarded(std::ptr::null_mut(), |_| gpu_unsupported("SYCL"))
}

/// Creates a CUDA device: NULL with TEMC_ERROR_UNSUPPORTED_HARDWARE.
#[no_mangle]
pub extern "C" fn temcNewCUDADevice(
    _device_ids: *const i32,
    _streams: *const c_void,
    _num_pairs: i32,
) -> TEMCDevice {
    guarded(std::ptr::null_mut(), |_| gpu_unsupported("CUDA"))
}

/// Creates a HIP device: NULL with TEMC_ERROR_UNSUPPORTED_HARDWARE.
#[no_mangle]
pub extern "C" fn temcNewHIPDevice(
    _device_ids: *const i32,
    _streams: *const c_void,
    _num_pairs: i32,
) -> TEMCDevice {
    guarded(std::ptr::null_mut(), |_| gpu_unsupported("HIP"))
}

/// Creates a Metal device: NULL with TEMC_ERROR_UNSUPPORTED_HARDWARE.
#[no_mangle]
pub extern "C" fn temcNewMetalDevice(
    _command_queues: *const c_void,
    _num_queues: i32,
) -> TEMCDevice {
    guarded(std::ptr::null_mut(), |_| gpu_unsupported("Metal"))
}

/// Adds a reference to the device.
#[no_mangle]
pub extern "C" fn temcRetainDevice(device: TEMCDevice) {
    guarded((), |_| retain_in(&DEVICES, device.addr(), "device"))
}

/// Drops a reference; with the last one the handle is dead, after the device's queued
/// work (filters and buffers made on the device keep what they need of it until they are
/// released too).
#[no_mangle]
pub extern "C" fn temcReleaseDevice(device: TEMCDevice) {
    guarded((), |_| release_in(&DEVICES, device.addr(), "device", |d| d))
}

/// Commits the device's parameters (builds its thread pool). Required before filters run.
#[no_mangle]
pub extern "C" fn temcCommitDevice(device: TEMCDevice) {
    guarded((), |c| Ok(c.device(device)?.device.commit()?))
}

/// Waits for the work the `Async` calls queued on the device. The first error of that
/// work (since the last sync point: this, temcExecuteFilter, temcCommitFilter) is
/// reported now, as OIDN reports asynchronous errors. As OIDN, the device must be
/// committed.
#[no_mangle]
pub extern "C" fn temcSyncDevice(device: TEMCDevice) {
    guarded((), |c| committed_device(c, device)?.sync())
}

/// The device of a call OIDN allows only on a committed device (sync, new buffers, new
/// filters, semaphores): TEMC_ERROR_INVALID_OPERATION, with OIDN's message, before
/// commit and after a change that needs another (such as "numThreads").
fn committed_device(c: &mut objects::Call, device: TEMCDevice) -> Outcome<Arc<DeviceObj>> {
    let d = c.device(device)?;
    if d.device.is_committed() {
        Ok(d)
    } else {
        Err(Failure::operation(
            "changes to the device are not committed",
        ))
    }
}

fn set_device_int(d: &DeviceObj, name: &str, value: i32) -> Outcome<()> {
    match name {
        "numThreads" if value >= 0 => d.device.set_num_threads(value as usize),
        "numThreads" => {
            return Err(Failure::invalid(format!(
                "numThreads must be >= 0, got {value}"
            )))
        }
        "verbose" => d.device.set_verbose(value),
        // Thread pinning: temc's pool does not pin; the value is kept for reading back.
        "setAffinity" => d.set_affinity.store(value != 0, Ordering::Relaxed),
        other => d.warn(&format!("unknown device parameter {other:?} ignored")),
    }
    Ok(())
}

fn get_device_int(d: &DeviceObj, name: &str) -> i32 {
    match name {
        "type" => TEMC_DEVICE_TYPE_CPU as i32,
        "version" => TEMC_VERSION as i32,
        "versionMajor" => TEMC_VERSION_MAJOR as i32,
        "versionMinor" => TEMC_VERSION_MINOR as i32,
        "versionPatch" => TEMC_VERSION_PATCH as i32,
        "libraryVersion" => {
            let v: Vec<i32> = env!("CARGO_PKG_VERSION")
                .split('.')
                .map(|p| p.parse().unwrap_or(0))
                .collect();
            v[0] * 10000 + v[1] * 100 + v[2]
        }
        "numThreads" => d.device.num_threads() as i32,
        "verbose" => d.device.verbose(),
        "setAffinity" => affinity(d) as i32,
        "systemMemorySupported" | "managedMemorySupported" => 1,
        "externalMemoryTypes" => TEMC_EXTERNAL_MEMORY_TYPE_FLAG_NONE as i32,
        "externalSemaphoreTypes" => TEMC_EXTERNAL_SEMAPHORE_TYPE_FLAG_NONE as i32,
        other => {
            d.warn(&format!("unknown device parameter {other:?}"));
            0
        }
    }
}

/// Sets an int (or bool) device parameter: "numThreads" (0 = all cores; more than the
/// cores are capped at them when the device commits), "verbose",
/// "setAffinity". Unknown names are ignored with a warning (printed when verbose).
///
/// # Safety
/// `name` must be NULL or a NUL-terminated string.
#[no_mangle]
pub unsafe extern "C" fn temcSetDeviceInt(device: TEMCDevice, name: *const c_char, value: i32) {
    guarded((), |c| {
        let d = c.device(device)?;
        // SAFETY: the caller's contract.
        set_device_int(&d, unsafe { name_arg(name) }?, value)
    })
}

/// Sets a bool device parameter (as temcSetDeviceInt with 0 or 1).
///
/// # Safety
/// As temcSetDeviceInt.
#[no_mangle]
pub unsafe extern "C" fn temcSetDeviceBool(device: TEMCDevice, name: *const c_char, value: bool) {
    // SAFETY: forwarded contract.
    unsafe { temcSetDeviceInt(device, name, value as i32) }
}

/// Sets an unsigned int device parameter (as temcSetDeviceInt).
///
/// # Safety
/// As temcSetDeviceInt.
#[no_mangle]
pub unsafe extern "C" fn temcSetDeviceUInt(device: TEMCDevice, name: *const c_char, value: u32) {
    // SAFETY: forwarded contract.
    unsafe { temcSetDeviceInt(device, name, value as i32) }
}

/// Deprecated OIDN 1.x name of temcSetDeviceBool.
///
/// # Safety
/// As temcSetDeviceInt.
#[no_mangle]
pub unsafe extern "C" fn temcSetDevice1b(device: TEMCDevice, name: *const c_char, value: bool) {
    // SAFETY: forwarded contract.
    unsafe { temcSetDeviceBool(device, name, value) }
}

/// Deprecated OIDN 1.x name of temcSetDeviceInt.
///
/// # Safety
/// As temcSetDeviceInt.
#[no_mangle]
pub unsafe extern "C" fn temcSetDevice1i(device: TEMCDevice, name: *const c_char, value: i32) {
    // SAFETY: forwarded contract.
    unsafe { temcSetDeviceInt(device, name, value) }
}

/// Reads an int (or bool) device parameter: "type", "version" (TEMC_VERSION),
/// "versionMajor", "versionMinor", "versionPatch", "libraryVersion" (temc's own,
/// major*10000+minor*100+patch), "numThreads", "verbose", "setAffinity",
/// "systemMemorySupported", "managedMemorySupported", "externalMemoryTypes",
/// "externalSemaphoreTypes" (0: the CPU device imports no semaphores). Unknown names read
/// 0 with a warning.
///
/// # Safety
/// `name` must be NULL or a NUL-terminated string.
#[no_mangle]
pub unsafe extern "C" fn temcGetDeviceInt(device: TEMCDevice, name: *const c_char) -> i32 {
    guarded(0, |c| {
        let d = c.device(device)?;
        // SAFETY: the caller's contract.
        Ok(get_device_int(&d, unsafe { name_arg(name) }?))
    })
}

/// Reads a bool device parameter (as temcGetDeviceInt, != 0).
///
/// # Safety
/// As temcGetDeviceInt.
#[no_mangle]
pub unsafe extern "C" fn temcGetDeviceBool(device: TEMCDevice, name: *const c_char) -> bool {
    // SAFETY: forwarded contract.
    unsafe { temcGetDeviceInt(device, name) != 0 }
}

/// Reads an unsigned int device parameter (as temcGetDeviceInt).
///
/// # Safety
/// As temcGetDeviceInt.
#[no_mangle]
pub unsafe extern "C" fn temcGetDeviceUInt(device: TEMCDevice, name: *const c_char) -> u32 {
    // SAFETY: forwarded contract.
    unsafe { temcGetDeviceInt(device, name) as u32 }
}

/// Deprecated OIDN 1.x name of temcGetDeviceBool.
///
/// # Safety
/// As temcGetDeviceInt.
#[no_mangle]
pub unsafe extern "C" fn temcGetDevice1b(device: TEMCDevice, name: *const c_char) -> bool {
    // SAFETY: forwarded contract.
    unsafe { temcGetDeviceBool(device, name) }
}

/// Deprecated OIDN 1.x name of temcGetDeviceInt.
///
/// # Safety
/// As temcGetDeviceInt.
#[no_mangle]
pub unsafe extern "C" fn temcGetDevice1i(device: TEMCDevice, name: *const c_char) -> i32 {
    // SAFETY: forwarded contract.
    unsafe { temcGetDeviceInt(device, name) }
}

/// Registers a function called with every error of this device (NULL removes it). It is
/// called with no temc lock held, so it may call temcGetDeviceError.
///
/// # Safety
/// `func` must be safe to call with `user_ptr` from any thread that uses the device, until
/// it is replaced or the device is gone.
#[no_mangle]
pub unsafe extern "C" fn temcSetDeviceErrorFunction(
    device: TEMCDevice,
    func: TEMCErrorFunction,
    user_ptr: *mut c_void,
) {
    guarded((), |c| {
        c.device(device)?.set_error_function(func, user_ptr);
        Ok(())
    })
}

/// Returns the first error not yet queried by the calling thread (errors are kept per
/// thread, as in OIDN) and clears it; `out_message` (may be NULL)
/// receives its text (NULL for no error), valid until the next query. A NULL device
/// returns this thread's errors that had no device (device creation, NULL or released
/// handles, physical device queries).
///
/// # Safety
/// `out_message` must be NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn temcGetDeviceError(
    device: TEMCDevice,
    out_message: *mut *const c_char,
) -> TEMCError {
    let (code, message) = guarded((TEMC_ERROR_UNKNOWN, std::ptr::null()), |c| {
        if device.is_null() {
            return Ok(take_error(None));
        }
        // A dead handle is itself an error, reported (like OIDN) on this thread.
        let d = c.device(device)?;
        Ok(take_error(Some(&d)))
    });
    // A dead handle: what was just recorded globally is the answer.
    let (code, message) = if code == TEMC_ERROR_UNKNOWN && message.is_null() {
        take_error(None)
    } else {
        (code, message)
    };
    if !out_message.is_null() {
        // SAFETY: the caller passes a writable pointer or NULL.
        unsafe { *out_message = message };
    }
    code
}

// ---------------------------------------------------------------------------------------
// Buffers: host memory.

fn new_buffer(obj: BufferObj) -> Outcome<TEMCBuffer> {
    BUFFERS
        .insert(obj)
        .map(handle)
        .ok_or_else(|| Failure::new(TEMC_ERROR_OUT_OF_MEMORY, "too many buffers"))
}

/// Creates a zeroed host buffer of `byte_size` bytes. The device must be committed
/// (TEMC_ERROR_INVALID_OPERATION otherwise, as in OIDN).
#[no_mangle]
pub extern "C" fn temcNewBuffer(device: TEMCDevice, byte_size: usize) -> TEMCBuffer {
    temcNewBufferWithStorage(device, byte_size, TEMC_STORAGE_HOST)
}

/// Creates a buffer with a storage mode; every mode is host memory on the CPU device (the
/// host may use temcGetBufferData for all of them). The device must be committed.
#[no_mangle]
pub extern "C" fn temcNewBufferWithStorage(
    device: TEMCDevice,
    byte_size: usize,
    storage: TEMCStorage,
) -> TEMCBuffer {
    guarded(std::ptr::null_mut(), |c| {
        let d = committed_device(c, device)?;
        let storage = match storage {
            TEMC_STORAGE_UNDEFINED => TEMC_STORAGE_HOST,
            s @ (TEMC_STORAGE_HOST | TEMC_STORAGE_DEVICE | TEMC_STORAGE_MANAGED) => s,
            other => return Err(Failure::invalid(format!("unknown storage mode {other}"))),
        };
        new_buffer(BufferObj::owned(d, byte_size, storage)?)
    })
}

/// Creates a buffer over the caller's memory (no copy). The device must be committed.
///
/// # Safety
/// `ptr` must be valid for reads and writes of `byte_size` bytes for the buffer's lifetime
/// (until its last release, and while a filter has an image of it set).
#[no_mangle]
pub unsafe extern "C" fn temcNewSharedBuffer(
    device: TEMCDevice,
    ptr: *mut c_void,
    byte_size: usize,
) -> TEMCBuffer {
    guarded(std::ptr::null_mut(), |c| {
        let d = committed_device(c, device)?;
        if ptr.is_null() && byte_size > 0 {
            return Err(Failure::invalid("shared buffer: NULL pointer"));
        }
        new_buffer(BufferObj::shared(d, ptr as *mut u8, byte_size))
    })
}

fn no_external_memory(device: TEMCDevice) -> TEMCBuffer {
    guarded(std::ptr::null_mut(), |c| {
        committed_device(c, device)?;
        Err(Failure::operation(
            "the CPU device imports no external memory (\"externalMemoryTypes\" is 0)",
        ))
    })
}

/// Imports external memory from a file descriptor: not supported on the CPU device (NULL,
/// TEMC_ERROR_INVALID_OPERATION).
#[no_mangle]
pub extern "C" fn temcNewSharedBufferFromFD(
    device: TEMCDevice,
    _fd_type: TEMCExternalMemoryTypeFlag,
    _fd: i32,
    _byte_size: usize,
) -> TEMCBuffer {
    no_external_memory(device)
}

/// Imports external memory from a Win32 handle: not supported (as temcNewSharedBufferFromFD).
#[no_mangle]
pub extern "C" fn temcNewSharedBufferFromWin32Handle(
    device: TEMCDevice,
    _handle_type: TEMCExternalMemoryTypeFlag,
    _handle: *mut c_void,
    _name: *const c_void,
    _byte_size: usize,
) -> TEMCBuffer {
    no_external_memory(device)
}

/// Wraps a Metal buffer: not supported (as temcNewSharedBufferFromFD).
#[no_mangle]
pub extern "C" fn temcNewSharedBufferFromMetal(
    device: TEMCDevice,
    _buffer: *mut c_void,
) -> TEMCBuffer {
    no_external_memory(device)
}

/// Returns the buffer's size in bytes (0 on error).
#[no_mangle]
pub extern "C" fn temcGetBufferSize(buffer: TEMCBuffer) -> usize {
    guarded(0, |c| Ok(c.buffer(buffer)?.size))
}

/// Returns the buffer's storage mode.
#[no_mangle]
pub extern "C" fn temcGetBufferStorage(buffer: TEMCBuffer) -> TEMCStorage {
    guarded(TEMC_STORAGE_UNDEFINED, |c| Ok(c.buffer(buffer)?.storage))
}

/// Returns the buffer's data, host-accessible (NULL for an empty buffer or on error).
#[no_mangle]
pub extern "C" fn temcGetBufferData(buffer: TEMCBuffer) -> *mut c_void {
    guarded(std::ptr::null_mut(), |c| {
        Ok(c.buffer(buffer)?.ptr as *mut c_void)
    })
}

/// A buffer copy to or from host memory, checked as OIDN checks it before running or
/// queuing it. It holds the buffer, so a queued copy outlives the buffer's release.
struct BufferCopy {
    buffer: Arc<BufferObj>,
    offset: usize,
    size: usize,
    host: SendPtr,
    /// Buffer to host (a read), else host to buffer.
    read: bool,
}

impl BufferCopy {
    fn new(
        buffer: Arc<BufferObj>,
        offset: usize,
        size: usize,
        host: *mut c_void,
        read: bool,
    ) -> Outcome<Self> {
        buffer.check_range(offset, size)?;
        if size > 0 && host.is_null() {
            return Err(Failure::invalid(if read {
                "read buffer: NULL destination"
            } else {
                "write buffer: NULL source"
            }));
        }
        Ok(Self {
            buffer,
            offset,
            size,
            host: SendPtr(host),
            read,
        })
    }

    /// # Safety
    /// The host memory must be valid for `size` bytes (readable, or writable for a read).
    unsafe fn run(&self) {
        if self.size == 0 {
            return;
        }
        // SAFETY: `new` checked that the range lies inside the buffer; the caller's
        // contract covers the host side. `copy` allows the two to overlap.
        unsafe {
            let inside = self.buffer.ptr.add(self.offset);
            let host = self.host.0 as *mut u8;
            if self.read {
                std::ptr::copy(inside, host, self.size);
            } else {
                std::ptr::copy(host as *const u8, inside, self.size);
            }
        }
    }
}

/// The four buffer copy calls: a blocking copy runs after the device's queued work (as
/// OIDN's), an `Async` one is queued after it.
///
/// # Safety
/// As temcReadBuffer / temcWriteBuffer; for a queued copy, until it has run (temcSyncDevice).
unsafe fn buffer_copy(
    buffer: TEMCBuffer,
    offset: usize,
    size: usize,
    host: *mut c_void,
    read: bool,
    queued: bool,
) {
    guarded((), |c| {
        let b = c.buffer(buffer)?;
        let copy = BufferCopy::new(b.clone(), offset, size, host, read)?;
        if queued {
            return b.device.queue.push(Box::new(move || {
                // SAFETY: the caller keeps the host memory valid until the copy has run.
                unsafe { copy.run() };
                Ok(())
            }));
        }
        b.device.queue.wait_idle();
        // SAFETY: the caller's contract.
        unsafe { copy.run() };
        Ok(())
    })
}

/// Copies `byte_size` bytes at `byte_offset` of the buffer to `dst_host_ptr`, after the
/// work queued on the buffer's device.
///
/// # Safety
/// `dst_host_ptr` must be writable for `byte_size` bytes.
#[no_mangle]
pub unsafe extern "C" fn temcReadBuffer(
    buffer: TEMCBuffer,
    byte_offset: usize,
    byte_size: usize,
    dst_host_ptr: *mut c_void,
) {
    // SAFETY: forwarded contract.
    unsafe { buffer_copy(buffer, byte_offset, byte_size, dst_host_ptr, true, false) }
}

/// temcReadBuffer, queued on the device: returns at once; the copy is done after
/// temcSyncDevice (or any call that waits for the queue).
///
/// # Safety
/// `dst_host_ptr` must stay writable for `byte_size` bytes until the copy is done.
#[no_mangle]
pub unsafe extern "C" fn temcReadBufferAsync(
    buffer: TEMCBuffer,
    byte_offset: usize,
    byte_size: usize,
    dst_host_ptr: *mut c_void,
) {
    // SAFETY: forwarded contract.
    unsafe { buffer_copy(buffer, byte_offset, byte_size, dst_host_ptr, true, true) }
}

/// Copies `byte_size` bytes from `src_host_ptr` into the buffer at `byte_offset`, after
/// the work queued on the buffer's device.
///
/// # Safety
/// `src_host_ptr` must be readable for `byte_size` bytes.
#[no_mangle]
pub unsafe extern "C" fn temcWriteBuffer(
    buffer: TEMCBuffer,
    byte_offset: usize,
    byte_size: usize,
    src_host_ptr: *const c_void,
) {
    let src = src_host_ptr as *mut c_void;
    // SAFETY: forwarded contract (a write only reads the host memory).
    unsafe { buffer_copy(buffer, byte_offset, byte_size, src, false, false) }
}

/// temcWriteBuffer, queued on the device: returns at once; the copy is done after
/// temcSyncDevice (or any call that waits for the queue).
///
/// # Safety
/// `src_host_ptr` must stay readable for `byte_size` bytes until the copy is done.
#[no_mangle]
pub unsafe extern "C" fn temcWriteBufferAsync(
    buffer: TEMCBuffer,
    byte_offset: usize,
    byte_size: usize,
    src_host_ptr: *const c_void,
) {
    let src = src_host_ptr as *mut c_void;
    // SAFETY: forwarded contract (a write only reads the host memory).
    unsafe { buffer_copy(buffer, byte_offset, byte_size, src, false, true) }
}

/// Adds a reference to the buffer.
#[no_mangle]
pub extern "C" fn temcRetainBuffer(buffer: TEMCBuffer) {
    guarded((), |_| retain_in(&BUFFERS, buffer.addr(), "buffer"))
}

/// Drops a reference; the memory goes with the last one (after the device's queued work),
/// or later while a filter still has an image of it set.
#[no_mangle]
pub extern "C" fn temcReleaseBuffer(buffer: TEMCBuffer) {
    guarded((), |_| {
        release_in(&BUFFERS, buffer.addr(), "buffer", |b| &*b.device)
    })
}

// ---------------------------------------------------------------------------------------
// Semaphores (OIDN 2.5): the CPU device imports none. Each call fails as OIDN 2.5.1's CPU
// device makes it fail: the same checks in the same order, codes and messages.

/// OIDN's type check: the types must be among the device's "externalSemaphoreTypes" (none).
fn semaphore_types(types: TEMCExternalSemaphoreTypeFlags) -> Outcome<()> {
    if types == TEMC_EXTERNAL_SEMAPHORE_TYPE_FLAG_NONE {
        Ok(())
    } else {
        Err(Failure::invalid(
            "external semaphore type not supported by the device (\"externalSemaphoreTypes\" is 0)",
        ))
    }
}

/// Imports an external semaphore from a POSIX file descriptor: the CPU device imports
/// none, so this returns NULL (TEMC_ERROR_INVALID_ARGUMENT for any type, as
/// "externalSemaphoreTypes" is 0; TEMC_ERROR_INVALID_OPERATION for no type) and `fd`
/// stays the caller's.
#[no_mangle]
pub extern "C" fn temcNewSharedSemaphoreFromFD(
    device: TEMCDevice,
    fd_type: TEMCExternalSemaphoreTypeFlags,
    _fd: i32,
) -> TEMCSemaphore {
    guarded(std::ptr::null_mut(), |c| {
        committed_device(c, device)?; // OIDN checks this first
        semaphore_types(fd_type)?;
        Err(Failure::operation(
            "creating a shared semaphore from a POSIX file descriptor is not supported by the device",
        ))
    })
}

/// Imports an external semaphore from a Win32 handle or name: NULL, as
/// temcNewSharedSemaphoreFromFD (and TEMC_ERROR_INVALID_ARGUMENT unless exactly one of
/// `handle` and `name` is given).
#[no_mangle]
pub extern "C" fn temcNewSharedSemaphoreFromWin32Handle(
    device: TEMCDevice,
    handle_type: TEMCExternalSemaphoreTypeFlags,
    handle: *mut c_void,
    name: *const c_void,
) -> TEMCSemaphore {
    guarded(std::ptr::null_mut(), |c| {
        committed_device(c, device)?; // OIDN checks this first
        semaphore_types(handle_type)?;
        if handle.is_null() == name.is_null() {
            return Err(Failure::invalid(
                "exactly one of the external semaphore handle and name must be non-null",
            ));
        }
        Err(Failure::operation(
            "creating a shared semaphore from a Win32 handle is not supported by the device",
        ))
    })
}

/// Signals external semaphores after the device's queued work: not supported by the CPU
/// device (TEMC_ERROR_INVALID_OPERATION; no semaphore can exist on it).
#[no_mangle]
pub extern "C" fn temcSignalSemaphoresAsync(
    device: TEMCDevice,
    _semaphores: *const TEMCSemaphore,
    _values: *const u64,
    _num_semaphores: i32,
) {
    guarded((), |c| {
        committed_device(c, device)?; // OIDN checks this first
        Err(Failure::operation(
            "signaling semaphores is not supported by the device",
        ))
    })
}

/// Makes the device's later work wait for external semaphores: not supported by the CPU
/// device (TEMC_ERROR_INVALID_OPERATION).
#[no_mangle]
pub extern "C" fn temcWaitSemaphoresAsync(
    device: TEMCDevice,
    _semaphores: *const TEMCSemaphore,
    _values: *const u64,
    _timeouts_ms: *const u32,
    _num_semaphores: i32,
) {
    guarded((), |c| {
        committed_device(c, device)?; // OIDN checks this first
        Err(Failure::operation(
            "waiting on semaphores is not supported by the device",
        ))
    })
}

fn no_semaphore(semaphore: TEMCSemaphore) -> Outcome<()> {
    Err(Failure::invalid(if semaphore.is_null() {
        "semaphore handle is null"
    } else {
        "invalid semaphore handle (the CPU device imports no semaphores)"
    }))
}

/// Adds a reference to a semaphore: every handle is invalid on the CPU device
/// (TEMC_ERROR_INVALID_ARGUMENT, reported without a device).
#[no_mangle]
pub extern "C" fn temcRetainSemaphore(semaphore: TEMCSemaphore) {
    guarded((), |_| no_semaphore(semaphore))
}

/// Drops a reference to a semaphore: as temcRetainSemaphore.
#[no_mangle]
pub extern "C" fn temcReleaseSemaphore(semaphore: TEMCSemaphore) {
    guarded((), |_| no_semaphore(semaphore))
}

// ---------------------------------------------------------------------------------------
// Filters.

/// Creates a filter: "RT" (OIDN's: TEMC-2 with "hdr" false by default, and the default
/// quality, balanced; given only "albedo" or only "normal" and an "output", it denoises
/// that aux image),
/// "RTLightmap" (TEMC-2 on HDR colour; "directional" must stay false), or temc's
/// "TEMC2", "TEMC1", "DEMC", "AE" (HDR, balanced). The device must be committed
/// (TEMC_ERROR_INVALID_OPERATION otherwise, as in OIDN).
///
/// # Safety
/// `filter_type` must be NULL or a NUL-terminated string.
#[no_mangle]
pub unsafe extern "C" fn temcNewFilter(
    device: TEMCDevice,
    filter_type: *const c_char,
) -> TEMCFilter {
    guarded(std::ptr::null_mut(), |c| {
        let d = committed_device(c, device)?;
        // SAFETY: the caller's contract.
        let state = FilterState::new(&d, unsafe { name_arg(filter_type) }?)?;
        FILTERS
            .insert(FilterObj::new(d, state))
            .map(handle)
            .ok_or_else(|| Failure::new(TEMC_ERROR_OUT_OF_MEMORY, "too many filters"))
    })
}

/// Adds a reference to the filter.
#[no_mangle]
pub extern "C" fn temcRetainFilter(filter: TEMCFilter) {
    guarded((), |_| retain_in(&FILTERS, filter.addr(), "filter"))
}

/// Drops a reference; the filter (with its hold on the device and buffers) goes with the
/// last one, after the work queued on its device (as in OIDN) and any execution still
/// running on another thread. Executions still queued hold the filter meanwhile.
#[no_mangle]
pub extern "C" fn temcReleaseFilter(filter: TEMCFilter) {
    guarded((), |_| {
        release_in(&FILTERS, filter.addr(), "filter", |f| &*f.device)
    })
}

fn layout(
    format: TEMCFormat,
    width: usize,
    height: usize,
    byte_offset: usize,
    pixel_stride: usize,
    row_stride: usize,
) -> Outcome<Layout> {
    let format = Format::from_raw(format)
        .ok_or_else(|| Failure::invalid(format!("unknown format {format}")))?;
    Ok(Layout {
        format,
        width,
        height,
        byte_offset,
        pixel_stride,
        row_stride,
    })
}

/// Sets an image stored in a buffer (which the filter holds while the image is set). A
/// NULL or released buffer is TEMC_ERROR_INVALID_ARGUMENT on the filter's device, as in
/// OIDN (temcSetSharedFilterImage with NULL memory unsets the image instead).
/// Names: "color", "albedo", "normal", "depth", "output", "spectral" (see
/// temcSetSharedFilterImage). Strides of 0 mean tightly packed.
///
/// # Safety
/// `name` must be NULL or a NUL-terminated string.
#[no_mangle]
#[allow(clippy::too_many_arguments)]
pub unsafe extern "C" fn temcSetFilterImage(
    filter: TEMCFilter,
    name: *const c_char,
    buffer: TEMCBuffer,
    format: TEMCFormat,
    width: usize,
    height: usize,
    byte_offset: usize,
    pixel_byte_stride: usize,
    row_byte_stride: usize,
) {
    guarded((), |c| {
        // OIDN's order: the filter, then the buffer, whose errors go to the filter's device.
        let f = c.filter(filter)?;
        let b = c.buffer_arg(buffer)?;
        if !Arc::ptr_eq(&b.device, &f.device) {
            return Err(Failure::invalid("the buffer belongs to another device"));
        }
        // SAFETY: the caller's contract.
        let name = unsafe { name_arg(name) }?;
        let l = layout(
            format,
            width,
            height,
            byte_offset,
            pixel_byte_stride,
            row_byte_stride,
        )?;
        let mut st = f.lock_idle();
        st.check_buffer_image(name, &l, &b)?;
        let ptr = b.ptr;
        // SAFETY: the layout fits the buffer, and the state holds the buffer while the
        // image is set.
        unsafe { st.set_image(&f.device, name, ptr, l, Some(b)) }
    })
}

/// Sets an image in the caller's memory: "color" (linear RGB; sRGB-encoded with "srgb"
/// and "hdr" false), "albedo", "normal", "depth" (1 channel), "output" (may be the same
/// memory as "color": in-place), or "spectral": N bands per pixel of one float type
/// (`format` TEMC_FORMAT_FLOAT or TEMC_FORMAT_HALF is the type of one band), N the
/// filter's int "spectralBands", the bands splitting [float "spectralMin", float
/// "spectralMax"] nm (default 380..780) evenly, each band's value its mean spectral
/// radiance; temc converts it with the CIE 1931 colour matching functions to linear sRGB
/// and denoises that (set "spectral" instead of "color"). A pixel stride of 0 means N
/// packed bands. Unknown names are ignored with a warning.
///
/// # Safety
/// `name` must be NULL or a NUL-terminated string; `dev_ptr` must be valid for reads (and
/// writes, for "output") of the bytes the layout spans, from this call until the image is
/// unset or the filter released.
#[no_mangle]
#[allow(clippy::too_many_arguments)]
pub unsafe extern "C" fn temcSetSharedFilterImage(
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
    guarded((), |c| {
        let f = c.filter(filter)?;
        // SAFETY: the caller's contract.
        let name = unsafe { name_arg(name) }?;
        let l = layout(
            format,
            width,
            height,
            byte_offset,
            pixel_byte_stride,
            row_byte_stride,
        )?;
        // SAFETY: the caller's contract.
        let mut st = f.lock_idle();
        // SAFETY: the caller's contract.
        unsafe { st.set_image(&f.device, name, dev_ptr as *mut u8, l, None) }
    })
}

/// Removes an image from the filter.
///
/// # Safety
/// `name` must be NULL or a NUL-terminated string.
#[no_mangle]
pub unsafe extern "C" fn temcUnsetFilterImage(filter: TEMCFilter, name: *const c_char) {
    guarded((), |c| {
        let f = c.filter(filter)?;
        // SAFETY: the caller's contract.
        let name = unsafe { name_arg(name) }?;
        let mut st = f.lock_idle();
        st.unset_image(&f.device, name)
    })
}

/// Deprecated OIDN 1.x name of temcUnsetFilterImage.
///
/// # Safety
/// As temcUnsetFilterImage.
#[no_mangle]
pub unsafe extern "C" fn temcRemoveFilterImage(filter: TEMCFilter, name: *const c_char) {
    // SAFETY: forwarded contract.
    unsafe { temcUnsetFilterImage(filter, name) }
}

/// Sets opaque data: "weights" = a temc ONNX model (copied now and at each
/// temcUpdateFilterData; NULL with 0 bytes unsets it, as in OIDN). Weights that do not
/// load fail the next temcCommitFilter with TEMC_ERROR_INVALID_OPERATION, as in OIDN.
///
/// # Safety
/// `name` must be NULL or a NUL-terminated string; `host_ptr` readable for `byte_size`
/// bytes now and at every temcUpdateFilterData until the data is unset.
#[no_mangle]
pub unsafe extern "C" fn temcSetSharedFilterData(
    filter: TEMCFilter,
    name: *const c_char,
    host_ptr: *mut c_void,
    byte_size: usize,
) {
    guarded((), |c| {
        let f = c.filter(filter)?;
        // SAFETY: the caller's contract.
        let mut st = f.lock_idle();
        // SAFETY: the caller's contract.
        unsafe { st.set_data(&f.device, name_arg(name)?, host_ptr as *const u8, byte_size) }
    })
}

/// Tells the filter that opaque data changed in place (re-reads "weights"; commit again).
///
/// # Safety
/// `name` must be NULL or a NUL-terminated string; the data's memory still readable.
#[no_mangle]
pub unsafe extern "C" fn temcUpdateFilterData(filter: TEMCFilter, name: *const c_char) {
    guarded((), |c| {
        let f = c.filter(filter)?;
        // SAFETY: the caller's contract.
        let mut st = f.lock_idle();
        // SAFETY: the caller's contract.
        unsafe { st.update_data(&f.device, name_arg(name)?) }
    })
}

/// Removes opaque data ("weights").
///
/// # Safety
/// `name` must be NULL or a NUL-terminated string.
#[no_mangle]
pub unsafe extern "C" fn temcUnsetFilterData(filter: TEMCFilter, name: *const c_char) {
    guarded((), |c| {
        let f = c.filter(filter)?;
        // SAFETY: the caller's contract.
        let name = unsafe { name_arg(name) }?;
        let mut st = f.lock_idle();
        st.unset_data(&f.device, name)
    })
}

/// Deprecated OIDN 1.x name of temcUnsetFilterData.
///
/// # Safety
/// As temcUnsetFilterData.
#[no_mangle]
pub unsafe extern "C" fn temcRemoveFilterData(filter: TEMCFilter, name: *const c_char) {
    // SAFETY: forwarded contract.
    unsafe { temcUnsetFilterData(filter, name) }
}

/// Sets an int (or bool: OIDN treats them alike) parameter. Bools: "hdr", "srgb",
/// "cleanAux" (accepted; temc uses the aux as given), "directional" (RTLightmap; true is
/// refused). Ints: "quality" (TEMC_QUALITY_*), "maxMemoryMB" (-1: the default budget),
/// "tileSize", "passes" (the flip ensemble: 1, 2 or 4; 0, the default: the model's own),
/// "spectralBands". Unknown names are ignored with a warning.
///
/// # Safety
/// `name` must be NULL or a NUL-terminated string.
#[no_mangle]
pub unsafe extern "C" fn temcSetFilterInt(filter: TEMCFilter, name: *const c_char, value: i32) {
    guarded((), |c| {
        let f = c.filter(filter)?;
        // SAFETY: the caller's contract.
        let name = unsafe { name_arg(name) }?;
        let mut st = f.lock_idle();
        st.set_int(&f.device, name, value)
    })
}

/// Sets a bool parameter (as temcSetFilterInt with 0 or 1).
///
/// # Safety
/// As temcSetFilterInt.
#[no_mangle]
pub unsafe extern "C" fn temcSetFilterBool(filter: TEMCFilter, name: *const c_char, value: bool) {
    // SAFETY: forwarded contract.
    unsafe { temcSetFilterInt(filter, name, value as i32) }
}

/// Reads an int (or bool) parameter: those of temcSetFilterInt, and the read-only
/// "alignment" and "overlap" (also "tileAlignment", "tileOverlap") of the committed
/// model (0 before commit). Unknown names read 0 with a warning.
///
/// # Safety
/// `name` must be NULL or a NUL-terminated string.
#[no_mangle]
pub unsafe extern "C" fn temcGetFilterInt(filter: TEMCFilter, name: *const c_char) -> i32 {
    guarded(0, |c| {
        let f = c.filter(filter)?;
        // SAFETY: the caller's contract.
        let name = unsafe { name_arg(name) }?;
        let st = f.lock();
        st.get_int(&f.device, name)
    })
}

/// Reads a bool parameter (as temcGetFilterInt, != 0).
///
/// # Safety
/// As temcGetFilterInt.
#[no_mangle]
pub unsafe extern "C" fn temcGetFilterBool(filter: TEMCFilter, name: *const c_char) -> bool {
    // SAFETY: forwarded contract.
    unsafe { temcGetFilterInt(filter, name) != 0 }
}

/// Sets a float parameter: "inputScale" (NaN = automatic exposure), its OIDN 1.x alias
/// "hdrScale", "spectralMin", "spectralMax" (nm). Unknown names: a warning.
///
/// # Safety
/// `name` must be NULL or a NUL-terminated string.
#[no_mangle]
pub unsafe extern "C" fn temcSetFilterFloat(filter: TEMCFilter, name: *const c_char, value: f32) {
    guarded((), |c| {
        let f = c.filter(filter)?;
        // SAFETY: the caller's contract.
        let name = unsafe { name_arg(name) }?;
        let mut st = f.lock_idle();
        st.set_float(&f.device, name, value)
    })
}

/// Reads a float parameter ("inputScale" is NaN while automatic); unknown names read 0.
///
/// # Safety
/// `name` must be NULL or a NUL-terminated string.
#[no_mangle]
pub unsafe extern "C" fn temcGetFilterFloat(filter: TEMCFilter, name: *const c_char) -> f32 {
    guarded(f32::NAN, |c| {
        let f = c.filter(filter)?;
        // SAFETY: the caller's contract.
        let name = unsafe { name_arg(name) }?;
        let st = f.lock();
        st.get_float(&f.device, name)
    })
}

/// Deprecated OIDN 1.x name of temcSetFilterBool.
///
/// # Safety
/// As temcSetFilterInt.
#[no_mangle]
pub unsafe extern "C" fn temcSetFilter1b(filter: TEMCFilter, name: *const c_char, value: bool) {
    // SAFETY: forwarded contract.
    unsafe { temcSetFilterBool(filter, name, value) }
}

/// Deprecated OIDN 1.x name of temcGetFilterBool.
///
/// # Safety
/// As temcGetFilterInt.
#[no_mangle]
pub unsafe extern "C" fn temcGetFilter1b(filter: TEMCFilter, name: *const c_char) -> bool {
    // SAFETY: forwarded contract.
    unsafe { temcGetFilterBool(filter, name) }
}

/// Deprecated OIDN 1.x name of temcSetFilterInt.
///
/// # Safety
/// As temcSetFilterInt.
#[no_mangle]
pub unsafe extern "C" fn temcSetFilter1i(filter: TEMCFilter, name: *const c_char, value: i32) {
    // SAFETY: forwarded contract.
    unsafe { temcSetFilterInt(filter, name, value) }
}

/// Deprecated OIDN 1.x name of temcGetFilterInt.
///
/// # Safety
/// As temcGetFilterInt.
#[no_mangle]
pub unsafe extern "C" fn temcGetFilter1i(filter: TEMCFilter, name: *const c_char) -> i32 {
    // SAFETY: forwarded contract.
    unsafe { temcGetFilterInt(filter, name) }
}

/// Deprecated OIDN 1.x name of temcSetFilterFloat.
///
/// # Safety
/// As temcSetFilterFloat.
#[no_mangle]
pub unsafe extern "C" fn temcSetFilter1f(filter: TEMCFilter, name: *const c_char, value: f32) {
    // SAFETY: forwarded contract.
    unsafe { temcSetFilterFloat(filter, name, value) }
}

/// Deprecated OIDN 1.x name of temcGetFilterFloat.
///
/// # Safety
/// As temcGetFilterFloat.
#[no_mangle]
pub unsafe extern "C" fn temcGetFilter1f(filter: TEMCFilter, name: *const c_char) -> f32 {
    // SAFETY: forwarded contract.
    unsafe { temcGetFilterFloat(filter, name) }
}

/// A C caller's pointer used on temc's threads.
struct SendPtr(*mut c_void);
// SAFETY: the C caller owns the pointer and promises it may be used from the threads temc
// runs on: a progress monitor's user pointer (as OIDN requires of its monitors), the host
// memory of a queued buffer copy (valid until the copy has run, as OIDN requires).
unsafe impl Send for SendPtr {}

/// Sets the progress monitor (NULL removes it); returning false from it cancels execution
/// with TEMC_ERROR_CANCELLED and leaves the output untouched.
///
/// # Safety
/// `func` must be safe to call with `user_ptr` from temc's worker threads while the filter
/// executes, until it is replaced or the filter released.
#[no_mangle]
pub unsafe extern "C" fn temcSetFilterProgressMonitorFunction(
    filter: TEMCFilter,
    func: TEMCProgressMonitorFunction,
    user_ptr: *mut c_void,
) {
    guarded((), |c| {
        let f = c.filter(filter)?;
        let mut st = f.lock_idle();
        match func {
            None => st.core().unset_progress_monitor(),
            Some(cb) => {
                let user = SendPtr(user_ptr);
                st.core().set_progress_monitor(move |n| {
                    let u = &user;
                    // SAFETY: the caller registered this callback for these arguments.
                    unsafe { cb(u.0, n) }
                });
            }
        }
        Ok(())
    })
}

/// Commits the filter's parameters (loads the model). Required after changes. Checks what
/// OIDN's commit checks, failing with TEMC_ERROR_INVALID_OPERATION and OIDN's message: no
/// input, no output, an unsupported format (fewer than 3 channels), input and output of
/// different channel counts, images of another size than the output, "hdr" with "srgb",
/// aux images without colour (beyond "RT"'s one-image prefilter). A filter whose commit
/// failed stays uncommitted. As OIDN's, it first waits for the device's queued work and
/// fails with that work's first error, if any (the filter then stays as it was).
#[no_mangle]
pub extern "C" fn temcCommitFilter(filter: TEMCFilter) {
    guarded((), |c| {
        let f = c.filter(filter)?;
        f.device.sync()?;
        let mut state = f.lock_idle();
        state.commit()
    })
}

/// Runs the filter, after the work queued on its device; returns when it is done. On
/// error nothing is written to the output. As OIDN's, the error reported is the queued
/// work's first, if it failed, else this execution's. The first run at an image size also
/// builds the network's plan for that size (about 0.1 s); the filter keeps the plans of
/// the four sizes it ran most recently.
#[no_mangle]
pub extern "C" fn temcExecuteFilter(filter: TEMCFilter) {
    guarded((), |c| {
        let f = c.filter(filter)?;
        let queued = f.device.sync();
        let own = f.lock_idle().execute();
        queued.and(own)
    })
}

/// Queues an execution of the filter on its device and returns at once (an uncommitted
/// filter is an error now). The execution runs after the work queued before it, with the
/// images and parameters the filter has now: changing the filter waits for its queued
/// executions, and the execution holds the filter (and its buffers) until it has run, so
/// releasing the filter meanwhile is safe. temcSyncDevice waits for it and reports its
/// error. Shared (caller) memory must stay valid until then.
#[no_mangle]
pub extern "C" fn temcExecuteFilterAsync(filter: TEMCFilter) {
    guarded((), |c| c.filter(filter)?.execute_async())
}

/// Executes on a SYCL queue: not possible on the CPU device (TEMC_ERROR_INVALID_OPERATION).
#[no_mangle]
pub extern "C" fn temcExecuteSYCLFilterAsync(
    filter: TEMCFilter,
    _dep_events: *const c_void,
    _num_dep_events: i32,
    _done_event: *mut c_void,
) {
    guarded((), |c| {
        c.filter(filter)?;
        Err(Failure::operation(
            "temcExecuteSYCLFilterAsync needs a SYCL device; use temcExecuteFilterAsync",
        ))
    })
}
