//! The Haar section: a 2-D integer Haar (S-transform) pyramid, dead-zone quantized, range
//! coded with per-subband contexts — the wavelet baseline of the Voronoi paper.
//!
//! Samples map to integer codes on a value lattice (the source's code lattice for integer
//! types, step 1 for float data holding integers, a fine lattice for other float data), the
//! codes go through a Mallat pyramid of integer lifting steps (exactly invertible), and
//! the coefficients are quantized with a dead zone and range coded band by band. A
//! `--max-error` bound is met by a closed loop on the quantizer step: the encoder rebuilds
//! every sample exactly as [`decode`] does and checks it against the bound. The byte layout
//! is in spec/FORMAT.md ("Haar section").

mod method;
pub(crate) use method::Haar;
pub use method::HaarOptions;

mod coding;
mod decoder;
mod encoder;
mod lattice;
mod quant;
mod transform;

pub use decoder::{decode, describe};
#[cfg(test)]
use encoder::encode;
pub(crate) use encoder::{encode_progress, encode_step};

/// Coding 0: S-transform Mallat pyramid, dead-zone quantizer, range-coded bands.
const CODING_PYRAMID: u8 = 0;
/// Quantizer steps are stored in units of 1/16 of a lattice step.
const STEP_UNIT: u64 = 16;
/// Largest step a decoder accepts (in 1/16 units).
const MAX_STEP: u64 = 1 << 52;

/// Parameters of the Haar representation.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct HaarParams {
    /// Max absolute error in data units; 0 means lossless (integer-valued data only).
    pub max_error: f64,
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::path::Path;

    use super::transform::max_levels;
    use crate::container::Header;
    use crate::container::bytes::PutLe;
    use crate::error::Error;
    use crate::model::{Raster, SampleType, ValueMapping};
    use crate::testutil::Rng;

    fn header_of(r: &Raster) -> Header {
        Header::of(r).expect("small raster")
    }

    /// Midpoint-displacement-like fractal surface: sums of random octaves of bilinear noise.
    fn fractal(w: usize, h: usize, seed: u64, amplitude: f64) -> Vec<f64> {
        let mut rng = Rng(seed);
        let mut out = vec![0.0; w * h];
        let mut cell = 64usize;
        let mut amp = amplitude;
        while cell >= 1 {
            let gw = w / cell + 2;
            let gh = h / cell + 2;
            let grid: Vec<f64> = (0..gw * gh).map(|_| rng.unit() * 2.0 - 1.0).collect();
            for y in 0..h {
                for x in 0..w {
                    let (fx, fy) = (x as f64 / cell as f64, y as f64 / cell as f64);
                    let (ix, iy) = (fx as usize, fy as usize);
                    let (tx, ty) = (fx - ix as f64, fy - iy as f64);
                    let g = |a: usize, b: usize| grid[b * gw + a];
                    let v = g(ix, iy) * (1.0 - tx) * (1.0 - ty)
                        + g(ix + 1, iy) * tx * (1.0 - ty)
                        + g(ix, iy + 1) * (1.0 - tx) * ty
                        + g(ix + 1, iy + 1) * tx * ty;
                    out[y * w + x] += v * amp;
                }
            }
            cell /= 2;
            amp *= 0.5;
        }
        out
    }

    fn crater() -> Raster {
        crate::formats::read_path(
            Path::new(concat!(
                env!("CARGO_MANIFEST_DIR"),
                "/corpus/scape_crater.png"
            )),
            &Default::default(),
        )
        .unwrap()
    }

    /// Decode and check every valid sample against `bound` (and the reported error).
    fn check_round_trip(r: &Raster, payload: &[u8], reported: f64, bound: f64) -> Vec<f64> {
        let back = decode(payload, &header_of(r), r.mask.as_deref()).unwrap();
        let mut max = 0f64;
        for (i, &b) in back.iter().enumerate() {
            if r.is_valid(i) {
                max = max.max((b - r.data[i]).abs());
            } else {
                match r.nodata {
                    Some(nd) => assert_eq!(b, nd),
                    None => assert!(b.is_nan()),
                }
            }
        }
        assert!(max <= bound, "max error {max} > bound {bound}");
        assert_eq!(max, reported);
        back
    }

    proptest! {
        #![proptest_config(crate::testutil::proptest_config(24))]

        /// Any size, bound, sample type and nodata pattern: the decoded raster meets the
        /// bound the encoder reports, and the reported error is the measured one.
        #[test]
        fn round_trip_meets_the_bound(
            w in 1usize..60, h in 1usize..60, seed in any::<u64>(),
            pct in 0.05f64..30.0, int in any::<bool>(), holes in any::<bool>(),
        ) {
            let mut data = fractal(w, h, seed, 200.0);
            if int {
                data.iter_mut().for_each(|v| *v = v.round());
            }
            let st = if int { SampleType::I16 } else { SampleType::F32 };
            if !int {
                data.iter_mut().for_each(|v| *v = *v as f32 as f64);
            }
            let mut nodata = None;
            if holes {
                nodata = Some(-9999.0);
                let mut rng = Rng(seed ^ 0x5555);
                for v in data.iter_mut() {
                    if rng.unit() < 0.1 {
                        *v = -9999.0;
                    }
                }
            }
            let r = Raster::from_values(w, h, data, nodata, st).unwrap();
            let Some((lo, hi)) = r.valid_range() else { return Ok(()); };
            let bound = ((hi - lo) * pct / 100.0).max(1e-3);
            let (payload, err) = encode(&r, &HaarParams { max_error: bound }).unwrap();
            check_round_trip(&r, &payload, err, bound);
        }
    }

    #[test]
    fn lossless_is_bit_exact_on_integer_data() {
        for (w, h) in [(1, 1), (1, 30), (30, 1), (37, 23), (64, 64), (3, 2)] {
            let data: Vec<f64> = fractal(w, h, 7, 500.0)
                .iter()
                .map(|v| (v + 1000.0).round())
                .collect();
            for st in [SampleType::I16, SampleType::F32, SampleType::F64] {
                let r = Raster::from_values(w, h, data.clone(), None, st).unwrap();
                let (payload, err) = encode(&r, &HaarParams { max_error: 0.0 }).unwrap();
                assert_eq!(err, 0.0);
                let back = check_round_trip(&r, &payload, 0.0, 0.0);
                assert_eq!(back, r.data);
            }
        }
        let r = crater();
        let (payload, err) = encode(&r, &HaarParams::default()).unwrap();
        assert_eq!(err, 0.0);
        check_round_trip(&r, &payload, 0.0, 0.0);
    }

    #[test]
    fn negative_value_scale() {
        // u16 codes with value = 100 − 0.5·code: the lattice runs the other way.
        let (w, h) = (29, 17);
        let mapping = ValueMapping {
            scale: -0.5,
            offset: 100.0,
        };
        let data: Vec<f64> = fractal(w, h, 17, 2000.0)
            .iter()
            .map(|v| mapping.to_value((v + 3000.0).round()))
            .collect();
        let mut r = Raster::from_values(w, h, data, None, SampleType::U16).unwrap();
        r.mapping = mapping;
        for bound in [0.0, 3.0] {
            let (payload, err) = encode(&r, &HaarParams { max_error: bound }).unwrap();
            let back = check_round_trip(&r, &payload, err, bound);
            for &b in &back {
                assert_eq!(mapping.to_value(mapping.to_code(b).round()), b);
            }
        }
    }

    /// An 11×7 raster with nodata, 4 levels (odd sizes, empty bands), bound 2.
    fn golden_raster() -> Raster {
        let (w, h) = (11, 7);
        let data: Vec<f64> = fractal(w, h, 19, 60.0)
            .iter()
            .enumerate()
            .map(|(i, v)| {
                if i % 13 == 5 {
                    -1.0
                } else {
                    (v + 200.0).round()
                }
            })
            .collect();
        Raster::from_values(w, h, data, Some(-1.0), SampleType::I16).unwrap()
    }

    /// A payload the encoder wrote for [`golden_raster`] (4 levels, steps 1 to 4.4, bias
    /// 96/256) and what it decodes to: a change here is a format change.
    const GOLDEN: &[u8] = &[
        0, 0, 4, 96, 0, 0, 0, 0, 0, 0, 240, 63, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 64,
        16, 16, 16, 16, 16, 16, 16, 16, 16, 35, 47, 47, 71, 63, 218, 115, 91, 43, 218, 47, 76, 47,
        210, 190, 138, 178, 3, 244, 6, 0, 0, 0,
    ];
    const GOLDEN_DECODED: [i16; 77] = [
        242, 242, 241, 241, 240, -1, 241, 241, 239, 239, 238, 242, 242, 241, 241, 240, 240, 241,
        -1, 239, 239, 238, 242, 242, 238, 238, 243, 240, 237, 237, 238, -1, 237, 242, 242, 238,
        238, 236, 239, 237, 237, 238, 238, 237, -1, 240, 238, 238, 235, 235, 237, 237, 237, 237,
        236, 240, 240, -1, 238, 235, 235, 237, 237, 237, 237, 236, 240, 240, 235, 235, -1, 236,
        235, 235, 236, 236, 235,
    ];

    #[test]
    fn format_is_frozen() {
        let r = golden_raster();
        let back = decode(GOLDEN, &header_of(&r), r.mask.as_deref()).unwrap();
        let expected: Vec<f64> = GOLDEN_DECODED.iter().map(|&v| v as f64).collect();
        assert_eq!(back, expected);
        for (i, (&b, &v)) in back.iter().zip(&r.data).enumerate() {
            assert!(!r.is_valid(i) || (b - v).abs() <= 2.0);
        }
    }

    #[test]
    fn lossless_non_integer_float_is_refused() {
        let r = Raster::from_values(4, 4, vec![0.5; 16], None, SampleType::F32).unwrap();
        assert!(matches!(
            encode(&r, &HaarParams::default()),
            Err(Error::Unmet { .. })
        ));
        // ... but a bound works.
        let (payload, err) = encode(&r, &HaarParams { max_error: 0.01 }).unwrap();
        check_round_trip(&r, &payload, err, 0.01);
    }

    #[test]
    fn lossy_meets_the_bound_on_a_fractal_surface() {
        let (w, h) = (101, 77);
        let data = fractal(w, h, 3, 300.0);
        for st in [SampleType::F32, SampleType::F64] {
            let data: Vec<f64> = if st == SampleType::F32 {
                data.iter().map(|&v| v as f32 as f64).collect()
            } else {
                data.clone()
            };
            let r = Raster::from_values(w, h, data, None, st).unwrap();
            let mut last = usize::MAX;
            for bound in [0.01, 0.3, 1.0, 5.0, 30.0] {
                let (payload, err) = encode(&r, &HaarParams { max_error: bound }).unwrap();
                check_round_trip(&r, &payload, err, bound);
                assert!(payload.len() < last, "{st:?} {bound}: {}", payload.len());
                last = payload.len();
            }
        }
        // Integer data with a mapping (decimetres + offset): outputs stay on the code lattice.
        let data: Vec<f64> = data
            .iter()
            .map(|v| (v * 10.0).round() / 10.0 - 50.0)
            .collect();
        let mut r = Raster::from_values(w, h, data, None, SampleType::I16).unwrap();
        r.mapping = ValueMapping {
            scale: 0.1,
            offset: -50.0,
        };
        r.data = r
            .data
            .iter()
            .map(|&v| r.mapping.to_value(r.mapping.to_code(v).round()))
            .collect();
        for bound in [0.0, 0.25, 2.0] {
            let (payload, err) = encode(&r, &HaarParams { max_error: bound }).unwrap();
            let back = check_round_trip(&r, &payload, err, bound);
            for &b in &back {
                let c = r.mapping.to_code(b).round();
                assert_eq!(r.mapping.to_value(c), b);
            }
        }
    }

    #[test]
    fn lossy_meets_the_bound_on_crater() {
        let r = crater();
        let mut last = usize::MAX;
        for bound in [1.0, 3.0, 10.0, 30.0] {
            let (payload, err) = encode(&r, &HaarParams { max_error: bound }).unwrap();
            check_round_trip(&r, &payload, err, bound);
            assert!(payload.len() < last);
            last = payload.len();
        }
        for step in [2.0, 20.0, 200.0] {
            let (payload, err) = encode_step(&r, step).unwrap();
            check_round_trip(&r, &payload, err, f64::INFINITY);
        }
    }

    #[test]
    fn nodata_samples_get_the_fill() {
        let (w, h) = (45, 31);
        let mut data: Vec<f64> = fractal(w, h, 11, 200.0).iter().map(|v| v.round()).collect();
        for (i, v) in data.iter_mut().enumerate() {
            let (x, y) = (i % w, i / w);
            // a hole, a full invalid row, a ragged edge
            if (x > 10 && x < 20 && y > 5 && y < 12) || y == 20 || x + y < 6 {
                *v = -9999.0;
            }
        }
        for nodata in [Some(-9999.0), None] {
            let mut data = data.clone();
            if nodata.is_none() {
                data.iter_mut()
                    .filter(|v| **v == -9999.0)
                    .for_each(|v| *v = f64::NAN);
            }
            let r = Raster::from_values(w, h, data, nodata, SampleType::I16).unwrap();
            assert!(r.mask.is_some());
            for bound in [0.0, 2.0, 20.0] {
                let (payload, err) = encode(&r, &HaarParams { max_error: bound }).unwrap();
                check_round_trip(&r, &payload, err, bound);
            }
        }
        // Nothing valid at all.
        let r = Raster::from_values(3, 5, vec![f64::NAN; 15], None, SampleType::F32).unwrap();
        let (payload, err) = encode(&r, &HaarParams { max_error: 1.0 }).unwrap();
        check_round_trip(&r, &payload, err, 1.0);
    }

    #[test]
    fn f32_output_rounding_is_in_the_loop() {
        // Large values with small bounds: the f32 rounding is a sizeable part of the error.
        let (w, h) = (40, 33);
        let data: Vec<f64> = fractal(w, h, 5, 50.0)
            .iter()
            .map(|v| (v + 4000.0) as f32 as f64)
            .collect();
        let r = Raster::from_values(w, h, data, None, SampleType::F32).unwrap();
        for bound in [0.001, 0.01, 0.1] {
            let (payload, err) = encode(&r, &HaarParams { max_error: bound }).unwrap();
            let back = check_round_trip(&r, &payload, err, bound);
            assert!(back.iter().all(|&v| v as f32 as f64 == v));
        }
    }

    /// A 71×45 raster (2 levels, odd sizes) and its payload at a bound of 3.
    fn sample_payload() -> (Raster, Vec<u8>) {
        static SAMPLE: std::sync::OnceLock<(Raster, Vec<u8>)> = std::sync::OnceLock::new();
        SAMPLE
            .get_or_init(|| {
                let (w, h) = (71, 45);
                let data: Vec<f64> = fractal(w, h, 13, 100.0).iter().map(|v| v.round()).collect();
                let r = Raster::from_values(w, h, data, None, SampleType::I16).unwrap();
                let (payload, _) = encode(&r, &HaarParams { max_error: 3.0 }).unwrap();
                assert_eq!(payload[2], 2);
                (r, payload)
            })
            .clone()
    }

    #[test]
    fn every_truncation_is_an_error() {
        let (r, payload) = sample_payload();
        let golden = golden_raster();
        for (r, payload) in [(&r, payload.as_slice()), (&golden, GOLDEN)] {
            let (header, mask) = (header_of(r), r.mask.as_deref());
            decode(payload, &header, mask).unwrap();
            for cut in 0..payload.len() {
                assert!(decode(&payload[..cut], &header, mask).is_err(), "cut {cut}");
            }
            let mut longer = payload.to_vec();
            longer.push(0);
            assert!(decode(&longer, &header, mask).is_err());
        }
    }

    #[test]
    fn bad_metadata_is_rejected() {
        let (r, payload) = sample_payload();
        let header = header_of(&r);
        decode(&payload, &header, None).unwrap();
        let bad = |at: usize, bytes: &[u8]| {
            let mut p = payload.clone();
            p[at..at + bytes.len()].copy_from_slice(bytes);
            match decode(&p, &header, None) {
                Err(Error::Corrupt { .. }) => {}
                other => panic!("byte {at}: {other:?}"),
            }
        };
        bad(0, &[1]); // coding
        bad(1, &[1]); // reserved flags
        bad(2, &[max_levels(71, 45) as u8 + 1]); // levels
        bad(4, &0f64.to_le_bytes()); // lattice step
        bad(4, &(-1f64).to_le_bytes());
        bad(4, &f64::NAN.to_le_bytes());
        bad(12, &f64::INFINITY.to_le_bytes()); // offset
        bad(20, &(-1f64).to_le_bytes()); // max error
        bad(28, &[15]); // a band step below 1
        // a mask of the wrong size
        assert!(decode(&payload, &header, Some(&[true; 3])).is_err());
    }

    proptest! {
        #![proptest_config(crate::testutil::proptest_config(200))]
        #[test]
        fn garbage_never_panics(
            bytes in prop::collection::vec(any::<u8>(), 0..200),
            w in 1u32..40,
            h in 1u32..40,
            levels in 0u8..8,
            st in 0u8..6,
        ) {
            let header = Header {
                width: w,
                height: h,
                sample_type: SampleType::from_code(st).unwrap(),
                primary: 0,
                mapping: Default::default(),
                nodata: None,
                range: None,
                georef: None,
            };
            let _ = decode(&bytes, &header, None);
            // A plausible header in front of the garbage reaches the coefficient decoder.
            let mut p = vec![0u8, 0, levels, 100];
            p.put_f64(0.5);
            p.put_f64(-3.0);
            p.put_f64(1.0);
            p.extend_from_slice(&bytes);
            let _ = decode(&p, &header, None);
        }

        #[test]
        fn flipped_bytes_never_panic(at in 0usize..10_000, xor in 1u8..=255) {
            let (r, mut payload) = sample_payload();
            let at = at % payload.len();
            payload[at] ^= xor;
            let _ = decode(&payload, &header_of(&r), None);
        }
    }

    /// Rate–distortion on crater (run with `--ignored --nocapture`): prints bps, RMSE and
    /// L∞ in % of the range for a few steps, bisects the step for 1.6 and 0.16 bits/sample
    /// (1:10 and 1:100 against 16-bit samples), and the max-error mode at a few bounds.
    #[test]
    #[ignore]
    fn crater_rate_distortion() {
        let r = crater();
        let (lo, hi) = r.valid_range().unwrap();
        let range = hi - lo;
        let n = r.len() as f64;
        let header = header_of(&r);
        let stats = |payload: &[u8]| {
            let back = decode(payload, &header, None).unwrap();
            let mut se = 0.0;
            let mut mx = 0f64;
            for (a, b) in back.iter().zip(&r.data) {
                se += (a - b) * (a - b);
                mx = mx.max((a - b).abs());
            }
            (
                payload.len() as f64 * 8.0 / n,
                (se / n).sqrt() / range * 100.0,
                mx / range * 100.0,
            )
        };
        let t = std::time::Instant::now();
        let (lossless, _) = encode(&r, &HaarParams::default()).unwrap();
        eprintln!(
            "lossless: {} bytes, {:.4} bps ({:?})",
            lossless.len(),
            lossless.len() as f64 * 8.0 / n,
            t.elapsed()
        );
        for step in [1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0] {
            let (p, _) = encode_step(&r, step).unwrap();
            let (bps, rmse, linf) = stats(&p);
            eprintln!("step {step}: {bps:.4} bps, RMSE {rmse:.4} %, L∞ {linf:.3} %");
        }
        for target in [1.6, 0.16] {
            let (mut a, mut b) = (0.5f64, 2000.0f64);
            for _ in 0..40 {
                let mid = (a * b).sqrt();
                let (p, _) = encode_step(&r, mid).unwrap();
                if p.len() as f64 * 8.0 / n > target {
                    a = mid;
                } else {
                    b = mid;
                }
            }
            let t = std::time::Instant::now();
            let (p, _) = encode_step(&r, b).unwrap();
            let te = t.elapsed();
            let t = std::time::Instant::now();
            decode(&p, &header, None).unwrap();
            let td = t.elapsed();
            let (bps, rmse, linf) = stats(&p);
            eprintln!(
                "target {target} bps: step {b:.3}, {bps:.4} bps, RMSE {rmse:.4} %, L∞ {linf:.3} % (enc {te:?}, dec {td:?})"
            );
        }
        for pct in [0.1, 0.3, 1.0, 3.0, 10.0] {
            let t = std::time::Instant::now();
            let (p, err) = encode(
                &r,
                &HaarParams {
                    max_error: range * pct / 100.0,
                },
            )
            .unwrap();
            let te = t.elapsed();
            let (bps, rmse, linf) = stats(&p);
            eprintln!(
                "max error {pct} %: {} bytes, {bps:.4} bps, RMSE {rmse:.4} %, L∞ {linf:.3} % (err {err}, enc {te:?})",
                p.len()
            );
        }
    }
}
