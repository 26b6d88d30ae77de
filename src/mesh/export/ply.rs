//! Stanford PLY: `binary_little_endian 1.0`, positions as doubles (exact), normals and texture
//! coordinates as floats when the mesh has them.
//!
//! - `element vertex N`: `double x y z`, then `float nx ny nz` with normals, then `float s t`
//!   with texture coordinates (v upwards as in the mesh; `s t` is what Blender, MeshLab and
//!   Open3D read as texture coordinates).
//! - `element face M`: `property list uchar uint vertex_indices`, each face `3 a b c`,
//!   0-based, counter-clockwise seen from +z.
//! - One `comment` line naming vtz and the axes; no other elements.

use crate::error::Result;
use crate::mesh::Mesh;

pub(super) fn encode(mesh: &Mesh) -> Result<Vec<u8>> {
    let (n, m) = (mesh.positions.len(), mesh.triangles.len());
    let mut header = String::from("ply\nformat binary_little_endian 1.0\n");
    header.push_str("comment vtz mesh: x east, y north, z up\n");
    header.push_str(&format!("element vertex {n}\n"));
    header.push_str("property double x\nproperty double y\nproperty double z\n");
    if mesh.normals.is_some() {
        header.push_str("property float nx\nproperty float ny\nproperty float nz\n");
    }
    if mesh.uvs.is_some() {
        header.push_str("property float s\nproperty float t\n");
    }
    header.push_str(&format!("element face {m}\n"));
    header.push_str("property list uchar uint vertex_indices\nend_header\n");

    let vertex_size =
        24 + 12 * usize::from(mesh.normals.is_some()) + 8 * usize::from(mesh.uvs.is_some());
    let mut out = Vec::with_capacity(header.len() + n * vertex_size + m * 13);
    out.extend_from_slice(header.as_bytes());
    for (i, p) in mesh.positions.iter().enumerate() {
        for c in p {
            out.extend_from_slice(&c.to_le_bytes());
        }
        if let Some(normals) = &mesh.normals {
            for c in normals[i] {
                out.extend_from_slice(&c.to_le_bytes());
            }
        }
        if let Some(uvs) = &mesh.uvs {
            for c in uvs[i] {
                out.extend_from_slice(&c.to_le_bytes());
            }
        }
    }
    for t in &mesh.triangles {
        out.push(3);
        for i in t {
            out.extend_from_slice(&i.to_le_bytes());
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::super::{MeshFormat, encode, testmesh};
    use ply_rs::parser::Parser;
    use ply_rs::ply::{DefaultElement, Property};

    #[test]
    fn ply_rs_reads_back_positions_exactly_attributes_faces_and_winding() {
        for case in testmesh::variety() {
            let (name, m) = (case.name, &case.mesh);
            let bytes = encode(m, MeshFormat::Ply).unwrap();
            let ply = Parser::<DefaultElement>::new()
                .read_ply(&mut &bytes[..])
                .unwrap();
            assert_eq!(
                ply.header.encoding,
                ply_rs::ply::Encoding::BinaryLittleEndian,
                "{name}"
            );
            let vertices = &ply.payload["vertex"];
            let faces = &ply.payload["face"];
            assert_eq!(vertices.len(), m.positions.len(), "{name}");
            assert_eq!(faces.len(), m.triangles.len(), "{name}");
            let double = |p: &Property| match p {
                Property::Double(v) => *v,
                other => panic!("{name}: not a double: {other:?}"),
            };
            let float = |p: &Property| match p {
                Property::Float(v) => *v,
                other => panic!("{name}: not a float: {other:?}"),
            };
            let pos: Vec<[f64; 3]> = vertices
                .iter()
                .map(|v| ["x", "y", "z"].map(|k| double(&v[k])))
                .collect();
            assert_eq!(pos, m.positions, "{name}");
            let has = |k: &str| vertices[0].contains_key(k);
            match &m.normals {
                Some(n) => {
                    let back: Vec<[f32; 3]> = vertices
                        .iter()
                        .map(|v| ["nx", "ny", "nz"].map(|k| float(&v[k])))
                        .collect();
                    assert_eq!(&back, n, "{name}");
                }
                None => assert!(!has("nx"), "{name}"),
            }
            match &m.uvs {
                Some(t) => {
                    let back: Vec<[f32; 2]> = vertices
                        .iter()
                        .map(|v| ["s", "t"].map(|k| float(&v[k])))
                        .collect();
                    assert_eq!(&back, t, "{name}");
                }
                None => assert!(!has("s"), "{name}"),
            }
            let tris: Vec<[usize; 3]> = faces
                .iter()
                .map(|f| match &f["vertex_indices"] {
                    Property::ListUInt(l) => {
                        assert_eq!(l.len(), 3, "{name}");
                        [l[0] as usize, l[1] as usize, l[2] as usize]
                    }
                    other => panic!("{name}: not a list of uint: {other:?}"),
                })
                .collect();
            let want: Vec<[usize; 3]> = m.triangles.iter().map(|t| t.map(|i| i as usize)).collect();
            assert_eq!(tris, want, "{name}");
            testmesh::assert_faces_out(&case, &pos, &tris);
        }
    }

    #[test]
    fn the_header_declares_what_follows() {
        let m = testmesh::surface(4, 3, true, true, None, false);
        let bytes = encode(&m, MeshFormat::Ply).unwrap();
        let end = bytes
            .windows(11)
            .position(|w| w == b"end_header\n")
            .unwrap()
            + 11;
        let header = std::str::from_utf8(&bytes[..end]).unwrap();
        assert!(header.starts_with("ply\nformat binary_little_endian 1.0\n"));
        assert!(header.contains("element vertex 12\n"));
        assert!(header.contains("property list uchar uint vertex_indices\n"));
        // 12 vertices of 3 doubles, 3 + 2 floats; faces of 1 + 3 × 4 bytes.
        assert_eq!(bytes.len() - end, 12 * (24 + 20) + m.triangles.len() * 13);
    }
}
