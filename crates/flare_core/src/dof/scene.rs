//! A synthetic night street with its depth map, to try the depth of field with (and the flare over it):
//! strings of lamps at several depths, a lit building, a sign in the middle distance, a post close to the
//! camera, the ground running to the horizon, a sky at infinity with a low sun.
//!
//! # How it works
//! A pinhole camera of `FOCAL_MM` on a 36 mm-wide sensor, `EYE_HEIGHT_M` above a flat ground, looks level.
//! Each pixel is the nearest of the objects its ray meets (painter's order, far to near), so the plate and the
//! depth map agree exactly: the depth is measured along the axis, as [`super::DofModel`] measures it. Lamps
//! are small discs of high radiance (linear, up to 60), so they bloom into bokeh when out of focus.

use super::depth::DepthMap;
use crate::image::HdrImage;

/// The pinhole's focal length and the eye height above the ground.
pub(crate) const FOCAL_MM: f64 = 40.0;
pub(crate) const EYE_HEIGHT_M: f64 = 1.6;
const SENSOR_WIDTH_MM: f64 = 36.0;

/// Where the sun sits in the scene (pixels as a fraction of the frame): its light position for a flare.
pub const SUN_AT: [f64; 2] = [0.62, 0.15];

/// Draws the street at `width` x `height`: the plate (linear RGB) and its depth map (metres, infinity for the
/// sky).
pub fn street(width: u32, height: u32) -> (HdrImage, DepthMap) {
    let (w, h) = (f64::from(width), f64::from(height));
    let px_mm = SENSOR_WIDTH_MM / w;
    // A pixel's ray: x right, y up, in units of the focal length.
    let ray = |x: f64, y: f64| [((x + 0.5) - 0.5 * w) * px_mm / FOCAL_MM, (0.5 * h - (y + 0.5)) * px_mm / FOCAL_MM];
    // Where a point (X right, Y up, Z ahead, metres) images: pixels.
    let project = |p: [f64; 3]| [0.5 * w + p[0] / p[2] * FOCAL_MM / px_mm, 0.5 * h - p[1] / p[2] * FOCAL_MM / px_mm];
    let mut plate = HdrImage::black(width, height);
    let mut metres = vec![f64::INFINITY; (width * height) as usize];
    for y in 0..height {
        for x in 0..width {
            let [rx, ry] = ray(f64::from(x), f64::from(y));
            let k = (y * width + x) as usize;
            // Sky: a dusk gradient and a low sun.
            let up = ry.max(0.0);
            let mut colour = [0.05 + 0.25 * (-up * 6.0).exp(), 0.07 + 0.18 * (-up * 5.0).exp(), 0.16 + 0.1 * up];
            let mut depth = f64::INFINITY;
            let sun = [SUN_AT[0] * w, SUN_AT[1] * h];
            let r = (f64::from(x) + 0.5 - sun[0]).hypot(f64::from(y) + 0.5 - sun[1]);
            let sun_r = 0.012 * w;
            if r < sun_r {
                colour = [400.0, 360.0, 300.0];
            }
            // The ground below the horizon: Z = eye height / -ry.
            if ry < 0.0 {
                let z = EYE_HEIGHT_M / -ry;
                let gx = rx * z;
                // Asphalt with lane marks, darker with distance.
                let lane = (gx.abs() - 0.1).abs() < 0.06 && (z % 6.0) < 3.0;
                let v = if lane { 0.5 } else { 0.06 + 0.02 * ((gx * 3.0).sin() * (z * 2.0).cos()) };
                colour = [v, v * 0.95, v * 0.9];
                depth = z;
            }
            // A building on the right, 14 m ahead from x = 3 m on, 9 m tall, with lit windows.
            let z_building = 14.0;
            let (bx, by) = (rx * z_building, ry * z_building + EYE_HEIGHT_M);
            if bx > 3.0 && (0.0..9.0).contains(&by) && z_building < depth {
                let window = (bx * 1.2).fract() < 0.5 && (by * 0.9).fract() < 0.45 && by > 1.0;
                colour = if window { [3.0, 2.2, 1.0] } else { [0.12, 0.1, 0.09] };
                depth = z_building;
            }
            // A sign in the middle distance (in focus at 5 m): a checker of white and red squares.
            let z_sign = 5.0;
            let (sx, sy) = (rx * z_sign + 0.9, ry * z_sign + EYE_HEIGHT_M - 1.2);
            if (0.0..1.2).contains(&sx) && (0.0..0.8).contains(&sy) && z_sign < depth {
                let check = ((sx * 10.0).floor() + (sy * 10.0).floor()) as i64 % 2 == 0;
                colour = if check { [0.9, 0.9, 0.85] } else { [0.8, 0.08, 0.05] };
                depth = z_sign;
            }
            // A post close to the camera, on the left: 1.2 m ahead.
            let z_post = 1.2;
            let px = rx * z_post;
            if (-0.42..-0.34).contains(&px) && z_post < depth {
                colour = [0.03, 0.03, 0.035];
                depth = z_post;
            }
            plate.pixels[k] = [colour[0] as f32, colour[1] as f32, colour[2] as f32, 1.0];
            metres[k] = depth;
        }
    }
    // Strings of lamps along the street, 3 m up, every 4 m from 3 to 60 m, on both sides.
    for side in [-2.6, 2.2] {
        for n in 0..15 {
            let z = 3.0 + 4.0 * f64::from(n);
            let centre = project([side, 3.0 - EYE_HEIGHT_M, z]);
            let radius_px = (0.09 / z * FOCAL_MM / px_mm).max(0.6);
            lamp(&mut plate, &mut metres, centre, radius_px, z, [60.0, 40.0, 18.0]);
        }
    }
    // Small blue signal lights far away and close.
    for (p, z) in [([-0.6, 0.4, 30.0], 30.0), ([0.5, -0.6, 2.5], 2.5), ([-1.2, 1.4, 9.0], 9.0)] {
        let centre = project(p);
        lamp(&mut plate, &mut metres, centre, (0.05 / z * FOCAL_MM / px_mm).max(0.6), z, [4.0, 12.0, 40.0]);
    }
    (plate, DepthMap { width, height, metres })
}

/// A lamp: a disc of `radius_px` at `centre` (pixels), `depth_m` ahead, in front of whatever is behind it.
fn lamp(plate: &mut HdrImage, metres: &mut [f64], centre: [f64; 2], radius_px: f64, depth_m: f64, rgb: [f32; 3]) {
    let (w, h) = (plate.width as i64, plate.height as i64);
    let reach = radius_px.ceil() as i64 + 1;
    let (cx, cy) = (centre[0].floor() as i64, centre[1].floor() as i64);
    for y in (cy - reach).max(0)..(cy + reach + 1).min(h) {
        for x in (cx - reach).max(0)..(cx + reach + 1).min(w) {
            let k = (y * w + x) as usize;
            let r = (x as f64 + 0.5 - centre[0]).hypot(y as f64 + 0.5 - centre[1]);
            // Coverage with a pixel-wide soft edge; the pixel takes the lamp's depth where the lamp covers most.
            let cover = (radius_px + 0.5 - r).clamp(0.0, 1.0) as f32;
            if cover > 0.0 && depth_m < metres[k] {
                let p = &mut plate.pixels[k];
                for c in 0..3 {
                    p[c] = p[c] * (1.0 - cover) + rgb[c] * cover;
                }
                if cover >= 0.5 {
                    metres[k] = depth_m;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_street_has_every_depth_and_finite_colours() {
        let (plate, depth) = super::street(320, 180);
        assert!(plate.pixels.iter().all(|p| p.iter().all(|v| v.is_finite() && *v >= 0.0)));
        let near = depth.metres.iter().cloned().fold(f64::INFINITY, f64::min);
        let sky = depth.metres.iter().filter(|d| d.is_infinite()).count();
        assert!(near > 1.0 && near < 1.3, "{near}");
        assert!(sky > 1000, "{sky}");
        for z in [5.0, 14.0] {
            assert!(depth.metres.contains(&z), "{z}");
        }
    }
}
