//! Grading sources for Lamina (grading-step-width paper, Eq. 2-8): a point, an axis or
//! a plane from which a material grading function f(d) of the distance d runs between
//! a start and an end composition. Each source's grading is truncated into steps of
//! width t_g; the layer is cut along the steps' boundaries into homogeneous regions,
//! several sources are overlaid by boolean intersection so that regions never overlap.
//! A region's composition is the weighted combination of Eq. 8 over the sources whose
//! effective grading region (0 <= f <= 1) holds it, R12 = R1 ∩* R2, so that a source
//! alone keeps its own composition (R1' = R1 /* R12); where no source grades, over the
//! complementary compositions of all of them.
//!
//! The `sources` stage is a discretiser that also grades: its regions follow the
//! material, so it sets their compositions itself (a `[grade]` table, if given,
//! overrides them).

mod shapes;
pub mod source;
mod stage;
