//! Geometry: triangle meshes and their file formats, iso-surface extraction.

pub mod isosurface;
pub mod mesh;
pub mod ply;

pub use mesh::TriMesh;
