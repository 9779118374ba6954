//! Scene families held out of training: layouts and lighting that neither
//! [`super::generate`] nor [`super::families`] ever makes, rendered into the test split
//! only. Held-out seeds of the training generator show whether a model generalises across
//! seeds; these show whether it learnt denoising or our generator's rooms (issue 15: "hold
//! out whole scene families, not just seeds").
//!
//! - `window`: a closed room with no lamp inside, lit by a sky and a small, very bright sun
//!   through one window in a side wall: a sunlit patch, the rest indirect light.
//! - `corridor`: a long, narrow hall seen along its length, lit by a row of small sphere
//!   lamps along the walls: many small bright emitters at grazing angles, falling off with
//!   depth.

use std::fmt::Write;

use super::generate::{closed_room, quad, Gen};
use crate::rng::Rng;

/// The held-out families, by name.
pub const FAMILIES: [&str; 2] = ["window", "corridor"];

/// A scene of held-out `family`, deterministic in `seed`; `None` for an unknown family.
pub fn scene_text(family: &str, seed: u64) -> Option<String> {
    // Another stream than the training generator's, so no seed gives it the same numbers.
    let mut g = Gen(Rng::new(seed ^ 0x401d_0075, seed));
    let mut s = format!("# Held-out scene {seed} ({family})\n");
    match family {
        "window" => window(&mut g, &mut s),
        "corridor" => corridor(&mut g, &mut s),
        _ => return None,
    }
    Some(s)
}

/// A room lit only through a window in its left wall.
fn window(g: &mut Gen, s: &mut String) {
    let (w, h, d) = (g.range(3.5, 6.0), g.range(2.4, 3.2), g.range(3.5, 6.0));
    let _ = writeln!(
        s,
        "camera eye {:.3} {:.3} {:.3} target {:.3} {:.3} {:.3} fov {:.1}",
        g.range(0.1, 0.4) * w,
        g.range(1.0, 1.7),
        -0.45 * d,
        g.range(-0.4, 0.0) * w,
        g.range(0.4, 1.0),
        g.range(0.0, 0.3) * d,
        g.range(40.0, 65.0)
    );
    closed_room(g, s, (w, h, d), true);
    // The left wall, built round an opening: below, above, in front and behind.
    let (x0, z0) = (-w / 2.0, -d / 2.0);
    let (y0, y1) = (g.range(0.6, 1.0), h - g.range(0.3, 0.6));
    let (za, zb) = (g.range(-0.35, 0.0) * d, g.range(0.1, 0.4) * d);
    quad(s, [x0, 0.0, z0], [0.0, y0, 0.0], [0.0, 0.0, d], "wall");
    quad(s, [x0, y1, z0], [0.0, h - y1, 0.0], [0.0, 0.0, d], "wall");
    quad(
        s,
        [x0, y0, z0],
        [0.0, y1 - y0, 0.0],
        [0.0, 0.0, za - z0],
        "wall",
    );
    quad(
        s,
        [x0, y0, zb],
        [0.0, y1 - y0, 0.0],
        [0.0, 0.0, -z0 - zb],
        "wall",
    );
    let sky = if g.chance(0.5) {
        "d65".to_string()
    } else {
        format!("blackbody {:.0}", g.range(7000.0, 14000.0))
    };
    let _ = writeln!(s, "environment {sky} scale {:.3}", g.range(0.1, 0.8));
    // The sun: 0.6 m wide at 25 m (about 0.0018 sr), placed so it shines in through the
    // opening and down onto the floor.
    let (elev, az) = (g.range(0.35, 0.9), g.range(-0.5, 0.5));
    let (cy, cz) = ((y0 + y1) / 2.0, (za + zb) / 2.0);
    let dir = [-elev.cos() * az.cos(), elev.sin(), elev.cos() * az.sin()];
    let _ = writeln!(
        s,
        "material sun emitter blackbody {:.0} scale {:.0}",
        g.range(4500.0, 6500.0),
        g.range(800.0, 4000.0)
    );
    let _ = writeln!(
        s,
        "sphere center {:.3} {:.3} {:.3} radius 0.6 material sun",
        x0 + 25.0 * dir[0],
        cy + 25.0 * dir[1],
        cz + 25.0 * dir[2]
    );
    g.objects(s, w, d);
}

/// A long hall lit by small lamps along both walls.
fn corridor(g: &mut Gen, s: &mut String) {
    let (w, h, d) = (g.range(1.6, 2.6), g.range(2.4, 3.2), g.range(8.0, 14.0));
    let _ = writeln!(
        s,
        "camera eye {:.3} {:.3} {:.3} target {:.3} {:.3} {:.3} fov {:.1}",
        g.range(-0.2, 0.2) * w,
        g.range(1.2, 1.7),
        -0.46 * d,
        g.range(-0.1, 0.1) * w,
        g.range(0.8, 1.4),
        0.3 * d,
        g.range(40.0, 60.0)
    );
    closed_room(g, s, (w, h, d), false);
    let lamps = 3 + (g.u() * 4.0) as usize;
    let spec = g.spectrum();
    let _ = writeln!(
        s,
        "material lamp emitter {spec} scale {:.0}",
        g.range(150.0, 800.0)
    );
    let (y, r) = (g.range(1.7, h - 0.3), g.range(0.03, 0.08));
    for k in 0..lamps {
        let z = -0.45 * d + (k as f32 + 0.5) * 0.9 * d / lamps as f32;
        for side in [-1.0f32, 1.0] {
            let x = side * (w / 2.0 - r - 0.05);
            let _ = writeln!(
                s,
                "sphere center {x:.3} {y:.3} {z:.3} radius {r:.3} material lamp"
            );
        }
    }
    g.objects(s, w, d * 0.3);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::description::format::parse;
    use crate::render::{render, Settings};

    #[test]
    fn held_out_scenes_parse_and_are_deterministic() {
        for family in FAMILIES {
            for seed in 0..50 {
                let t = scene_text(family, seed).unwrap();
                assert_eq!(Some(&t), scene_text(family, seed).as_ref());
                parse(&t, family, None).unwrap_or_else(|e| panic!("{e}\n{t}"));
            }
        }
        assert!(scene_text("attic", 0).is_none());
    }

    fn mean_luminance(text: &str) -> f64 {
        let scene = parse(text, "t", None).unwrap();
        let settings = Settings {
            width: 24,
            height: 24,
            spp: 16,
            ..Settings::default()
        };
        let img = render(&scene, &settings);
        img.color
            .iter()
            .map(|c| f64::from(c[0] + c[1] + c[2]))
            .sum::<f64>()
            / img.color.len() as f64
    }

    #[test]
    fn the_sun_lights_the_window_room_through_its_opening() {
        // Without the sun only the sky through the window lights the room; a sun that
        // shines in through the opening adds a sunlit patch (one behind a wall adds nothing).
        for seed in 0..3 {
            let t = scene_text("window", seed).unwrap();
            let dark = t.replace("radius 0.6 material sun", "radius 0.6 material wall");
            let (lit, sky) = (mean_luminance(&t), mean_luminance(&dark));
            assert!(
                lit > 1.25 * sky && sky > 0.0,
                "seed {seed}: {lit} vs sky only {sky}"
            );
        }
    }
}
