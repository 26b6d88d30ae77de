//! Mesh file formats: OBJ, PLY, STL and binary glTF (`.glb`), chosen by the output's extension.
//!
//! [`encode`] checks the mesh once (at least one triangle, indices in range, attributes of
//! the right length, finite numbers, counts the formats can hold) and hands it to the format's
//! writer. Every writer is deterministic: the same mesh gives the same bytes.
//!
//! | format | positions | normals | texture coordinates | notes |
//! | --- | --- | --- | --- | --- |
//! | OBJ | f64 text, exact | `vn` | `vt` | 1-based faces `f v/vt/vn` |
//! | PLY | f64 binary, exact | f32 | f32 `s t` | binary little-endian 1.0 |
//! | STL | f32 | per facet, computed | — | loses precision on georeferenced coordinates |
//! | GLB | f32 relative to the bounding box's minimum, the minimum as the node's translation | f32 | f32, V flipped | glTF is Y-up |

mod glb;
mod obj;
mod ply;
mod stl;

#[cfg(test)]
mod testmesh;

use crate::error::{Error, Result};
use crate::mesh::Mesh;

/// A mesh file format.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MeshFormat {
    /// Wavefront OBJ (text).
    Obj,
    /// Stanford PLY (binary little-endian).
    Ply,
    /// STL (binary).
    Stl,
    /// glTF 2.0 binary (`.glb`).
    Glb,
}

impl MeshFormat {
    /// Every format, in the order their extensions are listed in messages.
    pub const ALL: [MeshFormat; 4] = [
        MeshFormat::Obj,
        MeshFormat::Ply,
        MeshFormat::Stl,
        MeshFormat::Glb,
    ];

    /// The format an output path asks for by its extension (`.obj`, `.ply`, `.stl`, `.glb`,
    /// in any case).
    pub fn from_path(p: &std::path::Path) -> Result<MeshFormat> {
        let ext = p
            .extension()
            .and_then(|e| e.to_str())
            .map(|e| e.to_ascii_lowercase());
        Self::ALL
            .into_iter()
            .find(|f| ext.as_deref() == Some(f.extension()))
            .ok_or_else(|| {
                Error::invalid(format!(
                    "{}: unknown mesh format (the extension must be .obj, .ply, .stl or .glb)",
                    p.display()
                ))
            })
    }

    /// The format's short name, as in messages.
    pub fn name(self) -> &'static str {
        match self {
            MeshFormat::Obj => "OBJ",
            MeshFormat::Ply => "PLY",
            MeshFormat::Stl => "STL",
            MeshFormat::Glb => "glTF binary (GLB)",
        }
    }

    /// The file extension, lower case, without the dot.
    pub fn extension(self) -> &'static str {
        match self {
            MeshFormat::Obj => "obj",
            MeshFormat::Ply => "ply",
            MeshFormat::Stl => "stl",
            MeshFormat::Glb => "glb",
        }
    }
}

/// The bytes of `mesh` as a `format` file. Deterministic: the same mesh gives the same bytes.
pub fn encode(mesh: &Mesh, format: MeshFormat) -> Result<Vec<u8>> {
    check(mesh)
        .and_then(|()| match format {
            MeshFormat::Obj => obj::encode(mesh),
            MeshFormat::Ply => ply::encode(mesh),
            MeshFormat::Stl => stl::encode(mesh),
            MeshFormat::Glb => glb::encode(mesh),
        })
        .map_err(|e| e.context(format!("{} export", format.name())))
}

/// What every writer relies on: triangles, indices in range, attributes of the positions'
/// length, finite numbers, and no more vertices than a u32 index reaches.
fn check(mesh: &Mesh) -> Result<()> {
    check_counts(mesh.positions.len(), mesh.triangles.len())?;
    let n = mesh.positions.len();
    if let Some(bad) = mesh.triangles.iter().flatten().find(|&&i| i as usize >= n) {
        return Err(Error::invalid(format!(
            "a triangle refers to vertex {bad} of a mesh of {n} vertices"
        )));
    }
    if let Some(p) = mesh
        .positions
        .iter()
        .find(|p| !p.iter().all(|c| c.is_finite()))
    {
        return Err(Error::invalid(format!(
            "a vertex position is not finite: {p:?}"
        )));
    }
    if let Some(normals) = &mesh.normals {
        if normals.len() != n {
            return Err(Error::invalid(format!(
                "{} normals for {n} vertices",
                normals.len()
            )));
        }
        if let Some(v) = normals.iter().find(|v| !v.iter().all(|c| c.is_finite())) {
            return Err(Error::invalid(format!("a normal is not finite: {v:?}")));
        }
    }
    if let Some(uvs) = &mesh.uvs {
        if uvs.len() != n {
            return Err(Error::invalid(format!(
                "{} texture coordinates for {n} vertices",
                uvs.len()
            )));
        }
        if let Some(v) = uvs.iter().find(|v| !v.iter().all(|c| c.is_finite())) {
            return Err(Error::invalid(format!(
                "a texture coordinate is not finite: {v:?}"
            )));
        }
    }
    Ok(())
}

/// The counts alone: at least one triangle, and vertex indices 0 ..= u32::MAX − 1 (glTF
/// keeps u32::MAX as the primitive-restart value; PLY and OBJ indices are u32 too).
fn check_counts(vertices: usize, triangles: usize) -> Result<()> {
    if triangles == 0 {
        return Err(Error::invalid("the mesh has no triangles"));
    }
    if vertices > u32::MAX as usize {
        return Err(Error::limit(format!(
            "{vertices} vertices: mesh files index at most {} vertices (32-bit indices)",
            u32::MAX
        )));
    }
    if triangles > u32::MAX as usize {
        return Err(Error::limit(format!(
            "{triangles} triangles: mesh files hold at most {} triangles",
            u32::MAX
        )));
    }
    Ok(())
}

/// The unit normal of triangle `t` (counter-clockwise), computed in f64; zero for a triangle
/// of no area.
fn facet_normal(mesh: &Mesh, t: [u32; 3]) -> [f64; 3] {
    let n = crate::mesh::face_normal(t.map(|i| mesh.positions[i as usize]));
    let l = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    if l > 0.0 && l.is_finite() {
        n.map(|c| c / l)
    } else {
        [0.0; 3]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    #[test]
    fn the_format_follows_the_extension_in_any_case() {
        for (p, f) in [
            ("a.obj", MeshFormat::Obj),
            ("dir/b.PLY", MeshFormat::Ply),
            ("c.Stl", MeshFormat::Stl),
            ("/x/y.tile.glb", MeshFormat::Glb),
        ] {
            assert_eq!(MeshFormat::from_path(Path::new(p)).unwrap(), f, "{p}");
        }
        for p in ["a.gltf", "a", "a.obj.txt", ".glb"] {
            let e = MeshFormat::from_path(Path::new(p)).unwrap_err();
            assert!(matches!(e, Error::InvalidArgument { .. }), "{p}");
            let msg = e.to_string();
            assert!(
                [".obj", ".ply", ".stl", ".glb"]
                    .iter()
                    .all(|x| msg.contains(x)),
                "{msg}"
            );
        }
        for f in MeshFormat::ALL {
            assert!(!f.name().is_empty());
        }
    }

    #[test]
    fn empty_inconsistent_or_oversized_meshes_are_refused() {
        let mut m = testmesh::surface(3, 3, false, false, None, false);
        for f in MeshFormat::ALL {
            assert!(encode(&m, f).is_ok());
        }
        let empty = Mesh {
            positions: m.positions.clone(),
            ..Default::default()
        };
        for f in MeshFormat::ALL {
            let e = encode(&empty, f).unwrap_err();
            assert!(matches!(e, Error::InvalidArgument { .. }), "{e}");
            assert!(e.to_string().contains("the mesh has no triangles"), "{e}");
        }
        let bad_index = Mesh {
            triangles: vec![[0, 1, 9]],
            ..m.clone()
        };
        let bad_normals = Mesh {
            normals: Some(vec![[0.0, 0.0, 1.0]]),
            ..m.clone()
        };
        let bad_uvs = Mesh {
            uvs: Some(vec![[0.0, 0.0]; m.positions.len() + 1]),
            ..m.clone()
        };
        m.positions[2][1] = f64::NAN;
        for bad in [&bad_index, &bad_normals, &bad_uvs, &m] {
            for f in MeshFormat::ALL {
                assert!(matches!(encode(bad, f), Err(Error::InvalidArgument { .. })));
            }
        }
        // Too many vertices for 32-bit indices (checked on the counts: such a mesh would
        // need ~100 GB).
        assert!(check_counts(u32::MAX as usize, 1).is_ok());
        let e = check_counts(u32::MAX as usize + 1, 1).unwrap_err();
        assert!(matches!(e, Error::LimitExceeded { .. }), "{e}");
        let e = check_counts(3, u32::MAX as usize + 1).unwrap_err();
        assert!(matches!(e, Error::LimitExceeded { .. }), "{e}");
    }

    #[test]
    fn every_format_is_deterministic() {
        let m = testmesh::surface(6, 5, true, true, Some(4.0), true);
        for f in MeshFormat::ALL {
            let a = encode(&m, f).unwrap();
            assert_eq!(a, encode(&m.clone(), f).unwrap(), "{}", f.name());
        }
    }
}
