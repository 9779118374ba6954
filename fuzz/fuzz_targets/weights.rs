//! Any bytes given as "weights" are refused with an error at commit, or give a model that
//! denoises a tiny image; never a crash. Seeded with the test models, so mutations stay
//! close to real ONNX files.
#![no_main]
use libfuzzer_sys::fuzz_target;
use temc::filter::{Device, Filter};

fuzz_target!(|data: &[u8]| {
    let device = Device::new();
    device.set_num_threads(1);
    if device.commit().is_err() {
        return;
    }
    // Declared before the filters, which borrow it.
    let color = [0.5f32; 8 * 8 * 3];
    for kind in ["AE", "TEMC2"] {
        let Ok(mut f) = Filter::new(&device, kind) else {
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
