//! Ad-hoc timing: paraxial vs blended CPU frames for a lens and a baked LUT.
use flare_core::flare::{FlareConfig, PreparedFlare};
use flare_core::frame::{self, Frame, FrameRequest, LutUse, Sources};
use flare_core::lut::blend::LiveLut;
use flare_core::optics::library::builtin_lens;
use flare_core::render::DisplaySettings;
use std::time::Instant;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let lens = builtin_lens(&args[1]).unwrap();
    let lut = flare_core::lut::format::read_lut(std::path::Path::new(&args[2])).unwrap();
    let (w, h): (u32, u32) = (args[3].parse().unwrap(), args[4].parse().unwrap());
    let config = FlareConfig::default();
    let flare = PreparedFlare::new(&lens, &config).unwrap();
    let live = LiveLut::new(lut);
    for light in [[0.0, 0.0], [5.0, 3.0], [9.0, 5.0], [15.0, 10.0]] {
        let request = FrameRequest {
            light_deg: light,
            width: w,
            height: h,
            display: DisplaySettings { starburst: false, ..DisplaySettings::default() },
            ..FrameRequest::default()
        };
        let blended = FrameRequest { lut_use: LutUse::Blend, ..request.clone() };
        let mut t = [Vec::new(), Vec::new(), Vec::new()];
        for _ in 0..5 {
            let s = Instant::now();
            let f = Frame::build(&flare, None, &request);
            let _ = frame::draw_cpu_hdr(&f, &Sources { flare: &flare, lut: None, plate: None });
            t[0].push(s.elapsed().as_secs_f64() * 1e3);
            let s = Instant::now();
            let f = Frame::build(&flare, Some(&live), &blended);
            let _ = frame::draw_cpu_hdr(&f, &Sources { flare: &flare, lut: Some(&live), plate: None });
            t[1].push(s.elapsed().as_secs_f64() * 1e3);
            t[2].push(f.lut.as_ref().map_or(0, |l| l.instances.len()) as f64);
        }
        for v in &mut t {
            v.sort_by(f64::total_cmp);
        }
        println!("light {light:?}: paraxial {:.1} ms, blended {:.1} ms ({:.2}x), {} LUT instances", t[0][2], t[1][2], t[1][2] / t[0][2], t[2][2]);
    }
}
