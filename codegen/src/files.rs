//! Output files, all or nothing, for the generator and the command line.
//!
//! A regular file (or a new one) is written under a temporary name in its
//! directory and renamed onto it only once every output of the run has been
//! written: readers never see half a file, and a failed run leaves no
//! output, partial or complete, and no temporary file. A symbolic link is
//! resolved first, so the file it points to is replaced and the link kept.
//! A destination that is not a regular file (a device such as `/dev/null`
//! or `/dev/stdout`, a FIFO) cannot be replaced: it is written through,
//! opened as it is, after the run (its temporary copy lives in the system's
//! temporary directory), or, for an output streamed as it is produced
//! ([`OutputFiles::create`]: the rows of a long run), during the run.
//!
//! Input files are read up to a size limit ([`read_limited`]), never whole
//! before their size is known.

use std::ffi::OsString;
use std::fs::{self, OpenOptions};
use std::io::{ErrorKind, Read};
use std::path::{Path, PathBuf};

/// Where an output goes.
#[derive(Debug, Clone, PartialEq)]
enum Destination {
    /// A regular file, or a new one: replaced by a rename (the path with
    /// its symbolic links resolved).
    Replace(PathBuf),
    /// Not a regular file (a device, a FIFO, a dangling symbolic link):
    /// opened and written through.
    Through(PathBuf),
}

/// Where the output `path` goes, or why it cannot be written (a
/// directory, a parent that is not a directory or does not exist), so
/// that a command can check its outputs before it runs.
fn destination(path: &Path) -> Result<Destination, String> {
    let fail = |why: String| format!("cannot write {}: {why}", path.display());
    match fs::metadata(path) {
        Ok(m) if m.is_dir() => Err(fail("it is a directory".into())),
        Ok(m) if m.is_file() => fs::canonicalize(path)
            .map(Destination::Replace)
            .map_err(|e| fail(e.to_string())),
        Ok(_) => Ok(Destination::Through(path.to_path_buf())),
        Err(e) if e.kind() == ErrorKind::NotFound => {
            if fs::symlink_metadata(path).is_ok() {
                return Ok(Destination::Through(path.to_path_buf()));
            }
            if path.file_name().is_none() {
                return Err(fail("not a file name".into()));
            }
            let parent = match path.parent() {
                Some(p) if !p.as_os_str().is_empty() => p,
                _ => Path::new("."),
            };
            match fs::metadata(parent) {
                Ok(m) if m.is_dir() => Ok(Destination::Replace(path.to_path_buf())),
                Ok(_) => Err(fail(format!("{} is not a directory", parent.display()))),
                Err(e) => Err(fail(format!("directory {}: {e}", parent.display()))),
            }
        }
        Err(e) => Err(fail(e.to_string())),
    }
}

/// Checks that `path` can be written as an output (see [`OutputFiles`]):
/// commands call it before they run, so that a missing directory is
/// reported before the work, not after it.
pub fn check_output(path: &Path) -> Result<(), String> {
    destination(path).map(|_| ())
}

/// One staged output.
#[derive(Debug)]
struct Staged {
    /// The temporary file written.
    tmp: PathBuf,
    /// Where it goes.
    destination: Destination,
    /// The path as given, for messages.
    shown: PathBuf,
}

/// Output files of one run, all or nothing (module docs): each is written
/// to a temporary file by [`OutputFiles::write`] and moved into place by
/// [`OutputFiles::commit`] once all of them have been written. Dropped without
/// a commit, it removes its temporary files.
#[derive(Debug, Default)]
pub struct OutputFiles {
    staged: Vec<Staged>,
}

impl OutputFiles {
    /// Write the output destined for `path` through `write`, called with
    /// the temporary path (which keeps `path`'s file name, so its extension
    /// still picks a plot's format); errors name `path`.
    pub fn write(
        &mut self,
        path: &Path,
        write: impl FnOnce(&Path) -> Result<(), String>,
    ) -> Result<(), String> {
        let destination = destination(path)?;
        let tmp = self.stage(path, destination);
        write(&tmp).map_err(|e| e.replace(&tmp.display().to_string(), &path.display().to_string()))
    }

    /// Open the output destined for `path` to be written as it is produced
    /// (the rows of a long run, never all in memory): a regular file's
    /// temporary file, moved into place by [`OutputFiles::commit`]; any
    /// other destination (a device, a FIFO) itself, written through as the
    /// run goes. Errors name `path`.
    pub fn create(&mut self, path: &Path) -> Result<fs::File, String> {
        let fail = |e: std::io::Error| format!("cannot write {}: {e}", path.display());
        match destination(path)? {
            Destination::Through(dest) => open_through(&dest).map_err(fail),
            replace => fs::File::create(self.stage(path, replace)).map_err(fail),
        }
    }

    /// The temporary file of the output destined for `path`, registered
    /// (before it is written, so that a partly written file is removed too).
    fn stage(&mut self, path: &Path, destination: Destination) -> PathBuf {
        let name = path.file_name().unwrap_or(path.as_os_str());
        let mut tmp_name = OsString::from(format!(
            ".flexdyn-{}-{}-",
            std::process::id(),
            self.staged.len()
        ));
        tmp_name.push(name);
        let tmp = match &destination {
            Destination::Replace(real) => real.with_file_name(tmp_name),
            Destination::Through(_) => std::env::temp_dir().join(tmp_name),
        };
        self.staged.push(Staged {
            tmp: tmp.clone(),
            destination,
            shown: path.to_path_buf(),
        });
        tmp
    }

    /// [`OutputFiles::write`] of a text.
    pub fn write_text(&mut self, path: &Path, text: &str) -> Result<(), String> {
        self.write(path, |tmp| {
            fs::write(tmp, text).map_err(|e| format!("cannot write {}: {e}", tmp.display()))
        })
    }

    /// Move every output into place: first those written through (where a
    /// failure leaves the regular files untouched), then the renames.
    pub fn commit(self) -> Result<(), String> {
        for s in &self.staged {
            if let Destination::Through(dest) = &s.destination {
                let fail = |e: std::io::Error| format!("cannot write {}: {e}", s.shown.display());
                let mut from = fs::File::open(&s.tmp).map_err(fail)?;
                let mut to = open_through(dest).map_err(fail)?;
                std::io::copy(&mut from, &mut to).map_err(fail)?;
            }
        }
        for s in &self.staged {
            if let Destination::Replace(dest) = &s.destination {
                fs::rename(&s.tmp, dest)
                    .map_err(|e| format!("cannot write {}: {e}", s.shown.display()))?;
            }
        }
        Ok(())
    }
}

/// A destination that is not a regular file, opened to be written through.
fn open_through(dest: &Path) -> std::io::Result<fs::File> {
    OpenOptions::new()
        .write(true)
        .create(true)
        .truncate(true)
        .open(dest)
}

impl Drop for OutputFiles {
    fn drop(&mut self) {
        for s in &self.staged {
            let _ = fs::remove_file(&s.tmp);
        }
    }
}

/// Write `text` to `path` on its own, all or nothing ([`OutputFiles`]).
pub fn write_atomic(path: &Path, text: &str) -> Result<(), String> {
    let mut outputs = OutputFiles::default();
    outputs.write_text(path, text)?;
    outputs.commit()
}

/// The text of the file at `path`, refused without reading further once it
/// passes `limit` bytes (`/dev/zero`, a stray 1 GB file), and when it is not
/// UTF-8; errors say `what` it is and the limit (the caller names the
/// file).
pub fn read_limited(path: &Path, limit: u64, what: &str) -> Result<String, String> {
    let fail = |why: String| format!("cannot read {what}: {why}");
    let file = fs::File::open(path).map_err(|e| fail(e.to_string()))?;
    let mut bytes = Vec::new();
    file.take(limit.saturating_add(1))
        .read_to_end(&mut bytes)
        .map_err(|e| fail(e.to_string()))?;
    if bytes.len() as u64 > limit {
        return Err(fail(format!("larger than the limit of {limit} bytes")));
    }
    String::from_utf8(bytes).map_err(|e| {
        fail(format!(
            "not UTF-8 text (byte {} of the file)",
            e.utf8_error().valid_up_to()
        ))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn outputs_are_all_or_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (dir.path().join("a.csv"), dir.path().join("b.csv"));
        let listing = || fs::read_dir(dir.path()).unwrap().count();
        // The second output fails: the first is not left behind.
        let mut outputs = OutputFiles::default();
        outputs.write_text(&a, "x").unwrap();
        let e = outputs
            .write(&b, |tmp| {
                fs::write(tmp, "partial").unwrap();
                Err(format!("cannot plot to {}", tmp.display()))
            })
            .unwrap_err();
        assert_eq!(e, format!("cannot plot to {}", b.display()));
        drop(outputs);
        assert_eq!(listing(), 0);
        // Both succeed: both are in place, nothing else.
        let mut outputs = OutputFiles::default();
        outputs.write_text(&a, "x").unwrap();
        outputs.write_text(&b, "y").unwrap();
        outputs.commit().unwrap();
        assert_eq!(fs::read_to_string(&b).unwrap(), "y");
        assert_eq!(listing(), 2);
        // A directory, or a missing one, is refused before anything is written.
        let e = check_output(dir.path()).unwrap_err();
        assert!(e.contains("is a directory"), "{e}");
        let e = check_output(&dir.path().join("no/such.csv")).unwrap_err();
        assert!(e.contains("no/such.csv") && e.contains("directory"), "{e}");
        let e = check_output(&a.join("x.csv")).unwrap_err();
        assert!(e.to_lowercase().contains("not a directory"), "{e}");
    }

    #[test]
    fn streamed_outputs_are_staged_or_written_through() {
        use std::io::Write;
        let dir = tempfile::tempdir().unwrap();
        let a = dir.path().join("a.csv");
        let listing = || fs::read_dir(dir.path()).unwrap().count();
        // A regular file: only its temporary file until the commit.
        let mut outputs = OutputFiles::default();
        let mut file = outputs.create(&a).unwrap();
        file.write_all(b"t\n0\n").unwrap();
        assert!(!a.exists());
        assert_eq!(listing(), 1);
        outputs.commit().unwrap();
        assert_eq!(fs::read_to_string(&a).unwrap(), "t\n0\n");
        // Not committed: nothing left, the old file untouched.
        let mut outputs = OutputFiles::default();
        outputs.create(&a).unwrap().write_all(b"partial").unwrap();
        drop(outputs);
        assert_eq!(listing(), 1);
        assert_eq!(fs::read_to_string(&a).unwrap(), "t\n0\n");
        // A device is written through, nothing staged.
        let mut outputs = OutputFiles::default();
        outputs
            .create(Path::new("/dev/null"))
            .unwrap()
            .write_all(b"x")
            .unwrap();
        assert!(outputs.staged.is_empty());
        let e = outputs.create(dir.path()).unwrap_err();
        assert!(e.contains("is a directory"), "{e}");
    }

    #[test]
    fn inputs_are_read_up_to_their_limit() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("f.csv");
        fs::write(&file, "t,u\n").unwrap();
        assert_eq!(read_limited(&file, 4, "inputs").unwrap(), "t,u\n");
        let e = read_limited(&file, 3, "inputs").unwrap_err();
        assert_eq!(e, "cannot read inputs: larger than the limit of 3 bytes");
        fs::write(&file, b"t\xff").unwrap();
        let e = read_limited(&file, 10, "inputs").unwrap_err();
        assert!(e.contains("not UTF-8 text (byte 1"), "{e}");
        // An endless device stops at the limit.
        let e = read_limited(Path::new("/dev/zero"), 1 << 20, "scene").unwrap_err();
        assert!(e.contains("1048576 bytes"), "{e}");
    }

    #[cfg(unix)]
    #[test]
    fn links_are_resolved_and_devices_written_through() {
        use std::os::unix::fs::FileTypeExt;
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("target.csv");
        let link = dir.path().join("link.csv");
        fs::write(&target, "precious").unwrap();
        std::os::unix::fs::symlink("target.csv", &link).unwrap();
        write_atomic(&link, "new").unwrap();
        assert!(fs::symlink_metadata(&link)
            .unwrap()
            .file_type()
            .is_symlink());
        assert_eq!(fs::read_to_string(&target).unwrap(), "new");
        // A dangling link: the file it names is created.
        let dangling = dir.path().join("dangling.csv");
        std::os::unix::fs::symlink("created.csv", &dangling).unwrap();
        write_atomic(&dangling, "made").unwrap();
        assert_eq!(
            fs::read_to_string(dir.path().join("created.csv")).unwrap(),
            "made"
        );
        // A FIFO (like a device) is written through, not replaced.
        let fifo = dir.path().join("fifo");
        let made = std::process::Command::new("mkfifo").arg(&fifo).status();
        assert!(made.unwrap().success());
        let reader = {
            let fifo = fifo.clone();
            std::thread::spawn(move || fs::read_to_string(fifo).unwrap())
        };
        write_atomic(&fifo, "through").unwrap();
        assert_eq!(reader.join().unwrap(), "through");
        assert!(fs::symlink_metadata(&fifo).unwrap().file_type().is_fifo());
        assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 5);
    }
}
