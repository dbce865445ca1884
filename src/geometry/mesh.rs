//! Triangle meshes: vertices in metres (world frame), counter-clockwise triangles seen from
//! outside (so face normals point outwards).

use nalgebra::Vector3;

/// An indexed triangle mesh.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TriMesh {
    /// Vertex positions, metres.
    pub vertices: Vec<Vector3<f64>>,
    /// Triangles as vertex indices, counter-clockwise seen from outside.
    pub triangles: Vec<[u32; 3]>,
}

impl TriMesh {
    /// The vertices that share an edge with each vertex, sorted.
    pub fn vertex_neighbours(&self) -> Vec<Vec<u32>> {
        let mut out: Vec<Vec<u32>> = vec![Vec::new(); self.vertices.len()];
        for t in &self.triangles {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                out[a as usize].push(b);
                out[b as usize].push(a);
            }
        }
        for list in &mut out {
            list.sort_unstable();
            list.dedup();
        }
        out
    }

    /// Area-weighted vertex normals (unit length; zero for isolated vertices).
    pub fn vertex_normals(&self) -> Vec<Vector3<f64>> {
        let mut normals = vec![Vector3::zeros(); self.vertices.len()];
        for t in &self.triangles {
            let [a, b, c] = t.map(|i| self.vertices[i as usize]);
            // The cross product's length is twice the area: area weighting for free.
            let n = (b - a).cross(&(c - a));
            for &i in t {
                normals[i as usize] += n;
            }
        }
        for n in &mut normals {
            let len = n.norm();
            if len > 0.0 {
                *n /= len;
            }
        }
        normals
    }

    /// The mean length of the triangles' edges (each counted once per triangle), metres;
    /// 0 without triangles.
    pub fn mean_edge_length(&self) -> f64 {
        let total: f64 = self
            .triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| self.vertices[i as usize]);
                (b - a).norm() + (c - b).norm() + (a - c).norm()
            })
            .sum();
        total / (3 * self.triangles.len()).max(1) as f64
    }

    /// Signed volume enclosed by the mesh (positive when outward oriented), cubic metres.
    pub fn signed_volume(&self) -> f64 {
        self.triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| self.vertices[i as usize]);
                a.dot(&b.cross(&c)) / 6.0
            })
            .sum()
    }

    /// Generalized winding number of the surface around `p`: 1 inside a closed outward
    /// mesh, 0 outside (the sum of the triangles' signed solid angles over 4 pi, Van
    /// Oosterom and Strackee's formula).
    pub fn winding_number(&self, p: &Vector3<f64>) -> f64 {
        let total: f64 = self
            .triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| self.vertices[i as usize] - p);
                let (la, lb, lc) = (a.norm(), b.norm(), c.norm());
                let numerator = a.dot(&b.cross(&c));
                let denominator = la * lb * lc + a.dot(&b) * lc + b.dot(&c) * la + c.dot(&a) * lb;
                2.0 * numerator.atan2(denominator)
            })
            .sum();
        total / (4.0 * std::f64::consts::PI)
    }

    /// Axis-aligned bounding box (min, max); `None` for an empty mesh.
    pub fn bounds(&self) -> Option<(Vector3<f64>, Vector3<f64>)> {
        point_bounds(&self.vertices)
    }

    /// Whether every edge is shared by exactly two triangles with opposite directions
    /// (a closed, consistently oriented 2-manifold surface).
    /// The connected piece enclosing the most volume (pieces joined by shared vertices),
    /// its vertices renumbered; the mesh itself when it is one piece. Real silhouettes
    /// leave small phantom pieces (floor blobs, a cable) beside the body.
    pub fn largest_piece(&self) -> TriMesh {
        let n = self.vertices.len();
        let mut parent: Vec<u32> = (0..n as u32).collect();
        fn root(parent: &mut [u32], mut i: u32) -> u32 {
            while parent[i as usize] != i {
                parent[i as usize] = parent[parent[i as usize] as usize];
                i = parent[i as usize];
            }
            i
        }
        for t in &self.triangles {
            for k in 1..3 {
                let (a, b) = (root(&mut parent, t[0]), root(&mut parent, t[k]));
                if a != b {
                    parent[a.max(b) as usize] = a.min(b);
                }
            }
        }
        let mut volume: std::collections::HashMap<u32, f64> = Default::default();
        for t in &self.triangles {
            let [a, b, c] = t.map(|i| self.vertices[i as usize]);
            *volume.entry(root(&mut parent, t[0])).or_default() += a.dot(&b.cross(&c)) / 6.0;
        }
        if volume.len() <= 1 {
            return self.clone();
        }
        let Some((&keep, _)) = volume
            .iter()
            .max_by(|x, y| x.1.abs().total_cmp(&y.1.abs()).then(y.0.cmp(x.0)))
        else {
            return self.clone();
        };
        let mut index = vec![u32::MAX; n];
        let mut vertices = Vec::new();
        for (i, v) in self.vertices.iter().enumerate() {
            if root(&mut parent, i as u32) == keep {
                index[i] = vertices.len() as u32;
                vertices.push(*v);
            }
        }
        let triangles = self
            .triangles
            .iter()
            .filter(|t| index[t[0] as usize] != u32::MAX)
            .map(|t| t.map(|i| index[i as usize]))
            .collect();
        TriMesh {
            vertices,
            triangles,
        }
    }

    pub fn is_watertight(&self) -> bool {
        use std::collections::HashMap;
        let mut directed: HashMap<(u32, u32), u32> = HashMap::new();
        for t in &self.triangles {
            for k in 0..3 {
                *directed.entry((t[k], t[(k + 1) % 3])).or_default() += 1;
            }
        }
        directed
            .iter()
            .all(|(&(a, b), &n)| n == 1 && directed.get(&(b, a)) == Some(&1))
    }
}

/// Axis-aligned bounding box (min, max) of `points`; `None` for none.
pub fn point_bounds(points: &[Vector3<f64>]) -> Option<(Vector3<f64>, Vector3<f64>)> {
    let first = *points.first()?;
    Some(
        points
            .iter()
            .fold((first, first), |(lo, hi), v| (lo.inf(v), hi.sup(v))),
    )
}
