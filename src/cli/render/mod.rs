//! `flarelab render`: a preset's frame (or the default document's) with flags that override its fields, drawn
//! by the one frame pipeline and written by the one writer.
//!
//! The document comes from `--preset` (a file or a shipped name) or is the default one, the same the app
//! starts with; LENS replaces its lens; each flag given replaces one field. The frame is then built from the
//! document exactly as the app builds it ([`flare_core::preset::Document::frame_request`],
//! [`flare_core::frame::Frame::build`]) and drawn on the GPU or its CPU twin; the ray-traced methods replace
//! only the ghosts' accumulation and go through the same writer.

use std::path::Path;

use anyhow::{Context, Result, bail};
use flare_core::flare::PreparedFlare;
use flare_core::frame::{self, Device, Frame, Sources};
use flare_core::lut::blend::LiveLut;
use flare_core::lut::format;
use flare_core::lut::{GhostLut, LutKind};
use flare_core::output::read_plate;
use flare_core::preset::{Document, LutSource};
use flare_core::raytrace::{self};

use flare_core::footage::pattern::FramePattern;
use flare_core::shot::{
    self,
    sequence::{FrameOutcome, SequenceOptions, ShotSources, render_sequence, write_log},
    track::read_track,
};
use flare_core::traced::TracedGhosts;
use indicatif::{ProgressBar, ProgressStyle};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

mod flags;

pub use flags::{
    CameraFlags, ColourFlags, DofFlags, Exposure, ExrTypeArg, FLAGS, FlagField, Layers, LightArg, LightFlags,
    LookFlags, Method, MethodFlags, OutputFlags, RenderArgs, ShotFlags, StopFlags, TonemapArg, document, flag_of,
};

use super::common::DeviceArg;

/// What the flare's exposure was and why.
fn exposure_line(doc: &Document) -> String {
    if doc.exposure_auto {
        format!(
            "flare exposure {:+.2} EV (auto: the brightest ghost at display level {}; --exposure-ev N locks it)",
            doc.flare_ev,
            flare_core::exposure::AUTO_DISPLAY_LEVEL
        )
    } else {
        format!("flare exposure {:+.2} EV", doc.flare_ev)
    }
}

/// The method: the flag, else what the document's LUT source implies.
fn method_of(args: &RenderArgs, doc: &Document) -> Method {
    args.method.kind.unwrap_or(match doc.blend.lut {
        LutSource::None => Method::Paraxial,
        LutSource::Simulated { .. } => Method::Blended,
        LutSource::Photo { .. } => Method::Photo,
    })
}

/// The LUT of the document's source: read from its file (checked against the lens), or baked in memory.
/// The LUT a blended or photo frame draws: `--lut`, the preset's, else the cached bake (baked now on a miss).
/// Given `near_theta_deg` (a still's light angle), only the images drawn at that angle are read from a file.
fn lut_for(doc: &Document, flare: &PreparedFlare, method: Method, near_theta_deg: Option<f64>) -> Result<GhostLut> {
    let path = match &doc.blend.lut {
        LutSource::Simulated { path } => path.clone(),
        LutSource::Photo { path } => Some(path.clone()),
        LutSource::None => None,
    };
    match path {
        Some(path) => {
            let path = Path::new(&path);
            let lut =
                format::read_lut_near(path, near_theta_deg).with_context(|| format!("reading {}", path.display()))?;
            lut.check_for(&doc.lens, &flare.config).with_context(|| path.display().to_string())?;
            if method == Method::Photo && lut.kind != LutKind::Photo {
                bail!("{}: --method photo needs a photo LUT (this one is ray-traced)", path.display());
            }
            Ok(lut)
        }
        None if method == Method::Photo => bail!("--method photo needs --lut F.flut (made by `flarelab photo-lut`)"),
        None => {
            if let Err(why) = flare_core::lut::Symmetry::of(&doc.lens, &flare.config.aperture) {
                // Said before any classification or device probing: the bake would refuse it after.
                bail!("--method blended: no LUT ghosts: {why}");
            }
            // The LUT baked for this lens and these settings: the app's and this command's shared cache, else
            // baked now (and cached for next time).
            let settings = flare_core::bake::BakeSettings::default();
            let cache = flare_core::bake::cache::LutCache::user();
            if let Some(cache) = &cache {
                match cache.load_near(&doc.lens, &flare.config, &settings, near_theta_deg) {
                    flare_core::bake::cache::Lookup::Hit(lut) => {
                        eprintln!("LUT ghosts from the cache ({})", cache.dir.display());
                        return Ok(*lut);
                    }
                    flare_core::bake::cache::Lookup::Rejected(reason) => eprintln!("{reason}: baking it again"),
                    flare_core::bake::cache::Lookup::Miss => {}
                }
            }
            let renderer = flare.ray_grid_renderer();
            let choice = super::lut::LutChoice::default();
            let gpu = super::lut::bake_gpu(crate::cli::common::DeviceArg::Auto, false)?;
            let lut = super::lut::bake_lut(flare, &renderer, &choice, &settings, None, gpu.as_ref(), false)?.0;
            if let Some(cache) = &cache {
                match cache.store(&doc.lens, &flare.config, &settings, &lut) {
                    Ok(path) => eprintln!("cached the LUT as {}", path.display()),
                    Err(e) => eprintln!("the LUT could not be cached in {}: {e}", cache.dir.display()),
                }
            }
            Ok(lut)
        }
    }
}

pub fn run(args: &RenderArgs) -> Result<()> {
    if args.output.timings {
        flare_core::timing::start();
    }
    let started = std::time::Instant::now();
    let result = run_timed(args);
    if args.output.timings {
        print_timings(&flare_core::timing::finish(), started.elapsed());
    }
    result
}

/// `--timings`: the spans the command made, indented under the span they lie in, and the command's whole time.
fn print_timings(spans: &[flare_core::timing::Span], total: std::time::Duration) {
    eprintln!("timings (wall ms; an indented span lies inside the one above it):");
    for s in spans {
        let indent = (2 * s.depth).min(16);
        eprintln!("  {:indent$}{:<width$} {:>9.1}", "", s.name, s.ms, width = 32 - indent);
    }
    let top: f64 = spans.iter().filter(|s| s.depth == 0).map(|s| s.ms).sum();
    let total_ms = total.as_secs_f64() * 1e3;
    eprintln!("  {:<32} {:>9.1}", "the rest (checks, messages)", (total_ms - top).max(0.0));
    eprintln!("  {:<32} {:>9.1}", "the command (from its arguments)", total_ms);
}

fn run_timed(args: &RenderArgs) -> Result<()> {
    use flare_core::timing::span;
    let mut doc = span("read the document", || document(args))?;
    let method = method_of(args, &doc);
    let grid = grid_of(args, method)?;
    settle_lut_source(args, &mut doc, method)?;
    let choice = doc.layer_choice(args.output.layers == Some(Layers::Ghosts));
    // Everything that can be refused is checked before any work: the output's name and type, the range, the
    // plate, the track.
    let sequence = output_pattern(args, &doc, grid, choice)?;
    let range = frame_range(args, &doc)?;
    let track = args
        .light
        .track
        .as_deref()
        .map(|p| read_track(p).map_err(|e| anyhow::anyhow!("--track {}: {e}", p.display())))
        .transpose()?;
    let config = doc.flare_config().map_err(|e| anyhow::anyhow!("{e}"))?;
    let flare =
        span("prepare the lens", || PreparedFlare::new(&doc.lens, &config)).with_context(|| doc.lens.id.clone())?;
    doc.resolve_exposure(&flare.system);
    if let (Some(rows), Some(path)) = (&track, &args.light.track) {
        let (width, height) = shot::plan::frame_size(&doc, &range, args.output.size)?;
        let (position, intensity) =
            shot::track::to_keys(rows, &flare.system.mapping, doc.sensor_width_mm, (width, height), doc.desqueeze)
                .map_err(|e| anyhow::anyhow!("--track {}: {e}", path.display()))?;
        doc.timeline.light_deg = position;
        if !intensity.is_empty() {
            doc.timeline.light_ev = intensity;
        }
    }
    let mut device = device_for(args.method.device, grid)?;
    let cancel = AtomicBool::new(false);
    let plan = plan_shot(args, &doc, &flare, range, &cancel)?;
    // A still without motion blur draws the LUT's images at one light angle: only those are read.
    let near_theta_deg = match plan.frames.as_slice() {
        [still] if doc.timeline.shutter_deg <= 0.0 => {
            let u = flare_core::ghost::light_slopes_for_frame_position(still.light_deg[0], still.light_deg[1]);
            Some(flare_core::lut::light_direction_deg(u).0)
        }
        _ => None,
    };
    let lut = match method {
        Method::Blended | Method::Photo => {
            Some(span("load the LUT", || lut_for(&doc, &flare, method, near_theta_deg).map(LiveLut::new))?)
        }
        _ => None,
    };
    // The ray-traced methods write their accumulation at the frame's full size.
    let divisor = if grid.is_some() { 1 } else { args.method.accumulation_divisor };
    // The ray-traced methods trace each frame's ghosts, stills and sequences alike (`flare_core::traced`).
    let traced = grid.map(|n| Arc::new(TracedGhosts::new(&flare, n, args.method.gpu_samples, &device)));
    let Some(out) = sequence else {
        let still = Still { doc: &doc, flare: &flare, lut: lut.as_ref(), plan: &plan, divisor, choice };
        return render_still(args, &mut device, &still, traced.as_deref());
    };
    let sources = ShotSources { doc: &doc, flare: &flare, lut: lut.as_ref(), plan: &plan };
    let options = SequenceOptions {
        out,
        layers: choice,
        skip_existing: args.shot.skip_existing,
        divisor,
        parallel_frames: !args.shot.frames_in_turn,
        traced,
    };
    let result = render_frames(args, &mut device, &sources, &options, &cancel);
    eprintln!("{}", exposure_line(&doc));
    result
}

/// The ray grid of the method: `--grid` for `raygrid`, the converged reference's, none for the paraxial
/// methods (which refuse `--grid`).
fn grid_of(args: &RenderArgs, method: Method) -> Result<Option<raytrace::Grid>> {
    let grid = match (method, args.method.grid) {
        (Method::Paraxial | Method::Blended | Method::Photo, Some(_)) => {
            bail!("--grid applies to --method raygrid or reference")
        }
        (Method::Paraxial | Method::Blended | Method::Photo, None) => None,
        (Method::Raygrid, None) => bail!("--method raygrid needs --grid N (Hullin 2011 used 16 to 128)"),
        (Method::Raygrid, Some(n)) => Some(raytrace::Grid::Fixed(n)),
        (Method::Reference, n) => Some(raytrace::Grid::Adaptive(n.unwrap_or(raytrace::REFERENCE_GRID))),
    };
    if let Some(n) = grid.map(raytrace::Grid::cells)
        && !raytrace::GRID_RANGE.contains(&n)
    {
        bail!("--grid {n}: use {} to {}", raytrace::GRID_RANGE.start(), raytrace::GRID_RANGE.end());
    }
    Ok(grid)
}

/// The document's LUT source as the method needs it (`--lut` a photo LUT for `photo`; none for the ray-traced
/// methods), and the method's other flags checked.
fn settle_lut_source(args: &RenderArgs, doc: &mut Document, method: Method) -> Result<()> {
    if args.method.lut.is_some() && !matches!(method, Method::Blended | Method::Photo) {
        bail!("--lut applies to --method blended or photo");
    }
    if method == Method::Photo
        && let Some(path) = &args.method.lut
    {
        doc.blend.lut = LutSource::Photo { path: path.display().to_string() };
    }
    match method {
        Method::Blended if doc.blend.lut == LutSource::None => doc.blend.lut = LutSource::Simulated { path: None },
        Method::Blended | Method::Photo => {}
        _ => doc.blend.lut = LutSource::None,
    }
    if args.method.gpu_samples > 8 {
        bail!("--gpu-samples {}: use 0 (the box filter) or 1 to 8 samples a pixel across", args.method.gpu_samples);
    }
    if ![1, 2, 4].contains(&args.method.accumulation_divisor) {
        bail!("--accumulation-divisor {}: use 1, 2 or 4", args.method.accumulation_divisor);
    }
    Ok(())
}

/// `-o` checked before any work: a sequence's pattern (`Some`) or a still's file, its type against the layers,
/// the ray-traced methods' limits, and that its folder takes files.
fn output_pattern(
    args: &RenderArgs,
    doc: &Document,
    grid: Option<raytrace::Grid>,
    choice: frame::LayerChoice,
) -> Result<Option<FramePattern>> {
    let out = &args.output.out;
    let out_text = out.display().to_string();
    let out_pattern = FramePattern::parse(&out_text).map_err(|e| anyhow::anyhow!("-o {e}"))?;
    let sequence = match (args.shot.frames, out_pattern) {
        (Some(_), Some(pattern)) => Some(pattern),
        (Some(_), None) => bail!(
            "-o {out_text}: a sequence needs a frame field in the file name, e.g. out/flare.####.exr or \
             out/flare.%04d.exr"
        ),
        (None, Some(_)) => bail!("-o {out_text}: the name has a frame field; give --frames A-B to render a sequence"),
        (None, None) => None,
    };
    if grid.is_some() && doc.auto_light.is_some() {
        bail!("--light auto applies to the paraxial, blended and photo methods");
    }
    if grid.is_some() && doc.timeline.shutter_deg > 0.0 {
        bail!(
            "--shutter-deg {}: motion blur applies to the paraxial, blended and photo methods (a ray-traced frame \
             is traced at one instant); give --shutter-deg 0",
            doc.timeline.shutter_deg
        );
    }
    frame::check_output(out, choice).map_err(|e| match e {
        frame::FrameError::Request(reason) => anyhow::anyhow!("--layers ghosts: {reason}"),
        other => anyhow::anyhow!("{other}"),
    })?;
    // The folder takes the files now, before a bake, a trace or the first frame (a sequence makes its folder).
    match sequence {
        Some(_) => flare_core::files::check_sequence_target(out),
        None => flare_core::files::check_target(out),
    }
    .map_err(|e| anyhow::anyhow!("-o {e}"))?;
    Ok(sequence)
}

/// The frames drawn (`--frames`, else the still's `--frame` or the timeline's first), checked against the
/// plate sequence, with the plate that a still or the light found needs.
fn frame_range(args: &RenderArgs, doc: &Document) -> Result<std::ops::RangeInclusive<i64>> {
    let range = match args.shot.frames {
        Some((a, b)) => a..=b,
        None => {
            let f = args.shot.frame.unwrap_or(doc.timeline.first_frame);
            f..=f
        }
    };
    shot::plan::check_range(doc, &range).map_err(|e| anyhow::anyhow!("--background: {e}"))?;
    if doc.auto_light.is_some() && doc.background.is_none() {
        bail!("--light auto finds the light in the plate: give --background (a plate or a sequence)");
    }
    if let Some(background) = doc.background.as_deref()
        && !FramePattern::is_pattern(background)
    {
        read_plate(Path::new(background)).context("--background: the plate cannot be used")?;
    }
    Ok(range)
}

/// Where the frame is drawn: `--device`, except the reference, which is the f64 CPU tracer (ray grids trace
/// on the GPU too, `render::raygrid`).
fn device_for(device: DeviceArg, grid: Option<raytrace::Grid>) -> Result<Device> {
    Ok(match (device, grid) {
        (DeviceArg::Gpu, Some(raytrace::Grid::Adaptive(_))) => bail!(
            "--device gpu: the reference is the f64 CPU tracer; for ray grids on the GPU use --method raygrid --grid N"
        ),
        (_, Some(raytrace::Grid::Adaptive(_))) | (DeviceArg::Cpu, _) => Device::Cpu,
        (DeviceArg::Gpu, _) => Device::gpu(false).map_err(|e| anyhow::anyhow!("{e} (or use --device cpu)"))?,
        (DeviceArg::Auto, _) => Device::gpu(false).unwrap_or_else(|e| {
            eprintln!("no GPU ({e}): drawing on the CPU twin");
            Device::Cpu
        }),
    })
}

/// Every frame of `range` planned (the light, its gain, the plate), with a progress bar while the light is
/// found in a sequence's plates.
fn plan_shot(
    args: &RenderArgs,
    doc: &Document,
    flare: &PreparedFlare,
    range: std::ops::RangeInclusive<i64>,
    cancel: &AtomicBool,
) -> Result<shot::ShotPlan> {
    let scanning = (doc.auto_light.is_some() && range.clone().count() > 1)
        .then(|| progress_bar(range.clone().count(), "finding the light"));
    let plan = flare_core::timing::span("plan the shot", || {
        shot::plan::plan(
            doc,
            &flare.system,
            range,
            args.output.size,
            &|done, _| {
                if let Some(bar) = &scanning {
                    bar.set_position(done as u64);
                }
            },
            cancel,
        )
    })?;
    if let Some(bar) = scanning {
        bar.finish_and_clear();
    }
    Ok(plan)
}

/// What a still is drawn from.
struct Still<'a> {
    doc: &'a Document,
    flare: &'a PreparedFlare,
    lut: Option<&'a LiveLut>,
    plan: &'a shot::ShotPlan,
    divisor: u32,
    choice: frame::LayerChoice,
}

/// Draws and writes the still (its plate defocused where the document asks), then says what was drawn.
fn render_still(args: &RenderArgs, device: &mut Device, still: &Still, traced: Option<&TracedGhosts>) -> Result<()> {
    use flare_core::timing::span;
    let Still { doc, flare, lut, plan, divisor, choice } = *still;
    let planned = &plan.frames[0];
    let plate = still_plate(doc, flare, planned.frame, planned.plate.as_deref())?;
    let request = plan.request(doc, &flare.system, planned, divisor);
    let frame = span("build the frame", || Frame::build(flare, lut, &request));
    let sources = Sources { flare, lut, plate: plate.as_ref() };
    let out = &args.output.out;
    match traced {
        Some(t) => {
            // Ray-traced ghosts replace the paraxial accumulation; starburst, tonemap and writer are the same.
            let traced =
                span("draw and write (ray-traced)", || t.render_to_file(device, &frame, &sources, choice, out))?;
            eprintln!("{traced}");
        }
        None => {
            let made = span("draw", || frame::draw_for_file(device, &frame, &sources, choice, out))?;
            span("write", || frame::write_made(device, &frame, &sources, &made, choice, out))?;
            eprintln!("rendered on {}", device.name());
        }
    }
    eprintln!("{}", exposure_line(doc));
    report_still(args, still, &frame);
    Ok(())
}

/// The still's plate, then its depth of field: each error blamed on what caused it (a bad depth map is not the
/// plate's); what the depth of field does, said.
fn still_plate(
    doc: &Document,
    flare: &PreparedFlare,
    frame: i64,
    plate: Option<&Path>,
) -> Result<Option<flare_core::image::HdrImage>> {
    let plate = match plate {
        Some(p) => match shot::plate::frame_plate(doc, flare, frame, p) {
            Ok((plate, warning)) => {
                if let Some(warning) = warning {
                    eprintln!("warning: {warning}");
                }
                Some(plate)
            }
            Err(shot::plate::FramePlateError::Plate(e)) => {
                return Err(anyhow::anyhow!(e))
                    .with_context(|| format!("--background: frame {frame}: the plate cannot be used"));
            }
            Err(shot::plate::FramePlateError::DepthOfField(e)) => bail!("frame {frame}: {e}"),
        },
        None => None,
    };
    if doc.dof.enabled {
        match &plate {
            Some(_) => eprintln!(
                "depth of field: {} method, focus {}, f/{:.1}",
                doc.dof.method.word(),
                doc.dof.focus_px.map_or(format!("{} m", doc.dof.focus_m), |[x, y]| format!("on pixel ({x}, {y})")),
                flare.system.first_order.f_number / flare.system.settings.stop_scale
            ),
            None => {
                eprintln!("the preset's depth of field is on, but there is no plate to defocus (give --background)")
            }
        }
    }
    Ok(plate)
}

/// What the still drew: motion blur, the display, the ghosts, sprites and LUT images.
fn report_still(args: &RenderArgs, still: &Still, frame: &Frame) {
    let Still { doc, flare, lut, plan, .. } = *still;
    if let Some(s) = &frame.shutter {
        eprintln!(
            "motion blur ({} degree shutter): up to {} time samples, {:.1} a ghost on average; the fastest ghost moves \
             {:.1} px while it is open, at most {:.2} px between samples",
            doc.timeline.shutter_deg,
            s.count,
            s.mean_per_ghost(),
            s.longest_px,
            s.max_gap_px
        );
    }
    if doc.tonemap == flare_core::color::Tonemap::View
        && let Some(view) = &frame.request.view
    {
        let looks = if view.looks.is_empty() { String::new() } else { format!(", looks {}", view.looks) };
        eprintln!("display: {} / {}{looks} ({})", view.display, view.view, view.config);
    }
    let st = frame.sprites.stats;
    eprintln!(
        "wrote {} ({}x{}): {} ghosts x {} wavelengths, {} sprites drawn, culled {} dim / {} off sensor / {} empty entrance{}",
        args.output.out.display(),
        plan.width,
        plan.height,
        flare.system.ghosts.len(),
        flare.config.spectrum.len(),
        frame.scene.instances.len(),
        st.below_threshold,
        st.off_sensor,
        st.empty_entrance_region,
        match (lut, &frame.lut) {
            (Some(live), Some(l)) =>
                format!(", {} LUT images from {} LUT ghosts", l.instances.len(), live.lut.ghosts.len()),
            _ => String::new(),
        }
    );
}

/// A terminal progress bar with the rate and the time left.
fn progress_bar(total: usize, what: &str) -> ProgressBar {
    let bar = ProgressBar::new(total as u64);
    let style = ProgressStyle::with_template("{msg} [{bar:40}] {pos}/{len} frames, {per_sec}, ETA {eta}")
        .unwrap_or_else(|_| ProgressStyle::default_bar())
        .progress_chars("=> ");
    bar.set_style(style);
    bar.set_message(what.to_string());
    bar
}

/// `frames` for a message: at most 10 numbers, then how many more (`frames 1, 2, 3 and 997 more`).
fn frame_list(frames: impl Iterator<Item = i64>) -> String {
    let all: Vec<i64> = frames.collect();
    let shown: Vec<String> = all.iter().take(10).map(i64::to_string).collect();
    let more = all.len().saturating_sub(10);
    let word = if all.len() == 1 { "frame" } else { "frames" };
    if more == 0 {
        format!("{word} {}", shown.join(", "))
    } else {
        format!("{word} {} and {more} more", shown.join(", "))
    }
}

/// Renders the planned frames to the sequence `out` with a progress bar; the log when asked; an error (a
/// non-zero exit) when any frame failed, after all the others were rendered.
fn render_frames(
    args: &RenderArgs,
    device: &mut Device,
    sources: &ShotSources,
    options: &SequenceOptions,
    cancel: &AtomicBool,
) -> Result<()> {
    if let Some(dir) = Path::new(&options.out.text).parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("-o: cannot create {}", dir.display()))?;
    }
    let total = sources.plan.frames.len();
    let bar = progress_bar(total, "rendering");
    let started = std::time::Instant::now();
    let report = render_sequence(
        device,
        sources,
        options,
        &|record, done, _| {
            bar.set_position(done as u64);
            if let FrameOutcome::Failed(e) = &record.outcome {
                bar.suspend(|| eprintln!("failed: {e}"));
            }
        },
        cancel,
    );
    bar.finish_and_clear();
    if let Some(log) = &args.shot.log {
        write_log(log, &report).with_context(|| format!("--log {}", log.display()))?;
    }
    if let Some(warning) = &report.plate_warning {
        eprintln!("warning: {warning}");
    }
    let median = report.median_ms();
    eprintln!(
        "{} of {total} frames rendered ({} skipped, {} failed) in {:.1} s on {}, {}x{}: median {median:.0} ms a frame",
        report.rendered(),
        report.skipped(),
        report.failed(),
        started.elapsed().as_secs_f64(),
        device.name(),
        sources.plan.width,
        sources.plan.height,
    );
    let failed = report.failures();
    if !failed.is_empty() {
        // Exactly what was written: none, all but the failed ones, or the rest skipped as already there.
        let frames = frame_list(failed.iter().map(|(f, _)| *f));
        let others = match (report.rendered(), report.skipped()) {
            (0, 0) => "no frame was written".to_string(),
            (0, s) => format!("{s} were already there (skipped); none was written"),
            (r, 0) => format!("the other {r} were written"),
            (r, s) => format!("{r} were written and {s} already there (skipped)"),
        };
        bail!("{} of {total} frames failed ({frames}; the first: {}); {others}", failed.len(), failed[0].1);
    }
    Ok(())
}
