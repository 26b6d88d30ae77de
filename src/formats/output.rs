//! Safe output: write every file to a temporary sibling, then rename it into place.

use crate::error::{Error, Result};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard};

/// The temporaries this process is writing right now (files, and terrain directories),
/// so that a command stopped by a signal can remove them ([`remove_temporaries`]).
static LIVE: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

fn live() -> MutexGuard<'static, Vec<PathBuf>> {
    LIVE.lock().unwrap_or_else(|e| e.into_inner())
}

/// Note a temporary file or directory being written, until [`untrack`]: a Ctrl-C handler's
/// [`remove_temporaries`] removes it (the CLI's staging of an `s3://` output uses it too).
pub fn track(p: &Path) {
    live().push(p.to_path_buf());
}

/// The temporary `p` was renamed into place or removed.
pub fn untrack(p: &Path) {
    live().retain(|q| q != p);
}

/// Remove every temporary file or directory this process is writing (an output not yet
/// renamed into place). For a Ctrl-C / SIGTERM handler: the command stops and leaves
/// neither a half-written output nor a hidden temporary behind. Outputs already renamed
/// into place are complete and stay.
pub fn remove_temporaries() {
    for p in live().drain(..) {
        if p.is_dir() {
            let _ = std::fs::remove_dir_all(&p);
        } else {
            let _ = std::fs::remove_file(&p);
        }
    }
}

/// One output file a writer produced (a format may need a sidecar).
#[derive(Clone, Debug)]
pub struct OutputFile {
    /// Where it goes.
    pub path: PathBuf,
    /// What it holds.
    pub bytes: Vec<u8>,
}

fn temp_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "out".into());
    let tmp = format!(".{name}.vtz-tmp-{}", std::process::id());
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.join(tmp),
        _ => PathBuf::from(tmp),
    }
}

/// Write all `files`: refuse (before writing anything) when one exists and `force` is off;
/// write each to a temporary file in the same directory, sync it, then rename them all into
/// place. On any failure the temporaries are removed and no output is half-written.
pub fn write_files(files: &[OutputFile], force: bool) -> Result<()> {
    if !force {
        for f in files {
            if f.path.exists() {
                return Err(Error::invalid(format!(
                    "{} exists (use --force to overwrite)",
                    f.path.display()
                )));
            }
        }
    }
    let mut temps: Vec<PathBuf> = Vec::new();
    let cleanup = |temps: &[PathBuf]| {
        for t in temps {
            let _ = std::fs::remove_file(t);
            untrack(t);
        }
    };
    for f in files {
        let tmp = temp_path(&f.path);
        track(&tmp);
        let res = (|| -> std::io::Result<()> {
            let mut file = std::fs::File::create(&tmp)?;
            file.write_all(&f.bytes)?;
            file.sync_all()?;
            Ok(())
        })();
        temps.push(tmp);
        if let Err(e) = res {
            cleanup(&temps);
            return Err(Error::io(format!("writing {}", f.path.display()), e));
        }
    }
    for (f, tmp) in files.iter().zip(&temps) {
        if let Err(e) = std::fs::rename(tmp, &f.path) {
            cleanup(&temps);
            return Err(Error::io(format!("renaming into {}", f.path.display()), e));
        }
        untrack(tmp);
    }
    Ok(())
}

/// Write one file atomically: refuse an existing file unless `force`, write a temporary
/// sibling, sync it, rename it into place; on failure nothing is left half-written.
pub fn write_file(path: &Path, bytes: Vec<u8>, force: bool) -> Result<()> {
    write_files(
        &[OutputFile {
            path: path.to_path_buf(),
            bytes,
        }],
        force,
    )
}

/// A file written in pieces (a tiled `.vtz`, a GeoTIFF band by band), atomically: the
/// pieces go to a temporary sibling that [`PendingFile::commit`] syncs and renames into
/// place; dropped without a commit (an error, a panic), the temporary is removed.
pub struct PendingFile {
    path: PathBuf,
    tmp: PathBuf,
    out: Option<std::io::BufWriter<std::fs::File>>,
}

impl PendingFile {
    /// Refuse an existing `path` unless `force`; create the temporary.
    pub fn create(path: &Path, force: bool) -> Result<PendingFile> {
        if !force && path.exists() {
            return Err(Error::invalid(format!(
                "{} exists (use --force to overwrite)",
                path.display()
            )));
        }
        let tmp = temp_path(path);
        track(&tmp);
        let file = std::fs::File::create(&tmp).map_err(|e| {
            untrack(&tmp);
            Error::io(format!("creating {}", tmp.display()), e)
        })?;
        Ok(PendingFile {
            path: path.to_path_buf(),
            tmp,
            out: Some(std::io::BufWriter::with_capacity(1 << 20, file)),
        })
    }
    /// The temporary file to write (buffered, seekable).
    pub fn writer(&mut self) -> &mut std::io::BufWriter<std::fs::File> {
        self.out.as_mut().expect("present until commit")
    }
    /// Flush, sync and rename into place.
    pub fn commit(mut self) -> Result<()> {
        let out = self.out.take().expect("present until commit");
        let ctx = format!("writing {}", self.path.display());
        let res = out
            .into_inner()
            .map_err(|e| Error::io(&ctx, e.into_error()))
            .and_then(|file| file.sync_all().map_err(|e| Error::io(&ctx, e)))
            .and_then(|()| {
                std::fs::rename(&self.tmp, &self.path)
                    .map_err(|e| Error::io(format!("renaming into {}", self.path.display()), e))
            });
        if res.is_err() {
            let _ = std::fs::remove_file(&self.tmp);
        }
        untrack(&self.tmp);
        res
    }
}

impl Drop for PendingFile {
    fn drop(&mut self) {
        if self.out.is_some() {
            self.out = None;
            let _ = std::fs::remove_file(&self.tmp);
            untrack(&self.tmp);
        }
    }
}
