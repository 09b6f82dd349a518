//! `garmentbake batch`: many garments × clips from one manifest, as a graph of jobs that are
//! each one `garmentbake` command line, keyed by the hash of what they read, run here or on Ray.
//!
//! Why a child process per job rather than a library call: every job gets its own log (its
//! stderr), its own memory and thread pools (libtorch's are per process), can be killed alone,
//! and a crash stays inside it; the same command line runs unchanged on a Ray node or a farm.

pub mod engine;
pub mod ledger;
pub mod manifest;
pub mod plan;
pub mod ray;
pub mod run;
