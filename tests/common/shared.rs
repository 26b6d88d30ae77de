//! What the unit tests (`src/testutil.rs` includes this file), the integration tests and the
//! benches (`tests/common/mod.rs`) share: the one deterministic generator of test data
//! (SplitMix64) and the one exact comparison of two rasters. The including module provides
//! `Raster` (the crate's own or `vtz::Raster`).

use super::Raster;

/// SplitMix64: a tiny deterministic generator for test data.
pub struct Rng(pub u64);

impl Rng {
    pub fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// True with probability num / 2^16.
    pub fn bernoulli(&mut self, num: u64) -> bool {
        (self.next() >> 48) < num
    }
    pub fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
    /// Uniform in [0, 1).
    pub fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }
    /// `n` random bytes.
    pub fn bytes(&mut self, n: usize) -> Vec<u8> {
        (0..n).map(|_| self.next() as u8).collect()
    }
}

/// The same raster: size, sample type, mask, nodata, georef, and every valid sample to the
/// bit (invalid samples may hold different fills).
pub fn assert_same(a: &Raster, b: &Raster, what: &str) {
    assert_eq!((a.width, a.height), (b.width, b.height), "{what}: size");
    assert_eq!(a.sample_type, b.sample_type, "{what}: sample type");
    assert_eq!(a.mask, b.mask, "{what}: mask");
    assert_eq!(
        a.nodata.map(f64::to_bits),
        b.nodata.map(f64::to_bits),
        "{what}: nodata"
    );
    assert_eq!(a.georef, b.georef, "{what}: georef");
    for i in 0..a.len() {
        if a.is_valid(i) {
            assert_eq!(
                a.data[i].to_bits(),
                b.data[i].to_bits(),
                "{what}: sample {i}"
            );
        }
    }
}

/// A test that cannot run here says so where a CI log shows it: straight to the process's
/// stderr (the test harness captures only `print!`/`eprint!`), naming the test. With
/// `VTZ_REQUIRE_SHARED=1` (set by `.ci/run`, where `../shared` is present) missing data
/// fails the test instead.
pub fn skip(why: &str) {
    use std::io::Write;
    let name = std::thread::current()
        .name()
        .unwrap_or("a test")
        .to_string();
    if std::env::var_os("VTZ_REQUIRE_SHARED").is_some_and(|v| v == "1") {
        panic!("{name}: {why} (VTZ_REQUIRE_SHARED=1)");
    }
    let _ = writeln!(std::io::stderr(), "SKIPPED {name}: {why}");
}
