//! The integration tests, one module per file, in one test binary (`cargo test --test suite`;
//! one file's tests: `cargo test --test suite golden::`): one link of the vtz library
//! instead of one per file, and the tests of every file share the test threads.
//! Property tests replay `tests/proptest-regressions/<module>.txt` (proptest's default place
//! for a source file beside a `main.rs`; `common::proptest_config`).

#[path = "../common/mod.rs"]
mod common;

mod architecture;
mod best_choice;
mod cells;
mod cli;
mod cli_messages;
mod cloud;
mod container;
mod fuzz_seeds;
mod gdal;
mod gdal_written;
mod golden;
mod header_edit;
mod hostile;
mod limits;
mod lossless_size;
mod lsystem;
mod mesh;
mod methods;
mod new_user;
mod point_sets;
mod points;
mod rd_cli;
mod remote;
mod render;
mod residual;
mod scale;
mod shared_corpus;
mod silent_data;
mod sites;
mod terrain_bound;
mod tiles;
mod web;
