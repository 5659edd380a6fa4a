//! The text overlay (rates and latencies) as an RGBA image: 8x8 bitmap
//! glyphs, scaled, on a translucent dark panel. The same image is drawn in
//! the window and in snapshots.

use font8x8::legacy::BASIC_LEGACY;

/// Pixels per glyph pixel.
const SCALE: usize = 2;
/// Padding around the text (pixels).
const PAD: usize = 6;
const GLYPH: usize = 8 * SCALE;
const LINE: usize = GLYPH + 2 * SCALE;

/// An RGBA image, rows top to bottom.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// `width * height` pixels.
    pub pixels: Vec<[u8; 4]>,
}

/// Renders `lines` (ASCII; other characters show as '?') as a panel.
pub fn render(lines: &[String]) -> Image {
    let cols = lines.iter().map(|l| l.chars().count()).max().unwrap_or(0);
    let width = cols * GLYPH + 2 * PAD;
    let height = lines.len() * LINE + 2 * PAD;
    let mut pixels = vec![[16, 18, 24, 190]; width * height];
    for (row, line) in lines.iter().enumerate() {
        for (col, ch) in line.chars().enumerate() {
            let code = if ch.is_ascii() {
                ch as usize
            } else {
                '?' as usize
            };
            let glyph = BASIC_LEGACY[code];
            for (gy, bits) in glyph.iter().enumerate() {
                for gx in 0..8 {
                    if bits >> gx & 1 == 0 {
                        continue;
                    }
                    for sy in 0..SCALE {
                        for sx in 0..SCALE {
                            let x = PAD + col * GLYPH + gx * SCALE + sx;
                            let y = PAD + row * LINE + gy * SCALE + sy;
                            pixels[y * width + x] = [235, 235, 235, 255];
                        }
                    }
                }
            }
        }
    }
    Image {
        width,
        height,
        pixels,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_lights_pixels_inside_the_panel_only_where_glyphs_are() {
        let img = render(&["sim 1000 Hz".into(), "x".into()]);
        assert_eq!(img.width, 11 * GLYPH + 2 * PAD);
        assert_eq!(img.height, 2 * LINE + 2 * PAD);
        let lit = img.pixels.iter().filter(|p| p[3] == 255).count();
        assert!(lit > 100, "{lit}");
        // A space lights nothing: the column of the space in "sim 1000" is dark.
        let x0 = PAD + 3 * GLYPH;
        for y in PAD..PAD + GLYPH {
            for x in x0..x0 + GLYPH {
                assert_ne!(img.pixels[y * img.width + x][3], 255);
            }
        }
        assert_eq!(render(&[]).pixels.len(), 4 * PAD * PAD);
    }
}
