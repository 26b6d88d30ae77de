//! Wavefront OBJ: text, positions in full f64 precision, `vt`/`vn` when the mesh has them.
//!
//! - `v x y z`: Rust's shortest round-trip formatting of each f64 (parsing the text gives the
//!   same f64 back), never exponent notation, so every OBJ reader parses it.
//! - `vt u v` (OBJ's v runs upwards like the mesh's, so it is written as is) and `vn x y z`,
//!   f32 shortest round-trip, one per vertex in the same order as the `v` lines.
//! - Faces `f a b c`, `f a/a b/b c/c` (texture coordinates), `f a//a …` (normals) or
//!   `f a/a/a …` (both): 1-based, counter-clockwise seen from +z, the mesh's order.
//! - No material library, object or group: one anonymous object.

use std::fmt::Write;

use crate::error::Result;
use crate::mesh::Mesh;

pub(super) fn encode(mesh: &Mesh) -> Result<Vec<u8>> {
    // ~30 bytes per vertex line and face line.
    let mut s = String::with_capacity(40 * (mesh.positions.len() + mesh.triangles.len()));
    // Writing to a String cannot fail: the results of `writeln!` are ignored below.
    let _ = writeln!(
        s,
        "# vtz mesh: {} vertices, {} triangles; x east, y north, z up",
        mesh.positions.len(),
        mesh.triangles.len()
    );
    for p in &mesh.positions {
        let _ = writeln!(s, "v {} {} {}", p[0], p[1], p[2]);
    }
    if let Some(uvs) = &mesh.uvs {
        for t in uvs {
            let _ = writeln!(s, "vt {} {}", t[0], t[1]);
        }
    }
    if let Some(normals) = &mesh.normals {
        for n in normals {
            let _ = writeln!(s, "vn {} {} {}", n[0], n[1], n[2]);
        }
    }
    let (uv, normal) = (mesh.uvs.is_some(), mesh.normals.is_some());
    for t in &mesh.triangles {
        s.push('f');
        for &i in t {
            let i = u64::from(i) + 1;
            let _ = match (uv, normal) {
                (false, false) => write!(s, " {i}"),
                (true, false) => write!(s, " {i}/{i}"),
                (false, true) => write!(s, " {i}//{i}"),
                (true, true) => write!(s, " {i}/{i}/{i}"),
            };
        }
        s.push('\n');
    }
    Ok(s.into_bytes())
}

#[cfg(test)]
mod tests {
    use super::super::{MeshFormat, encode, testmesh};

    fn read(bytes: &[u8]) -> tobj::Mesh {
        // The update stays for tobj's optional fields (features `merging`, `reordering`).
        #[allow(clippy::needless_update)]
        let opts = tobj::LoadOptions {
            single_index: false,
            triangulate: false,
            ignore_points: true,
            ignore_lines: true,
            ..Default::default()
        };
        let (models, _) = tobj::load_obj_buf(&mut &bytes[..], &opts, |_| {
            Err(tobj::LoadError::OpenFileFailed)
        })
        .unwrap();
        assert_eq!(models.len(), 1);
        models.into_iter().next().unwrap().mesh
    }

    #[test]
    fn tobj_reads_back_positions_exactly_attributes_faces_and_winding() {
        for case in testmesh::variety() {
            let (name, m) = (case.name, &case.mesh);
            let bytes = encode(m, MeshFormat::Obj).unwrap();
            // The `v` lines, in order, parse to exactly the f64s.
            let text = std::str::from_utf8(&bytes).unwrap();
            let v: Vec<[f64; 3]> = text
                .lines()
                .filter_map(|l| l.strip_prefix("v "))
                .map(|l| {
                    let c: Vec<f64> = l.split(' ').map(|c| c.parse().unwrap()).collect();
                    [c[0], c[1], c[2]]
                })
                .collect();
            assert_eq!(v, m.positions, "{name}");
            // tobj renumbers vertices in order of first use: compare corner by corner, in
            // the mesh's numbering.
            let r = read(&bytes);
            assert!(r.face_arities.is_empty(), "{name}: all faces are triangles");
            assert_eq!(r.indices.len(), 3 * m.triangles.len(), "{name}");
            assert_eq!(
                r.positions.len(),
                3 * m.positions.len(),
                "{name}: every vertex"
            );
            let corners = m.triangles.iter().flatten().map(|&i| i as usize);
            let mut back = vec![[f64::NAN; 3]; m.positions.len()];
            for (k, i) in corners.clone().enumerate() {
                let j = r.indices[k] as usize;
                back[i] = [0, 1, 2].map(|c| r.positions[3 * j + c]);
                assert_eq!(back[i], m.positions[i], "{name}: exact positions");
            }
            match &m.normals {
                Some(n) => {
                    assert_eq!(r.normal_indices.len(), r.indices.len(), "{name}");
                    for (k, i) in corners.clone().enumerate() {
                        let j = r.normal_indices[k] as usize;
                        let got = [0, 1, 2].map(|c| r.normals[3 * j + c] as f32);
                        assert_eq!(got, n[i], "{name}: exact normals");
                    }
                }
                None => assert!(
                    r.normals.is_empty() && r.normal_indices.is_empty(),
                    "{name}"
                ),
            }
            match &m.uvs {
                Some(t) => {
                    assert_eq!(r.texcoord_indices.len(), r.indices.len(), "{name}");
                    for (k, i) in corners.clone().enumerate() {
                        let j = r.texcoord_indices[k] as usize;
                        let got = [0, 1].map(|c| r.texcoords[2 * j + c] as f32);
                        assert_eq!(got, t[i], "{name}: exact texture coordinates");
                    }
                }
                None => assert!(
                    r.texcoords.is_empty() && r.texcoord_indices.is_empty(),
                    "{name}"
                ),
            }
            // The winding of the faces read back: the surface up, the skirt's walls out.
            let tris: Vec<[usize; 3]> = m.triangles.iter().map(|t| t.map(|i| i as usize)).collect();
            testmesh::assert_faces_out(&case, &back, &tris);
        }
    }

    #[test]
    fn faces_take_the_form_of_what_the_mesh_carries() {
        let lines = |normals, uvs| {
            let m = testmesh::surface(3, 3, normals, uvs, None, false);
            let text = String::from_utf8(encode(&m, MeshFormat::Obj).unwrap()).unwrap();
            let f = text
                .lines()
                .find(|l| l.starts_with("f "))
                .unwrap()
                .to_string();
            let count = |p: &str| text.lines().filter(|l| l.starts_with(p)).count();
            (f, count("v "), count("vt "), count("vn "))
        };
        let (f, v, vt, vn) = lines(false, false);
        assert!(!f.contains('/'), "{f}");
        assert_eq!((v, vt, vn), (9, 0, 0));
        let (f, _, vt, vn) = lines(false, true);
        assert!(
            f.split(' ').skip(1).all(|c| c.split('/').count() == 2),
            "{f}"
        );
        assert_eq!((vt, vn), (9, 0));
        let (f, _, vt, vn) = lines(true, false);
        assert!(f.contains("//"), "{f}");
        assert_eq!((vt, vn), (0, 9));
        let (f, _, vt, vn) = lines(true, true);
        assert!(
            f.split(' ')
                .skip(1)
                .all(|c| c.split('/').count() == 3 && !c.contains("//"))
        );
        assert_eq!((vt, vn), (9, 9));
    }
}
