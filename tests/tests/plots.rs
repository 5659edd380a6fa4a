//! Every plot in `docs/hapbench/` (written by `hapbench ... --plot`) is
//! readable: its legend lists every series, in order; no two series share
//! both colour and marker; the legend and the title fit inside the page.
//!
//! The charts write their structure as data (`hapbench`'s `plot.rs`):
//! `<g class="series" data-name=.. data-color=.. data-marker=..>` per
//! series and `<g class="legend-entry" ...>` per legend entry, so this
//! reads the SVG text and needs no renderer.

use std::collections::HashSet;
use std::path::{Path, PathBuf};

/// Width of a character at 12 px sans-serif, generous (the widest
/// lower-case letters are about 0.6 em; digits 0.56 em).
const CHAR_PX_12: f64 = 7.5;
/// The same at the title's 15 px.
const CHAR_PX_15: f64 = 8.5;

fn plots_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/hapbench")
}

/// The value of `attr="..."` in `tag` (an element's opening text).
fn attr<'a>(tag: &'a str, attr: &str) -> Option<&'a str> {
    let key = format!(" {attr}=\"");
    let start = tag.find(&key)? + key.len();
    let len = tag[start..].find('"')?;
    Some(&tag[start..start + len])
}

/// The opening tags of the `<g class="{class}" ...>` groups, in order, with
/// the text after each (to its `</g>`).
fn groups<'a>(svg: &'a str, class: &str) -> Vec<(&'a str, &'a str)> {
    let key = format!("<g class=\"{class}\"");
    let mut out = Vec::new();
    let mut rest = svg;
    while let Some(i) = rest.find(&key) {
        let from = &rest[i..];
        let open_end = from.find('>').map_or(from.len(), |k| k + 1);
        let close = from.find("</g>").unwrap_or(from.len());
        out.push((&from[..open_end], &from[open_end..close.max(open_end)]));
        rest = &from[open_end..];
    }
    out
}

/// The characters a reader sees of SVG text (entities as one each).
fn visible_len(text: &str) -> usize {
    let mut n = 0;
    let mut in_entity = false;
    for c in text.chars() {
        match c {
            '&' => {
                in_entity = true;
                n += 1;
            }
            ';' if in_entity => in_entity = false,
            _ if in_entity => {}
            _ => n += 1,
        }
    }
    n
}

/// What is wrong with one plot (empty: nothing).
fn faults(name: &str, svg: &str) -> Vec<String> {
    let mut out = Vec::new();
    let Some(root) = svg.find("<svg").map(|i| &svg[i..]) else {
        return vec![format!("{name}: not an SVG")];
    };
    let width: f64 = attr(root, "width")
        .and_then(|w| w.parse().ok())
        .unwrap_or(0.0);
    let series = groups(svg, "series");
    let legend = groups(svg, "legend-entry");
    if series.is_empty() {
        out.push(format!(
            "{name}: no series groups (written by an old hapbench?)"
        ));
    }
    let names = |g: &[(&str, &str)]| -> Vec<String> {
        g.iter()
            .map(|(t, _)| attr(t, "data-name").unwrap_or("?").to_string())
            .collect()
    };
    if names(&series) != names(&legend) {
        out.push(format!(
            "{name}: series {:?} but legend entries {:?}",
            names(&series),
            names(&legend)
        ));
    }
    let mut seen = HashSet::new();
    for (tag, _) in &series {
        let style = (attr(tag, "data-color"), attr(tag, "data-marker"));
        if style.0.is_none() || style.1.is_none() {
            out.push(format!("{name}: a series without colour or marker: {tag}"));
        } else if !seen.insert(style) {
            out.push(format!(
                "{name}: two series share colour {} and marker {}",
                style.0.unwrap_or("?"),
                style.1.unwrap_or("?")
            ));
        }
    }
    for (tag, body) in &legend {
        let Some(t) = body.find("<text") else {
            out.push(format!("{name}: legend entry without text: {tag}"));
            continue;
        };
        let text_tag = &body[t..];
        let x: f64 = attr(text_tag, "x")
            .and_then(|x| x.parse().ok())
            .unwrap_or(f64::INFINITY);
        let content = text_tag
            .split_once('>')
            .map_or("", |(_, r)| r.split('<').next().unwrap_or(""));
        let right = x + CHAR_PX_12 * visible_len(content) as f64;
        if right > width {
            out.push(format!(
                "{name}: legend text {content:?} ends at {right:.0} px, past the page's {width} px"
            ));
        }
    }
    if let Some(t) = svg.find("font-size=\"15\">") {
        let title = svg[t + 15..].split('<').next().unwrap_or("");
        let x = svg[..t]
            .rfind("<text")
            .and_then(|k| attr(&svg[k..t + 15], "x"))
            .and_then(|x| x.parse::<f64>().ok())
            .unwrap_or(0.0);
        let right = x + CHAR_PX_15 * visible_len(title) as f64;
        if right > width || !svg[..t].ends_with("<text x=\"10\" y=\"22\" ") {
            out.push(format!(
                "{name}: the title {title:?} (to {right:.0} px) does not fit {width} px from the left edge"
            ));
        }
    }
    out
}

#[test]
fn every_plot_lists_each_series_once_in_its_legend_and_no_two_look_alike() {
    let dir = plots_dir();
    let mut checked = 0;
    let mut all = Vec::new();
    for entry in std::fs::read_dir(&dir).expect("docs/hapbench exists") {
        let path = entry.expect("readable directory").path();
        if path.extension().is_some_and(|e| e == "svg") {
            let svg = std::fs::read_to_string(&path).expect("readable plot");
            all.extend(faults(&path.display().to_string(), &svg));
            checked += 1;
        }
    }
    assert!(checked >= 5, "only {checked} plots in {}", dir.display());
    assert!(all.is_empty(), "{}", all.join("\n"));
}

#[test]
fn the_checks_catch_a_shared_style_a_missing_legend_entry_and_a_clipped_name() {
    let ok = r##"<svg xmlns="http://www.w3.org/2000/svg" width="300" height="100"><text x="10" y="22" font-size="15">t</text><g class="series" data-name="a" data-color="#000" data-marker="circle"></g><g class="legend-entry" data-name="a" data-color="#000" data-marker="circle"><text x="200" y="4">a</text></g></svg>"##;
    assert!(faults("ok", ok).is_empty(), "{:?}", faults("ok", ok));
    let shared = ok.replace(
        "</svg>",
        r##"<g class="series" data-name="b" data-color="#000" data-marker="circle"></g><g class="legend-entry" data-name="b" data-color="#000" data-marker="circle"><text x="200" y="4">b</text></g></svg>"##,
    );
    assert!(faults("shared", &shared)[0].contains("share colour"));
    let unlisted = ok.replace(
        "</svg>",
        r##"<g class="series" data-name="b" data-color="#111" data-marker="square"></g></svg>"##,
    );
    assert!(faults("unlisted", &unlisted)[0].contains("legend entries"));
    let clipped = ok.replace(">a</text>", ">a rather long name -&gt; here</text>");
    assert!(faults("clipped", &clipped)[0].contains("past the page"));
}
