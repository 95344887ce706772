//! `flarelab classify`, `flarelab bake`, `flarelab photo-lut`: the LUT ghosts from the command line.
//!
//! Bakes print their progress on stderr as they go; the LUT is written through a temporary file and a rename.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use flare_core::bake::classify::{ClassifySettings, GhostClass, classify};
use flare_core::bake::{BakeProgress, BakeSettings, bake_with, useful_field_deg};
use flare_core::flare::PreparedFlare;
use flare_core::lut::{GhostLut, format, photo};
use flare_core::raytrace::RayGridRenderer;
use flare_core::render::gpu::GpuContext;
use flare_core::render::raygrid::{GpuBake, SUPERSAMPLE};

use super::common::DeviceArg;

/// Which ghosts to bake and how.
#[derive(clap::Args, Debug, Clone)]
pub struct LutChoice {
    /// Largest light angle, degrees (default: the lens's useful field).
    #[arg(long)]
    pub theta_max: Option<f64>,
    /// Image error (0 to 1) above which a visible ghost is non-linear.
    #[arg(long, default_value_t = 0.15)]
    pub threshold: f64,
    /// A non-linear ghost whose peak is under this fraction of the brightest ghost's is faint and stays
    /// paraxial (0 bakes every non-linear ghost).
    #[arg(long, default_value_t = flare_core::bake::classify::DEFAULT_FAINT_FRACTION)]
    pub faint: f64,
    /// Ghosts to bake whatever the measure says, as surface pairs: 4-6,2-9.
    #[arg(long, value_delimiter = ',')]
    pub force_nonlinear: Vec<String>,
    /// Ghosts never to bake, as surface pairs.
    #[arg(long, value_delimiter = ',')]
    pub force_linear: Vec<String>,
}

#[derive(clap::Args, Debug)]
pub struct ClassifyArgs {
    #[command(flatten)]
    pub optics: super::common::OpticsChoice,
    #[command(flatten)]
    pub choice: LutChoice,
    /// One JSON document instead of the table.
    #[arg(long)]
    pub json: bool,
}

#[derive(clap::Args, Debug)]
pub struct BakeArgs {
    #[command(flatten)]
    pub optics: super::common::OpticsChoice,
    /// Output LUT (default: the lens's id with .flut).
    #[arg(short = 'o', long = "out", alias = "output")]
    pub out: Option<PathBuf>,
    #[command(flatten)]
    pub choice: LutChoice,
    /// Most texels across an entry of a ghost small on the sensor.
    #[arg(long, default_value_t = BakeSettings::default().res)]
    pub res: u32,
    /// Texels across the sensor's diagonal for the entries of ghosts large on the sensor whose detail needs them
    /// (--detail-tolerance): up to 2040 texels across, so that they show no stair steps when stretched over a
    /// large frame (README); 0 turns it off.
    #[arg(long, default_value_t = BakeSettings::default().diagonal_texels)]
    pub diagonal_texels: u32,
    /// A large ghost's entry is baked finer (--diagonal-texels) where halving it loses more than this share of
    /// its light's placement (relative L1): sharp rims and caustics, not smooth blurs. 0: every large ghost.
    #[arg(long, default_value_t = BakeSettings::default().detail_tolerance)]
    pub detail_tolerance: f64,
    /// Most ray-grid cells across a ghost's entrance region.
    #[arg(long, default_value_t = BakeSettings::default().grid)]
    pub grid: usize,
    /// Azimuth steps over the aperture's symmetry wedge (0: rotation only).
    #[arg(long, default_value_t = BakeSettings::default().phi_steps)]
    pub phi_steps: u32,
    /// Refine theta while the interpolated middle entry is off by more than this (relative L1).
    #[arg(long, default_value_t = BakeSettings::default().tolerance)]
    pub tolerance: f64,
    /// Finest theta step, degrees (an interval narrower than twice this is not split).
    #[arg(long, default_value_t = BakeSettings::default().min_step_deg)]
    pub min_step: f64,
    /// A previous LUT of this lens: ghosts whose settings are unchanged are kept, not re-baked.
    #[arg(long)]
    pub update: Option<PathBuf>,
    /// Where each column's rays are traced and drawn: `gpu` (any wgpu adapter, lavapipe included), `cpu`
    /// (the f64 tracer), or `auto`: a hardware GPU when there is one, else the CPU (a software adapter is
    /// slower than the CPU tracer, so `auto` does not pick it).
    #[arg(long, value_enum, default_value_t = DeviceArg::Auto)]
    pub device: DeviceArg,
}

#[derive(clap::Args, Debug)]
pub struct PhotoArgs {
    /// Folder of PNG/EXR images of a flare swept over theta (angles in flare.json or the file names).
    pub folder: PathBuf,
    /// Output LUT.
    #[arg(short = 'o', long = "out", alias = "output")]
    pub out: PathBuf,
}

impl Default for LutChoice {
    /// The command line's defaults.
    fn default() -> Self {
        Self {
            theta_max: None,
            threshold: 0.15,
            faint: flare_core::bake::classify::DEFAULT_FAINT_FRACTION,
            force_nonlinear: Vec::new(),
            force_linear: Vec::new(),
        }
    }
}

/// Lens ghost indices of surface pairs `I-J`.
fn ghost_indices(flare: &PreparedFlare, pairs: &[String]) -> Result<Vec<usize>> {
    pairs
        .iter()
        .map(|p| {
            let (i, j) = p
                .split_once('-')
                .and_then(|(i, j)| Some((i.trim().parse::<usize>().ok()?, j.trim().parse::<usize>().ok()?)))
                .ok_or_else(|| anyhow::anyhow!("ghost `{p}`: write the surface pair as I-J, e.g. 4-6"))?;
            flare
                .system
                .ghosts
                .iter()
                .position(|g| (g.i, g.j) == (i.min(j), i.max(j)))
                .ok_or_else(|| anyhow::anyhow!("ghost {p}: the lens has no ghost reflecting at surfaces {i} and {j}"))
        })
        .collect()
}

/// The measure of every ghost with the user's forced choices.
pub fn classify_ghosts(
    flare: &PreparedFlare,
    renderer: &RayGridRenderer,
    choice: &LutChoice,
) -> Result<Vec<GhostClass>> {
    if !(choice.threshold.is_finite() && (0.0..=1.0).contains(&choice.threshold)) {
        bail!("--threshold {}: 0 to 1", choice.threshold);
    }
    if let Err(why) = flare_core::lut::Symmetry::of(&flare.system.lens, &flare.config.aperture) {
        // Refused before any tracing (the bake would refuse it after).
        bail!("no LUT ghosts: {why}");
    }
    let mut forced: Vec<(usize, bool)> =
        ghost_indices(flare, &choice.force_nonlinear)?.into_iter().map(|g| (g, true)).collect();
    forced.extend(ghost_indices(flare, &choice.force_linear)?.into_iter().map(|g| (g, false)));
    let theta_max = choice.theta_max.unwrap_or_else(|| useful_field_deg(flare));
    let mut settings = ClassifySettings::for_flare(flare, theta_max);
    settings.threshold = choice.threshold;
    if !(choice.faint.is_finite() && (0.0..=1.0).contains(&choice.faint)) {
        bail!("--faint {}: 0 to 1", choice.faint);
    }
    settings.faint_fraction = choice.faint;
    Ok(classify(flare, renderer, &settings, &forced))
}

/// The GPU a bake's columns go to for `--device` (`None`: the CPU), said on stderr unless `quiet`.
pub fn bake_gpu(device: DeviceArg, quiet: bool) -> Result<Option<GpuContext>> {
    Ok(match device {
        DeviceArg::Cpu => None,
        DeviceArg::Gpu => Some(GpuContext::headless(false).map_err(|e| anyhow::anyhow!("{e} (or use --device cpu)"))?),
        DeviceArg::Auto => match GpuContext::hardware() {
            Ok(ctx) => Some(ctx),
            Err(why) => {
                if !quiet {
                    eprintln!("baking on the CPU: {why} (--device gpu uses any adapter)");
                }
                None
            }
        },
    })
}

/// Classifies and bakes in memory, printing progress to stderr; the LUT, the classes and the bake seconds.
/// With `gpu`, each column is traced and drawn there ([`GpuBake`]); a device lost on the way hands the rest
/// to the CPU, said once.
pub fn bake_lut(
    flare: &PreparedFlare,
    renderer: &RayGridRenderer,
    choice: &LutChoice,
    settings: &BakeSettings,
    previous: Option<&GhostLut>,
    gpu: Option<&GpuContext>,
    quiet: bool,
) -> Result<(GhostLut, Vec<GhostClass>, f64)> {
    let started = Instant::now();
    let classes = classify_ghosts(flare, renderer, choice)?;
    let chosen: Vec<usize> = classes.iter().filter(|c| c.nonlinear()).map(|c| c.ghost).collect();
    if !quiet {
        eprintln!(
            "classified {} ghosts in {:.1} s: {} non-linear to bake",
            classes.len(),
            started.elapsed().as_secs_f64(),
            chosen.len()
        );
    }
    let cancel = AtomicBool::new(false);
    let printed = AtomicUsize::new(0);
    let progress = |p: BakeProgress| {
        // Entries come a column (every azimuth of one theta) at a time: print as each 50 is passed.
        let bucket = p.entries / 50;
        if !quiet && (printed.swap(bucket, Ordering::Relaxed) != bucket || p.ghosts_done == p.ghosts_total) {
            eprint!(
                "\rbaking: {} entries, {}/{} ghosts ({} kept), {:.1} s   ",
                p.entries,
                p.ghosts_done,
                p.ghosts_total,
                p.ghosts_kept,
                started.elapsed().as_secs_f64()
            );
        }
    };
    let mut settings = settings.clone();
    settings.theta_max_deg = choice.theta_max;
    let on_gpu = gpu.map(|ctx| GpuBake::new(ctx, SUPERSAMPLE));
    let lut =
        bake_with(flare, renderer, GpuBake::or_cpu(on_gpu.as_ref()), &chosen, &settings, previous, &progress, &cancel)?;
    if !quiet {
        eprintln!();
        match (&on_gpu, gpu) {
            (Some(g), Some(ctx)) => {
                let (columns_gpu, columns_cpu) = g.columns();
                eprintln!(
                    "columns traced on the GPU ({}, box-filtered): {columns_gpu}, on the CPU: {columns_cpu}",
                    ctx.adapter.name
                );
            }
            _ => eprintln!("columns traced on the CPU (f64)"),
        }
    }
    if let Some(reason) = on_gpu.as_ref().and_then(GpuBake::fell_back) {
        eprintln!("the GPU failed during the bake ({reason}): the rest was traced on the CPU");
    }
    Ok((lut, classes, started.elapsed().as_secs_f64()))
}

fn print_classes(flare: &PreparedFlare, classes: &[GhostClass]) {
    println!(
        "{:>4} {:>3} {:>3}  {:>9} {:>8} {:>6} {:>7} {:>7} {:>10} {:>10}  verdict",
        "#", "i", "j", "centroid", "(rel)", "size", "error", "energy", "misplaced", "peak"
    );
    let mut order: Vec<&GhostClass> = classes.iter().collect();
    order.sort_by(|a, b| b.image_error.total_cmp(&a.image_error));
    for c in order {
        let verdict = match c.forced {
            Some(true) => "non-linear (forced)",
            Some(false) => "linear (forced)",
            None if c.measured_nonlinear => "non-linear",
            None if c.faint => "non-linear but faint: paraxial",
            None => "linear",
        };
        println!(
            "{:>4} {:>3} {:>3}  {:>7.3}mm {:>8.2} {:>6.2} {:>7.3} {:>7.2} {:>10.2e} {:>10.2e}  {verdict}",
            c.ghost,
            c.surfaces.0,
            c.surfaces.1,
            c.centroid_mm,
            c.centroid_rel,
            c.size_ratio,
            c.image_error,
            c.energy_ratio,
            c.misplaced_energy,
            c.peak_irradiance
        );
    }
    let n = classes.iter().filter(|c| c.nonlinear()).count();
    let faint = classes.iter().filter(|c| c.faint && c.forced.is_none()).count();
    println!(
        "{n} of {} ghosts non-linear, {faint} more too faint to bake ({} lens)",
        classes.len(),
        flare.system.lens.id
    );
}

pub fn classify_command(args: &ClassifyArgs) -> Result<()> {
    let flare = args.optics.flare()?;
    let lens = &flare.system.lens;
    let renderer = flare.ray_grid_renderer();
    let classes = classify_ghosts(&flare, &renderer, &args.choice)?;
    if args.json {
        let rows: Vec<serde_json::Value> = classes
            .iter()
            .map(|c| {
                serde_json::json!({
                    "ghost": c.ghost, "i": c.surfaces.0, "j": c.surfaces.1,
                    "centroid_mm": c.centroid_mm, "centroid_rel": c.centroid_rel, "size_ratio": c.size_ratio,
                    "image_error": c.image_error, "energy_ratio": c.energy_ratio,
                    "misplaced_energy": c.misplaced_energy, "peak_irradiance": c.peak_irradiance,
                    "measured_nonlinear": c.measured_nonlinear, "faint": c.faint, "forced": c.forced, "nonlinear": c.nonlinear(),
                })
            })
            .collect();
        println!("{}", serde_json::to_string_pretty(&serde_json::json!({ "lens": lens.id, "ghosts": rows }))?);
    } else {
        print_classes(&flare, &classes);
    }
    Ok(())
}

pub fn bake_command(args: &BakeArgs) -> Result<()> {
    let flare = args.optics.flare()?;
    let lens = flare.system.lens.clone();
    let renderer = flare.ray_grid_renderer();
    let previous = args
        .update
        .as_deref()
        .map(|p| format::read_lut(p).with_context(|| format!("reading {}", p.display())))
        .transpose()?;
    let settings = BakeSettings {
        res: args.res,
        diagonal_texels: args.diagonal_texels,
        detail_tolerance: args.detail_tolerance,
        grid: args.grid,
        phi_steps: args.phi_steps,
        tolerance: args.tolerance,
        min_step_deg: args.min_step,
        ..BakeSettings::default()
    };
    let out = args.out.clone().unwrap_or_else(|| PathBuf::from(format!("{}.flut", lens.id)));
    // Where the LUT goes is checked before the bake, not after it.
    check_lut_target(&out)?;
    let gpu = bake_gpu(args.device, false)?;
    let (lut, _, seconds) =
        bake_lut(&flare, &renderer, &args.choice, &settings, previous.as_ref(), gpu.as_ref(), false)?;
    let bytes = format::write_lut(&out, &lut).with_context(|| format!("writing {}", out.display()))?;
    for g in &lut.ghosts {
        println!(
            "ghost {:>3} ({}-{}): {} thetas {:?} deg x {} azimuths",
            g.ghost,
            g.surfaces[0],
            g.surfaces[1],
            g.thetas_deg.len(),
            g.thetas_deg.iter().map(|t| (t * 100.0).round() / 100.0).collect::<Vec<_>>(),
            g.phis_deg.len()
        );
    }
    println!(
        "baked {} ghosts, {} entries, {:.1} M texels in {seconds:.1} s; wrote {} ({:.2} MB, theta 0 to {:.1} deg)",
        lut.ghosts.len(),
        lut.entry_count(),
        lut.texel_count() as f64 / 1e6,
        out.display(),
        bytes as f64 / 1e6,
        lut.theta_max_deg
    );
    Ok(())
}

/// Checks, before any work, that `out` is named `.flut` (a LUT written as `l.png` was accepted, issue 61) and
/// that its folder takes a file.
fn check_lut_target(out: &Path) -> Result<()> {
    if !out.extension().is_some_and(|e| e.eq_ignore_ascii_case("flut")) {
        bail!("-o {}: a LUT file is named .flut", flare_core::files::shorten(&out.display().to_string()));
    }
    flare_core::files::check_target(out).map_err(|e| anyhow::anyhow!("-o {e}"))
}

pub fn photo_command(args: &PhotoArgs) -> Result<()> {
    check_lut_target(&args.out)?;
    let lut = photo::import_folder(&args.folder)?;
    let bytes = format::write_lut(&args.out, &lut).with_context(|| format!("writing {}", args.out.display()))?;
    println!(
        "imported {} images (theta {:?} deg) into {} ({:.2} MB)",
        lut.entry_count(),
        lut.ghosts[0].thetas_deg,
        args.out.display(),
        bytes as f64 / 1e6
    );
    Ok(())
}
