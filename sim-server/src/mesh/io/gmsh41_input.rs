//! The two inputs of the Gmsh MSH 4.1 reader ([`super::gmsh41`]): ASCII,
//! one record per line, and binary, native values of the writer's
//! endianness; the section logic reads both through [`Input`].

use super::error::{Location, MeshIoError};
use super::text::{Lines, as_text, parse_f64, parse_i64, parse_u64, perr, shown};

/// How a section reads its values.
pub(super) trait Input {
    /// Where the next value is.
    fn at(&self) -> Location;
    /// Bytes left: a bound on how many records can follow.
    fn remaining(&self) -> usize;
    /// Starts a record (ASCII: reads the next line and returns its number of
    /// fields; binary: nothing, `None`).
    fn record(&mut self, what: &str) -> Result<Option<usize>, MeshIoError>;
    /// Checks that the record has no values left.
    fn end_record(&mut self) -> Result<(), MeshIoError>;
    /// Skips a record of `values` size_t values.
    fn skip_records(&mut self, count: u64, values: usize, what: &str) -> Result<(), MeshIoError>;
    /// An unsigned size (`size_t` in binary).
    fn size(&mut self, what: &str) -> Result<u64, MeshIoError>;
    /// A signed int (`int` in binary).
    fn int(&mut self, what: &str) -> Result<i32, MeshIoError>;
    /// A double.
    fn float(&mut self, what: &str) -> Result<f64, MeshIoError>;
    /// The next section marker line (`$Nodes`...), `None` at the end.
    fn marker(&mut self) -> Result<Option<(Location, String)>, MeshIoError>;
    /// Skips to the end marker of an unneeded section.
    fn skip_section(&mut self, name: &str, at: Location) -> Result<(), MeshIoError>;
}

/// ASCII input: one record per line.
pub(super) struct Ascii<'a, 'f> {
    file: &'f str,
    lines: Lines<'a>,
    fields: Vec<&'a str>,
    next: usize,
    line: usize,
}

impl<'a, 'f> Ascii<'a, 'f> {
    /// The records of `lines`, the last line read being `line`.
    pub(super) fn new(file: &'f str, lines: Lines<'a>, line: usize) -> Self {
        Self {
            file,
            lines,
            fields: Vec::new(),
            next: 0,
            line,
        }
    }
}

impl<'a> Ascii<'a, '_> {
    fn field(&mut self, what: &str) -> Result<&'a str, MeshIoError> {
        let f = self.fields.get(self.next).copied().ok_or_else(|| {
            perr(
                self.file,
                Location::Line(self.line),
                format!("line ends early: expected {what}"),
            )
        })?;
        self.next += 1;
        Ok(f)
    }

    fn bad(&self, what: &str, found: &str) -> MeshIoError {
        perr(
            self.file,
            Location::Line(self.line),
            format!("expected {what}, found {}", shown(found)),
        )
    }
}

impl Input for Ascii<'_, '_> {
    fn at(&self) -> Location {
        Location::Line(self.line)
    }
    fn remaining(&self) -> usize {
        self.lines.remaining()
    }
    fn record(&mut self, what: &str) -> Result<Option<usize>, MeshIoError> {
        let l = self.lines.next_line().ok_or_else(|| {
            perr(
                self.file,
                Location::Line(self.lines.line_no() + 1),
                format!("file ends before {what}"),
            )
        })?;
        self.line = l.no;
        if l.text.trim_start().starts_with('$') {
            return Err(perr(
                self.file,
                l.at(),
                format!(
                    "section ends early: expected {what}, found {}",
                    shown(l.text.trim())
                ),
            ));
        }
        self.fields = l.fields().collect();
        self.next = 0;
        Ok(Some(self.fields.len()))
    }
    fn end_record(&mut self) -> Result<(), MeshIoError> {
        match self.fields.get(self.next) {
            None => Ok(()),
            Some(extra) => Err(perr(
                self.file,
                Location::Line(self.line),
                format!(
                    "unexpected extra value {} at the end of the line",
                    shown(extra)
                ),
            )),
        }
    }
    fn skip_records(&mut self, count: u64, _values: usize, what: &str) -> Result<(), MeshIoError> {
        for _ in 0..count {
            self.record(what)?;
        }
        Ok(())
    }
    fn size(&mut self, what: &str) -> Result<u64, MeshIoError> {
        let f = self.field(what)?;
        parse_u64(f).ok_or_else(|| self.bad(what, f))
    }
    fn int(&mut self, what: &str) -> Result<i32, MeshIoError> {
        let f = self.field(what)?;
        parse_i64(f)
            .and_then(|v| i32::try_from(v).ok())
            .ok_or_else(|| self.bad(what, f))
    }
    fn float(&mut self, what: &str) -> Result<f64, MeshIoError> {
        let f = self.field(what)?;
        parse_f64(f).ok_or_else(|| self.bad(what, f))
    }
    fn marker(&mut self) -> Result<Option<(Location, String)>, MeshIoError> {
        Ok(self.lines.next_line().map(|l| {
            self.line = l.no;
            (l.at(), l.text.trim().to_owned())
        }))
    }
    fn skip_section(&mut self, name: &str, at: Location) -> Result<(), MeshIoError> {
        let end = format!("$End{name}");
        while let Some(l) = self.lines.next_line() {
            if l.text.trim() == end {
                return Ok(());
            }
        }
        Err(perr(self.file, at, format!("section ${name} has no {end}")))
    }
}

/// Binary input: native values of the writer's endianness, `size_t` = 8 bytes.
pub(super) struct Binary<'a, 'f> {
    file: &'f str,
    src: &'a [u8],
    pos: usize,
    big_endian: bool,
}

impl<'a, 'f> Binary<'a, 'f> {
    /// Binary values of `src` from `pos` on, after the endianness mark
    /// (the int 1 in the writer's byte order) found there.
    pub(super) fn after_mark(
        file: &'f str,
        src: &'a [u8],
        pos: usize,
    ) -> Result<Self, MeshIoError> {
        let one: [u8; 4] = src
            .get(pos..pos + 4)
            .and_then(|s| s.try_into().ok())
            .ok_or_else(|| {
                perr(
                    file,
                    Location::Byte(pos),
                    "file ends before the endianness mark",
                )
            })?;
        let big_endian = match (u32::from_le_bytes(one), u32::from_be_bytes(one)) {
            (1, _) => false,
            (_, 1) => true,
            _ => {
                return Err(perr(
                    file,
                    Location::Byte(pos),
                    format!("expected the binary integer 1 (endianness mark), found {one:?}"),
                ));
            }
        };
        Ok(Self {
            file,
            src,
            pos: pos + 4,
            big_endian,
        })
    }
}

impl Binary<'_, '_> {
    fn take<const N: usize>(&mut self, what: &str) -> Result<[u8; N], MeshIoError> {
        let bytes: Option<[u8; N]> = self
            .src
            .get(self.pos..self.pos.saturating_add(N))
            .and_then(|s| s.try_into().ok());
        let mut bytes = bytes.ok_or_else(|| {
            perr(
                self.file,
                Location::Byte(self.pos),
                format!("file ends while reading {what}"),
            )
        })?;
        self.pos += N;
        if self.big_endian {
            bytes.reverse();
        }
        Ok(bytes)
    }
}

impl Input for Binary<'_, '_> {
    fn at(&self) -> Location {
        Location::Byte(self.pos)
    }
    fn remaining(&self) -> usize {
        self.src.len().saturating_sub(self.pos)
    }
    fn record(&mut self, _what: &str) -> Result<Option<usize>, MeshIoError> {
        Ok(None)
    }
    fn end_record(&mut self) -> Result<(), MeshIoError> {
        Ok(())
    }
    fn skip_records(&mut self, count: u64, values: usize, what: &str) -> Result<(), MeshIoError> {
        let bytes = count
            .checked_mul(values as u64 * 8)
            .and_then(|b| usize::try_from(b).ok())
            .filter(|&b| b <= self.remaining())
            .ok_or_else(|| {
                perr(
                    self.file,
                    Location::Byte(self.pos),
                    format!("file ends inside {count} {what}"),
                )
            })?;
        self.pos += bytes;
        Ok(())
    }
    fn size(&mut self, what: &str) -> Result<u64, MeshIoError> {
        Ok(u64::from_le_bytes(self.take(what)?))
    }
    fn int(&mut self, what: &str) -> Result<i32, MeshIoError> {
        Ok(i32::from_le_bytes(self.take(what)?))
    }
    fn float(&mut self, what: &str) -> Result<f64, MeshIoError> {
        Ok(f64::from_le_bytes(self.take(what)?))
    }
    fn marker(&mut self) -> Result<Option<(Location, String)>, MeshIoError> {
        while self.src.get(self.pos).is_some_and(u8::is_ascii_whitespace) {
            self.pos += 1;
        }
        if self.pos >= self.src.len() {
            return Ok(None);
        }
        let at = Location::Byte(self.pos);
        let rest = self.src.get(self.pos..).unwrap_or_default();
        let end = rest.iter().position(|&b| b == b'\n').unwrap_or(rest.len());
        // Past the newline: binary values start right after it.
        self.pos += (end + 1).min(rest.len());
        Ok(Some((at, as_text(&rest[..end]).trim().to_owned())))
    }
    fn skip_section(&mut self, name: &str, at: Location) -> Result<(), MeshIoError> {
        let end = format!("\n$End{name}");
        let rest = self.src.get(self.pos..).unwrap_or_default();
        match rest.windows(end.len()).position(|w| w == end.as_bytes()) {
            Some(k) => {
                self.pos += k + end.len();
                Ok(())
            }
            None => Err(perr(
                self.file,
                at,
                format!("section ${name} has no $End{name}"),
            )),
        }
    }
}

/// Reads the next marker line and checks that it is `end`.
pub(super) fn expect_marker(
    file: &str,
    input: &mut impl Input,
    end: &str,
) -> Result<(), MeshIoError> {
    match input.marker()? {
        Some((_, m)) if m == end => Ok(()),
        Some((at, m)) => Err(perr(
            file,
            at,
            format!("expected {end}, found {}", shown(&m)),
        )),
        None => Err(perr(file, input.at(), format!("file ends before {end}"))),
    }
}
