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
use pyo3::exceptions::PyBaseException;
use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyList, PyTuple, PyType};
use std::ops::Range;
use std::sync::{Arc, Mutex, MutexGuard};
use vtz::source::{COALESCE_GAP, FileSource, MemorySource, coalesce, split};
use vtz::{
    DecodeOptions, Decoder, EncodeOptions, Error, ErrorBound, FileInfo, Georef, Limits, Method,
    RangeSource, Raster, RasterType, SampleType, Scale, SectionChoice, Window,
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
    tile: Option<u32>,
) -> PyResult<EncodeOptions> {
    let mut o = EncodeOptions::default();
    o.effort = parse_effort(py, effort)?;
    o.tile = tile;
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
#[pyo3(signature = (array, max_error=None, lossless=false, nodata=None, method=None, threads=0, effort=None, offset=None, scale=None, tile=None))]
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
    tile: Option<u32>,
) -> PyResult<Bound<'py, PyBytes>> {
    let opts = encode_options(py, max_error, lossless, method, effort, threads, tile)?;
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
    let [x0, dx, rot_row, y0, rot_col, ndy] = g.geotransform();
    let t = PyTuple::new(py, [dx, rot_row, x0, rot_col, ndy, y0])?;
    d.set_item("transform", t)?;
    d.set_item("epsg", g.epsg)?;
    d.set_item("wkt", g.wkt.clone())?;
    // What GDAL's SetFromUserInput takes: the WKT (the file's own, else EPSG's from vtz's
    // table), else `EPSG:n`, else a PROJ string.
    d.set_item("crs_input", vtz::formats::crs_user_input(g))?;
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
    let d = info_dict(py, dec.info())?;
    // The bound the file guarantees (0 = lossless), read without decoding.
    let max_error = py.detach(|| dec.max_error()).map_err(|e| to_py(py, e))?;
    d.set_item("max_error", max_error)?;
    Ok(d)
}

/// A file's [`FileInfo`] as the dict `vtz.info` gives (without `max_error`, which reads a
/// section of an untiled file).
fn info_dict<'py>(py: Python<'py>, fi: &FileInfo) -> PyResult<Bound<'py, PyDict>> {
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
    // As the decoded array holds it: the nodata value, or its code when it holds codes.
    d.set_item("stored_nodata", fi.nodata.map(|nd| out.stored(nd)))?;
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
    match &fi.tiles {
        Some(t) => {
            let td = PyDict::new(py);
            td.set_item("tile_width", t.tile_width)?;
            td.set_item("tile_height", t.tile_height)?;
            td.set_item("cols", t.cols)?;
            td.set_item("rows", t.rows)?;
            td.set_item("margin", t.margin)?;
            // Where each tile's block lies in the file, in tile order: (offset, bytes) of its
            // first part (version 5: its head), and (offset, bytes) of the rest (version
            // 5's tail; 0 bytes in versions 2 and 4, whose blocks are whole).
            let blocks = PyList::empty(py);
            let tails = PyList::empty(py);
            for ti in &t.tiles {
                blocks.append((ti.offset, ti.head_bytes))?;
                tails.append((ti.tail_offset, ti.bytes - ti.head_bytes))?;
            }
            td.set_item("blocks", blocks)?;
            td.set_item("tails", tails)?;
            td.set_item("overview_split", t.overview_split)?;
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

// ------------------------------------------------------------------ lazy reads (vtz.open)

/// How a Python object reads byte ranges.
enum PyReads {
    /// An fsspec filesystem and a path in it: one `fs.cat_ranges(paths, starts, ends)` call
    /// per read, which fsspec's async filesystems (HTTP, S3, GCS, Azure) issue concurrently.
    Fsspec { fs: Py<PyAny>, path: Py<PyAny> },
    /// A binary file-like (`seek` + `read`): one range after another, one read at a time.
    File { file: Py<PyAny>, lock: Mutex<()> },
}

/// A [`RangeSource`] over a Python object. The decoder calls it with the GIL released (from
/// the calling thread or rayon's workers); it attaches to the interpreter only for the
/// Python calls. Ranges within [`COALESCE_GAP`] of each other are fetched as one.
struct PySource {
    reads: PyReads,
    len: u64,
    name: String,
    /// The Python exception behind the last failed read, chained as the cause of the vtz
    /// error the decode raises.
    error: Mutex<Option<PyErr>>,
}

fn locked<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

/// The bytes of a Python object a read gave (`bytes`, or anything `bytes()` takes).
fn bytes_of(py: Python<'_>, b: &Bound<'_, PyAny>) -> PyResult<Vec<u8>> {
    if let Ok(b) = b.cast::<PyBytes>() {
        return Ok(b.as_bytes().to_vec());
    }
    if b.is_none() {
        return Err(PyErr::new::<pyo3::exceptions::PyOSError, _>(
            "read() gave None (a non-blocking file with no data ready)",
        ));
    }
    let b = py.import("builtins")?.getattr("bytes")?.call1((b,))?;
    Ok(b.cast::<PyBytes>()
        .map_err(PyErr::from)?
        .as_bytes()
        .to_vec())
}

/// A Python exception in one line: `TypeName: message`.
fn py_error_line(py: Python<'_>, e: &PyErr) -> String {
    let ty = e
        .get_type(py)
        .name()
        .map_or_else(|_| "Exception".to_string(), |n| n.to_string());
    let msg = e
        .value(py)
        .str()
        .map_or_else(|_| String::new(), |s| s.to_string_lossy().into_owned());
    let msg = msg.split_whitespace().collect::<Vec<_>>().join(" ");
    if msg.is_empty() {
        ty
    } else {
        format!("{ty}: {msg}")
    }
}

impl PySource {
    fn fetch(&self, py: Python<'_>, ranges: &[Range<u64>]) -> PyResult<Vec<Vec<u8>>> {
        match &self.reads {
            PyReads::Fsspec { fs, path } => {
                let paths = PyList::new(py, ranges.iter().map(|_| path.bind(py)))?;
                let starts = PyList::new(py, ranges.iter().map(|r| r.start))?;
                let ends = PyList::new(py, ranges.iter().map(|r| r.end))?;
                let kw = PyDict::new(py);
                kw.set_item("on_error", "raise")?;
                let got =
                    fs.bind(py)
                        .call_method("cat_ranges", (paths, starts, ends), Some(&kw))?;
                let mut out = Vec::with_capacity(ranges.len());
                for item in got.try_iter()? {
                    let item = item?;
                    // fsspec returns an exception in place of bytes with on_error="return".
                    if item.is_instance_of::<PyBaseException>() {
                        return Err(PyErr::from_value(item));
                    }
                    out.push(bytes_of(py, &item)?);
                }
                Ok(out)
            }
            PyReads::File { file, .. } => {
                let f = file.bind(py);
                ranges
                    .iter()
                    .map(|r| {
                        f.call_method1("seek", (r.start,))?;
                        let want = (r.end - r.start) as usize;
                        let mut buf = Vec::with_capacity(want);
                        // A raw file may give fewer bytes than asked: read on to the end.
                        while buf.len() < want {
                            let got = bytes_of(py, &f.call_method1("read", (want - buf.len(),))?)?;
                            if got.is_empty() {
                                break;
                            }
                            buf.extend_from_slice(&got);
                        }
                        Ok(buf)
                    })
                    .collect()
            }
        }
    }
}

impl RangeSource for PySource {
    fn len(&self) -> vtz::Result<u64> {
        Ok(self.len)
    }

    fn read_ranges(&self, ranges: &[Range<u64>]) -> vtz::Result<Vec<Vec<u8>>> {
        if let Some(r) = ranges.iter().find(|r| r.start > r.end || r.end > self.len) {
            return Err(Error::corrupt(format!(
                "{} is truncated: bytes {}..{} asked of a {}-byte file",
                self.name, r.start, r.end, self.len
            )));
        }
        let (merged, owner) = coalesce(ranges, COALESCE_GAP);
        if merged.is_empty() {
            return Ok(ranges.iter().map(|_| Vec::new()).collect());
        }
        // A file-like's seek + read pairs must not interleave; the lock is taken before the
        // GIL, so a thread waiting for it never holds the GIL.
        let _one_at_a_time = match &self.reads {
            PyReads::File { lock, .. } => Some(locked(lock)),
            PyReads::Fsspec { .. } => None,
        };
        let got = Python::attach(|py| {
            self.fetch(py, &merged).map_err(|e| {
                let line = py_error_line(py, &e);
                *locked(&self.error) = Some(e);
                line
            })
        })
        .map_err(|line| {
            Error::io(
                format!("reading {}", self.name),
                std::io::Error::other(line),
            )
        })?;
        if got.len() != merged.len() {
            return Err(Error::io(
                format!("reading {}", self.name),
                std::io::Error::other(format!(
                    "cat_ranges gave {} ranges for {}",
                    got.len(),
                    merged.len()
                )),
            ));
        }
        for (r, b) in merged.iter().zip(&got) {
            if b.len() as u64 != r.end - r.start {
                return Err(Error::io(
                    format!("reading {}", self.name),
                    std::io::Error::new(
                        std::io::ErrorKind::UnexpectedEof,
                        format!(
                            "bytes {}..{} gave {} bytes, not {} (did the object change?)",
                            r.start,
                            r.end,
                            b.len(),
                            r.end - r.start
                        ),
                    ),
                ));
            }
        }
        Ok(split(ranges, &merged, &owner, &got))
    }

    fn name(&self) -> String {
        self.name.clone()
    }
}

/// A range read on opening and its bytes.
type KeptRead = (Range<u64>, Vec<u8>);

/// Recently read ranges (tile blocks), up to `cap` bytes, the oldest dropped first.
struct BlockCache {
    cap: u64,
    bytes: u64,
    map: std::collections::HashMap<(u64, u64), Arc<Vec<u8>>>,
    order: std::collections::VecDeque<(u64, u64)>,
}

impl BlockCache {
    fn get(&self, r: &Range<u64>) -> Option<Vec<u8>> {
        self.map.get(&(r.start, r.end)).map(|b| b.as_ref().clone())
    }

    fn put(&mut self, r: &Range<u64>, b: &[u8]) {
        let key = (r.start, r.end);
        let n = b.len() as u64;
        if n == 0 || n > self.cap || self.map.contains_key(&key) {
            return;
        }
        self.map.insert(key, Arc::new(b.to_vec()));
        self.order.push_back(key);
        self.bytes += n;
        while self.bytes > self.cap {
            let Some(old) = self.order.pop_front() else {
                break;
            };
            if let Some(b) = self.map.remove(&old) {
                self.bytes -= b.len() as u64;
            }
        }
    }
}

/// A source that keeps what its file's opening read (the first 64 KB; a version-2 file's
/// tile index), so the decoders opened later for concurrent reads open without a request,
/// and the last `cache_bytes` of blocks read: a tile's window reads its neighbours' blocks
/// too (it blends across their margins), so the reads of neighbouring windows (Dask's
/// tasks, one per tile) fetch each block about once instead of up to nine times.
struct KeepOpening {
    inner: Arc<dyn RangeSource>,
    /// True while the first decoder opens.
    recording: std::sync::atomic::AtomicBool,
    kept: Mutex<Vec<KeptRead>>,
    cache: Mutex<BlockCache>,
}

impl KeepOpening {
    fn new(inner: Arc<dyn RangeSource>, cache_bytes: u64) -> KeepOpening {
        KeepOpening {
            inner,
            recording: std::sync::atomic::AtomicBool::new(true),
            kept: Mutex::new(Vec::new()),
            cache: Mutex::new(BlockCache {
                cap: cache_bytes,
                bytes: 0,
                map: Default::default(),
                order: Default::default(),
            }),
        }
    }

    fn opened(&self) {
        self.recording
            .store(false, std::sync::atomic::Ordering::Release);
    }

    /// The bytes of `r` from what was kept, if one kept read holds it.
    fn kept_bytes(&self, r: &Range<u64>) -> Option<Vec<u8>> {
        locked(&self.kept).iter().find_map(|(k, b)| {
            (k.start <= r.start && r.end <= k.end && r.start <= r.end)
                .then(|| b[(r.start - k.start) as usize..(r.end - k.start) as usize].to_vec())
        })
    }
}

impl RangeSource for KeepOpening {
    fn len(&self) -> vtz::Result<u64> {
        self.inner.len()
    }

    fn read_ranges(&self, ranges: &[Range<u64>]) -> vtz::Result<Vec<Vec<u8>>> {
        let mut out: Vec<Option<Vec<u8>>> = ranges
            .iter()
            .map(|r| self.kept_bytes(r).or_else(|| locked(&self.cache).get(r)))
            .collect();
        let missing: Vec<usize> = (0..ranges.len()).filter(|&i| out[i].is_none()).collect();
        if !missing.is_empty() {
            let asked: Vec<Range<u64>> = missing.iter().map(|&i| ranges[i].clone()).collect();
            let got = self.inner.read_ranges(&asked)?;
            if got.len() != asked.len() {
                return Err(Error::corrupt(format!(
                    "{}: a read of {} ranges gave {}",
                    self.name(),
                    asked.len(),
                    got.len()
                )));
            }
            let recording = self.recording.load(std::sync::atomic::Ordering::Acquire);
            for ((i, r), b) in missing.into_iter().zip(&asked).zip(got) {
                if recording {
                    locked(&self.kept).push((r.clone(), b.clone()));
                } else {
                    locked(&self.cache).put(r, &b);
                }
                out[i] = Some(b);
            }
        }
        Ok(out.into_iter().flatten().collect())
    }

    fn name(&self) -> String {
        self.inner.name()
    }
}

/// An opened file: its source, what it holds, and decoders over the source (one per
/// concurrent read: a `Decoder` decodes one request at a time; those opened after the first
/// take the header and index from what the first read).
struct Opened {
    src: Arc<dyn RangeSource>,
    py_src: Option<Arc<PySource>>,
    info: FileInfo,
    idle: Mutex<Vec<Decoder>>,
}

/// A `.vtz` file opened for lazy reads (`vtz.open`): the header and index on opening, then
/// only the tile blocks each read needs. Thread-safe: reads from several threads decode side
/// by side.
#[pyclass(frozen, module = "vtz._vtz")]
struct Reader {
    opened: Mutex<Option<Arc<Opened>>>,
}

impl Reader {
    /// Open a decoder over `src` (the GIL released); `context` names a local file in the
    /// error, as `Decoder::open_path` does.
    fn open(
        py: Python<'_>,
        src: Arc<dyn RangeSource>,
        py_src: Option<Arc<PySource>>,
        context: Option<&std::path::Path>,
        cache_bytes: u64,
    ) -> PyResult<Reader> {
        let keep = Arc::new(KeepOpening::new(src, cache_bytes));
        let s: Arc<dyn RangeSource> = keep.clone();
        let dec = py
            .detach(|| Decoder::open_with_limits(s, Limits::default()))
            .map_err(|e| match context {
                Some(p) => e.context(p.display()),
                None => e,
            })
            .map_err(|e| source_error(py, py_src.as_deref(), e))?;
        keep.opened();
        let src: Arc<dyn RangeSource> = keep;
        let info = dec.info().clone();
        Ok(Reader {
            opened: Mutex::new(Some(Arc::new(Opened {
                src,
                py_src,
                info,
                idle: Mutex::new(vec![dec]),
            }))),
        })
    }

    fn get(&self, py: Python<'_>) -> PyResult<Arc<Opened>> {
        locked(&self.opened)
            .clone()
            .ok_or_else(|| invalid(py, "the vtz file is closed"))
    }
}

/// A vtz error as its Python exception, with the Python exception a read raised (if it did)
/// as its `__cause__`.
fn source_error(py: Python<'_>, src: Option<&PySource>, e: Error) -> PyErr {
    let is_io = matches!(e, Error::Io { .. });
    let err = to_py(py, e);
    if is_io && let Some(cause) = src.and_then(|s| locked(&s.error).take()) {
        err.set_cause(py, Some(cause));
    }
    err
}

#[pymethods]
impl Reader {
    /// A local file (positioned reads).
    #[staticmethod]
    fn from_path(py: Python<'_>, path: std::path::PathBuf) -> PyResult<Reader> {
        let src: Arc<dyn RangeSource> =
            Arc::new(FileSource::open(&path).map_err(|e| to_py(py, e))?);
        Reader::open(py, src, None, Some(&path), 0)
    }

    /// Bytes in memory.
    #[staticmethod]
    fn from_bytes(py: Python<'_>, data: &Bound<'_, PyBytes>) -> PyResult<Reader> {
        let src: Arc<dyn RangeSource> = Arc::new(MemorySource::new(data.as_bytes().to_vec()));
        Reader::open(py, src, None, None, 0)
    }

    /// An fsspec filesystem and a path in it (`size`: the object's length in bytes;
    /// `cache_bytes`: how many bytes of recently read blocks to keep).
    #[staticmethod]
    #[pyo3(signature = (fs, path, size, name, cache_bytes=0))]
    fn from_fsspec(
        py: Python<'_>,
        fs: Py<PyAny>,
        path: Py<PyAny>,
        size: u64,
        name: String,
        cache_bytes: u64,
    ) -> PyResult<Reader> {
        let src = Arc::new(PySource {
            reads: PyReads::Fsspec { fs, path },
            len: size,
            name,
            error: Mutex::new(None),
        });
        Reader::open(py, src.clone(), Some(src), None, cache_bytes)
    }

    /// A binary file-like with `seek` and `read` (`size`: its length in bytes;
    /// `cache_bytes`: how many bytes of recently read blocks to keep).
    #[staticmethod]
    #[pyo3(signature = (file, size, name, cache_bytes=0))]
    fn from_file(
        py: Python<'_>,
        file: Py<PyAny>,
        size: u64,
        name: String,
        cache_bytes: u64,
    ) -> PyResult<Reader> {
        let src = Arc::new(PySource {
            reads: PyReads::File {
                file,
                lock: Mutex::new(()),
            },
            len: size,
            name,
            error: Mutex::new(None),
        });
        Reader::open(py, src.clone(), Some(src), None, cache_bytes)
    }

    /// What the file holds (`vtz.info`'s dict, without `max_error`).
    fn info<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        info_dict(py, &self.get(py)?.info)
    }

    /// The bound every valid sample is within (0 = lossless): an untiled file reads its
    /// primary section's header for it.
    fn max_error(&self, py: Python<'_>) -> PyResult<f64> {
        let o = self.get(py)?;
        let res = py.detach(|| {
            let mut dec = o.take()?;
            let r = dec.max_error();
            o.give_back(dec, &r);
            r
        });
        res.map_err(|e| source_error(py, o.py_src.as_deref(), e))
    }

    /// Decode a window `(x, y, width, height)` (of overview K's samples when `overview` is
    /// given) into a numpy array, as `vtz.decode` gives it.
    #[pyo3(signature = (window=None, overview=None, threads=0))]
    fn read<'py>(
        &self,
        py: Python<'py>,
        window: Option<(usize, usize, usize, usize)>,
        overview: Option<u32>,
        threads: usize,
    ) -> PyResult<Bound<'py, PyAny>> {
        let o = self.get(py)?;
        let opts = decode_options(py, window, None, overview, threads)?;
        let res = py.detach(|| {
            let mut dec = o.take()?;
            let r = vtz::on_threads(threads, || dec.options(opts).decode()).and_then(|r| r);
            o.give_back(dec, &r);
            r
        });
        let r = res.map_err(|e| source_error(py, o.py_src.as_deref(), e))?;
        to_array(py, r)
    }

    /// Let go of the source (a read after this raises).
    fn close(&self) {
        locked(&self.opened).take();
    }

    /// Whether `close` was called.
    #[getter]
    fn closed(&self) -> bool {
        locked(&self.opened).is_none()
    }
}

impl Opened {
    /// An idle decoder, or a new one over the same source.
    fn take(&self) -> vtz::Result<Decoder> {
        match locked(&self.idle).pop() {
            Some(d) => Ok(d),
            None => Decoder::open_with_limits(self.src.clone(), Limits::default()),
        }
    }

    /// Back to the idle ones after a request that succeeded (one that failed may have left
    /// it anywhere: it is dropped).
    fn give_back<T>(&self, dec: Decoder, r: &vtz::Result<T>) {
        if r.is_ok() {
            locked(&self.idle).push(dec);
        }
    }
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
#[pyo3(signature = (path, array, nodata=None, transform=None, epsg=None, wkt=None, max_error=None, lossless=false, method=None, force=true, threads=0, effort=None, offset=None, scale=None, tile=None))]
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
    tile: Option<u32>,
) -> PyResult<()> {
    let opts = encode_options(py, max_error, lossless, method, effort, threads, tile)?;
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
            let w = vtz::formats::WriteOptions::default().with_force(force);
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
    m.add_class::<Reader>()?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
