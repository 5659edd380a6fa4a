//! The bytes of a message on zenoh: the same `#[repr(C)]` payloads as on
//! shared memory, behind a 16-byte preamble that carries what iceoryx2
//! checks when a service is opened (the protocol version and the layout):
//!
//! | bytes | field |
//! |---|---|
//! | 0..4 | magic `HAPS` |
//! | 4..8 | protocol version (u32, little-endian) |
//! | 8..12 | size of the message or header (u32) |
//! | 12..16 | size of one slice element (u32; 0 for a plain message) |
//! | 16.. | the message or header, then the elements |
//!
//! A peer of another version or layout is refused with [`DecodeError`]
//! naming the stream, never read as garbage.

use crate::protocol::PROTOCOL_VERSION;
use bytemuck::Pod;
use thiserror::Error;

/// The preamble's first four bytes.
pub const MAGIC: [u8; 4] = *b"HAPS";
/// Bytes before the payload.
pub const PREAMBLE_LEN: usize = 16;

/// Why a zenoh message was not accepted.
#[derive(Debug, Error, PartialEq, Eq)]
pub enum DecodeError {
    /// Not one of this project's messages (no `HAPS` preamble).
    #[error("{stream}: not a hapsim message ({len} bytes without the HAPS preamble)")]
    NotOurs {
        /// The stream's key.
        stream: String,
        /// The message's length.
        len: usize,
    },
    /// A peer of another protocol version.
    #[error(
        "{stream}: the peer speaks protocol version {found}, this program {PROTOCOL_VERSION}: rebuild both sides from the same release"
    )]
    Version {
        /// The stream's key.
        stream: String,
        /// The peer's version.
        found: u32,
    },
    /// The same version with another layout (a build of other sizes).
    #[error(
        "{stream}: payload layout differs (peer: {found_header} B header, {found_element} B elements; here: {header} B, {element} B)"
    )]
    Layout {
        /// The stream's key.
        stream: String,
        /// The peer's header size.
        found_header: u32,
        /// The peer's element size.
        found_element: u32,
        /// Ours.
        header: u32,
        /// Ours.
        element: u32,
    },
    /// The element bytes are not a whole number of elements.
    #[error("{stream}: {len} payload bytes are not whole elements of {element} B")]
    Truncated {
        /// The stream's key.
        stream: String,
        /// Bytes after the header.
        len: usize,
        /// Element size.
        element: usize,
    },
}

fn preamble(out: &mut Vec<u8>, header: usize, element: usize) {
    out.extend_from_slice(&MAGIC);
    out.extend_from_slice(&PROTOCOL_VERSION.to_le_bytes());
    out.extend_from_slice(&(header as u32).to_le_bytes());
    out.extend_from_slice(&(element as u32).to_le_bytes());
}

/// The bytes of one message.
pub fn encode<T: Pod>(msg: &T) -> Vec<u8> {
    let mut out = Vec::with_capacity(PREAMBLE_LEN + size_of::<T>());
    preamble(&mut out, size_of::<T>(), 0);
    out.extend_from_slice(bytemuck::bytes_of(msg));
    out
}

/// The bytes of a header and its slice (mesh frames, topology, rest).
pub fn encode_slice<H: Pod, T: Pod>(header: &H, items: &[T]) -> Vec<u8> {
    let mut out = Vec::with_capacity(PREAMBLE_LEN + size_of::<H>() + size_of_val(items));
    preamble(&mut out, size_of::<H>(), size_of::<T>());
    out.extend_from_slice(bytemuck::bytes_of(header));
    out.extend_from_slice(bytemuck::cast_slice(items));
    out
}

/// The checked preamble: the payload after it.
fn check<'a>(
    stream: &str,
    bytes: &'a [u8],
    header: usize,
    element: usize,
) -> Result<&'a [u8], DecodeError> {
    let word = |i: usize| u32::from_le_bytes([bytes[i], bytes[i + 1], bytes[i + 2], bytes[i + 3]]);
    if bytes.len() < PREAMBLE_LEN || bytes[..4] != MAGIC {
        return Err(DecodeError::NotOurs {
            stream: stream.to_string(),
            len: bytes.len(),
        });
    }
    let found = word(4);
    if found != PROTOCOL_VERSION {
        return Err(DecodeError::Version {
            stream: stream.to_string(),
            found,
        });
    }
    let (found_header, found_element) = (word(8), word(12));
    let rest = &bytes[PREAMBLE_LEN..];
    if found_header as usize != header || found_element as usize != element || rest.len() < header {
        return Err(DecodeError::Layout {
            stream: stream.to_string(),
            found_header,
            found_element,
            header: header as u32,
            element: element as u32,
        });
    }
    Ok(rest)
}

/// One message from its bytes (any alignment).
pub fn decode<T: Pod>(stream: &str, bytes: &[u8]) -> Result<T, DecodeError> {
    let rest = check(stream, bytes, size_of::<T>(), 0)?;
    if rest.len() != size_of::<T>() {
        return Err(DecodeError::Truncated {
            stream: stream.to_string(),
            len: rest.len(),
            element: size_of::<T>(),
        });
    }
    Ok(bytemuck::pod_read_unaligned(rest))
}

/// A header and its slice from their bytes, the slice appended to `items`
/// (cleared first; its capacity reused).
pub fn decode_slice<H: Pod, T: Pod>(
    stream: &str,
    bytes: &[u8],
    items: &mut Vec<T>,
) -> Result<H, DecodeError> {
    let rest = check(stream, bytes, size_of::<H>(), size_of::<T>())?;
    let (head, body) = rest.split_at(size_of::<H>());
    let element = size_of::<T>().max(1);
    if body.len() % element != 0 {
        return Err(DecodeError::Truncated {
            stream: stream.to_string(),
            len: body.len(),
            element,
        });
    }
    items.clear();
    items.extend(
        body.chunks_exact(element)
            .map(bytemuck::pod_read_unaligned::<T>),
    );
    Ok(bytemuck::pod_read_unaligned(head))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol::{ForceMsg, MeshHeader, PoseMsg};

    #[test]
    fn a_message_and_a_slice_come_back_bit_for_bit() {
        let mut f = ForceMsg {
            version: PROTOCOL_VERSION,
            tool_count: 1,
            seq: 9,
            t_ns: 123_456,
            ..ForceMsg::default()
        };
        f.tools[0].force_n = [0.5, -1.0, f64::MIN_POSITIVE];
        let bytes = encode(&f);
        assert_eq!(bytes.len(), PREAMBLE_LEN + size_of::<ForceMsg>());
        // Any alignment: read from an odd offset.
        let mut shifted = vec![0u8];
        shifted.extend_from_slice(&bytes);
        assert_eq!(decode::<ForceMsg>("force", &shifted[1..]).unwrap(), f);
        let h = MeshHeader {
            version: PROTOCOL_VERSION,
            vertex_count: 2,
            frame_seq: 4,
            topology_version: 1,
            t_ns: 77,
        };
        let items = [[1.0f32, 2.0, 3.0], [4.0, 5.0, 6.0]];
        let mut got = vec![[9.0f32; 3]; 5];
        let bytes = encode_slice(&h, &items);
        assert_eq!(
            decode_slice::<MeshHeader, _>("mesh", &bytes, &mut got),
            Ok(h)
        );
        assert_eq!(got, items);
    }

    #[test]
    fn another_version_another_layout_or_foreign_bytes_are_refused_by_name() {
        let mut bytes = encode(&PoseMsg::default());
        bytes[4..8].copy_from_slice(&999u32.to_le_bytes());
        let e = decode::<PoseMsg>("hapsim/s/pose", &bytes).unwrap_err();
        assert!(matches!(e, DecodeError::Version { found: 999, .. }), "{e}");
        assert!(e.to_string().contains("hapsim/s/pose"), "{e}");
        // A pose read as a force sample: the layout check refuses it.
        let e = decode::<ForceMsg>("force", &encode(&PoseMsg::default())).unwrap_err();
        assert!(matches!(e, DecodeError::Layout { .. }), "{e}");
        assert!(matches!(
            decode::<PoseMsg>("pose", b"hello"),
            Err(DecodeError::NotOurs { len: 5, .. })
        ));
        // A slice cut mid-element.
        let mut bytes = encode_slice(&MeshHeader::default(), &[[0.0f32; 3]; 2]);
        bytes.pop();
        let e = decode_slice::<MeshHeader, [f32; 3]>("mesh", &bytes, &mut Vec::new());
        assert!(matches!(e, Err(DecodeError::Truncated { .. })), "{e:?}");
        // A message with bytes missing.
        let mut bytes = encode(&PoseMsg::default());
        bytes.truncate(bytes.len() - 8);
        assert!(decode::<PoseMsg>("pose", &bytes).is_err());
    }
}
