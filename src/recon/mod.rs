//! The reconstruction algorithms, one module per step, as plain functions on typed data:
//! silhouettes, the voxel visual hull, the graph-cut refinement and the per-vertex
//! reliability. They read no files and know nothing of the cache; the stages in
//! [`crate::stages`] feed them and store what they return.

pub mod graphcut;
pub mod learned_background;
pub mod reliability;
pub mod silhouette;
pub mod visual_hull;
