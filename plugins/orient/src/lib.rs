//! Build orientation for Lamina (cmpm-process-planning 3.1): the `candidates` orienter
//! weighs candidate build directions (the axes, the normals of the largest flat faces,
//! an even sampling of the sphere, and any the user lists) and turns the object so that
//! the best one points up.

mod candidates;
mod surfaces;
