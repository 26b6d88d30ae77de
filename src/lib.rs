//! vtz: a compression codec and file format for elevation data (DEMs, height fields) with a
//! hard error bound: every valid sample decodes within the bound you give, checked by the
//! encoder on exactly what the decoder produces.
//!
//! ```
//! // A small synthetic DEM (any reader in `vtz::formats` gives the same `Raster`).
//! let (w, h) = (64, 48);
//! let heights: Vec<f64> = (0..w * h)
//!     .map(|i| (100.0 + 20.0 * ((i % w) as f64 / 9.0).sin() * ((i / w) as f64 / 7.0).cos()).round())
//!     .collect();
//! let dem = vtz::Raster::from_values(w, h, heights, None, vtz::SampleType::I16)?;
//!
//! // Encode within 1 metre, decode, check.
//! let bytes = vtz::Encoder::new().max_error(vtz::ErrorBound::Abs(1.0)).encode(&dem)?;
//! let back = vtz::decode(&bytes)?;
//! assert!(vtz::metrics::compare(&dem, &back)?.max_error <= 1.0);
//! assert!(bytes.len() < w * h * 2);
//! # Ok::<(), vtz::Error>(())
//! ```
//!
//! The pipeline (ARCHITECTURE.md): a format reads a file into a [`Raster`]; the codec
//! encodes it with one or more methods from the registry (sibson, grid, haar, fis) into
//! sections of the `.vtz` container; decoding runs the same way back. [`encode`] and
//! [`decode`] are the easy path; [`Encoder`] and [`Decoder`] take options, [`Limits`],
//! windows, typed buffers and readers.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod cells;
mod codec;
mod container;
mod entropy;
mod error;
pub mod formats;
mod geometry;
pub mod lsystem;
mod mesh;
mod methods;
pub mod metrics;
mod model;
mod points;
mod predict;
mod quant;
pub mod rd;
pub mod source;
mod terrain;
mod threads;
pub mod viz;
#[cfg(feature = "web")]
pub mod web;

#[cfg(test)]
mod testutil;

pub use codec::Surface;
pub use codec::{
    DEFAULT_TILE, DecodeOptions, Decoder, EncodeOptions, EncodeReport, Encoder, FileInfo, Sample,
    Scale, SectionChoice, SectionInfo, TileInfo, TilesInfo, Verified, decode, decode_from,
    decode_with, encode, encode_progress, encode_report, encode_stream, info, on_threads,
    read_path, tile_count, write_path,
};
pub use container::Limits;
pub use error::{Error, Result};
pub use mesh::export::{MeshFormat, encode as encode_mesh};
pub use mesh::{Fit as MeshFit, Mesh, MeshOptions};
pub use methods::{
    COMPACT_EFFORT, DEFAULT_EFFORT, FisOptions, HaarOptions, Method, MethodParams, Norm,
    SibsonOptions, Site, StatValue, Stats,
};
pub use model::{
    GeoKeys, Georef, InMemory, OutputType, PointSet, Raster, RasterType, RowSource, SampleType,
    ValueMapping, Window,
};
pub use points::{
    ColumnReport, DecodePoints, PointHierarchy, PointsInfo, PointsOptions, PointsReport,
    RasterizePoints, bands_to_points, decode_points, encode_points, is_points_file,
    point_hierarchy, points_info, rasterize_points, verify_points,
};
pub use quant::ErrorBound;
pub use source::RangeSource;
pub use terrain::{
    CellsRequest, FileCells, MeshRequest, Select, TerrainLevel, TerrainReport, TerrainRequest,
    file_cells, mesh_file, mesh_raster, write_terrain,
};

/// Internals for the crate's own tests, benches and examples (the `internals` feature):
/// no stability promise.
#[cfg(feature = "internals")]
#[doc(hidden)]
pub mod internals {
    /// The container's framing.
    pub mod container {
        pub use crate::codec::read_all as read;
        pub use crate::container::{
            Header, SF_REQUIRED, Section, SectionEntry, SectionKind, kind_name, write,
        };
    }
    /// The range coder.
    pub mod range {
        pub use crate::entropy::range::{Bit, Decoder, Encoder, IntModel};
    }
    /// The FIS section's own encoder and decoder (the paper reproduction).
    pub mod fis {
        pub use crate::methods::fis::{FisParams, decode, encode};
    }
    /// Each method's section type, in registry order (the fuzz targets build files with them).
    pub fn method_sections() -> Vec<(&'static str, crate::container::SectionKind)> {
        crate::methods::REGISTRY
            .iter()
            .map(|m| (m.id().name, m.id().section))
            .collect()
    }
    /// The raster readers, each on bytes in memory (the fuzz targets call them directly).
    pub mod formats {
        pub use crate::formats::asc::read as asc;
        pub use crate::formats::exr::read as exr;
        pub use crate::formats::geotiff::read as geotiff;
        pub use crate::formats::hgt::read as hgt;
        pub use crate::formats::png::RgbHeights;
        pub use crate::formats::png::read as png;
        pub use crate::formats::raw::read as raw;
    }
}
