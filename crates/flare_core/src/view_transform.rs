//! Colour management by OpenColorIO (the pure-Rust `ocio` crate): how the linear frame becomes display pixels,
//! and how a plate's pixels become linear.
//!
//! # How it works
//! Every image FlareLab holds is in its working space, [`WORKING_SPACE`] (scene-linear Rec. 709). A
//! document's [`ColorDoc`] names an OCIO config ([`DEFAULT_CONFIG`], built into the binary, unless a file or
//! another `ocio://` name is given), a display and a view (the config's defaults when not given), optional
//! looks, an optional `.cube` file and an optional input space for plates. [`ViewTransform::new`] resolves
//! them once: the config is read (a file at most `crate::files::MAX_TEXT_BYTES`), a `.cube` becomes a look
//! named [`CUBE_LOOK`] whose process space is the config's `color_timing` role (else `scene_linear`), so it
//! is applied where OCIO applies every look, and the display transform is OCIO's legacy viewing pipeline from
//! the working space to the display and view with those looks. Its CPU processor is the CPU twin
//! ([`ViewTransform::apply`]); its WGSL shader ([`WgslShader`], function `ocio_display`, its LUTs as 2D and
//! 3D textures of bind group `WGSL_GROUP`: no 1D ones, which OpenGL ES lacks) is what the tonemap pass of
//! the GPU renderer runs when the document's tonemap is [`crate::color::Tonemap::View`] (the default): the
//! same numbers to within OCIO's 1e-3. OCIO writes some tables into that shader as `var<private>` arrays (the
//! ACES 2.0 views' 363 hues), which each invocation would copy into its own memory before reading two entries
//! (a third of a lavapipe draft's time); `wgsl` makes each one a texture of the group (one row of texels), read
//! with the same clamped index, and keeps OCIO's text when one is of another form.
//!
//! FlareLab's own curves (clamp, Reinhard, Narkowicz's ACES fit, [`crate::color::Tonemap`]) are kept as the
//! other tonemaps: each is a tone curve followed by the sRGB encoding, as if on the "sRGB - Display" with the
//! curve as the view; they bypass the OCIO view and its looks.
//!
//! Plates: with no input space they come in as before (PNG and JPEG decoded from sRGB, EXR and HDR as
//! linear). With an input space, the file's own values (a PNG's encoded ones) are converted from that space
//! to the working space; `display` names the inverse of the display, view and looks, so a plate at 0 EV
//! with no flare goes out through the same view as it came in: as shot.
//!
//! [`ViewTransform::cached`] keeps the last few resolved transforms, so a frame request can carry one per
//! document without reading the config again.

use std::sync::{Arc, Mutex};

use serde::{Deserialize, Serialize};

use crate::image::HdrImage;

/// FlareLab's working space: its OCIO name in the built-in configs.
pub const WORKING_SPACE: &str = crate::output::WORKING_SPACE;
/// The config used when a document names none: OCIO's latest built-in studio config.
pub const DEFAULT_CONFIG: &str = "ocio://studio-config-latest";
/// The name of the look a document's `.cube` file becomes.
pub const CUBE_LOOK: &str = "flarelab_cube";
/// The input space that names the inverse of the display and view.
pub const DISPLAY_INPUT: &str = "display";
/// The bind group of the tonemap pass that holds the OCIO shader's LUT textures.
pub(crate) const WGSL_GROUP: u32 = 1;

/// The most looks a document applies (`color.looks`), each named once: a preset of 5,000 repeats once took
/// over a minute to refuse or apply (issue 61).
pub(crate) const MAX_LOOKS: usize = 16;

/// A document's colour management (its `color`): see the module documentation.
#[derive(Clone, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(default)]
pub struct ColorDoc {
    /// An OCIO config: a file (`.ocio`, `.ocioz`) or a built-in `ocio://` name; `None`: [`DEFAULT_CONFIG`].
    pub config: Option<String>,
    /// The display; `None`: the config's default display.
    pub display: Option<String>,
    /// The view; `None`: the display's default view.
    pub view: Option<String>,
    /// OCIO looks applied before the view, comma-separated (`None`: the view's own).
    pub looks: Option<String>,
    /// A `.cube` (or any LUT file OCIO reads) applied as a look after `looks`.
    pub cube: Option<String>,
    /// The colour space of plate files (`display`: the inverse of the display and view); `None`: by file
    /// type (PNG and JPEG sRGB, EXR and HDR linear).
    pub input_space: Option<String>,
}

/// Why a colour setting cannot be used: the document's field and the reason.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("color.{field}: {reason}")]
pub struct ViewError {
    pub field: &'static str,
    pub reason: String,
}

fn refuse(field: &'static str, reason: impl Into<String>) -> ViewError {
    ViewError { field, reason: crate::files::one_line(&reason.into()) }
}

/// A texture of the OCIO shader: its binding in `WGSL_GROUP`, its size and its texels.
#[derive(Clone, Debug, PartialEq)]
pub struct WgslTexture {
    pub binding: u32,
    /// 1, 2 or 3.
    pub dimensions: u32,
    pub size: [u32; 3],
    /// `Rgba32Float` when true, else `R32Float`.
    pub rgba: bool,
    /// The texels as f32 values.
    pub bytes: Vec<u8>,
    /// Uploaded as 16-bit floats (`Rgba16Float`, `R16Float`) and filterable, for the shader's sampler
    /// ([`WgslShader::sampler`]); else 32-bit and read by `textureLoad` (OCIO's own).
    pub filtered: bool,
}

/// The OCIO display transform as WGSL: `fn ocio_display(inPixel: vec4<f32>) -> vec4<f32>`, its textures and
/// its uniform buffer (binding 0 of `WGSL_GROUP`, when it has uniforms).
#[derive(Clone, Debug, PartialEq)]
pub struct WgslShader {
    pub text: String,
    pub textures: Vec<WgslTexture>,
    pub uniforms: Option<Vec<u8>>,
    /// The binding of a linear, clamped sampler in `WGSL_GROUP`, where the shader samples its filtered
    /// textures (OCIO's shaders have none).
    pub sampler: Option<u32>,
}

/// What the app's menus offer for a config.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Menus {
    pub displays: Vec<String>,
    /// The views of the chosen display.
    pub views: Vec<String>,
    pub looks: Vec<String>,
    pub spaces: Vec<String>,
}

/// A document's colour management resolved (see the module documentation).
pub struct ViewTransform {
    /// What it was made from.
    pub doc: ColorDoc,
    /// The config, display and view in use (the defaults filled in).
    pub config: String,
    pub display: String,
    pub view: String,
    /// The looks applied, as OCIO's looks string (empty: the view's own).
    pub looks: String,
    /// A stable key of the settings (for upload caches).
    pub key: u64,
    pub menus: Menus,
    pub shader: WgslShader,
    forward: ocio::CpuProcessor,
    input: Option<ocio::CpuProcessor>,
    /// The private folder a `.ocioz` config was extracted to ([`crate::ocio_files`]): kept while the
    /// processors made from it live, removed with the last of them.
    _extracted: Option<std::sync::Arc<tempfile::TempDir>>,
}

impl std::fmt::Debug for ViewTransform {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ViewTransform")
            .field("config", &self.config)
            .field("display", &self.display)
            .field("view", &self.view)
            .field("looks", &self.looks)
            .field("input_space", &self.doc.input_space)
            .finish()
    }
}

impl PartialEq for ViewTransform {
    fn eq(&self, other: &Self) -> bool {
        self.doc == other.doc
    }
}

/// Reads `config` (a file, its YAML, the files it names and an archive's entries checked first, or an
/// `ocio://` name: [`crate::ocio_files::load`]).
fn load_config(config: &str) -> Result<crate::ocio_files::LoadedConfig, ViewError> {
    crate::ocio_files::load(config).map_err(|e| refuse("config", format!("{}: {e}", crate::files::shorten(config))))
}

impl ViewTransform {
    /// Resolves `doc` (see the module documentation); refuses, naming the field, a config that cannot be
    /// read, a display, view, look or space the config lacks, a config without the working space, and a LUT
    /// file that cannot be read.
    pub fn new(doc: &ColorDoc) -> Result<Self, ViewError> {
        let config_name = doc.config.clone().unwrap_or_else(|| DEFAULT_CONFIG.to_owned());
        let crate::ocio_files::LoadedConfig { mut config, extracted } = load_config(&config_name)?;
        if config.get_color_space(WORKING_SPACE).is_none() {
            return Err(refuse(
                "config",
                format!("{config_name} has no colour space `{WORKING_SPACE}` (FlareLab's working space)"),
            ));
        }
        let displays: Vec<String> = (0..config.num_displays()).map(|i| config.display(i)).collect();
        let display = doc.display.clone().unwrap_or_else(|| config.default_display());
        if !displays.contains(&display) {
            return Err(refuse(
                "display",
                format!("`{display}` is not a display of {config_name} ({})", displays.join(", ")),
            ));
        }
        let views: Vec<String> = (0..config.num_views(&display)).map(|i| config.view(&display, i)).collect();
        let view = doc.view.clone().unwrap_or_else(|| config.default_view(&display));
        if !views.contains(&view) {
            return Err(refuse("view", format!("`{view}` is not a view of {display} ({})", views.join(", "))));
        }
        let looks_list: Vec<String> =
            (0..config.num_looks()).map(|i| config.look_name_by_index(i).to_owned()).collect();
        let mut looks: Vec<String> = Vec::new();
        if let Some(l) = &doc.looks {
            for name in l.split(',').map(str::trim).filter(|n| !n.is_empty()) {
                let shown = crate::files::shorten(name);
                if looks.len() == MAX_LOOKS {
                    return Err(refuse("looks", format!("more than {MAX_LOOKS} looks: name each look once")));
                }
                if looks.iter().any(|k| k == name) {
                    return Err(refuse("looks", format!("`{shown}` is named twice: each look applies once")));
                }
                if !looks_list.iter().any(|k| k == name) {
                    return Err(refuse(
                        "looks",
                        format!("`{shown}` is not a look of {config_name} ({})", looks_list.join(", ")),
                    ));
                }
                looks.push(name.to_owned());
            }
        }
        if let Some(cube) = &doc.cube {
            // OCIO keeps files it read by path: a cube edited on disk is read again when the settings are.
            ocio::clear_all_caches();
            let path = std::path::Path::new(cube);
            crate::files::read_bounded(path, crate::files::MAX_TEXT_BYTES)
                .map_err(|e| refuse("cube", format!("{cube}: {e}")))?;
            let absolute = std::fs::canonicalize(path).map_err(|e| refuse("cube", format!("{cube}: {e}")))?;
            let process_space = if config.has_role("color_timing") { "color_timing" } else { "scene_linear" };
            let mut look = ocio::config::look::Look::new();
            look.set_name(CUBE_LOOK);
            look.set_process_space(process_space);
            look.set_transform(Some(ocio::Transform::File(ocio::FileTransform {
                src: absolute.display().to_string(),
                ..Default::default()
            })));
            config.add_look(&look).map_err(|e| refuse("cube", format!("{cube}: {e}")))?;
            looks.push(CUBE_LOOK.to_owned());
        }
        let looks = looks.join(", ");
        let pipeline = |direction| -> Result<ocio::Processor, ocio::Error> {
            let transform = ocio::DisplayViewTransform {
                direction,
                src: WORKING_SPACE.to_owned(),
                display: display.clone(),
                view: view.clone(),
                ..Default::default()
            };
            let mut legacy = ocio::apphelpers::legacy_viewing_pipeline::LegacyViewingPipeline::new();
            legacy.set_display_view_transform(Some(&transform));
            if !looks.is_empty() {
                legacy.set_looks_override_enabled(true);
                legacy.set_looks_override(&looks);
            }
            legacy.get_processor(&config)
        };
        let field = if doc.cube.is_some() { "cube" } else { "view" };
        let processor = pipeline(ocio::TransformDirection::Forward).map_err(|e| refuse(field, e.to_string()))?;
        let forward = processor.default_cpu_processor();
        let input = match doc.input_space.as_deref() {
            None => None,
            Some(DISPLAY_INPUT) => Some(
                pipeline(ocio::TransformDirection::Inverse)
                    .map_err(|e| refuse("input_space", format!("the inverse of {display} / {view}: {e}")))?
                    .default_cpu_processor(),
            ),
            Some(space) => {
                if config.get_color_space(space).is_none() {
                    return Err(refuse("input_space", format!("`{space}` is not a colour space of {config_name}")));
                }
                Some(
                    config
                        .get_processor(space, WORKING_SPACE)
                        .map_err(|e| refuse("input_space", e.to_string()))?
                        .default_cpu_processor(),
                )
            }
        };
        let shader =
            wgsl(&processor).map_err(|e| refuse(field, format!("no GPU shader for {display} / {view}: {e}")))?;
        let spaces = (0..config.num_color_spaces()).map(|i| config.color_space_name_by_index(i).to_owned()).collect();
        let key = crate::fingerprint::of(&(doc, &config_name, &display, &view, &looks));
        Ok(Self {
            doc: doc.clone(),
            config: config_name,
            display,
            view,
            looks,
            key,
            menus: Menus { displays, views, looks: looks_list, spaces },
            shader,
            forward,
            input,
            _extracted: extracted,
        })
    }

    /// [`Self::new`], kept among the last few resolved so a document's transform is made once.
    pub fn cached(doc: &ColorDoc) -> Result<Arc<Self>, ViewError> {
        static CACHE: Mutex<Vec<Arc<ViewTransform>>> = Mutex::new(Vec::new());
        if let Some(hit) = CACHE.lock().ok().and_then(|c| c.iter().find(|t| &t.doc == doc).cloned()) {
            return Ok(hit);
        }
        let made = Arc::new(Self::new(doc)?);
        if let Ok(mut cache) = CACHE.lock() {
            if cache.len() >= 8 {
                cache.remove(0);
            }
            cache.push(made.clone());
        }
        Ok(made)
    }

    /// The built-in default: [`DEFAULT_CONFIG`], its default display and view, no look.
    pub fn builtin() -> Arc<Self> {
        Self::cached(&ColorDoc::default()).expect("the built-in config's default view resolves")
    }

    /// The display value of one working-space colour: OCIO's CPU processor (display-encoded, not clamped;
    /// a value that is not finite comes out as 0).
    pub fn apply(&self, rgb: [f32; 3]) -> [f32; 3] {
        let mut p = [rgb[0], rgb[1], rgb[2], 1.0];
        self.forward.apply_rgba(&mut p);
        finite_rgb(p)
    }

    /// Display values of many colours at once (RGBA, in place; alpha untouched). The processor runs on every
    /// core, in chunks; a run of equal colours (a black background, a flat plate) is computed once: the ACES
    /// 2.0 views cost about 0.3 us a pixel on one core.
    pub fn apply_rgba(&self, pixels: &mut [[f32; 4]]) {
        use rayon::prelude::*;
        pixels.par_chunks_mut(4096).for_each(|chunk| {
            // The first colour of each run, all of a chunk's through the processor in one call (what `apply`
            // does to each: the same operators, value for value).
            let (mut runs, mut firsts) = (Vec::new(), Vec::new());
            let mut start = 0;
            while start < chunk.len() {
                let mut end = start + 1;
                while end < chunk.len() && chunk[end][..3] == chunk[start][..3] {
                    end += 1;
                }
                let c = chunk[start];
                runs.push(start..end);
                firsts.push([c[0], c[1], c[2], 1.0]);
                start = end;
            }
            self.forward.apply_rgba_slice(bytemuck::cast_slice_mut(&mut firsts));
            for (run, p) in runs.into_iter().zip(&firsts) {
                let p = finite_rgb(*p);
                for q in &mut chunk[run] {
                    q[..3].copy_from_slice(&p);
                }
            }
        });
    }

    /// A plate's own values (a PNG's encoded ones, an EXR's stored ones) converted to the working space by
    /// the input space; values that are not finite become 0.
    pub fn plate_to_working(&self, plate: &mut HdrImage) {
        if let Some(input) = &self.input {
            input.apply_rgba_slice(bytemuck::cast_slice_mut(&mut plate.pixels));
            for p in &mut plate.pixels {
                for v in &mut p[..3] {
                    if !v.is_finite() {
                        *v = 0.0;
                    }
                }
                p[3] = 1.0;
            }
        }
    }
}

/// The RGB of an RGBA value the processor gave, each channel that came out non-finite as 0 (no NaN or
/// infinity reaches an image).
fn finite_rgb(p: [f32; 4]) -> [f32; 3] {
    [p[0], p[1], p[2]].map(|v| if v.is_finite() { v } else { 0.0 })
}

/// The processor's WGSL shader and its resources (see [`WgslShader`]).
fn wgsl(processor: &ocio::Processor) -> Result<WgslShader, ocio::Error> {
    use ocio::gpu::{GpuShaderCreator, GpuShaderDesc};
    let gpu = processor.default_gpu_processor()?;
    let mut desc = GpuShaderDesc::new();
    desc.set_language(ocio::GpuLanguage::Wgsl);
    desc.set_function_name("ocio_display");
    desc.set_resource_prefix("ocio_");
    // 1D tables packed into 2D textures, as OCIO does for targets without 1D textures: OpenGL ES (wgpu's GL
    // backend, llvmpipe's OpenGL among them) has none, and there a 1D texture reads as zeros.
    desc.set_allow_texture_1d(false);
    desc.set_descriptor_set_index(WGSL_GROUP, 1)?;
    gpu.extract_gpu_shader_info(&mut desc)?;
    let bindings = desc.wgsl_bindings().ok_or_else(|| ocio::Error::msg("no WGSL bindings"))?;
    let mut textures = Vec::new();
    let mut add = |binding: u32, values: &[f32]| -> Result<(), ocio::Error> {
        let t = bindings
            .textures
            .iter()
            .find(|t| t.binding == binding)
            .ok_or_else(|| ocio::Error::msg(format!("no WGSL binding {binding}")))?;
        textures.push(WgslTexture {
            binding,
            dimensions: t.dimensions,
            size: [t.width, t.height, t.depth],
            rgba: t.format == ocio::gpu::wgsl::WgslTextureFormat::Rgba32Float,
            bytes: t.texel_data(values)?,
            filtered: false,
        });
        Ok(())
    };
    for i in 0..desc.num_textures() {
        add(desc.texture_shader_binding_index(i)?, desc.texture_values(i)?)?;
    }
    for i in 0..desc.num_3d_textures() {
        add(desc.texture_3d_shader_binding_index(i)?, desc.texture_3d_values(i)?)?;
    }
    let uniforms = match bindings.uniform_binding {
        Some(_) => Some(bindings.uniform_buffer(&desc)?),
        None => None,
    };
    // OCIO keeps some tables (the ACES 2.0 views' hues) as `var<private>` arrays: every invocation would
    // copy them into its own memory before reading a few entries. They become textures, as its others are.
    let mut text = desc.shader_text().to_owned();
    let free = textures.iter().map(|t| t.binding).max().unwrap_or(0) + 1;
    if let Some((rewritten, tables)) = private_arrays_as_textures(&text, free) {
        text = rewritten;
        textures.extend(tables);
    }
    Ok(WgslShader { text, textures, uniforms, sampler: None })
}

/// `text` with each module-scope `var<private> NAME: array<f32, N> = array<f32, N>(...)` made an `R32Float`
/// texture of N x 1 texels (2D: OpenGL ES has no 1D textures; bindings from `first_binding` in [`WGSL_GROUP`])
/// read by `NAME_at(i)`, the index clamped to the array as WGSL clamps an array's index; every `NAME[expr]`
/// becomes `NAME_at(i32(expr))`. `None` (the text kept as OCIO made it) when there is no such array or one
/// declaration is not of that form.
fn private_arrays_as_textures(text: &str, first_binding: u32) -> Option<(String, Vec<WgslTexture>)> {
    const PRIVATE: &str = "var<private> ";
    let mut out = text.to_owned();
    let mut textures = Vec::new();
    while let Some(start) = out.find(PRIVATE) {
        let rest = &out[start + PRIVATE.len()..];
        let (name, declared) = rest.split_once(':')?;
        let name = name.trim().to_owned();
        let declared = declared.trim_start();
        let values_start = declared.find('(')?;
        let values_end = declared.find(')')?;
        let head = &declared[..values_start];
        // `array<f32, N> = array<f32, N>`, nothing else.
        let (ty, init) = head.split_once('=')?;
        if !ty.trim().starts_with("array<f32,") || !init.trim().starts_with("array<f32,") {
            return None;
        }
        let values: Vec<f32> = declared[values_start + 1..values_end]
            .split(',')
            .map(|v| v.trim().trim_end_matches('f').parse::<f32>())
            .collect::<Result<_, _>>()
            .ok()?;
        if values.is_empty() || !values.iter().all(|v| v.is_finite()) || !declared[values_end..].starts_with(");") {
            return None;
        }
        let end = start + PRIVATE.len() + (rest.len() - declared.len()) + values_end + 2;
        let binding = first_binding + textures.len() as u32;
        let last = values.len() - 1;
        let declaration = format!(
            "@group({WGSL_GROUP}) @binding({binding}) var {name}_texture: texture_2d<f32>;\n\
             fn {name}_at(i: i32) -> f32 {{\n    \
             return textureLoad({name}_texture, vec2<i32>(clamp(i, 0, {last}), 0), 0).x;\n}}"
        );
        out.replace_range(start..end, &declaration);
        let index = format!("{name}[");
        while let Some(at) = out.find(&index) {
            let open = at + index.len() - 1;
            let mut depth = 0usize;
            let close = out[open..].char_indices().find_map(|(k, c)| {
                match c {
                    '[' => depth += 1,
                    ']' => {
                        depth -= 1;
                        if depth == 0 {
                            return Some(open + k);
                        }
                    }
                    _ => {}
                }
                None
            })?;
            let expr = out[open + 1..close].to_owned();
            out.replace_range(at..=close, &format!("{name}_at(i32({expr}))"));
        }
        textures.push(WgslTexture {
            binding,
            dimensions: 2,
            size: [values.len() as u32, 1, 1],
            rgba: false,
            bytes: bytemuck::cast_slice(&values).to_vec(),
            filtered: false,
        });
    }
    (!textures.is_empty()).then_some((out, textures))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_builtin_default_is_the_studio_configs_srgb_display() {
        let t = ViewTransform::builtin();
        assert_eq!(t.display, "sRGB - Display");
        assert!(t.view.starts_with("ACES"), "{}", t.view);
        let grey = t.apply([0.18, 0.18, 0.18]);
        assert!(grey.iter().all(|v| (0.2..0.6).contains(v)), "{grey:?}");
        assert_eq!(t.apply([f32::NAN, 0.0, 0.0])[0], 0.0);
        assert!(t.shader.text.contains("fn ocio_display("));
    }

    #[test]
    fn private_tables_become_textures_read_with_the_same_index() {
        let text = "var<private> t_hues: array<f32, 3> = array<f32, 3>(-1.5f, 0.0f, 2.25f);\n\
                    fn f(i: i32) -> f32 { return t_hues[i] + t_hues[min(i + 1, 2)] * t_hues[a[i]]; }";
        let (out, tables) = private_arrays_as_textures(text, 3).expect("one table");
        assert!(!out.contains("var<private>") && !out.contains("t_hues["), "{out}");
        assert!(out.contains("@group(1) @binding(3) var t_hues_texture: texture_2d<f32>;"), "{out}");
        assert!(out.contains("vec2<i32>(clamp(i, 0, 2), 0)"), "{out}");
        assert!(out.contains("t_hues_at(i32(i)) + t_hues_at(i32(min(i + 1, 2))) * t_hues_at(i32(a[i]))"), "{out}");
        assert_eq!(tables.len(), 1);
        assert_eq!((tables[0].binding, tables[0].dimensions, tables[0].size, tables[0].rgba), (3, 2, [3, 1, 1], false));
        assert_eq!(bytemuck::cast_slice::<u8, f32>(&tables[0].bytes), &[-1.5, 0.0, 2.25]);
        // What is not a table of f32 is left as OCIO wrote it.
        assert!(private_arrays_as_textures("var<private> n: i32 = 3;", 1).is_none());
        assert!(private_arrays_as_textures("var<private> v: array<f32, 2> = array<f32, 2>(1.0f, x);", 1).is_none());
        assert!(private_arrays_as_textures("fn f() {}", 1).is_none());
        // The built-in ACES 2.0 view's hue table is one.
        let shader = &ViewTransform::builtin().shader;
        assert!(!shader.text.contains("var<private>"));
        let hues = shader.textures.iter().find(|t| t.binding == 3).expect("the hue table at binding 3");
        assert_eq!(hues.size, [363, 1, 1]);
    }

    proptest::proptest! {
        /// Whatever text OCIO writes, the rewrite never panics, and a table it makes holds only finite values.
        #[test]
        fn the_rewrite_of_any_text_never_panics(
            head in "[a-z_ ]{0,6}",
            values in proptest::collection::vec(-1e6f32..1e6, 0..5),
            tail in "[\\[\\]();:=,<>a-z0-9 ]{0,40}",
            mangle in 0usize..60,
        ) {
            let list: Vec<String> = values.iter().map(|v| format!("{v:?}f")).collect();
            let mut text = format!(
                "{head}var<private> t: array<f32, {n}> = array<f32, {n}>({});\nfn f(i: i32) -> f32 {{ return t[i]; }}{tail}",
                list.join(", "),
                n = values.len()
            );
            // Cut off the end (the text is ASCII): a declaration broken off is kept as OCIO wrote it.
            text.truncate(text.len().saturating_sub(mangle));
            if let Some((out, tables)) = private_arrays_as_textures(&text, 1) {
                proptest::prop_assert!(!out.contains("var<private>"));
                for t in tables {
                    let v: Vec<f32> = bytemuck::pod_collect_to_vec(&t.bytes);
                    proptest::prop_assert!(v.iter().all(|x| x.is_finite()));
                }
            }
        }
    }

    #[test]
    fn unknown_names_are_refused_naming_the_field() {
        let bad = |doc: ColorDoc| ViewTransform::new(&doc).unwrap_err().field;
        assert_eq!(bad(ColorDoc { display: Some("Nope".into()), ..Default::default() }), "display");
        assert_eq!(bad(ColorDoc { view: Some("Nope".into()), ..Default::default() }), "view");
        assert_eq!(bad(ColorDoc { looks: Some("Nope".into()), ..Default::default() }), "looks");
        assert_eq!(bad(ColorDoc { input_space: Some("Nope".into()), ..Default::default() }), "input_space");
        assert_eq!(bad(ColorDoc { config: Some("/no/such.ocio".into()), ..Default::default() }), "config");
        assert_eq!(bad(ColorDoc { config: Some("ocio://nope".into()), ..Default::default() }), "config");
        assert_eq!(bad(ColorDoc { cube: Some("/no/such.cube".into()), ..Default::default() }), "cube");
    }

    /// Issue 61: a look list of 5,000 repeats (a 185 KB preset) ran past 60 s; now a repeat is refused at once.
    #[test]
    fn a_look_named_twice_is_refused_at_once() {
        let menus = ViewTransform::new(&ColorDoc::default()).unwrap().menus;
        let look = menus.looks.first().expect("the default config has a look").clone();
        let once = ColorDoc { looks: Some(look.clone()), ..Default::default() };
        ViewTransform::new(&once).unwrap();
        let repeats = ColorDoc { looks: Some(vec![look.as_str(); 5000].join(",")), ..Default::default() };
        let e = ViewTransform::new(&repeats).unwrap_err();
        assert_eq!(e.field, "looks");
        assert!(e.reason.contains("named twice"), "{}", e.reason);
    }
}
