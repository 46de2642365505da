//! Tiles of stratified MCMC (spec seed003 §8.2): one chain per pixel `s`,
//! confined to the pixels of its tile `N_s`, a fixed set of offsets around
//! `s` clipped to the image.

use crate::color::Rgb;

/// Most pixels a tile shape may hold (the 3×3 square).
pub const MAX_TILE_PIXELS: usize = 9;

crate::choice! {
    /// The shape of a tile.
    pub enum TileShape {
        /// The t-shaped ("plus") five-pixel tile of Gruson et al. 2020 (Eq. 3.34).
        Plus = "plus",
        /// The 3×3 square around the pixel.
        Square = "square",
    }
}

impl TileShape {
    /// The pixel offsets of the tile, its own pixel first (slot 0). The set
    /// is symmetric (`o` in it implies `−o`), so pixel `j` lies in the
    /// tiles `j − o` for every offset `o`.
    pub fn offsets(self) -> &'static [(i32, i32)] {
        match self {
            TileShape::Plus => &[(0, 0), (-1, 0), (1, 0), (0, -1), (0, 1)],
            TileShape::Square => &[
                (0, 0),
                (-1, -1),
                (0, -1),
                (1, -1),
                (-1, 0),
                (1, 0),
                (-1, 1),
                (0, 1),
                (1, 1),
            ],
        }
    }
}

/// The RGB values of one state at each slot of a tile (zero at slots
/// outside the image) and their summed luminance, the tile target
/// `π̃_s = Σ_q lum f(T_q(x))` (spec §8.5).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TileValues {
    /// `f` at each slot.
    pub f: [Rgb; MAX_TILE_PIXELS],
    /// `Σ_q lum f_q`.
    pub total: f64,
    /// The state's sub-pixel offset `(o_x, o_y)`: slot `q`'s path goes
    /// through raster position `q + o` (where a non-box filter spreads it).
    pub offset: [f32; 2],
}

/// The tiles of an image: one per pixel, row-major, each made of the
/// shape's offsets around its pixel that fall inside the image.
#[derive(Clone, Debug)]
pub struct Tiling {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    offsets: &'static [(i32, i32)],
}

impl Tiling {
    /// The tiling of a `width × height` image by `shape`.
    pub fn new(width: u32, height: u32, shape: TileShape) -> Self {
        Tiling {
            width,
            height,
            offsets: shape.offsets(),
        }
    }

    /// Number of tiles (= pixels).
    pub fn tiles(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// Slots per tile (the shape's size).
    pub fn slots(&self) -> usize {
        self.offsets.len()
    }

    /// The pixel at offset `o` from pixel index `s`, if inside the image.
    fn shifted(&self, s: usize, o: (i32, i32)) -> Option<usize> {
        let w = self.width as i64;
        let (x, y) = ((s as i64) % w + o.0 as i64, (s as i64) / w + o.1 as i64);
        (x >= 0 && y >= 0 && x < w && y < self.height as i64).then(|| (y * w + x) as usize)
    }

    /// The pixel (column, row) of each slot of tile `s`, `None` outside the image.
    pub fn slot_pixels(&self, s: usize) -> [Option<(u32, u32)>; MAX_TILE_PIXELS] {
        let mut out = [None; MAX_TILE_PIXELS];
        for (k, &o) in self.offsets.iter().enumerate() {
            out[k] = self.shifted(s, o).map(|j| {
                (
                    (j % self.width as usize) as u32,
                    (j / self.width as usize) as u32,
                )
            });
        }
        out
    }

    /// `(slot, pixel index)` of the pixels of tile `s` inside the image.
    pub fn pixels(&self, s: usize) -> impl Iterator<Item = (usize, usize)> + '_ {
        self.offsets
            .iter()
            .enumerate()
            .filter_map(move |(k, &o)| self.shifted(s, o).map(|j| (k, j)))
    }

    /// `(tile, slot)` of the tiles containing pixel `j` (`N(j)`, spec §8.2).
    pub fn covering(&self, j: usize) -> impl Iterator<Item = (usize, usize)> + '_ {
        self.offsets
            .iter()
            .enumerate()
            .filter_map(move |(k, &(dx, dy))| self.shifted(j, (-dx, -dy)).map(|s| (s, k)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn covering_inverts_pixels() {
        for shape in [TileShape::Plus, TileShape::Square] {
            let t = Tiling::new(5, 4, shape);
            for j in 0..t.tiles() {
                for (s, k) in t.covering(j) {
                    assert!(t.pixels(s).any(|p| p == (k, j)));
                }
            }
            for s in 0..t.tiles() {
                for (k, j) in t.pixels(s) {
                    assert!(t.covering(j).any(|c| c == (s, k)));
                }
            }
        }
        let t = Tiling::new(5, 4, TileShape::Plus);
        assert_eq!(t.covering(0).count(), 3);
        assert_eq!(t.covering(6).count(), 5);
    }
}
