//! hullpose: multi-view capture to visual hulls, refined surfaces, and the motion of an
//! articulated skeleton, robust to contact and to unobservable surface.
//!
//! The stages follow `method.md`: silhouettes, visual hull, graph-cut refinement, ZNCC
//! reliability, skin-bone model, robust articulated fitting, and exports.

pub mod artifacts;
pub mod autoskeleton;
pub mod bench;
pub mod cache;
pub mod calib_import;
pub mod camera;
pub mod commands;
pub mod config;
pub mod dataset;
pub mod drawing;
pub mod error;
pub mod eval;
pub mod export;
pub mod fit;
pub mod fsutil;
pub mod geometry;
pub mod imageio;
pub mod joints;
pub mod limits;
pub mod maxflow;
pub mod person;
pub mod photo;
pub mod plot;
pub mod poses;
pub mod recon;
pub mod report;
pub mod rng;
pub mod runner;
pub mod shell;
pub mod skeleton;
pub mod slurm;
pub mod stages;
pub mod synth;
pub mod text;
pub mod tracked_surface;
pub mod video;
pub mod yaml;

pub use error::{Error, Result};
