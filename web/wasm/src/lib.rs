//! vtz's decoder as a WebAssembly module with a plain C ABI, for `web/src/vtz.js` (no
//! wasm-bindgen: the JavaScript glue is hand-written).
//!
//! The module keeps one state (wasm32-unknown-unknown has one thread): an input buffer that
//! JavaScript fills, the heights of the last decode, its RGBA packing and the last error.
//! Every export returns plain numbers; buffers are read by JavaScript through `memory` at
//! the pointers the getters give, valid until the next call that changes that buffer.
//! There is no `unsafe` block: the input is a `Vec` the module owns and hands out the
//! address of, so `vtz_decode` checks that it is given that buffer instead of trusting a
//! pointer. (`#[unsafe(no_mangle)]` is the only unsafe attribute.)
//!
//! Status codes: 0 = success, 1 = error (message from `vtz_error_ptr`/`vtz_error_len`).

use std::cell::RefCell;

/// `vtz_decode` flag: nodata samples hold the header's nodata value (as f32), as in the
/// golden files' `.expected.f32` and `vtz decode -o X.f32`; without it they are NaN.
pub const NODATA_AS_VALUE: u32 = 1;

/// `vtz_to_rgba` encoding: Terrarium, `height = R·256 + G + B/256 − 32768`.
pub const TERRARIUM: u32 = 0;
/// `vtz_to_rgba` encoding: `height = (R·65536 + G·256 + B)·quantum − base_shift`
/// (MapLibre's `custom` raster-dem encoding).
pub const CUSTOM: u32 = 1;

#[derive(Default)]
struct State {
    input: Vec<u8>,
    heights: Vec<f32>,
    width: u32,
    height: u32,
    /// The header's nodata value, when `heights` holds it for nodata (`NODATA_AS_VALUE`).
    nodata_value: Option<f32>,
    /// The header's nodata value (NaN when it has none).
    nodata: f64,
    rgba: Vec<u8>,
    error: String,
}

thread_local! {
    static STATE: RefCell<State> = RefCell::new(State { nodata: f64::NAN, ..State::default() });
}

fn with<T>(f: impl FnOnce(&mut State) -> T) -> T {
    STATE.with(|s| f(&mut s.borrow_mut()))
}

fn status(s: &mut State, r: Result<(), String>) -> i32 {
    match r {
        Ok(()) => {
            s.error.clear();
            0
        }
        Err(e) => {
            s.error = e;
            1
        }
    }
}

/// Make the input buffer `len` bytes long (zeroed) and return its address, for JavaScript to
/// copy a `.vtz` stream into. Replaces the previous input buffer.
#[unsafe(no_mangle)]
pub extern "C" fn vtz_alloc(len: usize) -> *mut u8 {
    with(|s| {
        s.input = vec![0; len];
        s.input.as_mut_ptr()
    })
}

/// Release the input buffer (and the decoded heights and RGBA: the module's memory does
/// not shrink, but it is reused).
#[unsafe(no_mangle)]
pub extern "C" fn vtz_free() {
    with(|s| {
        s.input = Vec::new();
        s.heights = Vec::new();
        s.rgba = Vec::new();
    })
}

/// Decode the `.vtz` raster stream in the input buffer (`ptr` must be what `vtz_alloc`
/// returned, `len` at most its length) to f32 heights, row-major from the top row.
/// `flags`: [`NODATA_AS_VALUE`] or 0 (nodata → NaN).
#[unsafe(no_mangle)]
pub extern "C" fn vtz_decode(ptr: *const u8, len: usize, flags: u32) -> i32 {
    with(|s| {
        s.heights.clear();
        s.width = 0;
        s.height = 0;
        s.nodata = f64::NAN;
        s.nodata_value = None;
        let r = if !std::ptr::eq(ptr, s.input.as_ptr()) || len > s.input.len() {
            Err("vtz_decode: the input must be the buffer vtz_alloc returned".to_string())
        } else {
            decode(s, len, flags & NODATA_AS_VALUE != 0).map_err(|e| e.to_string())
        };
        status(s, r)
    })
}

/// The same conversion as the golden tests' `as_f32_bytes` (tests/suite/golden.rs) and the raw
/// `.f32` writer: valid samples `as f32`, nodata samples the header's nodata `as f32` (or
/// NaN).
fn decode(s: &mut State, len: usize, nodata_as_value: bool) -> vtz::Result<()> {
    let r = vtz::decode(&s.input[..len])?;
    let fill = if nodata_as_value {
        r.nodata.map_or(f32::NAN, |v| v as f32)
    } else {
        f32::NAN
    };
    s.heights.reserve_exact(r.len());
    s.heights.extend((0..r.len()).map(|i| {
        if r.is_valid(i) {
            r.data[i] as f32
        } else {
            fill
        }
    }));
    s.width = r.width as u32;
    s.height = r.height as u32;
    s.nodata = r.nodata.unwrap_or(f64::NAN);
    s.nodata_value = if nodata_as_value {
        r.nodata.map(|v| v as f32)
    } else {
        None
    };
    Ok(())
}

/// Width of the last decode (0 after an error).
#[unsafe(no_mangle)]
pub extern "C" fn vtz_width() -> u32 {
    with(|s| s.width)
}

/// Height of the last decode (0 after an error).
#[unsafe(no_mangle)]
pub extern "C" fn vtz_height() -> u32 {
    with(|s| s.height)
}

/// The header's nodata value of the last decode (NaN when it has none).
#[unsafe(no_mangle)]
pub extern "C" fn vtz_nodata() -> f64 {
    with(|s| s.nodata)
}

/// Address of the heights (`vtz_heights_len` f32s).
#[unsafe(no_mangle)]
pub extern "C" fn vtz_heights_ptr() -> *mut f32 {
    with(|s| s.heights.as_mut_ptr())
}

/// Number of heights (width × height).
#[unsafe(no_mangle)]
pub extern "C" fn vtz_heights_len() -> usize {
    with(|s| s.heights.len())
}

/// Make the heights buffer `width × height` NaNs (for JavaScript to copy heights into
/// before `vtz_to_rgba`) and return its address (null if the size overflows).
#[unsafe(no_mangle)]
pub extern "C" fn vtz_set_heights(width: u32, height: u32) -> *mut f32 {
    with(|s| {
        let Some(n) = (width as usize).checked_mul(height as usize) else {
            return std::ptr::null_mut();
        };
        s.heights = vec![f32::NAN; n];
        (s.width, s.height, s.nodata, s.nodata_value) = (width, height, f64::NAN, None);
        s.heights.as_mut_ptr()
    })
}

/// Pack the heights into RGBA8 (alpha 255), for MapLibre's `raster-dem`: the 24-bit code
/// `n = round((h + base_shift) / quantum)` clamped to 0..=2²⁴−1, `R = n >> 16`,
/// `G = (n >> 8) & 255`, `B = n & 255`. [`TERRARIUM`] is quantum 1/256, base_shift 32768
/// (the arguments are then ignored); [`CUSTOM`] takes them. Nodata (NaN, or the nodata
/// value under `NODATA_AS_VALUE`) packs `fill`.
#[unsafe(no_mangle)]
pub extern "C" fn vtz_to_rgba(encoding: u32, quantum: f64, base_shift: f64, fill: f64) -> i32 {
    with(|s| {
        let r = match encoding {
            TERRARIUM => pack(s, 1.0 / 256.0, 32768.0, fill),
            CUSTOM => pack(s, quantum, base_shift, fill),
            e => Err(format!("vtz_to_rgba: unknown encoding {e}")),
        };
        status(s, r)
    })
}

fn pack(s: &mut State, quantum: f64, base_shift: f64, fill: f64) -> Result<(), String> {
    if !(quantum.is_finite() && quantum > 0.0) {
        return Err(format!(
            "the quantum must be a positive number, not {quantum}"
        ));
    }
    if !base_shift.is_finite() || !fill.is_finite() {
        return Err(format!(
            "baseShift ({base_shift}) and fill ({fill}) must be finite"
        ));
    }
    const MAX: f64 = ((1 << 24) - 1) as f64;
    let nodata = s.nodata_value;
    let mut rgba = std::mem::take(&mut s.rgba);
    rgba.clear();
    rgba.resize(4 * s.heights.len(), 0);
    // One pass writing each pixel's four bytes in place (a `flat_map` into `extend` ran
    // 3 ms for a 512² tile in V8); `floor` is one wasm instruction where `f64::round` is a
    // call, and for v ≥ 0 `floor(v)`, plus one when the fraction is ≥ ½, is `round(v)`.
    // A power-of-two quantum (Terrarium's 1/256) divides exactly as a multiplication by
    // its inverse, which is several times cheaper than a division: the same codes.
    let pow2 = quantum.is_normal() && quantum.to_bits() & ((1 << 52) - 1) == 0;
    let inv = 1.0 / quantum;
    for (px, &h) in rgba.chunks_exact_mut(4).zip(&s.heights) {
        let h = if h.is_nan() || nodata == Some(h) {
            fill
        } else {
            h as f64
        };
        let x = h + base_shift;
        let v = (if pow2 { x * inv } else { x / quantum }).clamp(0.0, MAX);
        let f = v.floor();
        let n = (if v - f >= 0.5 { f + 1.0 } else { f }) as u32;
        px.copy_from_slice(&(n.swap_bytes() >> 8 | 0xff00_0000).to_le_bytes());
    }
    s.rgba = rgba;
    Ok(())
}

/// Address of the RGBA bytes of the last `vtz_to_rgba`.
#[unsafe(no_mangle)]
pub extern "C" fn vtz_rgba_ptr() -> *const u8 {
    with(|s| s.rgba.as_ptr())
}

/// Number of RGBA bytes (4 × width × height).
#[unsafe(no_mangle)]
pub extern "C" fn vtz_rgba_len() -> usize {
    with(|s| s.rgba.len())
}

/// Address of the last error message (UTF-8, `vtz_error_len` bytes; empty after a success).
#[unsafe(no_mangle)]
pub extern "C" fn vtz_error_ptr() -> *const u8 {
    with(|s| s.error.as_ptr())
}

/// Length of the last error message in bytes.
#[unsafe(no_mangle)]
pub extern "C" fn vtz_error_len() -> usize {
    with(|s| s.error.len())
}
