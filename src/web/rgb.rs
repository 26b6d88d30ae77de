//! Today's raster-dem tile encodings, for comparison with vtz tiles: heights packed into
//! 8-bit RGB (Terrarium, Mapbox Terrain-RGB), written as PNG or lossless WebP.
//!
//! - Terrarium (Mapzen, `encoding: 'terrarium'`): `h = R·256 + G + B/256 − 32768`, steps of
//!   1/256 m from −32768 m.
//! - Terrain-RGB (Mapbox, `encoding: 'mapbox'`): `h = −10000 + (R·65536 + G·256 + B)·0.1`,
//!   steps of 0.1 m.
//!
//! Neither has nodata: nodata pixels are written as 0 m, as the public sets do for the sea.
//! Heights are rounded to the nearest step (the error is at most half a step) and clamped to
//! the encoding's range.

use crate::error::{Error, Result};

/// An RGB height encoding.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RgbEncoding {
    /// Mapzen Terrarium: 1/256 m steps from −32768 m.
    Terrarium,
    /// Mapbox Terrain-RGB: 0.1 m steps from −10000 m.
    Mapbox,
}

impl RgbEncoding {
    /// (step in metres, height of code 0).
    fn step_base(self) -> (f64, f64) {
        match self {
            RgbEncoding::Terrarium => (1.0 / 256.0, -32768.0),
            RgbEncoding::Mapbox => (0.1, -10000.0),
        }
    }

    /// The 24-bit code of height `h` (NaN → 0 m): rounded to the nearest step, clamped.
    pub fn code(self, h: f32) -> u32 {
        let (step, base) = self.step_base();
        let h = if h.is_nan() { 0.0 } else { f64::from(h) };
        ((h - base) / step)
            .round()
            .clamp(0.0, f64::from((1u32 << 24) - 1)) as u32
    }

    /// The height a map reads from a 24-bit code.
    pub fn height(self, code: u32) -> f64 {
        let (step, base) = self.step_base();
        base + f64::from(code) * step
    }

    /// The heights as RGB bytes (3 per pixel).
    pub fn pack(self, heights: &[f32]) -> Vec<u8> {
        let mut out = Vec::with_capacity(heights.len() * 3);
        for &h in heights {
            let c = self.code(h);
            out.extend_from_slice(&[(c >> 16) as u8, (c >> 8) as u8, c as u8]);
        }
        out
    }
}

/// The image container of an RGB tile.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ImageFormat {
    /// PNG, zlib at its best compression with adaptive filters (what tilers write).
    Png,
    /// Lossless WebP (VP8L) from the pure-Rust `image-webp` encoder.
    Webp,
}

/// One tile image of `dim × dim` RGB pixels.
pub fn encode_image(rgb: &[u8], dim: u32, format: ImageFormat) -> Result<Vec<u8>> {
    use image::ImageEncoder;
    let mut out = Vec::new();
    let res =
        match format {
            ImageFormat::Png => image::codecs::png::PngEncoder::new_with_quality(
                &mut out,
                image::codecs::png::CompressionType::Best,
                image::codecs::png::FilterType::Adaptive,
            )
            .write_image(rgb, dim, dim, image::ExtendedColorType::Rgb8),
            ImageFormat::Webp => image::codecs::webp::WebPEncoder::new_lossless(&mut out)
                .write_image(rgb, dim, dim, image::ExtendedColorType::Rgb8),
        };
    res.map_err(|e| Error::invalid(format!("encoding a tile image: {e}")))?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_round_to_the_nearest_step() {
        let t = RgbEncoding::Terrarium;
        // 0 m is R=128, G=0, B=0 in Terrarium.
        assert_eq!(t.pack(&[0.0]), vec![128, 0, 0]);
        assert_eq!(t.pack(&[f32::NAN]), vec![128, 0, 0]);
        for h in [-11034.0f32, -0.3, 1.2345, 8848.86] {
            let back = t.height(t.code(h));
            assert!(
                (back - f64::from(h)).abs() <= 1.0 / 512.0 + 1e-9,
                "{h} -> {back}"
            );
        }
        let m = RgbEncoding::Mapbox;
        // 0 m is code 100000 = 0x0186A0.
        assert_eq!(m.pack(&[0.0]), vec![0x01, 0x86, 0xA0]);
        assert!((m.height(m.code(1234.56)) - 1234.6).abs() < 1e-9);
        // Clamped at the ends of the range.
        assert_eq!(m.code(-20000.0), 0);
        assert_eq!(t.code(1e6), (1 << 24) - 1);
    }

    #[test]
    fn images_decode_to_the_same_pixels() {
        let dim = 16u32;
        let heights: Vec<f32> = (0..dim * dim).map(|i| (i as f32) * 3.7 - 100.0).collect();
        let rgb = RgbEncoding::Terrarium.pack(&heights);
        for f in [ImageFormat::Png, ImageFormat::Webp] {
            let bytes = encode_image(&rgb, dim, f).unwrap();
            let img = image::load_from_memory(&bytes).unwrap().to_rgb8();
            assert_eq!(img.into_raw(), rgb, "{f:?}");
        }
    }
}
