//! The commands' logic, above the pipeline (`main.rs` parses the command line and calls
//! these). `pipeline run` is the runner's stages followed by the exports, which read the
//! cache and compute nothing of their own.

pub mod ablation;
pub mod evaluate;
pub mod run;
