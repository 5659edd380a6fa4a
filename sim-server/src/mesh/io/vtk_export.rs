//! The legacy VTK writer: ASCII `UNSTRUCTURED_GRID` in the classic `CELLS`
//! layout, point data as `VECTORS` or `SCALARS` (ParaView, VisIt, meshio and our own
//! reader read it). Values are written with Rust's shortest round-trip
//! formatting, so a re-read gives back the same f64. Indices are checked
//! before the file is created, as in [`super::export`].

use super::error::MeshIoError;
use super::export::{DataArray, check_indices, check_lengths, write_with};
use super::vtk_cells::VTK_TETRA;
use crate::ids::VertexId;
use crate::math::Vec3;
use std::io::Write;
use std::path::Path;

/// Writes a legacy ASCII VTK file: linear tetrahedra, `point_data` (one
/// value per position: vectors as `VECTORS`, scalars and ids as `SCALARS`)
/// and `cell_data` (one per tetrahedron, e.g. the `physical` tags).
/// Names must be one word (letters, digits, `_`): legacy VTK separates
/// fields by spaces.
pub fn write_vtk(
    path: &Path,
    positions_m: &[Vec3],
    tets: &[[VertexId; 4]],
    point_data: &[(&str, DataArray)],
    cell_data: &[(&str, DataArray)],
) -> Result<(), MeshIoError> {
    let file = path.display().to_string();
    check_indices(&file, positions_m.len(), tets.iter().flatten())?;
    check_lengths(&file, "point", point_data, positions_m.len(), "points")?;
    check_lengths(&file, "cell", cell_data, tets.len(), "tetrahedra")?;
    if let Some((name, _)) = point_data
        .iter()
        .chain(cell_data)
        .find(|(n, _)| n.is_empty() || !n.chars().all(|c| c.is_ascii_alphanumeric() || c == '_'))
    {
        return Err(MeshIoError::BadInput {
            file,
            message: format!("data {name:?}: a legacy VTK name must be one word"),
        });
    }
    if let Some((name, _)) = point_data.iter().chain(cell_data).find(|(_, a)| match a {
        DataArray::Ids(v) => v.iter().any(|&i| i > i32::MAX as u32),
        _ => false,
    }) {
        return Err(MeshIoError::BadInput {
            file,
            message: format!("data {name:?}: an id above 2^31 - 1 does not fit legacy VTK's int"),
        });
    }
    write_with(&file, path, |w| {
        writeln!(w, "# vtk DataFile Version 3.0")?;
        writeln!(w, "sim-server, metres")?;
        writeln!(w, "ASCII")?;
        writeln!(w, "DATASET UNSTRUCTURED_GRID")?;
        writeln!(w, "POINTS {} double", positions_m.len())?;
        for p in positions_m {
            writeln!(w, "{} {} {}", p.x, p.y, p.z)?;
        }
        writeln!(w, "CELLS {} {}", tets.len(), 5 * tets.len())?;
        for t in tets {
            writeln!(w, "4 {} {} {} {}", t[0].0, t[1].0, t[2].0, t[3].0)?;
        }
        writeln!(w, "CELL_TYPES {}", tets.len())?;
        for _ in tets {
            writeln!(w, "{VTK_TETRA}")?;
        }
        for (section, count, arrays) in [
            ("POINT_DATA", positions_m.len(), point_data),
            ("CELL_DATA", tets.len(), cell_data),
        ] {
            if !arrays.is_empty() {
                writeln!(w, "{section} {count}")?;
                for (name, values) in arrays {
                    write_array(w, name, values)?;
                }
            }
        }
        Ok(())
    })
}

/// One named array, as `VECTORS` or `SCALARS`.
fn write_array(w: &mut impl Write, name: &str, values: &DataArray) -> std::io::Result<()> {
    match values {
        DataArray::Vectors(v) => {
            writeln!(w, "VECTORS {name} double")?;
            for v in *v {
                writeln!(w, "{} {} {}", v.x, v.y, v.z)?;
            }
        }
        DataArray::Scalars(v) => {
            writeln!(w, "SCALARS {name} double 1\nLOOKUP_TABLE default")?;
            for x in *v {
                writeln!(w, "{x}")?;
            }
        }
        DataArray::Ids(v) => {
            writeln!(w, "SCALARS {name} int 1\nLOOKUP_TABLE default")?;
            for x in *v {
                writeln!(w, "{x}")?;
            }
        }
    }
    Ok(())
}
