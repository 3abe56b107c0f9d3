//! The shapes of the stage API, from `lamina-geom`: plugins reach them through core,
//! and the geometry algorithms they share through `lamina-geom` itself.

pub use lamina_geom::shape::*;
pub use lamina_geom::{closest_on_segment, contour_centroid, polygon_centroid, segment_distance};
