//! The native side of web/bench.mjs: the same decode and f32 conversion as `vtz_decode`, in
//! process, on a chosen number of threads (1 to compare with wasm, which has one).
//!   cargo run --release --example native_bench -- [--threads N] [--reps N] FILE.vtz...
fn main() {
    let (mut threads, mut reps, mut files) = (1usize, 20usize, Vec::new());
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--threads" => {
                threads = args
                    .next()
                    .and_then(|s| s.parse().ok())
                    .expect("--threads N")
            }
            "--reps" => reps = args.next().and_then(|s| s.parse().ok()).expect("--reps N"),
            _ => files.push(a),
        }
    }
    let mut opts = vtz::DecodeOptions::default();
    opts.threads = threads;
    for f in files {
        let bytes = std::fs::read(&f).expect("read");
        let mut times = Vec::new();
        let (mut w, mut h) = (0, 0);
        for _ in 0..reps {
            let t = std::time::Instant::now();
            let r = vtz::decode_with(&bytes, &opts).expect("decode");
            let fill = r.nodata.map_or(f32::NAN, |v| v as f32);
            let v: Vec<f32> = (0..r.len())
                .map(|i| {
                    if r.is_valid(i) {
                        r.data[i] as f32
                    } else {
                        fill
                    }
                })
                .collect();
            times.push(t.elapsed().as_secs_f64() * 1e3);
            std::hint::black_box(v);
            (w, h) = (r.width, r.height);
        }
        let first = times[0];
        let mut rest = times[1..].to_vec();
        rest.sort_by(f64::total_cmp);
        println!(
            "{f}: {w}x{h}, {} B, {threads} thread(s); decode first {first:.1} ms, min {:.2} ms, median {:.2} ms",
            bytes.len(),
            rest[0],
            rest[rest.len() / 2]
        );
    }
}
