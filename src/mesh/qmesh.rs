//! Cesium quantized-mesh-1.0 tiles: the 88-byte header, zig-zag delta-coded u, v and
//! heights in 0..=32767, high-water-mark triangle indices (16- or 32-bit), the four edge
//! index lists, and the oct-encoded vertex normal and water mask extensions.
//! (Hand-written: no maintained Rust crate writes the format; the layout follows
//! Cesium's published quantized-mesh-1.0 specification.)

use crate::error::{Error, Result};

/// WGS84 semi-major axis and squared eccentricity (Cesium's `Ellipsoid.WGS84`).
const WGS84_A: f64 = 6_378_137.0;
const WGS84_B: f64 = 6_356_752.314_245_18;

/// One tile ready to encode: vertices quantized over the tile's rectangle and height range.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct QuantizedTile {
    /// The tile's rectangle in degrees: west, south, east, north.
    pub rect: [f64; 4],
    /// Heights of 0 and 32767 (metres above the ellipsoid).
    pub min_height: f64,
    /// See `min_height`.
    pub max_height: f64,
    /// Per vertex: u (west 0 → east 32767), v (south 0 → north 32767), height code.
    pub vertices: Vec<[u16; 3]>,
    /// Triangles, counter-clockwise seen from above.
    pub triangles: Vec<[u32; 3]>,
    /// Unit normals (east, north, up in the tile's local frame converted to ECEF by the
    /// caller) per vertex, when the normals extension is wanted.
    pub normals: Option<Vec<[f64; 3]>>,
    /// Water mask: `Some(None)` all land, `Some(Some(v))` a 256×256 mask row-major from the
    /// north (255 = water), or a uniform one as a single byte.
    pub water: Option<WaterMask>,
}

/// The water mask extension's payload.
#[derive(Clone, Debug, PartialEq)]
pub enum WaterMask {
    /// The whole tile is land (0) or water (255).
    Uniform(u8),
    /// 256 × 256 bytes, north row first.
    Grid(Vec<u8>),
}

fn ecef(lon: f64, lat: f64, h: f64) -> [f64; 3] {
    let (lo, la) = (lon.to_radians(), lat.to_radians());
    let e2 = 1.0 - (WGS84_B * WGS84_B) / (WGS84_A * WGS84_A);
    let n = WGS84_A / (1.0 - e2 * la.sin() * la.sin()).sqrt();
    [
        (n + h) * la.cos() * lo.cos(),
        (n + h) * la.cos() * lo.sin(),
        (n * (1.0 - e2) + h) * la.sin(),
    ]
}

fn zigzag(v: i32) -> u16 {
    ((v << 1) ^ (v >> 31)) as u16
}

/// Oct-encode a unit vector into two bytes (Cesium's `AttributeCompression.octEncode`).
fn oct(n: [f64; 3]) -> [u8; 2] {
    let l1 = n[0].abs() + n[1].abs() + n[2].abs();
    let (mut x, mut y) = (n[0] / l1, n[1] / l1);
    if n[2] < 0.0 {
        let (ox, oy) = (x, y);
        x = (1.0 - oy.abs()) * if ox >= 0.0 { 1.0 } else { -1.0 };
        y = (1.0 - ox.abs()) * if oy >= 0.0 { 1.0 } else { -1.0 };
    }
    let q = |v: f64| ((v.clamp(-1.0, 1.0) * 0.5 + 0.5) * 255.0).round() as u8;
    [q(x), q(y)]
}

impl QuantizedTile {
    /// The `.terrain` bytes (not gzipped).
    pub fn encode(&self) -> Result<Vec<u8>> {
        let n = self.vertices.len();
        if n == 0 || self.triangles.is_empty() {
            return Err(Error::invalid(
                "a terrain tile needs vertices and triangles",
            ));
        }
        if n > u32::MAX as usize {
            return Err(Error::limit("too many vertices for a terrain tile"));
        }
        if self.triangles.iter().flatten().any(|&i| i as usize >= n) {
            return Err(Error::invalid(
                "a triangle names a vertex that does not exist",
            ));
        }
        if self.vertices.iter().flatten().any(|&c| c > 32767) {
            return Err(Error::invalid("quantized coordinates are 0..=32767"));
        }
        // Vertices renumbered by first use in the triangle list, as high-water-mark
        // coding needs (unused vertices go last).
        let mut order = vec![u32::MAX; n];
        let mut by_new: Vec<u32> = Vec::with_capacity(n);
        for &i in self.triangles.iter().flatten() {
            if order[i as usize] == u32::MAX {
                order[i as usize] = by_new.len() as u32;
                by_new.push(i);
            }
        }
        for i in 0..n as u32 {
            if order[i as usize] == u32::MAX {
                order[i as usize] = by_new.len() as u32;
                by_new.push(i);
            }
        }
        let verts: Vec<[u16; 3]> = by_new.iter().map(|&i| self.vertices[i as usize]).collect();
        let [w, s, e, nth] = self.rect;
        let lon = |u: u16| w + (e - w) * u as f64 / 32767.0;
        let lat = |v: u16| s + (nth - s) * v as f64 / 32767.0;
        let hgt =
            |c: u16| self.min_height + (self.max_height - self.min_height) * c as f64 / 32767.0;
        let pts: Vec<[f64; 3]> = verts
            .iter()
            .map(|v| ecef(lon(v[0]), lat(v[1]), hgt(v[2])))
            .collect();
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for p in &pts {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        let centre = [
            (lo[0] + hi[0]) / 2.0,
            (lo[1] + hi[1]) / 2.0,
            (lo[2] + hi[2]) / 2.0,
        ];
        let radius = pts
            .iter()
            .map(|p| {
                ((p[0] - centre[0]).powi(2)
                    + (p[1] - centre[1]).powi(2)
                    + (p[2] - centre[2]).powi(2))
                .sqrt()
            })
            .fold(0.0, f64::max);
        let horizon = horizon_point(&pts, centre);
        let mut out = Vec::with_capacity(88 + n * 6 + self.triangles.len() * 6);
        let f64s = |out: &mut Vec<u8>, v: &[f64]| {
            v.iter()
                .for_each(|x| out.extend_from_slice(&x.to_le_bytes()))
        };
        f64s(&mut out, &centre);
        out.extend_from_slice(&(self.min_height as f32).to_le_bytes());
        out.extend_from_slice(&(self.max_height as f32).to_le_bytes());
        f64s(&mut out, &centre);
        f64s(&mut out, &[radius]);
        f64s(&mut out, &horizon);
        out.extend_from_slice(&(n as u32).to_le_bytes());
        for k in 0..3 {
            let mut prev = 0i32;
            for v in &verts {
                out.extend_from_slice(&zigzag(v[k] as i32 - prev).to_le_bytes());
                prev = v[k] as i32;
            }
        }
        let wide = n > 65536;
        let align = if wide { 4 } else { 2 };
        while out.len() % align != 0 {
            out.push(0);
        }
        let put = |out: &mut Vec<u8>, i: u32| {
            if wide {
                out.extend_from_slice(&i.to_le_bytes());
            } else {
                out.extend_from_slice(&(i as u16).to_le_bytes());
            }
        };
        out.extend_from_slice(&(self.triangles.len() as u32).to_le_bytes());
        let mut highest = 0u32;
        for &i in self.triangles.iter().flatten() {
            let i = order[i as usize];
            let code = highest - i;
            if code == 0 {
                highest += 1;
            }
            put(&mut out, code);
        }
        // Edge vertices (u = 0 west, v = 0 south, u = max east, v = max north).
        for test in [
            (|v: &[u16; 3]| v[0] == 0) as fn(&[u16; 3]) -> bool,
            |v| v[1] == 0,
            |v| v[0] == 32767,
            |v| v[1] == 32767,
        ] {
            let edge: Vec<u32> = (0..n as u32)
                .filter(|&i| test(&verts[i as usize]))
                .collect();
            out.extend_from_slice(&(edge.len() as u32).to_le_bytes());
            for i in edge {
                put(&mut out, i);
            }
        }
        if let Some(normals) = &self.normals {
            if normals.len() != n {
                return Err(Error::invalid("one normal per vertex"));
            }
            out.push(1);
            out.extend_from_slice(&(2 * n as u32).to_le_bytes());
            for &i in &by_new {
                out.extend_from_slice(&oct(normals[i as usize]));
            }
        }
        match &self.water {
            None => {}
            Some(WaterMask::Uniform(b)) => {
                out.push(2);
                out.extend_from_slice(&1u32.to_le_bytes());
                out.push(*b);
            }
            Some(WaterMask::Grid(g)) => {
                if g.len() != 256 * 256 {
                    return Err(Error::invalid("a water mask grid is 256 × 256"));
                }
                out.push(2);
                out.extend_from_slice(&(g.len() as u32).to_le_bytes());
                out.extend_from_slice(g);
            }
        }
        Ok(out)
    }
}

/// Cesium's horizon occlusion point (`EllipsoidalOccluder.computeHorizonCullingPoint`): the
/// point along the direction to `centre`, in the ellipsoid-scaled space, from which every
/// vertex is above the horizon.
fn horizon_point(pts: &[[f64; 3]], centre: [f64; 3]) -> [f64; 3] {
    let scale = [1.0 / WGS84_A, 1.0 / WGS84_A, 1.0 / WGS84_B];
    let d = [
        centre[0] * scale[0],
        centre[1] * scale[1],
        centre[2] * scale[2],
    ];
    let dl = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    let d = [d[0] / dl, d[1] / dl, d[2] / dl];
    let mut mag: f64 = 0.0;
    for p in pts {
        let s = [p[0] * scale[0], p[1] * scale[1], p[2] * scale[2]];
        let m2 = s[0] * s[0] + s[1] * s[1] + s[2] * s[2];
        let m = m2.sqrt();
        let u = [s[0] / m, s[1] / m, s[2] / m];
        let cos_alpha = (u[0] * d[0] + u[1] * d[1] + u[2] * d[2]).clamp(-1.0, 1.0);
        let sin_alpha = (1.0 - cos_alpha * cos_alpha).max(0.0).sqrt();
        let cos_beta = 1.0 / m.max(1.0);
        let sin_beta = (m2.max(1.0) - 1.0).sqrt() * cos_beta;
        let v = 1.0 / (cos_alpha * cos_beta - sin_alpha * sin_beta);
        if v.is_finite() && v > 0.0 {
            mag = mag.max(v);
        }
    }
    let mag = if mag > 0.0 { mag } else { 1.0 };
    // In the ellipsoid-scaled frame, as the format stores it (not multiplied back to metres).
    [d[0] * mag, d[1] * mag, d[2] * mag]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A reader of the format written from the specification, independent of the writer's
    /// code paths: (vertices, triangles, west/south/east/north edge lists).
    type Read = (Vec<[u16; 3]>, Vec<[u32; 3]>, [Vec<u32>; 4]);

    fn read(b: &[u8]) -> Read {
        let u32_at = |o: usize| u32::from_le_bytes(b[o..o + 4].try_into().unwrap());
        let u16_at = |o: usize| u16::from_le_bytes(b[o..o + 2].try_into().unwrap());
        let n = u32_at(88) as usize;
        let mut o = 92;
        let mut cols = [vec![0u16; n], vec![0u16; n], vec![0u16; n]];
        for c in &mut cols {
            let mut acc = 0i32;
            for x in c.iter_mut() {
                let z = u16_at(o) as i32;
                o += 2;
                acc += (z >> 1) ^ -(z & 1);
                *x = acc as u16;
            }
        }
        let wide = n > 65536;
        let sz = if wide { 4 } else { 2 };
        while o % sz != 0 {
            o += 1;
        }
        let get = |o: usize| if wide { u32_at(o) } else { u16_at(o) as u32 };
        let t = u32_at(o) as usize;
        o += 4;
        let mut highest = 0u32;
        let mut idx = Vec::with_capacity(3 * t);
        for _ in 0..3 * t {
            let code = get(o);
            o += sz;
            idx.push(highest - code);
            if code == 0 {
                highest += 1;
            }
        }
        let tris = idx.chunks(3).map(|c| [c[0], c[1], c[2]]).collect();
        let mut edges: [Vec<u32>; 4] = Default::default();
        for e in &mut edges {
            let k = u32_at(o) as usize;
            o += 4;
            for _ in 0..k {
                e.push(get(o));
                o += sz;
            }
        }
        let verts = (0..n)
            .map(|i| [cols[0][i], cols[1][i], cols[2][i]])
            .collect();
        (verts, tris, edges)
    }

    #[test]
    fn a_tile_reads_back_with_its_vertices_triangles_and_edges() {
        let t = QuantizedTile {
            rect: [-160.0, 22.0, -159.5, 22.5],
            min_height: 0.0,
            max_height: 1500.0,
            vertices: vec![
                [0, 0, 0],
                [32767, 0, 100],
                [32767, 32767, 32767],
                [0, 32767, 5],
                [16000, 16000, 20000],
            ],
            triangles: vec![[4, 2, 3], [0, 1, 4], [1, 2, 4], [0, 4, 3]],
            normals: Some(vec![[0.0, 0.0, 1.0]; 5]),
            water: Some(WaterMask::Uniform(0)),
        };
        let b = t.encode().unwrap();
        let (v, tris, edges) = read(&b);
        assert_eq!(v.len(), 5);
        // The same triangles over the same vertices, whatever the renumbering.
        let mut got: Vec<[[u16; 3]; 3]> = tris.iter().map(|t| t.map(|i| v[i as usize])).collect();
        let mut want: Vec<[[u16; 3]; 3]> = t
            .triangles
            .iter()
            .map(|tr| tr.map(|i| t.vertices[i as usize]))
            .collect();
        got.sort();
        want.sort();
        assert_eq!(got, want);
        let count = |e: &Vec<u32>| e.len();
        assert_eq!(
            edges.iter().map(count).collect::<Vec<_>>(),
            vec![2, 2, 2, 2]
        );
        assert!(edges[0].iter().all(|&i| v[i as usize][0] == 0));
        assert!(edges[3].iter().all(|&i| v[i as usize][1] == 32767));
        // Header: the centre lies near Kauai (ECEF x negative, z positive).
        let cx = f64::from_le_bytes(b[0..8].try_into().unwrap());
        let cz = f64::from_le_bytes(b[16..24].try_into().unwrap());
        assert!(cx < 0.0 && cz > 2.0e6, "{cx} {cz}");
    }

    #[test]
    fn the_horizon_point_is_in_the_ellipsoid_scaled_frame() {
        let pts: Vec<[f64; 3]> = [(10.0, 45.0, 0.0), (10.1, 45.0, 3000.0), (10.0, 45.1, 100.0)]
            .iter()
            .map(|&(lo, la, h)| ecef(lo, la, h))
            .collect();
        let c = [
            (pts[0][0] + pts[1][0] + pts[2][0]) / 3.0,
            (pts[0][1] + pts[1][1] + pts[2][1]) / 3.0,
            (pts[0][2] + pts[1][2] + pts[2][2]) / 3.0,
        ];
        let h = horizon_point(&pts, c);
        let m = (h[0] * h[0] + h[1] * h[1] + h[2] * h[2]).sqrt();
        // Just above the unit sphere of the scaled frame (3 km of relief), not in metres.
        assert!(m > 1.0 && m < 1.01, "{m}");
        // The independent check (every vertex above the horizon seen from it) is
        // tests/js/check_terrain.mjs, run by .ci/run.
    }

    #[test]
    fn many_vertices_use_32_bit_indices() {
        let n = 70_000usize;
        let vertices: Vec<[u16; 3]> = (0..n)
            .map(|i| [(i % 300) as u16 * 100, (i / 300) as u16 * 100, 0])
            .collect();
        let triangles: Vec<[u32; 3]> = (0..n as u32 - 2).map(|i| [i, i + 1, i + 2]).collect();
        let t = QuantizedTile {
            rect: [0.0, 0.0, 1.0, 1.0],
            min_height: 0.0,
            max_height: 1.0,
            vertices,
            triangles: triangles.clone(),
            normals: None,
            water: Some(WaterMask::Grid(vec![255; 256 * 256])),
        };
        let b = t.encode().unwrap();
        // The water mask extension ends the tile: id 2, length 65536, the bytes.
        assert_eq!(b[b.len() - 65536 - 5], 2);
        let (v, tris, _) = read(&b);
        assert_eq!((v.len(), tris.len()), (n, triangles.len()));
        assert_eq!(tris[0], [0, 1, 2]);
    }
}
