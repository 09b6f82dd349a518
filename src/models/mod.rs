//! Neural garment models — PBNS (`pbns`, pose-driven; `swing`, the optional learnt swing on top
//! of it) and the motion-guided dynamic model (`dynamic`: generative space and motion stage) —
//! their inputs (`pose_features`), pose `coverage`, CPU skinning (`sparse_skin`) and the one
//! model file that holds any of them (`file`), its kind named in the metadata.

pub mod coverage;
pub mod dynamic;
pub mod file;
pub mod pbns;
pub mod pose_features;
pub mod sparse_skin;
pub mod swing;

pub use pbns::{Pbns, PbnsShape};
use serde::{Deserialize, Serialize};
use tch::Tensor;

/// A trained garment model, of the kind its file's metadata names.
pub enum Model {
    Pbns(Pbns),
    Dynamic(Box<dynamic::Dynamic>),
}

/// The model kinds a file can hold (the metadata's `model.kind`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ModelKind {
    Pbns,
    Dynamic,
}

/// Items (poses, frames) per forward pass when predicting without gradients: bounds memory on
/// long clips, and the same chunks everywhere keep training, eval and bake bit-identical.
pub const PREDICT_CHUNK: usize = 64;

/// `forward(start, len)` over `count` items in chunks of [`PREDICT_CHUNK`], without gradients,
/// concatenated along the first dimension (one empty chunk when `count` is 0).
pub fn predict_chunks(count: usize, mut forward: impl FnMut(usize, usize) -> Tensor) -> Tensor {
    tch::no_grad(|| {
        if count == 0 {
            return forward(0, 0);
        }
        let parts: Vec<Tensor> = (0..count)
            .step_by(PREDICT_CHUNK)
            .map(|s| forward(s, PREDICT_CHUNK.min(count - s)))
            .collect();
        Tensor::cat(&parts, 0)
    })
}
