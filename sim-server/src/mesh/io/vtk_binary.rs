//! Legacy VTK `BINARY` unstructured grids (meshio's default for `.vtk`):
//! keyword lines in ASCII, each followed by its values as big-endian binary,
//! in both cell layouts (classic `CELLS n size` of int32; 5.x `CELLS`
//! with `OFFSETS` and `CONNECTIVITY` arrays of a named type). Errors give the
//! byte offset; sizes are checked against the bytes present before anything
//! is allocated.

use super::error::{Location, MeshIoError};
use super::text::{as_text, perr, shown};
use super::vtk_cells::{CellLists, PHYSICAL_NAMES, add_cell_lists, physical_tag};
use super::{Builder, ImportedMesh};

/// Byte width of a legacy VTK data type name.
fn width(ty: &str) -> Option<usize> {
    Some(match ty.to_ascii_lowercase().as_str() {
        "bit" => return None,
        "char" | "unsigned_char" | "vtktypeint8" | "vtktypeuint8" => 1,
        "short" | "unsigned_short" | "vtktypeint16" | "vtktypeuint16" => 2,
        "int" | "unsigned_int" | "float" | "vtktypeint32" | "vtktypeuint32" | "vtktypefloat32" => 4,
        "long" | "unsigned_long" | "double" | "vtkidtype" | "vtktypeint64" | "vtktypeuint64"
        | "vtktypefloat64" => 8,
        _ => return None,
    })
}

/// Reads keyword lines and binary payloads in turn.
struct Reader<'a, 'f> {
    file: &'f str,
    src: &'a [u8],
    pos: usize,
}

impl<'a> Reader<'a, '_> {
    fn err(&self, at: usize, message: impl Into<String>) -> MeshIoError {
        perr(self.file, Location::Byte(at), message)
    }

    /// The next non-blank line's fields and where it starts (`None` at the end).
    fn line(&mut self) -> Option<(usize, Vec<&'a str>)> {
        while self.src.get(self.pos).is_some_and(u8::is_ascii_whitespace) {
            self.pos += 1;
        }
        let rest = self.src.get(self.pos..).filter(|r| !r.is_empty())?;
        let at = self.pos;
        let end = rest.iter().position(|&b| b == b'\n').unwrap_or(rest.len());
        self.pos += (end + 1).min(rest.len());
        Some((at, as_text(&rest[..end]).split_whitespace().collect()))
    }

    /// `count` values of type `ty` as f64 (integers exactly up to 2^53).
    fn values(&mut self, count: u64, ty: &str, what: &str) -> Result<Vec<f64>, MeshIoError> {
        let at = self.pos;
        let w = width(ty).ok_or_else(|| {
            self.err(
                at,
                format!("{what}: data type {} is not supported", shown(ty)),
            )
        })?;
        let bytes = count
            .checked_mul(w as u64)
            .and_then(|n| usize::try_from(n).ok())
            .and_then(|n| self.src.get(at..at.checked_add(n)?))
            .ok_or_else(|| self.err(at, format!("{what}: file ends inside {count} values")))?;
        self.pos += bytes.len();
        let float = matches!(
            ty.to_ascii_lowercase().as_str(),
            "float" | "double" | "vtktypefloat32" | "vtktypefloat64"
        );
        let unsigned = ty.to_ascii_lowercase().contains("unsigned") || ty.contains("uint");
        Ok(bytes
            .chunks_exact(w)
            .map(|c| {
                let mut b = [0u8; 8];
                b[8 - w..].copy_from_slice(c);
                let bits = u64::from_be_bytes(b);
                match (w, float, unsigned) {
                    (4, true, _) => f64::from(f32::from_bits(bits as u32)),
                    (8, true, _) => f64::from_bits(bits),
                    (_, false, true) => bits as f64,
                    // Sign-extend from w bytes.
                    _ => ((bits << (64 - 8 * w)) as i64 >> (64 - 8 * w)) as f64,
                }
            })
            .collect())
    }

    fn count(&self, at: usize, field: Option<&&str>, what: &str) -> Result<u64, MeshIoError> {
        field.and_then(|f| f.parse().ok()).ok_or_else(|| {
            self.err(
                at,
                format!(
                    "expected {what}, found {}",
                    shown(field.copied().unwrap_or(""))
                ),
            )
        })
    }
}

/// Integers from values, refusing fractions.
fn ints(values: Vec<f64>) -> Vec<i64> {
    values
        .into_iter()
        .map(|v| if v.fract() == 0.0 { v as i64 } else { -1 })
        .collect()
}

/// A binary legacy VTK file whose header lines end at `pos`.
pub(super) fn parse(file: &str, bytes: &[u8], pos: usize) -> Result<ImportedMesh, MeshIoError> {
    let mut r = Reader {
        file,
        src: bytes,
        pos,
    };
    match r.line() {
        Some((_, f)) if f.len() == 2 && f[1].eq_ignore_ascii_case("UNSTRUCTURED_GRID") => {}
        Some((at, f)) => {
            return Err(r.err(
                at,
                format!(
                    "only DATASET UNSTRUCTURED_GRID is supported, found {}",
                    shown(&f.join(" "))
                ),
            ));
        }
        None => return Err(r.err(pos, "file ends before DATASET")),
    }
    let mut b = Builder::new(file, "cell");
    let mut offsets: Option<(Vec<i64>, usize)> = None;
    let mut connectivity: Vec<i64> = Vec::new();
    let mut types: Option<(Vec<i64>, usize)> = None;
    let mut physical: Option<(usize, Vec<f64>, usize)> = None;
    let mut tuples = (0u64, false);
    while let Some((at, f)) = r.line() {
        let key = f[0].to_ascii_uppercase();
        match key.as_str() {
            "POINTS" => {
                let n = r.count(at, f.get(1), "the number of points")?;
                let ty = f.get(2).copied().unwrap_or("");
                let xyz = r.values(n.saturating_mul(3), ty, "POINTS")?;
                b.reserve_vertices(n, xyz.len() / 3);
                for (i, p) in xyz.chunks_exact(3).enumerate() {
                    b.vertex([p[0], p[1], p[2]], Location::Byte(at), "point", i as u64)?;
                }
            }
            "CELLS" => {
                let n = r.count(at, f.get(1), "the number of cells")?;
                let size = r.count(at, f.get(2), "the cell list size")?;
                let save = r.pos;
                match r.line() {
                    Some((_, g)) if g[0].eq_ignore_ascii_case("OFFSETS") => {
                        let ty = g.get(1).copied().unwrap_or("");
                        let o = ints(r.values(n, ty, "OFFSETS")?);
                        let c = r
                            .line()
                            .filter(|(_, h)| h[0].eq_ignore_ascii_case("CONNECTIVITY"));
                        let Some((_, h)) = c else {
                            return Err(r.err(r.pos, "expected CONNECTIVITY after OFFSETS"));
                        };
                        let ty = h.get(1).copied().unwrap_or("");
                        connectivity = ints(r.values(size, ty, "CONNECTIVITY")?);
                        offsets = Some((o, at));
                    }
                    _ => {
                        // Classic: each cell `k i1 .. ik`, all int32.
                        r.pos = save;
                        let list = ints(r.values(size, "int", "CELLS")?);
                        let mut o = vec![0i64];
                        let mut k = 0usize;
                        while k < list.len() && (o.len() as u64) <= n {
                            let m = usize::try_from(list[k]).unwrap_or(usize::MAX);
                            let end = k.saturating_add(1).saturating_add(m).min(list.len());
                            connectivity.extend_from_slice(&list[k + 1..end]);
                            o.push(connectivity.len() as i64);
                            k = end;
                        }
                        if o.len() as u64 != n + 1 || k != list.len() {
                            return Err(
                                r.err(at, format!("CELLS: {n} cells do not fill {size} values"))
                            );
                        }
                        offsets = Some((o, at));
                    }
                }
            }
            "CELL_TYPES" => {
                let n = r.count(at, f.get(1), "the number of cell types")?;
                types = Some((ints(r.values(n, "int", "CELL_TYPES")?), at));
            }
            "POINT_DATA" | "CELL_DATA" => {
                tuples = (
                    r.count(at, f.get(1), "the number of tuples")?,
                    key == "CELL_DATA",
                );
            }
            "METADATA" => {
                // Lines up to a blank one (INFORMATION, NAME, DATA...).
                while let Some(rest) = r.src.get(r.pos..).filter(|s| !s.is_empty()) {
                    let end = rest.iter().position(|&b| b == b'\n').unwrap_or(rest.len());
                    r.pos += (end + 1).min(rest.len());
                    if as_text(&rest[..end]).trim().is_empty() {
                        break;
                    }
                }
            }
            "FIELD" => {
                let arrays = r.count(at, f.get(2), "the number of arrays")?;
                for _ in 0..arrays {
                    let (aat, g) = r
                        .line()
                        .ok_or_else(|| r.err(r.pos, "file ends inside FIELD"))?;
                    let comps = r.count(aat, g.get(1), "the number of components")?;
                    let n = r.count(aat, g.get(2), "the number of tuples")?;
                    let ty = g.get(3).copied().unwrap_or("");
                    let v = r.values(comps.saturating_mul(n), ty, g[0])?;
                    keep_physical(&mut physical, g[0], comps, tuples.1, v, aat);
                }
            }
            "SCALARS" => {
                let name = f.get(1).copied().unwrap_or("");
                let ty = f.get(2).copied().unwrap_or("");
                let comps = f.get(3).and_then(|c| c.parse().ok()).unwrap_or(1u64);
                let save = r.pos;
                if !r
                    .line()
                    .is_some_and(|(_, g)| g[0].eq_ignore_ascii_case("LOOKUP_TABLE"))
                {
                    r.pos = save;
                }
                let v = r.values(comps.saturating_mul(tuples.0), ty, name)?;
                keep_physical(&mut physical, name, comps, tuples.1, v, at);
            }
            "VECTORS" | "NORMALS" => {
                let ty = f.get(2).copied().unwrap_or("");
                r.values(tuples.0.saturating_mul(3), ty, &key)?;
            }
            other => {
                return Err(r.err(at, format!("unknown keyword {}", shown(other))));
            }
        }
    }
    let offsets = offsets.ok_or_else(|| MeshIoError::NoTetrahedra {
        file: file.to_owned(),
        ignored: " (no CELLS section)".into(),
    })?;
    let (types, types_at) =
        types.ok_or_else(|| r.err(r.pos, "the file has CELLS but no CELL_TYPES"))?;
    let (offsets, cells_at) = offsets;
    let mut starts = Vec::with_capacity(offsets.len());
    for w in offsets.windows(2) {
        if !(0 <= w[0] && w[0] <= w[1] && w[1] as usize <= connectivity.len()) {
            return Err(r.err(
                cells_at,
                format!("OFFSETS {} .. {} out of order or range", w[0], w[1]),
            ));
        }
        starts.push(w[0] as usize);
    }
    starts.extend(offsets.last().map(|&o| o as usize));
    let tags = match physical {
        Some((_, v, at)) => {
            let tags = v.iter().map(|&x| {
                physical_tag(x)
                    .ok_or_else(|| r.err(at, format!("physical tag {x} is not a 32-bit integer")))
            });
            Some((tags.collect::<Result<Vec<i32>, _>>()?, Location::Byte(at)))
        }
        None => None,
    };
    add_cell_lists(
        &mut b,
        file,
        CellLists {
            types: &types,
            types_at: Location::Byte(types_at),
            offsets: &starts,
            connectivity: &connectivity,
            physical: tags.as_ref().map(|(t, at)| (t.as_slice(), *at)),
        },
        |_| Location::Byte(types_at),
    )?;
    b.finish()
}

/// Keeps a one-component cell array named as physical tags, the most
/// preferred name first.
fn keep_physical(
    kept: &mut Option<(usize, Vec<f64>, usize)>,
    name: &str,
    comps: u64,
    cell: bool,
    values: Vec<f64>,
    at: usize,
) {
    let Some(rank) = PHYSICAL_NAMES.iter().position(|n| *n == name) else {
        return;
    };
    if cell && comps == 1 && kept.as_ref().is_none_or(|(r, ..)| rank < *r) {
        *kept = Some((rank, values, at));
    }
}
