//! Triangle meshes of a height field for 3D tools and terrain tiles: the Delaunay
//! triangulation of a set of sites with their heights, in local or georeferenced
//! coordinates, with normals, texture coordinates and skirts on request; `export` writes
//! them as OBJ, PLY, STL and binary glTF; `terrain` and `qmesh` make Cesium
//! quantized-mesh tiles.

pub mod export;
pub mod qmesh;
pub mod quadtree;
pub mod terrain;

use crate::error::{Error, Result};
use crate::geometry::triangulation::{MAX_COORD, Triangulation};
use crate::model::Georef;

/// A triangle mesh: positions, counter-clockwise triangles seen from above (+z), and
/// optional per-vertex attributes.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    /// Vertex positions: x east, y north, z up.
    pub positions: Vec<[f64; 3]>,
    /// Triangles as vertex indices, counter-clockwise seen from +z.
    pub triangles: Vec<[u32; 3]>,
    /// Unit vertex normals (area-weighted means of the faces'), when asked for.
    pub normals: Option<Vec<[f32; 3]>>,
    /// Texture coordinates in [0, 1]: u east, v north (0 at the south edge), when asked for.
    pub uvs: Option<Vec<[f32; 2]>>,
    /// How its triangles fit the samples it was made from, when they were at hand.
    pub fit: Option<Fit>,
}

/// How a mesh is placed and what it carries.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub struct MeshOptions {
    /// Heights are multiplied by this (vertical exaggeration).
    pub z_scale: f64,
    /// Georeferenced coordinates (the raster's CRS units, sample centres) instead of local
    /// ones: the south-west sample at the origin, one sample apart = the ground distance in
    /// the height's units when the raster is georeferenced (a geographic CRS's degrees
    /// converted to metres at the raster's middle latitude; a projected CRS's units taken as
    /// the heights'), so the mesh has its true proportions; one unit per sample otherwise.
    pub georeferenced: bool,
    /// Compute vertex normals.
    pub normals: bool,
    /// Compute texture coordinates.
    pub uvs: bool,
    /// Hang a skirt of this depth (in height units, before `z_scale`) below every boundary
    /// edge, so neighbouring tiles show no cracks.
    pub skirt: Option<f64>,
}

impl Default for MeshOptions {
    fn default() -> Self {
        MeshOptions {
            z_scale: 1.0,
            georeferenced: false,
            normals: false,
            uvs: false,
            skirt: None,
        }
    }
}

/// A mesh vertex before placement: a sample position and its height.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Vertex {
    /// Column of the sample (0 = west).
    pub col: usize,
    /// Row of the sample (0 = north).
    pub row: usize,
    /// Height in data units.
    pub height: f64,
}

/// The Delaunay mesh of `vertices` over a `width × height` raster (positions must be
/// distinct and inside it), placed as `opts` says (`georef` for georeferenced coordinates).
pub fn triangulate(
    vertices: &[Vertex],
    (width, height): (usize, usize),
    georef: Option<&Georef>,
    opts: &MeshOptions,
) -> Result<Mesh> {
    if width as i64 > MAX_COORD || height as i64 > MAX_COORD {
        return Err(Error::limit("raster too large to mesh"));
    }
    if !(opts.z_scale.is_finite() && opts.z_scale != 0.0) {
        return Err(Error::invalid(format!(
            "vertical exaggeration {} must be a finite non-zero number",
            opts.z_scale
        )));
    }
    if opts.skirt.is_some_and(|d| !(d.is_finite() && d >= 0.0)) {
        return Err(Error::invalid("skirt depth must be a finite number ≥ 0"));
    }
    if opts.georeferenced && georef.is_none() {
        return Err(Error::invalid(
            "georeferenced coordinates need a georeferenced raster",
        ));
    }
    let mut seen = std::collections::HashSet::with_capacity(vertices.len());
    for v in vertices {
        if v.col >= width || v.row >= height {
            return Err(Error::invalid(format!(
                "vertex ({}, {}) is outside the {width}x{height} raster",
                v.col, v.row
            )));
        }
        if !seen.insert((v.col, v.row)) {
            return Err(Error::invalid(format!(
                "two vertices at ({}, {})",
                v.col, v.row
            )));
        }
    }
    let cells: Vec<(usize, usize)> = vertices.iter().map(|v| (v.col, v.row)).collect();
    let (tri, order) = delaunay(&cells)?;
    let spacing = ground_spacing(georef, height);
    // The triangulation's vertex ids follow insertion order: `order` maps them back.
    let place = |col: f64, row: f64, z: f64| -> [f64; 3] {
        match (opts.georeferenced, georef) {
            (true, Some(g)) => {
                let [x, y] = g.sample_centre(col, row);
                [x, y, z * opts.z_scale]
            }
            _ => [
                col * spacing[0],
                ((height - 1) as f64 - row) * spacing[1],
                z * opts.z_scale,
            ],
        }
    };
    let mut mesh = Mesh {
        positions: vertices
            .iter()
            .map(|v| place(v.col as f64, v.row as f64, v.height))
            .collect(),
        ..Default::default()
    };
    for t in tri.real_triangles() {
        let v = tri.tri(t).v.map(|k| order[k as usize] as u32);
        // Counter-clockwise in (col, row) with rows going south is clockwise seen from
        // above with y north: reverse.
        mesh.triangles.push([v[0], v[2], v[1]]);
    }
    mesh.triangles.sort_unstable();
    if let Some(depth) = opts.skirt {
        add_skirt(&mut mesh, depth * opts.z_scale.abs());
    }
    if opts.uvs {
        mesh.uvs = Some(
            vertices
                .iter()
                .map(|v| uv(v.col, v.row, width, height))
                .chain(skirt_uvs(&mesh, vertices, width, height))
                .collect(),
        );
    }
    if opts.normals {
        mesh.normals = Some(normals(&mesh));
    }
    Ok(mesh)
}

/// Add vertices until no triangle edge is longer than `max_edge` samples: the sample nearest
/// the middle of the longest too-long edge, with its height from `height_at` (a sample
/// `height_at` gives no height for, nodata, is skipped), until none is left. Martini's and
/// Delatin's users ask for this bound on triangle size (long thin triangles across flat
/// land shade badly and cannot be draped).
pub fn refine_max_edge(
    vertices: &mut Vec<Vertex>,
    (width, height): (usize, usize),
    height_at: &dyn Fn(usize, usize) -> Option<f64>,
    max_edge: f64,
) -> Result<()> {
    if !(max_edge.is_finite() && max_edge >= 2.0) {
        return Err(Error::invalid(format!(
            "a maximum edge of {max_edge} samples is not a number ≥ 2"
        )));
    }
    let cells: Vec<(usize, usize)> = vertices.iter().map(|v| (v.col, v.row)).collect();
    let (mut tri, _) = delaunay(&cells)?;
    let mut taken: std::collections::HashSet<(usize, usize)> = cells.iter().copied().collect();
    let too_long = |a: [i64; 2], b: [i64; 2]| {
        let (dx, dy) = ((a[0] - b[0]) as f64, (a[1] - b[1]) as f64);
        dx * dx + dy * dy > max_edge * max_edge
    };
    // Sweep until a pass inserts nothing; each pass splits every too-long edge once.
    loop {
        let mut wanted: std::collections::BTreeSet<(usize, usize)> = Default::default();
        for t in tri.real_triangles() {
            let v = tri.tri(t).v;
            for k in 0..3 {
                let (a, b) = (tri.point(v[k]), tri.point(v[(k + 1) % 3]));
                if too_long(a, b) {
                    let m = (((a[0] + b[0]) / 2) as usize, ((a[1] + b[1]) / 2) as usize);
                    if m.0 < width && m.1 < height && !taken.contains(&m) {
                        wanted.insert(m);
                    }
                }
            }
        }
        let mut added = 0;
        for (c, r) in wanted {
            taken.insert((c, r));
            let Some(h) = height_at(c, r) else { continue };
            tri.insert_near([c as i64, r as i64], None)?;
            vertices.push(Vertex {
                col: c,
                row: r,
                height: h,
            });
            added += 1;
        }
        if added == 0 {
            return Ok(());
        }
    }
}

/// Ground distance between neighbouring samples (east, north) for local coordinates: the
/// pixel size in the CRS's units, degrees of a geographic CRS (EPSG 4326, 4269, 4258, 4283,
/// 4617 or a WKT starting GEOGCS) converted to metres at the raster's middle latitude; 1 × 1
/// without georeferencing.
fn ground_spacing(georef: Option<&Georef>, height: usize) -> [f64; 2] {
    let Some(g) = georef else {
        return [1.0, 1.0];
    };
    let (sx, sy) = (g.pixel_size[0].abs(), g.pixel_size[1].abs());
    if !(sx > 0.0 && sy > 0.0 && sx.is_finite() && sy.is_finite()) {
        return [1.0, 1.0];
    }
    let geographic = matches!(g.epsg, Some(4326 | 4269 | 4258 | 4283 | 4617))
        || g.wkt
            .as_deref()
            .is_some_and(|w| w.trim_start().starts_with("GEOGCS"));
    if geographic {
        let lat = (g.origin[1] - g.pixel_size[1] * height as f64 / 2.0).clamp(-89.0, 89.0);
        // WGS84 metres per degree of longitude and of latitude at `lat`.
        let r = lat.to_radians();
        let east = 111_412.84 * r.cos() - 93.5 * (3.0 * r).cos();
        let north = 111_132.92 - 559.82 * (2.0 * r).cos() + 1.175 * (4.0 * r).cos();
        [sx * east, sy * north]
    } else {
        [sx, sy]
    }
}

/// How well a mesh's triangles (linear between its vertices) fit the raster's samples.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Fit {
    /// Valid samples inside the mesh.
    pub samples: usize,
    /// Largest |mesh − sample|.
    pub max_error: f64,
    /// Root mean square error.
    pub rmse: f64,
    /// Vertices added to meet the bound (`vtz mesh --max-error`).
    pub added: usize,
}

/// Per triangle of `vertices`' Delaunay triangulation, every valid sample inside it (a
/// sample on a shared edge once): `f(triangle, col, row, |linear − sample|)`.
fn each_error(
    vertices: &[Vertex],
    (width, height): (usize, usize),
    at: &dyn Fn(usize, usize) -> Option<f64>,
    mut f: impl FnMut(usize, usize, usize, f64),
) -> Result<()> {
    let cells: Vec<(usize, usize)> = vertices.iter().map(|v| (v.col, v.row)).collect();
    let (tri, order) = delaunay(&cells)?;
    let mut seen = vec![false; width * height];
    for (k, t) in tri.real_triangles().enumerate() {
        let ids = tri.tri(t).v.map(|v| order[v as usize]);
        let p = ids.map(|i| [vertices[i].col as f64, vertices[i].row as f64]);
        let h = ids.map(|i| vertices[i].height);
        samples_in_triangle(p, (width, height), |c, r, l| {
            if seen[r * width + c] {
                return;
            }
            seen[r * width + c] = true;
            if let Some(v) = at(c, r) {
                f(k, c, r, (l[0] * h[0] + l[1] * h[1] + l[2] * h[2] - v).abs());
            }
        });
    }
    Ok(())
}

/// The fit of `vertices`' mesh to the samples `at` gives.
pub fn fit(
    vertices: &[Vertex],
    size: (usize, usize),
    at: &dyn Fn(usize, usize) -> Option<f64>,
) -> Result<Fit> {
    let mut out = Fit::default();
    let mut ss = 0.0;
    each_error(vertices, size, at, |_, _, _, e| {
        out.samples += 1;
        out.max_error = out.max_error.max(e);
        ss += e * e;
    })?;
    out.rmse = if out.samples > 0 {
        (ss / out.samples as f64).sqrt()
    } else {
        0.0
    };
    Ok(out)
}

/// Add samples as vertices (each triangle's worst, with its own height) until every valid
/// sample inside the mesh is within `bound` of its triangles: the bound the greedy sites
/// meet for the Sibson surface, made to hold for the mesh itself. Roughly worst first: a
/// pass inserts only the triangles' worst samples above 0.8 of the largest error (measured
/// on scape_crater from the greedy sites: 0.5 costs 2–4 % more vertices, all at once 3–9 %
/// more); a triangle's worst sample is found once and kept while the triangle lives.
pub fn refine_to_bound(
    vertices: &mut Vec<Vertex>,
    (width, height): (usize, usize),
    at: &dyn Fn(usize, usize) -> Option<f64>,
    bound: f64,
) -> Result<Fit> {
    if !(bound.is_finite() && bound >= 0.0) {
        return Err(Error::invalid(format!(
            "mesh bound {bound} is not a number ≥ 0"
        )));
    }
    let mut taken: std::collections::HashSet<(usize, usize)> =
        vertices.iter().map(|v| (v.col, v.row)).collect();
    // A triangle is known by its corners' positions, so its worst sample survives the
    // rebuilds: each pass triangulates in the canonical order `triangulate` uses (Delaunay
    // ties on the integer grid depend on the order), so the mesh checked is the mesh written.
    type Worst = Option<(f64, usize, usize)>;
    type Key = [(usize, usize); 3];
    let mut cache: std::collections::HashMap<Key, Worst> = Default::default();
    let mut added = 0;
    loop {
        let cells: Vec<(usize, usize)> = vertices.iter().map(|v| (v.col, v.row)).collect();
        let (tri, id_of) = delaunay(&cells)?;
        let mut next: std::collections::HashMap<Key, Worst> =
            std::collections::HashMap::with_capacity(cache.len() + 64);
        let mut worst: Vec<(f64, usize, usize)> = Vec::new();
        for t in tri.real_triangles() {
            let ids = tri.tri(t).v.map(|v| id_of[v as usize]);
            let mut key = ids.map(|i| cells[i]);
            key.sort_unstable();
            let w = match cache.get(&key) {
                Some(w) => *w,
                None => {
                    let p = ids.map(|i| [vertices[i].col as f64, vertices[i].row as f64]);
                    let h = ids.map(|i| vertices[i].height);
                    triangle_worst(p, h, (width, height), at, bound)
                }
            };
            next.insert(key, w);
            worst.extend(w);
        }
        cache = next;
        let top = worst.iter().map(|w| w.0).fold(0.0, f64::max);
        let cut = (top * 0.8).max(bound);
        worst.sort_unstable_by_key(|w| (w.1, w.2));
        let mut n = 0;
        for (e, c, r) in worst {
            if e < cut && cut > bound {
                continue;
            }
            if taken.insert((c, r)) {
                if let Some(h) = at(c, r) {
                    vertices.push(Vertex {
                        col: c,
                        row: r,
                        height: h,
                    });
                    n += 1;
                }
            }
        }
        added += n;
        if std::env::var_os("VTZ_DEBUG_MESH").is_some() {
            eprintln!("refine: {} vertices, {} new, top {top}", vertices.len(), n);
        }
        if n == 0 {
            let mut f = fit(vertices, (width, height), at)?;
            f.added = added;
            return Ok(f);
        }
    }
}

/// The Delaunay triangulation of distinct `cells`, inserted in the canonical order of
/// [`quadtree::insertion_order`] (the hull, then along a Hilbert curve: each point location
/// starts next to the last, and Delaunay ties on the integer grid resolve the same way for
/// the same set), and that order: triangulation vertex `k` is `cells[order[k]]`.
pub(crate) fn delaunay(cells: &[(usize, usize)]) -> Result<(Triangulation, Vec<usize>)> {
    let order = quadtree::insertion_order(cells);
    let mut tri = Triangulation::default();
    for &i in &order {
        tri.insert_near([cells[i].0 as i64, cells[i].1 as i64], None)?;
    }
    Ok((tri, order))
}

/// Every sample (col, row) of a `width × height` grid inside the closed triangle `p` (sample
/// coordinates), with its barycentric coordinates; nothing for a triangle of no area.
fn samples_in_triangle(
    p: [[f64; 2]; 3],
    (width, height): (usize, usize),
    mut f: impl FnMut(usize, usize, [f64; 3]),
) {
    let det = (p[1][0] - p[0][0]) * (p[2][1] - p[0][1]) - (p[2][0] - p[0][0]) * (p[1][1] - p[0][1]);
    if det == 0.0 {
        return;
    }
    let c0 = p.iter().map(|q| q[0]).fold(f64::INFINITY, f64::min) as usize;
    let c1 = (p.iter().map(|q| q[0]).fold(0.0, f64::max) as usize).min(width - 1);
    let r0 = p.iter().map(|q| q[1]).fold(f64::INFINITY, f64::min) as usize;
    let r1 = (p.iter().map(|q| q[1]).fold(0.0, f64::max) as usize).min(height - 1);
    for r in r0..=r1 {
        for c in c0..=c1 {
            let (x, y) = (c as f64, r as f64);
            let l1 = ((p[1][0] - x) * (p[2][1] - y) - (p[2][0] - x) * (p[1][1] - y)) / det;
            let l2 = ((p[2][0] - x) * (p[0][1] - y) - (p[0][0] - x) * (p[2][1] - y)) / det;
            let l3 = 1.0 - l1 - l2;
            if l1 >= -1e-12 && l2 >= -1e-12 && l3 >= -1e-12 {
                f(c, r, [l1, l2, l3]);
            }
        }
    }
}

/// A triangle's worst valid sample above `bound` (error, col, row), if any.
fn triangle_worst(
    p: [[f64; 2]; 3],
    h: [f64; 3],
    (width, height): (usize, usize),
    at: &dyn Fn(usize, usize) -> Option<f64>,
    bound: f64,
) -> Option<(f64, usize, usize)> {
    let mut worst = None;
    let mut we = bound;
    samples_in_triangle(p, (width, height), |c, r, l| {
        if let Some(v) = at(c, r) {
            let e = (l[0] * h[0] + l[1] * h[1] + l[2] * h[2] - v).abs();
            if e > we {
                we = e;
                worst = Some((e, c, r));
            }
        }
    });
    worst
}

fn uv(col: usize, row: usize, width: usize, height: usize) -> [f32; 2] {
    let u = col as f64 / (width.max(2) - 1) as f64;
    let v = 1.0 - row as f64 / (height.max(2) - 1) as f64;
    [u as f32, v as f32]
}

/// The texture coordinates of the skirt's vertices: those of the vertex each hangs from.
fn skirt_uvs<'a>(
    mesh: &'a Mesh,
    vertices: &'a [Vertex],
    width: usize,
    height: usize,
) -> impl Iterator<Item = [f32; 2]> + 'a {
    let n = vertices.len();
    (n..mesh.positions.len()).map(move |i| {
        // Skirt vertex i hangs below the surface vertex with the same x, y.
        let p = mesh.positions[i];
        let j = (0..n)
            .find(|&j| mesh.positions[j][0] == p[0] && mesh.positions[j][1] == p[1])
            .unwrap_or(0);
        uv(vertices[j].col, vertices[j].row, width, height)
    })
}

/// Hang a vertical skirt of `depth` below every boundary edge (an edge of one triangle
/// only): one new vertex below each boundary vertex, two triangles per edge, facing out.
fn add_skirt(mesh: &mut Mesh, depth: f64) {
    let mut count: std::collections::HashMap<(u32, u32), u32> = std::collections::HashMap::new();
    for t in &mesh.triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            *count.entry((a.min(b), a.max(b))).or_default() += 1;
        }
    }
    let mut boundary: Vec<(u32, u32)> = Vec::new();
    for t in &mesh.triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            if count[&(a.min(b), a.max(b))] == 1 {
                boundary.push((a, b));
            }
        }
    }
    boundary.sort_unstable();
    let mut below: std::collections::BTreeMap<u32, u32> = std::collections::BTreeMap::new();
    for &(a, b) in &boundary {
        for v in [a, b] {
            below.entry(v).or_insert(0);
        }
    }
    for (v, id) in below.iter_mut() {
        let p = mesh.positions[*v as usize];
        *id = mesh.positions.len() as u32;
        mesh.positions.push([p[0], p[1], p[2] - depth]);
    }
    for (a, b) in boundary {
        // The surface triangle runs a → b counter-clockwise, so outside is to the right:
        // the wall a, a', b' and a, b', b faces out.
        let (a2, b2) = (below[&a], below[&b]);
        mesh.triangles.push([a, a2, b2]);
        mesh.triangles.push([a, b2, b]);
    }
}

/// The normal of triangle `[a, b, c]` (counter-clockwise), its length twice the area.
pub(crate) fn face_normal([a, b, c]: [[f64; 3]; 3]) -> [f64; 3] {
    let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
    let v = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
    [
        u[1] * v[2] - u[2] * v[1],
        u[2] * v[0] - u[0] * v[2],
        u[0] * v[1] - u[1] * v[0],
    ]
}

/// Unit vertex normals: the area-weighted mean of the adjacent faces' normals.
fn normals(mesh: &Mesh) -> Vec<[f32; 3]> {
    let mut acc = vec![[0.0f64; 3]; mesh.positions.len()];
    for t in &mesh.triangles {
        let n = face_normal(t.map(|i| mesh.positions[i as usize]));
        for &i in t {
            for k in 0..3 {
                acc[i as usize][k] += n[k];
            }
        }
    }
    acc.iter()
        .map(|n| {
            let l = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
            if l > 0.0 {
                [(n[0] / l) as f32, (n[1] / l) as f32, (n[2] / l) as f32]
            } else {
                [0.0, 0.0, 1.0]
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(n: usize) -> Vec<Vertex> {
        (0..n * n)
            .map(|i| Vertex {
                col: i % n,
                row: i / n,
                height: (i % n + i / n) as f64,
            })
            .collect()
    }

    #[test]
    fn a_grid_of_sites_makes_counter_clockwise_triangles_covering_the_hull() {
        let m = triangulate(&grid(4), (4, 4), None, &MeshOptions::default()).unwrap();
        assert_eq!(m.positions.len(), 16);
        assert_eq!(m.triangles.len(), 18, "2 (n−1)² triangles");
        let mut area = 0.0;
        for t in &m.triangles {
            let [a, b, c] = t.map(|i| m.positions[i as usize]);
            let cross = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
            assert!(cross > 0.0, "counter-clockwise from above");
            area += cross / 2.0;
        }
        assert_eq!(area, 9.0);
        // Local coordinates: north up, the south-west sample at the origin.
        assert_eq!(m.positions[0], [0.0, 3.0, 0.0]);
    }

    #[test]
    fn skirts_hang_below_every_boundary_edge_and_normals_point_up() {
        let o = MeshOptions {
            skirt: Some(10.0),
            normals: true,
            uvs: true,
            z_scale: 2.0,
            ..Default::default()
        };
        let m = triangulate(&grid(3), (3, 3), None, &o).unwrap();
        // 8 boundary vertices, 8 boundary edges: 8 new vertices, 16 wall triangles.
        assert_eq!(m.positions.len(), 9 + 8);
        assert_eq!(m.triangles.len(), 8 + 16);
        assert!(
            m.positions[9..]
                .iter()
                .all(|p| p[2] < 0.0 || p[2] <= 2.0 * 4.0 - 20.0)
        );
        let n = m.normals.as_ref().unwrap();
        // z = 2 (col + row) rises 2 per sample east and 2 per sample south (y falls):
        // the normal of that plane is (−2, 2, 1) / 3.
        let want = [-2.0f32 / 3.0, 2.0 / 3.0, 1.0 / 3.0];
        assert!(
            (0..3).all(|k| (n[4][k] - want[k]).abs() < 1e-6),
            "{:?}",
            n[4]
        );
        assert_eq!(m.uvs.as_ref().unwrap().len(), m.positions.len());
    }

    #[test]
    fn refinement_leaves_no_edge_longer_than_asked() {
        let mut v = vec![
            Vertex {
                col: 0,
                row: 0,
                height: 0.0,
            },
            Vertex {
                col: 99,
                row: 0,
                height: 0.0,
            },
            Vertex {
                col: 0,
                row: 99,
                height: 0.0,
            },
            Vertex {
                col: 99,
                row: 99,
                height: 0.0,
            },
        ];
        refine_max_edge(&mut v, (100, 100), &|c, r| Some((c + r) as f64), 10.0).unwrap();
        let m = triangulate(&v, (100, 100), None, &MeshOptions::default()).unwrap();
        for t in &m.triangles {
            for k in 0..3 {
                let (a, b) = (
                    m.positions[t[k] as usize],
                    m.positions[t[(k + 1) % 3] as usize],
                );
                assert!((a[0] - b[0]).hypot(a[1] - b[1]) <= 10.0, "{a:?} {b:?}");
            }
        }
        assert!(refine_max_edge(&mut v, (100, 100), &|_, _| Some(0.0), 0.5).is_err());
    }

    #[test]
    fn refinement_to_a_bound_holds_on_the_mesh_written() {
        let (w, h) = (40usize, 30usize);
        let f = |c: usize, r: usize| {
            50.0 * ((c as f64) / 6.0).sin() * ((r as f64) / 4.0).cos() + c as f64
        };
        let at = |c: usize, r: usize| (c != 7 || r != 7).then(|| f(c, r)); // one nodata sample
        let mut v: Vec<Vertex> = [(0, 0), (w - 1, 0), (0, h - 1), (w - 1, h - 1)]
            .iter()
            .map(|&(c, r)| Vertex {
                col: c,
                row: r,
                height: f(c, r),
            })
            .collect();
        for bound in [20.0, 5.0, 0.5] {
            let fit0 = refine_to_bound(&mut v, (w, h), &at, bound).unwrap();
            assert!(fit0.max_error <= bound, "{fit0:?}");
            assert_eq!(fit0.samples, w * h - 1);
            // The mesh `triangulate` builds from these vertices is the one measured.
            let m = triangulate(&v, (w, h), None, &MeshOptions::default()).unwrap();
            let mut worst = 0.0f64;
            for t in &m.triangles {
                let p = t.map(|i| m.positions[i as usize]);
                for r in 0..h {
                    for c in 0..w {
                        let (x, y) = (c as f64, (h - 1 - r) as f64);
                        let d = (p[1][0] - p[0][0]) * (p[2][1] - p[0][1])
                            - (p[2][0] - p[0][0]) * (p[1][1] - p[0][1]);
                        let l1 =
                            ((p[1][0] - x) * (p[2][1] - y) - (p[2][0] - x) * (p[1][1] - y)) / d;
                        let l2 =
                            ((p[2][0] - x) * (p[0][1] - y) - (p[0][0] - x) * (p[2][1] - y)) / d;
                        let l3 = 1.0 - l1 - l2;
                        if l1 >= -1e-12 && l2 >= -1e-12 && l3 >= -1e-12 {
                            if let Some(s) = at(c, r) {
                                worst = worst
                                    .max((l1 * p[0][2] + l2 * p[1][2] + l3 * p[2][2] - s).abs());
                            }
                        }
                    }
                }
            }
            assert!(worst <= bound + 1e-9, "written mesh: {worst} > {bound}");
        }
    }

    #[test]
    fn bad_options_and_vertices_are_refused() {
        let o = MeshOptions {
            z_scale: 0.0,
            ..Default::default()
        };
        assert!(triangulate(&grid(3), (3, 3), None, &o).is_err());
        let mut v = grid(3);
        v[1] = v[0];
        assert!(triangulate(&v, (3, 3), None, &MeshOptions::default()).is_err());
        let g = MeshOptions {
            georeferenced: true,
            ..Default::default()
        };
        assert!(triangulate(&grid(3), (3, 3), None, &g).is_err());
    }
}
