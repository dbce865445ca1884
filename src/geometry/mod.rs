//! Geometry: triangle meshes and their file formats, voxel grids, distance transforms,
//! iso-surface extraction, rasterization, smoothing and nearest-point queries.

pub mod axes;
pub mod cell_grid;
pub mod cone_distance;
pub mod distance;
pub mod grid;
pub mod isosurface;
pub mod mesh;
pub mod nearest;
pub mod obj;
pub mod oriented_nearest;
pub mod ply;
pub mod raster;
pub mod smooth;
pub mod up;

pub use mesh::TriMesh;
