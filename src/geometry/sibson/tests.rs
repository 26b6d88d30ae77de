//! Tests of the surface and its evaluators against the spec's reference.

use super::*;
use crate::geometry::triangulation::Location;
use crate::testutil::Rng;

fn surface(pts: &[[i64; 2]], mut f: impl FnMut([i64; 2]) -> f64) -> Surface {
    let mut s = Surface::new();
    for &p in pts {
        s.insert(p, f(p)).unwrap();
    }
    s
}

fn random_sites(n: usize, w: i64, h: i64, seed: u64) -> Vec<[i64; 2]> {
    let mut rng = Rng(seed);
    let mut pts = vec![[0, 0], [w, 0], [w, h], [0, h]];
    while pts.len() < n {
        let p = [
            rng.below(w as u64 + 1) as i64,
            rng.below(h as u64 + 1) as i64,
        ];
        if !pts.contains(&p) {
            pts.push(p);
        }
    }
    pts
}

#[test]
fn reproduces_linear_functions() {
    let f = |p: [i64; 2]| 3.0 + 0.75 * p[0] as f64 - 1.25 * p[1] as f64;
    for seed in 1..6 {
        let pts = random_sites(60, 50, 40, seed);
        let s = surface(&pts, f);
        let mut sc = Scratch::default();
        let mut hint = 0;
        for y in 0..=40 {
            for x in 0..=50 {
                let v = s.eval([x, y], &mut hint, &mut sc).unwrap();
                assert!(
                    (v - f([x, y])).abs() < 1e-9,
                    "({x},{y}): {v} vs {}",
                    f([x, y])
                );
            }
        }
    }
}

#[test]
fn interpolates_sites_and_stays_within_their_range() {
    let pts = random_sites(80, 30, 30, 7);
    let mut rng = Rng(99);
    let hs: Vec<f64> = (0..pts.len()).map(|_| rng.below(1000) as f64).collect();
    let mut s = Surface::new();
    for (p, h) in pts.iter().zip(&hs) {
        s.insert(*p, *h).unwrap();
    }
    let mut sc = Scratch::default();
    let mut hint = 0;
    for (p, h) in pts.iter().zip(&hs) {
        assert_eq!(s.eval(*p, &mut hint, &mut sc), Some(*h));
    }
    for y in 0..=30 {
        for x in 0..=30 {
            let v = s.eval([x, y], &mut hint, &mut sc).unwrap();
            assert!((0.0..=999.0).contains(&v), "{v}");
        }
    }
}

#[test]
fn result_does_not_depend_on_the_hint() {
    let pts = random_sites(100, 40, 40, 3);
    let mut rng = Rng(5);
    let s = surface(&pts, |_| rng.below(500) as f64 * 0.37);
    let tris: Vec<u32> = s.triangulation().real_triangles().collect();
    let mut sc = Scratch::default();
    for y in 0..=40 {
        for x in 0..=40 {
            let mut h0 = tris[0];
            let v0 = s.eval([x, y], &mut h0, &mut sc).unwrap();
            for &t in tris.iter().step_by(7) {
                let mut h = t;
                let v = s.eval([x, y], &mut h, &mut sc).unwrap();
                assert_eq!(v.to_bits(), v0.to_bits(), "({x},{y})");
            }
        }
    }
}

#[test]
fn matches_spade_natural_neighbour() {
    use spade::{DelaunayTriangulation, HasPosition, Point2, Triangulation as _};
    struct Ph(Point2<f64>, f64);
    impl HasPosition for Ph {
        type Scalar = f64;
        fn position(&self) -> Point2<f64> {
            self.0
        }
    }
    let pts = random_sites(150, 64, 48, 11);
    let mut rng = Rng(17);
    let hs: Vec<f64> = (0..pts.len())
        .map(|_| rng.below(3000) as f64 * 0.1)
        .collect();
    let mut ours = Surface::new();
    let mut theirs: DelaunayTriangulation<Ph> = DelaunayTriangulation::new();
    for (p, h) in pts.iter().zip(&hs) {
        ours.insert(*p, *h).unwrap();
        theirs
            .insert(Ph(Point2::new(p[0] as f64, p[1] as f64), *h))
            .unwrap();
    }
    let nn = theirs.natural_neighbor();
    let mut sc = Scratch::default();
    let mut hint = 0;
    let mut worst: f64 = 0.0;
    for y in 0..=48 {
        for x in 0..=64 {
            let v = ours.eval([x, y], &mut hint, &mut sc).unwrap();
            if let Some(r) = nn.interpolate(|v| v.data().1, Point2::new(x as f64, y as f64)) {
                worst = worst.max((v - r).abs());
            }
        }
    }
    assert!(worst < 1e-6, "largest difference from spade: {worst}");
}

#[test]
fn window_evaluation_matches_pointwise_bit_for_bit() {
    let pts = random_sites(120, 45, 33, 23);
    let mut rng = Rng(8);
    let s = surface(&pts, |_| rng.below(900) as f64 * 1.3);
    let full = s.eval_window(0, 0, 46, 34, |_, _| true).unwrap();
    let mut sc = Scratch::default();
    let mut hint = 0;
    for y in 0..34 {
        for x in 0..46 {
            let v = s.eval([x, y], &mut hint, &mut sc).unwrap();
            assert_eq!(
                v.to_bits(),
                full[(y * 46 + x) as usize].to_bits(),
                "({x},{y})"
            );
        }
    }
    let win = s
        .eval_window(7, 5, 20, 11, |x, y| (x + y) % 5 != 0)
        .unwrap();
    for y in 0..11 {
        for x in 0..20 {
            let v = win[y * 20 + x];
            let (gx, gy) = (x as i64 + 7, y as i64 + 5);
            if (gx + gy) % 5 != 0 {
                assert_eq!(v.to_bits(), full[(gy * 46 + gx) as usize].to_bits());
            } else {
                assert!(v.is_nan());
            }
        }
    }
    assert!(
        s.eval_window(0, 0, 47, 34, |_, _| true).is_none(),
        "outside the hull"
    );
}

/// Every sample of `[0, w] × [0, h]` by the fast evaluator (in scanline order, reusing
/// cavities, and in a scrambled order) against the reference, bit for bit.
fn check_fast_matches_reference(s: &Surface, w: i64, h: i64, seed: u64) {
    let mut fast = Scratch::default();
    let mut refs = Scratch::default();
    let mut pts: Vec<[i64; 2]> = (0..=h).flat_map(|y| (0..=w).map(move |x| [x, y])).collect();
    for pass in 0..2 {
        if pass == 1 {
            let mut rng = Rng(seed);
            for i in (1..pts.len()).rev() {
                pts.swap(i, rng.below(i as u64 + 1) as usize);
            }
        }
        for &p in &pts {
            let Location::Triangle(t) = s.tri.locate(p, None) else {
                continue;
            };
            let a = s.eval_in(p, t, &mut fast);
            let b = s.eval_in_reference(p, t, &mut refs);
            assert_eq!(a.to_bits(), b.to_bits(), "{p:?}: {a} vs {b}");
        }
    }
    // The grid evaluators (row order, cavities reused and flooded from the last one):
    // whole grid, windows and lattices of several steps, each point against the
    // reference (or the site's height, or the hull edge's interpolant).
    let reference = |p: [i64; 2], refs: &mut Scratch| match s.tri.locate(p, None) {
        Location::Triangle(t) => Some(s.eval_in_reference(p, t, refs)),
        Location::Vertex(v) => Some(s.heights[v as usize]),
        Location::Outside => None,
    };
    for (x0, y0, step) in [(0, 0, 1), (3, 2, 1), (0, 0, 2), (1, 1, 3)] {
        let (lw, lh) = (
            ((w - x0) / step + 1) as usize,
            ((h - y0) / step + 1) as usize,
        );
        let out = s.eval_lattice(x0, y0, lw, lh, step, &|x, y| (x * 7 + y) % 11 != 0);
        for j in 0..lh {
            for i in 0..lw {
                let p = [x0 + i as i64 * step, y0 + j as i64 * step];
                let v = out[j * lw + i];
                if (p[0] * 7 + p[1]) % 11 == 0 {
                    assert!(v.is_nan());
                    continue;
                }
                let r = reference(p, &mut refs).unwrap_or(f64::NAN);
                assert_eq!(v.to_bits(), r.to_bits(), "{p:?} step {step}: {v} vs {r}");
            }
        }
    }
}

#[test]
fn fast_evaluation_matches_the_reference_bit_for_bit() {
    for seed in 1..8 {
        let pts = random_sites(40 + 30 * seed as usize, 60, 45, seed);
        let mut rng = Rng(seed + 100);
        let s = surface(&pts, |_| rng.below(5000) as f64 * 0.37);
        check_fast_matches_reference(&s, 60, 45, seed);
    }
    // Co-circular sites on a lattice (the degenerate case of gridded data), and long thin
    // triangles (a few sites far apart, as over flat regions).
    let lattice: Vec<[i64; 2]> = (0..=8)
        .flat_map(|y| (0..=8).map(move |x| [x * 6, y * 5]))
        .collect();
    let s = surface(&lattice, |p| (p[0] * 7 + p[1] * p[1]) as f64);
    check_fast_matches_reference(&s, 48, 40, 9);
    let thin = [
        [0, 0],
        [300, 0],
        [300, 7],
        [0, 7],
        [150, 3],
        [40, 1],
        [260, 6],
    ];
    let s = surface(&thin, |p| (p[0] + 11 * p[1]) as f64 * 0.5);
    check_fast_matches_reference(&s, 300, 7, 10);
}

#[test]
fn collinear_sites_interpolate_linearly() {
    let s = surface(&[[0, 0], [10, 0], [4, 0]], |p| p[0] as f64 * 2.0);
    let mut sc = Scratch::default();
    let mut hint = 0;
    assert_eq!(s.eval([7, 0], &mut hint, &mut sc), Some(14.0));
    assert_eq!(s.eval([7, 1], &mut hint, &mut sc), None);
    assert_eq!(s.eval([11, 0], &mut hint, &mut sc), None);
}
