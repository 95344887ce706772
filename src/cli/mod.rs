//! The command line: one module per subcommand, all drawing frames through `flare_core::frame` and writing
//! them through `flare_core::output`.
//!
//! Every command that takes a lens reads it from a file (`.json`, `.zmx`, `.dat`, by extension or content) or
//! from the built-in library by name ([`common::open_lens`]); JSON output is one document on stdout; every
//! file is written through a temporary file and a rename; every output is named with `-o/--out`.

pub mod bench;
pub mod common;
pub mod dof;
pub mod ghosts;
pub mod lens;
pub mod lut;
pub mod preset;
pub mod render;
pub mod synth;
pub mod trace;

use anyhow::Result;
use clap::{Parser, Subcommand};

#[derive(Parser, Debug)]
#[command(
    name = "flarelab",
    version,
    about = "FlareLab: physically based lens flares. With no subcommand, opens the desktop app.",
    after_help = "LENS is a file (.json, .zmx, .dat, FlareSim .lens, OpenLensFlare .xml) or the name of a built-in lens (see `flarelab lens list`)."
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Option<Command>,
    /// A glass catalogue (Zemax .agf) whose glasses lens files may name, beside the built-in SCHOTT, OHARA,
    /// HOYA and CDGM ones; repeat for several. Named by the file stem (ohara.agf is OHARA and replaces the
    /// built-in OHARA glasses it holds; OHARA:S-BSL7 picks one).
    #[arg(long = "catalog", global = true, value_name = "FILE.agf")]
    pub catalogs: Vec<std::path::PathBuf>,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Inspect, list and convert lenses.
    #[command(subcommand)]
    Lens(lens::LensCommand),
    /// Trace one ray exactly through the lens (or along a ghost path) to the sensor.
    Trace(trace::TraceArgs),
    /// Every two-reflection ghost for a light direction: sprite, brightness, colour, and whether it is culled.
    Ghosts(ghosts::GhostsArgs),
    /// Render a flare to an image (PNG: tonemapped 8-bit sRGB; EXR: linear float with named layers).
    Render(Box<render::RenderArgs>),
    /// Write a preset (the document the app saves), or list the shipped ones.
    #[command(subcommand)]
    Preset(preset::PresetCommand),
    /// Run time against error of every method (paraxial, ray grids) versus the ray-traced reference.
    Bench(bench::BenchArgs),
    /// Measure every ghost's paraxial error against ray tracing over light angles: which are non-linear.
    Classify(lut::ClassifyArgs),
    /// Bake the non-linear ghosts into a LUT file (.flut) by exact ray tracing.
    Bake(lut::BakeArgs),
    /// Import a folder of photographs of a flare swept over theta as a photo LUT (.flut).
    PhotoLut(lut::PhotoArgs),
    /// Write a synthetic plate sequence (a sun crossing a sky, a bar crossing the sun) and its track.
    SynthShot(synth::SynthArgs),
    /// Defocus a plate through the lens's own aperture with a depth map (depth of field).
    Dof(Box<dof::DofArgs>),
    /// Write a synthetic night street (plate and depth map) to try the depth of field with.
    SynthDof(dof::SynthDofArgs),
}

pub fn run(command: Command) -> Result<()> {
    match command {
        Command::Lens(command) => lens::run(command),
        Command::Trace(args) => trace::run(&args),
        Command::Ghosts(args) => ghosts::run(&args),
        Command::Render(args) => render::run(&args),
        Command::Preset(command) => preset::run(command),
        // The depth of field's bench is its own (its module uses the flare bench's rows and chart).
        Command::Bench(args) if args.dof => bench::dof::run(&args),
        Command::Bench(args) => bench::run(&args),
        Command::Classify(args) => lut::classify_command(&args),
        Command::Bake(args) => lut::bake_command(&args),
        Command::PhotoLut(args) => lut::photo_command(&args),
        Command::SynthShot(args) => synth::run(&args),
        Command::Dof(args) => dof::run(&args),
        Command::SynthDof(args) => dof::synth(&args),
    }
}
