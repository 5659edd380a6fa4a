//! Legacy VTK, ASCII `DATASET UNSTRUCTURED_GRID` (binary files are read by
//! `vtk_binary.rs`), in both cell layouts: the
//! classic `CELLS n size` (each cell `k i1 .. ik`) and the 5.x `OFFSETS` /
//! `CONNECTIVITY` pair that meshio writes. Values are free-form (they may
//! wrap across lines), so the file is read as tokens, each with its line.
//!
//! Attribute sections (`POINT_DATA`, `CELL_DATA`, `FIELD`) are skipped value
//! by value, except the cell array that holds physical tags. The VTK cell type
//! table here is shared with the VTU reader.

use super::error::{Location, MeshIoError};
use super::text::{Lines, Token, Tokens, parse_f64, parse_i64, parse_u64, perr, shown};
use super::{Builder, ImportedMesh};

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

/// Cells as read: offsets into `connectivity`, and each cell's line.
struct Cells {
    offsets: Vec<usize>,
    connectivity: Vec<i64>,
    lines: Vec<usize>,
}

/// Parses a legacy VTK file.
pub(super) fn parse(file: &str, bytes: &[u8]) -> Result<ImportedMesh, MeshIoError> {
    let mut lines = Lines::new(bytes);
    let mut header = |what: &str| {
        lines
            .next_raw()
            .ok_or_else(|| perr(file, Location::Line(1), format!("file ends before {what}")))
    };
    let version = header("the '# vtk DataFile Version' line")?;
    if !version
        .text
        .trim_start()
        .to_ascii_lowercase()
        .starts_with("# vtk datafile version")
    {
        return Err(perr(
            file,
            version.at(),
            format!(
                "expected '# vtk DataFile Version x.y', found {}",
                shown(version.text)
            ),
        ));
    }
    header("the title line")?;
    let encoding = header("ASCII or BINARY")?;
    match encoding.text.trim().to_ascii_uppercase().as_str() {
        "ASCII" => {}
        "BINARY" => return super::vtk_binary::parse(file, bytes, lines.pos()),
        other => {
            return Err(perr(
                file,
                encoding.at(),
                format!("expected ASCII or BINARY, found {}", shown(other)),
            ));
        }
    }
    let mut t = Tokens::new(bytes, lines.pos(), lines.line_no() + 1, None);
    let mut r = Reader { file, t: &mut t };

    let dataset = r.keyword("DATASET")?;
    let kind = r.next("the dataset type")?;
    if !kind.text.eq_ignore_ascii_case("UNSTRUCTURED_GRID") {
        return Err(perr(
            file,
            dataset.at(),
            format!(
                "only DATASET UNSTRUCTURED_GRID is supported, found {}",
                shown(kind.text)
            ),
        ));
    }

    let mut b = Builder::new(file, "cell");
    let mut cells: Option<Cells> = None;
    let mut types: Option<(Vec<i64>, usize)> = None;
    let mut physical: Option<(usize, Vec<i32>, usize)> = None;
    // The number of tuples the current attribute section holds, and whether it is cell data.
    let mut section: Option<(u64, bool)> = None;
    while let Some(k) = r.t.next_token() {
        match k.text.to_ascii_uppercase().as_str() {
            "POINTS" => {
                let n = r.count("the number of points")?;
                r.next("the point data type")?;
                b.reserve_vertices(n, r.t.remaining() / 6);
                for i in 0..n {
                    let x = r.float("a point coordinate")?;
                    let at = x.1;
                    let p = [x.0, r.float("y")?.0, r.float("z")?.0];
                    b.vertex(p, at, &format!("point {i}"))?;
                }
            }
            "CELLS" => cells = Some(r.cells()?),
            "CELL_TYPES" => {
                let n = r.count("the number of cell types")?;
                let mut v = Vec::with_capacity(cap(n, r.t.remaining() / 2));
                for _ in 0..n {
                    v.push(r.int("a cell type")?.0);
                }
                types = Some((v, k.line));
            }
            "POINT_DATA" => section = Some((r.count("the number of points")?, false)),
            "CELL_DATA" => section = Some((r.count("the number of cells")?, true)),
            "METADATA" => r.skip_metadata(),
            "FIELD" => {
                r.next("the field name")?;
                let arrays = r.count("the number of arrays")?;
                for _ in 0..arrays {
                    let name = r.next("an array name")?;
                    let comps = r.count("the number of components")?;
                    let tuples = r.count("the number of tuples")?;
                    r.next("the array data type")?;
                    let keep = section.is_some_and(|(_, cell)| cell) && comps == 1;
                    r.values(name, comps.saturating_mul(tuples), keep, &mut physical)?;
                }
            }
            "SCALARS"
            | "VECTORS"
            | "NORMALS"
            | "TENSORS"
            | "TENSORS6"
            | "TEXTURE_COORDINATES"
            | "COLOR_SCALARS"
            | "GLOBAL_IDS"
            | "PEDIGREE_IDS"
            | "LOOKUP_TABLE" => {
                let kw = k.text.to_ascii_uppercase();
                let name = r.next("an attribute name")?;
                let tuples = section.map_or(0, |(n, _)| n);
                let (comps, keep) = match kw.as_str() {
                    "SCALARS" => {
                        r.next("the data type")?;
                        let comps = match r.t.peek() {
                            Some(c) if !c.first_on_line => r.count("the number of components")?,
                            _ => 1,
                        };
                        if r.t
                            .peek()
                            .is_some_and(|l| l.text.eq_ignore_ascii_case("LOOKUP_TABLE"))
                        {
                            r.t.next_token();
                            r.next("the lookup table name")?;
                        }
                        (comps, section.is_some_and(|(_, cell)| cell) && comps == 1)
                    }
                    "VECTORS" | "NORMALS" => (r.next("the data type").map(|_| 3)?, false),
                    "TENSORS" => (r.next("the data type").map(|_| 9)?, false),
                    "TENSORS6" => (r.next("the data type").map(|_| 6)?, false),
                    "TEXTURE_COORDINATES" => {
                        let d = r.count("the dimension")?;
                        r.next("the data type")?;
                        (d, false)
                    }
                    "COLOR_SCALARS" => (r.count("the number of values")?, false),
                    "LOOKUP_TABLE" => {
                        // `LOOKUP_TABLE name size`: `size` RGBA entries.
                        let entries = r.count("the table size")?;
                        r.values(name, entries.saturating_mul(4), false, &mut physical)?;
                        continue;
                    }
                    _ => (r.next("the data type").map(|_| 1)?, false),
                };
                r.values(name, comps.saturating_mul(tuples), keep, &mut physical)?;
            }
            _ => {
                return Err(perr(
                    file,
                    k.at(),
                    format!("unknown keyword {}", shown(k.text)),
                ));
            }
        }
    }

    let cells = cells.ok_or_else(|| MeshIoError::NoTetrahedra {
        file: file.to_owned(),
        ignored: " (no CELLS section)".into(),
    })?;
    let (types, types_line) = types.ok_or_else(|| {
        perr(
            file,
            Location::Line(r.t.line()),
            "the file has CELLS but no CELL_TYPES",
        )
    })?;
    let physical = physical.map(|(_, tags, line)| (tags, Location::Line(line)));
    add_cell_lists(
        &mut b,
        file,
        CellLists {
            types: &types,
            types_at: Location::Line(types_line),
            offsets: &cells.offsets,
            connectivity: &cells.connectivity,
            physical: physical.as_ref().map(|(t, at)| (t.as_slice(), *at)),
        },
        |c| Location::Line(cells.lines[c]),
    )?;
    b.finish()
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

/// The smaller of a claimed count and a bound from the input size.
fn cap(n: u64, bound: usize) -> usize {
    usize::try_from(n).unwrap_or(usize::MAX).min(bound)
}

/// Token reading with typed errors at the token's line.
struct Reader<'r, 'a> {
    file: &'r str,
    t: &'r mut Tokens<'a>,
}

impl<'a> Reader<'_, 'a> {
    fn next(&mut self, what: &str) -> Result<Token<'a>, MeshIoError> {
        self.t.next_token().ok_or_else(|| {
            perr(
                self.file,
                Location::Line(self.t.line()),
                format!("file ends before {what}"),
            )
        })
    }

    fn keyword(&mut self, kw: &str) -> Result<Token<'a>, MeshIoError> {
        let k = self.next(kw)?;
        if k.text.eq_ignore_ascii_case(kw) {
            Ok(k)
        } else {
            Err(perr(
                self.file,
                k.at(),
                format!("expected {kw}, found {}", shown(k.text)),
            ))
        }
    }

    fn count(&mut self, what: &str) -> Result<u64, MeshIoError> {
        let k = self.next(what)?;
        parse_u64(k.text).ok_or_else(|| {
            perr(
                self.file,
                k.at(),
                format!("expected {what}, found {}", shown(k.text)),
            )
        })
    }

    fn int(&mut self, what: &str) -> Result<(i64, usize), MeshIoError> {
        let k = self.next(what)?;
        parse_i64(k.text).map(|v| (v, k.line)).ok_or_else(|| {
            perr(
                self.file,
                k.at(),
                format!("expected {what}, found {}", shown(k.text)),
            )
        })
    }

    fn float(&mut self, what: &str) -> Result<(f64, Location), MeshIoError> {
        let k = self.next(what)?;
        parse_f64(k.text).map(|v| (v, k.at())).ok_or_else(|| {
            perr(
                self.file,
                k.at(),
                format!("expected {what}, found {}", shown(k.text)),
            )
        })
    }

    /// `CELLS` in either layout.
    fn cells(&mut self) -> Result<Cells, MeshIoError> {
        let header_line = self.t.line();
        let n = self.count("the number of cells")?;
        let size = self.count("the cell list size")?;
        let bound = self.t.remaining() / 2;
        let mut cells = Cells {
            offsets: vec![0],
            connectivity: Vec::with_capacity(cap(size, bound)),
            lines: Vec::with_capacity(cap(n, bound)),
        };
        if self
            .t
            .peek()
            .is_some_and(|k| k.text.eq_ignore_ascii_case("OFFSETS"))
        {
            // 5.x: n offsets (cells + 1), then `size` connectivity entries.
            self.keyword("OFFSETS")?;
            self.next("the offsets data type")?;
            cells.offsets.clear();
            for _ in 0..n {
                let (o, line) = self.int("an offset")?;
                let prev = cells.offsets.last().copied().unwrap_or(0);
                let o = usize::try_from(o)
                    .ok()
                    .filter(|&o| o >= prev && o as u64 <= size)
                    .ok_or_else(|| perr(self.file, Location::Line(line), format!("offset {o} is out of order or beyond the {size} connectivity entries")))?;
                if !cells.offsets.is_empty() {
                    cells.lines.push(line);
                }
                cells.offsets.push(o);
            }
            self.keyword("CONNECTIVITY")?;
            self.next("the connectivity data type")?;
            for _ in 0..size {
                cells.connectivity.push(self.int("a point index")?.0);
            }
            if cells
                .offsets
                .last()
                .is_some_and(|&o| o != cells.connectivity.len())
                || cells.offsets.is_empty()
            {
                return Err(perr(
                    self.file,
                    Location::Line(self.t.line()),
                    "the last offset must equal the connectivity size",
                ));
            }
        } else {
            for c in 0..n {
                let (k, line) = self.int("the number of points of a cell")?;
                let k = u64::try_from(k).map_err(|_| {
                    perr(
                        self.file,
                        Location::Line(line),
                        format!("cell {c} has a negative point count {k}"),
                    )
                })?;
                for _ in 0..k {
                    cells.connectivity.push(self.int("a point index")?.0);
                }
                cells.offsets.push(cells.connectivity.len());
                cells.lines.push(line);
            }
            let used = cells.connectivity.len() as u64 + n;
            if used != size {
                return Err(perr(
                    self.file,
                    Location::Line(header_line),
                    format!("CELLS declares a list size of {size} but its cells use {used} values"),
                ));
            }
        }
        Ok(cells)
    }

    /// Reads `count` values of an attribute; keeps them as physical tags if
    /// `keep` and the name is one of [`PHYSICAL_NAMES`] preferred to the one held.
    fn values(
        &mut self,
        name: Token,
        count: u64,
        keep: bool,
        physical: &mut Option<(usize, Vec<i32>, usize)>,
    ) -> Result<(), MeshIoError> {
        let rank = PHYSICAL_NAMES.iter().position(|n| *n == name.text);
        let keep =
            keep && rank.is_some_and(|r| physical.as_ref().is_none_or(|(held, ..)| r < *held));
        let mut tags = Vec::with_capacity(if keep {
            cap(count, self.t.remaining() / 2)
        } else {
            0
        });
        for _ in 0..count {
            let (v, at) = self.float("an attribute value")?;
            if keep {
                let tag = physical_tag(v).ok_or_else(|| {
                    perr(
                        self.file,
                        at,
                        format!("physical tag {v} is not a 32-bit integer"),
                    )
                })?;
                tags.push(tag);
            }
        }
        if let (true, Some(r)) = (keep, rank) {
            *physical = Some((r, tags, name.line));
        }
        Ok(())
    }

    /// Skips a `METADATA` block: everything up to the next keyword that starts a line.
    fn skip_metadata(&mut self) {
        const KEYWORDS: [&str; 6] = [
            "POINTS",
            "CELLS",
            "CELL_TYPES",
            "POINT_DATA",
            "CELL_DATA",
            "FIELD",
        ];
        while let Some(k) = self.t.peek() {
            if k.first_on_line && KEYWORDS.iter().any(|kw| k.text.eq_ignore_ascii_case(kw)) {
                return;
            }
            self.t.next_token();
        }
    }
}
