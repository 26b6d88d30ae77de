//! `vtz lsystem` and `vtz::lsystem`: the fractal-plant paper's Table I, the closed hull
//! cover, unknown symbols, and the OBJ read back by an independent parser.

use crate::common;

use std::path::Path;
use vtz::lsystem::{Cover, Frame, LSystem, counts};

fn bench(name: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("benches/lsystem")
        .join(name)
        .display()
        .to_string()
}

fn load(name: &str) -> LSystem {
    LSystem::from_toml(&std::fs::read_to_string(bench(name)).unwrap()).unwrap()
}

/// Table I's faces and vertices, and its edges (always one less than the triangulation's:
/// the paper's E = V + F − 2 on an open sheet, whose real count is V + F − 1).
const TABLE: [(&str, usize, usize, usize); 9] = [
    ("fig03_example1.toml", 110, 64, 172),
    ("fig05_example3.toml", 244, 125, 367),
    ("fig06_example4.toml", 98, 64, 160),
    ("fig07_example5.toml", 110, 64, 172),
    ("fig08_example6.toml", 102, 64, 164),
    ("fig11_example9.toml", 106, 64, 168),
    ("fig12_example10.toml", 102, 64, 164),
    ("fig13_example11.toml", 36, 25, 59),
    ("fig15_example13.toml", 98, 64, 160),
];

#[test]
fn table_one_reproduced_by_the_height_field_cover() {
    for (file, f, v, e) in TABLE {
        let plant = load(file).grow().unwrap();
        assert_eq!(plant.tips.len(), v, "{file}: tips");
        let c = counts(&Cover::HeightField.mesh(&plant.tips).unwrap());
        assert_eq!((c.faces, c.vertices), (f, v), "{file}");
        assert_eq!(c.edges, e + 1, "{file}: the paper's E is one less");
        assert_eq!(c.euler(), 1, "{file}: an open sheet");
    }
    // Figure 4: the faces match; four tips stand above others, so 121 vertices, not 125.
    let plant = load("fig04_example2.toml").grow().unwrap();
    assert_eq!(plant.tips.len(), 125);
    let c = counts(&Cover::HeightField.mesh(&plant.tips).unwrap());
    assert_eq!((c.faces, c.vertices), (212, 121));
}

#[test]
fn the_local_frame_merges_rolled_branches() {
    // In the turtle's own frame, / and \ roll about the heading, so [/F] and [\F] end on
    // the same point: fewer distinct tips than the paper's 64.
    let mut ls = load("fig15_example13.toml");
    assert_eq!(ls.frame, Frame::Fixed);
    ls.frame = Frame::Local;
    let plant = ls.grow().unwrap();
    let deepest = plant.segments.iter().map(|s| s.2).max().unwrap();
    assert_eq!(plant.segments.iter().filter(|s| s.2 == deepest).count(), 64);
    assert!(plant.tips.len() < 64, "{}", plant.tips.len());
}

#[test]
fn hull_cover_is_closed() {
    for (file, ..) in TABLE {
        let plant = load(file).grow().unwrap();
        let mesh = Cover::Hull.mesh(&plant.tips).unwrap();
        let c = counts(&mesh);
        assert_eq!(c.euler(), 2, "{file}: {c:?}");
        assert_eq!(2 * c.edges, 3 * c.faces, "{file}: every edge on two faces");
        // Every tip is inside or on the hull: no face sees it from outside.
        for p in &plant.tips {
            for t in &mesh.triangles {
                let [a, b, d] = t.map(|i| mesh.positions[i as usize]);
                let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
                let w = [d[0] - a[0], d[1] - a[1], d[2] - a[2]];
                let n = [
                    u[1] * w[2] - u[2] * w[1],
                    u[2] * w[0] - u[0] * w[2],
                    u[0] * w[1] - u[1] * w[0],
                ];
                let s: f64 = (0..3).map(|i| n[i] * (p[i] - a[i])).sum();
                assert!(s <= 1e-9, "{file}: {p:?} outside a face ({s})");
            }
        }
    }
}

#[test]
fn cli_unknown_symbol_is_a_usage_error() {
    let dir = tempfile::tempdir().unwrap();
    let rules = dir.path().join("bad.toml");
    std::fs::write(
        &rules,
        "axiom = \"F\"\niterations = 2\nalpha = 30.0\n[rules]\nF = \"F[+F]Q\"\n",
    )
    .unwrap();
    let out = dir.path().join("p.xyz");
    let o = common::vtz([
        "lsystem",
        rules.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2), "{}", common::stderr(&o));
    assert!(common::stderr(&o).contains("'Q'"), "{}", common::stderr(&o));
    assert!(!out.exists());
}

#[test]
fn cli_points_and_obj_read_back() {
    let dir = tempfile::tempdir().unwrap();
    let rules = bench("fig13_example11.toml");
    let xyz = dir.path().join("tips.xyz");
    let o = common::vtz(["lsystem", &rules, "-o", xyz.to_str().unwrap(), "--json"]);
    common::ok(&o);
    assert_eq!(common::json(&o)["tips"], 25);
    let text = std::fs::read_to_string(&xyz).unwrap();
    let pts: Vec<Vec<f64>> = text
        .lines()
        .map(|l| l.split(' ').map(|v| v.parse().unwrap()).collect())
        .collect();
    assert_eq!(pts.len(), 25);
    assert!(pts.iter().all(|p| p.len() == 3));
    // The same points as the library's.
    let plant = load("fig13_example11.toml").grow().unwrap();
    for (a, b) in pts.iter().zip(&plant.tips) {
        assert_eq!(a.as_slice(), b.as_slice());
    }

    for (cover, faces, euler) in [("heightfield", 36, 1), ("hull", 22, 2)] {
        let obj = dir.path().join(format!("{cover}.obj"));
        let args = [
            "lsystem",
            &rules,
            "-o",
            obj.to_str().unwrap(),
            "--cover",
            cover,
            "--json",
        ];
        let o = common::vtz(args);
        common::ok(&o);
        assert_eq!(common::json(&o)["faces"], faces);
        let (models, _) = tobj::load_obj(&obj, &tobj::LoadOptions::default()).unwrap();
        let m = &models[0].mesh;
        assert_eq!(m.indices.len(), 3 * faces);
        let mut edges = std::collections::HashSet::new();
        for t in m.indices.chunks(3) {
            for i in 0..3 {
                let (a, b) = (t[i], t[(i + 1) % 3]);
                edges.insert((a.min(b), a.max(b)));
            }
        }
        let v = m.positions.len() / 3;
        assert_eq!(
            v as i64 - edges.len() as i64 + faces as i64,
            euler,
            "{cover}"
        );
        // Every vertex is a tip.
        for p in m.positions.chunks(3) {
            assert!(
                plant.tips.iter().any(|t| (0..3).all(|i| t[i] == p[i])),
                "{p:?}"
            );
        }
        // No overwrite without --force; with it, the same bytes.
        let before = std::fs::read(&obj).unwrap();
        let o = common::vtz(args);
        assert_eq!(o.status.code(), Some(2));
        let mut forced = args.to_vec();
        forced.push("--force");
        common::ok(&common::vtz(forced));
        assert_eq!(std::fs::read(&obj).unwrap(), before);
    }
}

#[test]
fn bad_outputs_and_limits() {
    let dir = tempfile::tempdir().unwrap();
    let rules = bench("fig13_example11.toml");
    let png = dir.path().join("x.png");
    let o = common::vtz(["lsystem", &rules, "-o", png.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2));
    // A word past the module limit is a limit, not an allocation.
    let mut ls = load("fig13_example11.toml");
    ls.iterations = 40;
    assert!(matches!(ls.grow(), Err(vtz::Error::LimitExceeded { .. })));
}
