//! A minimal XML event scanner, enough for VTK XML files: start and end tags
//! with attributes, text, comments, processing instructions, CDATA and a
//! simple DOCTYPE. It reports byte offsets; [`LineIndex`] turns them into
//! lines. It does not check that tags nest (the VTU reader checks what it
//! needs) and it stops where the caller stops, which is how raw appended data,
//! which is not XML, is never scanned as markup.

use super::text::as_text;

/// One piece of markup.
pub(super) enum Event<'a> {
    /// `<name a="v">` or `<name/>` (then `empty`).
    Start {
        /// Tag name.
        name: &'a str,
        /// Attributes, values with the five predefined entities decoded.
        attrs: Vec<(&'a str, String)>,
        /// Whether the tag closes itself.
        empty: bool,
        /// Offset of the `<`.
        at: usize,
    },
    /// `</name>`.
    End {
        /// Tag name.
        name: &'a str,
        /// Offset of the `<`.
        at: usize,
    },
    /// Character data or CDATA (the VTU reader takes array content as the
    /// byte range between a start tag and its end tag instead).
    Text,
    /// End of input.
    Eof,
}

/// Scans events from a byte buffer.
pub(super) struct Xml<'a> {
    src: &'a [u8],
    pos: usize,
}

/// A scan error: the offset and what is wrong.
pub(super) type XmlError = (usize, String);

impl<'a> Xml<'a> {
    /// Starts at the beginning of `src`.
    pub fn new(src: &'a [u8]) -> Self {
        Self { src, pos: 0 }
    }

    /// The offset of the next unread byte.
    pub fn pos(&self) -> usize {
        self.pos
    }

    fn find(&self, from: usize, pat: &[u8]) -> Option<usize> {
        self.src
            .get(from..)?
            .windows(pat.len())
            .position(|w| w == pat)
            .map(|k| from + k)
    }

    fn starts_with(&self, pat: &[u8]) -> bool {
        self.src.get(self.pos..).is_some_and(|s| s.starts_with(pat))
    }

    /// The next event.
    pub fn next_event(&mut self) -> Result<Event<'a>, XmlError> {
        loop {
            let start = self.pos;
            let Some(&first) = self.src.get(start) else {
                return Ok(Event::Eof);
            };
            if first != b'<' {
                let end = self.find(start, b"<").unwrap_or(self.src.len());
                self.pos = end;
                return Ok(Event::Text);
            }
            let skip_to = |this: &Self, pat: &[u8], what: &str| {
                this.find(start, pat)
                    .map(|k| k + pat.len())
                    .ok_or_else(|| (start, format!("unterminated {what}")))
            };
            if self.starts_with(b"<!--") {
                self.pos = skip_to(self, b"-->", "comment")?;
            } else if self.starts_with(b"<![CDATA[") {
                self.pos = skip_to(self, b"]]>", "CDATA section")?;
                return Ok(Event::Text);
            } else if self.starts_with(b"<?") {
                self.pos = skip_to(self, b"?>", "processing instruction")?;
            } else if self.starts_with(b"<!") {
                self.pos = skip_to(self, b">", "declaration")?;
            } else if self.starts_with(b"</") {
                let end = self
                    .find(start, b">")
                    .ok_or((start, "unterminated end tag".into()))?;
                self.pos = end + 1;
                let name = as_text(self.src.get(start + 2..end).unwrap_or_default()).trim();
                return Ok(Event::End { name, at: start });
            } else {
                return self.start_tag(start);
            }
        }
    }

    fn start_tag(&mut self, start: usize) -> Result<Event<'a>, XmlError> {
        let src = self.src;
        let is_name_end = |b: u8| b.is_ascii_whitespace() || b == b'/' || b == b'>';
        let mut p = start + 1;
        while src.get(p).is_some_and(|&b| !is_name_end(b)) {
            p += 1;
        }
        let name = as_text(src.get(start + 1..p).unwrap_or_default());
        if name.is_empty() {
            return Err((start, "expected a tag name after '<'".into()));
        }
        let mut attrs = Vec::new();
        loop {
            while src.get(p).is_some_and(u8::is_ascii_whitespace) {
                p += 1;
            }
            match src.get(p) {
                None => return Err((start, format!("unterminated tag <{name}>"))),
                Some(b'>') => {
                    self.pos = p + 1;
                    return Ok(Event::Start {
                        name,
                        attrs,
                        empty: false,
                        at: start,
                    });
                }
                Some(b'/') if src.get(p + 1) == Some(&b'>') => {
                    self.pos = p + 2;
                    return Ok(Event::Start {
                        name,
                        attrs,
                        empty: true,
                        at: start,
                    });
                }
                Some(_) => {}
            }
            let a = p;
            while src.get(p).is_some_and(|&b| b != b'=' && !is_name_end(b)) {
                p += 1;
            }
            let attr = as_text(src.get(a..p).unwrap_or_default());
            while src.get(p).is_some_and(u8::is_ascii_whitespace) {
                p += 1;
            }
            if attr.is_empty() || src.get(p) != Some(&b'=') {
                return Err((p, format!("expected attribute=\"value\" in <{name}>")));
            }
            p += 1;
            while src.get(p).is_some_and(u8::is_ascii_whitespace) {
                p += 1;
            }
            let quote = match src.get(p) {
                Some(&q @ (b'"' | b'\'')) => q,
                _ => return Err((p, format!("expected a quoted value for {attr} in <{name}>"))),
            };
            let v = p + 1;
            let end = src
                .get(v..)
                .and_then(|s| s.iter().position(|&b| b == quote))
                .map(|k| v + k)
                .ok_or((p, format!("unterminated value of {attr} in <{name}>")))?;
            attrs.push((attr, unescape(as_text(src.get(v..end).unwrap_or_default()))));
            p = end + 1;
        }
    }
}

/// Decodes the predefined entities (and leaves anything else as it is).
pub(super) fn unescape(s: &str) -> String {
    if !s.contains('&') {
        return s.to_owned();
    }
    s.replace("&lt;", "<")
        .replace("&gt;", ">")
        .replace("&quot;", "\"")
        .replace("&apos;", "'")
        .replace("&amp;", "&")
}

/// Escapes text for an attribute value.
pub(super) fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// Byte offset to 1-based line.
pub(super) struct LineIndex {
    newlines: Vec<usize>,
}

impl LineIndex {
    /// Indexes the newlines of `src`.
    pub fn new(src: &[u8]) -> Self {
        Self {
            newlines: src
                .iter()
                .enumerate()
                .filter(|(_, b)| **b == b'\n')
                .map(|(i, _)| i)
                .collect(),
        }
    }

    /// The line of byte `offset`.
    pub fn line(&self, offset: usize) -> usize {
        self.newlines.partition_point(|&n| n < offset) + 1
    }
}
