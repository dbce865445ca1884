//! A learned person model for captures without masks or plates: per image, the person's
//! 33 body landmarks (with how visible each is) and a person mask, from MediaPipe's BlazePose
//! (Apache-2.0) converted to ONNX once by `tools/setup-person-model.sh`.

pub mod blazepose;
pub mod evidence;
pub mod model;
pub mod skeleton;
pub mod triangulate;

pub use blazepose::{Landmark, LANDMARKS, LANDMARK_NAMES};
pub use model::{Person, PersonModel};

use serde::{Deserialize, Serialize};

/// What one camera's image showed of the person.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PersonView {
    /// The camera's name.
    pub camera: String,
    /// Whether the detector found a person (if not, the camera's silhouette is the whole
    /// image: it carves nothing).
    pub found: bool,
    /// The detector's score, 0..1 (0 when nobody was found).
    pub score: f32,
    /// The share of the model's mask dropped because no other camera's silhouette supports
    /// it (multi-view consistency), 0..1.
    pub unsupported: f64,
    /// The 33 body landmarks in [`LANDMARK_NAMES`] order: x, y (image
    /// pixels, pixel centres at +0.5) and visibility (0..1). Empty when nobody was found.
    pub landmarks: Vec<[f64; 3]>,
}

/// A frame's evidence, one view per camera in calibration order.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PersonFrame {
    pub views: Vec<PersonView>,
}
