//! What the fuzz targets check alike.

use vtz::{Raster, Window};

/// A window decode equals the same crop of the full decode, bit for bit (NaN fills alike).
pub fn window_is_crop(part: &Raster, full: &Raster, win: Window) {
    assert_eq!((part.width, part.height), (win.width, win.height));
    for y in 0..win.height {
        for x in 0..win.width {
            let a = part.data[y * win.width + x];
            let b = full.data[(y + win.y) * full.width + x + win.x];
            assert!(
                a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()),
                "window sample ({x}, {y}) is {a}, the full decode has {b}"
            );
        }
    }
}
