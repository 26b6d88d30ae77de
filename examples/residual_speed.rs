//! Speed of the residual layer in-process (no file I/O in the timed part): encodes one
//! raster with `--method residual` at an effort, decodes it, RUNS times each, and prints
//! one JSON line with the bytes and the best and median M samples/s of each. Threads follow
//! rayon's pool (`RAYON_NUM_THREADS=1` for one core).
//!
//! `cargo run --release --example residual_speed -- FILE BOUND EFFORT RUNS`
//! (BOUND: `lossless`, an absolute bound `1`, or `1%` of the value range), or
//! `… -- FILE.vtz RUNS` to decode a file only (for `perf stat` instruction counts).
//! With `RESIDUAL_SPEED_OUT=F.vtz` the encoded bytes are written to F.vtz.

use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() == 3 {
        let bytes = std::fs::read(&args[1])?;
        let runs: usize = args[2].parse()?;
        let mut v = Vec::new();
        for _ in 0..runs {
            let t = Instant::now();
            let r = vtz::decode(&bytes)?;
            v.push(r.len() as f64 / 1e6 / t.elapsed().as_secs_f64());
        }
        v.sort_by(f64::total_cmp);
        println!("{}", serde_json::json!({"file": args[1], "decode_msps": v}));
        return Ok(());
    }
    if args.len() != 5 {
        return Err("usage: residual_speed FILE BOUND EFFORT RUNS".into());
    }
    let raster = vtz::read_path(std::path::Path::new(&args[1]), &Default::default())?;
    let mut enc = vtz::Encoder::new().method(vtz::Method::RESIDUAL);
    if args[2] != "lossless" {
        let b = match args[2].strip_suffix('%') {
            Some(p) => vtz::ErrorBound::PercentOfRange(p.parse()?),
            None => vtz::ErrorBound::Abs(args[2].parse()?),
        };
        enc = enc.max_error(b);
    }
    enc.options_mut().effort = Some(args[3].parse()?);
    let runs: usize = args[4].parse()?;
    let n = raster.len() as f64 / 1e6;
    let (mut te, mut td) = (Vec::new(), Vec::new());
    let mut size = 0;
    for _ in 0..runs {
        let t = Instant::now();
        let bytes = enc.encode(&raster)?;
        te.push(n / t.elapsed().as_secs_f64());
        let t = Instant::now();
        let back = vtz::decode(&bytes)?;
        td.push(n / t.elapsed().as_secs_f64());
        size = bytes.len();
        assert_eq!(back.data.len(), raster.data.len());
        if let Some(p) = std::env::var_os("RESIDUAL_SPEED_OUT") {
            std::fs::write(p, &bytes)?;
        }
    }
    let stats = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        (v[v.len() - 1], v[v.len() / 2])
    };
    let (eb, em) = stats(&mut te);
    let (db, dm) = stats(&mut td);
    println!(
        "{}",
        serde_json::json!({"file": args[1], "bound": args[2], "effort": args[3], "bytes": size,
            "encode_msps_best": eb, "encode_msps_median": em,
            "decode_msps_best": db, "decode_msps_median": dm})
    );
    Ok(())
}
