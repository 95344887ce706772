//! Ad-hoc timing: the paraxial frame on the CPU twin and on the GPU (compute and raster ghosts).
use flare_core::flare::{FlareConfig, PreparedFlare};
use flare_core::frame::{self, Frame, FrameRequest, GpuDrawer, Sources};
use flare_core::optics::library::builtin_lens;
use flare_core::render::DisplaySettings;
use std::time::Instant;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let lens = builtin_lens(&args[1]).unwrap();
    let (w, h): (u32, u32) = (args[2].parse().unwrap(), args[3].parse().unwrap());
    let flare = PreparedFlare::new(&lens, &FlareConfig::default()).unwrap();
    let live = args.get(4).map(|p| flare_core::lut::blend::LiveLut::new(flare_core::lut::format::read_lut(std::path::Path::new(p)).unwrap()));
    let request = FrameRequest {
        light_deg: [9.0, 5.0],
        width: w,
        height: h,
        display: DisplaySettings { starburst: false, ..DisplaySettings::default() },
        lut_use: if live.is_some() { flare_core::frame::LutUse::Blend } else { flare_core::frame::LutUse::Off },
        ..FrameRequest::default()
    };
    let sources = Sources { flare: &flare, lut: live.as_ref(), plate: None };
    let med = |mut v: Vec<f64>| { v.sort_by(f64::total_cmp); v[v.len() / 2] };
    let cpu: Vec<f64> = (0..5).map(|_| { let s = Instant::now(); let f = Frame::build(&flare, live.as_ref(), &request); let _ = frame::draw_cpu_hdr(&f, &sources); s.elapsed().as_secs_f64() * 1e3 }).collect();
    println!("CPU twin: {:.1} ms", med(cpu));
    for raster in [false, std::env::var("RASTER").is_ok()] {
        if raster && std::env::var("RASTER").is_err() { break; }
        let mut drawer = GpuDrawer::new(true).unwrap();
        if raster { drawer.renderer.force_raster_ghosts(); }
        let target = flare_core::render::gpu::texture_2d(&drawer.ctx.device, "t", w, h, wgpu::TextureFormat::Rgba8Unorm, wgpu::TextureUsages::RENDER_ATTACHMENT);
        let view = target.create_view(&Default::default());
        let mut wall = Vec::new();
        let mut gpu = Vec::new();
        for _ in 0..5 {
            let s = Instant::now();
            let f = Frame::build(&flare, live.as_ref(), &request);
            let t1 = s.elapsed().as_secs_f64() * 1e3;
            drawer.render_into(&f, &sources, &view).unwrap();
            let t2 = s.elapsed().as_secs_f64() * 1e3;
            let _ = drawer.ctx.device.poll(wgpu::PollType::wait_indefinitely());
            wall.push(s.elapsed().as_secs_f64() * 1e3);
            println!("  build {t1:.1} render_into {:.1} poll {:.1}", t2 - t1, wall.last().unwrap() - t2);
            if let Some(t) = drawer.renderer.wait_pass_times(&drawer.ctx.device, &drawer.ctx.queue) { gpu.push(t.total_ms()); println!("  {}", t.summary()); }
        }
        println!("GPU ({}, {}): wall {:.1} ms, GPU {:.1} ms", drawer.ctx.adapter.name, if raster { "raster" } else { "compute" }, med(wall), if gpu.is_empty() { f64::NAN } else { med(gpu) });
    }
}
