//! SRTM `.hgt` tiles: grids of big-endian i16 posts, -32768 = void, georeferenced by file name.
//!
//! A tile named like `N22W160.hgt` (the `[NS]dd[EW]ddd` pattern may appear anywhere in the
//! name, in any case) covers the 1×1 degree cell whose south-west corner is (lon -160,
//! lat 22); its posts are cell centres ([`RasterType::Point`]), row 0 at latitude 23, on
//! WGS84 (EPSG:4326). The grid is told by the file's size, as GDAL's SRTMHGT driver tells it:
//! N × N posts 1/(N-1)° apart (SRTM3 1201², SRTM1 3601², the 0.5″ 7201²; any N from 2 to
//! 10 000 is read), or the 1801 × 3601 of SRTM1 tiles north of 50° (1/1800° along a row,
//! 1/3600° down a column). Another size is unsupported.

use crate::error::{Error, Result};
use crate::formats::ReadOptions;
use crate::model::{Georef, Raster, RasterType, SampleType, check_size};

/// The void marker of SRTM tiles.
pub const VOID: i16 = i16::MIN;

/// Largest grid side accepted (SRTM1 tiles are 3601).
const MAX_SIDE: u64 = 10_000;

/// The south-west corner (lon, lat) of the tile named by the first `[NS]dd[EW]ddd` pattern
/// in `name` (case-insensitive, not part of a longer run of digits).
pub fn tile_corner(name: &str) -> Option<(f64, f64)> {
    let b = name.as_bytes();
    let digits = |s: &[u8]| -> Option<u32> {
        s.iter().try_fold(0u32, |acc, &c| {
            c.is_ascii_digit().then(|| acc * 10 + (c - b'0') as u32)
        })
    };
    for i in 0..b.len().saturating_sub(6) {
        let ns = b[i].to_ascii_uppercase();
        let ew = b[i + 3].to_ascii_uppercase();
        if !matches!(ns, b'N' | b'S') || !matches!(ew, b'E' | b'W') {
            continue;
        }
        if b.get(i + 7).is_some_and(u8::is_ascii_digit) {
            continue;
        }
        let (Some(lat), Some(lon)) = (digits(&b[i + 1..i + 3]), digits(&b[i + 4..i + 7])) else {
            continue;
        };
        if lat >= 90 || lon > 180 {
            continue;
        }
        let lat = if ns == b'S' {
            -(lat as f64)
        } else {
            lat as f64
        };
        let lon = if ew == b'W' {
            -(lon as f64)
        } else {
            lon as f64
        };
        return Some((lon, lat));
    }
    None
}

/// Columns and rows of the one non-square grid GDAL's SRTMHGT driver reads: SRTM1 north of
/// 50° (posts 2″ apart along a row, 1″ down a column).
const HIGH_LATITUDE_SRTM1: (usize, usize) = (1801, 3601);

/// The grid (columns, rows) of an `.hgt` file of `len` bytes.
fn geometry(len: u64) -> Result<(usize, usize)> {
    if len % 2 != 0 {
        return Err(Error::corrupt(format!(
            "hgt file of {len} bytes is not a whole number of 2-byte samples"
        )));
    }
    let samples = len / 2;
    let (w, h) = HIGH_LATITUDE_SRTM1;
    if samples == (w * h) as u64 {
        return Ok(HIGH_LATITUDE_SRTM1);
    }
    let side = samples.isqrt();
    if side * side == samples && side >= 2 {
        if side > MAX_SIDE {
            return Err(Error::limit(format!(
                "hgt grid of {side}x{side} is over the {MAX_SIDE}x{MAX_SIDE} limit"
            )));
        }
        return Ok((side as usize, side as usize));
    }
    Err(Error::unsupported(format!(
        "hgt file of {len} bytes is no .hgt grid vtz reads (N×N int16 posts such as 1201², \
         3601² or 7201², or 1801×3601 north of 50°)"
    )))
}

/// Whether `width × height` is a grid an `.hgt` file can hold (one [`read`] tells apart).
fn is_hgt_grid(width: usize, height: usize) -> bool {
    (width == height && width >= 2 && width as u64 <= MAX_SIDE)
        || (width, height) == HIGH_LATITUDE_SRTM1
}

/// Read an `.hgt` tile; `name` is the file name the georeferencing comes from.
pub fn read(bytes: &[u8], name: &str, opts: &ReadOptions) -> Result<Raster> {
    let (width, height) = geometry(bytes.len() as u64)?;
    let n = check_size(width as u64, height as u64, opts.max_samples())?;
    let nodata = VOID as f64;
    let mut data = Vec::with_capacity(n);
    let mut mask: Option<Vec<bool>> = None;
    for (i, c) in bytes.chunks_exact(2).enumerate() {
        let v = i16::from_be_bytes([c[0], c[1]]);
        if v == VOID {
            mask.get_or_insert_with(|| vec![true; n])[i] = false;
        }
        data.push(v as f64);
    }
    let georef = tile_corner(name).map(|(lon, lat)| Georef {
        origin: [lon, lat + 1.0],
        pixel_size: [1.0 / (width - 1) as f64, 1.0 / (height - 1) as f64],
        raster_type: RasterType::Point,
        epsg: Some(4326),
        wkt: None,
        geokeys: None,
    });
    Ok(Raster {
        georef,
        ..Raster::from_parts(width, height, data, mask, Some(nodata), SampleType::I16)
    })
}

/// The `[NS]dd[EW]ddd` name of the 1° tile whose south-west corner is (lon, lat).
fn tile_name(lon: f64, lat: f64) -> String {
    format!(
        "{}{:02}{}{:03}",
        if lat < 0.0 { 'S' } else { 'N' },
        lat.abs() as u32,
        if lon < 0.0 { 'W' } else { 'E' },
        lon.abs() as u32
    )
}

/// The south-west corner (lon, lat) of the 1° SRTM tile `r` is, when its georef makes it
/// one: WGS84 (or no CRS said), a grid an `.hgt` holds, its posts 1/(columns-1)° apart along
/// a row and 1/(rows-1)° down a column from a whole degree (pixel-is-point; pixel-is-area
/// half a post out, as GDAL reports an `.hgt`).
fn srtm_corner(r: &Raster) -> Option<(f64, f64)> {
    let g = r.georef.as_ref()?;
    if !is_hgt_grid(r.width, r.height) || g.epsg.is_some_and(|e| e != 4326) {
        return None;
    }
    let step = [1.0 / (r.width - 1) as f64, 1.0 / (r.height - 1) as f64];
    let tol = step[1] * 1e-3;
    if (g.pixel_size[0] - step[0]).abs() > tol || (g.pixel_size[1] - step[1]).abs() > tol {
        return None;
    }
    let half = match g.raster_type {
        RasterType::Point => [0.0, 0.0],
        RasterType::Area => [step[0] / 2.0, step[1] / 2.0],
    };
    let (lon, top) = (g.origin[0] + half[0], g.origin[1] - half[1]);
    let (flon, ftop) = (lon.round(), top.round());
    ((lon - flon).abs() <= tol && (top - ftop).abs() <= tol && ftop > -89.5 && ftop <= 90.0)
        .then_some((flon, ftop - 1.0))
}

/// An `.hgt` file is placed by its name alone: refuse to write `r` under `name` when the
/// name does not place it where its georef says (the georef would be lost without a word;
/// GDAL could not place the file). A raster without georef, or `drop_georef`, passes.
pub fn check_name(r: &Raster, name: &str, drop_georef: bool) -> Result<()> {
    if r.georef.is_none() || drop_georef {
        return Ok(());
    }
    let corner = srtm_corner(r);
    if corner.is_some() && corner == tile_corner(name) {
        return Ok(());
    }
    let fix = match corner {
        Some((lon, lat)) => format!(
            "this raster is SRTM tile {}: name the file so (e.g. {}.hgt)",
            tile_name(lon, lat),
            tile_name(lon, lat)
        ),
        None => "this raster is no 1° SRTM tile on WGS84".to_string(),
    };
    Err(Error::invalid(format!(
        "{name}: an .hgt file is placed by its name alone ([NS]dd[EW]ddd), and this name does \
         not place the raster where its georeferencing says; {fix}, or write a GeoTIFF (.tif), \
         or drop the georeferencing with --drop-georef"
    )))
}

/// Write a raster as an `.hgt` tile (the georef is not stored: the file name carries it):
/// an N × N grid (2 ≤ N ≤ 10 000) or the 1801 × 3601 of SRTM1 north of 50°, the grids
/// [`read`] tells apart by size. Values are rounded to the nearest integer and must fit i16
/// without being -32768; invalid samples become -32768.
pub fn write(r: &Raster) -> Result<Vec<u8>> {
    if !is_hgt_grid(r.width, r.height) {
        return Err(Error::invalid(format!(
            "an .hgt tile is a square grid of 2x2 to {MAX_SIDE}x{MAX_SIDE} posts or the \
             1801x3601 of SRTM1 north of 50°, this raster is {}x{}",
            r.width, r.height
        )));
    }
    let mut out = Vec::with_capacity(r.len() * 2);
    for (i, &v) in r.data.iter().enumerate() {
        let code = if r.is_valid(i) {
            let q = v.round();
            if !(q > VOID as f64 && q <= i16::MAX as f64) {
                return Err(Error::invalid(format!(
                    "sample {i} (row {}, col {}) = {v} does not fit an .hgt int16 (-32767..=32767; -32768 marks voids)",
                    i / r.width,
                    i % r.width
                )));
            }
            q as i16
        } else {
            VOID
        };
        out.extend_from_slice(&code.to_be_bytes());
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testutil::*;

    fn opts() -> ReadOptions {
        ReadOptions::default()
    }

    #[test]
    fn tile_names() {
        assert_eq!(tile_corner("N22W160.hgt"), Some((-160.0, 22.0)));
        assert_eq!(tile_corner("srtm3_N22W160_kauai.hgt"), Some((-160.0, 22.0)));
        assert_eq!(tile_corner("s01e010.HGT"), Some((10.0, -1.0)));
        assert_eq!(tile_corner("N37E051.SRTMGL1.hgt"), Some((51.0, 37.0)));
        assert_eq!(tile_corner("n45e0134.hgt"), None);
        assert_eq!(tile_corner("N95E010.hgt"), None);
        assert_eq!(tile_corner("tile.hgt"), None);
        assert_eq!(tile_corner(""), None);
        assert_eq!(tile_corner("ñN22W160ü.hgt"), Some((-160.0, 22.0)));
    }

    fn small_tile() -> Vec<u8> {
        let vals: [i16; 9] = [1, -5, VOID, 300, 32767, -32767, 0, 7, 8];
        vals.iter().flat_map(|v| v.to_be_bytes()).collect()
    }

    #[test]
    fn small_roundtrip_and_georef() {
        let b = small_tile();
        let r = read(&b, "S01E010.hgt", &opts()).unwrap();
        assert_eq!((r.width, r.height), (3, 3));
        assert_eq!(r.sample_type, SampleType::I16);
        assert_eq!(r.nodata, Some(-32768.0));
        assert!(!r.is_valid(2));
        assert_eq!(r.data[2], -32768.0);
        assert_eq!(r.data[5], -32767.0);
        let g = r.georef.clone().unwrap();
        assert_eq!(g.origin, [10.0, 0.0]);
        assert_eq!(g.pixel_size, [0.5, 0.5]);
        assert_eq!(g.raster_type, RasterType::Point);
        assert_eq!(g.epsg, Some(4326));
        assert_eq!(write(&r).unwrap(), b);
        assert!(read(&b, "tile.hgt", &opts()).unwrap().georef.is_none());
    }

    #[test]
    fn write_checks() {
        let r = Raster::from_values(2, 1, vec![1.0, 2.0], None, SampleType::I16).unwrap();
        assert!(matches!(write(&r), Err(Error::InvalidArgument { .. })));
        let r =
            Raster::from_values(2, 2, vec![1.0, 2.0, 3.0, 40000.0], None, SampleType::I32).unwrap();
        assert!(matches!(write(&r), Err(Error::InvalidArgument { .. })));
        let r = Raster::from_values(2, 2, vec![1.0, 2.0, 3.0, -32768.2], None, SampleType::F32)
            .unwrap();
        assert!(matches!(write(&r), Err(Error::InvalidArgument { .. })));
        // Rounding to nearest; NaN voids and another declared nodata become -32768.
        let r = Raster::from_values(
            2,
            2,
            vec![1.4, -2.6, f64::NAN, -9999.0],
            Some(-9999.0),
            SampleType::F32,
        )
        .unwrap();
        let b = write(&r).unwrap();
        let back: Vec<i16> = b
            .chunks_exact(2)
            .map(|c| i16::from_be_bytes([c[0], c[1]]))
            .collect();
        assert_eq!(back, [1, -3, VOID, VOID]);
    }

    #[test]
    fn garbage_and_limits() {
        let b = small_tile();
        for cut in 0..b.len() {
            // Every truncation fails except the one that is itself a square tile (2x2).
            let res = read(&b[..cut], "N00E000.hgt", &opts());
            assert_eq!(res.is_ok(), cut == 8, "cut {cut}");
        }
        let mut rng = Rng(7);
        for len in [1usize, 3, 5, 7, 10, 99, 1001] {
            assert!(read(&rng.bytes(len), "x.hgt", &opts()).is_err());
        }
        // A valid-sized tile over the sample limit.
        let o = ReadOptions {
            max_samples: Some(8),
            ..Default::default()
        };
        assert!(matches!(
            read(&b, "x.hgt", &o),
            Err(Error::LimitExceeded { .. })
        ));
    }

    #[test]
    fn names_must_place_a_georeferenced_tile() {
        let r = read(&small_tile(), "S01E010.hgt", &opts()).unwrap();
        assert!(check_name(&r, "S01E010.hgt", false).is_ok());
        assert!(check_name(&r, "x_s01e010_y.hgt", false).is_ok());
        let e = check_name(&r, "tile.hgt", false).unwrap_err().to_string();
        assert!(e.contains("S01E010.hgt"), "{e}");
        assert!(check_name(&r, "S01E011.hgt", false).is_err());
        assert!(check_name(&r, "tile.hgt", true).is_ok());
        // Pixel-is-area, half a post out (as GDAL reports an .hgt), is the same tile.
        let mut a = r.clone();
        let g = a.georef.as_mut().unwrap();
        g.raster_type = RasterType::Area;
        g.origin = [10.0 - 0.25, 0.25];
        assert!(check_name(&a, "S01E010.hgt", false).is_ok());
        // Without georef there is nothing to lose.
        let n = read(&small_tile(), "tile.hgt", &opts()).unwrap();
        assert!(check_name(&n, "tile.hgt", false).is_ok());
        // Not a 1° tile at all (a UTM grid): no name places it.
        let mut u = r.clone();
        let g = u.georef.as_mut().unwrap();
        g.epsg = Some(32611);
        let e = check_name(&u, "S01E010.hgt", false)
            .unwrap_err()
            .to_string();
        assert!(e.contains("no 1° SRTM tile"), "{e}");
    }

    #[test]
    fn corpus_tiles() {
        let names = [
            "srtm3_N22W160_kauai",
            "srtm3_N00E010_gabon",
            "srtm3_N44W072_white_mountains",
            "srtm3_N57E011_kattegat",
        ];
        for_each_corpus(&names, |dir, name| {
            let file = format!("{name}.hgt");
            let bytes = std::fs::read(dir.join(&file)).unwrap();
            let r = read(&bytes, &file, &opts()).unwrap();
            assert_eq!(raster_bits(&r), raw_bits(dir, name), "{name}");
            let raw = load_raw(dir, name);
            assert_eq!(r.mask, raw.mask, "{name}");
            assert_eq!(r.georef, raw.georef, "{name}");
            assert_eq!(r.nodata, raw.nodata);
            assert_eq!(write(&r).unwrap(), bytes, "{name}: write differs");
            if name.contains("kauai") {
                assert!(r.valid_count() < r.len(), "kauai has voids");
            }
        });
    }

    /// Every grid GDAL's SRTMHGT driver reads (1201², 3601², 7201², and 1801 × 3601 for SRTM1
    /// north of 50°) is read with its own spacing per axis and written back byte for byte;
    /// another even size is "unsupported", an odd one corrupt.
    #[test]
    fn every_gdal_geometry() {
        for (w, h) in [
            (1201usize, 1201usize),
            (3601, 3601),
            (1801, 3601),
            (7201, 7201),
        ] {
            let mut rng = Rng(w as u64);
            let vals: Vec<i16> = (0..w * h)
                .map(|i| {
                    if i % 1000 == 7 {
                        VOID
                    } else {
                        (rng.next() % 9000) as i16 - 500
                    }
                })
                .collect();
            let bytes: Vec<u8> = vals.iter().flat_map(|v| v.to_be_bytes()).collect();
            let r = read(&bytes, "N60E010.hgt", &opts()).unwrap_or_else(|e| panic!("{w}x{h}: {e}"));
            assert_eq!((r.width, r.height), (w, h));
            assert_eq!(r.data[1], f64::from(vals[1]));
            assert!(!r.is_valid(7));
            let g = r.georef.clone().unwrap();
            assert_eq!(g.origin, [10.0, 61.0]);
            assert_eq!(
                g.pixel_size,
                [1.0 / (w - 1) as f64, 1.0 / (h - 1) as f64],
                "{w}x{h}"
            );
            assert_eq!(write(&r).unwrap(), bytes, "{w}x{h}");
            assert!(check_name(&r, "N60E010.hgt", false).is_ok(), "{w}x{h}");
            let e = check_name(&r, "tile.hgt", false).unwrap_err().to_string();
            assert!(e.contains("N60E010.hgt"), "{e}");
        }
        // 601 x 1201 (or 1201 x 601: the same size), which GDAL does not open either; a size
        // of no grid; HTML saved as .hgt.
        for len in [601 * 1201 * 2, 1201 * 1201 * 2 + 2, 1000] {
            let e = read(&vec![0u8; len], "N60E010.hgt", &opts()).unwrap_err();
            assert!(matches!(e, Error::Unsupported { .. }), "{len}: {e}");
        }
        let e = read(b"<html></html>\n", "N60E010.hgt", &opts()).unwrap_err();
        assert!(matches!(e, Error::Unsupported { .. }), "{e}");
        let e = read(&[0u8; 1001], "N60E010.hgt", &opts()).unwrap_err();
        assert!(matches!(e, Error::Corrupt { .. }), "{e}");
        // The writer takes the same grids and no other.
        let r = Raster::from_values(3, 2, vec![0.0; 6], None, SampleType::I16).unwrap();
        assert!(matches!(write(&r), Err(Error::InvalidArgument { .. })));
    }
}
