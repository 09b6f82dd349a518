//! What one `batch run` created on disk (folders, its plan, logs, reports, keys) and what it
//! replaced, so that a run that cannot go on (a full disk) takes all of it back: the folder is
//! left as the run found it, but for the jobs that finished (their outputs, report, keys and log
//! stay, so the next run does not redo them).

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

#[derive(Default)]
pub struct Ledger {
    inner: Mutex<Entries>,
}

#[derive(Default)]
struct Entries {
    /// Folders this run created, outermost first.
    dirs: Vec<PathBuf>,
    /// Files this run created.
    files: Vec<PathBuf>,
    /// Files this run overwrote, with the bytes they held.
    replaced: Vec<(PathBuf, Vec<u8>)>,
    /// Files of finished jobs: not taken back.
    kept: BTreeSet<PathBuf>,
}

impl Ledger {
    fn entries(&self) -> std::sync::MutexGuard<'_, Entries> {
        // A panicking job thread cannot leave the lists half-updated: each push is one step.
        self.inner.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// `std::fs::create_dir_all`, noting each folder it creates.
    pub fn create_dir_all(&self, dir: &Path) -> std::io::Result<()> {
        let missing: Vec<&Path> = dir.ancestors().take_while(|d| !d.exists()).collect();
        std::fs::create_dir_all(dir)?;
        let mut e = self.entries();
        for d in missing.into_iter().rev() {
            if !d.as_os_str().is_empty() {
                e.dirs.push(d.to_path_buf());
            }
        }
        Ok(())
    }

    /// Notes that `path` is about to be written: created, or replaced (its bytes kept).
    fn note(&self, path: &Path) {
        let old = std::fs::read(path).ok();
        let mut e = self.entries();
        let known = e.files.iter().any(|f| f == path) || e.replaced.iter().any(|r| r.0 == path);
        if !known {
            match old {
                Some(bytes) => e.replaced.push((path.to_path_buf(), bytes)),
                None => e.files.push(path.to_path_buf()),
            }
        }
    }

    /// Writes `bytes` to `path` atomically (exporters::atomic), noting it.
    pub fn write(&self, path: &Path, bytes: &[u8]) -> std::io::Result<()> {
        self.note(path);
        exporters::atomic::write_atomic(path, bytes)
    }

    /// Creates (truncates) `path` for writing, noting it.
    pub fn create(&self, path: &Path) -> std::io::Result<std::fs::File> {
        self.note(path);
        std::fs::File::create(path)
    }

    /// These files stay whatever happens to the run (a finished job's).
    pub fn keep<'a>(&self, paths: impl IntoIterator<Item = &'a PathBuf>) {
        let mut e = self.entries();
        e.kept.extend(paths.into_iter().cloned());
    }

    /// Takes back what the run wrote: files it created are removed, files it overwrote get their
    /// bytes back, folders it created are removed when nothing kept is left in them. Best
    /// effort, in reverse order: the error that stopped the run is what the caller reports.
    pub fn roll_back(&self) {
        let e = self.entries();
        for f in e.files.iter().rev().filter(|f| !e.kept.contains(*f)) {
            let _ = std::fs::remove_file(f);
        }
        for (f, bytes) in e.replaced.iter().rev().filter(|r| !e.kept.contains(&r.0)) {
            // The disk is full: removing first frees the room the old bytes need.
            let _ = std::fs::remove_file(f);
            let _ = std::fs::write(f, bytes);
        }
        for d in e.dirs.iter().rev() {
            let _ = std::fs::remove_dir(d); // fails, as it should, on a folder still holding files
        }
    }
}

/// Whether an error line says the disk (or the quota) is full: the OS's words, which every
/// writer (ours, usd-core's, Blender's) passes on.
pub fn out_of_space(error: &str) -> bool {
    let e = error.to_ascii_lowercase();
    e.contains("no space left on device") || e.contains("disk quota exceeded")
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    #[test]
    fn a_roll_back_leaves_the_folder_as_it_was_but_for_kept_files() {
        let root = std::env::temp_dir().join(format!("ledger-test-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        std::fs::create_dir_all(&root).unwrap();
        std::fs::write(root.join("plan.json"), b"old plan").unwrap();
        let ledger = Ledger::default();
        ledger.create_dir_all(&root.join("out/logs")).unwrap();
        ledger.create_dir_all(&root.join("out/done")).unwrap();
        ledger.write(&root.join("plan.json"), b"new plan").unwrap();
        let mut log = ledger.create(&root.join("out/logs/a.log")).unwrap();
        writeln!(log, "# attempt 1").unwrap();
        ledger.write(&root.join("out/done/x.pc2"), b"x").unwrap();
        ledger.keep([&root.join("out/done/x.pc2")]);
        ledger.roll_back();
        let mut left: Vec<String> = walk(&root);
        left.sort();
        assert_eq!(left, ["out", "out/done", "out/done/x.pc2", "plan.json"]);
        assert_eq!(std::fs::read(root.join("plan.json")).unwrap(), b"old plan");
        std::fs::remove_dir_all(&root).unwrap();
        assert!(out_of_space(
            "cannot write /x/skirt.safetensors: No space left on device"
        ));
        assert!(!out_of_space("cannot read /x/clip.bvh: not a BVH file"));
    }

    fn walk(root: &Path) -> Vec<String> {
        let mut out = Vec::new();
        let mut stack = vec![root.to_path_buf()];
        while let Some(d) = stack.pop() {
            for e in std::fs::read_dir(&d).unwrap() {
                let p = e.unwrap().path();
                out.push(p.strip_prefix(root).unwrap().display().to_string());
                if p.is_dir() {
                    stack.push(p);
                }
            }
        }
        out
    }
}
