//! Every raster reader on any bytes: the first byte picks GeoTIFF, PNG (grey mapping,
//! Terrain-RGB or Terrarium), OpenEXR, SRTM hgt, ESRI ASCII grid or raw f32 + JSON sidecar; the rest is
//! the file. Errors are fine; panics and allocations beyond the sample limit are not. A
//! raster that reads must keep the model's invariants.
use vtz::formats::ReadOptions;
use vtz::internals::formats;

/// One input of the `readers` fuzz target (also replayed over its seeds by `tests/suite/fuzz_seeds.rs`).
pub fn run(data: &[u8]) {
    let Some((&pick, file)) = data.split_first() else {
        return;
    };
    let opts = ReadOptions::default().with_max_samples(Some(1 << 16));
    let r = match pick % 8 {
        0 => formats::geotiff(file, &opts),
        1 => formats::png(file, None, None, &opts),
        2 => formats::png(file, None, Some(formats::RgbHeights::TerrainRgb), &opts),
        7 => formats::png(file, None, Some(formats::RgbHeights::Terrarium), &opts),
        3 => formats::exr(file, &opts),
        4 => formats::hgt(file, "N22W160.hgt", &opts),
        5 => formats::asc(file, &opts),
        _ => {
            // The JSON sidecar's length first, then the JSON, then the samples.
            if file.len() < 2 {
                return;
            }
            let n = (u16::from_le_bytes([file[0], file[1]]) as usize).min(file.len() - 2);
            formats::raw(&file[2 + n..], &file[2..2 + n], &opts)
        }
    };
    if let Ok(r) = r {
        assert!(r.width >= 1 && r.height >= 1);
        assert_eq!(r.data.len(), r.width * r.height);
        assert!(r.data.len() as u64 <= 1 << 16);
        if let Some(m) = &r.mask {
            assert_eq!(m.len(), r.data.len());
        }
        for i in 0..r.data.len() {
            if r.is_valid(i) {
                assert!(r.data[i].is_finite(), "valid sample {i} is {}", r.data[i]);
            }
        }
    }
}
