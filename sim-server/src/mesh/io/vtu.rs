//! VTK XML unstructured grid (`.vtu`): `DataArray`s in `ascii`, inline base64
//! `binary` or `appended` raw format, uncompressed or zlib-compressed
//! (`vtk_zlib.rs`), any number of pieces.
//!
//! The markup is scanned first and each array only located (byte ranges, or
//! offsets into the appended block, which comes last in the file); values are
//! decoded afterwards (`vtu_decode.rs`). Errors name the line of the `DataArray`, or of the bad
//! number in ASCII data.

use super::error::{Location, MeshIoError};
use super::text::{perr, shown};
use super::vtk_cells::{PHYSICAL_NAMES, add_cells};
use super::vtu_decode::{Array, Data, Decoder, Settings, integers};
use super::xml::{Event, LineIndex, Xml};
use super::{Builder, ImportedMesh};
use std::ops::Range;

/// The arrays of one `Piece`.
#[derive(Default)]
struct Piece {
    points: u64,
    cells: u64,
    at: usize,
    positions: Option<Array>,
    connectivity: Option<Array>,
    offsets: Option<Array>,
    types: Option<Array>,
    /// The physical tag array and its rank in [`PHYSICAL_NAMES`].
    physical: Option<(usize, Array)>,
}

/// Parses a VTU file.
pub(super) fn parse(file: &str, bytes: &[u8]) -> Result<ImportedMesh, MeshIoError> {
    let lines = LineIndex::new(bytes);
    let at = |offset: usize| Location::Line(lines.line(offset));
    let err = |offset: usize, m: String| perr(file, at(offset), m);
    let mut xml = Xml::new(bytes);
    let mut stack: Vec<String> = Vec::new();
    let mut settings: Option<Settings> = None;
    let mut pieces: Vec<Piece> = Vec::new();
    // The open DataArray: its attributes and where its content starts.
    let mut open: Option<(Array, usize)> = None;
    let mut appended: Option<Range<usize>> = None;
    loop {
        let event = xml.next_event().map_err(|(o, m)| err(o, m))?;
        match event {
            Event::Eof => break,
            Event::Text => {}
            Event::End { name, at: o } => {
                match stack.pop() {
                    Some(open_name) if open_name == name => {}
                    Some(open_name) => {
                        return Err(err(o, format!("</{name}> closes <{open_name}>")));
                    }
                    None => return Err(err(o, format!("</{name}> closes nothing"))),
                }
                if name == "DataArray"
                    && let Some((mut array, content)) = open.take()
                {
                    if let Data::Ascii(r) | Data::Base64(r) = &mut array.data {
                        *r = content..o;
                    }
                    store(&stack, pieces.last_mut(), array);
                }
            }
            Event::Start {
                name,
                attrs,
                empty,
                at: o,
            } => {
                let get = |key: &str| attr(&attrs, key);
                match name {
                    "VTKFile" => settings = Some(file_settings(&attrs).map_err(|m| err(o, m))?),
                    "Piece" => {
                        let count = |key: &str| -> Result<u64, MeshIoError> {
                            get(key).and_then(|v| v.trim().parse().ok()).ok_or_else(|| {
                                err(o, format!("<Piece> needs a {key} attribute with a count"))
                            })
                        };
                        pieces.push(Piece {
                            points: count("NumberOfPoints")?,
                            cells: count("NumberOfCells")?,
                            at: o,
                            ..Piece::default()
                        });
                    }
                    "DataArray" => {
                        let components = match get("NumberOfComponents") {
                            None => 1,
                            Some(v) => v.trim().parse().map_err(|_| {
                                err(
                                    o,
                                    format!(
                                        "NumberOfComponents must be a count, found {}",
                                        shown(v)
                                    ),
                                )
                            })?,
                        };
                        let data = match get("format").unwrap_or("ascii") {
                            "ascii" => Data::Ascii(0..0),
                            "binary" => Data::Base64(0..0),
                            "appended" => Data::Appended(match get("offset") {
                                None => {
                                    return Err(err(
                                        o,
                                        "an appended DataArray needs an offset attribute".into(),
                                    ));
                                }
                                Some(v) => v.trim().parse().map_err(|_| {
                                    err(
                                        o,
                                        format!(
                                            "offset must be a byte count (a non-negative integer), found {}",
                                            shown(v)
                                        ),
                                    )
                                })?,
                            }),
                            f => {
                                return Err(err(
                                    o,
                                    format!("unknown DataArray format {}", shown(f)),
                                ));
                            }
                        };
                        let array = Array {
                            name: get("Name").unwrap_or("").to_owned(),
                            ty: get("type").unwrap_or("").to_owned(),
                            components,
                            data,
                            at: o,
                        };
                        if empty {
                            store(&stack, pieces.last_mut(), array);
                        } else {
                            open = Some((array, xml.pos()));
                        }
                    }
                    "AppendedData" => {
                        // Raw bytes follow a '_' up to the closing tag, which
                        // is the last one in the file: stop scanning markup.
                        match get("encoding").unwrap_or("raw") {
                            "raw" => {}
                            e => {
                                return Err(err(
                                    o,
                                    format!(
                                        "appended data encoding {} is not supported (raw is)",
                                        shown(e)
                                    ),
                                ));
                            }
                        }
                        let rest = bytes.get(xml.pos()..).unwrap_or_default();
                        let start = rest
                            .iter()
                            .position(|&b| b == b'_')
                            .map(|k| xml.pos() + k + 1)
                            .ok_or_else(|| {
                                err(o, "<AppendedData> has no '_' before its data".into())
                            })?;
                        appended = Some(start..bytes.len());
                        break;
                    }
                    _ => {}
                }
                if !empty {
                    stack.push(name.to_owned());
                }
            }
        }
    }
    let settings = settings.ok_or_else(|| err(0, "no <VTKFile> element".into()))?;
    let mut b = Builder::new(file, "cell");
    if pieces.is_empty() {
        return Err(err(0, "no <Piece> element".into()));
    }
    for piece in &pieces {
        let decoder = Decoder {
            file,
            bytes,
            lines: &lines,
            settings: &settings,
            appended: appended.clone(),
        };
        add_piece(&mut b, &decoder, piece)?;
    }
    b.finish()
}

/// The value of attribute `key`.
fn attr<'x>(attrs: &'x [(&str, String)], key: &str) -> Option<&'x str> {
    attrs
        .iter()
        .find(|(k, _)| *k == key)
        .map(|(_, v)| v.as_str())
}

/// Files the array under the role its enclosing elements give it.
fn store(stack: &[String], piece: Option<&mut Piece>, array: Array) {
    let Some(piece) = piece else { return };
    match stack.last().map(String::as_str) {
        Some("Points") => piece.positions = Some(array),
        Some("Cells") => match array.name.as_str() {
            "connectivity" => piece.connectivity = Some(array),
            "offsets" => piece.offsets = Some(array),
            "types" => piece.types = Some(array),
            _ => {}
        },
        Some("CellData") => {
            if let Some(rank) = PHYSICAL_NAMES.iter().position(|n| *n == array.name)
                && piece.physical.as_ref().is_none_or(|(held, _)| rank < *held)
            {
                piece.physical = Some((rank, array));
            }
        }
        _ => {}
    }
}

/// Reads the `<VTKFile>` attributes that matter.
fn file_settings(attrs: &[(&str, String)]) -> Result<Settings, String> {
    let get = |key: &str| attr(attrs, key);
    match get("type") {
        Some("UnstructuredGrid") => {}
        t => {
            return Err(format!(
                "only type=\"UnstructuredGrid\" is supported, found {t:?}"
            ));
        }
    }
    let zlib = match get("compressor").unwrap_or("") {
        "" => false,
        "vtkZLibDataCompressor" => true,
        c => {
            return Err(format!(
                "compressor {} is not supported (vtkZLibDataCompressor is): write zlib-compressed or uncompressed VTU",
                shown(c)
            ));
        }
    };
    let big_endian = match get("byte_order").unwrap_or("LittleEndian") {
        "LittleEndian" => false,
        "BigEndian" => true,
        o => return Err(format!("unknown byte_order {}", shown(o))),
    };
    let header_bytes = match get("header_type").unwrap_or("UInt32") {
        "UInt32" => 4,
        "UInt64" => 8,
        h => return Err(format!("unknown header_type {}", shown(h))),
    };
    Ok(Settings {
        big_endian,
        header_bytes,
        zlib,
    })
}

/// Adds one piece's points and cells.
fn add_piece(b: &mut Builder, d: &Decoder, p: &Piece) -> Result<(), MeshIoError> {
    let missing = |what: &str| d.err(p.at, format!("<Piece> has no {what} DataArray"));
    let pos = p.positions.as_ref().ok_or_else(|| missing("Points"))?;
    if pos.components != 3 {
        return Err(d.err(
            pos.at,
            format!("Points must have 3 components, found {}", pos.components),
        ));
    }
    let coords = d.values(pos, p.points.saturating_mul(3), "Points")?;
    let base = b.vertex_count() as i64;
    for (i, c) in coords.chunks_exact(3).enumerate() {
        b.vertex(
            [c[0], c[1], c[2]],
            Location::Line(d.lines.line(pos.at)),
            "point",
            i as u64,
        )?;
    }
    if p.cells == 0 {
        return Ok(());
    }
    let conn_a = p
        .connectivity
        .as_ref()
        .ok_or_else(|| missing("connectivity"))?;
    let offs_a = p.offsets.as_ref().ok_or_else(|| missing("offsets"))?;
    let types_a = p.types.as_ref().ok_or_else(|| missing("types"))?;
    let offsets = integers(d, offs_a, &d.values(offs_a, p.cells, "offsets")?, "offsets")?;
    let types = integers(d, types_a, &d.values(types_a, p.cells, "types")?, "types")?;
    let conn_len = offsets.last().copied().unwrap_or(0);
    let conn_len =
        u64::try_from(conn_len).map_err(|_| d.err(offs_a.at, "offsets: negative offset".into()))?;
    let connectivity: Vec<i64> = integers(
        d,
        conn_a,
        &d.values(conn_a, conn_len, "connectivity")?,
        "connectivity",
    )?
    .into_iter()
    .map(|i| if i >= 0 { i + base } else { i })
    .collect();
    let mut prev = 0i64;
    for &o in &offsets {
        if o < prev {
            return Err(d.err(
                offs_a.at,
                format!("offsets must not decrease, found {o} after {prev}"),
            ));
        }
        prev = o;
    }
    let physical = match &p.physical {
        Some((_, a)) => Some(
            integers(d, a, &d.values(a, p.cells, &a.name)?, &a.name)?
                .into_iter()
                .map(|v| {
                    i32::try_from(v)
                        .map_err(|_| d.err(a.at, format!("physical tag {v} is out of range")))
                })
                .collect::<Result<Vec<i32>, _>>()?,
        ),
        None => None,
    };
    let cells_at = Location::Line(d.lines.line(conn_a.at));
    add_cells(
        b,
        d.file,
        &types,
        |c| {
            let s = if c == 0 {
                0
            } else {
                offsets.get(c - 1).copied().unwrap_or(0) as usize
            };
            let e = offsets.get(c).copied().unwrap_or(0) as usize;
            connectivity.get(s..e).unwrap_or_default()
        },
        |_| cells_at,
        physical.as_deref(),
    )
}
