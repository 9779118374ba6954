//! Procedural textures on reflectance and roughness, evaluated on a surface's (u, v)
//! coordinates in scene units, so the data set carries detail the denoiser must keep.

/// How two values are mixed over the surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Pattern {
    /// Value `a` everywhere.
    Uniform,
    /// A checkerboard of `a` and `b` squares, `freq` squares per unit.
    Checker,
    /// Stripes along u, `freq` stripe pairs per unit.
    Stripes,
    /// Smooth value noise (three octaves) blending `a` into `b`.
    Noise,
    /// Thin `b` grid lines on `a`: high-frequency detail near the pixel scale.
    Fine,
}

/// A texture: a pattern blending `a` into `b`. Scalar textures use the first component.
#[derive(Clone, Copy, Debug)]
pub struct Texture {
    /// The pattern.
    pub pattern: Pattern,
    /// First value.
    pub a: [f32; 3],
    /// Second value.
    pub b: [f32; 3],
    /// Spatial frequency, features per scene unit.
    pub freq: f32,
}

impl Pattern {
    /// Whether the blend weight is only ever exactly 0 or 1 (the texture takes two
    /// colours).
    pub fn two_tone(self) -> bool {
        !matches!(self, Pattern::Noise)
    }
}

impl Texture {
    /// The same value everywhere.
    pub fn uniform(v: [f32; 3]) -> Self {
        Texture {
            pattern: Pattern::Uniform,
            a: v,
            b: v,
            freq: 1.0,
        }
    }

    /// A uniform scalar.
    pub fn scalar(v: f32) -> Self {
        Self::uniform([v; 3])
    }

    /// Blend weight of `b` at (u, v), in [0, 1].
    pub fn weight(&self, u: f32, v: f32) -> f32 {
        let (x, y) = (u * self.freq, v * self.freq);
        match self.pattern {
            Pattern::Uniform => 0.0,
            Pattern::Checker => ((x.floor() + y.floor()) as i64 & 1) as f32,
            Pattern::Stripes => (x.floor() as i64 & 1) as f32,
            Pattern::Noise => {
                let n = 0.5 * value_noise(x, y)
                    + 0.3 * value_noise(2.1 * x + 7.3, 2.1 * y + 1.7)
                    + 0.2 * value_noise(4.3 * x + 3.1, 4.3 * y + 9.2);
                n.clamp(0.0, 1.0)
            }
            Pattern::Fine => {
                let line = |t: f32| t - t.floor() < 0.18;
                (line(x) || line(y)) as u8 as f32
            }
        }
    }

    /// Colour at (u, v).
    pub fn eval(&self, u: f32, v: f32) -> [f32; 3] {
        let w = self.weight(u, v);
        std::array::from_fn(|i| self.a[i] + (self.b[i] - self.a[i]) * w)
    }

    /// Scalar at (u, v).
    pub fn eval_scalar(&self, u: f32, v: f32) -> f32 {
        self.eval(u, v)[0]
    }
}

fn hash(i: i32, j: i32) -> f32 {
    let mut h = (i as u32).wrapping_mul(0x8da6_b343) ^ (j as u32).wrapping_mul(0xd816_3841);
    h ^= h >> 13;
    h = h.wrapping_mul(0x85eb_ca6b);
    h ^= h >> 16;
    (h & 0xffff) as f32 / 65535.0
}

/// Bilinear value noise with a smoothstep fade, in [0, 1].
fn value_noise(x: f32, y: f32) -> f32 {
    let (i, j) = (x.floor() as i32, y.floor() as i32);
    let (fx, fy) = (x - x.floor(), y - y.floor());
    let s = |t: f32| t * t * (3.0 - 2.0 * t);
    let (sx, sy) = (s(fx), s(fy));
    let a = hash(i, j) + (hash(i + 1, j) - hash(i, j)) * sx;
    let b = hash(i, j + 1) + (hash(i + 1, j + 1) - hash(i, j + 1)) * sx;
    a + (b - a) * sy
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn patterns_stay_between_their_values() {
        for pattern in [
            Pattern::Uniform,
            Pattern::Checker,
            Pattern::Stripes,
            Pattern::Noise,
            Pattern::Fine,
        ] {
            let t = Texture {
                pattern,
                a: [0.1, 0.2, 0.3],
                b: [0.9, 0.5, 0.3],
                freq: 7.0,
            };
            let mut seen_b = false;
            for k in 0..2000 {
                let (u, v) = (k as f32 * 0.0137 - 5.0, (k * 7 % 113) as f32 * 0.031);
                let w = t.weight(u, v);
                assert!((0.0..=1.0).contains(&w), "{pattern:?} {w}");
                seen_b |= w > 0.5;
                let c = t.eval(u, v);
                assert!(c[0] >= 0.1 - 1e-6 && c[0] <= 0.9 + 1e-6);
            }
            assert_eq!(seen_b, pattern != Pattern::Uniform, "{pattern:?}");
        }
    }
}
