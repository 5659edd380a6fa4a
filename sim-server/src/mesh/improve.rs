//! Vertex relocation for the explicit step: the few elements a mesher
//! leaves whose own stable step is far below the median's set the whole
//! organ's step (one at a quarter of the median makes every step take four
//! times the sub-steps), so their vertices are moved to raise it.
//!
//! The objective is the proven one the integrator enforces: Irons' element
//! bound, dt_e = 2 / sqrt(lambda_max(K_e, M_e))
//! ([`crate::tensor_mass::stability`]). Each vertex of an element below
//! the threshold is moved to maximise the smallest dt_e of the elements
//! around it, by the active-element steepest ascent of Freitag and
//! Ollivier-Gooch ("Tetrahedral mesh improvement using swapping and
//! smoothing", IJNME 40, 1997): the gradient of the worst incident
//! element's bound (central differences), a backtracking line search that
//! accepts a move only when the minimum over all incident elements rises,
//! no element ever inverted. Interior vertices move freely; surface
//! vertices only within their tangent plane and by at most a quarter of
//! their shortest edge, and not at all on a crease, so the organ's shape
//! stays within the mesher's envelope; so do vertices on the interface of
//! two physical tags (a tumour's or a vessel's surface). Topology and tags
//! are unchanged.
//!
//! ```
//! use sim_server::material::Material;
//! use sim_server::math::Vec3;
//! use sim_server::mesh::improve::{ImproveOptions, improve_for_step};
//! // A cube of six tetrahedra around its diagonal, with an interior vertex
//! // pushed near one face: its thin elements set the step.
//! let mut p = vec![
//!     Vec3::new(0.0, 0.0, 0.0), Vec3::new(1.0, 0.0, 0.0), Vec3::new(1.0, 1.0, 0.0),
//!     Vec3::new(0.0, 1.0, 0.0), Vec3::new(0.0, 0.0, 1.0), Vec3::new(1.0, 0.0, 1.0),
//!     Vec3::new(1.0, 1.0, 1.0), Vec3::new(0.0, 1.0, 1.0), Vec3::new(0.5, 0.5, 0.03),
//! ];
//! // Every boundary triangle of the cube (listed outwards) joined to vertex 8.
//! let faces = [[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4],
//!              [1, 2, 6], [1, 6, 5], [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7]];
//! let tets: Vec<[u32; 4]> = faces.iter().map(|f| [f[0], f[2], f[1], 8]).collect();
//! let material = Material::isotropic(4500.0, 0.45, 1060.0, 0.0).unwrap();
//! let r = improve_for_step(&mut p, &tets, &[], &material, &ImproveOptions::default());
//! assert!(r.after_dt_s > 3.0 * r.before_dt_s);
//! ```

use crate::material::Material;
use crate::math::{Real, Vec3, tet_signed_volume};
use crate::mesh::TET_FACES;
use crate::mesh::quality::face_key;
use crate::tensor_mass::stability::isolated_element_lambda;
use crate::tensor_mass::{Geometry, TetElastic};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;

/// How far the pass goes.
#[derive(Clone, Debug, PartialEq)]
pub struct ImproveOptions {
    /// Elements whose stable step is below the median's divided by this
    /// are improved.
    pub below_median_factor: Real,
    /// Passes over those elements (each pass re-ranks them).
    pub max_passes: usize,
    /// A surface vertex moves at most this fraction of its shortest edge.
    pub surface_move_fraction: Real,
    /// A surface vertex whose faces' normals differ from their mean by
    /// more than this (degrees) is on a crease or corner and stays put.
    pub crease_deg: Real,
    /// The pass stops after this many element eigenvalue solves (about
    /// 4 us each on one core): the gains flatten long before.
    pub max_solves: u64,
}

impl Default for ImproveOptions {
    fn default() -> Self {
        Self {
            below_median_factor: 2.0,
            max_passes: 10,
            surface_move_fraction: 0.25,
            crease_deg: 25.0,
            max_solves: 2_000_000,
        }
    }
}

/// What the pass did.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ImproveReport {
    /// The shortest element stable step before (s).
    pub before_dt_s: Real,
    /// ... and after (s).
    pub after_dt_s: Real,
    /// The median element's stable step before (s).
    pub median_dt_s: Real,
    /// Elements below the median / `below_median_factor` before.
    pub below_before: usize,
    /// ... and after.
    pub below_after: usize,
    /// Interior vertices moved.
    pub moved_interior: usize,
    /// Surface vertices moved (within their tangent plane).
    pub moved_surface: usize,
    /// The largest distance a surface vertex moved (m).
    pub max_surface_move_m: Real,
    /// Passes run.
    pub passes: usize,
    /// The pass's time (s).
    pub seconds: Real,
    /// Element eigenvalue solves it used.
    pub solves: u64,
}

/// How a vertex may move.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Freedom {
    /// Anywhere.
    Free,
    /// Within the plane of this normal, at most this far from `origin`.
    Tangent {
        normal: Vec3,
        origin: Vec3,
        max_m: Real,
    },
    /// Not at all.
    Fixed,
}

/// Raises the shortest element stable step of the tetrahedra `tets`
/// (positively oriented, indices into `positions_m`; `tags` their physical
/// tags, or empty) by moving vertices;
/// `material` gives the bound its scale (the ratio before / after depends
/// only on Poisson's ratio). Elements are never inverted.
pub fn improve_for_step(
    positions_m: &mut [Vec3],
    tets: &[[u32; 4]],
    tags: &[i32],
    material: &Material,
    opts: &ImproveOptions,
) -> ImproveReport {
    let start = std::time::Instant::now();
    let pass = Pass::new(positions_m, tets, tags, material, opts);
    let mut report = pass.run(positions_m, opts);
    report.seconds = start.elapsed().as_secs_f64();
    report
}

/// The pass's state: adjacency, each element's bound, each vertex's freedom.
struct Pass<'a> {
    tets: &'a [[u32; 4]],
    elastic: TetElastic,
    density: Real,
    /// Per vertex, the tetrahedra using it (CSR).
    start: Vec<usize>,
    incident: Vec<u32>,
    dt: Vec<Real>,
    freedom: Vec<Freedom>,
    /// Eigenvalue solves so far.
    solves: std::cell::Cell<u64>,
    /// The incident tetrahedra of the vertex being moved, worst first.
    order: Vec<u32>,
}

impl<'a> Pass<'a> {
    fn new(
        positions: &[Vec3],
        tets: &'a [[u32; 4]],
        tags: &[i32],
        material: &Material,
        opts: &ImproveOptions,
    ) -> Self {
        let n = positions.len();
        let mut count = vec![0usize; n + 1];
        for t in tets {
            for &v in t {
                count[v as usize + 1] += 1;
            }
        }
        for i in 0..n {
            count[i + 1] += count[i];
        }
        let start = count.clone();
        let mut fill = count;
        let mut incident = vec![0u32; tets.len() * 4];
        for (i, t) in tets.iter().enumerate() {
            for &v in t {
                incident[fill[v as usize]] = i as u32;
                fill[v as usize] += 1;
            }
        }
        let elastic = TetElastic::new(material, Vec3::X);
        let density = material.density_kg_m3();
        let mut pass = Self {
            tets,
            elastic,
            density,
            start,
            incident,
            dt: Vec::new(),
            freedom: Vec::new(),
            solves: std::cell::Cell::new(0),
            order: Vec::new(),
        };
        pass.dt = (0..tets.len())
            .map(|t| pass.element_dt(positions, t, None))
            .collect();
        pass.freedom = surface_freedom(positions, tets, tags, &pass, opts);
        pass
    }

    fn incident(&self, v: usize) -> &[u32] {
        &self.incident[self.start[v]..self.start[v + 1]]
    }

    /// The shortest distance from `v` to another vertex of its elements
    /// (infinite when it has none): the scale of its moves.
    fn shortest_edge(&self, positions: &[Vec3], v: usize) -> Real {
        self.incident(v)
            .iter()
            .flat_map(|&t| self.tets[t as usize])
            .map(|w| (positions[w as usize] - positions[v]).length())
            .filter(|l| *l > 0.0)
            .fold(Real::INFINITY, Real::min)
    }

    /// Element `t`'s own stable step, with vertex `moved.0` at `moved.1`;
    /// 0 when that inverts or flattens it.
    fn element_dt(&self, positions: &[Vec3], t: usize, moved: Option<(usize, Vec3)>) -> Real {
        let p = self.tets[t].map(|v| match moved {
            Some((m, at)) if m == v as usize => at,
            _ => positions[v as usize],
        });
        let longest = (0..4)
            .flat_map(|i| (i + 1..4).map(move |j| (i, j)))
            .map(|(i, j)| (p[i] - p[j]).length())
            .fold(0.0, Real::max);
        let volume = tet_signed_volume(p[0], p[1], p[2], p[3]);
        // A move may not flatten an element; an element as given is
        // measured whatever its shape (the report must say its real bound).
        let floor = if moved.is_some() {
            1e-9 * longest.powi(3)
        } else {
            0.0
        };
        if volume.is_nan() || volume <= floor {
            return 0.0;
        }
        self.solves.set(self.solves.get() + 1);
        let lambda = isolated_element_lambda(&self.elastic, &Geometry::new(p), self.density);
        if lambda > 0.0 {
            2.0 / lambda.sqrt()
        } else {
            0.0
        }
    }

    /// The smallest stable step of the elements around `v` (in
    /// `self.order`) with it at `at`, and the element giving it; `None` as
    /// soon as one is not above `floor` (the worst are tried first, so a
    /// rejected move costs a solve or two).
    fn local_min_above(
        &self,
        positions: &[Vec3],
        v: usize,
        at: Vec3,
        floor: Real,
    ) -> Option<(Real, usize)> {
        let mut best = (Real::INFINITY, usize::MAX);
        for &t in &self.order {
            let d = self.element_dt(positions, t as usize, Some((v, at)));
            if d <= floor {
                return None;
            }
            if d < best.0 {
                best = (d, t as usize);
            }
        }
        Some(best)
    }

    fn median(&self) -> Real {
        let mut s = self.dt.clone();
        s.sort_by(Real::total_cmp);
        s.get(s.len() / 2).copied().unwrap_or(0.0)
    }

    fn run(mut self, positions: &mut [Vec3], opts: &ImproveOptions) -> ImproveReport {
        let original: Vec<Vec3> = positions.to_vec();
        let median = self.median();
        let threshold = median / opts.below_median_factor.max(1.0);
        let min_dt = |dt: &[Real]| dt.iter().copied().fold(Real::INFINITY, Real::min);
        let below = |dt: &[Real]| dt.iter().filter(|&&d| d < threshold).count();
        let mut report = ImproveReport {
            before_dt_s: min_dt(&self.dt),
            median_dt_s: median,
            below_before: below(&self.dt),
            ..ImproveReport::default()
        };
        let mut moved = vec![false; positions.len()];
        for _ in 0..opts.max_passes {
            report.passes += 1;
            let before = min_dt(&self.dt);
            // The elements under the threshold, and once none is, the ones
            // within a quarter of the shortest: the step is the minimum, so
            // the pass keeps lifting it while it can.
            let cut = threshold.max(1.25 * before);
            let mut bad: Vec<usize> = (0..self.dt.len()).filter(|&t| self.dt[t] < cut).collect();
            bad.sort_by(|a, b| self.dt[*a].total_cmp(&self.dt[*b]));
            let mut any = false;
            for t in bad {
                if self.solves.get() > opts.max_solves {
                    break;
                }
                for v in self.tets[t].map(|v| v as usize) {
                    if self.relocate(positions, v) {
                        moved[v] = true;
                        any = true;
                    }
                }
            }
            if !any || min_dt(&self.dt) < before * 1.01 || self.solves.get() > opts.max_solves {
                break;
            }
        }
        for (v, _) in moved.iter().enumerate().filter(|(_, m)| **m) {
            match self.freedom[v] {
                Freedom::Free => report.moved_interior += 1,
                _ => {
                    report.moved_surface += 1;
                    report.max_surface_move_m = report
                        .max_surface_move_m
                        .max((positions[v] - original[v]).length());
                }
            }
        }
        report.after_dt_s = min_dt(&self.dt);
        report.solves = self.solves.get();
        report.below_after = below(&self.dt);
        report
    }

    /// Moves `v` uphill on the smallest bound around it; whether it moved.
    fn relocate(&mut self, positions: &mut [Vec3], v: usize) -> bool {
        if self.freedom[v] == Freedom::Fixed || self.incident(v).is_empty() {
            return false;
        }
        let scale = self.shortest_edge(positions, v);
        if !scale.is_finite() {
            return false;
        }
        let mut order = std::mem::take(&mut self.order);
        order.clear();
        order.extend_from_slice(self.incident(v));
        order.sort_by(|a, b| self.dt[*a as usize].total_cmp(&self.dt[*b as usize]));
        self.order = order;
        let mut at = positions[v];
        let Some((mut best, mut active)) =
            self.local_min_above(positions, v, at, Real::NEG_INFINITY)
        else {
            return false;
        };
        let start_best = best;
        for _ in 0..8 {
            let h = 1e-4 * scale;
            let mut g = Vec3::ZERO;
            for axis in 0..3 {
                let mut e = Vec3::ZERO;
                e[axis] = h;
                let up = self.element_dt(positions, active, Some((v, at + e)));
                let down = self.element_dt(positions, active, Some((v, at - e)));
                g[axis] = (up - down) / (2.0 * h);
            }
            if let Freedom::Tangent { normal, .. } = self.freedom[v] {
                g -= normal * g.dot(normal);
            }
            let norm = g.length();
            if norm.is_nan() || norm <= 0.0 {
                break;
            }
            let dir = g / norm;
            let mut step = 0.25 * scale;
            let mut accepted = false;
            for _ in 0..10 {
                let candidate = self.clamp(v, at + dir * step);
                if let Some((value, worst)) =
                    self.local_min_above(positions, v, candidate, best * (1.0 + 1e-6))
                {
                    at = candidate;
                    best = value;
                    active = worst;
                    accepted = true;
                    break;
                }
                step *= 0.5;
            }
            if !accepted {
                break;
            }
        }
        if best <= start_best {
            return false;
        }
        positions[v] = at;
        for i in self.start[v]..self.start[v + 1] {
            let t = self.incident[i] as usize;
            self.dt[t] = self.element_dt(positions, t, None);
        }
        true
    }

    /// `p` brought within a surface vertex's allowed disc.
    fn clamp(&self, v: usize, p: Vec3) -> Vec3 {
        match self.freedom[v] {
            Freedom::Tangent {
                normal,
                origin,
                max_m,
            } => {
                let d = p - origin;
                let d = d - normal * d.dot(normal);
                let len = d.length();
                origin + if len > max_m { d * (max_m / len) } else { d }
            }
            _ => p,
        }
    }
}

/// Each vertex's freedom: surface vertices (on a face of one tetrahedron
/// only) and vertices on an interface between two tags (an inner surface
/// the mesher tagged: a tumour, a vessel) move in their tangent plane
/// unless on a crease, so each tagged region keeps its shape.
fn surface_freedom(
    positions: &[Vec3],
    tets: &[[u32; 4]],
    tags: &[i32],
    pass: &Pass,
    opts: &ImproveOptions,
) -> Vec<Freedom> {
    /// Per face: how many tetrahedra have it, whether two of different
    /// tags share it, and its vertices turned out of the lower tag's one.
    struct Face {
        count: u32,
        interface: bool,
        tag: i32,
        oriented: [u32; 3],
    }
    let tag = |t: usize| tags.get(t).copied().unwrap_or(0);
    let mut faces: HashMap<[u32; 3], Face> = HashMap::with_capacity(tets.len() * 2);
    for (i, t) in tets.iter().enumerate() {
        for (k, f) in TET_FACES.iter().enumerate() {
            let oriented = f.map(|j| t[j]);
            let key = face_key(t, k);
            let face = faces.entry(key).or_insert(Face {
                count: 0,
                interface: false,
                tag: tag(i),
                oriented,
            });
            face.count += 1;
            if face.count > 1 && face.tag != tag(i) {
                face.interface = true;
                if tag(i) < face.tag {
                    face.tag = tag(i);
                    face.oriented = oriented;
                }
            }
        }
    }
    let mut normals: Vec<Vec<Vec3>> = vec![Vec::new(); positions.len()];
    for f in faces.values().filter(|f| f.count == 1 || f.interface) {
        let p = f.oriented.map(|v| positions[v as usize]);
        let n = (p[1] - p[0]).cross(p[2] - p[0]);
        for v in f.oriented {
            normals[v as usize].push(n);
        }
    }
    let cos_crease = opts.crease_deg.to_radians().cos();
    (0..positions.len())
        .map(|v| {
            let ns = &normals[v];
            if ns.is_empty() {
                return Freedom::Free;
            }
            let mean = ns.iter().copied().sum::<Vec3>().normalize_or_zero();
            let flat = mean != Vec3::ZERO
                && ns
                    .iter()
                    .all(|n| n.normalize_or_zero().dot(mean) >= cos_crease);
            if !flat {
                return Freedom::Fixed;
            }
            let shortest = pass.shortest_edge(positions, v);
            Freedom::Tangent {
                normal: mean,
                origin: positions[v],
                max_m: opts.surface_move_fraction * shortest,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material_map::TetMaterials;
    use crate::mesh::{BoxSpec, CellSize, TetMesh};
    use crate::tensor_mass::{ElasticModel, element_bound};

    /// A 60 x 40 x 30 mm box of 5 mm cells with every vertex jittered by
    /// up to `amount` of a cell (surface vertices within their face).
    fn jittered(amount: Real) -> (Vec<Vec3>, Vec<[u32; 4]>) {
        let mesh = BoxSpec::new(Vec3::new(0.06, 0.04, 0.03), CellSize::EdgeM(0.005))
            .generate()
            .unwrap();
        let size = Vec3::new(0.06, 0.04, 0.03);
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut rand = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as Real / (1u64 << 53) as Real - 0.5
        };
        let p: Vec<Vec3> = mesh
            .positions_m()
            .iter()
            .map(|p| {
                let mut q = *p;
                for a in 0..3 {
                    // The outer faces and the plane x = 30 mm (the
                    // interface of the tagged test) stay planes.
                    let on_face = p[a].abs() < 1e-12
                        || (p[a] - size[a]).abs() < 1e-12
                        || (a == 0 && (p[a] - 0.03).abs() < 1e-12);
                    if !on_face {
                        q[a] += 2.0 * amount * 0.005 * rand();
                    }
                }
                q
            })
            .collect();
        let tets: Vec<[u32; 4]> = mesh.tets().iter().map(|t| t.map(|v| v.0)).collect();
        for t in &tets {
            let q = t.map(|v| p[v as usize]);
            assert!(
                tet_signed_volume(q[0], q[1], q[2], q[3]) > 0.0,
                "jitter {amount} inverts"
            );
        }
        (p, tets)
    }

    fn bound(p: &[Vec3], tets: &[[u32; 4]], material: &Material) -> Real {
        let mesh = TetMesh::new(p.to_vec(), tets.to_vec()).unwrap();
        let n = mesh.tet_count();
        let model = ElasticModel::new(mesh, TetMaterials::uniform(*material, n)).unwrap();
        element_bound(&model).dt_max_s
    }

    #[test]
    fn the_pass_raises_the_bound_the_integrator_enforces_without_inverting_or_leaving_the_surface()
    {
        let material = Material::isotropic(4500.0, 0.45, 1060.0, 0.0).unwrap();
        let (before, tets) = jittered(0.2);
        let mut after = before.clone();
        let opts = ImproveOptions {
            max_solves: 300_000,
            ..ImproveOptions::default()
        };
        let r = improve_for_step(&mut after, &tets, &[], &material, &opts);
        // What it reports is what the model's own bound says, before and after.
        let b0 = bound(&before, &tets, &material);
        let b1 = bound(&after, &tets, &material);
        assert!((r.before_dt_s / b0 - 1.0).abs() < 1e-12, "{r:?} vs {b0}");
        assert!((r.after_dt_s / b1 - 1.0).abs() < 1e-12, "{r:?} vs {b1}");
        assert!(b1 > 1.3 * b0, "{b0} -> {b1}: {r:?}");
        assert!(r.moved_interior > 0 && r.moved_surface > 0, "{r:?}");
        // No element inverted; the box keeps its faces (a face vertex moves
        // within its face, an edge or corner vertex not at all).
        for t in &tets {
            let q = t.map(|v| after[v as usize]);
            assert!(tet_signed_volume(q[0], q[1], q[2], q[3]) > 0.0);
        }
        let size = [0.06, 0.04, 0.03];
        for (p, q) in before.iter().zip(&after) {
            let faces: Vec<usize> = (0..3)
                .filter(|&a| p[a].abs() < 1e-12 || (p[a] - size[a]).abs() < 1e-12)
                .collect();
            for &a in &faces {
                assert!((q[a] - p[a]).abs() < 1e-15, "{p} -> {q} left its face");
            }
            if faces.len() >= 2 {
                assert_eq!(p, q, "an edge or corner vertex moved");
            }
        }
    }

    #[test]
    fn a_good_mesh_is_left_alone_and_a_budget_stops_the_pass() {
        let material = Material::isotropic(4500.0, 0.45, 1060.0, 0.0).unwrap();
        // A lattice: no element below half the median; only the worst are
        // touched, and only while they gain.
        let (mut p, tets) = jittered(0.0);
        let r = improve_for_step(&mut p, &tets, &[], &material, &ImproveOptions::default());
        assert_eq!(r.below_before, 0);
        assert!(r.after_dt_s >= r.before_dt_s, "{r:?}");
        let (before, tets) = jittered(0.2);
        let mut q = before.clone();
        let opts = ImproveOptions {
            max_solves: 1000,
            ..ImproveOptions::default()
        };
        let r = improve_for_step(&mut q, &tets, &[], &material, &opts);
        // Stopped at the vertex that crossed the budget.
        assert!(r.solves < 1000 + 10_000, "{r:?}");
        assert!(r.after_dt_s >= r.before_dt_s, "{r:?}");
    }

    #[test]
    fn an_interface_between_two_tags_stays_where_the_mesher_put_it() {
        let material = Material::isotropic(4500.0, 0.45, 1060.0, 0.0).unwrap();
        let (before, tets) = jittered(0.2);
        // Tag 2 beyond the plane x = 30 mm.
        let tags: Vec<i32> = tets
            .iter()
            .map(|t| {
                let x: Real = t.iter().map(|&v| before[v as usize].x).sum::<Real>() / 4.0;
                if x > 0.03 { 2 } else { 1 }
            })
            .collect();
        let volume_of_2 = |p: &[Vec3]| -> Real {
            tets.iter()
                .zip(&tags)
                .filter(|(_, g)| **g == 2)
                .map(|(t, _)| {
                    let q = t.map(|v| p[v as usize]);
                    tet_signed_volume(q[0], q[1], q[2], q[3])
                })
                .sum()
        };
        let opts = ImproveOptions {
            max_solves: 300_000,
            ..ImproveOptions::default()
        };
        let mut kept = before.clone();
        let r = improve_for_step(&mut kept, &tets, &tags, &material, &opts);
        assert!(r.after_dt_s > r.before_dt_s, "{r:?}");
        let v0 = volume_of_2(&before);
        assert!(
            (volume_of_2(&kept) / v0 - 1.0).abs() < 1e-12,
            "the tagged region changed"
        );
        // Without the tags the same pass moves the interface.
        let mut free = before.clone();
        improve_for_step(&mut free, &tets, &[], &material, &opts);
        assert!(
            (volume_of_2(&free) / v0 - 1.0).abs() > 1e-6,
            "a test that cannot fail"
        );
    }

    #[test]
    fn a_flat_element_a_reader_would_refuse_is_opened() {
        // The doc example's cube with its inner vertex 1e-13 m off the
        // bottom face: two elements of relative volume 1e-13.
        let mut p = vec![
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(0.0, 0.0, 1.0),
            Vec3::new(1.0, 0.0, 1.0),
            Vec3::new(1.0, 1.0, 1.0),
            Vec3::new(0.0, 1.0, 1.0),
            Vec3::new(0.4, 0.6, 1e-13),
        ];
        let faces = [
            [0, 2, 1],
            [0, 3, 2],
            [4, 5, 6],
            [4, 6, 7],
            [0, 1, 5],
            [0, 5, 4],
            [1, 2, 6],
            [1, 6, 5],
            [2, 3, 7],
            [2, 7, 6],
            [3, 0, 4],
            [3, 4, 7],
        ];
        let tets: Vec<[u32; 4]> = faces.iter().map(|f| [f[0], f[2], f[1], 8]).collect();
        assert!(
            TetMesh::new(p.clone(), tets.clone()).is_err(),
            "the reader's check"
        );
        let material = Material::isotropic(4500.0, 0.45, 1060.0, 0.0).unwrap();
        let r = improve_for_step(&mut p, &tets, &[], &material, &ImproveOptions::default());
        assert!(TetMesh::new(p.clone(), tets.clone()).is_ok(), "{r:?}");
        assert!(r.after_dt_s > 1e3 * r.before_dt_s, "{r:?}");
    }
}
