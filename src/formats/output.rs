//! Safe output: write every file to a temporary sibling, then rename it into place.

use crate::error::{Error, Result};
use std::io::Write;
use std::path::{Path, PathBuf};

/// One output file a writer produced (a format may need a sidecar).
#[derive(Clone, Debug)]
pub struct OutputFile {
    pub path: PathBuf,
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
        }
    };
    for f in files {
        let tmp = temp_path(&f.path);
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
        let file = std::fs::File::create(&tmp)
            .map_err(|e| Error::io(format!("creating {}", tmp.display()), e))?;
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
        let file = out
            .into_inner()
            .map_err(|e| Error::io(&ctx, e.into_error()))?;
        file.sync_all().map_err(|e| Error::io(&ctx, e))?;
        drop(file);
        std::fs::rename(&self.tmp, &self.path)
            .map_err(|e| Error::io(format!("renaming into {}", self.path.display()), e))
    }
}

impl Drop for PendingFile {
    fn drop(&mut self) {
        if self.out.is_some() {
            self.out = None;
            let _ = std::fs::remove_file(&self.tmp);
        }
    }
}
