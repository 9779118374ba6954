//! include/temc.h is generated from src/capi.rs by cbindgen; this test fails when the
//! committed header drifts from the code. `TEMC_BLESS=1 cargo test --release --test
//! c_header` rewrites it, and the version lines of include/temc_config.h (OIDN's config.h
//! under the temc names), which come from Cargo.toml. The hand-written C++ wrapper
//! include/temc.hpp depends on both: it must compile against them, and every temc function
//! and TEMC_ macro it names must be declared there.

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

fn bless() -> bool {
    std::env::var_os("TEMC_BLESS").is_some()
}

#[test]
fn header_matches_capi() {
    let generated = generated_header();
    let path = root().join("include/temc.h");
    if bless() {
        std::fs::write(&path, &generated).unwrap();
        return;
    }
    let committed = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(
        committed == generated,
        "include/temc.h is out of date with src/capi.rs: run TEMC_BLESS=1 cargo test --release --test c_header"
    );
    for name in [
        "#include \"temc_config.h\"",
        "TEMC_API TEMCDevice temcNewDevice(",
        "temcExecuteFilter",
        "temcNewBuffer",
        "temcSetFilterImage",
        "TEMC_ERROR_CANCELLED",
        "TEMC_FORMAT_HALF3",
    ] {
        assert!(generated.contains(name), "{name} missing from the header");
    }
    // The version lives in temc_config.h only, as OIDN's in config.h.
    assert!(!generated.contains("#define TEMC_VERSION"));
}

/// The `#define`s of temc_config.h that come from Cargo.toml, with their values.
fn version_defines() -> Vec<(&'static str, String)> {
    use temc::capi::{TEMC_VERSION, TEMC_VERSION_MAJOR, TEMC_VERSION_MINOR, TEMC_VERSION_PATCH};
    let api = format!("\"{TEMC_VERSION_MAJOR}.{TEMC_VERSION_MINOR}.{TEMC_VERSION_PATCH}\"");
    let lib: Vec<u32> = env!("CARGO_PKG_VERSION")
        .split('.')
        .map(|p| p.parse().expect("a numeric crate version"))
        .collect();
    vec![
        ("TEMC_VERSION_MAJOR", TEMC_VERSION_MAJOR.to_string()),
        ("TEMC_VERSION_MINOR", TEMC_VERSION_MINOR.to_string()),
        ("TEMC_VERSION_PATCH", TEMC_VERSION_PATCH.to_string()),
        ("TEMC_VERSION", TEMC_VERSION.to_string()),
        ("TEMC_VERSION_STRING", api.clone()),
        ("TEMC_VERSION_STRING_SHORT", api),
        ("TEMC_LIBRARY_VERSION_MAJOR", lib[0].to_string()),
        ("TEMC_LIBRARY_VERSION_MINOR", lib[1].to_string()),
        ("TEMC_LIBRARY_VERSION_PATCH", lib[2].to_string()),
        (
            "TEMC_LIBRARY_VERSION",
            (lib[0] * 10000 + lib[1] * 100 + lib[2]).to_string(),
        ),
        (
            "TEMC_LIBRARY_VERSION_STRING",
            format!("\"{}\"", env!("CARGO_PKG_VERSION")),
        ),
    ]
}

/// `text` with the value of each version `#define` set from Cargo.toml.
fn with_versions(text: &str) -> String {
    let defines = version_defines();
    let mut out = String::new();
    for line in text.lines() {
        let name = line
            .strip_prefix("#define ")
            .and_then(|rest| rest.split_whitespace().next());
        match defines.iter().find(|(n, _)| Some(*n) == name) {
            Some((n, v)) => out.push_str(&format!("#define {n} {v}")),
            None => out.push_str(line),
        }
        out.push('\n');
    }
    out
}

/// temc_config.h's version macros are Cargo.toml's: the OIDN API level of
/// `[package.metadata.temc]` (through build.rs and the Rust constants) and the crate's own.
#[test]
fn config_header_versions_come_from_cargo_toml() {
    let path = root().join("include/temc_config.h");
    let committed = std::fs::read_to_string(&path).unwrap();
    let expected = with_versions(&committed);
    if bless() {
        std::fs::write(&path, &expected).unwrap();
        return;
    }
    assert!(
        committed == expected,
        "include/temc_config.h's versions differ from Cargo.toml: run TEMC_BLESS=1 cargo test --release --test c_header"
    );
    for (name, _) in version_defines() {
        assert!(
            committed.contains(&format!("#define {name} ")),
            "{name} missing from temc_config.h"
        );
    }
    // build.rs read the API level from Cargo.toml (the constants above come from it).
    let manifest = std::fs::read_to_string(root().join("Cargo.toml")).unwrap();
    let api = format!(
        "oidn-api-version = \"{}.{}.{}\"",
        temc::capi::TEMC_VERSION_MAJOR,
        temc::capi::TEMC_VERSION_MINOR,
        temc::capi::TEMC_VERSION_PATCH
    );
    assert!(manifest.contains(&api), "Cargo.toml lacks {api}");
    const {
        assert!(
            temc::capi::TEMC_VERSION_MAJOR >= 2,
            "clients' 2.x checks must pass"
        )
    };
}

/// A C99 and a C++11 client see OIDN config.h's macros under the temc names through
/// temc.h alone (the Rust tests compare the device's "version" parameters with them).
#[test]
fn config_macros_compile_in_c_and_cpp() {
    let dir = std::env::temp_dir().join(format!("temc-config-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let checks = "#include \"temc.h\"\n\
        #if TEMC_VERSION != TEMC_VERSION_MAJOR * 10000 + TEMC_VERSION_MINOR * 100 + \
        TEMC_VERSION_PATCH || TEMC_VERSION_MAJOR < 2\n#error version\n#endif\n\
        #if TEMC_LIBRARY_VERSION != TEMC_LIBRARY_VERSION_MAJOR * 10000 + \
        TEMC_LIBRARY_VERSION_MINOR * 100 + TEMC_LIBRARY_VERSION_PATCH\n#error library\n#endif\n\
        #if defined(TEMC_API_NAMESPACE)\n#error no API namespace\n#endif\n\
        #if !defined(TEMC_DEVICE_CPU) || !defined(TEMC_FILTER_RT) || \
        !defined(TEMC_FILTER_RTLIGHTMAP) || defined(TEMC_DEVICE_CUDA)\n#error features\n#endif\n\
        TEMC_API_NAMESPACE_BEGIN\n\
        TEMC_API_EXPORT int temc_probe_exported(void);\n\
        TEMC_API_NAMESPACE_END\n\
        TEMC_API_NAMESPACE_USING\n\
        int temc_probe_exported(void) { return sizeof(TEMC_VERSION_STRING) > 5 && \
        sizeof(TEMC_VERSION_STRING_SHORT) > 5 && sizeof(TEMC_LIBRARY_VERSION_STRING) > 5; }\n\
        TEMC_DEPRECATED(\"old\") int temc_probe_old(void);\n";
    let cpp_checks = "TEMC_NAMESPACE_BEGIN inline int answer() { return 42; } TEMC_NAMESPACE_END\n\
        TEMC_NAMESPACE_USING\n\
        int temc_probe_answer() { return TEMC_NAMESPACE::answer() + answer(); }\n\
        TEMCDevice temc_probe_new() { return temcNewDevice(TEMC_DEVICE_TYPE_CPU); }\n";
    for cpp in [false, true] {
        let src = dir.join(if cpp { "config.cpp" } else { "config.c" });
        let text = if cpp {
            format!("{checks}{cpp_checks}")
        } else {
            checks.to_string()
        };
        std::fs::write(&src, text).unwrap();
        let (compiler, std) = if cpp {
            (
                std::env::var("CXX").unwrap_or_else(|_| "c++".into()),
                "-std=c++11",
            )
        } else {
            (
                std::env::var("CC").unwrap_or_else(|_| "cc".into()),
                "-std=c99",
            )
        };
        let out = Command::new(compiler)
            .args([std, "-Wall", "-Wextra", "-pedantic", "-Werror", "-c", "-I"])
            .arg(root().join("include"))
            .arg(&src)
            .arg("-o")
            .arg(src.with_extension("o"))
            .output()
            .expect("a C/C++ compiler");
        assert!(
            out.status.success(),
            "{}:\n{}",
            src.display(),
            String::from_utf8_lossy(&out.stderr)
        );
        if cpp {
            // TEMC_API made the declaration extern "C": C++ calls the unmangled symbol.
            let nm = Command::new("nm")
                .arg(src.with_extension("o"))
                .output()
                .expect("nm");
            let symbols = String::from_utf8_lossy(&nm.stdout);
            assert!(
                symbols.lines().any(|l| l.ends_with(" U temcNewDevice")),
                "C++ does not call the C symbol temcNewDevice:\n{symbols}"
            );
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn cpp_wrapper_uses_only_what_the_header_declares_and_compiles() {
    let header = std::fs::read_to_string(root().join("include/temc.h")).unwrap()
        + &std::fs::read_to_string(root().join("include/temc_config.h")).unwrap();
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
    // wrapper leaves out too (deprecated 1.x names, SYCL execution, Metal buffers). OIDN
    // 2.5's semaphore calls are wrapped as its clients use them (SemaphoreRef,
    // DeviceRef::newSemaphore, signal/waitSemaphore(s)Async).
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
