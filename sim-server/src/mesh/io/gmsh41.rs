//! Gmsh MSH 4.1, ASCII and binary, by one reader over two inputs.
//!
//! The two encodings hold the same values in the same order (section markers
//! are text lines in both); only how a value is stored differs. So the
//! section logic is written once against `Input` (`gmsh41_input.rs`); the ASCII input also checks
//! that every record is exactly one line, which is what lets it say
//! "expected 4 node tags for a tetrahedron, found 3" at the right line.
//!
//! Physical tags live on entities: an element block names its volume entity,
//! and `$Entities` gives that entity's physical groups.

use super::error::{Location, MeshIoError};
use super::gmsh::{TET4, TRI3, expect_end, gmsh_type, unsupported};
use super::gmsh41_input::{Ascii, Binary, Input, expect_marker};
use super::text::{Lines, perr, shown};
use super::{Builder, ImportedMesh, NodeMap};
use std::collections::HashMap;

/// Parses the body of an MSH 4.1 file; `lines` has just read the version line.
pub(super) fn parse(
    file: &str,
    bytes: &[u8],
    mut lines: Lines,
    binary: bool,
    data_size: &str,
    header_line: usize,
) -> Result<ImportedMesh, MeshIoError> {
    if !binary {
        expect_end(file, &mut lines, "$EndMeshFormat")?;
        return body(file, Ascii::new(file, lines, header_line));
    }
    if data_size != "8" {
        return Err(perr(
            file,
            Location::Line(header_line),
            format!(
                "data-size {} is not supported (only 8-byte size_t)",
                shown(data_size)
            ),
        ));
    }
    // The int 1 written in the writer's byte order tells the endianness.
    let mut input = Binary::after_mark(file, bytes, lines.pos())?;
    expect_marker(file, &mut input, "$EndMeshFormat")?;
    body(file, input)
}

/// The sections after `$EndMeshFormat`.
fn body(file: &str, mut input: impl Input) -> Result<ImportedMesh, MeshIoError> {
    let mut b = Builder::new(file, "element");
    let mut nodes = NodeMap::new();
    let mut physical = EntityPhysical::default();
    while let Some((at, marker)) = input.marker()? {
        match marker.as_str() {
            "$Entities" => entities(&mut input, &mut physical, &mut b)?,
            "$Nodes" => node_blocks(file, &mut input, &mut nodes, &mut b)?,
            "$Elements" => element_blocks(file, &mut input, &nodes, &physical, &mut b)?,
            m if m.starts_with("$End") => {
                return Err(perr(file, at, format!("unexpected {}", shown(m))));
            }
            m if m.starts_with('$') => {
                input.skip_section(&m[1..], at)?;
                continue;
            }
            m => {
                return Err(perr(
                    file,
                    at,
                    format!("expected a section such as $Nodes, found {}", shown(m)),
                ));
            }
        }
        expect_marker(file, &mut input, &format!("$End{}", &marker[1..]))?;
    }
    b.finish()
}

/// The first physical tag of each volume and surface entity.
#[derive(Default)]
struct EntityPhysical {
    volumes: HashMap<i32, i32>,
    surfaces: HashMap<i32, i32>,
}

/// `$Entities`: keeps the first physical tag of each volume and surface.
fn entities(
    input: &mut impl Input,
    physical: &mut EntityPhysical,
    b: &mut Builder,
) -> Result<(), MeshIoError> {
    input.record("the entity counts")?;
    let mut counts = [0u64; 4];
    for (c, what) in counts
        .iter_mut()
        .zip(["numPoints", "numCurves", "numSurfaces", "numVolumes"])
    {
        *c = input.size(what)?;
    }
    input.end_record()?;
    for (dim, &count) in counts.iter().enumerate() {
        for _ in 0..count {
            input.record("an entity")?;
            let tag = input.int("an entity tag")?;
            let coords = if dim == 0 { 3 } else { 6 };
            for _ in 0..coords {
                input.float("a bounding-box coordinate")?;
            }
            let n_physical = input.size("numPhysicalTags")?;
            let mut first = None;
            for _ in 0..n_physical {
                let p = input.int("a physical tag")?;
                first.get_or_insert(p);
            }
            if dim > 0 {
                let n_bounding = input.size("the number of bounding entities")?;
                for _ in 0..n_bounding {
                    input.int("a bounding entity tag")?;
                }
            }
            input.end_record()?;
            if dim >= 2 {
                let (what, map) = if dim == 3 {
                    ("volume", &mut physical.volumes)
                } else {
                    ("surface", &mut physical.surfaces)
                };
                if n_physical > 1 {
                    b.warn(format!(
                        "{what} {tag} is in {n_physical} physical groups; its elements get the first, {}",
                        first.unwrap_or(0)
                    ));
                }
                map.insert(tag, first.unwrap_or(0));
            }
        }
    }
    Ok(())
}

/// `$Nodes`: blocks of tags, then coordinates.
fn node_blocks(
    file: &str,
    input: &mut impl Input,
    nodes: &mut NodeMap,
    b: &mut Builder,
) -> Result<(), MeshIoError> {
    let at = input.at();
    input.record("the node counts")?;
    let blocks = input.size("numEntityBlocks")?;
    let total = input.size("numNodes")?;
    input.size("minNodeTag")?;
    input.size("maxNodeTag")?;
    input.end_record()?;
    b.reserve_vertices(total, input.remaining() / 8);
    let before = b.vertex_count();
    for _ in 0..blocks {
        input.record("a node block header")?;
        let dim = input.int("entityDim")?;
        input.int("entityTag")?;
        let parametric = input.int("parametric")?;
        let n = input.size("numNodesInBlock")?;
        input.end_record()?;
        let params = match (parametric, dim) {
            (0, _) => 0,
            (1, 0..=3) => dim as usize,
            _ => {
                return Err(perr(
                    file,
                    input.at(),
                    format!("bad node block: entityDim {dim}, parametric {parametric}"),
                ));
            }
        };
        let cap = usize::try_from(n)
            .unwrap_or(usize::MAX)
            .min(input.remaining() / 8);
        let mut tags = Vec::with_capacity(cap);
        for _ in 0..n {
            input.record("a node tag")?;
            tags.push(input.size("a node tag")?);
            input.end_record()?;
        }
        for tag in tags {
            input.record("node coordinates")?;
            let at = input.at();
            let p = [input.float("x")?, input.float("y")?, input.float("z")?];
            for _ in 0..params {
                input.float("a parametric coordinate")?;
            }
            input.end_record()?;
            let index = b.vertex_count() as u32;
            b.vertex(p, at, "node", tag)?;
            if !nodes.insert(tag, index) {
                return Err(perr(file, at, format!("node {tag} is defined twice")));
            }
        }
    }
    let found = b.vertex_count() - before;
    if found as u64 != total {
        return Err(perr(
            file,
            at,
            format!("$Nodes declares {total} nodes but its blocks hold {found}"),
        ));
    }
    Ok(())
}

/// Reads `n` element records of `K` nodes each (`what`: "a tetrahedron"),
/// handing each one's vertices, tag and place to `add`.
fn read_elements<const K: usize>(
    file: &str,
    input: &mut impl Input,
    nodes: &NodeMap,
    n: u64,
    what: &str,
    mut add: impl FnMut([u32; K], u64, Location),
) -> Result<(), MeshIoError> {
    for _ in 0..n {
        let fields = input.record(what)?;
        let at = input.at();
        if let Some(f) = fields.filter(|&f| f != K + 1) {
            return Err(perr(
                file,
                at,
                format!(
                    "expected {K} node tags for {what}, found {}",
                    f.saturating_sub(1)
                ),
            ));
        }
        let tag = input.size("an element tag")?;
        let mut v = [0u32; K];
        for slot in &mut v {
            let nt = input.size("a node tag")?;
            *slot = nodes.get(nt).ok_or_else(|| {
                perr(
                    file,
                    at,
                    format!("element {tag} references node {nt}, which is not in $Nodes"),
                )
            })?;
        }
        input.end_record()?;
        add(v, tag, at);
    }
    Ok(())
}

/// `$Elements`: blocks of one element type on one entity.
fn element_blocks(
    file: &str,
    input: &mut impl Input,
    nodes: &NodeMap,
    physical: &EntityPhysical,
    b: &mut Builder,
) -> Result<(), MeshIoError> {
    let at = input.at();
    input.record("the element counts")?;
    let blocks = input.size("numEntityBlocks")?;
    let total = input.size("numElements")?;
    input.size("minElementTag")?;
    input.size("maxElementTag")?;
    input.end_record()?;
    b.reserve_tets(total, input.remaining() / 16);
    let mut found = 0u64;
    for _ in 0..blocks {
        input.record("an element block header")?;
        let block_at = input.at();
        let dim = input.int("entityDim")?;
        let entity = input.int("entityTag")?;
        let t = input.int("elementType")?;
        let n = input.size("numElementsInBlock")?;
        input.end_record()?;
        found = found.saturating_add(n);
        let kind = gmsh_type(t.into()).ok_or_else(|| unsupported(file, block_at, t.into()))?;
        // Triangles of a physical surface are kept for surface selections.
        let surface = physical.surfaces.get(&entity).copied().unwrap_or(0);
        if i64::from(t) == TRI3 && dim == 2 && surface != 0 {
            read_elements(file, input, nodes, n, "a triangle", |v: [u32; 3], _, _| {
                b.triangle(v, surface)
            })?;
            continue;
        }
        if kind.dim < 3 && dim < 3 {
            input.skip_records(n, 1 + kind.nodes, kind.plural)?;
            b.ignore(kind.plural, usize::try_from(n).unwrap_or(usize::MAX));
            continue;
        }
        if i64::from(t) != TET4 {
            return Err(unsupported(file, block_at, t.into()));
        }
        let volume = physical.volumes.get(&entity).copied().unwrap_or(0);
        read_elements(file, input, nodes, n, "a tetrahedron", |v, tag, at| {
            b.tet(v, volume, tag, at)
        })?;
    }
    if found != total {
        return Err(perr(
            file,
            at,
            format!("$Elements declares {total} elements but its blocks hold {found}"),
        ));
    }
    Ok(())
}
