//! Any text given to the renderer's scene parser gives a scene or a line-numbered error;
//! a scene that parses can be inspected and a tiny image rendered from it.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    match temc_render::description::format::parse(text, "fuzz", None) {
        Ok(scene) => {
            let _ = scene.features();
            let img = temc_render::render(
                &scene,
                &temc_render::Settings {
                    width: 4,
                    height: 3,
                    spp: 1,
                    max_depth: 4,
                    ..Default::default()
                },
            );
            assert_eq!(img.color.len(), 12);
        }
        Err(e) => assert!(e.starts_with("fuzz"), "{e}"),
    }
});
