//! Textures: a glTF image decoded to linear RGB texels, with its sampler (wrap modes,
//! nearest or bilinear magnification) and `KHR_texture_transform`. A base-colour texel is
//! a spectral input like any colour: the renderer upsamples factor × texel with the same
//! RGB → spectrum model as plain factors (Smits), per hit.

use std::sync::Arc;

use glam::{Mat3, Vec2, Vec3};

/// Largest texture side decoded (a guard against image bombs).
pub const MAX_TEXTURE_SIDE: u32 = 8192;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Wrap {
    Repeat,
    Clamp,
    Mirror,
}

/// Decoded texels, linear RGB (sRGB-decoded for colour textures), row 0 at v = 0.
#[derive(Debug, PartialEq)]
pub struct Texture {
    pub width: u32,
    pub height: u32,
    pub texels: Vec<[f32; 3]>,
    /// Alpha per texel (linear), kept only where a cut-out needs it; empty: opaque.
    pub alpha: Vec<f32>,
    pub wrap: (Wrap, Wrap),
    /// Bilinear magnification (else nearest).
    pub linear: bool,
}

/// A texture as a material uses it: which UV set and the UV transform.
#[derive(Clone, Debug, PartialEq)]
pub struct TextureRef {
    pub texture: Arc<Texture>,
    /// `KHR_texture_transform` as a matrix on (u, v, 1).
    pub transform: Mat3,
}

fn wrap(x: i64, n: i64, mode: Wrap) -> i64 {
    match mode {
        Wrap::Repeat => x.rem_euclid(n),
        Wrap::Clamp => x.clamp(0, n - 1),
        Wrap::Mirror => {
            let p = x.rem_euclid(2 * n);
            if p < n { p } else { 2 * n - 1 - p }
        }
    }
}

impl Texture {
    fn texel(&self, x: i64, y: i64) -> Vec3 {
        let (w, h) = (self.width as i64, self.height as i64);
        let (x, y) = (wrap(x, w, self.wrap.0), wrap(y, h, self.wrap.1));
        Vec3::from(self.texels[(y * w + x) as usize])
    }

    fn alpha_texel(&self, x: i64, y: i64) -> f32 {
        let (w, h) = (self.width as i64, self.height as i64);
        let (x, y) = (wrap(x, w, self.wrap.0), wrap(y, h, self.wrap.1));
        self.alpha[(y * w + x) as usize]
    }

    /// The alpha at texture coordinates `uv`, filtered as the colour is (1 without an
    /// alpha channel; 0 at non-finite coordinates, as the colour is black there).
    pub fn sample_alpha(&self, uv: Vec2) -> f32 {
        if self.alpha.is_empty() {
            return 1.0;
        }
        if !uv.is_finite() {
            return 0.0;
        }
        let (fx, fy) = (uv.x * self.width as f32, uv.y * self.height as f32);
        if !self.linear {
            return self.alpha_texel(fx.floor() as i64, fy.floor() as i64);
        }
        let (x, y) = (fx - 0.5, fy - 0.5);
        let (x0, y0) = (x.floor(), y.floor());
        let (tx, ty) = (x - x0, y - y0);
        let (x0, y0) = (x0 as i64, y0 as i64);
        let lerp = |a: f32, b: f32, t: f32| a + (b - a) * t;
        let top = lerp(self.alpha_texel(x0, y0), self.alpha_texel(x0 + 1, y0), tx);
        let bottom = lerp(
            self.alpha_texel(x0, y0 + 1),
            self.alpha_texel(x0 + 1, y0 + 1),
            tx,
        );
        lerp(top, bottom, ty)
    }

    /// The colour at texture coordinates `uv`.
    pub fn sample(&self, uv: Vec2) -> [f32; 3] {
        if !uv.is_finite() || self.texels.is_empty() {
            return [0.0; 3];
        }
        let (fx, fy) = (uv.x * self.width as f32, uv.y * self.height as f32);
        if !self.linear {
            return self.texel(fx.floor() as i64, fy.floor() as i64).to_array();
        }
        let (x, y) = (fx - 0.5, fy - 0.5);
        let (x0, y0) = (x.floor(), y.floor());
        let (tx, ty) = (x - x0, y - y0);
        let (x0, y0) = (x0 as i64, y0 as i64);
        let top = self.texel(x0, y0).lerp(self.texel(x0 + 1, y0), tx);
        let bottom = self.texel(x0, y0 + 1).lerp(self.texel(x0 + 1, y0 + 1), tx);
        top.lerp(bottom, ty).to_array()
    }
}

impl TextureRef {
    pub fn sample(&self, uv: Vec2) -> [f32; 3] {
        let t = self.transform * uv.extend(1.0);
        self.texture.sample(Vec2::new(t.x, t.y))
    }

    pub fn sample_alpha(&self, uv: Vec2) -> f32 {
        let t = self.transform * uv.extend(1.0);
        self.texture.sample_alpha(Vec2::new(t.x, t.y))
    }
}

/// `KHR_texture_transform`: translation · rotation · scale, as the extension defines.
pub fn uv_transform(offset: [f32; 2], rotation: f32, scale: [f32; 2]) -> Mat3 {
    let t = Mat3::from_cols(Vec3::X, Vec3::Y, Vec3::new(offset[0], offset[1], 1.0));
    let (s, c) = rotation.sin_cos();
    let r = Mat3::from_cols(Vec3::new(c, -s, 0.0), Vec3::new(s, c, 0.0), Vec3::Z);
    let sc = Mat3::from_diagonal(Vec3::new(scale[0], scale[1], 1.0));
    t * r * sc
}

#[cfg(test)]
mod tests {
    use super::*;

    fn checker(linear: bool, wrap: Wrap) -> Texture {
        Texture {
            width: 2,
            height: 2,
            texels: vec![
                [1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [0.0, 0.0, 1.0],
                [1.0, 1.0, 1.0],
            ],
            alpha: vec![],
            wrap: (wrap, wrap),
            linear,
        }
    }

    #[test]
    fn nearest_and_bilinear_sampling_with_every_wrap_mode() {
        let t = checker(false, Wrap::Repeat);
        assert_eq!(t.sample(Vec2::new(0.25, 0.25)), [1.0, 0.0, 0.0]);
        assert_eq!(t.sample(Vec2::new(0.75, 0.75)), [1.0, 1.0, 1.0]);
        assert_eq!(t.sample(Vec2::new(1.25, 0.25)), [1.0, 0.0, 0.0], "repeat");
        let c = checker(false, Wrap::Clamp);
        assert_eq!(c.sample(Vec2::new(3.0, 0.25)), [0.0, 1.0, 0.0], "clamp");
        let m = checker(false, Wrap::Mirror);
        assert_eq!(m.sample(Vec2::new(1.25, 0.25)), [0.0, 1.0, 0.0], "mirror");
        // Bilinear: the centre of the 2×2 texture is the mean of the four texels.
        let l = checker(true, Wrap::Clamp);
        let mid = l.sample(Vec2::new(0.5, 0.5));
        for (v, want) in mid.iter().zip([0.5, 0.5, 0.5]) {
            assert!((v - want).abs() < 1e-6, "{mid:?}");
        }
        assert_eq!(l.sample(Vec2::new(f32::NAN, 0.0)), [0.0; 3]);
    }

    #[test]
    fn texture_transform_offsets_rotates_and_scales() {
        let m = uv_transform([0.5, 0.0], 0.0, [2.0, 1.0]);
        let p = m * Vec3::new(0.25, 0.5, 1.0);
        assert!((p.x - 1.0).abs() < 1e-6 && (p.y - 0.5).abs() < 1e-6);
        let r = uv_transform([0.0, 0.0], std::f32::consts::FRAC_PI_2, [1.0, 1.0]);
        let q = r * Vec3::new(1.0, 0.0, 1.0);
        // The extension's rotation turns +u towards −v.
        assert!(q.x.abs() < 1e-6 && (q.y + 1.0).abs() < 1e-6, "{q:?}");
    }
}
