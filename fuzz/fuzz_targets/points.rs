//! The `points` fuzz target: its body is `fuzz/targets/points.rs` (the stable tests replay it
//! over the seeds, `tests/suite/fuzz_seeds.rs`).
#![no_main]

#[path = "../targets/mod.rs"]
mod targets;

libfuzzer_sys::fuzz_target!(|data: &[u8]| targets::points::run(data));
