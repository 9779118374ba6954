//! Geometry: vectors, the primitives and their builders, and the BVH that finds hits.

pub mod bvh;
pub mod shape;
pub mod vec3;

/// How far a new ray's origin is pushed off the surface it leaves, so it does not hit that
/// surface again through rounding.
pub const RAY_OFFSET: f32 = 1e-4;
