//! The documents hold together: every relative link in the repository's
//! Markdown (README, ARCHITECTURE, docs/, the crates' READMEs) names a
//! file that exists, and the README stays a quick start (at most 200
//! lines, the two commands first, CI's test command in it).

use std::fs;
use system_tests::{files_with_extension, workspace_root};

/// The targets of `](target)` links in `text`, without their `#anchor`.
fn link_targets(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut rest = text;
    while let Some(i) = rest.find("](") {
        rest = &rest[i + 2..];
        let end = rest.find(')').unwrap_or(rest.len());
        let target = rest[..end].split('#').next().unwrap_or("").trim();
        if !target.is_empty() && !target.contains("://") && !target.starts_with("mailto:") {
            out.push(target.to_owned());
        }
    }
    out
}

#[test]
fn every_relative_link_in_the_documents_resolves() {
    let root = workspace_root();
    let files = files_with_extension(&root, "md");
    assert!(
        files.len() > 20,
        "found only {} Markdown files",
        files.len()
    );
    let mut checked = 0;
    let mut broken = Vec::new();
    for file in &files {
        let text = fs::read_to_string(file).expect("readable Markdown");
        let dir = file.parent().expect("a file has a folder");
        for target in link_targets(&text) {
            checked += 1;
            if !dir.join(&target).exists() {
                let from = file.strip_prefix(&root).unwrap_or(file).display();
                broken.push(format!("{from}: {target}"));
            }
        }
    }
    assert!(
        checked > 100,
        "only {checked} links found: is the reader broken?"
    );
    assert!(broken.is_empty(), "broken links:\n{}", broken.join("\n"));
}

#[test]
fn the_link_reader_finds_targets_and_skips_web_addresses() {
    let text = "see [a](docs/a.md#x), [b](https://e.org/b.md) and [c](../c.md).";
    assert_eq!(link_targets(text), ["docs/a.md", "../c.md"]);
}

#[test]
fn the_readme_is_a_quick_start_with_the_two_commands() {
    let root = workspace_root();
    let readme = fs::read_to_string(root.join("README.md")).expect("README.md");
    assert!(
        readme.lines().count() <= 200,
        "README.md: {} lines",
        readme.lines().count()
    );
    let first_block = readme.split("```sh").nth(1).expect("a sh block");
    let first_block = first_block.split("```").next().unwrap_or("");
    assert!(first_block.contains("scripts/demo.sh"), "{first_block}");
    let test_command = "cargo test --workspace --release --locked";
    assert!(first_block.contains(test_command), "{first_block}");
    let ci = fs::read_to_string(root.join(".ci/run")).expect(".ci/run");
    assert!(
        ci.contains(test_command),
        ".ci/run does not run the README's tests"
    );
    let architecture = fs::read_to_string(root.join("ARCHITECTURE.md")).expect("ARCHITECTURE.md");
    assert!(
        architecture.lines().count() <= 80,
        "ARCHITECTURE.md: {} lines",
        architecture.lines().count()
    );
}
