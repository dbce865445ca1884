//! The README's pipeline.yaml table against the code: every parameter has a row, every
//! row's default is the code's default (`config::default_values`, the one place they are
//! declared), and every parameter is in some stage's cache key unless its row says that no
//! stage reads it.

use hullpose::config::Config;
use hullpose::dataset::Sequence;
use hullpose::stages::STAGES;
use serde_json::Value;
use std::collections::BTreeMap;
use std::path::Path;

/// What a row of the README's table says: its default cell and its meaning.
struct Row {
    default: String,
    meaning: String,
}

/// The rows of README.md's "pipeline.yaml reference" table, by key.
fn readme_rows() -> BTreeMap<String, (usize, usize, Row)> {
    let readme =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("README.md")).unwrap();
    let start = readme
        .find("## pipeline.yaml reference")
        .expect("the table's section");
    let section = &readme[start..];
    let section = &section[..section[3..].find("\n## ").map_or(section.len(), |i| i + 3)];
    let mut rows = BTreeMap::new();
    for line in section.lines().filter(|l| l.starts_with("| `")) {
        let cells: Vec<&str> = line.split(" | ").collect();
        let keys = backticked(cells[0]);
        for (i, key) in keys.iter().enumerate() {
            rows.insert(
                key.clone(),
                (
                    i,
                    keys.len(),
                    Row {
                        default: cells[1].to_string(),
                        meaning: cells[2..].join(" | "),
                    },
                ),
            );
        }
    }
    rows
}

/// The backticked words of `cell`.
fn backticked(cell: &str) -> Vec<String> {
    cell.split('`')
        .skip(1)
        .step_by(2)
        .map(str::to_string)
        .collect()
}

/// Whether the README's text `shown` states the value `v`.
fn same(shown: &str, v: &Value) -> bool {
    match v {
        Value::Number(n) => shown
            .parse::<f64>()
            .is_ok_and(|x| (x - n.as_f64().unwrap()).abs() <= 1e-12 * x.abs().max(1.0)),
        Value::Bool(b) => shown == b.to_string(),
        Value::String(s) => shown == s,
        Value::Array(items) => {
            let inner = shown.trim_start_matches('[').trim_end_matches(']').trim();
            let parts: Vec<&str> = if inner.is_empty() {
                Vec::new()
            } else {
                inner.split(',').map(str::trim).collect()
            };
            parts.len() == items.len() && parts.iter().zip(items).all(|(p, i)| same(p, i))
        }
        Value::Null | Value::Object(_) => false,
    }
}

#[test]
fn every_default_in_the_readme_is_the_codes() {
    let rows = readme_rows();
    let mut wrong = Vec::new();
    for (key, value) in hullpose::config::default_values().unwrap() {
        let Some((i, n, row)) = rows.get(&key) else {
            wrong.push(format!("{key}: no row in README's pipeline.yaml table"));
            continue;
        };
        let shown = backticked(&row.default);
        let ok = match &value {
            // No default: the cell says so in words (none, unset, derived).
            Value::Null => shown.is_empty(),
            v => shown.len() == *n && same(&shown[*i], v),
        };
        if !ok {
            wrong.push(format!(
                "{key}: README says {}, the code's default is {value}",
                row.default
            ));
        }
    }
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
}

/// A valid value other than the default, for each parameter.
const CHANGED: &[(&str, &str)] = &[
    ("silhouette.background_color", "[10, 10, 10]"),
    ("silhouette.clean_given", "true"),
    ("silhouette.close_radius", "1"),
    ("silhouette.color_threshold", "14"),
    ("silhouette.constant_threshold", "40"),
    ("silhouette.learned_max_undecided", "0.05"),
    ("silhouette.learned_min_share", "0.3"),
    ("silhouette.learned_tolerance", "25"),
    ("silhouette.max_brightness", "1.3"),
    ("silhouette.max_hole_px", "80"),
    ("silhouette.method", "background"),
    ("silhouette.min_brightness", "0.5"),
    ("silhouette.min_component_fraction", "0.02"),
    ("silhouette.open_radius", "2"),
    ("visual_hull.all_but", "1"),
    (
        "visual_hull.bbox",
        "{min: [-0.5, -0.5, -0.1], max: [0.5, 0.5, 1.0]}",
    ),
    ("visual_hull.margin", "0.05"),
    ("visual_hull.memory_cap_mb", "2048"),
    ("visual_hull.min_views", "3"),
    ("visual_hull.smoothing_iterations", "4"),
    ("visual_hull.voxel_size", "0.012"),
    ("graphcut.ballooning", "150"),
    ("graphcut.ballooning_evidence", "0.3"),
    ("graphcut.band", "0.04"),
    ("graphcut.best_pairs", "2"),
    ("graphcut.max_pair_angle_deg", "40"),
    ("graphcut.patch_spacing", "0.6"),
    ("graphcut.photo_refine", "1.0"),
    ("graphcut.pin_rims", "true"),
    ("graphcut.sigma", "0.4"),
    ("graphcut.smoothing_iterations", "4"),
    ("graphcut.window", "5"),
    ("reliability.alpha_p", "4"),
    ("reliability.depth_tolerance", "2.0"),
    ("reliability.image_sigma", "0.8"),
    ("reliability.max_view_angle_deg", "50"),
    ("reliability.normal_search", "0.5"),
    ("reliability.patch_spacing", "0.6"),
    ("reliability.tau_p", "0.9"),
    ("reliability.window", "5"),
    ("model.blend_width", "0.03"),
    ("model.mesh", "body.ply"),
    ("fit.contact.alpha_c", "150"),
    ("fit.contact.rest_distance", "0.08"),
    ("fit.contact.rule", "adjacent"),
    ("fit.contact.tau_c", "0.03"),
    ("fit.health.bend_deg", "100"),
    ("fit.health.twist_deg", "60"),
    ("fit.health.energy_jump", "8"),
    ("fit.health.interpenetration_cm", "5"),
    ("fit.health.iou_drift", "0.8"),
    ("fit.health.iou_drop", "0.8"),
    ("fit.health.max_joint_speed", "5"),
    ("fit.health.unexplained_cm2", "10"),
    ("fit.health.surface_reach", "0.03"),
    ("fit.method", "rho_c"),
    ("fit.min_observed_share", "0.1"),
    ("fit.model_spacing", "0.012"),
    ("fit.motion_prior_acceleration", "10"),
    ("fit.normal_angle_deg", "40"),
    ("fit.restart.enabled", "false"),
    ("fit.restart.energy_ratio", "2"),
    ("fit.restart.rounds_factor", "3"),
    ("fit.restart.turn_deg", "30"),
    ("fit.sample_spacing", "0.012"),
    ("fit.start", "predicted"),
    ("fit.stop.baseline_max_rounds", "100"),
    ("fit.stop.baseline_tolerance", "0.00002"),
    ("fit.stop.max_rounds", "50"),
    ("fit.stop.tolerance", "0.0002"),
    ("export.bvh_rotation_order", "XYZ"),
    ("export.contact_sheet", "false"),
    ("export.formats", "[glb]"),
    ("export.frame_rate", "30"),
    ("export.overlay_cameras", "[cam00]"),
    ("export.up_axis", "+z"),
    ("world.up", "[0.1, 0.2, 0.9]"),
    ("world.floor", "0.05"),
    ("surface.reach", "0.08"),
    ("surface.shape", "2.0"),
    ("surface.anchor", "0.05"),
    ("surface.memory", "0.5"),
    ("surface.silhouette", "2.0"),
    ("surface.silhouette_tolerance", "2.0"),
    ("surface.rim", "2.0"),
    ("surface.rounds", "4"),
];

/// The words a row uses for a parameter no stage reads.
const NOT_IN_A_KEY: &str = "no stage reads it";

/// pipeline.yaml for the bundled sample with `key` (dotted) set to the YAML `value`.
fn config_with(dir: &Path, key: Option<(&str, &str)>) -> Config {
    let repo = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut text = format!(
        "calibration: {}\nsequence: {}\n",
        repo.join("calib/cameras.yaml").display(),
        repo.join("data/tripod").display()
    );
    if let Some((key, value)) = key {
        let parts: Vec<&str> = key.split('.').collect();
        for (depth, part) in parts.iter().enumerate() {
            let indent = "  ".repeat(depth);
            if depth + 1 == parts.len() {
                text += &format!("{indent}{part}: {value}\n");
            } else {
                text += &format!("{indent}{part}:\n");
            }
        }
    }
    std::fs::write(dir.join("body.ply"), b"").unwrap();
    let path = dir.join("pipeline.yaml");
    std::fs::write(&path, text).unwrap();
    Config::load(&path).unwrap_or_else(|e| panic!("{key:?}: {e}"))
}

/// Every stage's settings text under `config`.
fn settings(config: &Config, sequence: &Sequence) -> Vec<String> {
    STAGES
        .iter()
        .map(|s| s.settings_text(config, sequence).unwrap())
        .collect()
}

#[test]
fn every_parameter_is_in_a_stage_key_or_its_row_says_no_stage_reads_it() {
    let dir = tempfile::tempdir().unwrap();
    let rows = readme_rows();
    let base = config_with(dir.path(), None);
    let sequence = Sequence::open_with_calibration(&base.calibration, &base.sequence).unwrap();
    let before = settings(&base, &sequence);
    let defaults = hullpose::config::default_values().unwrap();
    let changed: BTreeMap<&str, &str> = CHANGED.iter().copied().collect();
    let mut wrong = Vec::new();
    for (key, _) in &defaults {
        let Some(value) = changed.get(key.as_str()) else {
            wrong.push(format!(
                "{key}: add a changed value to CHANGED in this test"
            ));
            continue;
        };
        let config = config_with(dir.path(), Some((key, value)));
        let after = settings(&config, &sequence);
        let keyed: Vec<&str> = STAGES
            .iter()
            .zip(before.iter().zip(&after))
            .filter(|(_, (b, a))| b != a)
            .map(|(s, _)| s.name)
            .collect();
        let says_unread = rows
            .get(key)
            .is_some_and(|r| r.2.meaning.contains(NOT_IN_A_KEY));
        match (keyed.is_empty(), says_unread) {
            (true, false) => wrong.push(format!(
                "{key}: no stage's key holds it; its README row must say \"{NOT_IN_A_KEY}\""
            )),
            (false, true) => wrong.push(format!(
                "{key}: the keys of {keyed:?} hold it, but its README row says \"{NOT_IN_A_KEY}\""
            )),
            _ => {}
        }
    }
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
}
