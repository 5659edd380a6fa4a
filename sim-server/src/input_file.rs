//! Reading an input file (a scene, a mesh) whole, within a bound: a path
//! that is not a regular file (a device such as `/dev/zero`, a pipe) or a
//! file larger than its kind can be is an error before memory grows with
//! it (a scene symlinked to `/dev/zero` grew to 2 GB and ran out of memory).

use std::io::{Error, ErrorKind, Read};
use std::path::Path;

/// The largest scene file (bytes): a scene is a page of TOML.
pub const MAX_SCENE_BYTES: u64 = 16 << 20;
/// The largest mesh file (bytes): a million tetrahedra in ASCII Gmsh are
/// about 100 MB.
pub const MAX_MESH_BYTES: u64 = 4 << 30;

/// The bytes of the regular file at `path`, refused past `limit` bytes.
pub fn read_at_most(path: &Path, limit: u64) -> std::io::Result<Vec<u8>> {
    let file = std::fs::File::open(path)?;
    let meta = file.metadata()?;
    if !meta.is_file() {
        return Err(Error::new(
            ErrorKind::InvalidInput,
            "not a regular file (a device, a pipe or a directory)",
        ));
    }
    if meta.len() > limit {
        return Err(too_large(limit));
    }
    let mut bytes = Vec::with_capacity(meta.len() as usize);
    // A file growing while it is read is still held to the bound.
    file.take(limit + 1).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > limit {
        return Err(too_large(limit));
    }
    Ok(bytes)
}

fn too_large(limit: u64) -> Error {
    Error::new(
        ErrorKind::FileTooLarge,
        format!(
            "larger than {} MiB, more than such a file can be",
            limit >> 20
        ),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn devices_and_oversized_files_are_refused() {
        let err = read_at_most(Path::new("/dev/zero"), 1 << 20).unwrap_err();
        assert_eq!(err.kind(), ErrorKind::InvalidInput, "{err}");
        let dir = std::env::temp_dir().join(format!("hapsim-input-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let f = dir.join("big.toml");
        std::fs::write(&f, vec![b'#'; 2048]).unwrap();
        assert_eq!(read_at_most(&f, 4096).unwrap().len(), 2048);
        let err = read_at_most(&f, 1024).unwrap_err();
        assert_eq!(err.kind(), ErrorKind::FileTooLarge, "{err}");
        let err = read_at_most(&dir, 1024).unwrap_err();
        assert!(
            err.kind() == ErrorKind::InvalidInput || err.kind() == ErrorKind::IsADirectory,
            "{err}"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
