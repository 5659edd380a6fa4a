//! Standard base64 (RFC 4648, `+/`, `=` padding), the encoding of VTK XML
//! "binary" data. Twenty lines each way do not justify a dependency.

const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";

/// Encodes bytes.
pub(super) fn encode(bytes: &[u8]) -> String {
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for chunk in bytes.chunks(3) {
        let b = [
            chunk[0],
            *chunk.get(1).unwrap_or(&0),
            *chunk.get(2).unwrap_or(&0),
        ];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for k in 0..4 {
            if k <= chunk.len() {
                out.push(ALPHABET[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

fn value(c: u8) -> Option<u32> {
    Some(match c {
        b'A'..=b'Z' => c - b'A',
        b'a'..=b'z' => c - b'a' + 26,
        b'0'..=b'9' => c - b'0' + 52,
        b'+' => 62,
        b'/' => 63,
        _ => return None,
    } as u32)
}

/// Decodes one padded (or unpadded) base64 stream without whitespace. On
/// failure, returns the index of the offending character.
pub(super) fn decode(text: &[u8]) -> Result<Vec<u8>, usize> {
    let data_len = text.iter().rposition(|&c| c != b'=').map_or(0, |k| k + 1);
    if text.len() - data_len > 2 || (!text.len().is_multiple_of(4) && data_len != text.len()) {
        return Err(data_len);
    }
    let mut out = Vec::with_capacity(data_len / 4 * 3 + 2);
    for (k, chunk) in text[..data_len].chunks(4).enumerate() {
        let mut n = 0u32;
        for (j, &c) in chunk.iter().enumerate() {
            n |= value(c).ok_or(k * 4 + j)? << (18 - 6 * j);
        }
        let bytes = [(n >> 16) as u8, (n >> 8) as u8, n as u8];
        match chunk.len() {
            4 => out.extend_from_slice(&bytes),
            3 => out.extend_from_slice(&bytes[..2]),
            2 => out.push(bytes[0]),
            _ => return Err(k * 4),
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_all_lengths() {
        let data: Vec<u8> = (0..=255).collect();
        for n in 0..20 {
            let e = encode(&data[..n * 7 % 256]);
            assert_eq!(decode(e.as_bytes()).unwrap(), &data[..n * 7 % 256]);
        }
        assert_eq!(encode(b"Man"), "TWFu");
        assert_eq!(encode(b"Ma"), "TWE=");
        assert!(decode(b"TW=u").is_err());
        assert!(decode(b"T").is_err());
    }
}
