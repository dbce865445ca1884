//! Wavefront OBJ writing (positions, optional normals, triangles).

use super::mesh::TriMesh;
use crate::error::Result;
use nalgebra::Vector3;
use std::io::Write;
use std::path::Path;

/// Writes `mesh` (with `normals` if given) as OBJ text.
pub fn write_obj_to(
    w: &mut dyn Write,
    mesh: &TriMesh,
    normals: Option<&[Vector3<f64>]>,
) -> std::io::Result<()> {
    writeln!(
        w,
        "# written by hullpose: {} vertices, {} triangles",
        mesh.vertices.len(),
        mesh.triangles.len()
    )?;
    for v in &mesh.vertices {
        writeln!(w, "v {} {} {}", v.x as f32, v.y as f32, v.z as f32)?;
    }
    if let Some(ns) = normals {
        for n in ns {
            writeln!(w, "vn {} {} {}", n.x as f32, n.y as f32, n.z as f32)?;
        }
    }
    for t in &mesh.triangles {
        let [a, b, c] = t.map(|i| i + 1);
        if normals.is_some() {
            writeln!(w, "f {a}//{a} {b}//{b} {c}//{c}")?;
        } else {
            writeln!(w, "f {a} {b} {c}")?;
        }
    }
    Ok(())
}

/// Writes an OBJ file atomically.
pub fn write_obj(path: &Path, mesh: &TriMesh, normals: Option<&[Vector3<f64>]>) -> Result<()> {
    crate::fsutil::write_atomic_with(path, |w| write_obj_to(w, mesh, normals))
}
