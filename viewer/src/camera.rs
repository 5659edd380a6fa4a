//! Where the camera looks from: framing the organ's bounding box for a
//! named view. The `top` view is orthographic with a documented mapping, so
//! tests can predict where each vertex lands in a snapshot.

use three_d::{Camera, InnerSpace, PhysicalPoint, Vec3, Viewport, degrees, vec3};

/// A named view of the scene.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum View {
    /// Perspective from above, in front (+y, the side the tools come
    /// from) and to the side (z up).
    Iso,
    // Plain text, no rustdoc link: these docs are also `--view`'s help.
    /// Orthographic looking down -z, +y up: the bounding box's centre at the
    /// image centre and its xy extent filling 90% of the image.
    Top,
    /// Perspective from +y (in front, where the tools come from) looking
    /// along -y (z up).
    Front,
}

/// Share of the image the top view's bounding box fills (the larger of
/// width and height ratio).
pub const TOP_FILL: f32 = 0.9;
const FOV_DEG: f32 = 40.0;

/// The axis-aligned bounds of `positions_m` (None when empty or not finite).
pub fn bounds(positions_m: &[[f32; 3]]) -> Option<(Vec3, Vec3)> {
    let mut lo = vec3(f32::INFINITY, f32::INFINITY, f32::INFINITY);
    let mut hi = -lo;
    for p in positions_m {
        if !p.iter().all(|x| x.is_finite()) {
            continue;
        }
        lo = vec3(lo.x.min(p[0]), lo.y.min(p[1]), lo.z.min(p[2]));
        hi = vec3(hi.x.max(p[0]), hi.y.max(p[1]), hi.z.max(p[2]));
    }
    (lo.x <= hi.x).then_some((lo, hi))
}

/// World height (m) the top view shows for bounds `lo..hi` in `viewport`.
pub fn top_view_height_m(viewport: Viewport, lo: Vec3, hi: Vec3) -> f32 {
    let aspect = viewport.width as f32 / viewport.height as f32;
    let ext = hi - lo;
    (ext.y.max(ext.x / aspect) / TOP_FILL).max(1e-6)
}

/// A camera framing `lo..hi` from `view`.
pub fn framing(viewport: Viewport, lo: Vec3, hi: Vec3, view: View) -> Camera {
    let centre = (lo + hi) * 0.5;
    let radius = ((hi - lo).x.hypot((hi - lo).y).hypot((hi - lo).z) * 0.5).max(1e-4);
    let up = vec3(0.0, 0.0, 1.0);
    match view {
        // three-d scales an orthographic height by the eye-target distance.
        View::Top => Camera::new_orthographic(
            viewport,
            centre + vec3(0.0, 0.0, 4.0 * radius),
            centre,
            vec3(0.0, 1.0, 0.0),
            top_view_height_m(viewport, lo, hi) / (4.0 * radius),
            0.01 * radius,
            10.0 * radius,
        ),
        View::Iso | View::Front => {
            let dir: Vec3 = if view == View::Iso {
                // From the anterior side (+y): the embedded scene's trocars
                // and the tissue its tools cut face this way.
                vec3(0.55, 1.0, 0.75)
            } else {
                vec3(0.0, 1.0, 0.0)
            };
            let len = (dir.x * dir.x + dir.y * dir.y + dir.z * dir.z).sqrt();
            let distance = radius / (FOV_DEG.to_radians() * 0.5).sin() * 1.05;
            Camera::new_perspective(
                viewport,
                centre + dir * (distance / len),
                centre,
                up,
                degrees(FOV_DEG),
                0.01 * distance,
                10.0 * distance,
            )
        }
    }
}

/// Where the mouse puts a driven tool's tip: on the line of sight under
/// `pixel`, where it crosses the plane through `centre` facing the camera,
/// then `depth_m` further along the view (W/S in the window). None when the
/// line of sight runs along that plane.
pub fn tip_under_cursor(
    camera: &Camera,
    pixel: PhysicalPoint,
    centre: Vec3,
    depth_m: f32,
) -> Option<Vec3> {
    let origin = camera.position_at_pixel(pixel);
    let dir = camera.view_direction_at_pixel(pixel);
    let n = camera.view_direction();
    let denom = dir.dot(n);
    (denom.abs() > 1e-6).then(|| {
        let t = (centre - origin).dot(n) / denom;
        origin + dir * t + n * depth_m
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The tip under the image centre is the organ's centre; under any
    /// pixel it lies on the centre's plane and projects back to that pixel;
    /// pushing in moves it along the view, away from the eye.
    #[test]
    fn the_tip_follows_the_cursor_on_the_plane_through_the_centre() {
        let vp = Viewport::new_at_origo(640, 480);
        let (lo, hi) = (vec3(-0.1, -0.05, -0.04), vec3(0.1, 0.05, 0.04));
        let centre = (lo + hi) * 0.5;
        for view in [View::Iso, View::Top, View::Front] {
            let cam = framing(vp, lo, hi, view);
            let mid = PhysicalPoint { x: 320.0, y: 240.0 };
            let tip = tip_under_cursor(&cam, mid, centre, 0.0).unwrap();
            assert!((tip - centre).magnitude() < 1e-4, "{view:?}: {tip:?}");
            let n = cam.view_direction();
            for (x, y) in [(100.0, 80.0), (600.0, 400.0), (320.0, 30.0)] {
                let p = PhysicalPoint { x, y };
                let tip = tip_under_cursor(&cam, p, centre, 0.0).unwrap();
                assert!(
                    (tip - centre).dot(n).abs() < 1e-4,
                    "{view:?}: off the plane"
                );
                let back = cam.pixel_at_position(tip);
                assert!(
                    (back.x - x).abs() < 0.5 && (back.y - y).abs() < 0.5,
                    "{view:?}: ({x}, {y}) -> {back:?}"
                );
                let pushed = tip_under_cursor(&cam, p, centre, 0.01).unwrap();
                let eye = cam.position();
                assert!((pushed - tip).dot(n) > 0.0099);
                assert!((pushed - eye).magnitude() > (tip - eye).magnitude());
            }
        }
    }

    #[test]
    fn bounds_skip_non_finite_points_and_top_height_fits_both_axes() {
        let p = [[0.0, 0.0, 0.0], [2.0, 1.0, 3.0], [f32::NAN, 0.0, 0.0]];
        let (lo, hi) = bounds(&p).unwrap();
        assert_eq!((lo, hi), (vec3(0.0, 0.0, 0.0), vec3(2.0, 1.0, 3.0)));
        assert!(bounds(&[]).is_none());
        // 2:1 box in a 4:3 image: the width limits, 2 / (4/3) / 0.9.
        let h = top_view_height_m(Viewport::new_at_origo(400, 300), lo, hi);
        assert!((h - 2.0 / (4.0 / 3.0) / TOP_FILL).abs() < 1e-6);
    }
}
