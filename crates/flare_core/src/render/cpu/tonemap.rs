//! `tonemap.wgsl` on the CPU: the composite `flare x 2^flare_ev + plate x 2^plate_ev` at the image size, then
//! the OCIO display and view ([`crate::view_transform::ViewTransform::apply`], the CPU twin of the shader's
//! `ocio_display`) or one of FlareLab's curves and the sRGB encoding.

use crate::color::{Tonemap, display_value, srgb_decode, to_u8};
use crate::image::{DisplayImage, HdrImage, Sampling};
use crate::render::FlareScene;

/// `tonemap.wgsl` for one composite value (flare and plate already multiplied by their gains): the OCIO view
/// (display-encoded; decoded again for a target that encodes sRGB itself; negative values, colours outside
/// the working gamut, go to the view as they are) or, negative values taken as 0, the operator and the sRGB
/// encoding; a clamp to [0, 1].
pub fn tonemap_pixel(c: [f32; 3], scene: &FlareScene) -> [f32; 3] {
    let globals = &scene.globals;
    let encode = globals.encode_srgb != 0;
    match globals.operator() {
        Tonemap::View => {
            let c = c.map(|v| if v.is_finite() { v } else { 0.0 });
            let out = scene.view_transform().apply(c).map(|v| v.clamp(0.0, 1.0));
            if encode { out } else { out.map(srgb_decode) }
        }
        op => c.map(|v| display_value(v, op, encode)),
    }
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
    let (w, h) = scene.output_size;
    hdr.resampled(w, h, Sampling::Bilinear, scene.globals.flare_gain)
}

/// The plate at the image size, times its gain (what the EXR's `plate` layer holds).
pub fn plate_layer(scene: &FlareScene, plate: &HdrImage) -> HdrImage {
    let (w, h) = scene.output_size;
    let mut layer = plate.resampled(w, h, Sampling::Nearest, scene.globals.plate_gain);
    for p in &mut layer.pixels {
        p[3] = 1.0;
    }
    layer
}

/// `tonemap.wgsl`: [`composite`], then tonemap and sRGB into 8-bit display pixels.
pub(crate) fn tonemap_pass(scene: &FlareScene, hdr: &HdrImage, plate: Option<&HdrImage>) -> DisplayImage {
    display_of(scene, &composite(scene, hdr, plate))
}

/// The display image of a composite already at the image size ([`tonemap_pixel`] of every pixel; the OCIO
/// view over the whole image at once).
pub(crate) fn display_of(scene: &FlareScene, composite: &HdrImage) -> DisplayImage {
    let pixels = if scene.globals.operator() == Tonemap::View {
        let encode = scene.globals.encode_srgb != 0;
        let mut values: Vec<[f32; 4]> = composite
            .pixels
            .iter()
            .map(|p| [p[0], p[1], p[2]].map(|v| if v.is_finite() { v } else { 0.0 }))
            .map(|c| [c[0], c[1], c[2], 1.0])
            .collect();
        scene.view_transform().apply_rgba(&mut values);
        values
            .iter()
            .map(|p| {
                let t = [p[0], p[1], p[2]].map(|v| v.clamp(0.0, 1.0));
                let t = if encode { t } else { t.map(srgb_decode) };
                [to_u8(t[0]), to_u8(t[1]), to_u8(t[2]), 255]
            })
            .collect()
    } else {
        composite
            .pixels
            .iter()
            .map(|p| {
                let t = tonemap_pixel([p[0], p[1], p[2]], scene);
                [to_u8(t[0]), to_u8(t[1]), to_u8(t[2]), 255]
            })
            .collect()
    };
    DisplayImage { width: composite.width, height: composite.height, pixels }
}
