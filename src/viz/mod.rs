//! Pictures for people: shaded relief, error maps and (with the `plot` feature) rate–distortion
//! plots, all as PNG bytes.

pub mod cells;
pub mod hillshade;
#[cfg(feature = "plot")]
pub mod plot;
