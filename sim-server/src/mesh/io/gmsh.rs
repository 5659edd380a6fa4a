//! Gmsh MSH: the `$MeshFormat` header that tells the version, the element type
//! table, and the MSH 2.2 ASCII reader (MSH 4.1 is in `gmsh41.rs`, MSH 1 and
//! binary MSH 2.2 in `gmsh_legacy.rs`).
//!
//! MSH 2.2 is one record per line: `$Nodes` holds `tag x y z`, `$Elements`
//! holds `tag type ntags tag... node...`, whose first tag is the physical group.

use super::error::{Location, MeshIoError};
use super::text::{Line, Lines, parse_f64, parse_i64, parse_u64, perr, shown};
use super::{Builder, ImportedMesh, NodeMap, gmsh_legacy, gmsh41};

/// The Gmsh element type 4: the 4-node tetrahedron.
pub(super) const TET4: i64 = 4;
/// Gmsh's 3-node triangle.
pub(super) const TRI3: i64 = 2;

/// What the importer knows about a Gmsh element type.
#[derive(Clone, Copy, Debug)]
pub(super) struct GmshType {
    /// Number of nodes.
    pub nodes: usize,
    /// Topological dimension.
    pub dim: u8,
    /// Name in messages, plural (for the "ignored" warning).
    pub plural: &'static str,
}

/// The element types of the MSH reference (those a mesher writes in practice).
/// Their node counts are needed to skip them in binary files.
const TYPES: &[(i64, usize, u8, &str)] = &[
    (15, 1, 0, "points"),
    (1, 2, 1, "lines"),
    (8, 3, 1, "3-node lines"),
    (26, 4, 1, "4-node lines"),
    (27, 5, 1, "5-node lines"),
    (28, 6, 1, "6-node lines"),
    (2, 3, 2, "triangles"),
    (9, 6, 2, "6-node triangles"),
    (20, 9, 2, "9-node triangles"),
    (21, 10, 2, "10-node triangles"),
    (22, 12, 2, "12-node triangles"),
    (23, 15, 2, "15-node triangles"),
    (24, 15, 2, "15-node triangles"),
    (25, 21, 2, "21-node triangles"),
    (3, 4, 2, "quadrangles"),
    (10, 9, 2, "9-node quadrangles"),
    (16, 8, 2, "8-node quadrangles"),
    (4, 4, 3, "tetrahedra"),
    (11, 10, 3, "10-node tetrahedra"),
    (29, 20, 3, "20-node tetrahedra"),
    (30, 35, 3, "35-node tetrahedra"),
    (31, 56, 3, "56-node tetrahedra"),
    (5, 8, 3, "hexahedra"),
    (12, 27, 3, "27-node hexahedra"),
    (17, 20, 3, "20-node hexahedra"),
    (92, 64, 3, "64-node hexahedra"),
    (93, 125, 3, "125-node hexahedra"),
    (6, 6, 3, "prisms"),
    (13, 18, 3, "18-node prisms"),
    (18, 15, 3, "15-node prisms"),
    (7, 5, 3, "pyramids"),
    (14, 14, 3, "14-node pyramids"),
    (19, 13, 3, "13-node pyramids"),
];

/// Looks up an element type.
pub(super) fn gmsh_type(t: i64) -> Option<GmshType> {
    TYPES
        .iter()
        .find(|(id, ..)| *id == t)
        .map(|&(_, nodes, dim, plural)| GmshType { nodes, dim, plural })
}

/// The refusal for a volume element that is not a 4-node tetrahedron, or for
/// a type the table does not know.
pub(super) fn unsupported(file: &str, at: Location, t: i64) -> MeshIoError {
    let element = match gmsh_type(t) {
        Some(k) => format!("{} (Gmsh type {t})", k.plural),
        None => format!("of unknown Gmsh type {t}"),
    };
    MeshIoError::UnsupportedElement {
        file: file.to_owned(),
        at,
        element,
    }
}

/// Parses a Gmsh file of any supported version.
pub(super) fn parse(file: &str, bytes: &[u8]) -> Result<ImportedMesh, MeshIoError> {
    let mut lines = Lines::new(bytes);
    let first = lines
        .next_line()
        .ok_or_else(|| perr(file, Location::Line(1), "empty file, expected $MeshFormat"))?;
    if first.text.trim() == "$NOD" {
        // MSH 1 (Gmsh before 2.0; most of SOFA's meshes) has no header.
        return gmsh_legacy::parse1(file, lines, first);
    }
    if first.text.trim() != "$MeshFormat" {
        return Err(perr(
            file,
            first.at(),
            format!("expected $MeshFormat, found {}", shown(first.text.trim())),
        ));
    }
    let header = lines.next_line().ok_or_else(|| {
        perr(
            file,
            Location::Line(first.no + 1),
            "file ends in $MeshFormat",
        )
    })?;
    let f: Vec<&str> = header.fields().collect();
    let [version, file_type, data_size] = f[..] else {
        return Err(perr(
            file,
            header.at(),
            format!(
                "expected 'version file-type data-size', found {}",
                shown(header.text)
            ),
        ));
    };
    let binary = match file_type {
        "0" => false,
        "1" => true,
        _ => {
            return Err(perr(
                file,
                header.at(),
                format!(
                    "file-type must be 0 (ASCII) or 1 (binary), found {}",
                    shown(file_type)
                ),
            ));
        }
    };
    match version {
        "4.1" => gmsh41::parse(file, bytes, lines, binary, data_size, header.no),
        "2.2" | "2.1" | "2" | "2.0" if !binary => {
            expect_end(file, &mut lines, "$EndMeshFormat")?;
            parse22(file, lines)
        }
        "2.2" | "2.1" | "2" | "2.0" => {
            gmsh_legacy::parse22_binary(file, bytes, lines.pos(), data_size, header.no)
        }
        _ => Err(perr(
            file,
            header.at(),
            format!(
                "MSH version {} is not supported (4.1, 2.2 and 1 are)",
                shown(version)
            ),
        )),
    }
}

/// Reads the next line and checks that it is the marker `end`.
pub(super) fn expect_end(file: &str, lines: &mut Lines, end: &str) -> Result<(), MeshIoError> {
    match lines.next_line() {
        Some(l) if l.text.trim() == end => Ok(()),
        Some(l) => Err(perr(
            file,
            l.at(),
            format!("expected {end}, found {}", shown(l.text.trim())),
        )),
        None => Err(perr(
            file,
            Location::Line(lines.line_no() + 1),
            format!("file ends before {end}"),
        )),
    }
}

/// Skips a section we do not need, up to its `$End...` marker.
pub(super) fn skip_section(file: &str, lines: &mut Lines, start: &Line) -> Result<(), MeshIoError> {
    let end = format!("$End{}", start.text.trim().trim_start_matches('$'));
    while let Some(l) = lines.next_line() {
        if l.text.trim() == end {
            return Ok(());
        }
    }
    Err(perr(
        file,
        start.at(),
        format!("section {} has no {end}", shown(start.text.trim())),
    ))
}

/// Reads a section's record count line.
pub(super) fn count_line(
    file: &str,
    lines: &mut Lines,
    what: &str,
) -> Result<(u64, usize), MeshIoError> {
    let l = lines.next_line().ok_or_else(|| {
        perr(
            file,
            Location::Line(lines.line_no() + 1),
            format!("file ends before the number of {what}"),
        )
    })?;
    let mut f = l.fields();
    match (f.next().and_then(parse_u64), f.next()) {
        (Some(n), None) => Ok((n, l.no)),
        _ => Err(perr(
            file,
            l.at(),
            format!("expected the number of {what}, found {}", shown(l.text)),
        )),
    }
}

/// The MSH 2.x ASCII body, after `$EndMeshFormat`.
fn parse22(file: &str, mut lines: Lines) -> Result<ImportedMesh, MeshIoError> {
    let mut b = Builder::new(file, "element");
    let mut nodes = NodeMap::new();
    while let Some(section) = lines.next_line() {
        match section.text.trim() {
            "$Nodes" => {
                let (n, _) = count_line(file, &mut lines, "nodes")?;
                b.reserve_vertices(n, lines.remaining() / 8);
                for k in 0..n {
                    let l = record(file, &mut lines, "$EndNodes", "nodes", n, k)?;
                    node_line(file, &l, &mut nodes, &mut b)?;
                }
                expect_end(file, &mut lines, "$EndNodes")?;
            }
            "$Elements" => {
                let (n, _) = count_line(file, &mut lines, "elements")?;
                b.reserve_tets(n, lines.remaining() / 16);
                for k in 0..n {
                    let l = record(file, &mut lines, "$EndElements", "elements", n, k)?;
                    element22(file, &l, &nodes, &mut b)?;
                }
                expect_end(file, &mut lines, "$EndElements")?;
            }
            s if s.starts_with("$End") => {
                return Err(perr(file, section.at(), format!("unexpected {}", shown(s))));
            }
            s if s.starts_with('$') => skip_section(file, &mut lines, &section)?,
            _ => {
                return Err(perr(
                    file,
                    section.at(),
                    format!(
                        "expected a section such as $Nodes, found {}",
                        shown(section.text)
                    ),
                ));
            }
        }
    }
    b.finish()
}

/// One node line of an MSH 1 or 2 ASCII file: `tag x y z`.
pub(super) fn node_line(
    file: &str,
    l: &Line,
    nodes: &mut NodeMap,
    b: &mut Builder,
) -> Result<(), MeshIoError> {
    let f: Vec<&str> = l.fields().collect();
    let parsed = match f[..] {
        [tag, x, y, z] => parse_u64(tag).zip(
            [x, y, z]
                .iter()
                .map(|s| parse_f64(s))
                .collect::<Option<Vec<f64>>>(),
        ),
        _ => None,
    };
    let Some((tag, p)) = parsed else {
        return Err(perr(
            file,
            l.at(),
            format!("expected a node 'tag x y z', found {}", shown(l.text)),
        ));
    };
    node(file, l.at(), tag, [p[0], p[1], p[2]], nodes, b)
}

/// Node `tag` at `p` becomes the next vertex.
pub(super) fn node(
    file: &str,
    at: Location,
    tag: u64,
    p: [f64; 3],
    nodes: &mut NodeMap,
    b: &mut Builder,
) -> Result<(), MeshIoError> {
    let index = b.vertex_count() as u32;
    b.vertex(p, at, "node", tag)?;
    if !nodes.insert(tag, index) {
        return Err(perr(file, at, format!("node {tag} is defined twice")));
    }
    Ok(())
}

/// The `k`-th of `n` records of a section, refusing the section's end marker
/// (which means the count in the header was too large).
pub(super) fn record<'a>(
    file: &str,
    lines: &mut Lines<'a>,
    end: &str,
    what: &str,
    n: u64,
    k: u64,
) -> Result<Line<'a>, MeshIoError> {
    match lines.next_line() {
        Some(l) if l.text.trim_start().starts_with('$') => Err(perr(
            file,
            l.at(),
            format!(
                "the section declares {n} {what} but {} ends after {k}",
                end.trim_start_matches("$End")
            ),
        )),
        Some(l) => Ok(l),
        None => Err(perr(
            file,
            Location::Line(lines.line_no() + 1),
            format!("file ends after {k} of {n} {what}"),
        )),
    }
}

/// One MSH 2 element line: `tag type ntags tag... node...`.
fn element22(file: &str, l: &Line, nodes: &NodeMap, b: &mut Builder) -> Result<(), MeshIoError> {
    let f: Vec<&str> = l.fields().collect();
    let ints: Option<Vec<i64>> = f.iter().map(|s| parse_i64(s)).collect();
    let Some(ints) = ints else {
        let bad = f
            .iter()
            .find(|s| parse_i64(s).is_none())
            .copied()
            .unwrap_or("");
        return Err(perr(
            file,
            l.at(),
            format!("expected integers in an element line, found {}", shown(bad)),
        ));
    };
    let [tag, t, ntags, rest @ ..] = &ints[..] else {
        return Err(perr(
            file,
            l.at(),
            "expected an element 'tag type ntags tags... nodes...'",
        ));
    };
    let ntags = usize::try_from(*ntags)
        .ok()
        .filter(|n| *n <= rest.len())
        .ok_or_else(|| {
            perr(
                file,
                l.at(),
                format!(
                    "element {tag} declares {ntags} tags but the line has {} more values",
                    rest.len()
                ),
            )
        })?;
    let (tags, node_tags) = rest.split_at(ntags);
    element(file, l.at(), [*tag, *t], tags, node_tags, nodes, b)
}

/// One element of an MSH 1 or 2 file, ASCII or binary: `[tag, type]`, its
/// tags (the first is the physical group) and its node tags. A tetrahedron
/// becomes one; lower-dimensional elements are counted as ignored; other
/// volume elements are refused.
pub(super) fn element(
    file: &str,
    at: Location,
    [tag, t]: [i64; 2],
    tags: &[i64],
    node_tags: &[i64],
    nodes: &NodeMap,
    b: &mut Builder,
) -> Result<(), MeshIoError> {
    let kind = gmsh_type(t).ok_or_else(|| unsupported(file, at, t))?;
    // Read only for the elements kept: a line or point with an odd tag is
    // skipped as before.
    let physical = || {
        tags.first().map_or(Ok(0), |&p| {
            i32::try_from(p)
                .map_err(|_| perr(file, at, format!("physical tag {p} is out of range")))
        })
    };
    if t == TRI3 && physical()? != 0 {
        // A triangle of a physical surface: kept for surface selections.
        let v = vertices::<3>(file, at, tag, node_tags, nodes, "a triangle")?;
        b.triangle(v, physical()?);
        return Ok(());
    }
    if kind.dim < 3 {
        b.ignore(kind.plural, 1);
        return Ok(());
    }
    if t != TET4 {
        return Err(unsupported(file, at, t));
    }
    let v = vertices::<4>(file, at, tag, node_tags, nodes, "a tetrahedron")?;
    b.tet(v, physical()?, tag as u64, at);
    Ok(())
}

/// The vertices of element `tag`'s `K` node tags (`what`: "a tetrahedron").
fn vertices<const K: usize>(
    file: &str,
    at: Location,
    tag: i64,
    node_tags: &[i64],
    nodes: &NodeMap,
    what: &str,
) -> Result<[u32; K], MeshIoError> {
    if node_tags.len() != K {
        return Err(perr(
            file,
            at,
            format!(
                "expected {K} node tags for {what}, found {}",
                node_tags.len()
            ),
        ));
    }
    let mut v = [0u32; K];
    for (slot, &nt) in v.iter_mut().zip(node_tags) {
        *slot = u64::try_from(nt)
            .ok()
            .and_then(|nt| nodes.get(nt))
            .ok_or_else(|| {
                perr(
                    file,
                    at,
                    format!("element {tag} references node {nt}, which is not in $Nodes"),
                )
            })?;
    }
    Ok(v)
}
