//! The viewer end to end. This process plays the simulation (it publishes
//! the embedded liver's scene, mesh state and surface by the protocol, the
//! viewer reading no scene file) so the pictures are predictable: a top-view snapshot covers exactly the organ's
//! projected silhouette, and after a cut the picture changes and shows cut
//! faces. With the real sim-server: a viewer started before the simulation
//! and one started after it both get the mesh, and a viewer that drives a
//! tool (no daemon) makes the simulation touch the liver.

use shared::protocol::{MeshHeader, PROTOCOL_VERSION, RestHeader, TopologyHeader};
use shared::{SessionName, monotonic_ns, services};
use sim_server::ids::TetId;
use sim_server::scene::{SceneSource, build_scene};
use sim_server::tensor_mass::ElasticModel;
use std::path::Path;
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use system_tests::{binary, finish, read_json, scratch_dir};

fn liver() -> ElasticModel {
    let src = SceneSource::embedded();
    build_scene(&src, &src.parse().unwrap()).unwrap().model
}

fn surface(model: &ElasticModel) -> Vec<[u32; 3]> {
    model
        .topology()
        .surface_triangles(model.mesh())
        .map(|t| t.map(|v| v.0))
        .collect()
}

fn rest(model: &ElasticModel) -> Vec<[f32; 3]> {
    model
        .mesh()
        .positions_m()
        .iter()
        .map(|p| [p.x as f32, p.y as f32, p.z as f32])
        .collect()
}

/// Publishes `positions` with the current `triangles` (and its version) at
/// about 60 Hz until `stop`.
fn fake_simulation(
    session: SessionName,
    rest_m: Vec<[f32; 3]>,
    positions: Vec<[f32; 3]>,
    triangles: Arc<Mutex<(u64, Vec<[u32; 3]>)>>,
    stop: Arc<AtomicBool>,
    frames: Arc<AtomicU64>,
) -> std::thread::JoinHandle<()> {
    std::thread::spawn(move || {
        let node = services::node("fake-sim").unwrap();
        let n = positions.len();
        let mesh = services::slice_publisher(&services::mesh_service(&node, &session).unwrap(), n)
            .unwrap();
        let topo_service = services::topology_service(&node, &session).unwrap();
        let topo = services::slice_publisher(&topo_service, 8 * n).unwrap();
        // The scene streams, once (history 1): the name, the rest shape
        // and the surface as built (what the viewer tells cut faces from).
        let rest_pub =
            services::slice_publisher(&services::rest_service(&node, &session).unwrap(), n)
                .unwrap();
        let mut header = RestHeader {
            vertex_count: n as u32,
            ..RestHeader::default()
        };
        header.set_name("fake liver");
        let mut s = rest_pub.loan_slice_uninit(n).unwrap();
        *s.user_header_mut() = header;
        s.write_from_fn(|i| rest_m[i]).send().unwrap();
        let uncut = triangles.lock().unwrap().1.clone();
        let surface0 = services::slice_publisher(
            &services::surface0_service(&node, &session).unwrap(),
            uncut.len(),
        )
        .unwrap();
        let mut s = surface0.loan_slice_uninit(uncut.len()).unwrap();
        *s.user_header_mut() = TopologyHeader {
            version: PROTOCOL_VERSION,
            triangle_count: uncut.len() as u32,
            topology_version: 1,
        };
        s.write_from_slice(&uncut).send().unwrap();
        let mut sent_version = 0;
        let mut seq = 0;
        while !stop.load(Ordering::Relaxed) {
            let (version, tris) = triangles.lock().unwrap().clone();
            if version != sent_version {
                let s = topo.loan_slice_uninit(tris.len()).unwrap();
                let mut s = s;
                *s.user_header_mut() = TopologyHeader {
                    version: PROTOCOL_VERSION,
                    triangle_count: tris.len() as u32,
                    topology_version: version,
                };
                s.write_from_slice(&tris).send().unwrap();
                sent_version = version;
            } else {
                use shared::services::UpdateConnections;
                topo.update_connections().unwrap();
                rest_pub.update_connections().unwrap();
                surface0.update_connections().unwrap();
            }
            let mut s = mesh.loan_slice_uninit(n).unwrap();
            *s.user_header_mut() = MeshHeader {
                version: PROTOCOL_VERSION,
                vertex_count: n as u32,
                frame_seq: seq,
                topology_version: version,
                t_ns: monotonic_ns(),
            };
            s.write_from_fn(|i| positions[i]).send().unwrap();
            seq += 1;
            frames.store(seq, Ordering::Relaxed);
            std::thread::sleep(Duration::from_millis(16));
        }
    })
}

fn snapshot(session: &str, out: &Path, extra: &[&str]) -> serde_json::Value {
    snapshot_sized(session, out, "320x240", extra)
}

/// `viewer --snapshot OUT --size SIZE EXTRA...` on `session`: its report.
fn snapshot_sized(session: &str, out: &Path, size: &str, extra: &[&str]) -> serde_json::Value {
    let json = out.with_extension("json");
    let run = Command::new(binary("viewer"))
        .args(["--session", session, "--wait-s", "20", "--size", size])
        .arg("--snapshot")
        .arg(out)
        .arg("--json")
        .arg(&json)
        .args(extra)
        .output()
        .expect("run viewer");
    assert!(
        run.status.success(),
        "viewer --snapshot: {}",
        String::from_utf8_lossy(&run.stderr)
    );
    read_json(&json)
}

/// RGB pixels, rows top to bottom.
fn read_png(path: &Path) -> (usize, usize, Vec<[u8; 3]>) {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).unwrap();
    let px = buf[..info.buffer_size()]
        .chunks(4)
        .map(|c| [c[0], c[1], c[2]])
        .collect();
    (info.width as usize, info.height as usize, px)
}

/// Which pixels the surface covers in the documented top view: orthographic
/// down -z, +y up, the xy bounding box centred and filling TOP_FILL.
fn expected_top_mask(pos: &[[f32; 3]], tris: &[[u32; 3]], w: usize, h: usize) -> Vec<bool> {
    let lo = [0, 1].map(|k| pos.iter().map(|p| p[k]).fold(f32::INFINITY, f32::min));
    let hi = [0, 1].map(|k| pos.iter().map(|p| p[k]).fold(f32::NEG_INFINITY, f32::max));
    let aspect = w as f32 / h as f32;
    let height_m = (hi[1] - lo[1]).max((hi[0] - lo[0]) / aspect) / viewer::camera::TOP_FILL;
    let scale = h as f32 / height_m;
    let c = [(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0];
    let px = |p: [f32; 3]| {
        [
            w as f32 / 2.0 + (p[0] - c[0]) * scale,
            h as f32 / 2.0 - (p[1] - c[1]) * scale,
        ]
    };
    let mut mask = vec![false; w * h];
    for t in tris {
        let [a, b, d] = t.map(|v| px(pos[v as usize]));
        let x0 = a[0].min(b[0]).min(d[0]).floor().max(0.0) as usize;
        let x1 = (a[0].max(b[0]).max(d[0]).ceil() as usize).min(w - 1);
        let y0 = a[1].min(b[1]).min(d[1]).floor().max(0.0) as usize;
        let y1 = (a[1].max(b[1]).max(d[1]).ceil() as usize).min(h - 1);
        let edge = |p: [f32; 2], q: [f32; 2], r: [f32; 2]| {
            (q[0] - p[0]) * (r[1] - p[1]) - (q[1] - p[1]) * (r[0] - p[0])
        };
        for y in y0..=y1 {
            for x in x0..=x1 {
                let p = [x as f32 + 0.5, y as f32 + 0.5];
                let (e0, e1, e2) = (edge(a, b, p), edge(b, d, p), edge(d, a, p));
                if (e0 >= 0.0 && e1 >= 0.0 && e2 >= 0.0) || (e0 <= 0.0 && e1 <= 0.0 && e2 <= 0.0) {
                    mask[y * w + x] = true;
                }
            }
        }
    }
    mask
}

/// Pixels in the cut faces' colour (pale orange: green above half the red).
fn cut_coloured(px: &[[u8; 3]]) -> usize {
    px.iter()
        .filter(|p| p[0] > 80 && p[0] > p[2] && p[1] as f32 > 0.55 * p[0] as f32)
        .count()
}

#[test]
fn snapshots_show_the_silhouette_and_change_after_a_cut() {
    let name = format!("viewsnap{}", std::process::id());
    let session = SessionName::new(&name).unwrap();
    let dir = scratch_dir("viewer-snap");
    let mut model = liver();
    let positions = rest(&model);
    let triangles = Arc::new(Mutex::new((1u64, surface(&model))));
    let stop = Arc::new(AtomicBool::new(false));
    let frames = Arc::new(AtomicU64::new(0));
    let sim = fake_simulation(
        session.clone(),
        positions.clone(),
        positions.clone(),
        triangles.clone(),
        stop.clone(),
        frames.clone(),
    );

    // Silhouette: the top view covers what the projected surface covers.
    let top = dir.join("top.png");
    let report = snapshot(
        &name,
        &top,
        &["--view", "top", "--no-overlay", "--no-forces"],
    );
    assert_eq!(report["cut_triangles"], 0, "{report}");
    assert_eq!(report["scene"], "fake liver", "{report}");
    let (w, h, px) = read_png(&top);
    let background = px[w * h - 1];
    let drawn: Vec<bool> = px.iter().map(|p| *p != background).collect();
    let expected = expected_top_mask(&positions, &triangles.lock().unwrap().1, w, h);
    let both = drawn
        .iter()
        .zip(&expected)
        .filter(|(a, b)| **a && **b)
        .count();
    let either = drawn
        .iter()
        .zip(&expected)
        .filter(|(a, b)| **a || **b)
        .count();
    let iou = both as f64 / either as f64;
    assert!(
        iou > 0.97,
        "silhouette IoU {iou} ({both} of {either} pixels)"
    );
    assert!(both > w * h / 4, "the organ fills a good part of the frame");

    // A cut: remove every tetrahedron within 2 cm of the top-most vertex.
    let before = dir.join("before.png");
    snapshot(&name, &before, &["--no-overlay"]);
    let top_vertex = (0..positions.len())
        .max_by(|&a, &b| positions[a][2].total_cmp(&positions[b][2]))
        .unwrap();
    let t = positions[top_vertex];
    let near = |v: usize| {
        let p = positions[v];
        ((p[0] - t[0]).powi(2) + (p[1] - t[1]).powi(2) + (p[2] - t[2]).powi(2)).sqrt() < 0.02
    };
    let doomed: Vec<TetId> = (0..model.mesh().tet_count())
        .map(TetId::from)
        .filter(|t| model.mesh().tets()[t.idx()].iter().any(|v| near(v.idx())))
        .collect();
    assert!(doomed.len() > 10);
    for t in doomed {
        model.remove_tet(t).unwrap();
    }
    *triangles.lock().unwrap() = (2, surface(&model));
    let after = dir.join("after.png");
    let report = snapshot(&name, &after, &["--no-overlay"]);
    stop.store(true, Ordering::Relaxed);
    sim.join().unwrap();
    assert_eq!(report["topology_version"], 2, "{report}");
    assert!(report["cut_triangles"].as_u64().unwrap() > 10, "{report}");
    let (_, _, a) = read_png(&before);
    let (_, _, b) = read_png(&after);
    let differ = a.iter().zip(&b).filter(|(p, q)| p != q).count();
    assert!(differ > 200, "only {differ} pixels changed after the cut");
    let (cut_a, cut_b) = (cut_coloured(&a), cut_coloured(&b));
    assert!(
        cut_a < 20 && cut_b > 200,
        "cut-coloured pixels {cut_a} -> {cut_b}"
    );
    assert!(frames.load(Ordering::Relaxed) > 2);
}

/// Publishes one hook (`fulcrum` to `tip`, 2.5 mm radius) in the scene
/// stream and its force sample, `force_n` in contact, at about 60 Hz until
/// `stop`.
fn fake_tool(
    session: SessionName,
    fulcrum: [f64; 3],
    tip: [f64; 3],
    force_n: [f64; 3],
    stop: Arc<AtomicBool>,
) -> std::thread::JoinHandle<()> {
    use shared::protocol::{CONTACT, ForceMsg, SceneInfo, TOOL_HOOK};
    std::thread::spawn(move || {
        let node = services::node("fake-tool").unwrap();
        let scene =
            services::publisher(&services::scene_service(&node, &session).unwrap()).unwrap();
        let mut info = SceneInfo {
            version: PROTOCOL_VERSION,
            tool_count: 1,
            ..SceneInfo::default()
        };
        info.tools[0].set_name("probe");
        info.tools[0].kind = TOOL_HOOK;
        info.tools[0].fulcrum_m = fulcrum;
        info.tools[0].length_m = 0.3;
        info.tools[0].radius_m = 0.0025;
        scene.send_copy(info).unwrap();
        let forces =
            services::publisher(&services::force_service(&node, &session).unwrap()).unwrap();
        let mut seq = 1;
        while !stop.load(Ordering::Relaxed) {
            let mut m = ForceMsg {
                version: PROTOCOL_VERSION,
                tool_count: 1,
                seq,
                t_ns: monotonic_ns(),
                ..ForceMsg::default()
            };
            m.tools[0].position_m = tip;
            m.tools[0].force_n = force_n;
            m.tools[0].flags = CONTACT;
            forces.send_copy(m).unwrap();
            // The scene message reaches viewers that join later.
            use shared::services::UpdateConnections;
            scene.update_connections().unwrap();
            seq += 1;
            std::thread::sleep(Duration::from_millis(16));
        }
    })
}

/// Pixels close to `c` (each channel within `tol`).
fn near_colour(px: &[[u8; 3]], c: [u8; 3], tol: u8) -> Vec<usize> {
    (0..px.len())
        .filter(|&i| (0..3).all(|k| px[i][k].abs_diff(c[k]) <= tol))
        .collect()
}

#[test]
fn a_press_is_shown_in_displacement_colours_with_its_bar_and_a_force_arrow_to_scale() {
    let name = format!("viewdent{}", std::process::id());
    let session = SessionName::new(&name).unwrap();
    let dir = scratch_dir("viewer-dent");
    let model = liver();
    let rest_m = rest(&model);
    // A dent under the top-most vertex: 8 mm deep at its centre, falling
    // to zero 25 mm away.
    let top = (0..rest_m.len())
        .max_by(|&a, &b| rest_m[a][2].total_cmp(&rest_m[b][2]))
        .unwrap();
    let c = rest_m[top];
    let dent = |p: [f32; 3]| {
        let d = ((p[0] - c[0]).powi(2) + (p[1] - c[1]).powi(2)).sqrt();
        if d < 0.025 {
            0.008 * (1.0 - (d / 0.025).powi(2))
        } else {
            0.0
        }
    };
    let pressed: Vec<[f32; 3]> = rest_m
        .iter()
        .map(|&p| [p[0], p[1], p[2] - dent(p)])
        .collect();
    let max_mm = rest_m.iter().map(|&p| dent(p) * 1e3).fold(0.0, f32::max);
    let triangles = Arc::new(Mutex::new((1u64, surface(&model))));
    let stop = Arc::new(AtomicBool::new(false));
    let frames = Arc::new(AtomicU64::new(0));
    let sim = fake_simulation(
        session.clone(),
        rest_m.clone(),
        pressed.clone(),
        triangles.clone(),
        stop.clone(),
        frames,
    );
    // The probe pressing at the dent's centre, the tissue pushing it back
    // sideways by 1 N along +x (so the top view shows the arrow's length).
    let tip = [f64::from(c[0]), f64::from(c[1]), f64::from(c[2]) - 0.008];
    let fulcrum = [tip[0], tip[1], tip[2] + 0.2];
    let tool = fake_tool(session, fulcrum, tip, [1.0, 0.0, 0.0], stop.clone());

    let shot = |file: &str, extra: &[&str]| {
        let out = dir.join(file);
        let view = [&["--view", "top"], extra].concat();
        (
            snapshot_sized(&name, &out, "640x480", &view),
            read_png(&out),
        )
    };
    let (report, (w, h, px)) = shot(
        "dent.png",
        &["--colour", "displacement", "--no-overlay", "--no-forces"],
    );
    // The bar's range is the frame's displacement range.
    let bar = report["colour_bar"].as_array().expect("a colour bar");
    let (lo, hi) = (bar[0].as_f64().unwrap(), bar[1].as_f64().unwrap());
    assert_eq!(lo, 0.0, "{report}");
    assert!(
        (hi - f64::from(max_mm)).abs() < 1e-3,
        "bar top {hi} mm, dent {max_mm} mm: {report}"
    );
    let max = report["max_displacement_mm"].as_f64().unwrap();
    assert!((max - f64::from(max_mm)).abs() < 1e-3, "{report}");
    // The bar holds the map's two ends exactly, the top colour above the
    // bottom one.
    let top_colour = viewer::colour::viridis(1.0);
    let bottom_colour = viewer::colour::viridis(0.0);
    let ups = near_colour(&px, top_colour, 2);
    let downs = near_colour(&px, bottom_colour, 2);
    assert!(
        ups.len() >= viewer::overlay::BAR_W && downs.len() >= viewer::overlay::BAR_W,
        "{} and {} pixels of the bar's ends",
        ups.len(),
        downs.len()
    );
    assert!(
        ups.iter().min().unwrap() / w < downs.iter().max().unwrap() / w,
        "the largest value is at the bar's top"
    );
    // The organ: warm (yellow-green) at the dent, cold (violet-blue) away
    // from it; the top view maps x right and y up as the silhouette test
    // checks.
    let lo_xy = [0, 1].map(|k| pressed.iter().map(|p| p[k]).fold(f32::INFINITY, f32::min));
    let hi_xy = [0, 1].map(|k| {
        pressed
            .iter()
            .map(|p| p[k])
            .fold(f32::NEG_INFINITY, f32::max)
    });
    let height_m = (hi_xy[1] - lo_xy[1]).max((hi_xy[0] - lo_xy[0]) / (w as f32 / h as f32))
        / viewer::camera::TOP_FILL;
    let scale = h as f32 / height_m;
    let centre = [(lo_xy[0] + hi_xy[0]) / 2.0, (lo_xy[1] + hi_xy[1]) / 2.0];
    let pixel = |p: [f32; 3]| {
        let x = (w as f32 / 2.0 + (p[0] - centre[0]) * scale) as usize;
        let y = (h as f32 / 2.0 - (p[1] - centre[1]) * scale) as usize;
        px[y.min(h - 1) * w + x.min(w - 1)]
    };
    let warm = |p: [u8; 3]| p[1] > p[2] + 30;
    assert!(
        warm(pixel(pressed[top])),
        "the dent's centre is drawn {:?}",
        pixel(pressed[top])
    );
    let far = (0..rest_m.len())
        .filter(|&v| ((rest_m[v][0] - c[0]).powi(2) + (rest_m[v][1] - c[1]).powi(2)).sqrt() > 0.06)
        .max_by(|&a, &b| rest_m[a][2].total_cmp(&rest_m[b][2]))
        .unwrap();
    assert!(
        !warm(pixel(pressed[far])) && pixel(pressed[far])[2] > pixel(pressed[far])[1],
        "an unmoved place is drawn {:?}",
        pixel(pressed[far])
    );

    // The force arrow: 1 N, drawn over the tissue along +x, as long as the
    // scale says (the cyan run along the tip's row).
    let arrow_px = |mm_per_n: &str| {
        let (report, (w, _, px)) = shot(
            &format!("arrow-{mm_per_n}.png"),
            &["--no-overlay", "--force-mm-per-n", mm_per_n],
        );
        let a = &report["arrows"][0];
        assert!(
            (a["force_n"].as_f64().unwrap() - 1.0).abs() < 1e-6,
            "{report}"
        );
        let cyan = near_colour(&px, [60, 230, 230], 90)
            .into_iter()
            .filter(|&i| px[i][0] < 140 && px[i][2] > 150)
            .collect::<Vec<_>>();
        let xs = cyan.iter().map(|i| i % w);
        let extent = xs.clone().max().unwrap_or(0) - xs.min().unwrap_or(0);
        (a["length_m"].as_f64().unwrap(), extent as f32)
    };
    let (len20, px20) = arrow_px("20");
    let (len40, px40) = arrow_px("40");
    stop.store(true, Ordering::Relaxed);
    sim.join().unwrap();
    tool.join().unwrap();
    assert!(
        (len20 - 0.02).abs() < 1e-6 && (len40 - 0.04).abs() < 1e-6,
        "{len20} {len40}"
    );
    for (len, extent) in [(len20, px20), (len40, px40)] {
        let expected = len as f32 * scale;
        assert!(
            (extent - expected).abs() < 0.15 * expected + 3.0,
            "arrow drawn {extent} px long, {expected} px expected"
        );
    }
}

#[test]
fn a_clipped_view_shows_the_vessel_fibres_the_surface_hides() {
    let name = format!("viewclip{}", std::process::id());
    let dir = scratch_dir("viewer-clip");
    let sim = sim_server(&name, "8", &dir.join("sim.json"));
    // Fibre-coloured pixels: light and grey (the tissue is red, the
    // background dark).
    let fibre_px = |px: &[[u8; 3]]| {
        px.iter()
            .filter(|p| p.iter().all(|&c| c > 150) && p[0].abs_diff(p[1]) < 40)
            .count()
    };
    let shot = |file: &str, extra: &[&str]| {
        let out = dir.join(file);
        let flags = ["--view", "front", "--fibres", "--no-overlay", "--no-forces"];
        let report = snapshot_sized(&name, &out, "640x480", &[&flags[..], extra].concat());
        let (_, _, px) = read_png(&out);
        (report, fibre_px(&px))
    };
    let (whole, hidden) = shot("whole.png", &[]);
    // The plane across y (the front view looks along -y) just behind the
    // embedded liver's portal vessels.
    let (clipped, shown) = shot("clipped.png", &["--clip", "y:0.65"]);
    finish(sim, Duration::from_secs(20), "sim-server");
    let fibres = whole["fibres"].as_u64().unwrap();
    assert!(fibres > 50, "the liver's vessels: {whole}");
    assert_eq!(
        clipped["fibres_drawn"], fibres,
        "every vessel is behind the plane: {clipped}"
    );
    assert_eq!(clipped["clip"][0], "y", "{clipped}");
    let (all, kept) = (
        whole["triangles_drawn"].as_u64().unwrap(),
        clipped["triangles_drawn"].as_u64().unwrap(),
    );
    assert!(
        kept < all && kept > all / 4,
        "{kept} of {all} surface triangles kept"
    );
    assert!(
        hidden < 30 && shown > 300,
        "fibre pixels: {hidden} with the whole surface, {shown} clipped open"
    );
}

#[test]
fn a_snapshot_of_the_demo_shows_the_cavitrons_cut_and_both_tools() {
    let dir = scratch_dir("viewer-demo");
    let mut demo = Command::new(binary("sim-server"))
        .args(["demo", "--headless", "--no-viewer", "--duration-s", "8"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start the demo");
    // The demo's session is named after its process.
    let name = format!("demo{}", demo.id());
    // The cavitron has removed tissue a few seconds in.
    std::thread::sleep(Duration::from_secs(5));
    let out = dir.join("demo.png");
    let report = snapshot(&name, &out, &["--view", "front", "--no-overlay"]);
    let _ = demo.wait();
    assert!(report["cut_triangles"].as_u64().unwrap() > 0, "{report}");
    assert!(report["topology_version"].as_u64().unwrap() > 1, "{report}");
    assert_eq!(
        report["tools"],
        serde_json::json!(["grasper", "cavitron"]),
        "{report}"
    );
    let (_, _, px) = read_png(&out);
    // The cut faces' pale orange, not the yellow of a tip in contact
    // (whose blue is under a third of its red).
    let cut = px
        .iter()
        .filter(|p| {
            let [r, g, b] = p.map(f32::from);
            r > 80.0 && b > 0.3 * r && g > 0.55 * r && g < 0.85 * r
        })
        .count();
    assert!(cut > 40, "{cut} cut-coloured pixels: {report}");
}

fn sim_server(session: &str, seconds: &str, json: &Path) -> std::process::Child {
    Command::new(binary("sim-server"))
        .args([
            "run",
            "--quiet",
            "--duration-s",
            seconds,
            "--session",
            session,
        ])
        .arg("--json")
        .arg(json)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start sim-server")
}

#[test]
fn a_viewer_started_before_or_after_the_simulation_shows_the_mesh() {
    let name = format!("vieworder{}", std::process::id());
    let dir = scratch_dir("viewer-order");
    let early_png = dir.join("early.png");
    let early = Command::new(binary("viewer"))
        .args(["--session", &name, "--wait-s", "30", "--size", "160x120"])
        .arg("--snapshot")
        .arg(&early_png)
        .arg("--json")
        .arg(early_png.with_extension("json"))
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start the early viewer");
    std::thread::sleep(Duration::from_millis(1500));
    let sim = sim_server(&name, "8", &dir.join("sim.json"));
    let early = early.wait_with_output().unwrap();
    assert!(
        early.status.success(),
        "{}",
        String::from_utf8_lossy(&early.stderr)
    );
    let late = snapshot(&name, &dir.join("late.png"), &[]);
    let early = read_json(&early_png.with_extension("json"));
    for r in [&early, &late] {
        assert!(r["triangles"].as_u64().unwrap() > 1000, "{r}");
        assert!(r["covered_pixels"].as_u64().unwrap() > 1000, "{r}");
        // The scene came with the session, the early viewer's too.
        assert_eq!(r["scene"], sim_server::scene::DEFAULT_SCENE_NAME, "{r}");
        assert!(
            r["fibres"].as_u64().unwrap() > 50,
            "the liver's vessels: {r}"
        );
    }
    finish(sim, Duration::from_secs(20), "sim-server");
}

#[test]
fn without_a_daemon_the_viewer_drives_a_tool_into_the_liver() {
    use viewer::drive::Driver;
    use viewer::session::Session;
    let name = format!("viewdrive{}", std::process::id());
    let dir = scratch_dir("viewer-drive");
    let sim_json = dir.join("sim.json");
    let sim = sim_server(&name, "5", &sim_json);
    let session_name = SessionName::new(&name).unwrap();
    let mut session = Session::join(&session_name).unwrap();
    let pos = rest(&liver());
    let top = pos
        .iter()
        .copied()
        .max_by(|a, b| a[2].total_cmp(&b[2]))
        .unwrap();
    let mut driver = Driver::new(2, [top[0] as f64, top[1] as f64, top[2] as f64 + 0.01]);
    let start = std::time::Instant::now();
    while start.elapsed() < Duration::from_secs(3) {
        session.poll(monotonic_ns());
        // Lower the tip from 1 cm above the top to 6 mm into it.
        let k = (start.elapsed().as_secs_f64() / 1.5).min(1.0);
        driver.tip_m[2] = top[2] as f64 + 0.01 - 0.016 * k;
        driver.update(&session);
        assert!(driver.active(), "no other pose source: the viewer drives");
        std::thread::sleep(Duration::from_millis(2));
    }
    // A daemon (another pose publisher) appears: the viewer lets go.
    let node = services::node("pretend-daemon").unwrap();
    let _daemon =
        services::publisher(&services::pose_service(&node, &session_name).unwrap()).unwrap();
    driver.update(&session);
    assert!(!driver.active());
    finish(sim, Duration::from_secs(20), "sim-server");
    let s = read_json(&sim_json);
    assert!(s["poses_received"].as_u64().unwrap() > 100, "{s}");
    assert!(s["contact_steps"].as_u64().unwrap() > 100, "{s}");
}

#[test]
fn the_viewer_session_follows_a_simulation_that_stops_and_restarts() {
    use viewer::session::Session;
    let name = format!("viewrestart{}", std::process::id());
    let dir = scratch_dir("viewer-restart");
    let mut session = Session::join(&SessionName::new(&name).unwrap()).unwrap();
    let wait_drawable = |session: &mut Session, after_frames: u64| {
        let start = std::time::Instant::now();
        while start.elapsed() < Duration::from_secs(15) {
            session.poll(monotonic_ns());
            if session.drawable() && session.frames > after_frames {
                return;
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        panic!("no drawable mesh state after {after_frames} frames");
    };
    let first = sim_server(&name, "2", &dir.join("a.json"));
    wait_drawable(&mut session, 0);
    let vertices = session.positions_m.len();
    finish(first, Duration::from_secs(20), "sim-server");
    // The simulation is gone: after a second without frames the viewer says so.
    std::thread::sleep(Duration::from_millis(1200));
    session.poll(monotonic_ns());
    assert!(!session.sim_alive(monotonic_ns()));
    let frames = session.frames;
    let second = sim_server(&name, "2", &dir.join("b.json"));
    wait_drawable(&mut session, frames + 2);
    assert!(session.sim_alive(monotonic_ns()));
    assert_eq!(session.positions_m.len(), vertices);
    assert_eq!(session.topology_version, 1, "the new simulation's surface");
    finish(second, Duration::from_secs(20), "sim-server");
}

#[test]
fn the_help_texts_hold_no_rustdoc_links() {
    // Doc comments double as --help: a `[`NAME`]` link reads as noise there.
    for bin in ["viewer", "sim-server", "haptic-daemon"] {
        let out = std::process::Command::new(system_tests::binary(bin))
            .arg("--help")
            .output()
            .unwrap();
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(
            out.status.success() && !text.contains("[`"),
            "{bin}: {text}"
        );
    }
}

#[test]
fn the_viewer_takes_the_scene_from_the_simulation() {
    // The simulation runs the box scene (one tool, "probe", isotropic); the
    // viewer reads no scene file: the tools it draws and reports, the
    // scene's name and its fibres come from the session's streams.
    let name = format!("viewtools{}", std::process::id());
    let dir = scratch_dir("viewer-tools");
    let box_scene = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("data/box-probe.toml");
    let mut sim = Command::new(binary("sim-server"))
        .args(["run", "--quiet", "--duration-s", "20", "--session", &name])
        .arg("--scene")
        .arg(&box_scene)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start sim-server");
    let report = snapshot(&name, &dir.join("box.png"), &["--no-overlay"]);
    // SAFETY: kill(2) on our own child's pid.
    unsafe { libc::kill(sim.id() as libc::pid_t, libc::SIGTERM) };
    let _ = sim.wait();
    assert_eq!(report["tools"], serde_json::json!(["probe"]), "{report}");
    assert_eq!(report["scene"], box_scene.display().to_string(), "{report}");
    assert_eq!(report["fibres"], 0, "{report}");
    assert_eq!(report["cut_triangles"], 0, "{report}");
}
