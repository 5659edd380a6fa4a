//! VTK's compressed binary arrays (`compressor="vtkZLibDataCompressor"`, the
//! default of VTK's XML writers, of ParaView and of meshio).
//!
//! An array is a header of `header_type` integers, `[blocks, block size,
//! last block size, compressed size of each block...]`, then the blocks,
//! each a zlib stream of `block size` bytes (the last of `last block size`,
//! or a whole block when that is 0). Inline (base64) arrays encode the header
//! and the blocks as two base64 streams; appended raw arrays store them as
//! they are. Inflating is flate2's (miniz_oxide, pure Rust); what this
//! module adds is the bounds: the sizes a header claims are checked against
//! the bytes present (no block inflates past its declared size, and a
//! header cannot claim more than zlib's largest ratio over what follows),
//! so a malformed file is an error, never an unbounded allocation.

use super::base64;
use std::io::Read;

/// Deflate's largest expansion (a stream of one repeated byte): 1032:1.
const MAX_RATIO: u64 = 1032;

/// Above this many inflated bytes an array is held to [`MAX_LARGE_RATIO`].
const LARGE_ARRAY_BYTES: u64 = 16 << 20;
/// The largest compression ratio of a large array: coordinates and
/// connectivity compress a few times at most.
const MAX_LARGE_RATIO: u64 = 64;

/// Block size of the compressed arrays this crate writes (VTK's default).
pub(super) const WRITE_BLOCK: usize = 1 << 15;

/// `payload` compressed as VTK stores it, in blocks of `block_size` bytes
/// with a header of `hb`-byte little-endian integers (4: UInt32, 8:
/// UInt64): the header's bytes and the blocks' bytes (base64-encoded apart
/// when inline). Fast compression: frames are written while a simulation
/// runs.
pub(super) fn deflate_array(payload: &[u8], block_size: usize, hb: usize) -> (Vec<u8>, Vec<u8>) {
    let chunks: Vec<&[u8]> = payload.chunks(block_size).collect();
    let mut header: Vec<u64> = vec![
        chunks.len() as u64,
        block_size as u64,
        chunks.last().map_or(0, |c| c.len() as u64),
    ];
    let mut blocks = Vec::with_capacity(payload.len() / 2);
    for c in &chunks {
        let before = blocks.len();
        let mut z = flate2::write::ZlibEncoder::new(&mut blocks, flate2::Compression::fast());
        // Writing to a Vec cannot fail.
        let _ = std::io::Write::write_all(&mut z, c);
        let _ = z.finish();
        header.push((blocks.len() - before) as u64);
    }
    let header = header
        .iter()
        .flat_map(|h| h.to_le_bytes().into_iter().take(hb))
        .collect();
    (header, blocks)
}

/// The uncompressed bytes of one compressed array stored raw (appended
/// data, or inline data once decoded); `hb` is the header integer width,
/// `big_endian` the file's byte order and `need` the bytes the array
/// holds (its value count times the value width, from the file's point
/// and cell counts): a header claiming more is refused before inflating
/// (zlib's ratio alone let a 1.4 MB file of five points ask for 1 GiB).
/// The error says what is wrong.
pub(super) fn inflate_array(
    raw: &[u8],
    hb: usize,
    big_endian: bool,
    need: u64,
) -> Result<Vec<u8>, String> {
    let int = |k: usize| -> Result<u64, String> {
        let bytes = raw
            .get(k * hb..(k + 1) * hb)
            .ok_or("compressed data shorter than its header")?;
        let mut b = [0u8; 8];
        b[..hb].copy_from_slice(bytes);
        if big_endian {
            b[..hb].reverse();
        }
        Ok(u64::from_le_bytes(b))
    };
    let blocks = int(0)?;
    let block_size = int(1)?;
    let last = match int(2)? {
        0 => block_size,
        l => l,
    };
    let header_len = blocks
        .checked_add(3)
        .and_then(|n| n.checked_mul(hb as u64))
        .and_then(|n| usize::try_from(n).ok())
        .filter(|&n| n <= raw.len())
        .ok_or_else(|| format!("compressed header of {blocks} blocks is longer than the data"))?;
    let total = match blocks {
        0 => 0,
        n => (n - 1)
            .checked_mul(block_size)
            .and_then(|t| t.checked_add(last))
            .ok_or("compressed header sizes overflow")?,
    };
    if total > need {
        return Err(format!(
            "compressed header claims {total} bytes, the array holds {need}"
        ));
    }
    let body = &raw[header_len..];
    // Counts are the file's word too (a file claiming 44 million points
    // passes `need`): a large array must also compress no better than
    // real mesh data does, where zlib's ratio alone let a 1.4 MB file
    // inflate to 1 GiB. (Small arrays may: a types array of one cell
    // type compresses about 1000:1.)
    if total > LARGE_ARRAY_BYTES && total > (body.len() as u64).saturating_mul(MAX_LARGE_RATIO) {
        return Err(format!(
            "compressed array of {} bytes claims {total} bytes, more than {MAX_LARGE_RATIO} times its size: not mesh data",
            body.len()
        ));
    }
    if total > (body.len() as u64).saturating_mul(MAX_RATIO) {
        return Err(format!(
            "compressed header claims {total} bytes from {} compressed ones",
            body.len()
        ));
    }
    let mut out = Vec::with_capacity(total as usize);
    let mut at = 0usize;
    for k in 0..blocks {
        let size = int(3 + k as usize)?;
        let block = usize::try_from(size)
            .ok()
            .and_then(|s| body.get(at..at.checked_add(s)?))
            .ok_or_else(|| format!("compressed block {k} of {size} bytes runs past the data"))?;
        at += block.len();
        let expect = if k + 1 == blocks { last } else { block_size };
        let before = out.len();
        flate2::read::ZlibDecoder::new(block)
            .take(expect)
            .read_to_end(&mut out)
            .map_err(|e| format!("compressed block {k}: {e}"))?;
        if (out.len() - before) as u64 != expect {
            return Err(format!(
                "compressed block {k} inflates to {} bytes, its header says {expect}",
                out.len() - before
            ));
        }
    }
    Ok(out)
}

/// Inline base64 text of a compressed array: the header and the blocks as
/// two base64 streams (VTK, meshio), or as one; `need` as for
/// [`inflate_array`].
pub(super) fn inflate_inline(
    text: &[u8],
    hb: usize,
    big_endian: bool,
    need: u64,
) -> Result<Vec<u8>, String> {
    // The block count is the first integer: the first whole base64 groups.
    let first = base64::decode(text.get(..hb.div_ceil(3) * 4).unwrap_or(text))
        .map_err(|_| "invalid base64 data")?;
    let mut b = [0u8; 8];
    let head = first
        .get(..hb)
        .ok_or("compressed data shorter than its header")?;
    b[..hb].copy_from_slice(head);
    if big_endian {
        b[..hb].reverse();
    }
    let blocks = u64::from_le_bytes(b);
    let split = blocks
        .checked_add(3)
        .and_then(|n| n.checked_mul(hb as u64))
        .map(|n| n.div_ceil(3) * 4)
        .and_then(|n| usize::try_from(n).ok())
        .filter(|&n| n <= text.len());
    let two_streams = split.and_then(|s| {
        let mut raw = base64::decode(&text[..s]).ok()?;
        raw.extend(base64::decode(&text[s..]).ok()?);
        Some(raw)
    });
    let raw = match two_streams {
        Some(raw) => raw,
        None => base64::decode(text).map_err(|_| "invalid base64 data")?,
    };
    inflate_array(&raw, hb, big_endian, need)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blocks_round_trip_and_bad_headers_are_errors() {
        let data: Vec<u8> = (0..10_000u32)
            .flat_map(|i| (i % 97).to_le_bytes())
            .collect();
        let need = data.len() as u64;
        let (header, blocks) = deflate_array(&data, 4096, 4);
        let packed = [header, blocks].concat();
        assert_eq!(inflate_array(&packed, 4, false, need).unwrap(), data);
        // Header and blocks as two base64 streams, as VTK writes inline.
        let blocks = u32::from_le_bytes(packed[..4].try_into().unwrap()) as usize;
        let h = (3 + blocks) * 4;
        let text = format!(
            "{}{}",
            base64::encode(&packed[..h]),
            base64::encode(&packed[h..])
        );
        assert_eq!(
            inflate_inline(text.as_bytes(), 4, false, need).unwrap(),
            data
        );
        // One stream is accepted too.
        let one = base64::encode(&packed);
        assert_eq!(
            inflate_inline(one.as_bytes(), 4, false, need).unwrap(),
            data
        );
        // A header claiming a huge size is refused before any allocation.
        let mut bomb = packed.clone();
        bomb[4..8].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(
            inflate_array(&bomb, 4, false, u64::MAX)
                .unwrap_err()
                .contains("claims")
        );
        // ... and so is one within zlib's ratio but beyond what the array
        // holds (its points and cells say how many bytes that is).
        let err = inflate_array(&packed, 4, false, need - 1).unwrap_err();
        assert!(err.contains("the array holds"), "{err}");
        // A large array compressing far better than mesh data (counts
        // declared to match it) is refused too; a small one may.
        let zeros = vec![0u8; 32 << 20];
        let (head, body) = deflate_array(&zeros, WRITE_BLOCK, 8);
        let bomb = [head, body].concat();
        let err = inflate_array(&bomb, 8, false, zeros.len() as u64).unwrap_err();
        assert!(err.contains("not mesh data"), "{err}");
        let small = vec![10u8; 1 << 20];
        let (head, body) = deflate_array(&small, WRITE_BLOCK, 8);
        let types = [head, body].concat();
        assert_eq!(
            inflate_array(&types, 8, false, small.len() as u64).unwrap(),
            small
        );
        // Truncated blocks and corrupt streams are errors, not panics.
        for cut in [0, 3, 12, h, packed.len() - 1] {
            assert!(
                inflate_array(&packed[..cut], 4, false, need).is_err(),
                "cut {cut}"
            );
        }
        let mut corrupt = packed.clone();
        corrupt[h + 2] ^= 0xff;
        assert!(inflate_array(&corrupt, 4, false, need).is_err());
    }
}
