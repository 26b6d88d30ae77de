//! Mesh file formats: OBJ, PLY, STL and binary glTF (`.glb`).
