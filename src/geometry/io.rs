//! Triangle meshes from files: Wavefront OBJ ([`tobj`]), STL, ASCII and
//! binary ([`stl_io`]), and PLY, ASCII and binary ([`ply_rs_bw`]), chosen by
//! the file's extension ([`load_mesh`]). Polygons are fanned into triangles;
//! points and lines are ignored. Every failure (a missing or truncated file,
//! an index past the vertices, a non-finite coordinate, no triangles) is an
//! [`Error::File`] naming the file.

use std::path::Path;

use glam::DVec3;

use super::mesh::Mesh;
use crate::error::{Error, Result};

/// The mesh formats [`load_mesh`] reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MeshFormat {
    Obj,
    Stl,
    Ply,
}

impl MeshFormat {
    /// The format of `path` by its extension (`.obj`, `.stl`, `.ply`, any case).
    pub fn of(path: &Path) -> Result<MeshFormat> {
        let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
        match ext.as_deref() {
            Some("obj") => Ok(MeshFormat::Obj),
            Some("stl") => Ok(MeshFormat::Stl),
            Some("ply") => Ok(MeshFormat::Ply),
            _ => Err(Error::file(path, "unknown mesh format (expected a .obj, .stl or .ply file)")),
        }
    }
}

/// Reads the triangles of the OBJ, STL or PLY file at `path` (coordinates
/// as stored: place them with [`Mesh::transformed`]); the file is bounded as
/// by [`load_mesh_within`] without a memory budget.
pub fn load_mesh(path: &Path) -> Result<Mesh> {
    load_mesh_within(path, None)
}

/// Longest line a text mesh (OBJ, ASCII STL, a PLY header or ASCII body)
/// may have: far beyond any real one, and it keeps a file without line
/// breaks from being read as one giant line.
pub const MAX_MESH_LINE: usize = 1 << 20;

/// Memory a mesh file takes to read, per byte of the file: the bytes
/// themselves and the parsed vertices and triangles (an upper bound for every
/// format).
pub const MESH_BYTES_PER_FILE_BYTE: u64 = 3;

/// [`load_mesh`] within a memory budget of `budget` bytes: the path must be
/// a regular file (a FIFO, a device, a directory is refused before it is
/// opened for reading), its size times [`MESH_BYTES_PER_FILE_BYTE`] must fit
/// the budget (checked before reading it), and a text format must have no
/// line longer than [`MAX_MESH_LINE`] bytes. Each refusal is an
/// [`Error::File`] naming the file.
pub fn load_mesh_within(path: &Path, budget: Option<u64>) -> Result<Mesh> {
    let format = MeshFormat::of(path)?;
    let bytes = read_bounded(path, budget)?;
    let bad = |why: String| Error::file(path, why);
    let (vertices, triangles) = match format {
        MeshFormat::Obj => read_obj(&bytes).map_err(bad)?,
        MeshFormat::Stl => read_stl(&bytes).map_err(bad)?,
        MeshFormat::Ply => read_ply(&bytes).map_err(bad)?,
    };
    drop(bytes);
    if triangles.is_empty() {
        return Err(Error::file(path, "the mesh has no triangles"));
    }
    Mesh::new(vertices, triangles).map_err(|e| Error::file(path, e.to_string()))
}

/// The bytes of mesh file `path`, after the checks of [`load_mesh_within`]
/// that need no parsing (regular file, size against the budget).
fn read_bounded(path: &Path, budget: Option<u64>) -> Result<Vec<u8>> {
    use std::io::Read;
    let not_regular = || Error::file(path, "not a regular file (a mesh is read from a file, not a device, FIFO or directory)");
    let meta = std::fs::metadata(path).map_err(|e| Error::file(path, format!("cannot read: {e}")))?;
    if !meta.is_file() {
        return Err(not_regular());
    }
    let f = std::fs::File::open(path).map_err(|e| Error::file(path, format!("cannot open: {e}")))?;
    // (what was opened, not what the name pointed to a moment before)
    let len = match f.metadata() {
        Ok(m) if m.is_file() => m.len(),
        Ok(_) => return Err(not_regular()),
        Err(e) => return Err(Error::file(path, format!("cannot read: {e}"))),
    };
    let need = len.saturating_mul(MESH_BYTES_PER_FILE_BYTE);
    if let Some(b) = budget
        && need > b
    {
        return Err(Error::file(
            path,
            format!(
                "the mesh file is {len} bytes; reading it needs about {need} bytes of memory, more than the budget of {b} bytes (--max-memory)"
            ),
        ));
    }
    let cap = usize::try_from(len).map_err(|_| Error::file(path, format!("the mesh file is too large ({len} bytes)")))?;
    let mut bytes = Vec::new();
    bytes.try_reserve_exact(cap).map_err(|_| Error::file(path, format!("not enough memory to read the mesh file ({len} bytes)")))?;
    // (at most the size just read: a file growing meanwhile is cut there)
    f.take(len).read_to_end(&mut bytes).map_err(|e| Error::file(path, format!("cannot read: {e}")))?;
    Ok(bytes)
}

/// An error when a line of `text` is longer than [`MAX_MESH_LINE`].
fn check_lines(text: &[u8]) -> std::result::Result<(), String> {
    let mut start = 0;
    for (i, &b) in text.iter().enumerate() {
        if b == b'\n' {
            start = i + 1;
        } else if i - start >= MAX_MESH_LINE {
            return Err(format!("a line longer than {MAX_MESH_LINE} bytes at byte {start}: not a text mesh"));
        }
    }
    Ok(())
}

type Triangles = (Vec<DVec3>, Vec<[u32; 3]>);

/// The triangles of polygon `face` (vertex indices), fanned from its first vertex.
fn fan(face: &[u32], out: &mut Vec<[u32; 3]>) {
    for w in 1..face.len().saturating_sub(1) {
        out.push([face[0], face[w], face[w + 1]]);
    }
}

fn read_obj(bytes: &[u8]) -> std::result::Result<Triangles, String> {
    check_lines(bytes)?;
    let opts = tobj::LoadOptions { single_index: true, triangulate: true, ignore_points: true, ignore_lines: true };
    // (materials are not needed: none is read, a missing .mtl is not an error)
    let (models, _materials) = tobj::load_obj_buf(&mut std::io::Cursor::new(bytes), &opts, |_| Err(tobj::LoadError::OpenFileFailed))
        .map_err(|e| format!("cannot read as OBJ: {e}"))?;
    let (mut vertices, mut triangles) = (vec![], vec![]);
    for m in models {
        let base = vertices.len() as u32;
        let p = &m.mesh.positions;
        if p.len() % 3 != 0 {
            return Err(format!("model '{}' has {} coordinates, not a multiple of 3", m.name, p.len()));
        }
        vertices.extend(p.chunks_exact(3).map(|c| DVec3::new(c[0] as f64, c[1] as f64, c[2] as f64)));
        for t in m.mesh.indices.chunks_exact(3) {
            triangles.push([base + t[0], base + t[1], base + t[2]]);
        }
    }
    Ok((vertices, triangles))
}

fn read_stl(bytes: &[u8]) -> std::result::Result<Triangles, String> {
    // binary: an 80-byte header, a triangle count, 50 bytes per triangle
    let binary = bytes.len() >= 84 && {
        let n = u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]) as u64;
        84 + 50 * n == bytes.len() as u64
    };
    if !binary {
        if !bytes.trim_ascii_start().starts_with(b"solid") {
            return Err(format!(
                "not an STL file: neither ASCII (\"solid …\") nor binary ({} bytes does not match the triangle count in its header)",
                bytes.len()
            ));
        }
        check_lines(bytes)?;
    }
    let mesh = stl_io::read_stl(&mut std::io::Cursor::new(bytes)).map_err(|e| format!("cannot read as STL: {e}"))?;
    let vertices = mesh.vertices.iter().map(|v| DVec3::new(v[0] as f64, v[1] as f64, v[2] as f64)).collect();
    let mut triangles = Vec::with_capacity(mesh.faces.len());
    for t in &mesh.faces {
        let i = t.vertices.map(|i| u32::try_from(i).unwrap_or(u32::MAX));
        triangles.push(i);
    }
    Ok((vertices, triangles))
}

fn read_ply(bytes: &[u8]) -> std::result::Result<Triangles, String> {
    use ply_rs_bw::parser::Parser;
    use ply_rs_bw::ply::DefaultElement;
    // the header is text (and an ASCII body): bounded lines
    let header_end = bytes.windows(10).position(|w| w == b"end_header").map_or(bytes.len(), |i| i + 10);
    let ascii = bytes[..header_end].windows(12).any(|w| w == b"format ascii");
    check_lines(if ascii { bytes } else { &bytes[..header_end] })?;
    let mut reader = std::io::Cursor::new(bytes);
    let ply = Parser::<DefaultElement>::new().read_ply(&mut reader).map_err(|e| format!("cannot read as PLY: {e}"))?;
    let verts = ply.payload.get("vertex").ok_or("no 'vertex' element")?;
    let coord = |e: &DefaultElement, k: &str| -> std::result::Result<f64, String> {
        let p = e.get(k).ok_or_else(|| format!("a vertex has no '{k}' property"))?;
        match p {
            ply_rs_bw::ply::Property::Double(d) => Ok(*d),
            p => p.to_f32_lossy().map(f64::from).ok_or_else(|| format!("vertex property '{k}' is a list")),
        }
    };
    let vertices = verts
        .iter()
        .map(|e| Ok(DVec3::new(coord(e, "x")?, coord(e, "y")?, coord(e, "z")?)))
        .collect::<std::result::Result<Vec<_>, String>>()?;
    let mut triangles = vec![];
    for face in ply.payload.get("face").map(|v| v.as_slice()).unwrap_or(&[]) {
        let list = face.get("vertex_indices").or_else(|| face.get("vertex_index")).ok_or("a face has no 'vertex_indices' list")?;
        let idx = list.to_u32_list().ok_or("a face's 'vertex_indices' is not a list of non-negative integers")?;
        fan(&idx, &mut triangles);
    }
    Ok((vertices, triangles))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(dir: &Path, name: &str, bytes: &[u8]) -> std::path::PathBuf {
        let p = dir.join(name);
        std::fs::write(&p, bytes).unwrap();
        p
    }

    /// A unit square as two triangles in each format, and the same tetrahedron.
    #[test]
    fn obj_stl_and_ply_read_the_same_triangles() {
        let dir = tempfile::tempdir().unwrap();
        let obj = write(dir.path(), "q.obj", b"# square\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n");
        let ply = write(
            dir.path(),
            "q.PLY",
            b"ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n",
        );
        let stl = write(
            dir.path(),
            "q.stl",
            b"solid q\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 1 1 0\nendloop\nendfacet\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 1 0\nvertex 0 1 0\nendloop\nendfacet\nendsolid q\n",
        );
        for p in [obj, ply, stl] {
            let m = load_mesh(&p).unwrap();
            assert_eq!(m.triangles.len(), 2, "{}", p.display());
            let area: f64 = m
                .triangles
                .iter()
                .map(|t| {
                    let [a, b, c] = t.map(|i| m.vertices[i as usize]);
                    0.5 * (b - a).cross(c - a).length()
                })
                .sum();
            assert!((area - 1.0).abs() < 1e-6, "{}: area {area}", p.display());
            // counter-clockwise seen from +z: the normals point up
            for t in &m.triangles {
                let [a, b, c] = t.map(|i| m.vertices[i as usize]);
                assert!((b - a).cross(c - a).z > 0.0);
            }
            assert_eq!(m.bounds().unwrap(), [DVec3::ZERO, DVec3::new(1.0, 1.0, 0.0)]);
        }
    }

    #[test]
    fn bad_mesh_files_are_errors_naming_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let cases: [(&str, &[u8]); 7] = [
            ("a.txt", b"v 0 0 0"),
            ("empty.obj", b""),
            ("lines.obj", b"v 0 0 0\nv 1 0 0\nl 1 2\n"),
            ("index.obj", b"v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 9\n"),
            ("trunc.stl", b"\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\x05\0\0\0\0\0"),
            ("noface.ply", b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n"),
            ("badidx.ply", b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n1 1 0\n3 0 1 7\n"),
        ];
        for (name, bytes) in cases {
            let p = write(dir.path(), name, bytes);
            let e = load_mesh(&p).unwrap_err().to_string();
            assert!(e.contains(name), "{name}: {e}");
        }
        let e = load_mesh(&dir.path().join("missing.obj")).unwrap_err().to_string();
        assert!(e.contains("missing.obj"), "{e}");
        // NaN coordinates
        let p = write(dir.path(), "nan.ply", b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\nnan 0 0\n1 0 0\n1 1 0\n3 0 1 2\n");
        assert!(load_mesh(&p).is_err());
    }
}
