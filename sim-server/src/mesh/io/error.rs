//! The one error type of mesh import and export. Every message starts with the
//! file name and, where the format has lines, the 1-based line
//! (`box.msh:123: ...`), so that a user can open the file at the fault; binary
//! data is located by byte offset instead (`mesh.msh:byte 4096: ...`).

use crate::mesh::MeshError;
use std::fmt;
use thiserror::Error;

/// Where in a file something is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Location {
    /// A 1-based line of a text file.
    Line(usize),
    /// A 0-based byte offset in binary data.
    Byte(usize),
}

impl Location {
    /// The line, if this is a line.
    pub fn line(self) -> Option<usize> {
        match self {
            Location::Line(l) => Some(l),
            Location::Byte(_) => None,
        }
    }
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Location::Line(l) => write!(f, "{l}"),
            Location::Byte(b) => write!(f, "byte {b}"),
        }
    }
}

/// `:123` or nothing, for messages that may or may not have a place.
fn place(location: &Option<Location>) -> String {
    location.map(|l| format!(":{l}")).unwrap_or_default()
}

/// Why a mesh could not be read or written.
#[derive(Debug, Error)]
pub enum MeshIoError {
    /// The file could not be opened, read or written.
    #[error("{file}: {reason}")]
    Io {
        /// The file.
        file: String,
        /// The operating-system error.
        reason: std::io::Error,
    },
    /// The file does not follow its format.
    #[error("{file}:{at}: {message}")]
    Parse {
        /// The file.
        file: String,
        /// Where (line for text, byte offset for binary data).
        at: Location,
        /// What is wrong, naming the field.
        message: String,
    },
    /// The file holds an element kind that cannot become a linear tetrahedral
    /// mesh (second-order tetrahedra, hexahedra, prisms...). Such files are
    /// refused rather than silently dropping part of the volume.
    #[error(
        "{file}:{at}: unsupported element {element}: only 4-node tetrahedra (and ignored lower-dimensional elements) can be imported"
    )]
    UnsupportedElement {
        /// The file.
        file: String,
        /// Where the element (or its block) is.
        at: Location,
        /// The element kind, e.g. `10-node tetrahedron (Gmsh type 11)`.
        element: String,
    },
    /// The file is well formed but has no tetrahedra.
    #[error("{file}: no tetrahedra in the file{ignored}")]
    NoTetrahedra {
        /// The file.
        file: String,
        /// What was found instead, e.g. ` (ignored 340 triangles)`, or empty.
        ignored: String,
    },
    /// The tetrahedra were read but do not form a valid mesh.
    #[error("{file}{}: {context}{reason}", place(.at))]
    Invalid {
        /// The file.
        file: String,
        /// Where the offending element is, if known.
        at: Option<Location>,
        /// The element in the file's own numbering, e.g. `element 1234: `.
        context: String,
        /// The validation failure (its indices are 0-based, in import order).
        reason: MeshError,
    },
    /// One element is at fault (a repeated vertex, zero volume, a
    /// duplicate): said in the file's own numbering, elements and vertices.
    #[error("{file}:{at}: {message}")]
    Element {
        /// The file.
        file: String,
        /// Where the element is.
        at: Location,
        /// What is wrong, e.g. `element 952 repeats a node: nodes 145 320 320 585`.
        message: String,
        /// The validation failure (its indices 0-based, in import order).
        kind: MeshError,
    },
    /// The file extension is none of `.msh`, `.vtk`, `.vtu`, `.mesh`.
    #[error("{file}: unknown mesh format (expected .msh, .vtk, .vtu or .mesh)")]
    UnknownFormat {
        /// The file.
        file: String,
    },
    /// A writer was given inconsistent data (an index out of range, an array of
    /// the wrong length, a non-finite time).
    #[error("{file}: {message}")]
    BadInput {
        /// The file that was to be written.
        file: String,
        /// What is wrong.
        message: String,
    },
}

impl MeshIoError {
    /// The line the error points at, if it has one (tests and tools use it).
    pub fn line(&self) -> Option<usize> {
        match self {
            MeshIoError::Parse { at, .. } | MeshIoError::UnsupportedElement { at, .. } => at.line(),
            MeshIoError::Invalid { at, .. } => at.and_then(Location::line),
            MeshIoError::Element { at, .. } => at.line(),
            _ => None,
        }
    }
}
