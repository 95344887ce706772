//! `flarelab synth-shot`: writes a synthetic plate sequence (a sun crossing a sky, a bar crossing the sun) and
//! its true track, to try shots with (`render --background ... --light auto` or `--track`).

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use flare_core::footage::pattern::FramePattern;
use flare_core::frame::parse_size;
use flare_core::shot::synthetic::SyntheticShot;

#[derive(clap::Args, Debug)]
pub struct SynthArgs {
    /// Frame size.
    #[arg(long, default_value = "1920x1080", value_parser = parse_size)]
    pub size: (u32, u32),
    /// Frames A-B.
    #[arg(long, default_value = "1-48")]
    pub frames: String,
    /// No bar crossing the sun.
    #[arg(long)]
    pub no_occluder: bool,
    /// Also write the sun's true track as CSV (frame,x_px,y_px).
    #[arg(long)]
    pub track: Option<PathBuf>,
    /// The plates, a pattern such as plates/sun.####.exr (linear RGB EXR).
    #[arg(short = 'o', long = "out")]
    pub out: String,
}

pub fn run(args: &SynthArgs) -> Result<()> {
    let Some(pattern) = FramePattern::parse(&args.out).map_err(|e| anyhow::anyhow!("-o {e}"))? else {
        bail!("-o {}: give a frame field, e.g. plates/sun.####.exr", args.out)
    };
    if !args.out.to_ascii_lowercase().ends_with(".exr") {
        bail!("-o {}: the plates are linear HDR: use .exr", args.out);
    }
    flare_core::files::check_sequence_target(std::path::Path::new(&args.out)).map_err(|e| anyhow::anyhow!("-o {e}"))?;
    let (a, b) = args
        .frames
        .split_once('-')
        .and_then(|(a, b)| Some((a.trim().parse::<i64>().ok()?, b.trim().parse::<i64>().ok()?)))
        .filter(|(a, b)| a <= b)
        .with_context(|| format!("--frames {}: expected A-B", args.frames))?;
    let mut shot = SyntheticShot::scaled(args.size.0, args.size.1, a..=b);
    if args.no_occluder {
        shot.occluder_px = None;
    }
    shot.write(&pattern, args.track.as_deref())?;
    eprintln!(
        "wrote {} plates {}x{} to {} (sun radius {:.1} px{})",
        b - a + 1,
        args.size.0,
        args.size.1,
        args.out,
        shot.sun_radius_px,
        if shot.occluder_px.is_some() { ", a bar crossing it" } else { "" }
    );
    Ok(())
}
