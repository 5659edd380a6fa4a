//! The older Gmsh files labs still have: MSH 1 and binary MSH 2.2.
//!
//! MSH 1 (Gmsh before 2.0; 15 of the 21 `.msh` files SOFA ships, its livers
//! among them) has no header: `$NOD` holds `tag x y z` lines up to `$ENDNOD`,
//! `$ELM` holds `tag type physical elementary node-count node...` lines up to
//! `$ENDELM`.
//!
//! Binary MSH 2.2 keeps the ASCII section markers and counts, with the
//! records in the writer's byte order (told by the int 1 after the header):
//! a node is `int tag, double x y z`; elements come in blocks headed by
//! `int type, int count, int tag-count`, each element `int tag, int tags...,
//! int nodes...`.

use super::error::{Location, MeshIoError};
use super::gmsh::{
    count_line, element, expect_end, gmsh_type, node, node_line, record, unsupported,
};
use super::gmsh41_input::{Binary, Input, expect_marker};
use super::text::{Line, Lines, parse_i64, perr, shown};
use super::{Builder, ImportedMesh, NodeMap};

/// An MSH 1 file whose first line, `first`, is `$NOD`.
pub(super) fn parse1(
    file: &str,
    mut lines: Lines,
    first: Line,
) -> Result<ImportedMesh, MeshIoError> {
    let mut b = Builder::new(file, "element");
    let mut nodes = NodeMap::new();
    let mut next = Some(first);
    while let Some(section) = next.take().or_else(|| lines.next_line()) {
        match section.text.trim() {
            "$NOD" => {
                let (n, _) = count_line(file, &mut lines, "nodes")?;
                b.reserve_vertices(n, lines.remaining() / 8);
                for k in 0..n {
                    let l = record(file, &mut lines, "$EndNOD", "nodes", n, k)?;
                    node_line(file, &l, &mut nodes, &mut b)?;
                }
                expect_end(file, &mut lines, "$ENDNOD")?;
            }
            "$ELM" => {
                let (n, _) = count_line(file, &mut lines, "elements")?;
                b.reserve_tets(n, lines.remaining() / 16);
                for k in 0..n {
                    let l = record(file, &mut lines, "$EndELM", "elements", n, k)?;
                    element1(file, &l, &nodes, &mut b)?;
                }
                expect_end(file, &mut lines, "$ENDELM")?;
            }
            s if s.to_ascii_uppercase().starts_with("$END") => {
                return Err(perr(file, section.at(), format!("unexpected {}", shown(s))));
            }
            s if s.starts_with('$') => {
                let end = format!("$END{}", s.trim_start_matches('$'));
                if !std::iter::from_fn(|| lines.next_line()).any(|l| l.text.trim() == end) {
                    return Err(perr(
                        file,
                        section.at(),
                        format!("section {} has no {end}", shown(s)),
                    ));
                }
            }
            _ => {
                return Err(perr(
                    file,
                    section.at(),
                    format!(
                        "expected a section such as $NOD or $ELM, found {}",
                        shown(section.text)
                    ),
                ));
            }
        }
    }
    b.finish()
}

/// One MSH 1 element line: `tag type physical elementary count node...`.
fn element1(file: &str, l: &Line, nodes: &NodeMap, b: &mut Builder) -> Result<(), MeshIoError> {
    let mut ints = [0i64; 32];
    let mut n = 0;
    for f in l.fields() {
        let v = parse_i64(f).ok_or_else(|| {
            perr(
                file,
                l.at(),
                format!("expected integers in an element line, found {}", shown(f)),
            )
        })?;
        if n == ints.len() {
            return Err(perr(
                file,
                l.at(),
                "an element line with more than 27 nodes",
            ));
        }
        ints[n] = v;
        n += 1;
    }
    let [tag, t, physical, elementary, count, node_tags @ ..] = &ints[..n] else {
        return Err(perr(
            file,
            l.at(),
            "expected an element 'tag type physical elementary node-count nodes...'",
        ));
    };
    if usize::try_from(*count).ok() != Some(node_tags.len()) {
        return Err(perr(
            file,
            l.at(),
            format!(
                "element {tag} declares {count} nodes but the line has {}",
                node_tags.len()
            ),
        ));
    }
    element(
        file,
        l.at(),
        [*tag, *t],
        &[*physical, *elementary],
        node_tags,
        nodes,
        b,
    )
}

/// The body of a binary MSH 2.x file from `pos` (just past the
/// `version 1 data-size` line, at the endianness mark).
pub(super) fn parse22_binary(
    file: &str,
    bytes: &[u8],
    pos: usize,
    data_size: &str,
    header_line: usize,
) -> Result<ImportedMesh, MeshIoError> {
    if data_size != "8" {
        return Err(perr(
            file,
            Location::Line(header_line),
            format!(
                "data-size {} is not supported (only 8-byte doubles)",
                shown(data_size)
            ),
        ));
    }
    let mut input = Binary::after_mark(file, bytes, pos)?;
    expect_marker(file, &mut input, "$EndMeshFormat")?;
    let mut b = Builder::new(file, "element");
    let mut nodes = NodeMap::new();
    while let Some((at, marker)) = input.marker()? {
        match marker.as_str() {
            "$Nodes" => {
                let n = count(file, &mut input, "nodes")?;
                b.reserve_vertices(n, input.remaining() / 28);
                for _ in 0..n {
                    let at = input.at();
                    let tag = input.int("a node tag")?;
                    let p = [
                        input.float("a node's x")?,
                        input.float("a node's y")?,
                        input.float("a node's z")?,
                    ];
                    let tag = u64::try_from(tag)
                        .map_err(|_| perr(file, at, format!("node tag {tag} is negative")))?;
                    node(file, at, tag, p, &mut nodes, &mut b)?;
                }
                expect_marker(file, &mut input, "$EndNodes")?;
            }
            "$Elements" => {
                let n = count(file, &mut input, "elements")?;
                b.reserve_tets(n, input.remaining() / 20);
                element_blocks(file, &mut input, n, &nodes, &mut b)?;
                expect_marker(file, &mut input, "$EndElements")?;
            }
            s if s.starts_with("$End") => {
                return Err(perr(file, at, format!("unexpected {}", shown(s))));
            }
            s if s.starts_with('$') => input.skip_section(&s[1..], at)?,
            s => {
                return Err(perr(
                    file,
                    at,
                    format!("expected a section such as $Nodes, found {}", shown(s)),
                ));
            }
        }
    }
    b.finish()
}

/// `n` binary elements in blocks of one type.
fn element_blocks(
    file: &str,
    input: &mut Binary,
    n: u64,
    nodes: &NodeMap,
    b: &mut Builder,
) -> Result<(), MeshIoError> {
    let mut read = 0u64;
    let mut tags = Vec::new();
    let mut node_tags = Vec::new();
    while read < n {
        let at = input.at();
        let t = i64::from(input.int("an element block's type")?);
        let count = input.int("an element block's count")?;
        let ntags = input.int("an element block's tag count")?;
        let kind = gmsh_type(t).ok_or_else(|| unsupported(file, at, t))?;
        let count = u64::try_from(count)
            .ok()
            .filter(|c| *c <= n - read)
            .ok_or_else(|| {
                perr(
                    file,
                    at,
                    format!(
                        "an element block of {count} elements, with {} of the {n} declared left",
                        n - read
                    ),
                )
            })?;
        let ntags = usize::try_from(ntags)
            .ok()
            .filter(|t| *t <= 64)
            .ok_or_else(|| perr(file, at, format!("{ntags} tags per element")))?;
        for _ in 0..count {
            let at = input.at();
            let tag = i64::from(input.int("an element tag")?);
            tags.clear();
            for _ in 0..ntags {
                tags.push(i64::from(input.int("an element's tag")?));
            }
            node_tags.clear();
            for _ in 0..kind.nodes {
                node_tags.push(i64::from(input.int("an element's node")?));
            }
            element(file, at, [tag, t], &tags, &node_tags, nodes, b)?;
        }
        read += count;
    }
    Ok(())
}

/// A section's count line (ASCII even in a binary file).
fn count(file: &str, input: &mut Binary, what: &str) -> Result<u64, MeshIoError> {
    match input.marker()? {
        Some((at, line)) => line.parse::<u64>().map_err(|_| {
            perr(
                file,
                at,
                format!("expected the number of {what}, found {}", shown(&line)),
            )
        }),
        None => Err(perr(
            file,
            input.at(),
            format!("file ends before the number of {what}"),
        )),
    }
}
