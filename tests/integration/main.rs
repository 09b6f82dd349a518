//! The integration tests: one binary (libtorch and pyo3 are linked once), a module per area, as
//! ripgrep's tests/ are laid out. Run one area with `cargo test --test integration bake::`.

mod common;

mod bake;
mod batch;
mod compare;
mod dynamic;
mod errors;
mod metrics;
mod model_file;
mod pbns;
mod pose;
mod progress;
mod retarget;
mod simulate;
mod usd;
mod validate;
mod view;
mod suite;
