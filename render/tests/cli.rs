//! The `temc-render` command line: interruption, scene-file errors, data-set resume.

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
