//! Correctness of the tracer on scenes with known answers.

use temc_render::{render, scene, Settings};

fn settings(w: usize, h: usize, spp: u32, seed: u64) -> Settings {
    Settings {
        width: w,
        height: h,
        spp,
        seed,
        max_depth: 64,
    }
}

fn luminance(c: [f32; 3]) -> f32 {
    0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]
}

#[test]
fn white_furnace_conserves_energy() {
    // A white Lambertian sphere under a uniform environment of radiance 1 is invisible:
    // every pixel's luminance is 1 (Russian roulette keeps it unbiased).
    let img = render(&scene::furnace(), settings(16, 16, 64, 3), &|_| {});
    let mean: f32 = img.color.iter().map(|&c| luminance(c)).sum::<f32>() / img.color.len() as f32;
    assert!((mean - 1.0).abs() < 0.02, "mean luminance {mean}");
    // The sphere covers the centre: its pixels alone must also average 1.
    let centre = luminance(img.color[8 * 16 + 8]);
    assert!((centre - 1.0).abs() < 0.15, "centre {centre}");
}

#[test]
fn error_falls_as_one_over_spp() {
    // A broad blackbody lamp: the error's tail is light enough for a small test to see
    // the 1/spp law (the spiky lamp's fireflies need far more pixels to average out).
    let sc = scene::named("cornell-warm").unwrap();
    let (w, h) = (24, 24);
    let reference = render(&sc, settings(w, h, 4096, 99), &|_| {});
    let relmse = |spp: u32| {
        let mut e = 0.0f64;
        for seed in 0..4 {
            let img = render(&sc, settings(w, h, spp, 1000 + seed), &|_| {});
            for (a, b) in img.color.iter().zip(&reference.color) {
                for k in 0..3 {
                    let r = b[k] as f64;
                    e += ((a[k] - b[k]) as f64).powi(2) / (r * r + 0.01);
                }
            }
        }
        e
    };
    let (e16, e64) = (relmse(16), relmse(64));
    let ratio = e16 / e64;
    // 4x the samples: about 4x less error.
    assert!(
        ratio > 2.8 && ratio < 5.5,
        "RelMSE ratio 16 spp / 64 spp = {ratio}"
    );
}

#[test]
fn layers_are_finite_and_deterministic() {
    let sc = scene::named("cornell-spiky").unwrap();
    let a = render(&sc, settings(20, 12, 4, 7), &|_| {});
    let b = render(&sc, settings(20, 12, 4, 7), &|_| {});
    assert_eq!(a.color, b.color, "same seed, same image");
    assert!(a.color.iter().flatten().all(|v| v.is_finite()));
    assert!(a
        .spectral
        .iter()
        .flatten()
        .all(|v| v.is_finite() && *v >= 0.0));
    assert!(a.albedo.iter().flatten().all(|v| (0.0..=1.0).contains(v)));
    assert!(a.depth.iter().all(|v| v.is_finite() && *v >= 0.0));
    assert!(a.depth.iter().filter(|v| **v > 0.0).count() > a.depth.len() / 2);
}

#[test]
fn exr_has_every_layer() {
    let sc = scene::named("cornell-spiky").unwrap();
    let img = render(&sc, settings(8, 6, 2, 1), &|_| {});
    let dir = std::env::temp_dir().join(format!("temc-render-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join("r.exr");
    img.write_exr(&p).unwrap();
    // The denoiser's reader finds colour, albedo, normal and depth by their layer names.
    let b = temc::io::read(&p).unwrap();
    assert_eq!((b.width, b.height), (8, 6));
    for (name, v) in [
        ("color", &b.color),
        ("albedo", &b.albedo),
        ("normal", &b.normal),
    ] {
        let v = v.as_ref().unwrap_or_else(|| panic!("{name} missing"));
        assert!(v.iter().all(|x| x.is_finite()), "{name}");
    }
    assert!(b.depth.is_some());
    std::fs::remove_dir_all(&dir).ok();
}
