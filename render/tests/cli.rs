//! The `temc-render` command line: interruption, scene-file errors, data-set resume, data
//! sets rendered in parts and merged (with `scripts/slurm-render`).

use std::path::PathBuf;
use std::process::Command;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_temc-render"))
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("temc-render-cli-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn ctrl_c_leaves_no_partial_file() {
    let d = tmp("int");
    let out = d.join("long.exr");
    let mut child = bin()
        .args([
            "render",
            "--scene",
            "dark-room",
            "--spp",
            "100000",
            "--size",
            "64x64",
            "-o",
        ])
        .arg(&out)
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(1500));
    unsafe { libc::kill(child.id() as i32, libc::SIGINT) };
    let status = child.wait().unwrap();
    assert_eq!(status.code(), Some(130));
    assert_eq!(
        std::fs::read_dir(&d).unwrap().count(),
        0,
        "something was written"
    );
    std::fs::remove_dir_all(&d).ok();
}

#[test]
fn scene_file_errors_name_the_line() {
    let d = tmp("bad");
    let f = d.join("bad.scene");
    std::fs::write(
        &f,
        "camera eye 0 1 -3 target 0 0 0\nmaterial w diffuse reflectance rgb 0.5 0.5 0.5\n\
         sphere center 0 0 0 radius -1 material w\n",
    )
    .unwrap();
    let o = bin()
        .args(["render", "--spp", "1", "--size", "8x8", "--file"])
        .arg(&f)
        .arg("-o")
        .arg(d.join("x.exr"))
        .output()
        .unwrap();
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("bad.scene:3:") && err.contains("radius"),
        "{err}"
    );
    assert!(!d.join("x.exr").exists());
    std::fs::remove_dir_all(&d).ok();
}

#[test]
fn dataset_renders_splits_and_resumes() {
    let d = tmp("ds");
    let run = || {
        bin()
            .args([
                "dataset",
                "--count",
                "3",
                "--size",
                "16",
                "--spp",
                "1,2",
                "--ref-spp",
                "4",
                "--holdout",
                "1",
            ])
            .arg("--out")
            .arg(&d)
            .output()
            .unwrap()
    };
    let o = run();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("manifest.json")).unwrap()).unwrap();
    let scenes = m["scenes"].as_array().unwrap();
    // Three generated scenes plus, in test, the named stress scenes (all but the furnace)
    // and one scene of each held-out family.
    let families = temc_render::description::held_out::FAMILIES.len();
    assert_eq!(
        scenes.len(),
        3 + temc_render::description::named::NAMED.len() - 1 + families
    );
    let held: Vec<_> = scenes
        .iter()
        .filter(|s| s["name"].as_str().unwrap().starts_with("holdout-"))
        .collect();
    assert_eq!(held.len(), families);
    assert!(held.iter().all(|s| s["split"] == "test"));
    for s in scenes {
        let dir = d.join(s["dir"].as_str().unwrap());
        for f in [
            "scene.txt",
            "spp0001.exr",
            "spp0002.exr",
            "ref.exr",
            "done.json",
        ] {
            assert!(dir.join(f).exists(), "{} lacks {f}", dir.display());
        }
    }
    // Resume: a finished scene is not rendered again.
    let done = d.join(scenes[0]["dir"].as_str().unwrap()).join("ref.exr");
    let before = std::fs::metadata(&done).unwrap().modified().unwrap();
    assert!(run().status.success());
    assert_eq!(
        std::fs::metadata(&done).unwrap().modified().unwrap(),
        before
    );
    // Other settings in the same folder are refused.
    let o = bin()
        .args(["dataset", "--count", "3", "--size", "32", "--out"])
        .arg(&d)
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("other settings"));
    std::fs::remove_dir_all(&d).ok();
}

#[test]
fn render_takes_sampling_modes_and_names_a_bad_one() {
    let d = tmp("sampling");
    let render = |modes: &str| {
        bin()
            .args([
                "render",
                "--scene",
                "cornell-warm",
                "--spp",
                "2",
                "--size",
                "8x8",
            ])
            .args(["--sampling", modes, "-o"])
            .arg(d.join("x.exr"))
            .output()
            .unwrap()
    };
    let o = succeeded(render("bsdf-only,uniform-wavelength"));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("sampling bsdf-only,uniform-wavelength"),
        "{err}"
    );
    let o = render("no-mis,early-rouléte");
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("unknown mode \"early-rouléte\"") && err.contains("early-roulette"),
        "{err}"
    );
    std::fs::remove_dir_all(&d).ok();
}

#[test]
fn dataset_renders_1_spp_inputs_and_records_weak_sampling() {
    let d = tmp("weak");
    let o = bin()
        .args([
            "dataset",
            "--count",
            "3",
            "--size",
            "8",
            "--spp",
            "1,4,16,64,256",
        ])
        .args(["--ref-spp", "4", "--no-named", "--holdout", "0"])
        .args(["--weak-share", "1", "--out"])
        .arg(&d)
        .output()
        .unwrap();
    succeeded(o);
    let m = json(&d.join("manifest.json"));
    let scenes = m["scenes"].as_array().unwrap();
    assert_eq!(scenes.len(), 3);
    for s in scenes {
        let noisy: Vec<&str> = s["noisy"]
            .as_array()
            .unwrap()
            .iter()
            .map(|f| f[1].as_str().unwrap())
            .collect();
        assert_eq!(
            noisy,
            [
                "spp0001.exr",
                "spp0004.exr",
                "spp0016.exr",
                "spp0064.exr",
                "spp0256.exr"
            ]
        );
        for f in noisy {
            assert!(d.join(s["dir"].as_str().unwrap()).join(f).exists());
        }
        let sampling = s["sampling"].as_str().unwrap();
        assert!(sampling
            .parse::<temc_render::Sampling>()
            .is_ok_and(|s| !s.is_default()));
        assert_eq!(m["sampling"][sampling].as_u64().map(|n| n >= 1), Some(true));
    }
    assert_eq!(json(&d.join("dataset.json"))["weak_share"], 1.0);
    std::fs::remove_dir_all(&d).ok();
}

#[test]
fn a_closed_output_pipe_ends_quietly() {
    // `temc-render generate --seed 1 | head -c 1`: the reader is gone before it writes.
    // Rust ignores SIGPIPE, so println! used to panic with a backtrace on stderr.
    use std::process::Stdio;
    let mut child = bin()
        .args(["generate", "--seed", "1"])
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
fn generate_prints_every_family_and_keeps_v2_by_default() {
    let text = |args: &[&str]| {
        let o = succeeded(bin().arg("generate").args(args).output().unwrap());
        String::from_utf8(o.stdout).unwrap()
    };
    let v2 = text(&["--seed", "4"]);
    assert_eq!(v2, text(&["--seed", "4", "--families", "v2"]));
    assert_eq!(v2, temc_render::description::generate::scene_text(4));
    for family in temc_render::description::families::FAMILIES {
        let t = text(&["--seed", "4", "--family", family]);
        assert!(t.starts_with("# Random scene 4 ("), "{family}: {t}");
    }
    let (family, all) = temc_render::description::families::scene(
        temc_render::description::families::Families::All,
        4,
    );
    assert_eq!(text(&["--seed", "4", "--families", "all"]), all, "{family}");
    assert!(text(&["--family", "window"]).starts_with("# Held-out scene 0 (window)"));
    let o = bin()
        .args(["generate", "--family", "attic"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("sun-sky") && err.contains("corridor"));
}

/// `scripts/slurm-render`, run as a Slurm array task would run it.
fn slurm_render() -> Command {
    let mut c = Command::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../scripts/slurm-render"
    ));
    c.env("TEMC_RENDER", env!("CARGO_BIN_EXE_temc-render"));
    for v in [
        "SLURM_ARRAY_TASK_MIN",
        "SLURM_ARRAY_TASK_MAX",
        "SLURM_CPUS_PER_TASK",
        "PARTS",
    ] {
        c.env_remove(v);
    }
    c
}

/// A tiny data set of every kind of scene, with the generated ones rotated (`--start`), so
/// the order a merge must rebuild is not the plain one, and half of them rendered with
/// weak sampling modes.
const TINY_SET: [&str; 17] = [
    "--count",
    "4",
    "--size",
    "8",
    "--spp",
    "1,2",
    "--ref-spp",
    "3",
    "--ref-prefix-spp",
    "2",
    "--holdout",
    "1",
    "--start",
    "1",
    "--weak-share",
    "0.5",
    "--threads=2",
];

fn succeeded(o: std::process::Output) -> std::process::Output {
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    o
}

fn json(path: &std::path::Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// A manifest or record without its render seconds, which no two runs share.
fn without_seconds(mut v: serde_json::Value) -> serde_json::Value {
    if let Some(o) = v.as_object_mut() {
        o.retain(|k, _| !k.starts_with("seconds_"));
        for r in o
            .get_mut("scenes")
            .and_then(|s| s.as_array_mut())
            .into_iter()
            .flatten()
        {
            *r = without_seconds(r.take());
        }
    }
    v
}

#[test]
fn parts_merge_into_what_a_whole_run_writes() {
    let (whole, parts) = (tmp("whole"), tmp("parts"));
    succeeded(
        bin()
            .arg("dataset")
            .args(TINY_SET)
            .arg("--out")
            .arg(&whole)
            .output()
            .unwrap(),
    );
    // Both parts into one folder, as array tasks on a shared file system, second first.
    for i in ["2", "1"] {
        succeeded(
            slurm_render()
                .env("SLURM_ARRAY_TASK_ID", i)
                .env("SLURM_ARRAY_TASK_COUNT", "2")
                .args(TINY_SET)
                .arg("--out")
                .arg(&parts)
                .output()
                .unwrap(),
        );
    }
    let (p1, p2) = (
        json(&parts.join("manifest.part-1-of-2.json")),
        json(&parts.join("manifest.part-2-of-2.json")),
    );
    let sizes = [&p1, &p2].map(|m| m["scenes"].as_array().unwrap().len());
    assert!(sizes[0].abs_diff(sizes[1]) <= 1, "{sizes:?}");
    assert!(
        !parts.join("manifest.json").exists(),
        "a part wrote the set's manifest"
    );
    succeeded(
        slurm_render()
            .args(["merge", "--out"])
            .arg(&parts)
            .output()
            .unwrap(),
    );
    let (a, b) = (
        json(&whole.join("manifest.json")),
        json(&parts.join("manifest.json")),
    );
    let names = |m: &serde_json::Value| -> Vec<String> {
        let scenes = m["scenes"].as_array().unwrap();
        scenes
            .iter()
            .map(|s| s["name"].as_str().unwrap().into())
            .collect()
    };
    assert_eq!(
        names(&b),
        names(&a),
        "the merged order is not a whole run's"
    );
    assert_eq!(without_seconds(b.clone()), without_seconds(a.clone()));
    assert_eq!(b["scenes"].as_array().unwrap().len(), sizes[0] + sizes[1]);
    // Rendering is deterministic (seeded by scene name, per pixel), so every file matches.
    for s in a["scenes"].as_array().unwrap() {
        let dir = s["dir"].as_str().unwrap();
        for f in std::fs::read_dir(whole.join(dir)).unwrap() {
            let name = f.unwrap().file_name();
            let (x, y) = (whole.join(dir).join(&name), parts.join(dir).join(&name));
            if name == "done.json" {
                assert_eq!(without_seconds(json(&y)), without_seconds(json(&x)));
            } else {
                assert!(
                    std::fs::read(&x).unwrap() == std::fs::read(&y).unwrap(),
                    "{}",
                    y.display()
                );
            }
        }
    }
    std::fs::remove_dir_all(&whole).ok();
    std::fs::remove_dir_all(&parts).ok();
}

/// `temc-render merge-manifests --out DIR`'s error, which must not be a panic.
fn merge_error(d: &std::path::Path) -> String {
    let o = bin()
        .args(["merge-manifests", "--out"])
        .arg(d)
        .output()
        .unwrap();
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(!err.contains("panicked"), "{err}");
    err
}

#[test]
fn merge_names_missing_unfinished_and_mismatched_parts() {
    let d = tmp("merge");
    assert!(merge_error(&d).contains("no part manifests"));
    let set = [
        "--count",
        "2",
        "--size",
        "8",
        "--spp",
        "1",
        "--ref-spp",
        "1",
        "--holdout",
        "0",
    ];
    let part = |p: &str| {
        bin()
            .args(["dataset", "--no-named", "--part", p])
            .args(set)
            .arg("--out")
            .arg(&d)
            .output()
            .unwrap()
    };
    succeeded(part("1/2"));
    let err = merge_error(&d);
    assert!(
        err.contains("1 of 2 parts have no manifest") && err.contains("part 2/2"),
        "{err}"
    );
    // Part 2's manifest as it stands before its one scene has finished.
    let mut m = json(&d.join("manifest.part-1-of-2.json"));
    m["part"]["index"] = 2.into();
    m["scenes"] = serde_json::json!([]);
    let write = |m: &serde_json::Value| {
        std::fs::write(d.join("manifest.part-2-of-2.json"), m.to_string()).unwrap()
    };
    write(&m);
    let err = merge_error(&d);
    assert!(
        err.contains("part 2/2 lacks 1 scene(s) (scene-00001)"),
        "{err}"
    );
    let mut other = m.clone();
    other["options"]["seed"] = 99.into();
    write(&other);
    assert!(merge_error(&d).contains("part 2/2 was rendered with other options"));
    m["part"]["start"] = 1.into();
    write(&m);
    assert!(merge_error(&d).contains("--start 1"));
    std::fs::remove_dir_all(&d).ok();
}

#[test]
fn bad_parts_are_refused_with_a_reason() {
    let d = tmp("badpart");
    for (part, says) in [
        ("0/2", "numbered 1 to 2"),
        ("3/2", "numbered 1 to 2"),
        ("1/0", "at least 1"),
        ("two/4", "expected I/N"),
        ("2", "expected I/N"),
    ] {
        let o = bin()
            .args(["dataset", "--count", "1", "--part", part, "--out"])
            .arg(&d)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(
            !o.status.success() && err.contains(says) && !err.contains("panicked"),
            "{part}: {err}"
        );
    }
    assert_eq!(
        std::fs::read_dir(&d).unwrap().count(),
        0,
        "something was written"
    );
    std::fs::remove_dir_all(&d).ok();
}

#[test]
fn slurm_render_submits_the_array_then_a_dependent_merge() {
    let d = tmp("sbatch");
    // A stand-in sbatch that logs its arguments and answers with a job id.
    let sbatch = d.join("sbatch");
    std::fs::write(
        &sbatch,
        "#!/bin/sh\necho \"$@\" >> \"$(dirname \"$0\")/log\"\necho 41\n",
    )
    .unwrap();
    std::fs::set_permissions(&sbatch, std::os::unix::fs::PermissionsExt::from_mode(0o755)).unwrap();
    let path = format!("{}:{}", d.display(), std::env::var("PATH").unwrap());
    succeeded(
        slurm_render()
            .env("PATH", path)
            .args(["submit", "3", "--count", "9", "--out", "data/x"])
            .output()
            .unwrap(),
    );
    let log = std::fs::read_to_string(d.join("log")).unwrap();
    let calls: Vec<&str> = log.lines().collect();
    assert_eq!(calls.len(), 2, "{log}");
    assert!(
        calls[0].contains("--array=1-3") && calls[0].ends_with("--count 9 --out data/x"),
        "{log}"
    );
    assert!(
        calls[1].contains("--dependency=afterok:41")
            && calls[1].ends_with("merge --out data/x --parts 3"),
        "{log}"
    );
    std::fs::remove_dir_all(&d).ok();
}
