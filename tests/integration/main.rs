//! The integration tests: one binary (libtorch and pyo3 are linked once), a module per area, as
//! ripgrep's tests/ are laid out. Run one area with `cargo test --test integration bake::`.

mod common;

mod bake;
mod batch;
mod compare;
mod docs;
mod dynamic;
mod engine;
mod errors;
mod flags;
mod metrics;
mod model_file;
mod outputs;
mod pbns;
mod pose;
mod progress;
mod retarget;
mod rigs;
mod simulate;
mod suite;
mod swing;
mod usd;
mod validate;
mod view;
