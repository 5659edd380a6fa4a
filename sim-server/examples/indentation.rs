//! A rigid probe pressed into a block, held at each depth until the tissue
//! settles: the static force against depth under either contact law, for
//! comparing the laws with each other and with an analytic indentation
//! (docs/design/contact.md, "The two laws against an analytic indentation").
//!
//! ```sh
//! cargo run --release -p sim-server --example indentation -- \
//!     --cell-m 0.00125 --law penalty [--width-m 0.024] [--at-m 0.012,0.012] \
//!     [--depths-mm 1,2,4] [--stiffness-factor 64] [--backend tensor-mass|precomputed] \
//!     [--refine-cell-m 0.000625 --refine-radius-m 0.006]
//! ```
//!
//! With `--refine-cell-m`, a `[[refine]]` sphere of `--refine-radius-m`
//! round the probe's contact point bisects the cells there down to that
//! size (the rest keeps `--cell-m`).
//!
//! The block is `width x width x 20 mm` (E 5 kPa, nu 0.45, damping 40 /s),
//! its bottom fixed, meshed with cubes of `--cell-m`; the probe is a hook of
//! radius 2.5 mm coming straight down at `--at-m` (x, y), at 10 mm/s
//! between depths, held 1.5 s at each, at a 1 ms step on the explicit
//! tensor-mass backend (default) or the precomputed (static) one.

use anyhow::{Context, Result, bail};
use sim_server::backend::{Backend, Precomputed};
use sim_server::contact::ToolInput;
use sim_server::prelude::*;
use sim_server::prepare::{Prepared, prepare, prepare_with};
use sim_server::scene::{SceneSource, build_scene};
use std::path::PathBuf;

mod common;
use common::numbers;

/// The block's height (m).
const HEIGHT_M: f64 = 0.02;
/// The probe's radius (m).
const RADIUS_M: f64 = 0.0025;
/// The probe's speed between depths (m per 1 ms step).
const SPEED_M_PER_STEP: f64 = 1e-5;
/// Steps held at each depth.
const HOLD_STEPS: usize = 1500;

struct Args {
    cell_m: f64,
    law: String,
    width_m: f64,
    at_m: [f64; 2],
    depths_mm: Vec<f64>,
    stiffness_factor: f64,
    backend: String,
    refine_cell_m: Option<f64>,
    refine_radius_m: f64,
}

fn parse() -> Result<Args> {
    let mut a = Args {
        cell_m: 0.0025,
        law: "penalty".into(),
        width_m: 0.024,
        at_m: [0.012, 0.012],
        depths_mm: vec![1.0, 2.0, 4.0],
        stiffness_factor: 64.0,
        backend: "tensor-mass".into(),
        refine_cell_m: None,
        refine_radius_m: 0.006,
    };
    let mut it = std::env::args().skip(1);
    while let Some(flag) = it.next() {
        let value = it.next().with_context(|| format!("{flag} needs a value"))?;
        match flag.as_str() {
            "--cell-m" => a.cell_m = numbers(&flag, &value)?[0],
            "--law" => a.law = value,
            "--width-m" => a.width_m = numbers(&flag, &value)?[0],
            "--at-m" => match numbers(&flag, &value)?[..] {
                [x, y] => a.at_m = [x, y],
                _ => bail!("--at-m takes x,y"),
            },
            "--depths-mm" => a.depths_mm = numbers(&flag, &value)?,
            "--stiffness-factor" => a.stiffness_factor = numbers(&flag, &value)?[0],
            "--backend" => a.backend = value,
            "--refine-cell-m" => a.refine_cell_m = Some(numbers(&flag, &value)?[0]),
            "--refine-radius-m" => a.refine_radius_m = numbers(&flag, &value)?[0],
            _ => bail!(
                "unknown flag {flag}: --cell-m, --law, --width-m, --at-m, --depths-mm, --stiffness-factor, --backend, --refine-cell-m, --refine-radius-m"
            ),
        }
    }
    if !(a.cell_m >= 5e-4 && a.cell_m <= HEIGHT_M) {
        bail!("--cell-m must lie in 0.0005..=0.02 m, got {}", a.cell_m);
    }
    if !(a.width_m >= 4.0 * RADIUS_M && a.width_m <= 0.2) {
        bail!("--width-m must lie in 0.01..=0.2 m, got {}", a.width_m);
    }
    if a.depths_mm
        .iter()
        .any(|d| !(*d > 0.0 && *d < 1e3 * HEIGHT_M))
    {
        bail!("--depths-mm must lie in (0, 20) mm");
    }
    Ok(a)
}

fn main() -> Result<()> {
    let a = parse()?;
    let (w, edge) = (a.width_m, a.width_m + 0.001);
    let refine = match a.refine_cell_m {
        Some(h) => format!(
            "[[refine]]\nname = \"under the probe\"\nselect = {{ sphere_m = [{x}, {y}, {HEIGHT_M}, {r}] }}\ncell_m = {h}\nmax_tets = 2000000\n",
            x = a.at_m[0],
            y = a.at_m[1],
            r = a.refine_radius_m,
        ),
        None => String::new(),
    };
    let text = format!(
        r#"
[mesh]
generate = {{ shape = "box", size_m = [{w}, {w}, {HEIGHT_M}], cell_m = {cell} }}
[material]
young_pa = 5000.0
poisson = 0.45
density_kg_m3 = 1000.0
damping_per_s = 40.0
[[fixed]]
name = "bottom"
select = {{ box_m = [[-0.001, -0.001, -0.001], [{edge}, {edge}, 0.0001]] }}
[[tool]]
name = "probe"
kind = "hook"
fulcrum_m = [{x}, {y}, 0.15]
length_m = 0.3
radius_m = {RADIUS_M}
tip_length_m = 0.01
[contact]
law = "{law}"
stiffness_factor = {factor}
{refine}
"#,
        cell = a.cell_m,
        x = a.at_m[0],
        y = a.at_m[1],
        law = a.law,
        factor = a.stiffness_factor,
    );
    let src = SceneSource {
        name: "<indentation>".into(),
        dir: PathBuf::from("."),
        text,
    };
    let built = build_scene(&src, &src.parse()?)?;
    match a.backend.as_str() {
        "tensor-mass" => press_all(&a, &mut prepare::<f64>(built, Some(1e-3))?),
        "precomputed" => {
            let fixed = built.fixed.clone();
            let mut p = prepare_with(built, Some(1e-3), |model, _, dt_s| {
                Precomputed::new(model, &fixed, dt_s, None, |_, _| {})
            })?;
            press_all(&a, &mut p)
        }
        other => bail!("--backend {other:?}: tensor-mass or precomputed"),
    }
}

/// The press and the forces at each depth, printed.
fn press_all<B: Backend>(a: &Args, p: &mut Prepared<B>) -> Result<()> {
    println!(
        "cell {} mm (refined to {:?} mm), {} tetrahedra, law {}, {}: depth (mm), force (N)",
        a.cell_m * 1e3,
        a.refine_cell_m.map(|h| h * 1e3),
        p.sim.model().mesh().tet_count(),
        a.law,
        p.sim.capabilities().name
    );
    let top = HEIGHT_M + RADIUS_M;
    let mut press = |depth_m: f64| {
        let input = [Some(ToolInput {
            tip_m: Vec3::new(a.at_m[0], a.at_m[1], top - depth_m),
            jaw_opening: 1.0,
        })];
        p.tools.update(&mut p.sim, &input);
        p.tools.step(&mut p.sim);
        p.tools.reaction(0, &p.sim).force_n
    };
    // In from the fulcrum, to 2 mm above the surface.
    for _ in 0..300 {
        press(-0.002);
    }
    let mut depth = 0.0;
    for d_mm in &a.depths_mm {
        let target = d_mm * 1e-3;
        while (target - depth).abs() > 1e-12 {
            depth += (target - depth).clamp(-SPEED_M_PER_STEP, SPEED_M_PER_STEP);
            press(depth);
        }
        let mut f = Vec3::ZERO;
        for _ in 0..HOLD_STEPS {
            f = press(depth);
        }
        println!("{d_mm} {:.5}", f.z);
    }
    Ok(())
}
