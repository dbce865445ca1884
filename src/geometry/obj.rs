//! Wavefront OBJ: writing (positions, optional normals and vertex colours, triangles) and
//! reading (with tobj). Vertex colours use the common `v x y z r g b` extension (r, g, b in
//! 0..1) that MeshLab and Blender read.

use super::mesh::TriMesh;
use crate::error::{Error, Result};
use nalgebra::Vector3;
use std::io::Write;
use std::path::Path;

/// Writes `mesh` (with `normals` and `colours` if given) as OBJ text.
pub fn write_obj_to(
    w: &mut dyn Write,
    mesh: &TriMesh,
    normals: Option<&[Vector3<f64>]>,
    colours: Option<&[[u8; 3]]>,
) -> std::io::Result<()> {
    writeln!(
        w,
        "# written by hullpose: {} vertices, {} triangles",
        mesh.vertices.len(),
        mesh.triangles.len()
    )?;
    for (i, v) in mesh.vertices.iter().enumerate() {
        match colours.and_then(|c| c.get(i)) {
            Some(c) => {
                let [r, g, b] = c.map(|x| x as f32 / 255.0);
                writeln!(
                    w,
                    "v {} {} {} {r:.4} {g:.4} {b:.4}",
                    v.x as f32, v.y as f32, v.z as f32
                )?
            }
            None => writeln!(w, "v {} {} {}", v.x as f32, v.y as f32, v.z as f32)?,
        }
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
pub fn write_obj(
    path: &Path,
    mesh: &TriMesh,
    normals: Option<&[Vector3<f64>]>,
    colours: Option<&[[u8; 3]]>,
) -> Result<()> {
    crate::fsutil::write_atomic_with(path, |w| write_obj_to(w, mesh, normals, colours))
}

/// Reads an OBJ file's geometry (every object, polygons triangulated) as one mesh.
pub fn read_obj(path: &Path) -> Result<TriMesh> {
    let bytes = crate::limits::read_mesh_file(path)?;
    let options = tobj::LoadOptions {
        triangulate: true,
        single_index: true,
        ..Default::default()
    };
    // Materials are not read (the geometry is all the pipeline uses).
    let no_materials = |_: &Path| Err(tobj::LoadError::OpenFileFailed);
    let (models, _) = tobj::load_obj_buf(&mut std::io::Cursor::new(bytes), &options, no_materials)
        .map_err(|e| Error::invalid(path, format!("cannot read the OBJ file: {e}")))?;
    let mut mesh = TriMesh::default();
    for m in models {
        let base = mesh.vertices.len() as u32;
        let p = &m.mesh.positions;
        if p.len() % 3 != 0 || m.mesh.indices.len() % 3 != 0 {
            return Err(Error::invalid(path, "malformed OBJ geometry"));
        }
        mesh.vertices.extend(
            p.chunks_exact(3)
                .map(|v| Vector3::new(v[0] as f64, v[1] as f64, v[2] as f64)),
        );
        let n = mesh.vertices.len() as u32;
        for t in m.mesh.indices.chunks_exact(3) {
            let tri = [t[0] + base, t[1] + base, t[2] + base];
            if tri.iter().any(|&i| i >= n) {
                return Err(Error::invalid(path, "a face refers to a missing vertex"));
            }
            mesh.triangles.push(tri);
        }
    }
    if mesh
        .vertices
        .iter()
        .any(|v| !v.iter().all(|x| x.is_finite()))
    {
        return Err(Error::invalid(path, "a vertex has a non-finite coordinate"));
    }
    Ok(mesh)
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
        write_obj_to(&mut buf, &mesh, Some(&normals), None).unwrap();
        let text = String::from_utf8(buf).unwrap();
        assert_eq!(text.lines().filter(|l| l.starts_with("v ")).count(), 3);
        assert_eq!(text.lines().filter(|l| l.starts_with("vn ")).count(), 3);
        assert!(text.contains("f 1//1 2//2 3//3"));
    }
}
