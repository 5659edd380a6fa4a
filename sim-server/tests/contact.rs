//! Tool contact laws: contact vertices lie on the contact plane outside the
//! tool and slide with it, the reaction opposes penetration, equals the sum
//! of the constraint forces, grows with depth and tends to the static
//! solver's, the contact stiffness is symmetric positive semidefinite,
//! gripped tissue follows the tool, and cutting tools remove exactly what
//! their rule names.

use sim_server::contact::{
    Constraint, ConstraintKind, ContactReport, Plane, Reaction, ToolInput, ToolPose, Tools,
};
use sim_server::prelude::*;
use sim_server::scene::ToolDecl;
use sim_server::scene::spec::ToolKind;
use std::collections::BTreeSet;

/// Block 4 x 4 x 2 cm, 4 mm cells, bottom face fixed.
const HEIGHT_M: f64 = 0.02;
const RADIUS_M: f64 = 0.005;
const CENTRE: [f64; 2] = [0.02, 0.02];

/// One tool in a [`Tools`] set, driven like a lone instrument.
struct Single(Tools);

impl Single {
    /// `decl` over `sim`, the fixed bottom reserved.
    fn new(decl: &ToolDecl, sim: &Explicit<f64>) -> Self {
        let mut tools = Tools::new(std::slice::from_ref(decl), sim.model());
        for v in bottom(sim) {
            tools.reserve(v);
        }
        Self(tools)
    }

    fn update(&mut self, sim: &mut Explicit<f64>, tip_m: Vec3, jaw_opening: f64) -> ContactReport {
        self.0
            .update(sim, &[Some(ToolInput { tip_m, jaw_opening })])[0]
    }

    fn constraints(&self) -> &[Constraint] {
        self.0.tool(0).constraints()
    }

    fn reaction(&self, sim: &Explicit<f64>) -> Reaction {
        self.0.reaction(0, sim)
    }

    fn pose(&self) -> Option<&ToolPose> {
        self.0.tool(0).pose()
    }

    fn decl(&self) -> &ToolDecl {
        self.0.tool(0).decl()
    }
}

fn setup(kind: ToolKind) -> (Explicit<f64>, Single) {
    setup_at(kind, 1e-3)
}

/// [`setup`] stepping `dt_s`.
fn setup_at(kind: ToolKind, dt_s: f64) -> (Explicit<f64>, Single) {
    let mesh = BoxSpec::new(Vec3::new(0.04, 0.04, HEIGHT_M), CellSize::EdgeM(0.004))
        .generate()
        .unwrap();
    let tissue = Material::isotropic(4500.0, 0.45, 1060.0, 20.0).unwrap();
    let materials = TetMaterials::uniform(tissue, mesh.tet_count());
    let model = ElasticModel::new(mesh, materials).unwrap();
    let mut sim = Explicit::<f64>::new(model, ExplicitConfig::new(dt_s)).unwrap();
    let decl = ToolDecl {
        name: "tool".into(),
        kind,
        fulcrum_m: [CENTRE[0], CENTRE[1], 0.12],
        length_m: 0.3,
        radius_m: RADIUS_M,
        tip_length_m: 0.01,
        friction: Default::default(),
    };
    for v in bottom(&sim) {
        sim.fix(v);
    }
    let tool = Single::new(&decl, &sim);
    (sim, tool)
}

fn bottom(sim: &Explicit<f64>) -> Vec<VertexId> {
    let p = sim.model().mesh().positions_m();
    (0..p.len())
        .filter(|&v| p[v].z == 0.0)
        .map(VertexId::from)
        .collect()
}

/// The tool end for a vertical tool whose lowest point is `depth_m` below
/// the top face at (x, y).
fn tip(depth_m: f64, x: f64, y: f64) -> Vec3 {
    Vec3::new(x, y, HEIGHT_M - depth_m + RADIUS_M)
}

/// Moves the tip linearly from `a` to `b` over `steps` steps (update, step).
fn travel(sim: &mut Explicit<f64>, tool: &mut Single, a: Vec3, b: Vec3, steps: usize, jaw: f64) {
    for k in 1..=steps {
        let t = a.lerp(b, k as f64 / steps as f64);
        tool.update(sim, t, jaw);
        sim.step();
    }
}

fn press(sim: &mut Explicit<f64>, tool: &mut Single, depth_m: f64, hold: usize) -> Vec3 {
    let end = tip(depth_m, CENTRE[0], CENTRE[1]);
    travel(sim, tool, tip(-0.001, CENTRE[0], CENTRE[1]), end, 100, 1.0);
    travel(sim, tool, end, end, hold, 1.0);
    end
}

fn surface_vertices(sim: &Explicit<f64>) -> BTreeSet<VertexId> {
    let m = sim.model();
    m.topology().surface_triangles(m.mesh()).flatten().collect()
}

/// Every tip constraint is where it was put, on the plane tangent to the
/// tip capsule, and no surface vertex is inside the tool by more than `slack_m`.
fn check_plane_and_clearance(sim: &Explicit<f64>, tool: &Single, slack_m: f64) {
    let pose = *tool.pose().unwrap();
    for c in tool.constraints() {
        let x = sim.position(c.vertex);
        assert!(
            (x - c.target_m).length() < 1e-12,
            "{:?} not at its target",
            c.vertex
        );
        let ConstraintKind::Tip(n) = c.kind else {
            panic!("unexpected {:?}", c.kind)
        };
        let h = Plane::tangent(&pose.tip, RADIUS_M, n).height_m(x);
        assert!(h.abs() < 1e-12, "{:?} is {h} m off the plane", c.vertex);
        assert!(pose.tip.distance_m(x) >= RADIUS_M - 1e-12);
    }
    for v in surface_vertices(sim) {
        let d = pose.tip.distance_m(sim.position(v));
        assert!(d >= RADIUS_M - slack_m, "{v:?} is {d} m from the tip axis");
    }
}

#[test]
fn pressed_tip_keeps_contacts_on_the_plane_outside_the_tool() {
    let (mut sim, mut tool) = setup(ToolKind::Hook);
    let end = press(&mut sim, &mut tool, 0.003, 100);
    for _ in 0..50 {
        let report = tool.update(&mut sim, end, 1.0);
        sim.step();
        assert!(
            report.contact && report.constrained_vertices >= 1,
            "{report:?}"
        );
        // Free vertices may enter the tool during one step (they are caught at
        // the next update): allow 2% of the radius.
        check_plane_and_clearance(&sim, &tool, 0.02 * RADIUS_M);
    }
}

#[test]
fn moving_sideways_slides_the_contact() {
    let (mut sim, mut tool) = setup(ToolKind::Hook);
    let start = press(&mut sim, &mut tool, 0.003, 100);
    let before: BTreeSet<VertexId> = tool.constraints().iter().map(|c| c.vertex).collect();
    let end = start + Vec3::new(0.008, 0.0, 0.0);
    for k in 1..=200 {
        tool.update(&mut sim, start.lerp(end, k as f64 / 200.0), 1.0);
        sim.step();
        check_plane_and_clearance(&sim, &tool, 0.02 * RADIUS_M);
    }
    let after: BTreeSet<VertexId> = tool.constraints().iter().map(|c| c.vertex).collect();
    assert!(!after.is_empty());
    assert!(after != before, "contact set did not change: {after:?}");
    // The contact follows the tool: its centroid moved along +x.
    let centroid =
        |s: &BTreeSet<VertexId>| s.iter().map(|v| sim.position(*v)).sum::<Vec3>() / s.len() as f64;
    assert!(centroid(&after).x > centroid(&before).x + 0.004);
}

#[test]
fn reaction_opposes_penetration_and_is_the_sum_of_constraint_forces() {
    let (mut sim, mut tool) = setup(ToolKind::Hook);
    press(&mut sim, &mut tool, 0.003, 300);
    let r = tool.reaction(&sim);
    assert!(r.force_n.z > 0.0, "{:?}", r.force_n);
    assert!(r.force_n.x.abs().max(r.force_n.y.abs()) < 0.2 * r.force_n.z);
    let u: Vec<Vec3> = sim
        .displacements()
        .iter()
        .map(|a| Vec3::from_array(*a))
        .collect();
    let mut f = vec![Vec3::ZERO; u.len()];
    sim.model().elastic_forces(&u, &mut f);
    let sum: Vec3 = tool.constraints().iter().map(|c| f[c.vertex.idx()]).sum();
    assert!(
        (sum - r.force_n).length() <= 1e-12 * sum.length(),
        "{sum} vs {}",
        r.force_n
    );
}

#[test]
fn reaction_grows_with_depth() {
    let mut last = 0.0;
    for depth in [0.001, 0.002, 0.003] {
        let (mut sim, mut tool) = setup(ToolKind::Hook);
        press(&mut sim, &mut tool, depth, 400);
        let fz = tool.reaction(&sim).force_n.z;
        assert!(fz > last, "depth {depth}: {fz} N after {last} N");
        last = fz;
    }
}

#[test]
fn contact_stiffness_is_symmetric_positive_semidefinite() {
    let (mut sim, mut tool) = setup(ToolKind::Hook);
    let start = press(&mut sim, &mut tool, 0.003, 100);
    // Tilted contact too: slide so the plane normal is not exactly z.
    travel(
        &mut sim,
        &mut tool,
        start,
        start + Vec3::new(0.006, 0.003, 0.0),
        50,
        1.0,
    );
    let k = tool.reaction(&sim).stiffness_n_per_m;
    let scale = sim_server::math::max_abs(&k);
    assert!(scale > 0.0);
    assert!(sim_server::math::max_abs(&(k - k.transpose())) <= 1e-12 * scale);
    let m = nalgebra::Matrix3::from_fn(|r, c| k.col(c)[r]);
    for e in m.symmetric_eigen().eigenvalues.iter() {
        assert!(*e >= -1e-12 * scale, "eigenvalue {e}");
    }
    // A vertical push is resisted mostly vertically.
    assert!(k.col(2).z > 0.5 * scale);
}

#[test]
fn gripped_vertices_follow_the_tip_and_are_released_when_the_jaws_open() {
    let (mut sim, mut tool) = setup(ToolKind::Grasper);
    let end = press(&mut sim, &mut tool, 0.002, 50);
    let report = tool.update(&mut sim, end, 0.3);
    sim.step();
    assert!(report.gripping, "{report:?}");
    let held: Vec<(VertexId, Vec3)> = tool
        .constraints()
        .iter()
        .filter(|c| c.kind == ConstraintKind::Grip)
        .map(|c| (c.vertex, sim.position(c.vertex)))
        .collect();
    assert!(!held.is_empty());
    let up = end + Vec3::new(0.0, 0.0, 0.005);
    for k in 1..=100 {
        let t = end.lerp(up, k as f64 / 100.0);
        assert!(tool.update(&mut sim, t, 0.3).gripping);
        sim.step();
        for (v, p0) in &held {
            let moved = sim.position(*v) - *p0;
            assert!((moved - (t - end)).length() < 1e-12, "{v:?} moved {moved}");
        }
    }
    let lifted: Vec<f64> = held.iter().map(|(v, _)| sim.position(*v).z).collect();
    let report = tool.update(&mut sim, up, 1.0);
    assert!(!report.gripping);
    assert!(
        held.iter()
            .all(|(v, _)| tool.constraints().iter().all(|c| c.vertex != *v))
    );
    for _ in 0..300 {
        tool.update(&mut sim, up, 1.0);
        sim.step();
    }
    for ((v, _), z) in held.iter().zip(lifted) {
        assert!(sim.position(*v).z < z - 0.001, "{v:?} stayed up");
    }
}

/// Live tetrahedra with a vertex within the radius of the tool's tip, by brute force.
fn touching_tip(sim: &Explicit<f64>, tool: &Single, tip_m: Vec3) -> BTreeSet<TetId> {
    let decl = tool.decl();
    let fulcrum = Vec3::from_array(decl.fulcrum_m);
    let t = (tip_m - fulcrum).normalize();
    let a = tip_m - t * decl.tip_length_m;
    let m = sim.model();
    (0..m.mesh().tet_count())
        .map(TetId::from)
        .filter(|t| m.topology().is_alive(*t))
        .filter(|t| {
            m.mesh().tets()[t.idx()].iter().any(|v| {
                let x = sim.position(*v);
                let s = ((x - a).dot(tip_m - a) / (tip_m - a).length_squared()).clamp(0.0, 1.0);
                x.distance(a + (tip_m - a) * s) < decl.radius_m
            })
        })
        .collect()
}

fn dead(sim: &Explicit<f64>) -> BTreeSet<TetId> {
    let m = sim.model();
    (0..m.mesh().tet_count())
        .map(TetId::from)
        .filter(|t| !m.topology().is_alive(*t))
        .collect()
}

#[test]
fn cavitron_removes_exactly_the_tetrahedra_touching_its_tip() {
    let (mut sim, mut tool) = setup(ToolKind::Cavitron);
    // Some deformation first, so current (not rest) positions matter.
    let off = tip(-0.002, 0.011, 0.013);
    travel(&mut sim, &mut tool, off, off, 5, 1.0);
    let at = tip(0.004, 0.011, 0.013);
    let expected = touching_tip(&sim, &tool, at);
    assert!(!expected.is_empty());
    let report = tool.update(&mut sim, at, 1.0);
    assert_eq!(report.tets_removed, expected.len());
    assert_eq!(dead(&sim), expected);
    sim.step();
    // Nothing is left within the radius: the same pose removes nothing more
    // unless the step moved tissue in.
    let again = touching_tip(&sim, &tool, at);
    let report = tool.update(&mut sim, at, 1.0);
    assert_eq!(report.tets_removed, again.len());
    assert!(sim.displacements().iter().flatten().all(|x| x.is_finite()));
}

#[test]
fn the_cavitron_burns_every_millisecond_of_simulated_time() {
    // At 0.25 ms steps it burns at the first update in tissue and every
    // fourth after, each time exactly what touches its tip then.
    let (mut sim, mut tool) = setup_at(ToolKind::Cavitron, 2.5e-4);
    let mut burnt_at = Vec::new();
    for k in 0..12 {
        let at = tip(0.002, 0.008 + 0.002 * k as f64, 0.013);
        let expected = touching_tip(&sim, &tool, at);
        let report = tool.update(&mut sim, at, 1.0);
        if report.tets_removed > 0 {
            assert_eq!(report.tets_removed, expected.len(), "update {k}");
            burnt_at.push(k);
        }
        sim.step();
    }
    assert_eq!(burnt_at, [0, 4, 8]);
    // Withdrawn right after a burn and back at the next update: it burns at
    // once (a tool that comes back starts afresh, not three steps short).
    let burnt = tool
        .update(&mut sim, tip(0.002, 0.034, 0.013), 1.0)
        .tets_removed;
    assert!(burnt > 0, "update 12 burns");
    tool.0.update(&mut sim, &[None]);
    let at = tip(0.002, 0.03, 0.03);
    assert!(tool.update(&mut sim, at, 1.0).tets_removed > 0);
}

#[test]
fn closed_jaws_cut_the_gripped_tissue() {
    let (mut sim, mut tool) = setup(ToolKind::Grasper);
    let end = press(&mut sim, &mut tool, 0.002, 50);
    tool.update(&mut sim, end, 0.3);
    sim.step();
    let held: BTreeSet<VertexId> = tool
        .constraints()
        .iter()
        .filter(|c| c.kind == ConstraintKind::Grip)
        .map(|c| c.vertex)
        .collect();
    assert!(!held.is_empty());
    let m = sim.model();
    let expected: BTreeSet<TetId> = (0..m.mesh().tet_count())
        .map(TetId::from)
        .filter(|t| m.mesh().tets()[t.idx()].iter().any(|v| held.contains(v)))
        .collect();
    let report = tool.update(&mut sim, end, 0.05);
    assert_eq!(report.tets_removed, expected.len());
    assert!(!report.gripping);
    assert_eq!(dead(&sim), expected);
    for _ in 0..50 {
        tool.update(&mut sim, end, 0.05);
        sim.step();
    }
    assert!(sim.displacements().iter().flatten().all(|x| x.is_finite()));
}

#[test]
fn shaft_pressing_across_the_top_pushes_it_down_along_the_shaft_plane() {
    let (mut sim, _) = setup(ToolKind::Hook);
    // A nearly horizontal tool along x whose shaft crosses the block.
    let z = HEIGHT_M + RADIUS_M - 0.002;
    let decl = ToolDecl {
        name: "shaft".into(),
        kind: ToolKind::Hook,
        fulcrum_m: [-0.1, 0.02, z],
        length_m: 0.3,
        radius_m: RADIUS_M,
        tip_length_m: 0.01,
        friction: Default::default(),
    };
    let mut tool = Single::new(&decl, &sim);
    let a = Vec3::new(0.1, 0.02, z + 0.003);
    let b = Vec3::new(0.1, 0.02, z);
    travel(&mut sim, &mut tool, a, b, 100, 1.0);
    travel(&mut sim, &mut tool, b, b, 200, 1.0);
    let shaft = tool.pose().unwrap().shaft.unwrap();
    assert!(!tool.constraints().is_empty());
    for c in tool.constraints() {
        let ConstraintKind::Shaft(n) = c.kind else {
            panic!("unexpected {:?}", c.kind)
        };
        assert!(
            n.dot(Vec3::X).abs() < 1e-12,
            "N_proj not orthogonal to the shaft"
        );
        let h = Plane::tangent(&shaft, RADIUS_M, n).height_m(sim.position(c.vertex));
        assert!(h.abs() < 1e-12);
    }
    let f = tool.reaction(&sim).force_n;
    assert!(f.z > 0.0 && f.x.abs() < 0.2 * f.z, "{f}");
}

#[test]
fn static_press_reaction_matches_the_static_solver() {
    let (mut sim, mut tool) = setup(ToolKind::Hook);
    let end = press(&mut sim, &mut tool, 0.003, 3000);
    // Cost of one update (detect, project, impose) and one reaction, for the record.
    let clock = std::time::Instant::now();
    for _ in 0..1000 {
        tool.update(&mut sim, end, 1.0);
        sim.step();
        std::hint::black_box(tool.reaction(&sim));
    }
    let with_step = clock.elapsed().as_secs_f64() / 1000.0;
    let clock = std::time::Instant::now();
    for _ in 0..1000 {
        tool.update(&mut sim, end, 1.0);
        std::hint::black_box(tool.reaction(&sim));
    }
    let contact_only = clock.elapsed().as_secs_f64() / 1000.0;
    println!(
        "update + reaction {:.1} us, with the step {:.1} us ({} vertices, {} substeps)",
        contact_only * 1e6,
        with_step * 1e6,
        sim.model().vertex_count(),
        sim.substeps()
    );
    sim.step();
    let dynamic = tool.reaction(&sim).force_n;
    let mut dirichlet = Dirichlet::new(sim.model().vertex_count());
    for v in bottom(&sim) {
        dirichlet.fix(v);
    }
    for c in tool.constraints() {
        dirichlet.prescribe(c.vertex, sim.displacement(c.vertex));
    }
    let loads = vec![Vec3::ZERO; sim.model().vertex_count()];
    let solution = solve_static(sim.model(), &dirichlet, &loads).unwrap();
    // The static solver reports the force the support exerts on the body;
    // the tool feels the opposite.
    let on_tool: Vec3 = -tool
        .constraints()
        .iter()
        .map(|c| solution.force_n[c.vertex.idx()])
        .sum::<Vec3>();
    let err = (dynamic - on_tool).length() / on_tool.length();
    println!("dynamic {dynamic} N, static {on_tool} N, relative difference {err:.2e}");
    assert!(err < 1e-6, "dynamic {dynamic} vs static {on_tool}");
}

/// Two vertical tools over the block: `kinds[i]` with its fulcrum above
/// (x_i, centre y).
fn two_tools(sim: &Explicit<f64>, kinds: [ToolKind; 2], x: [f64; 2]) -> Tools {
    let decls: Vec<ToolDecl> = (0..2)
        .map(|i| ToolDecl {
            name: format!("tool{i}"),
            kind: kinds[i],
            fulcrum_m: [x[i], CENTRE[1], 0.12],
            length_m: 0.3,
            radius_m: RADIUS_M,
            tip_length_m: 0.01,
            friction: Default::default(),
        })
        .collect();
    let mut tools = Tools::new(&decls, sim.model());
    for v in bottom(sim) {
        tools.reserve(v);
    }
    tools
}

/// Each constrained vertex belongs to exactly one tool, sits at its target
/// after the step (no tool released what another holds), and the tools'
/// reactions add up to the elastic force on the union of their vertices.
fn check_exclusive(sim: &Explicit<f64>, tools: &Tools) {
    let mut seen = BTreeSet::new();
    for (i, t) in tools.iter().enumerate() {
        for c in t.constraints() {
            assert!(seen.insert(c.vertex), "{:?} held by two tools", c.vertex);
            assert_eq!(tools.owner(c.vertex), Some(i));
            let x = sim.position(c.vertex);
            assert!((x - c.target_m).length() < 1e-12, "{:?} let go", c.vertex);
        }
    }
    let u: Vec<Vec3> = sim
        .displacements()
        .iter()
        .map(|a| Vec3::from_array(*a))
        .collect();
    let mut f = vec![Vec3::ZERO; u.len()];
    sim.model().elastic_forces(&u, &mut f);
    let union: Vec3 = seen.iter().map(|v| f[v.idx()]).sum();
    let total: Vec3 = (0..tools.len())
        .map(|i| tools.reaction(i, sim).force_n)
        .sum();
    assert!((union - total).length() <= 1e-12 * union.length().max(1e-30));
}

#[test]
fn two_tools_pressing_the_same_spot_never_share_a_vertex() {
    let (mut sim, _) = setup(ToolKind::Hook);
    // Side by side, 6 mm apart with 5 mm radii: their footprints overlap.
    let x = [CENTRE[0] - 0.003, CENTRE[0] + 0.003];
    let mut tools = two_tools(&sim, [ToolKind::Hook, ToolKind::Hook], x);
    let at = |i: usize, depth: f64| {
        Some(ToolInput {
            tip_m: tip(depth, x[i], CENTRE[1]),
            jaw_opening: 1.0,
        })
    };
    let mut both = [false; 2];
    for k in 0..=300 {
        let depth = 0.004 * (k.min(100) as f64 / 100.0) - 0.001;
        let reports = tools
            .update(&mut sim, &[at(0, depth), at(1, depth)])
            .to_vec();
        sim.step();
        check_exclusive(&sim, &tools);
        for i in 0..2 {
            both[i] |= reports[i].contact;
        }
    }
    assert_eq!(both, [true, true], "each tool touches the tissue");
    // Withdraw the first tool: the second keeps (and takes over) the rest.
    for _ in 0..200 {
        tools.update(&mut sim, &[None, at(1, 0.003)]);
        sim.step();
        check_exclusive(&sim, &tools);
        assert!(tools.tool(0).constraints().is_empty());
    }
    assert!(!tools.tool(1).constraints().is_empty());
    assert!(sim.displacements().iter().flatten().all(|x| x.is_finite()));
}

#[test]
fn gripped_tissue_stays_with_the_grasper_when_another_tool_presses_on_it() {
    let (mut sim, _) = setup(ToolKind::Grasper);
    let x = [CENTRE[0], CENTRE[0] + 0.002];
    let mut tools = two_tools(&sim, [ToolKind::Hook, ToolKind::Grasper], x);
    let grasper = |depth: f64, jaw: f64| {
        Some(ToolInput {
            tip_m: tip(depth, x[1], CENTRE[1]),
            jaw_opening: jaw,
        })
    };
    // The grasper (declared second) presses with its jaws open, then closes.
    for k in 0..=100 {
        tools.update(&mut sim, &[None, grasper(0.002 * k as f64 / 100.0, 1.0)]);
        sim.step();
    }
    let reports = tools
        .update(&mut sim, &[None, grasper(0.002, 0.3)])
        .to_vec();
    sim.step();
    assert!(reports[1].gripping);
    let held: BTreeSet<VertexId> = tools
        .tool(1)
        .constraints()
        .iter()
        .map(|c| c.vertex)
        .collect();
    // The hook (first in order) now comes down on the same spot.
    let hook = |depth: f64| {
        Some(ToolInput {
            tip_m: tip(depth, x[0], CENTRE[1]),
            jaw_opening: 1.0,
        })
    };
    for k in 0..=150 {
        let depth = 0.004 * (k.min(100) as f64 / 100.0) - 0.001;
        let reports = tools
            .update(&mut sim, &[hook(depth), grasper(0.002, 0.3)])
            .to_vec();
        sim.step();
        assert!(reports[1].gripping);
        check_exclusive(&sim, &tools);
        for v in &held {
            assert_eq!(tools.owner(*v), Some(1), "{v:?} taken from the grasper");
        }
    }
    assert!(
        !tools.tool(0).constraints().is_empty(),
        "the hook touches around the grip"
    );
}
