//! The Gmsh MSH 2.2 ASCII writer: nodes and 4-node tetrahedra (element type
//! 4) with two tags each, the physical group and the elementary entity (both
//! the tetrahedron's physical tag), as Gmsh, meshio and our own reader read
//! them. Values use Rust's shortest round-trip formatting.

use super::error::MeshIoError;
use super::export::{check_indices, write_with};
use crate::ids::VertexId;
use crate::math::Vec3;
use std::io::Write;
use std::path::Path;

/// Writes `.msh` version 2.2 (ASCII): `physical` holds one tag per
/// tetrahedron, or is empty for tag 1 everywhere.
pub fn write_msh(
    path: &Path,
    positions_m: &[Vec3],
    tets: &[[VertexId; 4]],
    physical: &[i32],
) -> Result<(), MeshIoError> {
    let file = path.display().to_string();
    check_indices(&file, positions_m.len(), tets.iter().flatten())?;
    if !physical.is_empty() && physical.len() != tets.len() {
        return Err(MeshIoError::BadInput {
            file,
            message: format!(
                "{} physical tags for {} tetrahedra",
                physical.len(),
                tets.len()
            ),
        });
    }
    write_with(&file, path, |w| {
        writeln!(w, "$MeshFormat\n2.2 0 8\n$EndMeshFormat")?;
        writeln!(w, "$Nodes\n{}", positions_m.len())?;
        for (i, p) in positions_m.iter().enumerate() {
            writeln!(w, "{} {} {} {}", i + 1, p.x, p.y, p.z)?;
        }
        writeln!(w, "$EndNodes\n$Elements\n{}", tets.len())?;
        for (i, t) in tets.iter().enumerate() {
            let tag = physical.get(i).copied().unwrap_or(1);
            writeln!(
                w,
                "{} 4 2 {tag} {tag} {} {} {} {}",
                i + 1,
                t[0].0 + 1,
                t[1].0 + 1,
                t[2].0 + 1,
                t[3].0 + 1
            )?;
        }
        writeln!(w, "$EndElements")
    })
}
