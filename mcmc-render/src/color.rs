//! Linear RGB radiance and throughput values.

use std::ops::{Add, AddAssign, Div, Mul, MulAssign, Sub};

/// Linear-sRGB triple used for radiance, throughput and reflectance.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Rgb {
    /// Red channel.
    pub r: f32,
    /// Green channel.
    pub g: f32,
    /// Blue channel.
    pub b: f32,
}

impl Rgb {
    /// Black (all channels zero).
    pub const BLACK: Rgb = Rgb::new(0.0, 0.0, 0.0);
    /// White (all channels one).
    pub const WHITE: Rgb = Rgb::new(1.0, 1.0, 1.0);

    /// Builds a colour from its three channels.
    pub const fn new(r: f32, g: f32, b: f32) -> Self {
        Rgb { r, g, b }
    }

    /// A grey value with every channel equal to `v`.
    pub const fn splat(v: f32) -> Self {
        Rgb::new(v, v, v)
    }

    /// Luminance with the sRGB/Rec.709 weights (pbrt's constants).
    pub fn luminance(self) -> f32 {
        0.212_671 * self.r + 0.715_160 * self.g + 0.072_169 * self.b
    }

    /// True when every channel is exactly zero.
    #[inline]
    pub fn is_black(self) -> bool {
        // `&`, not `&&`: three compares and no branches (the channels are
        // already loaded, so short-circuiting saves nothing).
        (self.r == 0.0) & (self.g == 0.0) & (self.b == 0.0)
    }

    /// True when every channel is finite (no NaN, no infinity).
    #[inline]
    pub fn is_finite(self) -> bool {
        // Branch-free, as in `is_black`.
        self.r.is_finite() & self.g.is_finite() & self.b.is_finite()
    }

    /// Largest channel.
    pub fn max_channel(self) -> f32 {
        self.r.max(self.g).max(self.b)
    }

    /// Smallest of the three channels.
    pub fn min_channel(self) -> f32 {
        self.r.min(self.g).min(self.b)
    }

    /// Channel-wise map.
    pub fn map(self, f: impl Fn(f32) -> f32) -> Self {
        Rgb::new(f(self.r), f(self.g), f(self.b))
    }

    /// The channels as an array.
    pub fn to_array(self) -> [f32; 3] {
        [self.r, self.g, self.b]
    }
}

impl Add for Rgb {
    type Output = Rgb;
    fn add(self, o: Rgb) -> Rgb {
        Rgb::new(self.r + o.r, self.g + o.g, self.b + o.b)
    }
}
impl AddAssign for Rgb {
    fn add_assign(&mut self, o: Rgb) {
        *self = *self + o;
    }
}
impl Sub for Rgb {
    type Output = Rgb;
    fn sub(self, o: Rgb) -> Rgb {
        Rgb::new(self.r - o.r, self.g - o.g, self.b - o.b)
    }
}
impl Mul for Rgb {
    type Output = Rgb;
    fn mul(self, o: Rgb) -> Rgb {
        Rgb::new(self.r * o.r, self.g * o.g, self.b * o.b)
    }
}
impl Mul<f32> for Rgb {
    type Output = Rgb;
    fn mul(self, s: f32) -> Rgb {
        Rgb::new(self.r * s, self.g * s, self.b * s)
    }
}
impl MulAssign for Rgb {
    fn mul_assign(&mut self, o: Rgb) {
        *self = *self * o;
    }
}
impl MulAssign<f32> for Rgb {
    fn mul_assign(&mut self, s: f32) {
        *self = *self * s;
    }
}
impl Div<f32> for Rgb {
    type Output = Rgb;
    fn div(self, s: f32) -> Rgb {
        Rgb::new(self.r / s, self.g / s, self.b / s)
    }
}
