//! PLY files (Stanford polygon format): a writer for triangle meshes with optional normals,
//! colours and extra per-vertex float properties (binary little-endian or ASCII), and a reader
//! for the vertex positions and triangles of any PLY (ASCII or binary, any scalar types).
//!
//! MeshLab reads a per-vertex `float quality` as its scalar quality; Blender imports extra
//! float properties as attributes.

use super::mesh::TriMesh;
use crate::error::{Error, Result};
use nalgebra::Vector3;
use std::io::Write;
use std::path::Path;

/// Optional per-vertex data written beside the positions.
#[derive(Default)]
pub struct VertexAttributes<'a> {
    /// Unit normals, one per vertex.
    pub normals: Option<&'a [Vector3<f64>]>,
    /// 8-bit RGB colours, one per vertex.
    pub colors: Option<&'a [[u8; 3]]>,
    /// Extra float properties: (name, one value per vertex).
    pub scalars: Vec<(&'a str, &'a [f32])>,
}

/// PLY encoding.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PlyFormat {
    BinaryLittleEndian,
    Ascii,
}

/// Writes `mesh` with `attrs` to `w`.
pub fn write_ply_to(
    w: &mut dyn Write,
    mesh: &TriMesh,
    attrs: &VertexAttributes,
    format: PlyFormat,
) -> std::io::Result<()> {
    let n = mesh.vertices.len();
    let fmt = match format {
        PlyFormat::BinaryLittleEndian => "binary_little_endian",
        PlyFormat::Ascii => "ascii",
    };
    writeln!(w, "ply\nformat {fmt} 1.0\ncomment written by hullpose")?;
    writeln!(w, "element vertex {n}")?;
    writeln!(w, "property float x\nproperty float y\nproperty float z")?;
    if attrs.normals.is_some() {
        writeln!(w, "property float nx\nproperty float ny\nproperty float nz")?;
    }
    if attrs.colors.is_some() {
        writeln!(
            w,
            "property uchar red\nproperty uchar green\nproperty uchar blue"
        )?;
    }
    for (name, values) in &attrs.scalars {
        assert_eq!(
            values.len(),
            n,
            "property {name} needs one value per vertex"
        );
        writeln!(w, "property float {name}")?;
    }
    writeln!(w, "element face {}", mesh.triangles.len())?;
    writeln!(w, "property list uchar int vertex_indices\nend_header")?;
    for i in 0..n {
        let mut floats: Vec<f32> = mesh.vertices[i].iter().map(|&v| v as f32).collect();
        if let Some(normals) = attrs.normals {
            floats.extend(normals[i].iter().map(|&v| v as f32));
        }
        let color = attrs.colors.map(|c| c[i]);
        let extra: Vec<f32> = attrs.scalars.iter().map(|(_, v)| v[i]).collect();
        match format {
            PlyFormat::BinaryLittleEndian => {
                for f in &floats {
                    w.write_all(&f.to_le_bytes())?;
                }
                if let Some(c) = color {
                    w.write_all(&c)?;
                }
                for f in &extra {
                    w.write_all(&f.to_le_bytes())?;
                }
            }
            PlyFormat::Ascii => {
                let mut parts: Vec<String> = floats.iter().map(|f| f.to_string()).collect();
                if let Some(c) = color {
                    parts.extend(c.iter().map(|b| b.to_string()));
                }
                parts.extend(extra.iter().map(|f| f.to_string()));
                writeln!(w, "{}", parts.join(" "))?;
            }
        }
    }
    for t in &mesh.triangles {
        match format {
            PlyFormat::BinaryLittleEndian => {
                w.write_all(&[3u8])?;
                for &i in t {
                    w.write_all(&(i as i32).to_le_bytes())?;
                }
            }
            PlyFormat::Ascii => writeln!(w, "3 {} {} {}", t[0], t[1], t[2])?,
        }
    }
    Ok(())
}

/// Writes a PLY file atomically.
pub fn write_ply(
    path: &Path,
    mesh: &TriMesh,
    attrs: &VertexAttributes,
    format: PlyFormat,
) -> Result<()> {
    crate::fsutil::write_atomic_with(path, |w| write_ply_to(w, mesh, attrs, format))
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(s: &str) -> Option<Scalar> {
        Some(match s {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }
}

#[derive(Debug)]
enum Property {
    Scalar(String, Scalar),
    List(String, Scalar, Scalar),
}

#[derive(Debug)]
struct Element {
    name: String,
    count: usize,
    properties: Vec<Property>,
}

/// Reads values one at a time from the body of a PLY file.
enum Body<'a> {
    Ascii(std::str::SplitAsciiWhitespace<'a>),
    Binary {
        data: &'a [u8],
        pos: usize,
        little: bool,
    },
}

impl Body<'_> {
    fn next(&mut self, ty: Scalar) -> Option<f64> {
        match self {
            Body::Ascii(tokens) => tokens.next()?.parse().ok(),
            Body::Binary { data, pos, little } => {
                let n = ty.size();
                let bytes = data.get(*pos..*pos + n)?;
                *pos += n;
                let mut buf = [0u8; 8];
                buf[..n].copy_from_slice(bytes);
                if !*little {
                    buf[..n].reverse();
                }
                Some(match ty {
                    Scalar::I8 => buf[0] as i8 as f64,
                    Scalar::U8 => buf[0] as f64,
                    Scalar::I16 => i16::from_le_bytes([buf[0], buf[1]]) as f64,
                    Scalar::U16 => u16::from_le_bytes([buf[0], buf[1]]) as f64,
                    Scalar::I32 => i32::from_le_bytes(buf[..4].try_into().unwrap()) as f64,
                    Scalar::U32 => u32::from_le_bytes(buf[..4].try_into().unwrap()) as f64,
                    Scalar::F32 => f32::from_le_bytes(buf[..4].try_into().unwrap()) as f64,
                    Scalar::F64 => f64::from_le_bytes(buf),
                })
            }
        }
    }
}

/// Parses PLY bytes into a triangle mesh (polygons are fan-triangulated). `path` names the
/// file in errors.
pub fn parse_ply(path: &Path, data: &[u8]) -> Result<TriMesh> {
    let bad = |msg: String| Error::invalid(path, msg);
    let header_end = data
        .windows(11)
        .position(|w| w == b"end_header\n" || w == b"end_header\r")
        .ok_or_else(|| bad("not a PLY file: no 'end_header' line".into()))?;
    let header = std::str::from_utf8(&data[..header_end])
        .map_err(|_| bad("the PLY header is not text".into()))?;
    let mut body_start = header_end + "end_header".len();
    while body_start < data.len() && (data[body_start] == b'\r' || data[body_start] == b'\n') {
        body_start += 1;
        if data[body_start - 1] == b'\n' {
            break;
        }
    }
    let mut lines = header.lines();
    if lines.next().map(str::trim) != Some("ply") {
        return Err(bad("not a PLY file: the first line must be 'ply'".into()));
    }
    let mut format = None;
    let mut elements: Vec<Element> = Vec::new();
    for line in lines {
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.as_slice() {
            ["format", f, _] => format = Some(f.to_string()),
            ["element", name, count] => elements.push(Element {
                name: name.to_string(),
                count: count
                    .parse()
                    .map_err(|_| bad(format!("element '{name}' has a bad count '{count}'")))?,
                properties: Vec::new(),
            }),
            ["property", "list", cty, ity, name] => {
                let (Some(c), Some(i)) = (Scalar::parse(cty), Scalar::parse(ity)) else {
                    return Err(bad(format!("unknown type in property list '{name}'")));
                };
                elements
                    .last_mut()
                    .ok_or_else(|| bad("property before any element".into()))?
                    .properties
                    .push(Property::List(name.to_string(), c, i));
            }
            ["property", ty, name] => {
                let t = Scalar::parse(ty)
                    .ok_or_else(|| bad(format!("unknown type '{ty}' of property '{name}'")))?;
                elements
                    .last_mut()
                    .ok_or_else(|| bad("property before any element".into()))?
                    .properties
                    .push(Property::Scalar(name.to_string(), t));
            }
            ["comment", ..] | ["obj_info", ..] | [] => {}
            _ => return Err(bad(format!("unrecognized header line '{line}'"))),
        }
    }
    let rest = &data[body_start.min(data.len())..];
    // Refuse counts the file cannot hold before allocating anything from them.
    let min_bytes: usize = elements
        .iter()
        .map(|e| {
            let per: usize = e
                .properties
                .iter()
                .map(|p| match p {
                    Property::Scalar(_, t) => t.size(),
                    Property::List(_, c, _) => c.size(),
                })
                .sum();
            e.count.saturating_mul(per.max(1))
        })
        .fold(0usize, |a, b| a.saturating_add(b));
    let mut body = match format.as_deref() {
        Some("ascii") => {
            let text =
                std::str::from_utf8(rest).map_err(|_| bad("ASCII PLY body is not text".into()))?;
            if min_bytes / 8 > text.len() {
                return Err(bad(
                    "the header's element counts exceed what the file holds".into(),
                ));
            }
            Body::Ascii(text.split_ascii_whitespace())
        }
        Some(f @ ("binary_little_endian" | "binary_big_endian")) => {
            if min_bytes > rest.len() {
                return Err(bad(format!(
                    "the header's element counts need at least {min_bytes} bytes but the body has {}",
                    rest.len()
                )));
            }
            Body::Binary {
                data: rest,
                pos: 0,
                little: f == "binary_little_endian",
            }
        }
        _ => return Err(bad("missing or unknown 'format' line".into())),
    };
    let truncated = || bad("the file ends before the data its header declares".into());
    let mut mesh = TriMesh::default();
    for e in &elements {
        let is_vertex = e.name == "vertex";
        let is_face = e.name == "face";
        if is_vertex {
            mesh.vertices.reserve(e.count);
        }
        for _ in 0..e.count {
            // None: the property is missing.
            let mut xyz: [Option<f64>; 3] = [None; 3];
            for p in &e.properties {
                match p {
                    Property::Scalar(name, t) => {
                        let v = body.next(*t).ok_or_else(truncated)?;
                        if is_vertex {
                            match name.as_str() {
                                "x" => xyz[0] = Some(v),
                                "y" => xyz[1] = Some(v),
                                "z" => xyz[2] = Some(v),
                                _ => {}
                            }
                        }
                    }
                    Property::List(name, ct, it) => {
                        let n = body.next(*ct).ok_or_else(truncated)? as usize;
                        let mut idx = Vec::with_capacity(n.min(64));
                        for _ in 0..n {
                            idx.push(body.next(*it).ok_or_else(truncated)?);
                        }
                        if is_face && (name == "vertex_indices" || name == "vertex_index") {
                            for k in 1..idx.len().saturating_sub(1) {
                                mesh.triangles
                                    .push([idx[0], idx[k], idx[k + 1]].map(|f| f as u32));
                            }
                        }
                    }
                }
            }
            if is_vertex {
                let [Some(x), Some(y), Some(z)] = xyz else {
                    return Err(bad("vertices need x, y and z properties".into()));
                };
                if ![x, y, z].iter().all(|v| v.is_finite()) {
                    return Err(bad(format!(
                        "vertex {} has a non-finite coordinate ({x}, {y}, {z})",
                        mesh.vertices.len()
                    )));
                }
                mesh.vertices.push(Vector3::new(x, y, z));
            }
        }
    }
    let nv = mesh.vertices.len() as u32;
    if mesh.triangles.iter().flatten().any(|&i| i >= nv) {
        return Err(bad(format!(
            "a face refers to a vertex beyond the {nv} vertices"
        )));
    }
    Ok(mesh)
}

/// Reads a PLY file.
pub fn read_ply(path: &Path) -> Result<TriMesh> {
    let data = crate::limits::read_mesh_file(path)?;
    parse_ply(path, &data)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tetra() -> TriMesh {
        TriMesh {
            vertices: vec![
                Vector3::new(0.0, 0.0, 0.0),
                Vector3::new(1.0, 0.0, 0.0),
                Vector3::new(0.0, 1.0, 0.0),
                Vector3::new(0.0, 0.0, 1.0),
            ],
            triangles: vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
        }
    }

    #[test]
    fn round_trip_both_formats_with_attributes() {
        let mesh = tetra();
        let normals = mesh.vertex_normals();
        let colors = vec![[1u8, 2, 3]; 4];
        let q = vec![0.5f32; 4];
        for format in [PlyFormat::BinaryLittleEndian, PlyFormat::Ascii] {
            let attrs = VertexAttributes {
                normals: Some(&normals),
                colors: Some(&colors),
                scalars: vec![("quality", &q)],
            };
            let mut buf = Vec::new();
            write_ply_to(&mut buf, &mesh, &attrs, format).unwrap();
            let back = parse_ply(Path::new("t.ply"), &buf).unwrap();
            assert_eq!(back, mesh);
        }
        assert!(mesh.is_watertight());
        assert!(mesh.signed_volume() > 0.0);
    }

    #[test]
    fn refuses_counts_beyond_the_file() {
        let text = b"ply\nformat binary_little_endian 1.0\nelement vertex 4000000000\nproperty float x\nproperty float y\nproperty float z\nend_header\n\0\0\0\0";
        let err = parse_ply(Path::new("huge.ply"), text)
            .unwrap_err()
            .to_string();
        assert!(err.contains("huge.ply") && err.contains("bytes"), "{err}");
    }
}
