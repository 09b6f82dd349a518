//! Never leave a half-written output: write next to the target, flush it to disk, then rename
//! over it. The one way every garmentbake output (models, meshes, pictures, caches) is written.

use std::io::Write;
use std::path::{Path, PathBuf};

/// Temporary sibling of `path` (same directory, so the final rename is atomic), named per process
/// and per call: two writers of one path (two tests or batch jobs filling a shared simulation
/// cache) each rename their own whole file, where one shared name let the second rename fail.
pub fn temp_path(path: &Path) -> PathBuf {
    static CALLS: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let call = CALLS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    path.with_file_name(format!(".{name}.{}-{call}.partial", std::process::id()))
}

/// Writes `bytes` to `path` atomically; the error names the path.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    write_atomic_with(path, |f| f.write_all(bytes))
}

/// Streams into a temporary file through `fill`, syncs it (so a crash cannot leave an empty
/// file under the final name), then renames it to `path`. The error keeps its kind and names
/// the path: `cannot write PATH: reason`.
pub fn write_atomic_with(
    path: &Path,
    fill: impl FnOnce(&mut std::io::BufWriter<std::fs::File>) -> std::io::Result<()>,
) -> std::io::Result<()> {
    let tmp = temp_path(path);
    let result = (|| {
        let file = std::fs::File::create(&tmp)?;
        let mut w = std::io::BufWriter::new(file);
        fill(&mut w)?;
        w.flush()?;
        let file = w.into_inner().map_err(|e| e.into_error())?;
        file.sync_all()?;
        drop(file);
        std::fs::rename(&tmp, path)
    })();
    if let Err(e) = result {
        // Best effort: the write error is what the caller needs to see.
        let _ = std::fs::remove_file(&tmp);
        return Err(std::io::Error::new(
            e.kind(),
            format!("cannot write {}: {}", path.display(), io_message(&e)),
        ));
    }
    Ok(())
}

/// `io::Error`'s message without the trailing " (os error N)", for one clean line.
pub fn io_message(e: &std::io::Error) -> String {
    let text = e.to_string();
    match text.rfind(" (os error ") {
        Some(i) if text.ends_with(')') => text[..i].to_string(),
        _ => text,
    }
}

/// Temporary sibling of `path` that keeps its extension (`skirt.usdc` → `.skirt.partial.usdc`),
/// for writers such as usd-core that choose the file format from the extension.
pub fn temp_path_keeping_extension(path: &Path) -> PathBuf {
    let stem = path
        .file_stem()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    match path.extension() {
        Some(ext) => path.with_file_name(format!(".{stem}.partial.{}", ext.to_string_lossy())),
        None => path.with_file_name(format!(".{stem}.partial")),
    }
}

/// Lets `fill` write the whole file at `tmp` (a [`temp_path_keeping_extension`] of `path`), then
/// renames it over `path`; on any failure the temporary file is removed and `path` is untouched.
pub fn replace_via<E: From<std::io::Error>>(
    path: &Path,
    fill: impl FnOnce(&Path) -> Result<(), E>,
) -> Result<(), E> {
    // Some writers (usd-core) create missing folders; refuse like every other output does.
    if let Some(dir) = path
        .parent()
        .filter(|d| !d.as_os_str().is_empty() && !d.is_dir())
    {
        return Err(E::from(std::io::Error::new(
            std::io::ErrorKind::NotFound,
            format!(
                "cannot write {}: no folder {}",
                path.display(),
                dir.display()
            ),
        )));
    }
    let tmp = temp_path_keeping_extension(path);
    let result = fill(&tmp).and_then(|()| {
        std::fs::rename(&tmp, path).map_err(|e| {
            E::from(std::io::Error::new(
                e.kind(),
                format!("cannot write {}: {e}", path.display()),
            ))
        })
    });
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// One output of an [`OutputSet`]: the flag that names it (for messages), its path, and the
/// extensions (lower case, without the dot) that flag writes (none: any name, such as a log).
pub struct Planned<'a> {
    pub flag: &'a str,
    pub path: &'a Path,
    pub extensions: &'a [&'a str],
}

/// The files one command writes together (a garment cache and the body's, a bake and its
/// page): all of them, or none. [`OutputSet::check`] refuses a bad path before any work
/// (extension, folder, writable, two flags naming one file); each file is then written into
/// a hidden staging folder beside its target under its own name (writers that name things
/// after the file, or write a `.gltf`'s `.bin` beside it, see the real name), and
/// [`OutputSet::commit`] moves them all into place at the end. A failure anywhere, a full disk
/// included, leaves the old outputs as they were and no staged file behind; dropping an
/// uncommitted set removes what it staged.
pub struct OutputSet {
    outputs: Vec<PathBuf>,
    /// Each target folder (as given, "" for the working folder) and its staging folder.
    staging: Vec<(PathBuf, PathBuf)>,
}

impl OutputSet {
    /// Checks every output before any work: a known extension for its flag, an existing folder
    /// we can create files in, no file named twice. The error names the flag and the path.
    pub fn check(outputs: &[Planned]) -> std::io::Result<OutputSet> {
        use std::io::{Error, ErrorKind};
        static SETS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
        let set = SETS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let mut checked = OutputSet {
            outputs: Vec::new(),
            staging: Vec::new(),
        };
        for o in outputs {
            let shown = o.path.display();
            // An extension may have two parts (`vat.exr`): the name's end must be one of them.
            let name = o
                .path
                .file_name()
                .map(|n| n.to_string_lossy().to_ascii_lowercase())
                .unwrap_or_default();
            let known = o
                .extensions
                .iter()
                .any(|e| name.len() > e.len() + 1 && name.ends_with(&format!(".{e}")));
            if !known && !o.extensions.is_empty() {
                let list: Vec<String> = o.extensions.iter().map(|e| format!(".{e}")).collect();
                let list = match list.split_last() {
                    Some((last, rest)) if !rest.is_empty() => {
                        format!("{} or {last}", rest.join(", "))
                    }
                    _ => list.join(""),
                };
                return Err(Error::new(
                    ErrorKind::InvalidInput,
                    format!("{} {shown}: unknown extension; write {list}", o.flag),
                ));
            }
            if let Some(i) = outputs
                .iter()
                .position(|p| same_file(p.path, o.path))
                .filter(|&i| !std::ptr::eq(&outputs[i], o))
            {
                return Err(Error::new(
                    ErrorKind::InvalidInput,
                    format!(
                        "{} {shown}: {} writes that file too",
                        o.flag, outputs[i].flag
                    ),
                ));
            }
            // Alembic is written through the Python bridge: a venv without `alembic3d` is bad
            // input, refused here rather than when the cache is written, after the work.
            #[cfg(feature = "usd")]
            if crate::FileKind::written(o.path) == Some(crate::FileKind::Alembic) {
                python_bridge::check_alembic().map_err(|e| {
                    Error::new(ErrorKind::InvalidInput, format!("{} {shown}: {e}", o.flag))
                })?;
            }
            let dir = o.path.parent().unwrap_or(Path::new("")).to_path_buf();
            let shown_dir = if dir.as_os_str().is_empty() {
                Path::new(".")
            } else {
                &dir
            };
            if !shown_dir.is_dir() {
                return Err(Error::new(
                    ErrorKind::NotFound,
                    format!("{} {shown}: no folder {}", o.flag, shown_dir.display()),
                ));
            }
            if !checked.staging.iter().any(|(d, _)| *d == dir) {
                let stage = dir.join(format!(".garmentbake-{}-{set}.partial", std::process::id()));
                // Creating (then removing) the staging folder is the test of "writable": it is
                // what the writes will need, and nothing is left there during the work.
                std::fs::create_dir(&stage)
                    .and_then(|()| std::fs::remove_dir(&stage))
                    .map_err(|e| {
                        Error::new(
                            e.kind(),
                            format!(
                                "{} {shown}: cannot write in {}: {}",
                                o.flag,
                                shown_dir.display(),
                                io_message(&e)
                            ),
                        )
                    })?;
                checked.staging.push((dir, stage));
            }
            checked.outputs.push(o.path.to_path_buf());
        }
        Ok(checked)
    }

    /// Where to write `path` (one of the set's outputs) now: its name in the staging folder.
    pub fn staged(&self, path: &Path) -> std::io::Result<PathBuf> {
        let stage = self.stage_of(path)?;
        match std::fs::create_dir(stage) {
            Err(e) if e.kind() != std::io::ErrorKind::AlreadyExists => {
                return Err(std::io::Error::new(
                    e.kind(),
                    format!("cannot write {}: {}", path.display(), io_message(&e)),
                ))
            }
            _ => {}
        }
        Ok(stage.join(path.file_name().unwrap_or_default()))
    }

    /// Runs `fill` on the staged name of `path`. Its error comes back as one line (the chain,
    /// outermost first, a cause already quoted not repeated) that names `path` where it named
    /// the staged file: the staging folder means nothing to the person reading it.
    pub fn write<T, E>(
        &self,
        path: &Path,
        fill: impl FnOnce(&Path) -> Result<T, E>,
    ) -> anyhow::Result<T>
    where
        E: Into<anyhow::Error>,
    {
        let staged = self.staged(path)?;
        fill(&staged).map_err(|e| {
            let (dir, stage) = self.folders_of(path);
            let mut text = String::new();
            for cause in e.into().chain() {
                let cause = cause.to_string();
                if !text.contains(&cause) {
                    if !text.is_empty() {
                        text.push_str(": ");
                    }
                    text.push_str(&cause);
                }
            }
            let real = if dir.as_os_str().is_empty() {
                String::new()
            } else {
                format!("{}/", dir.display())
            };
            anyhow::anyhow!(text.replace(&format!("{}/", stage.display()), &real))
        })
    }

    /// Moves every staged file into place (a `.gltf`'s `.bin` with it). Should one move fail,
    /// the files already moved are taken out again and the ones they replaced put back: the
    /// targets are left as they were before the command.
    pub fn commit(self) -> std::io::Result<()> {
        let mut moved: Vec<(PathBuf, Option<PathBuf>)> = Vec::new();
        let result = self.move_all(&mut moved);
        if result.is_err() {
            for (target, old) in moved.iter().rev() {
                let _ = std::fs::remove_file(target);
                if let Some(old) = old {
                    let _ = std::fs::rename(old, target);
                }
            }
        }
        result
        // Dropping `self` removes the staging folders (and the replaced files kept there).
    }

    fn move_all(&self, moved: &mut Vec<(PathBuf, Option<PathBuf>)>) -> std::io::Result<()> {
        for (dir, stage) in &self.staging {
            let Ok(entries) = std::fs::read_dir(stage) else {
                continue; // nothing was staged in this folder
            };
            let names: Vec<_> = entries
                .filter_map(|e| e.ok())
                .map(|e| e.file_name())
                .filter(|n| n != REPLACED)
                .collect();
            for name in names {
                let target = dir.join(&name);
                let fail = |e: std::io::Error| {
                    std::io::Error::new(
                        e.kind(),
                        format!("cannot write {}: {}", target.display(), io_message(&e)),
                    )
                };
                // Keep the file it replaces until the whole set is in place.
                let old = match std::fs::symlink_metadata(&target) {
                    Ok(m) if !m.is_dir() => {
                        let keep = stage.join(REPLACED);
                        std::fs::create_dir_all(&keep).map_err(fail)?;
                        let old = keep.join(&name);
                        std::fs::rename(&target, &old).map_err(fail)?;
                        Some(old)
                    }
                    _ => None,
                };
                match std::fs::rename(stage.join(&name), &target) {
                    Ok(()) => moved.push((target, old)),
                    Err(e) => {
                        if let Some(old) = &old {
                            let _ = std::fs::rename(old, &target);
                        }
                        return Err(fail(e));
                    }
                }
            }
        }
        Ok(())
    }

    fn stage_of(&self, path: &Path) -> std::io::Result<&Path> {
        if !self.outputs.iter().any(|o| o == path) {
            return Err(std::io::Error::other(format!(
                "{} is not an output of this command",
                path.display()
            )));
        }
        Ok(self.folders_of(path).1)
    }

    fn folders_of(&self, path: &Path) -> (&Path, &Path) {
        let dir = path.parent().unwrap_or(Path::new(""));
        let (d, s) = self
            .staging
            .iter()
            .find(|(d, _)| d == dir)
            .expect("every output's folder has a staging folder");
        (d, s)
    }
}

impl Drop for OutputSet {
    fn drop(&mut self) {
        for (_, stage) in &self.staging {
            // Best effort: absent when nothing was staged there.
            let _ = std::fs::remove_dir_all(stage);
        }
    }
}

/// The staging folder's own folder for the files a commit replaces.
const REPLACED: &str = ".replaced";

/// Two outputs naming one file: the same name in the same folder, however the folder is spelt.
fn same_file(a: &Path, b: &Path) -> bool {
    let place = |p: &Path| {
        let dir = p.parent().filter(|d| !d.as_os_str().is_empty());
        let dir = dir.unwrap_or(Path::new(".")).canonicalize().ok()?;
        Some(dir.join(p.file_name()?))
    };
    a == b || matches!((place(a), place(b)), (Some(x), Some(y)) if x == y)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_writer_failing_midway_keeps_the_old_file_and_leaves_no_temp() {
        let dir = std::env::temp_dir().join(format!("atomic-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("out.bin");
        std::fs::write(&path, b"old").unwrap();
        let err = write_atomic_with(&path, |w| {
            w.write_all(&[7u8; 100_000])?;
            Err(std::io::Error::other("disk full"))
        })
        .unwrap_err();
        assert_eq!(
            err.to_string(),
            format!("cannot write {}: disk full", path.display())
        );
        assert_eq!(std::fs::read(&path).unwrap(), b"old");
        write_atomic(&path, b"new").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"new");
        let names: Vec<_> = std::fs::read_dir(&dir).unwrap().collect();
        assert_eq!(names.len(), 1);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn writers_racing_for_one_path_each_land_a_whole_file() {
        // Two tests once filled the shared simulation cache with the same entry at once; with one
        // temporary name the slower rename found its file gone ("No such file or directory").
        let dir = scratch("race");
        let path = dir.join("entry.pc2");
        let writers: Vec<_> = (0..4u8)
            .map(|w| {
                let path = path.clone();
                std::thread::spawn(move || {
                    for _ in 0..200 {
                        write_atomic(&path, &[w; 4096]).unwrap();
                    }
                })
            })
            .collect();
        for w in writers {
            w.join().unwrap();
        }
        let bytes = std::fs::read(&path).unwrap();
        assert!(bytes.len() == 4096 && bytes.iter().all(|&b| b == bytes[0]));
        assert_eq!(names(&dir), ["entry.pc2"], "no temporary file left");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    fn scratch(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("output-set-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    fn names(dir: &Path) -> Vec<String> {
        let mut n: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        n.sort();
        n
    }

    const CACHE: &[&str] = &["pc2"];

    #[test]
    fn an_output_set_is_checked_before_the_work_and_moved_in_all_together() {
        let dir = scratch("commit");
        let (a, b) = (dir.join("a.pc2"), dir.join("b.pc2"));
        let plan = |a: &Path, b: &Path| {
            OutputSet::check(&[
                Planned {
                    flag: "--out",
                    path: a,
                    extensions: CACHE,
                },
                Planned {
                    flag: "--body-out",
                    path: b,
                    extensions: CACHE,
                },
            ])
        };
        let err = plan(&a, &dir.join("b.obj")).err().unwrap().to_string();
        assert!(
            err.starts_with("--body-out ") && err.ends_with("write .pc2"),
            "{err}"
        );
        let err = plan(&a, &dir.join("none/b.pc2")).err().unwrap().to_string();
        assert!(err.contains("no folder"), "{err}");
        let err = plan(&a, &dir.join(".").join("a.pc2"))
            .err()
            .unwrap()
            .to_string();
        assert!(err.contains("--out writes that file too"), "{err}");
        assert!(
            names(&dir).is_empty(),
            "a check leaves nothing: {:?}",
            names(&dir)
        );
        std::fs::write(&a, b"old a").unwrap();
        let set = plan(&a, &b).unwrap();
        set.write(&a, |p| write_atomic(p, b"new a")).unwrap();
        set.write(&b, |p| write_atomic(p, b"new b")).unwrap();
        assert_eq!(
            std::fs::read(&a).unwrap(),
            b"old a",
            "nothing moves before the commit"
        );
        assert!(!b.exists());
        set.commit().unwrap();
        assert_eq!(std::fs::read(&a).unwrap(), b"new a");
        assert_eq!(std::fs::read(&b).unwrap(), b"new b");
        assert_eq!(names(&dir), ["a.pc2", "b.pc2"]);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_failed_write_or_move_leaves_the_old_outputs_and_no_staged_file() {
        let dir = scratch("rollback");
        let (a, b) = (dir.join("a.pc2"), dir.join("b.pc2"));
        let planned = [
            Planned {
                flag: "--out",
                path: &a,
                extensions: CACHE,
            },
            Planned {
                flag: "--body-out",
                path: &b,
                extensions: CACHE,
            },
        ];
        std::fs::write(&a, b"old a").unwrap();
        // The second file fails to write (a full disk): the error names the real path.
        let set = OutputSet::check(&planned).unwrap();
        set.write(&a, |p| write_atomic(p, b"new a")).unwrap();
        let err = set
            .write(&b, |p| {
                write_atomic_with(p, |_| Err(std::io::Error::other("No space left on device")))
            })
            .unwrap_err();
        assert_eq!(
            err.to_string(),
            format!("cannot write {}: No space left on device", b.display())
        );
        drop(set);
        assert_eq!(names(&dir), ["a.pc2"]);
        assert_eq!(std::fs::read(&a).unwrap(), b"old a");
        // Both written, the second move fails (a folder in its place): the first is undone.
        std::fs::create_dir(&b).unwrap();
        let set = OutputSet::check(&planned).unwrap();
        set.write(&a, |p| write_atomic(p, b"new a")).unwrap();
        set.write(&b, |p| write_atomic(p, b"new b")).unwrap();
        let err = set.commit().unwrap_err().to_string();
        assert!(err.contains(&*b.to_string_lossy()), "{err}");
        assert_eq!(names(&dir), ["a.pc2", "b.pc2"]);
        assert_eq!(std::fs::read(&a).unwrap(), b"old a");
        assert!(b.is_dir());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
