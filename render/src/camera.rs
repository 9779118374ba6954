//! The pinhole camera: where the scene is seen from, and the ray through a point of a
//! pixel.

use crate::geometry::vec3::V3;
use crate::rng::Rng;

/// A pinhole camera, as a scene describes it.
#[derive(Clone, Debug)]
pub struct Camera {
    /// Eye position.
    pub eye: V3,
    /// Point looked at.
    pub target: V3,
    /// Vertical field of view, degrees.
    pub fov_deg: f32,
}

/// A camera set up for one image size: the frame and the scale from pixels to directions.
#[derive(Clone, Copy, Debug)]
pub struct Pinhole {
    eye: V3,
    fwd: V3,
    right: V3,
    up: V3,
    tan: f32,
    aspect: f32,
    width: usize,
    height: usize,
}

impl Camera {
    /// The camera for a `width` x `height` image (y is up, so the camera must not look
    /// straight up or down; the scene format refuses that).
    pub fn pinhole(&self, width: usize, height: usize) -> Pinhole {
        let fwd = (self.target - self.eye).norm();
        let right = V3(0.0, 1.0, 0.0).cross(fwd).norm();
        Pinhole {
            eye: self.eye,
            fwd,
            right,
            up: fwd.cross(right),
            tan: (self.fov_deg.to_radians() * 0.5).tan(),
            aspect: width as f32 / height as f32,
            width,
            height,
        }
    }
}

impl Pinhole {
    /// Origin and unit direction of a ray through a uniformly jittered point of pixel
    /// (x, y), row 0 at the top. Draws two numbers from `rng`, x's first.
    pub fn ray(&self, x: usize, y: usize, rng: &mut Rng) -> (V3, V3) {
        let sx =
            (2.0 * (x as f32 + rng.uniform()) / self.width as f32 - 1.0) * self.tan * self.aspect;
        let sy = (1.0 - 2.0 * (y as f32 + rng.uniform()) / self.height as f32) * self.tan;
        (self.eye, (self.fwd + self.right * sx + self.up * sy).norm())
    }
}
