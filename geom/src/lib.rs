//! Lamina's planar geometry: the shapes every stage passes on (contours, polygons with
//! holes, boxes) and the algorithms more than one plugin needs, written once. Plugins
//! depend on `lamina-core` (the stage API, which re-exports the shapes) and on this
//! crate, never on each other.
//!
//! - [`shape`]: contours, polygons and boxes with their measures; they cross the
//!   plugin boundary.
//! - [`segment`]: a point against a segment.
//! - [`centroid`]: the centroids of contours and polygons.
//! - [`ring`]: the `[x, y]` rings and shapes the boolean engine takes, and conversions.
//! - [`simplify`]: the one ring simplifier.
//! - [`follow`]: one solid area followed from layer to layer.
//! - [`reference`](mod@reference): a region's reference point, by one rule for every stage.
//! - [`field`]: a sampled distance field of contours on a square grid;
//! - [`iso`]: its iso-loops (marching squares), the sets {v >= t} as contours;
//! - [`lattice`]: a lattice of spherical voids and the circles it cuts in a plane;
//! - [`base_cell`]: base cells (sphere, box, cylinder) on a lattice that may be tilted,
//!   and the sections a layer's plane cuts from them (the search band of Fig. 5).
//! - [`offset`]: offsets in and out, one engine of raw loops, on the discretisers'
//!   family grids and on a grid of their own for float shapes.

pub mod base_cell;
pub mod centroid;
pub mod field;
pub mod follow;
pub mod iso;
pub mod lattice;
pub mod offset;
pub mod reference;
pub mod ring;
pub mod segment;
pub mod shape;
pub mod simplify;

pub use centroid::{contour_centroid, polygon_centroid};
pub use ring::{Ring, Shape, Shapes};
pub use segment::{closest_on_segment, segment_distance, segment_distance2, segment_parameter};
pub use shape::{BBox2, Contour, Point2, Polygon, Vector2};
pub use simplify::simplify_ring;
