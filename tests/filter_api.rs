//! The filter through its public Rust API: invariance to tiles and threads, in-place,
//! non-finite inputs, errors that leave the output untouched, cancellation.
//! The model is the untrained TEMC-2 test model: these tests are about the machinery,
//! not about denoising quality.

mod common;

use common::{device, test_model as model_file};
use temc::color;
use temc::engine::PLAN_CACHE_SIZES;
use temc::filter::{filter_type_for, Filter, Quality};
use temc::Error;

fn weights() -> Vec<u8> {
    model_file("temc2")
}

/// A smooth, colourful HDR test image with some structure.
fn image(w: usize, h: usize) -> Vec<f32> {
    let mut v = Vec::with_capacity(w * h * 3);
    for y in 0..h {
        for x in 0..w {
            let (fx, fy) = (x as f32 / w as f32, y as f32 / h as f32);
            v.push(0.05 + 2.0 * fx * fx + 0.3 * ((x / 7 + y / 5) % 2) as f32);
            v.push(0.4 + 0.3 * (fy * 9.0).sin());
            v.push(0.2 + 5.0 * fx * fy);
        }
    }
    v
}

struct Run {
    output: Vec<f32>,
    tiles: usize,
}

fn denoise(color: &[f32], w: usize, h: usize, threads: usize, tile: usize) -> Run {
    denoise_with("temc2", color, w, h, threads, tile)
}

fn denoise_with(arch: &str, color: &[f32], w: usize, h: usize, threads: usize, tile: usize) -> Run {
    let dev = device(threads);
    let model = model_file(arch);
    let mut output = vec![0f32; w * h * 3];
    let mut f = Filter::new(&dev, filter_type_for(arch).unwrap()).unwrap();
    f.set_weights(&model);
    f.set_input_f32("color", color, w, h).unwrap();
    f.set_output_f32(&mut output, w, h).unwrap();
    f.set_input_scale(1.0).unwrap();
    f.set_tile_size(tile);
    f.commit().unwrap();
    let stats = f.execute().unwrap();
    drop(f);
    Run {
        output,
        tiles: stats.tiles,
    }
}

/// Largest difference of two linear images after PQ encoding each channel.
fn max_pq_diff(a: &[f32], b: &[f32]) -> f32 {
    let pq = |v: f32| color::pq::encode(v as f64 * 100.0 / 10000.0) as f32;
    a.iter()
        .zip(b)
        .map(|(x, y)| (pq(*x) - pq(*y)).abs())
        .fold(0.0, f32::max)
}

#[test]
fn tiled_equals_untiled_within_1e3_pq() {
    let (w, h) = (1000, 700);
    let img = image(w, h);
    let untiled = denoise(&img, w, h, 2, 4096);
    let tiled = denoise(&img, w, h, 2, 64);
    assert_eq!(untiled.tiles, 1);
    assert!(tiled.tiles > 20, "{} tiles", tiled.tiles);
    let d = max_pq_diff(&untiled.output, &tiled.output);
    println!("max PQ difference, untiled vs 64-pixel tiles: {d:e}");
    assert!(d <= 1e-3, "{d}");
}

#[test]
fn one_and_two_threads_are_bit_identical() {
    // The autoencoder's smaller receptive field gives many tiles at a low cost.
    let (w, h) = (500, 300);
    let img = image(w, h);
    let a = denoise_with("ae", &img, w, h, 1, 32);
    let b = denoise_with("ae", &img, w, h, 2, 32);
    assert!(a.tiles > 4, "{} tiles", a.tiles);
    assert_eq!(a.output, b.output);
}

#[test]
fn in_place_matches_separate_output() {
    let (w, h) = (130, 70);
    let img = image(w, h);
    let separate = denoise(&img, w, h, 2, 32);
    let dev = device(2);
    let model = weights();
    let mut buf = img.clone();
    let mut f = Filter::new(&dev, "TEMC2").unwrap();
    f.set_weights(&model);
    f.set_input_scale(1.0).unwrap();
    f.set_tile_size(32);
    let layout = temc::image::Layout::packed(temc::image::Format::Float3, w, h);
    // SAFETY: `buf` outlives the filter and is not otherwise used while it runs.
    unsafe {
        f.set_shared_image("color", buf.as_mut_ptr() as *mut u8, layout)
            .unwrap();
        f.set_shared_image("output", buf.as_mut_ptr() as *mut u8, layout)
            .unwrap();
    }
    f.commit().unwrap();
    f.execute().unwrap();
    drop(f);
    assert_eq!(buf, separate.output);
}

#[test]
fn non_finite_and_extreme_inputs_give_finite_output() {
    let (w, h) = (64, 48);
    let mut img = image(w, h);
    img[0] = f32::NAN;
    img[4] = f32::INFINITY;
    img[8] = f32::NEG_INFINITY;
    img[12] = -5.0;
    img[30] = 1e30;
    img[60] = f32::from_bits(1);
    for scale in [None, Some(1e-6), Some(1e6)] {
        let dev = device(2);
        let model = weights();
        let mut out = vec![0f32; w * h * 3];
        let mut f = Filter::new(&dev, "TEMC2").unwrap();
        f.set_weights(&model);
        f.set_input_f32("color", &img, w, h).unwrap();
        f.set_output_f32(&mut out, w, h).unwrap();
        if let Some(s) = scale {
            f.set_input_scale(s).unwrap();
        }
        f.commit().unwrap();
        f.execute().unwrap();
        drop(f);
        assert!(
            out.iter().all(|v| v.is_finite() && *v >= 0.0),
            "scale {scale:?}"
        );
    }
}

#[test]
fn tiny_and_odd_sizes() {
    for (w, h) in [(1, 1), (1, 37), (33, 1), (31, 33)] {
        let img = image(w, h);
        let r = denoise(&img, w, h, 2, 0);
        assert_eq!(r.output.len(), w * h * 3);
        assert!(r.output.iter().all(|v| v.is_finite()));
    }
}

#[test]
fn aux_buffers_change_the_result_and_nan_aux_is_harmless() {
    let (w, h) = (64, 64);
    let img = image(w, h);
    let plain = denoise(&img, w, h, 1, 0).output;
    let dev = device(1);
    let model = weights();
    let albedo = vec![0.7f32; w * h * 3];
    let mut normal = vec![0f32; w * h * 3];
    for n in normal.chunks_mut(3) {
        n[2] = 1.0;
    }
    normal[0] = f32::NAN;
    let mut depth = vec![3.0f32; w * h];
    depth[5] = f32::INFINITY;
    let mut out = vec![0f32; w * h * 3];
    let mut f = Filter::new(&dev, "TEMC2").unwrap();
    f.set_weights(&model);
    f.set_input_f32("color", &img, w, h).unwrap();
    f.set_input_f32("albedo", &albedo, w, h).unwrap();
    f.set_input_f32("normal", &normal, w, h).unwrap();
    f.set_input_f32("depth", &depth, w, h).unwrap();
    f.set_output_f32(&mut out, w, h).unwrap();
    f.set_input_scale(1.0).unwrap();
    f.commit().unwrap();
    f.execute().unwrap();
    drop(f);
    assert!(out.iter().all(|v| v.is_finite()));
    assert_ne!(out, plain);
}

#[test]
fn errors_leave_the_output_untouched() {
    let (w, h) = (40, 30);
    let img = image(w, h);
    let dev = device(1);
    let model = weights();
    let sentinel = vec![-7.0f32; w * h * 3];

    // Execute before commit.
    let mut out = sentinel.clone();
    {
        let mut f = Filter::new(&dev, "TEMC2").unwrap();
        f.set_weights(&model);
        f.set_input_f32("color", &img, w, h).unwrap();
        f.set_output_f32(&mut out, w, h).unwrap();
        assert!(matches!(f.execute(), Err(Error::InvalidOperation(_))));
    }
    assert_eq!(out, sentinel);

    // Size mismatch between color and output.
    let mut small = vec![-7.0f32; (w - 1) * h * 3];
    {
        let mut f = Filter::new(&dev, "TEMC2").unwrap();
        f.set_weights(&model);
        f.set_input_f32("color", &img, w, h).unwrap();
        f.set_output_f32(&mut small, w - 1, h).unwrap();
        f.commit().unwrap();
        assert!(matches!(f.execute(), Err(Error::InvalidArgument(_))));
    }
    assert!(small.iter().all(|&v| v == -7.0));

    // Missing color; buffers too short for their layout; unknown names; wrong model type.
    let mut out = sentinel.clone();
    {
        let mut f = Filter::new(&dev, "TEMC2").unwrap();
        f.set_weights(&model);
        f.set_output_f32(&mut out, w, h).unwrap();
        f.commit().unwrap();
        assert!(matches!(f.execute(), Err(Error::InvalidOperation(_))));
        assert!(f.set_input_f32("color", &img[3..], w, h).is_err());
        assert!(f.set_input_f32("colour", &img, w, h).is_err());
        assert!(temc::filter::Quality::from_raw(3).is_none());
        assert!(f.set_input_scale(-1.0).is_err());
        assert!(f.set_input_scale(f32::INFINITY).is_err());
    }
    assert_eq!(out, sentinel);
    assert!(Filter::new(&dev, "OIDN").is_err());
    let mut demc = Filter::new(&dev, "DEMC").unwrap();
    demc.set_weights(&model);
    assert!(matches!(demc.commit(), Err(Error::InvalidArgument(_))));
    // Without weights TEMC-2 runs its built-in model; the baselines have none.
    let mut builtin = Filter::new(&dev, "TEMC2").unwrap();
    assert!(builtin.commit().is_ok());
    let mut none = Filter::new(&dev, "DEMC").unwrap();
    assert!(matches!(none.commit(), Err(Error::InvalidOperation(_))));
    let mut bad = Filter::new(&dev, "TEMC2").unwrap();
    bad.set_weights(b"garbage");
    assert!(bad.commit().is_err());
}

#[test]
fn cancellation_leaves_no_output_and_the_filter_usable() {
    let (w, h) = (200, 150);
    let img = image(w, h);
    let dev = device(2);
    let model = weights();
    let sentinel = vec![-7.0f32; w * h * 3];
    let mut out = sentinel.clone();
    let calls = std::sync::atomic::AtomicUsize::new(0);
    {
        let mut f = Filter::new(&dev, "TEMC2").unwrap();
        f.set_weights(&model);
        f.set_input_f32("color", &img, w, h).unwrap();
        f.set_output_f32(&mut out, w, h).unwrap();
        f.set_tile_size(32);
        f.set_progress_monitor(|p| {
            calls.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
            p < 0.3
        });
        f.commit().unwrap();
        assert!(matches!(f.execute(), Err(Error::Cancelled)));
        f.unset_progress_monitor();
        f.execute().unwrap();
    }
    assert!(calls.load(std::sync::atomic::Ordering::SeqCst) >= 1);
    assert!(out.iter().all(|v| v.is_finite() && *v >= 0.0));
}

#[test]
fn a_constant_image_stays_constant() {
    // Whatever the network predicts, the filters' weights sum to one and filter linear
    // radiance: a flat colour comes back unchanged, at any level of the pyramid.
    let (w, h) = (96, 64);
    let img: Vec<f32> = (0..w * h).flat_map(|_| [0.18f32, 0.5, 3.0]).collect();
    let r = denoise(&img, w, h, 1, 0);
    for (got, want) in r.output.iter().zip(&img) {
        assert!((got - want).abs() <= 1e-5 * want, "{got} against {want}");
    }
}

#[test]
fn each_builtin_model_tiled_equals_untiled_with_its_measured_overlap() {
    // A shipped model's overlap is its measured effective reach (an impulse's effect
    // below 1e-4 of its size), not half its theoretical receptive field: tiled and untiled
    // must still agree within 1e-3 in PQ on a noisy image, for every quality mode.
    let (w, h) = (520, 330);
    let mut s = 0x2545_f491_4f6c_dd1du64;
    let img: Vec<f32> = image(w, h)
        .into_iter()
        .map(|v| {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            let u = (s >> 40) as f32 / (1u64 << 24) as f32;
            v * 3.0 * u * u
        })
        .collect();
    let dev = device(2);
    let run = |quality: Quality, tile: usize| {
        let mut out = vec![0f32; w * h * 3];
        let mut f = Filter::new(&dev, "TEMC2").unwrap();
        f.set_input_f32("color", &img, w, h).unwrap();
        f.set_output_f32(&mut out, w, h).unwrap();
        f.set_input_scale(1.0).unwrap();
        f.set_quality(quality);
        f.set_tile_size(tile);
        f.commit().unwrap();
        let tiles = f.execute().unwrap().tiles;
        drop(f);
        (out, tiles)
    };
    for q in [Quality::Fast, Quality::Balanced, Quality::High] {
        let (untiled, one) = run(q, 4096);
        let (tiled, many) = run(q, 48);
        assert_eq!(one, 1);
        // A wider overlap makes the planner's tiles larger: fast's 160 px leaves 4.
        assert!(many >= 4, "{q:?}: {many} tiles");
        let d = max_pq_diff(&untiled, &tiled);
        println!("{q:?}: max PQ difference, untiled vs 48-pixel tiles: {d:e}");
        assert!(d <= 1e-3, "{q:?}: {d}");
    }
}

/// A new frame's images need another commit; with the same weights it reuses the parsed
/// model (and so its cached plans), while new weights are parsed anew.
#[test]
fn recommit_with_the_same_weights_reuses_the_model() {
    let dev = device(1);
    let (w, h) = (32, 24);
    let (a, b) = (image(w, h), vec![0.3f32; w * h * 3]);
    let mut f = Filter::new(&dev, "TEMC2").unwrap();
    f.set_weights(&weights());
    f.set_input_f32("color", &a, w, h).unwrap();
    f.commit().unwrap();
    let first = f.model().unwrap().clone();
    f.set_input_f32("color", &b, w, h).unwrap();
    assert!(
        f.model().is_none(),
        "a changed filter reports no committed model"
    );
    f.commit().unwrap();
    assert!(std::sync::Arc::ptr_eq(&first, f.model().unwrap()));
    f.set_weights(&weights());
    f.commit().unwrap();
    assert!(!std::sync::Arc::ptr_eq(&first, f.model().unwrap()));
}

#[test]
fn a_resizing_host_keeps_a_bounded_number_of_plans() {
    let dev = device(1);
    let sizes: Vec<usize> = (1..=PLAN_CACHE_SIZES + 2).map(|k| 32 * k).collect();
    let images: Vec<Vec<f32>> = sizes.iter().map(|&s| image(s, s)).collect();
    let mut f = Filter::new(&dev, "TEMC2").unwrap();
    f.set_weights(&weights());
    for (&s, color) in sizes.iter().zip(&images) {
        f.set_input_f32("color", color, s, s).unwrap();
        f.commit().unwrap();
        f.execute_to_vec().unwrap();
        let kept = f.model().unwrap().cached_sizes();
        assert!(kept.len() <= PLAN_CACHE_SIZES, "{kept:?}");
        assert!(kept.iter().any(|&(h, w)| h >= s && w >= s), "{s}: {kept:?}");
    }
    let kept = f.model().unwrap().cached_sizes();
    assert_eq!(kept.len(), PLAN_CACHE_SIZES, "{kept:?}");
    assert!(
        kept.iter().all(|&(h, _)| h > 32),
        "the first size, least recently used, was dropped: {kept:?}"
    );
}

/// The resident memory of this process in MB (Linux) once the allocator has returned what
/// it can, so that what is left is what is held, for the measurement below.
fn rss_mb() -> Option<f64> {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: malloc_trim only returns free heap memory to the system.
    unsafe {
        libc::malloc_trim(0);
    }
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmRSS:"))?;
    Some(line.split_whitespace().nth(1)?.parse::<f64>().ok()? / 1024.0)
}

/// A host that resizes its viewport: one filter with the built-in balanced model,
/// recommitted for 16 image sizes in turn, then the first four again. Prints each size's
/// execute time and the memory the process holds; docs/speed.md, "A host that resizes",
/// quotes it. `cargo test --release --test filter_api -- --ignored --nocapture resizing`
#[test]
#[ignore = "a measurement: run it with --nocapture"]
fn resizing_host_memory() {
    let dev = device(1);
    let sizes: Vec<usize> = (0..16)
        .map(|k| 160 + 32 * k)
        .chain((0..4).map(|k| 160 + 32 * k))
        .collect();
    let images: Vec<Vec<f32>> = sizes.iter().map(|&s| image(s, s)).collect();
    let mut f = Filter::new(&dev, "TEMC2").unwrap();
    for (i, (&s, color)) in sizes.iter().zip(&images).enumerate() {
        f.set_input_f32("color", color, s, s).unwrap();
        f.commit().unwrap();
        let t = std::time::Instant::now();
        let (out, _) = f.execute_to_vec().unwrap();
        assert!(out.iter().all(|v| v.is_finite()));
        let plans = f.model().map_or(0, |m| m.cached_sizes().len());
        println!(
            "run {i:2}: {s}x{s}, {:.3} s, {plans} plan(s) cached, resident {:.0} MB",
            t.elapsed().as_secs_f64(),
            rss_mb().unwrap_or(f64::NAN)
        );
    }
}

/// The flip ensemble: with four passes the filter commutes with a mirror image (the
/// normal's x mirrored with it), which one pass of the untrained network does not; NaN and
/// Inf stay harmless; other counts are refused.
#[test]
fn four_passes_commute_with_a_mirror_image() {
    let (w, h) = (64, 64);
    let img = image(w, h);
    let normal: Vec<f32> = (0..w * h)
        .flat_map(|i| {
            let (x, y) = ((i % w) as f32 / w as f32, (i / w) as f32 / h as f32);
            [x - 0.5, 0.3 - y, 0.8]
        })
        .collect();
    let mirror = |v: &[f32]| -> Vec<f32> {
        (0..w * h)
            .flat_map(|i| {
                let j = (i / w) * w + (w - 1 - i % w);
                v[j * 3..j * 3 + 3].to_vec()
            })
            .collect()
    };
    let run = |color: &[f32], normal: &[f32], passes: usize| -> Vec<f32> {
        let dev = device(2);
        let model = weights();
        let mut out = vec![0f32; w * h * 3];
        let mut f = Filter::new(&dev, "TEMC2").unwrap();
        f.set_weights(&model);
        f.set_input_f32("color", color, w, h).unwrap();
        f.set_input_f32("normal", normal, w, h).unwrap();
        f.set_output_f32(&mut out, w, h).unwrap();
        f.set_input_scale(1.0).unwrap();
        f.set_passes(passes).unwrap();
        f.commit().unwrap();
        assert_eq!(f.execute().unwrap().passes, passes);
        drop(f);
        out
    };
    let mut mirrored_normal = mirror(&normal);
    mirrored_normal.chunks_mut(3).for_each(|n| n[0] = -n[0]);
    let gap = |passes| {
        let direct = mirror(&run(&img, &normal, passes));
        max_pq_diff(&direct, &run(&mirror(&img), &mirrored_normal, passes))
    };
    let (one, four) = (gap(1), gap(4));
    assert!(four < 1e-5, "four passes: {four}");
    assert!(
        one > 1e-4,
        "one pass: {one} (the check above could not fail)"
    );

    let mut bad = img.clone();
    bad[0] = f32::NAN;
    bad[40] = f32::INFINITY;
    bad[100] = -3.0;
    assert!(run(&bad, &normal, 2)
        .iter()
        .all(|v| v.is_finite() && *v >= 0.0));
    let mut f = Filter::new(&device(1), "TEMC2").unwrap();
    assert_eq!(f.passes(), 0, "the model's own count by default");
    f.set_passes(2).unwrap();
    for n in [3, 8] {
        assert!(
            matches!(f.set_passes(n), Err(Error::InvalidArgument(_))),
            "{n}"
        );
    }
    assert_eq!(f.passes(), 2, "a refused count keeps the last");
}
