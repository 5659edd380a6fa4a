//! Decoding a VTU file's located `DataArray`s ([`super::vtu`]) into
//! numbers: ASCII, inline base64 or appended raw data, uncompressed or
//! zlib-compressed, in the file's byte order and header width.

use super::base64;
use super::error::{Location, MeshIoError};
use super::text::{Tokens, parse_f64, perr, shown};
use super::vtk_zlib;
use super::xml::LineIndex;
use std::ops::Range;

/// Where an array's values are.
pub(super) enum Data {
    Ascii(Range<usize>),
    Base64(Range<usize>),
    Appended(u64),
}

/// A located `DataArray`.
pub(super) struct Array {
    pub(super) name: String,
    pub(super) ty: String,
    pub(super) components: u64,
    pub(super) data: Data,
    /// Offset of the `<DataArray` tag.
    pub(super) at: usize,
}

/// File-level settings from `<VTKFile>`.
pub(super) struct Settings {
    pub(super) big_endian: bool,
    pub(super) header_bytes: usize,
    /// `compressor="vtkZLibDataCompressor"`.
    pub(super) zlib: bool,
}

/// Decodes arrays to numbers.
pub(super) struct Decoder<'a> {
    pub(super) file: &'a str,
    pub(super) bytes: &'a [u8],
    pub(super) lines: &'a LineIndex,
    pub(super) settings: &'a Settings,
    pub(super) appended: Option<Range<usize>>,
}

impl Decoder<'_> {
    pub(super) fn err(&self, offset: usize, message: String) -> MeshIoError {
        perr(self.file, Location::Line(self.lines.line(offset)), message)
    }

    /// The array's values as f64 (exact for every integer an index can be),
    /// checking that there are `count` of them.
    pub(super) fn values(
        &self,
        a: &Array,
        count: u64,
        what: &str,
    ) -> Result<Vec<f64>, MeshIoError> {
        let width = match a.ty.as_str() {
            "Int8" | "UInt8" => 1,
            "Int16" | "UInt16" => 2,
            "Int32" | "UInt32" | "Float32" => 4,
            "Int64" | "UInt64" | "Float64" => 8,
            t => return Err(self.err(a.at, format!("{what}: unknown DataArray type {}", shown(t)))),
        };
        let bound = self.bytes.len();
        // The bytes the array holds: a compressed one may not inflate past them.
        let need = count.saturating_mul(width as u64);
        let values = match &a.data {
            Data::Ascii(r) => {
                let line = self.lines.line(r.start);
                let mut t = Tokens::new(
                    self.bytes.get(..r.end).unwrap_or_default(),
                    r.start,
                    line,
                    None,
                );
                let mut v =
                    Vec::with_capacity(usize::try_from(count).unwrap_or(usize::MAX).min(bound / 2));
                while let Some(tok) = t.next_token() {
                    v.push(parse_f64(tok.text).ok_or_else(|| {
                        perr(
                            self.file,
                            tok.at(),
                            format!("{what}: expected a number, found {}", shown(tok.text)),
                        )
                    })?);
                }
                v
            }
            Data::Base64(r) => {
                let text: Vec<u8> = self
                    .bytes
                    .get(r.clone())
                    .unwrap_or_default()
                    .iter()
                    .copied()
                    .filter(|c| !c.is_ascii_whitespace())
                    .collect();
                let raw = if self.settings.zlib {
                    let s = self.settings;
                    vtk_zlib::inflate_inline(&text, s.header_bytes, s.big_endian, need)
                        .map_err(|e| self.err(a.at, format!("{what}: {e}")))?
                } else {
                    self.inline_binary(&text, a, what)?
                };
                self.convert(&raw, width, &a.ty)
            }
            Data::Appended(offset) => {
                let region = self.appended.clone().ok_or_else(|| {
                    self.err(
                        a.at,
                        format!("{what}: appended array but no <AppendedData>"),
                    )
                })?;
                let start = usize::try_from(*offset)
                    .ok()
                    .and_then(|o| region.start.checked_add(o))
                    .filter(|&s| s <= region.end)
                    .ok_or_else(|| {
                        self.err(
                            a.at,
                            format!("{what}: offset {offset} is beyond the appended data"),
                        )
                    })?;
                let stored = self.bytes.get(start..region.end).unwrap_or_default();
                if self.settings.zlib {
                    let s = self.settings;
                    let raw = vtk_zlib::inflate_array(stored, s.header_bytes, s.big_endian, need)
                        .map_err(|e| self.err(a.at, format!("{what}: {e}")))?;
                    self.convert(&raw, width, &a.ty)
                } else {
                    self.convert(self.with_header(stored, a, what)?, width, &a.ty)
                }
            }
        };
        if values.len() as u64 != count {
            return Err(self.err(
                a.at,
                format!("{what}: expected {count} values, found {}", values.len()),
            ));
        }
        Ok(values)
    }

    /// Base64 inline data: a byte-count header, then the data. VTK encodes
    /// them as one stream when uncompressed, but some writers encode the
    /// header separately (padding in the middle): both are accepted.
    fn inline_binary(&self, text: &[u8], a: &Array, what: &str) -> Result<Vec<u8>, MeshIoError> {
        if let Ok(raw) = base64::decode(text) {
            return Ok(self.with_header(&raw, a, what)?.to_vec());
        }
        let split = self.settings.header_bytes.div_ceil(3) * 4;
        let decoded = text.get(..split).zip(text.get(split..)).and_then(|(h, d)| {
            let mut raw = base64::decode(h).ok()?;
            raw.extend(base64::decode(d).ok()?);
            Some(raw)
        });
        let raw = decoded.ok_or_else(|| self.err(a.at, format!("{what}: invalid base64 data")))?;
        Ok(self.with_header(&raw, a, what)?.to_vec())
    }

    /// Strips the byte-count header and returns exactly that many bytes.
    fn with_header<'b>(
        &self,
        raw: &'b [u8],
        a: &Array,
        what: &str,
    ) -> Result<&'b [u8], MeshIoError> {
        let hb = self.settings.header_bytes;
        let header = raw.get(..hb).ok_or_else(|| {
            self.err(a.at, format!("{what}: binary data shorter than its header"))
        })?;
        let mut h = [0u8; 8];
        h[..hb].copy_from_slice(header);
        if self.settings.big_endian {
            h[..hb].reverse();
        }
        let n = u64::from_le_bytes(h);
        usize::try_from(n)
            .ok()
            .and_then(|n| raw.get(hb..hb.checked_add(n)?))
            .ok_or_else(|| {
                self.err(
                    a.at,
                    format!(
                        "{what}: header says {n} bytes but only {} follow",
                        raw.len() - hb
                    ),
                )
            })
    }

    fn convert(&self, raw: &[u8], width: usize, ty: &str) -> Vec<f64> {
        let big = self.settings.big_endian;
        raw.chunks_exact(width)
            .map(|c| {
                let mut b = [0u8; 8];
                b[..width].copy_from_slice(c);
                if big {
                    b[..width].reverse();
                }
                match ty {
                    "Int8" => f64::from(b[0] as i8),
                    "UInt8" => f64::from(b[0]),
                    "Int16" => f64::from(i16::from_le_bytes([b[0], b[1]])),
                    "UInt16" => f64::from(u16::from_le_bytes([b[0], b[1]])),
                    "Int32" => f64::from(i32::from_le_bytes([b[0], b[1], b[2], b[3]])),
                    "UInt32" => f64::from(u32::from_le_bytes([b[0], b[1], b[2], b[3]])),
                    "Float32" => f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]])),
                    "Int64" => i64::from_le_bytes(b) as f64,
                    "UInt64" => u64::from_le_bytes(b) as f64,
                    _ => f64::from_le_bytes(b),
                }
            })
            .chain(
                // A trailing partial value makes the count wrong, which is reported.
                (!raw.len().is_multiple_of(width)).then_some(f64::NAN),
            )
            .collect()
    }
}

/// Integers from decoded values, refusing fractions and out-of-range values.
pub(super) fn integers(
    d: &Decoder,
    a: &Array,
    values: &[f64],
    what: &str,
) -> Result<Vec<i64>, MeshIoError> {
    values
        .iter()
        .map(|&v| {
            (v.fract() == 0.0 && v.abs() < 9.0e15)
                .then_some(v as i64)
                .ok_or_else(|| d.err(a.at, format!("{what}: {v} is not an integer")))
        })
        .collect()
}
