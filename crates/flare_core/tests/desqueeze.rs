//! The desqueeze of the frame ([`flare_core::frame::FrameRequest::desqueeze`]): a desqueezed frame is drawn on
//! the sensor's square pixels (the very frame of that size, sprite for sprite) and averaged down to the delivered
//! size, by the CPU twin and the GPU alike; a desqueeze of 1 changes nothing; a tracked pixel of a desqueezed
//! plate maps to the light that images there; the preset refuses what it cannot draw.

use flare_core::flare::{FlareConfig, PreparedFlare};
use flare_core::frame::{self, Frame, FrameRequest, Sources, sensor_pixels};
use flare_core::image::HdrImage;
use flare_core::optics::library::default_lens;

fn request(size: (u32, u32), desqueeze: f64) -> FrameRequest {
    FrameRequest { light_deg: [7.0, 4.0], width: size.0, height: size.1, desqueeze, ..FrameRequest::default() }
}

/// The mean of each `k` neighbouring rows (k > 1) or columns (k < 1 as 1 / k) of `image`.
fn averaged(image: &HdrImage, rows: usize, columns: usize) -> HdrImage {
    let (w, h) = (image.width as usize / columns, image.height as usize / rows);
    let mut pixels = vec![[0.0f32; 4]; w * h];
    for (k, p) in pixels.iter_mut().enumerate() {
        let (x, y) = (k % w, k / w);
        for j in 0..rows {
            for i in 0..columns {
                let s = image.pixels[(y * rows + j) * image.width as usize + x * columns + i];
                for c in 0..4 {
                    p[c] += s[c] / (rows * columns) as f32;
                }
            }
        }
    }
    HdrImage { width: w as u32, height: h as u32, pixels }
}

/// Desqueezed by 2 (or 1/2), the frame is the frame of twice the rows (or columns) on the same sensor width,
/// sprite for sprite, and its flare layer is that frame's, each two rows (columns) averaged: the irradiance kept,
/// the light's energy over the delivered pixels (twice the area) the same.
#[test]
fn a_desqueezed_frame_is_the_sensors_pixels_averaged() {
    let flare = PreparedFlare::new(&default_lens(), &FlareConfig::default()).unwrap();
    let sources = Sources { flare: &flare, lut: None, plate: None };
    for (desqueeze, rows, columns) in [(2.0, 2, 1), (0.5, 1, 2)] {
        let delivered = (160, 90);
        let sensor = sensor_pixels(delivered.0, delivered.1, desqueeze);
        assert_eq!(sensor, (delivered.0 * columns as u32, delivered.1 * rows as u32));
        let squeezed = Frame::build(&flare, None, &request(delivered, desqueeze));
        let plain = Frame::build(&flare, None, &request(sensor, 1.0));
        assert_eq!(squeezed.size(), delivered);
        assert_eq!(squeezed.scene.instances, plain.scene.instances, "the same sprites on the sensor");
        let (a, b) = (frame::draw_cpu(&squeezed, &sources), frame::draw_cpu(&plain, &sources));
        assert_eq!((a.display.width, a.display.height), delivered);
        let (la, lb) = (a.layers(&squeezed, &sources), b.layers(&plain, &sources));
        let expected = averaged(&lb.flare, rows, columns);
        let (mut worst, mut total_a, mut total_b) = (0.0f32, 0.0f64, 0.0f64);
        for (p, q) in la.flare.pixels.iter().zip(&expected.pixels) {
            worst = worst.max((p[1] - q[1]).abs() / q[1].abs().max(1e-3));
            total_a += f64::from(p[1]);
        }
        total_b += lb.flare.pixels.iter().map(|p| f64::from(p[1])).sum::<f64>();
        println!(
            "desqueeze {desqueeze}: worst relative difference {worst:.1e}; energy ratio {}",
            total_a * 2.0 / total_b
        );
        assert!(worst < 1e-5, "desqueeze {desqueeze}: {worst}");
        assert!((total_a * 2.0 / total_b - 1.0).abs() < 1e-5, "the light's energy is kept");
    }
    // A desqueeze of 1 is the frame itself.
    let one = Frame::build(&flare, None, &request((160, 90), 1.0));
    assert_eq!(one.scene.output_size, (one.scene.width, one.scene.height));
    assert_eq!(one.scene.globals.inv_output_px, one.scene.globals.inv_viewport_px);
}

/// The GPU delivers the desqueezed frame its CPU twin does (the tonemap pass sampling the sensor's rows at the
/// delivered pixels).
#[test]
fn the_gpu_desqueezes_as_its_cpu_twin_does() {
    let Some(ctx) = flare_core::render::gpu::test_context() else { return };
    let mut device = frame::Device::Gpu(Box::new(frame::GpuDrawer::on(ctx)));
    let flare = PreparedFlare::new(&default_lens(), &FlareConfig::default()).unwrap();
    let sources = Sources { flare: &flare, lut: None, plate: None };
    for desqueeze in [2.0, 1.33, 0.5] {
        let frame = Frame::build(&flare, None, &request((256, 144), desqueeze));
        let gpu = device.draw(&frame, &sources).unwrap();
        let cpu = frame::draw_cpu(&frame, &sources);
        assert_eq!((gpu.display.width, gpu.display.height), (256, 144));
        let (mut sum, mut worst) = (0u64, 0u8);
        for (g, c) in gpu.display.pixels.iter().zip(&cpu.display.pixels) {
            for k in 0..3 {
                let d = g[k].abs_diff(c[k]);
                sum += u64::from(d);
                worst = worst.max(d);
            }
        }
        let mean = sum as f64 / (3 * cpu.display.pixels.len()) as f64;
        println!("desqueeze {desqueeze}: display mean {mean:.3}/255, worst {worst}/255");
        assert!(mean < 0.5 && worst <= 4, "desqueeze {desqueeze}: mean {mean}, worst {worst}");
    }
}

/// A tracker's pixel of a desqueezed plate is the light that images there: light angles placed on the sensor,
/// taken to delivered pixels, read back as a track, give the same angles.
#[test]
fn a_tracked_pixel_of_a_desqueezed_plate_is_the_light_there() {
    use flare_core::optics::sensor::Sensor;
    let flare = PreparedFlare::new(&default_lens(), &FlareConfig::default()).unwrap();
    let mapping = &flare.system.mapping;
    let (width, height, desqueeze) = (400u32, 300u32, 1.5);
    let (columns, rows) = sensor_pixels(width, height, desqueeze);
    let sensor = Sensor::for_frame(36.0, columns, rows);
    let lights = [[5.0, 3.0], [-9.0, -6.0]];
    let mut csv = String::from("frame,x_px,y_px\n");
    for (k, light) in lights.iter().enumerate() {
        let p = mapping.pixel_for_light_deg(*light, &sensor, columns, rows);
        let delivered = [p[0] * f64::from(width) / f64::from(columns), p[1] * f64::from(height) / f64::from(rows)];
        csv += &format!("{},{},{}\n", k + 1, delivered[0], delivered[1]);
    }
    let parsed = flare_core::shot::track::parse_track(&csv).unwrap();
    let (position, _) = flare_core::shot::track::to_keys(&parsed, mapping, 36.0, (width, height), desqueeze).unwrap();
    for (key, light) in position.keys.iter().zip(lights) {
        for k in 0..2 {
            assert!((key.value[k] - light[k]).abs() < 1e-6, "{:?} read back as {:?}", light, key.value);
        }
    }
}

/// The preset keeps its desqueeze and refuses one it cannot draw, naming the field.
#[test]
fn the_preset_keeps_its_desqueeze_and_refuses_a_bad_one() {
    use flare_core::preset::Document;
    let doc = Document { desqueeze: 1.33, ..Document::default() };
    assert_eq!(Document::from_json(&doc.to_json()).unwrap().desqueeze, 1.33);
    let system = flare_core::ghost::GhostSystem::build(&doc.lens, &Default::default());
    if let Ok(system) = system {
        assert_eq!(doc.frame_request(&system, 64, 36, 1).desqueeze, 1.33);
    }
    for bad in [0.1, 5.0, -1.0] {
        let mut json: serde_json::Value = serde_json::from_str(&doc.to_json()).unwrap();
        json["desqueeze"] = serde_json::json!(bad);
        let why = Document::from_json(&json.to_string()).unwrap_err().to_string();
        assert!(why.contains("desqueeze"), "{bad}: {why}");
    }
}
