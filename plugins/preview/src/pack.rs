//! The viewer's compact geometry: coordinates quantised to a grid, each point written as
//! its step from the previous one in zigzag LEB128 varints, the bytes as base64 text.
//!
//! Why: a layer of offset rings and toolpaths holds tens of thousands of points. As JSON
//! numbers they cost 14 bytes each and the browser must parse every one before showing
//! anything; as steps on a 0.01 mm grid most coordinates fit in one byte, and the page
//! decodes a layer only when it is shown. The layout is read by `reader` in
//! `assets/viewer.js`:
//!
//! - a ring: its point count, then each point as (dx, dy) from the previous point
//!   written (the cursor runs on across rings, so a ring's first point is a short step
//!   too);
//! - a path: `tool * 3 + kind` (0 extrude, 1 travel, 2 pause), its point count, then its
//!   points as for a ring;
//! - a run of machine moves read from G-code (`moves`): its motion system, `tool * 3 +
//!   kind`, its point count, then each point as (dx, dy, dt), dt in milliseconds.

use base64::Engine as _;
use lamina_geom::simplify::simplify_ring;

/// Writes quantised, delta-coded points.
pub struct Packer {
    bytes: Vec<u8>,
    /// Grid steps per millimetre.
    scale: f64,
    /// Tolerance of the ring simplification (mm): half a grid step, so that what is
    /// dropped could not be seen after quantisation anyway.
    eps: f64,
    last: (i64, i64),
    /// Time of the last timed point (ms).
    last_ms: i64,
    /// Reused buffer of quantised points.
    points: Vec<(i64, i64)>,
}

impl Packer {
    /// A packer on a grid of `10^-digits` mm.
    pub fn new(digits: i32) -> Self {
        let scale = 10f64.powi(digits);
        Packer {
            bytes: Vec::new(),
            scale,
            eps: 0.5 / scale,
            last: (0, 0),
            last_ms: 0,
            points: Vec::new(),
        }
    }

    fn uint(&mut self, mut v: u64) {
        while v >= 0x80 {
            self.bytes.push((v as u8 & 0x7f) | 0x80);
            v >>= 7;
        }
        self.bytes.push(v as u8);
    }

    fn int(&mut self, v: i64) {
        self.uint(((v << 1) ^ (v >> 63)) as u64);
    }

    fn grid(&self, v: f64) -> i64 {
        // Clamped to what the page's numbers hold exactly (2^52 steps, 4,500 km at the
        // finest grid), so that no step overflows and none is decoded inexactly.
        const MOST: f64 = 4_503_599_627_370_496.0;
        (v * self.scale).round().clamp(-MOST, MOST) as i64
    }

    /// Quantises points into the buffer, dropping repeats (which the grid makes of
    /// points closer than a step).
    fn quantise(&mut self, pts: impl Iterator<Item = [f64; 2]>, closed: bool) {
        let mut points = std::mem::take(&mut self.points);
        points.clear();
        for [x, y] in pts {
            let q = (self.grid(x), self.grid(y));
            if points.last() != Some(&q) {
                points.push(q);
            }
        }
        if closed && points.len() > 1 && points.first() == points.last() {
            points.pop();
        }
        self.points = points;
    }

    fn points(&mut self) {
        let points = std::mem::take(&mut self.points);
        self.uint(points.len() as u64);
        for &(x, y) in &points {
            self.int(x - self.last.0);
            self.int(y - self.last.1);
            self.last = (x, y);
        }
        self.points = points;
    }

    /// A closed ring, simplified to within half a grid step.
    pub fn ring(&mut self, ring: &[[f64; 2]]) {
        let simple = simplify_ring(ring, self.eps);
        self.quantise(simple.into_iter(), true);
        self.points();
    }

    /// An open path with its tool and kind, every point kept (a move is a move).
    pub fn path(&mut self, tool: usize, kind: u8, pts: impl Iterator<Item = [f64; 2]>) {
        self.uint(tool as u64 * 3 + kind as u64);
        self.quantise(pts, false);
        self.points();
    }

    /// A run of machine moves: its motion system, `tool * 3 + kind`, then each point
    /// with its time (ms from the layer's start, as a signed step from the previous
    /// point's time: runs of different systems overlap in time).
    pub fn timed(&mut self, system: usize, tool: usize, kind: u8, pts: &[([f64; 2], f64)]) {
        self.uint(system as u64);
        self.uint(tool as u64 * 3 + kind as u64);
        self.uint(pts.len() as u64);
        for &([x, y], t) in pts {
            let (qx, qy) = (self.grid(x), self.grid(y));
            let ms = (t * 1000.0).round() as i64;
            self.int(qx - self.last.0);
            self.int(qy - self.last.1);
            self.int(ms - self.last_ms);
            self.last = (qx, qy);
            self.last_ms = ms;
        }
    }

    /// The bytes as base64 text (standard alphabet, padded: what `atob` reads), and the
    /// packer emptied for the next block.
    pub fn take_base64(&mut self) -> String {
        let text = base64::engine::general_purpose::STANDARD.encode(&self.bytes);
        self.bytes.clear();
        self.last = (0, 0);
        self.last_ms = 0;
        text
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Reads the layout back, as the viewer's script does.
    fn decode(text: &str, digits: i32) -> Vec<Vec<(f64, f64)>> {
        let bytes = base64::engine::general_purpose::STANDARD
            .decode(text)
            .expect("base64");
        let mut at = 0;
        let uint = |at: &mut usize| {
            let (mut v, mut shift) = (0u64, 0);
            loop {
                let b = bytes[*at];
                *at += 1;
                v |= u64::from(b & 0x7f) << shift;
                shift += 7;
                if b < 0x80 {
                    return v;
                }
            }
        };
        let unzig = |v: u64| ((v >> 1) as i64) ^ -((v & 1) as i64);
        let s = 10f64.powi(-digits);
        let (mut x, mut y) = (0i64, 0i64);
        let mut out = Vec::new();
        while at < bytes.len() {
            let n = uint(&mut at);
            let mut ring = Vec::new();
            for _ in 0..n {
                x += unzig(uint(&mut at));
                y += unzig(uint(&mut at));
                ring.push((x as f64 * s, y as f64 * s));
            }
            out.push(ring);
        }
        out
    }

    #[test]
    fn rings_come_back_on_the_grid_without_their_redundant_points() {
        let mut p = Packer::new(2);
        // A square with points along its edges, and a far-off negative ring.
        let square: Vec<[f64; 2]> = (0..40)
            .map(|i| {
                let t = f64::from(i % 10) / 10.0;
                match i / 10 {
                    0 => [t, 0.0],
                    1 => [1.0, t],
                    2 => [1.0 - t, 1.0],
                    _ => [0.0, 1.0 - t],
                }
            })
            .collect();
        p.ring(&square);
        p.ring(&[[-500.004, -3.0], [-499.0, -3.0], [-499.0, -2.0]]);
        let rings = decode(&p.take_base64(), 2);
        assert_eq!(rings.len(), 2);
        let mut corners = rings[0].clone();
        corners.sort_by(|a, b| a.partial_cmp(b).expect("finite"));
        assert_eq!(corners, vec![(0.0, 0.0), (0.0, 1.0), (1.0, 0.0), (1.0, 1.0)]);
        assert_eq!(rings[1], vec![(-500.0, -3.0), (-499.0, -3.0), (-499.0, -2.0)]);
    }

    #[test]
    fn small_steps_take_one_byte_a_coordinate() {
        let mut p = Packer::new(2);
        let pts: Vec<[f64; 2]> = (0..1000)
            .map(|i| [f64::from(i) * 0.3, 0.5 * f64::from(i % 2)])
            .collect();
        p.path(1, 0, pts.iter().copied());
        let bytes = p.bytes.len();
        assert!(bytes <= 2 + 2 + 2 * 1000 + 4, "{bytes} bytes for 1000 points");
    }
}
