//! What the unit tests (`src/testutil.rs` includes this file), the integration tests and the
//! benches (`tests/common/mod.rs`) share: the one deterministic generator of test data
//! (SplitMix64), the one exact comparison of two rasters and the one configuration of
//! property tests (a fixed seed unless the random search asks for one). The including module provides
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

// ---------------------------------------------------------------- property tests

/// Set to `1` for the random search (`tests/random_search.sh`): property tests draw from a
/// random seed, run [`PROPTEST_SCALE`] times their cases, and persist what fails.
pub const PROPTEST_RANDOM: &str = "VTZ_PROPTEST_RANDOM";
/// How many times its cases a property test runs in the random search (default 8).
pub const PROPTEST_SCALE: &str = "VTZ_PROPTEST_SCALE";
/// The seed every property test draws from in a normal run.
pub const PROPTEST_SEED: u64 = 0x7674_7a5f_6369_0035;

/// The configuration of every property test (`#![proptest_config(common::proptest_config(n))]` in `tests/`, `crate::testutil::proptest_config(n)` in unit tests):
/// in a normal run (CI, the README's test command) `cases` cases drawn from the fixed
/// [`PROPTEST_SEED`], after the cases of the test's committed regression file (proptest's
/// default place: `tests/proptest-regressions/NAME.txt` for `tests/suite/NAME.rs`,
/// `proptest-regressions/PATH.txt` for `src/PATH.rs`), which is read but never written. The same inputs on every run: a failure is a
/// regression, not luck. With [`PROPTEST_RANDOM`]`=1` the random search: a random seed,
/// `cases` × [`PROPTEST_SCALE`] cases, and a failure's seed appended to the regression file
/// (commit it, and the shrunk input as a plain `#[test]`).
pub fn proptest_config(cases: u32) -> proptest::test_runner::Config {
    use proptest::test_runner::{Config, FileFailurePersistence, RngSeed};
    let random = std::env::var(PROPTEST_RANDOM).is_ok_and(|v| v == "1");
    let files = FileFailurePersistence::default();
    if random {
        let scale: u32 = std::env::var(PROPTEST_SCALE)
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(8);
        Config {
            cases: cases.saturating_mul(scale.max(1)),
            rng_seed: RngSeed::Random,
            failure_persistence: Some(Box::new(files)),
            ..Config::default()
        }
    } else {
        Config {
            cases,
            rng_seed: RngSeed::Fixed(PROPTEST_SEED),
            failure_persistence: Some(Box::new(ReadOnly(files))),
            ..Config::default()
        }
    }
}

/// Failure persistence that replays the regression file's cases and never writes it.
#[derive(Clone, Debug, PartialEq)]
struct ReadOnly(proptest::test_runner::FileFailurePersistence);

impl proptest::test_runner::FailurePersistence for ReadOnly {
    fn load_persisted_failures2(
        &self,
        source_file: Option<&'static str>,
    ) -> Vec<proptest::test_runner::PersistedSeed> {
        self.0.load_persisted_failures2(source_file)
    }

    fn save_persisted_failure2(
        &mut self,
        _source_file: Option<&'static str>,
        _seed: proptest::test_runner::PersistedSeed,
        _shrunken_value: &dyn std::fmt::Debug,
    ) {
    }

    fn box_clone(&self) -> Box<dyn proptest::test_runner::FailurePersistence> {
        Box::new(self.clone())
    }

    fn eq(&self, other: &dyn proptest::test_runner::FailurePersistence) -> bool {
        other.as_any().downcast_ref::<ReadOnly>() == Some(self)
    }

    fn as_any(&self) -> &dyn std::any::Any {
        self
    }
}
