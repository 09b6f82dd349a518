//! garmentbake: train neural garment deformers and bake them into standard files.
//!
//! Data flows one way; a module imports only modules on layers below its own
//! (docs/architecture.md holds the layer table; `scripts/layers.sh` checks the code against it):
//!
//! 1. `geometry`, `fabric`, `compute`, `progress`, `preview`, `build_id` — meshes and maths,
//!    physical parameters, devices, progress bars, the software rasteriser, which build this is
//! 2. `rig` — skeleton, forward kinematics, skinning, clips, retargeting (format-neutral)
//! 3. `body` — the rigged body, posed, and where points lie relative to it
//! 4. `io` — importers (OBJ, BVH, joint maps, glTF body, MakeHuman, USD meshes)
//! 5. `motion`, `garment` — clips loaded onto a skeleton; garments and their fitting
//! 6. `metrics` — garment metrics of posed frames
//! 7. `models` — the networks and the model file
//! 8. `train`, `eval`, `simulate`, `rollout`, `interpolate` — training; evaluation over clips;
//!    cloth-simulated ground truth; dynamic models rolled out frame by frame; latent walks
//! 9. `bake`, `compare` — model output → the exporter-neutral baked asset (`exporters::asset`);
//!    caches against perturbed simulations (spread, own error, e(k), the hem's swing)
//! 10. `validate` — files checked: structure, and replay against the model
//! 11. `pipeline` — the steps behind commands that gather several layers' work (preview's
//!     sheet, view's page)
//! 12. `batch` — manifests expanded into keyed jobs (command lines), run here or on Ray
//! 13. `cli` — one command per pipeline step: flags, a call into the library, the report

pub mod bake;
pub mod batch;
pub mod body;
pub mod build_id;
pub mod cli;
pub mod compare;
pub mod compute;
pub mod eval;
pub mod fabric;
pub mod garment;
pub mod geometry;
pub mod interpolate;
pub mod io;
pub mod metrics;
pub mod models;
pub mod motion;
pub mod pipeline;
pub mod preview;
pub mod progress;
pub mod rig;
pub mod rollout;
pub mod simulate;
pub mod train;
pub mod validate;
