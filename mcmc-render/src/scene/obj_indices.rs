//! A check of an OBJ file's face indices before tobj reads it.
//!
//! tobj 4.0.5 resolves a relative (negative) index that reaches before the
//! first element to a huge `usize`, then multiplies it (`vt * 2 + 1`,
//! `vn * 3 + 2`): a panic where overflow checks are on, a wrapped and
//! silently wrong texture coordinate or normal in release builds (the `obj`
//! fuzz target's findings). Index 0 becomes its "missing" marker, so a
//! `1/0` corner silently loses its texture coordinate. Every index of every
//! `f` and `l` line is checked here first, so tobj only sees indices that
//! name an element the file has.

/// What the three slots of a face corner (`v/vt/vn`) index.
const KINDS: [&str; 3] = ["vertex", "texture coordinate", "normal"];
/// Their plurals, for the counts in messages.
const PLURALS: [&str; 3] = ["vertices", "texture coordinates", "normals"];

/// Refuses the first face index that does not name an element of the file:
/// not an integer, 0, a relative index reaching before the first element
/// read so far (tobj resolves relative indices against the counts read so
/// far), or an absolute one beyond the file's count. The error is one line,
/// `line N: …`, naming the corner and the value.
///
/// It reads bytes, not text: a line that is not UTF-8 is read lossily here
/// (refused later, with its line, by the reader), so that an index error
/// before it is still the one reported.
pub(crate) fn check_face_indices(bytes: &[u8]) -> Result<(), String> {
    // Elements read so far, per kind.
    let mut count = [0usize; 3];
    // The largest absolute index per kind, with its line and corner, checked
    // against the file's totals at the end (tobj exports faces when an
    // object ends, so an index may name a vertex listed after the face).
    let mut largest: [Option<(usize, usize, String)>; 3] = [None, None, None];
    for (number, line) in bytes.split(|&b| b == b'\n').enumerate() {
        let number = number + 1;
        let line = String::from_utf8_lossy(line);
        let mut words = line.split_whitespace();
        match words.next() {
            Some("v") => count[0] += 1,
            Some("vt") => count[1] += 1,
            Some("vn") => count[2] += 1,
            Some(keyword @ ("f" | "l")) => {
                let mut corners = 0;
                for corner in words {
                    corners += 1;
                    for (slot, part) in corner.split('/').enumerate() {
                        let Some(&kind) = KINDS.get(slot) else {
                            return Err(format!(
                                "line {number}: face corner '{corner}' has more than three indices"
                            ));
                        };
                        if part.is_empty() {
                            continue;
                        }
                        let value: isize = part.parse().map_err(|_| {
                            format!(
                                "line {number}: {kind} index '{part}' of face corner '{corner}' is not an integer"
                            )
                        })?;
                        let magnitude = value.unsigned_abs();
                        if value == 0 {
                            return Err(format!(
                                "line {number}: {kind} index 0 in face corner '{corner}' (OBJ indices start at 1)"
                            ));
                        } else if value < 0 && magnitude > count[slot] {
                            return Err(format!(
                                "line {number}: relative {kind} index {value} in face corner '{corner}' reaches before the first {kind} ({} read so far)",
                                count[slot]
                            ));
                        } else if value > 0
                            && largest[slot].as_ref().is_none_or(|l| magnitude > l.0)
                        {
                            largest[slot] = Some((magnitude, number, corner.to_string()));
                        }
                    }
                }
                if corners == 0 {
                    return Err(format!("line {number}: '{keyword}' with no indices"));
                }
            }
            _ => {}
        }
    }
    for (slot, largest) in largest.iter().enumerate() {
        if let Some((value, number, corner)) = largest
            && *value > count[slot]
        {
            return Err(format!(
                "line {number}: {} index {value} in face corner '{corner}', but the file has {} {}",
                KINDS[slot], count[slot], PLURALS[slot]
            ));
        }
    }
    Ok(())
}
