//! The benchmark chart: error (PSNR against the reference) over run time, one point per lens, angle, method.
//!
//! Drawn with plotters into an RGB buffer (its bitmap backend, text through ab_glyph with egui's embedded
//! Ubuntu font, so no system font is needed), then written as a PNG through a temporary file and a rename.

use std::path::Path;

use anyhow::{Result, anyhow};
use plotters::prelude::*;
use plotters::style::FontStyle;

use flare_core::metrics::Comparison;

const SIZE: (u32, u32) = (1100, 700);

/// One method at one lens and angle: a point of the chart and a row of the tables.
#[derive(Clone, Debug)]
pub struct Row {
    pub lens: String,
    pub surfaces: usize,
    pub ghosts: usize,
    pub field_deg: f64,
    pub method: String,
    pub ms_median: f64,
    pub runs: usize,
    pub errors: Comparison,
    /// GPU rows: the median GPU time of the frame's passes measured by timestamp queries (ms, no read-back, no
    /// CPU work), and the last run's per-pass split.
    pub gpu: Option<(f64, String)>,
}

/// The method's family and its colour.
fn family(method: &str) -> (&'static str, RGBColor) {
    if method == "paraxial" {
        ("paraxial sprites (CPU twin)", RGBColor(220, 50, 47))
    } else if method == "paraxial-half" {
        ("paraxial sprites (CPU, half-res accumulation)", RGBColor(203, 75, 22))
    } else if method == "paraxial-gpu" {
        ("paraxial sprites (wgpu)", RGBColor(211, 54, 130))
    } else if method.starts_with("raygrid") && method.ends_with("-gpu") {
        ("ray grids on the GPU (wgpu)", RGBColor(42, 161, 152))
    } else if method.starts_with("raygrid") {
        ("ray grids (Hullin 2011)", RGBColor(38, 139, 210))
    } else if method.starts_with("blended") {
        ("blended LUT ghosts", RGBColor(133, 153, 0))
    } else if method.starts_with("dof-live-cpu") {
        ("depth of field, live (CPU twin)", RGBColor(220, 50, 47))
    } else if method.starts_with("dof-live-gpu") {
        ("depth of field, live (wgpu)", RGBColor(211, 54, 130))
    } else if method.starts_with("reference-") {
        ("depth of field, reference (thicker layers)", RGBColor(38, 139, 210))
    } else {
        ("other", RGBColor(88, 88, 88))
    }
}

/// Writes the chart of `rows` (the reference itself left out) to `path`.
pub fn error_against_time(rows: &[Row], path: &Path) -> Result<()> {
    error_against_time_titled(rows, path, "Error against run time (each point: one lens, light angle and method)")
}

/// [`error_against_time`] with another title; rows whose PSNR is not finite (a reference against itself) are
/// left out.
pub fn error_against_time_titled(rows: &[Row], path: &Path, title: &str) -> Result<()> {
    // Registering twice is harmless; the font is compiled in.
    let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, epaint_default_fonts::UBUNTU_LIGHT);
    let points: Vec<&Row> =
        rows.iter().filter(|r| r.method != "reference" && r.ms_median > 0.0 && r.errors.psnr_db.is_finite()).collect();
    let mut buffer = vec![255u8; (SIZE.0 * SIZE.1 * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buffer, SIZE).into_drawing_area();
        root.fill(&WHITE).map_err(|e| anyhow!("plot: {e}"))?;
        let (t_min, t_max) = points
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), r| (a.min(r.ms_median), b.max(r.ms_median)));
        let (t_min, t_max) = if t_min.is_finite() { (t_min / 2.0, t_max * 2.0) } else { (0.1, 1000.0) };
        let p_max = points.iter().map(|r| r.errors.psnr_db).fold(40.0f64, f64::max).min(100.0) + 5.0;
        let p_min = points.iter().map(|r| r.errors.psnr_db).fold(20.0f64, f64::min) - 5.0;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 24))
            .margin(15)
            .x_label_area_size(45)
            .y_label_area_size(60)
            .build_cartesian_2d((t_min..t_max).log_scale(), p_min..p_max)
            .map_err(|e| anyhow!("plot: {e}"))?;
        chart
            .configure_mesh()
            .x_desc("median time per frame (ms, log scale)")
            .y_desc("PSNR against the reference (dB, higher is better)")
            .label_style(("sans-serif", 16))
            .axis_desc_style(("sans-serif", 18))
            .draw()
            .map_err(|e| anyhow!("plot: {e}"))?;
        let mut families: Vec<(&str, RGBColor)> = points.iter().map(|r| family(&r.method)).collect();
        families.dedup_by_key(|f| f.0);
        families.sort_by_key(|f| f.0);
        families.dedup_by_key(|f| f.0);
        for (name, colour) in families {
            let series: Vec<&&Row> = points.iter().filter(|r| family(&r.method).0 == name).collect();
            chart
                .draw_series(series.iter().map(|r| {
                    let size = if r.method.starts_with("raygrid") {
                        // Bigger grids, bigger dots.
                        3 + r
                            .method
                            .trim_start_matches("raygrid-")
                            .parse::<u32>()
                            .unwrap_or(16)
                            .ilog2()
                            .saturating_sub(3)
                    } else {
                        5
                    };
                    Circle::new((r.ms_median, r.errors.psnr_db), size, colour.filled())
                }))
                .map_err(|e| anyhow!("plot: {e}"))?
                .label(name)
                .legend(move |(x, y)| Circle::new((x, y), 5, colour.filled()));
        }
        chart
            .configure_series_labels()
            .label_font(("sans-serif", 18))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .position(SeriesLabelPosition::LowerRight)
            .draw()
            .map_err(|e| anyhow!("plot: {e}"))?;
        root.present().map_err(|e| anyhow!("plot: {e}"))?;
    }
    let image = image::RgbImage::from_raw(SIZE.0, SIZE.1, buffer).ok_or_else(|| anyhow!("plot: buffer size"))?;
    let mut bytes = Vec::new();
    image.write_to(&mut std::io::Cursor::new(&mut bytes), image::ImageFormat::Png)?;
    flare_core::files::write_atomic(path, &bytes)?;
    Ok(())
}
