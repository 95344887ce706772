//! The look out of the box: the default document (the app's first frame and `flarelab render` with no flags)
//! reads as a lens flare, judged on the frame the one pipeline draws: a chain of distinct ghosts on the line
//! through the centre, and no wash.

use flare_core::flare::PreparedFlare;
use flare_core::frame::{Frame, Sources, draw_cpu};
use flare_core::preset::Document;
use flare_core::render::sensor_to_pixel;

/// The default frame at `width` x `height`: the frame and its display image.
fn default_frame(width: u32, height: u32) -> (Frame, flare_core::image::DisplayImage) {
    let mut doc = Document::default();
    let flare = PreparedFlare::new(&doc.lens, &doc.flare_config().unwrap()).unwrap();
    doc.resolve_exposure(&flare.system);
    let request = doc.frame_request(&flare.system, width, height, 1);
    let frame = Frame::build(&flare, None, &request);
    let display = draw_cpu(&frame, &Sources { flare: &flare, lut: None, plate: None }).display;
    (frame, display)
}

#[test]
fn the_default_frame_shows_at_least_five_distinct_ghosts_and_no_wash() {
    let (width, height) = (640u32, 360u32);
    let (frame, display) = default_frame(width, height);
    let gain = f64::from(frame.scene.globals.flare_gain);
    let sensor = flare_core::optics::sensor::Sensor::for_frame(36.0, width, height);
    // Each lens ghost: its brightest channel summed over the wavelengths (what shows), its centre and radius in
    // pixels (averaged over the wavelengths).
    let mut ghosts: std::collections::BTreeMap<usize, ([f64; 3], [f64; 2], f64, usize)> = Default::default();
    for s in frame.sprites.sprites.iter().filter(|s| s.culled.is_none()) {
        let e = ghosts.entry(s.ghost).or_insert(([0.0; 3], [0.0; 2], 0.0, 0));
        let c = sensor_to_pixel(s.centre_mm, &sensor, width, height);
        for k in 0..3 {
            e.0[k] += s.rgb[k];
        }
        e.1 = [e.1[0] + c[0], e.1[1] + c[1]];
        e.2 += s.half_size_mm[0].abs() * f64::from(width) / sensor.width_mm;
        e.3 += 1;
    }
    // Visible: at least 5 % of white at the frame's exposure; distinct: smaller than half the frame's height,
    // centred inside the frame, and not on top of a brighter visible ghost (centres 3 px or more apart, or
    // sizes 30 % apart).
    let mut visible: Vec<(f64, [f64; 2], f64)> = ghosts
        .values()
        .map(|(rgb, c, r, n)| {
            (rgb[0].max(rgb[1]).max(rgb[2]) * gain, [c[0] / *n as f64, c[1] / *n as f64], r / *n as f64)
        })
        .filter(|(level, c, r)| {
            *level >= 0.05
                && *r < 0.5 * f64::from(height)
                && (0.0..f64::from(width)).contains(&c[0])
                && (0.0..f64::from(height)).contains(&c[1])
        })
        .collect();
    visible.sort_by(|a, b| b.0.total_cmp(&a.0));
    let mut distinct: Vec<(f64, [f64; 2], f64)> = Vec::new();
    for g in visible {
        let apart = |d: &(f64, [f64; 2], f64)| {
            (g.1[0] - d.1[0]).hypot(g.1[1] - d.1[1]) >= 3.0 || (g.2 / d.2.max(1e-9) - 1.0).abs() > 0.3
        };
        if distinct.iter().all(apart) {
            distinct.push(g);
        }
    }
    // Washed out: a pixel brighter than mid grey, or clipped.
    let luma = |p: &[u8; 4]| 0.2126 * f64::from(p[0]) + 0.7152 * f64::from(p[1]) + 0.0722 * f64::from(p[2]);
    let n = display.pixels.len() as f64;
    let bright = display.pixels.iter().filter(|p| luma(p) >= 128.0).count() as f64 / n;
    let clipped = display.pixels.iter().filter(|p| p[..3].iter().any(|&v| v >= 250)).count() as f64 / n;
    eprintln!(
        "default frame: {} distinct visible ghosts, {:.1} % of pixels above mid grey, {:.2} % clipped",
        distinct.len(),
        100.0 * bright,
        100.0 * clipped
    );
    assert!(distinct.len() >= 5, "{} distinct ghosts: {distinct:?}", distinct.len());
    assert!(bright <= 0.25, "{:.1} % of the frame is washed out", 100.0 * bright);
    assert!(clipped <= 0.05, "{:.2} % clipped", 100.0 * clipped);
    // The ghosts lie on the line through the frame's centre and the light (a chain, not a scatter).
    let light = frame.scene.globals.starburst_centre_px;
    let (cx, cy) = (f64::from(width) / 2.0, f64::from(height) / 2.0);
    let axis = [f64::from(light[0]) - cx, f64::from(light[1]) - cy];
    for (_, c, _) in &distinct {
        let v = [c[0] - cx, c[1] - cy];
        let off_line = (v[0] * axis[1] - v[1] * axis[0]).abs() / axis[0].hypot(axis[1]);
        assert!(off_line < 0.02 * f64::from(width), "a ghost {off_line:.1} px off the line");
    }
}
