//! Covers of a plant's tips: the height-field triangulation (2D Delaunay of x, y with z as
//! the height, an open sheet: V − E + F = 1) and the 3D convex hull (a closed polyhedron:
//! V − E + F = 2), both as a [`Mesh`], and their face, vertex and edge counts.

use crate::error::{Error, Result};
use crate::mesh::Mesh;
use std::collections::{HashMap, HashSet};

/// Which triangulation covers the tips.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Cover {
    /// 2D Delaunay triangulation of (x, y), z as the height: the paper's Table I.
    #[default]
    HeightField,
    /// The 3D convex hull: a closed cover.
    Hull,
}

impl std::str::FromStr for Cover {
    type Err = Error;
    fn from_str(s: &str) -> Result<Cover> {
        match s {
            "heightfield" => Ok(Cover::HeightField),
            "hull" => Ok(Cover::Hull),
            _ => Err(Error::invalid(format!(
                "unknown cover {s:?} (heightfield or hull)"
            ))),
        }
    }
}

impl Cover {
    /// The cover of `points` as a mesh.
    pub fn mesh(self, points: &[[f64; 3]]) -> Result<Mesh> {
        match self {
            Cover::HeightField => heightfield_mesh(points),
            Cover::Hull => hull_mesh(points),
        }
    }
}

/// A mesh's faces, vertices (those some face uses) and distinct undirected edges.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub struct Counts {
    /// Triangles.
    pub faces: usize,
    /// Vertices used by a triangle.
    pub vertices: usize,
    /// Distinct edges.
    pub edges: usize,
}

impl Counts {
    /// V − E + F.
    pub fn euler(&self) -> i64 {
        self.vertices as i64 - self.edges as i64 + self.faces as i64
    }
}

/// Count a mesh's faces, used vertices and distinct edges.
pub fn counts(mesh: &Mesh) -> Counts {
    let mut edges = HashSet::new();
    let mut used = HashSet::new();
    for t in &mesh.triangles {
        for i in 0..3 {
            let (a, b) = (t[i], t[(i + 1) % 3]);
            edges.insert((a.min(b), a.max(b)));
            used.insert(a);
        }
    }
    Counts {
        faces: mesh.triangles.len(),
        vertices: used.len(),
        edges: edges.len(),
    }
}

/// The Delaunay triangulation of the points' (x, y), each vertex at its height z; points
/// with the same (x, y) up to 1e-9 keep the first. [`Error::Unmet`] when they are collinear.
pub fn heightfield_mesh(points: &[[f64; 3]]) -> Result<Mesh> {
    use spade::{DelaunayTriangulation, Point2, Triangulation};
    let mut dt: DelaunayTriangulation<Point2<f64>> = DelaunayTriangulation::new();
    let mut seen = HashSet::new();
    let mut z = Vec::new();
    for p in points {
        if !seen.insert(super::key([p[0], p[1], 0.0])) {
            continue;
        }
        let h = dt
            .insert(Point2::new(p[0], p[1]))
            .map_err(|e| Error::invalid(format!("point {p:?}: {e:?}")))?;
        if h.index() >= z.len() {
            z.resize(h.index() + 1, 0.0);
            z[h.index()] = p[2];
        }
    }
    let positions: Vec<[f64; 3]> = dt
        .vertices()
        .map(|v| [v.position().x, v.position().y, z[v.fix().index()]])
        .collect();
    let triangles: Vec<[u32; 3]> = dt
        .inner_faces()
        .map(|f| f.vertices().map(|v| v.fix().index() as u32))
        .collect();
    if triangles.is_empty() {
        return Err(Error::unmet(format!(
            "the {} tips are collinear seen from above: no height-field triangle",
            positions.len()
        )));
    }
    Ok(Mesh {
        positions,
        triangles,
        ..Mesh::default()
    })
}

/// The 3D convex hull of the points, triangulated, faces counter-clockwise seen from
/// outside (incremental, with Shewchuk's exact orientation test, so coplanar and repeated
/// points do not break it; points inside or on the hull's faces are left out).
/// [`Error::Unmet`] when the points are coplanar.
pub fn hull_mesh(points: &[[f64; 3]]) -> Result<Mesh> {
    let c = |p: [f64; 3]| robust::Coord3D {
        x: p[0],
        y: p[1],
        z: p[2],
    };
    let orient = |a: usize, b: usize, d: usize, p: usize| {
        robust::orient3d(c(points[a]), c(points[b]), c(points[d]), c(points[p]))
    };
    let flat = || {
        Error::unmet(format!(
            "the {} tips are coplanar: no closed hull",
            points.len()
        ))
    };
    let dist2 = |a: [f64; 3], b: [f64; 3]| (0..3).map(|i| (a[i] - b[i]).powi(2)).sum::<f64>();
    if points.len() < 4 {
        return Err(flat());
    }
    let p0 = 0;
    let p1 = (0..points.len())
        .max_by(|&i, &j| dist2(points[p0], points[i]).total_cmp(&dist2(points[p0], points[j])))
        .expect("points");
    let area = |i: usize| {
        let (a, b, q) = (points[p0], points[p1], points[i]);
        let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
        let v = [q[0] - a[0], q[1] - a[1], q[2] - a[2]];
        let x = [
            u[1] * v[2] - u[2] * v[1],
            u[2] * v[0] - u[0] * v[2],
            u[0] * v[1] - u[1] * v[0],
        ];
        x[0] * x[0] + x[1] * x[1] + x[2] * x[2]
    };
    let p2 = (0..points.len())
        .max_by(|&i, &j| area(i).total_cmp(&area(j)))
        .expect("points");
    if area(p2) == 0.0 {
        return Err(flat());
    }
    let p3 = (0..points.len())
        .find(|&i| orient(p0, p1, p2, i) != 0.0)
        .ok_or_else(flat)?;
    let (p1, p2) = if orient(p0, p1, p2, p3) > 0.0 {
        (p1, p2)
    } else {
        (p2, p1)
    };
    let mut faces: Vec<[usize; 3]> = vec![[p0, p1, p2], [p1, p0, p3], [p2, p1, p3], [p0, p2, p3]];
    for p in 0..points.len() {
        if [p0, p1, p2, p3].contains(&p) {
            continue;
        }
        // Outside a face = above its plane (robust's orient3d is negative there).
        let visible: Vec<bool> = faces
            .iter()
            .map(|f| orient(f[0], f[1], f[2], p) < 0.0)
            .collect();
        if !visible.contains(&true) {
            continue;
        }
        let mut seen_edges = HashSet::new();
        for (f, _) in faces.iter().zip(&visible).filter(|(_, v)| **v) {
            for i in 0..3 {
                seen_edges.insert((f[i], f[(i + 1) % 3]));
            }
        }
        let horizon: Vec<(usize, usize)> = seen_edges
            .iter()
            .filter(|(a, b)| !seen_edges.contains(&(*b, *a)))
            .copied()
            .collect();
        let mut kept: Vec<[usize; 3]> = faces
            .iter()
            .zip(&visible)
            .filter(|(_, v)| !**v)
            .map(|(f, _)| *f)
            .collect();
        let mut horizon = horizon;
        horizon.sort_unstable();
        kept.extend(horizon.into_iter().map(|(a, b)| [a, b, p]));
        faces = kept;
    }
    let mut index: HashMap<usize, u32> = HashMap::new();
    let mut positions = Vec::new();
    let mut triangles = Vec::with_capacity(faces.len());
    for f in &faces {
        triangles.push(f.map(|v| {
            *index.entry(v).or_insert_with(|| {
                positions.push(points[v]);
                (positions.len() - 1) as u32
            })
        }));
    }
    Ok(Mesh {
        positions,
        triangles,
        ..Mesh::default()
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cube_hull_is_closed() {
        let mut pts = Vec::new();
        for i in 0..27 {
            pts.push([(i % 3) as f64, ((i / 3) % 3) as f64, (i / 9) as f64]);
        }
        let m = hull_mesh(&pts).unwrap();
        let c = counts(&m);
        assert_eq!(c.euler(), 2, "{c:?}");
        // Every edge is shared by exactly two faces, in opposite directions.
        let mut directed = HashSet::new();
        for t in &m.triangles {
            for i in 0..3 {
                assert!(directed.insert((t[i], t[(i + 1) % 3])));
            }
        }
        assert!(directed.iter().all(|(a, b)| directed.contains(&(*b, *a))));
        // The centre and the face centres are not hull vertices; the 8 corners are.
        assert!(c.vertices >= 8 && c.vertices <= 26);
        assert!(hull_mesh(&[[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0]]).is_err());
    }

    #[test]
    fn heightfield_is_planar() {
        let pts: Vec<[f64; 3]> = (0..30)
            .map(|i| {
                let t = i as f64 * 0.7;
                [t.cos() * (1.0 + i as f64), t.sin() * (1.0 + i as f64), t]
            })
            .collect();
        let c = counts(&heightfield_mesh(&pts).unwrap());
        assert_eq!(c.euler(), 1, "{c:?}");
        assert_eq!(c.vertices, 30);
    }
}
