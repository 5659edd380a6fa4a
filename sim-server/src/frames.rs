//! `sim-server run --save-frames DIR`: the run as a ParaView time series,
//! a zlib-compressed VTU file per frame and `frames.pvd` listing them with
//! their simulated times.
//!
//! Writing a frame (compressing, base64-encoding and writing a few hundred
//! kilobytes for the liver) takes milliseconds: far too long for the
//! stepping thread, which must not stall. So the step only copies what a
//! frame needs into a buffer (and, for a linear scene, computes -K u: one
//! pass over the tensors, as one explicit sub-step costs) and hands it to
//! a writer thread over a channel of
//! [`QUEUE`] frames; buffers come back for reuse, so neither side allocates
//! per frame once warm. If the disk cannot keep up, frames are dropped
//! (counted in the run summary), never the step delayed. `frames.pvd` is
//! rewritten every [`PVD_EVERY`] frames (less often in long runs) and at the end, so a run that is
//! killed keeps a readable series up to the last rewrite.
//!
//! Each frame holds the live tetrahedra (cuts removed) in the rest
//! positions with point data `displacement` (m; ParaView's "Warp By Vector"
//! shows the deformed organ), `elastic_force` (N, the force the tissue's
//! elasticity exerts on each vertex, -K u: where a tool, support or load
//! holds the tissue still it is minus what they apply; linear scenes only,
//! as a nonlinear model's forces are not -K u) and `original_id` when the
//! scene renumbered the vertices, and cell data `tet_id` (each
//! tetrahedron's index in the scene's mesh: the gaps are what was cut).

use crate::ids::{TetId, VertexId};
use crate::math::{Real, Vec3};
use crate::mesh::io::{DataArray, MeshIoError, write_pvd, write_vtu_zlib};
use crate::tensor_mass::ElasticModel;
use std::path::{Path, PathBuf};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, channel, sync_channel};
use std::thread::JoinHandle;
use thiserror::Error;

/// Frames waiting for the writer at most; more are dropped.
pub const QUEUE: usize = 4;
/// `frames.pvd` is rewritten after this many new frames, or a quarter of
/// those written if more (so a long run's rewrites cost O(n) in all), and
/// at the end.
pub const PVD_EVERY: usize = 30;

/// Why the frames could not be saved.
#[derive(Debug, Error)]
pub enum FramesError {
    /// The directory could not be created.
    #[error("--save-frames {dir}: cannot create the directory: {reason}")]
    Dir {
        /// The directory.
        dir: String,
        /// Why.
        reason: std::io::Error,
    },
    /// The writer thread could not be started, or it failed.
    #[error("--save-frames: the frame writer thread: {0}")]
    Thread(std::io::Error),
    /// Writing a frame or the series failed (the run went on; frames
    /// written before are kept).
    #[error(transparent)]
    Write(#[from] Box<MeshIoError>),
}

/// One frame's data, reused.
#[derive(Default)]
struct Frame {
    t_s: Real,
    u_m: Vec<Vec3>,
    force_n: Vec<Vec3>,
    tets: Vec<[VertexId; 4]>,
    tet_ids: Vec<u32>,
}

/// What the recorder did (the run summary's `frames_saved`,
/// `frames_dropped`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FrameCounts {
    /// Frames written.
    pub saved: u64,
    /// Frames dropped because the writer was behind (not those after a
    /// write error, which stops the series).
    pub dropped: u64,
}

/// Saves frames on a writer thread (see the module docs).
pub struct FrameRecorder {
    frames: Option<SyncSender<Frame>>,
    spare: Receiver<Frame>,
    /// A buffer the queue had no room for, kept for the next frame.
    unsent: Option<Frame>,
    writer: Option<JoinHandle<(u64, Option<FramesError>)>>,
    dropped: u64,
    /// Whether `elastic_force` is written (linear scenes).
    forces: bool,
}

impl FrameRecorder {
    /// Creates `dir` (and parents) and starts the writer thread for frames
    /// of `model`'s mesh; `original_ids` is written as `original_id`.
    pub fn start(
        dir: &Path,
        model: &ElasticModel,
        original_ids: Option<Vec<u32>>,
    ) -> Result<Self, FramesError> {
        std::fs::create_dir_all(dir).map_err(|source| FramesError::Dir {
            dir: dir.display().to_string(),
            reason: source,
        })?;
        let (frames_tx, frames_rx) = sync_channel::<Frame>(QUEUE);
        let (spare_tx, spare_rx) = channel::<Frame>();
        for _ in 0..QUEUE + 1 {
            spare_tx.send(Frame::default()).expect("receiver alive");
        }
        let rest = model.mesh().positions_m().to_vec();
        let dir = dir.to_path_buf();
        let writer = std::thread::Builder::new()
            .name("frame-writer".into())
            .spawn(move || write_frames(&dir, &rest, original_ids, frames_rx, spare_tx))
            .map_err(FramesError::Thread)?;
        let membrane_nonlinear = model
            .membrane()
            .is_some_and(|m| m.model() == crate::membrane::MembraneModel::Nonlinear);
        Ok(Self {
            frames: Some(frames_tx),
            spare: spare_rx,
            unsent: None,
            writer: Some(writer),
            dropped: 0,
            forces: model.nonlinear_tets() == 0 && !membrane_nonlinear,
        })
    }

    /// Writes no `force` arrays: for a run whose elements turn
    /// corotational while it runs (`[contact] corotational_radius_m`),
    /// where -K u is not the elastic force.
    pub fn without_forces(mut self) -> Self {
        self.forces = false;
        self
    }

    /// Offers the state at simulated time `t_s`: copied and queued, or
    /// dropped (counted) if the writer is behind. Allocates nothing once
    /// the buffers have grown to the mesh's size.
    pub fn offer(&mut self, t_s: Real, model: &ElasticModel, u_m: &[[Real; 3]]) {
        if self.frames.is_none() {
            // The writer stopped on an error (`finish` reports it).
            return;
        }
        let Some(mut f) = self.unsent.take().or_else(|| self.spare.try_recv().ok()) else {
            self.dropped += 1;
            return;
        };
        f.t_s = t_s;
        f.u_m.clear();
        f.u_m.extend(u_m.iter().map(|u| Vec3::from_array(*u)));
        f.force_n.clear();
        if self.forces {
            f.force_n.resize(u_m.len(), Vec3::ZERO);
            model.elastic_forces(&f.u_m, &mut f.force_n);
        }
        f.tets.clear();
        f.tet_ids.clear();
        let (mesh, topo) = (model.mesh(), model.topology());
        for (i, t) in mesh.tets().iter().enumerate() {
            if topo.is_alive(TetId::from(i)) {
                f.tets.push(*t);
                f.tet_ids.push(i as u32);
            }
        }
        let Some(tx) = &self.frames else { return };
        match tx.try_send(f) {
            Ok(()) => {}
            Err(TrySendError::Full(f)) => {
                self.unsent = Some(f);
                self.dropped += 1;
            }
            // The writer stopped on an error: no more frames are copied
            // (`finish` reports it).
            Err(TrySendError::Disconnected(_)) => self.frames = None,
        }
    }

    /// Waits for the writer to write what is queued and the final
    /// `frames.pvd`. A write that failed stopped the series there (the
    /// frames before it and their `frames.pvd` are kept): it comes back
    /// beside the counts, so the run's own results are not lost to it.
    pub fn finish(mut self) -> (FrameCounts, Option<FramesError>) {
        self.frames = None;
        let (saved, error) = match self.writer.take().map(JoinHandle::join) {
            Some(Ok(r)) => r,
            Some(Err(_)) => (
                0,
                Some(FramesError::Thread(std::io::Error::other(
                    "the frame writer panicked",
                ))),
            ),
            None => (0, None),
        };
        let counts = FrameCounts {
            saved,
            dropped: self.dropped,
        };
        (counts, error)
    }
}

impl Drop for FrameRecorder {
    /// A run that ends on an error (not through [`FrameRecorder::finish`])
    /// still lets the writer write what is queued and the final
    /// `frames.pvd`.
    fn drop(&mut self) {
        self.frames = None;
        if let Some(w) = self.writer.take() {
            let _ = w.join();
        }
    }
}

/// The writer thread: a VTU per frame, the PVD now and then and at the end.
fn write_frames(
    dir: &Path,
    rest_m: &[Vec3],
    original_ids: Option<Vec<u32>>,
    frames: Receiver<Frame>,
    spare: std::sync::mpsc::Sender<Frame>,
) -> (u64, Option<FramesError>) {
    let pvd = dir.join("frames.pvd");
    let mut series: Vec<(f64, PathBuf)> = Vec::new();
    let mut error = None;
    let mut next_pvd = PVD_EVERY;
    for f in frames.iter() {
        let name = dir.join(format!("frame_{:06}.vtu", series.len()));
        let mut point_data = vec![("displacement", DataArray::Vectors(&f.u_m))];
        if !f.force_n.is_empty() {
            point_data.push(("elastic_force", DataArray::Vectors(&f.force_n)));
        }
        if let Some(ids) = &original_ids {
            point_data.push(("original_id", DataArray::Ids(ids)));
        }
        let written = write_vtu_zlib(
            &name,
            rest_m,
            &f.tets,
            &point_data,
            &[("tet_id", DataArray::Ids(&f.tet_ids))],
        );
        let t_s = f.t_s;
        let _ = spare.send(f);
        if let Err(e) = written {
            error = Some(Box::new(e).into());
            break;
        }
        series.push((t_s, name));
        if series.len() >= next_pvd {
            if let Err(e) = write_pvd(&pvd, &series) {
                error = Some(Box::new(e).into());
                break;
            }
            next_pvd = series.len() + PVD_EVERY.max(series.len() / 4);
        }
    }
    // The series written so far, whatever stopped it.
    if let Err(e) = write_pvd(&pvd, &series) {
        error.get_or_insert(Box::new(e).into());
    }
    (series.len() as u64, error)
}
