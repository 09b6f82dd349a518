//! Embed the rpath of the venv's base libpython (pyenv), not Debian's, or `import pxr` fails.
fn main() {
    pyo3_build_config::add_libpython_rpath_link_args();
}
