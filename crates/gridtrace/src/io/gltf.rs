//! glTF 2.0 (`.gltf` with external or embedded buffers, and binary `.glb`), via the `gltf` crate.
//!
//! Every node of every scene is walked (recursively, transforms composed); each triangle
//! primitive (strips and fans are converted) is baked into world space: positions by the world
//! matrix, normals by its inverse transpose. Points and lines are skipped. Materials: base colour
//! factor RGB → diffuse, metallic factor → reflectivity; one `Material` per glTF material used,
//! plus a default one for primitives without a material. Images are never loaded.

use std::collections::HashMap;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::Path;

use ::gltf::mesh::Mode;
use glam::{Mat3, Mat4, Vec3};

use super::finish;
use crate::{Error, Location, Material, Mesh, Result};

/// Most node visits a file may cause (shared children are visited once per parent, so a small
/// file could otherwise describe an exponential number of instances).
const MAX_NODE_VISITS: usize = 1 << 20;
/// Deepest node hierarchy accepted (deeper is almost certainly a cycle).
const MAX_DEPTH: usize = 256;

/// Loads a `.gltf` or `.glb` file; external buffers are resolved relative to its folder.
pub fn load(path: &Path) -> Result<Mesh> {
    let data = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    parse_with_base(&data, path, Some(path.parent().unwrap_or(Path::new(""))))
}

/// Parses a self-contained glTF: a `.glb`, or a `.gltf` whose buffers are embedded as `data:`
/// URIs. A reference to an external file is an error. `path` is only used in errors.
pub fn parse_slice(data: &[u8], path: &Path) -> Result<Mesh> {
    parse_with_base(data, path, None)
}

/// Parses glTF bytes, resolving external buffers relative to `base` when given.
pub(crate) fn parse_with_base(data: &[u8], path: &Path, base: Option<&Path>) -> Result<Mesh> {
    let is_text = !data.starts_with(b"glTF");
    let wrap = |e: ::gltf::Error| {
        let location = match &e {
            ::gltf::Error::Deserialize(j) if is_text && j.line() > 0 => Location::Line(j.line()),
            _ => Location::Whole,
        };
        Error::parse(path, location, format!("glTF: {e}"))
    };
    if data.is_empty() {
        return Err(Error::parse(path, Location::Whole, "empty file"));
    }
    // gltf-json's validation indexes arrays with file-provided indices (fuzzing found a panic on
    // a POSITION accessor index out of range, gltf-json 1.4.1 mesh.rs:151): a panic is an error.
    let ::gltf::Gltf { document, blob } = catch_unwind(AssertUnwindSafe(|| ::gltf::Gltf::from_slice(data)))
        .map_err(|_| Error::parse(path, Location::Whole, "glTF: malformed document (index out of range)"))?
        .map_err(wrap)?;
    // gltf 1.4.1 unwraps the percent-decoding of a relative buffer URI (import.rs:50): a URI
    // whose escapes decode to invalid UTF-8 panics (found by fuzzing). Checked here first, for a
    // precise error; the catch_unwind is the backstop for anything else in the import.
    for b in document.buffers() {
        if let ::gltf::buffer::Source::Uri(uri) = b.source()
            && !uri.starts_with("data:")
            && !percent_decodes_to_utf8(uri)
        {
            return Err(Error::parse(
                path,
                Location::Whole,
                format!("glTF: buffer {}: URI is not valid percent-encoded UTF-8", b.index()),
            ));
        }
    }
    let buffers = catch_unwind(AssertUnwindSafe(|| ::gltf::import_buffers(&document, base, blob)))
        .map_err(|_| Error::parse(path, Location::Whole, "glTF: malformed buffer"))?
        .map_err(wrap)?;
    // The crate's accessor readers index and do arithmetic on file-provided offsets and counts;
    // a panic there must become an error, not take the program down.
    let mesh = catch_unwind(AssertUnwindSafe(|| build(&document, &buffers, path)))
        .unwrap_or_else(|_| Err(Error::parse(path, Location::Whole, "glTF: malformed accessor data")))?;
    finish(mesh, path)
}

/// Whether the `%XX` escapes of `uri` decode to valid UTF-8 (a `%` not followed by two hex
/// digits stays as it is, as the `urlencoding` crate does).
fn percent_decodes_to_utf8(uri: &str) -> bool {
    let b = uri.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        let hex = |c: u8| (c as char).to_digit(16);
        if b[i] == b'%'
            && let (Some(h), Some(l)) = (b.get(i + 1).and_then(|&c| hex(c)), b.get(i + 2).and_then(|&c| hex(c)))
        {
            out.push((h * 16 + l) as u8);
            i += 3;
            continue;
        }
        out.push(b[i]);
        i += 1;
    }
    std::str::from_utf8(&out).is_ok()
}

fn build(doc: &::gltf::Document, buffers: &[::gltf::buffer::Data], path: &Path) -> Result<Mesh> {
    let err = |msg: String| Error::parse(path, Location::Whole, msg);
    let mut out = Builder {
        mesh: Mesh::default(),
        all_normals: true,
        materials: HashMap::new(),
    };

    // Roots: every scene's nodes; without scenes, every node that is nobody's child.
    let mut stack: Vec<(::gltf::Node, Mat4, usize)> = Vec::new();
    if doc.scenes().len() > 0 {
        for scene in doc.scenes() {
            stack.extend(scene.nodes().map(|n| (n, Mat4::IDENTITY, 0)));
        }
    } else {
        let mut is_child = vec![false; doc.nodes().len()];
        for n in doc.nodes() {
            for c in n.children() {
                is_child[c.index()] = true;
            }
        }
        stack.extend(
            doc.nodes()
                .filter(|n| !is_child[n.index()])
                .map(|n| (n, Mat4::IDENTITY, 0)),
        );
    }
    stack.reverse(); // visit in file order

    let mut visits = 0usize;
    while let Some((node, parent, depth)) = stack.pop() {
        visits += 1;
        if visits > MAX_NODE_VISITS || depth > MAX_DEPTH {
            return Err(err(format!(
                "node hierarchy too deep or too many instances (at node {})",
                node.index()
            )));
        }
        let world = parent * Mat4::from_cols_array_2d(&node.transform().matrix());
        if let Some(mesh) = node.mesh() {
            for prim in mesh.primitives() {
                out.primitive(&prim, world, buffers)
                    .map_err(|m| err(format!("mesh {} primitive {}: {m}", mesh.index(), prim.index())))?;
            }
        }
        let first_child = stack.len();
        stack.extend(node.children().map(|c| (c, world, depth + 1)));
        stack[first_child..].reverse();
    }
    if !out.all_normals {
        out.mesh.normals.clear();
    }
    Ok(out.mesh)
}

struct Builder {
    mesh: Mesh,
    /// Whether every primitive so far had normals.
    all_normals: bool,
    /// glTF material index (None: the default material) → index into `mesh.materials`.
    materials: HashMap<Option<usize>, u32>,
}

impl Builder {
    fn primitive(
        &mut self,
        prim: &::gltf::Primitive,
        world: Mat4,
        buffers: &[::gltf::buffer::Data],
    ) -> std::result::Result<(), String> {
        let mode = prim.mode();
        if !matches!(mode, Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan) {
            return Ok(());
        }
        let reader = prim.reader(|b| buffers.get(b.index()).map(|d| &d[..]));
        let positions: Vec<Vec3> = reader
            .read_positions()
            .ok_or("no readable POSITION attribute")?
            .map(|p| world.transform_point3(Vec3::from_array(p)))
            .collect();
        let count = positions.len();
        let indices: Vec<u32> = match reader.read_indices() {
            Some(ix) => ix.into_u32().collect(),
            None => (0..count as u32).collect(),
        };
        if let Some(&bad) = indices.iter().find(|&&i| i as usize >= count) {
            return Err(format!("index {bad} out of range ({count} vertices)"));
        }
        let base = self.mesh.positions.len();
        if base + count > u32::MAX as usize {
            return Err("more vertices than 32-bit indices can address".into());
        }
        let base = base as u32;
        let flip = world.determinant() < 0.0; // mirrored: keep triangles front-facing
        let tri = |a: u32, b: u32, c: u32| {
            if flip {
                [base + a, base + c, base + b]
            } else {
                [base + a, base + b, base + c]
            }
        };
        let first_triangle = self.mesh.triangles.len();
        match mode {
            Mode::Triangles => {
                for t in indices.chunks_exact(3) {
                    self.mesh.triangles.push(tri(t[0], t[1], t[2]));
                }
            }
            Mode::TriangleStrip => {
                for k in 0..indices.len().saturating_sub(2) {
                    let (a, b, c) = (indices[k], indices[k + 1], indices[k + 2]);
                    self.mesh
                        .triangles
                        .push(if k % 2 == 0 { tri(a, b, c) } else { tri(b, a, c) });
                }
            }
            _ => {
                for k in 1..indices.len().saturating_sub(1) {
                    self.mesh.triangles.push(tri(indices[0], indices[k], indices[k + 1]));
                }
            }
        }
        self.mesh.positions.extend(positions);
        match reader.read_normals() {
            Some(normals) if self.all_normals => {
                let m = Mat3::from_mat4(world).inverse().transpose();
                let before = self.mesh.normals.len();
                self.mesh
                    .normals
                    .extend(normals.map(|n| (m * Vec3::from_array(n)).normalize_or_zero()));
                if self.mesh.normals.len() - before != count {
                    self.all_normals = false;
                }
            }
            _ => self.all_normals = false,
        }

        let material = prim.material();
        let next = self.mesh.materials.len() as u32;
        let id = *self.materials.entry(material.index()).or_insert(next);
        if id == next {
            self.mesh.materials.push(match material.index() {
                None => Material::default(),
                Some(i) => {
                    let pbr = material.pbr_metallic_roughness();
                    let [r, g, b, _] = pbr.base_color_factor();
                    Material {
                        name: material.name().map_or_else(|| format!("material{i}"), str::to_string),
                        diffuse: Vec3::new(r, g, b),
                        reflectivity: pbr.metallic_factor().clamp(0.0, 1.0),
                    }
                }
            });
        }
        let added = self.mesh.triangles.len() - first_triangle;
        self.mesh.triangle_materials.extend(std::iter::repeat_n(id, added));
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Packs JSON and a binary chunk into a GLB container.
    fn glb(json: &str, bin: &[u8]) -> Vec<u8> {
        let mut json = json.as_bytes().to_vec();
        while !json.len().is_multiple_of(4) {
            json.push(b' ');
        }
        let mut bin = bin.to_vec();
        while !bin.len().is_multiple_of(4) {
            bin.push(0);
        }
        let total = 12 + 8 + json.len() + if bin.is_empty() { 0 } else { 8 + bin.len() };
        let mut out = Vec::new();
        out.extend_from_slice(b"glTF");
        out.extend_from_slice(&2u32.to_le_bytes());
        out.extend_from_slice(&(total as u32).to_le_bytes());
        out.extend_from_slice(&(json.len() as u32).to_le_bytes());
        out.extend_from_slice(b"JSON");
        out.extend_from_slice(&json);
        if !bin.is_empty() {
            out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
            out.extend_from_slice(b"BIN\0");
            out.extend_from_slice(&bin);
        }
        out
    }

    fn f32s(v: &[f32]) -> Vec<u8> {
        v.iter().flat_map(|f| f.to_le_bytes()).collect()
    }

    /// One triangle, non-indexed, in a node translated by (1, 2, 3), with a red half-metal
    /// material.
    fn triangle_glb() -> Vec<u8> {
        let json = r#"{
            "asset": {"version": "2.0"},
            "scene": 0,
            "scenes": [{"nodes": [0]}],
            "nodes": [{"mesh": 0, "translation": [1, 2, 3]}],
            "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "material": 0}]}],
            "materials": [{"name": "red", "pbrMetallicRoughness":
                {"baseColorFactor": [1, 0, 0, 1], "metallicFactor": 0.5}}],
            "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                           "min": [0, 0, 0], "max": [1, 1, 0]}],
            "bufferViews": [{"buffer": 0, "byteLength": 36}],
            "buffers": [{"byteLength": 36}]
        }"#;
        glb(json, &f32s(&[0., 0., 0., 1., 0., 0., 0., 1., 0.]))
    }

    /// A quad (indexed, u16, with normals) under a parent scaled by 2 and a child rotated 90°
    /// about X, plus a points primitive that must be skipped, and a second instance of the mesh
    /// at the root with no material on the quad.
    fn hierarchy_json(buffer_uri: &str) -> String {
        let s = std::f32::consts::FRAC_1_SQRT_2;
        format!(
            r#"{{
            "asset": {{"version": "2.0"}},
            "scenes": [{{"nodes": [0]}}, {{"nodes": [2]}}],
            "nodes": [
                {{"scale": [2, 2, 2], "children": [1]}},
                {{"mesh": 0, "rotation": [{s}, 0, 0, {s}]}},
                {{"mesh": 1, "matrix": [1,0,0,0, 0,1,0,0, 0,0,1,0, 10,0,0,1]}}
            ],
            "meshes": [
                {{"primitives": [
                    {{"attributes": {{"POSITION": 0, "NORMAL": 1}}, "indices": 2}},
                    {{"attributes": {{"POSITION": 0}}, "mode": 0}}
                ]}},
                {{"primitives": [{{"attributes": {{"POSITION": 0, "NORMAL": 1}}, "indices": 2,
                                   "mode": 5}}]}}
            ],
            "accessors": [
                {{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
                  "min": [0, 0, 0], "max": [1, 1, 0]}},
                {{"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC3"}},
                {{"bufferView": 2, "componentType": 5123, "count": 6, "type": "SCALAR"}}
            ],
            "bufferViews": [
                {{"buffer": 0, "byteOffset": 0, "byteLength": 48}},
                {{"buffer": 0, "byteOffset": 48, "byteLength": 48}},
                {{"buffer": 0, "byteOffset": 96, "byteLength": 12}}
            ],
            "buffers": [{{"byteLength": 108 {buffer_uri}}}]
        }}"#
        )
    }

    fn hierarchy_bin() -> Vec<u8> {
        let mut bin = f32s(&[0., 0., 0., 1., 0., 0., 1., 1., 0., 0., 1., 0.]);
        bin.extend(f32s(&[0., 0., 1.].repeat(4)));
        for i in [0u16, 1, 2, 0, 2, 3] {
            bin.extend_from_slice(&i.to_le_bytes());
        }
        bin
    }

    fn close(a: Vec3, b: Vec3) -> bool {
        (a - b).length() < 1e-5
    }

    #[test]
    fn glb_triangle_with_translation() {
        let m = parse_slice(&triangle_glb(), Path::new("t.glb")).unwrap();
        assert_eq!(
            m.positions,
            vec![Vec3::new(1., 2., 3.), Vec3::new(2., 2., 3.), Vec3::new(1., 3., 3.)]
        );
        assert_eq!(m.triangles, vec![[0, 1, 2]]);
        assert!(m.normals.is_empty());
        assert_eq!(m.materials.len(), 1);
        assert_eq!(m.materials[0].name, "red");
        assert_eq!(m.materials[0].diffuse, Vec3::new(1., 0., 0.));
        assert_eq!(m.materials[0].reflectivity, 0.5);
        assert_eq!(m.triangle_materials, vec![0]);
    }

    #[test]
    fn hierarchy_transforms_and_strips() {
        let data = glb(&hierarchy_json(""), &hierarchy_bin());
        let m = parse_slice(&data, Path::new("h.glb")).unwrap();
        // Scene 0: quad (2 triangles) scaled by 2 and rotated +90° about X (y → z).
        // Scene 1: the strip 0,1,2,0,2,3 → 4 triangles, translated by 10 in x.
        assert_eq!(m.positions.len(), 8);
        assert_eq!(m.triangles.len(), 6);
        assert!(close(m.positions[2], Vec3::new(2., 0., 2.)), "{}", m.positions[2]);
        assert!(close(m.positions[6], Vec3::new(11., 1., 0.)), "{}", m.positions[6]);
        assert_eq!(m.normals.len(), 8);
        assert!(close(m.normals[0], Vec3::new(0., -1., 0.)), "{}", m.normals[0]);
        assert!(close(m.normals[7], Vec3::Z));
        assert_eq!(&m.triangles[..2], &[[0, 1, 2], [0, 2, 3]]);
        assert_eq!(m.triangles[2], [4, 5, 6]);
        assert_eq!(m.triangles[3], [6, 5, 4]); // odd strip triangle: (1, 2, 0) → (2, 1, 0)
        assert_eq!(m.materials, vec![Material::default()]);
        assert_eq!(m.triangle_materials, vec![0; 6]);
    }

    #[test]
    fn embedded_and_external_buffers() {
        // Embedded data URI.
        let uri = format!(
            r#", "uri": "data:application/octet-stream;base64,{}""#,
            base64(&hierarchy_bin())
        );
        let json = hierarchy_json(&uri);
        let m = parse_slice(json.as_bytes(), Path::new("e.gltf")).unwrap();
        assert_eq!(m.triangles.len(), 6);

        // External file: an error for a slice, loaded relative to the file by load().
        let json = hierarchy_json(r#", "uri": "quad.bin""#);
        let e = parse_slice(json.as_bytes(), Path::new("x.gltf"))
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("x.gltf: glTF:"), "{e}");
        let dir = crate::io::tests::TempDir::new("gltf");
        std::fs::write(dir.0.join("quad.bin"), hierarchy_bin()).unwrap();
        std::fs::write(dir.0.join("x.gltf"), &json).unwrap();
        assert_eq!(load(&dir.0.join("x.gltf")).unwrap().triangles.len(), 6);
        assert_eq!(crate::io::load_mesh(&dir.0.join("x.gltf")).unwrap().triangles.len(), 6);
        std::fs::write(dir.0.join("t.GLB"), triangle_glb()).unwrap();
        assert_eq!(crate::io::load_mesh(&dir.0.join("t.GLB")).unwrap().triangles.len(), 1);
    }

    fn base64(data: &[u8]) -> String {
        const ABC: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
        let mut out = String::new();
        for chunk in data.chunks(3) {
            let b = [chunk[0], *chunk.get(1).unwrap_or(&0), *chunk.get(2).unwrap_or(&0)];
            let n = (b[0] as u32) << 16 | (b[1] as u32) << 8 | b[2] as u32;
            for k in 0..4 {
                if k <= chunk.len() {
                    out.push(ABC[(n >> (18 - 6 * k)) as usize & 63] as char);
                } else {
                    out.push('=');
                }
            }
        }
        out
    }

    #[test]
    fn malformed_inputs() {
        let e = parse_slice(
            b"{\"asset\": {\"version\": \"2.0\"},\n \"nodes\": [}",
            Path::new("bad.gltf"),
        )
        .unwrap_err()
        .to_string();
        assert!(e.starts_with("bad.gltf:line 2:"), "{e}");
        assert!(
            parse_slice(b"", Path::new("bad.glb"))
                .unwrap_err()
                .to_string()
                .contains("bad.glb")
        );
        let e = parse_slice(b"glTF\x02\x00\x00\x00garbage", Path::new("bad.glb")).unwrap_err();
        assert!(e.to_string().starts_with("bad.glb: glTF:"), "{e}");
        // No meshes at all.
        let e = parse_slice(br#"{"asset": {"version": "2.0"}}"#, Path::new("bad.gltf")).unwrap_err();
        assert!(e.to_string().contains("no triangles"));
        // Index out of range.
        let mut bin = hierarchy_bin();
        bin[96 + 10] = 9;
        let e = parse_slice(&glb(&hierarchy_json(""), &bin), Path::new("bad.glb")).unwrap_err();
        assert!(e.to_string().contains("out of range"), "{e}");
        // NaN position.
        let mut bin = hierarchy_bin();
        bin[4..8].copy_from_slice(&f32::NAN.to_le_bytes());
        let e = parse_slice(&glb(&hierarchy_json(""), &bin), Path::new("bad.glb")).unwrap_err();
        assert!(e.to_string().contains("non-finite"), "{e}");
        // A node that is its own child.
        let json = r#"{"asset": {"version": "2.0"}, "scenes": [{"nodes": [0]}],
                       "nodes": [{"children": [0]}]}"#;
        assert!(parse_slice(json.as_bytes(), Path::new("cycle.gltf")).is_err());
    }

    #[test]
    fn every_prefix_never_panics() {
        let data = triangle_glb();
        for len in 0..data.len() {
            let _ = parse_slice(&data[..len], Path::new("p.glb"));
        }
    }
}
