//! The acceleration structures: the paper's uniform grid with proximity clouds and its traversal,
//! and a BVH to compare it with.

pub mod aabb;
pub mod bvh;
pub mod grid;
pub mod huge;
pub mod proximity;
pub mod traverse;
pub mod tri_box;
pub mod triangle;

pub use aabb::Aabb;
pub use bvh::{Bvh, BvhAccel, BvhNode};
pub use grid::{Cell, Grid, GridStats, Resolution};
pub use traverse::{
    AccelKind, Counters, GridAccel, Hit, NoCounters, Ray, TraversalCounters, brute_force_intersect,
    brute_force_occluded,
};
pub use triangle::{TriAccel, TriAccel4, TriHit, TriHit4};
