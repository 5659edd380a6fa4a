//! Base64 (RFC 4648, standard alphabet), the encoding of VTK XML "binary"
//! data, by the `base64` crate: padded on output, padding optional on input
//! (VTK writes it, some writers drop it). A decoding error carries no
//! position the user could use: the readers report the array's line.

use base64::Engine;
use base64::alphabet::STANDARD;
use base64::engine::{DecodePaddingMode, GeneralPurpose, GeneralPurposeConfig};

const ENGINE: GeneralPurpose = GeneralPurpose::new(
    &STANDARD,
    GeneralPurposeConfig::new().with_decode_padding_mode(DecodePaddingMode::Indifferent),
);

/// Encodes bytes (padded).
pub(super) fn encode(bytes: &[u8]) -> String {
    ENGINE.encode(bytes)
}

/// Decodes one padded or unpadded base64 stream without whitespace.
pub(super) fn decode(text: &[u8]) -> Result<Vec<u8>, base64::DecodeError> {
    ENGINE.decode(text)
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
