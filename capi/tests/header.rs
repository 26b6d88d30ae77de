//! The committed header is what cbindgen makes of src/lib.rs today. After changing the
//! ABI: `VTZ_BLESS=1 cargo test --test header` rewrites include/vtz.h (then review it).

use std::path::Path;

#[test]
fn the_committed_header_is_current() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    let config = cbindgen::Config::from_file(dir.join("cbindgen.toml")).expect("cbindgen.toml");
    let mut made = Vec::new();
    cbindgen::Builder::new()
        .with_crate(dir)
        .with_config(config)
        .generate()
        .expect("cbindgen reads src/lib.rs")
        .write(&mut made);
    let path = dir.join("include/vtz.h");
    if std::env::var_os("VTZ_BLESS").is_some() {
        std::fs::write(&path, &made).expect("write include/vtz.h");
        return;
    }
    let committed = std::fs::read(&path).expect("include/vtz.h is committed");
    assert!(
        committed == made,
        "include/vtz.h is stale: run `VTZ_BLESS=1 cargo test --test header` in capi/ and commit it"
    );
}
