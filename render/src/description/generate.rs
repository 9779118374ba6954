//! Random scenes from a seed, for training diversity. The generator writes scene-file
//! text (so every data-set scene can be read, edited and re-rendered) in two layouts: a
//! closed room lit by ceiling panels, and an open floor under a sky with a lamp. The layouts
//! it never trains on are in [`super::held_out`].

use std::fmt::Write;

use crate::rng::Rng;

pub(super) struct Gen(pub(super) Rng);

impl Gen {
    pub(super) fn u(&mut self) -> f32 {
        self.0.uniform()
    }
    pub(super) fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.u()
    }
    pub(super) fn pick<'a, T>(&mut self, v: &'a [T]) -> &'a T {
        &v[((self.u() * v.len() as f32) as usize).min(v.len() - 1)]
    }
    pub(super) fn chance(&mut self, p: f32) -> bool {
        self.u() < p
    }
    fn rgb(&mut self, lo: f32, hi: f32) -> String {
        // Saturated colours as often as pastel ones.
        let base = self.range(lo, hi);
        let c: Vec<f32> = (0..3)
            .map(|_| {
                if self.chance(0.5) {
                    base
                } else {
                    self.range(lo, hi)
                }
            })
            .collect();
        format!("{:.3} {:.3} {:.3}", c[0], c[1], c[2])
    }
    pub(super) fn texture(&mut self, lo: f32, hi: f32) -> String {
        let pattern = *self.pick(&["rgb", "rgb", "checker", "stripes", "noise", "fine"]);
        if pattern == "rgb" {
            return format!("rgb {}", self.rgb(lo, hi));
        }
        let freq = match pattern {
            "fine" => self.range(6.0, 30.0),
            _ => self.range(1.5, 12.0),
        };
        format!(
            "{pattern} {} {} {freq:.2}",
            self.rgb(lo, hi),
            self.rgb(lo, hi)
        )
    }
    fn roughness(&mut self) -> String {
        if self.chance(0.25) {
            return "0".into();
        }
        if self.chance(0.2) {
            let (a, b) = (self.range(0.01, 0.15), self.range(0.2, 0.5));
            let p = *self.pick(&["checker", "stripes", "noise"]);
            return format!("{p} {a:.3} {b:.3} {:.2}", self.range(2.0, 10.0));
        }
        format!("{:.3}", self.range(0.02, 0.45))
    }
    /// The `floor` and `wall` materials: diffuse, textured, reflectance in the (lo, hi)
    /// ranges given.
    pub(super) fn floor_and_wall(&mut self, s: &mut String, floor: (f32, f32), wall: (f32, f32)) {
        for (name, (lo, hi)) in [("floor", floor), ("wall", wall)] {
            let t = self.texture(lo, hi);
            let _ = writeln!(s, "material {name} diffuse reflectance {t}");
        }
    }
    pub(super) fn spectrum(&mut self) -> String {
        match self.u() {
            x if x < 0.35 => format!("blackbody {:.0}", self.range(2200.0, 9000.0)),
            x if x < 0.55 => "d65".into(),
            x if x < 0.85 => "fluorescent".into(),
            x if x < 0.93 => format!(
                "laser {:.0} {:.1}",
                self.range(420.0, 660.0),
                self.range(0.5, 4.0)
            ),
            _ => format!("rgb {}", self.rgb(0.3, 1.0)),
        }
    }
    pub(super) fn material(&mut self, name: &str) -> String {
        match self.u() {
            x if x < 0.4 => format!(
                "material {name} diffuse reflectance {}",
                self.texture(0.05, 0.9)
            ),
            x if x < 0.6 => format!(
                "material {name} plastic reflectance {} ior {:.2} roughness {}",
                self.texture(0.05, 0.9),
                self.range(1.3, 1.8),
                self.roughness()
            ),
            x if x < 0.8 => format!(
                "material {name} conductor metal {} roughness {}",
                self.pick(&["Au", "Ag", "Cu", "Al"]),
                self.roughness()
            ),
            _ => {
                let ior = match self.u() {
                    x if x < 0.3 => format!("ior {:.2}", self.range(1.3, 1.9)),
                    x if x < 0.55 => "sellmeier bk7".into(),
                    x if x < 0.8 => "sellmeier sf11".into(),
                    _ => format!(
                        "cauchy {:.3} {:.4}",
                        self.range(1.4, 1.7),
                        self.range(0.004, 0.03)
                    ),
                };
                let r = if self.chance(0.7) {
                    "0".to_string()
                } else {
                    format!("{:.3}", self.range(0.02, 0.3))
                };
                format!("material {name} dielectric {ior} roughness {r}")
            }
        }
    }
}

/// A random scene's text, deterministic in `seed`.
pub fn scene_text(seed: u64) -> String {
    let mut g = Gen(Rng::new(seed ^ 0x5eed_5ce7e, seed));
    let mut s = String::new();
    let room = g.chance(0.55);
    let _ = writeln!(
        s,
        "# Random scene {seed} ({})",
        if room { "room" } else { "open" }
    );
    let (w, d, h) = (g.range(3.0, 6.0), g.range(3.0, 6.0), g.range(2.2, 3.5));
    // Objects stand in the middle third; the camera sits near the front looking in.
    let look = (g.range(-0.3, 0.3), g.range(0.2, 0.8), g.range(-0.3, 0.3));
    let eye = (
        g.range(-0.4, 0.4) * w,
        g.range(0.4, 0.8) * h.min(2.5),
        -0.48 * d,
    );
    let _ = writeln!(
        s,
        "camera eye {:.3} {:.3} {:.3} target {:.3} {:.3} {:.3} fov {:.1}",
        eye.0,
        eye.1,
        eye.2,
        look.0,
        look.1,
        look.2,
        g.range(35.0, 65.0)
    );
    g.floor_and_wall(&mut s, (0.1, 0.85), (0.2, 0.85));
    let (x0, z0) = (-w / 2.0, -d / 2.0);
    let _ = writeln!(
        s,
        "quad corner {x0:.3} 0 {z0:.3} edge1 0 0 {d:.3} edge2 {w:.3} 0 0 material floor"
    );
    let lights = 1 + g.chance(0.35) as usize;
    for l in 0..lights {
        let spec = g.spectrum();
        let _ = writeln!(
            s,
            "material lamp{l} emitter {spec} scale {:.2}",
            g.range(4.0, 30.0) / lights as f32
        );
    }
    let shell = Shell {
        w,
        d,
        h,
        x0,
        z0,
        lights,
    };
    if room {
        g.room(&mut s, &shell);
    } else {
        g.open(&mut s, &shell);
    }
    g.objects(&mut s, w, d);
    s
}

/// The layout's size (width, depth, height, the floor's corner) and its lamp count.
struct Shell {
    w: f32,
    d: f32,
    h: f32,
    x0: f32,
    z0: f32,
    lights: usize,
}

impl Gen {
    /// A closed room: ceiling and four walls, lit by ceiling panels.
    fn room(&mut self, s: &mut String, b: &Shell) {
        let Shell {
            w,
            d,
            h,
            x0,
            z0,
            lights,
        } = *b;
        let _ = writeln!(
            s,
            "quad corner {x0:.3} {h:.3} {z0:.3} edge1 {w:.3} 0 0 edge2 0 0 {d:.3} material wall"
        );
        let _ = writeln!(
            s,
            "quad corner {x0:.3} 0 {:.3} edge1 {w:.3} 0 0 edge2 0 {h:.3} 0 material wall",
            -z0
        );
        let _ = writeln!(
            s,
            "quad corner {x0:.3} 0 {z0:.3} edge1 0 {h:.3} 0 edge2 0 0 {d:.3} material wall"
        );
        let _ = writeln!(
            s,
            "quad corner {:.3} 0 {z0:.3} edge1 0 0 {d:.3} edge2 0 {h:.3} 0 material wall",
            -x0
        );
        let _ = writeln!(
            s,
            "quad corner {x0:.3} 0 {z0:.3} edge1 {w:.3} 0 0 edge2 0 {h:.3} 0 material wall"
        );
        for l in 0..lights {
            let (lw, ld) = (self.range(0.2, 1.2), self.range(0.2, 1.2));
            let (lx, lz) = (self.range(-0.35, 0.35) * w, self.range(-0.2, 0.4) * d);
            let _ = writeln!(
                s,
                "quad corner {:.3} {:.3} {:.3} edge1 {lw:.3} 0 0 edge2 0 0 {ld:.3} material lamp{l}",
                lx - lw / 2.0,
                h - 0.002,
                lz - ld / 2.0
            );
        }
    }

    /// An open floor under a sky, with a back wall and lamps above.
    fn open(&mut self, s: &mut String, b: &Shell) {
        let Shell {
            w,
            h,
            x0,
            z0,
            lights,
            ..
        } = *b;
        let sky = if self.chance(0.5) {
            format!("blackbody {:.0}", self.range(6000.0, 15000.0))
        } else {
            "d65".into()
        };
        let _ = writeln!(s, "environment {sky} scale {:.3}", self.range(0.05, 0.8));
        let _ = writeln!(
            s,
            "quad corner {x0:.3} 0 {:.3} edge1 {w:.3} 0 0 edge2 0 {h:.3} 0 material wall",
            -z0
        );
        for l in 0..lights {
            if self.chance(0.5) {
                let _ = writeln!(
                    s,
                    "sphere center {:.3} {:.3} {:.3} radius {:.3} material lamp{l}",
                    self.range(-1.5, 1.5),
                    self.range(1.5, 3.0),
                    self.range(-1.0, 1.5),
                    self.range(0.05, 0.3)
                );
            } else {
                let sz = self.range(0.3, 1.5);
                let _ = writeln!(
                    s,
                    "quad corner {:.3} {:.3} {:.3} edge1 {sz:.3} 0 0 edge2 0 0 {sz:.3} material lamp{l}",
                    self.range(-1.5, 1.0),
                    self.range(2.0, 3.5),
                    self.range(-1.0, 1.0)
                );
            }
        }
    }

    /// Two to six objects with random materials in the middle of the floor.
    pub(super) fn objects(&mut self, s: &mut String, w: f32, d: f32) {
        let n = 2 + (self.u() * 5.0) as usize;
        for i in 0..n {
            let m = self.material(&format!("m{i}"));
            let _ = writeln!(s, "{m}");
            let (x, z) = (self.range(-0.3, 0.3) * w, self.range(-0.1, 0.3) * d);
            let size = self.range(0.2, 0.6);
            let shape = match self.u() {
                v if v < 0.4 => format!("sphere center {x:.3} {size:.3} {z:.3} radius {size:.3}"),
                v if v < 0.65 => format!(
                    "box min {:.3} 0 {:.3} max {:.3} {:.3} {:.3} rotate {:.1}",
                    x - size,
                    z - size,
                    x + size,
                    self.range(0.3, 1.5),
                    z + size,
                    self.range(0.0, 90.0)
                ),
                v if v < 0.85 => format!(
                    "prism center {x:.3} 0 {z:.3} size {:.3} height {:.3} rotate {:.1}",
                    2.0 * size,
                    self.range(0.3, 1.2),
                    self.range(0.0, 180.0)
                ),
                _ => format!(
                    "torus center {x:.3} {:.3} {z:.3} radii {:.3} {:.3} tilt {:.1}",
                    size + 0.2,
                    size,
                    size * 0.35,
                    self.range(0.0, 90.0)
                ),
            };
            let _ = writeln!(s, "{shape} material m{i}");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn generated_scenes_parse_and_are_deterministic() {
        let mut kinds = std::collections::HashSet::new();
        for seed in 0..200 {
            let t = scene_text(seed);
            assert_eq!(t, scene_text(seed));
            let s = crate::description::format::parse(&t, "gen", None)
                .unwrap_or_else(|e| panic!("{e}\n{t}"));
            let f = s.features();
            kinds.insert((f.dispersion, f.transmission, f.spiky_emitters, f.glossy));
        }
        // The generator covers the kernels' feature combinations.
        assert!(kinds.len() >= 6, "{kinds:?}");
    }
}
