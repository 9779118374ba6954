//! The objects behind C handles, error recording, and the one guard every entry point runs in.

use std::collections::HashMap;
use std::ffi::{c_char, c_void, CStr, CString};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::ThreadId;

pub(crate) use super::failure::{Failure, Outcome};
use super::filter_state::{FilterDevice, FilterState, ImageBuffer};
use super::queue::Queue;
use super::registry::Registry;
use super::{
    TEMCBuffer, TEMCDevice, TEMCError, TEMCErrorFunction, TEMCFilter, TEMCStorage, TEMC_ERROR_NONE,
    TEMC_ERROR_OUT_OF_MEMORY, TEMC_ERROR_UNKNOWN, TEMC_STORAGE_HOST,
};
use crate::filter::Device;

struct ErrorState {
    /// Per thread, as OIDN keeps a device's errors: a thread sees the errors of its own
    /// calls, so two threads sharing a device do not take each other's.
    first: HashMap<ThreadId, (TEMCError, CString)>,
    /// Per thread, the message last handed out by temcGetDeviceError; valid until that
    /// thread's next query.
    returned: HashMap<ThreadId, CString>,
    callback: TEMCErrorFunction,
    user_ptr: usize,
}

/// A device: the core's [`Device`] plus the error state and the queue of the C ABI.
pub(crate) struct DeviceObj {
    pub device: Device,
    errors: Mutex<ErrorState>,
    pub set_affinity: AtomicBool,
    /// The work of the `Async` calls, in order.
    pub queue: Queue,
}

impl DeviceObj {
    pub fn new() -> Self {
        Self {
            device: Device::new(),
            errors: Mutex::new(ErrorState {
                first: HashMap::new(),
                returned: HashMap::new(),
                callback: None,
                user_ptr: 0,
            }),
            set_affinity: AtomicBool::new(true),
            queue: Queue::default(),
        }
    }

    /// OIDN's waitAndThrow: waits for the queued work and fails with its first error.
    pub fn sync(&self) -> Outcome<()> {
        self.queue.wait_idle();
        self.queue.take_error().map_or(Ok(()), Err)
    }

    fn errors(&self) -> MutexGuard<'_, ErrorState> {
        self.errors.lock().unwrap_or_else(|e| e.into_inner())
    }

    pub fn set_error_function(&self, func: TEMCErrorFunction, user_ptr: *mut c_void) {
        let mut st = self.errors();
        st.callback = func;
        st.user_ptr = user_ptr as usize;
    }

    /// OIDN's warning for a parameter it does not know: printed when verbose, never an error.
    pub fn warn(&self, message: &str) {
        if self.device.verbose() >= 1 {
            eprintln!("temc: warning: {message}");
        }
    }
}

impl FilterDevice for DeviceObj {
    fn device(&self) -> &Device {
        &self.device
    }

    fn warn(&self, message: &str) {
        DeviceObj::warn(self, message)
    }
}

/// A filter: its device (kept alive by the filter) and its state.
pub(crate) struct FilterObj {
    pub device: Arc<DeviceObj>,
    state: Mutex<FilterState>,
    /// Executions of this filter queued on the device and not finished. While there are
    /// any, the state stays as they were queued with: changes wait ([`Self::lock_idle`]),
    /// as OIDN's queued work keeps the images and parameters it was submitted with.
    queued: Mutex<usize>,
    /// Signalled when `queued` drops.
    idle: Condvar,
}

/// The filter's state with none of its executions queued; holding it keeps others from
/// being queued, so the state can change.
pub(crate) struct IdleFilter<'a> {
    _queued: MutexGuard<'a, usize>,
    state: MutexGuard<'a, FilterState>,
}

impl std::ops::Deref for IdleFilter<'_> {
    type Target = FilterState;
    fn deref(&self) -> &FilterState {
        &self.state
    }
}

impl std::ops::DerefMut for IdleFilter<'_> {
    fn deref_mut(&mut self) -> &mut FilterState {
        &mut self.state
    }
}

/// Ends a queued execution's count, also when it panics.
struct Finished<'a>(&'a FilterObj);

impl Drop for Finished<'_> {
    fn drop(&mut self) {
        *self.0.queued() -= 1;
        self.0.idle.notify_all();
    }
}

impl FilterObj {
    pub fn new(device: Arc<DeviceObj>, state: FilterState) -> Self {
        Self {
            device,
            state: Mutex::new(state),
            queued: Mutex::new(0),
            idle: Condvar::new(),
        }
    }

    /// The state, for reading (or for running it: queued executions hold it while they run).
    pub fn lock(&self) -> MutexGuard<'_, FilterState> {
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn queued(&self) -> MutexGuard<'_, usize> {
        self.queued.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The state, for changing it or running it now: after this filter's queued
    /// executions. Lock order: `queued`, then `state`.
    pub fn lock_idle(&self) -> IdleFilter<'_> {
        let queued = self
            .idle
            .wait_while(self.queued(), |n| *n > 0)
            .unwrap_or_else(|e| e.into_inner());
        IdleFilter {
            _queued: queued,
            state: self.lock(),
        }
    }

    /// Queues an execution on the device and returns. Whether the filter is committed is
    /// checked now, as OIDN does; while executions are queued it cannot have changed.
    pub fn execute_async(self: &Arc<Self>) -> Outcome<()> {
        let mut queued = self.queued();
        if *queued == 0 {
            self.lock().check_committed()?;
        }
        let filter = self.clone();
        self.device.queue.push(Box::new(move || {
            let _done = Finished(&filter);
            // Unlocked before `_done` counts the execution finished.
            let mut state = filter.lock();
            state.execute()
        }))?;
        // Counted under the lock the job's end takes, so it cannot end before this.
        *queued += 1;
        Ok(())
    }
}

/// A buffer: host memory, owned (New*Buffer) or the caller's (NewSharedBuffer).
pub(crate) struct BufferObj {
    pub device: Arc<DeviceObj>,
    pub ptr: *mut u8,
    pub size: usize,
    pub storage: TEMCStorage,
    /// The allocation to free, for owned buffers.
    owned: Option<std::alloc::Layout>,
}

// SAFETY: the buffer's bytes are plain memory; concurrent access to them is the C
// caller's responsibility, as in OIDN. The struct itself is immutable after creation.
unsafe impl Send for BufferObj {}
// SAFETY: as for Send.
unsafe impl Sync for BufferObj {}

/// Owned buffers are aligned for any SIMD load the core might use.
const BUFFER_ALIGN: usize = 64;

impl BufferObj {
    /// A zeroed host buffer of `size` bytes.
    pub fn owned(device: Arc<DeviceObj>, size: usize, storage: TEMCStorage) -> Outcome<Self> {
        if size == 0 {
            return Ok(Self {
                device,
                ptr: std::ptr::null_mut(),
                size,
                storage,
                owned: None,
            });
        }
        let layout = std::alloc::Layout::from_size_align(size, BUFFER_ALIGN).map_err(|_| {
            Failure::new(
                TEMC_ERROR_OUT_OF_MEMORY,
                format!("buffer of {size} bytes is too large"),
            )
        })?;
        // SAFETY: the layout has a non-zero size.
        let ptr = unsafe { std::alloc::alloc_zeroed(layout) };
        if ptr.is_null() {
            return Err(Failure::new(
                TEMC_ERROR_OUT_OF_MEMORY,
                format!("cannot allocate a buffer of {size} bytes"),
            ));
        }
        Ok(Self {
            device,
            ptr,
            size,
            storage,
            owned: Some(layout),
        })
    }

    /// A buffer over the caller's memory (which must outlive it).
    pub fn shared(device: Arc<DeviceObj>, ptr: *mut u8, size: usize) -> Self {
        Self {
            device,
            ptr,
            size,
            storage: TEMC_STORAGE_HOST,
            owned: None,
        }
    }

    /// Checks that `[offset, offset + len)` lies in the buffer.
    pub fn check_range(&self, offset: usize, len: usize) -> Outcome<()> {
        match offset.checked_add(len) {
            Some(end) if end <= self.size => Ok(()),
            _ => Err(Failure::invalid(format!(
                "range of {len} bytes at offset {offset} exceeds the buffer's {} bytes",
                self.size
            ))),
        }
    }
}

impl ImageBuffer for BufferObj {
    fn size(&self) -> usize {
        self.size
    }
}

impl Drop for BufferObj {
    fn drop(&mut self) {
        if let Some(layout) = self.owned {
            // SAFETY: allocated in `owned` with this layout; no image refers to it any more
            // (filters hold the buffer while an image of it is set).
            unsafe { std::alloc::dealloc(self.ptr, layout) };
        }
    }
}

/// The live devices, filters and buffers.
pub(crate) static DEVICES: Registry<DeviceObj> = Registry::new(1);
pub(crate) static FILTERS: Registry<FilterObj> = Registry::new(2);
pub(crate) static BUFFERS: Registry<BufferObj> = Registry::new(3);

thread_local! {
    /// Errors with no device to hold them (device creation, NULL or dead handles), per
    /// thread as in OIDN: the slot and the message last handed out.
    static GLOBAL_ERROR: std::cell::RefCell<(Option<(TEMCError, CString)>, CString)> =
        std::cell::RefCell::new((None, CString::default()));
}

fn cstring(s: String) -> CString {
    CString::new(s.replace('\0', " ")).unwrap_or_default()
}

/// Stores an error (the first one wins until queried) and calls the device's error
/// function. The function is called after the lock is released, so it may call back into
/// temc (temcGetDeviceError included) without deadlocking.
pub(crate) fn record(device: Option<&DeviceObj>, code: TEMCError, message: String) {
    let message = cstring(message);
    match device {
        Some(d) => {
            let callback = {
                let mut st = d.errors();
                st.first
                    .entry(std::thread::current().id())
                    .or_insert_with(|| (code, message.clone()));
                st.callback.map(|cb| (cb, st.user_ptr))
            };
            if let Some((cb, user)) = callback {
                // SAFETY: the caller registered this function for exactly these arguments
                // (temcSetDeviceErrorFunction's contract).
                unsafe { cb(user as *mut c_void, code, message.as_ptr()) };
            }
        }
        None => GLOBAL_ERROR.with(|g| {
            let mut g = g.borrow_mut();
            if g.0.is_none() {
                g.0 = Some((code, message));
            }
        }),
    }
}

/// Takes the first unqueried error of `device` (or of this thread, for None); the message
/// pointer stays valid until the next query.
pub(crate) fn take_error(device: Option<&DeviceObj>) -> (TEMCError, *const c_char) {
    let take = |slot: &mut Option<(TEMCError, CString)>, returned: &mut CString| {
        let (c, m) = slot.take().unwrap_or((TEMC_ERROR_NONE, CString::default()));
        *returned = m;
        let p = if c == TEMC_ERROR_NONE {
            std::ptr::null()
        } else {
            returned.as_ptr()
        };
        (c, p)
    };
    match device {
        Some(d) => {
            let mut st = d.errors();
            let st = &mut *st;
            let me = std::thread::current().id();
            let mut slot = st.first.remove(&me);
            take(&mut slot, st.returned.entry(me).or_default())
        }
        None => GLOBAL_ERROR.with(|g| {
            let mut g = g.borrow_mut();
            let (slot, returned) = &mut *g;
            take(slot, returned)
        }),
    }
}

/// What an entry point has resolved so far: the device its errors go to.
pub(crate) struct Call {
    device: Option<Arc<DeviceObj>>,
}

impl Call {
    /// The live device behind `h`; its errors are recorded on it from now on.
    pub fn device(&mut self, h: TEMCDevice) -> Outcome<Arc<DeviceObj>> {
        if h.is_null() {
            return Err(Failure::invalid("NULL device"));
        }
        let d = DEVICES
            .get(h.addr())
            .ok_or_else(|| Failure::invalid("invalid or released device handle"))?;
        self.device = Some(d.clone());
        Ok(d)
    }

    /// The live filter behind `h`; errors go to its device.
    pub fn filter(&mut self, h: TEMCFilter) -> Outcome<Arc<FilterObj>> {
        if h.is_null() {
            return Err(Failure::invalid("NULL filter"));
        }
        let f = FILTERS
            .get(h.addr())
            .ok_or_else(|| Failure::invalid("invalid or released filter handle"))?;
        self.device = Some(f.device.clone());
        Ok(f)
    }

    /// The live buffer behind `h`; errors go to its device.
    pub fn buffer(&mut self, h: TEMCBuffer) -> Outcome<Arc<BufferObj>> {
        let b = Self::live_buffer(h)?;
        self.device = Some(b.device.clone());
        Ok(b)
    }

    /// The live buffer behind `h` as an argument of a call on another object (a filter's
    /// image): errors stay with the device already resolved, as OIDN reports them.
    pub fn buffer_arg(&mut self, h: TEMCBuffer) -> Outcome<Arc<BufferObj>> {
        Self::live_buffer(h)
    }

    fn live_buffer(h: TEMCBuffer) -> Outcome<Arc<BufferObj>> {
        if h.is_null() {
            return Err(Failure::invalid("NULL buffer"));
        }
        BUFFERS
            .get(h.addr())
            .ok_or_else(|| Failure::invalid("invalid or released buffer handle"))
    }
}

/// Runs an entry point's body: catches panics, records a failure (or a panic) on the
/// device the body resolved (or as this thread's global error), and returns `fallback`
/// then. Every extern "C" function of the ABI goes through here, so no panic crosses into
/// C and every failure is reported one way.
pub(crate) fn guarded<T>(fallback: T, body: impl FnOnce(&mut Call) -> Outcome<T>) -> T {
    let mut call = Call { device: None };
    let result = catch_unwind(AssertUnwindSafe(|| body(&mut call)));
    let failure = match result {
        Ok(Ok(v)) => return v,
        Ok(Err(f)) => f,
        Err(_) => Failure::new(TEMC_ERROR_UNKNOWN, "internal error (panic)"),
    };
    // Recording cannot panic in practice; if it did, swallowing it is still better than
    // unwinding into C.
    let _ = catch_unwind(AssertUnwindSafe(|| {
        record(call.device.as_deref(), failure.code, failure.message)
    }));
    fallback
}

/// Reads a parameter name.
///
/// # Safety
/// `name` must be NULL or a NUL-terminated string.
pub(crate) unsafe fn name_arg<'a>(name: *const c_char) -> Outcome<&'a str> {
    if name.is_null() {
        return Err(Failure::invalid("NULL name"));
    }
    // SAFETY: the caller passes a NUL-terminated string.
    unsafe { CStr::from_ptr(name) }
        .to_str()
        .map_err(|_| Failure::invalid("name is not UTF-8"))
}

/// Whether a device's "setAffinity" is set (OIDN's default: true).
pub(crate) fn affinity(d: &DeviceObj) -> bool {
    d.set_affinity.load(Ordering::Relaxed)
}
