//! Hostile files (issue 33): each class of the fuzzing campaign's findings reproduced, and a fuzzing harness
//! over every reader: generated and mutated inputs (proptest, stable Rust) for lens files in all five formats,
//! presets, tracks, glass catalogues, photo LUT sidecars, LUTs, plates, depth maps and aperture images. A reader may refuse an
//! input (one line, no panic) or accept it (then what it gives is finite and within its stated limits); it
//! never panics, never allocates past the header's checked size, and never hangs. The case count is
//! `PROPTEST_CASES` (64 a reader by default, bounded for CI); every case that ever failed is kept by proptest
//! in `tests/hostile.proptest-regressions` and replayed first on every run.

use std::path::{Path, PathBuf};

use flare_core::dof::depth::DepthMap;
use flare_core::optics::formats::{read_lens_bytes, read_lens_file};
use flare_core::optics::library::builtin_lens;
use flare_core::output::{MAX_IMAGE_SIDE_PX, MAX_PLATE_VALUE, read_plate, read_plate_checked};
use flare_core::preset::Document;
use flare_core::shot::track::parse_track;
use proptest::prelude::*;

mod common;

/// The CRC-32 of PNG chunks (ISO 3309).
fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = 0xffff_ffffu32;
    for &b in bytes {
        crc ^= u32::from(b);
        for _ in 0..8 {
            crc = if crc & 1 != 0 { (crc >> 1) ^ 0xedb8_8320 } else { crc >> 1 };
        }
    }
    !crc
}

/// A PNG of a few dozen bytes whose header claims `w` x `h` 8-bit grey pixels (its data would decompress to
/// that size): a decompression bomb's header.
fn png_claiming(w: u32, h: u32) -> Vec<u8> {
    let mut out = b"\x89PNG\r\n\x1a\n".to_vec();
    let mut chunk = |kind: &[u8], data: &[u8]| {
        out.extend_from_slice(&(data.len() as u32).to_be_bytes());
        let mut body = kind.to_vec();
        body.extend_from_slice(data);
        out.extend_from_slice(&body);
        out.extend_from_slice(&crc32(&body).to_be_bytes());
    };
    let mut ihdr = Vec::new();
    ihdr.extend_from_slice(&w.to_be_bytes());
    ihdr.extend_from_slice(&h.to_be_bytes());
    ihdr.extend_from_slice(&[8, 0, 0, 0, 0]);
    chunk(b"IHDR", &ihdr);
    chunk(b"IDAT", &[0x78, 0x9c, 0x03, 0x00, 0x00, 0x00, 0x00, 0x01]);
    chunk(b"IEND", &[]);
    out
}

/// A one-channel EXR (`Z`) of 1 x 1 pixel whose data window is then rewritten to claim `w` x `h`.
fn exr_claiming(dir: &Path, w: i32, h: i32) -> PathBuf {
    let path = dir.join("claims.exr");
    flare_core::output::write_exr_channel(&path, 1, 1, "Z", &[2.0]).unwrap();
    let mut bytes = std::fs::read(&path).unwrap();
    for name in [&b"dataWindow\0box2i\0"[..], &b"displayWindow\0box2i\0"[..]] {
        let at = bytes.windows(name.len()).position(|s| s == name).expect("the attribute") + name.len() + 4;
        bytes[at + 8..at + 12].copy_from_slice(&(w - 1).to_le_bytes());
        bytes[at + 12..at + 16].copy_from_slice(&(h - 1).to_le_bytes());
    }
    std::fs::write(&path, bytes).unwrap();
    path
}

/// A 16x16 EXR whose display window its header states as `side` x `side` pixels.
fn exr_in_window(dir: &Path, side: i32) -> PathBuf {
    let path = dir.join("window.exr");
    flare_core::output::write_exr_channel(&path, 16, 16, "R", &[0.5; 256]).unwrap();
    let mut bytes = std::fs::read(&path).unwrap();
    let name = &b"displayWindow\0box2i\0"[..];
    let at = bytes.windows(name.len()).position(|s| s == name).expect("the attribute") + name.len() + 4;
    bytes[at + 8..at + 12].copy_from_slice(&(side - 1).to_le_bytes());
    bytes[at + 12..at + 16].copy_from_slice(&(side - 1).to_le_bytes());
    std::fs::write(&path, bytes).unwrap();
    path
}

/// Memory blow-ups before any size check: a few-dozen-byte PNG claiming 9000-16000 pixels a side (as a plate,
/// an aperture image, a depth map) and a few-hundred-byte EXR claiming 100000 x 100000 (as a depth map and a
/// plate) are refused from their headers, naming the size and the limit, before any pixel is decoded.
#[test]
fn image_headers_past_the_frame_limit_are_refused_before_decoding() {
    let dir = tempfile::tempdir().unwrap();
    for (w, h) in [(9000, 9000), (16000, 16000), (8193, 10), (10, 100_000)] {
        let png = dir.path().join(format!("bomb_{w}x{h}.png"));
        std::fs::write(&png, png_claiming(w, h)).unwrap();
        let e = read_plate(&png).unwrap_err().to_string();
        assert!(e.contains(&format!("{w} x {h} pixels")) && e.contains(&MAX_IMAGE_SIDE_PX.to_string()), "{e}");
        assert!(e.contains("plate") && e.lines().count() == 1, "{e}");
        let e = flare_core::aperture::Aperture::image_shape_from_file(&png, 64).unwrap_err().to_string();
        assert!(e.contains("aperture image") && e.contains(&format!("{w} x {h}")), "{e}");
        let range = Some(flare_core::dof::depth::PngRange { near_m: 0.5, far_m: 100.0 });
        let e = DepthMap::read(&png, range).unwrap_err().to_string();
        assert!(e.contains("depth map") && e.contains(&format!("{w} x {h}")), "{e}");
        assert_eq!(e.matches(&png.display().to_string()).count(), 1, "the file named once: {e}");
    }
    let exr = exr_claiming(dir.path(), 100_000, 100_000);
    assert!(std::fs::metadata(&exr).unwrap().len() < 1000);
    let e = DepthMap::read(&exr, None).unwrap_err().to_string();
    assert!(e.contains("100000 x 100000") && e.contains("depth map"), "{e}");
    let e = read_plate(&exr).unwrap_err().to_string();
    assert!(e.contains("100000 x 100000"), "{e}");
    // At the limit itself a plate is fine.
    let edge = dir.path().join("edge.png");
    image::GrayImage::new(MAX_IMAGE_SIDE_PX, 2).save(&edge).unwrap();
    assert_eq!(read_plate(&edge).unwrap().width, MAX_IMAGE_SIDE_PX);
}

/// Reads that never stop: every text input given an endless device (`/dev/zero`) is refused before it is read
/// (it was read to its bound; now a device is refused as one), with a one-line error naming it.
#[cfg(unix)]
#[test]
fn endless_files_are_refused_before_they_are_read() {
    let zero = Path::new("/dev/zero");
    let e = Document::open(zero).unwrap_err().to_string();
    assert!(e.contains("not a regular file") && e.contains("/dev/zero"), "{e}");
    let e = flare_core::shot::track::read_track(zero).unwrap_err().to_string();
    assert!(e.contains("not a regular file"), "{e}");
    let e = flare_core::optics::formats::load_glass_catalogue(zero).unwrap_err();
    assert!(e.contains("not a regular file"), "{e}");
    let e = read_lens_file(zero).unwrap_err().to_string();
    assert!(e.contains("not a regular file"), "{e}");
}

/// `work` on a thread, its outcome within `seconds` (`None`: it was still running, a hang).
fn within<T: Send + 'static>(seconds: u64, work: impl FnOnce() -> T + Send + 'static) -> Option<T> {
    let (send, receive) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let _ = send.send(work());
    });
    receive.recv_timeout(std::time::Duration::from_secs(seconds)).ok()
}

/// Issue 61: FIFOs as inputs (a lens, a preset, `--cube`, `--ocio-config`, a plate, an existing frame under
/// `--skip-existing`) blocked forever in `open()`. Each is refused at once, naming the file.
#[cfg(unix)]
#[test]
fn fifos_as_inputs_are_refused_without_waiting() {
    let dir = tempfile::tempdir().unwrap();
    let fifo = |name: &str| {
        let path = dir.path().join(name);
        assert!(std::process::Command::new("mkfifo").arg(&path).status().unwrap().success());
        path
    };
    let (lens, preset, cube, config, plate, frame) =
        (fifo("a.json"), fifo("b.json"), fifo("c.cube"), fifo("d.ocio"), fifo("e.exr"), fifo("f.0001.png"));
    let outcome = within(20, move || {
        let mut said = vec![
            read_lens_file(&lens).unwrap_err().to_string(),
            Document::open(&preset).unwrap_err().to_string(),
            read_plate(&plate).unwrap_err().to_string(),
        ];
        for colour in [
            flare_core::view_transform::ColorDoc { cube: Some(cube.display().to_string()), ..Default::default() },
            flare_core::view_transform::ColorDoc { config: Some(config.display().to_string()), ..Default::default() },
        ] {
            said.push(flare_core::view_transform::ViewTransform::new(&colour).unwrap_err().to_string());
        }
        assert!(!flare_core::shot::sequence::reads_back_whole(&frame), "a FIFO is no frame to skip");
        said
    });
    let said = outcome.expect("every FIFO refused within 20 s (it blocked in open() before)");
    for e in said {
        assert!(e.contains("not a regular file") && e.lines().count() == 1, "{e}");
    }
}

/// Issue 61: a 3.6 KB EXR of 16x16 pixels in an 8192x8192 display window passed the header check (which read
/// the data window) and aborted at 5.4 GB; a 65 KB black 8192x8192 PNG plate, `--size 8192x8192` and
/// `--desqueeze 4` the same. Each frame's memory is now known from its sizes before any work, and refused
/// with the figure.
#[test]
fn frames_that_need_more_memory_than_allowed_are_refused_before_work() {
    let dir = tempfile::tempdir().unwrap();
    let path = exr_in_window(dir.path(), 8192);
    assert!(std::fs::metadata(&path).unwrap().len() < 4096);
    let doc = Document { background: Some(path.display().to_string()), ..Document::default() };
    let e = flare_core::shot::plan::frame_size(&doc, &(1..=1), None).unwrap_err().to_string();
    assert!(e.contains("8192x8192") && e.contains("GB"), "{e}");
    let png = dir.path().join("black.png");
    image::GrayImage::new(8192, 8192).save(&png).unwrap();
    let doc = Document { background: Some(png.display().to_string()), ..Document::default() };
    let e = flare_core::shot::plan::frame_size(&doc, &(1..=1), None).unwrap_err().to_string();
    assert!(e.contains("8192x8192") && e.contains("GB"), "{e}");
    let plain = Document::default();
    let e = flare_core::shot::plan::frame_size(&plain, &(1..=1), Some((8192, 8192))).unwrap_err().to_string();
    assert!(e.contains("needs about 8.9 GB"), "{e}");
    let squeezed = Document { desqueeze: 4.0, ..Document::default() };
    let e = flare_core::shot::plan::frame_size(&squeezed, &(1..=1), Some((8192, 4320))).unwrap_err().to_string();
    assert!(e.contains("drawn at 8192x17280"), "{e}");
    // What fits is accepted: the default still, and a 4K frame desqueezed by 2.
    flare_core::shot::plan::frame_size(&plain, &(1..=1), Some((1920, 1080))).unwrap();
    let two = Document { desqueeze: 2.0, ..Document::default() };
    flare_core::shot::plan::frame_size(&two, &(1..=1), Some((4096, 2160))).unwrap();
}

/// Wrong output: a plate whose values overflow when exposed (3e38 at +1 EV) and a +Inf sun pixel are clamped
/// to the largest kept value with one warning, so the composite stays finite and keeps the flare; the EXR
/// writer keeps an overflow as the brightest float, not black.
#[test]
fn overflowing_and_infinite_plates_keep_the_flare_in_the_composite() {
    use exr::prelude::{
        AnyChannel, AnyChannels, Encoding, FlatSamples, Image, Layer, LayerAttributes, SmallVec, WritableImage,
    };
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("sun.exr");
    let values = [3e38f32, f32::INFINITY, 0.5, f32::NAN];
    let channel = |name: &str| AnyChannel::new(name, FlatSamples::F32(values.to_vec()));
    let layer = Layer::new(
        (2, 2),
        LayerAttributes::default(),
        Encoding::UNCOMPRESSED,
        AnyChannels::sort(SmallVec::from_vec(vec![channel("R"), channel("G"), channel("B")])),
    );
    Image::from_layer(layer).write().to_file(&path).unwrap();
    let (plate, warning) = read_plate_checked(&path).unwrap();
    let warning = warning.expect("the clamp is said");
    assert!(warning.contains("6 plate values") && warning.contains("clamped"), "{warning}");
    let red: Vec<f32> = plate.pixels.iter().map(|p| p[0]).collect();
    assert_eq!(red, [MAX_PLATE_VALUE, MAX_PLATE_VALUE, 0.5, 0.0]);
    // Exposed by +64 EV, the largest exposure a preset allows, it stays finite; the flare adds on top.
    let exposed = plate.resampled(2, 2, flare_core::image::Sampling::Nearest, 2f32.powi(64));
    assert!(exposed.pixels.iter().flatten().all(|v| v.is_finite()));
    let flare = flare_core::image::HdrImage { width: 2, height: 2, pixels: vec![[1.0, 2.0, 3.0, 1.0]; 4] };
    let composite = flare.plus(&plate);
    assert!(composite.pixels.iter().flatten().all(|v| v.is_finite()));
    assert_eq!(composite.pixels[2][1], 2.5, "the flare is in the composite");
    // The writer: an infinite value is written as the largest float (bright), never 0.
    let out = dir.path().join("out.exr");
    let hot = flare_core::image::HdrImage { width: 1, height: 1, pixels: vec![[f32::INFINITY, 1.0, 0.0, 1.0]] };
    flare_core::output::write_linear(&out, &hot).unwrap();
    assert_eq!(read_plate(&out).unwrap().pixels[0][0], MAX_PLATE_VALUE, "bright, then clamped on reading");
}

/// Hangs: a 400,000-row track parses in one pass (a repeated frame is found through a map, not by scanning
/// every row before it), and an OpenLensFlare file of 1.7 MB counts its lines once.
#[test]
fn large_tracks_and_xml_files_are_read_in_one_pass() {
    let mut text = String::from("frame,x_px,y_px\n");
    for f in 0..400_000 {
        text.push_str(&format!("{f},{}.5,{}\n", f % 1920, f % 1080));
    }
    let rows = parse_track(&text).unwrap();
    assert_eq!(rows.len(), 400_000);
    text.push_str("17,1,1\n");
    let e = parse_track(&text).unwrap_err().to_string();
    assert!(e.contains("frame 17 was already given on line 19"), "{e}");
    // A track spanning more frames than a timeline holds is refused (its frames become the timeline's).
    let e = parse_track("frame,x,y\n1,1,1\n9000000000000,2,2\n").unwrap_err().to_string();
    assert!(e.contains("line 3") && e.contains("more than 1000000 frames"), "{e}");
    // 1.7 MB of OpenLensFlare: tags the reader skips, each an event that asks for its line.
    let padding = "<comment>x</comment>\n".repeat(85_000);
    let xml = format!(
        "<?xml version=\"1.0\"?>\n<opticalSystem>\n<name>padded</name>\n{padding}<elements>\n<element><type>sensor</type><height>1</height></element>\n</elements>\n</opticalSystem>\n"
    );
    assert!(xml.len() > 1_700_000);
    let e = read_lens_bytes(xml.as_bytes(), Path::new("padded.xml")).unwrap_err().to_string();
    assert!(!e.is_empty() && e.lines().count() == 1, "{e}");
}

/// Garbage accepted silently: an all-black aperture image is refused (it drew nothing without a word).
#[test]
fn a_black_aperture_image_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let black = dir.path().join("black.png");
    image::GrayImage::new(64, 64).save(&black).unwrap();
    let e = flare_core::aperture::Aperture::image_shape_from_file(&black, 64).unwrap_err().to_string();
    assert!(e.contains("black everywhere"), "{e}");
}

/// Messages: a 100,000-character token is quoted cut to a few dozen characters, control characters escaped.
#[test]
fn offending_tokens_are_shortened_and_escaped() {
    let long = format!("{}\u{1b}[2J", "9".repeat(100_000));
    let e = parse_track(&format!("frame,x,y\n1,{long},3\n")).unwrap_err().to_string();
    assert!(e.len() < 200 && e.contains("(100004 characters)") && !e.contains('\u{1b}'), "{e}");
    let doc = Document::default().to_json().replacen("\"flare_ev\"", &format!("\"{long}\": 1,\n\"flare_ev\""), 1);
    let e = Document::from_json(&doc).unwrap_err().to_string();
    assert!(e.len() < 300 && !e.contains('\u{1b}'), "{e}");
}

// The fuzzing harness.

/// Valid files of every lens format, from the shipped lenses: what the mutations start from.
fn lens_sources() -> Vec<(&'static str, Vec<u8>)> {
    static SOURCES: std::sync::OnceLock<Vec<(&'static str, Vec<u8>)>> = std::sync::OnceLock::new();
    SOURCES
        .get_or_init(|| {
            let lens = builtin_lens("pbrt_dgauss_50mm").unwrap();
            let aspheric = builtin_lens("aspheric_zoom_us5793533").unwrap();
            let toroidal = common::toroidal_test_lens();
            use flare_core::optics::formats::{flaresim, pbrt, zmx};
            vec![
                ("toroidal.json", flare_core::optics::formats::to_json(&toroidal).into_bytes()),
                ("toroidal.zmx", zmx::write(&toroidal).unwrap().into_bytes()),
                ("lens.json", flare_core::optics::formats::to_json(&aspheric).into_bytes()),
                ("lens.zmx", zmx::write(&aspheric).unwrap().into_bytes()),
                ("lens.dat", pbrt::write(&lens).unwrap().into_bytes()),
                ("lens.lens", flaresim::write(&lens).unwrap().into_bytes()),
                ("lens.xml", OLF_SAMPLE.as_bytes().to_vec()),
            ]
        })
        .clone()
}

const OLF_SAMPLE: &str = "<?xml version=\"1.0\"?>\n<opticalSystem>\n<name>t</name>\n<elements>\n\
<element><type>lensSpherical</type><height>12</height><thickness>4</thickness><radius>30</radius><refractiveIndex>1.62</refractiveIndex><abbeNumber>60</abbeNumber></element>\n\
<element><type>lensSpherical</type><height>12</height><thickness>5</thickness><radius>-200</radius></element>\n\
<element><type>apertureStop</type><height>8</height><thickness>4</thickness></element>\n\
<element><type>lensSpherical</type><height>9</height><thickness>40</thickness><radius>-60</radius><refractiveIndex>1.62</refractiveIndex><abbeNumber>36</abbeNumber></element>\n\
<element><type>sensor</type><height>43</height></element>\n</elements>\n</opticalSystem>\n";

/// `bytes` with `flips` applied (xor at positions modulo the length), `cut` bytes cut from the end, and
/// `insert` spliced in at `at`.
fn mutate(mut bytes: Vec<u8>, flips: &[(usize, u8)], cut: usize, at: usize, insert: &[u8]) -> Vec<u8> {
    for &(k, v) in flips {
        let n = bytes.len().max(1);
        if let Some(b) = bytes.get_mut(k % n) {
            *b ^= v;
        }
    }
    let keep = bytes.len().saturating_sub(cut % (bytes.len() + 1));
    bytes.truncate(keep);
    let at = at % (bytes.len() + 1);
    bytes.splice(at..at, insert.iter().copied());
    bytes
}

/// Tokens a hostile file likes: huge, negative, non-finite and repeated numbers, and keywords out of place.
fn nasty_token() -> impl Strategy<Value = Vec<u8>> {
    prop_oneof![
        Just(b"1e308".to_vec()),
        Just(b"-1e308".to_vec()),
        Just(b"NaN".to_vec()),
        Just(b"inf".to_vec()),
        Just(b"-0".to_vec()),
        Just(b"99999999999999999999".to_vec()),
        Just(b"\nCURV 5\nCURV 7\n".to_vec()),
        Just(b"\nSURF 0\n".to_vec()),
        Just(b"<element>".to_vec()),
        Just(b"\"surfaces\": [],".to_vec()),
        Just(vec![0xff, 0xfe, 0]),
        proptest::collection::vec(any::<u8>(), 0..16),
    ]
}

/// A value a reader gave back is finite, so nothing it accepted can put NaN into a frame.
fn lens_is_finite(lens: &flare_core::optics::Lens) -> bool {
    lens.surfaces.iter().all(|s| {
        s.radius_mm.is_finite()
            && s.semi_aperture_mm.is_finite()
            && s.thickness_mm.is_none_or(f64::is_finite)
            && s.radius_x_mm.is_none_or(f64::is_finite)
            && s.medium.n_d.is_finite()
    })
}

/// A 3^3 `.cube` (identity but for a warmer red).
fn small_cube() -> String {
    let mut text = String::from("TITLE \"t\"\nLUT_3D_SIZE 3\n");
    for b in 0..3 {
        for g in 0..3 {
            for r in 0..3 {
                text += &format!("{} {} {}\n", (r as f32 * 0.55).min(1.0), g as f32 * 0.5, b as f32 * 0.5);
            }
        }
    }
    text
}

/// The smallest OCIO config with FlareLab's working space, one display and one view.
const MINIMAL_CONFIG: &str = r#"ocio_profile_version: 2
roles:
  default: Linear Rec.709 (sRGB)
  scene_linear: Linear Rec.709 (sRGB)
displays:
  sRGB:
    - !<View> {name: Raw, colorspace: Linear Rec.709 (sRGB)}
colorspaces:
  - !<ColorSpace>
    name: Linear Rec.709 (sRGB)
    encoding: scene-linear
"#;

proptest! {
    #![proptest_config(ProptestConfig { cases: common::cases_or(64), ..ProptestConfig::default() })]

    /// Every lens format: a mutated file is refused in one line or read into a valid, finite lens.
    #[test]
    fn fuzz_lens_files(
        which in 0usize..7,
        flips in proptest::collection::vec((any::<usize>(), any::<u8>()), 0..6),
        cut in any::<usize>(),
        at in any::<usize>(),
        insert in nasty_token(),
    ) {
        let (name, source) = lens_sources()[which].clone();
        let bytes = mutate(source, &flips, cut % 64, at, &insert);
        match read_lens_bytes(&bytes, Path::new(name)) {
            Ok(loaded) => {
                prop_assert!(loaded.lens.validate().is_ok());
                prop_assert!(lens_is_finite(&loaded.lens));
            }
            Err(e) => {
                let message = e.to_string();
                prop_assert!(!message.is_empty() && message.len() < 2000, "{}", message);
            }
        }
    }

    /// Presets: mutated JSON is refused naming the field, or reads back into a document that checks.
    #[test]
    fn fuzz_presets(
        flips in proptest::collection::vec((any::<usize>(), any::<u8>()), 0..4),
        at in any::<usize>(),
        insert in nasty_token(),
    ) {
        let source = Document::default().to_json().into_bytes();
        let bytes = mutate(source, &flips, 0, at, &insert);
        let Ok(text) = String::from_utf8(bytes) else { return Ok(()) };
        if let Ok(doc) = Document::from_json(&text) {
            prop_assert!(doc.check().is_ok());
            prop_assert!(Document::from_json(&doc.to_json()).is_ok(), "what is read is written back readably");
        }
    }

    /// Tracks: any text is refused naming its line, or parsed into finite rows with distinct frames.
    #[test]
    fn fuzz_tracks(lines in proptest::collection::vec(
        (any::<i64>(), prop_oneof![any::<f64>().prop_map(|v| v.to_string()), Just("nan".to_owned()), Just("".to_owned())],
         any::<f64>(), proptest::option::of(any::<f64>())), 0..20)
    ) {
        let mut text = String::from("frame,x_px,y_px\n");
        for (f, x, y, ev) in &lines {
            text.push_str(&format!("{f},{x},{y}"));
            if let Some(ev) = ev {
                text.push_str(&format!(",{ev}"));
            }
            text.push('\n');
        }
        if let Ok(rows) = parse_track(&text) {
            prop_assert!(rows.iter().all(|r| r.x_px.is_finite() && r.y_px.is_finite()));
            prop_assert!(rows.windows(2).all(|w| w[0].frame < w[1].frame));
        }
    }

    /// Glass catalogues: a mutated AGF is refused or gives finite glasses.
    #[test]
    fn fuzz_glass_catalogues(
        flips in proptest::collection::vec((any::<usize>(), any::<u8>()), 0..6),
        cut in any::<usize>(),
        at in any::<usize>(),
        insert in nasty_token(),
    ) {
        let source = include_bytes!("../../../assets/glass/flarelab-hoya.agf").to_vec();
        let bytes = mutate(source, &flips, cut % 4096, at, &insert);
        let Ok(text) = flare_core::optics::formats::decode_text(&bytes) else { return Ok(()) };
        if let Ok(glasses) = flare_core::optics::agf::parse_agf(&text, "FUZZ") {
            prop_assert!(glasses.iter().all(|g| g.n_d.is_finite() && g.v_d.is_finite()));
        }
    }

    /// Photo LUT folders: a mutated sidecar (`flare.json`) over two real photos is refused or makes a LUT of
    /// at most as many entries as photos, never a panic.
    #[test]
    fn fuzz_photo_lut_sidecars(
        flips in proptest::collection::vec((any::<usize>(), any::<u8>()), 0..4),
        at in any::<usize>(),
        insert in nasty_token(),
    ) {
        let dir = tempfile::tempdir().unwrap();
        for name in ["a.png", "b.png"] {
            image::RgbImage::from_pixel(8, 8, image::Rgb([200, 100, 50])).save(dir.path().join(name)).unwrap();
        }
        let sidecar = br#"{"azimuth_deg": 0, "images": [{"file": "a.png", "theta_deg": 0}, {"file": "b.png", "theta_deg": 10}]}"#;
        let bytes = mutate(sidecar.to_vec(), &flips, 0, at, &insert);
        std::fs::write(dir.path().join("flare.json"), &bytes).unwrap();
        if let Ok(lut) = flare_core::lut::photo::import_folder(dir.path()) {
            prop_assert!(lut.ghosts.iter().map(|g| g.entries.len()).sum::<usize>() <= 2);
        }
    }

    /// Colour files: a mutated `.cube` or OCIO config is refused (naming `cube` or `config`) or makes a view whose
    /// display values are finite, never a panic.
    #[test]
    fn fuzz_colour_files(
        config in any::<bool>(),
        flips in proptest::collection::vec((any::<usize>(), any::<u8>()), 0..6),
        cut in any::<usize>(),
        at in any::<usize>(),
        insert in nasty_token(),
    ) {
        use flare_core::view_transform::{ColorDoc, ViewTransform};
        let dir = tempfile::tempdir().unwrap();
        let (name, source) = if config { ("c.ocio", MINIMAL_CONFIG.to_owned()) } else { ("l.cube", small_cube()) };
        let bytes = mutate(source.into_bytes(), &flips, cut % 64, at, &insert);
        let path = dir.path().join(name);
        std::fs::write(&path, &bytes).unwrap();
        let file = Some(path.display().to_string());
        let doc = if config { ColorDoc { config: file, ..Default::default() } } else { ColorDoc { cube: file, ..Default::default() } };
        match ViewTransform::new(&doc) {
            Ok(view) => {
                for c in [[0.0, 0.0, 0.0], [0.18, 0.5, 2.0], [1e4, 1e-4, 1.0]] {
                    prop_assert!(view.apply(c).iter().all(|v| v.is_finite()));
                }
            }
            Err(e) => prop_assert!(e.field == "cube" || e.field == "config" || e.field == "display" || e.field == "view", "{e}"),
        }
    }

    /// Images (plates, depth maps, aperture images): a mutated PNG or EXR, or a PNG claiming any size, is
    /// refused or decoded within the limit, never a panic or an allocation past the header's size.
    #[test]
    fn fuzz_images(
        exr in any::<bool>(),
        flips in proptest::collection::vec((any::<usize>(), any::<u8>()), 0..6),
        cut in any::<usize>(),
        claim in (0u32..70_000, 0u32..70_000),
    ) {
        let dir = tempfile::tempdir().unwrap();
        let source = dir.path().join(if exr { "s.exr" } else { "s.png" });
        if exr && claim.0 % 2 == 0 {
            // A frame's EXR with a ghost layer in a part of its own (a data window smaller than the frame).
            let image = |v: f32| flare_core::image::HdrImage { width: 8, height: 4, pixels: vec![[v, v, v, 1.0]; 32] };
            let mut ghost = flare_core::image::HdrImage::black(8, 4);
            ghost.pixels[9] = [2.0, 1.0, 0.5, 1.0];
            let layers = flare_core::output::FrameLayers {
                composite: image(0.5),
                flare: image(0.25),
                starburst: image(0.0),
                dirt: None,
                plate: None,
                ghosts: vec![("ghost_1_2".into(), ghost)],
            };
            flare_core::output::write_exr_layers(&source, &layers, Default::default()).unwrap();
        } else if exr {
            flare_core::output::write_exr_channel(&source, 8, 4, "Z", &[1.5; 32]).unwrap();
        } else if claim.0 % 3 == 0 {
            std::fs::write(&source, png_claiming(claim.0, claim.1)).unwrap();
        } else {
            image::RgbImage::from_pixel(8, 4, image::Rgb([200, 10, 30])).save(&source).unwrap();
        }
        let bytes = mutate(std::fs::read(&source).unwrap(), &flips, cut % 64, 0, &[]);
        std::fs::write(&source, &bytes).unwrap();
        if let Ok(plate) = read_plate(&source) {
            prop_assert!(plate.width <= MAX_IMAGE_SIDE_PX && plate.height <= MAX_IMAGE_SIDE_PX);
            prop_assert!(plate.pixels.iter().flatten().all(|v| v.is_finite() && *v >= 0.0));
        }
        let range = Some(flare_core::dof::depth::PngRange { near_m: 0.5, far_m: 100.0 });
        if let Ok(map) = DepthMap::read(&source, range) {
            prop_assert!(map.width <= MAX_IMAGE_SIDE_PX && map.height <= MAX_IMAGE_SIDE_PX);
        }
        let _ = flare_core::aperture::Aperture::image_shape_from_file(&source, 32);
        if let Ok(flare_core::dirt::DirtPattern::Image { size, luminance }) =
            flare_core::dirt::DirtPattern::image_from_file(&source)
        {
            prop_assert_eq!(luminance.len(), size * size);
            prop_assert!(luminance.iter().all(|v| (0.0..=1.0).contains(v)));
        }
        if let Ok(read) = flare_core::output::read_exr_channels(&source) {
            prop_assert!(read.width <= MAX_IMAGE_SIDE_PX && read.height <= MAX_IMAGE_SIDE_PX);
            let size = read.width as usize * read.height as usize;
            prop_assert!(read.channels.values().all(|c| c.len() == size));
        }
    }
}

/// JPEG plates, listed in the help, are read (they were refused), decoded from sRGB like PNG.
#[test]
fn a_jpeg_plate_is_read_like_a_png() {
    let dir = tempfile::tempdir().unwrap();
    let (jpg, png) = (dir.path().join("p.jpg"), dir.path().join("p.png"));
    let image = image::RgbImage::from_pixel(16, 8, image::Rgb([128, 128, 128]));
    image.save(&jpg).unwrap();
    image.save(&png).unwrap();
    let (a, b) = (read_plate(&jpg).unwrap(), read_plate(&png).unwrap());
    assert_eq!((a.width, a.height), (16, 8));
    assert!((a.pixels[0][1] - b.pixels[0][1]).abs() < 0.01, "{:?} against {:?}", a.pixels[0], b.pixels[0]);
}

/// `--layers ghosts` needed more than 6 GB at 1920x1080: ghost layers are now 16-bit channels made as each
/// ghost is drawn, and what would pass the stated budget is refused before drawing, naming the memory.
#[test]
fn ghost_layers_past_the_memory_budget_are_refused_naming_the_memory() {
    use flare_core::frame::check_ghost_layers;
    assert!(
        check_ghost_layers(254, 1920, 1080, flare_core::output::ExrPixel::Auto).is_ok(),
        "the default zoom's layers at 1080p fit"
    );
    let e = check_ghost_layers(254, 3840, 2160, flare_core::output::ExrPixel::Auto).unwrap_err().to_string();
    assert!(e.contains("254 ghost layers at 3840x2160 need about 12.6 GB") && e.contains("--size"), "{e}");
}

/// The sources the colour fuzzing mutates are valid as they are (the fuzzing starts from files that load).
#[test]
fn the_colour_fuzzings_sources_load() {
    use flare_core::view_transform::{ColorDoc, ViewTransform};
    let dir = tempfile::tempdir().unwrap();
    let (config, cube) = (dir.path().join("c.ocio"), dir.path().join("l.cube"));
    std::fs::write(&config, MINIMAL_CONFIG).unwrap();
    std::fs::write(&cube, small_cube()).unwrap();
    let view =
        ViewTransform::new(&ColorDoc { config: Some(config.display().to_string()), ..Default::default() }).unwrap();
    assert_eq!((view.display.as_str(), view.view.as_str()), ("sRGB", "Raw"));
    assert_eq!(view.apply([0.25, 0.5, 2.0]), [0.25, 0.5, 2.0], "Raw is the identity");
    ViewTransform::new(&ColorDoc { cube: Some(cube.display().to_string()), ..Default::default() }).unwrap();
}

/// Issue 61's untrue or flooding words: a 302-digit `semi_aperture` echoed whole, "PARM value value", a plain
/// cylinder refused by the `.dat` and `.lens` writers as "aspheric or conic".
#[test]
fn messages_name_the_real_reason_in_a_line() {
    let lens = builtin_lens("heliar").unwrap();
    let mut text = flare_core::optics::formats::json::write(&lens);
    text = text.replacen("\"semi_aperture\": 14.5", &format!("\"semi_aperture\": 1{}", "0".repeat(302)), 1);
    assert!(text.contains(&"0".repeat(302)), "the value went in");
    let e = read_lens_bytes(text.as_bytes(), Path::new("big.json")).unwrap_err().to_string();
    assert!(e.contains("1.000e302") && e.len() < 200, "{e}");
    let zmx = "VERS 1\nUNIT MM X W X CM MR CPMM\nSURF 0\n  TYPE EVENASPH\n  PARM 2 abc\n";
    let e = read_lens_bytes(zmx.as_bytes(), Path::new("a.zmx")).unwrap_err().to_string();
    assert!(e.contains("PARM 2 value `abc`") && !e.contains("value value"), "{e}");
    let anamorphic = builtin_lens("panavision_anamorphic_us20060050403").unwrap();
    for e in [
        flare_core::optics::formats::pbrt::write(&anamorphic).unwrap_err().to_string(),
        flare_core::optics::formats::flaresim::write(&anamorphic).unwrap_err().to_string(),
    ] {
        assert!(e.contains("is cylindrical") && !e.contains("aspheric or conic"), "{e}");
    }
}

/// Issue 61: an aperture image of white pixels beside NaN and infinite ones was refused as "black
/// everywhere" (the resampling spread the NaN over the image); now each pixel is brought into [0, 1] first.
#[test]
fn an_aperture_with_nan_and_infinite_pixels_keeps_its_white() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("aperture.exr");
    // A checkerboard: every white pixel beside a NaN or an infinity.
    let (w, h) = (4usize, 4usize);
    let mut image = flare_core::image::HdrImage::black(w as u32, h as u32);
    for (k, p) in image.pixels.iter_mut().enumerate() {
        *p = match ((k % w) + k / w) % 2 {
            0 => [1.0; 4],
            _ if k % 3 == 0 => [f32::INFINITY; 4],
            _ => [f32::NAN; 4],
        };
    }
    // Written raw (the writer would clamp): an EXR of floats as a hostile file holds them.
    let channel = |c: usize| image.pixels.iter().map(|p| p[c]).collect::<Vec<f32>>();
    let layer = exr::prelude::Layer::new(
        (w, h),
        exr::prelude::LayerAttributes::default(),
        exr::prelude::Encoding::UNCOMPRESSED,
        exr::prelude::AnyChannels::sort(exr::prelude::SmallVec::from_vec(
            ["B", "G", "R"]
                .iter()
                .zip([2, 1, 0])
                .map(|(name, c)| exr::prelude::AnyChannel::new(*name, exr::prelude::FlatSamples::F32(channel(c))))
                .collect(),
        )),
    );
    use exr::prelude::WritableImage;
    exr::prelude::Image::from_layer(layer).write().to_file(&path).unwrap();
    let shape = flare_core::aperture::Aperture::image_shape_from_file(&path, 16).unwrap();
    let flare_core::aperture::ApertureShape::Image { luminance, .. } = shape else { panic!("an image shape") };
    assert!(luminance.iter().all(|v| v.is_finite() && (0.0..=1.0).contains(v)));
    let mean = luminance.iter().sum::<f32>() / luminance.len() as f32;
    assert!(mean > 0.25, "the white (and the infinities, as white) stay: mean {mean}");
}

/// Issue 61: an EXR whose display window the `exr` crate refuses was named without its size; the message now
/// says the windows the header states.
#[test]
fn a_refused_exr_window_is_named_with_its_size() {
    let dir = tempfile::tempdir().unwrap();
    let path = exr_in_window(dir.path(), i32::MAX);
    let e = read_plate(&path).unwrap_err().to_string();
    assert!(e.contains("display window 2147483647 x 2147483647 pixels") && e.lines().count() == 1, "{e}");
}

/// Issue 61: 200 photos of 2046x2046 aborted `photo-lut` at 5.7 GB (every photo's texels kept at once), and 70
/// made a `.flut` that `--lut` refused as corrupt. The texels are now summed from the headers before any photo
/// is decoded, against the bound the reader keeps; a LUT the reader would refuse is not written.
#[test]
fn photo_luts_past_what_a_lut_holds_are_refused_before_decoding() {
    let dir = tempfile::tempdir().unwrap();
    for k in 0..70 {
        std::fs::write(dir.path().join(format!("flare_{k}deg.png")), png_claiming(2046, 2046)).unwrap();
    }
    let e = flare_core::lut::photo::import_folder(dir.path()).unwrap_err().to_string();
    assert!(e.contains("70 photos make 293028120 texels") && e.contains("268435456"), "{e}");
}

proptest! {
    #![proptest_config(ProptestConfig { cases: common::cases_or(64), ..ProptestConfig::default() })]

    /// Issue 61's new readers under the fuzz harness: a frame pattern is refused or names files of bounded
    /// length for every frame (a `%070000d` once panicked in the formatter).
    #[test]
    fn frame_patterns_are_refused_or_name_short_files(
        text in "[a-z/._]{0,8}(#{0,30}|%0?[0-9]{0,7}d)[a-z._#%0-9d]{0,8}",
        frame in any::<i64>(),
    ) {
        if let Ok(Some(pattern)) = flare_core::footage::pattern::FramePattern::parse(&text) {
            let path = pattern.path(frame);
            prop_assert!(path.as_os_str().len() <= text.len() + 21 + 8, "{}", path.display());
        }
    }

    /// Keyed timelines: any keys are refused naming the field, or sample to finite values everywhere.
    #[test]
    fn keyed_timelines_are_refused_or_sample_finitely(
        keys in proptest::collection::vec((any::<i64>(), -100.0f64..100.0, prop_oneof![Just(1.0f64), Just(1e39), Just(-1.0), Just(f64::NAN), 0.0f64..1e6]), 0..6),
        at in prop_oneof![any::<f64>(), -1e18f64..1e18],
    ) {
        let mut timeline = flare_core::timeline::Timeline::default();
        for &(frame, deg, gain) in &keys {
            timeline.light_deg.set(frame, [deg * 0.8, 0.0]);
            timeline.ghost_gain.entry("2-5".into()).or_default().set(frame, gain);
        }
        if timeline.check().is_ok() && at.is_finite() {
            let sample = timeline.sample(at);
            prop_assert!(sample.light_deg.is_none_or(|d| d.iter().all(|a| a.is_finite() && a.abs() < 90.0)));
            prop_assert!(sample.ghost_gain.values().all(|g| g.is_finite() && (0.0..=1e6).contains(g)));
        }
    }

    /// `.ocioz` archives: any archive (entries named to leave the folder among them), its bytes then damaged,
    /// is refused in one line or extracted with every file inside the private folder, within the bounds.
    #[test]
    fn ocioz_archives_are_refused_or_extracted_inside_their_folder(
        entries in proptest::collection::vec(
            (prop_oneof![
                "[a-z]{1,8}(\\.cube)?",
                "[a-z]{1,6}/[a-z]{1,6}\\.cube",
                Just("../escape.cube".to_owned()),
                Just("/abs.cube".to_owned()),
                Just("a/../../b.cube".to_owned()),
            ], 0usize..3000),
            0..6,
        ),
        damage in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 0..4),
    ) {
        use std::io::Write;
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("config.ocioz");
        let mut bytes = Vec::new();
        {
            let mut zip = zip::ZipWriter::new(std::io::Cursor::new(&mut bytes));
            for (name, size) in &entries {
                let options = zip::write::SimpleFileOptions::default();
                if zip.start_file(name.as_str(), options).is_ok() {
                    zip.write_all(&vec![b'1'; *size]).unwrap();
                }
            }
            zip.finish().unwrap();
        }
        for (at, byte) in &damage {
            if !bytes.is_empty() {
                let k = at.index(bytes.len());
                bytes[k] ^= byte;
            }
        }
        std::fs::write(&path, &bytes).unwrap();
        match flare_core::ocio_files::extract_archive(&path) {
            Ok(folder) => {
                let root = folder.path().canonicalize().unwrap();
                let mut total = 0u64;
                let mut stack = vec![root.clone()];
                while let Some(d) = stack.pop() {
                    for entry in std::fs::read_dir(&d).unwrap() {
                        let p = entry.unwrap().path().canonicalize().unwrap();
                        prop_assert!(p.starts_with(&root), "{} left {}", p.display(), root.display());
                        if p.is_dir() { stack.push(p) } else { total += std::fs::metadata(&p).unwrap().len() }
                    }
                }
                prop_assert!(total <= 256 << 20);
                prop_assert!(!dir.path().join("escape.cube").exists() && !Path::new("/abs.cube").exists());
            }
            Err(e) => prop_assert_eq!(e.lines().count(), 1, "{}", e),
        }
    }

    /// Multi-part EXRs as FlareLab writes them (the frame's part and a part per ghost layer, each compression
    /// it writes, half or float): whatever the values (NaN, infinities, past half's range, negative), the file
    /// reads back whole, every value finite and where it was put (issue 61: the `exr` crate's B44 lost values;
    /// the blocks are now compressed by FlareLab's own parallel encoder).
    #[test]
    fn multi_part_exrs_read_back_what_was_written(
        (w, h) in (1u32..24, 1u32..24),
        values in proptest::collection::vec(prop_oneof![
            -1e6f32..1e6,
            Just(f32::NAN),
            Just(f32::INFINITY),
            Just(f32::NEG_INFINITY),
            Just(65504.0f32),
            Just(1e30f32),
        ], 16),
        ghosts in proptest::collection::vec((any::<prop::sample::Index>(), any::<prop::sample::Index>()), 0..4),
        compression in 0usize..6,
        half in any::<bool>(),
    ) {
        use flare_core::output::{ExrCompression, ExrPixel, ExrSettings, FrameLayers, read_exr_channels, write_exr_layers};
        use flare_core::image::HdrImage;
        let n = (w * h) as usize;
        let image = |seed: usize| HdrImage {
            width: w,
            height: h,
            pixels: (0..n).map(|i| [0, 1, 2, 3].map(|c| values[(i * 3 + c + seed) % values.len()])).collect(),
        };
        let ghost_layers: Vec<(String, HdrImage)> = ghosts
            .iter()
            .enumerate()
            .map(|(k, (a, b))| {
                // One or two lit pixels: the part's data window is the rectangle holding them.
                let mut g = HdrImage { width: w, height: h, pixels: vec![[0.0; 4]; n] };
                g.pixels[a.index(n)] = [1.5, -2.0, 3.0, 1.0];
                g.pixels[b.index(n)] = [0.25, 0.5, 0.75, 1.0];
                (format!("ghost_{k}_{}", k + 1), g)
            })
            .collect();
        let layers = FrameLayers {
            composite: image(0),
            flare: image(1),
            starburst: image(2),
            dirt: None,
            plate: Some(image(3)),
            ghosts: ghost_layers.clone(),
        };
        let settings = ExrSettings {
            pixel_type: if half { ExrPixel::Half } else { ExrPixel::Float },
            compression: ExrCompression::ALL[compression],
        };
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("x.exr");
        write_exr_layers(&path, &layers, settings).unwrap();
        let back = read_exr_channels(&path).unwrap();
        prop_assert_eq!((back.width, back.height), (w, h));
        prop_assert_eq!(back.parts.len(), 1 + usize::from(!ghost_layers.is_empty()) * ghost_layers.len());
        let expect = |v: f32| {
            let v = if v.is_nan() { 0.0 } else { v.clamp(-f32::MAX, f32::MAX) };
            if half { exr::prelude::f16::from_f32(v.clamp(-65504.0, 65504.0)).to_f32() } else { v }
        };
        let lossy = settings.compression == ExrCompression::Pxr24 && !half;
        for (name, layer) in [("flare.R", &layers.flare), ("plate.G", &layers.plate.clone().unwrap())] {
            let channel = name.ends_with('G') as usize;
            for (i, p) in layer.pixels.iter().enumerate() {
                let (got, want) = (back.channels[name][i], expect(p[channel]));
                prop_assert!(got.is_finite(), "{name}[{i}] = {got}");
                if lossy {
                    prop_assert!((got - want).abs() <= want.abs() * 1e-4, "{name}[{i}]: {got} for {want}");
                } else {
                    prop_assert_eq!(got, want, "{}[{}]", name, i);
                }
            }
        }
        for (name, g) in &ghost_layers {
            for (i, p) in g.pixels.iter().enumerate() {
                prop_assert_eq!(back.channels[&format!("{name}.G")][i], p[1], "{}[{}]", name, i);
            }
        }
    }

    /// OCIO configs' YAML: any text with anchors and aliases is counted as events without expanding, refused
    /// in one line or read; it never panics and never builds the tree.
    #[test]
    fn ocio_yaml_is_counted_without_expanding(
        depth in 1usize..14,
        width in 1usize..12,
        tail in "[a-z:&* \\[\\],{}\\n-]{0,60}",
    ) {
        let mut text = String::from("ocio_profile_version: 2\na0: &a0 [x]\n");
        for k in 1..depth {
            text.push_str(&format!("a{k}: &a{k} [{}]\n", vec![format!("*a{}", k - 1); width].join(", ")));
        }
        text.push_str(&tail);
        match flare_core::ocio_files::check_config_text(&text) {
            Ok(_) => prop_assert!((width as f64).powi(depth as i32 - 1) <= 2.0e6),
            Err(e) => prop_assert_eq!(e.lines().count(), 1),
        }
    }
}
