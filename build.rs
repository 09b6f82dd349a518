//! Embed run-time search paths so the binary finds libtorch and the venv's libpython without
//! LD_LIBRARY_PATH, and the commit the sources are at (see `src/build_id.rs`).
use std::path::{Path, PathBuf};
use std::process::Command;

/// What is compiled into the binary: a change here must make the build's id change.
const SOURCES: [&str; 9] = [
    "src",
    "exporters",
    "python_bridge",
    "samples/fabrics",
    "samples/motions",
    "Cargo.toml",
    "Cargo.lock",
    "build.rs",
    ".cargo/config.toml",
];

fn main() {
    commit();
    println!("cargo:rerun-if-env-changed=LIBTORCH");
    println!("cargo:rerun-if-env-changed=GARMENTBAKE_CUDA_LINK");
    // GPU builds: keep libtorch_cuda linked even though no symbol of it is referenced directly,
    // or CUDA stays unavailable at run time (docs/gpu.md). Only for the binary, only when asked.
    if std::env::var_os("GARMENTBAKE_CUDA_LINK").is_some() {
        for arg in [
            "-Wl,--no-as-needed",
            "-ltorch_cuda",
            "-ltorch",
            "-Wl,--as-needed",
        ] {
            println!("cargo:rustc-link-arg-bins={arg}");
        }
    }
    if let Ok(libtorch) = std::env::var("LIBTORCH") {
        println!("cargo:rustc-link-arg=-Wl,-rpath,{libtorch}/lib");
    }
    if std::env::var_os("CARGO_FEATURE_USD").is_some() {
        pyo3_build_config::add_libpython_rpath_link_args();
    }
}

/// `GARMENTBAKE_BUILD_ID` (see `src/build_id.rs`): the commit when the compiled files equal
/// it, else the commit (if any) and a hash of the compiled files. The script runs again whenever
/// a compiled file changes, so the id follows every edit; a commit made after the build leaves
/// the id `…-changed.…`, which only costs a re-run of cached work.
fn commit() {
    for path in SOURCES {
        println!("cargo:rerun-if-changed={path}");
    }
    let git = |args: &[&str]| {
        // No optional locks: `status` must not take the index lock another git command needs.
        Command::new("git")
            .arg("--no-optional-locks")
            .args(args)
            .output()
            .ok()
            .filter(|o| o.status.success())
            .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
    };
    let commit = git(&["rev-parse", "HEAD"]).unwrap_or_default();
    let mut status = vec!["status", "--porcelain", "--untracked-files=normal", "--"];
    status.extend(SOURCES);
    let clean = !commit.is_empty() && git(&status).is_some_and(|s| s.is_empty());
    let id = match (clean, commit.is_empty()) {
        (true, _) => commit,
        (false, false) => format!("{commit}-changed.{:016x}", sources_hash()),
        (false, true) => format!("src.{:016x}", sources_hash()),
    };
    println!("cargo:rustc-env=GARMENTBAKE_BUILD_ID={id}");
}

/// FNV-1a 64 of every compiled file's path and bytes, in path order.
fn sources_hash() -> u64 {
    fn walk(path: &Path, files: &mut Vec<PathBuf>) {
        let name = path.file_name().unwrap_or_default().to_string_lossy();
        if name == "__pycache__" || name.ends_with(".pyc") || name == "target" {
            return;
        }
        if path.is_dir() {
            let mut entries: Vec<PathBuf> = std::fs::read_dir(path)
                .map(|d| d.filter_map(|e| e.ok().map(|e| e.path())).collect())
                .unwrap_or_default();
            entries.sort();
            for e in entries {
                walk(&e, files);
            }
        } else if path.is_file() {
            files.push(path.to_path_buf());
        }
    }
    let mut files = Vec::new();
    for path in SOURCES {
        walk(Path::new(path), &mut files);
    }
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let mut eat = |bytes: &[u8]| {
        for &b in (bytes.len() as u64).to_le_bytes().iter().chain(bytes) {
            h ^= b as u64;
            h = h.wrapping_mul(0x0100_0000_01b3);
        }
    };
    for f in files {
        eat(f.to_string_lossy().as_bytes());
        eat(&std::fs::read(&f).unwrap_or_default());
    }
    h
}
