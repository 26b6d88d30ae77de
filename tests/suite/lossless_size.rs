//! Sizes where a simple peer used to win (issue 35): a constant raster costs about a header
//! at every bound, lossless included (item 8); a float raster on a lattice of another
//! unit's step (whole feet × 0.3048 in f32) codes on that lattice, bit for bit (item 7).

use crate::common;

use common::{encode_opts, read_corpus};
use flate2::Compression;
use flate2::write::DeflateEncoder;
use std::io::Write;
use vtz::{ErrorBound, Raster, SampleType};

/// A `w`×`h` raster of `value` everywhere, with `holes` rectangles of nodata (−32768).
fn constant(w: usize, h: usize, value: f64, st: SampleType, holes: bool) -> Raster {
    let nodata = -32768.0;
    let mut data = vec![value; w * h];
    if holes {
        for &(x0, y0, rw, rh) in &[(10, 20, 7, 3), (600, 600, 40, 25), (1190, 1000, 11, 9)] {
            for y in y0..(y0 + rh).min(h) {
                for x in x0..(x0 + rw).min(w) {
                    data[y * w + x] = nodata;
                }
            }
        }
    }
    Raster::from_values(w, h, data, Some(nodata), st).unwrap()
}

/// The valid samples and the mask of `got` are `want`'s, bit for bit.
fn same_bits(want: &Raster, got: &Raster, what: &str) {
    assert_eq!((got.width, got.height), (want.width, want.height), "{what}");
    for i in 0..want.data.len() {
        assert_eq!(
            got.is_valid(i),
            want.is_valid(i),
            "{what}: validity of sample {i}"
        );
        if want.is_valid(i) {
            assert_eq!(
                got.data[i].to_bits(),
                want.data[i].to_bits(),
                "{what}: sample {i}: {} decoded as {}",
                want.data[i],
                got.data[i]
            );
        }
    }
}

/// A constant SRTM-sized tile (−29 m; 3.25 for f32), with and without nodata holes,
/// untiled and tiled: lossless is never larger than `--max-error 1`, costs about a header
/// (before: 603 bytes lossless against 192 at max error 1 untiled, 3 118 against 266 for a
/// 3601² .hgt), and decodes exactly (within 1 at max error 1).
#[test]
fn a_constant_raster_costs_about_a_header_at_every_bound() {
    let (w, h) = (1201, 1201);
    for st in [SampleType::I16, SampleType::F32] {
        let value = if st == SampleType::I16 { -29.0 } else { 3.25 };
        for holes in [false, true] {
            let r = constant(w, h, value, st, holes);
            for tile in [None, Some(512)] {
                let what = format!("{st:?} holes {holes} tile {tile:?}");
                let size = |bound: Option<ErrorBound>| {
                    let mut o = encode_opts(&[], bound);
                    o.tile = tile;
                    let bytes = vtz::encode(&r, &o).unwrap();
                    let got = vtz::decode(&bytes).unwrap();
                    if bound.is_none() {
                        same_bits(&r, &got, &what);
                    } else {
                        // The samples beside the holes are the method's, within the bound.
                        for i in 0..r.data.len() {
                            assert_eq!(got.is_valid(i), r.is_valid(i), "{what}");
                            assert!(
                                !r.is_valid(i) || (got.data[i] - r.data[i]).abs() <= 1.0,
                                "{what}"
                            );
                        }
                    }
                    bytes.len()
                };
                let lossless = size(None);
                let lossy = size(Some(ErrorBound::Abs(1.0)));
                assert!(
                    lossless <= lossy,
                    "{what}: {lossless} bytes lossless, {lossy} at max error 1"
                );
                // A header and a flat region per tile (3 × 3 tiles of 512), and the mask of
                // the holes.
                let limit = match (tile, holes) {
                    (None, false) => 300,
                    (None, true) => 500,
                    (Some(_), false) => 9 * 250,
                    (Some(_), true) => 9 * 250 + 400,
                };
                assert!(
                    lossless <= limit,
                    "{what}: {lossless} bytes lossless, over {limit}"
                );
            }
        }
    }
}

/// Whole feet × 0.3048 in f32 (computed in f64, rounded once): the Kauai tile in feet, with
/// its voids.
fn kauai_feet() -> Raster {
    let m = read_corpus("srtm3_N22W160_kauai.hgt");
    let nodata = -32768.0;
    let data: Vec<f64> = (0..m.data.len())
        .map(|i| {
            if m.is_valid(i) {
                ((m.data[i] / 0.3048).round() * 0.3048) as f32 as f64
            } else {
                nodata
            }
        })
        .collect();
    Raster::from_values(m.width, m.height, data, Some(nodata), SampleType::F32).unwrap()
}

/// The raw little-endian f32 bytes of `r` (nodata as NaN), DEFLATEd at the best level: the
/// simple reference every lossless float coding should beat.
fn deflate_of_raw(r: &Raster) -> usize {
    let raw: Vec<u8> = (0..r.data.len())
        .flat_map(|i| {
            let v = if r.is_valid(i) {
                r.data[i] as f32
            } else {
                f32::NAN
            };
            v.to_le_bytes()
        })
        .collect();
    let mut e = DeflateEncoder::new(Vec::new(), Compression::best());
    e.write_all(&raw).unwrap();
    e.finish().unwrap().len()
}

/// The feet raster codes on its own lattice: smaller than DEFLATE of its raw f32 bytes
/// (before: the grid's f32 bit keys, 254 999 bytes against DEFLATE's 252 237), within 10 %
/// of the same raster's integer feet coded as integers (109 385 bytes), and back bit for
/// bit; the same bytes twice.
#[test]
fn feet_times_0_3048_codes_on_its_lattice() {
    let r = kauai_feet();
    let bytes = vtz::encode(&r, &Default::default()).unwrap();
    same_bits(&r, &vtz::decode(&bytes).unwrap(), "feet");
    let deflate = deflate_of_raw(&r);
    assert!(
        bytes.len() < deflate,
        "{} bytes against DEFLATE's {deflate}",
        bytes.len()
    );
    // The integer feet as i32 codes: what a lattice of 0.3048 must cost.
    let ints: Vec<f64> = (0..r.data.len())
        .map(|i| {
            if r.is_valid(i) {
                (r.data[i] / 0.3048).round()
            } else {
                -32768.0
            }
        })
        .collect();
    let ri = Raster::from_values(r.width, r.height, ints, Some(-32768.0), SampleType::I32).unwrap();
    let int_len = vtz::encode(&ri, &Default::default()).unwrap().len();
    assert!(
        bytes.len() as f64 <= 1.1 * int_len as f64,
        "{} bytes against {int_len} for the integer feet",
        bytes.len()
    );
    assert_eq!(
        bytes,
        vtz::encode(&r, &Default::default()).unwrap(),
        "deterministic"
    );
}

/// The lattice path keeps every bit: −0, subnormals, a sample off the lattice, NaN holes,
/// lossless (the odd samples stored verbatim) and within a bound.
#[test]
fn feet_with_negative_zero_subnormals_and_holes_round_trip() {
    let base = kauai_feet();
    // A 300 × 200 window with land (the lattice has at least a few distinct values).
    let (x0, y0, w, h) = (500, 500, 300, 200);
    let mut data = Vec::with_capacity(w * h);
    for y in 0..h {
        for x in 0..w {
            let i = (y0 + y) * base.width + x0 + x;
            data.push(if base.is_valid(i) {
                base.data[i]
            } else {
                f64::NAN
            });
        }
    }
    let odd = [
        (3, -0.0),
        (777, f32::from_bits(1) as f64),
        (778, -(f32::from_bits(0x0040_0000) as f64)),
        (4000, 0.0),
        (5001, 123.456_f32 as f64),
        (9000, f64::NAN),
        (9001, f64::NAN),
    ];
    for &(i, v) in &odd {
        data[i] = v;
    }
    let r = Raster::from_values(w, h, data, None, SampleType::F32).unwrap();
    let bytes = vtz::encode(&r, &Default::default()).unwrap();
    let got = vtz::decode(&bytes).unwrap();
    same_bits(&r, &got, "lossless");
    assert!(
        got.data[3].is_sign_negative() && got.data[3] == 0.0,
        "−0 kept"
    );
    assert!(
        !got.is_valid(9000) && !got.is_valid(9001),
        "NaN holes stay nodata"
    );
    let deflate = deflate_of_raw(&r);
    assert!(
        bytes.len() < deflate,
        "{} bytes against DEFLATE's {deflate}",
        bytes.len()
    );
    // Whole metres in f32 with −0 and NaN holes: whole numbers, but not the same bits on
    // the whole-number lattice (before: −0 decoded as +0).
    let m = read_corpus("srtm3_N22W160_kauai.hgt");
    let mut metres: Vec<f64> = (0..w * h)
        .map(|j| {
            let i = (y0 + j / w) * m.width + x0 + j % w;
            if m.is_valid(i) { m.data[i] } else { f64::NAN }
        })
        .collect();
    for i in [5, 6, 700, 12_345] {
        metres[i] = -0.0;
    }
    metres[800] = f64::NAN;
    let rm = Raster::from_values(w, h, metres, None, SampleType::F32).unwrap();
    same_bits(
        &rm,
        &vtz::decode(&vtz::encode(&rm, &Default::default()).unwrap()).unwrap(),
        "metres",
    );
    // Within a bound: every valid sample within it.
    let bytes = vtz::encode(&r, &encode_opts(&[], Some(ErrorBound::Abs(0.5)))).unwrap();
    let got = vtz::decode(&bytes).unwrap();
    for i in 0..r.data.len() {
        assert_eq!(got.is_valid(i), r.is_valid(i));
        if r.is_valid(i) {
            assert!((got.data[i] - r.data[i]).abs() <= 0.5, "sample {i}");
        }
    }
}
