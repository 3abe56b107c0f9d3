//! lamina-process: the operations of the CMPM hybrid process (cmpm-process-planning §2)
//! and NC code for the machine that runs them.
//!
//! Each operation is a `[[process]]` stage; the stages run on every planned layer in the
//! order the pipeline lists them, each appending its [`Operation`]s to the layer's plan.
//! The paper's order for a layer of a material region is:
//!
//! 1. `end-mill`: where an adjoining region stands higher, its spray overhangs this
//!    region's area: an end mill contours the area's boundary along it, offset by the
//!    cutter's radius;
//! 2. `spray`: the layer, thicker by the rough and finish grinding allowances, with the
//!    inclusions of a composite;
//! 3. `grind` (rough): a cup wheel takes the surface down to the layer's height plus
//!    the finish allowance; the surface to be ground must stand higher than the others;
//! 4. `engrave`: a laser engraves the voids of a periodic microstructure;
//! 5. `fill`: the voids are filled with a low-strength, high-melting material;
//! 6. `grind` (finish): down to the layer's design height;
//! 7. repeat from step 1 for the next layer until the part is done; the filler stays in
//!    the voids, where it protects the part from erosion. (`remove-filler`, an extra
//!    operation a pipeline may ask for, melts or leaches it out at the end.)
//!
//! The `nc` exporter writes the operations as G-code for a hybrid machine.

mod area;
mod engrave;
mod fill;
mod grind;
mod hybrid;
mod mill;
mod nc;
mod regions;
mod spray;
mod tool;

pub use area::{adjoining_runs, layer_area, offset, raster};
