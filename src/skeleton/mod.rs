//! The skeleton as `skeleton.yaml` declares it: bones with heads and tails at the reference
//! frame t0, parents listed first (`shared/dataset-format.md`).

use crate::error::Refusal;
use crate::error::{Error, Result};
use nalgebra::Vector3;
use serde::Deserialize;
use std::collections::HashMap;
use std::fmt::Write as _;
use std::path::Path;

pub mod embed;
pub mod follow;
pub mod model;
pub mod pose;
pub mod sides;
pub mod skinning;
mod tree;

pub use pose::{Pose, PosedBones};

/// One bone at the reference frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Bone {
    /// Unique bone name.
    pub name: String,
    /// Index of the parent bone in [`Skeleton::bones`]; `None` for the root.
    pub parent: Option<usize>,
    /// Head (the point the bone rotates about), world metres at t0.
    pub head: Vector3<f64>,
    /// Tail, world metres at t0.
    pub tail: Vector3<f64>,
}

impl Bone {
    /// Bone length, metres.
    pub fn length(&self) -> f64 {
        (self.tail - self.head).norm()
    }
}

/// The most bones a skeleton may have (each bone costs the fit three unknowns).
pub const MAX_BONES: usize = 256;

/// The articulated structure embedded in the subject at the reference frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Skeleton {
    /// The frame index t0 whose reconstruction becomes the body model.
    pub reference_frame: u32,
    /// Bones, parents before children; exactly one root (the first bone).
    pub bones: Vec<Bone>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SkeletonFile {
    reference_frame: u32,
    bones: Vec<BoneEntry>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct BoneEntry {
    name: String,
    parent: Option<String>,
    head: [f64; 3],
    tail: [f64; 3],
}

/// Bone names appear in CSV rows, BVH joint names and file names: a plain file name
/// ([`crate::camera::check_name`]) without commas, quotes or white space.
pub fn check_bone_name(name: &str) -> std::result::Result<(), Refusal> {
    crate::camera::check_name(name)?;
    if name.contains([',', '"']) || name.chars().any(char::is_whitespace) {
        return Err(format!(
            "the bone name {name:?} must not contain commas, quotes or white space (it is written into CSV and BVH files)"
        ).into());
    }
    Ok(())
}

impl Skeleton {
    /// Number of pose parameters: 6 for the root, 3 for every other bone.
    pub fn parameter_count(&self) -> usize {
        3 * self.bones.len() + 3
    }

    /// Index of the bone named `name`.
    pub fn bone_index(&self, name: &str) -> Option<usize> {
        self.bones.iter().position(|b| b.name == name)
    }

    /// Children of each bone.
    pub fn children(&self) -> Vec<Vec<usize>> {
        let mut c = vec![Vec::new(); self.bones.len()];
        for (i, b) in self.bones.iter().enumerate() {
            if let Some(p) = b.parent {
                c[p].push(i);
            }
        }
        c
    }

    /// Parses and validates skeleton.yaml text; `path` names the file in errors.
    ///
    /// Bones may be listed in any order as long as they form one tree: the bones are
    /// returned parents first (in file order where the file already is). Refused with a
    /// clear error: no bone, a bad or duplicate name, an unknown parent, no root or more than
    /// one, a cycle, a non-finite coordinate, a zero-length bone.
    pub fn parse(path: &Path, text: &str) -> Result<Skeleton> {
        let file: SkeletonFile = crate::yaml::from_str(path, text)?;
        let bad = |msg: String| Error::invalid(path, msg);
        if file.bones.is_empty() {
            return Err(bad("the skeleton has no bone".into()));
        }
        if file.bones.len() > MAX_BONES {
            return Err(bad(format!(
                "the skeleton has {} bones; at most {MAX_BONES} are supported (a body has 15 to 60)",
                file.bones.len()
            )));
        }
        let mut index: HashMap<&str, usize> = HashMap::new();
        let mut comparable: HashMap<String, usize> = HashMap::new();
        for (i, e) in file.bones.iter().enumerate() {
            check_bone_name(&e.name).map_err(|m| bad(format!("bone {i}: {m}")))?;
            index.insert(&e.name, i);
            if comparable
                .insert(crate::camera::comparable_name(&e.name), i)
                .is_some()
            {
                return Err(bad(format!(
                    "bone '{}' is declared twice (names that differ only by case or by Unicode \
                     composition are one name)",
                    e.name
                )));
            }
            let head = Vector3::from(e.head);
            let tail = Vector3::from(e.tail);
            if head.iter().chain(tail.iter()).any(|v| !v.is_finite()) {
                return Err(bad(format!(
                    "bone '{}' has a non-finite coordinate",
                    e.name
                )));
            }
            if (tail - head).norm() < 1e-6 {
                return Err(bad(format!(
                    "bone '{}' has zero length (head = tail)",
                    e.name
                )));
            }
        }
        let mut parents = Vec::with_capacity(file.bones.len());
        for e in &file.bones {
            parents.push(match e.parent.as_deref() {
                None => None,
                Some(p) => Some(*index.get(p).ok_or_else(|| {
                    bad(format!(
                        "bone '{}' names parent '{p}', which is not a bone of this skeleton",
                        e.name
                    ))
                })?),
            });
        }
        let roots: Vec<&str> = file
            .bones
            .iter()
            .zip(&parents)
            .filter(|(_, p)| p.is_none())
            .map(|(e, _)| e.name.as_str())
            .collect();
        if roots.len() != 1 {
            return Err(bad(format!(
                "a skeleton has exactly one root bone (parent: null); this one has {}{}",
                roots.len(),
                if roots.is_empty() {
                    String::new()
                } else {
                    format!(": {}", roots.join(", "))
                }
            )));
        }
        let order = tree::parents_first(&parents).map_err(|cycle| {
            let names: Vec<&str> = cycle.iter().map(|&i| file.bones[i].name.as_str()).collect();
            bad(format!(
                "the bones' parents form a cycle through {}; a skeleton must be a tree",
                names.join(" -> ")
            ))
        })?;
        let mut new_index = vec![0; order.len()];
        for (k, &i) in order.iter().enumerate() {
            new_index[i] = k;
        }
        let bones = order
            .iter()
            .map(|&i| {
                let e = &file.bones[i];
                Bone {
                    name: e.name.clone(),
                    parent: parents[i].map(|p| new_index[p]),
                    head: Vector3::from(e.head),
                    tail: Vector3::from(e.tail),
                }
            })
            .collect();
        Ok(Skeleton {
            reference_frame: file.reference_frame,
            bones,
        })
    }

    /// Reads and validates skeleton.yaml.
    pub fn read(path: &Path) -> Result<Skeleton> {
        let text = crate::fsutil::read_to_string(path)?;
        Skeleton::parse(path, &text)
    }

    /// The skeleton.yaml text (numbers in shortest round-trip form).
    pub fn to_yaml(&self) -> String {
        let v = |p: &Vector3<f64>| format!("[{:?}, {:?}, {:?}]", p.x, p.y, p.z);
        let mut s = format!("reference_frame: {}\nbones:\n", self.reference_frame);
        for b in &self.bones {
            // Names through the YAML serializer: `*x`, `null` or `~` must stay names.
            let parent = b
                .parent
                .map(|p| crate::yaml::scalar(&self.bones[p].name))
                .unwrap_or_else(|| "null".into());
            let _ = writeln!(s, "  - name: {}", crate::yaml::scalar(&b.name));
            let _ = writeln!(s, "    parent: {parent}");
            let _ = writeln!(s, "    head: {}", v(&b.head));
            let _ = writeln!(s, "    tail: {}", v(&b.tail));
        }
        s
    }

    /// Writes skeleton.yaml atomically.
    pub fn write(&self, path: &Path) -> Result<()> {
        crate::fsutil::write_atomic(path, self.to_yaml().as_bytes())
    }
}

#[cfg(test)]
mod tests {
    use super::Skeleton;
    use std::path::Path;

    fn parse(bones: &str) -> Result<Skeleton, String> {
        Skeleton::parse(
            Path::new("skeleton.yaml"),
            &format!("reference_frame: 0\nbones:\n{bones}"),
        )
        .map_err(|e| e.to_string())
    }

    fn bone(name: &str, parent: &str, tail_x: f64) -> String {
        format!(
            "  - name: {name}\n    parent: {parent}\n    head: [0, 0, 0]\n    tail: [{tail_x}, 0, 1]\n"
        )
    }

    #[test]
    fn bad_skeletons_are_refused_naming_the_bone() {
        let cases = [
            (
                bone("a", "null", 0.0) + &bone("b", "nope", 0.0),
                "parent 'nope'",
            ),
            (
                bone("a", "null", 0.0) + &bone("a", "a", 0.0),
                "'a' is declared twice",
            ),
            (
                bone("a", "null", 0.0) + &bone("b", "null", 0.0),
                "exactly one root",
            ),
            (
                bone("r", "null", 0.0) + &bone("a", "b", 0.0) + &bone("b", "a", 0.0),
                "cycle through a -> b",
            ),
            (
                "  - name: z\n    parent: null\n    head: [1, 1, 1]\n    tail: [1, 1, 1]\n"
                    .to_string(),
                "'z' has zero length",
            ),
            (bone("a/b", "null", 0.0), "must not contain '/'"),
        ];
        for (yaml, expected) in cases {
            let err = parse(&yaml).unwrap_err();
            assert!(
                err.contains(expected) && err.contains("skeleton.yaml"),
                "{err}"
            );
        }
    }

    #[test]
    fn children_listed_before_parents_are_reordered() {
        let s = parse(&(bone("b", "a", 1.0) + &bone("a", "null", 0.0))).unwrap();
        assert_eq!(s.bones[0].name, "a");
        assert_eq!(s.bones[1].parent, Some(0));
    }
}
