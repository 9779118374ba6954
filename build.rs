//! Gives the shared library a versioned SONAME on Linux, so an installed libtemc.so.0 can
//! be upgraded in place and programs link against the ABI major version.
fn main() {
    if std::env::var("CARGO_CFG_TARGET_OS").as_deref() == Ok("linux") {
        let major = std::env::var("CARGO_PKG_VERSION_MAJOR").unwrap_or_else(|_| "0".into());
        println!("cargo:rustc-cdylib-link-arg=-Wl,-soname,libtemc.so.{major}");
    }
}
