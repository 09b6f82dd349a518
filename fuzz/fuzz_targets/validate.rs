//! validate's checks on any bytes, as a GLB, a glTF, a PC2 and an MDD: problems listed, never a
//! panic. A glTF whose structure passes is then replayed as `validate --model` replays one: the
//! spec's evaluator (`validate::scene`: samplers, node hierarchy, morph targets, skinning) on
//! every mesh node at rest and at its animations' keys, between them and past both ends, and
//! `replay_gltf` (garment node, `sourceVertex` map, the per-frame comparison) against the file's
//! own rest pose.
#![no_main]
use garmentbake::validate::container::Document;
use garmentbake::validate::replay::{replay_gltf, Reference};
use garmentbake::validate::scene::Scene;
use garmentbake::validate::structure::Accessors;
use garmentbake::validate::{cache, check_gltf, Problems};
use libfuzzer_sys::fuzz_target;
use std::path::Path;

/// Bounds that keep one input's work small (a mutated file can declare many nodes and keys).
const NODES: usize = 8;
const ANIMATIONS: usize = 4;
const FRAMES: usize = 64;

fn replay(doc: &Document, accessors: &Accessors) {
    let scene = Scene::new(doc, accessors);
    let root = &doc.root;
    let meshes = (0..root.nodes.len()).filter(|&n| root.nodes[n].mesh.is_some());
    for node in meshes.take(NODES) {
        let rest = scene.positions(node, None, 0.0);
        for a in 0..root.animations.len().min(ANIMATIONS) {
            let times = scene.times(a);
            let (Some(&first), Some(&last)) = (times.first(), times.last()) else {
                continue;
            };
            let between = times.get(1).map_or(first, |&t| 0.5 * (first + t));
            for t in [first - 1.0, first, between, 0.5 * (first + last), last, last + 1.0] {
                let _ = scene.positions(node, Some(a), t);
            }
        }
        // The rest pose held for the first animation's keys, as a model's frames would be.
        let keys = root.animations.first().map_or(1, |_| scene.times(0).len());
        if (1..=FRAMES).contains(&keys) {
            let frame: Vec<[f32; 3]> = rest.iter().map(|p| p.map(|x| x as f32)).collect();
            let reference = Reference::of_frames("fuzz", vec![frame; keys], 30.0, Vec::new());
            let _ = replay_gltf(doc, accessors, &reference, 1.0);
        }
    }
}

fuzz_target!(|data: &[u8]| {
    // A .gltf's external buffers are looked up beside this path: none exist there.
    for name in ["fuzz-none/x.glb", "fuzz-none/x.gltf"] {
        let mut problems = Problems::default();
        let checked = check_gltf(Path::new(name), data, &mut problems);
        // `validate` replays only what passed the structural checks; so does this.
        if let (Some(doc), Some(accessors), true) =
            (&checked.document, &checked.accessors, problems.passed())
        {
            replay(doc, accessors);
        }
    }
    let _ = cache::check_pc2(data, &mut Problems::default());
    let _ = cache::check_mdd(data, &mut Problems::default());
});
