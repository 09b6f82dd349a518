//! validate's structural checks on any bytes, as a GLB, a glTF, a PC2 and an MDD: problems
//! listed, never a panic.
#![no_main]
use garmentbake::validate::{cache, check_gltf, Problems};
use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    // A .gltf's external buffers are looked up beside this path: none exist there.
    for name in ["fuzz-none/x.glb", "fuzz-none/x.gltf"] {
        let _ = check_gltf(Path::new(name), data, &mut Problems::default());
    }
    let _ = cache::check_pc2(data, &mut Problems::default());
    let _ = cache::check_mdd(data, &mut Problems::default());
});
