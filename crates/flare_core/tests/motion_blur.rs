//! Motion blur from the shutter: a light that moves within a frame streaks each ghost by the distance it moves
//! while the shutter is open, with the energy of the sharp frame; a closed shutter is the sharp frame exactly;
//! the GPU draws the same streaks as its CPU twin.

use flare_core::flare::PreparedFlare;
use flare_core::frame::{self, Device, Frame, GpuDrawer, Sources};
use flare_core::image::HdrImage;
use flare_core::preset::Document;
use flare_core::render::gpu::test_context;
use flare_core::timeline::{Interpolation, Key};

const W: u32 = 480;
const H: u32 = 320;
/// The light's horizontal speed (degrees per frame) on a horizontal line through the frame's centre: the
/// ghosts line up with it and move horizontally.
const DEG_PER_FRAME: f64 = 0.6;

/// A one-wavelength document on a 200 mm zoom (one sprite per ghost) whose light crosses the frame horizontally, linearly,
/// `DEG_PER_FRAME` a frame from frame 1, with a `shutter_deg` shutter.
fn moving(shutter_deg: f64) -> Document {
    // A telephoto: its ghosts are small enough to be measured whole in the frame.
    let mut doc =
        Document::for_lens(flare_core::optics::library::builtin_lens("canon_zoom_70_200mm_at_200mm").unwrap());
    doc.wavelengths = 1;
    doc.starburst = false;
    doc.exposure_auto = false;
    doc.timeline.interpolation = Interpolation::Linear;
    doc.timeline.light_deg.keys =
        vec![Key { frame: 1, value: [1.0, 0.0] }, Key { frame: 21, value: [1.0 + 20.0 * DEG_PER_FRAME, 0.0] }];
    doc.timeline.shutter_deg = shutter_deg;
    doc
}

fn prepared(doc: &Document) -> PreparedFlare {
    PreparedFlare::new(&doc.lens, &doc.flare_config().unwrap()).unwrap()
}

fn draw(flare: &PreparedFlare, doc: &Document, frame: f64, gains: Option<Vec<f32>>) -> (Frame, HdrImage) {
    let mut request = doc.frame_request_at(&flare.system, frame, W, H, 1);
    if let Some(g) = gains {
        request.ghost_gains = g;
    }
    let built = Frame::build(flare, None, &request);
    let hdr = frame::draw_cpu_hdr(&built, &Sources { flare, lut: None, plate: None });
    (built, hdr)
}

fn energy(image: &HdrImage) -> f64 {
    image.pixels.iter().map(|p| f64::from(p[0]) + f64::from(p[1]) + f64::from(p[2])).sum()
}

/// The columns an image is lit in (any channel above `floor`): first and last, or `None`.
fn lit_columns(image: &HdrImage, floor: f32) -> Option<(u32, u32)> {
    let lit = |x: u32| {
        (0..image.height).any(|y| image.pixels[(y * image.width + x) as usize][..3].iter().any(|&v| v > floor))
    };
    let first = (0..image.width).find(|&x| lit(x))?;
    let last = (0..image.width).rev().find(|&x| lit(x))?;
    Some((first, last))
}

/// The energy-weighted mean and variance of an image's x (pixel centres at `x + 0.5`).
fn moments_x(image: &HdrImage) -> (f64, f64) {
    let (mut sum, mut sx, mut sxx) = (0.0, 0.0, 0.0);
    for (i, p) in image.pixels.iter().enumerate() {
        let v = f64::from(p[0]) + f64::from(p[1]) + f64::from(p[2]);
        let x = (i as u32 % image.width) as f64 + 0.5;
        sum += v;
        sx += v * x;
        sxx += v * x * x;
    }
    let mean = sx / sum;
    (mean, sxx / sum - mean * mean)
}

#[test]
fn a_closed_shutter_or_a_still_light_is_the_sharp_frame_exactly() {
    let doc = moving(0.0);
    let flare = prepared(&doc);
    let request = doc.frame_request_at(&flare.system, 8.0, W, H, 1);
    assert!(request.motion.is_none(), "0 degrees: no path");
    let sharp = Frame::build(&flare, None, &request);
    assert!(sharp.shutter.is_none());
    // The same frame with a shutter but a light that stands still (no keys): the sharp frame, byte for byte.
    let mut still = doc.clone();
    still.timeline.light_deg.keys.clear();
    still.light_deg = request.light_deg;
    still.timeline.shutter_deg = 180.0;
    let still_request = still.frame_request_at(&flare.system, 8.0, W, H, 1);
    assert!(still_request.motion.is_none(), "a still light has no path");
    let sources = Sources { flare: &flare, lut: None, plate: None };
    let a = frame::draw_cpu(&sharp, &sources);
    let b = frame::draw_cpu(&Frame::build(&flare, None, &still_request), &sources);
    assert_eq!(a, b);
}

#[test]
fn a_180_degree_shutter_streaks_each_ghost_by_half_its_motion_with_the_same_energy() {
    let (sharp_doc, blur_doc) = (moving(0.0), moving(180.0));
    let flare = prepared(&sharp_doc);
    let at = 8.0;
    // The light's own image moves N pixels a frame; the ghosts each at their own rate.
    let px_of = |f: f64| {
        let req = sharp_doc.frame_request_at(&flare.system, f, W, H, 1);
        let u = flare_core::render::light_slopes_for_frame_position(req.light_deg[0], req.light_deg[1]);
        let sensor = flare_core::optics::sensor::Sensor::for_frame(req.sensor_width(), W, H);
        flare_core::render::sensor_to_pixel(flare.system.light_image_mm(u), &sensor, W, H)
    };
    let light_px_per_frame = (px_of(at + 1.0)[0] - px_of(at)[0]).abs();
    assert!(light_px_per_frame > 8.0, "the light moves {light_px_per_frame} px a frame");

    let (blurred, blurred_hdr) = draw(&flare, &blur_doc, at, None);
    let (_, sharp_hdr) = draw(&flare, &sharp_doc, at, None);
    let samples = blurred.shutter.clone().expect("the light moves while the shutter is open");
    assert!(samples.count > 2 && samples.max_gap_px <= 1.0, "{samples:?}");
    let ratio = energy(&blurred_hdr) / energy(&sharp_hdr);
    println!(
        "light {light_px_per_frame:.1} px/frame: {} samples, {:.1} a ghost, longest {:.1} px, largest gap {:.2} px, energy blurred / sharp {ratio:.5}",
        samples.count,
        samples.mean_per_ghost(),
        samples.longest_px,
        samples.max_gap_px
    );
    assert!((ratio - 1.0).abs() < 0.01, "energy ratio {ratio}");

    // Each ghost alone, measured along the motion (x): its motion per frame is the move of its centroid from
    // this frame to the next; its streak is the box the shutter convolves it with, whose length L adds L^2 / 12
    // to the variance along x ((N + 1) / (N - 1) of that for N evenly spaced samples).
    let ghosts = flare.system.ghosts.len();
    let mut measured = 0;
    for g in 0..ghosts {
        let alone: Vec<f32> = (0..ghosts).map(|h| if h == g { 1.0 } else { 0.0 }).collect();
        let (_, sharp) = draw(&flare, &sharp_doc, at, Some(alone.clone()));
        let (_, next) = draw(&flare, &sharp_doc, at + 1.0, Some(alone.clone()));
        let peak = sharp.pixels.iter().map(|p| p[0].max(p[1]).max(p[2])).fold(0.0f32, f32::max);
        if peak <= 0.0 || energy(&sharp) <= 0.0 || energy(&next) <= 0.0 {
            continue;
        }
        let motion_px = (moments_x(&next).0 - moments_x(&sharp).0).abs();
        // Only ghosts wholly inside the frame with room for their streak (a clipped ghost's moments are not its
        // own), that move at least 2 pixels a frame and keep their shape while they do (a ghost that grows or
        // is cut by a moving mask adds variance of its own).
        let reshaped = (moments_x(&next).1 - moments_x(&sharp).1).abs();
        if reshaped > 0.1 * (motion_px / 2.0).powi(2) / 12.0 {
            continue;
        }

        let Some((a0, a1)) = lit_columns(&sharp, peak * 1e-6) else { continue };
        let room = motion_px + 2.0;
        if motion_px < 2.0 || f64::from(a0) < room || f64::from(a1) + room > f64::from(W) {
            continue;
        }
        let (_, blurred) = draw(&flare, &blur_doc, at, Some(alone.clone()));
        let n = samples.per_ghost[g] as f64;
        let added = moments_x(&blurred).1 - moments_x(&sharp).1;
        let streak = (12.0 * added.max(0.0) * (n - 1.0) / (n + 1.0)).sqrt();
        // A ghost whose light changes as it moves (a clear aperture cutting it more or less) streaks the mean of
        // its light over the open shutter (frames at - 1/4 to at + 1/4), not the middle frame's.
        let over_shutter = (0..=8)
            .map(|i| energy(&draw(&flare, &sharp_doc, at - 0.25 + 0.0625 * f64::from(i), Some(alone.clone())).1))
            .collect::<Vec<f64>>();
        let mean = (over_shutter[1..8].iter().sum::<f64>() + 0.5 * (over_shutter[0] + over_shutter[8])) / 8.0;
        let e = energy(&blurred) / mean;
        println!(
            "ghost {g}: moves {motion_px:.2} px/frame, streak {streak:.2} px (half its motion: {:.2}), energy {e:.4}",
            motion_px / 2.0
        );
        assert!(
            (streak - motion_px / 2.0).abs() <= 1.0,
            "ghost {g}: streak {streak} px, half its motion {}",
            motion_px / 2.0
        );
        assert!((e - 1.0).abs() < 0.01, "ghost {g}: energy ratio {e}");
        measured += 1;
    }
    // Since every clear aperture cuts the ghosts, most of this lens's ghosts change shape as the light moves 4 degrees a
    // frame (they are left out above); the two that keep it are the bright one on the light's image and one more.
    assert!(measured >= 2, "only {measured} ghosts could be measured");
}

#[test]
fn the_gpu_draws_the_blurred_frame_as_its_cpu_twin() {
    let Some(ctx) = test_context() else { return };
    let doc = moving(270.0);
    let flare = prepared(&doc);
    let request = doc.frame_request_at(&flare.system, 6.0, 160, 100, 1);
    let built = Frame::build(&flare, None, &request);
    assert!(built.shutter.as_ref().is_some_and(|s| s.count > 1));
    let sources = Sources { flare: &flare, lut: None, plate: None };
    let cpu = frame::draw_cpu(&built, &sources);
    let mut device = Device::Gpu(Box::new(GpuDrawer::on(ctx)));
    let gpu = device.draw(&built, &sources).unwrap();
    let worst = cpu.display.worst_difference(&gpu.display);
    println!("blurred frame: {} samples, GPU vs CPU twin worst {worst}/255", built.shutter.as_ref().unwrap().count);
    assert!(worst <= 2, "worst display difference {worst}/255");
}

/// Issue 59's shot: a double Gauss whose light is keyed linearly from 2 to 10 degrees over frames 1 to 3 (4
/// degrees a frame), seen at frame 2 through a 180-degree shutter, 480x270, one wavelength, no starburst.
fn issue_59_shot(shutter_deg: f64) -> Document {
    let mut doc = Document::for_lens(flare_core::optics::library::builtin_lens("pbrt_dgauss_50mm").unwrap());
    doc.wavelengths = 1;
    doc.starburst = false;
    doc.exposure_auto = false;
    doc.timeline.interpolation = Interpolation::Linear;
    doc.timeline.light_deg.keys = vec![Key { frame: 1, value: [2.0, 0.0] }, Key { frame: 3, value: [10.0, 0.0] }];
    doc.timeline.shutter_deg = shutter_deg;
    doc
}

/// The time integral of the open shutter: the mean of `STILLS` still frames at the middles of equal slices of
/// it (frames 1.75 to 2.25), each ghost at `gains`.
fn integral(flare: &PreparedFlare, still: &Document, w: u32, h: u32, gains: &[f32]) -> HdrImage {
    const STILLS: usize = 256;
    let mut sum = vec![[0.0f64; 3]; (w * h) as usize];
    for i in 0..STILLS {
        let t = 1.75 + 0.5 * (i as f64 + 0.5) / STILLS as f64;
        let mut request = still.frame_request_at(&flare.system, t, w, h, 1);
        request.ghost_gains = gains.to_vec();
        let hdr = frame::draw_cpu_hdr(&Frame::build(flare, None, &request), &Sources { flare, lut: None, plate: None });
        for (s, p) in sum.iter_mut().zip(&hdr.pixels) {
            for k in 0..3 {
                s[k] += f64::from(p[k]);
            }
        }
    }
    let mut out = HdrImage::black(w, h);
    for (o, s) in out.pixels.iter_mut().zip(&sum) {
        for k in 0..3 {
            o[k] = (s[k] / STILLS as f64) as f32;
        }
    }
    out
}

/// Per column, the brightest pixel of any channel.
fn column_peaks(image: &HdrImage) -> Vec<f32> {
    (0..image.width)
        .map(|x| {
            (0..image.height)
                .map(|y| image.pixels[(y * image.width + x) as usize][..3].iter().copied().fold(0.0f32, f32::max))
                .fold(0.0f32, f32::max)
        })
        .collect()
}

#[test]
fn a_blurred_frame_is_the_time_integral_of_still_frames_and_never_breaks_a_streak() {
    let (w, h) = (480, 270);
    let (blur_doc, still_doc) = (issue_59_shot(180.0), issue_59_shot(0.0));
    let flare = prepared(&blur_doc);
    let ghosts = flare.system.ghosts.len();
    let ones = vec![1.0f32; ghosts];
    let blurred_request = blur_doc.frame_request_at(&flare.system, 2.0, w, h, 1);
    let blurred = Frame::build(&flare, None, &blurred_request);
    let samples = blurred.shutter.clone().expect("the light moves while the shutter is open");
    let sources = Sources { flare: &flare, lut: None, plate: None };
    let test = frame::draw_cpu_hdr(&blurred, &sources);
    let reference = integral(&flare, &still_doc, w, h, &ones);
    let exposure = flare_core::metrics::exposure_for(&reference);
    let psnr = flare_core::metrics::psnr(
        &flare_core::metrics::display_values(&test, exposure),
        &flare_core::metrics::display_values(&reference, exposure),
    );
    let ratio = energy(&test) / energy(&reference);
    println!(
        "issue 59's shot: {} samples ({:.1} a ghost, longest {:.1} px, largest gap {:.2} px): {psnr:.2} dB against 256 stills, energy {ratio:.5}",
        samples.count,
        samples.mean_per_ghost(),
        samples.longest_px,
        samples.max_gap_px
    );
    assert!(psnr >= 40.0, "{psnr} dB against the integral");
    assert!((ratio - 1.0).abs() <= 0.01, "energy ratio {ratio}");

    // The ghost focused near the sensor (the brightest drawn sprite, a point of light near the light's own
    // image): alone, its streak has no gap along it wider than a pixel where the integral's streak is lit.
    let focused = blurred
        .sprites
        .sprites
        .iter()
        .filter(|s| s.culled.is_none())
        .max_by(|a, b| a.irradiance.total_cmp(&b.irradiance))
        .expect("a ghost is drawn")
        .ghost;
    let alone: Vec<f32> = (0..ghosts).map(|g| if g == focused { 1.0 } else { 0.0 }).collect();
    let mut request = blurred_request.clone();
    request.ghost_gains = alone.clone();
    let streak = column_peaks(&frame::draw_cpu_hdr(&Frame::build(&flare, None, &request), &sources));
    let expected = column_peaks(&integral(&flare, &still_doc, w, h, &alone));
    let peak = expected.iter().copied().fold(0.0f32, f32::max);
    let (mut gap, mut widest, mut lit) = (0, 0, 0);
    for (s, e) in streak.iter().zip(&expected) {
        if *e > 0.05 * peak {
            lit += 1;
            gap = if *s < 0.25 * e { gap + 1 } else { 0 };
            widest = widest.max(gap);
        }
    }
    println!(
        "ghost {focused} (the brightest): {lit} lit columns, {} samples, widest gap {widest} px",
        samples.per_ghost[focused]
    );
    assert!(lit > 10, "the focused ghost streaks across {lit} columns");
    assert!(widest <= 1, "ghost {focused}'s streak has a gap of {widest} px");
}
