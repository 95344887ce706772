//! Colour: luminance, the sRGB transfer curve, the tonemap operators and exposures in stops, in one place.
//!
//! # How it works
//! Every image FlareLab holds is linear Rec. 709 RGB (the OCIO working space
//! [`crate::view_transform::WORKING_SPACE`]). Exposures are in stops (EV): a gain of `2^ev` (`gain_from_ev`).
//! A display value is made by the document's [`Tonemap`]: by default the OCIO display and view
//! ([`crate::view_transform`]); else one of FlareLab's own curves in `display_value`: the linear value
//! times its gain, the operator (clamp only, Reinhard `c / (1 + c)`, or Narkowicz's fit of the ACES filmic
//! curve), a clamp to [0, 1] and, for 8-bit targets, the sRGB encoding. `shaders/tonemap.wgsl` does the same
//! steps; `crate::render::cpu::tonemap_pass` is its CPU twin and calls these functions.

use serde::{Deserialize, Serialize};

/// Rec. 709 luminance of a linear RGB colour.
pub fn luminance(rgb: [f64; 3]) -> f64 {
    0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2]
}

/// The linear gain of an exposure of `ev` stops (`2^ev`); a non-finite `ev` is 0 stops.
pub(crate) fn gain_from_ev(ev: f64) -> f32 {
    if ev.is_finite() { ev.clamp(-64.0, 64.0).exp2() as f32 } else { 1.0 }
}

/// The sRGB encoding of a linear value in [0, 1].
pub(crate) fn srgb_encode(c: f32) -> f32 {
    if c <= 0.0031308 { c * 12.92 } else { 1.055 * c.powf(1.0 / 2.4) - 0.055 }
}

/// The linear value of an sRGB-encoded one in [0, 1].
pub(crate) fn srgb_decode(v: f32) -> f32 {
    if v <= 0.04045 { v / 12.92 } else { ((v + 0.055) / 1.055).powf(2.4) }
}

/// Narkowicz 2015's fit of the ACES filmic curve, clamped to [0, 1].
pub fn aces(x: f32) -> f32 {
    ((x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14)).clamp(0.0, 1.0)
}

/// How the linear frame becomes display values: the OCIO display and view (the default), or one of
/// FlareLab's own tone curves followed by the sRGB encoding (see [`crate::view_transform`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Tonemap {
    /// The document's OCIO display and view ([`crate::view_transform::ViewTransform`]), with its looks.
    #[default]
    View,
    /// Clamp only, then sRGB.
    None,
    /// `c / (1 + c)` per channel, then sRGB.
    Reinhard,
    /// Narkowicz's fit of the ACES filmic curve, then sRGB.
    Aces,
}

impl Tonemap {
    /// Every operator, in menu order.
    pub const ALL: [Self; 4] = [Self::View, Self::None, Self::Reinhard, Self::Aces];

    /// The code the tonemap shader reads (`Globals.tonemap_operator`, its `TONEMAP_*` constants).
    pub fn code(self) -> u32 {
        match self {
            Self::None => 0,
            Self::Reinhard => 1,
            Self::Aces => 2,
            Self::View => 3,
        }
    }

    /// The operator of a shader code; an unknown code is the OCIO view (the shader's last branch too).
    pub fn from_code(code: u32) -> Self {
        match code {
            0 => Self::None,
            1 => Self::Reinhard,
            2 => Self::Aces,
            _ => Self::View,
        }
    }

    /// The name used in files and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Self::View => "view",
            Self::None => "none",
            Self::Reinhard => "reinhard",
            Self::Aces => "aces",
        }
    }
}

/// One linear, already exposed value to display by one of FlareLab's own curves: the operator, a clamp to
/// [0, 1], and the sRGB encoding when `encode` is set. [`Tonemap::View`] works on whole colours
/// ([`crate::render::cpu::tonemap_pixel`]); here it clamps only.
pub(crate) fn display_value(v: f32, tonemap: Tonemap, encode: bool) -> f32 {
    let mut v = if v.is_finite() { v.max(0.0) } else { 0.0 };
    v = match tonemap {
        Tonemap::Aces => aces(v),
        Tonemap::Reinhard => v / (1.0 + v),
        Tonemap::None | Tonemap::View => v,
    };
    v = v.clamp(0.0, 1.0);
    if encode { srgb_encode(v) } else { v }
}

/// An 8-bit channel of a display value in [0, 1] (rounded to the nearest step).
pub fn to_u8(v: f32) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stops_double_and_srgb_round_trips() {
        assert_eq!(gain_from_ev(0.0), 1.0);
        assert_eq!(gain_from_ev(3.0), 8.0);
        assert_eq!(gain_from_ev(-1.0), 0.5);
        assert_eq!(gain_from_ev(f64::NAN), 1.0);
        for k in 0..=20 {
            let v = k as f32 / 20.0;
            assert!((srgb_decode(srgb_encode(v)) - v).abs() < 1e-5, "{v}");
        }
        for t in Tonemap::ALL {
            assert_eq!(Tonemap::from_code(t.code()), t);
            assert_eq!(display_value(f32::NAN, t, true), 0.0);
            assert_eq!(display_value(-3.0, t, true), 0.0);
        }
        assert_eq!(display_value(0.5, Tonemap::Reinhard, false), 0.5 / 1.5);
    }
}
