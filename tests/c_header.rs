//! include/temc.h is generated from src/capi.rs by cbindgen; this test fails when the
//! committed header drifts from the code. `TEMC_BLESS=1 cargo test --release --test
//! c_header` rewrites it.

use std::path::Path;

#[test]
fn header_matches_capi() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let config = cbindgen::Config::from_file(root.join("cbindgen.toml")).expect("cbindgen.toml");
    let mut generated = Vec::new();
    cbindgen::Builder::new()
        .with_config(config)
        .with_src(root.join("src/capi.rs"))
        .generate()
        .expect("cbindgen")
        .write(&mut generated);
    let generated = String::from_utf8(generated).unwrap();
    let path = root.join("include/temc.h");
    if std::env::var_os("TEMC_BLESS").is_some() {
        std::fs::write(&path, &generated).unwrap();
        return;
    }
    let committed = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(
        committed == generated,
        "include/temc.h is out of date with src/capi.rs: run TEMC_BLESS=1 cargo test --release --test c_header"
    );
    for name in [
        "temcNewDevice",
        "temcExecuteFilter",
        "TEMC_ERROR_CANCELLED",
        "TEMC_FORMAT_HALF3",
    ] {
        assert!(generated.contains(name), "{name} missing from the header");
    }
}
