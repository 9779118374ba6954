//! The scene families of `dataset --families all` (issue 36: "noise users have, not only
//! ours"). `v2` is [`super::generate`]'s frozen generator, a room or an open floor; `all`
//! draws one of [`FAMILIES`] per scene by a hash of its seed:
//!
//! - `room`, `open`: the `v2` layouts.
//! - `sun-sky`: outdoors under a sky and a sun (a sphere 0.5–1° across, 5000–6000 K,
//!   1.5–10x the sky's illuminance), with a few free-standing walls or canopies.
//! - `small-lights`: 8 to 40 small lamps (pendants, downlights, floor and table lamps) of
//!   a few spectra and powers spread 25x, in a room or on an open floor at dusk.
//! - `glossy-interior`: a room with a glossy floor, satin walls, mirrors on the walls, and
//!   metal, plastic and glass objects.
//! - `caustic-fireflies`: tiny, very bright lamps above and behind smooth glass and metal,
//!   under a dim fill light: caustics, and fireflies where paths find the lamps by chance.
//! - `fine-texture`: every surface textured at 12 to 80 cycles per metre, down to and
//!   below a pixel.
//!
//! None is a held-out layout of [`super::held_out`]: no room lit through a window, no
//! hall with a row of lamps along its walls.

use std::f32::consts::PI;
use std::fmt::{self, Write};
use std::str::FromStr;

use super::generate::{camera, closed_room, quad, room_or_open, Gen, Style};
use crate::rng::{splitmix, Rng};

/// Which families a data set's generated scenes come from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Families {
    /// The `v2` generator alone: a room or an open floor, as the `spectral-v2` set.
    #[default]
    V2,
    /// Every family of [`FAMILIES`], one per scene.
    All,
}

impl FromStr for Families {
    type Err = String;
    fn from_str(s: &str) -> Result<Families, String> {
        match s {
            "v2" => Ok(Families::V2),
            "all" => Ok(Families::All),
            _ => Err(format!("unknown families {s:?} (v2 or all)")),
        }
    }
}

impl fmt::Display for Families {
    fn fmt(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str(match self {
            Families::V2 => "v2",
            Families::All => "all",
        })
    }
}

/// The families `all` draws from, equally often.
pub const FAMILIES: [&str; 7] = [
    "room",
    "open",
    "sun-sky",
    "small-lights",
    "glossy-interior",
    "caustic-fireflies",
    "fine-texture",
];

/// Generated scene `seed` of `families`: its family and its text, deterministic in `seed`.
/// `V2` gives exactly [`super::generate::scene_text`].
pub fn scene(families: Families, seed: u64) -> (&'static str, String) {
    match families {
        Families::V2 => room_or_open(seed, None),
        Families::All => {
            let family = FAMILIES[(splitmix(seed ^ 0x0fa4_11e5) % FAMILIES.len() as u64) as usize];
            // Every listed family has a generator (the tests parse each one).
            (family, family_text(family, seed).unwrap_or_default())
        }
    }
}

/// A scene of `family` (one of [`FAMILIES`]), deterministic in `seed`; `None` for another
/// name.
pub fn family_text(family: &str, seed: u64) -> Option<String> {
    // Another stream than v2's and the held-out families', so no seed repeats their draws.
    let mut g = Gen(Rng::new(seed ^ 0x0fa3_11e5, seed));
    let (layout, body) = match family {
        "room" | "open" => return Some(room_or_open(seed, Some(family == "room")).1),
        "sun-sky" => ("outdoors", sun_sky(&mut g)),
        "small-lights" => small_lights(&mut g),
        "glossy-interior" => g.layout(Some(true), &GLOSSY),
        "caustic-fireflies" => g.layout(None, &CAUSTIC),
        "fine-texture" => g.layout(None, &FINE),
        _ => return None,
    };
    Some(format!(
        "# Random scene {seed} ({family}, {layout})\n{body}"
    ))
}

/// The sun's distance: far enough that its light is nearly parallel over the scene.
const SUN_DISTANCE: f32 = 100.0;
/// Half the ground's side: past the horizon the camera sees.
const GROUND: f32 = 40.0;

/// Outdoors: ground, sky and sun, a few walls or canopies, objects.
fn sun_sky(g: &mut Gen) -> String {
    let mut s = String::new();
    let (w, d) = (g.range(4.0, 8.0), g.range(4.0, 8.0));
    let eye = [g.range(-0.3, 0.3) * w, g.range(1.0, 2.2), -0.6 * d];
    let target = [
        g.range(-0.3, 0.3) * w,
        g.range(0.2, 1.2),
        g.range(0.0, 0.3) * d,
    ];
    camera(&mut s, eye, target, g.range(40.0, 70.0));
    g.floor_and_wall(&mut s, (0.1, 0.6), (0.2, 0.8));
    let (c, e) = (-GROUND, 2.0 * GROUND);
    quad(&mut s, [c, 0.0, c], [0.0, 0.0, e], [e, 0.0, 0.0], "floor");
    let sky = g.range(0.05, 0.5);
    let spectrum = if g.chance(0.5) {
        "d65".to_string()
    } else {
        format!("blackbody {:.0}", g.range(7000.0, 16000.0))
    };
    let _ = writeln!(s, "environment {spectrum} scale {sky:.3}");
    sun(g, &mut s, sky);
    for _ in 0..(g.u() * 4.0) as usize {
        prop(g, &mut s, w, d);
    }
    g.objects(&mut s, w, d);
    s
}

/// A sun of 1.5 to 10 times the sky's illuminance on level ground (`sky`: the sky's
/// luminance).
fn sun(g: &mut Gen, s: &mut String, sky: f32) {
    // At least 0.5 degrees: below that 1 - cos(θmax) lies within a few hundred f32 steps
    // of 1, and the sphere sampler's cone and density lose precision.
    let theta = g.range(0.5, 1.0).to_radians();
    let (elev, az) = (g.range(10.0, 70.0).to_radians(), g.range(-PI, PI));
    let dir = [elev.cos() * az.sin(), elev.sin(), elev.cos() * az.cos()];
    // Illuminance: the sun's L·π·θ² against the sky's π·L_sky.
    let ratio = g.range(1.5, 10.0);
    let _ = writeln!(
        s,
        "material sun emitter blackbody {:.0} scale {:.0}",
        g.range(5000.0, 6000.0),
        ratio * sky / (theta * theta)
    );
    let [x, y, z] = dir.map(|v| v * SUN_DISTANCE);
    let _ = writeln!(
        s,
        "sphere center {x:.3} {y:.3} {z:.3} radius {:.3} material sun",
        SUN_DISTANCE * theta.tan()
    );
}

/// A free-standing wall or a canopy near the objects: shade and occluded sun.
fn prop(g: &mut Gen, s: &mut String, w: f32, d: f32) {
    if g.chance(0.6) {
        let (len, height, a) = (g.range(2.0, 5.0), g.range(1.0, 3.0), g.range(0.0, PI));
        let (cx, cz) = (g.range(-0.5, 0.5) * w, g.range(0.2, 0.6) * d);
        let (dx, dz) = (len * a.cos(), len * a.sin());
        let corner = [cx - dx / 2.0, 0.0, cz - dz / 2.0];
        quad(s, corner, [dx, 0.0, dz], [0.0, height, 0.0], "wall");
    } else {
        let (cw, cd, y) = (g.range(1.5, 3.0), g.range(1.5, 3.0), g.range(2.2, 3.0));
        let corner = [g.range(-0.5, 0.2) * w, y, g.range(-0.2, 0.4) * d];
        quad(s, corner, [cw, 0.0, 0.0], [0.0, 0.0, cd], "wall");
    }
}

/// Many small lamps in a room or on an open floor at dusk.
fn small_lights(g: &mut Gen) -> (&'static str, String) {
    let mut s = String::new();
    let room = g.chance(0.6);
    let (w, d, h) = (g.range(4.0, 8.0), g.range(4.0, 8.0), g.range(2.5, 3.5));
    let eye = [g.range(-0.4, 0.4) * w, g.range(0.8, 1.8), -0.46 * d];
    let target = [g.range(-0.3, 0.3), g.range(0.3, 1.2), g.range(-0.3, 0.3)];
    camera(&mut s, eye, target, g.range(40.0, 70.0));
    if room {
        closed_room(g, &mut s, (w, h, d), false);
    } else {
        g.floor_and_wall(&mut s, (0.1, 0.8), (0.3, 0.85));
        let (x0, z0) = (-w / 2.0, -d / 2.0);
        quad(&mut s, [x0, 0.0, z0], [0.0, 0.0, d], [w, 0.0, 0.0], "floor");
        quad(&mut s, [x0, 0.0, -z0], [w, 0.0, 0.0], [0.0, h, 0.0], "wall");
        let _ = writeln!(s, "environment d65 scale {:.3}", g.range(0.005, 0.05));
    }
    let _ = writeln!(s, "material post conductor metal Al roughness 0.3");
    lamps(g, &mut s, (w, h, d), room);
    g.objects(&mut s, w, d);
    (if room { "room" } else { "open" }, s)
}

/// 8 to 40 lamps of a few spectra, scattered: their luminance-times-area adds up to that
/// of the `v2` rooms' panels, each lamp's share spread 25x.
fn lamps(g: &mut Gen, s: &mut String, (w, h, d): (f32, f32, f32), room: bool) {
    let n = 8 + (g.u() * 33.0) as usize;
    let spectra: Vec<String> = (0..1 + (g.u() * 4.0) as usize)
        .map(|_| g.spectrum())
        .collect();
    let total = g.range(3.0, 15.0);
    let top = if room { h } else { g.range(2.4, 3.2) };
    for i in 0..n {
        let spectrum = g.pick(&spectra).clone();
        let power = total / n as f32 * g.range(-1.6, 1.6).exp();
        let (x, z) = (g.range(-0.45, 0.45) * w, g.range(-0.3, 0.45) * d);
        let name = format!("lamp{i}");
        // The shape after its material, which it names.
        let mut shape = String::new();
        let area = match g.u() {
            v if v < 0.35 => {
                let r = g.range(0.03, 0.08);
                sphere(&mut shape, [x, top - g.range(0.15, 0.8), z], r, &name);
                PI * r * r
            }
            v if v < 0.55 => {
                // A downlight: emits along edge1 x edge2, which points down.
                let a = g.range(0.08, 0.25);
                let corner = [x - a / 2.0, top - 0.002, z - a / 2.0];
                quad(&mut shape, corner, [a, 0.0, 0.0], [0.0, 0.0, a], &name);
                a * a
            }
            v if v < 0.8 => {
                let (r, y) = (g.range(0.06, 0.15), g.range(1.2, 1.8));
                let _ = writeln!(
                    shape,
                    "box min {:.3} 0 {:.3} max {:.3} {y:.3} {:.3} material post",
                    x - 0.02,
                    z - 0.02,
                    x + 0.02,
                    z + 0.02
                );
                sphere(&mut shape, [x, y + r, z], r, &name);
                PI * r * r
            }
            _ => {
                let r = g.range(0.02, 0.05);
                sphere(&mut shape, [x, g.range(0.4, 1.6), z], r, &name);
                PI * r * r
            }
        };
        let _ = writeln!(
            s,
            "material {name} emitter {spectrum} scale {:.1}",
            power / area
        );
        s.push_str(&shape);
    }
}

/// Writes a sphere statement.
fn sphere(s: &mut String, [x, y, z]: [f32; 3], r: f32, material: &str) {
    let _ = writeln!(
        s,
        "sphere center {x:.3} {y:.3} {z:.3} radius {r:.3} material {material}"
    );
}

/// `glossy-interior`: glossy floor and walls, mirrors, glossy objects.
const GLOSSY: Style = Style {
    surfaces: glossy_surfaces,
    lamp_scale: 1.0,
    objects: |g, s, w, d| {
        mirrors(g, s, w, d);
        g.objects_with(s, w, d, glossy_material);
    },
};

/// A polished floor (metal, or varnished with a texture) and satin or matt walls.
fn glossy_surfaces(g: &mut Gen, s: &mut String) {
    let floor = if g.chance(0.3) {
        let metal = g.pick(&["Au", "Ag", "Cu", "Al"]);
        format!(
            "conductor metal {metal} roughness {:.3}",
            g.range(0.02, 0.3)
        )
    } else {
        let r = smooth_or(g, 0.3, 0.2);
        format!(
            "plastic reflectance {} ior {:.2} roughness {r:.3}",
            g.texture(0.1, 0.8),
            g.range(1.4, 1.7)
        )
    };
    let _ = writeln!(s, "material floor {floor}");
    let wall = g.texture(0.3, 0.85);
    let wall = if g.chance(0.5) {
        format!(
            "plastic reflectance {wall} roughness {:.3}",
            g.range(0.05, 0.3)
        )
    } else {
        format!("diffuse reflectance {wall}")
    };
    let _ = writeln!(s, "material wall {wall}");
}

/// One or two mirrors hung just off the back or a side wall of a w x d room.
fn mirrors(g: &mut Gen, s: &mut String, w: f32, d: f32) {
    let _ = writeln!(
        s,
        "material mirror conductor metal {} roughness {:.3}",
        g.pick(&["Ag", "Al"]),
        smooth_or(g, 0.5, 0.04)
    );
    for _ in 0..1 + g.chance(0.5) as usize {
        let (len, y0, y1) = (g.range(0.6, 2.0), g.range(0.3, 0.9), g.range(1.5, 2.1));
        let along = g.range(-0.3, 0.3);
        let corner = match g.u() {
            v if v < 0.5 => [along * w - len / 2.0, y0, d / 2.0 - 0.01],
            v if v < 0.75 => [w / 2.0 - 0.01, y0, along * d - len / 2.0],
            _ => [-w / 2.0 + 0.01, y0, along * d - len / 2.0],
        };
        let e1 = if corner[2] > d / 2.0 - 0.02 {
            [len, 0.0, 0.0]
        } else {
            [0.0, 0.0, len]
        };
        quad(s, corner, e1, [0.0, y1 - y0, 0.0], "mirror");
    }
}

/// The least nonzero roughness (microfacet alpha) the families write: below it a lobe is
/// a mirror in all but cost (light samples almost never land in it), and the `v2`
/// generator never goes below 0.01 either. (Alphas of a few thousandths also gave NaN
/// until GGX's D was clamped, `near_mirror_roughness_stays_finite` in render/tests.)
const MIN_ROUGHNESS: f32 = 0.02;

/// A roughness: smooth (0) with probability `p`, else up to `hi`.
fn smooth_or(g: &mut Gen, p: f32, hi: f32) -> f32 {
    if g.chance(p) {
        0.0
    } else {
        g.range(MIN_ROUGHNESS, hi)
    }
}

/// A glossy material: metal, plastic or glass, smooth or slightly rough.
fn glossy_material(g: &mut Gen, name: &str) -> String {
    match g.u() {
        x if x < 0.4 => format!(
            "material {name} conductor metal {} roughness {:.3}",
            g.pick(&["Au", "Ag", "Cu", "Al"]),
            smooth_or(g, 0.3, 0.3)
        ),
        x if x < 0.75 => format!(
            "material {name} plastic reflectance {} ior {:.2} roughness {:.3}",
            g.texture(0.05, 0.9),
            g.range(1.3, 1.8),
            smooth_or(g, 0.3, 0.2)
        ),
        _ => format!(
            "material {name} dielectric {} roughness {:.3}",
            g.ior(),
            smooth_or(g, 0.3, 0.2)
        ),
    }
}

/// `caustic-fireflies`: the `v2` layouts under a dim fill light, with smooth glass and
/// metal and tiny bright lamps by them.
const CAUSTIC: Style = Style {
    surfaces: |g, s| g.floor_and_wall(s, (0.3, 0.85), (0.3, 0.85)),
    lamp_scale: 0.15,
    objects: caustic_objects,
};

/// Glass and metal objects, each with a chance of a tiny lamp above it (its light focused
/// onto the floor) and one lamp behind them, seen through them.
fn caustic_objects(g: &mut Gen, s: &mut String, w: f32, d: f32) {
    let n = 2 + (g.u() * 4.0) as usize;
    let mut sparks = Vec::new();
    for i in 0..n {
        let name = format!("m{i}");
        let m = if g.chance(0.65) {
            format!("material {name} dielectric {} roughness 0", g.ior())
        } else {
            let metal = g.pick(&["Au", "Ag", "Cu", "Al"]);
            format!(
                "material {name} conductor metal {metal} roughness {:.3}",
                smooth_or(g, 0.4, 0.05)
            )
        };
        let _ = writeln!(s, "{m}");
        let (x, z, size) = (
            g.range(-0.3, 0.3) * w,
            g.range(-0.1, 0.3) * d,
            g.range(0.15, 0.45),
        );
        if g.chance(0.5) {
            sphere(s, [x, size, z], size, &name);
        } else {
            let _ = writeln!(
                s,
                "prism center {x:.3} 0 {z:.3} size {:.3} height {:.3} rotate {:.1} material {name}",
                2.0 * size,
                g.range(0.3, 1.0),
                g.range(0.0, 180.0)
            );
        }
        if g.chance(0.6) {
            let (dx, dz) = (g.range(-0.4, 0.4), g.range(-0.4, 0.4));
            sparks.push([x + dx, 2.0 * size + g.range(0.3, 1.2), z + dz]);
        }
    }
    if sparks.is_empty() || g.chance(0.5) {
        sparks.push([
            g.range(-0.3, 0.3) * w,
            g.range(0.2, 1.0),
            g.range(0.35, 0.45) * d,
        ]);
    }
    for (i, c) in sparks.into_iter().enumerate() {
        // Luminance-times-area 0.3 to 3 on a sphere 1.6 to 6 cm across: smaller ones
        // leave caustics unconverged even in the references (a path off smooth glass
        // finds the lamp only by chance, with probability ~ its solid angle).
        let r = g.range(0.008, 0.03);
        let spectrum = if g.chance(0.6) {
            format!("blackbody {:.0}", g.range(2700.0, 6500.0))
        } else {
            g.spectrum()
        };
        let scale = g.range(0.3, 3.0) / (PI * r * r);
        let _ = writeln!(s, "material spark{i} emitter {spectrum} scale {scale:.0}");
        sphere(s, c, r, &format!("spark{i}"));
    }
}

/// `fine-texture`: the `v2` layouts with every surface finely textured.
const FINE: Style = Style {
    surfaces: |g, s| {
        for (name, lo, hi) in [("floor", 0.1, 0.85), ("wall", 0.2, 0.85)] {
            let t = fine_texture(g, lo, hi);
            let _ = writeln!(s, "material {name} diffuse reflectance {t}");
        }
    },
    lamp_scale: 1.0,
    objects: |g, s, w, d| g.objects_with(s, w, d, fine_material),
};

/// A pattern at 12 to 80 cycles per metre (log-uniform): about a pixel to a few pixels
/// per cycle at the data set's 128x128 over a few metres.
fn fine_texture(g: &mut Gen, lo: f32, hi: f32) -> String {
    let pattern = *g.pick(&["checker", "stripes", "noise", "fine"]);
    let freq = g.range(12f32.ln(), 80f32.ln()).exp();
    format!("{pattern} {} {} {freq:.2}", g.rgb(lo, hi), g.rgb(lo, hi))
}

/// A diffuse, plastic or metal material with a fine reflectance or roughness texture.
fn fine_material(g: &mut Gen, name: &str) -> String {
    let rough = |g: &mut Gen| {
        let pattern = *g.pick(&["checker", "stripes", "noise", "fine"]);
        let (a, b) = (g.range(MIN_ROUGHNESS, 0.1), g.range(0.2, 0.5));
        let freq = g.range(12f32.ln(), 60f32.ln()).exp();
        format!("{pattern} {a:.3} {b:.3} {freq:.2}")
    };
    match g.u() {
        x if x < 0.5 => format!(
            "material {name} diffuse reflectance {}",
            fine_texture(g, 0.05, 0.9)
        ),
        x if x < 0.8 => format!(
            "material {name} plastic reflectance {} ior {:.2} roughness {}",
            fine_texture(g, 0.05, 0.9),
            g.range(1.3, 1.8),
            rough(g)
        ),
        _ => format!(
            "material {name} conductor metal {} roughness {}",
            g.pick(&["Au", "Ag", "Cu", "Al"]),
            rough(g)
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::description::format::parse;
    use crate::render::{render, Settings};

    #[test]
    fn every_family_parses_is_lit_and_is_deterministic() {
        for family in FAMILIES {
            for seed in 0..60 {
                let t = family_text(family, seed).unwrap();
                assert_eq!(Some(&t), family_text(family, seed).as_ref(), "{family}");
                // The parser refuses scenes with nothing that emits.
                parse(&t, family, None).unwrap_or_else(|e| panic!("{e}\n{t}"));
            }
            assert_ne!(family_text(family, 1), family_text(family, 2), "{family}");
        }
        assert!(family_text("window", 0).is_none());
        assert!(family_text("corridor", 0).is_none());
    }

    #[test]
    fn v2_is_the_frozen_generator_and_all_draws_every_family() {
        for seed in 0..50 {
            let (layout, text) = scene(Families::V2, seed);
            assert_eq!(text, super::super::generate::scene_text(seed));
            assert!(text.starts_with(&format!("# Random scene {seed} ({layout})\n")));
        }
        let mut n = std::collections::BTreeMap::new();
        for seed in 0..200 {
            let (family, text) = scene(Families::All, seed);
            assert_eq!(Some(text), family_text(family, seed));
            *n.entry(family).or_insert(0) += 1;
        }
        // Each of the 7 about 200 / 7 = 29 times.
        assert_eq!(n.len(), FAMILIES.len(), "{n:?}");
        assert!(n.values().all(|&k| (12..=50).contains(&k)), "{n:?}");
        assert_eq!("all".parse(), Ok(Families::All));
        assert_eq!(Families::default().to_string(), "v2");
        assert!("v3".parse::<Families>().is_err());
    }

    #[test]
    fn the_families_have_what_they_are_named_for() {
        let count = |t: &str, what: &str| t.lines().filter(|l| l.contains(what)).count();
        for seed in 0..20 {
            let t = family_text("small-lights", seed).unwrap();
            assert!((8..=40).contains(&count(&t, " emitter ")), "{t}");
            let t = family_text("sun-sky", seed).unwrap();
            assert!(t.contains("material sun emitter blackbody") && t.contains("environment"));
            let t = family_text("caustic-fireflies", seed).unwrap();
            assert!(count(&t, "material spark") >= 1, "{t}");
            let t = family_text("glossy-interior", seed).unwrap();
            assert!(t.contains("material mirror conductor"), "{t}");
            let t = family_text("fine-texture", seed).unwrap();
            assert!(!t.contains("reflectance rgb"), "only patterns: {t}");
        }
    }

    #[test]
    fn no_family_writes_a_roughness_the_tracer_cannot_take() {
        for family in FAMILIES {
            for seed in 0..200 {
                let t = family_text(family, seed).unwrap();
                for w in t.split(" roughness ").skip(1) {
                    let words: Vec<&str> = w.split_whitespace().take(4).collect();
                    // A value, or PATTERN A B FREQ.
                    let values = match words[0].parse::<f32>() {
                        Ok(v) => vec![v],
                        Err(_) => vec![words[1].parse().unwrap(), words[2].parse().unwrap()],
                    };
                    for v in values {
                        assert!(v == 0.0 || v >= 0.01, "{family} {seed}: roughness {v}");
                    }
                }
            }
        }
    }

    #[test]
    fn scenes_of_every_family_render_without_nan() {
        let settings = Settings {
            width: 12,
            height: 12,
            spp: 4,
            ..Settings::default()
        };
        for (k, family) in FAMILIES.iter().enumerate() {
            let t = family_text(family, 7 + k as u64).unwrap();
            let img = render(&parse(&t, family, None).unwrap(), &settings);
            assert!(
                img.color.iter().flatten().all(|v| v.is_finite()),
                "{family}: {t}"
            );
            let sum: f32 = img.color.iter().flatten().sum();
            assert!(sum > 0.0, "{family} renders black");
        }
    }
}
