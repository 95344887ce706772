//! `tonemap.wgsl` on the CPU: the composite `flare x 2^flare_ev + plate x 2^plate_ev` at the image size, the
//! tonemap and the sRGB encoding.

use crate::color::{display_value, to_u8};
use crate::image::{DisplayImage, HdrImage, Sampling};
use crate::render::{FlareScene, Globals};

/// `tonemap.wgsl` for one composite value (flare and plate already multiplied by their gains): the operator,
/// a clamp and the sRGB encoding.
pub fn tonemap_pixel(c: [f32; 3], globals: &Globals) -> [f32; 3] {
    let encode = globals.tonemap[2] > 0.5;
    c.map(|v| display_value(v, globals.operator(), encode))
}

/// The first step of `tonemap.wgsl`: the composite `flare * 2^flare_ev + plate * 2^plate_ev` at the image
/// size, the HDR accumulation read bilinearly (upsampled when it is smaller) and the plate at its nearest
/// texel, linear.
pub fn composite(scene: &FlareScene, hdr: &HdrImage, plate: Option<&HdrImage>) -> HdrImage {
    let flare = flare_layer(scene, hdr);
    match plate {
        Some(plate) => flare.plus(&plate_layer(scene, plate)),
        None => flare,
    }
}

/// The flare alone at the image size, times its gain (what the EXR's `flare` layer holds).
pub fn flare_layer(scene: &FlareScene, hdr: &HdrImage) -> HdrImage {
    hdr.resampled(scene.width, scene.height, Sampling::Bilinear, scene.globals.flare_gain())
}

/// The plate at the image size, times its gain (what the EXR's `plate` layer holds).
pub fn plate_layer(scene: &FlareScene, plate: &HdrImage) -> HdrImage {
    let mut layer = plate.resampled(scene.width, scene.height, Sampling::Nearest, scene.globals.plate_gain());
    for p in &mut layer.pixels {
        p[3] = 1.0;
    }
    layer
}

/// `tonemap.wgsl`: [`composite`], then tonemap and sRGB into 8-bit display pixels.
pub fn tonemap_pass(scene: &FlareScene, hdr: &HdrImage, plate: Option<&HdrImage>) -> DisplayImage {
    display_of(scene, &composite(scene, hdr, plate))
}

/// The display image of a composite already at the image size.
pub fn display_of(scene: &FlareScene, composite: &HdrImage) -> DisplayImage {
    let pixels = composite
        .pixels
        .iter()
        .map(|p| {
            let t = tonemap_pixel([p[0], p[1], p[2]], &scene.globals);
            [to_u8(t[0]), to_u8(t[1]), to_u8(t[2]), 255]
        })
        .collect();
    DisplayImage { width: scene.width, height: scene.height, pixels }
}
