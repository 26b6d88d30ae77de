//! Encode and decode speed of vtz's methods on corpus rasters (criterion).
//!
//! `cargo bench --bench codec` — samples/s are reported as throughput (elements = samples).
//! Methods: sibson, grid and haar at 1 % (sibson also at 10 %, grid and haar also lossless),
//! fis at 10 % (the tightest bound it meets on these rasters). A method whose encode fails on a raster is skipped with a note on stderr.
//! Uses `corpus/scape_crater.png` (154 224 samples) and, when `../shared/corpus` is present,
//! the 1201² White Mountains SRTM tile.

#[path = "../tests/common/mod.rs"]
mod common;

use common::{decode_opts, encode_opts, read_corpus, read_shared};
use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use std::time::Duration;
use vtz::{ErrorBound, Method};

fn rasters() -> Vec<(String, vtz::Raster)> {
    let mut v = vec![("scape_crater".to_string(), read_corpus("scape_crater.png"))];
    v.extend(
        read_shared("srtm3_N44W072_white_mountains.f32")
            .map(|r| ("white_mountains_1201".to_string(), r)),
    );
    v
}

fn bench(c: &mut Criterion) {
    for (name, r) in rasters() {
        let mut g = c.benchmark_group(&name);
        g.sample_size(10)
            .measurement_time(Duration::from_secs(8))
            .warm_up_time(Duration::from_secs(1));
        g.throughput(Throughput::Elements(r.len() as u64));
        for (label, method, bound) in [
            (
                "sibson_1pct",
                Method::SIBSON,
                Some(ErrorBound::PercentOfRange(1.0)),
            ),
            (
                "sibson_10pct",
                Method::SIBSON,
                Some(ErrorBound::PercentOfRange(10.0)),
            ),
            (
                "grid_1pct",
                Method::GRID,
                Some(ErrorBound::PercentOfRange(1.0)),
            ),
            ("grid_lossless", Method::GRID, None),
            // FIS meets no bound below ~6–10 % on these rasters (it says so): bench it at 10 %.
            (
                "fis_10pct",
                Method::FIS,
                Some(ErrorBound::PercentOfRange(10.0)),
            ),
            (
                "haar_1pct",
                Method::HAAR,
                Some(ErrorBound::PercentOfRange(1.0)),
            ),
            ("haar_lossless", Method::HAAR, None),
        ] {
            let opts = encode_opts(&[method], bound);
            // A method that cannot meet the request here (or is not implemented) is skipped
            // with a note instead of failing the whole run.
            let bytes = match vtz::encode(&r, &opts) {
                Ok(b) => b,
                Err(e) => {
                    eprintln!("note: {name}: skipping {label}: {e}");
                    continue;
                }
            };
            if let Err(e) = vtz::decode(&bytes) {
                eprintln!("note: {name}: skipping {label}: decoding failed: {e}");
                continue;
            }
            g.bench_function(format!("encode_{label}"), |b| {
                b.iter(|| vtz::encode(&r, &opts).unwrap())
            });
            for threads in [1, 2] {
                let d = decode_opts(|o| o.threads = threads);
                g.bench_function(format!("decode_{label}_t{threads}"), |b| {
                    b.iter(|| vtz::decode_with(&bytes, &d).unwrap())
                });
            }
        }
        g.finish();
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
