//! The glTF/GLB body reader on any bytes: a body or an error, never a panic.
#![no_main]
use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let _ = garmentbake::io::gltf_body::parse_body(data, Path::new("fuzz.glb"));
});
