//! Rasters on one grid as one point set (`vtz encode a.tif --band b.tif`): a value column
//! per raster.

use crate::error::{Error, Result};
use crate::model::{PointSet, Raster};
use std::path::PathBuf;

/// A raster and its bands, each with the file it came from, as one point set: a point per
/// sample valid in every raster, at the sample's centre (the first raster's CRS units when
/// it is georeferenced, else column and minus the row), one value column per raster named
/// by its file's stem (a stem seen before gets `_k`, k its place counted from 1), the first
/// raster's CRS. Also returns how many samples are valid in some rasters but not all: a
/// point set holds every column at every point, so they are left out.
///
/// # Errors
/// [`Error::InvalidArgument`] when `bands` is empty or a raster's grid (width × height)
/// differs from the first's (naming both files).
pub fn bands_to_points(bands: &[(PathBuf, Raster)]) -> Result<(PointSet, usize)> {
    let Some((file0, first)) = bands.first() else {
        return Err(Error::invalid("no rasters to turn into points"));
    };
    for (f, r) in bands.iter().skip(1) {
        if (r.width, r.height) != (first.width, first.height) {
            return Err(Error::invalid(format!(
                "{} is {}x{}, {} is {}x{}: bands must have one grid",
                f.display(),
                r.width,
                r.height,
                file0.display(),
                first.width,
                first.height
            )));
        }
    }
    let mut names: Vec<String> = bands
        .iter()
        .map(|(f, _)| {
            f.file_stem()
                .map_or("band".into(), |s| s.to_string_lossy().into_owned())
        })
        .collect();
    for i in 1..names.len() {
        if names[..i].contains(&names[i]) {
            names[i] = format!("{}_{}", names[i], i + 1);
        }
    }
    let (w, h) = (first.width, first.height);
    let mut p = PointSet {
        names,
        values: vec![Vec::new(); bands.len()],
        ..Default::default()
    };
    let g = first.georef.clone();
    let mut dropped = 0usize;
    for i in 0..w * h {
        if !bands.iter().all(|(_, r)| r.is_valid(i)) {
            dropped += bands.iter().any(|(_, r)| r.is_valid(i)) as usize;
            continue;
        }
        let (col, row) = ((i % w) as f64, (i / w) as f64);
        let [x, y] = match &g {
            Some(g) => g.sample_centre(col, row),
            None => [col, -row],
        };
        p.x.push(x);
        p.y.push(y);
        for (c, (_, r)) in bands.iter().enumerate() {
            p.values[c].push(r.data[i]);
        }
    }
    if let Some(g) = &g {
        p.epsg = g.epsg;
        p.wkt = g.wkt.clone();
    }
    Ok((p, dropped))
}
