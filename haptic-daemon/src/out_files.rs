//! The files a command writes, checked against each other and against
//! the files it reads before anything is opened: one path named twice
//! interleaved two streams into one file, and `--record` naming the
//! replayed trajectory overwrote it.

use anyhow::{Result, bail};
use std::path::{Path, PathBuf};

/// Whether two output paths name one file (which may not exist yet): their
/// directories resolved, then their names compared.
pub(crate) fn same_file(a: &Path, b: &Path) -> bool {
    let resolved = |p: &Path| {
        let dir = match p.parent() {
            Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
            _ => PathBuf::from("."),
        };
        let dir = std::fs::canonicalize(&dir).unwrap_or(dir);
        p.file_name().map(|n| dir.join(n))
    };
    match (std::fs::canonicalize(a), std::fs::canonicalize(b)) {
        (Ok(x), Ok(y)) => x == y,
        _ => {
            let a = resolved(a);
            a.is_some() && a == resolved(b)
        }
    }
}

/// Refuses any two of `named` (flag, path) that name one file, outputs
/// among themselves and outputs against `inputs`.
pub(crate) fn distinct(
    outputs: &[(&str, Option<&Path>)],
    inputs: &[(&str, Option<&Path>)],
) -> Result<()> {
    for (i, (flag_a, a)) in outputs.iter().enumerate() {
        for (flag_b, b) in outputs[i + 1..].iter().chain(inputs) {
            if let (Some(a), Some(b)) = (a, b)
                && same_file(a, b)
            {
                bail!(
                    "{flag_a} and {flag_b} name the same file ({}): give each its own",
                    a.display()
                );
            }
        }
    }
    Ok(())
}
