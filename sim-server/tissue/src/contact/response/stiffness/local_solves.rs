//! What a contact problem asks of the stiffness solver: the tissue's
//! compliance at its vertices and the column mass G = C^T M C (see
//! [`LocalContact`]), from the factor's cached K^-1 columns.

use super::{LocalContact, Solver};
use crate::math::Real;
use crate::tensor_mass::ElasticModel;

impl Solver {
    /// Adds the compliance at `lc`'s vertices and, when its velocities were
    /// taken (see [`super::LocalSpec::inertia`]), the column mass; false
    /// without a factor.
    pub(in crate::contact) fn solve_local(
        &mut self,
        model: &ElasticModel,
        lc: &mut LocalContact,
    ) -> bool {
        let LocalContact {
            vertices,
            compliance_m_per_n,
            column_mass,
            velocities_m_per_s,
            ..
        } = lc;
        column_mass.clear();
        if !self.compliance(model, vertices, compliance_m_per_n) {
            return false;
        }
        if !velocities_m_per_s.is_empty() {
            self.column_mass(model, column_mass);
        }
        true
    }

    /// W = (K^-1)_VV (m/N, row-major, 3|V| x 3|V|) of the vertices
    /// `verts` into `out`; false without a factor (the diagonal blocks
    /// alone would not be the tissue's compliance).
    fn compliance(&mut self, model: &ElasticModel, verts: &[u32], out: &mut Vec<Real>) -> bool {
        self.refresh(model);
        if self.factor.is_none() {
            return false;
        }
        self.verts.clear();
        self.verts.extend_from_slice(verts);
        let nv = 3 * verts.len();
        self.fill_s(model, nv);
        out.clear();
        out.extend_from_slice(&self.s);
        true
    }

    /// G = C_V^T M C_V (m^2/N^2 kg, row-major 3|V| square): the lumped
    /// masses seen through the static response columns C_V = K^-1 P_V^T of
    /// the vertices [`Solver::compliance`] was just given (its factor, its
    /// vertices and their columns: the Guyan reduction of the tissue's mass
    /// onto V is W^-1 G W^-1).
    fn column_mass(&mut self, model: &ElasticModel, out: &mut Vec<Real>) {
        let verts = &self.verts;
        let n = model.vertex_count();
        let m = model.masses_kg();
        let nv = 3 * verts.len();
        out.clear();
        out.resize(nv * nv, 0.0);
        // By vertex pairs: a pair's 3x3 block is kept (the columns do not
        // change while the factor stands) and a problem 8 ms after the last
        // mostly has the same vertices; a new block is M times a's three
        // columns dotted with b's, over flat slices with four partial sums
        // so that they vectorise (each block 9 x 3n multiply-adds: all 300
        // blocks of 24 vertices of the liver took half of a core at a
        // problem every 8 ms).
        // The blocks were made with the masses of one topology: a cut
        // changes the masses at once (the factor, and the columns with it,
        // only when its rebuild is done).
        self.columns.blocks_at(model.topology_changes());
        let (columns, weighted) = (&mut self.columns, &mut self.weighted);
        for (i, &a) in verts.iter().enumerate() {
            // M times a's three columns, made once when a block is missing.
            let mut weighted_ready = false;
            for (j, &b) in verts.iter().enumerate().skip(i) {
                let (lo, hi) = (a.min(b), a.max(b));
                // Stored as (lo's axes) x (hi's axes).
                let stored = match columns.block(lo, hi) {
                    Some(block) => block,
                    None => {
                        if !weighted_ready {
                            weighted.clear();
                            for axis in 0..3 {
                                weighted.extend(
                                    columns
                                        .flat(a, axis)
                                        .iter()
                                        .enumerate()
                                        .map(|(k, x)| m[k / 3] * x),
                                );
                            }
                            weighted_ready = true;
                        }
                        let mut ab = [0.0; 9];
                        for r in 0..3 {
                            let wr = &weighted[r * 3 * n..(r + 1) * 3 * n];
                            for c in 0..3 {
                                ab[3 * r + c] = dot(wr, columns.flat(b, c));
                            }
                        }
                        let block = if a <= b { ab } else { transpose3(ab) };
                        columns.set_block(lo, hi, block);
                        block
                    }
                };
                let ab = if a <= b { stored } else { transpose3(stored) };
                for r in 0..3 {
                    for c in 0..3 {
                        let g = ab[3 * r + c];
                        out[(3 * i + r) * nv + 3 * j + c] = g;
                        out[(3 * j + c) * nv + 3 * i + r] = g;
                    }
                }
            }
        }
    }
}

/// The dot product of two equal-length slices, four partial sums.
fn dot(a: &[Real], b: &[Real]) -> Real {
    let mut s = [0.0; 4];
    let (ca, cb) = (a.chunks_exact(4), b.chunks_exact(4));
    let tail: Real = ca
        .remainder()
        .iter()
        .zip(cb.remainder())
        .map(|(x, y)| x * y)
        .sum();
    for (x, y) in ca.zip(cb) {
        for i in 0..4 {
            s[i] += x[i] * y[i];
        }
    }
    (s[0] + s[1]) + (s[2] + s[3]) + tail
}

/// A 3x3 block (row-major) transposed.
fn transpose3(b: [Real; 9]) -> [Real; 9] {
    [b[0], b[3], b[6], b[1], b[4], b[7], b[2], b[5], b[8]]
}
