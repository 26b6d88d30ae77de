//! Files GDAL writes (or reads) that vtz once got wrong (issue 35, items 3, 4, 13, 16 and 19):
//! south-up GeoTIFFs, ASCII grids with `NODATA_value nan`, GeoTIFFs with an internal mask
//! band, 16-bit PNGs of heights + 32768, Terrarium PNGs, compound CRSs.
//!
//! The GeoTIFF and ASCII inputs are GDAL's own bytes (`tests/gdal_written/`, made by
//! `make.py` there with GDAL 3.6), so these tests need no GDAL. What GDAL reads back from
//! vtz's outputs is checked with `gdal_translate` / `gdalinfo` where they are installed; where
//! they are not, those checks print `SKIPPED (gdal_translate not found): …` on stderr.

use crate::common;

use common::{ok, stderr, tmp, vtz};
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;
use vtz::{GeoKeys, Georef, Raster, RasterType, SampleType};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/gdal_written")
        .join(name)
}

fn read(path: &Path) -> Raster {
    vtz::read_path(path, &Default::default()).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn s(p: &Path) -> String {
    p.to_string_lossy().into_owned()
}

/// Whether `tool` runs here; if not, says so on the process's stderr.
fn have(tool: &str, what: &str) -> bool {
    match Command::new(tool).arg("--version").output() {
        Ok(o) if o.status.success() => true,
        _ => {
            let _ = writeln!(std::io::stderr(), "SKIPPED ({tool} not found): {what}");
            false
        }
    }
}

/// The centre of sample (col, row) on the ground, from vtz's georef.
fn centre(g: &Georef, col: usize, row: usize) -> (f64, f64) {
    let half = match g.raster_type {
        RasterType::Area => 0.5,
        RasterType::Point => 0.0,
    };
    (
        g.origin[0] + (col as f64 + half) * g.pixel_size[0],
        g.origin[1] - (row as f64 + half) * g.pixel_size[1],
    )
}

/// Where each valid value lies: ((x, y) of its centre in millionths, value as f32 bits),
/// sorted. Two rasters with the same list hold the same values at the same places, whatever
/// their row order.
fn placed(r: &Raster) -> Vec<((i64, i64), u32)> {
    let g = r.georef.as_ref().expect("georeferenced");
    let mut v: Vec<_> = (0..r.len())
        .filter(|&i| r.is_valid(i))
        .map(|i| {
            let (x, y) = centre(g, i % r.width, i / r.width);
            let key = ((x * 1e6).round() as i64, (y * 1e6).round() as i64);
            (key, (r.data[i] as f32).to_bits())
        })
        .collect();
    v.sort();
    v
}

/// The same, as GDAL reads a file: `gdal_translate -of XYZ` lists every sample's centre and
/// value (nodata ones too: they are left out here by the value GDAL says is nodata).
fn placed_by_gdal(path: &Path) -> Vec<((i64, i64), u32)> {
    let o = Command::new("gdal_translate")
        .args(["-q", "-of", "XYZ"])
        .arg(path)
        .arg("/vsistdout/")
        .env("GDAL_PAM_ENABLED", "YES")
        .output()
        .expect("run gdal_translate");
    assert!(
        o.status.success(),
        "gdal_translate {}: {}",
        path.display(),
        String::from_utf8_lossy(&o.stderr)
    );
    let mut v: Vec<_> = String::from_utf8_lossy(&o.stdout)
        .lines()
        .filter_map(|l| {
            let f: Vec<f64> = l
                .split_whitespace()
                .map(|t| t.parse().unwrap_or(f64::NAN))
                .collect();
            (f.len() == 3 && f[2].is_finite()).then(|| {
                (
                    ((f[0] * 1e6).round() as i64, (f[1] * 1e6).round() as i64),
                    (f[2] as f32).to_bits(),
                )
            })
        })
        .collect();
    v.sort();
    v
}

// ---------------------------------------------------------------- item 3: south-up rasters

/// A south-up GeoTIFF (row 0 at the south; GDAL writes it with a ModelTransformation): every
/// output of `vtz decode` holds each value where the source has it, for vtz and for GDAL. The
/// GeoTIFF keeps the source's row order with a ModelTransformation (no negative ScaleY,
/// which GDAL reads as north-up); the ASCII grid, which can only say north-up, is flipped;
/// the raw `.f32` sidecar says row 0 is the southern edge.
#[test]
fn south_up_outputs_keep_every_sample_in_place() {
    let src = fixture("south_up.tif");
    let r = read(&src);
    let g = r.georef.clone().unwrap();
    assert_eq!(g.pixel_size, [0.5, -0.25], "read as south-up");
    assert_eq!(g.origin, [10.0, 40.0]);
    let want = placed(&r);
    assert_eq!(want.len(), 35);

    let dir = tempfile::tempdir().unwrap();
    let packed = tmp(&dir, "s.vtz");
    ok(&vtz(["encode", &s(&src), "-o", &packed]));
    let mut outputs = Vec::new();
    for ext in ["tif", "asc", "f32", "exr"] {
        let out = dir.path().join(format!("decoded.{ext}"));
        let o = vtz(["decode", &packed, "-o", &s(&out)]);
        assert!(o.status.success(), "decode .{ext}: {}", stderr(&o));
        let conv = dir.path().join(format!("converted.{ext}"));
        let o = vtz(["convert", &s(&src), &s(&conv)]);
        assert!(o.status.success(), "convert .{ext}: {}", stderr(&o));
        outputs.push(out);
        outputs.push(conv);
    }
    for out in &outputs {
        let back = read(out);
        assert_eq!(placed(&back), want, "{}", out.display());
    }

    // The GeoTIFF: a ModelTransformation with a positive north-south step, no ScaleY < 0.
    for name in ["decoded.tif", "converted.tif"] {
        let f = std::fs::File::open(dir.path().join(name)).unwrap();
        let mut d = tiff::decoder::Decoder::new(f).unwrap();
        let scale = d.find_tag(tiff::tags::Tag::ModelPixelScaleTag).unwrap();
        if let Some(v) = scale {
            let v = v.into_f64_vec().unwrap();
            assert!(v[1] > 0.0, "{name}: ModelPixelScale {v:?}");
        }
        let m = d
            .find_tag(tiff::tags::Tag::ModelTransformationTag)
            .unwrap()
            .expect("a ModelTransformation")
            .into_f64_vec()
            .unwrap();
        assert_eq!(
            m[..8],
            [0.5, 0.0, 0.0, 10.0, 0.0, 0.25, 0.0, 40.0],
            "{name}"
        );
    }
    // The ASCII grid is north-up: row 0 is the source's last row.
    let asc = read(&dir.path().join("decoded.asc"));
    assert_eq!(asc.georef.as_ref().unwrap().pixel_size, [0.5, 0.25]);
    assert_eq!(asc.data[..7], r.data[28..35]);
    // The raw sidecar says which edge row 0 is.
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("decoded.json")).unwrap()).unwrap();
    let order = json["row_order"].as_str().unwrap();
    assert!(order.starts_with("row 0 is the southern"), "{order}");

    if !have("gdal_translate", "GDAL's view of south-up outputs") {
        return;
    }
    let gdal_src = placed_by_gdal(&src);
    assert_eq!(gdal_src, want, "GDAL and vtz place the source alike");
    for out in &outputs {
        // GDAL 3.6 has no EXR driver; its PAM is checked through the GeoTIFF and ASCII cases.
        if out.extension().is_some_and(|e| e == "exr") {
            continue;
        }
        assert_eq!(placed_by_gdal(out), want, "GDAL: {}", out.display());
    }
}

// ---------------------------------------------------------------- item 4: NODATA_value nan

/// `gdal_translate -of AAIGrid` of a float raster whose nodata is NaN: `NODATA_value  nan`
/// and `nan` samples. vtz reads it (NaN is nodata) and encodes it.
#[test]
fn gdal_ascii_grid_with_nan_nodata_is_read() {
    let src = fixture("nan_nodata.asc");
    let text = std::fs::read_to_string(&src).unwrap();
    assert!(text.contains("NODATA_value  nan"), "{text}");
    let r = read(&src);
    assert_eq!((r.width, r.height, r.sample_type), (4, 3, SampleType::F32));
    assert_eq!(r.valid_count(), 11);
    assert!(!r.is_valid(5));
    assert_eq!(r.data[6], 107.0);
    let dir = tempfile::tempdir().unwrap();
    let packed = tmp(&dir, "n.vtz");
    ok(&vtz(["encode", &s(&src), "-o", &packed]));
    let out = dir.path().join("back.asc");
    ok(&vtz(["decode", &packed, "-o", &s(&out)]));
    assert_eq!(placed(&read(&out)), placed(&r));
}

// ---------------------------------------------------------------- item 16: internal masks

/// Where the fixtures' mask lets samples through (make.py's `masked`): outside a disc, and
/// not in the first column.
fn mask_valid(w: usize, h: usize, x: usize, y: usize) -> bool {
    let (wf, hf) = (w as f64, h as f64);
    let r = wf.min(hf) * 0.3;
    let (dx, dy) = (x as f64 - wf * 0.6, y as f64 - hf * 0.4);
    dx * dx + dy * dy > r * r && x != 0
}

fn mask_value(x: usize, y: usize) -> f64 {
    let (x, y) = (x as f64, y as f64);
    f64::from((100.0 + 3.0 * x + 0.5 * y * y + 0.25 * x * y) as f32)
}

fn check_masked(r: &Raster, what: &str) {
    let (w, h) = (r.width, r.height);
    let mut masked = 0;
    for i in 0..r.len() {
        let (x, y) = (i % w, i / w);
        let want = mask_valid(w, h, x, y);
        assert_eq!(r.is_valid(i), want, "{what}: sample ({x}, {y})");
        if want {
            assert_eq!(r.data[i], mask_value(x, y), "{what}: ({x}, {y})");
        } else {
            masked += 1;
        }
    }
    assert!(masked > w, "{what}: the mask masks something");
}

const MASKED: [&str; 5] = [
    "mask_strips.tif",
    "mask_tiles_lzw.tif",
    "mask_packbits.tif",
    "mask_none.tif",
    "mask_cog.tif",
];

/// GDAL's per-dataset internal mask (no nodata tag), in strips, in tiles and in a COG with an
/// overview: the masked samples are nodata, read whole or band by band (the path of large
/// rasters), and `vtz encode` says it read the mask.
#[test]
fn an_internal_mask_band_makes_its_samples_nodata() {
    for name in MASKED {
        let src = fixture(name);
        let r = read(&src);
        assert_eq!(r.nodata, None, "{name}: no nodata tag");
        check_masked(&r, name);

        let mut bands = vtz::formats::open_source(&src, &Default::default()).unwrap();
        let (w, h) = (bands.width(), bands.height());
        let mut data = Vec::new();
        let mut mask = Vec::new();
        let mut y = 0;
        while y < h {
            let rows = 7.min(h - y);
            let b = bands.band(y, rows).unwrap();
            for i in 0..b.len() {
                mask.push(b.is_valid(i));
            }
            data.extend(b.data);
            y += rows;
        }
        let mut streamed = Raster::from_values(w, h, data, None, r.sample_type).unwrap();
        streamed.mask = Some(mask);
        check_masked(&streamed, &format!("{name} by bands"));
        let notes = bands.notes().join("\n");
        assert!(notes.contains("internal mask band"), "{name}: {notes}");
    }
}

/// Through `vtz encode` and `vtz decode`: the masked samples stay nodata in the decoded
/// GeoTIFF (NaN, declared as GDAL_NODATA: every GIS reads that), so GDAL's mask of it is the
/// source's internal mask.
#[test]
fn masked_samples_stay_nodata_through_vtz() {
    let dir = tempfile::tempdir().unwrap();
    for name in ["mask_strips.tif", "mask_cog.tif"] {
        let src = fixture(name);
        let packed = tmp(&dir, &format!("{name}.vtz"));
        let o = vtz(["encode", &s(&src), "-o", &packed]);
        assert!(o.status.success(), "{}", stderr(&o));
        assert!(stderr(&o).contains("internal mask band"), "{}", stderr(&o));
        let out = dir.path().join(format!("{name}.decoded.tif"));
        ok(&vtz(["decode", &packed, "-o", &s(&out)]));
        let back = read(&out);
        assert!(back.nodata.is_none_or(f64::is_nan));
        check_masked(&back, &format!("{name} decoded"));

        if !have("gdal_translate", "GDAL's view of masked samples after vtz") {
            continue;
        }
        // GDAL's mask band (`-b mask`: 255 valid, 0 not) of the decoded file, made from its
        // nodata, is the source's internal mask, sample for sample.
        let mask = |p: &Path| -> Vec<String> {
            let o = Command::new("gdal_translate")
                .args(["-q", "-b", "mask", "-of", "XYZ"])
                .arg(p)
                .arg("/vsistdout/")
                .env("GDAL_PAM_ENABLED", "NO")
                .output()
                .expect("run gdal_translate");
            assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
            String::from_utf8_lossy(&o.stdout)
                .lines()
                .map(String::from)
                .collect()
        };
        let want = mask(&src);
        assert!(
            want.iter().any(|l| l.ends_with(" 0")),
            "{name}: GDAL sees the mask"
        );
        assert_eq!(mask(&out), want, "{name}: GDAL's mask of the decoded file");
    }
}

// ---------------------------------------------------------------- item 13: PNG codes

/// A 16-bit PNG of SRTM heights + 32768 read without a mapping: the codes are read as they
/// are, and `vtz encode` says what `--png-offset -32768 --png-nodata 0` would read.
#[test]
fn png_codes_around_32768_get_a_note() {
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (40usize, 30usize);
    let codes: Vec<f64> = (0..w * h)
        .map(|i| {
            if i == 17 {
                0.0
            } else {
                32731.0 + (i % 1524) as f64
            }
        })
        .collect();
    let r = Raster::from_values(w, h, codes, None, SampleType::U16).unwrap();
    let png = dir.path().join("srtm.png");
    vtz::write_path(&r, &png, &Default::default()).unwrap();
    let o = vtz(["encode", &s(&png), "-o", &tmp(&dir, "a.vtz")]);
    assert!(o.status.success(), "{}", stderr(&o));
    let e = stderr(&o);
    let note: Vec<&str> = e.lines().filter(|l| l.contains("--png-offset")).collect();
    assert_eq!(note.len(), 1, "{e}");
    assert!(note[0].starts_with("note: "), "{e}");
    assert!(
        note[0].contains("32731…33930") && note[0].contains("-37…1162 m"),
        "{}",
        note[0]
    );
    assert!(
        note[0].contains("code 0 (1 sample here) as nodata"),
        "{}",
        note[0]
    );
    // Told the mapping, nothing to say.
    let o = vtz([
        "encode",
        &s(&png),
        "-o",
        &tmp(&dir, "b.vtz"),
        "--png-offset",
        "-32768",
        "--png-nodata",
        "0",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(!stderr(&o).contains("--png-offset"), "{}", stderr(&o));
    // Codes far from 32768 (a 0–4000 m raster in metres): no note.
    let r =
        Raster::from_values(4, 1, vec![0.0, 10.0, 2000.0, 4000.0], None, SampleType::U16).unwrap();
    let plain = dir.path().join("plain.png");
    vtz::write_path(&r, &plain, &Default::default()).unwrap();
    let o = vtz(["encode", &s(&plain), "-o", &tmp(&dir, "c.vtz")]);
    assert!(!stderr(&o).contains("--png-offset"), "{}", stderr(&o));
}

// ---------------------------------------------------------------- item 19: Terrarium

/// A Terrarium PNG (`(R·256 + G + B/256) - 32768`) is read with `--from terrarium` (and
/// `--format terrarium`), exactly; an unknown name lists the known ones.
#[test]
fn terrarium_pngs_are_read() {
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (9u32, 5u32);
    let heights: Vec<f64> = (0..w * h)
        .map(|i| -412.5 + f64::from(i) * 97.25 + f64::from(i % 3) / 256.0)
        .collect();
    let mut px = Vec::new();
    for &v in &heights {
        let code = ((v + 32768.0) * 256.0) as u32;
        px.extend_from_slice(&[(code >> 16) as u8, (code >> 8) as u8, code as u8]);
    }
    let png = dir.path().join("tile.png");
    image::save_buffer(&png, &px, w, h, image::ExtendedColorType::Rgb8).unwrap();

    let out = dir.path().join("tile.tif");
    let o = vtz(["convert", &s(&png), &s(&out), "--from", "terrarium"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let r = read(&out);
    assert_eq!(r.data, heights);
    let packed = tmp(&dir, "t.vtz");
    let o = vtz(["encode", &s(&png), "--format", "terrarium", "-o", &packed]);
    assert!(o.status.success(), "{}", stderr(&o));
    // Decoded back to a PNG, it is a Terrarium PNG again, byte for byte the same pixels.
    let back = dir.path().join("back.png");
    ok(&vtz(["decode", &packed, "-o", &s(&back)]));
    let pixels = |p: &Path| image::open(p).unwrap().to_rgb8().into_raw();
    assert_eq!(pixels(&back), px);

    let o = vtz([
        "convert",
        &s(&png),
        &s(&out),
        "--from",
        "terarium",
        "--force",
    ]);
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(
        e.contains("unknown raster format 'terarium'") && e.contains("terrarium"),
        "{e}"
    );
}

// ---------------------------------------------------------------- item 19: compound CRS

/// A GeoTIFF whose keys give a vertical CRS besides the horizontal one (as GDAL writes
/// `-a_srs EPSG:32611+5703`): `vtz info` names both parts.
#[test]
fn info_names_both_parts_of_a_compound_crs() {
    let dir = tempfile::tempdir().unwrap();
    let mut r = Raster::from_values(
        3,
        2,
        vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0],
        None,
        SampleType::F32,
    )
    .unwrap();
    r.georef = Some(Georef {
        origin: [500000.0, 4100000.0],
        pixel_size: [30.0, 30.0],
        raster_type: RasterType::Area,
        epsg: Some(32611),
        wkt: None,
        geokeys: Some(GeoKeys {
            directory: vec![
                1, 1, 0, 5, 1024, 0, 1, 1, 1025, 0, 1, 1, 3072, 0, 1, 32611, 4096, 0, 1, 5703,
                4097, 34737, 14, 0,
            ],
            doubles: vec![],
            ascii: "NAVD88 height|".to_string(),
        }),
    });
    let tif = dir.path().join("compound.tif");
    vtz::write_path(&r, &tif, &Default::default()).unwrap();
    let packed = tmp(&dir, "c.vtz");
    ok(&vtz(["encode", &s(&tif), "-o", &packed]));
    let o = vtz(["info", &packed]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    let line = out.lines().find(|l| l.starts_with("crs ")).unwrap_or("");
    assert_eq!(
        line, "crs           EPSG:32611 + vertical EPSG:5703 (NAVD88 height)",
        "{out}"
    );
}
