//! The app's options from the environment: every `FLARELAB_*` variable the window reads, read once when it
//! opens ([`AppOptions::from_env`]) and handed to the parts that use them (the core's own, `FLARELAB_CACHE_DIR`,
//! `FLARELAB_SIMD` and `FLARELAB_REQUIRE_GPU`, are the core's). The UI tests build the app with
//! [`AppOptions::default`], whatever the environment says.

use std::path::PathBuf;

use super::drag_bench::Sweep;

/// What the environment asks of the window (see the module documentation).
#[derive(Clone, Debug, PartialEq)]
pub struct AppOptions {
    /// `FLARELAB_WINDOW=WxH`: the window's first size (points; 1440x900 without it).
    pub window: (f32, f32),
    /// `FLARELAB_PRESET=FILE`: open this preset instead of the last session.
    pub preset: Option<PathBuf>,
    /// `FLARELAB_FRESH` set: start from the default document, not the last session.
    pub fresh: bool,
    /// `FLARELAB_AUTO_BAKE=0`: no automatic bake competing for the cores (measurements).
    pub auto_bake: bool,
    /// `FLARELAB_RAYGRID=N` (one of [`super::jobs::raygrid_view::GRIDS`]): start the view in its ray-grid mode.
    pub raygrid: Option<usize>,
    /// `FLARELAB_VIEW_PX=WxH`: draw the view at this size whatever the window's (the drag bench).
    pub view_px: Option<(u32, u32)>,
    /// `FLARELAB_DRAG_BENCH=N` frames of `FLARELAB_DRAG_BENCH_WHAT` (light, exposure, scrub, blades).
    pub drag_bench: Option<(usize, Sweep)>,
    /// `FLARELAB_FRAME_LOG=FILE`: record every UI frame's start and duration there (see [`super::frame_log`]).
    pub frame_log: Option<PathBuf>,
}

impl Default for AppOptions {
    fn default() -> Self {
        Self {
            window: (1440.0, 900.0),
            preset: None,
            fresh: false,
            auto_bake: true,
            raygrid: None,
            view_px: None,
            drag_bench: None,
            frame_log: None,
        }
    }
}

impl AppOptions {
    /// The options the environment sets; a value that does not parse is left at its default.
    pub fn from_env() -> Self {
        Self::from_vars(|name| std::env::var_os(name).map(|v| v.to_string_lossy().into_owned()))
    }

    /// The options from `var` (a variable's value by name).
    pub fn from_vars(var: impl Fn(&str) -> Option<String>) -> Self {
        let size = |name: &str| var(name).and_then(|s| flare_core::frame::parse_size(&s).ok());
        let default = Self::default();
        Self {
            window: size("FLARELAB_WINDOW").map_or(default.window, |(w, h)| (w as f32, h as f32)),
            preset: var("FLARELAB_PRESET").filter(|p| !p.is_empty()).map(PathBuf::from),
            fresh: var("FLARELAB_FRESH").is_some(),
            auto_bake: var("FLARELAB_AUTO_BAKE").is_none_or(|v| v != "0"),
            raygrid: var("FLARELAB_RAYGRID")
                .and_then(|s| s.trim().parse().ok())
                .filter(|n| super::jobs::raygrid_view::GRIDS.contains(n)),
            view_px: size("FLARELAB_VIEW_PX"),
            drag_bench: var("FLARELAB_DRAG_BENCH").and_then(|s| s.trim().parse().ok()).map(|frames| {
                let what = match var("FLARELAB_DRAG_BENCH_WHAT").as_deref() {
                    Some("exposure") => Sweep::Exposure,
                    Some("scrub") => Sweep::Scrub,
                    Some("blades") => Sweep::Blades,
                    _ => Sweep::Light,
                };
                (frames, what)
            }),
            frame_log: var("FLARELAB_FRAME_LOG").filter(|p| !p.is_empty()).map(PathBuf::from),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_variable_is_read_and_a_bad_value_keeps_the_default() {
        let set = |pairs: &'static [(&'static str, &'static str)]| {
            AppOptions::from_vars(move |name| pairs.iter().find(|(n, _)| *n == name).map(|(_, v)| v.to_string()))
        };
        assert_eq!(set(&[]), AppOptions::default());
        let all = set(&[
            ("FLARELAB_WINDOW", "1024x700"),
            ("FLARELAB_PRESET", "look.json"),
            ("FLARELAB_FRESH", "1"),
            ("FLARELAB_AUTO_BAKE", "0"),
            ("FLARELAB_RAYGRID", "32"),
            ("FLARELAB_VIEW_PX", "1280x720"),
            ("FLARELAB_DRAG_BENCH", "40"),
            ("FLARELAB_DRAG_BENCH_WHAT", "scrub"),
            ("FLARELAB_FRAME_LOG", "frames.txt"),
        ]);
        assert_eq!(
            all,
            AppOptions {
                window: (1024.0, 700.0),
                preset: Some(PathBuf::from("look.json")),
                fresh: true,
                auto_bake: false,
                raygrid: Some(32),
                view_px: Some((1280, 720)),
                drag_bench: Some((40, Sweep::Scrub)),
                frame_log: Some(PathBuf::from("frames.txt")),
            }
        );
        let bad = set(&[("FLARELAB_WINDOW", "big"), ("FLARELAB_RAYGRID", "17"), ("FLARELAB_DRAG_BENCH", "x")]);
        assert_eq!(bad, AppOptions::default());
    }
}
