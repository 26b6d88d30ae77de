//! ESRI ASCII grids (`.asc`): a `key value` header, then `nrows × ncols` numbers in text.
//!
//! Header keys (case-insensitive, any order): `ncols`, `nrows`, `xllcorner`|`xllcenter`,
//! `yllcorner`|`yllcenter`, `cellsize` (or `dx` and `dy`), optional `NODATA_value`. Values
//! are read as f64; a grid whose numbers are all integers in i32 range, written without a
//! decimal point, is [`SampleType::I32`], anything else is [`SampleType::F32`] with every
//! value rounded once to f32. Corner headers give a [`RasterType::Area`] georef, centre
//! headers a [`RasterType::Point`] one. The grid itself carries no CRS: `formats::read_path`
//! takes it from a `NAME.prj` beside the file, and `formats::encode_path` writes one.

use crate::error::{Error, Result};
use crate::formats::ReadOptions;
use crate::model::{Georef, Raster, RasterType, SampleType, check_size};
use std::fmt::Write as _;

/// Header values as read.
#[derive(Default)]
struct Header {
    ncols: Option<u64>,
    nrows: Option<u64>,
    /// (value, is_centre)
    xll: Option<(f64, bool)>,
    yll: Option<(f64, bool)>,
    cellsize: Option<f64>,
    dx: Option<f64>,
    dy: Option<f64>,
    nodata: Option<f64>,
}

fn set<T>(slot: &mut Option<T>, v: T, key: &str) -> Result<()> {
    if slot.is_some() {
        return Err(Error::corrupt(format!(
            "ESRI ASCII header has '{key}' twice (or two forms of it)"
        )));
    }
    *slot = Some(v);
    Ok(())
}

fn header_f64(key: &str, val: &str) -> Result<f64> {
    match val.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        _ => Err(Error::corrupt(format!(
            "ESRI ASCII header '{key}' value '{val}' is not a finite number"
        ))),
    }
}

/// `NODATA_value`: a number, or NaN / ±infinity in any of the spellings GDAL's AAIGrid
/// writer and C's `printf` give them (`nan`, `NaN`, `-nan`, `inf`, `-inf`, `Infinity`).
fn header_nodata(key: &str, val: &str) -> Result<f64> {
    // One NaN whatever its sign (`-nan`), so that it reads back the same after a write.
    let canonical = |v: f64| if v.is_nan() { f64::NAN } else { v };
    val.parse::<f64>().map(canonical).map_err(|_| {
        Error::corrupt(format!(
            "ESRI ASCII header '{key}' value '{}' is not a number",
            truncate(val)
        ))
    })
}

fn header_count(key: &str, val: &str) -> Result<u64> {
    val.parse::<u64>().map_err(|_| {
        Error::corrupt(format!(
            "ESRI ASCII header '{key}' value '{val}' is not a non-negative integer"
        ))
    })
}

fn truncate(s: &str) -> &str {
    match s.char_indices().nth(40) {
        Some((i, _)) => &s[..i],
        None => s,
    }
}

/// Parse the header; returns it and the text where the numbers start.
fn parse_header(text: &str) -> Result<(Header, &str)> {
    let mut h = Header::default();
    let mut rest = text;
    loop {
        if rest.is_empty() {
            break;
        }
        let line_end = rest.find('\n').map_or(rest.len(), |p| p + 1);
        let line = &rest[..line_end];
        let mut toks = line.split_ascii_whitespace();
        let Some(first) = toks.next() else {
            rest = &rest[line_end..];
            continue;
        };
        if !first.starts_with(|c: char| c.is_ascii_alphabetic()) || first.parse::<f64>().is_ok() {
            break;
        }
        let key = first.to_ascii_lowercase();
        let Some(val) = toks.next() else {
            return Err(Error::corrupt(format!(
                "ESRI ASCII header line '{}' has no value",
                truncate(line.trim())
            )));
        };
        if toks.next().is_some() {
            return Err(Error::corrupt(format!(
                "ESRI ASCII header line '{}' has more than a key and a value",
                truncate(line.trim())
            )));
        }
        match key.as_str() {
            "ncols" => set(&mut h.ncols, header_count(&key, val)?, &key)?,
            "nrows" => set(&mut h.nrows, header_count(&key, val)?, &key)?,
            "xllcorner" => set(&mut h.xll, (header_f64(&key, val)?, false), &key)?,
            "xllcenter" | "xllcentre" => set(&mut h.xll, (header_f64(&key, val)?, true), &key)?,
            "yllcorner" => set(&mut h.yll, (header_f64(&key, val)?, false), &key)?,
            "yllcenter" | "yllcentre" => set(&mut h.yll, (header_f64(&key, val)?, true), &key)?,
            "cellsize" => set(&mut h.cellsize, header_f64(&key, val)?, &key)?,
            "dx" | "xdim" => set(&mut h.dx, header_f64(&key, val)?, &key)?,
            "dy" | "ydim" => set(&mut h.dy, header_f64(&key, val)?, &key)?,
            "nodata_value" | "nodata" => set(&mut h.nodata, header_nodata(&key, val)?, &key)?,
            _ => {
                return Err(Error::corrupt(format!(
                    "ESRI ASCII header has an unknown key '{}'",
                    truncate(first)
                )));
            }
        }
        rest = &rest[line_end..];
    }
    Ok((h, rest))
}

/// Read an ESRI ASCII grid.
pub fn read(bytes: &[u8], opts: &ReadOptions) -> Result<Raster> {
    let text = std::str::from_utf8(bytes)
        .map_err(|e| Error::corrupt(format!("ESRI ASCII grid is not UTF-8 text: {e}")))?;
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let (h, body) = parse_header(text)?;
    let missing = |k: &str| Error::corrupt(format!("ESRI ASCII header has no '{k}'"));
    let ncols = h.ncols.ok_or_else(|| missing("ncols"))?;
    let nrows = h.nrows.ok_or_else(|| missing("nrows"))?;
    let (x, x_centre) = h.xll.ok_or_else(|| missing("xllcorner or xllcenter"))?;
    let (y, y_centre) = h.yll.ok_or_else(|| missing("yllcorner or yllcenter"))?;
    if x_centre != y_centre {
        return Err(Error::corrupt(
            "ESRI ASCII header mixes corner and centre forms of xll/yll",
        ));
    }
    let (dx, dy) = match (h.cellsize, h.dx, h.dy) {
        (Some(c), None, None) => (c, c),
        (None, Some(dx), Some(dy)) => (dx, dy),
        (Some(_), _, _) => {
            return Err(Error::corrupt(
                "ESRI ASCII header has both 'cellsize' and 'dx'/'dy'",
            ));
        }
        _ => return Err(missing("cellsize (or dx and dy)")),
    };
    if dx <= 0.0 || dy <= 0.0 {
        return Err(Error::corrupt(format!(
            "ESRI ASCII cell size {dx} x {dy} is not positive"
        )));
    }
    let n = check_size(ncols, nrows, opts.max_samples())?;
    let (width, height) = (ncols as usize, nrows as usize);
    // A NaN NODATA_value (GDAL writes `nan` for a float raster whose nodata is NaN) declares
    // no value: NaN samples are nodata anyway.
    let declared = h.nodata.filter(|v| !v.is_nan());

    let mut values = Vec::with_capacity(n);
    let mut has_dot = false;
    let mut all_int = true;
    for tok in body.split_ascii_whitespace() {
        let i = values.len();
        if i == n {
            return Err(Error::corrupt(format!(
                "ESRI ASCII grid has more than the {n} values of {width}x{height} ('{}' follows)",
                truncate(tok)
            )));
        }
        let v: f64 = tok.parse().map_err(|_| {
            Error::corrupt(format!(
                "ESRI ASCII value '{}' at row {}, col {} is not a number",
                truncate(tok),
                i / width,
                i % width
            ))
        })?;
        // NaN samples are nodata (as `nan` in GDAL's own grids); an infinite one only as the
        // declared NODATA_value.
        if v.is_infinite() && h.nodata != Some(v) {
            return Err(Error::corrupt(format!(
                "ESRI ASCII value '{}' at row {}, col {} is infinite",
                truncate(tok),
                i / width,
                i % width
            )));
        }
        has_dot |= tok.contains('.');
        all_int &= v.fract() == 0.0 && v >= i32::MIN as f64 && v <= i32::MAX as f64;
        values.push(v);
    }
    if values.len() != n {
        return Err(Error::corrupt(format!(
            "ESRI ASCII grid of {width}x{height} needs {n} values, found {}",
            values.len()
        )));
    }
    let nodata_int =
        declared.is_none_or(|v| v.fract() == 0.0 && v >= i32::MIN as f64 && v <= i32::MAX as f64);
    let (sample_type, nodata) = if all_int && !has_dot && nodata_int {
        for v in &mut values {
            *v += 0.0; // -0 → 0
        }
        (SampleType::I32, declared.map(|v| v + 0.0))
    } else {
        for (i, v) in values.iter_mut().enumerate() {
            let s = *v as f32;
            if s.is_infinite() && !v.is_infinite() {
                return Err(Error::corrupt(format!(
                    "ESRI ASCII value {v} at row {}, col {} is out of float32 range",
                    i / width,
                    i % width
                )));
            }
            *v = s as f64;
        }
        let nd = match declared {
            Some(v) if (v as f32).is_infinite() && !v.is_infinite() => {
                return Err(Error::corrupt(format!(
                    "ESRI ASCII NODATA_value {v} is out of float32 range"
                )));
            }
            other => other.map(|v| v as f32 as f64),
        };
        (SampleType::F32, nd)
    };
    let mut r = Raster::from_values(width, height, values, nodata, sample_type)?;
    r.georef = Some(if x_centre {
        Georef {
            origin: [x, y + (nrows - 1) as f64 * dy],
            pixel_size: [dx, dy],
            raster_type: RasterType::Point,
            epsg: None,
            wkt: None,
            geokeys: None,
        }
    } else {
        Georef {
            origin: [x, y + nrows as f64 * dy],
            pixel_size: [dx, dy],
            raster_type: RasterType::Area,
            epsg: None,
            wkt: None,
            geokeys: None,
        }
    });
    Ok(r)
}

/// Move `x` by `k` steps through the ordered f64 values.
fn step(x: f64, k: i64) -> f64 {
    let ord = |b: i64| if b < 0 { b ^ i64::MAX } else { b };
    f64::from_bits(ord(ord(x.to_bits() as i64).saturating_add(k)) as u64)
}

/// The `yll` that makes the reader's `yll + t` give back `target` exactly, when one exists
/// near `target - t`.
fn invert_sum(target: f64, t: f64) -> f64 {
    let y0 = target - t;
    for k in 0..64i64 {
        for y in [step(y0, k), step(y0, -k)] {
            if y.is_finite() && y + t == target {
                return y;
            }
        }
    }
    y0
}

/// Text for one value: integers without a decimal point for integer sample types; the
/// shortest f32 form (which always has a '.' or an exponent) for f32; the shortest f64 form
/// otherwise. Each form re-reads to the same value.
fn format_value(out: &mut String, v: f64, t: SampleType) {
    if t.is_integer() && v.fract() == 0.0 && v.abs() < 9.0e15 {
        let _ = write!(out, "{}", v as i64);
        return;
    }
    if t == SampleType::F32 && (v as f32) as f64 == v {
        let s = v as f32;
        let start = out.len();
        let _ = write!(out, "{s:?}");
        if out[start..].parse::<f64>().map(|p| p as f32) == Ok(s) {
            return;
        }
        out.truncate(start);
    }
    let _ = write!(out, "{v:?}");
}

/// Write an ESRI ASCII grid. Rasters without a georef get `xllcorner 0`, `yllcorner 0`,
/// `cellsize 1`; invalid samples get the declared nodata value, or -9999 (or another unused
/// sentinel) when none is declared.
pub fn write(r: &Raster) -> Result<Vec<u8>> {
    let t = r.sample_type;
    let (ncols, nrows) = (r.width, r.height);
    let mut out = String::with_capacity(r.len() * 8 + 200);
    let _ = writeln!(out, "ncols        {ncols}");
    let _ = writeln!(out, "nrows        {nrows}");
    match &r.georef {
        None => {
            out.push_str("xllcorner    0\nyllcorner    0\ncellsize     1\n");
        }
        Some(g) => {
            let [dx, dy] = g.pixel_size;
            if !(dx > 0.0 && dy > 0.0 && dx.is_finite() && dy.is_finite()) {
                return Err(Error::invalid(format!(
                    "an ESRI ASCII grid needs positive pixel sizes, this raster has {dx} x {dy}"
                )));
            }
            let (kx, ky, rows) = match g.raster_type {
                RasterType::Area => ("xllcorner", "yllcorner", nrows as f64),
                RasterType::Point => ("xllcenter", "yllcenter", (nrows - 1) as f64),
            };
            let yll = invert_sum(g.origin[1], rows * dy);
            let _ = writeln!(out, "{kx:<12} {}", g.origin[0]);
            let _ = writeln!(out, "{ky:<12} {yll}");
            if dx == dy {
                let _ = writeln!(out, "cellsize     {dx}");
            } else {
                let _ = writeln!(out, "dx           {dx}");
                let _ = writeln!(out, "dy           {dy}");
            }
        }
    }
    let has_invalid = r.valid_count() < r.len();
    let nodata = match r.nodata {
        Some(nd) => Some(nd),
        None if has_invalid => {
            let used = |c: f64| {
                r.data
                    .iter()
                    .enumerate()
                    .any(|(i, &v)| r.is_valid(i) && (v == c || (v as f32) == (c as f32)))
            };
            Some(
                [-9999.0, -32768.0, -99999.0, f32::MIN as f64]
                    .into_iter()
                    .find(|&c| !used(c))
                    .ok_or_else(|| {
                        Error::invalid("no unused NODATA_value sentinel for this ESRI ASCII grid")
                    })?,
            )
        }
        None => None,
    };
    let mut nodata_text = String::new();
    if let Some(nd) = nodata {
        format_value(&mut nodata_text, nd, t);
        let _ = writeln!(out, "NODATA_value {nodata_text}");
    }
    for row in 0..nrows {
        for col in 0..ncols {
            let i = row * ncols + col;
            if col > 0 {
                out.push(' ');
            }
            if r.is_valid(i) {
                let start = out.len();
                format_value(&mut out, r.data[i], t);
                if nodata.is_some() && out[start..] == nodata_text {
                    return Err(Error::invalid(format!(
                        "sample {i} (row {row}, col {col}) = {} is written the same as NODATA_value {nodata_text}",
                        r.data[i]
                    )));
                }
            } else {
                out.push_str(&nodata_text);
            }
        }
        out.push('\n');
    }
    Ok(out.into_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testutil::*;

    fn opts() -> ReadOptions {
        ReadOptions::default()
    }

    const SMALL: &str = "NCOLS 3\nnrows 2\nxllcenter 10.5\nYLLCENTER -3\ncellsize 0.5\nnodata_value -9999\n1 2 -9999\n4\n5 -6\n";

    #[test]
    fn small_int_grid() {
        let r = read(SMALL.as_bytes(), &opts()).unwrap();
        assert_eq!((r.width, r.height), (3, 2));
        assert_eq!(r.sample_type, SampleType::I32);
        assert_eq!(r.nodata, Some(-9999.0));
        assert!(!r.is_valid(2));
        assert_eq!(r.data[5], -6.0);
        let g = r.georef.clone().unwrap();
        assert_eq!(g.raster_type, RasterType::Point);
        assert_eq!(g.origin, [10.5, -2.5]);
        let back = read(&write(&r).unwrap(), &opts()).unwrap();
        assert_same(&r, &back, "asc round trip");
    }

    #[test]
    fn float_detection() {
        let t = "ncols 2\nnrows 1\nxllcorner 0\nyllcorner 0\ncellsize 1\n1.0 2\n";
        let r = read(t.as_bytes(), &opts()).unwrap();
        assert_eq!(r.sample_type, SampleType::F32);
        let t = "ncols 2\nnrows 1\nxllcorner 0\nyllcorner 0\ncellsize 1\n1e3 -0\n";
        let r = read(t.as_bytes(), &opts()).unwrap();
        assert_eq!(r.sample_type, SampleType::I32);
        assert_eq!(r.data[1].to_bits(), 0.0f64.to_bits());
        let t = "ncols 2\nnrows 1\nxllcorner 0\nyllcorner 0\ncellsize 1\n0.1 3000000000\n";
        let r = read(t.as_bytes(), &opts()).unwrap();
        assert_eq!(r.sample_type, SampleType::F32);
        assert_eq!(r.data[0], 0.1f32 as f64);
        assert_eq!(r.georef.unwrap().origin, [0.0, 1.0]);
        // F32 rasters with integral values stay F32 through a write.
        let r = Raster::from_values(2, 1, vec![1.0, 2.0], None, SampleType::F32).unwrap();
        let back = read(&write(&r).unwrap(), &opts()).unwrap();
        assert_eq!(back.sample_type, SampleType::F32);
    }

    #[test]
    fn random_roundtrip() {
        let mut rng = Rng(42);
        for case in 0..20 {
            let (w, h) = (
                1 + (rng.next() % 17) as usize,
                1 + (rng.next() % 9) as usize,
            );
            let float = case % 2 == 0;
            let data: Vec<f64> = (0..w * h)
                .map(|_| {
                    let u = rng.next();
                    if u % 7 == 0 {
                        f64::NAN
                    } else if float {
                        let e = (u >> 8) % 40;
                        (f32::from_bits((u >> 32) as u32 & 0x807f_ffff | 0x3f80_0000) as f64)
                            * 2f64.powi(e as i32 - 20)
                    } else {
                        ((u >> 16) as i32 / 4096) as f64
                    }
                })
                .collect();
            let t = if float {
                SampleType::F32
            } else {
                SampleType::I32
            };
            let mut r = Raster::from_values(w, h, data, None, t).unwrap();
            r.georef = Some(Georef {
                origin: [0.1 + 0.2 * case as f64, 1.0 / 3.0 + case as f64 * 1e5],
                pixel_size: [1.0 / 3600.0, 1.0 / 3600.0 + (case % 3) as f64 * 0.1],
                raster_type: if case % 4 < 2 {
                    RasterType::Area
                } else {
                    RasterType::Point
                },
                epsg: None,
                wkt: None,
                geokeys: None,
            });
            let r1 = read(&write(&r).unwrap(), &opts()).unwrap();
            // The first read declares a sentinel nodata; from then on it is stable.
            assert_eq!(r1.sample_type, t);
            assert_eq!(r1.mask, r.mask);
            for i in 0..r.len() {
                if r.is_valid(i) {
                    assert_eq!(r1.data[i].to_bits(), r.data[i].to_bits());
                }
            }
            assert_eq!(r1.georef, r.georef, "case {case}");
            let r2 = read(&write(&r1).unwrap(), &opts()).unwrap();
            assert_same(&r1, &r2, "asc round trip");
        }
    }

    #[test]
    fn garbage_and_limits() {
        let b = SMALL.as_bytes();
        let last_token = SMALL.rfind("-6").unwrap();
        for cut in 0..b.len() {
            let res = read(&b[..cut], &opts());
            if cut <= last_token {
                assert!(res.is_err(), "cut {cut}");
            }
        }
        let mut rng = Rng(5);
        for len in [0, 1, 10, 100, 1000] {
            assert!(read(&rng.bytes(len), &opts()).is_err());
        }
        for bad in [
            "ncols 2\nnrows 1\nxllcorner 0\nyllcorner 0\ncellsize 1\n1 2 3\n",
            "ncols 2\nnrows 1\nxllcorner 0\nyllcorner 0\ncellsize 1\n1 x\n",
            "ncols 2\nnrows 1\nxllcorner 0\nyllcorner 0\ncellsize 1\n1 inf\n",
            "ncols 2\nnrows 1\nxllcorner 0\nyllcenter 0\ncellsize 1\n1 2\n",
            "ncols 2\nnrows 1\nxllcorner 0\nyllcorner 0\ncellsize -1\n1 2\n",
            "ncols 2\nncols 2\nnrows 1\nxllcorner 0\nyllcorner 0\ncellsize 1\n1 2\n",
            "ncols 2\nnrows 1\nxllcorner 0\nyllcorner 0\n1 2\n",
            "ncols 2\nnrows 1\nxllcorner 0\nyllcorner 0\ncellsize 1\nfoo 3\n1 2\n",
            "ncols -2\nnrows 1\nxllcorner 0\nyllcorner 0\ncellsize 1\n1 2\n",
            "ncols 0\nnrows 1\nxllcorner 0\nyllcorner 0\ncellsize 1\n",
            "ncols 1\nnrows 1\nxllcorner 0\nyllcorner 0\ncellsize 1\n1e39\n",
        ] {
            assert!(read(bad.as_bytes(), &opts()).is_err(), "{bad}");
        }
        let big = "ncols 100000000\nnrows 100000000\nxllcorner 0\nyllcorner 0\ncellsize 1\n1 2\n";
        assert!(matches!(
            read(big.as_bytes(), &opts()),
            Err(Error::LimitExceeded { .. })
        ));
        let huge = "ncols 18446744073709551615\nnrows 18446744073709551615\nxllcorner 0\nyllcorner 0\ncellsize 1\n";
        assert!(matches!(
            read(huge.as_bytes(), &opts()),
            Err(Error::LimitExceeded { .. })
        ));
    }

    #[test]
    fn write_rejects_bad_georef() {
        let mut r = Raster::from_values(1, 1, vec![1.0], None, SampleType::I32).unwrap();
        r.georef = Some(Georef {
            origin: [0.0, 0.0],
            pixel_size: [1.0, -1.0],
            raster_type: RasterType::Area,
            epsg: None,
            wkt: None,
            geokeys: None,
        });
        assert!(matches!(write(&r), Err(Error::InvalidArgument { .. })));
    }

    #[test]
    fn corpus_grids() {
        let Some(dir) = corpus() else { return };
        for (name, t, nd) in [
            ("lidar5m_west_bijou_gully_landlab", SampleType::F32, None),
            (
                "nasadem_west_bijou_escarpment_landlab",
                SampleType::I32,
                Some(-32768.0),
            ),
        ] {
            let bytes = std::fs::read(dir.join(format!("{name}.asc"))).unwrap();
            let r = read(&bytes, &opts()).unwrap();
            assert_eq!(raster_bits(&r), raw_bits(&dir, name), "{name}");
            assert_eq!(r.sample_type, t);
            assert_eq!(r.nodata, nd);
            // Same placement as the corpus sidecar text says (the .asc has no CRS).
            let (g, raw) = (
                r.georef.clone().unwrap(),
                load_raw(&dir, name).georef.unwrap(),
            );
            assert_eq!(g.origin, raw.origin, "{name}");
            assert_eq!(g.pixel_size, raw.pixel_size, "{name}");
            assert_eq!(g.raster_type, raw.raster_type, "{name}");
            assert_eq!(g.epsg, None);
            let w = write(&r).unwrap();
            let back = read(&w, &opts()).unwrap();
            assert_same(&r, &back, "asc round trip");
            assert_eq!(write(&back).unwrap(), w);
        }
    }

    /// `gdal_translate -of AAIGrid` of a float raster whose nodata is NaN (GDAL 3.6's bytes),
    /// and the other spellings of NaN and infinity GDAL and C's printf write.
    #[test]
    fn gdal_nan_and_infinite_nodata() {
        let gdal = "ncols        4\nnrows        3\nxllcorner    10.000000000000\n\
                    yllcorner    17.000000000000\ncellsize     1.000000000000\n\
                    NODATA_value  nan\n 0.0 1.5 3 4.5\n 6 nan 9 10.5\n 12 13.5 15 16.5\n";
        let r = read(gdal.as_bytes(), &opts()).unwrap();
        assert_eq!(r.sample_type, SampleType::F32);
        assert_eq!(
            r.nodata, None,
            "NaN samples are nodata without a declared value"
        );
        assert_eq!(r.valid_count(), 11);
        assert!(!r.is_valid(5));
        assert_eq!(r.data[6], 9.0);
        // Written back, the invalid samples get a NODATA_value sentinel (-9999): the same
        // samples are valid, with the same values.
        let same = |a: &Raster, b: &Raster, what: &str| {
            assert_eq!(a.mask, b.mask, "{what}");
            for i in (0..a.len()).filter(|&i| a.is_valid(i)) {
                assert_eq!(a.data[i].to_bits(), b.data[i].to_bits(), "{what}: {i}");
            }
        };
        let back = read(&write(&r).unwrap(), &opts()).unwrap();
        same(&r, &back, "NaN nodata round trip");

        for (nd, sample) in [
            ("NaN", "NaN"),
            ("-nan", "-nan"),
            ("nan", "-9999"),
            ("-inf", "-inf"),
            ("inf", "inf"),
            ("-Infinity", "-Infinity"),
        ] {
            let t = format!(
                "ncols 2\nnrows 1\nxllcorner 0\nyllcorner 0\ncellsize 1\nNODATA_value {nd}\n1.5 {sample}\n"
            );
            let r = read(t.as_bytes(), &opts()).unwrap_or_else(|e| panic!("{nd} {sample}: {e}"));
            let want_valid = sample == "-9999";
            assert_eq!(r.is_valid(1), want_valid, "{nd} {sample}");
            let back = read(&write(&r).unwrap(), &opts()).unwrap();
            same(&r, &back, nd);
        }
        // NaN samples are nodata whatever the declared value; an infinite one that is not
        // the NODATA_value is still refused.
        let t =
            "ncols 2\nnrows 1\nxllcorner 0\nyllcorner 0\ncellsize 1\nNODATA_value -9999\nnan 2\n";
        let r = read(t.as_bytes(), &opts()).unwrap();
        assert!(!r.is_valid(0));
        let t =
            "ncols 2\nnrows 1\nxllcorner 0\nyllcorner 0\ncellsize 1\nNODATA_value -inf\ninf 2\n";
        assert!(read(t.as_bytes(), &opts()).is_err());
        let t = "ncols 2\nnrows 1\nxllcorner 0\nyllcorner 0\ncellsize 1\nNODATA_value none\n1 2\n";
        assert!(matches!(
            read(t.as_bytes(), &opts()),
            Err(Error::Corrupt { .. })
        ));
    }
}
