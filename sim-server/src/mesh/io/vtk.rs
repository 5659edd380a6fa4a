//! Legacy VTK, ASCII `DATASET UNSTRUCTURED_GRID` (binary files are read by
//! `vtk_binary.rs`), in both cell layouts: the
//! classic `CELLS n size` (each cell `k i1 .. ik`) and the 5.x `OFFSETS` /
//! `CONNECTIVITY` pair that meshio writes. Values are free-form (they may
//! wrap across lines), so the file is read as tokens, each with its line.
//!
//! Attribute sections (`POINT_DATA`, `CELL_DATA`, `FIELD`) are skipped value
//! by value, except the cell array that holds physical tags. The VTK cell type
//! table and the cells' checks are in `vtk_cells.rs`, shared with the binary
//! and VTU readers.

use super::error::{Location, MeshIoError};
use super::text::{Lines, Token, Tokens, parse_f64, parse_i64, parse_u64, perr, shown};
use super::vtk_cells::{CellLists, PHYSICAL_NAMES, add_cell_lists, physical_tag};
use super::{Builder, ImportedMesh};

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
                    b.vertex(p, at, "point", i)?;
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
