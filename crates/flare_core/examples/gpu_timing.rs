//! The paraxial (or, given a `.flut`, blended) frame of a built-in lens on the CPU twin and on the GPU, with the
//! ghosts drawn by the compute passes and by the raster passes (the tonemap too): medians of 9 frames, each
//! waited for (no read-back), and the GPU's own time of the passes by timestamps. What the README's lavapipe
//! and real-GPU tables came from. The starburst is left out unless the last argument is `starburst`.
//!
//! `cargo run --release -p flare_core --example gpu_timing -- LENS WIDTH HEIGHT [LUT.flut] [starburst] [compute]
//! [resolve=rows|scan] [pieces=N] [buffer] [gather] [once] [inline]` (`compute`: the GPU compute passes only,
//! no CPU twin and no raster passes; the rest pick the ghost pass's form, `render::gpu_ghosts::ComputeForm`,
//! from the device's own: `buffer` and `gather` look the stop masks up as words (the texture of words) or by
//! `textureGather`, `once` works each item out once,
//! `pieces=N` or `once` spread the items over invocations rather than a workgroup a sprite, `resolve=` picks the
//! per-row sum; `frames=N`: N frames rather than 9, their medians; `inline`: the LUT
//! pass samples its coarse instances at every pixel instead of into coarse images; `base-mask`: every sprite
//! reads the base level of the stop mask, as before `GhostMasks`, for a before-and-after in one build).

use std::time::Instant;

use flare_core::flare::{FlareConfig, PreparedFlare};
use flare_core::frame::{self, Frame, FrameRequest, GpuDrawer, LutUse, Sources};
use flare_core::lut::blend::LiveLut;
use flare_core::metrics::median;
use flare_core::optics::library::builtin_lens;
use flare_core::render::DisplaySettings;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let usage = "usage: gpu_timing LENS WIDTH HEIGHT [LUT.flut] [starburst] [compute] [resolve=rows|scan] [pieces=N] \
                 [buffer] [gather] [once] [inline] [base-mask] [frames=N]";
    let flag = |name: &str| args.iter().any(|a| a == name);
    let value = |key: &str| args.iter().find_map(|a| a.strip_prefix(key).map(str::to_owned));
    let (starburst, compute_only) = (flag("starburst"), flag("compute"));
    let frames: usize = value("frames=").map_or(Ok(9), |n| n.parse())?;
    let form_args = (value("resolve="), value("pieces="), flag("buffer"), flag("once"));
    let options = ["starburst", "compute", "buffer", "inline", "once", "gather", "base-mask"];
    let args: Vec<String> =
        args.iter().filter(|a| !options.contains(&a.as_str()) && !a.contains('=')).cloned().collect();
    let lens = builtin_lens(args.get(1).ok_or(usage)?)?;
    let (w, h): (u32, u32) = (args.get(2).ok_or(usage)?.parse()?, args.get(3).ok_or(usage)?.parse()?);
    let flare = PreparedFlare::new(&lens, &FlareConfig::default())?;
    let live = match args.get(4) {
        Some(path) => Some(LiveLut::new(flare_core::lut::format::read_lut(std::path::Path::new(path))?)),
        None => None,
    };
    let request = FrameRequest {
        light_deg: [9.0, 5.0],
        width: w,
        height: h,
        display: DisplaySettings { starburst, ..DisplaySettings::default() },
        lut_use: if live.is_some() { LutUse::Blend } else { LutUse::Off },
        ..FrameRequest::default()
    };
    let sources = Sources { flare: &flare, lut: live.as_ref(), plate: None };
    let base_mask = flag("base-mask");
    let build = || {
        let mut f = Frame::build(&flare, live.as_ref(), &request);
        if base_mask {
            for stop in f.scene.instances.iter_mut().flat_map(|i| &mut i.stops) {
                stop[3] = stop[3].min(1.0);
            }
        }
        f
    };
    let cpu: Vec<f64> = (0..if compute_only { 0 } else { 9 })
        .map(|_| {
            let start = Instant::now();
            let f = build();
            let _ = frame::draw_cpu_hdr(&f, &sources);
            start.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    if !compute_only {
        println!("CPU twin: {:.1} ms", median(&cpu));
    }
    for raster in [false, true].into_iter().take(if compute_only { 1 } else { 2 }) {
        let mut drawer = GpuDrawer::new(true)?;
        drawer.renderer.set_lut_coarse_images(!flag("inline"));
        if raster {
            drawer.renderer.force_raster_ghosts();
        } else if let Some(mut form) = drawer.renderer.ghost_compute_form() {
            let (resolve, pieces, buffer, once) = &form_args;
            if let Some(r) = resolve {
                form.scan = match r.as_str() {
                    "rows" => false,
                    "scan" => true,
                    _ => return Err(usage.into()),
                };
            }
            if let Some(p) = pieces {
                form.pieces = Some(p.parse()?);
            }
            form.gather_masks = (form.gather_masks || flag("gather")) && !*buffer;
            form.setup_once |= *once;
            // Pieces or a walks buffer ask for the items spread over invocations (not a workgroup a sprite).
            form.sprite_groups &= !(*once || pieces.is_some());
            drawer.renderer.set_ghost_compute_form(form);
            println!("form: {form:?}");
        }
        // The raster row is the earlier path whole: its tonemap a fragment pass too (no storage binding).
        let usage = if raster { wgpu::TextureUsages::RENDER_ATTACHMENT } else { drawer.renderer.target_usage() };
        let format = drawer.renderer.target_format();
        let target = flare_core::render::gpu::texture_2d(&drawer.ctx.device, "t", w, h, format, usage);
        let view = target.create_view(&Default::default());
        let (mut wall, mut gpu, mut last) = (Vec::new(), Vec::new(), None);
        for _ in 0..frames {
            let start = Instant::now();
            let f = build();
            drawer.render_into(&f, &sources, &view)?;
            wall.push(start.elapsed().as_secs_f64() * 1e3);
            if let Some(t) = drawer.renderer.wait_pass_times(&drawer.ctx.device, &drawer.ctx.queue) {
                gpu.push(t.total_ms());
                last = Some(t.summary());
            }
        }
        // An error wgpu reported on its own (a pipeline that did not build) leaves nothing drawn: say so.
        if let Some(failure) = drawer.ctx.failure() {
            return Err(format!("the GPU reported: {failure}").into());
        }
        println!(
            "GPU ({}, {} passes): wall {:.1} ms, GPU time by timestamps {:.2} ms (last frame: {})",
            drawer.ctx.adapter.name,
            if raster { "raster" } else { "compute" },
            median(&wall),
            median(&gpu),
            last.unwrap_or_else(|| "no timestamp queries".to_owned())
        );
    }
    Ok(())
}
