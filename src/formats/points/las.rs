//! LAS and LAZ points through the `las` crate: positions and z (one value column `z`), an
//! optional classification filter, the CRS from the WKT or GeoTIFF-key VLRs; written on a
//! scale's integer grid with the CRS as a WKT VLR.
//!
//! Reading trusts no count of the header for an allocation: points come in batches and the
//! columns grow as they arrive (with a capped reserve). Before the `las` crate sees a file,
//! the sizes it would allocate by (the point records of a LAS, the extended VLR, a LAZ chunk
//! table) are checked against the file's length.
//!
//! Writing: LAS 1.2, point format 0, without a CRS; LAS 1.4, point format 6 with the OGC WKT
//! VLR (user `LASF_Projection`, record 2112) and the global-encoding WKT bit, when the point
//! set has a WKT or an EPSG code the `crs` table knows. The offsets are the minima rounded
//! down to a multiple of 1000 (or of the scale, when coarser than 1000).

use crate::error::{Error, Result};
use crate::formats::crs;
use crate::model::PointSet;
use std::io::{BufReader, Read, Seek, SeekFrom};
use std::path::Path;

/// The default grid step of stored coordinates (millimetres for metres).
pub(super) const DEFAULT_SCALE: f64 = 0.001;
/// Points decoded at once.
const BATCH: u64 = 1 << 16;
/// At most this many points are reserved up front on the header's word.
const MAX_RESERVE: u64 = 1 << 22;

/// GeoTIFF keys: ProjectedCSTypeGeoKey and GeographicTypeGeoKey.
const PROJECTED_KEY: u16 = 3072;
const GEOGRAPHIC_KEY: u16 = 2048;

fn las_err(e: ::las::Error) -> Error {
    match e {
        ::las::Error::Io(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => {
            Error::corrupt("truncated: the file ends before the header's points do")
        }
        ::las::Error::Io(e) => Error::io("reading", e),
        e => Error::corrupt(e.to_string()),
    }
}

fn read_u32_at<R: Read + Seek>(f: &mut R, pos: u64) -> std::io::Result<u32> {
    let mut b = [0u8; 4];
    f.seek(SeekFrom::Start(pos))?;
    f.read_exact(&mut b)?;
    Ok(u32::from_le_bytes(b))
}

/// Check what the `las` crate would allocate by against the file's length `len`.
fn precheck<R: Read + Seek>(f: &mut R, len: u64) -> Result<()> {
    let io = |e: std::io::Error| match e.kind() {
        std::io::ErrorKind::UnexpectedEof => Error::corrupt("truncated header"),
        _ => Error::io("reading the header", e),
    };
    let raw = ::las::raw::Header::read_from(&mut *f).map_err(las_err)?;
    let n = raw
        .large_file
        .map_or(u64::from(raw.number_of_point_records), |l| {
            l.number_of_point_records
        });
    let start = u64::from(raw.offset_to_point_data);
    let compressed = raw.point_data_record_format & 0x80 != 0;
    if !compressed {
        let need = n
            .checked_mul(u64::from(raw.point_data_record_length))
            .and_then(|b| b.checked_add(start));
        if need.is_none_or(|need| need > len) {
            return Err(Error::corrupt(format!(
                "the header declares {n} points of {} bytes from byte {start}, more than the file's {len} bytes",
                raw.point_data_record_length
            )));
        }
    } else if start.checked_add(8).is_some_and(|e| e <= len) {
        // LAZ: the chunk table's offset, then at that offset its version and chunk count.
        f.seek(SeekFrom::Start(start)).map_err(io)?;
        let mut b = [0u8; 8];
        f.read_exact(&mut b).map_err(io)?;
        let table = i64::from_le_bytes(b);
        if let Ok(table) = u64::try_from(table) {
            if table.checked_add(8).is_some_and(|e| e <= len) {
                let chunks = read_u32_at(f, table + 4).map_err(io)?;
                if u64::from(chunks) > len {
                    return Err(Error::corrupt(format!(
                        "the LAZ chunk table declares {chunks} chunks in a file of {len} bytes"
                    )));
                }
            }
        }
    }
    if let Some(evlr) = raw.evlr {
        if evlr.number_of_evlrs > 0 {
            // The record length after the EVLR's 60-byte header is a u64 at byte 20.
            let pos = evlr.start_of_first_evlr;
            let mut b = [0u8; 8];
            let ok = pos.checked_add(60).is_some_and(|e| e <= len)
                && f.seek(SeekFrom::Start(pos + 20)).is_ok()
                && f.read_exact(&mut b).is_ok()
                && u64::from_le_bytes(b) <= len - pos - 60;
            if !ok {
                return Err(Error::corrupt(
                    "the extended VLR does not fit in the file".to_string(),
                ));
            }
        }
    }
    f.seek(SeekFrom::Start(0)).map_err(io)?;
    Ok(())
}

/// The CRS of a LAS header: the WKT VLR's text, and the EPSG code of the GeoTIFF keys (a
/// projected code first, else a geographic one), else of the WKT's root.
fn crs_of(h: &::las::Header) -> (Option<u32>, Option<String>) {
    let wkt = h.get_wkt_crs_bytes().and_then(|b| {
        let s = String::from_utf8_lossy(b);
        let s = s.trim_matches(|c: char| c == '\0' || c.is_whitespace());
        (!s.is_empty()).then(|| s.to_string())
    });
    let key = |id: u16| {
        let keys = h.get_geotiff_crs().ok().flatten()?;
        keys.entries.iter().find_map(|e| match e.data {
            ::las::crs::GeoTiffData::U16(v) if e.id == id && (1024..=32766).contains(&v) => {
                Some(u32::from(v))
            }
            _ => None,
        })
    };
    let epsg = key(PROJECTED_KEY)
        .or_else(|| key(GEOGRAPHIC_KEY))
        .or_else(|| wkt.as_deref().and_then(crs::epsg_of_wkt));
    (epsg, wkt)
}

/// Read a LAS or LAZ file: x, y and z of every point (of class `class` when given), and a
/// note naming what a point set does not keep (the classification, intensity, GPS time,
/// colour of the point format), `None` when the file holds nothing beyond x, y and z.
/// A class filter that keeps no point is an [`Error::Unmet`] naming the classes present.
pub(super) fn read(path: &Path, class: Option<u8>) -> Result<(PointSet, Option<String>)> {
    let file = std::fs::File::open(path).map_err(|e| Error::io("opening", e))?;
    let len = file
        .metadata()
        .map_err(|e| Error::io("reading the file's length", e))?
        .len();
    let mut r = BufReader::with_capacity(1 << 16, file);
    precheck(&mut r, len)?;
    let mut reader = ::las::Reader::new(r).map_err(las_err)?;
    let header = reader.header();
    let (epsg, wkt) = crs_of(header);
    let format = *header.point_format();
    let declared = header.number_of_points();
    let extra = (format.extra_bytes > 0).then(|| extra_bytes_note(header, format.extra_bytes));
    let reserve = if class.is_some() {
        0
    } else {
        declared.min(MAX_RESERVE) as usize
    };
    let mut x = Vec::with_capacity(reserve);
    let mut y = Vec::with_capacity(reserve);
    let mut z = Vec::with_capacity(reserve);
    // Points per classification (all points, before the filter), and whether any has an
    // intensity: what the note says is not kept.
    let mut classes = [0u64; 256];
    let mut intensity = false;
    let mut batch = ::las::PointDataBuilder::new().for_header(header).build();
    loop {
        let got = reader.fill_points(BATCH, &mut batch).map_err(las_err)?;
        if got == 0 {
            break;
        }
        for k in batch.classification() {
            classes[k as usize] += 1;
        }
        intensity |= batch.intensity().any(|i| i != 0);
        match class {
            None => {
                x.extend(batch.x());
                y.extend(batch.y());
                z.extend(batch.z());
            }
            Some(c) => {
                let keep = batch.classification().map(|k| k == c);
                for (keep, ((px, py), pz)) in keep.zip(batch.x().zip(batch.y()).zip(batch.z())) {
                    if keep {
                        x.push(px);
                        y.push(py);
                        z.push(pz);
                    }
                }
            }
        }
    }
    let present: Vec<String> = (0..256)
        .filter(|&k| classes[k] > 0)
        .map(|k| k.to_string())
        .collect();
    if let Some(c) = class.filter(|_| x.is_empty()) {
        let have = if present.is_empty() {
            "the file has no points".to_string()
        } else {
            format!("classes present: {}", present.join(", "))
        };
        return Err(Error::unmet(format!("no points of class {c} ({have})")));
    }
    let mut dropped = Vec::new();
    if classes[1..].iter().any(|&n| n > 0) {
        dropped.push(match class {
            Some(c) => format!("classification (class {c})"),
            None => format!("classification (classes {})", present.join(", ")),
        });
    }
    if intensity {
        dropped.push("intensity".to_string());
    }
    if format.has_gps_time {
        dropped.push("GPS time".to_string());
    }
    if format.has_color {
        dropped.push("colour".to_string());
    }
    if format.has_nir {
        dropped.push("NIR".to_string());
    }
    dropped.extend(extra);
    let note = (!dropped.is_empty()).then(|| {
        let n = format.to_u8().map_or("?".to_string(), |n| n.to_string());
        format!(
            "a point set keeps x, y and z only: the {} of LAS point format {n} are not kept \
             (a LAS/LAZ decoded from it has point format 0, or 6 with a CRS, and class 0)",
            dropped.join(", ")
        )
    });
    let mut ps = PointSet::from_xyz(x, y, z)?;
    ps.epsg = epsg;
    ps.wkt = wkt;
    Ok((ps, note))
}

/// What the extra bytes of each point hold, for the note: the attributes the Extra Bytes
/// VLR (LASF_Spec, record 4: 192 bytes per attribute, its name in bytes 4..36) names, else
/// their count.
fn extra_bytes_note(header: &::las::Header, n: u16) -> String {
    let names: Vec<String> = header
        .vlrs()
        .iter()
        .chain(header.evlrs())
        .filter(|v| v.user_id.trim_end_matches('\0') == "LASF_Spec" && v.record_id == 4)
        .flat_map(|v| v.data.chunks_exact(192))
        .map(|d| {
            let name = &d[4..36];
            let end = name.iter().position(|&b| b == 0).unwrap_or(name.len());
            String::from_utf8_lossy(&name[..end]).trim().to_string()
        })
        .filter(|s| !s.is_empty())
        .collect();
    if names.is_empty() {
        format!("{n} extra bytes per point")
    } else {
        format!(
            "extra-bytes attribute{} {} ({n} bytes per point)",
            if names.len() == 1 { "" } else { "s" },
            names.join(", ")
        )
    }
}

/// The offset of one axis: the minimum rounded down to a multiple of 1000 (or of `scale`,
/// when coarser), so stored integers start near 0.
fn offset_of(min: f64, scale: f64) -> f64 {
    let step = scale.max(1000.0);
    (min / step).floor() * step
}

/// Encode `ps` (one value column) as LAS or LAZ bytes on a grid of `scale`, and a note when
/// anything was rounded.
pub(super) fn encode(
    ps: &PointSet,
    compressed: bool,
    scale: f64,
) -> Result<(Vec<u8>, Option<String>)> {
    if !(scale.is_finite() && scale > 0.0) {
        return Err(Error::invalid(format!(
            "the LAS scale must be a positive number, not {scale}"
        )));
    }
    if ps.columns() != 1 {
        return Err(Error::unsupported(format!(
            "LAS/LAZ stores one value per point (z); this point set has {} columns ({}): \
             write text (.xyz, .csv) or select one column",
            ps.columns(),
            ps.names.join(", ")
        )));
    }
    let z = &ps.values[0];
    let b = ps.bounds().unwrap_or([0.0; 4]);
    let (zmin, zmax) = z
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
            (lo.min(v), hi.max(v))
        });
    let (zmin, zmax) = if z.is_empty() {
        (0.0, 0.0)
    } else {
        (zmin, zmax)
    };
    let mut transforms = ::las::Vector {
        x: ::las::Transform { scale, offset: 0.0 },
        y: ::las::Transform { scale, offset: 0.0 },
        z: ::las::Transform { scale, offset: 0.0 },
    };
    for (t, lo, hi, axis) in [
        (&mut transforms.x, b[0], b[2], "x"),
        (&mut transforms.y, b[1], b[3], "y"),
        (&mut transforms.z, zmin, zmax, "z"),
    ] {
        t.offset = offset_of(lo, scale);
        let top = ((hi - t.offset) / scale).round();
        if top > f64::from(i32::MAX) {
            return Err(Error::invalid(format!(
                "{axis} spans {lo} to {hi}, more than LAS's 32-bit integers hold at a scale of {scale}: use a coarser scale"
            )));
        }
    }
    let wkt: Option<String> = ps
        .wkt
        .clone()
        .or_else(|| ps.epsg.and_then(crs::wkt_of_epsg).map(str::to_string));
    let mut builder = ::las::Builder::from(if wkt.is_some() { (1, 4) } else { (1, 2) });
    builder.point_format = ::las::point::Format::new(if wkt.is_some() { 6 } else { 0 })
        .map_err(|e| Error::invalid(e.to_string()))?;
    builder.point_format.is_compressed = compressed;
    builder.transforms = transforms;
    builder.generating_software = "vtz".into();
    let mut header = builder
        .into_header()
        .map_err(|e| Error::invalid(format!("LAS header: {e}")))?;
    if let Some(w) = &wkt {
        // The WKT VLR is a null-terminated string; the crate sets the WKT bit.
        let mut bytes = w.as_bytes().to_vec();
        bytes.push(0);
        header
            .set_wkt_crs(bytes)
            .map_err(|e| Error::invalid(format!("LAS WKT VLR: {e}")))?;
    }
    let gps_time = wkt.is_some().then_some(0.0);
    let enc = |e: ::las::Error| Error::invalid(format!("LAS encoding: {e}"));
    let mut writer = ::las::Writer::new(std::io::Cursor::new(Vec::new()), header).map_err(enc)?;
    let (mut dxy, mut dz) = (0.0f64, 0.0f64);
    for ((&x, &y), &zi) in ps.x.iter().zip(&ps.y).zip(z) {
        let stored = |t: &::las::Transform, v: f64| t.inverse(v).map(|n| t.direct(n));
        let (sx, sy, sz) = (
            stored(&transforms.x, x).map_err(enc)?,
            stored(&transforms.y, y).map_err(enc)?,
            stored(&transforms.z, zi).map_err(enc)?,
        );
        dxy = dxy.max((sx - x).abs()).max((sy - y).abs());
        dz = dz.max((sz - zi).abs());
        let p = ::las::Point {
            x,
            y,
            z: zi,
            return_number: 1,
            number_of_returns: 1,
            gps_time,
            ..Default::default()
        };
        writer.write_point(p).map_err(enc)?;
    }
    let bytes = writer.into_inner().map_err(enc)?.into_inner();
    let num = crate::metrics::num;
    let note = (dxy > 0.0 || dz > 0.0).then(|| {
        format!(
            "LAS stores coordinates on a grid of {}: z rounded by up to {}, x and y by up to {}",
            num(scale),
            num(dz),
            num(dxy)
        )
    });
    Ok((bytes, note))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::formats::points::{
        ReadPointsOptions, WritePointsOptions, read_points, write_points,
    };

    fn cloud() -> PointSet {
        let n = 1000;
        let x = (0..n)
            .map(|i| 85000.0 + i as f64 * 0.37 + 0.00012)
            .collect();
        let y = (0..n)
            .map(|i| 446000.0 + (i * 7 % 13) as f64 * 1.1)
            .collect();
        let z = (0..n)
            .map(|i| -2.5 + (i as f64 * 0.731).sin() * 10.0)
            .collect();
        PointSet::from_xyz(x, y, z).unwrap()
    }

    fn within(a: &PointSet, b: &PointSet, tol: f64) {
        assert_eq!(a.len(), b.len());
        for i in 0..a.len() {
            assert!((a.x[i] - b.x[i]).abs() <= tol, "x {i}");
            assert!((a.y[i] - b.y[i]).abs() <= tol, "y {i}");
            assert!((a.values[0][i] - b.values[0][i]).abs() <= tol, "z {i}");
        }
    }

    #[test]
    fn las_and_laz_round_trip_within_the_scale() {
        let dir = tempfile::tempdir().unwrap();
        let ps = cloud();
        for (name, scale) in [("a.las", None), ("a.laz", None), ("b.laz", Some(0.01))] {
            let p = dir.path().join(name);
            let o = WritePointsOptions {
                scale,
                ..Default::default()
            };
            let report = write_points(&p, &ps, &o).unwrap();
            let s = scale.unwrap_or(DEFAULT_SCALE);
            let note = report.note.expect("rounded, so said");
            assert!(note.contains("z rounded by up to"), "{note}");
            let back = read_points(&p, &Default::default()).unwrap();
            assert_eq!(back.names, ["z"]);
            assert_eq!((back.epsg, back.wkt.as_deref()), (None, None));
            within(&back, &ps, s * 0.5 * (1.0 + 1e-9));
            // What is on the grid already is kept exactly, with no note.
            let p2 = dir.path().join(format!("again_{name}"));
            let r2 = write_points(&p2, &back, &o).unwrap();
            assert_eq!(r2.note, None, "{name}");
            assert_eq!(read_points(&p2, &Default::default()).unwrap(), back);
        }
    }

    #[test]
    fn the_crs_goes_into_the_wkt_vlr() {
        let dir = tempfile::tempdir().unwrap();
        let mut ps = cloud();
        ps.epsg = Some(28992);
        for name in ["crs.las", "crs.laz"] {
            let p = dir.path().join(name);
            write_points(&p, &ps, &Default::default()).unwrap();
            let back = read_points(&p, &Default::default()).unwrap();
            assert_eq!(back.epsg, Some(28992), "{name}");
            let wkt = back.wkt.expect("WKT VLR");
            assert!(wkt.contains("Amersfoort"), "{wkt}");
            let r = ::las::Reader::from_path(&p).unwrap();
            assert!(r.header().has_wkt_crs());
            assert_eq!(r.header().point_format().to_u8().unwrap(), 6);
        }
    }

    #[test]
    fn class_filter_keeps_one_class() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("classes.laz");
        let mut b = ::las::Builder::from((1, 2));
        b.point_format = ::las::point::Format::new(1).unwrap();
        b.point_format.is_compressed = true;
        let mut w = ::las::Writer::from_path(&p, b.into_header().unwrap()).unwrap();
        for i in 0..100u8 {
            w.write_point(::las::Point {
                x: f64::from(i),
                y: 1.0,
                z: f64::from(i) / 2.0,
                classification: ::las::point::Classification::new(i % 7).unwrap(),
                gps_time: Some(0.0),
                ..Default::default()
            })
            .unwrap();
        }
        w.close().unwrap();
        drop(w);
        let ground = ReadPointsOptions {
            class: Some(2),
            ..Default::default()
        };
        let ps = read_points(&p, &ground).unwrap();
        let want: Vec<f64> = (0..100u8).filter(|i| i % 7 == 2).map(f64::from).collect();
        assert_eq!(ps.x, want);
        assert_eq!(
            ps.values[0],
            want.iter().map(|v| v / 2.0).collect::<Vec<_>>()
        );
        assert_eq!(read_points(&p, &Default::default()).unwrap().len(), 100);
    }

    /// Extra-bytes attributes are dropped like the rest, and the note names them (from the
    /// Extra Bytes VLR), or counts their bytes when no VLR names them.
    #[test]
    fn the_note_names_dropped_extra_bytes() {
        let dir = tempfile::tempdir().unwrap();
        for named in [true, false] {
            let p = dir.path().join(format!("extra_{named}.las"));
            let mut b = ::las::Builder::from((1, 4));
            b.point_format = ::las::point::Format::new(1).unwrap();
            b.point_format.extra_bytes = 4;
            if named {
                let mut d = vec![0u8; 192];
                d[2] = 9; // float
                d[4..13].copy_from_slice(b"amplitude");
                b.vlrs.push(::las::Vlr {
                    user_id: "LASF_Spec".into(),
                    record_id: 4,
                    description: "extra bytes".into(),
                    data: d,
                });
            }
            let mut w = ::las::Writer::from_path(&p, b.into_header().unwrap()).unwrap();
            for i in 0..10u8 {
                w.write_point(::las::Point {
                    x: f64::from(i),
                    y: 1.0,
                    z: 2.0,
                    gps_time: Some(0.0),
                    extra_bytes: vec![i; 4],
                    ..Default::default()
                })
                .unwrap();
            }
            w.close().unwrap();
            drop(w);
            let (ps, note) = read(&p, None).unwrap();
            assert_eq!(ps.len(), 10);
            let note = note.expect("a note");
            let want = if named {
                "extra-bytes attribute amplitude (4 bytes per point)"
            } else {
                "4 extra bytes per point"
            };
            assert!(note.contains(want), "{note}");
        }
    }

    #[test]
    fn several_columns_are_refused_and_bad_scales_too() {
        let dir = tempfile::tempdir().unwrap();
        let mut ps = cloud();
        ps.names.push("sigma".into());
        ps.values.push(vec![0.1; ps.len()]);
        let e = write_points(&dir.path().join("a.las"), &ps, &Default::default()).unwrap_err();
        assert!(matches!(e, Error::Unsupported { .. }), "{e}");
        assert!(e.to_string().contains("sigma"), "{e}");
        for scale in [0.0, -1.0, f64::NAN] {
            let o = WritePointsOptions {
                scale: Some(scale),
                ..Default::default()
            };
            let e = write_points(&dir.path().join("b.las"), &cloud(), &o).unwrap_err();
            assert!(matches!(e, Error::InvalidArgument { .. }), "{e}");
        }
        // A span the 32-bit grid cannot hold at this scale.
        let wide = PointSet::from_xyz(vec![0.0, 1e7], vec![0.0, 0.0], vec![0.0, 0.0]).unwrap();
        let e = write_points(&dir.path().join("c.las"), &wide, &Default::default()).unwrap_err();
        assert!(e.to_string().contains("coarser scale"), "{e}");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
    }

    #[test]
    fn lying_headers_are_corrupt_not_allocations() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.las");
        write_points(&p, &cloud(), &Default::default()).unwrap();
        let good = std::fs::read(&p).unwrap();
        // LAS 1.2: the legacy point count is a u32 at byte 107.
        let mut bad = good.clone();
        bad[107..111].copy_from_slice(&u32::MAX.to_le_bytes());
        std::fs::write(&p, &bad).unwrap();
        let e = read_points(&p, &Default::default()).unwrap_err();
        assert!(matches!(e, Error::Corrupt { .. }), "{e}");
        // Truncated points.
        std::fs::write(&p, &good[..good.len() - 7]).unwrap();
        let e = read_points(&p, &Default::default()).unwrap_err();
        assert!(matches!(e, Error::Corrupt { .. }), "{e}");
        // LAZ: a chunk table declaring more chunks than the file has bytes.
        let p = dir.path().join("a.laz");
        write_points(&p, &cloud(), &Default::default()).unwrap();
        let mut bad = std::fs::read(&p).unwrap();
        let start = u32::from_le_bytes(bad[96..100].try_into().unwrap()) as usize;
        let table = i64::from_le_bytes(bad[start..start + 8].try_into().unwrap()) as usize;
        bad[table + 4..table + 8].copy_from_slice(&u32::MAX.to_le_bytes());
        std::fs::write(&p, &bad).unwrap();
        let e = read_points(&p, &Default::default()).unwrap_err();
        assert!(e.to_string().contains("chunk table"), "{e}");
        // Not LAS at all.
        std::fs::write(&p, b"hello").unwrap();
        assert!(read_points(&p, &Default::default()).is_err());
    }
}
