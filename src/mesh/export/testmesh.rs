//! Test meshes for the writers' round trips: Delaunay meshes of a small synthetic height field.

use crate::mesh::{Mesh, MeshOptions, Vertex, triangulate};

/// The height of the synthetic hill at sample (col, row) of a `w × h` raster: with fractions,
/// so positions are not all integers, and gentle enough that every triangle faces up.
fn hill(col: usize, row: usize, w: usize, h: usize) -> f64 {
    let (x, y) = (col as f64 / w as f64, row as f64 / h as f64);
    1234.5678 + 3.0 * (3.0 * x).sin() * (2.0 * y).cos() + 0.1 * col as f64
}

/// The mesh of every sample of a `w × h` hill, with normals, texture coordinates, a skirt and
/// UTM coordinates on request.
pub fn surface(
    w: usize,
    h: usize,
    normals: bool,
    uvs: bool,
    skirt: Option<f64>,
    georeferenced: bool,
) -> Mesh {
    let vertices: Vec<Vertex> = (0..w * h)
        .map(|i| Vertex {
            col: i % w,
            row: i / w,
            height: hill(i % w, i / w, w, h),
        })
        .collect();
    mesh_of(&vertices, (w, h), normals, uvs, skirt, georeferenced)
}

/// The mesh of `count` distinct pseudo-random samples of a `side × side` hill, with normals,
/// texture coordinates, a skirt and UTM coordinates. (Large meshes are made this way: the
/// triangulation of a full regular grid is much slower, its points being cocircular.)
pub fn scattered(side: usize, count: usize, skirt: Option<f64>) -> Mesh {
    let mut seen = std::collections::HashSet::new();
    let mut vertices = Vec::with_capacity(count);
    let mut rng = crate::testutil::Rng(0x9E37_79B9_7F4A_7C15);
    while vertices.len() < count {
        let x = rng.next();
        let (col, row) = (
            (x % side as u64) as usize,
            ((x >> 32) % side as u64) as usize,
        );
        if seen.insert((col, row)) {
            let height = hill(col, row, side, side);
            vertices.push(Vertex { col, row, height });
        }
    }
    mesh_of(&vertices, (side, side), true, true, skirt, true)
}

fn mesh_of(
    vertices: &[Vertex],
    size: (usize, usize),
    normals: bool,
    uvs: bool,
    skirt: Option<f64>,
    georeferenced: bool,
) -> Mesh {
    let georef = crate::testutil::utm11_georef();
    let opts = MeshOptions {
        z_scale: 1.5,
        georeferenced,
        normals,
        uvs,
        skirt,
    };
    triangulate(vertices, size, Some(&georef), &opts).unwrap()
}

/// The unit normal of triangle `t` of `positions` (f64), for checking winding after a round trip.
pub fn normal_of(positions: &[[f64; 3]], t: [usize; 3]) -> [f64; 3] {
    let n = crate::mesh::face_normal(t.map(|i| positions[i]));
    let l = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    n.map(|c| c / l)
}

/// A test mesh, its name, and how many of its vertices are the surface's (the skirt's come
/// after them).
pub struct Case {
    pub name: &'static str,
    pub mesh: Mesh,
    pub surface: usize,
}

/// Every combination the writers distinguish: attributes or none, a skirt, georeferenced.
pub fn variety() -> Vec<Case> {
    let case = |name, w, h, normals, uvs, skirt, georeferenced| Case {
        name,
        mesh: surface(w, h, normals, uvs, skirt, georeferenced),
        surface: w * h,
    };
    vec![
        case("bare", 5, 4, false, false, None, false),
        case("normals", 5, 4, true, false, None, false),
        case("uvs", 5, 4, false, true, None, false),
        case("all+skirt", 7, 6, true, true, Some(25.0), false),
        case(
            "georeferenced+all+skirt",
            9,
            8,
            true,
            true,
            Some(25.0),
            true,
        ),
    ]
}

/// Winding after a round trip, on the positions and triangles read back (x east, y north,
/// z up): the surface's triangles face up, the skirt's walls are vertical and face out.
pub fn assert_faces_out(case: &Case, positions: &[[f64; 3]], triangles: &[[usize; 3]]) {
    assert_eq!(triangles.len(), case.mesh.triangles.len(), "{}", case.name);
    let n_surface = case.surface as f64;
    let centre =
        [0, 1].map(|k| positions[..case.surface].iter().map(|p| p[k]).sum::<f64>() / n_surface);
    for t in triangles {
        let n = normal_of(positions, *t);
        if t.iter().all(|&i| i < case.surface) {
            assert!(
                n[2] > 0.1,
                "{}: surface triangle {t:?} faces {n:?}",
                case.name
            );
        } else {
            assert!(
                n[2].abs() < 1e-3,
                "{}: wall {t:?} is not vertical: {n:?}",
                case.name
            );
            let mid = [0, 1].map(|k| t.iter().map(|&i| positions[i][k]).sum::<f64>() / 3.0);
            let out = (mid[0] - centre[0]) * n[0] + (mid[1] - centre[1]) * n[1];
            assert!(out > 0.0, "{}: wall {t:?} faces in: {n:?}", case.name);
        }
    }
}
