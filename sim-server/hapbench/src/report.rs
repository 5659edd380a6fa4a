//! `hapbench report`: a benchmark's JSON (`--json` of `hapbench ...` or
//! `sim-server bench`, stamped with its provenance) rendered as a results
//! page in Markdown, so that `docs/results/measured/` is written by the
//! benchmarks from what they measured, with date, commit and machine,
//! never typed by hand.
//!
//! The layout follows the JSON: its scalar figures in one table; each
//! object of objects (per method, per backend) a table with a row per
//! entry; each array of objects (a sweep, the stability cases) a table with
//! a row per element. Nested objects become dotted columns, arrays of
//! numbers one cell. Numbers are shown to six significant digits (the JSON
//! beside keeps them all).

use anyhow::{Context, Result};
use serde_json::{Map, Value};
use sim_server::provenance::Provenance;
use std::collections::BTreeSet;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// `hapbench report` arguments.
#[derive(clap::Args)]
pub struct Args {
    /// Benchmark JSON files (`--json` of `hapbench ...` or `sim-server
    /// bench`).
    #[arg(required = true)]
    pub json: Vec<PathBuf>,
    /// Directory for the pages: one `NAME.md` per `NAME.json`.
    #[arg(long)]
    pub out: PathBuf,
}

/// Columns at most in one table (a wider record is cut, and says so).
const MAX_COLUMNS: usize = 14;

pub fn run(args: &Args) -> Result<()> {
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    for path in &args.json {
        let page = render_file(path)?;
        let stem = path
            .file_stem()
            .map_or("results".into(), |s| s.to_string_lossy());
        let out = args.out.join(format!("{stem}.md"));
        std::fs::write(&out, page).with_context(|| format!("cannot write {}", out.display()))?;
        println!("{} -> {}", path.display(), out.display());
    }
    Ok(())
}

/// The page for the JSON file `path`.
fn render_file(path: &Path) -> Result<String> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    let value: Value =
        serde_json::from_str(&text).with_context(|| format!("{}: not JSON", path.display()))?;
    let name = path.file_name().map_or("?".into(), |s| s.to_string_lossy());
    render(&name, &value).with_context(|| format!("{}", path.display()))
}

/// The page for `value`, read from the file `name`.
pub fn render(name: &str, value: &Value) -> Result<String> {
    let Value::Object(top) = value else {
        anyhow::bail!("not a benchmark report (a JSON object)");
    };
    let provenance: Provenance = match top.get("provenance") {
        Some(p) => serde_json::from_value(p.clone())
            .context("`provenance` is not a date, commit, machine and command")?,
        None => anyhow::bail!(
            "no `provenance`: written before the benchmarks stamped their JSON, or by another tool; run the benchmark again with --json"
        ),
    };
    let mut page = String::new();
    let title = name.strip_suffix(".json").unwrap_or(name);
    let _ = writeln!(page, "# Measured: {title}\n");
    let _ = writeln!(
        page,
        "Written by `hapbench report` from `{name}`; not edited by hand (run the command below with\n`--json`, then `hapbench report`, to measure again).\n"
    );
    let _ = writeln!(page, "| | |\n|---|---|");
    let _ = writeln!(page, "| date (UTC) | {} |", provenance.date_utc);
    let _ = writeln!(page, "| commit | `{}` |", provenance.commit);
    let _ = writeln!(
        page,
        "| machine | {} |",
        cell_text(&provenance.machine.line())
    );
    let _ = writeln!(page, "| command | `{}` |", cell_text(&provenance.command));
    let figures: Vec<(String, String)> = (top.iter())
        .filter(|(k, v)| *k != "provenance" && is_cell(v))
        .map(|(k, v)| (k.clone(), format_cell(v)))
        .collect();
    if !figures.is_empty() {
        let _ = writeln!(page, "\n## Figures\n\n| figure | value |\n|---|---|");
        for (k, v) in figures {
            let _ = writeln!(page, "| `{k}` | {v} |");
        }
    }
    for (key, v) in top
        .iter()
        .filter(|(k, v)| *k != "provenance" && !is_cell(v))
    {
        let rows: Vec<(String, Map<String, Value>)> = match v {
            Value::Object(m) if m.values().all(Value::is_object) => {
                (m.iter()).map(|(k, v)| (k.clone(), flatten(v))).collect()
            }
            Value::Object(m) => vec![(key.clone(), flatten(&Value::Object(m.clone())))],
            Value::Array(a) => (a.iter().enumerate())
                .map(|(i, v)| (i.to_string(), flatten(v)))
                .collect(),
            _ => continue,
        };
        let _ = writeln!(page, "\n## {key}\n");
        table(&mut page, key, &rows);
    }
    Ok(page)
}

/// A table with a row per entry of `rows` and a column per figure any of
/// them has (in first-seen order).
fn table(page: &mut String, key: &str, rows: &[(String, Map<String, Value>)]) {
    let mut seen = BTreeSet::new();
    let mut columns: Vec<&str> = Vec::new();
    for (_, r) in rows {
        for k in r.keys() {
            if seen.insert(k.as_str()) {
                columns.push(k);
            }
        }
    }
    let cut = columns.len().saturating_sub(MAX_COLUMNS);
    columns.truncate(MAX_COLUMNS);
    let _ = write!(page, "| {key} |");
    for c in &columns {
        let _ = write!(page, " `{c}` |");
    }
    let _ = write!(page, "\n|---|");
    for _ in &columns {
        let _ = write!(page, "---|");
    }
    let _ = writeln!(page);
    for (name, r) in rows {
        let _ = write!(page, "| {} |", cell_text(name));
        for c in &columns {
            let _ = write!(page, " {} |", r.get(*c).map_or(String::new(), format_cell));
        }
        let _ = writeln!(page);
    }
    if cut > 0 {
        let _ = writeln!(page, "\n({cut} more columns in the JSON.)");
    }
}

/// `v`'s leaves under dotted names (arrays of numbers and strings kept as
/// one cell; arrays of objects by index).
fn flatten(v: &Value) -> Map<String, Value> {
    fn walk(prefix: &str, v: &Value, out: &mut Map<String, Value>) {
        match v {
            Value::Object(m) => {
                for (k, v) in m {
                    let name = if prefix.is_empty() {
                        k.clone()
                    } else {
                        format!("{prefix}.{k}")
                    };
                    walk(&name, v, out);
                }
            }
            Value::Array(a) if !is_cell(v) => {
                for (i, v) in a.iter().enumerate() {
                    walk(&format!("{prefix}.{i}"), v, out);
                }
            }
            _ => {
                out.insert(
                    if prefix.is_empty() {
                        "value".into()
                    } else {
                        prefix.into()
                    },
                    v.clone(),
                );
            }
        }
    }
    let mut out = Map::new();
    walk("", v, &mut out);
    out
}

/// Whether `v` fits one cell: a scalar, or an array of scalars.
fn is_cell(v: &Value) -> bool {
    match v {
        Value::Object(_) => false,
        Value::Array(a) => a.iter().all(|x| !x.is_object() && !x.is_array()),
        _ => true,
    }
}

/// A cell's text: numbers to six significant digits, arrays as `a / b`.
fn format_cell(v: &Value) -> String {
    match v {
        Value::Number(n) => match (n.as_i64(), n.as_u64(), n.as_f64()) {
            (Some(i), _, _) => i.to_string(),
            (_, Some(u), _) => u.to_string(),
            (_, _, Some(x)) => number(x),
            _ => n.to_string(),
        },
        Value::String(s) => cell_text(s),
        Value::Bool(b) => b.to_string(),
        Value::Null => "-".into(),
        Value::Array(a) => a.iter().map(format_cell).collect::<Vec<_>>().join(" / "),
        Value::Object(_) => String::new(),
    }
}

/// `x` to six significant digits, in exponent form outside 1e-3..1e6.
fn number(x: f64) -> String {
    if x == 0.0 || !x.is_finite() {
        return x.to_string();
    }
    let a = x.abs();
    if !(1e-3..1e6).contains(&a) {
        return format!("{x:.5e}");
    }
    let digits = (5 - a.log10().floor() as i32).max(0) as usize;
    let s = format!("{x:.digits$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

/// `s` safe in a table cell (pipes escaped, one line).
fn cell_text(s: &str) -> String {
    s.replace('|', "\\|").replace('\n', " ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_keep_six_significant_digits() {
        assert_eq!(number(3.848512345), "3.84851");
        assert_eq!(number(0.0123456789), "0.0123457");
        assert_eq!(number(250.0), "250");
        assert_eq!(number(1234567.0), "1.23457e6");
        assert_eq!(number(-2.5e-5), "-2.50000e-5");
    }

    #[test]
    fn a_report_without_provenance_is_refused() {
        let err = render("x.json", &serde_json::json!({ "a": 1 })).unwrap_err();
        assert!(format!("{err:#}").contains("no `provenance`"), "{err:#}");
    }
}
