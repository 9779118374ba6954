//! A small 3-vector for geometry.

use std::ops::{Add, Div, Mul, Neg, Sub};

/// A point or direction in 3-D.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct V3(pub f32, pub f32, pub f32);

impl V3 {
    /// Dot product.
    pub fn dot(self, o: V3) -> f32 {
        self.0 * o.0 + self.1 * o.1 + self.2 * o.2
    }
    /// Cross product.
    pub fn cross(self, o: V3) -> V3 {
        V3(
            self.1 * o.2 - self.2 * o.1,
            self.2 * o.0 - self.0 * o.2,
            self.0 * o.1 - self.1 * o.0,
        )
    }
    /// Length.
    pub fn len(self) -> f32 {
        self.dot(self).sqrt()
    }
    /// Unit vector in the same direction.
    pub fn norm(self) -> V3 {
        self / self.len()
    }
}

impl Add for V3 {
    type Output = V3;
    fn add(self, o: V3) -> V3 {
        V3(self.0 + o.0, self.1 + o.1, self.2 + o.2)
    }
}
impl Sub for V3 {
    type Output = V3;
    fn sub(self, o: V3) -> V3 {
        V3(self.0 - o.0, self.1 - o.1, self.2 - o.2)
    }
}
impl Mul<f32> for V3 {
    type Output = V3;
    fn mul(self, s: f32) -> V3 {
        V3(self.0 * s, self.1 * s, self.2 * s)
    }
}
impl Div<f32> for V3 {
    type Output = V3;
    fn div(self, s: f32) -> V3 {
        V3(self.0 / s, self.1 / s, self.2 / s)
    }
}
impl Neg for V3 {
    type Output = V3;
    fn neg(self) -> V3 {
        V3(-self.0, -self.1, -self.2)
    }
}

/// An orthonormal basis around `n` (Duff et al. 2017's branchless construction).
pub fn basis(n: V3) -> (V3, V3) {
    let s = if n.2 >= 0.0 { 1.0 } else { -1.0 };
    let a = -1.0 / (s + n.2);
    let b = n.0 * n.1 * a;
    (
        V3(1.0 + s * n.0 * n.0 * a, s * b, -s * n.0),
        V3(b, s + n.1 * n.1 * a, -n.1),
    )
}
