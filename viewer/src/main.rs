//! `viewer`: live view of a session, or one PNG snapshot without a display.

use anyhow::{Context, Result, bail};
use clap::Parser;
use std::path::PathBuf;
use viewer::camera::View;
use viewer::render::Layers;
use viewer::session::Session;

/// Live 3D view of a hapsim session (organ, tools, forces, rates).
#[derive(Parser)]
#[command(version, allow_negative_numbers = true)]
struct Args {
    /// Session to join (shared with sim-server and haptic-daemon).
    #[arg(long, default_value = "default")]
    session: String,
    /// Render one frame into this PNG without any display, then exit.
    #[arg(long)]
    snapshot: Option<PathBuf>,
    /// Snapshot size, WIDTHxHEIGHT.
    #[arg(long, default_value = "1024x768", value_parser = parse_size)]
    size: (u32, u32),
    /// Snapshot view.
    #[arg(long, value_enum, default_value = "iso")]
    view: View,
    /// How long a snapshot waits for the simulation (s).
    #[arg(long, default_value_t = 10.0)]
    wait_s: f64,
    /// Draw the fibre directions.
    #[arg(long)]
    fibres: bool,
    /// No force vectors.
    #[arg(long)]
    no_forces: bool,
    /// No text overlay.
    #[arg(long)]
    no_overlay: bool,
    /// What the organ's colour shows: its tissue, or each vertex's
    /// displacement from rest with a colour bar (key C in the window).
    #[arg(long, value_enum, default_value = "tissue")]
    colour: viewer::colour::ColourBy,
    /// Cut the view open: leave out what lies beyond a plane across AXIS
    /// (x, y or z) at FRACTION of the organ's extent (default 0.5), to see
    /// inside (with --fibres: the vessels' fibres); `y` opens the side the
    /// front view looks at. Key K in the window.
    #[arg(long, value_name = "AXIS[:FRACTION]")]
    clip: Option<viewer::render::Clip>,
    /// Force arrow length per newton (mm/N; the overlay prints it).
    #[arg(long, default_value_t = viewer::render::FORCE_MM_PER_N)]
    force_mm_per_n: f32,
    /// Write what the snapshot showed as JSON here.
    #[arg(long)]
    json: Option<PathBuf>,
    /// Watch a session on another host through zenoh at this endpoint (its
    /// `sim-server bridge`, e.g. tcp/10.0.0.5:7447), touching no shared
    /// memory and reading no file; repeatable.
    #[arg(long, value_name = "ENDPOINT")]
    connect: Vec<String>,
    /// A zenoh configuration file (JSON5: TLS, mutual authentication;
    /// docs/guide/remote.md); implies a remote session.
    #[arg(long, value_name = "FILE")]
    zenoh_config: Option<PathBuf>,
    /// The bridge's token (default: bridge.token in this user's private
    /// directory; on another host, a copy of the bridge's; docs/guide/security.md).
    #[arg(long, value_name = "FILE")]
    token_file: Option<PathBuf>,
}

fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("{s:?} is not WIDTHxHEIGHT"))?;
    let parse = |v: &str| {
        v.trim()
            .parse::<u32>()
            .ok()
            .filter(|&n| (16..=8192).contains(&n))
            .ok_or_else(|| format!("{v:?} is not a size between 16 and 8192 pixels"))
    };
    Ok((parse(w)?, parse(h)?))
}

fn main() -> Result<()> {
    let args = Args::parse();
    if !(args.wait_s.is_finite() && args.wait_s >= 0.0) {
        bail!("--wait-s must be a non-negative number of seconds");
    }
    let name = shared::SessionName::new(&args.session)?;
    let mut session = match shared::remote::RemoteConfig::client(
        &args.connect,
        args.zenoh_config.as_deref(),
        args.token_file.as_deref(),
    )? {
        None => Session::join(&name)?,
        Some(cfg) => {
            let wait = std::time::Duration::from_secs_f64(args.wait_s.clamp(1.0, 86_400.0));
            let link = shared::remote::Link::join(&cfg, &name, wait)?;
            eprintln!("viewer: {}", link.summary());
            Session::join_remote(std::sync::Arc::new(link))?
        }
    };
    if !(args.force_mm_per_n.is_finite() && args.force_mm_per_n > 0.0 && args.force_mm_per_n <= 1e4)
    {
        bail!(
            "--force-mm-per-n must be a length per newton between 0 and 10000 mm/N, got {}",
            args.force_mm_per_n
        );
    }
    let layers = Layers {
        fibres: args.fibres,
        forces: !args.no_forces,
        overlay: !args.no_overlay,
        colour_by: args.colour,
        force_mm_per_n: args.force_mm_per_n,
        clip: args.clip,
    };
    if let Some(out) = &args.snapshot {
        let cfg = viewer::snapshot::SnapshotConfig {
            session: args.session.clone(),
            out: out.clone(),
            size: args.size,
            view: args.view,
            layers,
            wait_s: args.wait_s,
        };
        let report = viewer::snapshot::snapshot(&mut session, &cfg)?;
        println!(
            "viewer: wrote {} ({}x{}, {} triangles, {} made by cuts, topology v{})",
            out.display(),
            report.width,
            report.height,
            report.triangles,
            report.cut_triangles,
            report.topology_version
        );
        if let Some(path) = &args.json {
            let text = serde_json::to_string_pretty(&report)? + "\n";
            std::fs::write(path, text)
                .with_context(|| format!("cannot write {}", path.display()))?;
        }
        return Ok(());
    }
    run_window(session, layers)
}

#[cfg(feature = "window")]
fn run_window(session: Session, layers: Layers) -> Result<()> {
    viewer::window::run(session, layers)
}

#[cfg(not(feature = "window"))]
fn run_window(_: Session, _: Layers) -> Result<()> {
    bail!(
        "this viewer was built without the window (cargo feature `window`); rebuild with \
         `cargo build --release -p viewer --features window`, or use --snapshot FILE.png"
    )
}
