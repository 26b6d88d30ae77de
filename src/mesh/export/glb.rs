//! Binary glTF 2.0 (`.glb`): one scene, one node, one mesh of one indexed triangle primitive,
//! positions as f32 relative to the mesh's bounding-box minimum and that minimum, in f64, as
//! the node's translation, so georeferenced coordinates keep their precision (the
//! relative-to-centre idea of 3D Tiles).
//!
//! - Axes: glTF is Y-up, so a vertex (x east, y north, z up) becomes (x, z, −y). That map is a
//!   proper rotation (a quarter turn about x), so the mesh's counter-clockwise triangles stay
//!   counter-clockwise, glTF's front face. The translation is the minimum (x, y, z) (the
//!   south-west bottom corner) mapped the same way, so local Y ≥ 0, X ≥ 0 and Z ≤ 0; the
//!   translation is written with full f64 digits.
//! - Accessors: `POSITION` (f32 VEC3, with the `min`/`max` the spec requires, exactly the f32
//!   values written), `NORMAL` (f32 VEC3, renormalised as glTF requires unit normals, a zero
//!   one becoming up) and `TEXCOORD_0` (f32 VEC2, V = 1 − v: glTF's V runs down from the
//!   image's top) when the mesh has them; indices `UNSIGNED_SHORT` up to 65535 vertices (65535
//!   itself is the restart value, never an index), else `UNSIGNED_INT`. One buffer view per
//!   accessor, tightly packed, each 4-byte aligned, indices last; the `BIN` chunk is padded
//!   with zeros to 4 bytes and the JSON chunk with spaces.
//! - A default material (white, not metallic, fully rough, `doubleSided: false`: back faces
//!   are culled as in any terrain viewer, and the skirt's walls face out); `asset.generator`
//!   is `vtz`. The material has no texture: `TEXCOORD_0` is there to drape an image on, and
//!   the Khronos validator notes it as "may be unused" (an info, not a warning).
//! - The file must stay under 4 GiB (the GLB header's u32 length): beyond, `Error::limit`.

use serde_json::json;

use crate::error::{Error, Result};
use crate::mesh::Mesh;

const FLOAT: u32 = 5126;
const UNSIGNED_SHORT: u32 = 5123;
const UNSIGNED_INT: u32 = 5125;
const ARRAY_BUFFER: u32 = 34962;
const ELEMENT_ARRAY_BUFFER: u32 = 34963;
const TRIANGLES: u32 = 4;
/// The most vertices 16-bit indices address: 0 ..= 65534 (65535 restarts primitives).
const MAX_U16_VERTICES: usize = 65535;

/// (x east, y north, z up) → glTF's (x, y up, z south). `0.0 - y` keeps a zero positive.
fn to_gltf(p: [f64; 3]) -> [f64; 3] {
    [p[0], p[2], 0.0 - p[1]]
}

pub(super) fn encode(mesh: &Mesh) -> Result<Vec<u8>> {
    let n = mesh.positions.len();
    let short = n <= MAX_U16_VERTICES;
    let index_size = if short { 2 } else { 4 };
    // Sizes first (in u64), so an impossible file fails before allocating.
    let sizes = [
        12 * n as u64,
        if mesh.normals.is_some() {
            12 * n as u64
        } else {
            0
        },
        if mesh.uvs.is_some() { 8 * n as u64 } else { 0 },
        3 * index_size * mesh.triangles.len() as u64,
    ];
    let bin_len = sizes.iter().sum::<u64>().next_multiple_of(4);
    // Header, two chunk headers, and room for the JSON.
    if bin_len + 12 + 16 + 4096 > u64::from(u32::MAX) {
        return Err(Error::limit(format!(
            "{n} vertices and {} triangles need {bin_len} bytes: a GLB file holds under 4 GiB",
            mesh.triangles.len()
        )));
    }

    // Positions relative to the bounding box's minimum, in glTF axes.
    let mut lo = [f64::INFINITY; 3];
    for p in &mesh.positions {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
        }
    }
    let origin = to_gltf(lo);
    let mut bin = Vec::with_capacity(bin_len as usize);
    let mut pmin = [f32::INFINITY; 3];
    let mut pmax = [f32::NEG_INFINITY; 3];
    for p in &mesh.positions {
        let q = to_gltf(*p);
        for k in 0..3 {
            let f = (q[k] - origin[k]) as f32;
            if !f.is_finite() {
                return Err(Error::limit(format!(
                    "the mesh spans more than glTF's 32-bit floats hold ({} from {})",
                    q[k], origin[k]
                )));
            }
            pmin[k] = pmin[k].min(f);
            pmax[k] = pmax[k].max(f);
            bin.extend_from_slice(&f.to_le_bytes());
        }
    }
    if let Some(normals) = &mesh.normals {
        for v in normals {
            let g = to_gltf(v.map(f64::from));
            let l = (g[0] * g[0] + g[1] * g[1] + g[2] * g[2]).sqrt();
            let u = if l > 0.0 {
                g.map(|c| c / l)
            } else {
                [0.0, 1.0, 0.0]
            };
            for c in u {
                bin.extend_from_slice(&(c as f32).to_le_bytes());
            }
        }
    }
    if let Some(uvs) = &mesh.uvs {
        for t in uvs {
            bin.extend_from_slice(&t[0].to_le_bytes());
            bin.extend_from_slice(&((1.0 - f64::from(t[1])) as f32).to_le_bytes());
        }
    }
    for &i in mesh.triangles.iter().flatten() {
        if short {
            // n ≤ 65535, so every index (checked < n) fits.
            bin.extend_from_slice(&(i as u16).to_le_bytes());
        } else {
            bin.extend_from_slice(&i.to_le_bytes());
        }
    }
    bin.resize(bin_len as usize, 0);

    // Buffer views and accessors, in the order written.
    let mut views = Vec::new();
    let mut accessors = Vec::new();
    let mut offset = 0u64;
    let mut add = |size: u64, target: u32, accessor: serde_json::Value| -> usize {
        views.push(json!({
            "buffer": 0,
            "byteOffset": offset,
            "byteLength": size,
            "target": target,
        }));
        offset += size;
        let mut a = accessor;
        a["bufferView"] = json!(views.len() - 1);
        accessors.push(a);
        accessors.len() - 1
    };
    let f32s = |v: [f32; 3]| v.map(f64::from);
    let mut attributes = serde_json::Map::new();
    attributes.insert(
        "POSITION".into(),
        json!(add(
            sizes[0],
            ARRAY_BUFFER,
            json!({
                "componentType": FLOAT,
                "count": n,
                "type": "VEC3",
                "min": f32s(pmin),
                "max": f32s(pmax),
            })
        )),
    );
    if mesh.normals.is_some() {
        let a = add(
            sizes[1],
            ARRAY_BUFFER,
            json!({ "componentType": FLOAT, "count": n, "type": "VEC3" }),
        );
        attributes.insert("NORMAL".into(), json!(a));
    }
    if mesh.uvs.is_some() {
        let a = add(
            sizes[2],
            ARRAY_BUFFER,
            json!({ "componentType": FLOAT, "count": n, "type": "VEC2" }),
        );
        attributes.insert("TEXCOORD_0".into(), json!(a));
    }
    let indices = add(
        sizes[3],
        ELEMENT_ARRAY_BUFFER,
        json!({
            "componentType": if short { UNSIGNED_SHORT } else { UNSIGNED_INT },
            "count": 3 * mesh.triangles.len(),
            "type": "SCALAR",
        }),
    );
    let doc = json!({
        "asset": { "version": "2.0", "generator": "vtz" },
        "scene": 0,
        "scenes": [{ "nodes": [0] }],
        "nodes": [{ "mesh": 0, "translation": origin }],
        "meshes": [{
            "primitives": [{
                "attributes": attributes,
                "indices": indices,
                "material": 0,
                "mode": TRIANGLES,
            }],
        }],
        "materials": [{
            "pbrMetallicRoughness": {
                "baseColorFactor": [1.0, 1.0, 1.0, 1.0],
                "metallicFactor": 0.0,
                "roughnessFactor": 1.0,
            },
            "doubleSided": false,
        }],
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [{ "byteLength": bin_len }],
    });
    let mut json =
        serde_json::to_vec(&doc).map_err(|e| Error::invalid(format!("glTF JSON: {e}")))?;
    json.resize(json.len().next_multiple_of(4), b' ');

    let total = 12 + 8 + json.len() as u64 + 8 + bin_len;
    let total = u32::try_from(total)
        .map_err(|_| Error::limit(format!("{total} bytes: a GLB file holds under 4 GiB")))?;
    let mut out = Vec::with_capacity(total as usize);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&total.to_le_bytes());
    out.extend_from_slice(&(json.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&json);
    out.extend_from_slice(&(bin_len as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(&bin);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::super::{MeshFormat, encode, testmesh};
    use crate::mesh::Mesh;

    /// What the gltf crate (with its validation) reads back, in glTF's axes, and the index type.
    struct Back {
        translation: [f32; 3],
        positions: Vec<[f32; 3]>,
        normals: Option<Vec<[f32; 3]>>,
        uvs: Option<Vec<[f32; 2]>>,
        triangles: Vec<[usize; 3]>,
        index_type: gltf::accessor::DataType,
        translation_f64: [f64; 3],
    }

    /// The JSON chunk of a GLB file, parsed.
    fn json_chunk(bytes: &[u8]) -> serde_json::Value {
        let len = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
        serde_json::from_slice(&bytes[20..20 + len]).unwrap()
    }

    fn read(bytes: &[u8]) -> Back {
        let g = gltf::Gltf::from_slice(bytes).expect("the gltf crate validates the file");
        let blob = g.blob.as_deref().expect("a BIN chunk");
        assert_eq!(g.document.scenes().count(), 1);
        assert_eq!(g.document.nodes().count(), 1);
        assert_eq!(g.document.meshes().count(), 1);
        let node = g.document.nodes().next().unwrap();
        let gltf::scene::Transform::Decomposed {
            translation,
            rotation,
            scale,
        } = node.transform()
        else {
            panic!("a decomposed transform")
        };
        assert_eq!((rotation, scale), ([0.0, 0.0, 0.0, 1.0], [1.0; 3]));
        // The gltf crate hands out f32: take the translation's f64s from the JSON chunk.
        let t = &json_chunk(bytes)["nodes"][0]["translation"];
        let translation_f64 = [0, 1, 2].map(|k| t[k].as_f64().unwrap());
        let mesh = node.mesh().unwrap();
        assert_eq!(mesh.primitives().count(), 1);
        let p = mesh.primitives().next().unwrap();
        assert_eq!(p.mode(), gltf::mesh::Mode::Triangles);
        assert!(!p.material().double_sided());
        assert_eq!(g.document.as_json().asset.generator.as_deref(), Some("vtz"));
        let r = p.reader(|_| Some(blob));
        let indices: Vec<u32> = r.read_indices().unwrap().into_u32().collect();
        Back {
            translation,
            positions: r.read_positions().unwrap().collect(),
            normals: r.read_normals().map(|n| n.collect()),
            uvs: r.read_tex_coords(0).map(|t| t.into_f32().collect()),
            triangles: indices
                .chunks(3)
                .map(|c| [c[0] as usize, c[1] as usize, c[2] as usize])
                .collect(),
            index_type: p.indices().unwrap().data_type(),
            translation_f64,
        }
    }

    /// Check `bytes` against `m` (and, for `case`, the winding); returns the index type.
    fn check(m: &Mesh, bytes: &[u8], case: Option<&testmesh::Case>) -> gltf::accessor::DataType {
        let b = read(bytes);
        let name = case.map_or("mesh", |c| c.name);
        assert_eq!(b.positions.len(), m.positions.len(), "{name}");
        assert_eq!(b.translation, b.translation_f64.map(|c| c as f32));
        // Back to x east, y north, z up: (X, Y, Z) + t → (X, −Z, Y).
        let t = b.translation_f64;
        let ours: Vec<[f64; 3]> = b
            .positions
            .iter()
            .map(|q| {
                let g = [0, 1, 2].map(|k| f64::from(q[k]) + t[k]);
                [g[0], -g[2], g[1]]
            })
            .collect();
        // Within an f32 step of the span (the offsets are relative to the minimum).
        let mut span = 0f64;
        for (k, lo) in [t[0], -t[2], t[1]].into_iter().enumerate() {
            let hi = m.positions.iter().map(|p| p[k]).fold(f64::MIN, f64::max);
            assert_eq!(
                lo,
                m.positions.iter().map(|p| p[k]).fold(f64::MAX, f64::min),
                "{name}: min"
            );
            span = span.max(hi - lo);
        }
        let tol = span * f64::from(f32::EPSILON);
        for (a, w) in ours.iter().zip(&m.positions) {
            for k in 0..3 {
                assert!(
                    (a[k] - w[k]).abs() <= tol,
                    "{name}: {a:?} against {w:?} (±{tol})"
                );
            }
        }
        // Normals mapped to glTF's axes, uvs with V flipped.
        match (&m.normals, &b.normals) {
            (Some(want), Some(got)) => {
                for (w, g) in want.iter().zip(got) {
                    let w = [w[0], w[2], -w[1]];
                    assert!(
                        (0..3).all(|k| (w[k] - g[k]).abs() < 1e-6),
                        "{name}: {w:?} {g:?}"
                    );
                }
            }
            (None, None) => {}
            _ => panic!("{name}: normals present in one only"),
        }
        match (&m.uvs, &b.uvs) {
            (Some(want), Some(got)) => {
                for (w, g) in want.iter().zip(got) {
                    assert_eq!(g[0], w[0], "{name}");
                    assert!((g[1] - (1.0 - w[1])).abs() <= f32::EPSILON, "{name}");
                }
            }
            (None, None) => {}
            _ => panic!("{name}: texture coordinates present in one only"),
        }
        let want: Vec<[usize; 3]> = m.triangles.iter().map(|t| t.map(|i| i as usize)).collect();
        assert_eq!(b.triangles, want, "{name}");
        if let Some(case) = case {
            // Winding in glTF's own axes: the surface faces +Y (up) ...
            let gpos: Vec<[f64; 3]> = b.positions.iter().map(|q| q.map(f64::from)).collect();
            for t in b
                .triangles
                .iter()
                .filter(|t| t.iter().all(|&i| i < case.surface))
            {
                assert!(testmesh::normal_of(&gpos, *t)[1] > 0.1, "{name}: {t:?}");
            }
            // ... and, mapped back, the surface up and the walls out.
            testmesh::assert_faces_out(case, &ours, &b.triangles);
        }
        b.index_type
    }

    #[test]
    fn the_gltf_crate_validates_and_reads_back_every_attribute_and_the_winding() {
        for case in testmesh::variety() {
            let bytes = encode(&case.mesh, MeshFormat::Glb).unwrap();
            let ty = check(&case.mesh, &bytes, Some(&case));
            assert_eq!(ty, gltf::accessor::DataType::U16, "{}", case.name);
        }
    }

    #[test]
    fn georeferenced_positions_keep_their_precision_through_the_translation() {
        let m = testmesh::surface(9, 8, false, false, None, true);
        let bytes = encode(&m, MeshFormat::Glb).unwrap();
        let b = read(&bytes);
        // UTM northings of ~3.8e6 m: an f32 would step by 0.25 m; relative offsets over a
        // ~270 m span step by ~30 µm at most.
        assert!(b.translation_f64[2] < -3.8e6);
        for (q, p) in b.positions.iter().zip(&m.positions) {
            let x = f64::from(q[0]) + b.translation_f64[0];
            let y = -(f64::from(q[2]) + b.translation_f64[2]);
            assert!(
                (x - p[0]).abs() < 1e-4 && (y - p[1]).abs() < 1e-4,
                "{x} {y} {p:?}"
            );
        }
    }

    #[test]
    fn the_layout_is_aligned_and_the_chunks_padded() {
        // An odd number of triangles makes the 16-bit index view end off a 4-byte boundary.
        let mut m = testmesh::surface(4, 3, true, true, None, false);
        m.triangles.truncate(3);
        let bytes = encode(&m, MeshFormat::Glb).unwrap();
        assert_eq!(&bytes[..4], b"glTF");
        let u32_at = |o: usize| u32::from_le_bytes(bytes[o..o + 4].try_into().unwrap()) as usize;
        assert_eq!(u32_at(4), 2);
        assert_eq!(u32_at(8), bytes.len());
        let json_len = u32_at(12);
        assert_eq!(&bytes[16..20], b"JSON");
        assert_eq!(json_len % 4, 0);
        let bin_at = 20 + json_len;
        assert_eq!(&bytes[bin_at + 4..bin_at + 8], b"BIN\0");
        assert_eq!(u32_at(bin_at) % 4, 0);
        assert_eq!(bin_at + 8 + u32_at(bin_at), bytes.len());
        let json: serde_json::Value = serde_json::from_slice(&bytes[20..bin_at]).unwrap();
        for v in json["bufferViews"].as_array().unwrap() {
            assert_eq!(v["byteOffset"].as_u64().unwrap() % 4, 0);
        }
        assert_eq!(
            json["buffers"][0]["byteLength"].as_u64().unwrap() as usize,
            u32_at(bin_at)
        );
        check(&m, &bytes, None);
    }

    #[test]
    fn sixteen_bit_indices_up_to_65535_vertices_then_thirty_two() {
        // 65535 vertices: the last 16-bit mesh; one vertex more needs 32 bits.
        let m = testmesh::scattered(300, 65535, None);
        assert_eq!(m.positions.len(), 65535);
        let bytes = encode(&m, MeshFormat::Glb).unwrap();
        assert_eq!(check(&m, &bytes, None), gltf::accessor::DataType::U16);
        let case = testmesh::Case {
            name: "65536+skirt",
            mesh: testmesh::scattered(300, 65536, Some(10.0)),
            surface: 65536,
        };
        assert!(case.mesh.positions.len() > 65536);
        let bytes = encode(&case.mesh, MeshFormat::Glb).unwrap();
        assert_eq!(
            check(&case.mesh, &bytes, Some(&case)),
            gltf::accessor::DataType::U32
        );
        write_sample("large_u32.glb", &bytes);
    }

    /// Writes the file into the folder `VTZ_GLB_OUT` names, when it is set, for the Khronos
    /// validator (tests/js/validate_glb.mjs).
    fn write_sample(name: &str, bytes: &[u8]) {
        if let Some(dir) = std::env::var_os("VTZ_GLB_OUT") {
            let dir = std::path::Path::new(&dir);
            std::fs::create_dir_all(dir).unwrap();
            std::fs::write(dir.join(name), bytes).unwrap();
        }
    }

    #[test]
    fn samples_for_the_khronos_validator() {
        for case in testmesh::variety() {
            let bytes = encode(&case.mesh, MeshFormat::Glb).unwrap();
            write_sample(&format!("{}.glb", case.name.replace('+', "_")), &bytes);
        }
    }
}
