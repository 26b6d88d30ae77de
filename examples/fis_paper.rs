//! Reproduce the fractal-interpolation paper's experiment on 257×257 crops of corpus DEMs:
//! every 8th and every 16th sample as interpolation points, with the paper's fixed s = 0.02
//! and with vtz's fitted vertical scaling functions. Prints a markdown table and writes
//! side-by-side hillshades (original | s = 0.02 | fitted) per crop and k.
//!
//! `cargo run --release --example fis_paper -- OUTDIR`

use std::path::{Path, PathBuf};
use vtz::Raster;
use vtz::internals::fis::{FisParams, encode};
use vtz::viz::hillshade::{ShadeOptions, hillshade_image};

/// A `size`×`size` crop at (x0, y0).
fn crop(r: &Raster, x0: usize, y0: usize, size: usize) -> Raster {
    let mut data = Vec::with_capacity(size * size);
    let mut mask = Vec::with_capacity(size * size);
    for y in y0..y0 + size {
        for x in x0..x0 + size {
            let i = y * r.width + x;
            data.push(r.data[i]);
            mask.push(r.is_valid(i));
        }
    }
    let mut c = r.clone();
    c.width = size;
    c.height = size;
    c.data = data;
    c.mask = Some(mask);
    c.georef = r.georef.as_ref().map(|g| g.window(x0, y0));
    c.normalize_mask();
    c
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let out = PathBuf::from(
        std::env::args()
            .nth(1)
            .unwrap_or_else(|| "fis_paper".into()),
    );
    std::fs::create_dir_all(&out)?;
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    // (label, file, crop origin): centre-ish crops of three corpus DEMs.
    let sources = [
        ("scape_crater", "corpus/scape_crater.png", (40, 100)),
        ("kauai", "corpus/srtm3_N22W160_kauai.hgt", (420, 900)),
        (
            "bigtujunga",
            "corpus/srtm30m_bigtujunga_utm11.tif",
            (300, 300),
        ),
    ];
    println!(
        "| crop | k | points (%) | s | bytes | bits/sample | RMSE | RMSE % | L∞ | L∞ % | s0 | mean abs s_ij |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|");
    for (label, file, (x0, y0)) in sources {
        let full = vtz::read_path(&root.join(file), &Default::default())?;
        let r = crop(&full, x0, y0, 257);
        let (lo, hi) = r.valid_range().unwrap_or((0.0, 1.0));
        let range = (hi - lo).max(f64::MIN_POSITIVE);
        let shade = ShadeOptions::default();
        let orig = hillshade_image(&r, &shade)?;
        let mut rows = Vec::new();
        for k in [8usize, 16] {
            let mut tiles = vec![orig.clone()];
            let mut fitted_file = 0usize;
            for fixed in [Some(0.0), Some(0.02), None] {
                let (payload, st) = encode(
                    &r,
                    &FisParams {
                        max_error: None,
                        k: Some(k),
                        fixed_s: fixed,
                        size_cap: None,
                    },
                )?;
                let header = vtz::internals::container::Header::of(&r)?;
                let data = vtz::internals::fis::decode(&payload, &header, r.mask.as_deref())?;
                let mut back = r.clone();
                back.data = data;
                let c = vtz::metrics::compare(&r, &back)?;
                assert!((c.max_error - st.max_error).abs() <= 1e-9 * range);
                if fixed != Some(0.0) {
                    tiles.push(hillshade_image(&back, &shade)?);
                }
                // The same surface as a whole .vtz file, for the size comparison below.
                let mut opts = vtz::EncodeOptions::default();
                opts.methods = vec![vtz::Method::FIS];
                opts.params.fis.k = Some(k);
                opts.params.fis.s = fixed;
                let file = vtz::encode(&r, &opts)?;
                fitted_file = file.len();
                println!(
                    "| {label} | {k} | {} ({:.2} %) | {} | {} | {:.4} | {:.3} | {:.3} | {:.2} | {:.2} | {:.3} | {:.3} |",
                    st.points,
                    100.0 * st.points as f64 / (257.0 * 257.0),
                    fixed.map_or("fitted".to_string(), |s| s.to_string()),
                    file.len(),
                    8.0 * file.len() as f64 / (257.0 * 257.0),
                    c.rmse,
                    100.0 * c.rmse / range,
                    c.max_error,
                    100.0 * c.max_error / range,
                    st.s0,
                    st.mean_abs_s
                );
            }
            // Sibson sites in a file of the same size as the fitted FIS, for scale.
            let (file, rep) = vtz::Encoder::new()
                .method(vtz::Method::SIBSON)
                .target_bytes(fitted_file as u64)
                .encode_report(&r)?;
            let back = vtz::decode(&file)?;
            let c = vtz::metrics::compare(&r, &back)?;
            println!(
                "| {label} | {k} | {} sites | sibson, same size | {} | {:.4} | {:.3} | {:.3} | {:.2} | {:.2} | | |",
                rep.stats
                    .as_ref()
                    .and_then(|s| s.count("sites"))
                    .unwrap_or(0),
                file.len(),
                8.0 * file.len() as f64 / (257.0 * 257.0),
                c.rmse,
                100.0 * c.rmse / range,
                c.max_error,
                100.0 * c.max_error / range,
            );
            rows.push(tiles);
        }
        // One picture per crop: rows k = 8 and k = 16; columns original | s = 0.02 | fitted.
        let gap = 4u32;
        let (tw, th) = (rows[0][0].width(), rows[0][0].height());
        let mut img =
            image::RgbImage::from_pixel(3 * tw + 2 * gap, 2 * th + gap, image::Rgb([255; 3]));
        for (ry, tiles) in rows.iter().enumerate() {
            for (cx, t) in tiles.iter().enumerate() {
                let (x, y) = (cx as u32 * (tw + gap), ry as u32 * (th + gap));
                image::imageops::replace(&mut img, t, x as i64, y as i64);
            }
        }
        let png = vtz::viz::hillshade::encode_png(&img, &[])?;
        std::fs::write(out.join(format!("fis_{label}.png")), png)?;
    }
    Ok(())
}
