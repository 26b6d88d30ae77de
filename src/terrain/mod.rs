//! Terrain from rasters and `.vtz` files, built on the codec's public surface: meshes
//! (`mesh`: vertex selection for `vtz mesh`, from a file's stored sites or a raster's
//! greedy or quadtree selection), Cesium terrain pyramids (`pyramid`: `vtz tiles`' zoom
//! levels of quantized-mesh tiles and `layer.json`) and a file's cells (`cells`: `vtz cells`'
//! inputs: a level's sites, its Sibson surface, the reference, GeoJSON and a picture).

mod cells;
mod mesh;
mod pyramid;

pub use cells::{CellsRequest, FileCells, file_cells};
pub use mesh::{MeshRequest, Select, mesh_file, mesh_raster};
pub use pyramid::{TerrainLevel, TerrainReport, TerrainRequest, write_terrain};
