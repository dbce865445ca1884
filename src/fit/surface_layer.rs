//! The surface the fit's health measures a pose with: the posed, rigidly skinned model,
//! each vertex moved onto the frame's observed surface where that lies within a reach
//! (`fit.health.surface_reach`).
//!
//! The skinned model keeps the reference frame's shape: a dress that swings, a sleeve
//! that folds, or the hull's phantom detail in another frame lie a few centimetres off it
//! however right the pose is, and on the real dancer they cost the posed model 0.08-0.1 of
//! silhouette IoU against the frame's own hull (README "Reading the fit's health"). Moved
//! onto the observed surface within 5 cm, the model takes that shape; a limb the pose lost
//! stays tens of centimetres off and still shows in the silhouettes.

use crate::geometry::nearest::NearestTree;
use crate::geometry::TriMesh;
use nalgebra::Vector3;
use rayon::prelude::*;

/// Rounds of neighbour averaging of the moves (so that the surface stays a surface where
/// neighbouring vertices found different nearest points).
const SMOOTHING_ROUNDS: usize = 2;

/// `posed` with each vertex moved to its nearest `observed` point when that lies within
/// `reach` metres, the moves averaged with the neighbours' [`SMOOTHING_ROUNDS`] times. A
/// reach of 0, or no observed point, leaves it as it is.
pub fn follow(posed: &TriMesh, observed: &[Vector3<f64>], reach: f64) -> TriMesh {
    if reach <= 0.0 || observed.is_empty() {
        return posed.clone();
    }
    let tree = NearestTree::new(observed);
    let mut moves: Vec<Vector3<f64>> = posed
        .vertices
        .par_iter()
        .map(|v| match tree.nearest(v) {
            Some((j, d2)) if d2 <= reach * reach => observed[j] - v,
            _ => Vector3::zeros(),
        })
        .collect();
    let mut neighbours = vec![Vec::new(); posed.vertices.len()];
    for t in &posed.triangles {
        for k in 0..3 {
            let (a, b) = (t[k] as usize, t[(k + 1) % 3] as usize);
            neighbours[a].push(b);
            neighbours[b].push(a);
        }
    }
    for _ in 0..SMOOTHING_ROUNDS {
        moves = (0..moves.len())
            .map(|i| {
                let n = &neighbours[i];
                let sum: Vector3<f64> = n.iter().map(|&j| moves[j]).sum();
                (moves[i] + sum) / (1 + n.len()) as f64
            })
            .collect();
    }
    TriMesh {
        vertices: posed
            .vertices
            .iter()
            .zip(&moves)
            .map(|(v, m)| v + m)
            .collect(),
        triangles: posed.triangles.clone(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A sphere meshed from its distance field (5 mm samples).
    fn sphere(r: f64, centre: Vector3<f64>) -> TriMesh {
        crate::geometry::isosurface::sphere(r, centre, 0.005)
    }

    #[test]
    fn a_surface_within_reach_is_followed_and_one_beyond_it_is_not() {
        let model = sphere(0.10, Vector3::zeros());
        let observed = sphere(0.13, Vector3::zeros()).vertices;
        // 3 cm out: within a 5 cm reach, the model takes the observed radius.
        let followed = follow(&model, &observed, 0.05);
        for v in &followed.vertices {
            assert!((v.norm() - 0.13).abs() < 0.005, "{}", v.norm());
        }
        // Beyond the reach (an observed sphere 30 cm away): nothing moves.
        let far = sphere(0.10, Vector3::new(0.4, 0.0, 0.0)).vertices;
        assert_eq!(follow(&model, &far, 0.05).vertices, model.vertices);
        assert_eq!(follow(&model, &observed, 0.0).vertices, model.vertices);
    }
}
