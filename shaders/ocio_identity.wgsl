// A stand-in for the OCIO display transform that `tonemap.wgsl` calls: at run time the renderer puts the WGSL
// that OCIO generates for the document's display and view here instead (crate::view_transform::WgslShader,
// `fn ocio_display`, its LUT textures in bind group 1). This one only lets the shaders be validated alone.
fn ocio_display(inPixel: vec4<f32>) -> vec4<f32> {
    return inPixel;
}
