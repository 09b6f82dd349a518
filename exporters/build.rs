//! Embeds three.js for `garmentbake view` at build time, so an installed binary writes
//! self-contained pages with no tools/node next to it. The files come from the pinned npm package
//! that scripts/setup.sh installs in tools/node (or GARMENTBAKE_THREE_DIR); a build without it
//! still succeeds, and `view` then says how to get it.
use std::path::{Path, PathBuf};

/// The package files the page needs (path inside the `three` package).
const FILES: [&str; 5] = [
    "package.json",
    "LICENSE",
    "build/three.module.min.js",
    "examples/jsm/loaders/GLTFLoader.js",
    "examples/jsm/utils/BufferGeometryUtils.js",
];

fn main() {
    println!("cargo:rerun-if-env-changed=GARMENTBAKE_THREE_DIR");
    let manifest = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").expect("cargo sets it"));
    let three = std::env::var_os("GARMENTBAKE_THREE_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| manifest.join("../tools/node/node_modules/three"));
    let out = PathBuf::from(std::env::var("OUT_DIR").expect("cargo sets it")).join("three");
    std::fs::create_dir_all(out.join("build")).expect("create OUT_DIR/three");
    let found = FILES.iter().all(|f| three.join(f).is_file());
    for f in FILES {
        let src = three.join(f);
        println!("cargo:rerun-if-changed={}", src.display());
        let dst = out.join(Path::new(f).file_name().expect("file name"));
        // Missing package: empty files, and the page writer refuses with a message.
        let bytes = if found {
            std::fs::read(&src).expect("read three.js file")
        } else {
            Vec::new()
        };
        std::fs::write(dst, bytes).expect("write OUT_DIR/three");
    }
    if !found {
        println!(
            "cargo:warning=three.js not found at {} (run scripts/setup.sh): `garmentbake view` will be unavailable in this build",
            three.display()
        );
    }
}
