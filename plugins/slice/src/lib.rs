//! Slicers for Lamina. [`cut`] turns a mesh into the closed contours of one plane;
//! the stages decide where the planes go (`uniform`, `adaptive`).

mod adaptive;
pub mod cut;
mod holes;
mod uniform;

pub use cut::{CutMesh, CutOptions, FillRule};
