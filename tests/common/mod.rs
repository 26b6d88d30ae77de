//! Helpers shared by the integration tests (`tests/suite/main.rs`; `use crate::common;` in
//! its modules) and the benches
//! (`#[path = "../tests/common/mod.rs"] mod common;`): one random generator, one synthetic
//! terrain, one runner of the `vtz` binary, the corpora and temporary paths.
//!
//! Each test file uses a part of this; the rest is dead code (or an unused re-export) there.
#![allow(dead_code, unused_imports)]

use std::ffi::OsStr;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use vtz::{DecodeOptions, EncodeOptions, ErrorBound, Method, Raster, SampleType};

// ---------------------------------------------------------------- random numbers

mod shared;
pub use shared::{
    PROPTEST_RANDOM, PROPTEST_SCALE, PROPTEST_SEED, Rng, assert_same, proptest_config, skip,
};

// ---------------------------------------------------------------- synthetic terrain

/// The relief of a synthetic [`terrain`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// Six octaves of sine waves with random phases around 500.
    Fbm,
    /// A disc at 800 on a slope from 200.
    Plateau,
    /// A wavy floor near 100 and a cliff up to ~1000 at 60 % of the width.
    Cliff,
    /// 42 everywhere (plus the noise).
    Constant,
    /// A smooth hill of 500 with ridges and a 5-step ramp pattern, without noise.
    Hill,
}

/// The nodata value of every [`terrain`].
pub const NODATA: f64 = -9999.0;

/// A deterministic synthetic terrain: `kind`'s relief, plus uniform noise of ±2 (none for
/// [`Kind::Hill`]), rounded for integer sample types and rounded to f32 for `F32`; with
/// `holes`, three random discs of nodata. The nodata value is always [`NODATA`].
///
/// Its stream is a 64-bit LCG (Knuth's MMIX constants) seeded with `seed | 1`, kept so the
/// terrains are the very samples the tests were written against.
pub fn terrain(kind: Kind, w: usize, h: usize, seed: u64, holes: bool, st: SampleType) -> Raster {
    let mut s = seed | 1;
    let mut rnd = move || {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    let phases: Vec<f64> = (0..12).map(|_| rnd() * std::f64::consts::TAU).collect();
    let noise = if kind == Kind::Hill { 0.0 } else { 4.0 };
    let mut data = Vec::with_capacity(w * h);
    for y in 0..h {
        for x in 0..w {
            let (fx, fy) = (x as f64, y as f64);
            let v = match kind {
                Kind::Fbm => {
                    (0..6)
                        .map(|o| {
                            let f = 0.05 * 2f64.powi(o);
                            (fx * f + phases[o as usize]).sin()
                                * (fy * f * 1.3 + phases[o as usize + 6]).cos()
                                * 100.0
                                / 2f64.powi(o)
                        })
                        .sum::<f64>()
                        + 500.0
                }
                Kind::Plateau => {
                    if (fx - w as f64 / 2.0).hypot(fy - h as f64 / 2.0) < w.min(h) as f64 / 3.0 {
                        800.0
                    } else {
                        200.0 + fx
                    }
                }
                Kind::Cliff => {
                    if fx > w as f64 * 0.6 {
                        1000.0 + fy * 3.0
                    } else {
                        100.0 + (fx * 0.3).sin() * 20.0
                    }
                }
                Kind::Constant => 42.0,
                Kind::Hill => {
                    let (ux, uy) = (fx / w as f64, fy / h as f64);
                    500.0 * (-((ux - 0.4).powi(2) + (uy - 0.6).powi(2)) * 6.0).exp()
                        + 30.0 * (ux * 17.0).sin() * (uy * 11.0).cos()
                        + 7.0 * ((x * 7 + y * 13) % 5) as f64
                }
            };
            let v = v + (rnd() - 0.5) * noise;
            data.push(match st {
                SampleType::F32 => v as f32 as f64,
                SampleType::F64 => v,
                // Integer codes have no −0 (rounding −0.3 gives −0.0, which an integer
                // raster cannot hold: its decode is 0).
                _ => v.round() + 0.0,
            });
        }
    }
    if holes {
        for _ in 0..3 {
            let (cx, cy, r) = (
                rnd() * w as f64,
                rnd() * h as f64,
                1.0 + rnd() * w.min(h) as f64 / 5.0,
            );
            for y in 0..h {
                for x in 0..w {
                    if (x as f64 - cx).hypot(y as f64 - cy) < r {
                        data[y * w + x] = NODATA;
                    }
                }
            }
        }
    }
    Raster::from_values(w, h, data, Some(NODATA), st).unwrap()
}

/// The samples' bit patterns (to compare decodes exactly, NaN fills included).
pub fn bits(r: &Raster) -> Vec<u64> {
    r.data.iter().map(|v| v.to_bits()).collect()
}

// ---------------------------------------------------------------- options

/// Encode options that write `methods` (none: the best one) within `max_error` (`None`:
/// lossless), the rest default.
pub fn encode_opts(methods: &[Method], max_error: Option<ErrorBound>) -> EncodeOptions {
    let mut o = EncodeOptions::default();
    o.methods = methods.to_vec();
    o.max_error = max_error;
    o
}

/// Decode options: the defaults but for what `set` changes.
pub fn decode_opts(set: impl FnOnce(&mut DecodeOptions)) -> DecodeOptions {
    let mut o = DecodeOptions::default();
    set(&mut o);
    o
}

// ---------------------------------------------------------------- the vtz binary

/// Run the `vtz` binary with these arguments.
pub fn vtz<I, S>(args: I) -> Output
where
    I: IntoIterator<Item = S>,
    S: AsRef<OsStr>,
{
    Command::new(env!("CARGO_BIN_EXE_vtz"))
        .args(args)
        .output()
        .expect("run vtz")
}

/// What a run wrote to stderr.
pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Assert that a run succeeded (showing its stderr if not).
pub fn ok(o: &Output) {
    assert!(o.status.success(), "vtz failed: {}", stderr(o));
}

/// The JSON a successful run printed.
pub fn json(o: &Output) -> serde_json::Value {
    assert!(o.status.success(), "{}", stderr(o));
    serde_json::from_slice(&o.stdout).expect("json on stdout")
}

// ---------------------------------------------------------------- files

/// The path of `corpus/NAME` (the crate's own corpus).
pub fn corpus(name: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("corpus")
        .join(name)
        .to_string_lossy()
        .into_owned()
}

/// The golden files' folder, `tests/golden` (spec/FORMAT.md: decoded forever).
pub fn golden_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/golden")
}

/// Every golden `.vtz` file, sorted by name; fails when they are missing.
pub fn golden_files() -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(golden_dir())
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "vtz"))
        .collect();
    v.sort();
    assert!(v.len() >= 3, "the golden files are missing");
    v
}

/// Read `corpus/NAME`.
pub fn read_corpus(name: &str) -> Raster {
    vtz::read_path(Path::new(&corpus(name)), &Default::default()).unwrap()
}

/// The shared corpus (`../shared/corpus`), or `None` with a message when it is absent.
pub fn shared_corpus() -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/corpus");
    if p.join("manifest.json").exists() {
        Some(p)
    } else {
        skip(&format!("{} is absent", p.display()));
        None
    }
}

/// `name` of the shared corpus (`../shared/corpus/NAME`), when it is there (the benches'
/// larger rasters); `None` with a message otherwise.
pub fn read_shared(name: &str) -> Option<Raster> {
    let p = shared_corpus()?.join(name);
    if !p.exists() {
        skip(&format!("{} is absent", p.display()));
        return None;
    }
    Some(vtz::read_path(&p, &Default::default()).unwrap())
}

/// The path of `name` in a temporary directory.
pub fn tmp(dir: &tempfile::TempDir, name: &str) -> String {
    dir.path().join(name).to_string_lossy().into_owned()
}

// ---------------------------------------------------------------- counting reads

/// A range source that records every call a reader makes (each call's ranges), over any
/// other source: what the container asks for, before a remote source merges anything.
pub struct Counting<S> {
    pub inner: S,
    pub calls: std::sync::Mutex<Vec<Vec<std::ops::Range<u64>>>>,
}

impl<S: vtz::RangeSource> vtz::RangeSource for Counting<S> {
    fn len(&self) -> vtz::Result<u64> {
        self.inner.len()
    }
    fn read_ranges(&self, ranges: &[std::ops::Range<u64>]) -> vtz::Result<Vec<Vec<u8>>> {
        self.calls.lock().unwrap().push(ranges.to_vec());
        self.inner.read_ranges(ranges)
    }
    fn name(&self) -> String {
        self.inner.name()
    }
}

impl<S> Counting<S> {
    pub fn new(inner: S) -> std::sync::Arc<Counting<S>> {
        std::sync::Arc::new(Counting {
            inner,
            calls: std::sync::Mutex::new(Vec::new()),
        })
    }
    /// Requests a remote source would make: each call's ranges merged as
    /// `vtz::source::coalesce` does; and their bytes.
    pub fn requests(&self) -> (usize, u64) {
        let calls = self.calls.lock().unwrap();
        let mut n = 0;
        let mut bytes = 0;
        for c in calls.iter() {
            let (m, _) = vtz::source::coalesce(c, vtz::source::COALESCE_GAP);
            n += m.len();
            bytes += m.iter().map(|r| r.end - r.start).sum::<u64>();
        }
        (n, bytes)
    }
    /// Bytes the reader asked for.
    pub fn asked(&self) -> u64 {
        let calls = self.calls.lock().unwrap();
        calls.iter().flatten().map(|r| r.end - r.start).sum()
    }
    pub fn reset(&self) {
        self.calls.lock().unwrap().clear();
    }
}

impl Counting<vtz::source::MemorySource> {
    pub fn over_bytes(bytes: &[u8]) -> std::sync::Arc<Self> {
        Counting::new(vtz::source::MemorySource::new(bytes.to_vec()))
    }
}
