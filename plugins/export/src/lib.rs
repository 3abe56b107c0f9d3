//! Writers of Lamina's outputs. Every writer streams: it receives the layers in build
//! order and writes each one as it comes, so memory does not grow with the part.

pub mod bitmap;
pub mod cli;
pub mod contour_ids;
pub mod json;
pub mod threemf;
