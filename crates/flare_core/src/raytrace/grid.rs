//! The grids and windows of the ray-traced renderer: grid sizes ([`Grid`]), windows of the sensor plane
//! ([`Window`], [`View`]) and the traced vertex (`Vertex`) that a view sees.

use crate::optics::sensor::Sensor;

/// Most grid cells across a ghost's entrance region in the reference renderer (see the convergence table in the
/// README).
pub const REFERENCE_GRID: usize = 256;
/// Fewest grid cells across a ghost's entrance region in the reference renderer.
pub(crate) const REFERENCE_MIN_GRID: usize = 64;
/// How many rays a render traces per ghost and wavelength.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Grid {
    /// N x N cells over every ghost's entrance region: Hullin 2011's ray grids.
    Fixed(usize),
    /// Up to N x N cells: about two cells per pixel of the ghost's extent in the frame (measured by the
    /// pre-pass), at least `REFERENCE_MIN_GRID`, rounded up to a power of two: the reference, whose triangles
    /// are then at most about half a pixel on the sensor wherever they are not compressed into a caustic.
    Adaptive(usize),
}
impl Grid {
    /// The largest number of cells across.
    pub fn cells(self) -> usize {
        match self {
            Self::Fixed(n) | Self::Adaptive(n) => n,
        }
    }

    /// Cells across for a ghost extending `extent_px` pixels in the frame.
    pub(super) fn for_extent(self, extent_px: f64) -> usize {
        match self {
            Self::Fixed(n) => n,
            Self::Adaptive(n) => {
                let wanted = (2.0 * extent_px).ceil().clamp(1.0, n as f64) as usize;
                wanted.next_power_of_two().clamp(REFERENCE_MIN_GRID.min(n), n)
            }
        }
    }
}
/// Samples of the ray-traced renderers' reflectance tables over sin^2(i).
pub(crate) const DENSE_TABLE_SAMPLES: usize = 1025;
/// The smallest and largest grid a ray-grid render accepts.
pub const GRID_RANGE: std::ops::RangeInclusive<usize> = 2..=4096;
/// The part of the sensor plane an image covers: a rectangle of centre `centre_mm` and width `width_mm`, drawn
/// `width` x `height` square pixels in the display orientation (the sensor rotated by 180 degrees, as
/// [`crate::ghost::sensor_to_pixel`] does for the whole frame). The whole frame is the window centred on the
/// axis with the sensor's width ([`Window::frame`]); a LUT bake uses a window around one ghost.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Window {
    pub centre_mm: [f64; 2],
    pub width_mm: f64,
    pub width: u32,
    pub height: u32,
}
impl Window {
    /// The whole frame of a `width` x `height` image on the full-frame sensor ([`Sensor::full_frame_for`]).
    pub fn frame(width: u32, height: u32) -> Self {
        Self::for_sensor(Sensor::full_frame_for(width, height).width_mm, width, height)
    }

    /// The whole frame of a `width` x `height` image on a sensor `sensor_width_mm` wide.
    pub fn for_sensor(sensor_width_mm: f64, width: u32, height: u32) -> Self {
        Self { centre_mm: [0.0, 0.0], width_mm: sensor_width_mm, width, height }
    }

    /// Pixels per millimetre.
    pub fn px_per_mm(&self) -> f64 {
        f64::from(self.width) / self.width_mm
    }

    /// The pixel position of the sensor point `p_mm`.
    pub fn to_pixel(&self, p_mm: [f64; 2]) -> [f64; 2] {
        let k = self.px_per_mm();
        [
            0.5 * f64::from(self.width) - (p_mm[0] - self.centre_mm[0]) * k,
            0.5 * f64::from(self.height) + (p_mm[1] - self.centre_mm[1]) * k,
        ]
    }

    /// The sensor point at the pixel position `p` (the inverse of [`Self::to_pixel`]).
    pub fn to_mm(&self, p: [f64; 2]) -> [f64; 2] {
        let k = self.px_per_mm();
        [
            self.centre_mm[0] - (p[0] - 0.5 * f64::from(self.width)) / k,
            self.centre_mm[1] + (p[1] - 0.5 * f64::from(self.height)) / k,
        ]
    }
}
/// A window of the sensor plane seen with the light turned by `turn_deg` about the optical axis
/// (counter-clockwise, x right, y up) from the light a render is asked for (see [`super::RayGridRenderer::render_request`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct View {
    pub window: Window,
    pub turn_deg: f64,
}
impl View {
    /// What this view makes of a traced vertex: its landing point (sensor mm, in `v.pixel` when traced) and
    /// stop coordinates turned, the landing point then in the window's pixels. The turn's sine and cosine are
    /// taken once, here, not per vertex.
    pub(super) fn seer(&self) -> impl Fn(&Vertex) -> Vertex + '_ {
        let (s, c) = self.turn_deg.to_radians().sin_cos();
        let turned = self.turn_deg != 0.0;
        move |v: &Vertex| {
            let turn = |p: [f64; 2]| if turned { [c * p[0] - s * p[1], s * p[0] + c * p[1]] } else { p };
            let mut seen = *v;
            seen.stops = v.stops.map(turn);
            seen.pixel = self.window.to_pixel(turn(v.pixel));
            seen.valid = v.valid && seen.pixel.iter().all(|c| c.is_finite());
            seen
        }
    }
}
/// An empty bounding box `[x_min, y_min, x_max, y_max]`, for [`grow`].
pub(super) const NO_BOUNDS: [f64; 4] = [f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY];
/// The bounding box `b` grown to hold `p`.
pub(super) fn grow(b: [f64; 4], p: [f64; 2]) -> [f64; 4] {
    [b[0].min(p[0]), b[1].min(p[1]), b[2].max(p[0]), b[3].max(p[1])]
}
/// One traced grid vertex.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Vertex {
    pub(super) valid: bool,
    /// Landing point in image pixels.
    pub(super) pixel: [f64; 2],
    /// Coordinates at each stop crossing, in stop radii.
    pub(super) stops: [[f64; 2]; 3],
    /// Largest h / semi-aperture over the other surfaces.
    pub(super) ratio: f64,
    pub(super) weight: f64,
}
impl Vertex {
    /// Passes every aperture (the stop's unit square holds any mask).
    pub(super) fn passes(&self, stop_count: usize) -> bool {
        self.valid
            && self.ratio <= 1.0
            && self.stops[..stop_count].iter().all(|s| s[0].abs() <= 1.0 && s[1].abs() <= 1.0)
    }
}
