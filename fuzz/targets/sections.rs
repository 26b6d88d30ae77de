//! Each method's section decoder, reached through the method registry: the input picks a
//! method, a raster shape, a sample type and optionally a mask and a flat section, and the rest is the
//! payload, framed in a well-formed container (checksums right), then decoded in full, as
//! a window, and as stats and sites. Errors are fine; panics are not.
use super::check;
use std::io::Cursor;
use vtz::internals::container::{self, Header, SF_REQUIRED, Section, SectionKind};
use vtz::{Decoder, Limits, SampleType, ValueMapping, Window};

/// One input of the `sections` fuzz target (also replayed over its seeds by `tests/suite/fuzz_seeds.rs`).
pub fn run(data: &[u8]) {
    if data.len() < 7 {
        return;
    }
    let methods = vtz::internals::method_sections();
    let (_, kind) = methods[data[0] as usize % methods.len()];
    let flags = data[1];
    let width = 1 + u16::from_le_bytes([data[2], data[3]]) as u32 % 64;
    let height = 1 + u16::from_le_bytes([data[4], data[5]]) as u32 % 64;
    let Some(sample_type) = SampleType::from_code(data[6] % 8) else {
        return;
    };
    let mut rest = &data[7..];
    let mut sections = Vec::new();
    if flags & 1 != 0 && rest.len() >= 2 {
        let n = (u16::from_le_bytes([rest[0], rest[1]]) as usize).min(rest.len() - 2);
        sections.push(Section {
            kind: SectionKind::MASK,
            flags: SF_REQUIRED,
            payload: rest[2..2 + n].to_vec(),
        });
        rest = &rest[2 + n..];
    }
    if flags & 8 != 0 && rest.len() >= 2 {
        let n = (u16::from_le_bytes([rest[0], rest[1]]) as usize).min(rest.len() - 2);
        sections.push(Section {
            kind: SectionKind::FLAT,
            flags: SF_REQUIRED,
            payload: rest[2..2 + n].to_vec(),
        });
        rest = &rest[2 + n..];
    }
    let primary = sections.len() as u16;
    sections.push(Section {
        kind,
        flags: SF_REQUIRED,
        payload: rest.to_vec(),
    });
    let header = Header {
        width,
        height,
        sample_type,
        primary,
        mapping: ValueMapping::default(),
        nodata: (flags & 2 != 0).then_some(-9999.0),
        range: (flags & 4 != 0).then_some((-120.0, 3120.5)),
        georef: None,
    };
    let file = container::write(&header, &sections);
    let limits = Limits {
        max_samples: 1 << 16,
        max_section_bytes: 1 << 20,
    };
    let Ok(mut d) = Decoder::with_limits(Cursor::new(file[..].to_vec()), limits) else {
        return;
    };
    let _ = d.stats();
    let _ = d.sites();
    if let Ok(full) = d.decode() {
        let (w, h) = (full.width, full.height);
        let win = Window {
            x: w / 2,
            y: h / 3,
            width: w - w / 2,
            height: h - h / 3,
        };
        if let Ok(part) = d.window(win).decode() {
            check::window_is_crop(&part, &full, win);
        }
    }
}
