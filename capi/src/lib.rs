//! The C ABI of vtz: open a `.vtz` from a path, from memory or through the caller's
//! range-read callbacks (`VtzReader`: a file on a server fetched by ranges), with limits, read what it
//! holds without decoding (size, sample type, nodata, geotransform, CRS, GDAL metadata, tile
//! grid, stored max error), decode the whole raster or a window into the caller's typed
//! buffer, and encode the caller's buffer with a bound, losslessly or with a method.
//!
//! Every entry point returns a status code (`VTZ_OK` or one `VTZ_ERR_*` per cause of
//! `vtz::Error`, plus `VTZ_ERR_PANIC`); the message of the last error on the calling thread
//! is `vtz_last_error()`. No panic crosses the boundary: each call runs inside
//! `catch_unwind`. A `VtzFile` may be shared between threads: its calls take a lock, so two
//! threads decoding the same handle take turns (each decode runs on the threads it asks for).
//!
//! `unsafe` lives here and only here (the codec forbids it): every pointer the caller gives
//! is checked for null and turned into a slice of the length the caller states, once, at
//! the top of each function; see the `SAFETY` comments. `include/vtz.h` is generated from
//! this file by cbindgen (`tests/header.rs` fails when it is stale).

use std::cell::RefCell;
use std::ffi::{CStr, CString, c_char, c_void};
use std::fs::File;
use std::io::{BufReader, Cursor, Read, Seek};
use std::ops::Range;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use vtz::{
    Decoder, EncodeOptions, Error, ErrorBound, FileInfo, Georef, Limits, Method, Raster,
    RasterType, SampleType, ValueMapping, Window,
};

/// Success.
pub const VTZ_OK: i32 = 0;
/// Reading or writing a file failed (the message names the file and the system's reason).
pub const VTZ_ERR_IO: i32 = 1;
/// The input is not a valid `.vtz` (or raster): bad magic, checksum, range, truncation.
pub const VTZ_ERR_CORRUPT: i32 = 2;
/// A valid input this build cannot handle (a point set where a raster is wanted, a newer
/// version, an unknown required section).
pub const VTZ_ERR_UNSUPPORTED: i32 = 3;
/// The caller's arguments are wrong (a null pointer, a buffer of the wrong size or of a type
/// that cannot hold the values, a window outside the raster, an option out of range).
pub const VTZ_ERR_INVALID_ARGUMENT: i32 = 4;
/// The request cannot be met (e.g. a method that cannot reach the bound).
pub const VTZ_ERR_UNMET: i32 = 5;
/// The input would need more than the limits allow.
pub const VTZ_ERR_LIMIT: i32 = 6;
/// A bug in vtz (a panic, caught at the boundary). Please report it with the input.
pub const VTZ_ERR_PANIC: i32 = 7;

/// Sample types, as in the `.vtz` header (spec/FORMAT.md): unsigned 8-bit.
pub const VTZ_U8: i32 = 0;
/// Signed 16-bit.
pub const VTZ_I16: i32 = 1;
/// Unsigned 16-bit.
pub const VTZ_U16: i32 = 2;
/// Signed 32-bit.
pub const VTZ_I32: i32 = 3;
/// 32-bit float.
pub const VTZ_F32: i32 = 4;
/// 64-bit float.
pub const VTZ_F64: i32 = 5;

/// An open `.vtz` file (opaque). Made by `vtz_open_path` / `vtz_open_memory` /
/// `vtz_open_reader`, released by `vtz_close`.
pub struct VtzFile {
    dec: Mutex<Decoder>,
    info: FileInfo,
    /// The CRS as GDAL's SetFromUserInput takes it (WKT, else `EPSG:n`, else PROJ),
    /// NUL-terminated; empty when none.
    wkt: CString,
    /// The GDAL metadata XML as a full decode gives it back, NUL-terminated.
    gdal_metadata: Option<CString>,
    /// The max error the file guarantees (0 = lossless).
    max_error: f64,
    /// A 1 x 1 GeoTIFF carrying the georeferencing (GeoTIFF keys included), made on the
    /// first `vtz_get_georef_geotiff` (a Zarr chunk's handle never asks); empty when the file
    /// has none or it cannot be written.
    georef_tiff: std::sync::OnceLock<Vec<u8>>,
}

/// What a reader needs: a file or bytes in memory, moved between threads with its handle.
pub trait ReadSeek: Read + Seek + Send {}
impl<T: Read + Seek + Send> ReadSeek for T {}

/// Limits on what a file may make the decoder allocate (0 in a field: vtz's default).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default)]
pub struct VtzLimits {
    /// Most samples (width × height) a decoded raster or window may have.
    pub max_samples: u64,
    /// Most bytes any one section may hold.
    pub max_section_bytes: u64,
}

/// What a file holds, read from its header and directory without decoding a sample.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default)]
pub struct VtzInfo {
    /// Raster width in samples.
    pub width: u32,
    /// Raster height in samples.
    pub height: u32,
    /// The sample type a decode gives back (`VTZ_U8` … `VTZ_F64`).
    pub sample_type: i32,
    /// 1 when the source declared a nodata value (then `nodata` holds it), else 0.
    pub has_nodata: i32,
    /// The nodata value.
    pub nodata: f64,
    /// 1 when any sample is valid (then `min`, `max` are their range), else 0.
    pub has_range: i32,
    /// The smallest valid source value.
    pub min: f64,
    /// The largest valid source value.
    pub max: f64,
    /// 1 when the file is georeferenced (then `geotransform` holds GDAL's six numbers).
    pub has_geotransform: i32,
    /// GDAL's geotransform: x origin, pixel width, 0, y origin, 0, −pixel height (the
    /// corner of pixel (0, 0), also for a point raster; see `pixel_is_point`).
    pub geotransform: [f64; 6],
    /// 1 when a pixel is the point at its centre (GDAL's AREA_OR_POINT=Point).
    pub pixel_is_point: i32,
    /// EPSG code of the CRS, 0 when none is known (`vtz_crs_wkt` may still give a WKT).
    pub epsg: u32,
    /// 1 for a tiled file (container version 2), else 0.
    pub tiled: i32,
    /// Tile width in samples (the raster's width for an untiled file).
    pub tile_width: u32,
    /// Tile height in samples (the raster's height for an untiled file).
    pub tile_height: u32,
    /// Tiles per row (1 for an untiled file).
    pub tile_cols: u32,
    /// Rows of tiles (1 for an untiled file).
    pub tile_rows: u32,
    /// The max error the file guarantees on every valid sample (0 = lossless).
    pub max_error: f64,
    /// Bytes of the whole file.
    pub file_bytes: u64,
    /// The type a GDAL band of the file holds, and `vtz_read_band` gives (`VTZ_U8` …
    /// `VTZ_F64`; capi/README.md, "Output types"): `sample_type` for the identity mapping,
    /// the smallest integer type holding the values for an integer mapping (a u16 PNG mapped
    /// by −32768: `VTZ_I16`), else the codes' type (then `has_offset_scale` is 1).
    pub value_type: i32,
    /// 1 when `vtz_read_band` gives codes, whose values are `value_offset + value_scale ·
    /// code` (GDAL's band offset and scale); 0 when it gives the values.
    pub has_offset_scale: i32,
    /// The band offset (0 when `has_offset_scale` is 0).
    pub value_offset: f64,
    /// The band scale (1 when `has_offset_scale` is 0).
    pub value_scale: f64,
    /// The nodata value as `vtz_read_band` gives it (its code when `has_offset_scale` is 1).
    pub value_nodata: f64,
}

/// How `vtz_encode` / `vtz_encode_to_path` encode. Start from `vtz_encode_options_init`.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct VtzEncodeOptions {
    /// The bound: every valid sample decodes within it (data units, or percent of the
    /// valid range when `max_error_percent` is 1). Negative: lossless (the default).
    pub max_error: f64,
    /// 1: `max_error` is a percentage of the valid range, as `--max-error 1%`.
    pub max_error_percent: i32,
    /// The method's name (`best`, `residual`, `sites`, `grid`, `haar`, `fis`, or a comma
    /// list); null = `best`.
    pub method: *const c_char,
    /// Encoder effort 1..=9; 0 = the default (5).
    pub effort: i32,
    /// Tile side in samples; 0 = vtz's default (tiles of 1024 above 4096² samples); −1 =
    /// never tile.
    pub tile: i32,
    /// Threads; 0 = all the machine offers.
    pub threads: u32,
    /// 1 when `nodata` is the nodata value of the buffer (NaN samples are nodata anyway).
    pub has_nodata: i32,
    /// The nodata value.
    pub nodata: f64,
    /// 1 when `geotransform` georeferences the raster (north-up: elements 2 and 4 are 0).
    pub has_geotransform: i32,
    /// GDAL's geotransform.
    pub geotransform: [f64; 6],
    /// 1 when a pixel is the point at its centre.
    pub pixel_is_point: i32,
    /// EPSG code of the CRS, 0 = none.
    pub epsg: u32,
    /// The CRS as WKT, NUL-terminated; null = none.
    pub crs_wkt: *const c_char,
    /// GDAL metadata XML (GDAL_METADATA), NUL-terminated; null = none.
    pub gdal_metadata: *const c_char,
    /// Called with the fraction done (0 at the start, never decreasing, 1 at the end) and
    /// `progress_data`, one call at a time, from the thread that runs the encode; null =
    /// none.
    pub progress: Option<unsafe extern "C" fn(fraction: f64, progress_data: *mut c_void)>,
    /// Passed to `progress` as it is.
    pub progress_data: *mut c_void,
    /// 1 when `data` holds integer codes whose values are `value_offset + value_scale ·
    /// code` (GDAL's band offset and scale; `nodata` is then a code too): the file keeps the
    /// mapping, `max_error` bounds the values. Only for integer data types.
    pub has_offset_scale: i32,
    /// Value of code 0.
    pub value_offset: f64,
    /// Value per code step (finite, not 0).
    pub value_scale: f64,
}

thread_local! {
    static LAST_ERROR: RefCell<CString> = RefCell::new(CString::default());
}

fn set_error(msg: &str) {
    let c = CString::new(msg.replace('\0', " ")).unwrap_or_default();
    LAST_ERROR.with(|e| *e.borrow_mut() = c);
}

fn status(e: &Error) -> i32 {
    match e {
        Error::Io { .. } => VTZ_ERR_IO,
        Error::Corrupt { .. } => VTZ_ERR_CORRUPT,
        Error::Unsupported { .. } => VTZ_ERR_UNSUPPORTED,
        Error::InvalidArgument { .. } => VTZ_ERR_INVALID_ARGUMENT,
        Error::Unmet { .. } => VTZ_ERR_UNMET,
        Error::LimitExceeded { .. } => VTZ_ERR_LIMIT,
        _ => VTZ_ERR_CORRUPT,
    }
}

/// Run `f` behind the boundary: its error becomes a code and the thread's message, a panic
/// `VTZ_ERR_PANIC`.
fn guard(f: impl FnOnce() -> vtz::Result<()>) -> i32 {
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(Ok(())) => {
            set_error("");
            VTZ_OK
        }
        Ok(Err(e)) => {
            set_error(&e.to_string());
            status(&e)
        }
        Err(p) => {
            let what = p
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| p.downcast_ref::<String>().cloned())
                .unwrap_or_default();
            set_error(&format!(
                "internal error (a bug in vtz, please report it): {what}"
            ));
            VTZ_ERR_PANIC
        }
    }
}

fn null(what: &str) -> Error {
    Error::invalid(format!("{what} is a null pointer"))
}

fn limits(l: Option<&VtzLimits>) -> Limits {
    let mut out = Limits::default();
    if let Some(l) = l {
        if l.max_samples != 0 {
            out.max_samples = l.max_samples;
        }
        if l.max_section_bytes != 0 {
            out.max_section_bytes = l.max_section_bytes;
        }
    }
    out
}

fn type_code(t: SampleType) -> i32 {
    match t {
        SampleType::U8 => VTZ_U8,
        SampleType::I16 => VTZ_I16,
        SampleType::U16 => VTZ_U16,
        SampleType::I32 => VTZ_I32,
        SampleType::F32 => VTZ_F32,
        _ => VTZ_F64,
    }
}

fn sample_type(code: i32) -> vtz::Result<SampleType> {
    Ok(match code {
        VTZ_U8 => SampleType::U8,
        VTZ_I16 => SampleType::I16,
        VTZ_U16 => SampleType::U16,
        VTZ_I32 => SampleType::I32,
        VTZ_F32 => SampleType::F32,
        VTZ_F64 => SampleType::F64,
        _ => {
            return Err(Error::invalid(format!(
                "sample type {code} is not one of VTZ_U8 … VTZ_F64 (0 … 5)"
            )));
        }
    })
}

fn bytes_per_sample(t: SampleType) -> usize {
    match t {
        SampleType::U8 => 1,
        SampleType::I16 | SampleType::U16 => 2,
        SampleType::I32 | SampleType::F32 => 4,
        _ => 8,
    }
}

fn open(reader: Box<dyn ReadSeek>, lim: Option<&VtzLimits>) -> vtz::Result<Box<VtzFile>> {
    handle(Decoder::with_limits(reader, limits(lim))?)
}

/// The handle of an opened decoder (what it holds read once).
fn handle(mut dec: Decoder) -> vtz::Result<Box<VtzFile>> {
    let max_error = dec.max_error()?;
    let gdal_metadata = dec
        .gdal_metadata()?
        .map(|x| CString::new(x.replace('\0', " ")).unwrap_or_default());
    let info = dec.info().clone();
    let wkt = info
        .georef
        .as_ref()
        .and_then(vtz::formats::crs_user_input)
        .unwrap_or_default();
    Ok(Box::new(VtzFile {
        georef_tiff: std::sync::OnceLock::new(),
        dec: Mutex::new(dec),
        info,
        wkt: CString::new(wkt.replace('\0', " ")).unwrap_or_default(),
        gdal_metadata,
        max_error,
    }))
}

/// An open: `*out` is null until `f` gives the handle, then the handle.
///
/// # Safety
/// `out` is null or writable.
unsafe fn open_into(
    out: *mut *mut VtzFile,
    f: impl FnOnce() -> vtz::Result<Box<VtzFile>>,
) -> vtz::Result<()> {
    if out.is_null() {
        return Err(null("out"));
    }
    // SAFETY: not null, writable (the caller's promise).
    unsafe { *out = std::ptr::null_mut() };
    let handle = f()?;
    // SAFETY: as above.
    unsafe { *out = Box::into_raw(handle) };
    Ok(())
}

/// Open the `.vtz` at `path` (UTF-8, NUL-terminated). `limits` may be null (vtz's
/// defaults). Reads the header and the directory; on success `*out` is a handle for
/// `vtz_close`, else `*out` is null.
///
/// # Safety
/// `path` is null or a NUL-terminated string; `limits` is null or points to a
/// `VtzLimits`; `out` is null or points to writable storage for a pointer.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vtz_open_path(
    path: *const c_char,
    limits: *const VtzLimits,
    out: *mut *mut VtzFile,
) -> i32 {
    guard(|| {
        let opened = || {
            if path.is_null() {
                return Err(null("path"));
            }
            // SAFETY: not null; the caller says it is NUL-terminated.
            let p = unsafe { CStr::from_ptr(path) }
                .to_str()
                .map_err(|_| Error::invalid("path is not UTF-8"))?;
            // SAFETY: null or a valid VtzLimits, as the caller says.
            let lim = unsafe { limits.as_ref() };
            let path = PathBuf::from(p);
            let file = File::open(&path).map_err(|e| Error::io(path.display().to_string(), e))?;
            open(Box::new(BufReader::new(file)), lim).map_err(|e| e.context(path.display()))
        };
        // SAFETY: `out` is null or writable (the caller's promise).
        unsafe { open_into(out, opened) }
    })
}

/// Open a `.vtz` held in memory: the `len` bytes at `data` are copied, so the caller may
/// free them as soon as this returns. `limits` may be null.
///
/// # Safety
/// `data` is null only when `len` is 0, else points to `len` readable bytes; `limits` is
/// null or points to a `VtzLimits`; `out` is null or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vtz_open_memory(
    data: *const u8,
    len: usize,
    limits: *const VtzLimits,
    out: *mut *mut VtzFile,
) -> i32 {
    guard(|| {
        let opened = || {
            let bytes = if len == 0 {
                Vec::new()
            } else if data.is_null() {
                return Err(null("data"));
            } else {
                // SAFETY: not null, `len` readable bytes as the caller says.
                unsafe { std::slice::from_raw_parts(data, len) }.to_vec()
            };
            // SAFETY: null or a valid VtzLimits.
            let lim = unsafe { limits.as_ref() };
            open(Box::new(Cursor::new(bytes)), lim)
        };
        // SAFETY: `out` is null or writable (the caller's promise).
        unsafe { open_into(out, opened) }
    })
}

/// Reads byte ranges of a `.vtz` for [`vtz_open_reader`]: the caller's own I/O (GDAL's
/// `VSIFReadMultiRangeL` over `/vsicurl/` or `/vsis3/`, an object store's client, a cache),
/// so a decode fetches only the header, the tile index and the blocks of the tiles a window
/// touches.
///
/// Threads: for one handle, `read_ranges` is called by one thread at a time (the handle
/// serializes the calls), though not always the thread that called into vtz (a decode may
/// run on a pool thread). Two handles may call at the same time; a `user` shared between
/// handles needs its own lock. A callback must not call into vtz with the same handle,
/// and must not unwind (throw a C++ exception or `longjmp`) out of the call.
#[repr(C)]
pub struct VtzReader {
    /// Passed as it is to `read_ranges` and `close`.
    pub user: *mut c_void,
    /// The file's length in bytes (vtz never asks for a byte at or past it).
    pub length: u64,
    /// Fill `buffers[i]` with exactly `lengths[i]` bytes from offset `offsets[i]`, for i in
    /// 0..n (n ≥ 1; the ranges are ascending, none empty, none overlapping, each inside
    /// `length`; overlapping ranges are given as one, adjacent ones (the blocks of tiles
    /// side by side) apart, so a caller may cache each and issue them as they come,
    /// concurrently or merged into one request). Returns 0 when every buffer
    /// is filled, anything else on failure (a short read included); then it may write a
    /// NUL-terminated reason of at most `message_cap` bytes, NUL included, into `message`
    /// (it holds an empty string on entry), and the call into vtz returns `VTZ_ERR_IO` with
    /// that reason in `vtz_last_error()`.
    pub read_ranges: Option<
        unsafe extern "C" fn(
            user: *mut c_void,
            n: usize,
            offsets: *const u64,
            lengths: *const usize,
            buffers: *const *mut u8,
            message: *mut c_char,
            message_cap: usize,
        ) -> i32,
    >,
    /// Called once with `user` when vtz no longer needs it: by `vtz_close`, or before
    /// `vtz_open_reader` returns when the open fails. Null: nothing is called.
    pub close: Option<unsafe extern "C" fn(user: *mut c_void)>,
    /// The file's path or URL for messages (UTF-8, NUL-terminated, copied); null: "the
    /// reader".
    pub name: *const c_char,
}

type ReadRangesFn = unsafe extern "C" fn(
    *mut c_void,
    usize,
    *const u64,
    *const usize,
    *const *mut u8,
    *mut c_char,
    usize,
) -> i32;

/// The caller's callbacks and their data; `close` runs on drop.
struct Callbacks {
    user: *mut c_void,
    read: Option<ReadRangesFn>,
    close: Option<unsafe extern "C" fn(*mut c_void)>,
}

// SAFETY: `VtzReader`'s contract lets vtz call the callbacks from any thread, one call at a
// time per handle; `CallbackSource` holds them behind a mutex, so no two threads use them
// at once, and `user` is only passed back to them.
unsafe impl Send for Callbacks {}

impl Drop for Callbacks {
    fn drop(&mut self) {
        if let Some(close) = self.close {
            // SAFETY: the caller's close, once (this value is dropped once), with its data.
            unsafe { close(self.user) }
        }
    }
}

/// A [`vtz::RangeSource`] over the caller's `VtzReader`.
struct CallbackSource {
    calls: Mutex<Callbacks>,
    len: u64,
    name: String,
}

/// The longest reason a read callback may give, NUL included.
const READER_MESSAGE_CAP: usize = 512;

impl vtz::RangeSource for CallbackSource {
    fn len(&self) -> vtz::Result<u64> {
        Ok(self.len)
    }

    fn read_ranges(&self, ranges: &[Range<u64>]) -> vtz::Result<Vec<Vec<u8>>> {
        for r in ranges {
            if r.start > r.end || r.end > self.len {
                return Err(Error::corrupt(format!(
                    "{} is truncated: bytes {}..{} asked of a {}-byte file",
                    self.name, r.start, r.end, self.len
                )));
            }
        }
        // Ascending ranges for the callback, overlapping ones merged and adjacent ones
        // (tile blocks side by side) kept apart, so a caller caches each block alone and
        // its transport merges consecutive ranges itself; empty ones need no read.
        let (merged, owner) = vtz::source::disjoint(ranges);
        let wanted: Vec<usize> = (0..merged.len())
            .filter(|&i| merged[i].end > merged[i].start)
            .collect();
        let mut got: Vec<Vec<u8>> = merged.iter().map(|_| Vec::new()).collect();
        for &i in &wanted {
            let n = usize::try_from(merged[i].end - merged[i].start)
                .map_err(|_| Error::limit("a read larger than memory can address"))?;
            got[i] = vec![0u8; n];
        }
        if !wanted.is_empty() {
            let offsets: Vec<u64> = wanted.iter().map(|&i| merged[i].start).collect();
            let lengths: Vec<usize> = wanted.iter().map(|&i| got[i].len()).collect();
            let mut message = [0 as c_char; READER_MESSAGE_CAP];
            let rc = {
                let calls = self.calls.lock().unwrap_or_else(|p| p.into_inner());
                let Some(read) = calls.read else {
                    return Err(null("read_ranges"));
                };
                let buffers: Vec<*mut u8> = wanted.iter().map(|&i| got[i].as_mut_ptr()).collect();
                // SAFETY: the caller's callback with its data; `offsets`, `lengths` and
                // `buffers` hold `wanted.len()` entries, each buffer `lengths[i]` writable
                // bytes (alive until the call returns), `message` `READER_MESSAGE_CAP`
                // writable bytes holding an empty string. One call at a time (the lock).
                unsafe {
                    read(
                        calls.user,
                        wanted.len(),
                        offsets.as_ptr(),
                        lengths.as_ptr(),
                        buffers.as_ptr(),
                        message.as_mut_ptr(),
                        READER_MESSAGE_CAP,
                    )
                }
            };
            if rc != 0 {
                // The reason, up to its NUL (or the buffer's end if the callback left none).
                let bytes: Vec<u8> = message
                    .iter()
                    .take_while(|&&c| c != 0)
                    .map(|&c| c as u8)
                    .collect();
                let why = String::from_utf8_lossy(&bytes).into_owned();
                let why = if why.is_empty() {
                    format!("the read callback returned {rc}")
                } else {
                    why
                };
                let (first, last) = (offsets[0], merged[*wanted.last().unwrap_or(&0)].end);
                return Err(Error::io(
                    format!(
                        "reading {} ({} range(s) in bytes {first}..{last})",
                        self.name,
                        wanted.len()
                    ),
                    std::io::Error::other(why),
                ));
            }
        }
        Ok(vtz::source::split(ranges, &merged, &owner, &got))
    }

    fn name(&self) -> String {
        self.name.clone()
    }
}

/// Open a `.vtz` read through the caller's callbacks (`VtzReader`): one read of its first
/// 64 KB (the header, and a version-4 file's tile index), the rest as decodes need it (a
/// version-2 file's tile index at its end; then each window's tile blocks). `reader` is
/// copied (its `name` too); `limits` may be null. On success `*out` is a handle for
/// `vtz_close`, which calls `reader->close`; on failure `*out` is null and
/// `reader->close` has been called (when `reader` is not null). A failing callback gives
/// `VTZ_ERR_IO` with its reason; a file shorter than its framing says, `VTZ_ERR_CORRUPT`.
///
/// # Safety
/// `reader` is null or points to a `VtzReader` whose callbacks and `user` keep the
/// contract documented on it until `close` is called, and whose `name` is null or
/// NUL-terminated; `limits` is null or points to a `VtzLimits`; `out` is null or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vtz_open_reader(
    reader: *const VtzReader,
    limits: *const VtzLimits,
    out: *mut *mut VtzFile,
) -> i32 {
    guard(|| {
        if !out.is_null() {
            // SAFETY: writable (the caller's promise).
            unsafe { *out = std::ptr::null_mut() };
        }
        // SAFETY: null or a valid VtzReader (the caller's promise).
        let Some(r) = (unsafe { reader.as_ref() }) else {
            return Err(null("reader"));
        };
        // From here on `close` runs exactly once, when `calls` is dropped: on any early
        // return below, or with the handle.
        let calls = Callbacks {
            user: r.user,
            read: r.read_ranges,
            close: r.close,
        };
        // SAFETY: null or NUL-terminated (the caller's promise).
        let name = unsafe { text(r.name, "reader->name") }?.unwrap_or_else(|| "the reader".into());
        if calls.read.is_none() {
            return Err(null("reader->read_ranges"));
        }
        let src = CallbackSource {
            calls: Mutex::new(calls),
            len: r.length,
            name: name.clone(),
        };
        // SAFETY: null or a valid VtzLimits.
        let lim = crate::limits(unsafe { limits.as_ref() });
        // SAFETY: `out` is null or writable (the caller's promise).
        unsafe {
            open_into(out, move || {
                let dec =
                    Decoder::open_with_limits(Arc::new(src), lim).map_err(|e| e.context(&name))?;
                handle(dec)
            })
        }
    })
}

/// Release a handle (null: nothing happens).
///
/// # Safety
/// `file` is null or a handle from `vtz_open_*` not yet closed, and no other thread uses it.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vtz_close(file: *mut VtzFile) {
    if !file.is_null() {
        let _ = catch_unwind(AssertUnwindSafe(|| {
            // SAFETY: from Box::into_raw in vtz_open_*, closed once (the caller's promise).
            drop(unsafe { Box::from_raw(file) })
        }));
    }
}

/// Fill `*out` with what the file holds.
///
/// # Safety
/// `file` is null or an open handle; `out` is null or points to a writable `VtzInfo`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vtz_get_info(file: *const VtzFile, out: *mut VtzInfo) -> i32 {
    guard(|| {
        // SAFETY: null or an open handle / writable VtzInfo, as the caller says.
        let (Some(f), Some(out)) = (unsafe { file.as_ref() }, unsafe { out.as_mut() }) else {
            return Err(null("file or out"));
        };
        let i = &f.info;
        let mut v = VtzInfo {
            width: i.width,
            height: i.height,
            sample_type: type_code(i.sample_type),
            max_error: f.max_error,
            file_bytes: i.file_bytes,
            tile_width: i.width,
            tile_height: i.height,
            tile_cols: 1,
            tile_rows: 1,
            ..Default::default()
        };
        let kind = vtz::OutputType::of(i.sample_type, i.mapping, i.nodata);
        v.value_type = type_code(kind.sample_type());
        v.value_scale = 1.0;
        if let Some(m) = kind.offset_scale() {
            v.has_offset_scale = 1;
            v.value_offset = m.offset;
            v.value_scale = m.scale;
        }
        if let Some(nd) = i.nodata {
            v.has_nodata = 1;
            v.nodata = nd;
            v.value_nodata = kind.stored(nd);
        }
        if let Some((lo, hi)) = i.range {
            v.has_range = 1;
            v.min = lo;
            v.max = hi;
        }
        if let Some(g) = &i.georef {
            v.has_geotransform = 1;
            v.geotransform = g.geotransform();
            v.pixel_is_point = i32::from(g.raster_type == RasterType::Point);
            v.epsg = g.epsg.unwrap_or(0);
        }
        if let Some(t) = &i.tiles {
            v.tiled = 1;
            v.tile_width = t.tile_width;
            v.tile_height = t.tile_height;
            v.tile_cols = t.cols;
            v.tile_rows = t.rows;
        }
        *out = v;
        Ok(())
    })
}

/// Copy `text` (with its NUL) into `buf` of `cap` bytes when it fits; the length it needs,
/// NUL included, either way.
fn give_text(text: &CStr, buf: *mut c_char, cap: usize) -> usize {
    let b = text.to_bytes_with_nul();
    if !buf.is_null() && cap >= b.len() {
        // SAFETY: `buf` holds `cap` ≥ b.len() writable bytes (the caller's promise).
        unsafe { std::ptr::copy_nonoverlapping(b.as_ptr().cast::<c_char>(), buf, b.len()) };
    }
    b.len()
}

/// The CRS as GDAL's `SetFromUserInput` takes it (the file's WKT, else its EPSG code's WKT,
/// else `EPSG:n`, else a PROJ string), NUL-terminated, copied into `buf` when `cap` bytes
/// hold it. Returns the bytes it needs with the NUL (1: no CRS, an empty
/// string; 0: `file` is null). Call with `buf` null to learn the size.
///
/// # Safety
/// `file` is null or an open handle; `buf` is null or holds `cap` writable bytes.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vtz_get_crs(file: *const VtzFile, buf: *mut c_char, cap: usize) -> usize {
    // SAFETY: null or an open handle.
    match unsafe { file.as_ref() } {
        Some(f) => give_text(&f.wkt, buf, cap),
        None => 0,
    }
}

/// The GDAL metadata XML a full decode gives back (the source's GDAL_METADATA; without
/// its statistics when the file is lossy), as `vtz_get_crs` gives text. Returns 0
/// when the file has none (or `file` is null).
///
/// # Safety
/// `file` is null or an open handle; `buf` is null or holds `cap` writable bytes.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vtz_get_gdal_metadata(
    file: *const VtzFile,
    buf: *mut c_char,
    cap: usize,
) -> usize {
    // SAFETY: null or an open handle.
    match unsafe { file.as_ref() }.and_then(|f| f.gdal_metadata.as_ref()) {
        Some(x) => give_text(x, buf, cap),
        None => 0,
    }
}

/// The georeferencing as a GeoTIFF of 1 x 1 samples (geotransform, CRS as EPSG code, WKT or
/// GeoTIFF keys, pixel-is-point: what `vtz decode -o X.tif` writes), copied into `buf` when
/// `cap` bytes hold it. Returns the bytes it needs; 0 when the file is not georeferenced (or
/// `file` is null). For readers that interpret GeoTIFF keys themselves (GDAL: open it from
/// memory and take its spatial reference) when `vtz_get_crs` gives an empty string: a CRS
/// the source stored only as GeoTIFF keys.
///
/// # Safety
/// `file` is null or an open handle; `buf` is null or holds `cap` writable bytes.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vtz_get_georef_geotiff(
    file: *const VtzFile,
    buf: *mut u8,
    cap: usize,
) -> usize {
    // SAFETY: null or an open handle.
    let Some(f) = (unsafe { file.as_ref() }) else {
        return 0;
    };
    let b = f.georef_tiff.get_or_init(|| {
        let Some(g) = &f.info.georef else {
            return Vec::new();
        };
        catch_unwind(AssertUnwindSafe(|| {
            let mut r = Raster::from_values(1, 1, vec![0.0], None, SampleType::U8).ok()?;
            r.georef = Some(g.clone());
            vtz::formats::geotiff_bytes(&r).ok()
        }))
        .ok()
        .flatten()
        .unwrap_or_default()
    });
    if !buf.is_null() && cap >= b.len() {
        // SAFETY: `buf` holds `cap` ≥ b.len() writable bytes (the caller's promise).
        unsafe { std::ptr::copy_nonoverlapping(b.as_ptr(), buf, b.len()) };
    }
    b.len()
}

macro_rules! fill {
    ($dec:expr, $buf:expr, $n:expr, $t:ty, $as:expr) => {{
        // SAFETY: `$buf` holds `$n` samples of `$t` (checked against the caller's byte
        // count) and is suitably aligned (checked by the caller of this macro).
        let s = unsafe { std::slice::from_raw_parts_mut($buf as *mut $t, $n) };
        $dec.decode_into_as::<$t>(s, $as)
    }};
}

/// Decode the window of `width` × `height` samples at (`x`, `y`) (the whole raster: 0, 0,
/// its width, its height) into `buf`, row-major, as samples of `buf_type` (the file's
/// sample type or a wider one; a value the type cannot hold is `VTZ_ERR_INVALID_ARGUMENT`,
/// never a silent change). Nodata
/// samples get the nodata value (NaN for floats without one). `buf_bytes` must be exactly
/// width × height × the type's size. `threads`: 0 = all the machine offers. Only the tiles
/// (and, for fast-coded files, the rows) the window touches are decoded. The same bits for
/// any thread count and any window.
///
/// # Safety
/// `file` is null or an open handle; `buf` is null or holds `buf_bytes` writable bytes
/// aligned for `buf_type`.
#[unsafe(no_mangle)]
#[allow(clippy::too_many_arguments)]
pub unsafe extern "C" fn vtz_read(
    file: *const VtzFile,
    x: u32,
    y: u32,
    width: u32,
    height: u32,
    buf_type: i32,
    buf: *mut std::ffi::c_void,
    buf_bytes: usize,
    threads: u32,
) -> i32 {
    // SAFETY: the caller's promises, passed on.
    unsafe {
        read(
            file,
            0,
            [x, y, width, height],
            buf_type,
            buf,
            buf_bytes,
            threads,
            false,
        )
    }
}

/// As [`vtz_read`], from overview `level` (0: the full resolution, as `vtz_read`): the
/// raster of ⌈width / 2^level⌉ × ⌈height / 2^level⌉ samples, pixels 2^level times larger,
/// the same corner (GDAL's overview); the window is in the overview's samples. Sample (x, y)
/// is a decoded sample of the source at (x·2^level, y·2^level): in an untiled file the full
/// decode's there, bit for bit; in a tiled file the decode of the tile whose core holds it,
/// at that tile's nearest point of its own 2^level lattice. The residual layer's
/// interpolation codings decode only their coarse levels for it (about 1/4^level of the
/// work); other methods decode in full. `level` ≤ 30.
///
/// # Safety
/// As [`vtz_read`].
#[unsafe(no_mangle)]
#[allow(clippy::too_many_arguments)]
pub unsafe extern "C" fn vtz_read_overview(
    file: *const VtzFile,
    level: u32,
    x: u32,
    y: u32,
    width: u32,
    height: u32,
    buf_type: i32,
    buf: *mut std::ffi::c_void,
    buf_bytes: usize,
    threads: u32,
) -> i32 {
    // SAFETY: the caller's promises, passed on.
    unsafe {
        read(
            file,
            level,
            [x, y, width, height],
            buf_type,
            buf,
            buf_bytes,
            threads,
            false,
        )
    }
}

/// As [`vtz_read_overview`], giving what a GDAL band of the file holds (`VtzInfo::
/// value_type`; capi/README.md, "Output types"): the values, or, when
/// `VtzInfo::has_offset_scale` is 1, each value's integer code `(value − value_offset) /
/// value_scale` (nodata samples: `value_nodata`). `buf_type` is `value_type` or a wider
/// type. The GDAL plugin reads its bands with it.
///
/// # Safety
/// As [`vtz_read`].
#[unsafe(no_mangle)]
#[allow(clippy::too_many_arguments)]
pub unsafe extern "C" fn vtz_read_band(
    file: *const VtzFile,
    level: u32,
    x: u32,
    y: u32,
    width: u32,
    height: u32,
    buf_type: i32,
    buf: *mut std::ffi::c_void,
    buf_bytes: usize,
    threads: u32,
) -> i32 {
    // SAFETY: the caller's promises, passed on.
    unsafe {
        read(
            file,
            level,
            [x, y, width, height],
            buf_type,
            buf,
            buf_bytes,
            threads,
            true,
        )
    }
}

/// [`vtz_read`], [`vtz_read_overview`] (`level` 0: the full resolution) and, with `band`,
/// [`vtz_read_band`].
///
/// # Safety
/// As [`vtz_read`].
#[allow(clippy::too_many_arguments)]
unsafe fn read(
    file: *const VtzFile,
    level: u32,
    [x, y, width, height]: [u32; 4],
    buf_type: i32,
    buf: *mut std::ffi::c_void,
    buf_bytes: usize,
    threads: u32,
    band: bool,
) -> i32 {
    guard(|| {
        // SAFETY: null or an open handle.
        let Some(f) = (unsafe { file.as_ref() }) else {
            return Err(null("file"));
        };
        if buf.is_null() {
            return Err(null("buf"));
        }
        let t = sample_type(buf_type)?;
        let size = bytes_per_sample(t);
        let n = (width as usize)
            .checked_mul(height as usize)
            .ok_or_else(|| Error::invalid("the window's sample count overflows"))?;
        if n.checked_mul(size) != Some(buf_bytes) {
            return Err(Error::invalid(format!(
                "buf_bytes {buf_bytes} is not {width} x {height} samples of {size} bytes"
            )));
        }
        if !(buf as usize).is_multiple_of(size) {
            return Err(Error::invalid(format!(
                "buf is not aligned for samples of {size} bytes"
            )));
        }
        let mut dec = f
            .dec
            .lock()
            .map_err(|_| Error::invalid("the handle was poisoned by an earlier panic"))?;
        let mut opts = vtz::DecodeOptions::default();
        opts.window = Some(Window {
            x: x as usize,
            y: y as usize,
            width: width as usize,
            height: height as usize,
        });
        opts.overview = (level > 0).then_some(level);
        opts.threads = threads as usize;
        dec.options(opts);
        let dec = &mut *dec;
        let out = if band {
            dec.output_type()
        } else {
            vtz::OutputType::Values(f.info.sample_type)
        };
        let buf = buf as usize;
        vtz::on_threads(threads as usize, || {
            let buf = buf as *mut std::ffi::c_void;
            match t {
                SampleType::U8 => fill!(dec, buf, n, u8, out),
                SampleType::I16 => fill!(dec, buf, n, i16, out),
                SampleType::U16 => fill!(dec, buf, n, u16, out),
                SampleType::I32 => fill!(dec, buf, n, i32, out),
                SampleType::F32 => fill!(dec, buf, n, f32, out),
                _ => fill!(dec, buf, n, f64, out),
            }
        })?
    })
}

/// Options with their defaults: lossless, `best`, effort 5, vtz's tiling, all threads, no
/// nodata, no georeferencing.
#[unsafe(no_mangle)]
pub extern "C" fn vtz_encode_options_init() -> VtzEncodeOptions {
    VtzEncodeOptions {
        max_error: -1.0,
        max_error_percent: 0,
        method: std::ptr::null(),
        effort: 0,
        tile: 0,
        threads: 0,
        has_nodata: 0,
        nodata: 0.0,
        has_geotransform: 0,
        geotransform: [0.0, 1.0, 0.0, 0.0, 0.0, -1.0],
        pixel_is_point: 0,
        epsg: 0,
        crs_wkt: std::ptr::null(),
        gdal_metadata: std::ptr::null(),
        progress: None,
        progress_data: std::ptr::null_mut(),
        has_offset_scale: 0,
        value_offset: 0.0,
        value_scale: 1.0,
    }
}

/// A NUL-terminated UTF-8 string, or `None` for null.
///
/// # Safety
/// `p` is null or NUL-terminated.
unsafe fn text(p: *const c_char, what: &str) -> vtz::Result<Option<String>> {
    if p.is_null() {
        return Ok(None);
    }
    // SAFETY: not null, NUL-terminated (the caller's promise).
    let s = unsafe { CStr::from_ptr(p) }
        .to_str()
        .map_err(|_| Error::invalid(format!("{what} is not UTF-8")))?;
    Ok(Some(s.to_string()))
}

/// The raster and options of an encode call.
///
/// # Safety
/// As `vtz_encode`.
unsafe fn encode_job(
    data: *const std::ffi::c_void,
    data_type: i32,
    width: u32,
    height: u32,
    opts: *const VtzEncodeOptions,
) -> vtz::Result<(Raster, EncodeOptions, usize, Progress)> {
    if data.is_null() {
        return Err(null("data"));
    }
    let default = vtz_encode_options_init();
    // SAFETY: null or a valid VtzEncodeOptions.
    let o = unsafe { opts.as_ref() }.unwrap_or(&default);
    let t = sample_type(data_type)?;
    let n = (width as usize)
        .checked_mul(height as usize)
        .ok_or_else(|| Error::invalid("the raster's sample count overflows"))?;
    if !(data as usize).is_multiple_of(bytes_per_sample(t)) {
        return Err(Error::invalid("data is not aligned for its sample type"));
    }
    macro_rules! take {
        ($t:ty) => {{
            // SAFETY: `data` holds width × height samples of the type (the caller's
            // promise), aligned (checked above).
            let s = unsafe { std::slice::from_raw_parts(data as *const $t, n) };
            s.iter().map(|&v| v as f64).collect::<Vec<f64>>()
        }};
    }
    let values = match t {
        SampleType::U8 => take!(u8),
        SampleType::I16 => take!(i16),
        SampleType::U16 => take!(u16),
        SampleType::I32 => take!(i32),
        SampleType::F32 => take!(f32),
        _ => take!(f64),
    };
    let nodata = (o.has_nodata != 0 && !o.nodata.is_nan()).then_some(o.nodata);
    if let (Some(nd), Some((lo, hi))) = (nodata, t.int_range())
        && !(nd >= lo && nd <= hi && nd.fract() == 0.0)
    {
        return Err(Error::invalid(format!(
            "nodata {nd} is not a value of the sample type"
        )));
    }
    // Codes with a band offset and scale: the raster holds their values.
    let mapping = if o.has_offset_scale != 0 {
        let m = ValueMapping {
            offset: o.value_offset,
            scale: o.value_scale,
        };
        if !t.is_integer() {
            return Err(Error::invalid(
                "has_offset_scale needs integer codes (a data type VTZ_U8 ... VTZ_I32)",
            ));
        }
        if !(m.scale.is_finite() && m.scale != 0.0 && m.offset.is_finite()) {
            return Err(Error::invalid(format!(
                "value_scale {} / value_offset {} is not a usable mapping (a finite scale, not 0, and a finite offset)",
                m.scale, m.offset
            )));
        }
        Some(m)
    } else {
        None
    };
    let (values, nodata) = match mapping {
        Some(m) => (
            values.into_iter().map(|c| m.to_value(c)).collect(),
            nodata.map(|c| m.to_value(c)),
        ),
        None => (values, nodata),
    };
    let mut raster = Raster::from_values(width as usize, height as usize, values, nodata, t)?;
    if let Some(m) = mapping {
        raster.mapping = m;
    }
    // SAFETY: null or NUL-terminated (the caller's promise).
    let wkt = unsafe { text(o.crs_wkt, "crs_wkt") }?.filter(|w| !w.is_empty());
    // SAFETY: as above.
    raster.gdal_metadata = unsafe { text(o.gdal_metadata, "gdal_metadata") }?;
    if o.has_geotransform != 0 {
        // GDAL's order: x origin, pixel width, row rotation, y origin, column rotation,
        // pixel height (negative for north-up).
        let [origin_x, pixel_w, rot_row, origin_y, rot_col, neg_pixel_h] = o.geotransform;
        if rot_row != 0.0 || rot_col != 0.0 {
            return Err(Error::unsupported(
                "a rotated or sheared geotransform ([2] or [4] not 0)",
            ));
        }
        let pixel_h = -neg_pixel_h;
        if !(pixel_w > 0.0
            && pixel_h > 0.0
            && pixel_w.is_finite()
            && pixel_h.is_finite()
            && origin_x.is_finite()
            && origin_y.is_finite())
        {
            return Err(Error::invalid(format!(
                "geotransform {:?}: vtz takes north-up rasters ([1] > 0, [5] < 0)",
                o.geotransform
            )));
        }
        let point = o.pixel_is_point != 0;
        let (ox, oy) = if point {
            (origin_x + pixel_w / 2.0, origin_y - pixel_h / 2.0)
        } else {
            (origin_x, origin_y)
        };
        raster.georef = Some(Georef {
            origin: [ox, oy],
            pixel_size: [pixel_w, pixel_h],
            raster_type: if point {
                RasterType::Point
            } else {
                RasterType::Area
            },
            epsg: (o.epsg != 0).then_some(o.epsg),
            wkt,
            geokeys: None,
        });
    } else if o.epsg != 0 || wkt.is_some() {
        return Err(Error::invalid("a CRS without a geotransform"));
    }
    let mut eo = EncodeOptions::default();
    if o.max_error >= 0.0 {
        if !o.max_error.is_finite() {
            return Err(Error::invalid("max_error is not finite"));
        }
        eo.max_error = Some(if o.max_error_percent != 0 {
            ErrorBound::parse(&format!("{}%", o.max_error))?
        } else {
            ErrorBound::Abs(o.max_error)
        });
    } else if o.max_error_percent != 0 {
        return Err(Error::invalid("max_error_percent without a max_error"));
    }
    // SAFETY: null or NUL-terminated.
    if let Some(m) = unsafe { text(o.method, "method") }? {
        eo.methods = Method::parse_list(&m)?;
    }
    eo.effort = match o.effort {
        0 => None,
        e @ 1..=9 => Some(e as u8),
        e => {
            return Err(Error::invalid(format!(
                "effort {e} is not in 1..=9 (0 = the default, 5)"
            )));
        }
    };
    eo.tile = match o.tile {
        0 => None,
        -1 => Some(0),
        t if t >= 64 => Some(t as u32),
        t => {
            return Err(Error::invalid(format!(
                "tile {t} is not a side of at least 64 samples (0 = the default, -1 = never tile)"
            )));
        }
    };
    eo.threads = o.threads as usize;
    let progress = Progress(o.progress, o.progress_data);
    Ok((raster, eo, o.threads as usize, progress))
}

/// The caller's progress callback and its data.
#[derive(Clone, Copy)]
struct Progress(Option<unsafe extern "C" fn(f64, *mut c_void)>, *mut c_void);

// SAFETY: the encode runs on one thread of a pool while the caller's thread waits for it;
// the callback is called from that one thread, one call at a time, as its documentation
// says, and `progress_data` is only passed back to it.
unsafe impl Send for Progress {}

/// Encode with the caller's progress callback.
fn encode_with(
    raster: &Raster,
    eo: &EncodeOptions,
    threads: usize,
    p: Progress,
) -> vtz::Result<Vec<u8>> {
    vtz::on_threads(threads, move || {
        let p = p;
        let mut report = |f: f64| {
            if let Some(cb) = p.0 {
                // SAFETY: a callback the caller gave for this call, with its own data.
                unsafe { cb(f, p.1) }
            }
        };
        vtz::encode_progress(raster, eo, &mut report).map(|(bytes, _)| bytes)
    })?
}

/// Encode `width` × `height` samples of `data_type` at `data` (row-major, row 0 north) with
/// `opts` (null: the defaults). On success `*out` holds `*out_len` bytes of a `.vtz`, to be
/// released with `vtz_free_bytes`; else `*out` is null and `*out_len` 0. The encoder checks
/// the bound on exactly what a decoder will produce.
///
/// # Safety
/// `data` holds width × height samples of the type, aligned for it; `opts` is null or a
/// valid `VtzEncodeOptions` whose strings are null or NUL-terminated; `out` and `out_len`
/// are null or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vtz_encode(
    data: *const std::ffi::c_void,
    data_type: i32,
    width: u32,
    height: u32,
    opts: *const VtzEncodeOptions,
    out: *mut *mut u8,
    out_len: *mut usize,
) -> i32 {
    guard(|| {
        if out.is_null() || out_len.is_null() {
            return Err(null("out or out_len"));
        }
        // SAFETY: both writable (checked not null; the caller's promise).
        unsafe {
            *out = std::ptr::null_mut();
            *out_len = 0;
        }
        // SAFETY: the caller's promises, passed on.
        let (raster, eo, threads, progress) =
            unsafe { encode_job(data, data_type, width, height, opts) }?;
        let bytes = encode_with(&raster, &eo, threads, progress)?;
        let boxed = bytes.into_boxed_slice();
        let len = boxed.len();
        // SAFETY: as above; the box is released by vtz_free_bytes with the same length.
        unsafe {
            *out = Box::into_raw(boxed).cast::<u8>();
            *out_len = len;
        }
        Ok(())
    })
}

/// Encode as `vtz_encode` and write the file at `path` atomically (a temporary file, then
/// renamed: never a half-written output). An existing file is replaced.
///
/// # Safety
/// As `vtz_encode`; `path` is null or NUL-terminated.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vtz_encode_to_path(
    data: *const std::ffi::c_void,
    data_type: i32,
    width: u32,
    height: u32,
    opts: *const VtzEncodeOptions,
    path: *const c_char,
) -> i32 {
    guard(|| {
        // SAFETY: null or NUL-terminated.
        let Some(p) = (unsafe { text(path, "path") })? else {
            return Err(null("path"));
        };
        // SAFETY: the caller's promises, passed on.
        let (raster, eo, threads, progress) =
            unsafe { encode_job(data, data_type, width, height, opts) }?;
        let bytes = encode_with(&raster, &eo, threads, progress)?;
        vtz::formats::write_file(std::path::Path::new(&p), bytes, true)
    })
}

/// Release bytes from `vtz_encode` (null: nothing happens).
///
/// # Safety
/// `bytes` and `len` are exactly what `vtz_encode` gave, released once.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vtz_free_bytes(bytes: *mut u8, len: usize) {
    if !bytes.is_null() {
        // SAFETY: made by Box::into_raw of a boxed slice of `len` bytes in vtz_encode.
        drop(unsafe { Box::from_raw(std::ptr::slice_from_raw_parts_mut(bytes, len)) });
    }
}

/// The message of the last failed call on this thread (empty after a success), valid until
/// the thread's next call into vtz.
#[unsafe(no_mangle)]
pub extern "C" fn vtz_last_error() -> *const c_char {
    LAST_ERROR.with(|e| e.borrow().as_ptr())
}

/// The library's version, e.g. "0.1.0" (static).
#[unsafe(no_mangle)]
pub extern "C" fn vtz_version() -> *const c_char {
    static V: &CStr =
        match CStr::from_bytes_with_nul(concat!(env!("CARGO_PKG_VERSION"), "\0").as_bytes()) {
            Ok(v) => v,
            Err(_) => c"",
        };
    V.as_ptr()
}
