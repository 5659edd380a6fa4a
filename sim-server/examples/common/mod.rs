//! What the examples share: their flags' comma-separated numbers.

use anyhow::{Context, Result};

/// The finite numbers of a flag's comma-separated `text`, or which one is not.
pub fn numbers(flag: &str, text: &str) -> Result<Vec<f64>> {
    text.split(',')
        .map(|x| {
            x.trim()
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .with_context(|| format!("{flag}: {x:?} is not a number"))
        })
        .collect()
}
