//! `flarelab dof`: a plate defocused through a lens's own aperture with a depth map (the live method on the GPU
//! or its CPU twin, or the reference), written linear (EXR) or as sRGB (PNG); and `flarelab synth-dof`, the
//! synthetic street scene (plate and depth map) to try it with.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use flare_core::dof::depth::PngRange;
use flare_core::dof::live::LivePlan;
use flare_core::dof::{self, DofDoc};
use flare_core::frame::parse_size;
use flare_core::output::{read_plate, write_linear};
use flare_core::render::dof_gpu::GpuDof;
use flare_core::render::gpu::GpuContext;

use super::common::{DeviceArg, MethodArg, OpticsChoice, parse_aperture};

#[derive(clap::Args, Debug)]
pub struct DofArgs {
    /// The plate (EXR/HDR linear, PNG/JPEG sRGB); it spans the sensor's width (--sensor-mm).
    pub plate: PathBuf,
    /// The depth map: metres from the lens (EXR: channel Z, else the first), or a 16-bit PNG with --depth-range.
    #[arg(long)]
    pub depth: PathBuf,
    /// NEAR:FAR metres for a 16-bit PNG depth map (0 is NEAR, 65535 is FAR).
    #[arg(long, value_parser = PngRange::parse)]
    pub depth_range: Option<PngRange>,
    /// Focus distance from the entrance pupil, in metres.
    #[arg(long, conflicts_with = "focus_px")]
    pub focus_m: Option<f64>,
    /// Focus on the depth at this plate pixel, X,Y from the top-left.
    #[arg(long, value_parser = super::common::parse_pair_u32)]
    pub focus_px: Option<(u32, u32)>,
    /// The lens (file or built-in name; default: the preset's, else the default lens).
    #[arg(long)]
    pub lens: Option<String>,
    /// A preset whose lens, aperture and depth-of-field settings to start from.
    #[arg(long)]
    pub preset: Option<String>,
    /// f-number, shared with the flare's stop (default: the preset's, else wide open).
    #[arg(long)]
    pub f_number: Option<f64>,
    /// The aperture: circle, blades:N[:ROTATION_DEG[:ROUNDNESS]] or image:PATH (default: the preset's).
    #[arg(long)]
    pub aperture: Option<String>,
    /// live: layered gather (GPU, or its CPU twin); reference: every pixel's kernel scattered (slow, exact).
    #[arg(long, value_enum, default_value = "live")]
    pub method: MethodArg,
    /// Where the live method runs.
    #[arg(long, value_enum, default_value = "auto")]
    pub device: DeviceArg,
    /// The sensor width the plate spans (mm).
    #[arg(long, default_value_t = 36.0)]
    pub sensor_mm: f64,
    /// No cat's eye: the kernel is not cut by the front lens off-axis.
    #[arg(long)]
    pub no_cat_eye: bool,
    /// Axial colour: each of R, G and B defocused at its own wavelength (650, 510, 475 nm), the sensor where the
    /// d-line focuses (three times the work).
    #[arg(long)]
    pub axial_colour: bool,
    /// The output: .exr (linear, default layer R, G, B, A) or .png (sRGB, clamped).
    #[arg(short = 'o', long = "out")]
    pub out: PathBuf,
}

pub fn run(args: &DofArgs) -> Result<()> {
    if !(args.sensor_mm.is_finite() && args.sensor_mm > 0.0) {
        bail!("--sensor-mm {}: a positive width", args.sensor_mm);
    }
    // Check the output's kind before any work: nothing is half-written, and nothing is computed for nothing.
    flare_core::output::ImageKind::from_path(&args.out)?;
    flare_core::files::check_target(&args.out).map_err(|e| anyhow::anyhow!("-o {e}"))?;
    if args.method == MethodArg::Reference && args.device == DeviceArg::Gpu {
        bail!("--device gpu: the reference runs on the CPU (it is the exact method); use --method live on the GPU");
    }
    let optics =
        OpticsChoice { file: args.lens.clone(), preset: args.preset.clone(), coating: None, f_number: args.f_number };
    let mut doc = optics.document()?;
    if let Some(spec) = &args.aperture {
        doc.aperture = parse_aperture(spec, doc.aperture.f_number)?;
    }
    doc.sensor_width_mm = args.sensor_mm;
    doc.dof = DofDoc {
        enabled: true,
        depth: Some(args.depth.display().to_string()),
        depth_range_m: args.depth_range,
        focus_m: args.focus_m.unwrap_or(doc.dof.focus_m),
        focus_px: if args.focus_m.is_some() { None } else { args.focus_px.map(|(x, y)| [x, y]).or(doc.dof.focus_px) },
        cat_eye: !args.no_cat_eye,
        axial_colour: args.axial_colour,
        method: args.method.into(),
    };
    doc.check().map_err(|e| anyhow::anyhow!("{e}"))?;
    let config = doc.flare_config().map_err(|e| anyhow::anyhow!("{e}"))?;
    let flare = flare_core::PreparedFlare::new(&doc.lens, &config).with_context(|| doc.lens.id.clone())?;
    let (w, h) = flare_core::output::image_size(&args.plate, "the plate").map_err(|e| anyhow::anyhow!("{e}"))?;
    check_memory("the plate", (w, h), DOF_BYTES_PER_PX)?;
    let plate = read_plate(&args.plate).context("the plate")?;
    let lens = flare_core::shot::plate::dof_lens(&doc, &flare);
    let (models, depth) = dof::prepare(&doc.dof, lens, &args.depth, (plate.width, plate.height))?;
    // Every depth checked before anything is said or drawn.
    dof::defocus_map(&models[0], &depth)?;
    for model in &models {
        eprintln!(
            "{} at f/{:.1}, {:.0} nm, focus {:.3} m: the far field blurs to {:.1} px, {:.3} mm on the sensor (pupil {:.2} mm, m = {:.5})",
            doc.lens.id,
            flare.system.first_order.f_number / flare.system.settings.stop_scale,
            model.wavelength_nm,
            model.focus_mm / 1000.0,
            model.far_defocus_px(),
            model.coc_mm(f64::INFINITY),
            2.0 * model.pupil_radius_mm,
            model.focus_magnification
        );
    }
    if let Some(f) = args.f_number
        && f < flare.system.first_order.f_number
    {
        eprintln!("f/{f} is faster than the lens opens (f/{:.1}): drawn wide open", flare.system.first_order.f_number);
    }
    let started = Instant::now();
    let gpu = match (args.method, args.device) {
        (MethodArg::Reference, _) | (_, DeviceArg::Cpu) => None,
        (_, DeviceArg::Gpu) => {
            Some(GpuContext::headless(false).map_err(|e| anyhow::anyhow!("{e} (or use --device cpu)"))?)
        }
        (_, DeviceArg::Auto) => {
            GpuContext::headless(false).map_err(|e| eprintln!("no GPU ({e}): the live method's CPU twin draws it")).ok()
        }
    };
    let mut gpu_dof = gpu.as_ref().map(|ctx| GpuDof::new(&ctx.device));
    let mut said = Vec::new();
    let image = dof::per_channel(&plate, &models, |plate, model| -> Result<_> {
        if args.method == MethodArg::Reference {
            return Ok(dof::reference::render(plate, &depth, model, flare.mask())?);
        }
        let plan = LivePlan::new(&depth, model, flare.mask())?;
        if let (Some(ctx), Some(g)) = (&gpu, gpu_dof.as_mut()) {
            match g.render(ctx, &plan, plate) {
                Ok(out) => {
                    said.push(format!(
                        "live on the GPU ({}): {} layers{}",
                        ctx.adapter.name,
                        plan.layers.len(),
                        out.gpu_ms.map_or(String::new(), |ms| format!(", {ms:.1} ms GPU time"))
                    ));
                    return Ok(out.image);
                }
                Err(e) if args.device == DeviceArg::Gpu && !matches!(e, flare_core::render::gpu::GpuError::Lost(_)) => {
                    bail!("the live method on {}: {e}", ctx.adapter.name)
                }
                Err(e) => {
                    said.push(format!("the live method on {} failed ({e}): its CPU twin draws it", ctx.adapter.name))
                }
            }
        }
        said.push(format!("live on the CPU: {} layers", plan.layers.len()));
        Ok(plan.render_cpu(plate))
    })?;
    said.dedup();
    let how = if args.method == MethodArg::Reference { "reference (CPU)".to_owned() } else { said.join("; ") };
    eprintln!(
        "{how}{}: {:.2} s",
        if models.len() == 3 { ", each of R, G, B at its own wavelength" } else { "" },
        started.elapsed().as_secs_f64()
    );
    write_linear(&args.out, &image)?;
    eprintln!("wrote {} ({}x{})", args.out.display(), image.width, image.height);
    Ok(())
}

#[derive(clap::Args, Debug)]
pub struct SynthDofArgs {
    /// Frame size.
    #[arg(long, default_value = "1920x1080", value_parser = parse_size)]
    pub size: (u32, u32),
    /// The plate (linear EXR).
    #[arg(short = 'o', long = "out")]
    pub out: PathBuf,
    /// The depth map (EXR, channel Z, metres; the sky is infinite).
    #[arg(long)]
    pub depth: PathBuf,
}

/// What `synth-dof` keeps per pixel at most (bytes): the plate's RGBA floats, the depth map in f64 and f32, and
/// the file's channels. Measured as peak RSS: 3.46 GB at 8192x8192, 51 bytes a pixel.
const SYNTH_BYTES_PER_PX: u64 = 56;

/// What `dof` keeps per plate pixel at most (bytes): the plate, its depth map, the defocus map, the layers and
/// the output. Measured as peak RSS on the CPU twin: 0.72 GB at 4096x2160 (82 bytes a pixel), 4.1 GB at
/// 8192x8192 (61).
const DOF_BYTES_PER_PX: u64 = 96;

/// Refuses `what` of `w` x `h` pixels at `bytes_per_px` when that passes nine tenths of the memory available
/// now, naming the figures, before any work.
fn check_memory(what: &str, (w, h): (u32, u32), bytes_per_px: u64) -> Result<()> {
    let need = u64::from(w) * u64::from(h) * bytes_per_px;
    if let Some(available) = flare_core::frame::available_memory_bytes()
        && need > flare_core::frame::usable_memory_bytes(available)
    {
        bail!(
            "{what} ({w}x{h}) needs about {:.1} GB, more than nine tenths of the {:.1} GB this machine has free",
            need as f64 / 1e9,
            available as f64 / 1e9
        );
    }
    Ok(())
}

pub fn synth(args: &SynthDofArgs) -> Result<()> {
    for path in [&args.out, &args.depth] {
        if !path.to_string_lossy().to_ascii_lowercase().ends_with(".exr") {
            bail!("{}: the plate and the depth map are linear: use .exr", path.display());
        }
        flare_core::files::check_target(path).map_err(|e| anyhow::anyhow!("{e}"))?;
    }
    check_memory("the street", args.size, SYNTH_BYTES_PER_PX)?;
    let (plate, depth) = dof::scene::street(args.size.0, args.size.1);
    write_linear(&args.out, &plate)?;
    dof::depth::write_exr(&args.depth, &depth).map_err(|e| anyhow::anyhow!("{}: {e}", args.depth.display()))?;
    let (near, far) =
        depth.metres.iter().filter(|d| d.is_finite()).fold((f64::INFINITY, 0.0f64), |(a, b), &d| (a.min(d), b.max(d)));
    eprintln!(
        "wrote {} and {} ({}x{}): depths {near:.1} to {far:.0} m and the sky; a sign at 5 m, lamps from 3 to 59 m, a post at 1.2 m; the sun at pixel ({:.0}, {:.0})",
        args.out.display(),
        args.depth.display(),
        args.size.0,
        args.size.1,
        dof::scene::SUN_AT[0] * f64::from(args.size.0),
        dof::scene::SUN_AT[1] * f64::from(args.size.1)
    );
    Ok(())
}
