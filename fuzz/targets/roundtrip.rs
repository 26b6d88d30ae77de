//! Encode → decode on small fuzzed rasters: every method (and `best`) at efforts 1, 5 and 9
//! (the residual layer's fast coding, its default, both), every sample type,
//! nodata holes, absolute and percent bounds and lossless. The decode must have the source's
//! shape, type and nodata pattern, every valid sample within the bound the encoder reports
//! (and within the requested bound), and a window decode must equal the crop. With the top
//! bit of the type byte set ("wide"), samples are raw bits instead (f32 or f64 bits, any
//! magnitude up to ±3.4e38 or ±1.8e308, non-finite ones holes; integer codes over the
//! type's whole range): lattices as wide as the format allows and none at all.
use super::check;
use vtz::{EncodeOptions, ErrorBound, Method, Raster, SampleType, Window};

/// One input of the `roundtrip` fuzz target (also replayed over its seeds by `tests/suite/fuzz_seeds.rs`).
pub fn run(data: &[u8]) {
    if data.len() < 6 {
        return;
    }
    let width = 1 + data[0] as usize % 24;
    let height = 1 + data[1] as usize % 24;
    let Some(st) = SampleType::from_code((data[2] & 0x7f) % 6) else {
        return;
    };
    let wide = data[2] & 0x80 != 0;
    let methods: Vec<Method> = Method::all().collect();
    let pick = data[3] as usize % (methods.len() + 1);
    let bound_code = data[4];
    let scale = 1u32 << (data[5] % 12);
    // The residual layer's codings: the fast one (effort 1), the default, and all (9).
    let effort = [1u8, vtz::DEFAULT_EFFORT, 9][(data[5] / 12) as usize % 3];
    let body = &data[6..];
    let n = width * height;
    let (lo, hi) = st.int_range().unwrap_or((-1e6, 1e6));
    let mut values = Vec::with_capacity(n);
    for i in 0..n {
        if wide {
            let b = |k: usize| body.get(8 * i + k).copied().unwrap_or(0);
            let b8: [u8; 8] = std::array::from_fn(b);
            let v = match st {
                SampleType::F32 => f32::from_le_bytes([b8[0], b8[1], b8[2], b8[3]]) as f64,
                SampleType::F64 => f64::from_le_bytes(b8),
                _ => {
                    let code = i32::from_le_bytes([b8[0], b8[1], b8[2], b8[3]]) as f64;
                    code.rem_euclid(hi - lo + 1.0) + lo
                }
            };
            values.push(if v.is_finite() { v } else { f64::NAN });
            continue;
        }
        let b = |k: usize| body.get(2 * i + k).copied().unwrap_or(0);
        let raw = i16::from_le_bytes([b(0), b(1)]);
        let v = if raw == i16::MIN {
            f64::NAN // a hole
        } else {
            let v = raw as f64 * scale as f64 / 64.0;
            match st {
                SampleType::F32 => (v as f32) as f64,
                SampleType::F64 => v,
                _ => v.round().clamp(lo, hi),
            }
        };
        values.push(v);
    }
    let nodata = if st.is_integer() { Some(lo) } else { None };
    let values: Vec<f64> = values
        .into_iter()
        .map(|v| {
            if v.is_nan() {
                nodata.unwrap_or(f64::NAN)
            } else {
                v
            }
        })
        .collect();
    let Ok(src) = Raster::from_values(width, height, values, nodata, st) else {
        return;
    };
    let bound = match bound_code % 4 {
        0 => None,
        1 => Some(ErrorBound::Abs((bound_code / 4) as f64 * 0.25)),
        2 => Some(ErrorBound::PercentOfRange((bound_code / 4) as f64 * 0.2)),
        _ => Some(ErrorBound::Abs((bound_code / 4) as f64 * 7.5)),
    };
    let mut opts = EncodeOptions::default();
    opts.max_error = bound;
    opts.effort = Some(effort);
    if pick < methods.len() {
        opts.methods = vec![methods[pick]];
    }
    let Ok((bytes, report)) = vtz::encode_report(&src, &opts) else {
        return;
    };
    let requested = bound.map_or(0.0, |b| b.absolute(src.valid_range()));
    assert!(
        report.max_error <= requested,
        "reported {} over {requested}",
        report.max_error
    );
    let dec = vtz::decode(&bytes)
        .unwrap_or_else(|e| panic!("an encoded file decodes: {e} (methods {:?})", opts.methods));
    assert_eq!(
        (dec.width, dec.height, dec.sample_type),
        (width, height, st)
    );
    for i in 0..n {
        assert_eq!(dec.is_valid(i), src.is_valid(i), "validity of sample {i}");
        if src.is_valid(i) {
            let e = (dec.data[i] - src.data[i]).abs();
            assert!(
                e <= report.max_error,
                "sample {i}: error {e} over {}",
                report.max_error
            );
        }
    }
    let win = Window {
        x: width / 2,
        y: height / 2,
        width: width - width / 2,
        height: height - height / 2,
    };
    let mut dopts = vtz::DecodeOptions::default();
    dopts.window = Some(win);
    let part = vtz::decode_with(&bytes, &dopts).expect("a window decodes");
    check::window_is_crop(&part, &dec, win);
}
