//! Triangle meshes: OBJ (tobj) and PLY (ply-rs-bw) loading, Mitsuba's
//! built-in rectangle and cube, transformation to world space, validation
//! (NaN vertices refused, zero-area triangles dropped and counted),
//! Mitsuba's vertex-normal rules and its texture coordinates (UVs).

use glam::{Mat3, Mat4, Vec2, Vec3};
use std::path::Path;

/// A mesh as read from a file, in object space.
#[derive(Clone, Debug, Default)]
pub struct RawMesh {
    /// Vertex positions.
    pub positions: Vec<Vec3>,
    /// Per-vertex normals, when the file has them.
    pub normals: Option<Vec<Vec3>>,
    /// Per-vertex texture coordinates, when the file has them (as stored:
    /// [`RawMesh::flip_tex_coords`] applies Mitsuba's OBJ convention).
    pub uvs: Option<Vec<Vec2>>,
    /// Triangles as vertex indices.
    pub indices: Vec<[u32; 3]>,
}

/// A validated world-space triangle mesh.
#[derive(Clone, Debug, Default)]
pub struct TriMesh {
    /// World-space vertex positions.
    pub positions: Vec<Vec3>,
    /// World-space unit vertex normals; `None` means flat (face) shading.
    pub normals: Option<Vec<Vec3>>,
    /// Per-vertex UVs (`None`: the mesh has none).
    pub uvs: Option<Vec<Vec2>>,
    /// Triangles (degenerate ones already removed).
    pub indices: Vec<[u32; 3]>,
    /// How many zero-area triangles were dropped.
    pub dropped_degenerate: usize,
}

/// Reads a Wavefront OBJ file (all objects merged, polygons triangulated).
pub fn load_obj(path: &Path) -> Result<RawMesh, String> {
    // Read whole: the face indices are checked before tobj parses the text.
    let bytes = std::fs::read(path).map_err(|e| e.to_string())?;
    obj_from_bytes(&bytes)
}

/// Reads OBJ text held in memory, as [`load_obj`] reads a file. Every face
/// index is checked first (`obj_indices`): one naming no element of the
/// file is refused with its line, before tobj's index arithmetic sees it.
pub fn obj_from_bytes(bytes: &[u8]) -> Result<RawMesh, String> {
    super::obj_indices::check_face_indices(bytes)?;
    std::str::from_utf8(bytes).map_err(|e| {
        let line = bytes[..e.valid_up_to()]
            .iter()
            .filter(|&&b| b == b'\n')
            .count()
            + 1;
        format!("line {line}: not UTF-8 text")
    })?;
    let opts = tobj::LoadOptions {
        triangulate: true,
        single_index: true,
        ignore_points: true,
        ignore_lines: true,
    };
    // Materials are not used, so `mtllib` files are not opened (one naming
    // a device such as /dev/zero would never end).
    let mut reader = LineCounter {
        rest: bytes,
        read: 0,
    };
    let (models, _materials) =
        tobj::load_obj_buf(&mut reader, &opts, |_| Err(tobj::LoadError::OpenFileFailed))
            .map_err(|e| reader.locate(bytes, e))?;
    let mut out = RawMesh::default();
    let mut all_have_normals = true;
    let mut normals = Vec::new();
    let mut all_have_uvs = true;
    let mut uvs = Vec::new();
    for m in &models {
        let mesh = &m.mesh;
        let base = u32::try_from(out.positions.len())
            .map_err(|_| "more than 2^32 vertices".to_string())?;
        out.positions.extend(
            mesh.positions
                .chunks_exact(3)
                .map(|p| Vec3::new(p[0], p[1], p[2])),
        );
        if mesh.normals.len() == mesh.positions.len() && !mesh.normals.is_empty() {
            normals.extend(
                mesh.normals
                    .chunks_exact(3)
                    .map(|n| Vec3::new(n[0], n[1], n[2])),
            );
        } else {
            all_have_normals = false;
        }
        if mesh.texcoords.len() / 2 == mesh.positions.len() / 3 && !mesh.texcoords.is_empty() {
            uvs.extend(
                mesh.texcoords
                    .chunks_exact(2)
                    .map(|t| Vec2::new(t[0], t[1])),
            );
        } else {
            all_have_uvs = false;
        }
        for t in mesh.indices.chunks_exact(3) {
            let shift = |i: u32| base.checked_add(i).ok_or("more than 2^32 vertices");
            out.indices.push([shift(t[0])?, shift(t[1])?, shift(t[2])?]);
        }
    }
    if all_have_normals && !normals.is_empty() {
        out.normals = Some(normals);
    }
    if all_have_uvs && !uvs.is_empty() {
        out.uvs = Some(uvs);
    }
    if out.indices.is_empty() {
        return Err("the file holds no triangles".into());
    }
    Ok(out)
}

/// The OBJ bytes as tobj reads them, counting what it has consumed so that
/// its errors (which carry no position) can name their line.
struct LineCounter<'a> {
    rest: &'a [u8],
    read: usize,
}

impl std::io::Read for LineCounter<'_> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.rest.read(buf)?;
        self.read += n;
        Ok(n)
    }
}

impl std::io::BufRead for LineCounter<'_> {
    fn fill_buf(&mut self) -> std::io::Result<&[u8]> {
        Ok(self.rest)
    }
    fn consume(&mut self, amount: usize) {
        self.rest = &self.rest[amount..];
        self.read += amount;
    }
}

impl LineCounter<'_> {
    /// tobj's error, with the line it stopped at for errors raised while
    /// parsing a line (index errors are raised when an object ends, and
    /// `obj_indices` has already refused those with their own line).
    fn locate(&self, bytes: &[u8], e: tobj::LoadError) -> String {
        use tobj::LoadError::*;
        match e {
            FaceVertexOutOfBounds
            | FaceTexCoordOutOfBounds
            | FaceNormalOutOfBounds
            | FaceColorOutOfBounds
            | InvalidPolygon
            | GenericFailure => e.to_string(),
            _ => {
                let read = &bytes[..self.read];
                let mut line = read.iter().filter(|&&b| b == b'\n').count();
                if read.last().is_some_and(|&b| b != b'\n') {
                    line += 1;
                }
                format!("line {line}: {e}")
            }
        }
    }
}

/// One PLY vertex as read (typed, so a large file costs no per-vertex maps).
struct PlyVertex {
    p: [f32; 3],
    n: [f32; 3],
    uv: [f32; 2],
    /// Bit i set: coordinate i of `p` present; bit 3 + i: of `n`; bit
    /// 6 + i: of `uv`.
    seen: u8,
}

impl ply_rs_bw::ply::PropertyAccess for PlyVertex {
    fn new() -> Self {
        PlyVertex {
            p: [0.0; 3],
            n: [0.0; 3],
            uv: [0.0; 2],
            seen: 0,
        }
    }
    fn set_property(
        &mut self,
        name: &str,
        property: ply_rs_bw::ply::Property,
    ) -> ply_rs_bw::ply::PropertyAccessResult {
        use ply_rs_bw::ply::PropertyAccessResult;
        let slot = match name {
            "x" => 0,
            "y" => 1,
            "z" => 2,
            "nx" => 3,
            "ny" => 4,
            "nz" => 5,
            // The texture-coordinate names Mitsuba's PLY reader accepts.
            "u" | "s" | "texture_u" => 6,
            "v" | "t" | "texture_v" => 7,
            _ => return PropertyAccessResult::Ignored,
        };
        let Some(v) = property.to_f32_lossy() else {
            return PropertyAccessResult::UnsupportedType;
        };
        match slot {
            0..3 => self.p[slot] = v,
            3..6 => self.n[slot - 3] = v,
            _ => self.uv[slot - 6] = v,
        }
        self.seen |= 1 << slot;
        PropertyAccessResult::Set
    }
}

/// One PLY face: its vertex indices (`None` if a negative index was read).
struct PlyFace {
    idx: Option<Vec<u32>>,
}

impl ply_rs_bw::ply::PropertyAccess for PlyFace {
    fn new() -> Self {
        PlyFace { idx: None }
    }
    fn set_property(
        &mut self,
        name: &str,
        property: ply_rs_bw::ply::Property,
    ) -> ply_rs_bw::ply::PropertyAccessResult {
        use ply_rs_bw::ply::PropertyAccessResult;
        if name != "vertex_indices" && name != "vertex_index" {
            return PropertyAccessResult::Ignored;
        }
        match property.to_u32_list() {
            Some(v) => {
                self.idx = Some(v);
                PropertyAccessResult::Set
            }
            None => PropertyAccessResult::UnsupportedType,
        }
    }
}

/// Elements other than vertex and face are read and dropped.
struct PlySkip;

impl ply_rs_bw::ply::PropertyAccess for PlySkip {
    fn new() -> Self {
        PlySkip
    }
}

/// Reads a PLY file (ASCII or binary): `vertex` with x, y, z, optional
/// nx, ny, nz and optional UVs (u, v or s, t or texture_u, texture_v); `face` with `vertex_indices` (or `vertex_index`), polygons
/// fan-triangulated.
pub fn load_ply(path: &Path) -> Result<RawMesh, String> {
    let file = std::fs::File::open(path).map_err(|e| e.to_string())?;
    ply_from_reader(std::io::BufReader::new(file))
}

/// Reads PLY data held in memory, as [`load_ply`] reads a file.
pub fn ply_from_bytes(bytes: &[u8]) -> Result<RawMesh, String> {
    ply_from_reader(bytes)
}

fn ply_from_reader(input: impl std::io::BufRead) -> Result<RawMesh, String> {
    use ply_rs_bw::parser::{Parser, Reader};
    let mut reader = Reader::new(input);
    fn perr(e: impl std::fmt::Display) -> String {
        format!("PLY parse error: {}", one_line(&e.to_string()))
    }
    let vparser = Parser::<PlyVertex>::new();
    let header = vparser.read_header(&mut reader).map_err(perr)?;
    // An element without properties takes no bytes of a binary payload,
    // so the file's length does not bound its count: ply-rs then reads
    // `count` empty entries into memory (the fuzzer's `element face
    // 614891469123651` with no property ran out of memory).
    if header.encoding != ply_rs_bw::ply::Encoding::Ascii
        && let Some(e) = header
            .elements
            .values()
            .find(|e| e.count > 0 && e.properties.is_empty())
    {
        return Err(format!(
            "element '{}' has {} entries but no properties",
            e.name, e.count
        ));
    }
    let mut vertices = None;
    let mut faces = None;
    for (_, element) in &header.elements {
        match element.name.as_str() {
            "vertex" => {
                vertices = Some(
                    vparser
                        .read_payload_for_element(&mut reader, element, &header)
                        .map_err(perr)?,
                )
            }
            "face" => {
                faces = Some(
                    Parser::<PlyFace>::new()
                        .read_payload_for_element(&mut reader, element, &header)
                        .map_err(perr)?,
                )
            }
            _ => {
                Parser::<PlySkip>::new()
                    .read_payload_for_element(&mut reader, element, &header)
                    .map_err(perr)?;
            }
        }
    }
    let vertices = vertices.ok_or("the file has no 'vertex' element")?;
    let faces = faces.ok_or("the file has no 'face' element")?;
    let mut out = RawMesh {
        positions: Vec::with_capacity(vertices.len()),
        normals: None,
        uvs: None,
        indices: Vec::with_capacity(faces.len()),
    };
    let has_normals =
        !vertices.is_empty() && vertices.iter().all(|v| v.seen & 0b111000 == 0b111000);
    for (i, v) in vertices.iter().enumerate() {
        if v.seen & 0b111 != 0b111 {
            return Err(format!("vertex {i} lacks x, y or z"));
        }
        out.positions.push(Vec3::from(v.p));
    }
    if has_normals {
        out.normals = Some(vertices.iter().map(|v| Vec3::from(v.n)).collect());
    }
    if !vertices.is_empty() && vertices.iter().all(|v| v.seen & 0b1100_0000 == 0b1100_0000) {
        out.uvs = Some(vertices.iter().map(|v| Vec2::from(v.uv)).collect());
    }
    drop(vertices);
    // Face indices are u32: a vertex count beyond that could not be indexed.
    let n = u32::try_from(out.positions.len()).map_err(|_| {
        format!(
            "the file has {} vertices; at most {} are supported",
            out.positions.len(),
            u32::MAX
        )
    })?;
    for (i, f) in faces.iter().enumerate() {
        let idx = f
            .idx
            .as_ref()
            .ok_or_else(|| format!("face {i} has no non-negative vertex_indices list"))?;
        if idx.len() < 3 {
            return Err(format!("face {i} has fewer than 3 vertices"));
        }
        if let Some(bad) = idx.iter().find(|&&j| j >= n) {
            return Err(format!(
                "face {i} refers to vertex {bad}, but there are {n}"
            ));
        }
        for k in 1..idx.len() - 1 {
            out.indices.push([idx[0], idx[k], idx[k + 1]]);
        }
    }
    if out.indices.is_empty() {
        return Err("the file holds no faces".into());
    }
    Ok(out)
}

/// Mitsuba's `rectangle`: [-1,1]² in the z = 0 plane, normal +z, with
/// Mitsuba's UVs u = (x + 1)/2, v = (y + 1)/2.
pub fn rectangle() -> RawMesh {
    let corners = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)];
    RawMesh {
        positions: corners.map(|(x, y)| Vec3::new(x, y, 0.0)).to_vec(),
        normals: None,
        uvs: Some(
            corners
                .map(|(x, y)| Vec2::new((x + 1.0) / 2.0, (y + 1.0) / 2.0))
                .to_vec(),
        ),
        indices: vec![[0, 1, 2], [0, 2, 3]],
    }
}

/// Mitsuba's `cube`: `[-1,1]³` with outward face normals; every face maps
/// onto `[0,1]²` in UV as Mitsuba 3's cube does: its four corners, in the
/// order listed, get UVs (0,1), (1,1), (1,0), (0,0).
pub fn cube() -> RawMesh {
    // Per face: the corners (x, y, z), counter-clockwise seen from outside.
    const FACES: [[[f32; 3]; 4]; 6] = [
        [
            [1., -1., -1.],
            [1., -1., 1.],
            [-1., -1., 1.],
            [-1., -1., -1.],
        ], // −y
        [[1., 1., -1.], [-1., 1., -1.], [-1., 1., 1.], [1., 1., 1.]], // +y
        [[1., -1., -1.], [1., 1., -1.], [1., 1., 1.], [1., -1., 1.]], // +x
        [[1., -1., 1.], [1., 1., 1.], [-1., 1., 1.], [-1., -1., 1.]], // +z
        [
            [-1., -1., 1.],
            [-1., 1., 1.],
            [-1., 1., -1.],
            [-1., -1., -1.],
        ], // −x
        [
            [1., 1., -1.],
            [1., -1., -1.],
            [-1., -1., -1.],
            [-1., 1., -1.],
        ], // −z
    ];
    const UVS: [[f32; 2]; 4] = [[0., 1.], [1., 1.], [1., 0.], [0., 0.]];
    let mut m = RawMesh {
        uvs: Some(Vec::new()),
        ..RawMesh::default()
    };
    for face in FACES {
        let base = m.positions.len() as u32;
        m.positions.extend(face.map(Vec3::from));
        m.uvs
            .as_mut()
            .expect("set above")
            .extend(UVS.map(Vec2::from));
        m.indices.push([base, base + 1, base + 2]);
        m.indices.push([base + 3, base, base + 2]);
    }
    m
}

impl RawMesh {
    /// Mirrors the v coordinate (v → 1 − v), Mitsuba's `flip_tex_coords`
    /// (on by default for OBJ files, whose images have their origin at the
    /// bottom, off for PLY).
    pub fn flip_tex_coords(&mut self) {
        for uv in self.uvs.iter_mut().flatten() {
            uv.y = 1.0 - uv.y;
        }
    }

    /// Transforms to world space, validates, and applies Mitsuba's normal
    /// rules: `face_normals` discards vertex normals; without it, a file
    /// without normals gets angle-weighted vertex normals (as Mitsuba 3
    /// computes them).
    pub fn finish(self, to_world: &Mat4, face_normals: bool) -> Result<TriMesh, String> {
        let n = self.positions.len();
        if let Some(i) = self.positions.iter().position(|p| !p.is_finite()) {
            return Err(format!("vertex {i} has a NaN or infinite coordinate"));
        }
        if let Some(i) = self.uvs.iter().flatten().position(|t| !t.is_finite()) {
            return Err(format!("texture coordinate {i} is NaN or infinite"));
        }
        if self.indices.iter().flatten().any(|&i| i as usize >= n) {
            return Err("a triangle refers to a vertex that does not exist".into());
        }
        let positions: Vec<Vec3> = self
            .positions
            .iter()
            .map(|p| to_world.transform_point3(*p))
            .collect();
        let mut indices = Vec::with_capacity(self.indices.len());
        let mut dropped = 0;
        for t in &self.indices {
            let [a, b, c] = t.map(|i| positions[i as usize]);
            let area2 = (b - a).cross(c - a).length();
            if area2 > 0.0 && area2.is_finite() {
                indices.push(*t);
            } else {
                dropped += 1;
            }
        }
        if indices.is_empty() {
            return Err(format!(
                "all {} triangles have zero area",
                self.indices.len()
            ));
        }
        let normals = if face_normals {
            None
        } else if let Some(ns) = self.normals {
            let normal_matrix = Mat3::from_mat4(*to_world).inverse().transpose();
            let mut out = Vec::with_capacity(ns.len());
            for (i, nrm) in ns.iter().enumerate() {
                let w = (normal_matrix * *nrm)
                    .try_normalize()
                    .ok_or_else(|| format!("vertex normal {i} is zero, NaN or infinite"))?;
                out.push(w);
            }
            Some(out)
        } else {
            Some(vertex_normals(&positions, &indices))
        };
        Ok(TriMesh {
            positions,
            normals,
            uvs: self.uvs,
            indices,
            dropped_degenerate: dropped,
        })
    }
}

/// Angle-weighted vertex normals (Thürmer & Wüthrich), which Mitsuba 3 uses
/// when a mesh has none. A vertex no triangle touches gets +z (never used).
fn vertex_normals(positions: &[Vec3], indices: &[[u32; 3]]) -> Vec<Vec3> {
    let mut acc = vec![Vec3::ZERO; positions.len()];
    for t in indices {
        let p = t.map(|i| positions[i as usize]);
        let n = (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero();
        for k in 0..3 {
            let e1 = (p[(k + 1) % 3] - p[k]).normalize_or_zero();
            let e2 = (p[(k + 2) % 3] - p[k]).normalize_or_zero();
            let angle = e1.dot(e2).clamp(-1.0, 1.0).acos();
            acc[t[k] as usize] += n * angle;
        }
    }
    acc.into_iter()
        .map(|n| n.try_normalize().unwrap_or(Vec3::Z))
        .collect()
}

/// A `ply-rs-bw` error on one line. Its message is a paragraph: the line
/// and what failed, then `String: '…'` (the offending text, which spans a
/// line break) and `Error: …` causes, the last of which can be a debug
/// dump of the grammar's expected tokens. Kept: the first line, the
/// offending text and the last cause unless it is such a dump.
fn one_line(message: &str) -> String {
    let lines: Vec<&str> = message.lines().map(str::trim).collect();
    let first = lines.first().copied().unwrap_or_default();
    let mut out = first.trim_end_matches('.').to_string();
    if let Some(text) = lines.iter().find_map(|l| l.strip_prefix("String: '")) {
        out.push_str(&format!(" (at '{}')", text.trim_end_matches('\'').trim()));
    }
    let cause = lines.iter().rev().find_map(|l| l.strip_prefix("Error: "));
    if let Some(cause) = cause.filter(|c| !c.contains(" { ")) {
        out.push_str(&format!(": {cause}"));
    }
    out
}
