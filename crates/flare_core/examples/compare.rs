//! Two renders of one size compared as the bench compares them (`metrics::compare`: display values at the
//! reference's exposure): PSNR, SSIM and relative L1. EXR files are read by their `flare.R/G/B` channels (the
//! linear flare `render` writes), other images as plates are. What the README's Heliar stair-step figures came
//! from.
//!
//! `cargo run --release -p flare_core --example compare -- TEST REFERENCE`

use exr::prelude::{FlatSamples, read_all_flat_layers_from_file};
use flare_core::image::HdrImage;
use std::path::Path;

fn read(path: &Path) -> Result<HdrImage, Box<dyn std::error::Error>> {
    if path.extension().is_none_or(|e| !e.eq_ignore_ascii_case("exr")) {
        return Ok(flare_core::output::read_plate(path)?);
    }
    let image = read_all_flat_layers_from_file(path)?;
    for layer in &image.layer_data {
        let prefix = layer.attributes.layer_name.as_ref().map(|n| format!("{n}.")).unwrap_or_default();
        let channel = |name: &str| {
            layer.channel_data.list.iter().find(|c| format!("{prefix}{}", c.name) == name).map(|c| {
                match &c.sample_data {
                    FlatSamples::F16(v) => v.iter().map(|x| x.to_f32()).collect::<Vec<f32>>(),
                    FlatSamples::F32(v) => v.clone(),
                    FlatSamples::U32(v) => v.iter().map(|&x| x as f32).collect(),
                }
            })
        };
        if let (Some(r), Some(g), Some(b)) = (channel("flare.R"), channel("flare.G"), channel("flare.B")) {
            let size = layer.size;
            let pixels = (0..r.len()).map(|k| [r[k], g[k], b[k], 1.0]).collect();
            return Ok(HdrImage { width: size.0 as u32, height: size.1 as u32, pixels });
        }
    }
    Err(format!("{}: no flare.R/G/B channels", path.display()).into())
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let usage = "usage: compare TEST REFERENCE";
    let test = read(Path::new(args.get(1).ok_or(usage)?))?;
    let reference = read(Path::new(args.get(2).ok_or(usage)?))?;
    if (test.width, test.height) != (reference.width, reference.height) {
        let (a, b) = ((test.width, test.height), (reference.width, reference.height));
        return Err(format!("{a:?} against {b:?}: not one size").into());
    }
    let c = flare_core::metrics::compare(&test, &[], &reference, &[]);
    println!("PSNR {:.1} dB, SSIM {:.4}, rel. L1 {:.4}", c.psnr_db, c.ssim, c.relative_l1);
    Ok(())
}
