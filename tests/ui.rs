//! The app's panels driven by label through egui_kittest (no GPU needed), checked against the document;
//! and one snapshot of the whole window rendered by wgpu (lavapipe in CI; skipped with the reason printed
//! where no adapter exists).

use egui_kittest::Harness;
use egui_kittest::kittest::Queryable;
use flarelab::app::{FlareLabApp, Tab};

mod common;
use common::*;

fn harness() -> Harness<'static, FlareLabApp> {
    harness_on(None)
}

/// [`harness`] on `doc` (the default document when `None`).
fn harness_on(doc: Option<flare_core::preset::Document>) -> Harness<'static, FlareLabApp> {
    Harness::builder()
        .with_size(egui::vec2(1280.0, 800.0))
        .build_ui_state(|ui, app: &mut FlareLabApp| app.ui_root(ui), quiet(FlareLabApp::new(None, doc)))
}

/// The default document on the double Gauss (issue 32's scenarios of refused and accepted radii).
fn dgauss() -> flare_core::preset::Document {
    flare_core::preset::Document {
        lens: flare_core::optics::library::builtin_lens("dgauss").unwrap(),
        ..flare_core::preset::Document::default()
    }
}

fn show(h: &mut Harness<'static, FlareLabApp>, tab: Tab) {
    h.state_mut().show_tab(tab);
    h.run();
}

/// Clicks `item` in the menu of the Lens table's row `k` (its number), as a user does.
fn surface_menu(h: &mut Harness<'static, FlareLabApp>, k: usize, item: &str) {
    h.get_by_label(&k.to_string()).click();
    h.run();
    h.get_by_label(item).click();
    h.run();
}

const ADD_DUMMY: &str = "+ dummy surface after";
const REMOVE_SURFACE: &str = "x remove";

#[test]
fn editing_a_radius_marks_an_impossible_value_and_keeps_the_last_valid_lens() {
    let mut h = harness();
    show(&mut h, Tab::Lens);
    let before = h.state().doc().lens.surfaces[1].radius_mm;
    h.get_by_label("radius 1").set_value_accesskit(before * 1.1);
    h.run();
    let r = h.state().doc().lens.surfaces[1].radius_mm;
    assert!((r - before * 1.1).abs() < 1e-9, "radius {r}, wanted {}", before * 1.1);
    assert!(h.state().derived().lens_problem().is_none());
    let flare_before = h.state().flare().unwrap().system.lens.clone();
    assert_eq!(flare_before.surfaces[1].radius_mm, r, "the flare follows a valid edit");
    // A radius smaller than the clear semi-aperture is no sphere: refused, its cell marked, the flare kept.
    let stop = h.state().doc().lens.stop_index();
    h.get_by_label(&format!("radius {stop}")).set_value_accesskit(2.0);
    h.run();
    let problem = h.state().derived().lens_problem().clone().expect("an impossible radius is refused");
    assert_eq!((problem.surface, problem.field), (Some(stop), Some("radius")), "{problem:?}");
    assert!(problem.reason.contains("no sphere is that wide"), "{}", problem.reason);
    assert_eq!(h.state().flare().unwrap().system.lens, flare_before, "the viewport keeps the last valid lens");
    assert!(h.query_by_label_contains("the view shows the last valid lens").is_some(), "the reason is shown");
    // The status bar says it too, and stops saying it once the lens is valid again.
    let said = h.state().message().map(str::to_owned).unwrap_or_default();
    assert!(said.contains("lens edit refused") && said.contains("no sphere is that wide"), "{said}");
    // Undo (Ctrl+Z) takes the bad value back and the lens is valid again.
    h.key_press_modifiers(egui::Modifiers::COMMAND, egui::Key::Z);
    h.run();
    assert_eq!(h.state().doc().lens.surfaces[stop].radius_mm, 0.0);
    assert!(h.state().derived().lens_problem().is_none());
    let said = h.state().message().map(str::to_owned).unwrap_or_default();
    assert!(said.contains("valid again") && !said.contains("refused"), "{said}");
}

#[test]
fn blades_ghost_toggles_and_undo_redo_change_the_document() {
    let mut h = harness();
    show(&mut h, Tab::Aperture);
    h.get_by_role_and_label(egui::accesskit::Role::Slider, "blades").set_value_accesskit(9.0);
    h.run();
    assert_eq!(h.state().doc().aperture.blades, 9);
    let flare = h.state().flare().unwrap();
    assert!(
        matches!(flare.config.aperture.shape, flare_core::aperture::ApertureShape::Blades { count: 9, .. }),
        "the flare is rebuilt with 9 blades"
    );
    // The ghost list: the brightest ghost first; switch it off, then give another a gain.
    show(&mut h, Tab::Ghosts);
    let mut rows = h.state().derived().ghosts().clone();
    rows.sort_by(|a, b| b.intensity().total_cmp(&a.intensity()));
    let (a, b) = (&rows[0], &rows[1]);
    assert!(a.culled.is_none(), "the brightest ghost is drawn");
    h.get_by_label(&format!("ghost {}-{}", a.i, a.j)).click();
    h.run();
    assert_eq!(h.state().doc().ghost_gain(a.i, a.j), 0.0, "ghost {}-{} switched off", a.i, a.j);
    h.get_by_label(&format!("gain {}-{}", b.i, b.j)).set_value_accesskit(2.5);
    h.run();
    assert_eq!(h.state().doc().ghost_gain(b.i, b.j), 2.5);
    // Undo walks back one edit at a time: the gain, the toggle, the blades; redo comes forward again.
    let undo = |h: &mut Harness<'static, FlareLabApp>| {
        h.key_press_modifiers(egui::Modifiers::COMMAND, egui::Key::Z);
        h.run();
    };
    undo(&mut h);
    assert_eq!(h.state().doc().ghost_gain(b.i, b.j), 1.0);
    assert_eq!(h.state().doc().ghost_gain(a.i, a.j), 0.0);
    undo(&mut h);
    assert_eq!(h.state().doc().ghost_gain(a.i, a.j), 1.0);
    undo(&mut h);
    assert_eq!(h.state().doc().aperture.blades, 6);
    h.key_press_modifiers(egui::Modifiers::COMMAND | egui::Modifiers::SHIFT, egui::Key::Z);
    h.run();
    assert_eq!(h.state().doc().aperture.blades, 9);
}

#[test]
fn dragging_in_the_viewport_moves_the_light_and_undo_takes_the_whole_drag_back() {
    let mut h = harness();
    show(&mut h, Tab::Ghosts);
    let before = h.state().doc().light_deg;
    // The viewport fills the window's left (a placeholder without a GPU, with the same input).
    let centre = h.state().view_rect().expect("a viewport").center();
    let (from, to) = (centre + egui::vec2(-40.0, 40.0), centre + egui::vec2(80.0, -10.0));
    drag(&mut h, from, to);
    let after = h.state().doc().light_deg;
    assert_ne!(after, before, "the drag moved the light");
    // The drop point is right of and above the view's centre: +x and +y in the frame.
    assert!(after[0] > 0.0 && after[1] > 0.0, "{after:?}");
    // The optics put the light's image (the starburst) under the pointer where it was dropped, and every ghost
    // moved to where the paraxial matrices send it for the new light: on the line through the optical centre
    // and the light's image, at the ghost's own fixed ratio of the light's image (its matrix's A element).
    let light_on_screen = h.state().light_on_screen().expect("the light is on screen");
    assert!(light_on_screen.distance(to) < 1.0, "light drawn at {light_on_screen:?}, dropped at {to:?}");
    let flare = h.state().flare().unwrap();
    let ratios = |light: [f64; 2]| -> Vec<(usize, f64)> {
        let u = flare_core::render::light_slopes_for_frame_position(light[0], light[1]);
        // The paraxial image of the light (the starburst sits at the real one, on the same radial line).
        let k = flare.system.mapping.paraxial_mm_per_slope;
        let l = [k * u[0], k * u[1]];
        let frame = flare.system.frame(u, &flare.frame_settings(960, 540, 1000.0));
        frame
            .sprites
            .iter()
            .filter(|s| s.wavelength == 1)
            .map(|s| (s.ghost, (s.centre_mm[0] * l[0] + s.centre_mm[1] * l[1]) / (l[0] * l[0] + l[1] * l[1])))
            .collect()
    };
    for ((g, r_before), (h_, r_after)) in ratios(before).into_iter().zip(ratios(after)) {
        assert_eq!(g, h_);
        assert!((r_before - r_after).abs() < 1e-9, "ghost {g}: {r_before} vs {r_after} of the light's image");
    }
    h.key_press_modifiers(egui::Modifiers::COMMAND, egui::Key::Z);
    h.run();
    assert_eq!(h.state().doc().light_deg, before, "one undo step for the whole drag");
}

#[test]
fn an_image_exports_at_the_chosen_size_as_png_and_exr() {
    let mut h = harness();
    h.run();
    let dir = tempfile::tempdir().unwrap();
    for name in ["flare.png", "flare.exr"] {
        let path = dir.path().join(name);
        h.state().export_image_to((320, 180), &path).unwrap();
        let img = image::open(&path).unwrap().to_rgb32f();
        assert_eq!(img.dimensions(), (320, 180), "{name}");
        assert!(img.pixels().any(|p| p.0.iter().sum::<f32>() > 0.05), "{name} shows the flare");
        assert!(img.pixels().all(|p| p.0.iter().all(|v| v.is_finite())), "{name}");
    }
    let e = h.state().export_image_to((320, 180), &dir.path().join("flare.bmp")).unwrap_err().to_string();
    assert!(e.contains("bmp") || e.contains("png"), "{e}");
}

/// File > Export image draws and writes on a thread: the window goes on, the status bar has its progress and
/// Cancel, a second export waits its turn, and the outcome lands in the status bar.
#[test]
fn the_image_export_runs_on_a_thread() {
    let mut h = harness();
    h.run();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("flare.exr");
    h.state_mut().export_image_file(&path);
    assert!(h.state().jobs().exporting_image());
    h.state_mut().export_image_file(&dir.path().join("other.png"));
    assert!(h.state().message().is_some_and(|m| m.contains("an export is running")));
    let started = std::time::Instant::now();
    while h.state().jobs().exporting_image() {
        assert!(started.elapsed().as_secs() < 120, "the export did not finish");
        h.run();
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let message = h.state().message().map(str::to_owned).unwrap_or_default();
    assert!(message.starts_with("wrote ") && message.contains("flare.exr"), "{message}");
    let img = image::open(&path).unwrap().to_rgb32f();
    assert!(img.pixels().any(|p| p.0.iter().sum::<f32>() > 0.05), "the export shows the flare");
    assert!(!dir.path().join("other.png").exists());
}

#[test]
fn dragging_the_light_moves_the_ghosts_along_the_line_through_the_optical_centre() {
    let mut h = harness();
    show(&mut h, Tab::Ghosts);
    let centre_of = |h: &Harness<'static, FlareLabApp>| -> Vec<[f64; 2]> {
        let flare = h.state().flare().unwrap();
        let u = flare_core::render::light_slopes_for_frame_position(
            h.state().doc().light_deg[0],
            h.state().doc().light_deg[1],
        );
        let frame = flare.system.frame(u, &flare.frame_settings(960, 540, 1000.0));
        frame.sprites.iter().filter(|s| s.culled.is_none() && s.wavelength == 1).map(|s| s.centre_mm).collect()
    };
    for light in [[8.0, 3.0], [-5.0, 12.0], [40.0, -2.0]] {
        h.state_mut().edit().light_deg = light;
        h.run();
        let flare = h.state().flare().unwrap();
        let u = flare_core::render::light_slopes_for_frame_position(light[0], light[1]);
        let l = flare.system.light_image_mm(u);
        let centres = centre_of(&h);
        assert!(!centres.is_empty(), "ghosts drawn at {light:?}");
        for c in centres {
            // Collinear with the optical centre and the light's image: cross product ~ 0.
            let cross = c[0] * l[1] - c[1] * l[0];
            let scale = (c[0].hypot(c[1]) * l[0].hypot(l[1])).max(1e-9);
            assert!(cross.abs() / scale < 1e-6, "ghost at {c:?}, light image at {l:?}");
        }
    }
}

#[test]
fn the_blend_panel_bakes_on_a_thread_cancels_and_shows_the_classification() {
    use flare_core::preset::LutSource;
    use flarelab::panels::BakeStatus;
    let mut h = harness_on(Some(heliar()));
    show(&mut h, Tab::Blend);
    // Cancel stops a bake and says so; nothing changes in the document.
    h.get_by_label("Bake").click();
    h.run_steps(2);
    assert!(matches!(h.state().bake_status(), BakeStatus::Running { .. }), "{:?}", h.state().bake_status());
    h.get_by_label("Cancel").click();
    step_until(&mut h, 300.0, |app| !matches!(app.bake_status(), BakeStatus::Running { .. }));
    assert!(
        matches!(h.state().bake_status(), BakeStatus::Failed(t) if t.contains("cancelled")),
        "{:?}",
        h.state().bake_status()
    );
    assert!(h.state().lut().is_none());
    // A whole bake: the LUT is used, the ghost list shows which ghosts are non-linear. Export LUT while it
    // runs says that the bake is on its way, not only that there is no LUT.
    h.get_by_label("Bake").click();
    h.run_steps(2);
    h.get_by_label("Export LUT…").click();
    h.run();
    let said = h.state().message().map(str::to_owned).unwrap_or_default();
    assert!(said.contains("no LUT to export yet: the bake is at"), "{said}");
    let seconds = step_until(&mut h, 600.0, |app| app.lut().is_some());
    println!("the Heliar baked from the Blend panel in {seconds:.1} s");
    // The document is not written (undo gives back what was there); what the view draws and a saved preset
    // say is "simulated".
    assert_eq!(h.state().doc().blend.lut, LutSource::None);
    let resolved = h.state().derived().resolved(h.state().doc());
    assert!(matches!(resolved.blend.lut, LutSource::Simulated { path: None }));
    let baked = h.state().lut().unwrap().ghosts.len();
    assert!(baked > 0);
    show(&mut h, Tab::Ghosts);
    assert_eq!(h.query_all_by_label("baked").count(), baked, "one row per baked ghost says so");
    // The baked LUT written to a file opens in a fresh app for the same lens; a damaged copy is refused
    // with the reason and changes nothing.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("heliar.flut");
    flare_core::lut::format::write_lut(&path, h.state().lut().unwrap()).unwrap();
    let mut fresh = quiet(FlareLabApp::new(None, Some(heliar())));
    let mut bytes = std::fs::read(&path).unwrap();
    let n = bytes.len();
    bytes[n / 2] ^= 0x5a;
    let damaged = dir.path().join("damaged.flut");
    std::fs::write(&damaged, &bytes).unwrap();
    fresh.open_lut(&damaged);
    assert!(
        fresh.lut().is_none() && fresh.message().is_some_and(|m| m.contains("damaged.flut")),
        "{:?}",
        fresh.message()
    );
    assert_eq!(fresh.doc().blend.lut, LutSource::None);
    fresh.open_lut(&path);
    assert_eq!(fresh.lut().map(|l| l.ghosts.len()), Some(baked));
    assert!(matches!(&fresh.doc().blend.lut, LutSource::Simulated { path: Some(p) } if p.ends_with("heliar.flut")));
    // A lens edit invalidates the LUT (it was baked for the old lens).
    show(&mut h, Tab::Lens);
    let r = h.state().doc().lens.surfaces[0].radius_mm;
    h.get_by_label("radius 0").set_value_accesskit(r * 1.05);
    h.run();
    assert!(h.state().lut().is_none(), "a LUT for another lens is not drawn");
}

/// Two snapshots of the whole window rendered by wgpu, the flare viewport included: the app gets the test
/// renderer's device, so its paint callback draws the flare exactly as in the window.
#[test]
fn snapshots_of_the_whole_window_with_the_flare() {
    let Some(mut h) = gpu_harness(None) else { return };
    // Tolerant of rasterisation differences between Mesa versions, not of a changed layout or flare.
    let options = egui_kittest::SnapshotOptions::new().threshold(2.0).max_failed_pixels(3000);
    let snap = |h: &mut Harness<'static, FlareLabApp>, name: &str| {
        h.run();
        // The status bar's frame summary (its details, measured times, on hover) is masked across the window: not
        // part of the golden image.
        let rect = h.get_by_label_contains(" sprites | ").rect();
        h.mask(egui::Rect::from_x_y_ranges(0.0..=rect.right() + 4000.0, rect.y_range()));
        h.snapshot_options(name, &options);
    };
    h.state_mut().show_tab(Tab::Lens);
    snap(&mut h, "app_lens_panel");
    // The brightest drawn ghost selected: ringed in the viewport, traced in the ray diagram.
    let mut rows = h.state().derived().ghosts().clone();
    rows.sort_by(|a, b| b.intensity().total_cmp(&a.intensity()));
    h.state_mut().show_tab(Tab::Ghosts);
    h.state_mut().select(rows.iter().find(|r| r.culled.is_none()).map(|r| r.ghost));
    h.state_mut().edit().light_deg = [10.0, 6.0];
    snap(&mut h, "app_ghost_selected");
}

#[test]
fn a_bad_lens_file_is_refused_and_the_document_keeps_its_lens() {
    let mut app = FlareLabApp::new(None, None);
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.json");
    std::fs::write(&bad, r#"{"surfaces": [{"radius": "flat?", "thickness": 1, "nd": 1.5, "semi_aperture": 5}]}"#)
        .unwrap();
    let lens = app.doc().lens.clone();
    app.open_lens(&bad);
    assert_eq!(app.doc().lens, lens);
    let message = app.message().map(str::to_owned).unwrap_or_default();
    assert!(message.contains("bad.json") && message.contains("radius"), "{message}");
    // A good file replaces the lens.
    let good = dir.path().join("tessar.json");
    std::fs::write(
        &good,
        flare_core::optics::formats::to_json(&flare_core::optics::library::builtin_lens("tessar").unwrap()),
    )
    .unwrap();
    app.open_lens(&good);
    app.sync();
    assert_eq!(app.flare().unwrap().system.lens.surfaces.len(), app.doc().lens.surfaces.len());
    assert_ne!(app.doc().lens, lens);
}

/// eframe's storage as a map (the app's `save` and the start-up read go through `eframe::{set,get}_value`).
#[derive(Default)]
struct MemoryStorage(std::collections::HashMap<String, String>);

impl eframe::Storage for MemoryStorage {
    fn get_string(&self, key: &str) -> Option<String> {
        self.0.get(key).cloned()
    }
    fn set_string(&mut self, key: &str, value: String) {
        self.0.insert(key.to_owned(), value);
    }
    fn remove_string(&mut self, key: &str) {
        self.0.remove(key);
    }
    fn flush(&mut self) {}
}

#[test]
fn the_session_round_trips_through_eframes_storage() {
    use eframe::App as _;
    let mut app = FlareLabApp::new(None, None);
    app.edit().light_deg = [12.5, -3.0];
    app.edit().aperture.blades = 7;
    app.edit().ghost_mut(2, 6).gain = 0.25;
    app.edit().lens.surfaces[0].radius_mm *= 1.01;
    let mut storage = MemoryStorage::default();
    app.save(&mut storage);
    let restored = flarelab::app::restore(&storage).expect("the stored session reads back");
    assert_eq!(restored, *app.doc());
    // The recent files come back with it.
    assert!(flarelab::app::restore_recent(&storage).is_empty());
    app.files_mut().remember(std::path::Path::new("/tmp/a look.json"));
    app.save(&mut storage);
    assert_eq!(flarelab::app::restore_recent(&storage), vec![std::path::PathBuf::from("/tmp/a look.json")]);
    // A damaged session is ignored, not a crash.
    storage.0.insert("flarelab_document".into(), "{ damaged".into());
    assert!(flarelab::app::restore(&storage).is_none());
}

#[test]
fn the_exposure_slider_rebuilds_no_optics_and_no_texture() {
    // On a GPU the viewport uploads textures: counted. Without one only the optics and frames are.
    let mut h = gpu_harness(None).unwrap_or_else(harness);
    show(&mut h, Tab::Ghosts);
    let before = h.state().derived().rebuilds();
    assert!(before.optics >= 1 && before.frames >= 1, "{before:?}");
    let mut frame_ms = Vec::new();
    for ev in [8.0, 9.5, 11.0, 12.5, 4.0, 10.5] {
        h.get_by_role_and_label(egui::accesskit::Role::Slider, "flare exposure").set_value_accesskit(ev);
        let started = std::time::Instant::now();
        h.run();
        frame_ms.push(started.elapsed().as_secs_f64() * 1e3);
        assert_eq!(h.state().doc().flare_ev, ev);
    }
    let after = h.state().derived().rebuilds();
    assert_eq!((after.optics, after.textures), (before.optics, before.textures), "{before:?} -> {after:?}");
    assert!(after.frames > before.frames, "each exposure is a new frame");
    frame_ms.sort_by(f64::total_cmp);
    println!("exposure drag: median {:.1} ms per UI update (harness, all passes)", frame_ms[frame_ms.len() / 2]);
    // Tonemap, starburst and plate exposure are display settings too.
    h.state_mut().edit().tonemap = flare_core::color::Tonemap::Reinhard;
    h.state_mut().edit().starburst = false;
    h.state_mut().edit().plate_ev = 2.0;
    h.run();
    let display = h.state().derived().rebuilds();
    assert_eq!((display.optics, display.textures), (before.optics, before.textures));
    // An optics edit does rebuild: the counter can see one.
    h.state_mut().edit().aperture.f_number = Some(8.0);
    h.run();
    assert_eq!(h.state().derived().rebuilds().optics, before.optics + 1);
}

/// A look with most of the document off its defaults: ghost gains, exposures, tonemap, aperture, a plate.
fn a_look(dir: &std::path::Path) -> flare_core::preset::Document {
    let plate = dir.join("plate.png");
    image::RgbImage::from_fn(64, 36, |x, y| image::Rgb([(x * 3) as u8, (y * 5) as u8, 90])).save(&plate).unwrap();
    let mut doc = flare_core::preset::Document::for_lens(flare_core::optics::library::builtin_lens("dgauss").unwrap());
    doc.light_deg = [-7.5, 4.0];
    doc.flare_ev = 9.0;
    doc.plate_ev = -0.5;
    doc.tonemap = flare_core::color::Tonemap::Reinhard;
    doc.aperture.blades = 7;
    doc.aperture.roundness = 0.2;
    doc.aperture.f_number = Some(4.0);
    doc.ghost_mut(2, 9).gain = 3.0;
    doc.ghost_mut(1, 4).enabled = false;
    doc.background = Some(plate.display().to_string());
    doc
}

#[test]
fn the_apps_export_and_render_preset_give_the_same_image() {
    let dir = tempfile::tempdir().unwrap();
    let doc = a_look(dir.path());
    let preset = dir.path().join("look.json");
    doc.save(&preset).unwrap();
    let mut h = Harness::builder()
        .with_size(egui::vec2(1280.0, 800.0))
        .build_ui_state(|ui, app: &mut FlareLabApp| app.ui_root(ui), quiet(FlareLabApp::new(None, Some(doc))));
    h.run();
    let render = |device: &str, name: &str| {
        let out = dir.path().join(name);
        let result = std::process::Command::new(env!("CARGO_BIN_EXE_flarelab"))
            .args(["render", "--preset", preset.to_str().unwrap(), "--size", "240x135", "--device", device, "-o"])
            .arg(&out)
            .output()
            .unwrap();
        (result, out)
    };
    for name in ["app.png", "app.exr"] {
        h.state().export_image_to((240, 135), &dir.path().join(name)).unwrap();
    }
    // The CPU twin: the same bytes.
    let (result, cli_png) = render("cpu", "cli.png");
    assert!(result.status.success(), "{}", String::from_utf8_lossy(&result.stderr));
    assert_eq!(std::fs::read(&cli_png).unwrap(), std::fs::read(dir.path().join("app.png")).unwrap());
    let (result, cli_exr) = render("cpu", "cli.exr");
    assert!(result.status.success(), "{}", String::from_utf8_lossy(&result.stderr));
    let pixels = |p: &std::path::Path| image::open(p).unwrap().to_rgba32f().into_raw();
    assert_eq!(pixels(&cli_exr), pixels(&dir.path().join("app.exr")));
    // The GPU: within the twins' tolerance (see gpu_matches_its_cpu_twin in crates/flare_core/tests/render.rs).
    let (result, gpu_png) = render("gpu", "gpu.png");
    if !result.status.success() {
        let stderr = String::from_utf8_lossy(&result.stderr);
        assert!(stderr.contains("no GPU adapter"), "{stderr}");
        flare_core::render::gpu::skip_without_gpu(&format!("the GPU half: {stderr}"));
        return;
    }
    let (a, b) =
        (image::open(&gpu_png).unwrap().to_rgba8(), image::open(dir.path().join("app.png")).unwrap().to_rgba8());
    let diffs: Vec<u8> = a.as_raw().iter().zip(b.as_raw()).map(|(x, y)| x.abs_diff(*y)).collect();
    let mean = diffs.iter().map(|&d| f64::from(d)).sum::<f64>() / diffs.len() as f64;
    let worst = diffs.iter().copied().max().unwrap();
    let over_two = diffs.iter().filter(|&&d| d > 2).count() as f64 / diffs.len() as f64;
    println!("app export (CPU twin) vs render --device gpu: mean {mean:.3}/255, worst {worst}/255");
    assert!(mean < 0.5 && worst <= 4 && over_two <= 1e-4, "mean {mean}, worst {worst}, over 2: {over_two}");
}

/// The flare exposure's slider steers in stops: its track is wide enough that a 36 px drag moves the exposure by
/// about 6 EV (issue 60: 7 to 25 EV before), and the value beside it drags at 50 px a stop.
#[test]
fn the_exposure_slider_moves_a_stop_every_few_pixels() {
    let mut h = harness();
    h.run();
    let ev = |h: &Harness<'static, FlareLabApp>| h.state().derived().flare_ev(h.state().doc());
    let track = h.get_by_role_and_label(egui::accesskit::Role::Slider, "flare exposure").rect();
    let px_per_ev = track.width() / 32.0;
    println!("flare exposure track {:.0} px wide: {px_per_ev:.1} px a stop", track.width());
    assert!(px_per_ev >= 5.0, "{px_per_ev} px a stop");
    // From the handle (a press elsewhere on the track jumps to it first).
    let before = ev(&h);
    let from = egui::pos2(track.left() + ((before + 4.0) / 32.0) as f32 * track.width(), track.center().y);
    h.drag_at(from);
    h.run_steps(2);
    for k in 1..=6 {
        h.hover_at(from + egui::vec2(6.0 * k as f32, 0.0));
        h.run_steps(1);
    }
    h.drop_at(from + egui::vec2(36.0, 0.0));
    h.run();
    let moved = ev(&h) - before;
    println!("a 36 px drag of the track: {moved:+.2} EV");
    assert!(moved > 3.0 && moved < 8.0, "{moved} EV");
    assert!(!h.state().doc().exposure_auto, "moving the exposure locks it");
}

/// Drags in the viewport from `from` to `to` (the viewport is the top left of the window).
fn drag(h: &mut Harness<'static, FlareLabApp>, from: egui::Pos2, to: egui::Pos2) {
    h.drag_at(from);
    h.run_steps(2);
    for k in 1..=5 {
        h.hover_at(from + (to - from) * (k as f32 / 5.0));
        h.run_steps(1);
    }
    h.drop_at(to);
    h.run();
}

#[test]
fn the_timeline_keys_the_light_interpolates_plays_and_undo_covers_the_keys() {
    let mut h = harness();
    show(&mut h, Tab::Shot);
    let a = [-10.0, 2.0];
    h.state_mut().edit().light_deg = a;
    h.run();
    h.get_by_label("Set key").click();
    h.run();
    assert_eq!(h.state().doc().timeline.light_deg.keys.len(), 1);
    let said = h.state().message().map(str::to_owned).unwrap_or_default();
    assert!(said.contains("keyed frame 1") && said.contains("(-10.00, 2.00) deg"), "Set key says what it did: {said}");
    assert_eq!(h.state().doc().timeline.light_deg.key_at(1).unwrap().value, a);
    // Frame 11: dragging the light keys it there.
    h.get_by_label("frame").set_value_accesskit(11.0);
    h.run();
    assert_eq!(h.state().playhead(), 11);
    // Right of and above the view's centre: +x and +y in the frame.
    let centre = h.state().view_rect().expect("a viewport").center();
    let (to, again) = (centre + egui::vec2(80.0, -10.0), centre + egui::vec2(40.0, 20.0));
    drag(&mut h, centre + egui::vec2(-40.0, 40.0), to);
    let b = h.state().doc().timeline.light_deg.key_at(11).expect("the drag keyed frame 11").value;
    assert!(b[0] > 0.0 && b[1] > 0.0, "{b:?}");
    assert_eq!(h.state().doc().light_deg, a, "the static light is not what a keyed drag moves");
    assert_eq!(h.state().doc().timeline.key_frames(), vec![1, 11], "the ticks");
    // Dragging again at a keyed frame edits that key.
    drag(&mut h, to, again);
    let b2 = h.state().doc().timeline.light_deg.key_at(11).unwrap().value;
    assert_ne!(b2, b);
    assert_eq!(h.state().doc().timeline.light_deg.keys.len(), 2);
    // Frame 6 is between the keys: two keys make a straight line, smooth or not.
    h.get_by_label("frame").set_value_accesskit(6.0);
    h.run();
    let mid = h.state().derived().light_deg(h.state().doc());
    for c in 0..2 {
        assert!((mid[c] - 0.5 * (a[c] + b2[c])).abs() < 1e-9, "{mid:?} between {a:?} and {b2:?}");
    }
    // Undo takes the edit of the key back, then the key itself.
    h.key_press_modifiers(egui::Modifiers::COMMAND, egui::Key::Z);
    h.run();
    assert_eq!(h.state().doc().timeline.light_deg.key_at(11).unwrap().value, b);
    h.key_press_modifiers(egui::Modifiers::COMMAND, egui::Key::Z);
    h.run();
    assert!(h.state().doc().timeline.light_deg.key_at(11).is_none());
    // Delete the key at frame 1.
    h.get_by_label("frame").set_value_accesskit(1.0);
    h.run();
    h.get_by_label("Delete key").click();
    h.run();
    assert!(h.state().doc().timeline.light_deg.is_empty());
    // Play advances the playhead at the timeline's rate; pause stops it.
    h.get_by_label("Play").click();
    h.run_steps(2);
    std::thread::sleep(std::time::Duration::from_millis(300));
    h.step();
    let playing_at = h.state().playhead();
    assert!(playing_at > 1, "24 fps for 0.3 s: frame {playing_at}");
    h.get_by_label("Pause").click();
    h.run_steps(2);
    h.run();
    let paused_at = h.state().playhead();
    std::thread::sleep(std::time::Duration::from_millis(200));
    h.step();
    assert_eq!(h.state().playhead(), paused_at);
}

#[test]
fn the_shutter_control_blurs_a_moving_light_while_playing_and_undo_takes_it_back() {
    let mut doc = flare_core::preset::Document::default();
    doc.timeline.interpolation = flare_core::timeline::Interpolation::Linear;
    doc.timeline.light_deg.keys = vec![
        flare_core::timeline::Key { frame: 1, value: [-12.0, 4.0] },
        flare_core::timeline::Key { frame: 100, value: [12.0, -4.0] },
    ];
    let mut h = harness_on(Some(doc));
    show(&mut h, Tab::Shot);
    let shutter = |h: &Harness<'static, FlareLabApp>| {
        h.state().derived().view_frame().as_ref().and_then(|(_, f)| f.shutter.clone())
    };
    assert!(shutter(&h).is_none(), "0 degrees: the sharp frame");
    h.get_by_label("shutter").set_value_accesskit(180.0);
    h.run();
    assert_eq!(h.state().doc().timeline.shutter_deg, 180.0);
    let s = shutter(&h).expect("the light moves while the shutter is open");
    assert!(s.count > 1 && s.max_gap_px <= 1.0, "{s:?}");
    // Playing: every frame shown is blurred along the light's motion.
    h.get_by_label("Play").click();
    h.run_steps(2);
    std::thread::sleep(std::time::Duration::from_millis(200));
    h.step();
    h.run_steps(2);
    assert!(h.state().playhead() > 1);
    let playing = h.state().derived().view_frame().as_ref().map(|(_, f)| f.request.clone()).unwrap();
    assert!(playing.motion.is_some(), "the frame shown while playing carries the light's path");
    assert!(shutter(&h).is_some_and(|s| s.count > 1));
    h.get_by_label("Pause").click();
    h.run_steps(2);
    // Undo returns the shutter exactly as it was.
    h.key_press_modifiers(egui::Modifiers::COMMAND, egui::Key::Z);
    h.run();
    assert_eq!(h.state().doc().timeline.shutter_deg, 0.0);
    assert!(shutter(&h).is_none());
}

#[test]
fn the_colour_row_sets_the_view_refuses_what_does_not_resolve_and_undo_returns_it() {
    use flare_core::view_transform::ColorDoc;
    let mut h = harness();
    h.run();
    let shown = |h: &Harness<'static, FlareLabApp>| {
        let frame = h.state().derived().view_frame().as_ref().map(|(_, f)| f.clone()).unwrap();
        let view = frame.scene.view_transform();
        (view.display.clone(), view.view.clone())
    };
    assert_eq!(shown(&h), ("sRGB - Display".to_owned(), "ACES 2.0 - SDR 100 nits (Rec.709)".to_owned()));
    // The colour rows open by their toggle; the view menu lists the display's views; choosing one changes the
    // frame's view.
    assert!(h.query_by_label("view").is_none(), "the colour rows start folded");
    h.get_by_label("colour").click();
    h.run();
    h.get_by_label("view").click();
    h.run();
    h.get_by_label("Video (colorimetric)").click();
    h.run();
    assert_eq!(h.state().doc().color.view.as_deref(), Some("Video (colorimetric)"));
    assert_eq!(shown(&h).1, "Video (colorimetric)");
    // A config that cannot be read is said and the document keeps its settings.
    let before = h.state().doc().color.clone();
    h.state_mut().set_color(ColorDoc { config: Some("/no/such/config.ocio".into()), ..before.clone() });
    h.run();
    assert_eq!(h.state().doc().color, before);
    assert!(h.state().message().is_some_and(|m| m.contains("config")), "{:?}", h.state().message());
    // Undo returns exactly the default.
    h.key_press_modifiers(egui::Modifiers::COMMAND, egui::Key::Z);
    h.run();
    assert_eq!(h.state().doc().color, ColorDoc::default());
    assert_eq!(shown(&h).1, "ACES 2.0 - SDR 100 nits (Rec.709)");
}

#[test]
fn a_plate_sequence_finds_the_light_and_exports_on_a_thread_as_render_frames_does() {
    use flare_core::shot::synthetic::SyntheticShot;
    let dir = tempfile::tempdir().unwrap();
    let shot = SyntheticShot { frames: 1..=4, ..SyntheticShot::small() };
    let plates = dir.path().join("plates/sun.####.exr").display().to_string();
    shot.write(&flare_core::footage::pattern::FramePattern::parse(&plates).unwrap().unwrap(), None).unwrap();
    let mut doc = flare_core::preset::Document {
        background: Some(plates),
        auto_light: Some(Default::default()),
        ..Default::default()
    };
    doc.timeline.first_frame = 1;
    doc.timeline.last_frame = 4;
    let preset = dir.path().join("shot.json");
    doc.save(&preset).unwrap();
    let mut h = Harness::builder()
        .with_size(egui::vec2(1280.0, 800.0))
        .build_ui_state(|ui, app: &mut FlareLabApp| app.ui_root(ui), quiet(FlareLabApp::new(None, Some(doc))));
    h.state_mut().show_tab(Tab::Shot);
    h.run();
    step_until(&mut h, 120.0, |app| app.derived().shot_plan().is_some());
    // The frame shown has the light found in its plate.
    h.get_by_label("frame").set_value_accesskit(3.0);
    h.run();
    let found = h.state().derived().shot_plan().as_ref().unwrap().frames[2].clone();
    assert_eq!(h.state().derived().light_deg(h.state().doc()), found.light_deg);
    assert!(found.light_px.is_some_and(|p| (p[0] - shot.sun_px(3)[0]).hypot(p[1] - shot.sun_px(3)[1]) < 0.5));
    // Export on a thread: the UI keeps running while it works.
    let out = dir.path().join("app/f.####.png").display().to_string();
    h.state_mut().export_sequence(&out, false);
    assert!(h.state().jobs().shot_running());
    let mut frames_while_exporting = 0;
    while h.state().jobs().shot_running() {
        h.step();
        frames_while_exporting += 1;
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    assert!(frames_while_exporting > 1, "the window ran while the export worked");
    let report = h.state().jobs().last_export().cloned().expect("the export finished");
    assert_eq!(report.rendered(), 4, "{}", h.state().jobs().shot_status());
    // The same frames as `flarelab render --preset --frames`, byte for byte (both on the CPU twin).
    let cli = dir.path().join("cli/f.####.png").display().to_string();
    let result = std::process::Command::new(env!("CARGO_BIN_EXE_flarelab"))
        .args(["render", "--preset", preset.to_str().unwrap(), "--frames", "1-4", "--device", "cpu", "-o", &cli])
        .output()
        .unwrap();
    assert!(result.status.success(), "{}", String::from_utf8_lossy(&result.stderr));
    for f in 1..=4 {
        let name = format!("f.{f:04}.png");
        assert_eq!(
            std::fs::read(dir.path().join("app").join(&name)).unwrap(),
            std::fs::read(dir.path().join("cli").join(&name)).unwrap(),
            "frame {f}"
        );
    }
    // Cancel stops it; a pattern without a frame field is refused with the reason.
    h.state_mut().export_sequence(&dir.path().join("again/f.####.png").display().to_string(), false);
    h.state_mut().jobs_mut().cancel_shot();
    step_until(&mut h, 60.0, |app| !app.jobs().shot_running());
    assert!(h.state().jobs().shot_status().contains("cancel"), "{}", h.state().jobs().shot_status());
    h.state_mut().export_sequence(&dir.path().join("still.png").display().to_string(), false);
    assert!(!h.state().jobs().shot_running());
    assert!(h.state().message().is_some_and(|m| m.contains("frame field")), "{:?}", h.state().message());
}

#[test]
fn inserting_a_surface_splits_a_gap_and_changes_nothing_optically() {
    let mut h = harness_on(Some(heliar()));
    show(&mut h, Tab::Lens);
    let before = h.state().doc().lens.clone();
    let fo = |app: &FlareLabApp| app.derived().first_order().clone().expect("a valid lens");
    let (efl, bfd) = (fo(h.state()).efl_mm, fo(h.state()).bfd_mm);
    // "+" on row 1 (inside glass) and on the last row.
    surface_menu(&mut h, 1, ADD_DUMMY);
    surface_menu(&mut h, before.surfaces.len(), ADD_DUMMY);
    let after = &h.state().doc().lens;
    assert_eq!(after.surfaces.len(), before.surfaces.len() + 2);
    assert!(h.state().derived().lens_problem().is_none(), "{:?}", h.state().derived().lens_problem());
    assert_eq!(
        after.surfaces[1].thickness_mm.unwrap() + after.surfaces[2].thickness_mm.unwrap(),
        before.surfaces[1].thickness_mm.unwrap()
    );
    assert_eq!(after.surfaces[2].medium, before.surfaces[1].medium, "the same medium on both sides");
    // The same focal length and focal plane; the back focal distance now counts from the new last surface,
    // 1 mm behind the old one.
    let now = fo(h.state());
    assert!((now.efl_mm - efl).abs() < 1e-9, "{} vs {efl}", now.efl_mm);
    assert!((now.bfd_mm + 1.0 - bfd).abs() < 1e-9, "{} vs {bfd}", now.bfd_mm);
    assert_eq!(after.ghost_pairs().len(), before.ghost_pairs().len(), "no new reflecting surface");
}

#[test]
fn lut_ghosts_bake_by_themselves_and_undo_to_a_baked_lens_needs_no_bake() {
    use flare_core::bake::BakeSettings;
    use flare_core::bake::cache::LutCache;
    use flare_core::preset::LutSource;
    use flarelab::panels::BakeStatus;
    let dir = tempfile::tempdir().unwrap();
    // Coarse bakes keep the test short; the cache key includes the settings.
    let coarse = BakeSettings { res: 32, grid: 16, initial_steps: 2, tolerance: 0.5, ..BakeSettings::default() };
    let app_on = |doc| {
        let mut app = FlareLabApp::new(None, Some(doc));
        app.jobs_mut().autobake_mut().cache = Some(LutCache::new(dir.path()));
        app.jobs_mut().autobake_mut().settings = coarse.clone();
        // Bakes start as soon as the optics change here (the settling has its own test).
        app.jobs_mut().autobake_mut().settle = std::time::Duration::ZERO;
        Harness::builder()
            .with_size(egui::vec2(1280.0, 800.0))
            .build_ui_state(|ui, app: &mut FlareLabApp| app.ui_root(ui), app)
    };
    let mut h = app_on(heliar());
    h.run_steps(2);
    // The bake starts by itself (once the disk cache, read on a thread, said it has none); until it is done the
    // paraxial flare shows, and the status bar says so.
    step_until(&mut h, 10.0, |app| app.jobs().autobake().bakes_started == 1);
    assert!(h.state().lut().is_none());
    assert!(h.query_by_label_contains("the paraxial flare until").is_some(), "the status bar says what shows");
    step_until(&mut h, 600.0, |app| app.lut().is_some());
    assert_eq!(h.state().lut().unwrap().lens_id, "heliar_tronnier_us2645156");
    let resolved = h.state().derived().resolved(h.state().doc());
    assert_eq!(resolved.blend.lut, LutSource::Simulated { path: None }, "a saved preset renders it blended");
    assert_eq!(h.state().doc().blend.lut, LutSource::None, "the bake writes nothing into the document");
    assert!(!h.state().session().can_undo(), "a bake is no edit to undo");
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1, "the LUT went into the cache");
    // Change the lens: its bake starts by itself, the old LUT is not drawn for it, and the new one is used.
    h.state_mut().edit().lens = flare_core::optics::library::builtin_lens("tessar").unwrap();
    h.run_steps(2);
    // (After the disk cache, read on a thread, said it has none.)
    step_until(&mut h, 10.0, |app| app.jobs().autobake().bakes_started == 2);
    assert!(h.state().lut().is_none());
    // Undo while it bakes: the Heliar's LUT at once, and the bake for the optics left stops (issue 60: it ran on
    // "for earlier optics (kept for a redo)"): no bake shows, its thread ends. Redo bakes the Tessar again.
    // (At once: from memory, its atlas made on a thread in a few frames; the window never waits for it.)
    h.state_mut().undo();
    h.run();
    let heliar_lut = |app: &FlareLabApp| app.lut().is_some_and(|l| l.lens_id == "heliar_tronnier_us2645156");
    step_until(&mut h, 10.0, heliar_lut);
    assert!(!matches!(h.state().bake_status(), BakeStatus::Running { .. }), "no bake job for the optics left");
    step_until(&mut h, 60.0, |app| app.jobs().stopping_bakes() == 0);
    h.state_mut().redo();
    h.run_steps(2);
    step_until(&mut h, 10.0, |app| app.jobs().autobake().bakes_started == 3);
    step_until(&mut h, 600.0, |app| app.lut().is_some());
    assert_eq!(h.state().lut().unwrap().lens_id, "brendel_tessar_usp2854889");
    // Undo: the Heliar and its LUT at once, without a new bake.
    h.state_mut().undo();
    h.run();
    assert_eq!(h.state().doc().lens.id, "heliar_tronnier_us2645156");
    step_until(&mut h, 10.0, heliar_lut);
    assert_eq!(h.state().jobs().autobake().bakes_started, 3, "no new bake");
    // Undo all the way, then redo: exactly the documents that were there (the bakes wrote nothing into them).
    let heliar_json = h.state().doc().to_json();
    assert!(heliar_json == heliar().to_json(), "back to the document the session opened");
    h.state_mut().redo();
    h.run();
    assert_eq!(h.state().doc().lens.id, "brendel_tessar_usp2854889");
    assert_eq!(h.state().doc().blend.lut, LutSource::None);
    // "none" in the Blend panel: paraxial only, the automatic LUT leaves the screen; "simulated" brings it back.
    show(&mut h, Tab::Blend);
    h.get_by_label("none").click();
    h.run();
    assert!(h.state().lut().is_none() && !h.state().jobs().autobake().enabled);
    assert_eq!(h.state().derived().resolved(h.state().doc()).blend.lut, LutSource::None, "a saved preset too");
    h.get_by_label("simulated").click();
    h.run_steps(3);
    step_until(&mut h, 10.0, |app| app.lut().is_some_and(|l| l.lens_id == "brendel_tessar_usp2854889"));
    // A new session finds both LUTs in the disk cache: no bake at all.
    let mut fresh = app_on(heliar());
    fresh.run_steps(2);
    step_until(&mut fresh, 10.0, heliar_lut);
    assert_eq!(fresh.state().jobs().autobake().bakes_started, 0);
    // "+" (a dummy surface: the same optics) keeps the LUT on screen, says nothing of it and starts no bake.
    show(&mut fresh, Tab::Lens);
    surface_menu(&mut fresh, 1, ADD_DUMMY);
    fresh.run_steps(3);
    assert_eq!(fresh.state().doc().lens.surfaces.len(), heliar().lens.surfaces.len() + 1);
    let said = fresh.state().message().map(str::to_owned);
    assert_eq!(fresh.state().lut().map(|l| l.lens_id.as_str()), Some("heliar_tronnier_us2645156"), "{said:?}");
    assert!(!said.as_deref().is_some_and(|m| m.contains("optics changed")), "{said:?}");
    assert_eq!(fresh.state().jobs().autobake().bakes_started, 0, "no bake for a dummy surface");
    // A damaged cache entry is not trusted: it is reported and baked again.
    for entry in std::fs::read_dir(dir.path()).unwrap() {
        let path = entry.unwrap().path();
        let mut bytes = std::fs::read(&path).unwrap();
        let n = bytes.len();
        bytes[n / 2] ^= 0x5a;
        std::fs::write(&path, bytes).unwrap();
    }
    let mut damaged = app_on(heliar());
    damaged.run_steps(2);
    step_until(&mut damaged, 10.0, |app| app.jobs().autobake().bakes_started == 1);
    assert!(damaged.state().message().is_some_and(|m| m.contains("ignored")), "{:?}", damaged.state().message());
}

#[test]
fn without_a_native_dialog_file_actions_use_the_in_app_browser_and_remember_recent_files() {
    use flarelab::app::files::FileUse;
    let dir = tempfile::tempdir().unwrap();
    // egui_file's own text fields carry no accessible names: the check is off for this window only.
    let mut h = Harness::builder()
        .with_size(egui::vec2(1280.0, 800.0))
        .with_accessibility_check(false)
        .build_ui_state(|ui, app: &mut FlareLabApp| app.ui_root(ui), quiet(FlareLabApp::new(None, None)));
    h.state_mut().files_mut().native = false;
    h.get_by_label("File").click();
    h.run();
    h.get_by_label("Save preset…").click();
    h.run();
    // FlareLab's own browser is open for that action (a window titled like the action).
    assert_eq!(h.state().files().browsing(), Some(FileUse::SavePreset));
    assert!(h.query_by_label("💾  Save preset").is_some(), "the browser window is titled by the action");
    // Why not the desktop's dialog is said, once.
    if !flarelab::app::files::native_dialog_available() {
        let said = h.state().message().map(str::to_owned).unwrap_or_default();
        assert!(said.contains("no desktop file dialog") && said.contains("zenity"), "{said}");
    }
    // A name without the extension gets it.
    h.state_mut().use_file(FileUse::SavePreset, &dir.path().join("mylook"));
    assert!(dir.path().join("mylook.json").exists() && !dir.path().join("mylook").exists());
    // What it picks does the action and joins the recent files; Escape closes it and says so.
    let path = dir.path().join("look.json");
    h.state_mut().use_file(FileUse::SavePreset, &path);
    assert!(path.exists());
    assert!(h.state().message().is_some_and(|m| m.contains("saved")), "{:?}", h.state().message());
    h.key_press(egui::Key::Escape);
    h.run();
    assert_eq!(h.state().files().browsing(), None);
    assert!(h.state().message().is_some_and(|m| m.contains("no file chosen")), "{:?}", h.state().message());
    // A failed action leaves its reason in the status bar, and the document as it was.
    let lens = h.state().doc().lens.clone();
    let bad = dir.path().join("bad.zmx");
    std::fs::write(&bad, "SURF 0\n  CURV not-a-number\n").unwrap();
    h.state_mut().use_file(FileUse::OpenLens, &bad);
    h.run();
    assert_eq!(h.state().doc().lens, lens);
    let said = h.state().message().map(str::to_owned).unwrap_or_default();
    assert!(said.contains("bad.zmx"), "{said}");
    assert!(h.query_by_label_contains("bad.zmx").is_some(), "the reason is shown in the status bar");
    // Open recent opens a remembered preset again by what it is.
    assert_eq!(h.state().files().recent.first().and_then(|p| p.file_name()), Some(bad.file_name().unwrap()));
    h.state_mut().edit().light_deg = [1.0, 1.0];
    let saved = std::fs::canonicalize(&path).unwrap();
    h.state_mut().open_recent(&saved);
    assert_ne!(h.state().doc().light_deg, [1.0, 1.0], "the saved preset is open again");
    // Opening by a typed name: the name field and the Open button do what Enter does.
    h.state_mut().edit().light_deg = [2.0, 2.0];
    h.state_mut().pick_file(FileUse::OpenPreset);
    h.run();
    assert_eq!(h.state().files().browsing(), Some(FileUse::OpenPreset));
    let name_field = h.get_all_by_role(egui::accesskit::Role::TextInput).last().unwrap();
    name_field.focus();
    h.run();
    h.key_press_modifiers(egui::Modifiers::COMMAND, egui::Key::A);
    h.event(egui::Event::Text(path.display().to_string()));
    h.run();
    h.get_by_label("Open").click();
    h.run();
    assert_eq!(h.state().files().browsing(), None, "Open took the typed name");
    assert_ne!(h.state().doc().light_deg, [2.0, 2.0], "the typed preset is open");
}

#[test]
fn the_looks_panel_renders_thumbnails_on_a_worker_and_applies_a_look_as_one_undo_step() {
    let mut h = harness();
    // The panel repaints while its worker runs: step, do not wait for it to settle.
    h.state_mut().show_tab(Tab::Looks);
    h.run_steps(2);
    step_until(&mut h, 300.0, |app| app.jobs().looks().ready());
    h.run_steps(2);
    let shipped = flare_core::preset::shipped();
    assert!(
        h.state().jobs().looks().thumbnails.iter().all(|t| matches!(t, Some(Ok(_)))),
        "every look has its thumbnail"
    );
    let before = h.state().doc().clone();
    let k = shipped.iter().position(|p| p.name == "vintage-uncoated").unwrap();
    h.get_by_label("vintage-uncoated").click();
    h.run_steps(2);
    // Said if it fails (seen once in a full run, not reproduced): where the label was and what the app said.
    let label = h.get_by_label("vintage-uncoated").rect();
    assert_eq!(
        h.state().doc().lens.id,
        "pbrt_dgauss_50mm",
        "label at {label:?}; the app said {:?}",
        h.state().message()
    );
    assert_eq!(h.state().doc().aperture, shipped[k].document().unwrap().aperture);
    let look = h.state().doc().to_json();
    h.state_mut().undo();
    h.run();
    assert_eq!(h.state().doc().lens, before.lens, "one undo step takes the look back");
    assert!(h.state().doc().to_json() == before.to_json(), "the whole document, as saved, is what it was");
    assert!(h.state().message().is_some_and(|m| m.starts_with("undid: ")), "{:?}", h.state().message());
    h.state_mut().redo();
    h.run();
    assert!(h.state().doc().to_json() == look, "redo gives the look back exactly");
}

#[test]
fn the_report_tab_ranks_ghosts_on_a_worker_sorts_selects_and_exports() {
    let mut h = harness_on(Some(heliar()));
    h.state_mut().show_tab(Tab::Report);
    h.run_steps(2);
    let ready = |app: &FlareLabApp| {
        matches!(&app.jobs().report().shown, Some((_, Ok(r))) if r.ghosts.len() == 28)
            && app.derived().flare().as_ref().is_some_and(|f| {
                let light = app.derived().light_deg(app.doc());
                let u = flare_core::optics::sensor::light_slopes_for_frame_position(light[0], light[1]);
                !app.jobs().report().stale(flarelab::app::jobs::report::ReportKey::new(f, u))
            })
    };
    step_until(&mut h, 120.0, ready);
    h.run_steps(2);
    // Worst first by default; the peak header sorts by peak (highest first), a second click reverses it.
    let report = match &h.state().jobs().report().shown {
        Some((_, Ok(r))) => r.clone(),
        _ => unreachable!(),
    };
    // A row selects its ghost (the viewport rings it, the ray diagram traces it).
    let worst = format!("{}-{}", report.ghosts[0].i, report.ghosts[0].j);
    h.get_by_label(worst.as_str()).click();
    h.run_steps(2);
    let selected = h.state().session().selected().expect("a ghost is selected");
    let g = &h.state().derived().flare().as_ref().unwrap().system.ghosts[selected];
    assert_eq!((g.i, g.j), (report.ghosts[0].i, report.ghosts[0].j));
    // The peak header sorts by peak, highest first; a second click reverses it.
    h.get_by_label("peak").click();
    h.run_steps(2);
    assert_eq!(h.state().jobs().report().sort, (flarelab::app::jobs::report::ReportColumn::Peak, true));
    h.get_by_label("peak v").click();
    h.run_steps(2);
    assert_eq!(h.state().jobs().report().sort, (flarelab::app::jobs::report::ReportColumn::Peak, false));
    // Moving the light recomputes the report for the new light.
    h.state_mut().edit().light_deg = [-4.0, 2.0];
    h.run_steps(2);
    step_until(&mut h, 120.0, ready);
    let moved = match &h.state().jobs().report().shown {
        Some((_, Ok(r))) => r.clone(),
        _ => unreachable!(),
    };
    assert_ne!(moved.light_slope, report.light_slope);
    // Export: CSV (the command line's table) and JSON (everything), through the file actions.
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("report.csv");
    h.state_mut().use_file(flarelab::app::files::FileUse::ExportReport, &csv);
    let text = std::fs::read_to_string(&csv).unwrap();
    assert!(text.starts_with(flare_core::report::CSV_HEADER) && text.lines().count() == 29, "{text}");
    let json = dir.path().join("report.json");
    h.state_mut().use_file(flarelab::app::files::FileUse::ExportReport, &json);
    let value: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(value["ghosts"].as_array().unwrap().len(), 28);
    assert_eq!(value["sensitivity"].as_array().unwrap().len(), 8);
    assert!(h.state().message().unwrap_or("").contains("wrote"));
}

#[test]
fn a_transcription_that_needs_clipping_opens_with_its_warning_in_the_lens_panel() {
    let mut h = harness_on(Some(heliar()));
    // The Nikon zoom as the public transcription gives it (semi-apertures 26.2 and 20 on surfaces 3 and 4).
    let mut lens = flare_core::optics::library::builtin_lens("nikon").unwrap();
    lens.surfaces[3].semi_aperture_mm = 26.2;
    lens.surfaces[4].semi_aperture_mm = 20.0;
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("nikon_transcribed.json");
    std::fs::write(&file, flare_core::optics::formats::to_json(&lens)).unwrap();
    h.state_mut().open_lens(&file);
    show(&mut h, Tab::Lens);
    h.run_steps(2);
    let state = h.state();
    assert!((state.doc().lens.surfaces[3].semi_aperture_mm - 18.608).abs() < 1e-3, "clipped where they meet");
    assert!(state.message().unwrap_or("").contains("meet at a height of 18.61 mm"), "{:?}", state.message());
    assert!(h.query_by_label_contains("(i) surfaces 3 and 4 meet at a height of 18.61 mm").is_some(), "in the panel");
    // The conic column edits the surface's conic constant; the viewport's flare follows a valid edit.
    h.get_by_label("conic 0").set_value_accesskit(-0.5);
    h.run_steps(2);
    assert_eq!(h.state().doc().lens.surfaces[0].conic, -0.5);
    assert_eq!(h.state().flare().unwrap().system.lens.surfaces[0].conic, -0.5);
    // Another lens: the warning is not shown for it.
    h.state_mut().edit().lens = flare_core::optics::library::builtin_lens("tessar").unwrap();
    h.run_steps(2);
    assert!(h.query_by_label_contains("(i) surfaces 3 and 4").is_none());
}

/// The DoF row: a plate defocused on a thread (the CPU twin here, no GPU in this harness) exactly as the
/// command line defocuses it from the same document; focus by click; a depth map of another size said once.
#[test]
fn the_depth_of_field_defocuses_the_plate_on_a_thread_as_the_command_line_does() {
    let dir = tempfile::tempdir().unwrap();
    let doc = street_doc(dir.path(), 320, 180, false);
    let mut h = harness_on(Some(doc));
    h.run();
    // Off: the plate as read. Its rows open by their toggle.
    assert!(!h.state().doc().dof.enabled);
    h.get_by_label("DoF").click();
    h.run();
    h.get_by_label("depth of field").click();
    h.step();
    h.step();
    assert!(h.state().doc().dof.enabled);
    step_until(&mut h, 60.0, |app| {
        !app.jobs().dof().busy() && app.jobs().dof().status.contains("live on the CPU twin")
    });
    let app = h.state();
    let (shown, sharp) = (app.derived().plate().clone().unwrap(), app.derived().sharp_plate().clone().unwrap());
    assert_ne!(shown.pixels, sharp.pixels, "the plate is defocused");
    let flare = app.flare().unwrap();
    let cli = flare_core::shot::plate::defocus(app.doc(), flare, app.playhead(), &sharp).unwrap();
    assert_eq!(cli.pixels, shown.pixels, "the app's plate is the command line's");
    // Focus by click: the toggle, then a click in the view focuses on the depth there.
    h.get_by_label("focus by click").click();
    h.step();
    h.step();
    assert!(h.state().focus_pick());
    let rect = egui::Rect::from_min_size(egui::pos2(0.0, 0.0), egui::vec2(320.0, 180.0));
    h.state_mut().focus_from_pointer(egui::pos2(100.0, 90.0), rect);
    assert_eq!(h.state().doc().dof.focus_px, Some([100, 90]));
    assert!(!h.state().focus_pick());
    step_until(&mut h, 60.0, |app| !app.jobs().dof().busy() && app.jobs().dof().status.contains("focus 5.00 m"));
    // A depth map of another size: said once, the sharp plate shown, nothing lost.
    let (_, small) = flare_core::dof::scene::street(160, 90);
    let wrong = dir.path().join("small_z.exr");
    flare_core::dof::depth::write_exr(&wrong, &small).unwrap();
    h.state_mut().edit().dof.depth = Some(wrong.display().to_string());
    step_until(&mut h, 60.0, |app| !app.jobs().dof().busy() && app.jobs().dof().status.contains("same size"));
    let app = h.state();
    assert!(app.message().is_some_and(|m| m.contains("160x90") && m.contains("320x180")), "{:?}", app.message());
    assert_eq!(app.derived().plate().as_ref().unwrap().pixels, app.derived().sharp_plate().as_ref().unwrap().pixels);
    assert!(app.doc().dof.enabled && app.doc().background.is_some());
}

/// The app's depth of field on its own wgpu device (lavapipe here, made to use it although the CPU twin is
/// faster there) gives the CPU twin's plate to the bit.
#[test]
fn the_depth_of_field_runs_on_the_apps_gpu_as_its_cpu_twin_does() {
    let dir = tempfile::tempdir().unwrap();
    let doc = street_doc(dir.path(), 256, 144, true);
    let Some(mut h) = gpu_harness(Some(doc)) else { return };
    // The first frame may have started a job on the CPU twin already: a new focus starts one on the GPU.
    h.state_mut().jobs_mut().dof_mut().gpu_on_software = true;
    h.state_mut().edit().dof.focus_m = 1.0;
    step_until(&mut h, 120.0, |app| !app.jobs().dof().busy() && app.jobs().dof().status.contains("focus 1.00 m"));
    let app = h.state();
    let status = app.jobs().dof().status.clone();
    assert!(status.contains("live on") && !status.contains("CPU twin"), "{status}");
    let shown = app.derived().plate().clone().unwrap();
    let cpu = flare_core::shot::plate::defocus(
        app.doc(),
        app.flare().unwrap(),
        app.playhead(),
        app.derived().sharp_plate().as_ref().unwrap(),
    )
    .unwrap();
    assert_eq!(shown.pixels, cpu.pixels, "{status}");
}

/// The view's ray-grid mode traces the frame shown on a thread (here on the CPU: the only adapter is software)
/// and the viewport shows it: every ghost traced exactly, a different image from the paraxial one, drawn
/// through the frame pipeline as `render --method raygrid` draws. A drag shows paraxial drafts and the new
/// frame is traced when input stops; Cancel stops a trace; the look comes back when the mode is left.
#[test]
fn the_ray_grid_view_traces_the_frame_shown_and_shows_it_in_the_viewport() {
    let Some(mut h) = gpu_harness(Some(heliar())) else { return };
    h.run();
    h.state_mut().jobs_mut().raygrid_mut().grid = Some(16);
    let traced = |app: &FlareLabApp| app.view_shows_traced();
    step_until(&mut h, 120.0, traced);
    let app = h.state();
    assert!(app.jobs().raygrid().status.starts_with("ray grid 16 (CPU"), "{}", app.jobs().raygrid().status);
    let (generation, frame) = app.derived().view_frame().clone().unwrap();
    let shown = app.jobs().raygrid().traced(generation).unwrap().display.clone();
    // The same frame's ghosts traced again through the public pipeline give the same pixels.
    let flare = app.flare().unwrap();
    let scene = &frame.scene;
    let window =
        flare_core::raytrace::Window::for_sensor(frame.request.sensor_width_mm, scene.hdr_width, scene.hdr_height);
    let view = flare_core::raytrace::View { window, turn_deg: 0.0 };
    // The jobs too dim to see left out as every CPU ray grid of a frame leaves them out.
    let grid = flare_core::raytrace::Grid::Fixed(16);
    let request = flare_core::raytrace::RayGridRequest::views(frame.request.light_deg, vec![view], grid)
        .dim(flare_core::traced::dim_for(&flare.config, &frame, grid));
    let ghosts = flare.ray_grid_renderer().render_request(&request).unwrap().remove(0).hdr;
    let sources = flare_core::frame::Sources { flare, lut: None, plate: None };
    let again = flare_core::frame::drawn_with_traced_ghosts(&frame, &sources, ghosts);
    assert_eq!(again.display.pixels, shown.pixels);
    // Not the paraxial drawing of the frame, but as bright overall (the same light through the same lens).
    let paraxial = flare_core::frame::draw_cpu(&frame, &sources).display;
    let mean = |img: &flare_core::image::DisplayImage| {
        img.pixels.iter().map(|p| f64::from(p[0]) + f64::from(p[1]) + f64::from(p[2])).sum::<f64>()
            / img.pixels.len() as f64
    };
    assert_ne!(paraxial.pixels, shown.pixels);
    let ratio = mean(&shown) / mean(&paraxial);
    assert!((0.5..2.0).contains(&ratio), "traced / paraxial brightness {ratio}");
    // A new frame that differs only in its LUT (a bake that finished) shows the same trace, not a new one.
    h.state_mut().show_lut_again();
    h.step();
    assert_ne!(h.state().derived().view_frame().as_ref().unwrap().0, generation);
    assert!(
        h.state().view_shows_traced() && !h.state().jobs().raygrid().busy(),
        "{}",
        h.state().jobs().raygrid().status
    );
    // A drag: paraxial drafts while it lasts, then the new frame is traced.
    drag(&mut h, egui::pos2(300.0, 250.0), egui::pos2(380.0, 220.0));
    assert!(!h.state().view_shows_traced(), "the frame changed: the traced image is not shown");
    step_until(&mut h, 120.0, traced);
    assert_ne!(h.state().derived().view_frame().as_ref().unwrap().0, generation);
    // Cancel stops the trace of a new frame; leaving the mode draws the look again.
    h.state_mut().jobs_mut().raygrid_mut().grid = Some(32);
    h.step();
    assert!(h.state().jobs().raygrid().busy());
    h.state_mut().jobs_mut().raygrid_mut().cancel();
    h.step();
    assert!(h.state().jobs().raygrid().progress().is_none() && h.state().jobs().raygrid().status.contains("cancelled"));
    // Its thread ends (the CPU trace stops at its next ghost), watched by the view.
    step_until(&mut h, 60.0, |app| app.jobs().raygrid().stopping() == 0);
    // Issue 60's hang: every exposure step of a drag made a new frame, each new trace cancelled the one before,
    // and the cancelled ones ran on to the end, 136 of them queued in the pool the frame itself uses. Now a
    // burst of new frames leaves one trace running, at most one replaced trace still stopping, and the last
    // frame waiting for it (the board's `Slot`).
    h.state_mut().jobs_mut().raygrid_mut().grid = Some(128);
    for k in 0..12 {
        h.state_mut().edit().flare_ev = 7.0 + f64::from(k);
        h.step();
        assert!(h.state().jobs().raygrid().stopping() <= 1, "traces pile up");
    }
    assert!(h.state().jobs().raygrid().busy(), "the last frame is being traced");
    let stopped_in = step_until(&mut h, 60.0, |app| app.jobs().raygrid().stopping() == 0);
    println!("12 replaced ray-grid 128 traces ended {stopped_in:.2} s after the last new frame");
    h.state_mut().jobs_mut().raygrid_mut().cancel();
    step_until(&mut h, 60.0, |app| app.jobs().raygrid().stopping() == 0 && !app.jobs().raygrid().busy());
    h.state_mut().jobs_mut().raygrid_mut().grid = None;
    h.run();
    assert!(!h.state().view_shows_traced() && h.state().jobs().raygrid().status.is_empty());
}

/// Undo and redo walk through a refused edit and the automatic exposure and give back the document exactly, as
/// saved JSON (issue 32's scenario on the double Gauss: a radius typed as -1, refused, then -12; undo five
/// times, redo). The automatic exposure follows the lens as a derived value: it is never written into the
/// document, so it makes no undo step and clears no redo.
#[test]
fn undo_and_redo_return_the_document_exactly_through_a_refused_edit_and_auto_exposure() {
    let mut h = harness_on(Some(dgauss()));
    show(&mut h, Tab::Lens);
    let json = |h: &Harness<'static, FlareLabApp>| h.state().doc().to_json();
    let shown_ev = |h: &Harness<'static, FlareLabApp>| h.state().derived().flare_ev(h.state().doc());
    assert!(h.state().doc().exposure_auto);
    let (j0, ev0) = (json(&h), shown_ev(&h));
    h.get_by_label("radius 6").set_value_accesskit(-1.0);
    h.run();
    assert!(h.state().derived().lens_problem().is_some(), "-1 mm is refused");
    let j1 = json(&h);
    h.get_by_label("radius 6").set_value_accesskit(-12.0);
    h.run();
    assert!(h.state().derived().lens_problem().is_none(), "-12 mm is a valid radius");
    let (j2, ev2) = (json(&h), shown_ev(&h));
    assert!(j0 != j1 && j1 != j2);
    assert!(ev0 != ev2, "the automatic exposure follows the lens ({ev0} -> {ev2})");
    let undo = |h: &mut Harness<'static, FlareLabApp>| {
        h.key_press_modifiers(egui::Modifiers::COMMAND, egui::Key::Z);
        h.run();
    };
    let redo = |h: &mut Harness<'static, FlareLabApp>| {
        h.key_press_modifiers(egui::Modifiers::COMMAND | egui::Modifiers::SHIFT, egui::Key::Z);
        h.run();
    };
    for (k, expected) in [&j1, &j0, &j0, &j0, &j0].into_iter().enumerate() {
        undo(&mut h);
        assert!(json(&h) == *expected, "undo {}: the document is not what it was", k + 1);
        // The status bar names what was undone, then that there is nothing more.
        let said = h.state().message().map(str::to_owned).unwrap_or_default();
        // The first undo goes back to the refused radius and says so; the second to a valid lens.
        let wanted = match k {
            0 => "undid: lens surface 6; lens edit refused: surface 6, field `radius`",
            1 => "undid: lens surface 6; the lens is valid again",
            _ => "nothing to undo",
        };
        assert!(said.starts_with(wanted), "undo {}: {said}", k + 1);
    }
    assert_eq!(shown_ev(&h), ev0, "back on the first lens, its automatic exposure");
    redo(&mut h);
    assert!(json(&h) == j1, "redo 1");
    let said = h.state().message().map(str::to_owned).unwrap_or_default();
    assert!(said.starts_with("redid: lens surface 6; lens edit refused"), "{said}");
    redo(&mut h);
    assert!(json(&h) == j2, "redo 2");
    redo(&mut h);
    assert!(json(&h) == j2, "nothing more to redo");
    assert_eq!(shown_ev(&h), ev2);
    // Locking the exposure keeps the value shown and is one step of its own.
    h.get_by_label("auto").click();
    h.run();
    assert!(!h.state().doc().exposure_auto && h.state().doc().flare_ev == ev2);
    undo(&mut h);
    assert!(json(&h) == j2, "the lock undone");
}

/// "+" on the first row of every shipped lens inserts an inert dummy surface (EFL, BFD and ghost count
/// unchanged to 1e-9), and "x" on the row it added gives back exactly the lens that was there.
#[test]
fn plus_then_x_on_every_shipped_lens_gives_back_the_lens() {
    let mut h = harness();
    show(&mut h, Tab::Lens);
    let optics = |app: &FlareLabApp| {
        assert!(app.derived().lens_problem().is_none(), "{:?}", app.derived().lens_problem());
        let first = app.derived().first_order().clone().expect("a valid lens");
        (first.efl_mm, first.bfd_mm, app.flare().unwrap().system.ghosts.len())
    };
    for id in flare_core::optics::library::ids() {
        h.state_mut().edit().lens = flare_core::optics::library::builtin_lens(id).unwrap();
        h.run();
        let before = h.state().doc().lens.clone();
        let (efl0, bfd0, ghosts0) = optics(h.state());
        surface_menu(&mut h, 0, ADD_DUMMY);
        assert_eq!(h.state().doc().lens.surfaces.len(), before.surfaces.len() + 1, "{id}: {:?}", h.state().message());
        let (efl, bfd, ghosts) = optics(h.state());
        assert!((efl - efl0).abs() < 1e-9 && (bfd - bfd0).abs() < 1e-9, "{id}: {efl} {bfd} against {efl0} {bfd0}");
        assert_eq!(ghosts, ghosts0, "{id}: a dummy surface makes no ghost");
        surface_menu(&mut h, 1, REMOVE_SURFACE);
        assert_eq!(h.state().doc().lens, before, "{id}: x removes exactly what + added ({:?})", h.state().message());
        let (efl, bfd, ghosts) = optics(h.state());
        assert!((efl - efl0).abs() < 1e-9 && (bfd - bfd0).abs() < 1e-9 && ghosts == ghosts0, "{id}");
    }
}

/// The priority rule: a bake is a background job (its threads at the lowest priority), so a new focus of the
/// depth of field, which the user waits for, finishes while the zoom's bake (tens of seconds) still runs
/// (issue 32: the focus waited 75 s for the bake). Ordering, not timing, is what is held.
#[test]
fn a_focus_finishes_while_a_bake_runs_in_the_background() {
    use flarelab::panels::BakeStatus;
    let dir = tempfile::tempdir().unwrap();
    let mut doc = street_doc(dir.path(), 320, 180, true);
    doc.lens = flare_core::preset::Document::default().lens;
    let mut h = harness_on(Some(doc));
    h.run();
    step_until(&mut h, 120.0, |app| !app.jobs().dof().busy() && app.jobs().dof().status.contains("focus 5.00 m"));
    show(&mut h, Tab::Blend);
    h.get_by_label("Bake").click();
    h.run_steps(2);
    assert!(matches!(h.state().bake_status(), BakeStatus::Running { .. }), "{:?}", h.state().bake_status());
    h.state_mut().edit().dof.focus_m = 2.0;
    let seconds =
        step_until(&mut h, 300.0, |app| !app.jobs().dof().busy() && app.jobs().dof().status.contains("focus 2.00 m"));
    let status = h.state().bake_status();
    println!("a focus while the zoom bakes: {seconds:.1} s ({status:?})");
    assert!(matches!(status, BakeStatus::Running { .. }), "the bake finished first: {status:?}");
    h.get_by_label("Cancel").click();
    step_until(&mut h, 300.0, |app| !matches!(app.bake_status(), BakeStatus::Running { .. }));
}

/// Background jobs run at the lowest priority, their pool's threads too; interactive jobs a step below the window.
#[cfg(target_os = "linux")]
#[test]
fn background_jobs_run_at_the_lowest_priority() {
    use flarelab::app::jobs::job::{Job, JobPoll, Priority};
    let nice = || {
        // SAFETY: getpriority reads the calling thread's nice value.
        unsafe { libc::getpriority(libc::PRIO_PROCESS, 0) }
    };
    // The window stays at the app's priority; the interactive jobs a step below it, the background ones lowest.
    let app_nice = nice();
    for (priority, expected) in [(Priority::Background, 19), (Priority::Interactive, app_nice.max(10))] {
        let job = Job::spawn_with(priority, "", move |_, _| {
            let pool: Vec<i32> = rayon::broadcast(|_| nice());
            (nice(), pool)
        });
        let (own, pool) = loop {
            if let JobPoll::Finished(outcome) = job.poll() {
                break outcome;
            }
            std::thread::sleep(std::time::Duration::from_millis(10));
        };
        assert_eq!(own, expected, "{priority:?}: the job's thread");
        assert!(pool.iter().all(|&n| n == expected), "{priority:?}: its pool's threads {pool:?}");
    }
}

/// File > Export image draws at the plate's size unless the user set one, as `render` does without --size
/// (issue 32: it wrote 1920x1080 over a 960x540 plate); a size the user sets wins.
#[test]
fn an_export_over_a_plate_is_the_plates_size_unless_set() {
    use flarelab::app::files::FileUse;
    let dir = tempfile::tempdir().unwrap();
    let doc = street_doc(dir.path(), 480, 270, false);
    let mut h = harness_on(Some(doc));
    h.run();
    assert_eq!(h.state().export_px(), (480, 270));
    let export = |h: &mut Harness<'static, FlareLabApp>, name: &str| {
        let path = dir.path().join(name);
        h.state_mut().use_file(FileUse::ExportImage, &path);
        step_until(h, 120.0, |_| path.exists());
        image::open(&path).unwrap().to_rgb8().dimensions()
    };
    assert_eq!(export(&mut h, "plate.png"), (480, 270));
    h.get_by_label("File").click();
    h.run();
    h.get_by_label("export width").set_value_accesskit(320.0);
    h.run();
    assert_eq!(h.state().export_px(), (320, 270));
    assert_eq!(export(&mut h, "set.png"), (320, 270));
}

/// The automatic bake restarts only for the optics it serves, once an edit has stood (`autobake::SETTLE`): a
/// drag of the exposure never restarts it; three quick edits of a radius start one bake, for the last value,
/// which keeps the ghosts of the LUT before it that did not change.
#[test]
fn an_exposure_tweak_does_not_restart_the_bake_and_quick_lens_edits_start_one() {
    use flare_core::bake::BakeSettings;
    use flarelab::panels::BakeStatus;
    let coarse = BakeSettings { res: 32, grid: 16, initial_steps: 2, tolerance: 0.5, ..BakeSettings::default() };
    let mut app = FlareLabApp::new(None, Some(flare_core::preset::Document::default()));
    app.jobs_mut().autobake_mut().cache = None;
    app.jobs_mut().autobake_mut().settings = coarse;
    let mut h = Harness::builder()
        .with_size(egui::vec2(1280.0, 800.0))
        .build_ui_state(|ui, app: &mut FlareLabApp| app.ui_root(ui), app);
    h.run_steps(2);
    assert_eq!(h.state().jobs().autobake().bakes_started, 1, "the session's optics bake at once");
    assert!(matches!(h.state().bake_status(), BakeStatus::Running { .. }));
    for ev in [6.0, 9.0, 12.0] {
        h.get_by_role_and_label(egui::accesskit::Role::Slider, "flare exposure").set_value_accesskit(ev);
        h.run_steps(2);
    }
    assert_eq!(h.state().jobs().autobake().bakes_started, 1, "the exposure is not the optics");
    assert!(matches!(h.state().bake_status(), BakeStatus::Running { .. }), "{:?}", h.state().bake_status());
    h.state_mut().show_tab(Tab::Lens);
    h.run_steps(2);
    let r = h.state().doc().lens.surfaces[0].radius_mm;
    for scale in [1.01, 1.02, 1.03] {
        h.get_by_label("radius 0").set_value_accesskit(r * scale);
        h.run_steps(2);
    }
    assert_eq!(h.state().jobs().autobake().bakes_started, 1, "nothing starts while the edits come");
    step_until(&mut h, 60.0, |app| app.jobs().autobake().bakes_started == 2);
    std::thread::sleep(std::time::Duration::from_millis(1000));
    h.run_steps(2);
    assert_eq!(h.state().jobs().autobake().bakes_started, 2, "one bake, for the last value");
    h.state_mut().show_tab(Tab::Blend);
    h.run_steps(2);
    h.get_by_label("Cancel").click();
    step_until(&mut h, 300.0, |app| !matches!(app.bake_status(), BakeStatus::Running { .. }));
}

/// The Lens panel fits the default window, 1440x900: its Open button and every row's buttons lie inside it
/// (issue 32 saw them clipped; the table scrolls where it is taller than the window).
#[test]
fn the_lens_panels_buttons_are_inside_the_default_window() {
    let mut h = Harness::builder()
        .with_size(egui::vec2(1440.0, 900.0))
        .build_ui_state(|ui, app: &mut FlareLabApp| app.ui_root(ui), quiet(FlareLabApp::new(None, None)));
    show(&mut h, Tab::Lens);
    let window = egui::Rect::from_min_size(egui::Pos2::ZERO, egui::vec2(1440.0, 900.0));
    let mut seen = 0;
    let rows: Vec<String> = (0..h.state().doc().lens.surfaces.len()).map(|k| k.to_string()).collect();
    for label in std::iter::once("Open…").chain(rows.iter().map(String::as_str)) {
        for node in h.get_all_by_label(label) {
            let r = node.rect();
            // Rows scrolled below the panel's bottom are not shown; what is shown lies inside the window.
            if r.min.y < window.max.y {
                assert!(r.max.x <= window.max.x && r.min.x >= 0.0, "{label} at {r:?}");
                seen += 1;
            }
        }
    }
    assert!(seen > 20, "{seen} buttons seen");
}

/// Picture first: from 1024x700 to 2560x1440 with the side panel open, the viewport takes most of the window
/// (at least 60 % at 1440x900, where a 600-point panel and six rows under the view left it 31 %), the status
/// bar is one line, and every tab's content fits the panel's width (nothing lies right of the window: the
/// panel would scroll sideways); the sections under the view open by their toggles and fold back.
#[test]
fn the_viewport_takes_most_of_the_window_and_every_tab_fits_the_panel() {
    use egui_kittest::kittest::by;
    for (width, height, least) in [(1024.0, 700.0, 0.45), (1440.0, 900.0, 0.60), (2560.0, 1440.0, 0.60)] {
        let mut h = Harness::builder()
            .with_size(egui::vec2(width, height))
            .build_ui_state(|ui, app: &mut FlareLabApp| app.ui_root(ui), quiet(FlareLabApp::new(None, None)));
        h.run_steps(2);
        let view = h.state().view_rect().expect("a viewport");
        let share = view.area() / (width * height);
        println!(
            "{width}x{height}: the viewport {:.0}x{:.0}, {:.1} % of the window",
            view.width(),
            view.height(),
            100.0 * share
        );
        assert!(share >= least, "{width}x{height}: the viewport {view:?} is {share:.3} of the window");
        let mut widened = Vec::new();
        for tab in Tab::ALL {
            // (The Looks tab's thumbnails keep a spinner turning: steps, not `run`.)
            h.state_mut().show_tab(tab);
            h.run_steps(3);
            for node in h.query_all(by().predicate(|n| n.bounding_box().is_some())) {
                let r = node.rect();
                assert!(r.max.x <= width + 0.5, "{width}x{height}, {tab:?}: {node:?} at {r:?}");
            }
            // No tab widens the panel: the view keeps its size.
            let now = h.state().view_rect().unwrap();
            if now != view {
                widened.push(format!("{width}x{height}: {tab:?} left the view {now:?}"));
            }
        }
        assert!(widened.is_empty(), "{widened:#?} (was {view:?})");
        // The status bar: one line (a button's height), under the view.
        let status = h.get_by_label_contains("sprites").rect();
        assert!(status.height() <= 24.0 && status.min.y > view.max.y, "{status:?}");
        // A section opens under the view (the view gives it room) and folds back.
        h.get_by_label("ray diagram").click();
        h.run_steps(2);
        h.run_steps(2);
        h.run_steps(2);
        let open = h.state().view_rect().unwrap();
        assert!(h.state().ui_state().rays_open && open.area() < 0.95 * view.area(), "{open:?} against {view:?}");
        h.get_by_label("ray diagram").click();
        h.run_steps(4);
        assert_eq!(h.state().view_rect().unwrap(), view, "folded, the view takes its height back");
    }
}

/// Lens table cells apply a typed value on Enter (or focus loss), not on every keystroke: typing "-12" never
/// passes through the refused "-1" (issue 32: a refused intermediate value moved the table and once lost a
/// keystroke); Escape gives back the value the edit started from.
#[test]
fn a_lens_cell_applies_a_typed_value_on_enter_and_escape_reverts() {
    let mut h = harness_on(Some(dgauss()));
    show(&mut h, Tab::Lens);
    let before = h.state().doc().lens.surfaces[6].radius_mm;
    let steps = h.state().session().can_undo();
    h.get_by_label("radius 6").click();
    h.run();
    h.key_press_modifiers(egui::Modifiers::COMMAND, egui::Key::A);
    h.event(egui::Event::Text("-1".into()));
    h.run();
    assert_eq!(h.state().doc().lens.surfaces[6].radius_mm, before, "nothing applies while typing");
    assert!(h.state().derived().lens_problem().is_none(), "no refusal for a value not yet entered");
    h.event(egui::Event::Text("2".into()));
    h.run();
    h.key_press(egui::Key::Enter);
    h.run();
    assert_eq!(h.state().doc().lens.surfaces[6].radius_mm, -12.0, "Enter applies the whole value");
    assert!(h.state().derived().lens_problem().is_none());
    assert!(h.state().session().can_undo() && !steps);
    // Escape gives back the value the edit started from.
    h.get_by_label("radius 6").click();
    h.run();
    h.key_press_modifiers(egui::Modifiers::COMMAND, egui::Key::A);
    h.event(egui::Event::Text("-3".into()));
    h.run();
    h.key_press(egui::Key::Escape);
    h.run();
    assert_eq!(h.state().doc().lens.surfaces[6].radius_mm, -12.0, "Escape reverts");
}

/// A refused value does not move the lens table (its reason takes the line the first-order data had): the
/// user's next click lands on the row aimed at (issue 32: the refusal's line pushed the table down, and "-12"
/// went into the row above).
#[test]
fn a_refusal_does_not_move_the_lens_table() {
    let mut h = harness_on(Some(dgauss()));
    show(&mut h, Tab::Lens);
    let row = |h: &Harness<'static, FlareLabApp>| h.get_by_label("radius 7").rect();
    let before = row(&h);
    h.get_by_label("radius 6").set_value_accesskit(-1.0);
    h.run();
    assert!(h.state().derived().lens_problem().is_some());
    assert!(h.query_by_label_contains("the view shows the last valid lens").is_some(), "the reason is shown");
    assert_eq!(row(&h), before, "the table stayed where it was");
}

/// An anamorphic lens in the Lens panel: each toroid's x-z radius is a cell of its own (a surface of revolution
/// shows `=`), editing it reaches the document and the flare (the ghosts are ellipses per section), an
/// impossible one is refused on its cell with the reason, and undo gives back exactly what was there.
#[test]
fn a_toroids_x_radius_is_edited_in_the_lens_table() {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/reference/toroidal/toroidal_test_lens.json");
    let lens = flare_core::optics::formats::load_lens_file(&path).unwrap();
    let doc = flare_core::preset::Document { lens, ..flare_core::preset::Document::default() };
    let mut h = harness_on(Some(doc));
    show(&mut h, Tab::Lens);
    assert!(h.query_by_label_contains("squeeze").is_some(), "the summary gives the squeeze");
    assert!(h.query_by_label("radius x 1").is_none(), "surface 1 is a surface of revolution");
    let before = h.state().doc().lens.clone();
    h.get_by_label("radius x 0").set_value_accesskit(44.0);
    h.run();
    assert_eq!(h.state().doc().lens.surfaces[0].radius_x_mm, Some(44.0));
    assert!(h.state().derived().lens_problem().is_none());
    let flare = h.state().flare().unwrap();
    assert!(flare.system.is_anamorphic() && flare.system.lens.surfaces[0].radius_x_mm == Some(44.0));
    // A radius of rotation narrower than the clear aperture: refused on its cell, the flare kept.
    h.get_by_label("radius x 0").set_value_accesskit(5.0);
    h.run();
    let problem = h.state().derived().lens_problem().clone().expect("refused");
    assert_eq!((problem.surface, problem.field), (Some(0), Some("radius_x")), "{problem:?}");
    assert_eq!(h.state().flare().unwrap().system.lens.surfaces[0].radius_x_mm, Some(44.0));
    h.key_press_modifiers(egui::Modifiers::COMMAND, egui::Key::Z);
    h.run();
    h.key_press_modifiers(egui::Modifiers::COMMAND, egui::Key::Z);
    h.run();
    assert_eq!(h.state().doc().lens, before, "undo gives back exactly what was there");
}

/// The aperture panel's dirt: choosing a pattern prepares its map and the view's frame draws a glow; the amount
/// slider changes only the display (no optics rebuilt); undo returns exactly the clean lens.
#[test]
fn the_dirt_control_dirties_the_front_element_and_undo_cleans_it() {
    use flare_core::dirt::DirtKind;
    let mut h = harness();
    show(&mut h, Tab::Aperture);
    h.run();
    let before = h.state().doc().dirt.clone();
    assert!(h.query_by_label_contains("a clean lens").is_some());
    h.get_by_label("dirt").click();
    h.run();
    h.get_by_label("dust").click();
    h.run();
    step_until(&mut h, 30.0, |app| app.flare().is_some_and(|f| f.dirt.is_some()));
    assert_eq!(h.state().doc().dirt.pattern, DirtKind::Dust);
    assert!(h.state().flare().unwrap().dirt.is_some(), "the map is prepared");
    step_until(&mut h, 30.0, |app| app.derived().view_frame().as_ref().is_some_and(|(_, f)| f.scene.has_dirt_glow()));
    let frame = h.state().derived().view_frame().as_ref().map(|(_, f)| f.clone()).unwrap();
    assert!(frame.scene.has_dirt_glow() && frame.dirt_taken > 0.0, "the view draws the glow");
    assert!(h.query_by_label_contains("of the light at its position into the glow").is_some());
    let optics = h.state().derived().rebuilds().optics;
    h.get_by_role_and_label(egui::accesskit::Role::Slider, "dirt amount").set_value_accesskit(5.0);
    h.run();
    assert!((h.state().doc().dirt.amount - 0.05).abs() < 1e-12, "{}", h.state().doc().dirt.amount);
    assert_eq!(h.state().derived().rebuilds().optics, optics, "the amount rebuilds no optics");
    for _ in 0..2 {
        h.key_press_modifiers(egui::Modifiers::COMMAND, egui::Key::Z);
        h.run();
    }
    assert_eq!(h.state().doc().dirt, before, "undo gives back exactly the clean lens");
}

/// One truth (issue 60): every shipped look applied in the app draws the frame `flarelab render --preset NAME`
/// draws. The anamorphic look kept the app's 36 mm sensor and framed its light 1.5x wider than the command
/// line. Each look applied to the fresh document (undone after), both at 192x108 on the CPU twin without LUT
/// ghosts (the app's bake is off here; `--method paraxial`), the app through File > Export image's writer,
/// compared in display values.
#[test]
fn every_shipped_look_applied_in_the_app_draws_the_command_lines_frame() {
    let dir = tempfile::tempdir().unwrap();
    let mut h = harness();
    h.run();
    for (k, preset) in flare_core::preset::shipped().iter().enumerate() {
        h.state_mut().apply_look(k);
        // The optics are prepared on the UI thread's next frames.
        step_until(&mut h, 60.0, |app| app.derived().flare().as_ref().is_some_and(|f| f.system.lens == app.doc().lens));
        h.run_steps(2);
        let app_png = dir.path().join(format!("app-{k}.png"));
        let cli_png = dir.path().join(format!("cli-{k}.png"));
        h.state().export_image_to((192, 108), &app_png).unwrap();
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_flarelab"))
            .args(["render", "--preset", preset.name, "--size", "192x108", "--device", "cpu"])
            .args(["--method", "paraxial", "-o", cli_png.to_str().unwrap()])
            .env("FLARELAB_CACHE_DIR", dir.path().join("cache"))
            .output()
            .unwrap();
        assert!(out.status.success(), "{}: {}", preset.name, String::from_utf8_lossy(&out.stderr));
        let read = |p: &std::path::Path| -> Vec<[f32; 3]> {
            let image = image::open(p).unwrap().to_rgb8();
            image.pixels().map(|p| p.0.map(|v| f32::from(v) / 255.0)).collect()
        };
        let (app, cli) = (read(&app_png), read(&cli_png));
        assert_eq!(app.len(), cli.len(), "{}", preset.name);
        let psnr = flare_core::metrics::psnr(&app, &cli);
        println!("{}: the app's frame against the command line's {psnr:.1} dB", preset.name);
        assert!(psnr >= 40.0, "{}: the app's frame is {psnr:.1} dB from the command line's", preset.name);
        assert_eq!(h.state().doc().sensor_width_mm, preset.document().unwrap().sensor_width_mm, "{}", preset.name);
        // Back to the fresh document (an animated look's keys would otherwise stay as the user's shot).
        h.state_mut().undo();
        h.run();
    }
}

/// View changes are said: the ghosts' method (the look or a ray grid) and folding the side panel away (which
/// gives the view the window's width), each replacing what the status line said.
#[test]
fn view_changes_say_what_the_view_now_draws() {
    let mut h = Harness::builder()
        .with_size(egui::vec2(1440.0, 900.0))
        .build_ui_state(|ui, app: &mut FlareLabApp| app.ui_root(ui), quiet(FlareLabApp::new(None, None)));
    h.run_steps(2);
    let view = h.state().view_rect().unwrap();
    h.get_by_label("ghosts").click();
    h.run_steps(2);
    h.get_by_label("ray grid 16 (exact)").click();
    h.run_steps(2);
    let said = h.state().message().unwrap_or_default().to_owned();
    assert!(said.contains("ray grid 16") && said.contains("exports still draw the look"), "{said}");
    h.state_mut().jobs_mut().raygrid_mut().grid = None;
    h.get_by_label("View").click();
    h.run_steps(2);
    h.get_by_label("Panels").click();
    h.run_steps(3);
    let said = h.state().message().unwrap_or_default().to_owned();
    assert!(said.contains("folded away"), "{said}");
    let wide = h.state().view_rect().unwrap();
    assert!(wide.area() > 1.2 * view.area(), "{wide:?} against {view:?}");
}

/// On a software adapter the draft passes are warmed once the first frame is shown: a draft of the view drawn
/// aside, and again through the view's cube once that is baked, so that the first draft of the user's first
/// drag does not wait on llvmpipe compiling its code and on the cube's bake (issue 60's replay: 109 ms for
/// that input before, under 75 ms after). The warm-up changes nothing shown.
#[test]
fn the_draft_passes_are_warmed_after_the_first_frame_without_changing_it() {
    let Some(mut warmed) = gpu_harness(None) else { return };
    // Frame by frame, so that the picture compared is the one drawn right after the last warm-up.
    let started = std::time::Instant::now();
    while !warmed.state().drafts_warm() {
        assert!(started.elapsed().as_secs() < 60, "the draft passes were not warmed in 60 s");
        std::thread::sleep(std::time::Duration::from_millis(50));
        warmed.step();
    }
    let doc_view = warmed.state().derived().view_frame().clone().unwrap().1.scene.view_transform();
    assert!(flare_core::view_lut::ViewLut::ready_or_bake(&doc_view).is_some(), "the view's cube is baked");
    // The same window drawn without the warm-up: the viewport's pixels are the same.
    let mut plain = gpu_harness(None).unwrap();
    plain.state_mut().skip_draft_warm_up();
    plain.run();
    let crop = |h: &mut egui_kittest::Harness<'static, FlareLabApp>| {
        let rect = h.state().view_rect().expect("the viewport is laid out");
        let image = h.render().unwrap();
        let (x, y) = (rect.left().ceil() as u32 + 1, rect.top().ceil() as u32 + 1);
        image::imageops::crop_imm(&image, x, y, rect.width() as u32 - 2, rect.height() as u32 - 2).to_image()
    };
    let (with, without) = (crop(&mut warmed), crop(&mut plain));
    assert!(without.pixels().any(|p| p.0[..3] != [0, 0, 0]), "the viewport shows a flare");
    assert!(with == without, "the warm-up changed the picture");
}
