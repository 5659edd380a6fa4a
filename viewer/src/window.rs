//! The native window (cargo feature `window`): the live view, camera by
//! mouse and keyboard, and, when no daemon is in the session, the mouse
//! driving a tool.
//!
//! Controls: right drag orbits, wheel zooms; the keys and the left button
//! are [`crate::controls`] (R resets the view, F/V/O/C/K layers; driving, when
//! no daemon is in the session: the tip follows the cursor on the plane
//! through the organ's centre facing the camera, W/S push it in and out,
//! left button grips, X held cuts, 1-4 pick the tool).

use crate::camera::{View, bounds, framing, tip_under_cursor};
use crate::controls::{Controls, Request};
use crate::drive::Driver;
use crate::overlay;
use crate::render::{Layers, Renderer};
use crate::session::Session;
use crate::show::{field, overlay_lines, tool_shapes};
use shared::monotonic_ns;
use three_d::*;

/// Opens the window and runs until it is closed.
pub fn run(mut session: Session, layers: Layers) -> anyhow::Result<()> {
    let window = Window::new(WindowSettings {
        title: "hapsim viewer".into(),
        max_size: None,
        ..Default::default()
    })?;
    let context = window.gl();
    let mut renderer = Renderer::new(&context);
    // The organ is where the simulation's streams say (a default box
    // until they arrive): wait briefly for them, so the first picture is
    // framed.
    let start = monotonic_ns();
    while session.info.rest_m.is_empty() && monotonic_ns() - start < 1_000_000_000 {
        session.poll(monotonic_ns());
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    let (mut lo, mut hi) =
        bounds(&session.info.rest_m).unwrap_or((vec3(-0.1, -0.1, -0.1), vec3(0.1, 0.1, 0.1)));
    let mut camera = framing(window.viewport(), lo, hi, View::Iso);
    let size = (hi - lo).magnitude();
    let centre = (lo + hi) * 0.5;
    let mut driver = Driver::new(
        session.info.tools.len(),
        [centre.x as f64, centre.y as f64, hi.z as f64],
    );
    let mut cursor: Option<PhysicalPoint> = None;
    let mut controls = Controls::new(size, session.info.tools.len(), layers);
    let mut shown_frames = u64::MAX;
    // The scene's name, fibres and rest surface, set when they arrive.
    let mut shown_scene = String::new();
    let mut shown_colour = None;
    let mut shown_clip = controls.layers.clip;
    window.render_loop(move |mut frame| {
        let now = monotonic_ns();
        camera.set_viewport(frame.viewport);
        let changed = session.poll(now);
        let clip = controls.layers.clip;
        if session.info.name != shown_scene || clip != shown_clip {
            shown_scene = session.info.name.clone();
            shown_clip = clip;
            renderer.set_clip(clip.map(|c| (c, c.at_m(lo, hi))));
            shown_colour = None;
            renderer.set_fibres(&session.info.fibres, size * 0.003);
            driver.tool_count = session.info.tools.len().min(shared::protocol::MAX_TOOLS);
            controls = Controls::new(size, session.info.tools.len(), controls.layers);
            if session.frames == 0 {
                // Until the simulation sends a state, the scene at rest.
                renderer.set_surface(&session.info.rest_m, &session.info.surface, |_| false, None);
            }
        }
        let colour_by = controls.layers.colour_by;
        if (changed || Some(colour_by) != shown_colour)
            && session.drawable()
            && (session.frames != shown_frames || Some(colour_by) != shown_colour)
        {
            shown_frames = session.frames;
            shown_colour = Some(colour_by);
            let same_scene = session.same_scene();
            let info = &session.info;
            let colour_field = field(&session, colour_by);
            renderer.set_surface(
                &session.positions_m,
                &session.triangles,
                |t| same_scene && info.is_cut_face(t),
                colour_field.as_ref().map(|f| f.colours.as_slice()),
            );
            renderer.set_colour_bar(colour_field.as_ref().map(|f| f.bar()).as_ref());
            if let Some(b) = bounds(&session.positions_m) {
                (lo, hi) = b;
            }
        }
        for event in frame.events.iter_mut() {
            match event {
                Event::MouseMotion {
                    button,
                    delta,
                    position,
                    ..
                } => {
                    cursor = Some(*position);
                    if *button == Some(MouseButton::Right) {
                        camera.rotate_around_with_fixed_up(
                            (lo + hi) * 0.5,
                            0.01 * delta.0,
                            0.01 * delta.1,
                        );
                    }
                }
                Event::MouseWheel { delta, .. } => {
                    let target = (lo + hi) * 0.5;
                    let speed = 0.01 * target.distance(camera.position()) + 0.001;
                    camera.zoom_towards(target, speed * delta.1, size * 0.05, size * 20.0);
                }
                Event::MousePress {
                    button: MouseButton::Left,
                    ..
                } => controls.grip(true),
                Event::MouseRelease {
                    button: MouseButton::Left,
                    ..
                } => controls.grip(false),
                Event::KeyPress { kind, .. } => match controls.key_press(*kind) {
                    Request::ResetView => camera = framing(frame.viewport, lo, hi, View::Iso),
                    Request::None => {}
                },
                Event::KeyRelease { kind, .. } => controls.key_release(*kind),
                _ => {}
            }
        }
        // The tip: under the cursor, on the plane through the organ's centre
        // facing the camera, moved along the view by W/S.
        if let Some(tip) =
            cursor.and_then(|p| tip_under_cursor(&camera, p, (lo + hi) * 0.5, controls.depth_m))
        {
            driver.tip_m = [tip.x as f64, tip.y as f64, tip.z as f64];
        }
        driver.tool = controls.tool;
        driver.jaw_opening = controls.jaw_opening();
        driver.update(&session);
        let driving = driver.active().then_some(driver.tool);
        let driven = driving.map(|k| (k, driver.tip_m));
        let layers = controls.layers;
        renderer.set_tools(
            &tool_shapes(&session, driven),
            layers.forces,
            layers.force_mm_per_n,
        );
        renderer.set_overlay(&overlay::fit(
            overlay::render_coloured(&overlay_lines(
                &session,
                now,
                driving,
                layers.force_mm_per_n,
            )),
            frame.viewport.width.saturating_sub(16) as usize,
        ));
        renderer.draw(&frame.screen(), &camera, &layers);
        FrameOutput::default()
    });
    Ok(())
}
