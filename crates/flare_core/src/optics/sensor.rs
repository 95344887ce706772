//! The sensor and the frame convention, written once: a sensor `sensor_width_mm` wide (36 mm, full frame, unless
//! a document or `--sensor-mm` says otherwise) with the image's aspect, centred on the axis; the displayed frame is the sensor image turned by 180 degrees (as a camera shows it),
//! pixels running right and down from the top-left corner; a light seen at the frame position (X right, Y up,
//! field angles in degrees) has rays of slope `(-tan X, -tan Y)`.

/// The physical sensor the flare is drawn on, centred on the axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sensor {
    pub width_mm: f64,
    pub height_mm: f64,
}

/// The width of a full-frame sensor, the default one.
pub(crate) const FULL_FRAME_WIDTH_MM: f64 = 36.0;

impl Sensor {
    /// A full-frame-wide sensor (36 mm) with the aspect of a `width` x `height` image.
    pub fn full_frame_for(width_px: u32, height_px: u32) -> Self {
        Self::for_frame(FULL_FRAME_WIDTH_MM, width_px, height_px)
    }

    /// A sensor `width_mm` wide with the aspect of a `width` x `height` image.
    pub fn for_frame(width_mm: f64, width_px: u32, height_px: u32) -> Self {
        Self { width_mm, height_mm: width_mm * height_px.max(1) as f64 / width_px.max(1) as f64 }
    }
}

/// The light slopes of a light seen at the frame position given by field angles (degrees, X right, Y up).
pub fn light_slopes_for_frame_position(x_deg: f64, y_deg: f64) -> [f64; 2] {
    [-x_deg.to_radians().tan(), -y_deg.to_radians().tan()]
}

/// Pixel position of the sensor point `p_mm` (display rotated by 180 degrees).
pub fn sensor_to_pixel(p_mm: [f64; 2], sensor: &Sensor, width: u32, height: u32) -> [f64; 2] {
    let k = width as f64 / sensor.width_mm;
    [0.5 * width as f64 - p_mm[0] * k, 0.5 * height as f64 + p_mm[1] * k]
}

/// The sensor point (mm) shown at pixel `p` (the inverse of [`sensor_to_pixel`]).
pub(crate) fn pixel_to_sensor(p: [f64; 2], sensor: &Sensor, width: u32, height: u32) -> [f64; 2] {
    let k = width as f64 / sensor.width_mm;
    [(0.5 * width as f64 - p[0]) / k, (p[1] - 0.5 * height as f64) / k]
}
