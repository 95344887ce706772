//! `flarelab bench --dof`: the depth of field's methods on one chart of error against run time, on the synthetic
//! street ([`flare_core::dof::scene`]): the reference with thinner and thicker layers, the live method at several
//! settings on the CPU twin and the GPU, each against the finest reference (PSNR and SSIM); then the live
//! method's frame time at 1920x1080.

use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result};
use flare_core::dof::live::{LivePlan, LiveSettings};
use flare_core::dof::{self, DofModel};
use flare_core::flare::{FlareConfig, PreparedFlare};
use flare_core::image::HdrImage;
use flare_core::metrics::{self, Comparison};
use flare_core::render::dof_gpu::GpuDof;
use flare_core::render::gpu::GpuContext;

use super::{BenchArgs, Row, timed};
use crate::cli::common::open_lens;

const README_START: &str = "<!-- dof-bench:start -->";
const README_END: &str = "<!-- dof-bench:end -->";

/// The scene's focus (the sign) and the lens the bench uses unless `--lens` names one.
const FOCUS_M: f64 = 5.0;
const DEFAULT_LENS: &str = "zeiss_master_prime_us5537259";
/// The live method's settings on the chart: (taps across a kernel, most layers).
const LIVE: [(f64, usize); 4] = [(6.0, 12), (8.0, 16), (12.0, 24), (16.0, 32)];
/// The reference's layer thicknesses (px of defocus); the first is the one everything is measured against.
const REFERENCE_LAYERS: [f64; 3] = [0.5, 2.0, 8.0];

struct Scene {
    plate: HdrImage,
    depth_mm: Vec<f64>,
    model: DofModel,
}

fn scene(flare: &PreparedFlare, width: u32, height: u32) -> Result<Scene> {
    let (plate, depth) = dof::scene::street(width, height);
    let model =
        DofModel::new(&flare.system.lens, flare.system.settings.stop_scale, FOCUS_M, 36.0, (width, height), true)?;
    Ok(Scene { plate, depth_mm: depth.millimetres(), model })
}

pub fn run(args: &BenchArgs) -> Result<()> {
    let (width, height) = flare_core::frame::parse_size(args.size.as_deref().unwrap_or("960x540"))
        .map_err(|e| anyhow::anyhow!("--size: {e}"))?;
    let name = args.lens.first().cloned().unwrap_or_else(|| DEFAULT_LENS.to_owned());
    let lens = open_lens(&name)?;
    let flare = PreparedFlare::new(&lens, &FlareConfig::default()).with_context(|| name.clone())?;
    let repeats = super::checked_repeats(args.repeats, 3)?;
    if let Some(readme) = &args.update_readme {
        super::readme_section(readme, (README_START, README_END))?;
    }
    std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    let s = scene(&flare, width, height)?;
    let mask = flare.mask();
    eprintln!(
        "depth of field on the street ({width}x{height}) through {} at f/{:.1}, focus {FOCUS_M} m: the far field blurs to {:.1} px",
        lens.id,
        flare.system.first_order.f_number,
        s.model.far_defocus_px()
    );
    let row = |method: String, ms: f64, runs: usize, errors: Comparison, gpu: Option<(f64, String)>| Row {
        lens: lens.id.clone(),
        surfaces: lens.surfaces.len(),
        ghosts: 0,
        field_deg: 0.0,
        method,
        ms_median: ms,
        runs,
        errors,
        gpu,
    };
    let mut rows = Vec::new();
    // The finest reference, once: everything is measured against it.
    let started = Instant::now();
    let reference = dof::reference::render_layers(&s.plate, &s.depth_mm, &s.model, mask, REFERENCE_LAYERS[0])?;
    let reference_ms = started.elapsed().as_secs_f64() * 1e3;
    eprintln!("reference ({} px layers): {:.1} s", REFERENCE_LAYERS[0], reference_ms / 1e3);
    let judge = metrics::Reference::new(&reference, &[]);
    // Measured against itself: no error to chart (PSNR infinite, shown as "itself").
    let itself = Comparison { psnr_db: f64::INFINITY, ..judge.compare(&reference, &[]) };
    rows.push(row(format!("reference-{}px", REFERENCE_LAYERS[0]), reference_ms, 1, itself, None));
    let images = args.out.join("dof");
    std::fs::create_dir_all(&images)?;
    write_png(&images.join("plate.png"), &s.plate)?;
    write_png(&images.join("reference.png"), &reference)?;
    for &layer_px in &REFERENCE_LAYERS[1..] {
        let (ms, runs, image) =
            timed(1, || Ok(dof::reference::render_layers(&s.plate, &s.depth_mm, &s.model, mask, layer_px)?))?;
        rows.push(row(format!("reference-{layer_px}px"), ms, runs, judge.compare(&image, &[]), None));
        eprintln!("reference ({layer_px} px layers): {ms:.0} ms, {:.1} dB", rows.last().unwrap().errors.psnr_db);
    }
    let mut gpu = live_gpu();
    let adapter = gpu.as_ref().map(|(ctx, _)| ctx.adapter.name.clone());
    for (taps, layers) in LIVE {
        let settings = LiveSettings { taps_across: taps, max_layers: layers };
        let label = format!("{taps}x{layers}");
        let (ms, runs, image) =
            timed(
                repeats,
                || Ok(LivePlan::with_settings(&s.depth_mm, &s.model, mask, settings)?.render_cpu(&s.plate)),
            )?;
        rows.push(row(format!("dof-live-cpu-{label}"), ms, runs, judge.compare(&image, &[]), None));
        if settings == LiveSettings::default() {
            write_png(&images.join("live.png"), &image)?;
        }
        if let Some((ctx, dof)) = gpu.as_mut() {
            let mut gpu_ms = Vec::new();
            let (ms, runs, out) = timed(repeats, || {
                let plan = LivePlan::with_settings(&s.depth_mm, &s.model, mask, settings)?;
                let out = dof.render(ctx, &plan, &s.plate)?;
                gpu_ms.extend(out.gpu_ms);
                Ok(out.image)
            })?;
            let gpu_time = (!gpu_ms.is_empty()).then(|| (metrics::median(&gpu_ms), "dof".to_owned()));
            rows.push(row(format!("dof-live-gpu-{label}"), ms, runs, judge.compare(&out, &[]), gpu_time));
        }
        eprintln!(
            "live {label}: {}",
            rows.iter().rev().take(1 + usize::from(gpu.is_some())).map(summary).collect::<Vec<_>>().join("; ")
        );
    }
    let hd = full_hd_times(&flare, repeats, gpu.as_mut())?;
    let threads = rayon::current_num_threads();
    let md = markdown(&rows, &hd, &lens.id, width, height, s.model.far_defocus_px(), threads, adapter.as_deref());
    flare_core::files::write_atomic(&args.out.join("dof_bench.md"), md.as_bytes())?;
    flare_core::files::write_atomic(&args.out.join("dof_bench.csv"), super::csv(&rows).as_bytes())?;
    super::plot::error_against_time_titled(
        &rows,
        &args.out.join("dof_bench.png"),
        "Depth of field: error against run time (the street, each point one method and setting)",
    )?;
    println!("{md}");
    if let Some(readme) = &args.update_readme {
        super::update_readme(readme, (README_START, README_END), &md)?;
    }
    Ok(())
}

/// The headless GPU and its depth-of-field pass, or `None` (said once) where there is none.
fn live_gpu() -> Option<(GpuContext, GpuDof)> {
    match GpuContext::headless(false) {
        Ok(ctx) => {
            let dof = GpuDof::new(&ctx.device);
            Some((ctx, dof))
        }
        Err(e) => {
            eprintln!("no dof-live-gpu rows: {e}");
            None
        }
    }
}

/// One device's frame time at 1920x1080: (device, median ms, runs, median GPU ms).
type HdTime = (String, f64, usize, Option<f64>);

/// The live method's frame time at 1920x1080 (default settings): the CPU twin's, and the GPU's where there
/// is one.
fn full_hd_times(flare: &PreparedFlare, repeats: usize, gpu: Option<&mut (GpuContext, GpuDof)>) -> Result<Vec<HdTime>> {
    let mask = flare.mask();
    let full = scene(flare, 1920, 1080)?;
    let (cpu_ms, cpu_runs, _) =
        timed(repeats, || Ok(LivePlan::new(&full.depth_mm, &full.model, mask)?.render_cpu(&full.plate)))?;
    let mut hd = vec![("CPU twin".to_owned(), cpu_ms, cpu_runs, None)];
    if let Some((ctx, dof)) = gpu {
        let mut gpu_ms = Vec::new();
        let (ms, runs, _) = timed(repeats, || {
            let plan = LivePlan::new(&full.depth_mm, &full.model, mask)?;
            let out = dof.render(ctx, &plan, &full.plate)?;
            gpu_ms.extend(out.gpu_ms);
            Ok(())
        })?;
        hd.push((
            format!("GPU: {}", ctx.adapter.name),
            ms,
            runs,
            (!gpu_ms.is_empty()).then(|| metrics::median(&gpu_ms)),
        ));
    }
    Ok(hd)
}

fn summary(r: &Row) -> String {
    format!("{} {:.0} ms, {:.1} dB, SSIM {:.4}", r.method, r.ms_median, r.errors.psnr_db, r.errors.ssim)
}

fn write_png(path: &Path, image: &HdrImage) -> Result<()> {
    flare_core::output::write_linear(path, image)?;
    Ok(())
}

#[allow(clippy::too_many_arguments)]
fn markdown(
    rows: &[Row],
    hd: &[HdTime],
    lens: &str,
    width: u32,
    height: u32,
    far_px: f64,
    threads: usize,
    adapter: Option<&str>,
) -> String {
    let mut out = format!(
        "The street at {width}x{height} through `{lens}` wide open, focus {FOCUS_M} m (the far field blurs to {far_px:.0} px), cat's eye on, \
         6 blades; {threads} CPU threads{}. Errors against the reference with 0.5 px layers (display values at its exposure, ACES).\n\n",
        adapter.map_or(String::new(), |a| format!("; GPU rows on {a}"))
    );
    out.push_str("| method | median ms | runs | GPU ms (timestamps) | PSNR dB | SSIM |\n|---|---|---|---|---|---|\n");
    for r in rows {
        let psnr = if r.errors.psnr_db.is_finite() { format!("{:.1}", r.errors.psnr_db) } else { "(itself)".into() };
        out.push_str(&format!(
            "| {} | {:.0} | {} | {} | {psnr} | {:.4} |\n",
            r.method,
            r.ms_median,
            r.runs,
            r.gpu.as_ref().map_or("-".into(), |g| format!("{:.1}", g.0)),
            r.errors.ssim
        ));
    }
    out.push_str("\nThe live method (default settings, 12 taps across, at most 24 layers) at 1920x1080, wall time with upload and read-back:\n\n");
    out.push_str("| where | median ms | runs | GPU ms (timestamps) |\n|---|---|---|---|\n");
    for (name, ms, runs, gpu) in hd {
        out.push_str(&format!("| {name} | {ms:.0} | {runs} | {} |\n", gpu.map_or("-".into(), |g| format!("{g:.1}"))));
    }
    out
}
