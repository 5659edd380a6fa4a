//! Which tool holds each vertex this step: two tools never impose the same
//! vertex, and a tool never lets go of a vertex another tool has just taken.

use crate::ids::VertexId;

const FREE: u8 = 0;
/// The scene fixes or prescribes it: no tool ever takes it.
const SCENE: u8 = u8::MAX;

/// The owner of each vertex for the step being built.
pub struct Claims {
    owner: Vec<u8>,
    taken: Vec<VertexId>,
}

impl Claims {
    /// No claims over `n` vertices.
    pub fn new(n: usize) -> Self {
        Self {
            owner: vec![FREE; n],
            taken: Vec::new(),
        }
    }

    /// Reserves `v` for the scene for good (a fixed or prescribed vertex).
    pub fn reserve(&mut self, v: VertexId) {
        self.owner[v.idx()] = SCENE;
    }

    /// Whether no tool (and not the scene) holds `v` this step.
    pub fn is_free(&self, v: VertexId) -> bool {
        self.owner[v.idx()] == FREE
    }

    /// Tool `slot` holds `v` this step (`v` must be free).
    pub fn take(&mut self, v: VertexId, slot: usize) {
        debug_assert!(self.is_free(v));
        self.owner[v.idx()] = slot as u8 + 1;
        self.taken.push(v);
    }

    /// The tool holding `v` this step, if any.
    pub fn owner(&self, v: VertexId) -> Option<usize> {
        match self.owner[v.idx()] {
            FREE | SCENE => None,
            k => Some(k as usize - 1),
        }
    }

    /// Starts a new step: every tool claim is dropped (scene ones stay).
    pub fn clear(&mut self) {
        for v in self.taken.drain(..) {
            self.owner[v.idx()] = FREE;
        }
    }
}
