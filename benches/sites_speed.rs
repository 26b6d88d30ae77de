//! Speed of the sites (Sibson) method, one thread: encode and decode wall time per raster and
//! bound, median of paired runs, as samples/s. Not criterion: it times whole encodes that
//! take seconds, and it is the scaling script's engine (`benches/sites_scaling.sh`).
//!
//! `cargo bench --bench sites_speed -- [--runs N] [--bounds 1%,10%] [--decode-only] RASTER…`
//! (default: White Mountains 1201², Half Dome and Istria 2400² from `../shared/corpus`).
//! Run it under `taskset -c 0` for one core: the encoder's closed loop and the decoder use
//! every core they are given, so one core makes the times per-thread times.
//! Prints one tab-separated row per (raster, bound).

#[path = "../tests/common/mod.rs"]
mod common;

use std::path::PathBuf;
use std::time::Instant;
use vtz::{DecodeOptions, EncodeOptions, ErrorBound, Method};

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

fn main() {
    let mut args: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| a != "--bench")
        .collect();
    let mut take = |flag: &str| -> Option<String> {
        let i = args.iter().position(|a| a == flag)?;
        let v = args.get(i + 1).cloned();
        args.drain(i..(i + 2).min(args.len()));
        v
    };
    let runs: usize = take("--runs").map_or(3, |v| v.parse().expect("--runs N"));
    let bounds = take("--bounds").unwrap_or_else(|| "1%,10%".into());
    let decode_only = args.iter().any(|a| a == "--decode-only");
    args.retain(|a| a != "--decode-only");
    let files: Vec<PathBuf> = if args.is_empty() {
        let Some(dir) = common::shared_corpus() else {
            return;
        };
        [
            "srtm3_N44W072_white_mountains.f32",
            "ned1_halfdome_yosemite.f32",
            "srtm1_N45E013_istria_crop2400.f32",
        ]
        .iter()
        .map(|f| dir.join(f))
        .collect()
    } else {
        args.iter().map(PathBuf::from).collect()
    };
    println!("raster\tsamples\tbound\tbytes\tencode_s\tdecode_s\tencode_Msps\tdecode_Msps");
    for f in files {
        let r = vtz::read_path(&f, &Default::default()).expect("read raster");
        let n = r.len() as f64;
        for b in bounds.split(',') {
            let bound = ErrorBound::parse(b).expect("bound");
            let mut opts = EncodeOptions::default();
            opts.methods = vec![Method::SIBSON];
            opts.max_error = Some(bound);
            let mut dopts = DecodeOptions::default();
            dopts.threads = 1;
            let mut enc = Vec::new();
            let mut dec = Vec::new();
            let mut bytes = vtz::encode(&r, &opts).expect("encode");
            for _ in 0..runs {
                if !decode_only {
                    let t = Instant::now();
                    bytes = vtz::encode(&r, &opts).expect("encode");
                    enc.push(t.elapsed().as_secs_f64());
                }
                let t = Instant::now();
                let d = vtz::decode_with(&bytes, &dopts).expect("decode");
                dec.push(t.elapsed().as_secs_f64());
                assert_eq!(d.len(), r.len());
            }
            let e = if enc.is_empty() {
                f64::NAN
            } else {
                median(enc)
            };
            let d = median(dec);
            println!(
                "{}\t{}\t{}\t{}\t{:.4}\t{:.4}\t{:.3}\t{:.3}",
                f.file_stem().unwrap_or_default().to_string_lossy(),
                r.len(),
                b,
                bytes.len(),
                e,
                d,
                n / e / 1e6,
                n / d / 1e6
            );
        }
    }
}
