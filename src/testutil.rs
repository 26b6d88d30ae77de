//! Test helpers shared by the unit tests (compiled only for tests): one random generator and
//! the format modules' corpus, test-data and comparison helpers.

use crate::formats::{ReadOptions, raw};
use crate::model::Raster;
use std::path::{Path, PathBuf};

// The one test generator, shared with the integration tests and the benches.
#[path = "../tests/common/shared.rs"]
mod shared;
pub use shared::{Rng, assert_same, proptest_config, skip};

/// The shared corpus directory, or `None` (with a message) when it is absent.
pub fn corpus() -> Option<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/corpus");
    if dir.is_dir() {
        Some(dir)
    } else {
        skip(&format!("{} is absent", dir.display()));
        None
    }
}

/// Run `f(dir, name)` for each named corpus dataset; nothing when the corpus is absent.
pub fn for_each_corpus(names: &[&str], mut f: impl FnMut(&Path, &str)) {
    let Some(dir) = corpus() else { return };
    for name in names {
        f(&dir, name);
    }
}

/// `n` samples `value(i)`, with a NaN hole wherever `i % every == at` (`value` is not called
/// there).
pub fn with_holes(
    n: usize,
    every: usize,
    at: usize,
    mut value: impl FnMut(usize) -> f64,
) -> Vec<f64> {
    (0..n)
        .map(|i| if i % every == at { f64::NAN } else { value(i) })
        .collect()
}

/// Load corpus dataset `name` from its `.f32` + `.json`.
pub fn load_raw(dir: &Path, name: &str) -> Raster {
    let f = std::fs::read(dir.join(format!("{name}.f32"))).unwrap();
    let j = std::fs::read(dir.join(format!("{name}.json"))).unwrap();
    raw::read(&f, &j, &ReadOptions::default()).unwrap()
}

/// The raw `.f32` values of corpus dataset `name`, as bits.
pub fn raw_bits(dir: &Path, name: &str) -> Vec<u32> {
    let f = std::fs::read(dir.join(format!("{name}.f32"))).unwrap();
    f.chunks_exact(4)
        .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect()
}

/// The raster's samples as f32 bits (invalid samples as the f32 of their fill value).
pub fn raster_bits(r: &Raster) -> Vec<u32> {
    r.data.iter().map(|&v| (v as f32).to_bits()).collect()
}

/// A UTM zone 11N georef (the Big Tujunga tile's: 30 m area pixels, EPSG:32611).
pub fn utm11_georef() -> crate::model::Georef {
    crate::model::Georef {
        origin: [376313.6554542635, 3807917.8276283755],
        pixel_size: [30.0, 30.0],
        raster_type: crate::model::RasterType::Area,
        epsg: Some(32611),
        wkt: None,
        geokeys: None,
    }
}
