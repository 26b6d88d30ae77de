//! Scattered elevation points: reading and writing a [`PointSet`] as XYZ/CSV text or LAS/LAZ.
//!
//! The format comes from the extension ([`PointFormat::from_path`]): `.xyz` and `.txt` are
//! whitespace-separated text, `.csv` comma-separated text with a header line (both read any
//! of whitespace, comma or semicolon separators and an optional header: module `xyz`), `.las`
//! ASPRS LAS and `.laz` LASzip-compressed LAS (through the `las` crate: module `las`).
//!
//! Text keeps every number exactly (f64 parsed exactly, written in the shortest form that
//! reads back to the same f64). LAS stores positions and z as integers on a grid of a
//! scale and an offset, so a write may round them: [`WriteReport::note`] says by how much.
//! LAS has no place for further value columns: a point set with more than one column is
//! refused for LAS output.

mod las;
mod xyz;

use crate::error::{Error, Result};
use crate::model::PointSet;
use std::path::Path;

/// The point file formats vtz reads and writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PointFormat {
    /// Whitespace-separated text (`.xyz`, `.txt`): `x y z [more columns]`, header optional.
    Xyz,
    /// Comma-separated text with a header line (`.csv`).
    Csv,
    /// ASPRS LAS (`.las`).
    Las,
    /// LASzip-compressed LAS (`.laz`).
    Laz,
}

impl PointFormat {
    /// The point format of a path by its extension (`.xyz .txt .csv .las .laz`, any case);
    /// `None` for any other extension.
    pub fn from_path(path: &Path) -> Option<Self> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        Some(match ext.as_str() {
            "xyz" | "txt" => PointFormat::Xyz,
            "csv" => PointFormat::Csv,
            "las" => PointFormat::Las,
            "laz" => PointFormat::Laz,
            _ => return None,
        })
    }
}

/// Whether `path`'s extension names a point format (see [`PointFormat::from_path`]).
pub fn is_points_path(path: &Path) -> bool {
    PointFormat::from_path(path).is_some()
}

/// Options for [`read_points`].
#[derive(Clone, Debug, Default)]
pub struct ReadPointsOptions {
    /// LAS/LAZ: keep only points of this ASPRS classification (2 = ground). An error for text.
    pub class: Option<u8>,
    /// Keep only these value columns, in this order, by name (a text file's header names, or
    /// `z`, `v2`, `v3`, … without a header; LAS has only `z`). An unknown name is an error.
    pub columns: Option<Vec<String>>,
}

/// Options for [`write_points`].
#[derive(Clone, Debug, Default)]
pub struct WritePointsOptions {
    /// Replace an existing file.
    pub force: bool,
    /// LAS/LAZ: the grid step of the stored integers for x, y and z (default 0.001, so
    /// millimetres for metres). Ignored by text, which is exact.
    pub scale: Option<f64>,
}

/// What [`write_points`] has to tell the caller.
#[derive(Clone, Debug, Default, PartialEq)]
#[non_exhaustive]
pub struct WriteReport {
    /// Something the caller should print: a LAS/LAZ write that rounded coordinates or z to
    /// the scale's grid says so here, with the largest change. `None` when nothing changed.
    pub note: Option<String>,
}

/// What [`read_points_report`] has to tell the caller.
#[derive(Clone, Debug, Default, PartialEq)]
#[non_exhaustive]
pub struct ReadReport {
    /// Something the caller should print: what the file holds that a point set does not
    /// keep (a LAS/LAZ file's classification, intensity, GPS time, colour). `None` when
    /// nothing is left out.
    pub note: Option<String>,
}

/// Read a point file, choosing the format by extension ([`PointFormat::from_path`]).
///
/// Text is read line by line; LAS/LAZ in batches, never trusting the header's point count
/// for an allocation. Errors name the file (and, for text, the line). A LAS/LAZ class
/// filter that keeps no point is an [`Error::Unmet`] naming the classes present.
pub fn read_points(path: &Path, opts: &ReadPointsOptions) -> Result<PointSet> {
    read_points_report(path, opts).map(|(ps, _)| ps)
}

/// [`read_points`], and what the file holds that the point set does not keep.
pub fn read_points_report(path: &Path, opts: &ReadPointsOptions) -> Result<(PointSet, ReadReport)> {
    let format = format_of(path)?;
    let ctx = path.display().to_string();
    let mut note = None;
    let mut ps = match format {
        PointFormat::Xyz | PointFormat::Csv => {
            if opts.class.is_some() {
                return Err(Error::invalid(format!(
                    "{ctx}: a classification filter applies to LAS/LAZ only; text points have no class"
                )));
            }
            let f = std::fs::File::open(path).map_err(|e| Error::io(&ctx, e))?;
            xyz::read(std::io::BufReader::with_capacity(1 << 16, f))
        }
        PointFormat::Las | PointFormat::Laz => las::read(path, opts.class).map(|(ps, n)| {
            note = n;
            ps
        }),
    }
    .map_err(|e| e.context(&ctx))?;
    if let Some(cols) = &opts.columns {
        select_columns(&mut ps, cols).map_err(|e| e.context(&ctx))?;
    }
    ps.validate().map_err(|e| e.context(&ctx))?;
    Ok((ps, ReadReport { note }))
}

/// Write a point set, choosing the format by extension, atomically (a temporary sibling,
/// then a rename; an existing file only with `opts.force`).
///
/// Text writes every value exactly; `.csv` gets a header line `x,y,<names>`, `.xyz`/`.txt` a
/// header line `x y <names>` only when the names are not the defaults `z`, `v2`, `v3`, ….
/// LAS/LAZ refuses more than one value column ([`Error::Unsupported`]) and rounds to the
/// scale's grid, reported in the returned [`WriteReport`].
pub fn write_points(path: &Path, ps: &PointSet, opts: &WritePointsOptions) -> Result<WriteReport> {
    ps.validate()?;
    let format = format_of(path)?;
    let ctx = path.display().to_string();
    match format {
        PointFormat::Xyz | PointFormat::Csv => {
            xyz::write(path, ps, format == PointFormat::Csv, opts.force)?;
            Ok(WriteReport::default())
        }
        PointFormat::Las | PointFormat::Laz => {
            // Refuse an existing file before the work (`write_file` checks again).
            if !opts.force && path.exists() {
                return Err(Error::invalid(format!(
                    "{} exists (use --force to overwrite)",
                    path.display()
                )));
            }
            let scale = opts.scale.unwrap_or(las::DEFAULT_SCALE);
            let (bytes, note) =
                las::encode(ps, format == PointFormat::Laz, scale).map_err(|e| e.context(&ctx))?;
            super::write_file(path, bytes, opts.force)?;
            Ok(WriteReport { note })
        }
    }
}

fn format_of(path: &Path) -> Result<PointFormat> {
    PointFormat::from_path(path).ok_or_else(|| {
        Error::invalid(format!(
            "cannot tell the point format of {} from its extension (known: xyz, txt, csv, las, laz)",
            path.display()
        ))
    })
}

/// Keep the value columns named in `cols`, in that order.
fn select_columns(ps: &mut PointSet, cols: &[String]) -> Result<()> {
    if cols.is_empty() {
        return Err(Error::invalid("no value column selected"));
    }
    let mut names = Vec::with_capacity(cols.len());
    let mut values = Vec::with_capacity(cols.len());
    for want in cols {
        let Some(c) = ps.names.iter().position(|n| n == want) else {
            return Err(Error::invalid(format!(
                "no value column '{want}' (the file has: {})",
                ps.names.join(", ")
            )));
        };
        names.push(ps.names[c].clone());
        values.push(ps.values[c].clone());
    }
    ps.names = names;
    ps.values = values;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn formats_by_extension() {
        let f = |p: &str| PointFormat::from_path(Path::new(p));
        assert_eq!(f("a.xyz"), Some(PointFormat::Xyz));
        assert_eq!(f("dir/a.TXT"), Some(PointFormat::Xyz));
        assert_eq!(f("a.Csv"), Some(PointFormat::Csv));
        assert_eq!(f("a.LAS"), Some(PointFormat::Las));
        assert_eq!(f("a.laz"), Some(PointFormat::Laz));
        assert_eq!(f("a.tif"), None);
        assert_eq!(f("laz"), None);
        assert!(is_points_path(Path::new("x.laz")));
        assert!(!is_points_path(Path::new("x.vtz")));
    }

    #[test]
    fn columns_are_selected_by_name() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.csv");
        std::fs::write(&p, "x,y,z,sigma\n1,2,3,0.5\n").unwrap();
        let o = ReadPointsOptions {
            columns: Some(vec!["sigma".into()]),
            ..Default::default()
        };
        let ps = read_points(&p, &o).unwrap();
        assert_eq!(ps.names, ["sigma"]);
        assert_eq!(ps.values, [[0.5]]);
        let o = ReadPointsOptions {
            columns: Some(vec!["nope".into()]),
            ..Default::default()
        };
        let e = read_points(&p, &o).unwrap_err().to_string();
        assert!(e.contains("nope") && e.contains("a.csv"), "{e}");
        // A class filter makes no sense for text.
        let o = ReadPointsOptions {
            class: Some(2),
            ..Default::default()
        };
        assert!(matches!(
            read_points(&p, &o),
            Err(Error::InvalidArgument { .. })
        ));
    }

    #[test]
    fn writes_are_atomic_and_refuse_existing_files() {
        let dir = tempfile::tempdir().unwrap();
        let ps = PointSet::from_xyz(vec![1.0], vec![2.0], vec![3.0]).unwrap();
        for name in ["a.xyz", "a.csv", "a.las", "a.laz"] {
            let p = dir.path().join(name);
            write_points(&p, &ps, &Default::default()).unwrap();
            let e = write_points(&p, &ps, &Default::default()).unwrap_err();
            assert!(e.to_string().contains("exists"), "{e}");
            let force = WritePointsOptions {
                force: true,
                ..Default::default()
            };
            write_points(&p, &ps, &force).unwrap();
            assert_eq!(read_points(&p, &Default::default()).unwrap(), ps, "{name}");
        }
        // No temporaries left behind.
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 4);
        let e = write_points(&dir.path().join("a.tif"), &ps, &Default::default()).unwrap_err();
        assert!(matches!(e, Error::InvalidArgument { .. }));
    }
}
