//! Speed of the paraxial flare (criterion): the per-frame CPU cost of every ghost with matrices cached, the
//! full rebuild after a lens edit, a whole 1280x720 GPU frame (lavapipe where there is no GPU), with and
//! without a dusty front element, and the front dirt's own costs (its map prepared once per lens and stop,
//! its glow per frame on the CPU twin), and what an edit of the stop's shape costs (its mask levels and
//! starburst made anew: a blade rotation dragged in the app pays it every frame).
//! Targets (issue 3): frame under 20 us and rebuild under 1 ms for a lens of 25+ surfaces.
//! Run: `cargo bench -p flare_core --bench flare`.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use flare_core::aperture::{Aperture, ApertureShape};
use flare_core::flare::{FlareConfig, PreparedFlare};
use flare_core::frame::{Frame, FrameRequest, GpuDrawer, Sources};
use flare_core::ghost::{FrameSettings, GhostFrame, GhostSettings, GhostSystem};
use flare_core::optics::Lens;
use flare_core::optics::library::{builtin_lens, synthetic_lens};
use flare_core::render::DisplaySettings;

fn lenses() -> Vec<(String, Lens)> {
    vec![
        ("heliar_9".to_owned(), builtin_lens("heliar").unwrap()),
        ("synthetic_26".to_owned(), synthetic_lens(26)),
        ("synthetic_60".to_owned(), synthetic_lens(60)),
    ]
}

fn ghost_frame(c: &mut Criterion) {
    let mut group = c.benchmark_group("ghost_frame_rgb");
    for (name, lens) in lenses() {
        let system = GhostSystem::build(&lens, &GhostSettings::default()).unwrap();
        let settings = FrameSettings::default();
        let mut frame = GhostFrame::default();
        let mut k = 0u32;
        group.bench_function(&name, |b| {
            b.iter(|| {
                // The light moves every frame, as when it is dragged.
                k = k.wrapping_add(1);
                let t = (k % 100) as f64 * 0.002;
                system.frame_into(black_box([0.05 + t, -0.03 + t]), &settings, &mut frame);
                black_box(frame.stats.drawn)
            })
        });
    }
    group.finish();
}

fn ghost_rebuild(c: &mut Criterion) {
    let mut group = c.benchmark_group("ghost_rebuild_rgb");
    for (name, lens) in lenses().into_iter().take(2) {
        group.bench_function(&name, |b| {
            b.iter(|| GhostSystem::build(black_box(&lens), &GhostSettings::default()).unwrap())
        });
    }
    group.finish();
}

fn gpu_frame(c: &mut Criterion) {
    // The app's path: a frame built by the one pipeline, drawn by the GPU entry point, waited for.
    let mut drawer = match GpuDrawer::new(false) {
        Ok(drawer) => drawer,
        Err(e) => {
            println!("gpu_frame skipped: {e}");
            return;
        }
    };
    println!("gpu_frame on {} ({:?})", drawer.ctx.adapter.name, drawer.ctx.adapter.device_type);
    let mut group = c.benchmark_group("gpu_frame_1280x720");
    group.sample_size(10);
    let target = flare_core::render::gpu::texture_2d(
        &drawer.ctx.device,
        "bench target",
        1280,
        720,
        drawer.renderer.target_format(),
        drawer.renderer.target_usage(),
    );
    let view = target.create_view(&wgpu::TextureViewDescriptor::default());
    let cases = [
        ("heliar_9", 1),
        ("heliar_9_half_res", 2),
        ("heliar_9_dusty", 1),
        ("synthetic_26", 1),
        ("synthetic_26_half_res", 2),
    ];
    for (name, divisor) in cases {
        let lens = if name.starts_with("heliar") { builtin_lens("heliar").unwrap() } else { synthetic_lens(26) };
        let dusty = name.ends_with("dusty");
        let dirt = dusty.then_some(flare_core::dirt::DirtPattern::Dust { seed: 1 });
        let flare = PreparedFlare::new(&lens, &FlareConfig { dirt, ..FlareConfig::default() }).unwrap();
        let dirt_amount = if dusty { 0.01 } else { 0.0 };
        let sources = Sources { flare: &flare, lut: None, plate: None };
        let mut k = 0u32;
        group.bench_function(name, |b| {
            b.iter(|| {
                k = k.wrapping_add(1);
                let t = (k % 50) as f64 * 0.1;
                let request = FrameRequest {
                    light_deg: [4.0 + t, 3.0 - t],
                    display: DisplaySettings {
                        accumulation_divisor: divisor,
                        dirt_amount,
                        ..DisplaySettings::default()
                    },
                    ..FrameRequest::default()
                };
                let frame = Frame::build(&flare, None, &request);
                drawer.render_into(&frame, &sources, &view).unwrap();
            })
        });
    }
    group.finish();
}

fn dirt(c: &mut Criterion) {
    let mut group = c.benchmark_group("dirt");
    group.sample_size(10);
    let lens = builtin_lens("heliar").unwrap();
    let flare = PreparedFlare::new(&lens, &FlareConfig::default()).unwrap();
    let pattern = flare_core::dirt::DirtPattern::Dust { seed: 1 };
    group.bench_function("prepare_map_320", |b| {
        b.iter(|| flare_core::dirt::PreparedDirt::new(&flare.system, flare.mask(), black_box(&pattern)))
    });
    let dusty = PreparedFlare::new(&lens, &FlareConfig { dirt: Some(pattern), ..FlareConfig::default() }).unwrap();
    let request = FrameRequest {
        display: DisplaySettings { dirt_amount: 0.01, ..DisplaySettings::default() },
        ..FrameRequest::default()
    };
    let frame = Frame::build(&dusty, None, &request);
    let mut image = flare_core::image::HdrImage::black(frame.scene.hdr_width, frame.scene.hdr_height);
    group.bench_function("cpu_glow_1280x720", |b| {
        b.iter(|| flare_core::render::cpu::dirt_pass(&frame.scene, dusty.dirt.as_ref(), black_box(&mut image)))
    });
    group.finish();
}

/// A prepared flare for a stop shape not seen before (each iteration turns the blades by another step, so the
/// cache of recent shapes never has it): the ghost system, the three mask levels and the starburst's FFT.
fn stop_shape(c: &mut Criterion) {
    let mut group = c.benchmark_group("stop_shape");
    group.sample_size(20);
    let lens = builtin_lens("heliar").unwrap();
    let mut k = 0u32;
    group.bench_function("new_shape_heliar_9", |b| {
        b.iter(|| {
            k = k.wrapping_add(1);
            let shape = ApertureShape::Blades { count: 6, rotation_deg: 0.01 * f64::from(k), roundness: 0.2 };
            let config = FlareConfig { aperture: Aperture { shape, f_number: None }, ..FlareConfig::default() };
            PreparedFlare::new(black_box(&lens), &config).unwrap()
        })
    });
    group.finish();
}

criterion_group!(benches, ghost_frame, ghost_rebuild, gpu_frame, dirt, stop_shape);
criterion_main!(benches);
