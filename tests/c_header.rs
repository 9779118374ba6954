//! include/temc.h is generated from src/capi.rs by cbindgen; this test fails when the
//! committed header drifts from the code. `TEMC_BLESS=1 cargo test --release --test
//! c_header` rewrites it. The hand-written C++ wrapper include/temc.hpp depends on it: it
//! must compile against the header, and every temc function and TEMC_ macro it names must
//! be declared there.

use std::collections::BTreeSet;
use std::path::Path;
use std::process::Command;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn generated_header() -> String {
    let config = cbindgen::Config::from_file(root().join("cbindgen.toml")).expect("cbindgen.toml");
    let mut generated = Vec::new();
    cbindgen::Builder::new()
        .with_config(config)
        .with_src(root().join("src/capi.rs"))
        .generate()
        .expect("cbindgen")
        .write(&mut generated);
    String::from_utf8(generated).unwrap()
}

/// The identifiers in `text` that start with `prefix` followed by an upper-case letter.
fn names(text: &str, prefix: &str) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    let mut rest = text;
    while let Some(i) = rest.find(prefix) {
        let before = rest[..i].chars().next_back();
        let tail = &rest[i..];
        let end = tail
            .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
            .unwrap_or(tail.len());
        let ident = &tail[..end];
        let next = ident[prefix.len()..].chars().next();
        if !before.is_some_and(|c| c.is_ascii_alphanumeric() || c == '_')
            && next.is_some_and(|c| c.is_ascii_uppercase())
        {
            out.insert(ident.to_string());
        }
        rest = &tail[end.max(1)..];
    }
    out
}

#[test]
fn header_matches_capi() {
    let generated = generated_header();
    let path = root().join("include/temc.h");
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
        "temcNewBuffer",
        "temcSetFilterImage",
        "TEMC_ERROR_CANCELLED",
        "TEMC_FORMAT_HALF3",
        "TEMC_VERSION_MAJOR",
        "TEMC_NAMESPACE_BEGIN",
    ] {
        assert!(generated.contains(name), "{name} missing from the header");
    }
}

/// The version string macro (hand-written in cbindgen.toml) agrees with the numbers.
#[test]
fn version_macros_agree() {
    let h = generated_header();
    let v = format!(
        "#define TEMC_VERSION_STRING \"{}.{}.{}\"",
        temc::capi::TEMC_VERSION_MAJOR,
        temc::capi::TEMC_VERSION_MINOR,
        temc::capi::TEMC_VERSION_PATCH
    );
    assert!(h.contains(&v), "expected {v} in the header");
    assert_eq!(
        temc::capi::TEMC_VERSION,
        temc::capi::TEMC_VERSION_MAJOR * 10000
            + temc::capi::TEMC_VERSION_MINOR * 100
            + temc::capi::TEMC_VERSION_PATCH
    );
    const {
        assert!(
            temc::capi::TEMC_VERSION_MAJOR >= 2,
            "clients' 2.x checks must pass"
        )
    };
}

#[test]
fn cpp_wrapper_uses_only_what_the_header_declares_and_compiles() {
    let header = std::fs::read_to_string(root().join("include/temc.h")).unwrap();
    let hpp = std::fs::read_to_string(root().join("include/temc.hpp")).unwrap();
    let declared: BTreeSet<String> = names(&header, "temc")
        .into_iter()
        .chain(names(&header, "TEMC"))
        .chain(names(&header, "TEMC_"))
        .collect();
    let used: BTreeSet<String> = names(&hpp, "temc")
        .into_iter()
        .chain(names(&hpp, "TEMC_"))
        .filter(|n| n != "TEMC_HPP")
        .collect();
    let missing: Vec<_> = used.difference(&declared).collect();
    assert!(
        missing.is_empty(),
        "temc.hpp uses names temc.h lacks: {missing:?}"
    );
    // Every C function the header declares has a C++ counterpart, except the ones OIDN's
    // wrapper leaves out too (deprecated 1.x names, SYCL execution, Metal buffers).
    let functions: BTreeSet<String> = names(&header, "temc")
        .into_iter()
        .filter(|n| header.contains(&format!("{n}(")))
        .collect();
    let unwrapped: Vec<_> = functions
        .iter()
        .filter(|f| !used.contains(*f))
        .filter(|f| {
            !(f.ends_with("1b")
                || f.ends_with("1i")
                || f.ends_with("1f")
                || f.starts_with("temcRemove")
                || f.contains("SYCL")
                || *f == "temcNewSharedBufferFromMetal"
                || *f == "temcGetPhysicalDeviceUInt" && used.contains("temcGetPhysicalDeviceInt"))
        })
        .collect();
    assert!(
        unwrapped.iter().all(|f| *f == "temcGetPhysicalDeviceUInt"),
        "temc.h functions temc.hpp does not wrap: {unwrapped:?}"
    );
    // Compile it, C++11, with the examples' warnings and -pedantic.
    let out = std::env::temp_dir().join(format!("temc-hpp-{}.o", std::process::id()));
    let src = std::env::temp_dir().join(format!("temc-hpp-{}.cpp", std::process::id()));
    std::fs::write(
        &src,
        "#include \"temc.hpp\"\nint main() { temc::DeviceRef d = temc::newDevice(); \
         temc::FilterRef f = d.newFilter(\"RT\"); (void)f.get<int>(\"quality\"); \
         return d ? 0 : 1; }\n",
    )
    .unwrap();
    let cxx = std::env::var("CXX").unwrap_or_else(|_| "c++".into());
    let result = Command::new(&cxx)
        .args([
            "-std=c++11",
            "-Wall",
            "-Wextra",
            "-pedantic",
            "-Werror",
            "-c",
            "-I",
        ])
        .arg(root().join("include"))
        .arg(&src)
        .arg("-o")
        .arg(&out)
        .output()
        .expect("a C++ compiler");
    let _ = std::fs::remove_file(&src);
    let _ = std::fs::remove_file(&out);
    assert!(
        result.status.success(),
        "temc.hpp does not compile against temc.h:\n{}",
        String::from_utf8_lossy(&result.stderr)
    );
}
