//! Shots on synthetic plate sequences (a sun disc on a sky gradient, moving, a bar crossing it): the light
//! found in the plate, the flare following its visibility without a strobe, a covered sun drawing nothing, and
//! a tracker's CSV giving the same flare as the light found in the plate.

use std::sync::atomic::AtomicBool;

use flare_core::flare::PreparedFlare;
use flare_core::footage::detect::{AutoLight, detect, triangular_filter};
use flare_core::footage::pattern::FramePattern;
use flare_core::frame::{Frame, Sources, draw_cpu};
use flare_core::preset::Document;
use flare_core::render::cpu;
use flare_core::shot::plan::{ShotPlan, plan};
use flare_core::shot::synthetic::SyntheticShot;
use flare_core::shot::track::{parse_track, to_keys};

/// Writes `shot` to a temporary folder and returns the folder and the document reading it with the light
/// found in the plate.
fn shot_document(shot: &SyntheticShot, track: bool) -> (tempfile::TempDir, Document) {
    let dir = tempfile::tempdir().unwrap();
    let pattern = format!("{}/sun.####.exr", dir.path().display());
    let track_path = dir.path().join("track.csv");
    shot.write(&FramePattern::parse(&pattern).unwrap().unwrap(), track.then_some(track_path.as_path())).unwrap();
    let doc = Document { background: Some(pattern), auto_light: Some(AutoLight::default()), ..Document::default() };
    (dir, doc)
}

fn plan_of(doc: &Document, flare: &PreparedFlare, shot: &SyntheticShot) -> ShotPlan {
    plan(doc, &flare.system, shot.frames.clone(), None, &|_, _| {}, &AtomicBool::new(false)).unwrap()
}

/// The flare layer's energy (sum of R + G + B) of every planned frame, drawn by the CPU twin; and whether
/// every value of every layer was finite.
fn flare_energies(doc: &Document, flare: &PreparedFlare, plan: &ShotPlan) -> (Vec<f64>, bool) {
    let mut finite = true;
    let energies = plan
        .frames
        .iter()
        .map(|p| {
            let request = plan.request(doc, &flare.system, p, 1);
            let frame = Frame::build(flare, None, &request);
            let plate = flare_core::output::read_plate(p.plate.as_deref().unwrap()).unwrap();
            let sources = Sources { flare, lut: None, plate: Some(&plate) };
            let drawn = draw_cpu(&frame, &sources);
            let layers = drawn.layers(&frame, &sources);
            finite &= layers.composite.pixels.iter().chain(&layers.flare.pixels).flatten().all(|v| v.is_finite());
            let flare_layer = cpu::flare_layer(&frame.scene, &drawn.hdr);
            flare_layer.pixels.iter().map(|q| f64::from(q[0]) + f64::from(q[1]) + f64::from(q[2])).sum()
        })
        .collect();
    (energies, finite)
}

#[test]
fn the_light_is_found_within_half_a_pixel_while_unoccluded() {
    let shot = SyntheticShot::small();
    let mut unoccluded = 0;
    for frame in shot.frames.clone() {
        let truth = shot.sun_px(frame);
        let scan = detect(&shot.plate(frame), AutoLight::default().threshold);
        let d = scan.detection.expect("the sun is found on every frame of this shot");
        if shot.visible_fraction(frame) == 1.0 {
            unoccluded += 1;
            let error = (d.centroid_px[0] - truth[0]).hypot(d.centroid_px[1] - truth[1]);
            assert!(error < 0.5, "frame {frame}: found {:?}, the disc's centre is {truth:?}", d.centroid_px);
        }
    }
    assert!(unoccluded >= 10, "{unoccluded} unoccluded frames");
}

#[test]
fn the_flare_follows_the_visible_fraction_frame_by_frame() {
    let shot = SyntheticShot::small();
    let (_dir, doc) = shot_document(&shot, false);
    let flare = PreparedFlare::new(&doc.lens, &doc.flare_config().unwrap()).unwrap();
    let plan = plan_of(&doc, &flare, &shot);
    // The visibility found is each frame's true visible fraction: the plate already integrates the shutter.
    let truth: Vec<f64> = shot.frames.clone().map(|f| shot.visible_fraction(f)).collect();
    for (p, t) in plan.frames.iter().zip(&truth) {
        assert!((p.visibility - t).abs() < 0.02, "frame {}: visibility {} vs {t}", p.frame, p.visibility);
    }
    assert!(truth.iter().any(|&v| v < 0.5), "the bar covers the sun: {truth:?}");
    // The flare's energy against the unoccluded flare's (the same frames at visibility 1): every frame on which
    // the sun is fully visible has the whole flare (within 2%), and the others the visible fraction.
    let (energies, finite) = flare_energies(&doc, &flare, &plan);
    assert!(finite);
    let unoccluded_plan = ShotPlan {
        frames: plan.frames.iter().map(|p| flare_core::shot::FramePlan { visibility: 1.0, ..p.clone() }).collect(),
        ..plan.clone()
    };
    let (full, _) = flare_energies(&doc, &flare, &unoccluded_plan);
    let (mut visible, mut partly) = (0, 0);
    for i in 0..energies.len() {
        assert!(full[i] > 0.0, "frame {i}: the unoccluded flare is drawn");
        let ratio = energies[i] / full[i];
        if truth[i] == 1.0 {
            visible += 1;
            assert!((ratio - 1.0).abs() < 0.02, "frame {i}: the sun is fully visible, the flare is {ratio} of it");
        } else {
            partly += 1;
            assert!(
                (ratio - truth[i]).abs() < 0.02,
                "frame {i}: {ratio} of the flare, {} of the sun visible",
                truth[i]
            );
        }
    }
    assert!(visible >= 5 && partly >= 3, "{visible} fully visible and {partly} covered frames");
}

#[test]
fn the_optional_denoise_fades_the_visibility_over_its_window() {
    let shot = SyntheticShot::small();
    let (_dir, mut doc) = shot_document(&shot, false);
    doc.auto_light.as_mut().unwrap().smooth_frames = 5;
    let flare = PreparedFlare::new(&doc.lens, &doc.flare_config().unwrap()).unwrap();
    let plan = plan_of(&doc, &flare, &shot);
    let truth: Vec<f64> = shot.frames.clone().map(|f| shot.visible_fraction(f)).collect();
    let expected = triangular_filter(&truth, 5);
    for (p, e) in plan.frames.iter().zip(&expected) {
        assert!((p.visibility - e).abs() < 0.02, "frame {}: visibility {} vs {e}", p.frame, p.visibility);
    }
    // The raw cut (the bar's edge) is a sharper change than the filtered fade.
    let jump = |v: &[f64]| v.windows(2).map(|w| (w[1] - w[0]).abs()).fold(0.0, f64::max);
    let smoothed: Vec<f64> = plan.frames.iter().map(|p| p.visibility).collect();
    assert!(jump(&smoothed) < jump(&truth), "filtered {} vs raw {}", jump(&smoothed), jump(&truth));
}

#[test]
fn a_fully_covered_sun_draws_no_flare_and_no_nan() {
    // A bar much wider than the sun and slow: the sun is fully covered for many frames in a row.
    let shot = SyntheticShot { occluder_width_px: 60.0, occluder_px: Some((100.0, 40.0)), ..SyntheticShot::small() };
    let truth: Vec<f64> = shot.frames.clone().map(|f| shot.visible_fraction(f)).collect();
    let covered: Vec<usize> =
        (2..truth.len() - 2).filter(|&i| truth[i - 2..=i + 2].iter().all(|&v| v == 0.0)).collect();
    assert!(covered.len() >= 3, "the shot covers the sun for long enough: {truth:?}");
    let (_dir, doc) = shot_document(&shot, false);
    let flare = PreparedFlare::new(&doc.lens, &doc.flare_config().unwrap()).unwrap();
    let plan = plan_of(&doc, &flare, &shot);
    let (energies, finite) = flare_energies(&doc, &flare, &plan);
    assert!(finite, "no NaN or infinity in any layer");
    for &i in &covered {
        assert_eq!(plan.frames[i].visibility, 0.0, "frame {}", plan.frames[i].frame);
        assert_eq!(energies[i], 0.0, "frame {}: a covered sun draws no flare", plan.frames[i].frame);
        // Its position continues from the track (between the last and next frames it was seen).
        assert!(plan.frames[i].light_deg.iter().all(|v| v.is_finite()));
    }
    assert!(energies.iter().any(|&e| e > 0.0));
}

#[test]
fn a_track_csv_and_the_light_found_in_the_plate_give_the_same_flare() {
    let shot = SyntheticShot { occluder_px: None, ..SyntheticShot::small() };
    let (dir, auto_doc) = shot_document(&shot, true);
    let flare = PreparedFlare::new(&auto_doc.lens, &auto_doc.flare_config().unwrap()).unwrap();
    let auto_plan = plan_of(&auto_doc, &flare, &shot);
    // The same shot with the tracker's CSV instead.
    let rows = parse_track(&std::fs::read_to_string(dir.path().join("track.csv")).unwrap()).unwrap();
    let sensor_mm = auto_plan.sensor.width_mm;
    let (position, _) = to_keys(&rows, &flare.system.mapping, sensor_mm, (shot.width, shot.height), 1.0).unwrap();
    let mut keyed_doc = Document { auto_light: None, ..auto_doc.clone() };
    keyed_doc.timeline.light_deg = position;
    let keyed_plan = plan_of(&keyed_doc, &flare, &shot);
    for (a, k) in auto_plan.frames.iter().zip(&keyed_plan.frames) {
        let d = (a.light_deg[0] - k.light_deg[0]).hypot(a.light_deg[1] - k.light_deg[1]);
        assert!(d < 0.01, "frame {}: {:?} vs {:?}", a.frame, a.light_deg, k.light_deg);
        assert!((a.visibility - 1.0).abs() < 0.01, "frame {}: unoccluded visibility {}", a.frame, a.visibility);
        let (ap, kp) = (a.light_px.unwrap(), k.light_px.unwrap());
        assert!((ap[0] - kp[0]).hypot(ap[1] - kp[1]) < 0.5);
    }
    let (auto_e, _) = flare_energies(&auto_doc, &flare, &auto_plan);
    let (keyed_e, _) = flare_energies(&keyed_doc, &flare, &keyed_plan);
    for (i, (a, k)) in auto_e.iter().zip(&keyed_e).enumerate() {
        assert!((a - k).abs() <= 0.01 * k, "frame {i}: flare energy {a} vs {k}");
    }
}

#[test]
fn keys_animate_the_light_its_intensity_and_a_ghost_gain_and_a_preset_carries_them() {
    let mut doc = Document::default();
    let flare = PreparedFlare::new(&doc.lens, &doc.flare_config().unwrap()).unwrap();
    let (i, j) = (flare.system.ghosts[3].i, flare.system.ghosts[3].j);
    let key = flare_core::preset::ghost_key(i, j);
    doc.timeline.interpolation = flare_core::timeline::Interpolation::Linear;
    doc.timeline.light_deg.set(1, [-10.0, 0.0]);
    doc.timeline.light_deg.set(11, [10.0, 4.0]);
    doc.timeline.light_ev.set(1, 0.0);
    doc.timeline.light_ev.set(11, -2.0);
    doc.timeline.ghost_gain.entry(key.clone()).or_default().set(1, 0.0);
    doc.timeline.ghost_gain.entry(key.clone()).or_default().set(11, 2.0);
    let r = doc.frame_request_at(&flare.system, 6.0, 320, 180, 1);
    assert_eq!(r.light_deg, [0.0, 2.0]);
    assert!((r.light_gain - 0.5).abs() < 1e-6, "-1 EV halfway: {}", r.light_gain);
    assert_eq!(r.ghost_gains[3], 1.0);
    assert!(r.ghost_gains.iter().enumerate().all(|(g, &v)| g == 3 || v == 1.0));
    // The ghost panel's off switch still wins over a key.
    doc.ghost_mut(i, j).enabled = false;
    assert_eq!(doc.frame_request_at(&flare.system, 6.0, 320, 180, 1).ghost_gains[3], 0.0);
    // A preset carries the timeline.
    let back = Document::from_json(&doc.to_json()).unwrap();
    assert_eq!(back, doc);
    // A bad key is refused with its field named.
    let mut bad = doc.clone();
    bad.timeline.light_ev.keys[1].frame = 1;
    let e = Document::from_json(&bad.to_json()).unwrap_err().to_string();
    assert!(e.contains("timeline.light_ev"), "{e}");
}

#[test]
fn a_light_leaving_the_frame_keeps_its_flare_and_its_track() {
    // The sun crosses the right edge at frame ~13 and is gone by frame ~15.
    let shot =
        SyntheticShot { start_px: [100.0, 40.0], end_px: [200.0, 46.0], occluder_px: None, ..SyntheticShot::small() };
    let (_dir, doc) = shot_document(&shot, false);
    let flare = PreparedFlare::new(&doc.lens, &doc.flare_config().unwrap()).unwrap();
    let plan = plan_of(&doc, &flare, &shot);
    let gone: Vec<usize> = (0..plan.frames.len()).filter(|&i| shot.sun_px(i as i64 + 1)[0] > 170.0).collect();
    assert!(gone.len() >= 4, "the sun leaves the frame");
    for &i in &gone {
        let p = &plan.frames[i];
        assert!(p.light_px.is_none(), "frame {}: off the plate", p.frame);
        assert!((p.visibility - 1.0).abs() < 0.01, "frame {}: out of view is not covered: {}", p.frame, p.visibility);
    }
    // The track continues at the speed it had: the angle keeps growing to the right, evenly.
    let x: Vec<f64> = plan.frames.iter().map(|p| p.light_deg[0]).collect();
    let steps: Vec<f64> = x.windows(2).map(|w| w[1] - w[0]).collect();
    assert!(steps.iter().all(|&d| d > 0.0), "{x:?}");
    let (first, last) = (steps[0], steps[steps.len() - 1]);
    assert!((last - first).abs() < 0.2 * first, "even steps: {steps:?}");
    let (energies, finite) = flare_energies(&doc, &flare, &plan);
    assert!(finite);
    assert!(gone.iter().all(|&i| energies[i] > 0.0), "its ghosts keep coming from off-screen");
}

#[test]
fn an_open_shutter_streaks_the_light_along_its_solved_track() {
    let shot = SyntheticShot::small();
    let (_dir, mut doc) = shot_document(&shot, false);
    doc.timeline.shutter_deg = 180.0;
    let flare = PreparedFlare::new(&doc.lens, &doc.flare_config().unwrap()).unwrap();
    let plan = plan_of(&doc, &flare, &shot);
    let n = plan.frames.len();
    for i in 1..n - 1 {
        let path = plan.frames[i].motion.as_ref().expect("the sun moves: the open shutter has a path");
        // Opening and closing a quarter of a frame either side, on the line through the neighbouring positions.
        let (before, here, after) =
            (plan.frames[i - 1].light_deg, plan.frames[i].light_deg, plan.frames[i + 1].light_deg);
        let open = path.points.first().unwrap().light_deg;
        let close = path.points.last().unwrap().light_deg;
        for c in 0..2 {
            assert!((open[c] - (here[c] + 0.25 * (before[c] - here[c]))).abs() < 1e-9, "frame {i}: {open:?}");
            assert!((close[c] - (here[c] + 0.25 * (after[c] - here[c]))).abs() < 1e-9, "frame {i}: {close:?}");
        }
        let mut request = doc.frame_request_at(&flare.system, plan.frames[i].frame as f64, plan.width, plan.height, 1);
        plan.frames[i].apply_to(&mut request);
        assert_eq!(request.motion.as_ref(), Some(path), "the request carries the track's path");
    }
    // The ends of the range continue at the speed of their last step.
    let last = plan.frames[n - 1].motion.as_ref().unwrap().points.last().unwrap().light_deg;
    let (a, b) = (plan.frames[n - 2].light_deg, plan.frames[n - 1].light_deg);
    assert!((last[0] - (b[0] + 0.25 * (b[0] - a[0]))).abs() < 1e-9);
    // A closed shutter: no path, the sharp frames.
    doc.timeline.shutter_deg = 0.0;
    assert!(plan_of(&doc, &flare, &shot).frames.iter().all(|f| f.motion.is_none()));
}
