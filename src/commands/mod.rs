//! The commands' logic, above the pipeline: `pipeline run` is the runner's stages followed
//! by the exports, which read the cache and compute nothing of their own.

pub mod run;
