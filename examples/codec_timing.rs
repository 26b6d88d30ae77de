//! Times the library's encode and decode of one raster in-process (no file I/O in the
//! timed part), for comparison with the same calls through the Python package
//! (`benches/python/overhead.py`). Prints one JSON line: every run's seconds.
//!
//! `cargo run --release --example codec_timing -- FILE MAX_ERROR RUNS`

use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() != 4 {
        return Err("usage: codec_timing FILE MAX_ERROR RUNS".into());
    }
    let mut raster = vtz::read_path(std::path::Path::new(&args[1]), &Default::default())?;
    // The Python side encodes a bare array (vtz.encode has no georeferencing): the same
    // samples, type and nodata here, so both write the same bytes.
    raster.georef = None;
    raster.gdal_metadata = None;
    let bound: f64 = args[2].parse()?;
    let runs: usize = args[3].parse()?;
    let enc = vtz::Encoder::new().max_error(vtz::ErrorBound::Abs(bound));
    let (mut te, mut td) = (Vec::new(), Vec::new());
    let mut size = 0;
    for _ in 0..runs {
        let t = Instant::now();
        let bytes = enc.encode(&raster)?;
        te.push(t.elapsed().as_secs_f64());
        let t = Instant::now();
        let back = vtz::decode(&bytes)?;
        td.push(t.elapsed().as_secs_f64());
        size = bytes.len();
        assert_eq!(back.data.len(), raster.data.len());
    }
    println!(
        "{}",
        serde_json::json!({"encode_s": te, "decode_s": td, "bytes": size,
                           "width": raster.width, "height": raster.height})
    );
    Ok(())
}
