//! Depth maps: metres from the entrance pupil, one per pixel.
//!
//! # How it works
//! An EXR depth map is read with the `exr` crate: the channel named `Z` (or ending in `.Z`, as `depth.Z`), else
//! the first channel, as metres. A PNG must be 16-bit grey (8 bits cannot hold a useful depth) and comes with a
//! near/far range: the value v in [0, 1] is the depth `near + v (far - near)`. Every value is checked against the
//! model when the defocus is made ([`super::defocus_map`]: NaN, 0, negative or inside the lens are refused with
//! the pixel), so a reader only refuses what it cannot read. A focus pixel reads its depth here
//! ([`DepthMap::at`]).

use std::path::Path;

use super::model::DofError;

/// A depth map: metres, row by row from the top-left.
#[derive(Clone, Debug, PartialEq)]
pub struct DepthMap {
    pub width: u32,
    pub height: u32,
    pub metres: Vec<f64>,
}

/// How a 16-bit PNG's values map to metres: `near + v (far - near)`, v in [0, 1].
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PngRange {
    pub near_m: f64,
    pub far_m: f64,
}

impl PngRange {
    /// Parses `NEAR:FAR` (metres).
    pub fn parse(text: &str) -> Result<Self, String> {
        let (a, b) = text.split_once(':').ok_or_else(|| format!("`{text}`: give NEAR:FAR in metres, e.g. 0.5:100"))?;
        let parse = |s: &str| s.trim().parse::<f64>().map_err(|_| format!("`{s}` is not a number of metres"));
        let (near_m, far_m) = (parse(a)?, parse(b)?);
        if !(near_m.is_finite() && far_m.is_finite() && near_m > 0.0 && far_m > near_m) {
            return Err(format!("`{text}`: need 0 < near < far, both finite"));
        }
        Ok(Self { near_m, far_m })
    }
}

impl DepthMap {
    /// Depths in mm (what the model takes).
    pub fn millimetres(&self) -> Vec<f64> {
        self.metres.iter().map(|m| m * 1000.0).collect()
    }

    /// The depth at pixel (`x`, `y`), refused outside the map.
    pub fn at(&self, x: u32, y: u32) -> Result<f64, DofError> {
        if x >= self.width || y >= self.height {
            return Err(DofError::FocusPixel { x, y, width: self.width, height: self.height });
        }
        Ok(self.metres[(y * self.width + x) as usize])
    }

    /// Reads an EXR (`Z`, else the first channel) or a 16-bit PNG with `png_range`.
    pub fn read(path: &Path, png_range: Option<PngRange>) -> Result<Self, DofError> {
        let shown = path.display().to_string();
        // The image readers name the file themselves: said once.
        let fail = |reason: String| DofError::DepthFile {
            reason: reason.strip_prefix(&format!("{shown}: ")).map_or(reason.clone(), str::to_owned),
            path: shown.clone(),
        };
        let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
        match ext.as_str() {
            "exr" => read_exr(path).map_err(fail),
            "png" => {
                let range = png_range
                    .ok_or_else(|| fail("a PNG depth map needs its range in metres (--depth-range NEAR:FAR)".into()))?;
                read_png(path, range).map_err(fail)
            }
            other => Err(fail(format!("`.{other}`: use an EXR in metres (channel Z) or a 16-bit PNG with a range"))),
        }
    }
}

fn read_exr(path: &Path) -> Result<DepthMap, String> {
    use exr::prelude::{FlatSamples, ReadChannels, ReadLayers};
    // The header first: a few hundred bytes must not be able to ask for gigabytes.
    crate::output::exr_size(path, "depth map")?;
    let image = exr::prelude::read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_file(path)
        .map_err(|e| e.to_string())?;
    let layer = &image.layer_data;
    let (w, h) = (layer.size.width(), layer.size.height());
    let channels = &layer.channel_data.list;
    let channel = channels
        .iter()
        .find(|c| {
            let name = c.name.to_string();
            name == "Z" || name.ends_with(".Z")
        })
        .or_else(|| channels.first())
        .ok_or("no channels")?;
    let metres: Vec<f64> = match &channel.sample_data {
        FlatSamples::F16(v) => v.iter().map(|x| f64::from(x.to_f32())).collect(),
        FlatSamples::F32(v) => v.iter().map(|&x| f64::from(x)).collect(),
        FlatSamples::U32(v) => v.iter().map(|&x| f64::from(x)).collect(),
    };
    if metres.len() != w * h || w == 0 || h == 0 {
        return Err(format!("{} samples for {w}x{h} pixels", metres.len()));
    }
    // The largest float is how a file holds the sky: infinitely far ([`write_exr`]).
    let metres = metres.into_iter().map(|m| if m >= f64::from(f32::MAX) { f64::INFINITY } else { m }).collect();
    Ok(DepthMap { width: w as u32, height: h as u32, metres })
}

fn read_png(path: &Path, range: PngRange) -> Result<DepthMap, String> {
    let img = crate::output::open_image(path, "depth map")?;
    let (width, height) = (img.width(), img.height());
    let grey = match img {
        image::DynamicImage::ImageLuma16(g) => g,
        other => {
            return Err(format!(
                "{:?}: a PNG depth map must be 16-bit grey (8 bits give 256 depths, too few)",
                other.color()
            ));
        }
    };
    let span = range.far_m - range.near_m;
    let metres = grey.into_raw().into_iter().map(|v| range.near_m + f64::from(v) / 65535.0 * span).collect();
    Ok(DepthMap { width, height, metres })
}

/// Writes a depth map as a one-channel EXR (`Z`, metres, 32-bit) through the one writer. No image holds an
/// infinity: the sky (infinitely far) is written as the largest float, which [`DepthMap::read`] reads back as
/// infinity (a NaN, which no depth map holds, as 0, refused when the defocus is made).
pub fn write_exr(path: &Path, map: &DepthMap) -> Result<(), String> {
    // The writer keeps an infinity as the largest float and a NaN as 0 (`write_exr_channel`).
    let values: Vec<f32> = map.metres.iter().map(|&m| m as f32).collect();
    crate::output::write_exr_channel(path, map.width, map.height, "Z", &values).map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exr_and_png_depths_read_back() {
        let dir = std::env::temp_dir().join(format!("flarelab-depth-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let map = DepthMap { width: 3, height: 2, metres: vec![1.0, 2.0, 3.5, 10.0, f64::INFINITY, 0.25] };
        let exr = dir.join("d.exr");
        write_exr(&exr, &map).unwrap();
        assert_eq!(DepthMap::read(&exr, None).unwrap(), map);
        let png = dir.join("d.png");
        image::ImageBuffer::<image::Luma<u16>, _>::from_raw(2, 1, vec![0u16, 65535]).unwrap().save(&png).unwrap();
        let range = PngRange::parse("0.5:10").unwrap();
        assert_eq!(DepthMap::read(&png, Some(range)).unwrap().metres, vec![0.5, 10.0]);
        assert!(DepthMap::read(&png, None).unwrap_err().to_string().contains("--depth-range"));
        let png8 = dir.join("d8.png");
        image::GrayImage::from_raw(1, 1, vec![7]).unwrap().save(&png8).unwrap();
        assert!(DepthMap::read(&png8, Some(range)).unwrap_err().to_string().contains("16-bit"));
        assert!(PngRange::parse("5:1").is_err() && PngRange::parse("x").is_err());
        assert!(map.at(3, 0).is_err() && map.at(2, 1).unwrap() == 0.25);
        std::fs::remove_dir_all(&dir).ok();
    }
}
