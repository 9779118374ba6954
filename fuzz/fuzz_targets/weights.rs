//! Any bytes given as "weights" are refused with an error at commit, or give a model that
//! denoises a tiny image; never a crash. Seeded with the test models, so mutations stay
//! close to real ONNX files.
#![no_main]
use std::sync::OnceLock;

use libfuzzer_sys::fuzz_target;
use temc::filter::{Device, Filter};

/// One device for the whole run. A device per input dropped its pool every execution,
/// and rayon's worker threads exit after the drop returns: LeakSanitizer's check at the
/// end of an input then sometimes caught a thread-local destructor record (32 bytes from
/// `__cxa_thread_atexit_impl`) of a thread still exiting, a report that did not
/// reproduce when the input was rerun alone (2026-12-02).
fn device() -> &'static Device {
    static DEVICE: OnceLock<Device> = OnceLock::new();
    DEVICE.get_or_init(|| {
        let d = Device::new();
        d.set_num_threads(1);
        d.commit().expect("a one-thread device commits");
        d
    })
}

fuzz_target!(|data: &[u8]| {
    let device = device();
    // Declared before the filters, which borrow it.
    let color = [0.5f32; 8 * 8 * 3];
    for kind in ["AE", "TEMC2"] {
        let Ok(mut f) = Filter::new(device, kind) else {
            continue;
        };
        f.set_weights(data);
        if f.set_input_f32("color", &color, 8, 8).is_err() {
            continue;
        }
        if f.commit().is_ok() {
            if let Ok((out, _)) = f.execute_to_vec() {
                assert_eq!(out.len(), color.len());
            }
        }
    }
});
