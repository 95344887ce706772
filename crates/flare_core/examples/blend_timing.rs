//! The blended frame's cost against the paraxial frame's on the CPU twin, for a built-in lens and a LUT baked for
//! it (`flarelab bake LENS -o LUT.flut`), at four light positions: medians of 5 frames, and the LUT instances
//! drawn. What the README's table of the CPU twin's LUT pass came from.
//!
//! `cargo run --release -p flare_core --example blend_timing -- LENS LUT.flut WIDTH HEIGHT [FLARE_EV]`

use std::time::Instant;

use flare_core::flare::{FlareConfig, PreparedFlare};
use flare_core::frame::{self, Frame, FrameRequest, LutUse, Sources};
use flare_core::lut::blend::LiveLut;
use flare_core::metrics::median;
use flare_core::optics::library::builtin_lens;
use flare_core::render::DisplaySettings;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let usage = "usage: blend_timing LENS LUT.flut WIDTH HEIGHT [FLARE_EV]";
    let lens = builtin_lens(args.get(1).ok_or(usage)?)?;
    let lut = flare_core::lut::format::read_lut(std::path::Path::new(args.get(2).ok_or(usage)?))?;
    let (w, h): (u32, u32) = (args.get(3).ok_or(usage)?.parse()?, args.get(4).ok_or(usage)?.parse()?);
    let flare = PreparedFlare::new(&lens, &FlareConfig::default())?;
    let live = LiveLut::new(lut);
    // An optional fifth argument: the flare exposure in stops (the bench draws at its reference's).
    let flare_ev: Option<f64> = args.get(5).map(|s| s.parse()).transpose()?;
    for light in [[0.0, 0.0], [5.0, 3.0], [9.0, 5.0], [15.0, 10.0], [8.66, 5.0], [17.32, 10.0]] {
        let request = FrameRequest {
            light_deg: light,
            width: w,
            height: h,
            display: DisplaySettings {
                starburst: false,
                flare_ev: flare_ev.unwrap_or(DisplaySettings::default().flare_ev),
                ..DisplaySettings::default()
            },
            ..FrameRequest::default()
        };
        let blended = FrameRequest { lut_use: LutUse::Blend, ..request.clone() };
        let (mut paraxial_ms, mut blended_ms, mut instances) = (Vec::new(), Vec::new(), 0);
        for _ in 0..5 {
            let start = Instant::now();
            let f = Frame::build(&flare, None, &request);
            let _ = frame::draw_cpu_hdr(&f, &Sources { flare: &flare, lut: None, plate: None });
            paraxial_ms.push(start.elapsed().as_secs_f64() * 1e3);
            let start = Instant::now();
            let f = Frame::build(&flare, Some(&live), &blended);
            let _ = frame::draw_cpu_hdr(&f, &Sources { flare: &flare, lut: Some(&live), plate: None });
            blended_ms.push(start.elapsed().as_secs_f64() * 1e3);
            instances = f.lut.as_ref().map_or(0, |l| l.instances.len());
        }
        let (p, b) = (median(&paraxial_ms), median(&blended_ms));
        println!("light {light:?}: paraxial {p:.1} ms, blended {b:.1} ms ({:.2}x), {instances} LUT instances", b / p);
    }
    Ok(())
}
