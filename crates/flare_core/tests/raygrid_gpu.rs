//! GPU ray grids (`render::raygrid`, `shaders/raygrid_*.wgsl`) against their f64 CPU twin: landings of the same
//! grid rays (the f32 drift, per lens, the anamorphic test lens's toroids included) and whole images at the same
//! grid.

use flare_core::flare::{FlareConfig, PreparedFlare};
use flare_core::metrics;
use flare_core::optics::library::builtin_lens;
use flare_core::raytrace::{Grid, RayGridRequest, Window};
use flare_core::render::gpu::test_context;
use flare_core::render::raygrid::{GpuRayGrid, GpuRayGridError, SUPERSAMPLE};

mod common;

/// A built-in lens by id, or `toroidal`: the anamorphic test lens of `tests/data/reference/toroidal/`.
fn prepared(id: &str) -> PreparedFlare {
    let lens = if id == "toroidal" { common::toroidal_test_lens() } else { builtin_lens(id).unwrap() };
    PreparedFlare::new(&lens, &FlareConfig::default()).unwrap()
}

/// Every traced vertex of the first jobs lands where the f64 tracer puts the same ray, to a few micrometres;
/// rays one says miss, the other says miss (but for a handful at grazing incidence). The tracer's two forms
/// (paths in workgroup memory, or in uniform chunks) give the same vertices to the bit.
#[test]
fn gpu_landings_follow_the_f64_tracer() {
    let Some(ctx) = test_context() else { return };
    let raygrid = GpuRayGrid::new(&ctx.device);
    let mut other_form = GpuRayGrid::new(&ctx.device);
    let window = Window::frame(480, 320);
    for (id, light) in [
        ("pbrt_dgauss_50mm", [6.0, 3.0]),
        ("heliar", [10.0, -4.0]),
        ("zeiss_master_prime", [5.0, 3.0]),
        ("aspheric_zoom", [8.0, 2.0]),
        ("nikon_zoom_28_75mm", [8.0, 5.0]),
        ("toroidal", [8.0, 5.0]),
    ] {
        let flare = prepared(id);
        let renderer = flare.ray_grid_renderer();
        let (jobs, vertices) = raygrid.trace_vertices(&ctx, &renderer, light, window, 16, 60).unwrap();
        assert!(!jobs.is_empty(), "{id}: no job has light");
        // The tracer's other form reads the paths from elsewhere and traces the same rays to the same bits.
        other_form.set_chunked_paths(!raygrid.chunked_paths());
        let (_, again) = other_form.trace_vertices(&ctx, &renderer, light, window, 16, 60).unwrap();
        assert!(
            bytemuck::cast_slice::<_, u8>(&again) == bytemuck::cast_slice::<_, u8>(&vertices),
            "{id}: the tracer's two forms differ"
        );
        let (mut worst_mm, mut compared, mut disagree) = (0.0f64, 0usize, 0usize);
        let mut drifts = Vec::new();
        let per_job = 17 * 17;
        let k = window.px_per_mm();
        for (j, job) in jobs.iter().enumerate() {
            let b = job.bounds;
            for v in 0..per_job {
                let x0 = [b[0] + (v % 17) as f64 * (b[2] - b[0]) / 16.0, b[1] + (v / 17) as f64 * (b[3] - b[1]) / 16.0];
                let (landing_mm, valid) = renderer.trace_planned(job, x0);
                let gpu = vertices[j * per_job + v];
                if valid != (gpu.valid != 0) {
                    disagree += 1;
                    continue;
                }
                if !valid {
                    continue;
                }
                // The GPU's landing is in window pixels (x left, y down from the centre): back to sensor mm.
                let gpu_mm = window.to_mm([f64::from(gpu.pixel[0]), f64::from(gpu.pixel[1])]);
                let d = (gpu_mm[0] - landing_mm[0]).hypot(gpu_mm[1] - landing_mm[1]);
                worst_mm = worst_mm.max(d);
                drifts.push(d);
                compared += 1;
            }
        }
        drifts.sort_by(f64::total_cmp);
        let at = |q: f64| drifts[((drifts.len() - 1) as f64 * q) as usize];
        eprintln!("{id}: drift median {:.2e}, 99% {:.2e}, 99.9% {:.2e} mm", at(0.5), at(0.99), at(0.999));
        eprintln!(
            "{id}: {compared} landings, f32 drift at most {:.2e} mm ({:.3} px at 480 wide); {disagree} rays missed by one tracer only",
            worst_mm,
            worst_mm * k
        );
        assert!(compared > 1000, "{id}: {compared}");
        // f32 keeps typical landings within nanometres; a few rays at grazing incidence or near a rim amplify
        // rounding, so the bound is on the 99th percentile and, loosely, the worst.
        assert!(at(0.99) < 1e-3, "{id}: f32 landings drift {} mm at the 99th percentile", at(0.99));
        assert!(worst_mm < 0.2, "{id}: f32 landings drift {worst_mm} mm");
        assert!(disagree * 200 < compared, "{id}: {disagree} of {compared} rays disagree on missing");
    }
}

/// The GPU's image of a frame against the CPU renderer's at the same grid: PSNR and SSIM on display values at
/// the CPU image's exposure. Box-filtered (the default, a compute pass) it is the CPU's image but for the f32
/// trace: at least 50 dB and the energy within 0.5% (measured on lavapipe: 60.3, 91.0 and 61.1 dB); rasterised
/// at one sample a pixel (the path kept to compare) it aliases (36-38 dB).
#[test]
fn gpu_ray_grids_draw_the_cpu_ray_grid_image() {
    let Some(ctx) = test_context() else { return };
    let raygrid = GpuRayGrid::new(&ctx.device);
    let (w, h) = (240, 160);
    for (id, light, cells) in [
        ("pbrt_dgauss_50mm", [6.0, 3.0], 64),
        ("heliar", [10.0, -4.0], 64),
        ("zeiss_master_prime", [5.0, 3.0], 48),
        ("toroidal", [8.0, 5.0], 48),
    ] {
        let flare = prepared(id);
        let renderer = flare.ray_grid_renderer();
        let cpu = renderer.render(light, w, h, Grid::Fixed(cells)).unwrap();
        let gpu = raygrid.render(&ctx, &renderer, light, Window::frame(w, h), cells, SUPERSAMPLE, &[]).unwrap();
        let point = raygrid.render(&ctx, &renderer, light, Window::frame(w, h), cells, 1, &[]).unwrap();
        eprintln!(
            "{id}: one sample per pixel: PSNR {:.1} dB",
            metrics::compare(&point.hdr, &[], &cpu.hdr, &[]).psnr_db
        );
        let c = metrics::compare(&gpu.hdr, &[], &cpu.hdr, &[]);
        let energy = |img: &flare_core::image::HdrImage| -> f64 {
            img.pixels.iter().map(|p| f64::from(p[0] + p[1] + p[2])).sum()
        };
        let ratio = energy(&gpu.hdr) / energy(&cpu.hdr);
        eprintln!(
            "{id} grid {cells}: {} jobs, PSNR {:.1} dB, SSIM {:.4}, energy GPU/CPU {ratio:.4}",
            gpu.jobs, c.psnr_db, c.ssim
        );
        assert!((ratio - 1.0).abs() < 0.005, "{id}: energy {ratio}");
        assert!(c.psnr_db > 50.0, "{id}: {c:?}");
    }
}

/// The box filter's sums are fixed-point integers: the same frame twice gives the same bytes, and a frame drawn
/// in strips of rows (as one whose sums pass the adapter's storage binding limit is) gives the bytes of one
/// piece.
#[test]
fn gpu_ray_grids_are_deterministic_and_draw_in_strips() {
    let Some(ctx) = test_context() else { return };
    let mut raygrid = GpuRayGrid::new(&ctx.device);
    let flare = prepared("pbrt_dgauss_50mm");
    let renderer = flare.ray_grid_renderer();
    // Wider than one chunk of the scanning resolve (256 columns), so that its sums carry from chunk to chunk.
    let (w, h) = (300, 130);
    let render = |raygrid: &GpuRayGrid| {
        raygrid.render(&ctx, &renderer, [7.0, -2.0], Window::frame(w, h), 32, SUPERSAMPLE, &[]).unwrap().hdr
    };
    let first = render(&raygrid);
    assert!(first.pixels.iter().any(|p| p[0] > 0.0));
    assert!(render(&raygrid) == first, "two runs differ");
    // 7 rows a strip: 19 strips, each tracing the jobs again.
    raygrid.box_strip_bytes = 7 * u64::from(w) * flare_core::render::raygrid::BOX_BYTES_PER_PIXEL;
    let strips = raygrid.render(&ctx, &renderer, [7.0, -2.0], Window::frame(w, h), 32, SUPERSAMPLE, &[]).unwrap();
    assert!(strips.batches >= 19, "{} dispatches", strips.batches);
    assert!(strips.hdr == first, "drawn in strips, the frame differs");
    // The other forms (a GPU's: each triangle's rows split over 8 invocations, each row resolved by a
    // workgroup's scan; lavapipe's: an invocation per triangle and per row), in strips and whole: the same bytes.
    let other = if raygrid.row_split() > 1 { 1 } else { 8 };
    raygrid.set_row_split(&ctx.device, other);
    assert!(render(&raygrid) == first, "row split {other}: drawn in strips, the frame differs");
    raygrid.box_strip_bytes = u64::MAX;
    assert!(render(&raygrid) == first, "row split {other}: the frame differs");
    // The tracer's other form (a GPU's: each job's path in workgroup memory, one dispatch; lavapipe's: paths in
    // uniform chunks, a dispatch a chunk): the same bytes.
    let chunked = !raygrid.chunked_paths();
    raygrid.set_chunked_paths(chunked);
    assert!(render(&raygrid) == first, "paths chunked {chunked}: the frame differs");
}

/// Per-ghost gains (a preset's gains, `enabled` and `solo`, as a frame request carries them) reach the ray
/// grids: on the CPU, one ghost at gain 0.5 and the rest at 0 is exactly half of that ghost traced alone; on the
/// GPU the same gains give the CPU's image (at least 50 dB).
#[test]
fn ray_grids_honour_per_ghost_gains() {
    let flare = prepared("heliar");
    let renderer = flare.ray_grid_renderer();
    let (w, h, light) = (160, 100, [8.0, 3.0]);
    let grid = Grid::Fixed(24);
    let all = renderer.render(light, w, h, grid).unwrap();
    // The brightest ghost: the one whose light is largest alone.
    let energy = |img: &flare_core::image::HdrImage| -> f64 { img.pixels.iter().map(|p| f64::from(p[1])).sum() };
    let g = (0..flare.system.ghosts.len())
        .max_by(|&a, &b| all.moments[a].energy.total_cmp(&all.moments[b].energy))
        .unwrap();
    let alone = renderer.render_request(&RayGridRequest::frame(light, w, h, grid).only(g)).unwrap().remove(0);
    let mut gains = vec![0.0f32; flare.system.ghosts.len()];
    gains[g] = 0.5;
    let half = renderer.render_request(&RayGridRequest::frame(light, w, h, grid).weighted(&gains)).unwrap().remove(0);
    assert!(energy(&alone.hdr) > 0.0 && energy(&alone.hdr) < energy(&all.hdr));
    for (a, b) in half.hdr.pixels.iter().zip(&alone.hdr.pixels) {
        for c in 0..3 {
            assert_eq!(a[c], 0.5 * b[c], "ghost {g} at gain 0.5 is half of it alone");
        }
    }
    // Missing entries are 1: no gains is every ghost.
    let ones = renderer.render_request(&RayGridRequest::frame(light, w, h, grid).weighted(&[])).unwrap().remove(0);
    assert!((energy(&ones.hdr) / energy(&all.hdr) - 1.0).abs() < 1e-9);
    let Some(ctx) = test_context() else { return };
    let raygrid = GpuRayGrid::new(&ctx.device);
    let gpu = raygrid.render(&ctx, &renderer, light, Window::frame(w, h), 24, SUPERSAMPLE, &gains).unwrap();
    let c = metrics::compare(&gpu.hdr, &[], &half.hdr, &[]);
    eprintln!("ghost {g} at gain 0.5 alone: GPU against CPU {:.1} dB, {} jobs", c.psnr_db, gpu.jobs);
    assert!(c.psnr_db > 50.0, "{c:?}");
    assert!(gpu.jobs <= 3, "only the ghost with gain is traced: {} jobs", gpu.jobs);
}

/// A grid beyond the adapter's limits is refused, naming the limit, before anything is dispatched.
#[test]
fn a_grid_beyond_the_adapters_limits_is_refused() {
    let Some(ctx) = test_context() else { return };
    let raygrid = GpuRayGrid::new(&ctx.device);
    let flare = prepared("heliar");
    let renderer = flare.ray_grid_renderer();
    let e = raygrid.render(&ctx, &renderer, [3.0, 2.0], Window::frame(64, 48), 4096, 1, &[]).unwrap_err();
    assert!(matches!(e, GpuRayGridError::Limit { .. }), "{e}");
    let text = e.to_string();
    assert!(text.contains("limit") && text.contains("max_"), "{text}");
    eprintln!("{text}");
}

/// A device lost before a render: an error that says so (the command line then traces on the CPU), no panic.
#[test]
fn a_lost_device_is_an_error_not_a_panic() {
    let Some(ctx) = test_context() else { return };
    let raygrid = GpuRayGrid::new(&ctx.device);
    let flare = prepared("heliar");
    let renderer = flare.ray_grid_renderer();
    ctx.device.destroy();
    let e = raygrid.render(&ctx, &renderer, [3.0, 2.0], Window::frame(64, 48), 16, 1, &[]).unwrap_err();
    assert!(matches!(e, GpuRayGridError::Gpu(flare_core::render::gpu::GpuError::Lost(_))), "{e}");
    eprintln!("{e}");
}

/// The LUT bake on the GPU (`GpuBake`: the same scouts and windows, each column traced in f32 and drawn at 4 x 4
/// samples a texel) makes the same entries as the CPU bake within a measured tolerance: per entry the
/// relative L1 of luminance and the energy ratio, on two lenses and ghosts of both kinds (one stop crossing and
/// three), several thetas and azimuths each.
#[test]
fn gpu_bake_matches_the_cpu_bake() {
    use flare_core::bake::{BakeSettings, bake, bake_with};
    use flare_core::render::raygrid::GpuBake;
    use half::f16;
    use std::sync::atomic::AtomicBool;
    let Some(ctx) = test_context() else { return };
    let settings = BakeSettings {
        theta_max_deg: Some(16.0),
        res: 64,
        grid: 48,
        initial_steps: 2,
        tolerance: 0.3,
        min_step_deg: 4.0,
        ..BakeSettings::default()
    };
    let luma = |p: &[f16; 4]| 0.2126 * p[0].to_f64() + 0.7152 * p[1].to_f64() + 0.0722 * p[2].to_f64();
    let (mut l1s, mut worst_energy, mut compared) = (Vec::new(), 0.0f64, 0usize);
    for (id, ghosts) in [("pbrt_dgauss_50mm", vec![3usize, 7, 20]), ("heliar", vec![2, 9])] {
        let flare = prepared(id);
        let renderer = flare.ray_grid_renderer();
        let cancel = AtomicBool::new(false);
        let cpu = bake(&flare, &renderer, &ghosts, &settings, None, &|_| {}, &cancel).unwrap();
        let gpu_bake = GpuBake::new(&ctx, SUPERSAMPLE);
        let gpu = bake_with(&flare, &renderer, &gpu_bake, &ghosts, &settings, None, &|_| {}, &cancel).unwrap();
        assert_eq!(gpu_bake.fell_back(), None, "{id}: the GPU fell back");
        let (on_gpu, on_cpu) = gpu_bake.columns();
        assert!(on_gpu > 0 && on_cpu == 0, "{id}: {on_gpu} columns on the GPU, {on_cpu} on the CPU");
        for (c, g) in cpu.ghosts.iter().zip(&gpu.ghosts) {
            for e in &c.entries {
                // The refinement may split an interval one way and not the other: compare the entries both have.
                let Some(f) = g.entries.iter().find(|f| f.theta_deg == e.theta_deg && f.phi_deg == e.phi_deg) else {
                    continue;
                };
                assert_eq!(e.is_empty(), f.is_empty(), "{id} ghost {} at {} deg", c.ghost, e.theta_deg);
                if e.is_empty() {
                    continue;
                }
                assert_eq!((e.width, e.height, e.centre_mm), (f.width, f.height, f.centre_mm), "windows differ");
                let total: f64 = e.texels.iter().map(luma).sum();
                let diff: f64 = e.texels.iter().zip(&f.texels).map(|(a, b)| (luma(a) - luma(b)).abs()).sum();
                l1s.push(diff / total.max(1e-30));
                worst_energy = worst_energy.max((f.energy() / e.energy() - 1.0).abs());
                compared += 1;
            }
        }
    }
    l1s.sort_by(f64::total_cmp);
    let (median, worst) = (l1s[l1s.len() / 2], l1s[l1s.len() - 1]);
    eprintln!(
        "GPU bake vs CPU bake: {compared} entries; relative L1 median {median:.4}, worst {worst:.4}; energy worst {worst_energy:.4}"
    );
    assert!(compared >= 20, "only {compared} entries compared");
    assert!(median < 0.015 && worst < 0.04, "relative L1 median {median}, worst {worst}");
    assert!(worst_energy < 0.02, "energy off by {worst_energy}");
}
