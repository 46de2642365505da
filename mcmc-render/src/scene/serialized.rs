//! Mitsuba's `.serialized` meshes (`<shape type="serialized">`).
//!
//! The format, as Mitsuba 3's `serialized` plugin documents it (all
//! little-endian): per shape a `u16` format id `0x041C` and a `u16`
//! version (3 or 4), then a zlib stream holding a `u32` of flags, in
//! version 4 the shape's NUL-terminated name, the `u64` vertex and
//! triangle counts, the positions, then optionally normals, texture
//! coordinates and vertex colours (`f32` or `f64` by the flags), and
//! `u32` triangle indices. Several shapes are concatenated; the file ends
//! with the offset of each shape (`u64` in version 4, `u32` in version 3)
//! and their `u32` count, which `shape_index` uses.
//!
//! Nothing is allocated on the file's word: the counts are checked
//! against what the compressed bytes left in the file could decompress
//! to, and arrays grow as their data arrives, so a truncated or lying
//! file is refused before it costs memory.

use super::mesh::RawMesh;
use flate2::read::ZlibDecoder;
use glam::{Vec2, Vec3};
use std::fs::File;
use std::io::{BufReader, Read, Seek, SeekFrom};
use std::path::Path;

/// The format id every shape starts with.
const FORMAT_ID: u16 = 0x041C;

/// Per-vertex normals follow the positions.
const HAS_NORMALS: u32 = 0x0001;
/// Per-vertex texture coordinates follow.
const HAS_TEXCOORDS: u32 = 0x0002;
/// Per-vertex colours follow.
const HAS_COLORS: u32 = 0x0008;
/// Shade with face normals (as the plugin's `face_normals="true"`).
const FACE_NORMALS: u32 = 0x0010;
/// Floating-point data in `f32`.
const SINGLE_PRECISION: u32 = 0x1000;
/// Floating-point data in `f64`.
const DOUBLE_PRECISION: u32 = 0x2000;
/// Every flag the format defines with a known layout (`0x0004`, tangents,
/// is reserved and its data layout undefined, so it is refused).
const KNOWN_FLAGS: u32 =
    HAS_NORMALS | HAS_TEXCOORDS | HAS_COLORS | FACE_NORMALS | SINGLE_PRECISION | DOUBLE_PRECISION;

/// DEFLATE cannot expand data by more than about 1032:1 (a 258-byte match
/// costs at least two bits); a count that needs more than this many bytes
/// per compressed byte left in the file is a lie.
const MAX_INFLATION: u128 = 1032;

/// Longest shape name read (names are short labels; a longer one means a
/// missing terminator).
const MAX_NAME: usize = 64 * 1024;

/// Bytes read per step when an array is filled (so memory follows data).
const CHUNK: usize = 1 << 16;

/// A mesh of a `.serialized` file.
pub struct SerializedMesh {
    /// Positions, normals and texture coordinates (when the file has
    /// them; UVs as stored, Mitsuba does not flip them) and triangles.
    pub mesh: RawMesh,
    /// The file asks for face normals (flag `0x0010`). Mitsuba 3 documents
    /// this flag as `face_normals="true"`; Mitsuba 0.6, which wrote these
    /// files, shaded such meshes flat.
    pub face_normals: bool,
}

/// Reads shape `shape_index` of the `.serialized` file `path`. Errors are
/// one line (the caller adds the file name and scene location).
pub fn load_serialized(path: &Path, shape_index: u32) -> Result<SerializedMesh, String> {
    let mut file = File::open(path).map_err(|e| e.to_string())?;
    let size = file.metadata().map_err(|e| e.to_string())?.len();
    read_serialized(&mut file, size, shape_index)
}

/// Reads shape `shape_index` of a `.serialized` file held in memory, as
/// [`load_serialized`] reads a file.
pub fn serialized_from_bytes(bytes: &[u8], shape_index: u32) -> Result<SerializedMesh, String> {
    let size = bytes.len() as u64;
    read_serialized(&mut std::io::Cursor::new(bytes), size, shape_index)
}

/// Reads shape `shape_index` from `file`, `size` bytes long.
fn read_serialized<R: Read + Seek>(
    file: &mut R,
    size: u64,
    shape_index: u32,
) -> Result<SerializedMesh, String> {
    let version = read_header(file, size)?;
    let (start, end) = if shape_index == 0 {
        (0, size)
    } else {
        shape_range(file, size, version, shape_index)?
    };
    if start != 0 {
        file.seek(SeekFrom::Start(start))
            .map_err(|e| e.to_string())?;
        let here = read_header(file, size - start)?;
        if here != version {
            return Err(format!(
                "shape {shape_index} (at byte {start}) has version {here}, the file's first shape {version}"
            ));
        }
    }
    // The compressed bytes this shape can use: up to the next shape's
    // offset, or to the end of the file.
    let compressed = end.saturating_sub(start + 4);
    let reader = BufReader::new(file.take(compressed));
    let mut z = Inflated {
        inner: ZlibDecoder::new(reader),
    };
    read_shape(&mut z, version, compressed)
}

/// Reads and checks the 4-byte header; returns the version.
fn read_header(file: &mut impl Read, left: u64) -> Result<u16, String> {
    if left < 4 {
        return Err(format!(
            "truncated: {left} bytes, shorter than the 4-byte header"
        ));
    }
    let mut h = [0u8; 4];
    file.read_exact(&mut h).map_err(|e| e.to_string())?;
    let format = u16::from_le_bytes([h[0], h[1]]);
    let version = u16::from_le_bytes([h[2], h[3]]);
    if format != FORMAT_ID {
        return Err(format!(
            "not a Mitsuba serialized mesh (format id 0x{format:04x}, expected 0x{FORMAT_ID:04x})"
        ));
    }
    if version != 3 && version != 4 {
        return Err(format!(
            "unsupported serialized version {version} (versions 3 and 4 are read)"
        ));
    }
    Ok(version)
}

/// The byte range of shape `index` from the end-of-file dictionary.
fn shape_range<R: Read + Seek>(
    file: &mut R,
    size: u64,
    version: u16,
    index: u32,
) -> Result<(u64, u64), String> {
    let word: u64 = if version == 4 { 8 } else { 4 };
    if size < 8 {
        return Err(format!(
            "truncated: {size} bytes cannot hold a shape and the end-of-file dictionary"
        ));
    }
    file.seek(SeekFrom::Start(size - 4))
        .map_err(|e| e.to_string())?;
    let count = u64::from(read_u32(file).map_err(|e| e.to_string())?);
    if u64::from(index) >= count {
        return Err(format!(
            "shape_index {index} is out of range: the file holds {count} shape(s)"
        ));
    }
    // The dictionary sits after the first shape's header at least.
    let table = count * word + 4;
    if table > size - 4 {
        return Err(format!(
            "the end-of-file dictionary claims {count} shapes, more than a file of {size} bytes holds"
        ));
    }
    let table_start = size - table;
    let offset_at = |file: &mut R, i: u64| -> Result<u64, String> {
        file.seek(SeekFrom::Start(table_start + i * word))
            .map_err(|e| e.to_string())?;
        if version == 4 {
            let mut b = [0u8; 8];
            file.read_exact(&mut b).map_err(|e| e.to_string())?;
            Ok(u64::from_le_bytes(b))
        } else {
            Ok(u64::from(read_u32(file).map_err(|e| e.to_string())?))
        }
    };
    let start = offset_at(file, u64::from(index))?;
    let end = if u64::from(index) + 1 < count {
        offset_at(file, u64::from(index) + 1)?
    } else {
        table_start
    };
    if start < 4 || start.saturating_add(4) > end || end > table_start {
        return Err(format!(
            "the end-of-file dictionary places shape {index} at bytes {start}..{end}, outside the {table_start} bytes of shape data"
        ));
    }
    Ok((start, end))
}

fn read_u32(r: &mut impl Read) -> std::io::Result<u32> {
    let mut b = [0u8; 4];
    r.read_exact(&mut b)?;
    Ok(u32::from_le_bytes(b))
}

/// The decompressed stream, with reads that name what was being read
/// when the data ended or was corrupt.
struct Inflated<R: Read> {
    inner: ZlibDecoder<R>,
}

impl<R: Read> Inflated<R> {
    fn exact(&mut self, buf: &mut [u8], what: &str) -> Result<(), String> {
        self.inner.read_exact(buf).map_err(|e| match e.kind() {
            std::io::ErrorKind::UnexpectedEof => {
                format!("truncated: the compressed data ends in the {what}")
            }
            _ => format!("corrupt compressed data in the {what}: {e}"),
        })
    }

    fn u32(&mut self, what: &str) -> Result<u32, String> {
        let mut b = [0u8; 4];
        self.exact(&mut b, what)?;
        Ok(u32::from_le_bytes(b))
    }

    fn u64(&mut self, what: &str) -> Result<u64, String> {
        let mut b = [0u8; 8];
        self.exact(&mut b, what)?;
        Ok(u64::from_le_bytes(b))
    }

    /// `count` little-endian values of `width` bytes, decoded by `decode`;
    /// the vector grows as the data arrives.
    fn array<T>(
        &mut self,
        count: usize,
        width: usize,
        what: &str,
        decode: impl Fn(&[u8]) -> T,
    ) -> Result<Vec<T>, String> {
        let mut out = Vec::with_capacity(count.min(CHUNK));
        let mut buf = vec![0u8; CHUNK - CHUNK % width];
        let mut left = count;
        while left > 0 {
            let n = left.min(buf.len() / width);
            self.exact(&mut buf[..n * width], what)?;
            out.extend(buf[..n * width].chunks_exact(width).map(&decode));
            left -= n;
        }
        Ok(out)
    }

    /// `count` floats (as `f32`), stored in single or double precision.
    fn floats(&mut self, count: usize, double: bool, what: &str) -> Result<Vec<f32>, String> {
        if double {
            // Mitsuba stores meshes in single precision too.
            self.array(count, 8, what, |b| {
                f64::from_le_bytes(b.try_into().expect("8 bytes")) as f32
            })
        } else {
            self.array(count, 4, what, |b| {
                f32::from_le_bytes(b.try_into().expect("4 bytes"))
            })
        }
    }
}

fn read_shape<R: Read>(
    z: &mut Inflated<R>,
    version: u16,
    compressed: u64,
) -> Result<SerializedMesh, String> {
    let flags = z.u32("flags")?;
    if flags & !KNOWN_FLAGS != 0 {
        return Err(format!(
            "unknown flags 0x{:x} (known: 0x{KNOWN_FLAGS:x})",
            flags & !KNOWN_FLAGS
        ));
    }
    if flags & SINGLE_PRECISION != 0 && flags & DOUBLE_PRECISION != 0 {
        return Err("the flags ask for both single and double precision".into());
    }
    // Neither precision flag: single, as Mitsuba reads it.
    let double = flags & DOUBLE_PRECISION != 0;
    if version == 4 {
        // The shape's name: skipped, but bounded.
        let mut len = 0;
        loop {
            let mut c = [0u8; 1];
            z.exact(&mut c, "shape name")?;
            if c[0] == 0 {
                break;
            }
            len += 1;
            if len > MAX_NAME {
                return Err(format!(
                    "the shape name is longer than {MAX_NAME} bytes (no terminator?)"
                ));
            }
        }
    }
    let vertices = z.u64("vertex count")?;
    let triangles = z.u64("triangle count")?;
    if vertices == 0 || triangles == 0 {
        return Err(format!(
            "the shape holds {vertices} vertices and {triangles} triangles: nothing to render"
        ));
    }
    if vertices > u64::from(u32::MAX) {
        return Err(format!(
            "{vertices} vertices: more than 2^32 - 1 (64-bit indices) are not supported"
        ));
    }
    let float = if double { 8 } else { 4 };
    let per_vertex = 3
        + 3 * u128::from(flags & HAS_NORMALS != 0)
        + 2 * u128::from(flags & HAS_TEXCOORDS != 0)
        + 3 * u128::from(flags & HAS_COLORS != 0);
    let bytes = u128::from(vertices) * per_vertex * float + u128::from(triangles) * 12;
    if bytes > MAX_INFLATION * u128::from(compressed) {
        return Err(format!(
            "the shape claims {vertices} vertices and {triangles} triangles ({bytes} bytes), more than the {compressed} compressed bytes in the file can hold"
        ));
    }
    // What the mesh will hold in memory: positions, normals, indices.
    crate::resources::check_memory(
        &format!("mesh of {vertices} vertices and {triangles} triangles"),
        u128::from(vertices) * 24 + u128::from(triangles) * 12,
    )?;
    let triangles_len = usize::try_from(triangles)
        .ok()
        .and_then(|t| t.checked_mul(3))
        .ok_or_else(|| format!("{triangles} triangles do not fit in memory"))?;
    // Fits: vertices ≤ u32::MAX.
    let n = vertices as usize;
    let positions = z.floats(3 * n, double, "vertex positions")?;
    let normals = if flags & HAS_NORMALS != 0 {
        Some(z.floats(3 * n, double, "vertex normals")?)
    } else {
        None
    };
    let uvs = if flags & HAS_TEXCOORDS != 0 {
        let flat = z.floats(2 * n, double, "texture coordinates")?;
        Some(flat.chunks_exact(2).map(Vec2::from_slice).collect())
    } else {
        None
    };
    // Vertex colours are read past (Mitsuba 3 skips them too).
    if flags & HAS_COLORS != 0 {
        z.floats(3 * n, double, "vertex colours")?;
    }
    let flat = z.array(triangles_len, 4, "triangle indices", |b| {
        u32::from_le_bytes(b.try_into().expect("4 bytes"))
    })?;
    if let Some(i) = flat.iter().position(|&j| u64::from(j) >= vertices) {
        return Err(format!(
            "triangle {} refers to vertex {}, but there are {vertices}",
            i / 3,
            flat[i]
        ));
    }
    let to_vec3 = |v: Vec<f32>| -> Vec<Vec3> { v.chunks_exact(3).map(Vec3::from_slice).collect() };
    Ok(SerializedMesh {
        mesh: RawMesh {
            positions: to_vec3(positions),
            normals: normals.map(to_vec3),
            uvs,
            indices: flat.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect(),
        },
        face_normals: flags & FACE_NORMALS != 0,
    })
}
