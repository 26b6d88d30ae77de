//! Container version 3, a point set: magic, version, the point-set header (counts, the
//! position grid, the value columns, the CRS), then the same checksummed section directory
//! as version 1 (spec/FORMAT.md, "Version 3: point sets").

use super::bytes::{ByteReader, PutLe};
use super::{
    FileStart, Limits, Section, SectionEntry, SectionKind, VERSION_POINTS, read_directory,
};
use crate::error::{Error, Result};
use std::io::Cursor;

/// Section type: the distinct positions and their multiplicities.
pub const POSITIONS: SectionKind = SectionKind(10);
/// Section type: the point-set sites (levels, values) and the values of shared positions.
pub const POINT_SITES: SectionKind = SectionKind(11);
/// Most value columns a point set may have.
pub const MAX_COLUMNS: usize = 256;
/// Positions are integers in `[0, MAX_EXTENT)` per axis (steps of the resolution).
pub const MAX_EXTENT: u32 = (1 << 24) + 1;
const MAX_NAME: usize = 255;
const MAX_WKT: usize = 1 << 16;

/// One value column: its name, height lattice, bound and the errors the encoder measured.
#[derive(Clone, Debug, PartialEq)]
pub struct ColumnHeader {
    /// The column's name (`z`, or the input's header name).
    pub name: String,
    /// Site values are `offset + step · code`.
    pub step: f64,
    /// The lattice's offset.
    pub offset: f64,
    /// The bound the encoder was asked to hold at every point.
    pub bound: f64,
    /// The largest error the encoder measured at the input points.
    pub max_error: f64,
    /// The RMSE the encoder measured at the input points.
    pub rmse: f64,
}

/// The point-set header.
#[derive(Clone, Debug, PartialEq)]
pub struct PointsHeader {
    /// Number of points (with repeats at shared positions).
    pub points: u64,
    /// Number of distinct positions.
    pub positions: u64,
    /// Grid step of the positions, in the CRS's units.
    pub resolution: f64,
    /// The grid's origin in steps: position (i, j) is `((kx0 + i)·r, (ky0 + j)·r)`.
    pub origin: [i64; 2],
    /// Positions lie in `[0, extent[0]) × [0, extent[1])`.
    pub extent: [u32; 2],
    /// The value columns.
    pub columns: Vec<ColumnHeader>,
    /// EPSG code of the CRS, when known.
    pub epsg: Option<u32>,
    /// WKT of the CRS, when known.
    pub wkt: Option<String>,
}

impl PointsHeader {
    fn to_bytes(&self) -> Vec<u8> {
        let mut b = Vec::new();
        b.put_u64(self.points);
        b.put_u64(self.positions);
        b.put_u16(self.columns.len() as u16);
        b.put_u16(0);
        b.put_f64(self.resolution);
        b.put_u64(self.origin[0] as u64);
        b.put_u64(self.origin[1] as u64);
        b.put_u32(self.extent[0]);
        b.put_u32(self.extent[1]);
        for c in &self.columns {
            b.put_u8(c.name.len() as u8);
            b.extend_from_slice(c.name.as_bytes());
            for v in [c.step, c.offset, c.bound, c.max_error, c.rmse] {
                b.put_f64(v);
            }
        }
        b.put_u32(self.epsg.unwrap_or(0));
        let wkt = self.wkt.as_deref().unwrap_or("");
        b.put_u32(wkt.len() as u32);
        b.extend_from_slice(wkt.as_bytes());
        b
    }

    fn from_bytes(body: &[u8], limits: &Limits) -> Result<PointsHeader> {
        let mut r = ByteReader::new(body, "point-set header");
        let points = r.u64("point count")?;
        let positions = r.u64("position count")?;
        let ncol = r.u16("column count")? as usize;
        if r.u16("reserved")? != 0 {
            return Err(r.corrupt("reserved field is not zero"));
        }
        let resolution = r.finite_f64("resolution")?;
        let origin = [r.u64("origin x")? as i64, r.u64("origin y")? as i64];
        let extent = [r.u32("extent x")?, r.u32("extent y")?];
        if resolution <= 0.0 {
            return Err(r.corrupt("resolution is not positive"));
        }
        for o in origin {
            if !(o as f64 * resolution).is_finite() || o.unsigned_abs() > 1 << 60 {
                return Err(r.corrupt("origin is out of range"));
            }
        }
        if extent.iter().any(|&e| e == 0 || e > MAX_EXTENT) {
            return Err(r.corrupt(format!("extent {extent:?} is out of range")));
        }
        if positions > points || (points > 0) != (positions > 0) {
            return Err(r.corrupt("position count does not fit the point count"));
        }
        if positions > extent[0] as u64 * extent[1] as u64 {
            return Err(r.corrupt("more positions than the grid holds"));
        }
        if ncol == 0 || ncol > MAX_COLUMNS {
            return Err(r.corrupt(format!("column count {ncol} is out of range")));
        }
        // The decoder holds a value per point and column (and a surface per column over
        // the sites): the sample limit bounds points × columns.
        if points.saturating_mul(ncol as u64) > limits.max_samples {
            return Err(Error::limit(format!(
                "point set of {points} points × {ncol} columns is over the limit of {} values",
                limits.max_samples
            )));
        }
        let mut columns = Vec::with_capacity(ncol);
        for _ in 0..ncol {
            let n = r.u8("column name length")? as usize;
            let name = std::str::from_utf8(r.take(n, "column name")?)
                .map_err(|_| r.corrupt("column name is not UTF-8"))?
                .to_string();
            let step = r.finite_f64("column step")?;
            let offset = r.finite_f64("column offset")?;
            let bound = r.finite_f64("column bound")?;
            let max_error = r.finite_f64("column max error")?;
            let rmse = r.finite_f64("column rmse")?;
            if step <= 0.0 || bound < 0.0 || max_error < 0.0 || rmse < 0.0 {
                return Err(r.corrupt("column lattice or errors out of range"));
            }
            columns.push(ColumnHeader {
                name,
                step,
                offset,
                bound,
                max_error,
                rmse,
            });
        }
        let epsg = Some(r.u32("epsg")?).filter(|&e| e != 0);
        let n = r.u32("wkt length")? as usize;
        if n > MAX_WKT {
            return Err(r.corrupt("wkt is over the limit of 64 KiB"));
        }
        let wkt =
            std::str::from_utf8(r.take(n, "wkt")?).map_err(|_| r.corrupt("wkt is not UTF-8"))?;
        let wkt = (!wkt.is_empty()).then(|| wkt.to_string());
        r.finish()?;
        Ok(PointsHeader {
            points,
            positions,
            resolution,
            origin,
            extent,
            columns,
            epsg,
            wkt,
        })
    }

    /// Check what a writer must not produce (the reader checks the same on reading).
    fn check(&self) -> Result<()> {
        if self.columns.is_empty() || self.columns.len() > MAX_COLUMNS {
            return Err(Error::limit(format!(
                "a point set holds 1 to {MAX_COLUMNS} value columns"
            )));
        }
        for c in &self.columns {
            if c.name.len() > MAX_NAME {
                return Err(Error::invalid(format!(
                    "column name '{}' is over {MAX_NAME} bytes",
                    c.name
                )));
            }
        }
        if self.wkt.as_ref().is_some_and(|w| w.len() > MAX_WKT) {
            return Err(Error::invalid("CRS WKT is over 64 KiB"));
        }
        Ok(())
    }
}

/// Serialize a point-set file.
pub fn write_points(header: &PointsHeader, sections: &[Section]) -> Result<Vec<u8>> {
    header.check()?;
    let body = header.to_bytes();
    let mut out = Vec::new();
    FileStart::write(&mut out, VERSION_POINTS, &body);
    super::directory_bytes(&mut out, sections);
    Ok(out)
}

/// A point-set file read from memory: its header and directory (framing checked).
pub struct PointsFile<'a> {
    bytes: &'a [u8],
    /// The header.
    pub header: PointsHeader,
    /// The sections.
    pub entries: Vec<SectionEntry>,
}

fn names(k: SectionKind) -> Option<&'static str> {
    match k {
        POSITIONS => Some("positions"),
        POINT_SITES => Some("point-sites"),
        _ => None,
    }
}

impl<'a> PointsFile<'a> {
    /// Check the framing of a whole file: its start ([`FileStart`]), the point-set header,
    /// the directory.
    pub fn read(bytes: &'a [u8], limits: Limits) -> Result<PointsFile<'a>> {
        let mut cur = Cursor::new(bytes);
        let start = FileStart::read(&mut cur, |version| {
            if version != VERSION_POINTS {
                return Err(Error::unsupported(format!(
                    "vtz format version {version} is not a point set"
                )));
            }
            Ok(())
        })?;
        let header = PointsHeader::from_bytes(&start.body, &limits)?;
        let entries = read_directory(&mut cur, start.end(), start.file_len, &limits, names, "")?;
        Ok(PointsFile {
            bytes,
            header,
            entries,
        })
    }

    /// The payload of the first section of type `kind` (checksum verified), if any.
    pub fn section(&self, kind: SectionKind) -> Result<Option<&'a [u8]>> {
        match self.entries.iter().position(|e| e.kind == kind) {
            Some(i) => self.payload(i).map(Some),
            None => Ok(None),
        }
    }

    /// The payload of directory entry `i` (checksum verified).
    pub fn payload(&self, i: usize) -> Result<&'a [u8]> {
        let e = &self.entries[i];
        let p = &self.bytes[e.offset as usize..(e.offset + e.length) as usize];
        if !super::checksum_ok(crc32fast::hash(p), &e.crc.to_le_bytes()) {
            return Err(Error::corrupt(format!(
                "{} section: checksum mismatch",
                e.name
            )));
        }
        Ok(p)
    }

    /// The payload of a section the file must have.
    pub fn required(&self, kind: SectionKind) -> Result<&'a [u8]> {
        self.section(kind)?.ok_or_else(|| {
            Error::corrupt(format!(
                "point set has no {} section",
                names(kind).unwrap_or("required")
            ))
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Vec<u8> {
        let h = PointsHeader {
            points: 3,
            positions: 2,
            resolution: 0.01,
            origin: [-5, 7],
            extent: [10, 20],
            columns: vec![ColumnHeader {
                name: "z".into(),
                step: 0.5,
                offset: 1.0,
                bound: 0.5,
                max_error: 0.25,
                rmse: 0.1,
            }],
            epsg: Some(28992),
            wkt: None,
        };
        let s = [Section {
            kind: POSITIONS,
            flags: super::super::SF_REQUIRED,
            payload: vec![1, 2, 3],
        }];
        write_points(&h, &s).unwrap()
    }

    #[test]
    fn round_trip_and_every_prefix_errors() {
        let b = sample();
        let f = PointsFile::read(&b, Limits::default()).unwrap();
        assert_eq!(f.header.origin, [-5, 7]);
        assert_eq!(f.header.epsg, Some(28992));
        assert_eq!(f.required(POSITIONS).unwrap(), &[1, 2, 3]);
        assert!(f.required(POINT_SITES).is_err());
        for n in 0..b.len() {
            assert!(
                PointsFile::read(&b[..n], Limits::default()).is_err(),
                "prefix {n}"
            );
        }
    }
}
