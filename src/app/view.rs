//! The view: where the viewport is on screen and at what size the flare is drawn for it, the one mapping
//! between the viewport's points and the light, the playhead, drafts while the user drags, and the options the
//! app reads once at start.
//!
//! # How it works
//! [`View`] is the only writer of its fields (they are private). Each UI frame the viewport lays itself out
//! through [`View::layout`], which keeps the widget's rect and returns the drawing size: the widget's pixels,
//! at most [`MAX_VIEW_WIDTH`] across (a larger window is upsampled), or `FLARELAB_VIEW_PX` (read once into [`super::options::AppOptions`]) in
//! [`View::new`]. Every conversion between a point of the viewport and the optics goes through one
//! [`LightMap`] (built by [`View::light_map`] from the live flare): sensor millimetres to points (the light's
//! marker, the selected ghost's ring, the ghost under a click), a pointer to the light's angles through the
//! lens's own image mapping (continued by the paraxial mapping past its traced field) and a pointer to a
//! plate pixel (focus by click); [`light_slopes`] turns the light's angles into the slopes the optics take.
//! The playhead is the view's, not the document's (moving it is no edit): [`View::seek`], playback at the
//! timeline's rate ([`View::step_playback`], looping over the range) and [`View::clamp_playhead`] after the
//! range changed. [`View::draft_step`] hands the frame source the draft to draw while the user drags (see
//! [`super::draft`]).

use std::time::Instant;

use eframe::egui;
use flare_core::flare::PreparedFlare;
use flare_core::frame::Draft;
use flare_core::optics::mapping::ImageMapping;
use flare_core::optics::sensor::Sensor;
use flare_core::render::sensor_to_pixel;

use super::draft::DraftControl;

/// Largest viewport render (pixels across); a larger window is upsampled.
pub const MAX_VIEW_WIDTH: f32 = 1920.0;

/// The light's slopes (tangents of its angles, the optics' input) for its angles in the frame (degrees): the
/// one conversion the viewport, the report and the overlays use.
pub fn light_slopes(light_deg: [f64; 2]) -> [f64; 2] {
    flare_core::render::light_slopes_for_frame_position(light_deg[0], light_deg[1])
}

pub struct View {
    /// Where the viewport was last laid out (points).
    rect: Option<egui::Rect>,
    /// `FLARELAB_VIEW_PX`: the flare drawn at this size whatever the widget's (from the options, read at start).
    fixed_px: Option<(u32, u32)>,
    /// Drafts while the user drags (see [`super::draft`]).
    draft: DraftControl,
    /// The next click in the viewport focuses the depth of field there.
    focus_pick: bool,
    /// The timeline frame shown.
    playhead: i64,
    /// Playing since, from the frame then shown.
    playing: Option<(Instant, i64)>,
}

impl View {
    /// The view at `first_frame`; `software`: the adapter is a software rasteriser (coarser drafts).
    pub fn new(software: bool, first_frame: i64, fixed_px: Option<(u32, u32)>) -> Self {
        Self {
            rect: None,
            fixed_px,
            draft: DraftControl::new(software),
            focus_pick: false,
            playhead: first_frame,
            playing: None,
        }
    }

    /// Takes the viewport widget's `rect` (points, at `pixels_per_point`) and returns the size the flare is
    /// drawn at for it (pixels).
    pub fn layout(&mut self, rect: egui::Rect, pixels_per_point: f32) -> (u32, u32) {
        self.rect = Some(rect);
        if let Some(fixed) = self.fixed_px {
            return fixed;
        }
        let scale = (MAX_VIEW_WIDTH / (rect.width() * pixels_per_point)).min(1.0);
        (
            (rect.width() * pixels_per_point * scale).round().max(16.0) as u32,
            (rect.height() * pixels_per_point * scale).round().max(16.0) as u32,
        )
    }

    /// The mapping between the viewport laid out last and the optics of `flare`, for a frame delivered at `px`
    /// on a sensor `sensor_width_mm` wide, desqueezed by `desqueeze` (the sensor's rows are
    /// [`flare_core::frame::sensor_pixels`] of the delivered ones); none before the first layout.
    pub fn light_map<'a>(
        &self,
        flare: &'a PreparedFlare,
        px: (u32, u32),
        sensor_width_mm: f64,
        desqueeze: f64,
    ) -> Option<LightMap<'a>> {
        let px = flare_core::frame::sensor_pixels(px.0, px.1, desqueeze);
        Some(LightMap { rect: self.rect?, px, sensor: Sensor::for_frame(sensor_width_mm, px.0, px.1), flare })
    }

    /// The viewport's rectangle laid out last (points); none before the first layout.
    pub fn rect(&self) -> Option<egui::Rect> {
        self.rect
    }

    pub fn playhead(&self) -> i64 {
        self.playhead
    }

    pub fn playing(&self) -> bool {
        self.playing.is_some()
    }

    /// Moves the playhead to `frame`, clamped to `first..=last` (playing on from there when playing).
    pub fn seek(&mut self, frame: i64, first: i64, last: i64) {
        self.playhead = frame.clamp(first, last.max(first));
        if self.playing.is_some() {
            self.playing = Some((Instant::now(), self.playhead));
        }
    }

    /// Keeps the playhead inside `first..=last` (after the range changed).
    pub fn clamp_playhead(&mut self, first: i64, last: i64) {
        self.playhead = self.playhead.clamp(first, last.max(first));
    }

    pub fn toggle_play(&mut self) {
        self.playing = match self.playing {
            Some(_) => None,
            None => Some((Instant::now(), self.playhead)),
        };
    }

    /// Advances the playhead while playing, at `fps` over `first..=last` (looping); true while playing.
    pub fn step_playback(&mut self, first: i64, last: i64, fps: f64) -> bool {
        let Some((since, start)) = self.playing else { return false };
        let advanced = (since.elapsed().as_secs_f64() * fps).floor() as i64;
        let length = last - first + 1;
        self.playhead = first + (start - first + advanced).rem_euclid(length.max(1));
        true
    }

    /// The drag bench moves the playhead itself.
    pub fn playhead_mut(&mut self) -> &mut i64 {
        &mut self.playhead
    }

    pub fn focus_pick(&self) -> bool {
        self.focus_pick
    }

    pub fn set_focus_pick(&mut self, on: bool) {
        self.focus_pick = on;
    }

    /// The draft to draw this UI frame (see [`DraftControl::step`]).
    pub fn draft_step(&mut self, interacting: bool, flare_gpu_ms: Option<f64>) -> Option<Draft> {
        self.draft.step(interacting, flare_gpu_ms, Instant::now())
    }
}

/// The one mapping between the viewport's points and the optics (see the module documentation).
pub struct LightMap<'a> {
    rect: egui::Rect,
    /// The sensor's pixels across the viewport (a desqueezed frame has more than it delivers).
    px: (u32, u32),
    sensor: Sensor,
    flare: &'a PreparedFlare,
}

impl LightMap<'_> {
    /// A point of the sensor (mm) in the viewport (points).
    pub fn to_screen(&self, p_mm: [f64; 2]) -> egui::Pos2 {
        let (w, h) = self.px;
        let p = sensor_to_pixel(p_mm, &self.sensor, w, h);
        self.rect.min
            + egui::vec2(
                (p[0] / f64::from(w)) as f32 * self.rect.width(),
                (p[1] / f64::from(h)) as f32 * self.rect.height(),
            )
    }

    /// Where the light at `light_deg` is imaged (the starburst's centre), in the viewport.
    pub fn light_on_screen(&self, light_deg: [f64; 2]) -> egui::Pos2 {
        self.to_screen(self.flare.system.light_image_mm(light_slopes(light_deg)))
    }

    /// The light's angles (degrees, each within +-85) that image it at `pointer`, through the lens's own
    /// mapping; past the lens's traced field the paraxial mapping continues it. None where neither reaches
    /// (a pointer beyond every angle the lens maps).
    pub fn light_deg_at(&self, pointer: egui::Pos2) -> Option<[f64; 2]> {
        let (w, h) = self.px;
        let px = [
            f64::from((pointer.x - self.rect.left()) / self.rect.width()) * f64::from(w),
            f64::from((pointer.y - self.rect.top()) / self.rect.height()) * f64::from(h),
        ];
        let mapping = &self.flare.system.mapping;
        let deg = mapping.light_deg_for_pixel(px, &self.sensor, w, h).or_else(|| {
            ImageMapping::paraxial(mapping.paraxial_mm_per_slope, mapping.paraxial_entrance_per_slope)
                .light_deg_for_pixel(px, &self.sensor, w, h)
        })?;
        Some(deg.map(|a| a.clamp(-85.0, 85.0)))
    }

    /// The pixel of a `width` x `height` image shown across the viewport under `pointer` (clamped inside).
    pub fn image_pixel_at(&self, pointer: egui::Pos2, width: u32, height: u32) -> [u32; 2] {
        image_pixel_at(self.rect, pointer, width, height)
    }
}

/// The pixel of a `width` x `height` image spanning `rect` under `pointer` (clamped inside).
pub fn image_pixel_at(rect: egui::Rect, pointer: egui::Pos2, width: u32, height: u32) -> [u32; 2] {
    let fx = ((pointer.x - rect.left()) / rect.width()).clamp(0.0, 0.9999);
    let fy = ((pointer.y - rect.top()) / rect.height()).clamp(0.0, 0.9999);
    [(fx * width as f32) as u32, (fy * height as f32) as u32]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flare() -> PreparedFlare {
        let doc = flare_core::preset::Document::default();
        PreparedFlare::new(&doc.lens, &doc.flare_config().unwrap()).unwrap()
    }

    /// A pointer put where the light is drawn gives back the light's angles: the two directions of the one
    /// mapping agree.
    #[test]
    fn the_light_drawn_at_a_point_is_the_light_a_pointer_there_gives() {
        let flare = flare();
        let mut view = View::new(false, 1, None);
        let px = view.layout(egui::Rect::from_min_size(egui::pos2(10.0, 20.0), egui::vec2(960.0, 540.0)), 1.0);
        assert_eq!(px, (960, 540));
        for desqueeze in [1.0, 2.0] {
            let map = view.light_map(&flare, px, 36.0, desqueeze).unwrap();
            for light in [[0.0, 0.0], [8.0, -3.5], [-15.0, 6.0]] {
                let p = map.light_on_screen(light);
                let back = map.light_deg_at(p).unwrap();
                for k in 0..2 {
                    assert!((back[k] - light[k]).abs() < 1e-3, "{light:?} drawn at {p:?} reads back as {back:?}");
                }
            }
            // The centre of the view is the optical axis.
            let centre = map.light_deg_at(egui::pos2(10.0 + 480.0, 20.0 + 270.0)).unwrap();
            assert!(centre[0].abs() < 1e-9 && centre[1].abs() < 1e-9, "{centre:?}");
            // Desqueezed by 2, the view shows twice the sensor's height: a light up the frame sits half as high.
            if desqueeze == 2.0 {
                let plain = view.light_map(&flare, px, 36.0, 1.0).unwrap();
                let (a, b) = (map.light_on_screen([0.0, 6.0]), plain.light_on_screen([0.0, 6.0]));
                let (ya, yb) = (a.y - (20.0 + 270.0), b.y - (20.0 + 270.0));
                assert!((ya / yb - 0.5).abs() < 1e-3, "{ya} {yb}");
            }
        }
    }

    #[test]
    fn a_wide_window_is_drawn_at_most_1920_across_and_the_playhead_stays_in_range() {
        let mut view = View::new(false, 1, None);
        let px = view.layout(egui::Rect::from_min_size(egui::Pos2::ZERO, egui::vec2(1600.0, 900.0)), 2.0);
        assert_eq!(px, (1920, 1080));
        view.seek(50, 1, 24);
        assert_eq!(view.playhead(), 24);
        view.clamp_playhead(30, 40);
        assert_eq!(view.playhead(), 30);
        assert_eq!(
            image_pixel_at(
                egui::Rect::from_min_size(egui::Pos2::ZERO, egui::vec2(100.0, 50.0)),
                egui::pos2(100.0, 60.0),
                200,
                100
            ),
            [199, 99]
        );
    }
}
