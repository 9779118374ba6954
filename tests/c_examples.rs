//! The C and C++ examples, compiled with the system compiler against include/temc.h and the
//! shared library, run as a real C host would: the misuse program asserts every error
//! code, the PFM denoiser's output must equal the Rust API's, bit for bit, and two OIDN
//! 2.x clients renamed to temc (the C buffer example, a C++ pass through temc.hpp) run
//! without errors.

use std::path::{Path, PathBuf};
use std::process::Command;

use temc::filter::{Device, Filter};

mod common;

const MODEL: &str = "tests/data/models/temc2_w0.0625.onnx";

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// Builds libtemc.so for this test profile and the examples; returns the examples' folder.
fn build_examples() -> PathBuf {
    // Tests run in parallel: build once.
    static BUILT: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();
    BUILT.get_or_init(build_examples_once).clone()
}

fn build_examples_once() -> PathBuf {
    let lib = common::built_library();
    let out = lib.parent().expect("target folder").join("c-examples");
    let status = Command::new("make")
        .current_dir(root().join("c-examples"))
        .arg(format!("TEMC_LIB={}", lib.display()))
        .arg(format!("OUT={}", out.display()))
        .status()
        .expect("make");
    assert!(status.success(), "building c-examples failed");
    out
}

fn write_pfm(path: &Path, w: usize, h: usize, rgb: &[f32]) {
    temc::io::write_rgb(path, w, h, rgb).unwrap();
}

fn read_pfm(path: &Path) -> (usize, usize, Vec<f32>) {
    let b = temc::io::pfm::read(path).unwrap();
    (b.width, b.height, b.color.expect("RGB PFM"))
}

#[test]
fn c_examples_build_and_behave() {
    let bin = build_examples();
    let model = root().join(MODEL);

    let misuse = Command::new(bin.join("misuse"))
        .arg(&model)
        .output()
        .unwrap();
    assert!(
        misuse.status.success(),
        "misuse checks failed:\n{}",
        String::from_utf8_lossy(&misuse.stderr)
    );

    let cpp = Command::new(bin.join("denoise_cpp"))
        .arg(&model)
        .output()
        .unwrap();
    assert!(
        cpp.status.success(),
        "{}",
        String::from_utf8_lossy(&cpp.stderr)
    );

    // OIDN 2.x clients, renamed: the C buffer example and a C++ renderer pass (temc.hpp);
    // OIDN's commit-time checks through the C++ wrapper.
    for prog in ["buffers", "oidn_client", "commit_checks"] {
        let run = Command::new(bin.join(prog)).output().unwrap();
        assert!(
            run.status.success(),
            "{prog} failed:\n{}{}",
            String::from_utf8_lossy(&run.stdout),
            String::from_utf8_lossy(&run.stderr)
        );
    }

    // PFM round trip through the C program, against the Rust API on the same inputs.
    let (w, h) = (75, 50);
    let color: Vec<f32> = (0..w * h * 3)
        .map(|i| 0.1 + (i % 29) as f32 * 0.05)
        .collect();
    let albedo: Vec<f32> = (0..w * h * 3).map(|i| (i % 7) as f32 / 7.0).collect();
    let normal: Vec<f32> = (0..w * h * 3)
        .map(|i| if i % 3 == 2 { 1.0 } else { 0.0 })
        .collect();
    let dir = std::env::temp_dir().join(format!("temc-c-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    write_pfm(&dir.join("color.pfm"), w, h, &color);
    write_pfm(&dir.join("albedo.pfm"), w, h, &albedo);
    write_pfm(&dir.join("normal.pfm"), w, h, &normal);
    let run = Command::new(bin.join("denoise"))
        .args(["-m".as_ref(), model.as_os_str()])
        .arg(dir.join("color.pfm"))
        .args(["-a".as_ref(), dir.join("albedo.pfm").as_os_str()])
        .args(["-n".as_ref(), dir.join("normal.pfm").as_os_str()])
        .args(["-o".as_ref(), dir.join("out.pfm").as_os_str()])
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let (ow, oh, from_c) = read_pfm(&dir.join("out.pfm"));
    assert_eq!((ow, oh), (w, h));

    let device = Device::new();
    device.commit().unwrap();
    let weights = std::fs::read(&model).unwrap();
    let mut from_rust = vec![0f32; w * h * 3];
    let mut f = Filter::new(&device, "TEMC2").unwrap();
    f.set_weights(&weights);
    f.set_input_f32("color", &color, w, h).unwrap();
    f.set_input_f32("albedo", &albedo, w, h).unwrap();
    f.set_input_f32("normal", &normal, w, h).unwrap();
    f.set_output_f32(&mut from_rust, w, h).unwrap();
    f.commit().unwrap();
    f.execute().unwrap();
    drop(f);
    assert_eq!(
        from_c, from_rust,
        "the C API and the Rust API must agree exactly"
    );

    // The built-in fast model, chosen by quality alone, through both APIs.
    let run = Command::new(bin.join("denoise"))
        .arg(dir.join("color.pfm"))
        .args(["-q", "fast", "-o"])
        .arg(dir.join("fast.pfm"))
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let mut f = Filter::new(&device, "TEMC2").unwrap();
    f.set_quality(temc::filter::Quality::Fast);
    f.set_input_f32("color", &color, w, h).unwrap();
    f.commit().unwrap();
    let (fast_rust, _) = f.execute_to_vec().unwrap();
    assert_eq!(read_pfm(&dir.join("fast.pfm")).2, fast_rust);
    assert_ne!(
        fast_rust, from_rust,
        "the built-in model is not the test model"
    );

    // Bad input files give a non-zero exit and no output.
    std::fs::write(dir.join("bad.pfm"), b"P6\n1 1\n255\n").unwrap();
    let bad = Command::new(bin.join("denoise"))
        .arg(dir.join("bad.pfm"))
        .args(["-o".as_ref(), dir.join("bad_out.pfm").as_os_str()])
        .output()
        .unwrap();
    assert!(!bad.status.success());
    assert!(!dir.join("bad_out.pfm").exists());
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn installed_tree_links_through_pkg_config() {
    build_examples(); // the release (or debug) library this test profile uses
    let release = !cfg!(debug_assertions);
    if !release {
        return; // `make install` installs the release build
    }
    let target =
        std::env::var_os("CARGO_TARGET_DIR").map_or_else(|| root().join("target"), PathBuf::from);
    let dir = std::env::temp_dir().join(format!("temc-install-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let prefix = dir.join("prefix");
    let status = Command::new("make")
        .current_dir(root())
        .args(["--quiet", "install-only"])
        .arg(format!("PREFIX={}", prefix.display()))
        .arg(format!("TARGET_DIR={}", target.display()))
        .status()
        .expect("make");
    assert!(status.success(), "make install-only failed");
    let lib = prefix.join("lib");
    for f in [
        "libtemc.so",
        "libtemc.so.0",
        "libtemc.a",
        "pkgconfig/temc.pc",
    ] {
        assert!(lib.join(f).exists(), "{f} not installed");
    }
    for h in ["temc.h", "temc_config.h", "temc.hpp"] {
        assert!(prefix.join("include").join(h).exists(), "{h} not installed");
    }
    let soname = Command::new("readelf")
        .arg("-d")
        .arg(lib.join("libtemc.so"))
        .output()
        .unwrap();
    assert!(String::from_utf8_lossy(&soname.stdout).contains("[libtemc.so.0]"));

    // Build the PFM example from the installed tree only, shared and static.
    let src = root().join("c-examples/denoise.c");
    let sh = |script: String| {
        let out = Command::new("sh")
            .arg("-c")
            .arg(&script)
            .env("PKG_CONFIG_PATH", lib.join("pkgconfig"))
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{script}\n{}",
            String::from_utf8_lossy(&out.stderr)
        );
    };
    let (shared, fixed) = (dir.join("denoise_shared"), dir.join("denoise_static"));
    sh(format!(
        "cc -std=c99 -O2 -Wall -Werror {src} -o {out} $(pkg-config --cflags --libs temc) \
         -Wl,-rpath,$(pkg-config --variable=libdir temc)",
        src = src.display(),
        out = shared.display()
    ));
    sh(format!(
        "cc -std=c99 -O2 -Wall -Werror {src} -o {out} $(pkg-config --cflags temc) \
         $(pkg-config --variable=libdir temc)/libtemc.a \
         $(pkg-config --static --libs-only-l temc | sed 's/-ltemc//')",
        src = src.display(),
        out = fixed.display()
    ));
    let (w, h) = (37, 21);
    let color: Vec<f32> = (0..w * h * 3).map(|i| (i % 17) as f32 / 17.0).collect();
    write_pfm(&dir.join("c.pfm"), w, h, &color);
    let mut outs = Vec::new();
    for (bin, name) in [(&shared, "s.pfm"), (&fixed, "t.pfm")] {
        // The built-in model: the installed library carries its weights.
        let run = Command::new(bin)
            .arg(dir.join("c.pfm"))
            .arg("-o")
            .arg(dir.join(name))
            .output()
            .unwrap();
        assert!(
            run.status.success(),
            "{}",
            String::from_utf8_lossy(&run.stderr)
        );
        outs.push(read_pfm(&dir.join(name)).2);
    }
    assert_eq!(outs[0], outs[1], "shared and static builds must agree");

    // Uninstall takes away everything install put there.
    let status = Command::new("make")
        .current_dir(root())
        .args(["--quiet", "uninstall"])
        .arg(format!("PREFIX={}", prefix.display()))
        .status()
        .expect("make");
    assert!(status.success(), "make uninstall failed");
    for d in ["include", "lib", "lib/pkgconfig"] {
        let left: Vec<_> = std::fs::read_dir(prefix.join(d))
            .unwrap()
            .filter_map(|e| e.ok())
            .filter(|e| e.file_type().is_ok_and(|t| !t.is_dir()))
            .map(|e| e.file_name())
            .collect();
        assert!(left.is_empty(), "left in {d}: {left:?}");
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// `make lib` leaves a build folder a C program links against and runs from: the
/// linker finds libtemc.so, and the loader the SONAME libtemc.so.0 it asks for, by
/// LD_LIBRARY_PATH alone (no rpath, nothing installed).
#[test]
fn a_c_program_links_and_runs_from_the_build_folder() {
    build_examples(); // this test profile's libtemc.so
    let release = !cfg!(debug_assertions);
    if !release {
        return; // `make lib` builds the release library
    }
    let target =
        std::env::var_os("CARGO_TARGET_DIR").map_or_else(|| root().join("target"), PathBuf::from);
    // A copy of the build folder, so that the other tests' programs, which load
    // target/release/libtemc.so.0, never see it missing; cargo's part of `make lib` is
    // done (CARGO=true), the rest of the recipe runs as written.
    let dir = std::env::temp_dir().join(format!("temc-buildfolder-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let lib = dir.join("release");
    std::fs::create_dir_all(&lib).unwrap();
    std::fs::copy(target.join("release/libtemc.so"), lib.join("libtemc.so")).unwrap();
    let status = Command::new("make")
        .current_dir(root())
        .args(["--quiet", "lib", "CARGO=true"])
        .arg(format!("TARGET_DIR={}", dir.display()))
        .status()
        .expect("make");
    assert!(status.success(), "make lib failed");
    let link = std::fs::read_link(lib.join("libtemc.so.0")).expect("libtemc.so.0 is a link");
    assert_eq!(link, Path::new("libtemc.so"));

    let exe = dir.join("denoise");
    let cc = std::env::var("CC").unwrap_or_else(|_| "cc".into());
    let out = Command::new(cc)
        .args(["-std=c99", "-O2", "-Wall", "-Werror", "-I"])
        .arg(root().join("include"))
        .arg(root().join("c-examples/denoise.c"))
        .arg("-o")
        .arg(&exe)
        .arg(format!("-L{}", lib.display()))
        .args(["-ltemc", "-lm"])
        .output()
        .expect("a C compiler");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let needed = Command::new("readelf")
        .arg("-d")
        .arg(&exe)
        .output()
        .unwrap();
    assert!(
        String::from_utf8_lossy(&needed.stdout).contains("[libtemc.so.0]"),
        "the program asks for the SONAME"
    );
    let (w, h) = (19, 13);
    let color: Vec<f32> = (0..w * h * 3).map(|i| (i % 11) as f32 / 11.0).collect();
    write_pfm(&dir.join("c.pfm"), w, h, &color);
    let run = |with_path: bool| {
        let mut cmd = Command::new(&exe);
        cmd.arg(dir.join("c.pfm"))
            .args(["-q", "fast", "-o"])
            .arg(dir.join("o.pfm"))
            .env_remove("LD_LIBRARY_PATH");
        if with_path {
            cmd.env("LD_LIBRARY_PATH", &lib);
        }
        cmd.output().unwrap()
    };
    // Without the path the loader has no libtemc.so.0 to find (cargo's LD_LIBRARY_PATH is
    // removed), unless one is installed system-wide.
    let installed = Command::new("ldconfig")
        .arg("-p")
        .output()
        .is_ok_and(|o| String::from_utf8_lossy(&o.stdout).contains("libtemc.so.0"));
    if !installed {
        let without = run(false);
        assert!(
            !without.status.success()
                && String::from_utf8_lossy(&without.stderr).contains("libtemc.so.0"),
            "{}",
            String::from_utf8_lossy(&without.stderr)
        );
    }
    let with = run(true);
    assert!(
        with.status.success(),
        "{}",
        String::from_utf8_lossy(&with.stderr)
    );
    let (ow, oh, denoised) = read_pfm(&dir.join("o.pfm"));
    assert_eq!((ow, oh), (w, h));
    assert!(denoised.iter().all(|v| v.is_finite()));
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn c_programs_run_clean_under_asan_and_valgrind() {
    let bin = build_examples();
    let status = Command::new("make")
        .current_dir(root().join("c-examples"))
        .arg("asan")
        .arg(format!("OUT={}", bin.display()))
        .arg(format!(
            "TEMC_LIB={}",
            bin.parent()
                .unwrap()
                .join(if cfg!(debug_assertions) {
                    "debug"
                } else {
                    "release"
                })
                .display()
        ))
        .status()
        .expect("make asan");
    assert!(status.success(), "building the ASan programs failed");
    let dir = std::env::temp_dir().join(format!("temc-san-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (w, h) = (29, 17);
    let color: Vec<f32> = (0..w * h * 3).map(|i| (i % 13) as f32 / 5.0).collect();
    write_pfm(&dir.join("c.pfm"), w, h, &color);
    write_pfm(&dir.join("a.pfm"), w, h, &vec![0.5; w * h * 3]);
    let model = root().join(MODEL);
    let denoise_args = |out: &str| -> Vec<std::ffi::OsString> {
        vec![
            "-m".into(),
            model.clone().into(),
            dir.join("c.pfm").into(),
            "-a".into(),
            dir.join("a.pfm").into(),
            "-o".into(),
            dir.join(out).into(),
        ]
    };
    let check = |what: &str, out: std::process::Output| {
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            out.status.success() && !err.contains("Sanitizer") && !err.contains("definitely lost"),
            "{what}: {}\n{err}",
            out.status
        );
    };
    // AddressSanitizer with leak detection.
    let asan = |prog: &str, args: Vec<std::ffi::OsString>| {
        Command::new(bin.join("asan").join(prog))
            .args(args)
            .env("ASAN_OPTIONS", "detect_leaks=1")
            .output()
            .unwrap()
    };
    check(
        "misuse under ASan",
        asan("misuse", vec![model.clone().into()]),
    );
    check(
        "denoise under ASan",
        asan("denoise", denoise_args("asan.pfm")),
    );
    check("buffers under ASan", asan("buffers", vec![]));
    check("oidn_client under ASan", asan("oidn_client", vec![]));
    check("commit_checks under ASan", asan("commit_checks", vec![]));
    // Valgrind's memcheck on the plain builds: no invalid access, nothing definitely or
    // indirectly lost.
    let vg = |prog: &str, args: Vec<std::ffi::OsString>| {
        Command::new("valgrind")
            .args([
                "-q",
                "--error-exitcode=99",
                "--leak-check=full",
                "--errors-for-leak-kinds=definite,indirect",
            ])
            .arg(bin.join(prog))
            .args(args)
            .output()
            .expect("valgrind must be installed (apt-get install valgrind)")
    };
    check(
        "misuse under valgrind",
        vg("misuse", vec![model.clone().into()]),
    );
    check(
        "denoise under valgrind",
        vg("denoise", denoise_args("vg.pfm")),
    );
    check("buffers under valgrind", vg("buffers", vec![]));
    assert_eq!(
        read_pfm(&dir.join("asan.pfm")).2,
        read_pfm(&dir.join("vg.pfm")).2
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// libtemc.so exports every function OIDN 2.5.1's library does (renamed oidn -> temc), so
/// an OIDN 2.5 client links; the only extras are OIDN's header-inline functions, which
/// temc exports as real symbols (the README lists both).
#[test]
fn exports_cover_oidn_2_5_1() {
    build_examples();
    let target =
        std::env::var_os("CARGO_TARGET_DIR").map_or_else(|| root().join("target"), PathBuf::from);
    let lib = target
        .join(if cfg!(debug_assertions) {
            "debug"
        } else {
            "release"
        })
        .join("libtemc.so");
    let nm = Command::new("nm")
        .args(["-D", "--defined-only"])
        .arg(&lib)
        .output()
        .expect("nm");
    let exported: std::collections::BTreeSet<String> = String::from_utf8_lossy(&nm.stdout)
        .lines()
        .filter_map(|l| l.split_whitespace().nth(2))
        .map(str::to_string)
        .collect();
    let oidn = std::fs::read_to_string(root().join("tests/data/oidn-2.5.1-exports.txt")).unwrap();
    let wanted: std::collections::BTreeSet<String> = oidn
        .lines()
        .filter(|l| !l.starts_with('#') && !l.is_empty())
        .map(|l| l.replacen("oidn", "temc", 1))
        .collect();
    assert_eq!(wanted.len(), 70, "OIDN 2.5.1 exports 70 functions");
    let missing: Vec<_> = wanted.difference(&exported).collect();
    assert!(
        missing.is_empty(),
        "OIDN 2.5.1 functions temc lacks: {missing:?}"
    );
    let extra: Vec<_> = exported.difference(&wanted).map(String::as_str).collect();
    assert_eq!(
        extra,
        [
            "temcGetDevice1b",
            "temcGetDevice1i",
            "temcGetDeviceUInt",
            "temcGetFilter1b",
            "temcGetFilter1f",
            "temcGetFilter1i",
            "temcGetPhysicalDeviceUInt",
            "temcRemoveFilterData",
            "temcRemoveFilterImage",
            "temcSetDevice1b",
            "temcSetDevice1i",
            "temcSetDeviceUInt",
            "temcSetFilter1b",
            "temcSetFilter1f",
            "temcSetFilter1i",
        ],
        "exports beyond OIDN's: only its header-inline functions"
    );
}
