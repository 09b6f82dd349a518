//! Which build of garmentbake this is: the id that keys the simulation cache and batch jobs and
//! names the writer of a model file, so results of one program are never taken for another's
//! (the package version keyed both before, and it was 0.1.0 through every change of output).
//!
//! build.rs makes it: a build of a clean checkout is its commit, so rebuilding that commit (a
//! fresh clone in CI, another farm node, `cargo clean`) keeps the id and reuses what it made. A
//! build of changed sources is the commit plus a hash of every compiled file (`…-changed.HASH`;
//! `src.HASH` without git): each edit is a new id, while a rebuild of the same bytes is not. A
//! hash of the executable would also follow every edit, but it changes with any relink and
//! reading a 280 MB debug binary took 1–2 s per process here; the sources are hashed once, at
//! build time.
//!
//! Not covered: libtorch is linked dynamically, so another libtorch under the same binary keeps
//! the id (scripts/setup.sh pins it); so does another compiler.

/// This build's id.
pub fn id() -> &'static str {
    env!("GARMENTBAKE_BUILD_ID")
}

#[cfg(test)]
mod tests {
    use std::path::{Path, PathBuf};

    /// The folders and files build.rs hashes and watches (its `SOURCES`).
    fn sources() -> Vec<String> {
        let build = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/build.rs"))
            .expect("build.rs");
        let list = build
            .split("const SOURCES")
            .nth(1)
            .and_then(|s| s.split("];").next())
            .expect("build.rs lists SOURCES");
        list.split('"')
            .skip(1)
            .step_by(2)
            .map(String::from)
            .collect()
    }

    fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
        for e in std::fs::read_dir(dir).into_iter().flatten().flatten() {
            let p = e.path();
            if p.is_dir() && !p.ends_with("target") {
                rust_files(&p, out);
            } else if p.extension().is_some_and(|x| x == "rs") {
                out.push(p);
            }
        }
    }

    /// A file compiled into the binary but outside SOURCES would change the binary without
    /// changing its id: every `include_str!` / `include_bytes!` must reach inside them.
    #[test]
    fn everything_compiled_in_is_in_the_build_ids_sources() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        let sources = sources();
        assert!(sources.contains(&"src".to_string()), "{sources:?}");
        let mut files = Vec::new();
        for dir in ["src", "exporters", "python_bridge"] {
            rust_files(&root.join(dir), &mut files);
        }
        let mut outside = Vec::new();
        for file in &files {
            let text = std::fs::read_to_string(file).unwrap();
            for (i, _) in text.match_indices("include_") {
                let rest = &text[i..];
                let Some(arg) = ["include_str!(\"", "include_bytes!(\""]
                    .iter()
                    .find_map(|m| rest.strip_prefix(m))
                else {
                    continue;
                };
                let rel = arg.split('"').next().unwrap();
                let target = file.parent().unwrap().join(rel);
                let target: PathBuf = target.components().fold(PathBuf::new(), |mut p, c| {
                    match c {
                        std::path::Component::ParentDir => {
                            p.pop();
                        }
                        c => p.push(c),
                    }
                    p
                });
                let inside = sources.iter().any(|s| target.starts_with(root.join(s)));
                if !inside {
                    outside.push(format!("{}: {rel}", file.display()));
                }
            }
        }
        assert!(files.len() > 50, "{}", files.len());
        assert!(outside.is_empty(), "compiled in, not hashed: {outside:#?}");
    }

    #[test]
    fn this_build_has_an_id_that_is_not_the_package_version() {
        let id = super::id();
        assert!(!id.is_empty() && id != env!("CARGO_PKG_VERSION"), "{id}");
    }
}
