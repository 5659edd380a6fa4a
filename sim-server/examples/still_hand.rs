//! A probe pressed deep into a box and held perfectly still: the force the
//! simulation publishes over the hold, its mean, spread and extremes, for
//! finding the slip of a coarse surface round a narrow tool (design notes,
//! contact: "a tool narrower than the cells") and what refinement under the
//! tool does to it. In-process, on the explicit tensor-mass backend at a 1 ms
//! step; the same hold through the real processes is in the results.
//!
//! ```sh
//! cargo run --release -p sim-server --example still_hand -- \
//!     [--size-m 0.1,0.04,0.04] [--cell-m 0.005] [--young-pa 30000] \
//!     [--radius-m 0.0025] [--depth-m 0.015] [--at-m 0.05,0.02] \
//!     [--model linear|corotational] [--hold-s 1.5] \
//!     [--refine-cell-m 0.0025 --refine-radius-m 0.0125] [--corotational-radius-m 0.02] \
//!     [--follow-radius-m 0.012] [--tool-refine-radius-m 0.0125] [--slide-m 0.01] [--multirate true]
//! ```
//!
//! The box (nu 0.45, density 1000, damping 20 /s) has its bottom fixed; the
//! probe comes straight down at 10 mm/s to `--depth-m` below the top and is
//! held there `--hold-s`; the statistics are over the last 0.5 s. With
//! `--refine-cell-m` a `[[refine]]` sphere of `--refine-radius-m` round the
//! probe's axis at the top bisects the cells there down to that size; with
//! `--corotational-radius-m` a `[[region]]` sphere there is corotational;
//! `--follow-radius-m` makes the corotational region follow the tip
//! (`[contact] corotational_radius_m`) and `--tool-refine-radius-m` the
//! refined cells (`[contact] refine_radius_m`, cells of the probe's radius).

use anyhow::{Context, Result, bail};
use sim_server::contact::ToolInput;
use sim_server::follow_refine::FollowRefine;
use sim_server::prelude::*;
use sim_server::prepare::prepare;
use sim_server::scene::{SceneSource, build_scene};
use std::path::PathBuf;

mod common;
use common::numbers;
use std::time::Instant;

struct Args {
    size_m: [f64; 3],
    cell_m: f64,
    young_pa: f64,
    radius_m: f64,
    depth_m: f64,
    at_m: [f64; 2],
    model: String,
    hold_s: f64,
    refine_cell_m: Option<f64>,
    refine_radius_m: f64,
    corotational_radius_m: Option<f64>,
    follow_radius_m: Option<f64>,
    tool_refine_radius_m: Option<f64>,
    slide_m: f64,
    multirate: bool,
}

fn parse() -> Result<Args> {
    let mut a = Args {
        size_m: [0.1, 0.04, 0.04],
        cell_m: 0.005,
        young_pa: 30_000.0,
        radius_m: 0.0025,
        depth_m: 0.015,
        at_m: [0.05, 0.02],
        model: "linear".into(),
        hold_s: 1.5,
        refine_cell_m: None,
        refine_radius_m: 0.0125,
        corotational_radius_m: None,
        follow_radius_m: None,
        tool_refine_radius_m: None,
        slide_m: 0.0,
        multirate: false,
    };
    let mut it = std::env::args().skip(1);
    while let Some(flag) = it.next() {
        let value = it.next().with_context(|| format!("{flag} needs a value"))?;
        let one = || -> Result<f64> { Ok(numbers(&flag, &value)?[0]) };
        match flag.as_str() {
            "--size-m" => match numbers(&flag, &value)?[..] {
                [x, y, z] => a.size_m = [x, y, z],
                _ => bail!("--size-m takes x,y,z"),
            },
            "--cell-m" => a.cell_m = one()?,
            "--young-pa" => a.young_pa = one()?,
            "--radius-m" => a.radius_m = one()?,
            "--depth-m" => a.depth_m = one()?,
            "--at-m" => match numbers(&flag, &value)?[..] {
                [x, y] => a.at_m = [x, y],
                _ => bail!("--at-m takes x,y"),
            },
            "--model" => a.model = value,
            "--hold-s" => a.hold_s = one()?,
            "--refine-cell-m" => a.refine_cell_m = Some(one()?),
            "--refine-radius-m" => a.refine_radius_m = one()?,
            "--corotational-radius-m" => a.corotational_radius_m = Some(one()?),
            "--multirate" => {
                a.multirate = match value.as_str() {
                    "true" => true,
                    "false" => false,
                    _ => bail!("--multirate takes true or false, got {value}"),
                }
            }
            "--follow-radius-m" => a.follow_radius_m = Some(one()?),
            "--tool-refine-radius-m" => a.tool_refine_radius_m = Some(one()?),
            "--slide-m" => a.slide_m = one()?,
            _ => bail!(
                "unknown flag {flag}: --size-m, --cell-m, --young-pa, --radius-m, --depth-m, --at-m, --model, --hold-s, --refine-cell-m, --refine-radius-m, --corotational-radius-m, --follow-radius-m, --tool-refine-radius-m, --slide-m, --multirate"
            ),
        }
    }
    if !(a.depth_m > 0.0 && a.depth_m < a.size_m[2]) {
        bail!("--depth-m must lie inside the box's height");
    }
    if !(a.hold_s >= 0.5 && a.hold_s <= 60.0) {
        bail!("--hold-s must lie in 0.5..=60 s");
    }
    Ok(a)
}

fn main() -> Result<()> {
    let a = parse()?;
    let [sx, sy, sz] = a.size_m;
    let (ex, ey) = (sx + 0.001, sy + 0.001);
    let refine = match a.refine_cell_m {
        Some(h) => format!(
            "[[refine]]\nname = \"under the probe\"\nselect = {{ sphere_m = [{x}, {y}, {sz}, {r}] }}\ncell_m = {h}\n",
            x = a.at_m[0],
            y = a.at_m[1],
            r = a.refine_radius_m,
        ),
        None => String::new(),
    };
    let corotational = match a.corotational_radius_m {
        Some(r) => format!(
            "[[region]]\nname = \"round the probe\"\nselect = {{ sphere_m = [{x}, {y}, {sz}, {r}] }}\nmodel = \"corotational\"\n",
            x = a.at_m[0],
            y = a.at_m[1],
        ),
        None => String::new(),
    };
    let mut follow = String::new();
    if let Some(r) = a.follow_radius_m {
        follow += &format!("corotational_radius_m = {r}\n");
    }
    if let Some(r) = a.tool_refine_radius_m {
        follow += &format!("refine_radius_m = {r}\n");
    }
    if !follow.is_empty() {
        follow.insert_str(0, "[contact]\n");
    }
    let text = format!(
        r#"
[mesh]
generate = {{ shape = "box", size_m = [{sx}, {sy}, {sz}], cell_m = {cell} }}
[material]
young_pa = {young}
poisson = 0.45
density_kg_m3 = 1000.0
damping_per_s = 20.0
model = "{model}"
[[fixed]]
name = "bottom"
select = {{ box_m = [[-0.001, -0.001, -0.001], [{ex}, {ey}, 0.0001]] }}
[[tool]]
name = "probe"
kind = "hook"
fulcrum_m = [{x}, {y}, {fz}]
length_m = 0.3
radius_m = {radius}
tip_length_m = 0.01
{refine}
{corotational}
{follow}
[simulation]
multirate = {multirate}
"#,
        multirate = a.multirate,
        cell = a.cell_m,
        young = a.young_pa,
        model = a.model,
        x = a.at_m[0],
        y = a.at_m[1],
        fz = sz + 0.13,
        radius = a.radius_m,
    );
    let src = SceneSource {
        name: "<still hand>".into(),
        dir: PathBuf::from("."),
        text,
    };
    let mut built = build_scene(&src, &src.parse()?)?;
    let mut refinement = FollowRefine::new(&src, &mut built)?;
    let mut p = prepare::<f64>(built, Some(1e-3))?;
    let top = sz + a.radius_m;
    let started = Instant::now();
    let mut steps = 0usize;
    let y = a.at_m[1];
    let mut press_at = |p: &mut sim_server::prepare::Prepared<Explicit<f64>>,
                        x: f64,
                        depth_m: f64|
     -> Result<f64> {
        let input = [Some(ToolInput {
            tip_m: Vec3::new(x, y, top - depth_m),
            jaw_opening: 1.0,
        })];
        p.tools.update(&mut p.sim, &input);
        p.tools.step(&mut p.sim);
        let f = p.tools.reaction(0, &p.sim).force_n.z;
        if let Some(r) = &mut refinement {
            r.follow(p, 1e-3, |_| {})?;
        }
        Ok(f)
    };
    for _ in 0..300 {
        press_at(&mut p, a.at_m[0], -0.002)?;
        steps += 1;
    }
    let mut depth = 0.0;
    while depth < a.depth_m {
        depth = (depth + 1e-5).min(a.depth_m);
        press_at(&mut p, a.at_m[0], depth)?;
        steps += 1;
    }
    let mut x = a.at_m[0];
    let mut forces = Vec::new();
    // A slide: along x at 20 mm/s, then the hold where it ends.
    while (x - a.at_m[0]).abs() < a.slide_m.abs() {
        x += 2e-5 * a.slide_m.signum();
        forces.push(press_at(&mut p, x, depth)?);
    }
    let slide_forces = forces.clone();
    forces.clear();
    let hold = (a.hold_s * 1e3) as usize;
    for _ in 0..hold {
        forces.push(press_at(&mut p, x, depth)?);
    }
    steps += slide_forces.len() + hold;
    let wall_s = started.elapsed().as_secs_f64();
    let last = &forces[hold - 500..];
    let n = last.len() as f64;
    let mean = last.iter().sum::<f64>() / n;
    let sd = (last.iter().map(|f| (f - mean).powi(2)).sum::<f64>() / n).sqrt();
    let (lo, hi) = last
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &f| {
            (l.min(f), h.max(f))
        });
    let zeros = last.iter().filter(|f| f.abs() < 1e-9).count();
    println!(
        "cells {} mm (refined to {:?} mm within {} mm), {} tetrahedra, {} sub-steps a 1 ms step, model {}, probe radius {} mm at {} mm",
        a.cell_m * 1e3,
        a.refine_cell_m.map(|h| h * 1e3),
        a.refine_radius_m * 1e3,
        p.sim.model().mesh().tet_count(),
        p.sim.substeps(),
        a.model,
        a.radius_m * 1e3,
        a.depth_m * 1e3
    );
    if let Some(m) = p.sim.multirate() {
        println!(
            "multirate (engaged: {}): {} of {} vertices fast, {} whole passes and {} fast sub-steps a step",
            m.engaged, m.fast_vertices, m.vertices, m.coarse_substeps, m.fine_substeps
        );
    }
    if let Some(r) = &refinement {
        let r = r.report();
        println!(
            "refinement round the tip: {} tetrahedra now ({} at most), {} meshes made{}{}",
            r.tets,
            r.most_tets,
            r.rebuilds,
            if r.stopped_at_budget {
                ", stopped at refine_max_tets"
            } else {
                ""
            },
            r.pinned
                .map_or(String::new(), |w| format!(", held once: {w}"))
        );
    }
    if let Some((region, rebuilds)) = p.tools.corotational_region() {
        let tets = region.iter().filter(|r| **r).count();
        println!(
            "corotational region round the tip: {tets} tetrahedra now, changed {rebuilds} times"
        );
    }
    if !slide_forces.is_empty() {
        let jumps: Vec<f64> = slide_forces
            .windows(2)
            .map(|w| (w[1] - w[0]).abs())
            .collect();
        let mut sorted = jumps.clone();
        sorted.sort_by(f64::total_cmp);
        let zeros = slide_forces.iter().filter(|f| f.abs() < 1e-9).count();
        println!(
            "slide of {} mm: force {:.4}..{:.4} N, per-step change p99 {:.4} N, max {:.4} N, zero steps {zeros}",
            a.slide_m * 1e3,
            slide_forces.iter().copied().fold(f64::INFINITY, f64::min),
            slide_forces
                .iter()
                .copied()
                .fold(f64::NEG_INFINITY, f64::max),
            sorted[(sorted.len() * 99 / 100).min(sorted.len() - 1)],
            sorted.last().unwrap()
        );
    }
    println!(
        "held force over the last 0.5 s: mean {mean:.4} N, sd {sd:.4} N ({:.2}% of the mean), min {lo:.4} N, max {hi:.4} N ({:.3}x the mean), zero steps {zeros}; {:.1} us of wall time a step",
        100.0 * sd / mean.abs().max(1e-12),
        hi / mean,
        1e6 * wall_s / steps as f64
    );
    Ok(())
}
