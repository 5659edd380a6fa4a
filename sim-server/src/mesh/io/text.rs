//! Reading text formats with line numbers: whole lines (Gmsh ASCII, where one
//! record is one line) and free-form tokens (legacy VTK and medit, where
//! numbers may wrap across lines), plus the number parsing they share.
//!
//! Input is bytes, not `str`: a file with stray non-UTF-8 bytes must give a
//! parse error at its line, not a refusal of the whole file without a place.

use super::error::{Location, MeshIoError};

/// A parse error at a place.
pub(super) fn perr(file: &str, at: Location, message: impl Into<String>) -> MeshIoError {
    MeshIoError::Parse {
        file: file.to_owned(),
        at,
        message: message.into(),
    }
}

/// Bytes as text for matching and messages; invalid UTF-8 becomes U+FFFD so
/// that it never matches a keyword or a number and is still printable.
pub(super) fn as_text(bytes: &[u8]) -> &str {
    std::str::from_utf8(bytes).unwrap_or("\u{FFFD}")
}

/// Shortens a token for an error message (a garbage "token" may be megabytes).
pub(super) fn shown(token: &str) -> String {
    const MAX: usize = 40;
    match token.char_indices().nth(MAX) {
        Some((cut, _)) => format!("'{}...'", &token[..cut]),
        None => format!("'{token}'"),
    }
}

/// Parses a finite or non-finite float (finiteness is checked by the caller,
/// which knows whether the value is a coordinate).
pub(super) fn parse_f64(token: &str) -> Option<f64> {
    token.parse().ok()
}

/// Parses an unsigned integer.
pub(super) fn parse_u64(token: &str) -> Option<u64> {
    token.parse().ok()
}

/// Parses a signed integer.
pub(super) fn parse_i64(token: &str) -> Option<i64> {
    token.parse().ok()
}

/// A line of text: its 1-based number and its whitespace-separated fields.
pub(super) struct Line<'a> {
    /// 1-based line number.
    pub no: usize,
    /// The line without its terminator.
    pub text: &'a str,
}

impl<'a> Line<'a> {
    /// The whitespace-separated fields.
    pub fn fields(&self) -> impl Iterator<Item = &'a str> + use<'a> {
        self.text.split_ascii_whitespace()
    }

    /// The place of this line.
    pub fn at(&self) -> Location {
        Location::Line(self.no)
    }
}

/// Reads a byte buffer line by line, counting lines.
pub(super) struct Lines<'a> {
    src: &'a [u8],
    pos: usize,
    line: usize,
}

impl<'a> Lines<'a> {
    /// Starts at the beginning of `src`.
    pub fn new(src: &'a [u8]) -> Self {
        Self {
            src,
            pos: 0,
            line: 0,
        }
    }

    /// The byte offset of the next unread line.
    pub fn pos(&self) -> usize {
        self.pos
    }

    /// The number of the last line returned (0 before the first).
    pub fn line_no(&self) -> usize {
        self.line
    }

    /// Bytes not yet read (an upper bound for record counts claimed by headers).
    pub fn remaining(&self) -> usize {
        self.src.len().saturating_sub(self.pos)
    }

    /// The next line, blank lines included; `None` at the end of the input.
    pub fn next_raw(&mut self) -> Option<Line<'a>> {
        let rest = self.src.get(self.pos..)?;
        if rest.is_empty() {
            return None;
        }
        let end = rest.iter().position(|&b| b == b'\n').unwrap_or(rest.len());
        let mut text = &rest[..end];
        if let [head @ .., b'\r'] = text {
            text = head;
        }
        self.pos += (end + 1).min(rest.len());
        self.line += 1;
        Some(Line {
            no: self.line,
            text: as_text(text),
        })
    }

    /// The next line that is not blank.
    pub fn next_line(&mut self) -> Option<Line<'a>> {
        loop {
            let line = self.next_raw()?;
            if !line.text.trim().is_empty() {
                return Some(line);
            }
        }
    }
}

/// One whitespace-separated token and where it is.
#[derive(Clone, Copy)]
pub(super) struct Token<'a> {
    /// The text.
    pub text: &'a str,
    /// 1-based line.
    pub line: usize,
    /// Whether it is the first token on its line.
    pub first_on_line: bool,
}

impl Token<'_> {
    /// The place of this token.
    pub fn at(&self) -> Location {
        Location::Line(self.line)
    }
}

/// Reads whitespace-separated tokens, skipping comments that start with
/// `comment` and run to the end of the line.
pub(super) struct Tokens<'a> {
    src: &'a [u8],
    pos: usize,
    line: usize,
    /// Whether no token has been read yet on the current line.
    fresh_line: bool,
    comment: Option<u8>,
    peeked: Option<Option<Token<'a>>>,
}

impl<'a> Tokens<'a> {
    /// Starts at byte `pos` (on 1-based line `line`) of `src`.
    pub fn new(src: &'a [u8], pos: usize, line: usize, comment: Option<u8>) -> Self {
        Self {
            src,
            pos,
            line,
            fresh_line: true,
            comment,
            peeked: None,
        }
    }

    /// Bytes not yet read.
    pub fn remaining(&self) -> usize {
        self.src.len().saturating_sub(self.pos)
    }

    /// The current line (of the last token read, or where reading stopped).
    pub fn line(&self) -> usize {
        match &self.peeked {
            Some(Some(t)) => t.line,
            _ => self.line,
        }
    }

    /// The next token without consuming it.
    pub fn peek(&mut self) -> Option<Token<'a>> {
        if self.peeked.is_none() {
            self.peeked = Some(self.scan());
        }
        self.peeked.flatten()
    }

    /// The next token.
    pub fn next_token(&mut self) -> Option<Token<'a>> {
        match self.peeked.take() {
            Some(t) => t,
            None => self.scan(),
        }
    }

    fn scan(&mut self) -> Option<Token<'a>> {
        loop {
            let &b = self.src.get(self.pos)?;
            if b == b'\n' {
                self.line += 1;
                self.fresh_line = true;
                self.pos += 1;
            } else if b.is_ascii_whitespace() {
                self.pos += 1;
            } else if Some(b) == self.comment {
                while self.src.get(self.pos).is_some_and(|&c| c != b'\n') {
                    self.pos += 1;
                }
            } else {
                break;
            }
        }
        let start = self.pos;
        while self
            .src
            .get(self.pos)
            .is_some_and(|c| !c.is_ascii_whitespace())
        {
            self.pos += 1;
        }
        let first_on_line = std::mem::replace(&mut self.fresh_line, false);
        Some(Token {
            text: as_text(self.src.get(start..self.pos).unwrap_or_default()),
            line: self.line,
            first_on_line,
        })
    }
}
