//! The scene description, the input side of rendering: the scene file format, OBJ meshes,
//! random scenes from a seed (the `v2` generator and the other families of
//! `--families all`), the held-out scene families, and the named scenes. All of them end
//! in [`format::parse`], which assembles a [`crate::scene::Scene`].

pub mod families;
pub mod format;
pub mod generate;
pub mod held_out;
pub mod named;
pub mod obj;
