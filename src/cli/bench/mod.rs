//! `flarelab bench`: every method renders the same frames; run time against error, on one chart.
//!
//! For each lens and light angle the reference renderer ([`flare_core::raytrace`] at its converged grid)
//! renders the ghosts once; then each method renders the same frame (same size, spectrum, aperture, coatings)
//! several times: the median wall-clock time is reported, and its image is compared with the reference by
//! [`flare_core::metrics`] (ghosts only, exposure fixed from the reference, PSNR / SSIM on the tonemapped
//! display values, relative L1 of linear energy, median per-ghost centroid error). What is timed is the
//! per-frame work of each method, after its per-lens preparation (the paraxial matrices, the ray-grid tracers),
//! as the app does it: paraxial = sprites for the light + the CPU twin's ghost pass (rayon over bands of rows);
//! paraxial-half = the same accumulated at half resolution and upsampled (the app's choice on software
//! adapters); paraxial-gpu = sprites + the wgpu renderer's draw, waited for (when an adapter exists, lavapipe
//! included); blended = paraxial with the lens's LUT ghosts (classified and baked once per lens at the default
//! settings, bake time and file size reported in their own table), sprites + LUT instances + the CPU twin's two
//! passes; raygrid-N / reference = tracing and splatting every ghost (rayon over ghosts).
//!
//! Writes `bench.csv`, `bench.md` (the tables that `--update-readme` puts into a Markdown page between the
//! `<!-- bench:start -->` and `<!-- bench:end -->` markers: `docs/ground-truth.md`) and `bench.png` (error against run time).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use flare_core::files::write_atomic;
use flare_core::flare::{FlareConfig, PreparedFlare};
use flare_core::frame::{self, Frame, FrameRequest, GpuDrawer, LutUse, Sources};
use flare_core::image::{DisplayImage, HdrImage, Sampling};
use flare_core::metrics::{self, Comparison};
use flare_core::raytrace::{Grid, REFERENCE_GRID, RayGridImage};
use flare_core::render::{DisplaySettings, FlareScene, cpu, gpu};

pub mod plot;

pub use plot::Row;

pub mod dof;

use super::common::open_lens;

/// Azimuth of the light in the frame (degrees from the horizontal): off the axes, so that nothing is
/// symmetric by accident.
pub const LIGHT_AZIMUTH_DEG: f64 = 30.0;
const README_START: &str = "<!-- bench:start -->";
const README_END: &str = "<!-- bench:end -->";

#[derive(clap::Args, Debug)]
pub struct BenchArgs {
    /// Two lenses (the Double Gauss and the 28-surface Nikon zoom), three angles, coarse grids: under 10 minutes
    /// on 2 cores.
    #[arg(long)]
    pub quick: bool,
    /// Lens files or built-in names (repeatable; default: every built-in lens, or the quick pair).
    #[arg(long)]
    pub lens: Vec<String>,
    /// Light angles from the axis, degrees, comma-separated (default 0,10,20 quick, 0,5,10,15,20,25 full).
    #[arg(long)]
    pub field_deg: Option<String>,
    /// Image size (the default is the 3:2 of a full-frame sensor; 960x540 with --dof).
    #[arg(long)]
    pub size: Option<String>,
    /// Ray-grid sizes to benchmark (default 16,32,64 quick, 16,32,64,128 full).
    #[arg(long)]
    pub grids: Option<String>,
    /// Grid of the reference renderer.
    #[arg(long, default_value_t = REFERENCE_GRID)]
    pub reference_grid: usize,
    /// Timed runs per method (the median is reported; a method whose first run takes over 2 s runs once).
    #[arg(long)]
    pub repeats: Option<usize>,
    /// Also replace the benchmark section (between its markers) of this Markdown page with the new tables: the
    /// book's `docs/ground-truth.md` (`docs/depth-of-field.md` with `--dof`).
    #[arg(long)]
    pub update_readme: Option<PathBuf>,
    /// Also write every method's image (ghosts only, at the reference's exposure, ACES, sRGB) to OUT/images.
    #[arg(long)]
    pub images: bool,
    /// The depth of field instead of the flare: its reference and live method (CPU twin and GPU) on the
    /// synthetic street, error against run time, and the live method's frame time at 1920x1080 (default lens:
    /// the Master Prime; --size for the error rows, default 960x540 here).
    #[arg(long)]
    pub dof: bool,
    /// Output folder.
    #[arg(short = 'o', long = "out", alias = "output")]
    pub out: PathBuf,
    /// Which ghosts the blended method bakes.
    #[command(flatten)]
    pub lut: super::lut::LutChoice,
    /// Most texels across a LUT entry of the blended method.
    #[arg(long, default_value_t = flare_core::bake::BakeSettings::default().res)]
    pub lut_res: u32,
}

/// Image change as the reference grid doubles.
#[derive(Clone, Debug)]
struct Convergence {
    lens: String,
    field_deg: f64,
    grid: usize,
    /// Against the image at half this grid.
    vs_half: Comparison,
    ms: f64,
}

fn parse_list<T: std::str::FromStr>(text: &str, what: &str) -> Result<Vec<T>> {
    text.split(',')
        .map(|s| s.trim().parse::<T>().map_err(|_| anyhow::anyhow!("{what}: `{s}` is not a number")))
        .collect()
}

/// A run slower than this is not repeated (its noise is small against its length).
const REPEAT_BELOW_MS: f64 = 2000.0;

/// Median wall-clock milliseconds of up to `runs` calls of `f` (one when the first takes longer than
/// [`REPEAT_BELOW_MS`]), how many ran, and the last result.
fn timed<T>(runs: usize, mut f: impl FnMut() -> Result<T>) -> Result<(f64, usize, T)> {
    let mut times = Vec::with_capacity(runs);
    let mut last = None;
    for _ in 0..runs.max(1) {
        let started = Instant::now();
        let value = f()?;
        times.push(started.elapsed().as_secs_f64() * 1e3);
        last = Some(value);
        if times[0] > REPEAT_BELOW_MS {
            break;
        }
    }
    Ok((metrics::median(&times), times.len(), last.expect("at least one run")))
}

/// Frame position (X, Y field angles in degrees) of a light `theta_deg` from the axis at [`LIGHT_AZIMUTH_DEG`].
pub fn light_position_deg(theta_deg: f64) -> [f64; 2] {
    let t = theta_deg.to_radians().tan();
    let phi = LIGHT_AZIMUTH_DEG.to_radians();
    [(t * phi.cos()).atan().to_degrees(), (t * phi.sin()).atan().to_degrees()]
}

/// What a run measures, from its flags.
struct Plan {
    width: u32,
    height: u32,
    lenses: Vec<String>,
    fields: Vec<f64>,
    grids: Vec<usize>,
    reference_grid: usize,
    repeats: usize,
    /// Where `--images` writes every method's image.
    images: Option<PathBuf>,
}

impl Plan {
    /// The plan of `args`, every flag checked (and the README's section found) before any benchmarking.
    fn new(args: &BenchArgs) -> Result<Self> {
        let (width, height) = flare_core::frame::parse_size(args.size.as_deref().unwrap_or("480x320"))
            .map_err(|e| anyhow::anyhow!("--size: {e}"))?;
        let lenses: Vec<String> = if !args.lens.is_empty() {
            args.lens.clone()
        } else if args.quick {
            vec!["pbrt_dgauss_50mm".into(), "nikon_zoom_28_75mm".into()]
        } else {
            flare_core::optics::library::ids().into_iter().map(str::to_owned).collect()
        };
        let fields: Vec<f64> = parse_list(
            args.field_deg.as_deref().unwrap_or(if args.quick { "0,10,20" } else { "0,5,10,15,20,25" }),
            "--field-deg",
        )?;
        if let Some(bad) = fields.iter().find(|f| !(f.is_finite() && (0.0..=89.0).contains(*f))) {
            bail!("--field-deg {bad}: angles from 0 to 89 degrees");
        }
        let grids: Vec<usize> = parse_list(
            args.grids.as_deref().unwrap_or(if args.quick { "16,32,64" } else { "16,32,64,128" }),
            "--grids",
        )?;
        let reference_grid = args.reference_grid;
        for &g in grids.iter().chain([&reference_grid]) {
            if !flare_core::raytrace::GRID_RANGE.contains(&g) {
                bail!("grid {g}: use 2 to 4096 cells across");
            }
        }
        if let Some(readme) = &args.update_readme {
            // Refuse before an hour of benchmarking, not after.
            readme_section(readme, (README_START, README_END))?;
        }
        let repeats = checked_repeats(args.repeats, if args.quick { 3 } else { 5 })?;
        std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
        let images = args.images.then(|| args.out.join("images"));
        if let Some(dir) = &images {
            std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        }
        Ok(Self { width, height, lenses, fields, grids, reference_grid, repeats, images })
    }
}

/// Everything a run measured.
#[derive(Default)]
struct Results {
    rows: Vec<Row>,
    convergence: Vec<Convergence>,
    bakes: Vec<Bake>,
    /// GPU ray grids against CPU ray grids at the same grid: (lens, angle, grid, comparison).
    twins: Vec<(String, f64, usize, Comparison)>,
}

pub fn run(args: &BenchArgs) -> Result<()> {
    let plan = Plan::new(args)?;
    let mut gpu = match GpuBench::new(plan.width, plan.height) {
        Ok(gpu) => Some(gpu),
        Err(e) => {
            eprintln!("no paraxial-gpu rows: {e}");
            None
        }
    };
    let started = Instant::now();
    let mut results = Results::default();
    for name in &plan.lenses {
        let lens = open_lens(name)?;
        let flare = PreparedFlare::new(&lens, &FlareConfig::default()).with_context(|| name.clone())?;
        let tracer = flare.ray_grid_renderer();
        let live = bake_for_blended(args, &flare, &tracer, &mut results, started)?;
        let lens_bench = LensBench { plan: &plan, flare: &flare, tracer: &tracer, live: &live, started };
        for (k, &theta) in plan.fields.iter().enumerate() {
            lens_bench.angle(theta, k == 0, gpu.as_mut(), &mut results)?;
        }
    }
    write_results(args, &plan, &results, gpu.as_ref(), started.elapsed().as_secs_f64())
}

/// The blended method's LUT of `flare`: classified and baked at the default settings, timed and measured once,
/// and kept beside the tables (so that the blended rows can be timed again: `blend_timing`).
fn bake_for_blended(
    args: &BenchArgs,
    flare: &PreparedFlare,
    tracer: &flare_core::raytrace::RayGridRenderer,
    results: &mut Results,
    started: Instant,
) -> Result<flare_core::lut::blend::LiveLut> {
    let lens = &flare.system.lens;
    let settings = flare_core::bake::BakeSettings { res: args.lut_res, ..Default::default() };
    let (lut, _, bake_s) = super::lut::bake_lut(flare, tracer, &args.lut, &settings, None, None, true)?;
    let lut_bytes = flare_core::lut::format::write_lut(&args.out.join(format!("{}.flut", lens.id)), &lut)
        .with_context(|| format!("writing the LUT of {}", lens.id))?;
    results.bakes.push(Bake {
        lens: lens.id.clone(),
        surfaces: lens.surfaces.len(),
        ghosts: flare.system.ghosts.len(),
        lut_ghosts: lut.ghosts.len(),
        entries: lut.entry_count(),
        seconds: bake_s,
        megabytes: lut_bytes as f64 / 1e6,
        theta_max_deg: lut.theta_max_deg,
    });
    eprintln!(
        "[{:6.1} s] {}: baked {} LUT ghosts ({} entries) in {bake_s:.1} s, {:.1} MB",
        started.elapsed().as_secs_f64(),
        lens.id,
        lut.ghosts.len(),
        lut.entry_count(),
        lut_bytes as f64 / 1e6
    );
    Ok(flare_core::lut::blend::LiveLut::new(lut))
}

/// One lens's benchmark: what every light angle of it measures with.
struct LensBench<'a> {
    plan: &'a Plan,
    flare: &'a PreparedFlare,
    tracer: &'a flare_core::raytrace::RayGridRenderer,
    live: &'a flare_core::lut::blend::LiveLut,
    started: Instant,
}

/// One light angle of one lens: its reference, and each method's row against it.
struct AngleBench<'a> {
    lens: &'a LensBench<'a>,
    theta: f64,
    light: [f64; 2],
    truth: metrics::Reference<'a>,
}

impl AngleBench<'_> {
    /// A row of the table for `method`.
    fn row(&self, method: String, ms_median: f64, runs: usize, errors: Comparison) -> Row {
        let flare = self.lens.flare;
        Row {
            lens: flare.system.lens.id.clone(),
            surfaces: flare.system.lens.surfaces.len(),
            ghosts: flare.system.ghosts.len(),
            field_deg: self.theta,
            method,
            ms_median,
            runs,
            errors,
            gpu: None,
        }
    }

    /// `method`'s image against the reference, and written out with `--images`.
    fn against(&self, method: &str, image: &HdrImage, moments: &[metrics::GhostMoments]) -> Result<Comparison> {
        if let Some(dir) = &self.lens.plan.images {
            let name = format!("{}_{}deg_{method}.png", self.lens.flare.system.lens.id, self.theta);
            write_display(&dir.join(name), image, self.truth.exposure)?;
        }
        Ok(self.truth.compare(image, moments))
    }

    /// The ray-traced image of this light at `grid`.
    fn trace(&self, grid: Grid) -> Result<RayGridImage> {
        self.lens.trace(self.light, grid)
    }
}

impl LensBench<'_> {
    /// The ray-traced image of the light at `light` (degrees) at `grid`.
    fn trace(&self, light: [f64; 2], grid: Grid) -> Result<RayGridImage> {
        Ok(self.tracer.render(light, self.plan.width, self.plan.height, grid)?)
    }

    /// Every method at the light `theta` degrees from the axis (and, at the `first` angle, the reference's
    /// convergence).
    fn angle(&self, theta: f64, first: bool, mut gpu: Option<&mut GpuBench>, results: &mut Results) -> Result<()> {
        let (plan, id) = (self.plan, &self.flare.system.lens.id);
        let light = light_position_deg(theta);
        let (ms, runs, reference) =
            timed(plan.repeats.min(3), || self.trace(light, Grid::Adaptive(plan.reference_grid)))?;
        eprintln!(
            "[{:6.1} s] {id} at {theta} deg: reference ({}) {ms:.0} ms, {} rays",
            self.started.elapsed().as_secs_f64(),
            plan.reference_grid,
            reference.stats.rays
        );
        let truth = metrics::Reference::new(&reference.hdr, &reference.moments);
        let at = AngleBench { lens: self, theta, light, truth };
        let errors = at.against("reference", &reference.hdr, &reference.moments)?;
        results.rows.push(at.row("reference".into(), ms, runs, errors));
        if first {
            at.convergence(&reference, &mut results.convergence)?;
        }
        at.paraxial_rows(&mut results.rows)?;
        if let Some(gpu) = gpu.as_deref_mut() {
            at.gpu_paraxial_row(gpu, &mut results.rows)?;
        }
        at.raygrid_rows(gpu.as_deref(), results)?;
        eprintln!("[{:6.1} s] {id} at {theta} deg: done", self.started.elapsed().as_secs_f64());
        Ok(())
    }
}

impl AngleBench<'_> {
    /// Convergence: the reference grid halved twice, each image against the finer one.
    fn convergence(&self, reference: &RayGridImage, out: &mut Vec<Convergence>) -> Result<()> {
        let mut finer = reference.clone();
        let mut grid = self.lens.plan.reference_grid;
        for _ in 0..2 {
            if grid / 2 < 4 {
                break;
            }
            let (ms_half, _, half) = timed(1, || self.trace(Grid::Adaptive(grid / 2)))?;
            let vs_half = metrics::compare(&half.hdr, &half.moments, &finer.hdr, &finer.moments);
            let lens = self.lens.flare.system.lens.id.clone();
            out.push(Convergence { lens, field_deg: self.theta, grid, vs_half, ms: ms_half });
            finer = half;
            grid /= 2;
        }
        Ok(())
    }

    /// The frame request of the paraxial methods: drawn at the reference's exposure (which sets the culling
    /// threshold), no starburst.
    fn request(&self) -> FrameRequest {
        let display = DisplaySettings {
            flare_ev: f64::from(self.truth.exposure).log2(),
            starburst: false,
            ..DisplaySettings::default()
        };
        let (width, height) = (self.lens.plan.width, self.lens.plan.height);
        FrameRequest { light_deg: self.light, width, height, display, ..FrameRequest::default() }
    }

    /// Paraxial, paraxial at half accumulation resolution and blended, through the one frame pipeline; the
    /// timing covers building the frame and the CPU twin's passes, as the app does it.
    fn paraxial_rows(&self, rows: &mut Vec<Row>) -> Result<()> {
        let (flare, plan, live) = (self.lens.flare, self.lens.plan, self.lens.live);
        let ghosts = flare.system.ghosts.len();
        let request = self.request();
        let sources = Sources { flare, lut: None, plate: None };
        let (ms, runs, (image, scene)) = timed(plan.repeats, || {
            let frame = Frame::build(flare, None, &request);
            Ok((frame::draw_cpu_hdr(&frame, &sources), frame.scene))
        })?;
        let moments = cpu::ghost_moments(&scene, &flare.ghost_masks, ghosts);
        rows.push(self.row("paraxial".into(), ms, runs, self.against("paraxial", &image, &moments)?));
        // The same at half accumulation resolution (the app's choice on software adapters), upsampled.
        let half_request =
            FrameRequest { display: DisplaySettings { accumulation_divisor: 2, ..request.display }, ..request.clone() };
        let (ms, runs, (image, scene)) = timed(plan.repeats, || {
            let frame = Frame::build(flare, None, &half_request);
            Ok((frame::draw_cpu_hdr(&frame, &sources), frame.scene))
        })?;
        let moments = cpu::ghost_moments(&scene, &flare.ghost_masks, ghosts);
        let upsampled = image.resampled(plan.width, plan.height, Sampling::Bilinear, 1.0);
        rows.push(self.row("paraxial-half".into(), ms, runs, self.against("paraxial-half", &upsampled, &moments)?));
        // Blended: the paraxial flare with the LUT ghosts (CPU twin), as the paraxial row is timed.
        let blend = flare_core::lut::blend::BlendSettings::default();
        let blended_request = FrameRequest { blend, lut_use: LutUse::Blend, ..request };
        let blended_sources = Sources { lut: Some(live), ..sources };
        let (ms, runs, (image, frame)) = timed(plan.repeats, || {
            let frame = Frame::build(flare, Some(live), &blended_request);
            Ok((frame::draw_cpu_hdr(&frame, &blended_sources), frame))
        })?;
        let mut moments = cpu::ghost_moments(&frame.scene, &flare.ghost_masks, ghosts);
        if let Some(lut_scene) = &frame.lut {
            lut_moments(&frame.scene, lut_scene, live, &mut moments);
        }
        rows.push(self.row("blended".into(), ms, runs, self.against("blended", &image, &moments)?));
        Ok(())
    }

    /// The paraxial frame on the GPU, as the app draws it: frame, upload, draw, wait (no read-back in the
    /// timing). The GPU's own time of the passes (timestamp queries) is reported beside the wall-clock time.
    fn gpu_paraxial_row(&self, gpu: &mut GpuBench, rows: &mut Vec<Row>) -> Result<()> {
        let (flare, plan) = (self.lens.flare, self.lens.plan);
        let request = self.request();
        let sources = Sources { flare, lut: None, plate: None };
        let mut gpu_times = Vec::new();
        let (ms, runs, frame) = timed(plan.repeats, || {
            let frame = Frame::build(flare, None, &request);
            gpu.drawer.render_into(&frame, &sources, &gpu.view)?;
            Ok(frame)
        })?;
        // Timed apart, so that waiting for the timestamps is not in the wall-clock time.
        for _ in 0..runs {
            let frame = Frame::build(flare, None, &request);
            gpu.drawer.render_into(&frame, &sources, &gpu.view)?;
            let (device, queue) = (&gpu.drawer.ctx.device, &gpu.drawer.ctx.queue);
            if let Some(times) = gpu.drawer.renderer.wait_pass_times(device, queue) {
                gpu_times.push(times);
            }
        }
        let image = gpu::read_hdr(&gpu.drawer.ctx, &gpu.drawer.renderer)?;
        let moments = cpu::ghost_moments(&frame.scene, &flare.ghost_masks, flare.system.ghosts.len());
        let mut measured = self.row("paraxial-gpu".into(), ms, runs, self.against("paraxial-gpu", &image, &moments)?);
        if let Some(last) = gpu_times.last() {
            let totals: Vec<f64> = gpu_times.iter().map(gpu::PassTimes::total_ms).collect();
            measured.gpu = Some((metrics::median(&totals), last.summary()));
        }
        rows.push(measured);
        Ok(())
    }

    /// Every ray grid on the CPU and, with a GPU, the same grid traced and box-filtered there, against the
    /// reference and against the CPU's image at this grid.
    fn raygrid_rows(&self, gpu: Option<&GpuBench>, results: &mut Results) -> Result<()> {
        let plan = self.lens.plan;
        for &grid in &plan.grids {
            let (ms, runs, image) = timed(plan.repeats, || self.trace(Grid::Fixed(grid)))?;
            let method = format!("raygrid-{grid}");
            let errors = self.against(&method, &image.hdr, &image.moments)?;
            results.rows.push(self.row(method, ms, runs, errors));
            let Some(gpu) = gpu else { continue };
            let window = flare_core::raytrace::Window::frame(plan.width, plan.height);
            let samples = flare_core::render::raygrid::SUPERSAMPLE;
            let mut gpu_times = Vec::new();
            let (ms, runs, gpu_image) = timed(plan.repeats, || {
                let image =
                    gpu.raygrid.render(&gpu.drawer.ctx, self.lens.tracer, self.light, window, grid, samples, &[])?;
                gpu_times.extend(image.gpu_times.clone());
                Ok(image)
            })?;
            let method = format!("raygrid-{grid}-gpu");
            // No per-ghost moments from the GPU: no centroid error ("-" in the table).
            let errors = self.against(&method, &gpu_image.hdr, &[])?;
            let twin = metrics::compare(&gpu_image.hdr, &[], &image.hdr, &[]);
            let mut measured = self.row(method, ms, runs, errors);
            if let Some(last) = gpu_times.last() {
                let totals: Vec<f64> = gpu_times.iter().map(gpu::PassTimes::total_ms).collect();
                measured.gpu = Some((metrics::median(&totals), last.summary()));
            }
            results.rows.push(measured);
            results.twins.push((self.lens.flare.system.lens.id.clone(), self.theta, grid, twin));
        }
        Ok(())
    }
}

/// The tables (CSV, Markdown), the chart and, with `--update-readme`, the page's section.
fn write_results(
    args: &BenchArgs,
    plan: &Plan,
    results: &Results,
    gpu: Option<&GpuBench>,
    elapsed_s: f64,
) -> Result<()> {
    let Results { rows, convergence, bakes, twins } = results;
    let adapter = gpu.map(|g| g.drawer.ctx.adapter.name.as_str());
    let device = adapter.map_or_else(|| "no GPU adapter".to_owned(), |name| format!("GPU: {name}"));
    let settings = format!(
        "{}x{}, {device}, RGB (650/510/475 nm), 6-blade aperture wide open, each lens's own coatings, light at {LIGHT_AZIMUTH_DEG} deg azimuth; reference grid {}; {} threads; median of {} timed runs per method (1 for runs over {:.0} s); whole run {elapsed_s:.0} s",
        plan.width,
        plan.height,
        plan.reference_grid,
        rayon::current_num_threads(),
        plan.repeats,
        REPEAT_BELOW_MS / 1e3
    );
    write_atomic(&args.out.join("bench.csv"), csv(rows).as_bytes())?;
    let mut markdown = markdown(rows, convergence, &settings);
    markdown.push_str(&twin_table(twins, adapter));
    markdown.push_str(&bake_table(bakes, rows));
    write_atomic(&args.out.join("bench.md"), markdown.as_bytes())?;
    plot::error_against_time(rows, &args.out.join("bench.png"))?;
    if let Some(readme) = &args.update_readme {
        update_readme(readme, (README_START, README_END), &markdown)?;
    }
    eprintln!("wrote {}/bench.csv, bench.md and bench.png in {elapsed_s:.0} s", args.out.display());
    print!("{markdown}");
    Ok(())
}

/// GPU ray grids against the CPU's at the same grid (PSNR and SSIM of the GPU image at the CPU image's
/// exposure).
fn twin_table(twins: &[(String, f64, usize, Comparison)], adapter: Option<&str>) -> String {
    let mut md = String::new();
    let Some(adapter) = adapter.filter(|_| !twins.is_empty()) else { return md };
    let _ = writeln!(
        md,
        "\nRay grids on the GPU ({adapter}, f32, box-filtered in a compute pass) against the CPU's (f64, box-filtered) at the same grid:\n"
    );
    let _ = writeln!(md, "| lens | field (deg) | grid | PSNR (dB) | SSIM | rel. L1 |");
    let _ = writeln!(md, "|---|---:|---:|---:|---:|---:|");
    for (lens, field, grid, c) in twins {
        let _ = writeln!(md, "| {lens} | {field} | {grid} | {:.1} | {:.4} | {:.4} |", c.psnr_db, c.ssim, c.relative_l1);
    }
    md
}

/// The frame pipeline's GPU drawer and a target to draw into, for the paraxial-gpu rows, and the GPU ray
/// grids.
struct GpuBench {
    drawer: GpuDrawer,
    view: wgpu::TextureView,
    raygrid: flare_core::render::raygrid::GpuRayGrid,
}

impl GpuBench {
    fn new(width: u32, height: u32) -> Result<Self> {
        let drawer = GpuDrawer::new(false)?;
        let target = gpu::texture_2d(
            &drawer.ctx.device,
            "bench target",
            width,
            height,
            drawer.renderer.target_format(),
            drawer.renderer.target_usage(),
        );
        let view = target.create_view(&wgpu::TextureViewDescriptor::default());
        let raygrid = flare_core::render::raygrid::GpuRayGrid::new(&drawer.ctx.device);
        Ok(Self { drawer, view, raygrid })
    }
}

/// One lens's LUT bake.
struct Bake {
    lens: String,
    surfaces: usize,
    ghosts: usize,
    lut_ghosts: usize,
    entries: usize,
    seconds: f64,
    megabytes: f64,
    theta_max_deg: f64,
}

/// Per-ghost moments of the LUT images: each instance's energy and centroid, added to its ghost's.
fn lut_moments(
    scene: &FlareScene,
    lut_scene: &flare_core::lut::blend::LutScene,
    live: &flare_core::lut::blend::LiveLut,
    moments: &mut [metrics::GhostMoments],
) {
    for (g, ghost) in live.lut.ghosts.iter().enumerate() {
        let only: Vec<usize> = (0..lut_scene.sources.len()).filter(|&k| lut_scene.sources[k].0 as usize == g).collect();
        if only.is_empty() {
            continue;
        }
        let part = flare_core::lut::blend::LutScene {
            instances: only.iter().map(|&k| lut_scene.instances[k]).collect(),
            sources: only.iter().map(|&k| lut_scene.sources[k]).collect(),
            ..Default::default()
        };
        let mut image = HdrImage {
            width: scene.hdr_width,
            height: scene.hdr_height,
            pixels: vec![[0.0; 4]; (scene.hdr_width * scene.hdr_height) as usize],
        };
        flare_core::lut::blend::lut_pass((scene.width, scene.height), &part, live, &mut image);
        let m = &mut moments[ghost.ghost as usize];
        for (k, p) in image.pixels.iter().enumerate() {
            let luma = metrics::luminance([p[0], p[1], p[2]].map(f64::from));
            if luma > 0.0 {
                let (x, y) = ((k % image.width as usize) as f64 + 0.5, (k / image.width as usize) as f64 + 0.5);
                m.add_sample(luma, [x, y]);
            }
        }
    }
}

/// The bake table and the blended method's summary against paraxial.
fn bake_table(bakes: &[Bake], rows: &[Row]) -> String {
    let mut md = String::new();
    let _ = writeln!(
        md,
        "\nBlended LUT ghosts (default settings: classify, bake, then per frame paraxial + LUT on the CPU twin); medians over the angles inside the LUT range:\n"
    );
    let _ = writeln!(
        md,
        "| lens | surfaces | ghosts | LUT ghosts | entries | bake (s) | .flut (MB) | theta max | blended PSNR | blended SSIM | paraxial PSNR | gain (dB) | blended / paraxial time |"
    );
    let _ = writeln!(md, "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    for b in bakes {
        let of = |method: &str| -> Vec<&Row> {
            rows.iter().filter(|r| r.lens == b.lens && r.method == method && r.field_deg <= b.theta_max_deg).collect()
        };
        let (blended, paraxial) = (of("blended"), of("paraxial"));
        let med = |v: Vec<f64>| metrics::median(&v);
        let gains: Vec<f64> = blended.iter().zip(&paraxial).map(|(a, p)| a.errors.psnr_db - p.errors.psnr_db).collect();
        let ratios: Vec<f64> =
            blended.iter().zip(&paraxial).map(|(a, p)| a.ms_median / p.ms_median.max(1e-6)).collect();
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} | {} | {:.1} | {:.1} | {:.1} | {:.1} | {:.3} | {:.1} | {:.1} | {:.2}x |",
            b.lens,
            b.surfaces,
            b.ghosts,
            b.lut_ghosts,
            b.entries,
            b.seconds,
            b.megabytes,
            b.theta_max_deg,
            med(blended.iter().map(|r| r.errors.psnr_db).collect()),
            med(blended.iter().map(|r| r.errors.ssim).collect()),
            med(paraxial.iter().map(|r| r.errors.psnr_db).collect()),
            med(gains),
            med(ratios)
        );
    }
    md
}

fn csv(rows: &[Row]) -> String {
    let mut out = String::from(
        "lens,field_deg,method,ms_median,psnr_db,ssim,rel_l1,centroid_px,centroid_ghosts,runs,surfaces,ghosts,gpu_ms\n",
    );
    for r in rows {
        let e = &r.errors;
        let _ = writeln!(
            out,
            "{},{},{},{:.3},{:.2},{:.4},{:.4},{:.2},{},{},{},{},{}",
            r.lens,
            r.field_deg,
            r.method,
            r.ms_median,
            e.psnr_db,
            e.ssim,
            e.relative_l1,
            e.centroid_px,
            e.centroid_ghosts,
            r.runs,
            r.surfaces,
            r.ghosts,
            r.gpu.as_ref().map_or(String::new(), |g| format!("{:.3}", g.0))
        );
    }
    out
}

fn markdown(rows: &[Row], convergence: &[Convergence], settings: &str) -> String {
    let mut md = String::new();
    let _ = writeln!(md, "Settings: {settings}.\n");
    let _ = writeln!(
        md,
        "| lens | field (deg) | method | ms (median) | PSNR (dB) | SSIM | rel. L1 | centroid err. (px) | GPU passes (timestamps, ms) |"
    );
    let _ = writeln!(md, "|---|---:|---|---:|---:|---:|---:|---:|---|");
    for r in rows.iter().filter(|r| r.method != "reference") {
        let e = &r.errors;
        let gpu = r.gpu.as_ref().map_or_else(|| "-".to_owned(), |g| format!("{:.2} ({})", g.0, g.1));
        let centroid = if e.centroid_ghosts == 0 { "-".to_owned() } else { format!("{:.1}", e.centroid_px) };
        let _ = writeln!(
            md,
            "| {} | {} | {} | {:.1} | {:.1} | {:.3} | {:.3} | {centroid} | {gpu} |",
            r.lens, r.field_deg, r.method, r.ms_median, e.psnr_db, e.ssim, e.relative_l1
        );
    }
    let _ = writeln!(
        md,
        "\nSpeed of the paraxial method against the reference, per lens (median over the angles of the ratio of the medians; - where not run):\n"
    );
    let variants = ["paraxial", "paraxial-half", "paraxial-gpu"];
    let _ = writeln!(
        md,
        "| lens | surfaces | ghosts | reference ms | {} | paraxial PSNR by angle (dB) |",
        variants.map(|v| format!("{v} ms | speed-up")).join(" | ")
    );
    let _ = writeln!(md, "|---|---:|---:|---:|{}---|", "---:|---:|".repeat(variants.len()));
    let mut lenses: Vec<&str> = rows.iter().map(|r| r.lens.as_str()).collect();
    lenses.dedup();
    let med = |v: Vec<f64>| metrics::median(&v);
    for lens in lenses {
        let of = |method: &str| -> Vec<&Row> { rows.iter().filter(|r| r.lens == lens && r.method == method).collect() };
        let reference = of("reference");
        let cells: Vec<String> = variants
            .iter()
            .map(|v| {
                let rows = of(v);
                if rows.is_empty() {
                    return "- | -".to_owned();
                }
                let ratios = reference.iter().zip(&rows).map(|(a, b)| a.ms_median / b.ms_median.max(1e-6)).collect();
                format!("{:.1} | {:.0}x", med(rows.iter().map(|r| r.ms_median).collect()), med(ratios))
            })
            .collect();
        let by_angle: Vec<String> =
            of("paraxial").iter().map(|r| format!("{}: {:.1}", r.field_deg, r.errors.psnr_db)).collect();
        let _ = writeln!(
            md,
            "| {lens} | {} | {} | {:.0} | {} | {} |",
            reference[0].surfaces,
            reference[0].ghosts,
            med(reference.iter().map(|r| r.ms_median).collect()),
            cells.join(" | "),
            by_angle.join(", ")
        );
    }
    if !convergence.is_empty() {
        let _ = writeln!(
            md,
            "\nConvergence of the reference: the image at grid N against the image at N/2 (first angle):\n"
        );
        let _ =
            writeln!(md, "| lens | field (deg) | N | PSNR vs N/2 (dB) | SSIM vs N/2 | rel. L1 vs N/2 | ms at N/2 |");
        let _ = writeln!(md, "|---|---:|---:|---:|---:|---:|---:|");
        for c in convergence {
            let e = &c.vs_half;
            let _ = writeln!(
                md,
                "| {} | {} | {} | {:.1} | {:.4} | {:.4} | {:.0} |",
                c.lens, c.field_deg, c.grid, e.psnr_db, e.ssim, e.relative_l1, c.ms
            );
        }
    }
    md
}

/// `image` as the metrics see it (exposure, ACES, sRGB), as an 8-bit PNG.
fn write_display(path: &Path, image: &HdrImage, exposure: f32) -> Result<()> {
    let to_u8 = |v: f32| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
    let pixels = metrics::display_values(image, exposure)
        .into_iter()
        .map(|p| [to_u8(p[0]), to_u8(p[1]), to_u8(p[2]), 255])
        .collect();
    flare_core::output::write_png(path, &DisplayImage { width: image.width, height: image.height, pixels })?;
    Ok(())
}

/// The most timed runs per method (`--repeats`): a median of 100 runs is as steady as it gets.
pub(crate) const MAX_REPEATS: usize = 100;

/// `--repeats` (or `default`), at least 1, refused past [`MAX_REPEATS`] before any work.
pub(crate) fn checked_repeats(repeats: Option<usize>, default: usize) -> Result<usize> {
    match repeats {
        Some(n) if n > MAX_REPEATS => bail!("--repeats {n}: at most {MAX_REPEATS} timed runs per method"),
        n => Ok(n.unwrap_or(default).max(1)),
    }
}

/// The most bytes of a README that `--update-readme` reads.
const MAX_README_BYTES: u64 = 16 << 20;

/// The README at `path` (read bounded, a FIFO or device refused) and where its section between `start` and
/// `end` lies; checked, with the README's folder taking a file, before any benchmarking and again when written.
pub(crate) fn readme_section(path: &Path, (start, end): (&str, &str)) -> Result<(String, usize, usize)> {
    flare_core::files::check_target(path).map_err(|e| anyhow::anyhow!("--update-readme {e}"))?;
    let text = flare_core::files::read_text_bounded(path, MAX_README_BYTES)
        .map_err(|e| anyhow::anyhow!("--update-readme {e}"))?;
    let (Some(a), Some(b)) = (text.find(start), text.find(end)) else {
        bail!("{}: no `{start}` ... `{end}` section to replace", path.display());
    };
    if b < a {
        bail!("{}: `{end}` comes before `{start}`", path.display());
    }
    Ok((text, a, b))
}

/// Replaces the text between the README's markers `start` and `end` with `markdown` (written atomically).
pub(crate) fn update_readme(path: &Path, (start, end): (&str, &str), markdown: &str) -> Result<()> {
    let (text, a, b) = readme_section(path, (start, end))?;
    let updated = format!("{}{start}\n{markdown}{}", &text[..a], &text[b..]);
    write_atomic(path, updated.as_bytes())?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn light_position_has_the_requested_angle_and_azimuth() {
        for theta in [0.0, 10.0, 45.0, 80.0] {
            let [x, y] = light_position_deg(theta);
            let (tx, ty) = (x.to_radians().tan(), y.to_radians().tan());
            assert!((tx.hypot(ty).atan().to_degrees() - theta).abs() < 1e-9);
            if theta > 0.0 {
                assert!((ty.atan2(tx).to_degrees() - LIGHT_AZIMUTH_DEG).abs() < 1e-9);
            }
        }
    }
}
