//! Any bytes given to the PFM reader give an image or an error, never a crash.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(b) = temc::io::pfm::parse(data, "fuzz") {
        let n = b.width * b.height;
        assert!(b.color.as_ref().map_or(true, |c| c.len() == 3 * n));
        assert!(b.depth.as_ref().map_or(true, |d| d.len() == n));
    }
});
