//! The on-disk cache of precomputed responses: a file per (mesh, tensors,
//! fixed set) hash, `MAGIC`, the vector count, then the vectors as
//! little-endian f64. A missing, foreign or truncated file is simply
//! recomputed.

use crate::ids::VertexId;
use crate::math::{Real, Vec3};
use crate::tensor_mass::ElasticModel;
use std::io::{Read, Write};
use std::path::Path;

const MAGIC: &[u8; 8] = b"HAPSIMP1";

/// The most a backend keeps in precomputed responses (bytes): far above
/// what a real-time mesh needs (the embedded liver's are about 0.1 GB),
/// below what would exhaust the machine: each response is a whole vertex
/// array per surface degree of freedom, which grows as the square of the
/// mesh.
pub const MAX_RESPONSE_BYTES: u64 = 8 << 30;

/// A mesh too large for precomputed responses.
#[derive(Clone, Debug, thiserror::Error, PartialEq, Eq)]
#[error(
    "{columns} precomputed responses over {vertices} vertices would take {gib:.1} GiB, more than the {max} GiB a backend keeps: use the tensor-mass backend, or the hybrid with a smaller precomputed part or surface",
    gib = (*columns as f64) * (*vertices as f64) * 24.0 / (1u64 << 30) as f64,
    max = MAX_RESPONSE_BYTES >> 30
)]
pub struct TooManyResponses {
    /// Responses (three per surface vertex, and per shared vertex for a hybrid).
    pub columns: usize,
    /// Vertices in each.
    pub vertices: usize,
}

/// The refusal when `columns` responses of `n` vertices each would pass
/// [`MAX_RESPONSE_BYTES`]; their vector count otherwise.
pub(super) fn check_responses(columns: usize, n: usize) -> Result<usize, TooManyResponses> {
    match columns.checked_mul(n) {
        Some(len) if len as u64 <= MAX_RESPONSE_BYTES / std::mem::size_of::<Vec3>() as u64 => {
            Ok(len)
        }
        _ => Err(TooManyResponses {
            columns,
            vertices: n,
        }),
    }
}

/// A zeroed buffer for `columns` responses of `n` vertices each, or the
/// refusal when they pass [`MAX_RESPONSE_BYTES`] or cannot be allocated.
pub(super) fn response_buffer(columns: usize, n: usize) -> Result<Vec<Vec3>, TooManyResponses> {
    let len = check_responses(columns, n)?;
    let mut v = Vec::new();
    v.try_reserve_exact(len).map_err(|_| TooManyResponses {
        columns,
        vertices: n,
    })?;
    v.resize(len, Vec3::ZERO);
    Ok(v)
}

/// FNV-1a's 64-bit offset basis: the hash of nothing.
pub const FNV_OFFSET: u64 = 0xcbf2_9ce4_8422_2325;

/// FNV-1a over `bytes`, continuing from `h` ([`FNV_OFFSET`] to start): the
/// cache keys' hash (stable across builds and machines, unlike std's).
pub fn fnv(bytes: impl Iterator<Item = u8>, mut h: u64) -> u64 {
    for b in bytes {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x100_0000_01b3);
    }
    h
}

/// The cache key: an FNV-1a hash of the mesh, the tensors (hence the
/// materials), the fixed set and `extra` (what else the responses depend on,
/// e.g. a hybrid's shared vertices).
pub(super) fn key(model: &ElasticModel, fixed: &[VertexId], extra: &[u32]) -> u64 {
    let mut h = FNV_OFFSET;
    let f = |x: Real| x.to_le_bytes();
    h = fnv(
        model
            .mesh()
            .positions_m()
            .iter()
            .flat_map(|p| p.to_array().map(f))
            .flatten(),
        h,
    );
    h = fnv(
        model
            .mesh()
            .tets()
            .iter()
            .flat_map(|t| t.map(|v| v.0.to_le_bytes()))
            .flatten(),
        h,
    );
    h = fnv(
        model
            .vertex_tensors()
            .iter()
            .chain(model.edge_tensors())
            .flat_map(|m| m.to_cols_array().map(f))
            .flatten(),
        h,
    );
    let mut fixed: Vec<u32> = fixed.iter().map(|v| v.0).collect();
    fixed.sort_unstable();
    h = fnv(fixed.iter().flat_map(|v| v.to_le_bytes()), h);
    fnv(extra.iter().flat_map(|v| v.to_le_bytes()), h)
}

/// Reads `expected` vectors written by [`write_cache`]; `None` when the
/// file is missing, foreign or of another size.
pub(super) fn read_cache(path: &Path, expected: usize) -> Option<Vec<Vec3>> {
    let mut f = std::fs::File::open(path).ok()?;
    let mut magic = [0u8; 8];
    f.read_exact(&mut magic).ok()?;
    let mut len = [0u8; 8];
    f.read_exact(&mut len).ok()?;
    if &magic != MAGIC || u64::from_le_bytes(len) as usize != expected {
        return None;
    }
    let mut bytes = Vec::new();
    f.read_to_end(&mut bytes).ok()?;
    if bytes.len() != expected * 24 {
        return None;
    }
    Some(
        bytes
            .chunks_exact(24)
            .map(|c| {
                Vec3::from_array(std::array::from_fn(|k| {
                    Real::from_le_bytes(c[8 * k..8 * k + 8].try_into().unwrap_or([0; 8]))
                }))
            })
            .collect(),
    )
}

/// Writes `responses` atomically (a temporary file renamed into place).
pub(super) fn write_cache(path: &Path, responses: &[Vec3]) -> std::io::Result<()> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir)?;
    }
    let tmp = path.with_extension("tmp");
    let mut f = std::io::BufWriter::new(std::fs::File::create(&tmp)?);
    f.write_all(MAGIC)?;
    f.write_all(&(responses.len() as u64).to_le_bytes())?;
    for r in responses {
        for x in r.to_array() {
            f.write_all(&x.to_le_bytes())?;
        }
    }
    f.flush()?;
    drop(f);
    std::fs::rename(tmp, path)
}
