//! Gives the shared library a versioned SONAME on Linux, so an installed libtemc.so.0 can
//! be upgraded in place and programs link against the ABI major version; and hands the OIDN
//! API level of `[package.metadata.temc]` in Cargo.toml to src/capi.rs, so the C ABI's
//! version has one source (tests/c_header.rs holds the header to it too).
fn main() {
    println!("cargo:rerun-if-changed=Cargo.toml");
    println!("cargo:rerun-if-changed=build.rs");
    if std::env::var("CARGO_CFG_TARGET_OS").as_deref() == Ok("linux") {
        let major = std::env::var("CARGO_PKG_VERSION_MAJOR").unwrap_or_else(|_| "0".into());
        println!("cargo:rustc-cdylib-link-arg=-Wl,-soname,libtemc.so.{major}");
    }
    let manifest = std::fs::read_to_string("Cargo.toml").expect("Cargo.toml");
    let version = oidn_api_version(&manifest)
        .expect("Cargo.toml: [package.metadata.temc] oidn-api-version = \"MAJOR.MINOR.PATCH\"");
    println!("cargo:rustc-env=TEMC_OIDN_API_VERSION={version}");
}

/// `oidn-api-version` of the `[package.metadata.temc]` table, checked to be three numbers.
/// (A line scan: build scripts get no TOML parser without a build dependency.)
fn oidn_api_version(manifest: &str) -> Option<String> {
    let mut in_table = false;
    for line in manifest.lines().map(str::trim) {
        if line.starts_with('[') {
            in_table = line == "[package.metadata.temc]";
        } else if in_table {
            let Some(value) = line.strip_prefix("oidn-api-version") else {
                continue;
            };
            let v = value.trim().strip_prefix('=')?.trim().trim_matches('"');
            let ok = v.split('.').count() == 3 && v.split('.').all(|p| p.parse::<u32>().is_ok());
            return ok.then(|| v.to_string());
        }
    }
    None
}
