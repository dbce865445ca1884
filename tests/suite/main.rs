//! The integration tests, one module per subject, built as one test binary so that one
//! link serves them all and the harness runs them side by side (`cargo test --test suite
//! MODULE::` runs one subject). Each module's doc comment says what it checks.
//!
//! The harness starts tests in the order of their names: the longest, the paper-setting
//! tripod through the whole pipeline, is named to start first (`at_paper_setting`), so
//! the others run beside it instead of after it.

mod common;

mod at_paper_setting;
mod auto_skeleton;
mod bad_input;
mod cache_soundness;
mod calib_import;
mod dance_recovery;
mod dancer;
mod export;
mod fit;
mod frame_rate;
mod fuzz_parsers;
mod graphcut;
mod graphcut_degenerate;
mod hostile_input;
mod hostile_round3;
mod hostile_round4;
mod humanoid_fit;
mod kill_resume;
mod lab_footage;
mod layers;
mod learned_background;
mod masks_only;
mod model;
mod parameter_table;
mod person_model;
mod pose_search;
mod quick_start;
mod realdata;
mod report;
mod runner;
mod skeleton_poses;
mod skeleton_refusals;
mod stage_functions;
mod synth_data;
mod synth_scenes;
mod tracked_surface;
mod video;
mod visual_hull;
