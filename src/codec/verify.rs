//! Integrity check of a whole file (`vtz verify`): every checksum, every section decoded,
//! and the decodes held against what the file itself claims (mask, value range, each
//! section's stored max error, and the sections against one another).

use crate::container::{ContainerReader, SectionKind};
use crate::error::{Error, Result};
use crate::methods::{self, DecodeJob};
use crate::model::Window;
use std::io::{Read, Seek};

/// What [`crate::Decoder::verify`] checked and found sound.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub struct Verified {
    /// Sections whose checksums were checked (all of them).
    pub sections: usize,
    /// The surface sections decoded in full: (directory index, method name, stored max
    /// error).
    pub surfaces: Vec<(usize, String, f64)>,
    /// Valid samples (from the mask), each checked in every surface.
    pub valid: u64,
    /// Optional sections of types this decoder does not know: checksum only.
    pub unknown: Vec<usize>,
    /// Tiles checked, each as a file of its own (0 for an untiled file; then `valid` counts
    /// each tile's coded samples, margins included, and `surfaces` lists every tile's).
    pub tiles: usize,
    /// A point set (version 3): `valid` counts its points, `surfaces` lists its value
    /// columns (column index, name, stored max error).
    pub point_set: bool,
}

/// Check everything the file says about itself; the first problem is the error.
pub(crate) fn verify<R: Read + Seek>(rd: &mut ContainerReader<R>) -> Result<Verified> {
    let header = rd.header().clone();
    let n = header.samples() as usize;
    let entries = rd.entries().to_vec();
    // Checksums of every section (the header's and the directory's were checked at opening).
    for i in 0..entries.len() {
        rd.read_section(i)?;
    }
    let mask = rd.read_mask()?;
    let valid = mask
        .as_ref()
        .map_or(n, |m| m.iter().filter(|&&b| b).count());
    match (header.range, valid) {
        (None, v) if v > 0 => {
            return Err(Error::corrupt(format!(
                "the header gives no value range, but the mask has {v} valid samples"
            )));
        }
        (Some(_), 0) => {
            return Err(Error::corrupt(
                "the header gives a value range, but the mask has no valid sample",
            ));
        }
        _ => {}
    }
    // The flat regions: decoded (and checked against the mask) here, then written over
    // every surface as a decoder does.
    let flat = rd.read_flat(mask.as_deref())?;
    let method_mask = super::decode::method_mask(mask.as_deref(), flat.as_ref(), n);
    let fill = header.nodata.unwrap_or(f64::NAN);
    let mut surfaces: Vec<(usize, String, f64, Vec<f64>)> = Vec::new();
    let mut unknown = Vec::new();
    for (i, e) in entries.iter().enumerate() {
        let at = |what: String| Error::corrupt(format!("section {i} ({}): {what}", e.name));
        if e.kind == SectionKind::MASK || e.kind == SectionKind::FLAT {
            continue;
        }
        if e.kind == SectionKind::METADATA {
            let p = rd.read_section(i)?;
            let text = std::str::from_utf8(&p).map_err(|_| at("not UTF-8".into()))?;
            serde_json::from_str::<serde_json::Value>(text)
                .map_err(|err| at(format!("not JSON: {err}")))?;
            continue;
        }
        if e.kind == SectionKind::GDAL_METADATA {
            let p = rd.read_section(i)?;
            std::str::from_utf8(&p).map_err(|_| at("not UTF-8".into()))?;
            continue;
        }
        let Some(m) = methods::by_section(e.kind) else {
            unknown.push(i);
            continue;
        };
        let payload = rd.read_section(i)?;
        let job = DecodeJob {
            payload: &payload,
            header: &header,
            mask: method_mask.as_deref().or(mask.as_deref()),
            window: Window::full(header.width as usize, header.height as usize),
            sites: None,
            levels: None,
            threads: 0,
            flat: flat.as_ref(),
            base: None,
            progress: &|_| {},
        };
        let mut data = m
            .decode_full(&job)
            .map_err(|err| err.context(format!("section {i}")))?;
        if data.len() != n {
            return Err(at(format!("decodes to {} samples, not {n}", data.len())));
        }
        if let Some(f) = &flat {
            let (w, h) = (header.width as usize, header.height as usize);
            f.overwrite(&mut data, w, (0, 0, w, h));
        }
        m.describe(&job)?;
        let off = m.id().bound_at;
        let bound = payload
            .get(off..off + 8)
            .map(|b| f64::from_le_bytes(b.try_into().expect("8 bytes")))
            .filter(|b| b.is_finite() && *b >= 0.0)
            .ok_or_else(|| at("no valid stored max error".into()))?;
        let (lo, hi) = header.range.unwrap_or((0.0, 0.0));
        let slack = 1e-9 * (lo.abs() + hi.abs() + bound);
        for (k, &v) in data.iter().enumerate() {
            let ok = mask.as_ref().is_none_or(|m| m[k]);
            if ok && !(v.is_finite() && v >= lo - bound - slack && v <= hi + bound + slack) {
                return Err(at(format!(
                    "sample {k} decodes to {v}, outside the stored range {lo}..{hi} widened by the stored max error {bound}"
                )));
            }
            if !(ok || v == fill || v.is_nan() && fill.is_nan()) {
                return Err(at(format!("nodata sample {k} decodes to {v}")));
            }
        }
        // Two surfaces of one source are within the sum of their bounds of each other.
        for (j, name, b2, other) in &surfaces {
            let tol = bound + b2 + slack;
            let bad = (0..n)
                .find(|&k| mask.as_ref().is_none_or(|m| m[k]) && (data[k] - other[k]).abs() > tol);
            if let Some(k) = bad {
                return Err(at(format!(
                    "sample {k} is {} here and {} in section {j} ({name}): further apart than their stored max errors {bound} + {b2} allow",
                    data[k], other[k]
                )));
            }
        }
        // The method's name, as `--method` and `vtz info` spell it (`sibson`, not `sites`).
        surfaces.push((i, m.name().to_string(), bound, data));
    }
    Ok(Verified {
        sections: entries.len(),
        surfaces: surfaces.into_iter().map(|(i, n, b, _)| (i, n, b)).collect(),
        valid: valid as u64,
        unknown,
        tiles: 0,
        point_set: false,
    })
}

/// [`verify`] for a raster file: an untiled file's one tile is the file, checked as one
/// container; a tiled file's global sections, then every tile's block (its checksum), its
/// sections checked as a file's, and its decode against its index entry (valid count,
/// range, max error).
pub(crate) fn verify_file(rd: &mut crate::container::tiled::RasterReader) -> Result<Verified> {
    if let Some(whole) = rd.whole() {
        return verify(whole);
    }
    for e in rd.sections().to_vec() {
        let p = rd.global_section(e.kind)?.expect("the directory lists it");
        let text = std::str::from_utf8(&p)
            .map_err(|_| Error::corrupt(format!("global {} section: not UTF-8", e.name)))?;
        if e.kind == SectionKind::METADATA {
            serde_json::from_str::<serde_json::Value>(text).map_err(|err| {
                Error::corrupt(format!("global metadata section: not JSON: {err}"))
            })?;
        }
    }
    let grid = rd.grid();
    let mut out = Verified {
        sections: rd.sections().len(),
        surfaces: Vec::new(),
        valid: 0,
        unknown: Vec::new(),
        tiles: rd.tiles().len(),
        point_set: false,
    };
    for k in 0..rd.tiles().len() {
        let name = crate::container::tiled::tile_name(&grid, k);
        let entry = rd.tiles()[k].clone();
        let block = rd.tile_block(k)?;
        let mut trd = rd.opener().open(k, block)?;
        let v = verify(&mut trd).map_err(|e| e.context(&name))?;
        if v.valid != entry.valid {
            return Err(Error::corrupt(format!(
                "{name}: the index gives {} valid samples, the tile has {}",
                entry.valid, v.valid
            )));
        }
        let primary = trd.header().primary as usize;
        if let Some((_, _, b)) = v.surfaces.iter().find(|s| s.0 == primary) {
            if *b != entry.max_error {
                return Err(Error::corrupt(format!(
                    "{name}: the index gives a max error of {}, its section stores {b}",
                    entry.max_error
                )));
            }
        }
        out.sections += v.sections;
        out.valid += v.valid;
        out.surfaces.extend(
            v.surfaces
                .into_iter()
                .map(|(i, n, b)| (k, format!("{name}: section {i} ({n})"), b)),
        );
    }
    Ok(out)
}
