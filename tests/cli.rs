//! `temc denoise` end to end on PFM and EXR files.

use std::path::{Path, PathBuf};
use std::process::Command;

const MODEL: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/tests/data/models/temc2_w0.0625.onnx"
);

fn temc() -> Command {
    Command::new(env!("CARGO_BIN_EXE_temc"))
}

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("temc-cli-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn image(w: usize, h: usize) -> Vec<f32> {
    (0..w * h * 3)
        .map(|i| 0.05 + ((i * 7919) % 101) as f32 / 50.0)
        .collect()
}

fn finite_rgb(path: &Path) -> (usize, usize, Vec<f32>) {
    let b = temc::io::read(path).unwrap();
    let c = b.color.unwrap();
    assert!(c.iter().all(|v| v.is_finite() && *v >= 0.0));
    (b.width, b.height, c)
}

/// A one-layer EXR holding `channels` (full names such as `color.R`).
fn write_exr(
    path: &Path,
    w: usize,
    h: usize,
    channels: Vec<exr::prelude::AnyChannel<exr::prelude::FlatSamples>>,
) {
    use exr::prelude::*;
    let layer = Layer::new(
        (w, h),
        LayerAttributes::default(),
        Encoding::FAST_LOSSLESS,
        AnyChannels::sort(channels.into()),
    );
    Image::from_layer(layer).write().to_file(path).unwrap();
}

#[test]
fn denoise_pfm_and_exr_with_json_report() {
    let d = scratch("formats");
    let (w, h) = (70, 45);
    temc::io::write_rgb(&d.join("in.pfm"), w, h, &image(w, h)).unwrap();
    temc::io::write_rgb(&d.join("in.exr"), w, h, &image(w, h)).unwrap();
    temc::io::write_rgb(&d.join("albedo.pfm"), w, h, &vec![0.5; w * h * 3]).unwrap();
    for (input, output) in [
        ("in.pfm", "out.pfm"),
        ("in.exr", "out.exr"),
        ("in.pfm", "out2.exr"),
    ] {
        let out = temc()
            .args(["denoise", "--model", MODEL, "--json", "--threads", "2"])
            .arg("--color")
            .arg(d.join(input))
            .arg("--albedo")
            .arg(d.join("albedo.pfm"))
            .arg("-o")
            .arg(d.join(output))
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        assert_eq!(report["width"], w);
        assert_eq!(report["aux"]["albedo"], true);
        assert!(report["tiles"].as_u64().unwrap() >= 1);
        assert!(report["seconds"]["denoise"].as_f64().unwrap() > 0.0);
        assert!(report["peak_rss_mb"].as_f64().unwrap() > 0.0);
        let (ow, oh, _) = finite_rgb(&d.join(output));
        assert_eq!((ow, oh), (w, h));
    }
    // Same input through PFM and EXR gives the same pixels.
    assert_eq!(
        finite_rgb(&d.join("out.pfm")).2,
        finite_rgb(&d.join("out.exr")).2
    );
    std::fs::remove_dir_all(&d).ok();
}

#[test]
fn failures_exit_non_zero_and_leave_no_output() {
    let d = scratch("fail");
    temc::io::write_rgb(&d.join("in.pfm"), 20, 10, &image(20, 10)).unwrap();
    temc::io::write_rgb(&d.join("albedo.pfm"), 21, 10, &image(21, 10)).unwrap();
    std::fs::write(d.join("garbage.exr"), b"definitely not an exr").unwrap();
    let cases: Vec<Vec<PathBuf>> = vec![
        vec!["--color".into(), d.join("missing.pfm")],
        vec![
            "--color".into(),
            d.join("in.pfm"),
            "--passes".into(),
            "3".into(),
        ],
        vec!["--color".into(), d.join("garbage.exr")],
        vec![
            "--color".into(),
            d.join("in.pfm"),
            "--albedo".into(),
            d.join("albedo.pfm"),
        ],
    ];
    for args in cases {
        let out = temc()
            .args(["denoise", "--model", MODEL])
            .args(&args)
            .arg("-o")
            .arg(d.join("out.pfm"))
            .output()
            .unwrap();
        assert!(!out.status.success(), "{args:?}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.starts_with("temc: "), "{err}");
        assert!(!d.join("out.pfm").exists(), "{args:?} left an output");
    }
    // A model file that is not there: a clear message naming it, no output.
    let out = temc()
        .args(["denoise", "--model", "no-such-model.onnx", "--color"])
        .arg(d.join("in.pfm"))
        .arg("-o")
        .arg(d.join("out.pfm"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("no-such-model.onnx"));
    assert!(!d.join("out.pfm").exists());
    // No model: the built-in TEMC-2 of the quality mode runs; the modes differ, and high
    // is balanced over two flip passes (the JSON report says how many ran).
    for (quality, name, passes) in [
        ("balanced", "b.pfm", 1),
        ("fast", "f.pfm", 1),
        ("high", "h.pfm", 2),
    ] {
        let out = temc()
            .args(["denoise", "--json", "--quality", quality, "--color"])
            .arg(d.join("in.pfm"))
            .arg("-o")
            .arg(d.join(name))
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        assert_eq!(report["passes"], passes, "{quality}");
    }
    let read = |name: &str| std::fs::read(d.join(name)).unwrap();
    assert_ne!(read("b.pfm"), read("f.pfm"));
    assert_ne!(read("b.pfm"), read("h.pfm"));
    // No temporary files left behind by any of it.
    let leftovers: Vec<_> = std::fs::read_dir(&d)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().contains(".tmp"))
        .collect();
    assert!(leftovers.is_empty());
    std::fs::remove_dir_all(&d).ok();
}

#[test]
fn info_prints_the_model_card() {
    let out = temc().args(["info", MODEL, "--json"]).output().unwrap();
    assert!(out.status.success());
    let card: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(card["temc.architecture"], "temc2");
}

#[test]
fn a_closed_output_pipe_ends_quietly() {
    // `temc info m.onnx | head -c 1`: the reader is gone before temc writes. Rust ignores
    // SIGPIPE, so println! used to panic with a backtrace on stderr.
    use std::process::Stdio;
    let mut child = temc()
        .args(["info", MODEL, "--json"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!err.contains("panicked"), "{err}");
}

#[test]
fn color_only_ignores_aux_layers_in_the_colour_file() {
    use exr::prelude::*;
    let d = scratch("color-only");
    let (w, h) = (40, 30);
    let names = [
        "color.R", "color.G", "color.B", "albedo.R", "albedo.G", "albedo.B", "normal.X",
        "normal.Y", "normal.Z", "depth.Z",
    ];
    let ch: Vec<AnyChannel<FlatSamples>> = names
        .iter()
        .map(|n| AnyChannel::new(*n, FlatSamples::F32(vec![0.5; w * h])))
        .collect();
    write_exr(&d.join("in.exr"), w, h, ch);
    // Which aux layers each flag keeps: (albedo, normal, depth).
    for (flags, expect) in [
        (&[][..], [true, true, true]),
        (&["--color-only"][..], [false, false, false]),
        (&["--aux", "none"][..], [false, false, false]),
        (&["--aux", "albedo"][..], [true, false, false]),
        (&["--aux", "full"][..], [true, true, true]),
    ] {
        let mut cmd = temc();
        cmd.args(["denoise", "--model", MODEL, "--json", "--color"])
            .arg(d.join("in.exr"))
            .arg("-o")
            .arg(d.join("out.pfm"))
            .args(flags);
        let out = cmd.output().unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        for (aux, want) in ["albedo", "normal", "depth"].iter().zip(expect) {
            assert_eq!(report["aux"][aux], want, "{flags:?} {aux}");
        }
    }
    // --color-only with an explicit aux file is a contradiction.
    let out = temc()
        .args(["denoise", "--model", MODEL, "--color-only", "--color"])
        .arg(d.join("in.exr"))
        .arg("--albedo")
        .arg(d.join("in.exr"))
        .arg("-o")
        .arg(d.join("x.pfm"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    std::fs::remove_dir_all(&d).ok();
}

#[test]
fn bench_reports_timings() {
    let out = temc()
        .args([
            "bench", "--model", MODEL, "--size", "64x48", "--repeat", "2", "--aux", "albedo",
            "--json",
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let r: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(
        (r["width"].as_u64(), r["height"].as_u64()),
        (Some(64), Some(48))
    );
    assert_eq!(r["seconds"].as_array().unwrap().len(), 2);
    assert!(r["median_seconds"].as_f64().unwrap() > 0.0);
    assert_eq!(r["aux"], "albedo");
    let bad = temc()
        .args(["bench", "--model", MODEL, "--size", "0x5"])
        .output()
        .unwrap();
    assert!(!bad.status.success());
}

/// temc-render's `spectral` layer: with `--spectral` (or when the file has no RGB colour)
/// the colour is the bands' linear sRGB, so denoising the spectral layer equals denoising
/// its conversion written as RGB; a file without the layer is refused.
#[test]
fn the_spectral_layer_is_denoised_through_the_cie_observer() {
    use exr::prelude::*;
    let d = scratch("spectral");
    let (w, h, bands) = (24, 20, 16);
    let value =
        |i: usize, b: usize| 0.2 + 0.05 * b as f32 + ((i * 7919 + b * 31) % 53) as f32 / 80.0;
    let mut ch: Vec<AnyChannel<FlatSamples>> = (0..bands)
        .map(|b| {
            let v = (0..w * h).map(|i| value(i, b)).collect();
            AnyChannel::new(format!("spectral.b{b:02}").as_str(), FlatSamples::F32(v))
        })
        .collect();
    write_exr(&d.join("spectral.exr"), w, h, ch.clone());
    let conv = temc::color::SpectralBands::uniform(bands, 380.0, 780.0).unwrap();
    let px: Vec<f32> = (0..w * h)
        .flat_map(|i| (0..bands).map(move |b| value(i, b)))
        .collect();
    temc::io::write_rgb(&d.join("rgb.pfm"), w, h, &conv.image_to_linear_srgb(&px)).unwrap();
    for c in ["R", "G", "B"] {
        ch.push(AnyChannel::new(
            format!("color.{c}").as_str(),
            FlatSamples::F32(vec![0.0; w * h]),
        ));
    }
    write_exr(&d.join("both.exr"), w, h, ch);
    let run = |input: &str, flags: &[&str], out: &str| {
        temc()
            .args(["denoise", "--model", MODEL, "--threads", "1", "--color"])
            .arg(d.join(input))
            .args(flags)
            .arg("-o")
            .arg(d.join(out))
            .output()
            .unwrap()
    };
    let want = {
        assert!(run("rgb.pfm", &[], "want.pfm").status.success());
        finite_rgb(&d.join("want.pfm")).2
    };
    for (input, flags) in [("spectral.exr", &[][..]), ("both.exr", &["--spectral"][..])] {
        let out = run(input, flags, "got.pfm");
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert_eq!(finite_rgb(&d.join("got.pfm")).2, want, "{input} {flags:?}");
    }
    let out = run("rgb.pfm", &["--spectral"], "no.pfm");
    assert!(!out.status.success() && !d.join("no.pfm").exists());
    assert!(String::from_utf8_lossy(&out.stderr).contains("no spectral layer"));
    let out = run(
        "spectral.exr",
        &["--spectral", "--spectral-range", "700,400"],
        "no.pfm",
    );
    assert!(!out.status.success() && !d.join("no.pfm").exists());
    std::fs::remove_dir_all(&d).ok();
}
