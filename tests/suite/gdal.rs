//! What GDAL (and so QGIS) sees in vtz's outputs.
//!
//! For every output format that can carry georeferencing (tif, png, exr, asc), a corpus raster
//! written by `vtz convert` and by `vtz encode` + `vtz decode` must give `gdalinfo -json` the
//! geotransform, EPSG code and nodata that GDAL reads from the *source* file: GDAL itself is
//! the reference. Tests that need `gdalinfo` print `SKIPPED (gdalinfo not found): …` to stderr
//! and return when it is absent. The sidecar contents (.prj, world file, .aux.xml) and the
//! GDAL_METADATA round trips are checked without GDAL.

use crate::common;

use common::{decode_opts, encode_opts, ok, tmp, vtz};
use serde_json::Value;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;

const TUJUNGA: &str = "srtm30m_bigtujunga_utm11.tif"; // UTM 11N, pixel is area, nodata 32767
const KAUAI: &str = "srtm3_N22W160_kauai.hgt"; // EPSG:4326, pixel is point, voids

fn corpus(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("corpus")
        .join(name)
}

/// Say why a check did not run, on the process's stderr itself: the test harness captures
/// `eprintln!` of passing tests, and a skip must not pass silently.
fn skipped(line: &str) {
    let _ = writeln!(std::io::stderr(), "{line}");
}

/// Whether `gdalinfo` runs here; if not, says so on stderr (the test then returns).
fn have_gdalinfo(what: &str) -> bool {
    match Command::new("gdalinfo").arg("--version").output() {
        Ok(o) if o.status.success() => true,
        _ => {
            skipped(&format!("SKIPPED (gdalinfo not found): {what}"));
            false
        }
    }
}

/// `gdalinfo -json PATH`.
fn gdalinfo(path: &Path) -> Value {
    let o = Command::new("gdalinfo")
        .arg("-json")
        .arg(path)
        .output()
        .expect("run gdalinfo");
    assert!(
        o.status.success(),
        "gdalinfo {}: {}",
        path.display(),
        String::from_utf8_lossy(&o.stderr)
    );
    serde_json::from_slice(&o.stdout).expect("gdalinfo json")
}

/// What the tests compare of a `gdalinfo -json`.
#[derive(Debug)]
struct Seen {
    geotransform: Vec<f64>,
    epsg: Option<u64>,
    /// NaN when GDAL says "NaN".
    nodata: Option<f64>,
    offset: Option<f64>,
    scale: Option<f64>,
    /// Dataset metadata, default domain.
    metadata: Value,
    band: Value,
}

fn seen_direct(path: &Path) -> Seen {
    let d = gdalinfo(path);
    let band = d["bands"][0].clone();
    let nodata = match &band["noDataValue"] {
        Value::Null => None,
        Value::String(s) if s.eq_ignore_ascii_case("nan") => Some(f64::NAN),
        v => Some(v.as_f64().unwrap_or_else(|| panic!("nodata {v}"))),
    };
    Seen {
        geotransform: d["geoTransform"]
            .as_array()
            .unwrap_or_else(|| panic!("{}: no geotransform", path.display()))
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect(),
        epsg: d["stac"]["proj:epsg"].as_u64(),
        nodata,
        offset: band["offset"].as_f64(),
        scale: band["scale"].as_f64(),
        metadata: d["metadata"][""].clone(),
        band,
    }
}

/// Same geotransform up to the digits `gdalinfo -json` prints (16 significant ones).
fn assert_geotransform(got: &[f64], want: &[f64], what: &str) {
    assert_eq!(got.len(), 6, "{what}");
    for (g, w) in got.iter().zip(want) {
        let tol = 1e-13 * g.abs().max(w.abs()) + 1e-15;
        assert!(
            (g - w).abs() <= tol,
            "{what}: geotransform {got:?}, want {want:?}"
        );
    }
}

/// The sources as GDAL opens them: GDAL's SRTMHGT driver insists on the tile's own name.
fn sources(dir: &tempfile::TempDir) -> Vec<(&'static str, PathBuf)> {
    let hgt = dir.path().join("N22W160.hgt");
    std::fs::copy(corpus(KAUAI), &hgt).unwrap();
    vec![("tujunga", corpus(TUJUNGA)), ("kauai", hgt)]
}

/// `vtz convert` and `vtz encode` + `vtz decode` of `src` into `NAME.ext`; the paths.
fn outputs(dir: &tempfile::TempDir, name: &str, src: &Path, ext: &str) -> Vec<PathBuf> {
    let s = |p: &Path| p.to_string_lossy().into_owned();
    // Kauai has values below 0 (and voids): a 16-bit PNG needs an offset for them.
    let png_args: Vec<String> = if ext == "png" && name == "kauai" {
        ["--png-offset", "-32768", "--png-nodata", "0"]
            .map(String::from)
            .to_vec()
    } else {
        vec![]
    };
    let conv = dir.path().join(format!("{name}_convert.{ext}"));
    let mut args = vec!["convert".to_string(), s(src), s(&conv)];
    args.extend(png_args.iter().cloned());
    ok(&vtz(&args));
    let packed = tmp(dir, &format!("{name}_{ext}.vtz"));
    ok(&vtz([
        "encode".to_string(),
        s(src),
        "-o".into(),
        packed.clone(),
    ]));
    let dec = dir.path().join(format!("{name}_decode.{ext}"));
    let mut args = vec!["decode".to_string(), packed, "-o".into(), s(&dec)];
    args.extend(png_args);
    ok(&vtz(&args));
    vec![conv, dec]
}

/// Every output of every source, through `gdalinfo`, against GDAL's view of the source.
/// `check(name, source_view, output_path, output_view)` adds the format's own expectations.
fn check_format(ext: &str, check: impl Fn(&str, &Seen, &Path, &Seen)) {
    let dir = tempfile::tempdir().unwrap();
    for (name, src) in sources(&dir) {
        let want = seen(&src);
        for out in outputs(&dir, name, &src, ext) {
            let what = out.file_name().unwrap().to_string_lossy().into_owned();
            let got = seen(&out);
            assert_geotransform(&got.geotransform, &want.geotransform, &what);
            assert!(
                want.epsg.is_some(),
                "{name}: GDAL names the source's EPSG code"
            );
            assert_eq!(got.epsg, want.epsg, "{what}: EPSG");
            check(name, &want, &out, &got);
        }
    }
}

#[test]
fn gdal_reads_geotiff_outputs() {
    if !have_gdalinfo("GeoTIFF outputs") {
        return;
    }
    check_format("tif", |_, want, out, got| {
        assert_eq!(got.nodata, want.nodata, "{}", out.display());
        assert_eq!(
            got.metadata["AREA_OR_POINT"],
            want.metadata["AREA_OR_POINT"]
        );
        // GDAL_METADATA items (tujunga: DataType=Generic) are back.
        assert_eq!(got.metadata["DataType"], want.metadata["DataType"]);
    });
}

#[test]
fn gdal_reads_raw_f32_outputs() {
    if !have_gdalinfo("raw .f32 outputs (ENVI .hdr)") {
        return;
    }
    check_format("f32", |_, want, out, got| {
        assert_eq!(got.nodata, want.nodata, "{}", out.display());
        assert!(out.with_extension("hdr").exists());
    });
}

#[test]
fn gdal_reads_png_outputs() {
    if !have_gdalinfo("PNG outputs (world file + .aux.xml)") {
        return;
    }
    check_format("png", |name, want, out, got| {
        // GDAL reads the stored codes: nodata is the code, the value mapping its offset and
        // scale, so code → value gives the source's values.
        let sidecar: Value = serde_json::from_slice(
            &std::fs::read(format!("{}.json", out.display())).unwrap_or_default(),
        )
        .unwrap_or(Value::Null);
        match name {
            "kauai" => {
                assert_eq!(got.nodata, Some(0.0), "{}", out.display());
                assert_eq!((got.offset, got.scale), (Some(-32768.0), Some(1.0)));
                assert_eq!(sidecar["nodata_code"], 0);
            }
            _ => {
                assert_eq!(got.nodata, want.nodata, "{}", out.display());
                assert_eq!((got.offset, got.scale), (None, None));
            }
        }
        assert_eq!(
            got.metadata["AREA_OR_POINT"],
            want.metadata["AREA_OR_POINT"]
        );
        assert_eq!(got.metadata["DataType"], want.metadata["DataType"]);
        // Without the PAM file, the world file alone still places it.
        let aux = format!("{}.aux.xml", out.display());
        let kept = std::fs::read(&aux).unwrap();
        std::fs::remove_file(&aux).unwrap();
        assert_geotransform(&seen(out).geotransform, &want.geotransform, "world file");
        std::fs::write(&aux, kept).unwrap();
    });
}

#[test]
fn gdal_reads_asc_outputs() {
    if !have_gdalinfo("ESRI ASCII outputs (.prj)") {
        return;
    }
    check_format("asc", |_, want, out, got| {
        assert_eq!(got.nodata, want.nodata, "{}", out.display());
        // Tujunga's GDAL_METADATA reaches GDAL through the .asc.aux.xml.
        assert_eq!(got.metadata["DataType"], want.metadata["DataType"]);
    });
}

#[test]
fn gdal_reads_exr_outputs() {
    if !have_gdalinfo("OpenEXR outputs (.aux.xml)") {
        return;
    }
    let has_exr = Command::new("gdalinfo")
        .arg("--formats")
        .output()
        .is_ok_and(|o| String::from_utf8_lossy(&o.stdout).contains("EXR -raster-"));
    if !has_exr {
        // Debian's GDAL 3.6 is built without OpenEXR. GDAL reads a PAM file the same way for
        // every driver, so the .exr.aux.xml is checked beside a GeoTIFF stand-in of the same
        // size that has no georeferencing or nodata of its own.
        skipped(
            "SKIPPED (this GDAL has no EXR driver): direct EXR read; checking NAME.exr.aux.xml \
             through a GeoTIFF stand-in instead",
        );
    }
    check_format("exr", |_, want, out, got| {
        // The EXR holds NaN wherever a sample is missing.
        assert!(
            got.nodata.is_some_and(f64::is_nan),
            "{}: {:?}",
            out.display(),
            got.nodata
        );
        assert_eq!(
            got.metadata["AREA_OR_POINT"],
            want.metadata["AREA_OR_POINT"]
        );
        assert_eq!(got.metadata["DataType"], want.metadata["DataType"]);
    });
}

/// `gdalinfo` on an EXR, or on a GeoTIFF stand-in carrying its `.aux.xml` when this GDAL
/// cannot open EXR (see `gdal_reads_exr_outputs`).
fn seen(path: &Path) -> Seen {
    if path.extension().is_some_and(|e| e == "exr")
        && !Command::new("gdalinfo")
            .arg("--formats")
            .output()
            .is_ok_and(|o| String::from_utf8_lossy(&o.stdout).contains("EXR -raster-"))
    {
        let r = vtz::read_path(path, &Default::default()).unwrap();
        let stand_in = path.with_extension("standin.tif");
        let o = Command::new("gdal_create")
            .args(["-of", "GTiff", "-ot", "Float32", "-bands", "1", "-outsize"])
            .arg(r.width.to_string())
            .arg(r.height.to_string())
            .arg(&stand_in)
            .output()
            .expect("run gdal_create");
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        std::fs::copy(
            format!("{}.aux.xml", path.display()),
            format!("{}.aux.xml", stand_in.display()),
        )
        .unwrap();
        return seen_direct(&stand_in);
    }
    seen_direct(path)
}

// ------------------------------------------------------------ sidecar contents, no GDAL

fn read(path: &Path) -> vtz::Raster {
    vtz::read_path(path, &Default::default()).unwrap()
}

fn write(r: &vtz::Raster, path: &Path) {
    vtz::write_path(r, path, &Default::default()).unwrap();
}

#[test]
fn asc_gets_a_prj_that_reads_back() {
    let dir = tempfile::tempdir().unwrap();
    for (src, code, wkt) in [
        (TUJUNGA, 32611, crs_definitions::EPSG_32611.wkt),
        (KAUAI, 4326, crs_definitions::EPSG_4326.wkt),
    ] {
        let r = read(&corpus(src));
        let asc = dir.path().join(format!("{code}.asc"));
        write(&r, &asc);
        let prj = std::fs::read_to_string(dir.path().join(format!("{code}.prj"))).unwrap();
        assert_eq!(prj, format!("{wkt}\n"), "{src}");
        let back = read(&asc);
        let g = back.georef.as_ref().unwrap();
        assert_eq!(
            g.epsg,
            Some(code),
            "{src}: EPSG from the .prj's root AUTHORITY"
        );
        assert_eq!(g.wkt.as_deref(), Some(wkt), "{src}");
        assert_eq!(g.origin, r.georef.as_ref().unwrap().origin, "{src}");
        // Written again, the .prj is the text that was read, byte for byte.
        let again = dir.path().join(format!("{code}_again.asc"));
        write(&back, &again);
        let prj2 = std::fs::read_to_string(dir.path().join(format!("{code}_again.prj"))).unwrap();
        assert_eq!(prj2, prj);
    }
}

#[test]
fn a_prj_vtz_cannot_interpret_is_kept_and_never_fails() {
    let dir = tempfile::tempdir().unwrap();
    let asc = dir.path().join("g.asc");
    std::fs::write(
        &asc,
        "ncols 2\nnrows 1\nxllcorner 0\nyllcorner 0\ncellsize 1\n1 2\n",
    )
    .unwrap();
    // No .prj: no CRS.
    let g = read(&asc).georef.unwrap();
    assert_eq!((g.epsg, g.wkt), (None, None));
    for (text, epsg) in [
        // ESRI's flavour names no authority.
        (
            "PROJCS[\"NAD_1983_UTM_Zone_11N\",GEOGCS[\"GCS_North_American_1983\"]]",
            None,
        ),
        ("whatever this is", None),
        ("GEOGCS[\"NAD83\",AUTHORITY[\"EPSG\",\"4269\"]]", Some(4269)),
    ] {
        std::fs::write(dir.path().join("g.prj"), format!("{text}\r\n")).unwrap();
        let g = read(&asc).georef.unwrap();
        assert_eq!((g.wkt.as_deref(), g.epsg), (Some(text), epsg));
    }
    // The uppercase name of old ESRI exports is found too.
    std::fs::remove_file(dir.path().join("g.prj")).unwrap();
    std::fs::write(dir.path().join("g.PRJ"), b"GEOGCS[\"Bogot\xe1\"]").unwrap();
    let g = read(&asc).georef.unwrap();
    if dir.path().join("g.prj").exists() {
        // A case-insensitive file system: the same file.
        assert!(g.wkt.is_some());
    } else {
        assert_eq!(g.wkt.as_deref(), Some("GEOGCS[\"Bogot\u{e1}\"]"));
    }
}

#[test]
fn png_world_file_and_aux_xml_content() {
    let dir = tempfile::tempdir().unwrap();
    let r = read(&corpus(TUJUNGA));
    let png = dir.path().join("t.png");
    write(&r, &png);
    // World file: pixel sizes, then the centre of the upper-left pixel.
    let pgw = std::fs::read_to_string(dir.path().join("t.pgw")).unwrap();
    let nums: Vec<f64> = pgw.lines().map(|l| l.parse().unwrap()).collect();
    let [x0, y0] = [376313.6554542635, 3807917.8276283755];
    assert_eq!(nums, [30.0, 0.0, 0.0, -30.0, x0 + 15.0, y0 - 15.0]);
    // PAM: the CRS, the corner geotransform (exact), nodata, GDAL_METADATA's item.
    let aux = std::fs::read_to_string(dir.path().join("t.png.aux.xml")).unwrap();
    let wkt = crs_definitions::EPSG_32611.wkt.replace('"', "&quot;");
    assert!(aux.contains(&format!("<SRS>{wkt}</SRS>")), "{aux}");
    let gt: Vec<f64> = aux
        .split("<GeoTransform>")
        .nth(1)
        .and_then(|s| s.split("</GeoTransform>").next())
        .unwrap()
        .split(',')
        .map(|t| t.trim().parse().unwrap())
        .collect();
    assert_eq!(gt, [x0, 30.0, 0.0, y0, 0.0, -30.0]);
    assert!(
        aux.contains("<MDI key=\"AREA_OR_POINT\">Area</MDI>"),
        "{aux}"
    );
    assert!(aux.contains("<MDI key=\"DataType\">Generic</MDI>"), "{aux}");
    assert!(aux.contains("<NoDataValue>32767.0</NoDataValue>"), "{aux}");
    // vtz still reads its own sidecar, and ignores GDAL's files.
    let back = read(&png);
    assert_eq!(back.georef, r.georef);
    assert_eq!(back.data, r.data);

    // Pixel is point: the geotransform's corner is half a pixel out, the world file's
    // reference point is the post itself.
    let k = read(&corpus(KAUAI));
    let o =
        vtz::formats::WriteOptions::default().with_png_mapping(Some(vtz::formats::PngMapping {
            scale: 1.0,
            offset: -32768.0,
            nodata_code: Some(0),
        }));
    let kpng = dir.path().join("k.png");
    vtz::write_path(&k, &kpng, &o).unwrap();
    let pgw = std::fs::read_to_string(dir.path().join("k.pgw")).unwrap();
    let d = 1.0 / 1200.0;
    let nums: Vec<f64> = pgw.lines().map(|l| l.parse().unwrap()).collect();
    assert_eq!(nums, [d, 0.0, 0.0, -d, -160.0, 23.0]);
    let aux = std::fs::read_to_string(dir.path().join("k.png.aux.xml")).unwrap();
    assert!(aux.contains(&format!(
        "<GeoTransform>{:?}, {d:?}, 0.0, {:?}, 0.0, {:?}</GeoTransform>",
        -160.0 - 0.5 * d,
        23.0 + 0.5 * d,
        -d
    )));
    assert!(
        aux.contains("<MDI key=\"AREA_OR_POINT\">Point</MDI>"),
        "{aux}"
    );
    assert!(aux.contains("<NoDataValue>0.0</NoDataValue>"), "{aux}");
    assert!(aux.contains("<Offset>-32768.0</Offset>") && aux.contains("<Scale>1.0</Scale>"));
}

#[test]
fn exr_aux_xml_content_and_stable_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let k = read(&corpus(KAUAI));
    let exr = dir.path().join("k.exr");
    write(&k, &exr);
    let aux = std::fs::read_to_string(dir.path().join("k.exr.aux.xml")).unwrap();
    let wkt = crs_definitions::EPSG_4326.wkt.replace('"', "&quot;");
    assert!(aux.contains(&format!("<SRS>{wkt}</SRS>")), "{aux}");
    assert!(aux.contains("<NoDataValue>nan</NoDataValue>"), "{aux}");
    // The same raster gives the same EXR bytes (the exr crate's attribute map is unordered).
    let exr2 = dir.path().join("k2.exr");
    write(&k, &exr2);
    assert!(std::fs::read(&exr).unwrap() == std::fs::read(&exr2).unwrap());
    // vtz reads its own attributes back.
    assert_eq!(read(&exr).georef, k.georef);
}

// ------------------------------------------------------------ GDAL_METADATA

const META: &str = "<GDALMetadata>\n  <Item name=\"DataType\">Generic</Item>\n  \
    <Item name=\"DESCRIPTION\" sample=\"0\" role=\"description\">Elevation &amp;amp; relief</Item>\n  \
    <Item name=\"UNITTYPE\" sample=\"0\" role=\"unittype\">metre</Item>\n  \
    <Item name=\"source\" sample=\"0\">SRTM 1\u{2033}</Item>\n</GDALMetadata>\n";

/// A GeoTIFF fixture with richer GDAL_METADATA, made by vtz's own writer. Values are escaped
/// twice, as GDAL writes them (`&` is `&amp;amp;`); GDAL reads `Elevation & relief`.
fn meta_fixture(dir: &tempfile::TempDir) -> PathBuf {
    let mut r = read(&corpus(TUJUNGA));
    r.gdal_metadata = Some(META.into());
    let p = dir.path().join("meta.tif");
    write(&r, &p);
    p
}

#[test]
fn gdal_metadata_survives_tif_to_tif_and_through_vtz() {
    let dir = tempfile::tempdir().unwrap();
    let src = meta_fixture(&dir);
    assert_eq!(read(&src).gdal_metadata.as_deref(), Some(META));
    // tif → tif
    let t2 = dir.path().join("t2.tif");
    ok(&vtz(["convert".as_ref(), src.as_os_str(), t2.as_os_str()]));
    assert_eq!(read(&t2).gdal_metadata.as_deref(), Some(META));
    // tif → vtz → tif, lossless and lossy, whole and windowed
    for extra in [&[][..], &["--max-error", "2"][..]] {
        let packed = dir.path().join("m.vtz");
        let mut args = vec![
            "encode",
            src.to_str().unwrap(),
            "-o",
            packed.to_str().unwrap(),
            "--force",
        ];
        args.extend(extra);
        ok(&vtz(&args));
        for window in [None, Some("10,20,100,50")] {
            let out = dir.path().join("back.tif");
            let mut args = vec![
                "decode",
                packed.to_str().unwrap(),
                "-o",
                out.to_str().unwrap(),
                "--force",
            ];
            if let Some(w) = window {
                args.extend(["--window", w]);
            }
            ok(&vtz(&args));
            assert_eq!(
                read(&out).gdal_metadata.as_deref(),
                Some(META),
                "{extra:?} {window:?}"
            );
        }
    }
    if !have_gdalinfo("GDAL_METADATA as GDAL reads it") {
        return;
    }
    for p in [&src, &t2, &dir.path().join("back.tif")] {
        let s = seen(p);
        assert_eq!(
            s.band["description"],
            "Elevation & relief",
            "{}",
            p.display()
        );
        assert_eq!(s.band["unit"], "metre");
        assert_eq!(s.band["metadata"][""]["source"], "SRTM 1\u{2033}");
        assert_eq!(s.metadata["DataType"], "Generic");
    }
}

#[test]
fn gdal_metadata_reaches_gdal_beside_png_exr_and_asc() {
    let dir = tempfile::tempdir().unwrap();
    let src = meta_fixture(&dir);
    for ext in ["png", "exr", "asc"] {
        let out = dir.path().join(format!("m.{ext}"));
        ok(&vtz(["convert".as_ref(), src.as_os_str(), out.as_os_str()]));
        let aux = std::fs::read_to_string(format!("{}.aux.xml", out.display())).unwrap();
        assert!(
            aux.contains("<Description>Elevation &amp; relief</Description>"),
            "{ext}: {aux}"
        );
        assert!(aux.contains("<UnitType>metre</UnitType>"), "{ext}");
        assert!(
            aux.contains("<MDI key=\"source\">SRTM 1\u{2033}</MDI>"),
            "{ext}"
        );
        if have_gdalinfo(&format!("GDAL_METADATA beside .{ext}")) {
            let s = seen(&out);
            assert_eq!(s.band["description"], "Elevation & relief", "{ext}");
            assert_eq!(s.band["unit"], "metre", "{ext}");
            assert_eq!(s.band["metadata"][""]["source"], "SRTM 1\u{2033}", "{ext}");
            assert_eq!(s.metadata["DataType"], "Generic", "{ext}");
        }
    }
}

#[test]
fn a_window_a_resampling_or_a_lossy_encode_drops_the_sources_statistics() {
    let mut r = read(&corpus(TUJUNGA));
    let with_stats = META.replace(
        "</GDALMetadata>",
        "  <Item name=\"STATISTICS_MAXIMUM\" sample=\"0\">2311</Item>\n</GDALMetadata>",
    );
    r.gdal_metadata = Some(with_stats.clone());
    let bytes = vtz::encode(&r, &Default::default()).unwrap();
    // The whole raster: its statistics still hold, the text is verbatim.
    let whole = vtz::decode(&bytes).unwrap();
    assert_eq!(whole.gdal_metadata.as_deref(), Some(with_stats.as_str()));
    let window = vtz::Window {
        x: 5,
        y: 5,
        width: 40,
        height: 30,
    };
    let part = vtz::decode_with(&bytes, &decode_opts(|o| o.window = Some(window))).unwrap();
    assert_eq!(part.gdal_metadata.as_deref(), Some(META));
    // A lossy encode of the whole: its values differ from the source's by up to the bound.
    let lossy = encode_opts(&[vtz::Method::GRID], Some(vtz::ErrorBound::Abs(2.0)));
    let back = vtz::decode(&vtz::encode(&r, &lossy).unwrap()).unwrap();
    assert_eq!(back.gdal_metadata.as_deref(), Some(META));
    // A resampling: a small part, encoded by sibson.
    let mut small = part;
    small.gdal_metadata = Some(with_stats);
    let opts = encode_opts(&[vtz::Method::SIBSON], Some(vtz::ErrorBound::Abs(5.0)));
    let bytes = vtz::encode(&small, &opts).unwrap();
    let half_scale = vtz::Scale { num: 1, den: 2 };
    let half = vtz::decode_with(&bytes, &decode_opts(|o| o.scale = Some(half_scale))).unwrap();
    assert_eq!(half.gdal_metadata.as_deref(), Some(META));
}

/// `--scale 2` is `gdal_translate -outsize 200% 200%`: twice the samples each way over the
/// same extent, so the geotransform GDAL reads from the output is the source's with the
/// pixel size halved from the same corner; for the pixel-is-point SRTM tile too, whose area
/// pixels GDAL places half a sample beyond the points (vtz keeps the type and moves the
/// first point to the new first pixel's centre).
#[test]
fn scale_2_keeps_the_corner_gdal_sees() {
    let dir = tempfile::tempdir().unwrap();
    let s = |p: &Path| p.to_string_lossy().into_owned();
    for (name, src) in sources(&dir) {
        let packed = tmp(&dir, &format!("{name}_scale.vtz"));
        ok(&vtz([
            "encode",
            &s(&src),
            "-o",
            &packed,
            "--max-error",
            "1",
        ]));
        let out = dir.path().join(format!("{name}_x2.tif"));
        ok(&vtz(["decode", &packed, "-o", &s(&out), "--scale", "2"]));
        let (a, b) = (read(&src), read(&out));
        assert_eq!((b.width, b.height), (2 * a.width, 2 * a.height), "{name}");
        // vtz's own reading: the same corner, half the pixel size, the same pixel type.
        let corner = |g: &vtz::Georef| match g.raster_type {
            vtz::RasterType::Area => g.origin,
            vtz::RasterType::Point => [
                g.origin[0] - g.pixel_size[0] / 2.0,
                g.origin[1] + g.pixel_size[1] / 2.0,
            ],
        };
        let (ga, gb) = (a.georef.as_ref().unwrap(), b.georef.as_ref().unwrap());
        assert_eq!(ga.raster_type, gb.raster_type, "{name}");
        assert_eq!(
            gb.pixel_size,
            [ga.pixel_size[0] / 2.0, ga.pixel_size[1] / 2.0]
        );
        for (u, v) in corner(ga).iter().zip(corner(gb)) {
            assert!(
                (u - v).abs() <= 1e-9 * u.abs().max(1.0),
                "{name}: {ga:?} {gb:?}"
            );
        }
        if !have_gdalinfo(&format!("{name} at --scale 2")) {
            continue;
        }
        let (sa, sb) = (seen_direct(&src), seen_direct(&out));
        let g = &sa.geotransform;
        let want = [g[0], g[1] / 2.0, g[2], g[3], g[4], g[5] / 2.0];
        assert_geotransform(&sb.geotransform, &want, name);
    }
}

/// A CRS the GeoTIFF's keys cannot carry (a WKT without an EPSG code, no stored keys)
/// reaches GDAL through a PAM `.aux.xml` beside the decoded GeoTIFF, with the window's
/// geotransform: untiled and tiled files (the tiled one written band by band), whole and
/// windowed.
#[test]
fn a_wkt_only_crs_reaches_gdal_beside_a_decoded_geotiff() {
    const LAEA: &str = "PROJCS[\"vtz test LAEA\",GEOGCS[\"GRS 1980\",DATUM[\"unknown\",SPHEROID[\"GRS80\",6378137,298.257222101]],PRIMEM[\"Greenwich\",0],UNIT[\"degree\",0.0174532925199433]],PROJECTION[\"Lambert_Azimuthal_Equal_Area\"],PARAMETER[\"latitude_of_center\",52],PARAMETER[\"longitude_of_center\",10],PARAMETER[\"false_easting\",4321000],PARAMETER[\"false_northing\",3210000],UNIT[\"metre\",1]]";
    let dir = tempfile::tempdir().unwrap();
    let mut r = read(&corpus("srtm3_N22W160_kauai.hgt"));
    r.georef = Some(vtz::Georef {
        origin: [4_000_000.0, 3_000_000.0],
        pixel_size: [100.0, 100.0],
        raster_type: vtz::RasterType::Area,
        epsg: None,
        wkt: Some(LAEA.into()),
        geokeys: None,
    });
    for tile in [None, Some(512)] {
        let mut o = vtz::EncodeOptions::default();
        o.max_error = Some(vtz::ErrorBound::Abs(1.0));
        o.tile = tile;
        let bytes = vtz::encode(&r, &o).unwrap();
        let f = dir.path().join("laea.vtz");
        std::fs::write(&f, &bytes).unwrap();
        for (win, origin) in [
            (None, [4_000_000.0, 3_000_000.0]),
            (Some("100,200,300,300"), [4_010_000.0, 2_980_000.0]),
        ] {
            let what = format!("tile {tile:?} window {win:?}");
            let out = dir.path().join("laea.tif");
            // No earlier iteration's sidecar may answer for this one.
            let _ = std::fs::remove_file(dir.path().join("laea.tif.aux.xml"));
            let mut args = vec![
                "decode".to_string(),
                f.display().to_string(),
                "-o".into(),
                out.display().to_string(),
                "-f".into(),
                "-q".into(),
            ];
            if let Some(w) = win {
                args.extend(["--window".into(), w.into()]);
            }
            let o = Command::new(env!("CARGO_BIN_EXE_vtz"))
                .args(&args)
                .output()
                .unwrap();
            assert!(
                o.status.success(),
                "{what}: {}",
                String::from_utf8_lossy(&o.stderr)
            );
            let aux =
                std::fs::read_to_string(dir.path().join("laea.tif.aux.xml")).expect("an .aux.xml");
            assert!(
                aux.contains("Lambert_Azimuthal_Equal_Area"),
                "{what}: {aux}"
            );
            if !have_gdalinfo(&what) {
                continue;
            }
            let d = gdalinfo(&out);
            let wkt = d["coordinateSystem"]["wkt"].as_str().unwrap_or_default();
            assert!(
                wkt.contains("Lambert Azimuthal Equal Area") && wkt.contains("4321000"),
                "{what}: {wkt}"
            );
            let gt: Vec<f64> = d["geoTransform"]
                .as_array()
                .unwrap()
                .iter()
                .map(|v| v.as_f64().unwrap())
                .collect();
            assert_eq!(
                gt,
                vec![origin[0], 100.0, 0.0, origin[1], 0.0, -100.0],
                "{what}"
            );
        }
    }
}

/// Issue 35, items 2 and 11: integer codes whose values go below 0 (a u16 PNG of SRTM
/// heights + 32768, read with `--png-offset -32768`) decode and convert to a GeoTIFF of the
/// values' own type, Int16 (it was Float32), tiled and untiled; `vtz info` names it beside
/// the codes' type.
#[test]
fn mapped_u16_codes_decode_to_int16_values() {
    let dir = tempfile::tempdir().unwrap();
    let pm = vtz::formats::PngMapping {
        scale: 1.0,
        offset: -32768.0,
        nodata_code: None,
    };
    let ro = vtz::formats::ReadOptions::default().with_png_mapping(Some(pm.clone()));
    let full = vtz::read_path(&corpus("srtm1_N45E013_istria_crop2400.png"), &ro).unwrap();
    // 2400 x 600 rows of the coast (values -29 ... 1023 m), as the same kind of PNG.
    let (w, h) = (full.width, 600);
    let mut r = vtz::Raster::from_values(
        w,
        h,
        full.data[..w * h].to_vec(),
        None,
        vtz::SampleType::U16,
    )
    .unwrap();
    r.mapping = full.mapping;
    assert!(
        r.data.iter().any(|&v| v < 0.0),
        "the crop has heights below 0"
    );
    let png = dir.path().join("istria.png");
    let wo = vtz::formats::WriteOptions::default().with_png_mapping(Some(pm));
    vtz::write_path(&r, &png, &wo).unwrap();
    let s = |p: &Path| p.to_string_lossy().into_owned();
    let conv = dir.path().join("convert.tif");
    ok(&vtz([
        "convert",
        &s(&png),
        &s(&conv),
        "--png-offset",
        "-32768",
    ]));
    let back = read(&conv);
    assert_eq!(back.sample_type, vtz::SampleType::I16, "convert");
    assert!(back.mapping.is_identity());
    assert_eq!(back.data, r.data, "convert is exact");
    for tile in ["512", "0"] {
        let packed = tmp(&dir, &format!("istria_{tile}.vtz"));
        ok(&vtz([
            "encode",
            &s(&png),
            "--png-offset",
            "-32768",
            "-o",
            &packed,
            "--max-error",
            "1",
            "--tile",
            tile,
        ]));
        let info = common::json(&vtz(["info", "--json", &packed]));
        assert_eq!(info["sample_type"], "u16");
        assert_eq!(info["output_type"]["type"], "i16", "{info}");
        assert!(info["output_type"]["scale"].is_null());
        let text = String::from_utf8_lossy(&vtz(["info", &packed]).stdout).into_owned();
        assert!(text.contains("values as     i16"), "{text}");
        let dec = dir.path().join(format!("decode_{tile}.tif"));
        ok(&vtz(["decode", &packed, "-o", &s(&dec)]));
        let got = read(&dec);
        assert_eq!(got.sample_type, vtz::SampleType::I16, "decode, tile {tile}");
        let worst = got
            .data
            .iter()
            .zip(&r.data)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(worst <= 1.0, "tile {tile}: max error {worst}");
        if have_gdalinfo("the decoded GeoTIFF's band type") {
            let band = &gdalinfo(&dec)["bands"][0];
            assert_eq!(band["type"], "Int16", "{band}");
            assert!(
                band["scale"].is_null() && band["offset"].is_null(),
                "{band}"
            );
        }
    }
}

/// Issue 35, item 6: an Int16 GeoTIFF of codes with a GDAL scale of 10 (metres): the bound
/// of `--max-error` is in metres, the values GDAL shows (it bounded the codes, so metres
/// moved by 10); encode, info and compare say so; scale, offset and unit come back.
#[test]
fn a_gdal_scale_makes_the_bound_metres() {
    let dir = tempfile::tempdir().unwrap();
    let s = |p: &Path| p.to_string_lossy().into_owned();
    let mut codes = read(&corpus(KAUAI));
    codes.gdal_metadata = Some(
        "<GDALMetadata>\n  <Item name=\"SCALE\" sample=\"0\" role=\"scale\">10</Item>\n  \
         <Item name=\"UNITTYPE\" sample=\"0\" role=\"unittype\">metre</Item>\n</GDALMetadata>"
            .into(),
    );
    // Written as GDAL writes it: the codes and the GDAL_METADATA items (identity mapping).
    let src = dir.path().join("scaled.tif");
    codes.mapping = vtz::ValueMapping::default();
    vtz::formats::write_file(&src, vtz::formats::geotiff_bytes(&codes).unwrap(), true).unwrap();
    let packed = tmp(&dir, "scaled.vtz");
    for bound in ["1", "25"] {
        let e: f64 = bound.parse().unwrap();
        let o = vtz([
            "encode",
            &s(&src),
            "-o",
            &packed,
            "--max-error",
            bound,
            "-f",
        ]);
        ok(&o);
        let said = String::from_utf8_lossy(&o.stdout).into_owned() + &common::stderr(&o);
        assert!(
            said.contains("values = 0 + 10 * code") && said.contains("max error is in values"),
            "{said}"
        );
        let info = common::json(&vtz(["info", "--json", &packed]));
        assert_eq!(info["value_scale"], 10.0, "{info}");
        assert!(info["max_error"].as_f64().unwrap() <= e, "{info}");
        let dec = dir.path().join(format!("decoded_{bound}.tif"));
        ok(&vtz(["decode", &packed, "-o", &s(&dec), "-f"]));
        let cmp = vtz(["compare", &s(&src), &s(&dec)]);
        let text = String::from_utf8_lossy(&cmp.stdout).into_owned();
        assert!(text.contains("errors are in values"), "{text}");
        // GDAL's values (offset + scale * code) of source and decode.
        if have_gdalinfo("GDAL's unscaled values of a scaled GeoTIFF") {
            let band = &gdalinfo(&dec)["bands"][0];
            assert_eq!(band["scale"], 10.0, "{band}");
            assert_eq!(band["unit"], "metre", "{band}");
            let metres = |p: &Path, name: &str| {
                let out = dir.path().join(name);
                let st = Command::new("gdal_translate")
                    .args(["-q", "-unscale", "-ot", "Float64"])
                    .arg(p)
                    .arg(&out)
                    .status()
                    .unwrap();
                assert!(st.success());
                read(&out)
            };
            let a = metres(&src, &format!("src_m_{bound}.tif"));
            let b = metres(&dec, &format!("dec_m_{bound}.tif"));
            assert_eq!(a.mask, b.mask);
            let worst = (0..a.len())
                .filter(|&i| a.is_valid(i))
                .map(|i| (a.data[i] - b.data[i]).abs())
                .fold(0.0, f64::max);
            assert!(
                worst <= e,
                "--max-error {bound}: GDAL's values moved by {worst} m"
            );
        }
    }
}
