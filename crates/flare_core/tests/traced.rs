//! Frames with ray-traced ghosts (`render --method raygrid | reference`) go through the one pipeline: per-ghost
//! layers traced alone that add up to the flare, and sequences whose frames are the stills of those frames, on
//! the CPU and (where there is one, lavapipe in CI) the GPU.

use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use flare_core::flare::PreparedFlare;
use flare_core::footage::pattern::FramePattern;
use flare_core::frame::{Device, Frame, LayerChoice, Sources};
use flare_core::preset::Document;
use flare_core::raytrace::Grid;
use flare_core::render::cpu;
use flare_core::shot::plan::plan;
use flare_core::shot::sequence::{FrameOutcome, SequenceOptions, ShotSources, render_sequence};
use flare_core::traced::TracedGhosts;

/// The Tessar with the light keyed across three frames, a ghost's gain halved (a preset's gains must reach the
/// tracer) and another ghost off.
fn keyed_document() -> (Document, PreparedFlare) {
    let mut doc =
        Document { lens: flare_core::optics::library::builtin_lens("tessar").unwrap(), ..Document::default() };
    let flare = PreparedFlare::new(&doc.lens, &doc.flare_config().unwrap()).unwrap();
    doc.timeline.light_deg.set(1, [-6.0, 2.0]);
    doc.timeline.light_deg.set(3, [6.0, -2.0]);
    let (i, j) = (flare.system.ghosts[2].i, flare.system.ghosts[2].j);
    doc.ghost_mut(i, j).gain = 0.5;
    let (i, j) = (flare.system.ghosts[5].i, flare.system.ghosts[5].j);
    doc.ghost_mut(i, j).enabled = false;
    (doc, flare)
}

fn devices() -> Vec<Device> {
    let mut devices = vec![Device::Cpu];
    if let Some(ctx) = flare_core::render::gpu::test_context() {
        devices.push(Device::Gpu(Box::new(flare_core::frame::GpuDrawer::on(ctx))));
    }
    devices
}

fn energy(img: &flare_core::image::HdrImage) -> f64 {
    img.pixels.iter().map(|p| f64::from(p[0]) + f64::from(p[1]) + f64::from(p[2])).sum()
}

#[test]
fn traced_ghost_layers_add_up_to_the_traced_flare() {
    let (doc, flare) = keyed_document();
    for device in devices() {
        let traced = TracedGhosts::new(&flare, Grid::Fixed(16), 0, &device);
        let request = doc.frame_request_at(&flare.system, 2.0, 160, 120, 1);
        let frame = Frame::build(&flare, None, &request);
        let sources = Sources { flare: &flare, lut: None, plate: None };
        let (drawn, how) = traced.draw(&device, &frame, &sources).unwrap();
        let layers = traced.ghost_layers(&device, &frame, &sources).unwrap();
        let off = format!("ghost_{}_{}", flare.system.ghosts[5].i, flare.system.ghosts[5].j);
        assert!(!layers.is_empty() && layers.iter().all(|(name, _)| name.starts_with("ghost_") && *name != off));
        // The flare layer less the starburst, against the sum of the ghosts' layers.
        let mut starburst = flare_core::image::HdrImage::black(frame.scene.hdr_width, frame.scene.hdr_height);
        cpu::starburst_pass(&frame.scene, &flare.starburst_texture, &mut starburst);
        let flare_layer = cpu::flare_layer(&frame.scene, &drawn.hdr);
        let ghosts = energy(&flare_layer) - energy(&cpu::flare_layer(&frame.scene, &starburst));
        let sum: f64 = layers.iter().map(|(_, l)| energy(l)).sum();
        eprintln!("{}: {} layers, sum / flare {:.6} ({how})", device.name(), layers.len(), sum / ghosts);
        assert!(ghosts > 0.0 && (sum / ghosts - 1.0).abs() < 1e-3, "{sum} against {ghosts}");
    }
}

#[test]
fn a_traced_sequence_writes_the_stills_of_its_frames() {
    let (doc, flare) = keyed_document();
    let plan = plan(&doc, &flare.system, 1..=3, Some((120, 80)), &|_, _| {}, &AtomicBool::new(false)).unwrap();
    for mut device in devices() {
        let dir = tempfile::tempdir().unwrap();
        let text = format!("{}/traced.####.exr", dir.path().display());
        let traced = Arc::new(TracedGhosts::new(&flare, Grid::Fixed(16), 0, &device));
        let options = SequenceOptions {
            out: FramePattern::parse(&text).unwrap().unwrap(),
            layers: LayerChoice { ghosts: true, ..Default::default() },
            skip_existing: false,
            divisor: 1,
            parallel_frames: true,
            traced: Some(traced.clone()),
        };
        let sources = ShotSources { doc: &doc, flare: &flare, lut: None, plan: &plan };
        let report = render_sequence(&mut device, &sources, &options, &|_, _, _| {}, &AtomicBool::new(false));
        assert_eq!(report.records.len(), 3);
        assert!(report.records.iter().all(|r| r.outcome == FrameOutcome::Rendered), "{:?}", report.records);
        // Frame 2 of the sequence is the still of frame 2, its ghost layers included.
        let request = plan.request(&doc, &flare.system, &plan.frames[1], 1);
        let frame = Frame::build(&flare, None, &request);
        let s = Sources { flare: &flare, lut: None, plate: None };
        let (drawn, _) = traced.draw(&device, &frame, &s).unwrap();
        let still = dir.path().join("still.exr");
        traced.write(&device, &frame, &s, &drawn, LayerChoice { ghosts: true, ..Default::default() }, &still).unwrap();
        // Written in one call (`render`'s way: the EXR from the accumulation alone, no display image made): the
        // same channels as the drawn frame's.
        let direct = dir.path().join("direct.exr");
        traced
            .render_to_file(&device, &frame, &s, LayerChoice { ghosts: true, ..Default::default() }, &direct)
            .unwrap();
        let channels = |p: &std::path::Path| flare_core::output::read_exr_channels(p).unwrap().channels;
        assert_eq!(channels(&direct), channels(&still), "{}: render_to_file against draw + write", device.name());
        let read = |p: &std::path::Path| {
            exr::prelude::read_all_flat_layers_from_file(p)
                .unwrap()
                .layer_data
                .iter()
                .map(|l| l.channel_data.list.len())
                .sum::<usize>()
        };
        let sequence_frame = options.out.path(2);
        assert_eq!(read(&sequence_frame), read(&still), "the same layers");
        let (a, b) =
            (flare_core::output::read_plate(&sequence_frame).unwrap(), flare_core::output::read_plate(&still).unwrap());
        let c = flare_core::metrics::compare(&a, &[], &b, &[]);
        eprintln!("{}: sequence frame 2 against its still: {:.1} dB", device.name(), c.psnr_db);
        assert!(c.psnr_db > 80.0, "{c:?}");
    }
}
