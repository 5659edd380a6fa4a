//! Linearly implicit contact springs (implicit-explicit integration): the
//! tissue's own forces stay explicit, the penalty springs are taken at the
//! end of the sub-step, linearised about its start, so they no longer limit
//! the step (the explicit springs needed about six sub-steps per
//! millisecond on the liver, each a full pass over the mesh).
//!
//! The explicit sub-step has already moved every free vertex i to
//! u*_i = u_i + a_i (f_i(u) ...) with the contact force at u; replacing that
//! force by f_c(u) - H (u+ - u), with H = sum_p J_p^T G_p J_p the springs'
//! Hessian (each point's slope along its normal, and a sticking point's
//! tangential stiffness), gives for delta = u+ - u on the contact vertices
//!
//! ```text
//! (D + H) delta = D (u* - u),     D = diag(1 / a_i) = m_i / h^2 + c_i / 2h
//! ```
//!
//! (vertices that are not free keep their motion, which moves to the right
//! side), symmetric positive definite: conjugate gradients with 3x3 block
//! Jacobi, from the explicit prediction, to a relative residual of 1e-10.
//! For springs this is the classical IMEX split (Ascher, Ruuth and Wetton
//! 1995; stiff penalty terms implicit as in SOFA's implicit solvers): the
//! step is bounded by the tissue alone, and the springs' high frequencies
//! are damped rather than resolved. The Hunt-Crossley damping and the
//! turning of the normal around the tool stay explicit (the damping is
//! bounded as before; the turning is soft).

use super::{ContactField, ContactPoint};
use crate::math::{Mat3, Real, Vec3};

/// Iterations at most (the system's condition is about 1 + k_p / (m / h^2),
/// a few hundred at worst).
const MAX_ITERATIONS: usize = 200;
/// Relative residual to stop at.
const TOLERANCE: Real = 1e-10;

/// One surface triangle's share of H: the sum over its acting points of
/// w_a w_b G_p for each pair of its corners, so that a conjugate-gradient
/// iteration costs a few 3x3 products per triangle instead of per point
/// (a triangle carries up to about 16 points at the default spacing, and
/// the iterations were the largest part of the contact's cost in a press).
#[derive(Clone, Copy, Debug)]
struct Group {
    /// The corners' slots among the unknowns (`u32::MAX`: imposed).
    slots: [u32; 3],
    /// The corners themselves.
    vertices: [u32; 3],
    /// Blocks (0,0), (1,1), (2,2), (0,1), (0,2), (1,2): H is symmetric, and
    /// so is each block.
    blocks: [Mat3; 6],
}

/// Block index of the corner pair (a, b) in [`Group::blocks`].
const PAIR: [[usize; 3]; 3] = [[0, 3, 4], [3, 1, 5], [4, 5, 2]];

impl Group {
    /// H restricted to this triangle applied to the corner values `x`,
    /// for corner `a`.
    #[inline]
    fn row(&self, a: usize, x: &[Vec3; 3]) -> Vec3 {
        let r = &PAIR[a];
        self.blocks[r[0]] * x[0] + self.blocks[r[1]] * x[1] + self.blocks[r[2]] * x[2]
    }
}

/// Scratch of the implicit correction (buffers reused across steps).
#[derive(Clone, Debug, Default)]
pub struct ImplicitSprings {
    /// Per vertex: its slot among the unknowns, `u32::MAX` if none.
    slot: Vec<u32>,
    /// Per slot: the vertex.
    vertices: Vec<u32>,
    /// Per slot: D_i (kg/s^2).
    d: Vec<Real>,
    /// Per slot: the inverse of the block-diagonal of D + H.
    precond: Vec<Mat3>,
    /// H summed per triangle (see [`Group`]), rebuilt every correction.
    groups: Vec<Group>,
    /// Per vertex of a point: the known motion of vertices that are not
    /// unknowns (zero for unknowns), scratch.
    known: Vec<Vec3>,
    b: Vec<Vec3>,
    x: Vec<Vec3>,
    r: Vec<Vec3>,
    z: Vec<Vec3>,
    p: Vec<Vec3>,
    q: Vec<Vec3>,
    /// Iterations of the last solve.
    iterations: usize,
}

impl ImplicitSprings {
    /// Iterations the last correction took.
    pub fn iterations(&self) -> usize {
        self.iterations
    }

    /// Corrects `u_new` (the explicit prediction u*) for the springs of
    /// `field`'s last evaluation, from `u_old` (u at the sub-step's
    /// start); `inverse_d(i)` is a_i = 1 / D_i for a free vertex, `None`
    /// for one whose motion is imposed. Writes into `tool_change_n`, per
    /// tool, the change of the force on the tool that the implicit springs
    /// make (N).
    pub fn correct(
        &mut self,
        field: &ContactField,
        inverse_d: impl Fn(usize) -> Option<Real>,
        u_old: &[[Real; 3]],
        u_new: &mut [[Real; 3]],
        tool_change_n: &mut [Vec3],
    ) {
        tool_change_n.fill(Vec3::ZERO);
        self.iterations = 0;
        if self.slot.len() < u_old.len() {
            self.slot.resize(u_old.len(), u32::MAX);
            self.known.resize(u_old.len(), Vec3::ZERO);
        }
        let hessians = field.spring_hessians();
        let acting = |i: usize| field.penetrations_m()[i] > 0.0;
        // The unknowns: free vertices of acting points.
        self.vertices.clear();
        self.d.clear();
        for (i, p) in field.points().iter().enumerate() {
            if !acting(i) {
                continue;
            }
            for v in p.vertices {
                let vi = v as usize;
                match inverse_d(vi) {
                    Some(a) if a > 0.0 && self.slot[vi] == u32::MAX => {
                        self.slot[vi] = self.vertices.len() as u32;
                        self.vertices.push(v);
                        self.d.push(1.0 / a);
                    }
                    Some(a) if a > 0.0 => {}
                    // Imposed: its motion is known.
                    _ => self.known[vi] = Vec3::from_array(u_new[vi]) - Vec3::from_array(u_old[vi]),
                }
            }
        }
        let n = self.vertices.len();
        for buf in [
            &mut self.b,
            &mut self.x,
            &mut self.r,
            &mut self.z,
            &mut self.p,
            &mut self.q,
        ] {
            buf.clear();
            buf.resize(n, Vec3::ZERO);
        }
        self.precond.clear();
        self.precond.resize(n, Mat3::ZERO);
        for s in 0..n {
            let v = self.vertices[s] as usize;
            self.x[s] = Vec3::from_array(u_new[v]) - Vec3::from_array(u_old[v]);
            self.b[s] = self.x[s] * self.d[s];
            self.precond[s] = Mat3::IDENTITY * self.d[s];
        }
        // H per triangle (consecutive points of one triangle share a group;
        // points of a triangle that are not consecutive only make more
        // groups), then b -= H_{unknown, known} delta_known and the block
        // diagonal of H from it.
        self.groups.clear();
        for (i, p) in field.points().iter().enumerate() {
            if !acting(i) {
                continue;
            }
            let g = hessians[i];
            let group = match self.groups.last_mut() {
                Some(last) if last.vertices == p.vertices => last,
                _ => {
                    self.groups.push(Group {
                        slots: p.vertices.map(|v| self.slot[v as usize]),
                        vertices: p.vertices,
                        blocks: [Mat3::ZERO; 6],
                    });
                    self.groups.last_mut().expect("just pushed")
                }
            };
            let w = p.weights;
            for (k, (a, b)) in [(0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)]
                .into_iter()
                .enumerate()
            {
                group.blocks[k] += g * (w[a] * w[b]);
            }
        }
        for group in &self.groups {
            let known = group.vertices.map(|v| self.known[v as usize]);
            for a in 0..3 {
                let slot = group.slots[a];
                if slot != u32::MAX {
                    let s = slot as usize;
                    self.b[s] -= group.row(a, &known);
                    self.precond[s] += group.blocks[a];
                }
            }
        }
        for m in &mut self.precond {
            *m = m.inverse();
        }
        // Conjugate gradients on (D + H) x = b.
        let b_norm = dot(&self.b, &self.b).sqrt();
        self.apply(true);
        for s in 0..n {
            self.r[s] = self.b[s] - self.q[s];
            self.z[s] = self.precond[s] * self.r[s];
        }
        self.p.copy_from_slice(&self.z);
        let mut rz = dot(&self.r, &self.z);
        while self.iterations < MAX_ITERATIONS && dot(&self.r, &self.r).sqrt() > TOLERANCE * b_norm
        {
            self.iterations += 1;
            self.apply(false);
            let pq = dot(&self.p, &self.q);
            // A non-positive curvature (or NaN) cannot come from an SPD
            // system except by round-off at convergence: stop there.
            if pq.is_nan() || pq <= 0.0 {
                break;
            }
            let alpha = rz / pq;
            for s in 0..n {
                self.x[s] += self.p[s] * alpha;
                self.r[s] -= self.q[s] * alpha;
                self.z[s] = self.precond[s] * self.r[s];
            }
            let rz_next = dot(&self.r, &self.z);
            let beta = rz_next / rz;
            rz = rz_next;
            for s in 0..n {
                self.p[s] = self.z[s] + self.p[s] * beta;
            }
        }
        for s in 0..n {
            let v = self.vertices[s] as usize;
            u_new[v] = (Vec3::from_array(u_old[v]) + self.x[s]).to_array();
        }
        // What the tool feels of the correction: each point's spring
        // changes by -G_p J_p delta on the tissue, the opposite on the tool.
        for (i, p) in field.points().iter().enumerate() {
            if !acting(i) {
                continue;
            }
            let y = at_point(p, |v| match self.slot[v] {
                u32::MAX => self.known[v],
                slot => self.x[slot as usize],
            });
            tool_change_n[field.parts()[p.part as usize].tool] += hessians[i] * y;
        }
        // Leave the per-vertex scratch clean.
        for (i, p) in field.points().iter().enumerate() {
            if acting(i) {
                for v in p.vertices {
                    self.slot[v as usize] = u32::MAX;
                    self.known[v as usize] = Vec3::ZERO;
                }
            }
        }
    }

    /// q = (D + H) x (`from_x`) or (D + H) p.
    fn apply(&mut self, from_x: bool) {
        let v = if from_x { &self.x } else { &self.p };
        for ((q, v), d) in self.q.iter_mut().zip(v).zip(&self.d) {
            *q = *v * *d;
        }
        for group in &self.groups {
            let x = group.slots.map(|slot| match slot {
                u32::MAX => Vec3::ZERO,
                s => v[s as usize],
            });
            for a in 0..3 {
                let slot = group.slots[a];
                if slot != u32::MAX {
                    self.q[slot as usize] += group.row(a, &x);
                }
            }
        }
    }
}

/// J_p applied to per-vertex `value`: its weighted sum over the point's
/// triangle.
fn at_point(p: &ContactPoint, value: impl Fn(usize) -> Vec3) -> Vec3 {
    (0..3).fold(Vec3::ZERO, |y, k| {
        y + value(p.vertices[k] as usize) * p.weights[k]
    })
}

fn dot(a: &[Vec3], b: &[Vec3]) -> Real {
    a.iter().zip(b).map(|(x, y)| x.dot(*y)).sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::contact::instrument::Segment;
    use crate::contact::penalty::field::ONSET_OF_RADIUS;
    use crate::contact::penalty::field::fixtures::{add_point, whole_step};

    /// Two triangles sharing an edge (four vertices), a point on each,
    /// both pressed by a flat-ish tool (a long shaft along x just below
    /// z = 0.002), evaluated once.
    fn pressed() -> (ContactField, Vec<Vec3>) {
        let rest = vec![
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(0.01, 0.0, 0.0),
            Vec3::new(0.0, 0.01, 0.0),
            Vec3::new(0.01, 0.01, 0.0),
        ];
        let mut f = ContactField::new(1, 0.0).with_implicit_springs(true);
        let seg = Segment {
            a_m: Vec3::new(-0.02, 0.005, 0.002),
            b_m: Vec3::new(0.03, 0.005, 0.002),
        };
        for point in [([0, 1, 2], [0.2, 0.5, 0.3]), ([1, 3, 2], [0.3, 0.3, 0.4])] {
            add_point(&mut f, (seg, seg), false, 0.004, point, 500.0);
        }
        let u = vec![[0.0; 3]; 4];
        let mut out = vec![[0.0; 3]; 4];
        f.add_forces(&rest, &u, &u, whole_step(1e-3), &mut out);
        assert!(f.penetrations_m().iter().all(|d| *d > 0.0));
        (f, rest)
    }

    /// H assembled densely (12 x 12) from the points' Hessians.
    fn dense_h(f: &ContactField) -> Vec<Vec<Real>> {
        let mut h = vec![vec![0.0; 12]; 12];
        for (p, g) in f.points().iter().zip(f.spring_hessians()) {
            let g = g.to_cols_array_2d();
            for a in 0..3 {
                for b in 0..3 {
                    let w = p.weights[a] * p.weights[b];
                    let (va, vb) = (p.vertices[a] as usize, p.vertices[b] as usize);
                    for r in 0..3 {
                        for c in 0..3 {
                            h[3 * va + r][3 * vb + c] += w * g[c][r];
                        }
                    }
                }
            }
        }
        h
    }

    #[test]
    fn the_correction_solves_the_implicit_system_with_imposed_vertices_on_the_right() {
        let (f, _) = pressed();
        let mut solver = ImplicitSprings::default();
        // Vertex 3 is imposed (it moved by a known amount); the others free
        // with different masses.
        let a = [2e-3, 1e-3, 4e-3, 0.0];
        let inverse_d = |i: usize| (i < 3).then(|| a[i]);
        let u_old = vec![
            [0.0, 0.0, 0.0],
            [1e-4, 0.0, 0.0],
            [0.0, -1e-4, 0.0],
            [0.0, 0.0, 0.0],
        ];
        let predicted = vec![
            [1e-4, 2e-4, -3e-4],
            [2e-4, 1e-4, -2e-4],
            [-1e-4, -2e-4, -4e-4],
            [0.0, 0.0, -5e-4],
        ];
        let mut u_new = predicted.clone();
        let mut change = vec![Vec3::ZERO; 1];
        solver.correct(&f, inverse_d, &u_old, &mut u_new, &mut change);
        assert!(solver.iterations() > 0);
        assert_eq!(
            u_new[3], predicted[3],
            "the imposed vertex keeps its motion"
        );
        let delta: Vec<Real> = (0..12)
            .map(|k| u_new[k / 3][k % 3] - u_old[k / 3][k % 3])
            .collect();
        let h = dense_h(&f);
        for i in 0..9 {
            let d = 1.0 / a[i / 3];
            let lhs = d * delta[i] + (0..12).map(|j| h[i][j] * delta[j]).sum::<Real>();
            let rhs = d * (predicted[i / 3][i % 3] - u_old[i / 3][i % 3]);
            assert!(
                (lhs - rhs).abs() < 1e-9 * rhs.abs().max(1e-3),
                "row {i}: {lhs} vs {rhs}"
            );
        }
        // The tool feels the springs' change: sum over points of G J delta.
        let mut expect = Vec3::ZERO;
        for (p, g) in f.points().iter().zip(f.spring_hessians()) {
            let y = (0..3).fold(Vec3::ZERO, |y, k| {
                let v = p.vertices[k] as usize;
                y + Vec3::new(delta[3 * v], delta[3 * v + 1], delta[3 * v + 2]) * p.weights[k]
            });
            expect += *g * y;
        }
        assert!(
            (change[0] - expect).length() < 1e-12,
            "{} vs {expect}",
            change[0]
        );
        // The scratch is left clean: the same call again gives the same.
        let mut again = predicted.clone();
        solver.correct(&f, inverse_d, &u_old, &mut again, &mut change);
        assert_eq!(again, u_new);
    }

    #[test]
    fn stiff_springs_on_a_light_vertex_settle_at_a_step_the_explicit_ones_cannot_take() {
        // One free vertex of mass m held by a soft tissue spring (100 N/m,
        // explicit) under a point of stiffness k, with h^2 k / m = 400
        // (explicit central differences need < 4): the implicit step
        // settles where the springs balance, the explicit one explodes.
        let (m, k, h) = (1e-3, 400.0, 1e-3);
        let run = |implicit: bool| {
            let rest = vec![
                Vec3::ZERO,
                Vec3::new(0.01, 0.0, 0.0),
                Vec3::new(0.0, 0.01, 0.0),
            ];
            let mut f = ContactField::new(1, 0.0).with_implicit_springs(implicit);
            let seg = Segment {
                a_m: Vec3::new(0.0, 0.0, 0.0025),
                b_m: Vec3::new(0.0, 0.0, 0.0015),
            };
            add_point(
                &mut f,
                (seg, seg),
                true,
                0.002,
                ([0, 1, 2], [1.0, 0.0, 0.0]),
                k,
            );
            let (mut prev, mut u) = (vec![[0.0; 3]; 3], vec![[0.0; 3]; 3]);
            let mut out = vec![[0.0; 3]; 3];
            let a = h * h / m;
            let mut largest: Real = 0.0;
            let (mut low, mut high) = (Real::INFINITY, Real::NEG_INFINITY);
            for step in 0..200 {
                f.zero(&mut out);
                f.add_forces(&rest, &u, &prev, whole_step(h), &mut out);
                let mut next = u.clone();
                for d in 0..3 {
                    next[0][d] = a * (out[0][d] - 100.0 * u[0][d]) + 2.0 * u[0][d] - prev[0][d];
                }
                let inverse_d = |i: usize| (i == 0).then_some(a);
                f.correct_implicit(inverse_d, &u, &mut next);
                prev = std::mem::replace(&mut u, next);
                largest = largest.max(u[0][2].abs());
                if step >= 150 {
                    low = low.min(u[0][2]);
                    high = high.max(u[0][2]);
                }
            }
            (largest, u[0][2], high - low)
        };
        // Balance: 100 u = k (0.5 mm - u - d0 / 2) down, u = 0.3968 mm.
        let balance = 400.0 * (0.0005 - 0.5 * ONSET_OF_RADIUS * 0.002) / 500.0;
        let (largest, last, spread) = run(true);
        assert!(largest < 2.0 * balance, "implicit: {largest}");
        assert!(
            (last + balance).abs() < 1e-3 * balance,
            "settled at {last}, not {}",
            -balance
        );
        assert!(spread < 1e-3 * balance);
        // Explicit: unstable in contact, it bounces off and back for ever.
        let (_, _, spread) = run(false);
        assert!(
            spread > 0.5 * balance,
            "explicit should not settle here: {spread}"
        );
    }
}
