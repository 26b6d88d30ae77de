//! `vtz._vtz`: the native half of the Python package (numpy arrays in, vtz bytes out, and
//! back). The Python half (`pysrc/vtz/`) checks the arguments' Python types and shapes and
//! builds rasterio-style profiles; this module does the work with the GIL released.
//!
//! Hand-written glue, not a generated binding: the crate's API is small and the numpy
//! conversions (dtype dispatch, nodata, windows) are what a user of the package cares about.

use numpy::ndarray::Array2;
use numpy::{
    IntoPyArray, PyArray2, PyArrayDescrMethods, PyArrayMethods, PyUntypedArray,
    PyUntypedArrayMethods,
};
use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyList, PyTuple, PyType};
use vtz::{
    DecodeOptions, EncodeOptions, Error, ErrorBound, Georef, Method, Raster, RasterType,
    SampleType, Scale, SectionChoice, Window,
};

/// A vtz error as the Python exception of its cause (the classes live in `vtz._errors`, so
/// that they can have two bases: `VtzError` and `ValueError`/`OSError`).
fn to_py(py: Python<'_>, e: Error) -> PyErr {
    let name = match &e {
        Error::Io { .. } => "VtzIOError",
        Error::Corrupt { .. } => "CorruptError",
        Error::Unsupported { .. } => "UnsupportedError",
        Error::InvalidArgument { .. } => "InvalidArgumentError",
        Error::Unmet { .. } => "UnmetError",
        Error::LimitExceeded { .. } => "LimitError",
        _ => "VtzError",
    };
    let msg = python_words(&e.to_string());
    match py
        .import("vtz._errors")
        .and_then(|m| m.getattr(name))
        .and_then(|c| c.cast_into::<PyType>().map_err(PyErr::from))
    {
        Ok(cls) => PyErr::from_type(cls, (msg,)),
        Err(err) => err,
    }
}

/// The library's messages name the command line's flags (`--scale`, `--max-error`); a
/// Python caller reads its own keyword arguments instead (`scale=`, `max_error=`). Flags
/// with no keyword in this package are left as they are.
fn python_words(msg: &str) -> String {
    const WORDS: [(&str, &str); 11] = [
        ("--max-error", "max_error="),
        ("--lossless", "lossless=True"),
        ("--scale", "scale="),
        ("--window", "window="),
        ("--overview", "overview="),
        ("--method", "method="),
        ("--threads", "threads="),
        ("--section", "section="),
        ("--force", "overwrite=True"),
        ("--nodata", "nodata="),
        ("--effort", "effort="),
    ];
    let mut out = String::with_capacity(msg.len());
    let mut rest = msg;
    'scan: while let Some(i) = rest.find("--") {
        out.push_str(&rest[..i]);
        let tail = &rest[i..];
        for (flag, word) in WORDS {
            let whole = tail.strip_prefix(flag).is_some_and(|after| {
                !after.starts_with(|c: char| c.is_ascii_alphanumeric() || c == '-')
            });
            if whole {
                out.push_str(word);
                rest = &tail[flag.len()..];
                continue 'scan;
            }
        }
        out.push_str("--");
        rest = &tail[2..];
    }
    out.push_str(rest);
    out
}

fn invalid(py: Python<'_>, msg: impl Into<String>) -> PyErr {
    to_py(py, Error::invalid(msg))
}

fn sample_type(py: Python<'_>, dtype: &str) -> PyResult<SampleType> {
    Ok(match dtype {
        "uint8" => SampleType::U8,
        "int16" => SampleType::I16,
        "uint16" => SampleType::U16,
        "int32" => SampleType::I32,
        "float32" => SampleType::F32,
        "float64" => SampleType::F64,
        other => {
            return Err(invalid(
                py,
                format!(
                    "dtype {other} is not supported (uint8, int16, uint16, int32, float32, float64)"
                ),
            ));
        }
    })
}

fn dtype_name(t: SampleType) -> &'static str {
    match t {
        SampleType::U8 => "uint8",
        SampleType::I16 => "int16",
        SampleType::U16 => "uint16",
        SampleType::I32 => "int32",
        SampleType::F32 => "float32",
        SampleType::F64 => "float64",
    }
}

/// The array's samples as f64, row-major (the array is 2-D, C-contiguous, native-endian:
/// the Python side checked; checked again here).
fn samples(
    py: Python<'_>,
    a: &Bound<'_, PyUntypedArray>,
) -> PyResult<(usize, usize, Vec<f64>, SampleType)> {
    if a.ndim() != 2 {
        return Err(invalid(
            py,
            format!("the array is {}-D; vtz codes 2-D arrays", a.ndim()),
        ));
    }
    if !a.is_c_contiguous() {
        return Err(invalid(
            py,
            "the array is not C-contiguous (pass numpy.ascontiguousarray(a))",
        ));
    }
    let dt = a.dtype();
    if !dt.is_native_byteorder().unwrap_or(true) {
        return Err(invalid(
            py,
            "the array is not in native byte order (pass a.astype(a.dtype.newbyteorder('=')))",
        ));
    }
    let (h, w) = (a.shape()[0], a.shape()[1]);
    let name: String = dt.getattr("name")?.extract()?;
    let st = sample_type(py, &name)?;
    macro_rules! take {
        ($t:ty) => {{
            let arr = a.cast::<PyArray2<$t>>().map_err(PyErr::from)?.readonly();
            let s = arr
                .as_slice()
                .map_err(|_| invalid(py, "the array is not contiguous"))?;
            s.iter().map(|&v| v as f64).collect::<Vec<f64>>()
        }};
    }
    let data = match st {
        SampleType::U8 => take!(u8),
        SampleType::I16 => take!(i16),
        SampleType::U16 => take!(u16),
        SampleType::I32 => take!(i32),
        SampleType::F32 => take!(f32),
        SampleType::F64 => take!(f64),
    };
    Ok((w, h, data, st))
}

fn parse_bound(py: Python<'_>, b: &Bound<'_, PyAny>) -> PyResult<ErrorBound> {
    if let Ok(s) = b.extract::<String>() {
        return ErrorBound::parse(&s).map_err(|e| to_py(py, e));
    }
    let v: f64 = b.extract().map_err(|_| {
        PyTypeError::new_err("max_error must be a number (data units) or a string like '0.5%'")
    })?;
    if !(v.is_finite() && v >= 0.0) {
        return Err(invalid(
            py,
            format!("max_error {v} is not a finite number >= 0"),
        ));
    }
    Ok(ErrorBound::Abs(v))
}

/// The encoder effort: `None` (the library's default), or an integer 1..=9; anything else
/// (0, 10, -1, a float, a string, a bool) is an `InvalidArgumentError` naming the range.
fn parse_effort(py: Python<'_>, e: Option<&Bound<'_, PyAny>>) -> PyResult<Option<u8>> {
    let Some(e) = e.filter(|e| !e.is_none()) else {
        return Ok(None);
    };
    let shown = || {
        e.repr()
            .map_or_else(|_| "?".to_string(), |r| r.to_string_lossy().into_owned())
    };
    let k = if e.is_instance_of::<pyo3::types::PyBool>() {
        None
    } else {
        e.extract::<i64>().ok()
    };
    match k {
        Some(k @ 1..=9) => Ok(Some(k as u8)),
        _ => Err(invalid(
            py,
            format!(
                "effort {} is not an integer in 1..=9 (None = the default, 5)",
                shown()
            ),
        )),
    }
}

fn encode_options(
    py: Python<'_>,
    max_error: Option<&Bound<'_, PyAny>>,
    lossless: bool,
    method: Option<&str>,
    effort: Option<&Bound<'_, PyAny>>,
    threads: usize,
) -> PyResult<EncodeOptions> {
    let mut o = EncodeOptions::default();
    o.effort = parse_effort(py, effort)?;
    if let Some(b) = max_error {
        if lossless {
            return Err(invalid(
                py,
                "lossless=True and a max_error exclude each other",
            ));
        }
        o.max_error = Some(parse_bound(py, b)?);
    }
    if let Some(m) = method {
        o.methods = Method::parse_list(m).map_err(|e| to_py(py, e))?;
    }
    o.threads = threads;
    Ok(o)
}

fn raster_from(
    py: Python<'_>,
    array: &Bound<'_, PyUntypedArray>,
    nodata: Option<f64>,
    offset_scale: Option<(f64, f64)>,
) -> PyResult<Raster> {
    let (w, h, data, st) = samples(py, array)?;
    // NaN samples are nodata whatever `nodata` says (as in the CLI and GDAL): with another
    // nodata value they decode as that value (`Raster::from_values`).
    if let Some(nd) = nodata
        && let Some((lo, hi)) = st.int_range()
        && !(nd >= lo && nd <= hi && nd.fract() == 0.0)
    {
        return Err(invalid(
            py,
            format!("nodata {nd} is not a value of dtype {}", dtype_name(st)),
        ));
    }
    let nodata = nodata.filter(|v| !v.is_nan());
    let Some((offset, scale)) = offset_scale else {
        return Raster::from_values(w, h, data, nodata, st).map_err(|e| to_py(py, e));
    };
    // Integer codes with an offset and scale (GDAL's): the raster holds their values, so a
    // bound is in values.
    if !st.is_integer() {
        return Err(invalid(
            py,
            format!(
                "scale/offset map integer codes; the array is {}",
                dtype_name(st)
            ),
        ));
    }
    if !(scale.is_finite() && scale != 0.0 && offset.is_finite()) {
        return Err(invalid(
            py,
            format!(
                "scale {scale} / offset {offset} is not usable (a finite scale, not 0, and a finite offset)"
            ),
        ));
    }
    let m = vtz::ValueMapping { scale, offset };
    let values = data.into_iter().map(|c| m.to_value(c)).collect();
    let mut r = Raster::from_values(w, h, values, nodata.map(|c| m.to_value(c)), st)
        .map_err(|e| to_py(py, e))?;
    r.mapping = m;
    Ok(r)
}

/// `(offset, scale)` from the Python side's optional offset and scale (`None` when neither).
fn offset_scale(offset: Option<f64>, scale: Option<f64>) -> Option<(f64, f64)> {
    (offset.is_some() || scale.is_some()).then(|| (offset.unwrap_or(0.0), scale.unwrap_or(1.0)))
}

/// Encode a 2-D array; returns the vtz bytes.
#[pyfunction]
#[pyo3(signature = (array, max_error=None, lossless=false, nodata=None, method=None, threads=0, effort=None, offset=None, scale=None))]
#[allow(clippy::too_many_arguments)]
fn encode<'py>(
    py: Python<'py>,
    array: &Bound<'py, PyUntypedArray>,
    max_error: Option<&Bound<'py, PyAny>>,
    lossless: bool,
    nodata: Option<f64>,
    method: Option<&str>,
    threads: usize,
    effort: Option<&Bound<'py, PyAny>>,
    offset: Option<f64>,
    scale: Option<f64>,
) -> PyResult<Bound<'py, PyBytes>> {
    let opts = encode_options(py, max_error, lossless, method, effort, threads)?;
    let raster = raster_from(py, array, nodata, offset_scale(offset, scale))?;
    let bytes = py
        .detach(|| vtz::on_threads(threads, || vtz::encode(&raster, &opts)).and_then(|r| r))
        .map_err(|e| to_py(py, e))?;
    Ok(PyBytes::new(py, &bytes))
}

fn decode_options(
    py: Python<'_>,
    window: Option<(usize, usize, usize, usize)>,
    scale: Option<&str>,
    overview: Option<u32>,
    threads: usize,
) -> PyResult<DecodeOptions> {
    let mut o = DecodeOptions::default();
    o.window = window.map(|(x, y, width, height)| Window {
        x,
        y,
        width,
        height,
    });
    if let Some(s) = scale {
        o.scale = Some(Scale::parse(s).map_err(|e| to_py(py, e))?);
    }
    o.overview = overview;
    o.threads = threads;
    o.section = SectionChoice::Primary;
    Ok(o)
}

/// A decoded raster as a numpy array of its output type ([`vtz::OutputType`], as GDAL's band:
/// the values in their own dtype or the smallest integer dtype holding them, or the integer
/// codes when the mapping is an offset and scale); nodata: the nodata value (its code), or NaN.
fn to_array<'py>(py: Python<'py>, r: Raster) -> PyResult<Bound<'py, PyAny>> {
    let (w, h) = (r.width, r.height);
    let out = vtz::OutputType::of(r.sample_type, r.mapping, r.nodata);
    let fill = r.nodata.map_or(f64::NAN, |nd| out.stored(nd));
    let mask = r.mask;
    let data = r.data;
    let value = |i: usize| match &mask {
        Some(m) if !m[i] => fill,
        _ => out.stored(data[i]),
    };
    macro_rules! int {
        ($t:ty) => {{
            let mut v: Vec<$t> = Vec::with_capacity(w * h);
            for i in 0..w * h {
                let x = value(i);
                let r = x.round();
                if !(r >= <$t>::MIN as f64 && r <= <$t>::MAX as f64) {
                    return Err(to_py(
                        py,
                        Error::corrupt(format!(
                            "decoded value {x} does not fit {}",
                            stringify!($t)
                        )),
                    ));
                }
                v.push(r as $t);
            }
            Array2::from_shape_vec((h, w), v)
                .expect("sized")
                .into_pyarray(py)
                .into_any()
        }};
    }
    Ok(match out.sample_type() {
        SampleType::U8 => int!(u8),
        SampleType::I16 => int!(i16),
        SampleType::U16 => int!(u16),
        SampleType::I32 => int!(i32),
        SampleType::F32 => {
            let v: Vec<f32> = (0..w * h).map(|i| value(i) as f32).collect();
            Array2::from_shape_vec((h, w), v)
                .expect("sized")
                .into_pyarray(py)
                .into_any()
        }
        SampleType::F64 => {
            let v: Vec<f64> = (0..w * h).map(value).collect();
            Array2::from_shape_vec((h, w), v)
                .expect("sized")
                .into_pyarray(py)
                .into_any()
        }
    })
}

/// Decode vtz bytes into a numpy array.
#[pyfunction]
#[pyo3(signature = (data, window=None, scale=None, overview=None, threads=0))]
fn decode<'py>(
    py: Python<'py>,
    data: &Bound<'py, PyBytes>,
    window: Option<(usize, usize, usize, usize)>,
    scale: Option<&str>,
    overview: Option<u32>,
    threads: usize,
) -> PyResult<Bound<'py, PyAny>> {
    let opts = decode_options(py, window, scale, overview, threads)?;
    let bytes = data.as_bytes();
    let r = py
        .detach(|| vtz::on_threads(threads, || vtz::decode_with(bytes, &opts)).and_then(|r| r))
        .map_err(|e| to_py(py, e))?;
    to_array(py, r)
}

/// The georeferencing as a dict the Python side turns into a profile: the GDAL geotransform
/// of pixel corners (`a, b, c, d, e, f` in affine's order), the EPSG code and the WKT.
fn georef_dict<'py>(py: Python<'py>, g: &Georef) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    let (mut x0, mut y0) = (g.origin[0], g.origin[1]);
    if g.raster_type == RasterType::Point {
        x0 -= 0.5 * g.pixel_size[0];
        y0 += 0.5 * g.pixel_size[1];
    }
    let t = PyTuple::new(py, [g.pixel_size[0], 0.0, x0, 0.0, -g.pixel_size[1], y0])?;
    d.set_item("transform", t)?;
    d.set_item("epsg", g.epsg)?;
    d.set_item("wkt", g.wkt.clone())?;
    d.set_item(
        "raster_type",
        match g.raster_type {
            RasterType::Point => "point",
            _ => "area",
        },
    )?;
    Ok(d)
}

/// What a vtz stream holds, without decoding samples.
#[pyfunction]
fn info<'py>(py: Python<'py>, data: &Bound<'py, PyBytes>) -> PyResult<Bound<'py, PyDict>> {
    let bytes = data.as_bytes();
    let mut dec =
        vtz::Decoder::new(std::io::Cursor::new(bytes.to_vec())).map_err(|e| to_py(py, e))?;
    let fi = dec.info().clone();
    let d = PyDict::new(py);
    d.set_item("width", fi.width)?;
    d.set_item("height", fi.height)?;
    // What `decode` gives: the output type (GDAL's band), its offset and scale when it holds
    // codes; the file's own codes' type and mapping beside.
    let out = vtz::OutputType::of(fi.sample_type, fi.mapping, fi.nodata);
    d.set_item("dtype", dtype_name(out.sample_type()))?;
    d.set_item("offset", out.offset_scale().map(|m| m.offset))?;
    d.set_item("scale", out.offset_scale().map(|m| m.scale))?;
    d.set_item("codes_dtype", dtype_name(fi.sample_type))?;
    d.set_item("value_offset", fi.mapping.offset)?;
    d.set_item("value_scale", fi.mapping.scale)?;
    d.set_item("nodata", fi.nodata)?;
    d.set_item("range", fi.range)?;
    d.set_item("bytes", fi.file_bytes)?;
    let primary = fi.sections.iter().find(|s| s.primary);
    d.set_item(
        "method",
        primary.map(|s| {
            s.method
                .map_or_else(|| s.name.clone(), |m| m.name().to_string())
        }),
    )?;
    let sections = PyList::empty(py);
    for s in &fi.sections {
        let e = PyDict::new(py);
        e.set_item("index", s.index)?;
        e.set_item("name", &s.name)?;
        e.set_item("method", s.method.map(|m| m.name()))?;
        e.set_item("bytes", s.bytes)?;
        e.set_item("primary", s.primary)?;
        e.set_item("required", s.required)?;
        sections.append(e)?;
    }
    d.set_item("sections", sections)?;
    // The bound the file guarantees (0 = lossless), read without decoding.
    let max_error = py.detach(|| dec.max_error()).map_err(|e| to_py(py, e))?;
    d.set_item("max_error", max_error)?;
    match &fi.tiles {
        Some(t) => {
            let td = PyDict::new(py);
            td.set_item("tile_width", t.tile_width)?;
            td.set_item("tile_height", t.tile_height)?;
            td.set_item("cols", t.cols)?;
            td.set_item("rows", t.rows)?;
            d.set_item("tiles", td)?;
        }
        None => d.set_item("tiles", py.None())?,
    }
    match &fi.georef {
        Some(g) => d.set_item("georef", georef_dict(py, g)?)?,
        None => d.set_item("georef", py.None())?,
    }
    Ok(d)
}

/// Read any raster file vtz reads; returns `(array, georef dict or None, nodata)`.
#[pyfunction]
fn read<'py>(py: Python<'py>, path: std::path::PathBuf) -> PyResult<Bound<'py, PyTuple>> {
    let r = py
        .detach(|| vtz::read_path(&path, &Default::default()))
        .map_err(|e| to_py(py, e.context(path.display())))?;
    let georef = match &r.georef {
        Some(g) => georef_dict(py, g)?.into_any(),
        None => py.None().into_bound(py),
    };
    // As the array holds them: the nodata value's code, and the offset and scale, when the
    // array holds codes.
    let out = vtz::OutputType::of(r.sample_type, r.mapping, r.nodata);
    let nodata = r.nodata.map(|nd| out.stored(nd));
    let os = out.offset_scale().map(|m| (m.offset, m.scale));
    let arr = to_array(py, r)?;
    PyTuple::new(
        py,
        [
            arr,
            georef,
            nodata.into_pyobject(py)?.into_any(),
            os.into_pyobject(py)?.into_any(),
        ],
    )
}

/// Write an array to a raster file (the format from the extension; `.vtz` is encoded with
/// the bound given). `georef`: `(transform 6-tuple, epsg or None, wkt or None)`.
#[pyfunction]
#[pyo3(signature = (path, array, nodata=None, transform=None, epsg=None, wkt=None, max_error=None, lossless=false, method=None, force=true, threads=0, effort=None, offset=None, scale=None))]
#[allow(clippy::too_many_arguments)]
fn write<'py>(
    py: Python<'py>,
    path: std::path::PathBuf,
    array: &Bound<'py, PyUntypedArray>,
    nodata: Option<f64>,
    transform: Option<(f64, f64, f64, f64, f64, f64)>,
    epsg: Option<u32>,
    wkt: Option<String>,
    max_error: Option<&Bound<'py, PyAny>>,
    lossless: bool,
    method: Option<&str>,
    force: bool,
    threads: usize,
    effort: Option<&Bound<'py, PyAny>>,
    offset: Option<f64>,
    scale: Option<f64>,
) -> PyResult<()> {
    let opts = encode_options(py, max_error, lossless, method, effort, threads)?;
    let mut raster = raster_from(py, array, nodata, offset_scale(offset, scale))?;
    if let Some((a, b, c, d, e, f)) = transform {
        if b != 0.0 || d != 0.0 {
            return Err(to_py(
                py,
                Error::unsupported("a rotated or sheared transform (b or d not 0)"),
            ));
        }
        if !(a > 0.0 && e < 0.0 && a.is_finite() && e.is_finite() && c.is_finite() && f.is_finite())
        {
            return Err(invalid(
                py,
                format!(
                    "transform {a}, {b}, {c}, {d}, {e}, {f}: vtz takes north-up rasters (a > 0, e < 0)"
                ),
            ));
        }
        raster.georef = Some(Georef {
            origin: [c, f],
            pixel_size: [a, -e],
            raster_type: RasterType::Area,
            epsg,
            wkt,
            geokeys: None,
        });
    } else if epsg.is_some() || wkt.is_some() {
        return Err(invalid(py, "a CRS without a transform"));
    }
    let is_vtz = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("vtz"));
    let res = py.detach(|| -> vtz::Result<()> {
        if is_vtz {
            let bytes = vtz::on_threads(threads, || vtz::encode(&raster, &opts))??;
            vtz::formats::write_file(&path, bytes, force)
        } else {
            if opts.max_error.is_some() {
                return Err(Error::invalid(format!(
                    "{}: max_error applies to .vtz output only",
                    path.display()
                )));
            }
            let w = vtz::formats::WriteOptions {
                force,
                ..Default::default()
            };
            vtz::write_path(&raster, &path, &w)
        }
    });
    res.map_err(|e| to_py(py, e))
}

/// The native module.
#[pymodule]
fn _vtz(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(encode, m)?)?;
    m.add_function(wrap_pyfunction!(decode, m)?)?;
    m.add_function(wrap_pyfunction!(info, m)?)?;
    m.add_function(wrap_pyfunction!(read, m)?)?;
    m.add_function(wrap_pyfunction!(write, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
