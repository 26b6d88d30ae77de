//! Any bytes as a point-set file (`.vtz` version 3): the summary, the full decode, a decode
//! of the first level only, the sites alone, and a rasterization of the surface. Checksums
//! are not enforced in fuzzing builds (`cfg(fuzzing)`), so the fuzzer reaches the payload
//! parsers behind them. Errors are fine; panics, aborts and allocations beyond the limits
//! are not.
use vtz::{DecodePoints, Limits, RasterizePoints};

/// One input of the `points` fuzz target (also replayed over its seeds by `tests/suite/fuzz_seeds.rs`).
pub fn run(data: &[u8]) {
    let limits = Limits {
        max_samples: 1 << 20,
        max_section_bytes: 1 << 20,
    };
    let Ok(info) = vtz::points_info(data, limits) else {
        // Whatever the summary rejects, the decoders reject too.
        assert!(vtz::decode_points(data, &opts(limits, false, None)).is_err());
        return;
    };
    if let Ok(p) = vtz::decode_points(data, &opts(limits, false, None)) {
        assert_eq!(p.len() as u64, info.points);
        assert_eq!(p.values.len(), info.columns.len());
        assert!(p.values.iter().all(|c| c.len() == p.len()));
    }
    if let Ok(p) = vtz::decode_points(data, &opts(limits, true, None)) {
        assert_eq!(p.len(), info.sites);
    }
    let _ = vtz::decode_points(data, &opts(limits, false, Some(1)));
    // Cells of 1 to 4 steps of the position grid.
    let k = 1.0 + (data.last().copied().unwrap_or(0) % 4) as f64;
    let mut r = RasterizePoints::new(info.resolution * k);
    r.limits = limits;
    if let Ok(raster) = vtz::rasterize_points(data, &r) {
        assert!(raster.len() as u64 <= limits.max_samples);
    }
    let _ = vtz::rasterize_points(data, &r.only_positions(true));
}

fn opts(limits: Limits, sites_only: bool, level: Option<usize>) -> DecodePoints {
    let mut o = DecodePoints::new().sites_only(sites_only).level(level);
    o.limits = limits;
    o
}
