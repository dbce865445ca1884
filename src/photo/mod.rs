//! The photo-consistency primitives the graph cut (stage 3), the reliability (stage 4), the
//! evaluation and the exports share: grey images ([`grey`]), patches on a tangent plane
//! ([`patch`]), ZNCC ([`zncc`]) and depth maps for visibility ([`depth`]).

pub mod depth;
pub mod grey;
pub mod patch;
pub mod refine;
pub mod zncc;

pub use depth::{depth_maps, farthest_around, Visibility};
pub use grey::{grey, GreyImage};
pub use patch::{mean_pair_zncc, patch_grid, sample_patch};
pub use zncc::{dot, normalize, zncc, zncc_of_pairs};
