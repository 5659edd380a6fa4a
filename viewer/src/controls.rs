//! What the window's keys and left button do, kept apart from the window
//! (cargo feature `window`) so that the bindings are tested without a
//! display: W/S push the driven tip in and out along the view by 1% of the
//! organ's size, the left button closes the jaws to grip, X held closes
//! them to cut (over a grip), 1-4 pick the driven tool among the scene's,
//! F, V and O toggle fibres, force vectors and the overlay, C colours the
//! organ by displacement (with a colour bar) or not, K clips the front half
//! away (to see inside) or not, R asks for the
//! default view.

use crate::colour::ColourBy;
use crate::drive::{JAW_CUT, JAW_GRIP};
use crate::render::Layers;
use three_d::Key;

/// What a key asks of the window beyond the state kept here.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Request {
    /// Nothing more.
    None,
    /// Reframe the camera on the organ.
    ResetView,
}

/// The driving and display state the keys and the left button change.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Controls {
    /// How far the tip is pushed along the view, into the scene (m).
    pub depth_m: f32,
    /// Left button held: jaws at the grip opening.
    pub gripping: bool,
    /// X held: jaws at the cut opening.
    pub cutting: bool,
    /// The tool the mouse drives.
    pub tool: usize,
    /// What is shown.
    pub layers: Layers,
    step_m: f32,
    tools: usize,
}

impl Controls {
    /// Controls for an organ of size `size_m` (its bounding box diagonal)
    /// with `tools` tools, showing `layers`.
    pub fn new(size_m: f32, tools: usize, layers: Layers) -> Self {
        Self {
            depth_m: 0.0,
            gripping: false,
            cutting: false,
            tool: 0,
            layers,
            step_m: size_m * 0.01,
            tools,
        }
    }

    /// A key went down.
    pub fn key_press(&mut self, key: Key) -> Request {
        match key {
            Key::W => self.depth_m += self.step_m,
            Key::S => self.depth_m -= self.step_m,
            Key::X => self.cutting = true,
            Key::F => self.layers.fibres = !self.layers.fibres,
            Key::V => self.layers.forces = !self.layers.forces,
            Key::O => self.layers.overlay = !self.layers.overlay,
            Key::K => {
                self.layers.clip = match self.layers.clip {
                    None => Some(crate::render::Clip {
                        axis: 1,
                        fraction: 0.5,
                    }),
                    Some(_) => None,
                }
            }
            Key::C => {
                self.layers.colour_by = match self.layers.colour_by {
                    ColourBy::Tissue => ColourBy::Displacement,
                    ColourBy::Displacement => ColourBy::Tissue,
                }
            }
            Key::R => return Request::ResetView,
            Key::Num1 | Key::Num2 | Key::Num3 | Key::Num4 => {
                let k = match key {
                    Key::Num1 => 0,
                    Key::Num2 => 1,
                    Key::Num3 => 2,
                    _ => 3,
                };
                if k < self.tools {
                    self.tool = k;
                }
            }
            _ => {}
        }
        Request::None
    }

    /// A key went up.
    pub fn key_release(&mut self, key: Key) {
        if key == Key::X {
            self.cutting = false;
        }
    }

    /// The left button went down (`true`) or up.
    pub fn grip(&mut self, pressed: bool) {
        self.gripping = pressed;
    }

    /// The jaw opening to publish: cut over grip over open.
    pub fn jaw_opening(&self) -> f64 {
        if self.cutting {
            JAW_CUT
        } else if self.gripping {
            JAW_GRIP
        } else {
            1.0
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_and_button_drive_the_tool_and_the_layers() {
        let mut c = Controls::new(0.2, 2, Layers::default());
        assert_eq!(c.jaw_opening(), 1.0);
        // W/S: 1% of the size per press, in and out.
        c.key_press(Key::W);
        c.key_press(Key::W);
        c.key_press(Key::S);
        assert!((c.depth_m - 0.002).abs() < 1e-7, "{}", c.depth_m);
        // Grip, then cut over it, then let go of each.
        c.grip(true);
        assert_eq!(c.jaw_opening(), JAW_GRIP);
        c.key_press(Key::X);
        assert_eq!(c.jaw_opening(), JAW_CUT);
        c.key_release(Key::X);
        assert_eq!(c.jaw_opening(), JAW_GRIP);
        c.grip(false);
        assert_eq!(c.jaw_opening(), 1.0);
        // Tools: only those the scene has.
        c.key_press(Key::Num2);
        assert_eq!(c.tool, 1);
        c.key_press(Key::Num4);
        assert_eq!(c.tool, 1, "the scene has two tools");
        c.key_press(Key::Num1);
        assert_eq!(c.tool, 0);
        // Layers toggle; R asks for the view; other keys do nothing.
        let before = c.layers;
        for k in [Key::F, Key::V, Key::O, Key::C, Key::K] {
            assert_eq!(c.key_press(k), Request::None);
        }
        assert_eq!(
            c.layers,
            Layers {
                fibres: !before.fibres,
                forces: !before.forces,
                overlay: !before.overlay,
                colour_by: ColourBy::Displacement,
                clip: Some(crate::render::Clip {
                    axis: 1,
                    fraction: 0.5
                }),
                ..before
            }
        );
        assert_eq!(c.key_press(Key::R), Request::ResetView);
        let same = c;
        c.key_press(Key::Q);
        c.key_release(Key::W);
        assert_eq!(c, same);
    }
}
