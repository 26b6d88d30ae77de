//! Binary STL: an 80-byte header, the triangle count, then per triangle its unit normal
//! (computed in f64 from the f64 positions) and three corners, all f32.
//!
//! - STL holds f32 only. Positions are written as they are, with nothing subtracted (STL has
//!   no offset a reader would add back): georeferenced coordinates lose precision there (at
//!   a UTM northing of ~4 000 km an f32 steps by 0.25–0.5 m). Use local coordinates, or OBJ,
//!   PLY or GLB, for georeferenced meshes.
//! - Corners are in the mesh's counter-clockwise order (seen from +z), so the normal follows
//!   the right-hand rule as STL requires; a triangle of no area gets the normal (0, 0, 0).
//! - The header is `vtz mesh ...` padded with zeros: it does not start with `solid`, which
//!   some readers would take for ASCII STL. Each triangle's attribute count is 0.
//! - Normals and texture coordinates of the mesh are not written (STL has no place for them).

use crate::error::{Error, Result};
use crate::mesh::Mesh;

/// The 80-byte header's text (zero-padded).
const HEADER: &[u8] = b"vtz mesh: binary STL, f32, x east, y north, z up";

pub(super) fn encode(mesh: &Mesh) -> Result<Vec<u8>> {
    let count = u32::try_from(mesh.triangles.len())
        .map_err(|_| Error::limit("STL holds at most 2^32 - 1 triangles"))?;
    let mut out = Vec::with_capacity(84 + 50 * mesh.triangles.len());
    out.extend_from_slice(HEADER);
    out.resize(80, 0);
    out.extend_from_slice(&count.to_le_bytes());
    for &t in &mesh.triangles {
        for c in super::facet_normal(mesh, t) {
            out.extend_from_slice(&(c as f32).to_le_bytes());
        }
        for i in t {
            for c in mesh.positions[i as usize] {
                let f = c as f32;
                if !f.is_finite() {
                    return Err(Error::limit(format!(
                        "coordinate {c} does not fit in STL's 32-bit floats"
                    )));
                }
                out.extend_from_slice(&f.to_le_bytes());
            }
        }
        out.extend_from_slice(&0u16.to_le_bytes());
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::super::{MeshFormat, encode, testmesh};
    use crate::mesh::Mesh;

    #[test]
    fn stl_io_reads_back_triangles_in_f32_with_upward_normals() {
        for case in testmesh::variety() {
            let (name, m) = (case.name, &case.mesh);
            let bytes = encode(m, MeshFormat::Stl).unwrap();
            assert_eq!(bytes.len(), 84 + 50 * m.triangles.len(), "{name}");
            assert!(!bytes.starts_with(b"solid"), "{name}");
            let mut cursor = std::io::Cursor::new(&bytes);
            let tris: Vec<stl_io::Triangle> = stl_io::create_stl_reader(&mut cursor)
                .unwrap()
                .collect::<std::io::Result<_>>()
                .unwrap();
            assert_eq!(tris.len(), m.triangles.len(), "{name}");
            // Every corner is the f32 of its vertex, in the mesh's order; the stored normal
            // is the unit normal of the f64 triangle.
            let mut back = vec![[f64::NAN; 3]; m.positions.len()];
            for (t, r) in m.triangles.iter().zip(&tris) {
                for (&i, v) in t.iter().zip(r.vertices.iter()) {
                    let want = m.positions[i as usize].map(|c| c as f32);
                    assert_eq!(v.0, want, "{name}: corners in the mesh's order, as f32");
                    back[i as usize] = v.0.map(f64::from);
                }
                let want = super::super::facet_normal(m, *t).map(|c| c as f32);
                assert_eq!(r.normal.0, want, "{name}");
                let l: f32 = r.normal.0.iter().map(|c| c * c).sum();
                assert!((l - 1.0).abs() < 1e-6, "{name}: unit normal");
            }
            // The corners read back wind so that the surface faces up and the walls out,
            // and each stored normal agrees with its corners' winding.
            let idx: Vec<[usize; 3]> = m.triangles.iter().map(|t| t.map(|i| i as usize)).collect();
            testmesh::assert_faces_out(&case, &back, &idx);
            for (t, r) in idx.iter().zip(&tris) {
                let n = testmesh::normal_of(&back, *t);
                let s = r.normal.0.map(f64::from);
                let dot = n[0] * s[0] + n[1] * s[1] + n[2] * s[2];
                assert!(
                    dot > 0.99,
                    "{name}: stored normal {s:?} against winding {n:?}"
                );
            }
        }
    }

    #[test]
    fn a_triangle_of_no_area_gets_a_zero_normal() {
        let m = Mesh {
            positions: vec![[0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [2.0, 2.0, 2.0]],
            triangles: vec![[0, 1, 2]],
            ..Default::default()
        };
        let bytes = encode(&m, MeshFormat::Stl).unwrap();
        assert_eq!(&bytes[84..96], &[0u8; 12]);
    }
}
