//! The structure the code keeps (ARCHITECTURE.md, "Rules"): inside the
//! `tissue` crate, the top-level modules import each other without a
//! cycle, and the integrators (`tensor_mass`, `backend`) import nothing of
//! `contact`, which implements their force term
//! (`tissue::tensor_mass::ForceTerm`); no source file is a `#[path]`
//! sibling of its module (a module with children is a folder).
//!
//! Imports are read from the source text: every `crate::NAME` outside
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

/// The top-level modules a line names through `crate::` (also inside a
/// `use crate::{a, b::c}` group).
fn crate_modules(line: &str, out: &mut BTreeSet<String>) {
    let mut rest = line;
    while let Some(i) = rest.find("crate::") {
        rest = &rest[i + "crate::".len()..];
        if let Some(group) = rest.strip_prefix('{') {
            let end = group.find('}').unwrap_or(group.len());
            for item in group[..end].split(',') {
                let head: String = item
                    .trim()
                    .chars()
                    .take_while(|c| c.is_alphanumeric() || *c == '_')
                    .collect();
                if !head.is_empty() {
                    out.insert(head);
                }
            }
        } else {
            let head: String = rest
                .chars()
                .take_while(|c| c.is_alphanumeric() || *c == '_')
                .collect();
            if !head.is_empty() {
                out.insert(head);
            }
        }
    }
}

/// tissue's module graph: top-level module -> the top-level modules it uses.
fn tissue_graph() -> BTreeMap<String, BTreeSet<String>> {
    let src = workspace_root().join("sim-server/tissue/src");
    let files = files_with_extension(&src, "rs");
    let mut graph: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for file in files {
        let rel = file.strip_prefix(&src).expect("under src");
        let first = rel.components().next().expect("a path");
        let top = first
            .as_os_str()
            .to_string_lossy()
            .trim_end_matches(".rs")
            .to_owned();
        if top == "lib" || top == "prelude" {
            continue;
        }
        let uses = graph.entry(top.clone()).or_default();
        for line in production_lines(&file) {
            crate_modules(&line, uses);
        }
        uses.remove(&top);
    }
    graph
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
    let mut seen = BTreeSet::new();
    crate_modules("use crate::{math::Real, ids::VertexId};", &mut seen);
    crate_modules("let x = crate::contact::Tools::new();", &mut seen);
    assert_eq!(
        seen.into_iter().collect::<Vec<_>>(),
        ["contact", "ids", "math"]
    );
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
