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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_vertices_normals_and_one_based_faces() {
        let mesh = TriMesh {
            vertices: vec![Vector3::zeros(), Vector3::x(), Vector3::y()],
            triangles: vec![[0, 1, 2]],
        };
        let normals = mesh.vertex_normals();
        let mut buf = Vec::new();
        write_obj_to(&mut buf, &mesh, Some(&normals)).unwrap();
        let text = String::from_utf8(buf).unwrap();
        assert_eq!(text.lines().filter(|l| l.starts_with("v ")).count(), 3);
        assert_eq!(text.lines().filter(|l| l.starts_with("vn ")).count(), 3);
        assert!(text.contains("f 1//1 2//2 3//3"));
    }
}
