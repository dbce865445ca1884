//! Stage 4: ZNCC tells the true surface from phantom volume and bridges, on the tripod at
//! the paper's setting (15 cameras, 1024x768, 1 cm voxels).

mod common;

use common::*;
use hullpose::stages::reliability::Observed;
use hullpose::synth::{SceneKind, SynthOptions};

/// Frames t6..t13 of the tripod at full size (earlier frames are not rendered).
fn late_tripod() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    let mut opts = SynthOptions::new(SceneKind::Tripod, dir.path());
    opts.frames = Some(14);
    opts.first_frame = 6;
    hullpose::synth::generate(&opts).unwrap();
    dir
}

#[test]
fn zncc_separates_true_from_false_surface() {
    let dir = late_tripod();
    let d = dir.path();
    let (ok, _, err) = run_cli(
        &[
            "run",
            "pipeline.yaml",
            "--frames",
            "6..13",
            "--until",
            "reliability",
        ],
        d,
    );
    assert!(ok, "{err}");
    let (ok, out, err) = run_cli(&["evaluate", "pipeline.yaml", "--frames", "6..13"], d);
    assert!(ok, "{err}");
    eprintln!("{out}");
    let csv = std::fs::read_to_string(d.join("output/evaluation/reliability.csv")).unwrap();
    let rows: Vec<Vec<f64>> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    assert_eq!(rows.len(), 8);
    for r in rows
        .iter()
        .filter(|r| [6.0, 7.0, 8.0, 11.0, 12.0, 13.0].contains(&r[0]))
    {
        let (frame, false_vertices, auc, rho_false, rho_true) = (r[0], r[2], r[3], r[4], r[5]);
        assert!(false_vertices > 1000.0, "t{frame}: phantom volume present");
        assert!(auc >= 0.85, "t{frame}: ROC AUC {auc}");
        assert!(
            rho_false < 0.2,
            "t{frame}: mean rho_p of false vertices {rho_false}"
        );
        assert!(
            rho_true > 0.4,
            "t{frame}: mean rho_p of true seen vertices {rho_true}"
        );
    }
    // The artifacts: a PLY MeshLab reads (quality = ZNCC) and the compact form agree.
    let ply = std::fs::read(d.join("cache/reliability/000008.ply")).unwrap();
    let header = String::from_utf8_lossy(&ply[..ply.len().min(600)]).to_string();
    for prop in ["quality", "zncc", "rho_p", "cameras", "red"] {
        assert!(header.contains(&format!(" {prop}\n")), "{prop} in {header}");
    }
    let path = d.join("cache/reliability/000008.obs");
    let obs = Observed::parse(&path, &std::fs::read(&path).unwrap()).unwrap();
    let mesh = hullpose::geometry::ply::read_ply(&d.join("cache/graphcut/000008.ply")).unwrap();
    assert_eq!(obs.vertices.len(), mesh.vertices.len());
    assert!(obs.zncc.iter().all(|z| (-1.0..=1.0).contains(z)));
    assert!(obs
        .zncc
        .iter()
        .zip(&obs.cameras)
        .all(|(&z, &c)| c >= 2 || z == -1.0));
    assert!(obs
        .rho_p
        .iter()
        .all(|r| r.is_finite() && *r > 0.0 && *r < 1.0));
}
