//! Mesh loaders. Each format has its own module with a `parse` function over bytes, so tests
//! and fuzzers can feed them data without touching the file system.
//!
//! Every parser ends with [`finish`], which checks the invariants the rest of the library relies
//! on (indices in range, finite coordinates, at least one triangle). Degenerate triangles are
//! kept: the scene layer drops and counts them.

use std::path::Path;

use glam::Vec3;

use crate::{Error, Location, Mesh, Result};

pub mod gltf;
pub mod obj;
pub mod off;
pub mod ply;
pub mod stl;

/// The formats [`load_mesh`] reads, as its errors list them.
pub const SUPPORTED_FORMATS: &str =
    "supported mesh formats: OBJ (.obj), PLY (.ply), glTF/GLB (.gltf, .glb), STL (.stl), OFF (.off)";

/// `"1 vertex"`, `"3 vertices"`: a count and its noun, with the noun's real plural (messages
/// used to build plurals with a bare `s`, giving "3 vertexs").
pub(crate) fn count_of(n: usize, noun: &str) -> String {
    if n == 1 {
        return format!("1 {noun}");
    }
    let plural = match noun {
        "vertex" => "vertices".to_string(),
        "index" => "indices".to_string(),
        "matrix" => "matrices".to_string(),
        n if n.ends_with('s') || n.ends_with('x') || n.ends_with("ch") || n.ends_with("sh") => format!("{n}es"),
        n => format!("{n}s"),
    };
    format!("{n} {plural}")
}

/// Loads a mesh, choosing the format from the file extension (case-insensitive): `obj`, `ply`,
/// `gltf`, `glb`, `stl`, `off`. OBJ material libraries and glTF external buffers are resolved
/// relative to the file's folder.
pub fn load_mesh(path: &Path) -> Result<Mesh> {
    // The format comes from the extension, so say exactly what is wrong with the name (or the
    // path) before reading anything: "unsupported mesh format '.'" helped nobody.
    let meta = std::fs::metadata(path);
    if meta.as_ref().is_ok_and(|m| m.is_dir()) {
        return Err(unusable(path, "is a directory, not a mesh file".into()));
    }
    if path.extension().is_none() {
        // A missing file is reported as missing, not as badly named.
        meta.map_err(|e| Error::io(path, e))?;
    }
    let format = format_of(path)?;
    let data = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    parse_format(&format, &data, path, Some(path.parent().unwrap_or(Path::new(""))))
}

/// Parses a mesh file's bytes, the format chosen from `name`'s extension as `load_mesh` chooses
/// it, with no file system: what a browser hands over (a file opened or dropped on the page).
/// The file comes alone, so an OBJ's material library and a glTF's external buffers are not
/// read (the OBJ keeps its geometry; a glTF that needs one is an error: a `.glb` or embedded
/// buffers work). `name` is used in errors.
pub fn parse_mesh(data: &[u8], name: &Path) -> Result<Mesh> {
    parse_format(&format_of(name)?, data, name, None)
}

/// `path`'s error for a name that gives no mesh format, with the formats there are.
fn unusable(path: &Path, what: String) -> Error {
    Error::parse(path, Location::Whole, format!("{what}; {SUPPORTED_FORMATS}"))
}

/// The mesh format `path`'s extension names, lower case, or the error saying why it names none.
fn format_of(path: &Path) -> Result<String> {
    let ext = match path.extension() {
        None => return Err(unusable(path, "has no extension, so its mesh format is unknown".into())),
        Some(e) => e.to_string_lossy().to_ascii_lowercase(),
    };
    if !matches!(ext.as_str(), "obj" | "ply" | "gltf" | "glb" | "stl" | "off") {
        return Err(unusable(path, format!("unsupported mesh format '.{ext}'")));
    }
    Ok(ext)
}

/// Parses `data` as `format` (from `format_of`); `dir`: the folder an OBJ's material library
/// and a glTF's external buffers are read from (`None`: not read).
fn parse_format(format: &str, data: &[u8], path: &Path, dir: Option<&Path>) -> Result<Mesh> {
    match format {
        "obj" => {
            let resolve = |name: &str| dir.and_then(|d| std::fs::read(d.join(name)).ok());
            obj::parse(data, path, &resolve)
        }
        "ply" => ply::parse(data, path),
        "gltf" | "glb" => gltf::parse_with_base(data, path, dir),
        "stl" => stl::parse(data, path),
        "off" => off::parse(data, path),
        _ => unreachable!("format_of returns one of these"),
    }
}

/// Fails with a located error unless all components of `v` are finite.
pub(crate) fn check_finite(path: &Path, location: Location, what: &str, v: Vec3) -> Result<()> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(Error::parse(
            path,
            location,
            format!("non-finite {what} ({}, {}, {})", v.x, v.y, v.z),
        ))
    }
}

/// Final check shared by all loaders. Parsers report problems with a precise location as they
/// find them; this catches whatever is left (and is the only check for glTF input):
///
/// * at least one triangle ("no triangles" otherwise),
/// * every index `< positions.len()`,
/// * every position finite,
/// * at least one triangle of non-zero area,
/// * `normals` empty or one per position (a mismatched or non-finite set is dropped, since
///   normals can always be recomputed),
/// * `triangle_materials` empty or one per triangle, each indexing `materials`.
pub(crate) fn finish(mut mesh: Mesh, path: &Path) -> Result<Mesh> {
    if mesh.triangles.is_empty() {
        return Err(Error::parse(path, Location::Whole, "no triangles"));
    }
    let n = mesh.positions.len();
    for (t, tri) in mesh.triangles.iter().enumerate() {
        for &i in tri {
            if i as usize >= n {
                return Err(Error::parse(
                    path,
                    Location::Whole,
                    format!(
                        "triangle {t}: vertex index {i} out of range ({})",
                        count_of(n, "vertex")
                    ),
                ));
            }
        }
    }
    for (i, &p) in mesh.positions.iter().enumerate() {
        check_finite(path, Location::Whole, &format!("position of vertex {i}"), p)?;
    }
    // Degenerate triangles are kept (the scene layer drops and counts them), but a mesh made of
    // nothing else has nothing to trace: say so here, where the file is known.
    let area = |t: &[u32; 3]| {
        let [a, b, c] = t.map(|i| mesh.positions[i as usize]);
        (b - a).cross(c - a).length_squared() > 0.0
    };
    if !mesh.triangles.iter().any(area) {
        return Err(Error::parse(
            path,
            Location::Whole,
            format!(
                "no triangles left: all {} have zero area (degenerate)",
                mesh.triangles.len()
            ),
        ));
    }
    if mesh.normals.len() != n || !mesh.normals.iter().all(|v| v.is_finite()) {
        mesh.normals.clear();
    }
    if !mesh.triangle_materials.is_empty() {
        if mesh.triangle_materials.len() != mesh.triangles.len() {
            return Err(Error::parse(
                path,
                Location::Whole,
                format!(
                    "{} triangle materials for {} triangles",
                    mesh.triangle_materials.len(),
                    mesh.triangles.len()
                ),
            ));
        }
        let m = mesh.materials.len();
        if let Some((t, &id)) = mesh
            .triangle_materials
            .iter()
            .enumerate()
            .find(|(_, id)| **id as usize >= m)
        {
            return Err(Error::parse(
                path,
                Location::Whole,
                format!("triangle {t}: material {id} out of range ({})", count_of(m, "material")),
            ));
        }
    }
    Ok(mesh)
}

/// How many records of at least `min_record_size` bytes could still fit in `remaining` bytes:
/// the most a parser may preallocate for `declared` records announced by a header.
pub(crate) fn capped_capacity(declared: u64, remaining: usize, min_record_size: usize) -> usize {
    let fit = remaining / min_record_size.max(1);
    usize::try_from(declared).unwrap_or(usize::MAX).min(fit)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;

    /// A fresh empty folder under the system temp dir, removed on drop.
    pub(crate) struct TempDir(pub PathBuf);

    impl TempDir {
        pub(crate) fn new(tag: &str) -> Self {
            use std::sync::atomic::{AtomicUsize, Ordering};
            static N: AtomicUsize = AtomicUsize::new(0);
            let dir = std::env::temp_dir().join(format!(
                "gridtrace-io-{tag}-{}-{}",
                std::process::id(),
                N.fetch_add(1, Ordering::Relaxed)
            ));
            let _ = std::fs::remove_dir_all(&dir);
            std::fs::create_dir_all(&dir).unwrap();
            TempDir(dir)
        }
    }

    impl Drop for TempDir {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }

    fn tri_mesh() -> Mesh {
        Mesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y],
            triangles: vec![[0, 1, 2]],
            ..Mesh::default()
        }
    }

    #[test]
    fn finish_checks_invariants() {
        let p = Path::new("m.obj");
        assert!(finish(tri_mesh(), p).is_ok());

        let err = finish(Mesh::default(), p).unwrap_err().to_string();
        assert!(err.contains("m.obj") && err.contains("no triangles"), "{err}");

        let mut m = tri_mesh();
        m.triangles[0][2] = 3;
        let err = finish(m, p).unwrap_err().to_string();
        assert!(err.contains("out of range"), "{err}");

        let mut m = tri_mesh();
        m.positions[1].y = f32::NAN;
        assert!(finish(m, p).unwrap_err().to_string().contains("non-finite"));

        // Degenerate triangles are kept.
        let mut m = tri_mesh();
        m.triangles.push([0, 0, 0]);
        assert_eq!(finish(m, p).unwrap().triangles.len(), 2);

        // Mismatched normals are dropped, not an error.
        let mut m = tri_mesh();
        m.normals = vec![Vec3::Z];
        assert!(finish(m, p).unwrap().normals.is_empty());

        let mut m = tri_mesh();
        m.triangle_materials = vec![1];
        assert!(finish(m, p).is_err());
    }

    #[test]
    fn counts_use_real_plurals() {
        assert_eq!(count_of(1, "vertex"), "1 vertex");
        assert_eq!(count_of(3, "vertex"), "3 vertices");
        assert_eq!(count_of(0, "normal"), "0 normals");
        assert_eq!(count_of(2, "index"), "2 indices");
    }

    #[test]
    fn capacity_is_capped_by_remaining_bytes() {
        assert_eq!(capped_capacity(4_000_000_000, 36, 12), 3);
        assert_eq!(capped_capacity(2, 1000, 12), 2);
        assert_eq!(capped_capacity(u64::MAX, 10, 0), 10);
    }

    #[test]
    fn load_mesh_dispatches_on_extension() {
        let dir = TempDir::new("dispatch");
        let obj = dir.0.join("quad.OBJ");
        std::fs::write(
            &obj,
            b"mtllib quad.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nusemtl red\nf 1 2 3 4\n",
        )
        .unwrap();
        std::fs::write(dir.0.join("quad.mtl"), b"newmtl red\nKd 1 0 0\n").unwrap();
        let m = load_mesh(&obj).unwrap();
        assert_eq!(m.triangles.len(), 2);
        assert_eq!(m.materials.len(), 1);
        assert_eq!(m.materials[0].diffuse, Vec3::new(1.0, 0.0, 0.0));

        let off = dir.0.join("t.off");
        std::fs::write(&off, b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n").unwrap();
        assert_eq!(load_mesh(&off).unwrap().triangles.len(), 1);

        let stl = dir.0.join("t.Stl");
        std::fs::write(
            &stl,
            b"solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\n\
              endloop\nendfacet\nendsolid t\n",
        )
        .unwrap();
        assert_eq!(load_mesh(&stl).unwrap().triangles.len(), 1);

        let ply = dir.0.join("t.ply");
        std::fs::write(
            &ply,
            b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
              property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n\
              0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
        )
        .unwrap();
        assert_eq!(load_mesh(&ply).unwrap().triangles.len(), 1);

        let err = load_mesh(&dir.0.join("x.fbx")).unwrap_err().to_string();
        assert!(err.contains("x.fbx") && err.contains("unsupported"), "{err}");

        // A name the format cannot be read from: say what is wrong, name the path, list the
        // formats.
        let err = load_mesh(&dir.0).unwrap_err().to_string();
        assert!(
            err.contains(dir.0.to_str().unwrap()) && err.contains("is a directory"),
            "{err}"
        );
        assert!(err.contains(SUPPORTED_FORMATS), "{err}");
        let bare = dir.0.join("bunny");
        std::fs::write(&bare, b"v 0 0 0\n").unwrap();
        let err = load_mesh(&bare).unwrap_err().to_string();
        assert!(
            err.contains("bunny: has no extension") && err.contains("PLY (.ply)"),
            "{err}"
        );
        assert!(!err.contains("'.'"), "{err}");
        let err = load_mesh(&dir.0.join("x.fbx")).unwrap_err().to_string();
        assert!(err.contains("'.fbx'") && err.contains("OBJ (.obj)"), "{err}");

        let missing = dir.0.join("missing.obj");
        let err = load_mesh(&missing).unwrap_err();
        assert!(matches!(err, Error::Io { .. }));
        assert!(err.to_string().contains("missing.obj"));

        // From bytes (a page's dropped file): the same format choice and mesh, no file read:
        // the OBJ keeps its geometry without its material library.
        for path in [&off, &stl, &ply] {
            let bytes = std::fs::read(path).unwrap();
            let name = Path::new(path.file_name().unwrap());
            let (a, b) = (parse_mesh(&bytes, name).unwrap(), load_mesh(path).unwrap());
            assert_eq!((a.positions, a.triangles), (b.positions, b.triangles), "{name:?}");
        }
        let from_bytes = parse_mesh(&std::fs::read(&obj).unwrap(), Path::new("quad.OBJ")).unwrap();
        assert_eq!((from_bytes.triangles.len(), from_bytes.positions), (2, m.positions));
        // `usemtl red` names a material the library would have given; without it, not red.
        assert!(
            from_bytes
                .materials
                .iter()
                .all(|m| m.diffuse != Vec3::new(1.0, 0.0, 0.0))
        );
        let err = parse_mesh(b"v 0 0 0\n", Path::new("bunny")).unwrap_err().to_string();
        assert!(err.contains("bunny: has no extension"), "{err}");
        let err = parse_mesh(b"", Path::new("x.fbx")).unwrap_err().to_string();
        assert!(err.contains("'.fbx'") && err.contains("OBJ (.obj)"), "{err}");
    }

    /// Real-world meshes from the shared data folder, when it is present.
    #[test]
    fn shared_meshes_when_present() {
        let root = concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/data/meshes/");
        let cases: [(&str, Option<usize>, usize); 5] = [
            ("bunny/bun_zipper.ply", Some(35_947), 69_451),
            ("dragon/dragon_vrip_res4.ply", Some(5_205), 11_102),
            ("sibenik/sibenik.obj", None, 73_564),
            ("knight/knight_456.stl", None, 456),
            ("armadillo/armadillo_cgal_52k.off", None, 52_000),
        ];
        for (file, verts, tris) in cases {
            let path = PathBuf::from(root).join(file);
            if !path.exists() {
                continue;
            }
            let m = load_mesh(&path).unwrap_or_else(|e| panic!("{e}"));
            if let Some(v) = verts {
                assert_eq!(m.positions.len(), v, "{file}");
            }
            assert_eq!(m.triangles.len(), tris, "{file}");
            if file.ends_with("sibenik.obj") {
                assert!(!m.materials.is_empty());
                assert_eq!(m.triangle_materials.len(), tris);
            }
        }
        // The other shared meshes must at least load.
        for file in [
            "bunny/bun_zipper_res2.ply",
            "bunny/bun_zipper_res4.ply",
            "bunny/stanford-bunny.obj",
            "bunny_lowpoly/bunny_1k.obj",
            "bunny_lowpoly/bunny_npm_3674.obj",
            "dragon/dragon_vrip_res2_binary.ply",
            "dragon/dragon_vrip_res3.ply",
            "knight/knight_422.obj",
            "knight/knight_chess_blend_384.obj",
        ] {
            let path = PathBuf::from(root).join(file);
            if path.exists() {
                let m = load_mesh(&path).unwrap_or_else(|e| panic!("{e}"));
                assert!(!m.triangles.is_empty(), "{file}");
            }
        }
    }
}
