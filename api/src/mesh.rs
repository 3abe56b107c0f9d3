//! Triangle meshes as read from STL/OBJ/3MF or made by a generator, and their bounds.

use serde::{Deserialize, Serialize};

pub type Point3 = nalgebra::Point3<f64>;
pub type Vector3 = nalgebra::Vector3<f64>;

/// An indexed triangle mesh. Winding is counter-clockwise seen from outside; stored
/// facet normals of the source file are not kept (the winding is trusted).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Mesh {
    /// Name for messages: the file name or the generator.
    pub name: String,
    pub vertices: Vec<Point3>,
    pub triangles: Vec<[u32; 3]>,
    /// Base material names per triangle when the source carries them (3MF), else empty.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub triangle_materials: Vec<u32>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub material_names: Vec<String>,
    /// What the reader repaired (welded, dropped), for the user.
    #[serde(skip)]
    pub warnings: Vec<crate::diagnostic::Warning>,
}

impl Mesh {
    pub fn new(name: impl Into<String>, vertices: Vec<Point3>, triangles: Vec<[u32; 3]>) -> Self {
        Self {
            name: name.into(),
            vertices,
            triangles,
            triangle_materials: Vec::new(),
            material_names: Vec::new(),
            warnings: Vec::new(),
        }
    }

    pub fn bbox(&self) -> BBox3 {
        let mut b = BBox3::EMPTY;
        for v in &self.vertices {
            b.include(*v);
        }
        b
    }

    /// The three corners of triangle `i`.
    pub fn triangle(&self, i: usize) -> [Point3; 3] {
        let [a, b, c] = self.triangles[i];
        [
            self.vertices[a as usize],
            self.vertices[b as usize],
            self.vertices[c as usize],
        ]
    }

    /// Scales about the origin, then translates.
    pub fn transform(&mut self, scale: f64, offset: Vector3) {
        for v in &mut self.vertices {
            *v = Point3::from(v.coords * scale + offset);
        }
    }

    /// Rotates every vertex about the origin by a row-major 3x3 matrix.
    pub fn rotate(&mut self, rotation: &[[f64; 3]; 3]) {
        let r = nalgebra::Matrix3::from_fn(|i, j| rotation[i][j]);
        for v in &mut self.vertices {
            *v = Point3::from(r * v.coords);
        }
    }

    /// Signed volume by the divergence theorem (positive for outward winding).
    pub fn signed_volume(&self) -> f64 {
        (0..self.triangles.len())
            .map(|i| {
                let [a, b, c] = self.triangle(i);
                a.coords.dot(&b.coords.cross(&c.coords)) / 6.0
            })
            .sum()
    }
}

/// An axis-aligned box in space.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BBox3 {
    pub min: Point3,
    pub max: Point3,
}

impl BBox3 {
    pub const EMPTY: BBox3 = BBox3 {
        min: Point3::new(f64::INFINITY, f64::INFINITY, f64::INFINITY),
        max: Point3::new(f64::NEG_INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY),
    };

    pub fn include(&mut self, p: Point3) {
        self.min = self.min.inf(&p);
        self.max = self.max.sup(&p);
    }

    pub fn union(&self, o: &BBox3) -> BBox3 {
        BBox3 {
            min: self.min.inf(&o.min),
            max: self.max.sup(&o.max),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.min.x > self.max.x || self.min.y > self.max.y || self.min.z > self.max.z
    }

    pub fn size(&self) -> Vector3 {
        if self.is_empty() {
            Vector3::zeros()
        } else {
            self.max - self.min
        }
    }
}
