use flare_core::optics::*;
use flare_core::optics::library::builtin_lens;
fn main() {
    let lens = builtin_lens("heliar").unwrap();
    let fo = FirstOrder::d_line(&lens).unwrap();
    let t = Tracer::new(&lens, &LightPath::image(&lens), D_LINE_NM, fo.sensor_z_mm());
    let r = t.trace(&pupil_ray(&fo.entrance_pupil(), 20f64.to_radians(), 0.0, -1.0), TraceOptions { apply_apertures: false, record_points: true });
    println!("{:?}", r);
}
