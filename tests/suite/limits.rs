//! Every size a decode derives — from the header, from an option (`--scale`, `--window`,
//! `--sites`, `--level`) or from their product — is checked against `Limits` before
//! anything of that size is allocated; over the limit is `LimitExceeded` naming the size.

use crate::common;

use common::{Kind, decode_opts as with, terrain, tmp, vtz};
use vtz::{DecodeOptions, Decoder, Error, ErrorBound, Limits, Method, SampleType, Scale, Window};

/// A small sites file (40 × 30 samples).
fn sites_file() -> Vec<u8> {
    let r = terrain(Kind::Fbm, 40, 30, 7, false, SampleType::I16);
    vtz::Encoder::new()
        .max_error(ErrorBound::PercentOfRange(2.0))
        .method(Method::SIBSON)
        .encode(&r)
        .unwrap()
}

fn limits(max_samples: u64) -> Limits {
    Limits {
        max_samples,
        ..Limits::default()
    }
}

fn limit_message(r: vtz::Result<vtz::Raster>) -> String {
    match r {
        Err(Error::LimitExceeded { what }) => what,
        other => panic!("expected LimitExceeded, got {other:?}"),
    }
}

#[test]
fn header_size_is_checked_against_the_limits() {
    let bytes = sites_file();
    // 1 200 samples: a limit of 1 199 refuses the file before any sample is decoded.
    let e = Decoder::with_limits(std::io::Cursor::new(bytes.to_vec()), limits(1199))
        .err()
        .expect("refused");
    assert!(matches!(e, Error::LimitExceeded { .. }), "{e}");
    assert!(Decoder::with_limits(std::io::Cursor::new(bytes.to_vec()), limits(1200)).is_ok());
}

#[test]
fn scale_output_is_checked_against_the_limits() {
    let bytes = sites_file();
    // The default limit (2^28 samples): a 4096× resampling of 40 × 30 is 163 840 × 122 880.
    let what = limit_message(vtz::decode_with(
        &bytes,
        &with(|o| o.scale = Some(Scale::parse("4096").unwrap())),
    ));
    assert!(what.contains("163840x122880"), "{what}");
    assert!(what.contains("20132659200 samples"), "{what}");
    // A tighter limit: ×2 makes 80 × 60 = 4 800 samples.
    let what = limit_message(vtz::decode_with(
        &bytes,
        &with(|o| {
            o.scale = Some(Scale::parse("2").unwrap());
            o.limits = limits(4799);
        }),
    ));
    assert!(what.contains("80x60 raster = 4800 samples"), "{what}");
    let r = vtz::decode_with(
        &bytes,
        &with(|o| {
            o.scale = Some(Scale::parse("2").unwrap());
            o.limits = limits(4800);
        }),
    )
    .unwrap();
    assert_eq!((r.width, r.height), (80, 60));
}

#[test]
fn window_is_checked_against_the_raster_before_allocation() {
    let bytes = sites_file();
    for w in [
        Window {
            x: 0,
            y: 0,
            width: usize::MAX,
            height: usize::MAX,
        },
        Window {
            x: usize::MAX,
            y: 0,
            width: 2,
            height: 2,
        },
        Window {
            x: 39,
            y: 29,
            width: 2,
            height: 1,
        },
        Window {
            x: 0,
            y: 0,
            width: 0,
            height: 3,
        },
    ] {
        match vtz::decode_with(&bytes, &with(|o| o.window = Some(w))) {
            Err(Error::InvalidArgument { what }) => {
                assert!(what.contains("is not inside"), "{what}")
            }
            other => panic!("window {w:?}: {other:?}"),
        }
    }
    let r = vtz::decode_with(
        &bytes,
        &with(|o| {
            o.window = Some(Window {
                x: 38,
                y: 28,
                width: 2,
                height: 2,
            })
        }),
    )
    .unwrap();
    assert_eq!(r.data.len(), 4);
}

#[test]
fn huge_site_and_level_counts_are_refused_without_allocating() {
    // `--sites N` and `--level K` past what the stream holds are errors that name the
    // range (never clamped silently), raised before anything is sized by N.
    let bytes = sites_file();
    for (set, what) in [
        (
            (|o: &mut DecodeOptions| o.sites = Some(usize::MAX)) as fn(&mut DecodeOptions),
            "--sites",
        ),
        (
            |o: &mut DecodeOptions| o.levels = Some(usize::MAX),
            "--level",
        ),
    ] {
        match vtz::decode_with(&bytes, &with(set)) {
            Err(vtz::Error::InvalidArgument { what: w }) => assert!(w.contains(what), "{w}"),
            other => panic!("{what}: {other:?}"),
        }
    }
}

#[test]
fn cli_scale_4096_is_a_one_line_limit_error() {
    let dir = tempfile::tempdir().unwrap();
    let f = tmp(&dir, "s.vtz");
    std::fs::write(&f, sites_file()).unwrap();
    let out = tmp(&dir, "big.tif");
    let o = vtz(["decode", f.as_str(), "-o", out.as_str(), "--scale", "4096"]);
    assert_eq!(o.status.code(), Some(1), "runtime error, not usage");
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.starts_with("vtz: limit exceeded: "), "{err}");
    assert!(err.contains("163840x122880"), "{err}");
    assert!(!std::path::Path::new(&out).exists(), "no output on error");
}
