//! Checksums catch accidents, not edits: someone may change a header or directory field and
//! recompute the checksums. Decoding such a file must then fail with an error, or produce
//! exactly what the edited header describes; never panic, never read outside a payload
//! (Rust's bounds checks turn such a read into a panic, which this test would catch).

use crate::common;

use proptest::prelude::*;
use std::io::Cursor;
use vtz::internals::container::{self, Header, SectionKind};
use vtz::{Decoder, Limits, SampleType, SectionChoice, ValueMapping};

/// The golden files: one per method, each with a mask section.
fn goldens() -> Vec<Vec<u8>> {
    let dir = crate::common::golden_dir();
    ["fis", "grid", "haar", "sites"]
        .iter()
        .map(|m| std::fs::read(dir.join(format!("v1_kauai_crop_{m}.vtz"))).unwrap())
        .collect()
}

/// One edit of a header or directory field.
#[derive(Clone, Debug)]
enum Edit {
    Width(u32),
    Height(u32),
    Type(u8),
    Primary(u16),
    Nodata(Option<f64>),
    Range(Option<(f64, f64)>),
    Mapping(f64, f64),
    /// Relabel section `.0` as type `.1` (a payload decoded by another method's decoder).
    Kind(usize, u16),
    Flags(usize, u16),
}

fn edit() -> impl Strategy<Value = Edit> {
    let dim = prop_oneof![0u32..70, Just(u32::MAX), 1u32..5000];
    let num = prop_oneof![
        any::<f64>(),
        -40000.0..40000.0f64,
        Just(f64::NAN),
        Just(f64::INFINITY),
        Just(0.0)
    ];
    prop_oneof![
        dim.clone().prop_map(Edit::Width),
        dim.prop_map(Edit::Height),
        (0u8..8).prop_map(Edit::Type),
        (0u16..4).prop_map(Edit::Primary),
        proptest::option::of(num.clone()).prop_map(Edit::Nodata),
        proptest::option::of((num.clone(), num.clone())).prop_map(Edit::Range),
        (num.clone(), num).prop_map(|(s, o)| Edit::Mapping(s, o)),
        (0usize..2, 0u16..9).prop_map(|(i, k)| Edit::Kind(i, k)),
        (0usize..2, 0u16..4).prop_map(|(i, f)| Edit::Flags(i, f)),
    ]
}

fn apply(h: &mut Header, sections: &mut [container::Section], e: &Edit) {
    match *e {
        Edit::Width(w) => h.width = w,
        Edit::Height(v) => h.height = v,
        Edit::Type(t) => {
            if let Some(st) = SampleType::from_code(t) {
                h.sample_type = st;
            }
        }
        Edit::Primary(p) => h.primary = p,
        Edit::Nodata(n) => h.nodata = n,
        Edit::Range(r) => h.range = r,
        Edit::Mapping(scale, offset) => h.mapping = ValueMapping { scale, offset },
        Edit::Kind(i, k) => {
            if let Some(s) = sections.get_mut(i) {
                s.kind = SectionKind(k);
            }
        }
        Edit::Flags(i, f) => {
            if let Some(s) = sections.get_mut(i) {
                s.flags = f;
            }
        }
    }
}

proptest! {
    #![proptest_config(common::proptest_config(400))]

    #[test]
    fn edited_headers_with_fresh_checksums_decode_as_described_or_fail(
        which in 0usize..4,
        edits in proptest::collection::vec(edit(), 1..4),
    ) {
        let golden = &goldens()[which];
        let c = container::read(golden, Limits::default()).unwrap();
        let (mut h, mut sections) = (c.header.clone(), c.sections.clone());
        for e in &edits {
            apply(&mut h, &mut sections, e);
        }
        // `write` frames the edited fields with correct checksums (it serializes what it is
        // given, even values a decoder must reject).
        let file = container::write(&h, &sections);
        let limits = Limits { max_samples: 1 << 22, max_section_bytes: 1 << 24 };
        let Ok(mut d) = Decoder::with_limits(Cursor::new(file.to_vec()), limits) else {
            return Ok(());
        };
        let info = d.info().clone();
        prop_assert_eq!((info.width, info.height), (h.width, h.height));
        prop_assert_eq!(info.sample_type, h.sample_type);
        let _ = d.stats();
        let _ = d.sites();
        let _ = d.verify();
        for i in 0..info.sections.len() {
            d.section(SectionChoice::Index(i));
            if let Ok(r) = d.decode() {
                prop_assert_eq!((r.width, r.height), (h.width as usize, h.height as usize));
                prop_assert_eq!(r.data.len(), r.width * r.height);
                prop_assert_eq!(r.sample_type, h.sample_type);
                prop_assert_eq!(r.mapping, h.mapping);
                for k in 0..r.data.len() {
                    if r.is_valid(k) {
                        prop_assert!(r.data[k].is_finite(), "valid sample {} is {}", k, r.data[k]);
                    }
                }
            }
        }
    }
}
