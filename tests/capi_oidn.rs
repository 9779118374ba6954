//! The C ABI's OIDN semantics, driven from Rust.
