//! `--method best` chooses from a probe (the residual layer and the grid on a sample of
//! rows) and encodes in full only the methods the probe cannot rule out, yet writes the
//! file of the exhaustive choice (every method encoded in full, the smallest kept).

use crate::common;
use common::*;
use vtz::{ErrorBound, Method};

/// Best's file and report, the exhaustive choice's method, and that method's file alone.
fn best_and_exhaustive(name: &str, b: ErrorBound) -> (Vec<u8>, vtz::EncodeReport, Method, Vec<u8>) {
    let r = read_corpus(name);
    let (best, rep) = vtz::encode_report(&r, &encode_opts(&[], Some(b))).unwrap();
    let all = encode_opts(&Method::all().collect::<Vec<_>>(), Some(b));
    let (_, exh) = vtz::encode_report(&r, &all).unwrap();
    let (alone, _) = vtz::encode_report(&r, &encode_opts(&[exh.method], Some(b))).unwrap();
    (best, rep, exh.method, alone)
}

// Crater Lake (393 × 392) within 1 m: the probe rules out the methods that win at low
// rates (sibson, FIS) and Haar, so `best` encodes the residual layer and at most the grid
// (before the probe: all five methods in full), and its file is the exhaustive choice's.
#[test]
fn best_encodes_only_the_residual_layer_where_the_probe_is_sure() {
    let (best, rep, exh, alone) = best_and_exhaustive("scape_crater.png", ErrorBound::Abs(1.0));
    assert_eq!(exh, Method::RESIDUAL);
    assert!(rep.encoded.contains(&Method::RESIDUAL), "{:?}", rep.encoded);
    assert!(
        rep.encoded
            .iter()
            .all(|m| [Method::RESIDUAL, Method::GRID].contains(m)),
        "{:?}",
        rep.encoded
    );
    assert_eq!(best, alone, "best writes the residual layer's file");
}

// Crater Lake within 10 % of the range: a smooth raster at a loose bound, where the sites
// win; the probe's low rate keeps them (and FIS) in the running, and `best` still finds them.
#[test]
fn best_still_finds_the_sites_at_a_loose_bound() {
    let (best, rep, exh, alone) =
        best_and_exhaustive("scape_crater.png", ErrorBound::PercentOfRange(10.0));
    assert_eq!(exh, Method::SIBSON);
    assert_eq!(rep.method, Method::SIBSON);
    assert!(rep.encoded.contains(&Method::SIBSON), "{:?}", rep.encoded);
    assert!(!rep.encoded.contains(&Method::HAAR), "{:?}", rep.encoded);
    assert_eq!(best, alone, "best writes the sites' file");
}

// The Delft lidar DSM (buildings' edges) within 0.1 % of the range: the grid wins by 7 %;
// the probe keeps it beside the residual layer and leaves the sites out.
#[test]
fn best_still_finds_the_grid_on_edges() {
    let (best, rep, exh, alone) =
        best_and_exhaustive("ahn3_delft_dsm_50cm.f32", ErrorBound::PercentOfRange(0.1));
    assert_eq!(exh, Method::GRID);
    assert_eq!(rep.method, Method::GRID);
    let mut enc = rep.encoded.clone();
    enc.sort_by_key(|m| m.name());
    assert_eq!(enc, vec![Method::GRID, Method::RESIDUAL]);
    assert_eq!(best, alone, "best writes the grid's file");
}
