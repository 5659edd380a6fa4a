//! The VTK cell types and the cells' way into a mesh, shared by the three
//! VTK readers (legacy ASCII `vtk.rs`, legacy binary `vtk_binary.rs`, XML
//! `vtu.rs`): which cell types are tetrahedra, ignored or refused, the
//! physical tag arrays, and the checks of cell lists against the points.

use super::Builder;
use super::error::{Location, MeshIoError};
use super::text::perr;

/// The VTK cell type of the linear tetrahedron.
pub(super) const VTK_TETRA: i64 = 10;

/// Cell data array names taken as physical tags, in order of preference.
pub(super) const PHYSICAL_NAMES: [&str; 3] = ["physical", "gmsh:physical", "CellEntityIds"];

/// What to do with a VTK cell type.
pub(super) enum CellKind {
    /// The linear tetrahedron.
    Tet,
    /// A lower-dimensional cell, ignored (plural noun for the warning).
    Lower(&'static str),
    /// A volume cell that is not a linear tetrahedron (or an unknown type).
    Unsupported(String),
}

/// VTK's linear triangle.
const VTK_TRIANGLE: i64 = 5;

/// Classifies a VTK cell type.
pub(super) fn cell_kind(t: i64) -> CellKind {
    let lower = match t {
        VTK_TETRA => return CellKind::Tet,
        0 => "empty cells",
        1 | 2 => "vertices",
        3 | 4 | 21 | 35 | 68 | 75 => "lines",
        5 | 22 | 34 | 69 | 76 => "triangles",
        6 => "triangle strips",
        7 | 36 => "polygons",
        8 | 9 | 23 | 28 | 70 | 77 => "quads",
        _ => {
            let name = match t {
                11 => "voxel",
                12 => "hexahedron",
                13 => "wedge",
                14 => "pyramid",
                15 => "pentagonal prism",
                16 => "hexagonal prism",
                24 => "quadratic tetrahedron",
                25 | 29 | 33 => "quadratic hexahedron",
                26 | 27 | 31 | 32 => "quadratic wedge or pyramid",
                42 => "polyhedron",
                71 | 78 => "higher-order tetrahedron",
                72..=74 | 79..=81 => "higher-order volume cell",
                _ => "of unknown type",
            };
            return CellKind::Unsupported(format!("{name} (VTK cell type {t})"));
        }
    };
    CellKind::Lower(lower)
}

/// The cells a legacy VTK file (ASCII or binary) described: cell `c` has
/// type `types[c]` and points `connectivity[offsets[c]..offsets[c + 1]]`.
pub(super) struct CellLists<'c> {
    /// The cell types.
    pub types: &'c [i64],
    /// Where `CELL_TYPES` is.
    pub types_at: Location,
    /// One more than there are cells, non-decreasing, within `connectivity`.
    pub offsets: &'c [usize],
    /// The cells' points.
    pub connectivity: &'c [i64],
    /// The physical tag array and where it is.
    pub physical: Option<(&'c [i32], Location)>,
}

/// Checks that the cell types and the physical tags match the cells, then
/// adds the cells ([`add_cells`]); `at(c)` is where cell `c` is.
pub(super) fn add_cell_lists(
    b: &mut Builder,
    file: &str,
    cells: CellLists,
    at: impl Fn(usize) -> Location,
) -> Result<(), MeshIoError> {
    let n_cells = cells.offsets.len().saturating_sub(1);
    if cells.types.len() != n_cells {
        return Err(perr(
            file,
            cells.types_at,
            format!(
                "CELL_TYPES has {} entries but CELLS has {n_cells} cells",
                cells.types.len()
            ),
        ));
    }
    if let Some((tags, tags_at)) = cells.physical
        && tags.len() != n_cells
    {
        return Err(perr(
            file,
            tags_at,
            format!(
                "the physical tag array has {} values for {n_cells} cells",
                tags.len()
            ),
        ));
    }
    add_cells(
        b,
        file,
        cells.types,
        |c| {
            let (s, e) = (cells.offsets[c], cells.offsets[c + 1]);
            cells.connectivity.get(s..e).unwrap_or_default()
        },
        at,
        cells.physical.map(|(t, _)| t),
    )
}

/// A physical tag read as a number: a 32-bit integer, or `None`.
pub(super) fn physical_tag(v: f64) -> Option<i32> {
    (v.fract() == 0.0 && v.abs() <= i32::MAX as f64).then_some(v as i32)
}

/// Adds VTK cells to a builder: tetrahedra, ignored lower-dimensional cells,
/// refusals. Shared with the VTU reader; `points(c)` and `at(c)` must accept
/// every `c < types.len()`.
pub(super) fn add_cells<'c>(
    b: &mut Builder,
    file: &str,
    types: &[i64],
    points: impl Fn(usize) -> &'c [i64],
    at: impl Fn(usize) -> Location,
    physical: Option<&[i32]>,
) -> Result<(), MeshIoError> {
    let n_vertices = b.vertex_count();
    // A cell's points as vertex indices, each checked against the points.
    let indices = |c: usize, out: &mut [u32]| -> Result<(), MeshIoError> {
        for (slot, &i) in out.iter_mut().zip(points(c)) {
            *slot = usize::try_from(i)
                .ok()
                .filter(|&i| i < n_vertices)
                .map(|i| i as u32)
                .ok_or_else(|| {
                    perr(
                        file,
                        at(c),
                        format!("cell {c} references point {i}, but there are {n_vertices} points"),
                    )
                })?;
        }
        Ok(())
    };
    for (c, &t) in types.iter().enumerate() {
        let tag = physical.and_then(|p| p.get(c)).copied().unwrap_or(0);
        match cell_kind(t) {
            // A tagged linear triangle: kept for surface selections.
            CellKind::Lower(_) if t == VTK_TRIANGLE && tag != 0 && points(c).len() == 3 => {
                let mut v = [0u32; 3];
                indices(c, &mut v)?;
                b.triangle(v, tag);
            }
            CellKind::Lower(kind) => b.ignore(kind, 1),
            CellKind::Unsupported(element) => {
                return Err(MeshIoError::UnsupportedElement {
                    file: file.to_owned(),
                    at: at(c),
                    element,
                });
            }
            CellKind::Tet => {
                let p = points(c);
                if p.len() != 4 {
                    return Err(perr(
                        file,
                        at(c),
                        format!(
                            "expected 4 points for tetrahedral cell {c}, found {}",
                            p.len()
                        ),
                    ));
                }
                let mut v = [0u32; 4];
                indices(c, &mut v)?;
                b.tet(v, tag, c as u64, at(c));
            }
        }
    }
    Ok(())
}
