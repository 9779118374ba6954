//! The weak sampling modes (`Settings::sampling`, `render --sampling`): each converges to
//! the default sampler's image, and each is noisier where the renderer it imitates is.

use temc_render::description::{format, named};
use temc_render::film::relmse;
use temc_render::scene::Scene;
use temc_render::{render, Sampling, Settings};

/// Every material the light strategies treat apart: rough plastic (coat and base), rough
/// glass (reflection sampled with the lights, refraction not), a rough metal, a diffuse
/// box, under a large dim panel and a small bright sphere lamp of unequal power.
const MIXED: &str = "camera eye 0 1.2 -3 target 0 0.4 0 fov 40\n\
    material floor plastic reflectance rgb 0.5 0.45 0.4 roughness 0.2\n\
    material glass dielectric ior 1.5 roughness 0.2\n\
    material gold conductor metal Au roughness 0.25\n\
    material white diffuse reflectance rgb 0.7 0.7 0.7\n\
    material panel emitter blackbody 4000 scale 3\n\
    material bulb emitter d65 scale 15\n\
    quad corner 3 0 -3 edge1 -6 0 0 edge2 0 0 6 material floor\n\
    sphere center -0.6 0.4 0 radius 0.4 material glass\n\
    sphere center 0.6 0.4 0.3 radius 0.4 material gold\n\
    box min -0.2 0 0.8 max 0.3 0.9 1.2 material white\n\
    quad corner -1 2.5 -1 edge1 2 0 0 edge2 0 0 2 material panel\n\
    sphere center 1.2 1.5 -0.5 radius 0.25 material bulb\n";

fn settings(size: usize, spp: u32, seed: u64, sampling: Sampling) -> Settings {
    Settings {
        width: size,
        height: size,
        spp,
        seed,
        max_depth: 12,
        kernel: None,
        sampling,
    }
}

fn luminance(c: &[f32; 3]) -> f64 {
    0.2126 * c[0] as f64 + 0.7152 * c[1] as f64 + 0.0722 * c[2] as f64
}

/// Mean luminance over the pixels `mask` keeps.
fn mean_luminance(c: &[[f32; 3]], mask: &[bool]) -> f64 {
    let kept: Vec<f64> = c
        .iter()
        .zip(mask)
        .filter(|(_, &m)| m)
        .map(|(c, _)| luminance(c))
        .collect();
    kept.iter().sum::<f64>() / kept.len() as f64
}

/// Parses each of `modes`.
fn parse(modes: &[&str]) -> Vec<Sampling> {
    modes.iter().map(|m| m.parse().unwrap()).collect()
}

/// The mean luminance of `sc` with each of `modes` must lie within `tolerance` (relative)
/// of the default sampler's at the same spp (another seed). The mean leaves out the lamps
/// seen directly (pixels brighter than 1 in a third, independent render; the lit scene is
/// about 0.2): every mode renders them alike, and a lamp's edge pixels, bright or dark by
/// where a sample falls, would swamp the comparison of what the modes do differently.
fn converges(sc: &Scene, size: usize, spp: u32, modes: &[Sampling], tolerance: f64) {
    let lamps = render(sc, &settings(size, 64, 0, Sampling::DEFAULT)).color;
    let mask: Vec<bool> = lamps.iter().map(|c| luminance(c) < 1.0).collect();
    let mean = |s, seed| mean_luminance(&render(sc, &settings(size, spp, seed, s)).color, &mask);
    let want = mean(Sampling::DEFAULT, 1);
    for &s in modes {
        let got = mean(s, 2);
        eprintln!("{}: {s}: {got:.5} against {want:.5}", sc.name);
        assert!(
            (got / want - 1.0).abs() < tolerance,
            "{} with sampling {s}: mean luminance {got}, default sampler {want}",
            sc.name
        );
    }
}

#[test]
fn every_mode_converges_on_glossy_glass_and_two_lamps() {
    let sc = format::parse(MIXED, "mixed", None).unwrap();
    let mut modes: Vec<Sampling> = Sampling::MODES.iter().map(|m| m.1).collect();
    modes.extend(parse(&[
        "uniform-lights,no-mis,uniform-wavelength,early-roulette",
        "bsdf-only,uniform-wavelength,early-roulette",
    ]));
    converges(&sc, 16, 1024, &modes, 0.04);
}

#[test]
fn wavelength_and_roulette_modes_converge_under_a_line_spectrum() {
    let sc = named::scene("cornell-spiky").unwrap();
    let modes = parse(&[
        "uniform-wavelength",
        "early-roulette",
        "uniform-wavelength,early-roulette",
    ]);
    converges(&sc, 16, 1024, &modes, 0.04);
}

#[test]
fn light_modes_converge_under_many_lamps_of_unequal_power() {
    let sc = named::scene("many-lights").unwrap();
    let modes = parse(&[
        "uniform-lights",
        "no-mis",
        "uniform-lights,no-mis",
        "bsdf-only",
    ]);
    converges(&sc, 16, 1024, &modes, 0.04);
}

/// Mean squared chromaticity error against `reference`, over pixels bright enough to have
/// a colour: noise in the colour of a pixel, not in its brightness.
fn chroma_error(x: &[[f32; 3]], reference: &[[f32; 3]]) -> f64 {
    let chroma = |c: &[f32; 3]| {
        let s = (c[0] + c[1] + c[2]) as f64;
        [c[0] as f64 / s, c[1] as f64 / s]
    };
    let lit: Vec<(&[f32; 3], &[f32; 3])> = x
        .iter()
        .zip(reference)
        .filter(|(a, r)| r.iter().sum::<f32>() > 0.05 && a.iter().sum::<f32>() > 0.0)
        .collect();
    let sum: f64 = lit
        .iter()
        .map(|(a, r)| {
            let (ca, cr) = (chroma(a), chroma(r));
            (ca[0] - cr[0]).powi(2) + (ca[1] - cr[1]).powi(2)
        })
        .sum();
    sum / lit.len().max(1) as f64
}

/// An error measure of an image against a reference.
type Measure = fn(&[[f32; 3]], &[[f32; 3]]) -> f64;

/// Error of `sampling` over the default sampler's on `scene` at equal spp, with `measure`
/// against a default-sampler reference, summed over 16 seeds: one small image's error is
/// ruled by its few brightest outliers, whichever sampler made it.
fn noise_ratio(scene: &str, sampling: &str, measure: Measure, spp: u32) -> f64 {
    let sc = named::scene(scene).unwrap();
    let size = 24;
    let reference = render(&sc, &settings(size, 1024, 99, Sampling::DEFAULT)).color;
    let error = |s: Sampling| -> f64 {
        (0..16)
            .map(|seed| {
                measure(
                    &render(&sc, &settings(size, spp, seed, s)).color,
                    &reference,
                )
            })
            .sum()
    };
    let ratio = error(sampling.parse().unwrap()) / error(Sampling::DEFAULT);
    eprintln!("{scene}: {sampling} error {ratio:.2}x the default sampler's at {spp} spp");
    ratio
}

#[test]
fn uniform_wavelengths_make_colour_noise_under_a_line_spectrum() {
    let r = noise_ratio("cornell-spiky", "uniform-wavelength", chroma_error, 16);
    assert!(r > 10.0, "chroma error only {r:.2}x the default sampler's");
}

#[test]
fn bsdf_sampling_alone_is_noisy_under_a_small_lamp() {
    let r = noise_ratio("cornell-warm", "bsdf-only", relmse, 16);
    assert!(r > 20.0, "RelMSE only {r:.2}x the default sampler's");
}

#[test]
fn uniform_light_selection_is_noisy_under_lamps_of_unequal_power() {
    let r = noise_ratio("many-lights", "uniform-lights", relmse, 16);
    assert!(r > 1.4, "RelMSE only {r:.2}x the default sampler's");
}

#[test]
fn light_sampling_without_mis_is_noisy_on_glossy_metal() {
    let r = noise_ratio("metals", "no-mis", relmse, 16);
    assert!(r > 1.3, "RelMSE only {r:.2}x the default sampler's");
}

#[test]
fn early_roulette_adds_noise_to_indirect_light() {
    let r = noise_ratio("cornell-warm", "early-roulette", relmse, 16);
    assert!(r > 1.1, "RelMSE only {r:.2}x the default sampler's");
}
