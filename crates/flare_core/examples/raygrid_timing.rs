//! Ray grids on the CPU and on the GPU at one grid: wall-clock medians of 3 runs each, whole renders (plan,
//! trace, box filter, read-back), the GPU's own time of its passes by timestamps, and the GPU image against the
//! CPU's. What the issue-31 ratio is judged by.
//!
//! `cargo run --release -p flare_core --example raygrid_timing -- LENS WIDTH HEIGHT GRID FIELD_DEG`

use std::time::Instant;

use flare_core::flare::{FlareConfig, PreparedFlare};
use flare_core::metrics::median;
use flare_core::optics::library::builtin_lens;
use flare_core::raytrace::{Grid, Window};
use flare_core::render::gpu::GpuContext;
use flare_core::render::raygrid::{GpuRayGrid, SUPERSAMPLE};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let usage = "usage: raygrid_timing LENS WIDTH HEIGHT GRID FIELD_DEG";
    let lens = builtin_lens(args.get(1).ok_or(usage)?)?;
    let (w, h): (u32, u32) = (args.get(2).ok_or(usage)?.parse()?, args.get(3).ok_or(usage)?.parse()?);
    let grid: usize = args.get(4).ok_or(usage)?.parse()?;
    let theta: f64 = args.get(5).ok_or(usage)?.parse()?;
    // The bench's light: `theta` from the axis at 30 degrees azimuth.
    let (t, phi) = (theta.to_radians().tan(), 30f64.to_radians());
    let light = [(t * phi.cos()).atan().to_degrees(), (t * phi.sin()).atan().to_degrees()];
    let flare = PreparedFlare::new(&lens, &FlareConfig::default())?;
    let tracer = flare.ray_grid_renderer();
    let time = |f: &mut dyn FnMut()| {
        let start = Instant::now();
        f();
        start.elapsed().as_secs_f64() * 1e3
    };
    let mut cpu_image = None;
    let cpu: Vec<f64> = (0..3)
        .map(|_| time(&mut || cpu_image = Some(tracer.render(light, w, h, Grid::Fixed(grid)).unwrap())))
        .collect();
    let ctx = GpuContext::headless(true)?;
    let gpu_grid = GpuRayGrid::new(&ctx.device);
    let window = Window::frame(w, h);
    let mut gpu_image = None;
    let _ = gpu_grid.render(&ctx, &tracer, light, window, grid, SUPERSAMPLE, &[])?;
    let mut gpu_ms = Vec::new();
    let gpu: Vec<f64> = (0..3)
        .map(|_| {
            time(&mut || {
                let image = gpu_grid.render(&ctx, &tracer, light, window, grid, SUPERSAMPLE, &[]).unwrap();
                gpu_ms.extend(image.gpu_times.as_ref().map(|t| t.total_ms()));
                gpu_image = Some(image)
            })
        })
        .collect();
    let plan: Vec<f64> =
        (0..3).map(|_| time(&mut || drop(tracer.plan_fixed(light, window, grid, &[]).unwrap()))).collect();
    let (cpu_image, gpu_image) = (cpu_image.unwrap(), gpu_image.unwrap());
    let twin = flare_core::metrics::compare(&gpu_image.hdr, &[], &cpu_image.hdr, &[]);
    let (cpu, gpu, plan) = (median(&cpu), median(&gpu), median(&plan));
    println!(
        "{} {w}x{h} grid {grid} at {theta} deg on {}: CPU {cpu:.1} ms, GPU {gpu:.1} ms ({:.2}x; plan {plan:.1} ms), {} jobs, GPU vs CPU {:.1} dB",
        args[1],
        ctx.adapter.name,
        gpu / cpu,
        gpu_image.jobs,
        twin.psnr_db
    );
    match &gpu_image.gpu_times {
        Some(t) => {
            println!("GPU time by timestamps: median {:.2} ms of 3 (last run: {})", median(&gpu_ms), t.summary())
        }
        None => println!("GPU time by timestamps: none (the adapter has no timestamp queries)"),
    }
    let dense = gpu_image.jobs as u64 * ((grid + 1) * (grid + 1)) as u64;
    println!(
        "CPU: {} rays (the pre-pass's too), {} triangles; GPU: {dense} grid vertices (those outside the lit cells are not traced)",
        cpu_image.stats.rays, cpu_image.stats.triangles
    );
    Ok(())
}
