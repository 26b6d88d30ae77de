//! Every fuzz seed through its fuzz target's body, on the stable toolchain, in the same
//! order on every run: `fuzz/make_seeds.py` writes the seeds (golden files, hostile header
//! edits, corpus crops in every format and method, wide lattices, point sets) with this
//! build's `vtz`, and each is handed to `fuzz/targets/<target>.rs`, the code libFuzzer runs.
//! So is every input under `fuzz/regressions/<target>/` (what a fuzzer once crashed on, kept
//! once fixed). A seed that panics there is a regression. The coverage-guided search itself (random,
//! nightly) is `fuzz/smoke.sh` and the long runs of fuzz/README.md, run before a stop.

#[path = "../../fuzz/targets/mod.rs"]
mod targets;

use std::path::Path;
use std::process::Command;

/// A fuzz target's body: one input.
type Target = fn(&[u8]);

#[test]
fn every_fuzz_seed_replays_through_its_target() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let out = tempfile::tempdir().unwrap();
    let made = Command::new("python3")
        .arg(root.join("fuzz/make_seeds.py"))
        .arg(env!("CARGO_BIN_EXE_vtz"))
        .arg(out.path())
        .output()
        .expect("python3 runs fuzz/make_seeds.py");
    assert!(
        made.status.success(),
        "make_seeds.py failed: {}",
        String::from_utf8_lossy(&made.stderr)
    );
    let targets: [(&str, Target); 5] = [
        ("container", targets::container::run),
        ("sections", targets::sections::run),
        ("readers", targets::readers::run),
        ("roundtrip", targets::roundtrip::run),
        ("points", targets::points::run),
    ];
    for (name, run) in targets {
        let mut seeds: Vec<_> = std::fs::read_dir(out.path().join(name))
            .unwrap_or_else(|e| panic!("no seeds for {name}: {e}"))
            .map(|e| e.unwrap().path())
            .collect();
        // The inputs the fuzzers found a crash with, committed once fixed.
        if let Ok(found) = std::fs::read_dir(root.join("fuzz/regressions").join(name)) {
            seeds.extend(found.map(|e| e.unwrap().path()));
        }
        seeds.sort();
        // Every target has seeds of its own (a seed generator that silently wrote none
        // would make this test pass on nothing).
        assert!(seeds.len() >= 10, "{name}: only {} seeds", seeds.len());
        for seed in &seeds {
            let data = std::fs::read(seed).unwrap();
            let caught = std::panic::catch_unwind(|| run(&data));
            assert!(
                caught.is_ok(),
                "fuzz target {name} panicked on seed {}",
                seed.display()
            );
        }
        eprintln!("fuzz target {name}: {} seeds replayed", seeds.len());
    }
}
