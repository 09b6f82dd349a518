//! Embed run-time search paths so the binary finds libtorch and the venv's libpython without LD_LIBRARY_PATH.
fn main() {
    println!("cargo:rerun-if-env-changed=LIBTORCH");
    if let Ok(libtorch) = std::env::var("LIBTORCH") {
        println!("cargo:rustc-link-arg=-Wl,-rpath,{libtorch}/lib");
    }
    if std::env::var_os("CARGO_FEATURE_USD").is_some() {
        pyo3_build_config::add_libpython_rpath_link_args();
    }
}
