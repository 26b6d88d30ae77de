//! Speed of the residual layer alone (criterion, one thread: the layer is sequential).
//!
//! `cargo bench --bench residual` — samples/s as throughput. Istria 2400² (the crate's
//! corpus, 5.76 M samples) and, with `../shared/corpus`, the 1201² White Mountains tile;
//! lossless, 1 m and 1 % of the range, at effort 1 (the fast coding) and at the default
//! effort (the range-coded predictors). benches/README.md
//! ("Residual layer: speed") has the table, beside SZ3 measured in the same run.

#[path = "../tests/common/mod.rs"]
mod common;

use common::{encode_opts, read_corpus, read_shared};
use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use std::time::Duration;
use vtz::{ErrorBound, Method};

fn rasters() -> Vec<(String, vtz::Raster)> {
    let mut v = vec![(
        "istria_2400".to_string(),
        read_corpus("srtm1_N45E013_istria_crop2400.png"),
    )];
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
            .measurement_time(Duration::from_secs(10))
            .warm_up_time(Duration::from_secs(1));
        g.throughput(Throughput::Elements(r.len() as u64));
        for (label, bound) in [
            ("lossless", None),
            ("1m", Some(ErrorBound::Abs(1.0))),
            ("1pct", Some(ErrorBound::PercentOfRange(1.0))),
        ] {
            for effort in [1u8, vtz::DEFAULT_EFFORT] {
                let mut opts = encode_opts(&[Method::RESIDUAL], bound);
                opts.effort = Some(effort);
                let bytes = vtz::encode(&r, &opts).unwrap();
                g.bench_function(format!("encode_{label}_e{effort}"), |b| {
                    b.iter(|| vtz::encode(&r, &opts).unwrap())
                });
                g.bench_function(format!("decode_{label}_e{effort}"), |b| {
                    b.iter(|| vtz::decode(&bytes).unwrap())
                });
            }
        }
        g.finish();
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
