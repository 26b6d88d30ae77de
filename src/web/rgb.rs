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
use crate::formats::png::RgbHeights;

/// The largest 24-bit code.
const MAX_CODE: u32 = (1 << 24) - 1;

/// The 24-bit code of height `h` (NaN → 0 m) in encoding `k`: rounded to the nearest step,
/// clamped to the code range (the PNG writer refuses such a value instead; a web tile
/// keeps the pixel).
pub(crate) fn code(k: RgbHeights, h: f32) -> u32 {
    let h = if h.is_nan() { 0.0 } else { f64::from(h) };
    k.mapping()
        .to_code(h)
        .round()
        .clamp(0.0, f64::from(MAX_CODE)) as u32
}

/// The height a map reads from a 24-bit code.
pub(crate) fn height(k: RgbHeights, code: u32) -> f64 {
    k.mapping().to_value(f64::from(code))
}

/// The heights as RGB bytes (3 per pixel).
pub(crate) fn pack(k: RgbHeights, heights: &[f32]) -> Vec<u8> {
    let mut out = Vec::with_capacity(heights.len() * 3);
    for &h in heights {
        let c = code(k, h);
        out.extend_from_slice(&[(c >> 16) as u8, (c >> 8) as u8, c as u8]);
    }
    out
}

/// The image container of an RGB tile.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum ImageFormat {
    /// PNG, zlib at its best compression with adaptive filters (what tilers write).
    Png,
    /// Lossless WebP (VP8L) from the pure-Rust `image-webp` encoder.
    Webp,
}

/// One tile image of `dim × dim` RGB pixels.
pub(crate) fn encode_image(rgb: &[u8], dim: u32, format: ImageFormat) -> Result<Vec<u8>> {
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
        let t = RgbHeights::Terrarium;
        // 0 m is R=128, G=0, B=0 in Terrarium.
        assert_eq!(pack(t, &[0.0]), vec![128, 0, 0]);
        assert_eq!(pack(t, &[f32::NAN]), vec![128, 0, 0]);
        for h in [-11034.0f32, -0.3, 1.2345, 8848.86] {
            let back = height(t, code(t, h));
            assert!(
                (back - f64::from(h)).abs() <= 1.0 / 512.0 + 1e-9,
                "{h} -> {back}"
            );
        }
        let m = RgbHeights::TerrainRgb;
        // 0 m is code 100000 = 0x0186A0.
        assert_eq!(pack(m, &[0.0]), vec![0x01, 0x86, 0xA0]);
        assert!((height(m, code(m, 1234.56)) - 1234.6).abs() < 1e-9);
        // Clamped at the ends of the range.
        assert_eq!(code(m, -20000.0), 0);
        assert_eq!(code(t, 1e6), (1 << 24) - 1);
    }

    #[test]
    fn images_decode_to_the_same_pixels() {
        let dim = 16u32;
        let heights: Vec<f32> = (0..dim * dim).map(|i| (i as f32) * 3.7 - 100.0).collect();
        let rgb = pack(RgbHeights::Terrarium, &heights);
        for f in [ImageFormat::Png, ImageFormat::Webp] {
            let bytes = encode_image(&rgb, dim, f).unwrap();
            let img = image::load_from_memory(&bytes).unwrap().to_rgb8();
            assert_eq!(img.into_raw(), rgb, "{f:?}");
        }
    }
}
