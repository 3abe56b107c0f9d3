//! Short labels on raster pictures ("layer 12  z 2.4 mm") in a 5 x 7 pixel font drawn
//! for the project: the few characters a tile's caption needs, scaled by whole pixels,
//! so that a picture carries its own caption without a font file or a text engine.

use tiny_skia::{Color, Paint, Pixmap, Rect, Transform};

/// Width and height of a glyph cell in font pixels (5 x 7 glyph, one column apart).
const ADVANCE: f32 = 6.0;
const HEIGHT: f32 = 7.0;

/// Rows of a glyph, top first, the five low bits of each from left (bit 4) to right.
fn glyph(c: char) -> Option<[u8; 7]> {
    Some(match c {
        '0' => [0x0e, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0e],
        '1' => [0x04, 0x0c, 0x04, 0x04, 0x04, 0x04, 0x0e],
        '2' => [0x0e, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1f],
        '3' => [0x1f, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0e],
        '4' => [0x02, 0x06, 0x0a, 0x12, 0x1f, 0x02, 0x02],
        '5' => [0x1f, 0x10, 0x1e, 0x01, 0x01, 0x11, 0x0e],
        '6' => [0x06, 0x08, 0x10, 0x1e, 0x11, 0x11, 0x0e],
        '7' => [0x1f, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08],
        '8' => [0x0e, 0x11, 0x11, 0x0e, 0x11, 0x11, 0x0e],
        '9' => [0x0e, 0x11, 0x11, 0x0f, 0x01, 0x02, 0x0c],
        '.' => [0x00, 0x00, 0x00, 0x00, 0x00, 0x0c, 0x0c],
        '-' => [0x00, 0x00, 0x00, 0x1f, 0x00, 0x00, 0x00],
        '=' => [0x00, 0x00, 0x1f, 0x00, 0x1f, 0x00, 0x00],
        'a' => [0x00, 0x00, 0x0e, 0x01, 0x0f, 0x11, 0x0f],
        'e' => [0x00, 0x00, 0x0e, 0x11, 0x1f, 0x10, 0x0e],
        'l' => [0x0c, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0e],
        'm' => [0x00, 0x00, 0x1a, 0x15, 0x15, 0x11, 0x11],
        'r' => [0x00, 0x00, 0x16, 0x19, 0x10, 0x10, 0x10],
        'y' => [0x00, 0x00, 0x11, 0x11, 0x0f, 0x01, 0x0e],
        'z' => [0x00, 0x00, 0x1f, 0x02, 0x04, 0x08, 0x1f],
        ' ' => [0; 7],
        _ => return None,
    })
}

/// The size in pixels of `text` drawn at `scale` pixels per font pixel.
pub fn size(text: &str, scale: f32) -> (f32, f32) {
    (text.chars().count() as f32 * ADVANCE * scale, HEIGHT * scale)
}

/// Draws `text` with its top-left corner at (x, y), on a white box a font pixel wider
/// all round so that it reads over the picture. Characters without a glyph are left
/// as spaces.
pub fn draw(pixmap: &mut Pixmap, text: &str, x: f32, y: f32, scale: f32) {
    let (w, h) = size(text, scale);
    let mut white = Paint::default();
    white.set_color(Color::WHITE);
    if let Some(r) = Rect::from_xywh(x - scale, y - scale, w + scale, h + 2.0 * scale) {
        pixmap.fill_rect(r, &white, Transform::identity(), None);
    }
    let mut ink = Paint::default();
    ink.set_color_rgba8(0, 0, 0, 255);
    for (k, c) in text.chars().enumerate() {
        let Some(rows) = glyph(c) else { continue };
        let left = x + k as f32 * ADVANCE * scale;
        for (row, bits) in rows.iter().enumerate() {
            for col in 0..5 {
                if bits & (0x10 >> col) != 0
                    && let Some(r) =
                        Rect::from_xywh(left + col as f32 * scale, y + row as f32 * scale, scale, scale)
                {
                    pixmap.fill_rect(r, &ink, Transform::identity(), None);
                }
            }
        }
    }
}

/// "layer 12 z 2.4 mm": the caption of a layer's tile.
pub fn layer_caption(index: usize, z: f64) -> String {
    let z = (z * 1000.0).round() / 1000.0;
    format!("layer {index} z {z} mm")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_caption_character_has_a_glyph() {
        for c in layer_caption(1234567890, -0.125).chars() {
            assert!(glyph(c).is_some(), "no glyph for {c:?}");
        }
    }

    #[test]
    fn a_label_inks_its_box_and_nothing_beyond() {
        let mut p = Pixmap::new(200, 40).unwrap();
        p.fill(Color::from_rgba8(200, 200, 200, 255));
        draw(&mut p, "layer 8", 10.0, 10.0, 2.0);
        let (w, h) = size("layer 8", 2.0);
        let dark = |x: u32, y: u32| p.pixel(x, y).unwrap().red() < 100;
        let inked = (0..40)
            .flat_map(|y| (0..200).map(move |x| (x, y)))
            .filter(|&(x, y)| dark(x, y));
        let mut any = false;
        for (x, y) in inked {
            any = true;
            assert!(
                x as f32 >= 10.0 && (x as f32) < 10.0 + w && y as f32 >= 10.0 && (y as f32) < 10.0 + h,
                "ink at {x}, {y}"
            );
        }
        assert!(any, "no ink");
    }
}
