//! The pinhole camera: where the scene is seen from, and the ray through a point of a
//! pixel.

use crate::geometry::vec3::V3;
use crate::rng::Rng;

/// A pinhole camera, as a scene describes it. The world is right-handed with y up: a
/// camera looking along -z has +x on its right, one looking along +z has +x on its left.
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
        // Right-handed world (y up): the image's x runs along forward x up, so what lies to
        // the camera's left (up x forward) appears on the image's left.
        let right = fwd.cross(V3(0.0, 1.0, 0.0)).norm();
        Pinhole {
            eye: self.eye,
            fwd,
            right,
            up: right.cross(fwd),
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Horizontal image position (0 = left edge, 1 = right edge) of the ray nearest to `p`.
    fn image_x(cam: &Camera, p: V3) -> f32 {
        let pin = cam.pinhole(64, 64);
        let mut rng = Rng::new(1, 1);
        let want = (p - cam.eye).norm();
        let best = (0..64)
            .max_by(|&a, &b| {
                let da = pin.ray(a, 32, &mut rng).1.dot(want);
                let db = pin.ray(b, 32, &mut rng).1.dot(want);
                da.total_cmp(&db)
            })
            .unwrap();
        best as f32 / 63.0
    }

    #[test]
    fn what_lies_to_the_cameras_left_appears_on_the_images_left() {
        for (eye, target) in [
            (V3(0.0, 0.0, 3.0), V3(0.0, 0.0, 0.0)),  // looking along -z
            (V3(0.0, 0.0, -3.0), V3(0.0, 0.0, 0.0)), // along +z
            (V3(-3.0, 1.0, 0.0), V3(0.0, 0.0, 0.0)), // along +x, a little down
        ] {
            let cam = Camera {
                eye,
                target,
                fov_deg: 40.0,
            };
            let fwd = (target - eye).norm();
            let left = V3(0.0, 1.0, 0.0).cross(fwd).norm();
            assert!(image_x(&cam, target + left * 0.5) < 0.3, "{eye:?}");
            assert!(image_x(&cam, target - left * 0.5) > 0.7, "{eye:?}");
        }
        // The convention spelled out: looking along -z, +x is on the right.
        let cam = Camera {
            eye: V3(0.0, 0.0, 3.0),
            target: V3(0.0, 0.0, 0.0),
            fov_deg: 40.0,
        };
        assert!(image_x(&cam, V3(0.5, 0.0, 0.0)) > 0.7);
    }
}
