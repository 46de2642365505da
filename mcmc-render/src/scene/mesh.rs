//! Triangle meshes: OBJ (tobj) and PLY (ply-rs-bw) loading, Mitsuba's
//! built-in rectangle and cube, transformation to world space, validation
//! (NaN vertices refused, zero-area triangles dropped and counted) and
//! Mitsuba's vertex-normal rules.

use glam::{Mat3, Mat4, Vec3};
use std::path::Path;

/// A mesh as read from a file, in object space.
#[derive(Clone, Debug, Default)]
pub struct RawMesh {
    /// Vertex positions.
    pub positions: Vec<Vec3>,
    /// Per-vertex normals, when the file has them.
    pub normals: Option<Vec<Vec3>>,
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
    /// Triangles (degenerate ones already removed).
    pub indices: Vec<[u32; 3]>,
    /// How many zero-area triangles were dropped.
    pub dropped_degenerate: usize,
}

/// Reads a Wavefront OBJ file (all objects merged, polygons triangulated).
pub fn load_obj(path: &Path) -> Result<RawMesh, String> {
    let opts = tobj::LoadOptions {
        triangulate: true,
        single_index: true,
        ignore_points: true,
        ignore_lines: true,
    };
    let (models, _materials) = tobj::load_obj(path, &opts).map_err(|e| e.to_string())?;
    let mut out = RawMesh::default();
    let mut all_have_normals = true;
    let mut normals = Vec::new();
    for m in &models {
        let mesh = &m.mesh;
        let base = out.positions.len() as u32;
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
        out.indices.extend(
            mesh.indices
                .chunks_exact(3)
                .map(|t| [base + t[0], base + t[1], base + t[2]]),
        );
    }
    if all_have_normals && !normals.is_empty() {
        out.normals = Some(normals);
    }
    if out.indices.is_empty() {
        return Err("the file holds no triangles".into());
    }
    Ok(out)
}

/// Reads a PLY file (ASCII or binary): `vertex` with x, y, z and optional
/// nx, ny, nz; `face` with `vertex_indices` (or `vertex_index`), polygons
/// fan-triangulated.
pub fn load_ply(path: &Path) -> Result<RawMesh, String> {
    use ply_rs_bw::parser::Parser;
    use ply_rs_bw::ply::DefaultElement;
    let file = std::fs::File::open(path).map_err(|e| e.to_string())?;
    let mut reader = std::io::BufReader::new(file);
    let ply = Parser::<DefaultElement>::new()
        .read_ply(&mut reader)
        .map_err(|e| format!("PLY parse error: {e}"))?;
    let vertices = ply
        .payload
        .get("vertex")
        .ok_or("the file has no 'vertex' element")?;
    let faces = ply
        .payload
        .get("face")
        .ok_or("the file has no 'face' element")?;
    let scalar = |e: &DefaultElement, k: &str| e.get(k).and_then(|p| p.to_f32_lossy());
    let mut out = RawMesh::default();
    let mut normals = Vec::with_capacity(vertices.len());
    let mut has_normals = true;
    for (i, v) in vertices.iter().enumerate() {
        let p = match (scalar(v, "x"), scalar(v, "y"), scalar(v, "z")) {
            (Some(x), Some(y), Some(z)) => Vec3::new(x, y, z),
            _ => return Err(format!("vertex {i} lacks x, y or z")),
        };
        out.positions.push(p);
        match (scalar(v, "nx"), scalar(v, "ny"), scalar(v, "nz")) {
            (Some(x), Some(y), Some(z)) => normals.push(Vec3::new(x, y, z)),
            _ => has_normals = false,
        }
    }
    if has_normals && !normals.is_empty() {
        out.normals = Some(normals);
    }
    let n = out.positions.len() as u32;
    for (i, f) in faces.iter().enumerate() {
        let idx = f
            .get("vertex_indices")
            .or_else(|| f.get("vertex_index"))
            .and_then(|p| p.to_u32_list())
            .ok_or_else(|| format!("face {i} has no integer vertex_indices list"))?;
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

/// Mitsuba's `rectangle`: [-1,1]² in the z = 0 plane, normal +z.
pub fn rectangle() -> RawMesh {
    RawMesh {
        positions: vec![
            Vec3::new(-1.0, -1.0, 0.0),
            Vec3::new(1.0, -1.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(-1.0, 1.0, 0.0),
        ],
        normals: None,
        indices: vec![[0, 1, 2], [0, 2, 3]],
    }
}

/// Mitsuba's `cube`: [-1,1]³ with outward face normals.
pub fn cube() -> RawMesh {
    let mut m = RawMesh::default();
    for axis in 0..3 {
        for sign in [-1.0f32, 1.0] {
            let mut n = Vec3::ZERO;
            n[axis] = sign;
            // Two tangents with t1 × t2 = n, so the winding faces outwards.
            let mut t1 = Vec3::ZERO;
            t1[(axis + 1) % 3] = 1.0;
            let t2 = n.cross(t1);
            let base = m.positions.len() as u32;
            for (a, b) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
                m.positions.push(n + t1 * a + t2 * b);
            }
            m.indices.push([base, base + 1, base + 2]);
            m.indices.push([base, base + 2, base + 3]);
        }
    }
    m
}

impl RawMesh {
    /// Transforms to world space, validates, and applies Mitsuba's normal
    /// rules: `face_normals` discards vertex normals; without it, a file
    /// without normals gets angle-weighted vertex normals (as Mitsuba 3
    /// computes them).
    pub fn finish(self, to_world: &Mat4, face_normals: bool) -> Result<TriMesh, String> {
        let n = self.positions.len();
        if let Some(i) = self.positions.iter().position(|p| !p.is_finite()) {
            return Err(format!("vertex {i} has a NaN or infinite coordinate"));
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
