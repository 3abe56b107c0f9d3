//! Sequencers for Lamina: they plan the fabrication sequence of the whole object before
//! it is sliced.
//!
//! - `work-cycles`: material regions that want different layer thicknesses; the object
//!   is cut into blocks at the regions' heights, each block is deposited in work cycles
//!   whose height is the least common multiple of the thicknesses present, and the
//!   adaptive slicer cuts each region at its own heights. A thickness may be `auto`:
//!   derived from the material (`auto`).

pub mod auto;
pub mod cycle;
mod work_cycles;
