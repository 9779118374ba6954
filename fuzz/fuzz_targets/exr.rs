//! Any bytes given to the EXR reader give an image or an error, never a crash or an
//! allocation the file cannot justify.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(b) = temc::io::exr::parse(data, "fuzz") {
        let n = b.width * b.height;
        for v in [&b.color, &b.albedo, &b.normal].into_iter().flatten() {
            assert_eq!(v.len(), 3 * n);
        }
    }
});
