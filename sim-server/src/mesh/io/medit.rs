//! medit / INRIA `.mesh` (ASCII): keyword sections, each a count and that many
//! fixed-size entries, free-form across lines, `#` comments. Vertices and
//! element indices are 1-based; every entry ends with a reference number,
//! which for tetrahedra is the physical tag.
//!
//! Also a small writer, so that meshes can go to tools that read medit (mmg,
//! tetgen) and so that the reader has a round-trip test.

use super::error::{Location, MeshIoError};
use super::text::{Token, Tokens, parse_f64, parse_i64, parse_u64, perr, shown};
use super::{Builder, ImportedMesh};
use crate::ids::VertexId;
use crate::math::Vec3;
use std::io::Write;
use std::path::Path;

/// What a section holds: values per entry, and what to do with it.
#[derive(Clone, Copy)]
enum Section {
    Vertices,
    Tetrahedra,
    /// Kept for surface selections when their reference is not 0.
    Triangles,
    /// Lower-dimensional elements (plural noun for the warning) or annotations
    /// such as corners and ridges (empty noun: not elements, no warning), skipped.
    Skip(usize, &'static str),
    /// Vectors of `dim` values (normals, tangents), skipped.
    SkipVectors,
    /// Volume elements other than linear tetrahedra.
    Unsupported(&'static str),
}

/// The section keywords of the medit format.
fn section(keyword: &str) -> Option<Section> {
    use Section::*;
    Some(match keyword {
        "Vertices" => Vertices,
        "Tetrahedra" => Tetrahedra,
        "Edges" => Skip(3, "edges"),
        "Triangles" => Triangles,
        "Quadrilaterals" => Skip(5, "quadrilaterals"),
        "EdgesP2" => Skip(4, "quadratic edges"),
        "TrianglesP2" => Skip(7, "quadratic triangles"),
        "QuadrilateralsQ2" => Skip(10, "quadratic quadrilaterals"),
        "Corners"
        | "Ridges"
        | "RequiredVertices"
        | "RequiredEdges"
        | "RequiredTriangles"
        | "RequiredQuadrilaterals"
        | "RequiredTetrahedra" => Skip(1, ""),
        "NormalAtVertices" | "TangentAtVertices" => Skip(2, ""),
        "NormalAtTriangleVertices" | "TangentAtEdges" => Skip(3, ""),
        "NormalAtQuadrilateralVertices" => Skip(3, ""),
        "Normals" | "Tangents" => SkipVectors,
        "Hexahedra" => Unsupported("hexahedra"),
        "Prisms" => Unsupported("prisms"),
        "Pyramids" => Unsupported("pyramids"),
        "TetrahedraP2" => Unsupported("quadratic tetrahedra (TetrahedraP2)"),
        "HexahedraQ2" => Unsupported("quadratic hexahedra (HexahedraQ2)"),
        _ => return None,
    })
}

/// Parses a medit file.
pub(super) fn parse<'a>(file: &str, bytes: &'a [u8]) -> Result<ImportedMesh, MeshIoError> {
    let mut t = Tokens::new(bytes, 0, 1, Some(b'#'));
    let mut b = Builder::new(file, "tetrahedron");
    let mut dim: Option<u64> = None;
    let next = |t: &mut Tokens<'a>, what: &str| next_token(t, file, what);
    let count = |t: &mut Tokens<'a>, what: &str| -> Result<u64, MeshIoError> {
        let k = next_token(t, file, what)?;
        parse_u64(k.text).ok_or_else(|| {
            perr(
                file,
                k.at(),
                format!("expected {what}, found {}", shown(k.text)),
            )
        })
    };
    let mut tet_number = 0u64;
    while let Some(k) = t.next_token() {
        match k.text {
            "MeshVersionFormatted" => {
                let v = count(&mut t, "the format version")?;
                if !(1..=4).contains(&v) {
                    return Err(perr(
                        file,
                        k.at(),
                        format!("unknown MeshVersionFormatted {v}"),
                    ));
                }
            }
            "Dimension" => {
                let d = count(&mut t, "the dimension")?;
                if d != 3 {
                    return Err(perr(
                        file,
                        k.at(),
                        format!("only 3D meshes can be imported, found Dimension {d}"),
                    ));
                }
                dim = Some(d);
            }
            "End" => break,
            "Identifier" | "Geometry" => {
                next(&mut t, "a name")?;
            }
            kw => {
                let s = section(kw).ok_or_else(|| {
                    perr(file, k.at(), format!("unknown medit keyword {}", shown(kw)))
                })?;
                let n = count(&mut t, &format!("the number of {kw}"))?;
                match s {
                    Section::Vertices => {
                        b.reserve_vertices(n, t.remaining() / 8);
                        for i in 1..=n {
                            let x = next(&mut t, "a vertex")?;
                            let at = x.at();
                            let mut p = [0.0; 3];
                            for (c, tok) in p.iter_mut().zip([Some(x), None, None]) {
                                let tok = match tok {
                                    Some(tok) => tok,
                                    None => next(&mut t, "a vertex coordinate")?,
                                };
                                *c = parse_f64(tok.text).ok_or_else(|| {
                                    perr(
                                        file,
                                        tok.at(),
                                        format!(
                                            "expected a coordinate of vertex {i}, found {}",
                                            shown(tok.text)
                                        ),
                                    )
                                })?;
                            }
                            let r = next(&mut t, "a vertex reference")?;
                            parse_i64(r.text).ok_or_else(|| {
                                perr(
                                    file,
                                    r.at(),
                                    format!(
                                        "expected the reference of vertex {i}, found {}",
                                        shown(r.text)
                                    ),
                                )
                            })?;
                            b.vertex(p, at, "vertex", i)?;
                        }
                    }
                    Section::Tetrahedra => {
                        b.reserve_tets(n, t.remaining() / 10);
                        let nv = b.vertex_count();
                        for _ in 0..n {
                            tet_number += 1;
                            let (v, physical, at) =
                                element::<4>(&mut t, file, nv, "tetrahedron", tet_number)?;
                            b.tet(v, physical, tet_number, at);
                        }
                    }
                    Section::Triangles => {
                        let nv = b.vertex_count();
                        for k in 1..=n {
                            let (v, physical, _) = element::<3>(&mut t, file, nv, "triangle", k)?;
                            b.triangle(v, physical);
                        }
                    }
                    Section::Skip(per, plural) => {
                        skip(&mut t, file, n.saturating_mul(per as u64), kw)?;
                        if !plural.is_empty() {
                            b.ignore(plural, usize::try_from(n).unwrap_or(usize::MAX));
                        }
                    }
                    Section::SkipVectors => {
                        skip(&mut t, file, n.saturating_mul(dim.unwrap_or(3)), kw)?
                    }
                    Section::Unsupported(element) => {
                        if n > 0 {
                            return Err(MeshIoError::UnsupportedElement {
                                file: file.to_owned(),
                                at: k.at(),
                                element: element.to_owned(),
                            });
                        }
                    }
                }
            }
        }
    }
    b.finish()
}

/// One element of `K` 1-based vertex indices and a reference (`noun`
/// `number` in messages): the 0-based vertices, the reference as a physical
/// tag and the place of its first index.
fn element<const K: usize>(
    t: &mut Tokens,
    file: &str,
    nv: usize,
    noun: &str,
    number: u64,
) -> Result<([u32; K], i32, Location), MeshIoError> {
    let mut int = |what: &str| -> Result<(i64, Location), MeshIoError> {
        let tok = next_token(t, file, what)?;
        parse_i64(tok.text).map(|v| (v, tok.at())).ok_or_else(|| {
            perr(
                file,
                tok.at(),
                format!(
                    "expected {what} of {noun} {number}, found {}",
                    shown(tok.text)
                ),
            )
        })
    };
    let mut v = [0u32; K];
    let mut first = None;
    for slot in &mut v {
        let (value, at) = int("a vertex index")?;
        first.get_or_insert(at);
        *slot = usize::try_from(value)
            .ok()
            .filter(|&i| (1..=nv).contains(&i))
            .map(|i| (i - 1) as u32)
            .ok_or_else(|| {
                perr(file, at, format!("{noun} {number} references vertex {value}, but there are {nv} vertices (Vertices must come first)"))
            })?;
    }
    let (value, at) = int("the reference")?;
    let physical = i32::try_from(value)
        .map_err(|_| perr(file, at, format!("reference {value} is out of range")))?;
    Ok((v, physical, first.unwrap_or(at)))
}

/// The next token, or an error at the line where the file ends.
fn next_token<'a>(t: &mut Tokens<'a>, file: &str, what: &str) -> Result<Token<'a>, MeshIoError> {
    let line = t.line();
    t.next_token().ok_or_else(|| {
        perr(
            file,
            Location::Line(line),
            format!("file ends before {what}"),
        )
    })
}

/// Skips `count` numeric values of a section.
fn skip(t: &mut Tokens, file: &str, count: u64, kw: &str) -> Result<(), MeshIoError> {
    for _ in 0..count {
        let line = t.line();
        let tok = t
            .next_token()
            .ok_or_else(|| perr(file, Location::Line(line), format!("file ends inside {kw}")))?;
        if parse_f64(tok.text).is_none() {
            return Err(perr(
                file,
                tok.at(),
                format!("expected a number in {kw}, found {}", shown(tok.text)),
            ));
        }
    }
    Ok(())
}

/// Writes a medit `.mesh` file (double precision, `MeshVersionFormatted 2`):
/// vertices with reference 0, tetrahedra with `refs` (one per tetrahedron, or
/// empty for all 0).
pub fn write_medit(
    path: &Path,
    positions_m: &[Vec3],
    tets: &[[VertexId; 4]],
    refs: &[i32],
) -> Result<(), MeshIoError> {
    let file = path.display().to_string();
    super::export::check_indices(&file, positions_m.len(), tets.iter().flatten())?;
    if !refs.is_empty() && refs.len() != tets.len() {
        return Err(MeshIoError::BadInput {
            file,
            message: format!("{} references for {} tetrahedra", refs.len(), tets.len()),
        });
    }
    super::export::write_with(&file, path, |w| {
        writeln!(
            w,
            "MeshVersionFormatted 2\nDimension 3\n\nVertices\n{}",
            positions_m.len()
        )?;
        for p in positions_m {
            // `{}` prints the shortest decimal that reads back to the same f64.
            writeln!(w, "{} {} {} 0", p.x, p.y, p.z)?;
        }
        writeln!(w, "\nTetrahedra\n{}", tets.len())?;
        for (i, t) in tets.iter().enumerate() {
            let r = refs.get(i).copied().unwrap_or(0);
            writeln!(
                w,
                "{} {} {} {} {r}",
                t[0].0 + 1,
                t[1].0 + 1,
                t[2].0 + 1,
                t[3].0 + 1
            )?;
        }
        writeln!(w, "\nEnd")
    })
}
