//! The fuzz binaries link libtorch (through garmentbake): find it at run time without
//! LD_LIBRARY_PATH, as the main binary does.
fn main() {
    println!("cargo:rerun-if-env-changed=LIBTORCH");
    if let Ok(libtorch) = std::env::var("LIBTORCH") {
        println!("cargo:rustc-link-arg=-Wl,-rpath,{libtorch}/lib");
    }
}
