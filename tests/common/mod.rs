//! What the UI test binaries share: the app in egui_kittest's harness (quiet: no automatic bake, no disk
//! cache), on a wgpu device (lavapipe in CI) where a test needs the viewport, and the documents they open.
#![allow(dead_code)]

use egui_kittest::Harness;
use flarelab::app::FlareLabApp;

/// The app with the automatic bake off and no disk cache: a test that is not about LUTs neither spends a
/// core on a background bake nor writes to the user's cache.
pub fn quiet(mut app: FlareLabApp) -> FlareLabApp {
    app.jobs_mut().autobake_mut().enabled = false;
    app.jobs_mut().autobake_mut().cache = None;
    app
}

/// The Heliar wide open (a small lens: a quick bake).
pub fn heliar() -> flare_core::preset::Document {
    flare_core::preset::Document::open_named("heliar-portrait").unwrap()
}

/// The app on a wgpu device (lavapipe in CI), so that its viewport draws and uploads textures as in the window;
/// `None` with the reason printed when there is no adapter, a failure under `FLARELAB_REQUIRE_GPU=1`.
pub fn gpu_harness(stored: Option<flare_core::preset::Document>) -> Option<Harness<'static, FlareLabApp>> {
    let adapter_ok = pollster::block_on(async {
        let instance = wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        instance.request_adapter(&wgpu::RequestAdapterOptions::default()).await.is_ok()
    });
    if !adapter_ok {
        flare_core::render::gpu::skip_without_gpu("no wgpu adapter (install mesa-vulkan-drivers for lavapipe)");
        return None;
    }
    let render_state = egui_kittest::wgpu::create_render_state(
        egui_kittest::wgpu::default_wgpu_setup(),
        eframe::egui_wgpu::RendererOptions::PREDICTABLE,
    );
    let app = quiet(FlareLabApp::new(Some(render_state.clone()), stored));
    Some(
        Harness::builder()
            .with_size(egui::vec2(1280.0, 800.0))
            .renderer(egui_kittest::wgpu::WgpuTestRenderer::from_render_state(render_state))
            .build_ui_state(|ui, app: &mut FlareLabApp| app.ui_root(ui), app),
    )
}

/// Steps the UI (with real time passing, for the bake thread) until `done` or `limit_s`.
pub fn step_until(h: &mut Harness<'static, FlareLabApp>, limit_s: f64, done: impl Fn(&FlareLabApp) -> bool) -> f64 {
    let started = std::time::Instant::now();
    while !done(h.state()) {
        assert!(started.elapsed().as_secs_f64() < limit_s, "not done after {limit_s} s: {:?}", h.state().bake_status());
        std::thread::sleep(std::time::Duration::from_millis(100));
        h.step();
    }
    started.elapsed().as_secs_f64()
}

/// The Heliar over the synthetic street of `width` x `height` written into `dir` (plate and depth map), focused
/// at 5 m, its depth of field `enabled` or not.
pub fn street_doc(dir: &std::path::Path, width: u32, height: u32, enabled: bool) -> flare_core::preset::Document {
    street_under(heliar(), dir, width, height, enabled)
}

/// `doc` over the synthetic street (see [`street_doc`]).
pub fn street_under(
    mut doc: flare_core::preset::Document,
    dir: &std::path::Path,
    width: u32,
    height: u32,
    enabled: bool,
) -> flare_core::preset::Document {
    let (plate, depth) = flare_core::dof::scene::street(width, height);
    let (plate_path, depth_path) = (dir.join("street.exr"), dir.join("street_z.exr"));
    flare_core::output::write_linear(&plate_path, &plate).unwrap();
    flare_core::dof::depth::write_exr(&depth_path, &depth).unwrap();
    doc.background = Some(plate_path.display().to_string());
    doc.dof = flare_core::dof::DofDoc {
        enabled,
        depth: Some(depth_path.display().to_string()),
        focus_m: 5.0,
        ..Default::default()
    };
    doc
}
