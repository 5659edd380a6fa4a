//! Mesh import and export: Gmsh MSH 4.1 and 2.2 (ASCII and binary) and MSH 1,
//! legacy VTK (ASCII and binary unstructured grid), VTU (XML, ascii and base64
//! inline or appended raw data, uncompressed or zlib) and medit `.mesh` in (a
//! file holding XML is read as VTU whatever its extension); VTU + PVD, legacy
//! VTK, MSH 2.2, OBJ, binary STL and medit out.
//!
//! Every parser is written by hand over a byte slice: the formats are simple,
//! the crates that read them lose the line of a fault or pull in large
//! dependency trees, and a hand-written parser can promise what the fuzzers
//! check: no panic on any input, and no allocation larger than the input
//! justifies (a header claiming 10^12 nodes is an error, not an OOM).
//!
//! Only 4-node tetrahedra become the mesh. Lower-dimensional elements
//! (boundary triangles, lines, points) are ignored with a warning; volume
//! elements of any other kind (10-node tetrahedra, hexahedra, prisms) are
//! refused, since dropping them would silently remove part of the body.

// `MeshIoError::Invalid` carries the `MeshError` by value so that callers can
// match on it; that makes the error ~140 bytes. Errors are the cold path of a
// file import, so the size costs nothing measurable.
#![allow(clippy::result_large_err)]

mod base64;
mod error;
mod export;
mod gmsh;
mod gmsh41;
mod gmsh41_input;
mod gmsh_export;
mod gmsh_legacy;
mod medit;
mod text;
mod vtk;
mod vtk_binary;
mod vtk_cells;
mod vtk_export;
mod vtk_zlib;
mod vtu;
mod vtu_decode;
mod xml;

pub use error::{Location, MeshIoError};
pub use export::{DataArray, write_obj, write_pvd, write_stl, write_vtu, write_vtu_zlib};
pub use gmsh_export::write_msh;
pub use medit::write_medit;
pub use vtk_export::write_vtk;

use crate::math::Vec3;
use crate::mesh::{MeshError, TetMesh};
use std::collections::HashMap;
use std::path::Path;

/// A mesh file format, detected from the file extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MeshFormat {
    /// Gmsh `.msh`, version 4.1 or 2.2 (ASCII or binary), or 1.
    Msh,
    /// Legacy VTK `.vtk`, ASCII or binary unstructured grid.
    VtkLegacy,
    /// VTK XML unstructured grid `.vtu`.
    Vtu,
    /// medit / INRIA `.mesh` (ASCII).
    Medit,
}

impl MeshFormat {
    /// The format for a file extension (case-insensitive), if it is known.
    pub fn from_path(path: &Path) -> Option<Self> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        match ext.as_str() {
            "msh" => Some(Self::Msh),
            "vtk" => Some(Self::VtkLegacy),
            "vtu" => Some(Self::Vtu),
            "mesh" => Some(Self::Medit),
            _ => None,
        }
    }
}

/// A tetrahedral mesh read from a file, with what the file said about it.
#[derive(Clone, Debug)]
pub struct ImportedMesh {
    /// The validated mesh (inverted tetrahedra reoriented). Vertices keep the
    /// file's order; unused vertices are kept.
    pub mesh: TetMesh,
    /// The physical tag of each tetrahedron (Gmsh physical group, medit
    /// reference, VTK cell data `physical` / `gmsh:physical` /
    /// `CellEntityIds`); 0 when the file has none.
    pub tet_physical: Vec<i32>,
    /// The file's triangles that carry a physical tag (a Gmsh physical
    /// surface, a medit reference, a tagged VTK triangle cell): 0-based
    /// vertex indices and the tag, for selections by surface
    /// (`select = { surface_physical = N }`). Untagged triangles are
    /// ignored like the other lower-dimensional elements.
    pub surface_physical: Vec<([u32; 3], i32)>,
    /// What the import changed or left out, for the user to see.
    pub warnings: Vec<String>,
}

/// Reads a mesh file, choosing the format by its extension.
pub fn read_mesh(path: &Path) -> Result<ImportedMesh, MeshIoError> {
    let name = path.display().to_string();
    let format = MeshFormat::from_path(path)
        .ok_or_else(|| MeshIoError::UnknownFormat { file: name.clone() })?;
    let bytes = crate::input_file::read_at_most(path, crate::input_file::MAX_MESH_BYTES).map_err(
        |source| MeshIoError::Io {
            file: name.clone(),
            reason: source,
        },
    )?;
    parse_mesh(&name, &bytes, format)
}

/// Parses a mesh from memory; `name` is used in error messages. Never panics,
/// whatever the bytes.
pub fn parse_mesh(
    name: &str,
    bytes: &[u8],
    format: MeshFormat,
) -> Result<ImportedMesh, MeshIoError> {
    if format != MeshFormat::Vtu && is_xml(bytes) {
        // VTK XML under another name (SOFA's Bunny.vtk is a VTU).
        let mut m = vtu::parse(name, bytes)?;
        m.warnings.push(format!(
            "{name} holds VTK XML (a VTU file), not the format its name says: read as VTU"
        ));
        return Ok(m);
    }
    match format {
        MeshFormat::Msh => gmsh::parse(name, bytes),
        MeshFormat::VtkLegacy => vtk::parse(name, bytes),
        MeshFormat::Vtu => vtu::parse(name, bytes),
        MeshFormat::Medit => medit::parse(name, bytes),
    }
}

/// Whether a file holds XML (after an optional byte-order mark and blanks).
fn is_xml(bytes: &[u8]) -> bool {
    let b = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
    let start = b
        .iter()
        .position(|c| !c.is_ascii_whitespace())
        .unwrap_or(b.len());
    b[start..].starts_with(b"<?xml") || b[start..].starts_with(b"<VTKFile")
}

/// Collects what a parser found and turns it into an [`ImportedMesh`],
/// translating validation failures back to the file's own numbering.
pub(crate) struct Builder<'f> {
    file: &'f str,
    /// How the file calls an element in messages ("element", "cell", ...).
    element_word: &'static str,
    positions: Vec<Vec3>,
    tets: Vec<[u32; 4]>,
    tet_physical: Vec<i32>,
    surface_physical: Vec<([u32; 3], i32)>,
    /// Each tetrahedron's number in the file and where it is.
    tet_origin: Vec<(u64, Location)>,
    /// Each vertex's number in the file (messages use the file's numbering).
    vertex_numbers: Vec<u64>,
    /// What the file calls a vertex (`node`, `vertex`, `point`).
    vertex_noun: &'static str,
    /// Lower-dimensional elements ignored, by kind (plural noun).
    ignored: Vec<(&'static str, usize)>,
    warnings: Vec<String>,
}

impl<'f> Builder<'f> {
    /// An empty builder; `element_word` names elements in messages.
    pub fn new(file: &'f str, element_word: &'static str) -> Self {
        Self {
            file,
            element_word,
            positions: Vec::new(),
            tets: Vec::new(),
            tet_physical: Vec::new(),
            surface_physical: Vec::new(),
            tet_origin: Vec::new(),
            vertex_numbers: Vec::new(),
            vertex_noun: "vertex",
            ignored: Vec::new(),
            warnings: Vec::new(),
        }
    }

    /// Reserves room for `n` more vertices, but never more than `cap` (the
    /// bytes left in the input bound how many records can follow).
    pub fn reserve_vertices(&mut self, n: u64, cap: usize) {
        let n = usize::try_from(n).unwrap_or(usize::MAX).min(cap);
        self.positions.reserve(n);
        self.vertex_numbers.reserve(n);
    }

    /// Reserves room for `n` more tetrahedra, capped like
    /// [`Builder::reserve_vertices`].
    pub fn reserve_tets(&mut self, n: u64, cap: usize) {
        let n = usize::try_from(n).unwrap_or(usize::MAX).min(cap);
        self.tets.reserve(n);
        self.tet_physical.reserve(n);
        self.tet_origin.reserve(n);
    }

    /// Number of vertices so far.
    pub fn vertex_count(&self) -> usize {
        self.positions.len()
    }

    /// Adds a vertex, `noun number` in the file's own numbering (`node 145`,
    /// `point 0`); refuses a non-finite coordinate here, where its line is
    /// known.
    pub fn vertex(
        &mut self,
        p: [f64; 3],
        at: Location,
        noun: &'static str,
        number: u64,
    ) -> Result<(), MeshIoError> {
        let label = format!("{noun} {number}");
        if !p.iter().all(|c| c.is_finite()) {
            return Err(text::perr(
                self.file,
                at,
                format!("{label} has a non-finite coordinate {p:?}"),
            ));
        }
        if self.positions.len() >= u32::MAX as usize {
            return Err(text::perr(
                self.file,
                at,
                "more than 2^32 - 1 vertices (indices are 32-bit)",
            ));
        }
        self.positions.push(Vec3::from_array(p));
        self.vertex_numbers.push(number);
        self.vertex_noun = noun;
        Ok(())
    }

    /// Adds a tetrahedron of 0-based vertex indices (already checked to be in
    /// range by the caller), its physical tag, its number in the file and place.
    pub fn tet(&mut self, v: [u32; 4], physical: i32, number: u64, at: Location) {
        self.tets.push(v);
        self.tet_physical.push(physical);
        self.tet_origin.push((number, at));
    }

    /// Adds a triangle of 0-based vertex indices (already checked to be in
    /// range by the caller) with its physical tag: kept for surface
    /// selections when the tag is not 0, else counted as ignored.
    pub fn triangle(&mut self, v: [u32; 3], physical: i32) {
        if physical == 0 {
            self.ignore("triangles", 1);
        } else {
            self.surface_physical.push((v, physical));
        }
    }

    /// Counts `n` ignored lower-dimensional elements of a kind (plural noun).
    pub fn ignore(&mut self, kind: &'static str, n: usize) {
        if n == 0 {
            return;
        }
        match self.ignored.iter_mut().find(|(k, _)| *k == kind) {
            Some((_, count)) => *count += n,
            None => self.ignored.push((kind, n)),
        }
    }

    /// Adds a warning.
    pub fn warn(&mut self, warning: String) {
        self.warnings.push(warning);
    }

    /// Validates the mesh and returns it.
    pub fn finish(mut self) -> Result<ImportedMesh, MeshIoError> {
        let ignored = if self.ignored.is_empty() {
            String::new()
        } else {
            let parts: Vec<String> = self
                .ignored
                .iter()
                .map(|(k, n)| format!("{n} {k}"))
                .collect();
            let list = match parts.split_last() {
                Some((last, [])) => last.clone(),
                Some((last, rest)) => format!("{} and {last}", rest.join(", ")),
                None => String::new(),
            };
            format!("ignored {list} (lower-dimensional elements)")
        };
        if self.tets.is_empty() {
            return Err(MeshIoError::NoTetrahedra {
                file: self.file.to_owned(),
                ignored: if ignored.is_empty() {
                    String::new()
                } else {
                    format!(" ({ignored})")
                },
            });
        }
        if !ignored.is_empty() {
            self.warnings.push(ignored);
        }
        let file = self.file;
        let element_word = self.element_word;
        let origin = std::mem::take(&mut self.tet_origin);
        let (numbers, noun) = (std::mem::take(&mut self.vertex_numbers), self.vertex_noun);
        let mesh = TetMesh::new(self.positions, self.tets).map_err(|source| {
            // An element's own fault, said in the file's numbering only.
            let source = match element_error(file, element_word, &origin, &numbers, noun, source) {
                Ok(e) => return e,
                Err(source) => source,
            };
            let tet = match &source {
                MeshError::IndexOutOfRange { tet, .. }
                | MeshError::RepeatedVertex { tet, .. }
                | MeshError::Degenerate { tet, .. }
                | MeshError::Duplicate { tet, .. } => Some(*tet),
                MeshError::Empty | MeshError::NonFinite { .. } | MeshError::OutOfRange { .. } => {
                    None
                }
            };
            let place = tet.and_then(|t| origin.get(t));
            MeshIoError::Invalid {
                file: file.to_owned(),
                at: place.map(|(_, at)| *at),
                context: place
                    .map(|(n, _)| format!("{element_word} {n}: "))
                    .unwrap_or_default(),
                reason: source,
            }
        })?;
        if mesh.reoriented() > 0 {
            // Named as the file numbers them, with their lines.
            let named: Vec<String> = mesh
                .reoriented_first()
                .iter()
                .filter_map(|t| origin.get(*t))
                .map(|(n, at)| match at {
                    Location::Line(l) => format!("{element_word} {n} (line {l})"),
                    other => format!("{element_word} {n} ({other})"),
                })
                .collect();
            let more = mesh.reoriented() - named.len();
            self.warnings.push(format!(
                "{} inverted tetrahedra reoriented: {}{}",
                mesh.reoriented(),
                named.join(", "),
                if more > 0 {
                    format!(" and {more} more")
                } else {
                    String::new()
                }
            ));
        }
        Ok(ImportedMesh {
            mesh,
            tet_physical: self.tet_physical,
            surface_physical: self.surface_physical,
            warnings: self.warnings,
        })
    }
}

/// Maps a format's node numbers (Gmsh tags: arbitrary, possibly sparse) to
/// 0-based vertex indices. Files almost always number nodes 1..n in order, so
/// that case needs no table; the hash map is built at the first exception.
pub(crate) struct NodeMap {
    /// Nodes so far numbered 1..=count in order.
    dense: usize,
    sparse: Option<HashMap<u64, u32>>,
}

impl NodeMap {
    /// An empty map.
    pub fn new() -> Self {
        Self {
            dense: 0,
            sparse: None,
        }
    }

    /// Records that node `tag` is vertex `index` (the next one). Returns false
    /// if the tag was seen before.
    pub fn insert(&mut self, tag: u64, index: u32) -> bool {
        if self.sparse.is_none() {
            if tag == self.dense as u64 + 1 && index as usize == self.dense {
                self.dense += 1;
                return true;
            }
            self.sparse = Some((0..self.dense).map(|i| (i as u64 + 1, i as u32)).collect());
        }
        match &mut self.sparse {
            Some(map) => map.insert(tag, index).is_none(),
            None => false,
        }
    }

    /// The vertex of node `tag`.
    pub fn get(&self, tag: u64) -> Option<u32> {
        match &self.sparse {
            Some(map) => map.get(&tag).copied(),
            None => (tag >= 1 && tag <= self.dense as u64).then(|| (tag - 1) as u32),
        }
    }
}

/// The [`MeshIoError::Element`] of a tetrahedron's own fault (a repeated
/// vertex, zero volume, a duplicate), in the file's numbering: its element
/// number and line, its vertices as the file numbers them. The fault back
/// when it is not one element's.
fn element_error(
    file: &str,
    element_word: &str,
    origin: &[(u64, Location)],
    numbers: &[u64],
    noun: &str,
    source: MeshError,
) -> Result<MeshIoError, MeshError> {
    let vertices = |v: &[usize; 4]| -> String {
        let n: Vec<String> = v
            .iter()
            .map(|i| numbers.get(*i).map_or(format!("#{i}"), u64::to_string))
            .collect();
        let plural = if noun == "vertex" {
            "vertices".to_string()
        } else {
            format!("{noun}s")
        };
        format!("{plural} {}", n.join(" "))
    };
    let (tet, message) = match &source {
        MeshError::RepeatedVertex { tet, vertices: v } => {
            (*tet, format!("repeats a {noun}: {}", vertices(v)))
        }
        MeshError::Degenerate {
            tet,
            vertices: v,
            volume_m3,
            longest_edge_m,
        } => (
            *tet,
            format!(
                "({}) has zero volume ({volume_m3:e} m^3 for a longest edge of {longest_edge_m:e} m)",
                vertices(v)
            ),
        ),
        MeshError::Duplicate { tet, first } => {
            let Some(first) = origin.get(*first) else {
                return Err(source);
            };
            (
                *tet,
                format!(
                    "is the same tetrahedron as {element_word} {} ({})",
                    first.0, first.1
                ),
            )
        }
        _ => return Err(source),
    };
    let Some((number, at)) = origin.get(tet) else {
        return Err(source);
    };
    Ok(MeshIoError::Element {
        file: file.to_owned(),
        at: *at,
        message: format!("{element_word} {number} {message}"),
        kind: source,
    })
}
