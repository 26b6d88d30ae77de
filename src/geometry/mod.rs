//! Planar geometry on integer sites: the Delaunay triangulation and Sibson's interpolant
//! over it (later: mesh extraction and basis-function surfaces).

pub(crate) mod basis;
pub(crate) mod sibson;
pub(crate) mod triangulation;
