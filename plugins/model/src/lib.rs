//! Model sources for Lamina: readers for STL (binary and ASCII), OBJ and 3MF meshes, and
//! generators for the parametric models the examples and tests use (gears, tubes,
//! boxes, cubes, turbine blades), so that the project ships no mesh files of its own.

pub mod blade;
pub mod extrude;
pub mod obj;
pub mod profile;
pub mod stl;
pub mod threemf;
pub mod weld;

mod stages;

pub use extrude::{edge_defect, extrude};
pub use weld::{Soup, WeldReport};
