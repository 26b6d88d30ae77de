//! Any bytes as a `.vtz` file: open (header, directory), then read the stats, the sites and
//! every section's decode (whole, a window, overview 1). Checksums are not enforced in fuzzing builds (`cfg(fuzzing)`),
//! so the fuzzer reaches the parsers behind them. Errors are fine; panics, aborts and
//! allocations beyond the limits are not.
use super::check;
use std::io::Cursor;
use vtz::{Decoder, Limits, SectionChoice, Window};

/// One input of the `container` fuzz target (also replayed over its seeds by `tests/suite/fuzz_seeds.rs`).
pub fn run(data: &[u8]) {
    let limits = Limits {
        max_samples: 1 << 16,
        max_section_bytes: 1 << 20,
    };
    let Ok(mut d) = Decoder::with_limits(Cursor::new(data.to_vec()), limits) else {
        return;
    };
    let info = d.info().clone();
    let _ = d.stats();
    let _ = d.sites();
    for i in 0..info.sections.len().min(8) {
        d.section(SectionChoice::Index(i));
        if let Ok(full) = d.decode() {
            assert_eq!(full.width, info.width as usize);
            assert_eq!(full.height, info.height as usize);
            // A window decodes to the crop of the full decode.
            let (w, h) = (full.width, full.height);
            let win = Window {
                x: w / 3,
                y: h / 2,
                width: w - w / 3,
                height: h - h / 2,
            };
            if let Ok(part) = d.window(win).decode() {
                check::window_is_crop(&part, &full, win);
            }
            // Overview 1 of an untiled file: every other sample of every other row of the
            // full decode, bit for bit (the residual layer stops after its coarse levels).
            let mut o = vtz::DecodeOptions::default();
            o.section = SectionChoice::Index(i);
            o.overview = Some(1);
            if let Ok(ov) = d.options(o).decode() {
                assert_eq!((ov.width, ov.height), (w.div_ceil(2), h.div_ceil(2)));
                if info.tiles.is_none() {
                    for y in 0..ov.height {
                        for x in 0..ov.width {
                            let (a, b) = (y * ov.width + x, 2 * y * w + 2 * x);
                            assert_eq!(ov.is_valid(a), full.is_valid(b));
                            assert_eq!(ov.data[a].to_bits(), full.data[b].to_bits());
                        }
                    }
                }
            }
            let mut o = vtz::DecodeOptions::default();
            o.section = SectionChoice::Index(i);
            d.options(o);
        }
    }
    // A tiled file: the full decode, a window of it, and a decode that skips corrupt tiles.
    if info.tiles.is_some() {
        d.section(SectionChoice::Primary);
        if let Ok(full) = d.decode() {
            let (w, h) = (full.width, full.height);
            let win = Window {
                x: w / 3,
                y: h / 2,
                width: w - w / 3,
                height: h - h / 2,
            };
            if let Ok(part) = d.window(win).decode() {
                check::window_is_crop(&part, &full, win);
            }
        }
        let mut o = vtz::DecodeOptions::default();
        o.skip_corrupt = true;
        let _ = d.options(o).decode();
        // Overview 2: each sample from its tile's own coarse levels.
        let mut o = vtz::DecodeOptions::default();
        o.overview = Some(2);
        if let Ok(ov) = d.options(o).decode() {
            let (w, h) = (info.width as usize, info.height as usize);
            assert_eq!((ov.width, ov.height), (w.div_ceil(4), h.div_ceil(4)));
        }
    }
}
