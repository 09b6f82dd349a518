//! Embed run-time search paths so the binary finds libtorch and the venv's libpython without LD_LIBRARY_PATH.
fn main() {
    println!("cargo:rerun-if-env-changed=LIBTORCH");
    println!("cargo:rerun-if-env-changed=GARMENTBAKE_CUDA_LINK");
    // GPU builds: keep libtorch_cuda linked even though no symbol of it is referenced directly,
    // or CUDA stays unavailable at run time (DESIGN.md). Only for the binary, only when asked.
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
