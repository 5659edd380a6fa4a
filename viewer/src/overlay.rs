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

/// Text colour of the overlay.
pub const TEXT: [u8; 3] = [235, 235, 235];
const PANEL: [u8; 4] = [16, 18, 24, 190];

/// Draws `text` (ASCII; other characters show as '?') with its top-left
/// corner at (x, y) into `img`, clipped to it.
fn draw_text(img: &mut Image, x: usize, y: usize, text: &str, colour: [u8; 3]) {
    for (col, ch) in text.chars().enumerate() {
        let code = if ch.is_ascii() {
            ch as usize
        } else {
            '?' as usize
        };
        for (gy, bits) in BASIC_LEGACY[code].iter().enumerate() {
            for gx in 0..8 {
                if bits >> gx & 1 == 0 {
                    continue;
                }
                for sy in 0..SCALE {
                    for sx in 0..SCALE {
                        let px = x + col * GLYPH + gx * SCALE + sx;
                        let py = y + gy * SCALE + sy;
                        if px < img.width && py < img.height {
                            img.pixels[py * img.width + px] =
                                [colour[0], colour[1], colour[2], 255];
                        }
                    }
                }
            }
        }
    }
}

/// Renders `lines` as a panel, all in the overlay's text colour.
pub fn render(lines: &[String]) -> Image {
    let coloured: Vec<(String, [u8; 3])> = lines.iter().map(|l| (l.clone(), TEXT)).collect();
    render_coloured(&coloured)
}

/// Renders `lines`, each in its own colour (a tool's line in its tip's
/// colour: the legend of the tip colours), as a panel.
pub fn render_coloured(lines: &[(String, [u8; 3])]) -> Image {
    let cols = lines.iter().map(|l| l.0.chars().count()).max().unwrap_or(0);
    let width = cols * GLYPH + 2 * PAD;
    let height = lines.len() * LINE + 2 * PAD;
    let mut img = Image {
        width,
        height,
        pixels: vec![PANEL; width * height],
    };
    for (row, (line, colour)) in lines.iter().enumerate() {
        draw_text(&mut img, PAD, PAD + row * LINE, line, *colour);
    }
    img
}

/// `img` as it fits `max_width_px`: unchanged when it does, else at half
/// size (every glyph pixel is a 2 x 2 block, so halving gives the same text
/// at one pixel per glyph pixel, still legible) so that a narrow window or
/// snapshot does not cut the overlay's lines off.
pub fn fit(img: Image, max_width_px: usize) -> Image {
    if img.width <= max_width_px || img.width < 2 {
        return img;
    }
    let (width, height) = (img.width / 2, img.height / 2);
    let pixels = (0..height)
        .flat_map(|y| (0..width).map(move |x| (x, y)))
        .map(|(x, y)| img.pixels[(2 * y) * img.width + 2 * x])
        .collect();
    Image {
        width,
        height,
        pixels,
    }
}

/// Height of a colour bar's gradient (pixels).
pub const BAR_H: usize = 200;
/// Width of a colour bar's gradient (pixels).
pub const BAR_W: usize = 20;

/// A colour bar: `title` above a vertical gradient of `map` from `range[0]`
/// (bottom) to `range[1]` (top), its ends and middle labelled in `unit`.
/// The gradient's pixels are exactly `map`'s colours, so a snapshot's
/// bar can be read back against the organ's.
pub fn colour_bar(title: &str, range: [f32; 2], unit: &str, map: fn(f32) -> [u8; 3]) -> Image {
    let label = |v: f32| format!("{v:.2} {unit}");
    let labels = [
        label(range[1]),
        label(0.5 * (range[0] + range[1])),
        label(range[0]),
    ];
    let label_cols = labels.iter().map(|l| l.chars().count()).max().unwrap_or(0);
    let width =
        (2 * PAD + BAR_W + 8 + label_cols * GLYPH).max(2 * PAD + title.chars().count() * GLYPH);
    let bar_top = PAD + LINE + GLYPH / 2;
    let height = bar_top + BAR_H + GLYPH / 2 + PAD;
    let mut img = Image {
        width,
        height,
        pixels: vec![PANEL; width * height],
    };
    draw_text(&mut img, PAD, PAD, title, TEXT);
    for row in 0..BAR_H {
        let t = 1.0 - row as f32 / (BAR_H - 1) as f32;
        let c = map(t);
        for col in 0..BAR_W {
            img.pixels[(bar_top + row) * width + PAD + col] = [c[0], c[1], c[2], 255];
        }
    }
    for (k, l) in labels.iter().enumerate() {
        let y = bar_top + k * (BAR_H - 1) / 2;
        draw_text(
            &mut img,
            PAD + BAR_W + 8,
            y.saturating_sub(GLYPH / 2),
            l,
            TEXT,
        );
    }
    img
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

    #[test]
    fn an_overlay_too_wide_for_the_view_is_drawn_at_half_size() {
        let img = render(&["a line of forty characters, more or less".into()]);
        let lit = |i: &Image| i.pixels.iter().filter(|p| p[3] == 255).count();
        let same = fit(img.clone(), img.width);
        assert_eq!(same, img);
        let half = fit(img.clone(), img.width - 1);
        assert_eq!((half.width, half.height), (img.width / 2, img.height / 2));
        assert_eq!(
            lit(&half) * 4,
            lit(&img),
            "each 2 x 2 glyph block becomes one pixel"
        );
    }

    #[test]
    fn a_colour_bar_holds_the_map_from_its_range_bottom_to_top() {
        let map = |t: f32| [(t * 255.0) as u8, 0, 0];
        let img = colour_bar("displacement", [0.0, 4.0], "mm", map);
        let bar_top = PAD + LINE + GLYPH / 2;
        let at = |row: usize| img.pixels[(bar_top + row) * img.width + PAD + BAR_W / 2];
        assert_eq!(at(0), [255, 0, 0, 255], "top: the range's end");
        assert_eq!(at(BAR_H - 1), [0, 0, 0, 255], "bottom: its start");
        assert!(img.width >= 2 * PAD + "displacement".len() * GLYPH);
    }
}
