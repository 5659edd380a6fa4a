//! The K^-1 columns of the touched vertices and the column mass's 3x3
//! blocks between them, kept in one block of memory sized by a byte budget
//! and written through when the solver is made.
//!
//! Why preallocated: the columns are 3n reals per vertex (150 kB on the
//! embedded liver, 4 MB on a 60,000-vertex mesh), so a cache bounded by a
//! count alone grew the server by tens of megabytes as a hand explored the
//! organ, and by a gigabyte on the largest factored mesh; it also grew
//! lazily, one vertex at a time, which made a long session's memory look
//! like a leak. Here the memory is claimed (and touched) once, when the
//! factor is made, off the haptic path; only a single problem with more
//! vertices than the cache holds makes it larger (to that problem's size).

use crate::math::{Real, Vec3};
use std::collections::HashMap;

/// What the columns and blocks may take together (bytes), unless one
/// problem needs more.
pub const COLUMN_BUDGET_BYTES: usize = 16 << 20;
/// At most this many vertices' columns, however small the mesh.
pub const MAX_CACHED: usize = 256;
/// At least this many, however large the mesh (a problem with more vertices
/// makes the cache larger for itself).
pub const MIN_CACHED: usize = 8;

/// How many vertices' columns of `n` vertices the budget holds, within
/// [`MIN_CACHED`]..=[`MAX_CACHED`].
pub fn slots_for(n: usize) -> usize {
    let per_slot = 3 * n.max(1) * std::mem::size_of::<Vec3>();
    (COLUMN_BUDGET_BYTES / per_slot).clamp(MIN_CACHED, MAX_CACHED)
}

/// K^-1 columns by vertex in fixed slots, and the 3x3 blocks of the column
/// mass by slot pair; emptied whole when full (a contact moves on: the
/// newest vertices are the ones asked for again).
pub(super) struct ColumnCache {
    /// Vertices per column.
    n: usize,
    /// Slot s holds its vertex's x, y and z columns at `3n s ..3n (s + 1)`.
    data: Vec<Vec3>,
    /// The slot of each cached vertex.
    slot_of: HashMap<u32, usize>,
    /// Slots in all and in use.
    slots: usize,
    used: usize,
    /// Slot pair (lo vertex's slot, hi vertex's slot) -> the block stored
    /// as (lo's axes) x (hi's axes), valid where `block_gen` is `generation`.
    blocks: Vec<[Real; 9]>,
    block_gen: Vec<u32>,
    generation: u32,
    /// `ElasticModel::topology_changes` the blocks' masses are of.
    blocks_for: u64,
}

impl ColumnCache {
    /// Empty and sized for columns of `n` vertices ([`slots_for`]).
    pub fn new(n: usize, topology: u64) -> Self {
        let mut out = Self {
            n,
            ..Self::unsized_for(topology)
        };
        out.allocate(slots_for(n));
        out
    }

    /// Nothing kept and no room (a solver without a factor).
    pub fn unsized_for(topology: u64) -> Self {
        Self {
            n: 0,
            data: Vec::new(),
            slot_of: HashMap::new(),
            slots: 0,
            used: 0,
            blocks: Vec::new(),
            block_gen: Vec::new(),
            generation: 1,
            blocks_for: topology,
        }
    }

    /// `slots` slots, written through so that the pages are resident now
    /// and not one by one as contacts first touch them.
    fn allocate(&mut self, slots: usize) {
        self.data = vec![Vec3::ONE; 3 * self.n * slots];
        self.data.fill(Vec3::ZERO);
        self.slot_of = HashMap::with_capacity(slots);
        self.blocks = vec![[1.0; 9]; slots * slots];
        self.block_gen = vec![0; slots * slots];
        self.slots = slots;
        self.used = 0;
        self.generation = 1;
    }

    /// How many vertices' columns fit.
    pub fn slots(&self) -> usize {
        self.slots
    }

    /// Vertices per column.
    pub fn vertex_count(&self) -> usize {
        self.n
    }

    /// Whether `v`'s columns are kept.
    pub fn contains(&self, v: u32) -> bool {
        self.slot_of.contains_key(&v)
    }

    /// Forgets every column and block.
    pub fn clear(&mut self) {
        self.slot_of.clear();
        self.used = 0;
        self.invalidate_blocks();
    }

    fn invalidate_blocks(&mut self) {
        self.generation = self.generation.wrapping_add(1);
        if self.generation == 0 {
            // After 2^32 invalidations a stale generation could match.
            self.block_gen.fill(0);
            self.generation = 1;
        }
    }

    /// Room for `new` more vertices of a problem of `total`: emptied when
    /// they would not fit, made larger (and emptied) when the problem alone
    /// does not fit.
    pub fn make_room(&mut self, new: usize, total: usize) {
        if total > self.slots() {
            self.allocate(total);
        } else if self.used + new > self.slots() {
            self.clear();
        }
    }

    /// Keeps `v`'s columns, written by `fill` into a zeroed 3n slice (x,
    /// then y, then z); call [`ColumnCache::make_room`] first.
    pub fn insert_with(&mut self, v: u32, fill: impl FnOnce(&mut [Vec3])) {
        debug_assert!(self.used < self.slots());
        let slot = self.used;
        let cols = &mut self.data[3 * self.n * slot..3 * self.n * (slot + 1)];
        cols.fill(Vec3::ZERO);
        fill(cols);
        self.slot_of.insert(v, slot);
        self.used += 1;
    }

    /// `v`'s K^-1 column for `axis` (n vectors); `v` must be kept.
    pub fn column(&self, v: u32, axis: usize) -> &[Vec3] {
        let start = 3 * self.n * self.slot_of[&v] + axis * self.n;
        &self.data[start..start + self.n]
    }

    /// [`ColumnCache::column`] as flat reals.
    pub fn flat(&self, v: u32, axis: usize) -> &[Real] {
        bytemuck::cast_slice::<Vec3, Real>(self.column(v, axis))
    }

    /// Drops the blocks when the masses they were made with changed (a
    /// cut changes the masses at once, the factor and columns only when
    /// its rebuild is done).
    pub fn blocks_at(&mut self, topology: u64) {
        if self.blocks_for != topology {
            self.invalidate_blocks();
            self.blocks_for = topology;
        }
    }

    fn block_index(&self, lo: u32, hi: u32) -> usize {
        self.slot_of[&lo] * self.slots() + self.slot_of[&hi]
    }

    /// The kept block of vertices `lo <= hi` (both kept).
    pub fn block(&self, lo: u32, hi: u32) -> Option<[Real; 9]> {
        let i = self.block_index(lo, hi);
        (self.block_gen[i] == self.generation).then(|| self.blocks[i])
    }

    /// Keeps the block of vertices `lo <= hi` (both kept).
    pub fn set_block(&mut self, lo: u32, hi: u32, block: [Real; 9]) {
        let i = self.block_index(lo, hi);
        self.blocks[i] = block;
        self.block_gen[i] = self.generation;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slots_follow_the_budget_and_columns_come_back_as_written() {
        // 2,000 vertices: 144 kB a slot, so the budget's 116 slots.
        let mut c = ColumnCache::new(2000, 0);
        assert_eq!(c.slots(), COLUMN_BUDGET_BYTES / (3 * 2000 * 24));
        assert_eq!(slots_for(10), MAX_CACHED);
        assert_eq!(slots_for(1_000_000), MIN_CACHED);
        c.make_room(2, 2);
        c.insert_with(7, |cols| cols[2000 + 3] = Vec3::new(1.0, 2.0, 3.0));
        c.insert_with(3, |cols| cols[0] = Vec3::X);
        assert!(c.contains(7) && c.contains(3) && !c.contains(4));
        assert_eq!(c.column(7, 1)[3], Vec3::new(1.0, 2.0, 3.0));
        assert_eq!(c.column(7, 0)[3], Vec3::ZERO);
        assert_eq!(c.flat(3, 0)[0], 1.0);
        // A slot reused after a clear starts from zero.
        c.clear();
        c.make_room(1, 1);
        c.insert_with(9, |_| ());
        assert_eq!(c.column(9, 1)[3], Vec3::ZERO);
    }

    #[test]
    fn blocks_are_dropped_with_the_columns_and_with_the_masses() {
        let mut c = ColumnCache::new(50, 4);
        c.make_room(2, 2);
        c.insert_with(1, |_| ());
        c.insert_with(5, |_| ());
        assert_eq!(c.block(1, 5), None);
        c.set_block(1, 5, [2.0; 9]);
        assert_eq!(c.block(1, 5), Some([2.0; 9]));
        assert_eq!(c.block(1, 1), None);
        c.blocks_at(4);
        assert_eq!(c.block(1, 5), Some([2.0; 9]));
        c.blocks_at(5);
        assert_eq!(c.block(1, 5), None);
        c.set_block(1, 5, [3.0; 9]);
        c.clear();
        c.make_room(2, 2);
        c.insert_with(5, |_| ());
        c.insert_with(1, |_| ());
        assert_eq!(c.block(1, 5), None);
    }

    #[test]
    fn a_full_cache_empties_and_a_problem_larger_than_it_grows_it() {
        let mut c = ColumnCache::new(20_000, 0);
        let slots = c.slots();
        c.make_room(slots, slots);
        for v in 0..slots as u32 {
            c.insert_with(v, |_| ());
        }
        c.make_room(1, 1);
        assert!(!c.contains(0), "emptied when the next would not fit");
        c.make_room(slots + 5, slots + 5);
        assert_eq!(c.slots(), slots + 5);
        for v in 0..slots as u32 + 5 {
            c.insert_with(v, |_| ());
        }
        assert!(c.contains(slots as u32 + 4));
    }
}
