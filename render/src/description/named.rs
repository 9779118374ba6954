//! The named scenes: scene files embedded in the binary, each stressing one thing a
//! denoiser finds hard.

use crate::description::format;
use crate::scene::Scene;

/// The named scenes: name, what it stresses, scene file text.
pub const NAMED: [(&str, &str, &str); 11] = [
    (
        "cornell-spiky",
        "Cornell box under a spiky fluorescent lamp: chroma speckle on white walls",
        include_str!("../../scenes/cornell-spiky.scene"),
    ),
    (
        "cornell-warm",
        "the same box under a 3200 K blackbody (the smooth-spectrum control)",
        include_str!("../../scenes/cornell-warm.scene"),
    ),
    (
        "prism",
        "a dispersive N-SF11 prism and glass sphere under a small white lamp: rainbow caustics",
        include_str!("../../scenes/prism.scene"),
    ),
    (
        "metals",
        "gold, silver, copper and aluminium, smooth and rough, under D65",
        include_str!("../../scenes/metals.scene"),
    ),
    (
        "textured",
        "checker, stripes, noise and fine-grid textures on reflectance and roughness",
        include_str!("../../scenes/textured.scene"),
    ),
    (
        "dark-room",
        "a room lit only indirectly through a gap: dim, slowly converging",
        include_str!("../../scenes/dark-room.scene"),
    ),
    (
        "firefly",
        "a tiny, very bright lamp seen through glossy bounces: fireflies",
        include_str!("../../scenes/firefly.scene"),
    ),
    (
        "laser",
        "a 532 nm laser-line lamp beside a warm lamp: wavelength sampling on a line",
        include_str!("../../scenes/laser.scene"),
    ),
    (
        "many-lights",
        "64 small ceiling lamps whose power spans 100x: light selection by power",
        include_str!("../../scenes/many-lights.scene"),
    ),
    (
        "line-lamp",
        "a one-sided lamp with a measured line spectrum written as a table",
        include_str!("../../scenes/line-lamp.scene"),
    ),
    (
        "furnace",
        "white furnace: a white sphere in a uniform environment (every pixel is 1)",
        include_str!("../../scenes/furnace.scene"),
    ),
];

/// The names [`scene`] knows.
pub fn names() -> Vec<&'static str> {
    NAMED.iter().map(|n| n.0).collect()
}

/// A named scene.
///
/// # Panics
/// If a built-in scene file does not parse (a test parses every one).
pub fn scene(name: &str) -> Option<Scene> {
    let (n, _, text) = NAMED.iter().find(|n| n.0 == name)?;
    Some(
        format::parse(text, n, None)
            .unwrap_or_else(|e| panic!("built-in scene {n} does not parse: {e}")),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_named_scene_parses_and_has_light() {
        for (name, _, _) in NAMED {
            let s = scene(name).unwrap();
            assert!(!s.prims.is_empty(), "{name}");
            assert!(
                !s.lights().is_empty() || s.environment.is_some(),
                "{name} has no light"
            );
        }
    }
}
