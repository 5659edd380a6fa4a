//! The structure the code keeps (ARCHITECTURE.md, "Rules"): inside the
//! `tissue` crate, at every level of the module tree (the crate's top
//! modules, the children of `contact`, of `contact::penalty`, ...) the
//! sibling modules import each other without a cycle (a module may use its
//! parent's items and its children, which is the tree itself), and the integrators (`tensor_mass`, `backend`) import nothing of
//! `contact`, which implements their force term
//! (`tissue::tensor_mass::ForceTerm`); no source file is a `#[path]`
//! sibling of its module (a module with children is a folder).
//!
//! Imports are read from the source text, through re-exports (a
//! `contact::ToolPose` is the `contact::instrument` module's): every
//! `crate::`, `super::` or `self::` path outside
//! comments and unit tests (a `tests.rs`, a test fixture, an inline
//! `mod tests`), where test code may reach across to check a whole path.

use std::collections::{BTreeMap, BTreeSet};
use std::fs;
use std::path::Path;
use system_tests::{files_with_extension, workspace_root};

/// The production text of a source file: no unit-test module, no comment.
fn production_lines(path: &Path) -> Vec<String> {
    let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
    if name == "tests.rs" || name == "fixtures.rs" {
        return Vec::new();
    }
    let text = fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let text = match text.find("#[cfg(test)]\nmod tests {") {
        Some(i) => &text[..i],
        None => &text[..],
    };
    text.lines()
        .map(str::trim)
        .filter(|l| !l.starts_with("//"))
        .map(str::to_owned)
        .collect()
}

/// The module paths a line names through `crate::`, `super::` or
/// `self::` (also each item of a `use crate::{a, b::c}` group), as written.
fn named_paths(line: &str) -> Vec<Vec<String>> {
    fn ident(s: &str) -> String {
        s.chars()
            .take_while(|c| c.is_alphanumeric() || *c == '_')
            .collect()
    }
    let mut out = Vec::new();
    let bytes = line.as_bytes();
    let mut i = 0;
    while i < line.len() {
        let rest = &line[i..];
        let starts_word = i == 0 || !(bytes[i - 1].is_ascii_alphanumeric() || bytes[i - 1] == b'_');
        let root = ["crate::", "super::", "self::"]
            .into_iter()
            .find(|r| rest.starts_with(r));
        let (Some(root), true) = (root, starts_word) else {
            i += rest.chars().next().map_or(1, char::len_utf8);
            continue;
        };
        let mut path = vec![root.trim_end_matches("::").to_owned()];
        let mut tail = &rest[root.len()..];
        loop {
            if let Some(group) = tail.strip_prefix('{') {
                let end = group.find('}').unwrap_or(group.len());
                for item in group[..end].split(',') {
                    let mut p = path.clone();
                    for word in item.trim().split("::") {
                        let head = ident(word);
                        if head.is_empty() || head != word.trim() {
                            if !head.is_empty() {
                                p.push(head);
                            }
                            break;
                        }
                        p.push(head);
                    }
                    if p.len() > path.len() {
                        out.push(p);
                    }
                }
                path.clear();
                tail = &group[end..];
                break;
            }
            let head = ident(tail);
            if head.is_empty() {
                break;
            }
            tail = &tail[head.len()..];
            path.push(head);
            match tail.strip_prefix("::") {
                Some(t) => tail = t,
                None => break,
            }
        }
        if path.len() > 1 {
            out.push(path);
        }
        i = line.len() - tail.len();
    }
    out
}

/// The absolute module path `path` names from inside module `module`.
fn resolve(module: &[String], path: &[String]) -> Vec<String> {
    let mut at = module.to_vec();
    let mut rest = path;
    match rest.first().map(String::as_str) {
        Some("crate") => {
            at.clear();
            rest = &rest[1..];
        }
        Some("self") => rest = &rest[1..],
        _ => {}
    }
    while rest.first().map(String::as_str) == Some("super") {
        at.pop();
        rest = &rest[1..];
    }
    at.extend(rest.iter().cloned());
    at
}

/// The module path of a source file under `src` (`a/b/mod.rs` and
/// `a/b.rs` are both `a::b`; `lib.rs` is the crate root).
fn module_of(src: &Path, file: &Path) -> Vec<String> {
    let rel = file.strip_prefix(src).expect("under src");
    let mut parts: Vec<String> = rel
        .components()
        .map(|c| c.as_os_str().to_string_lossy().into_owned())
        .collect();
    if let Some(last) = parts.last_mut() {
        *last = last.trim_end_matches(".rs").to_owned();
    }
    if matches!(parts.last().map(String::as_str), Some("mod" | "lib")) {
        parts.pop();
    }
    parts
}

/// The items a module re-exports (`pub use a::b::{C, D as E};`): the
/// path they are named by (`module::C`) -> the path they come from.
fn reexports(module: &[String], line: &str, out: &mut BTreeMap<Vec<String>, Vec<String>>) {
    let Some(at) = line.find("use ") else { return };
    if !line.starts_with("pub") || !line[..at].trim_end().ends_with(['b', ')']) {
        return;
    }
    let text = line[at + 4..].trim_end_matches(';').trim();
    let (prefix, items) = match text.find('{') {
        Some(i) => (
            text[..i].trim_end_matches("::"),
            text[i + 1..]
                .trim_end_matches('}')
                .split(',')
                .collect::<Vec<_>>(),
        ),
        None => match text.rfind("::") {
            Some(i) => (&text[..i], vec![&text[i + 2..]]),
            None => return,
        },
    };
    let prefix: Vec<String> = prefix.split("::").map(str::to_owned).collect();
    // A bare prefix is a child module's path, which `resolve` gives too.
    let from = resolve(module, &prefix);
    for item in items {
        let mut words = item.split(" as ").map(str::trim);
        let (Some(name), alias) = (words.next(), words.next()) else {
            continue;
        };
        if name.is_empty() || name == "self" || name == "*" {
            continue;
        }
        let mut named = module.to_vec();
        named.push(alias.unwrap_or(name).to_owned());
        let mut source = from.clone();
        source.push(name.to_owned());
        out.insert(named, source);
    }
}

/// `path` with a re-exported prefix replaced by where it comes from
/// (`contact::ToolPose` -> `contact::instrument::geometry::ToolPose`).
fn through_reexports(
    mut path: Vec<String>,
    table: &BTreeMap<Vec<String>, Vec<String>>,
) -> Vec<String> {
    for _ in 0..8 {
        let Some(n) = (1..=path.len())
            .rev()
            .find(|n| table.contains_key(&path[..*n]))
        else {
            break;
        };
        let mut real = table[&path[..n]].clone();
        real.extend(path[n..].iter().cloned());
        path = real;
    }
    path
}

/// A folder's import graph: sibling module -> the siblings it uses.
type Graph = BTreeMap<String, BTreeSet<String>>;

/// tissue's import graphs, one per module with children (`""` the crate
/// root, `"contact::penalty"` ...): inside each, which child module uses
/// which of its siblings. A child using its parent's own items, or a
/// parent its children, is the tree itself, not an edge.
fn tissue_graphs() -> BTreeMap<String, Graph> {
    let src = workspace_root().join("sim-server/tissue/src");
    let files: Vec<(Vec<String>, Vec<String>)> = files_with_extension(&src, "rs")
        .into_iter()
        .map(|f| (module_of(&src, &f), production_lines(&f)))
        .filter(|(m, _)| m.first().map(String::as_str) != Some("prelude"))
        .collect();
    let mut table = BTreeMap::new();
    for (module, lines) in &files {
        for line in lines {
            reexports(module, line, &mut table);
        }
    }
    let mut graphs: BTreeMap<String, Graph> = BTreeMap::new();
    for (module, lines) in &files {
        for line in lines {
            for path in named_paths(line) {
                let target = through_reexports(resolve(module, &path), &table);
                let common = module
                    .iter()
                    .zip(&target)
                    .take_while(|(a, b)| a == b)
                    .count();
                if common < module.len() && common < target.len() {
                    graphs
                        .entry(module[..common].join("::"))
                        .or_default()
                        .entry(module[common].clone())
                        .or_default()
                        .insert(target[common].clone());
                }
            }
        }
    }
    graphs
}

/// tissue's top-level graph: module -> the top-level modules it uses.
fn tissue_graph() -> Graph {
    tissue_graphs().remove("").unwrap_or_default()
}

/// A cycle through `graph`, if it has one (depth-first search).
fn find_cycle(graph: &BTreeMap<String, BTreeSet<String>>) -> Option<Vec<String>> {
    fn visit(
        node: &str,
        graph: &BTreeMap<String, BTreeSet<String>>,
        path: &mut Vec<String>,
        done: &mut BTreeSet<String>,
    ) -> Option<Vec<String>> {
        if let Some(i) = path.iter().position(|p| p == node) {
            let mut cycle = path[i..].to_vec();
            cycle.push(node.to_owned());
            return Some(cycle);
        }
        if done.contains(node) {
            return None;
        }
        path.push(node.to_owned());
        for next in graph.get(node).into_iter().flatten() {
            if let Some(c) = visit(next, graph, path, done) {
                return Some(c);
            }
        }
        path.pop();
        done.insert(node.to_owned());
        None
    }
    let mut done = BTreeSet::new();
    graph
        .keys()
        .find_map(|k| visit(k, graph, &mut Vec::new(), &mut done))
}

#[test]
fn tissue_s_top_level_modules_import_each_other_without_a_cycle() {
    let graph = tissue_graph();
    assert!(graph.contains_key("contact") && graph.contains_key("tensor_mass"));
    // The reader sees the known imports (the test would pass vacuously on
    // a parser that saw none).
    assert!(graph["contact"].contains("tensor_mass"), "{graph:?}");
    assert!(graph["backend"].contains("tensor_mass"), "{graph:?}");
    if let Some(cycle) = find_cycle(&graph) {
        panic!("tissue's modules import in a cycle: {}", cycle.join(" -> "));
    }
}

#[test]
fn inside_every_folder_of_tissue_the_modules_import_each_other_without_a_cycle() {
    let graphs = tissue_graphs();
    // The reader sees nested imports (e.g. the penalty law's sampling uses
    // its field), so a pass is not a parser that saw nothing.
    assert!(
        graphs
            .get("contact::penalty")
            .is_some_and(|g| g.get("sampling").is_some_and(|s| s.contains("field"))),
        "{graphs:?}"
    );
    assert!(graphs.len() > 5, "{graphs:?}");
    for (folder, graph) in &graphs {
        if let Some(cycle) = find_cycle(graph) {
            let folder = if folder.is_empty() { "tissue" } else { folder };
            panic!(
                "inside {folder}, modules import in a cycle: {}",
                cycle.join(" -> ")
            );
        }
    }
}

#[test]
fn the_integrators_import_nothing_of_contact() {
    let graph = tissue_graph();
    for integrator in ["tensor_mass", "backend"] {
        assert!(
            !graph[integrator].contains("contact"),
            "{integrator} imports contact: the force term it calls is tensor_mass::ForceTerm"
        );
    }
}

#[test]
fn the_cycle_finder_finds_a_cycle() {
    let mut graph: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    graph.entry("a".into()).or_default().insert("b".into());
    graph.entry("b".into()).or_default().insert("c".into());
    assert_eq!(find_cycle(&graph), None);
    graph.entry("c".into()).or_default().insert("a".into());
    assert_eq!(find_cycle(&graph).map(|c| c.len()), Some(4));
    let seen =
        named_paths("use crate::{math::Real, ids::VertexId}; let x = super::super::tool::T;");
    assert_eq!(seen.len(), 3, "{seen:?}");
    let module: Vec<String> = ["contact", "penalty", "field"].map(String::from).to_vec();
    let at = |p: &Vec<String>| resolve(&module, p).join("::");
    assert_eq!(at(&seen[0]), "math::Real");
    assert_eq!(at(&seen[1]), "ids::VertexId");
    assert_eq!(at(&seen[2]), "contact::tool::T");
    let mut table = BTreeMap::new();
    let contact = vec!["contact".to_owned()];
    reexports(
        &contact,
        "pub use instrument::{Plane, Segment as Seg};",
        &mut table,
    );
    reexports(&contact, "pub(crate) use crate::math::Vec3;", &mut table);
    let named = |p: &str| p.split("::").map(str::to_owned).collect::<Vec<_>>();
    assert_eq!(
        through_reexports(named("contact::Seg"), &table).join("::"),
        "contact::instrument::Segment"
    );
    assert_eq!(
        through_reexports(named("contact::Vec3"), &table).join("::"),
        "math::Vec3"
    );
    let src = Path::new("/s");
    assert_eq!(
        module_of(src, Path::new("/s/contact/penalty/field/mod.rs")),
        module
    );
    assert_eq!(module_of(src, Path::new("/s/lib.rs")), Vec::<String>::new());
}

#[test]
fn no_source_file_is_a_path_sibling_of_its_module() {
    let root = workspace_root();
    let files = ["sim-server", "haptic-daemon", "shared", "viewer", "tests"]
        .iter()
        .flat_map(|crate_dir| files_with_extension(&root.join(crate_dir), "rs"));
    let offenders: Vec<String> = files
        .filter(|f| {
            fs::read_to_string(f)
                .map(|t| t.lines().any(|l| l.trim_start().starts_with("#[path")))
                .unwrap_or(false)
        })
        .map(|f| f.strip_prefix(&root).unwrap_or(&f).display().to_string())
        .collect();
    assert!(offenders.is_empty(), "#[path] modules: {offenders:?}");
}
