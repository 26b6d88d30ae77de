//! The fuzz targets' bodies, one module each: `fuzz/fuzz_targets/*.rs` hands them libFuzzer's
//! inputs (nightly, `cargo fuzz`), and `tests/suite/fuzz_seeds.rs` replays every seed that
//! `fuzz/make_seeds.py` writes through them on the stable toolchain in `cargo test`.
#![allow(dead_code)]

pub mod check;
pub mod container;
pub mod points;
pub mod readers;
pub mod roundtrip;
pub mod sections;
