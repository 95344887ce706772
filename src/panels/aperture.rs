//! Aperture panel: blades (0 for a circle), their rotation and roundness, the f-number, a custom aperture
//! image; a live preview of the stop's mask and of its starburst (both from the prepared flare). Below it, the
//! front element's dirt ([`flare_core::dirt`]): pattern, seed, amount and spread, a dirt image, and previews of
//! the dirt and of the dirt as each pixel sees it through the stop, with the share of the light it takes.

use eframe::egui;

use super::{Action, PanelContext};
use flare_core::preset::Document;

/// Preview textures, rebuilt when the prepared flare changes.
#[derive(Default)]
pub struct AperturePreview {
    key: usize,
    mask: Option<egui::TextureHandle>,
    starburst: Option<egui::TextureHandle>,
    /// The dirt's share map and its mean over each footprint (the prepared flare's).
    dirt: Option<[egui::TextureHandle; 2]>,
}

pub fn aperture_ui(
    ui: &mut egui::Ui,
    doc: &mut Document,
    ctx: &PanelContext,
    preview: &mut AperturePreview,
    actions: &mut Vec<Action>,
) {
    let a = &mut doc.aperture;
    let mut blades = a.blades;
    ui.add(egui::Slider::new(&mut blades, 0..=flare_core::aperture::MAX_BLADES).text("blades"));

    // 1 and 2 blades make no opening: step over them.
    a.blades = match blades {
        1 | 2 if a.blades == 0 => 3,
        1 | 2 => 0,
        b => b,
    };
    if a.blades == 0 {
        ui.label("0 blades: a circular stop");
    }
    ui.add(egui::Slider::new(&mut a.rotation_deg, 0.0..=360.0).text("rotation (deg)"));
    ui.add(egui::Slider::new(&mut a.roundness, 0.0..=1.0).text("blade curvature"));
    let nominal = ctx.first_order.map_or(2.0, |fo| fo.f_number);
    let mut open = a.f_number.is_none();
    ui.horizontal(|ui| {
        ui.checkbox(&mut open, "wide open");
        if open {
            a.f_number = None;
        } else {
            let mut f = a.f_number.unwrap_or(nominal);
            ui.add(egui::Slider::new(&mut f, nominal..=32.0).logarithmic(true).text("f-number"));
            a.f_number = Some(f.max(nominal));
        }
    });
    if ui.button("Custom aperture image…").on_hover_text("a grey PNG: white is open").clicked() {
        actions.push(Action::OpenApertureImage);
    }
    let Some(flare) = ctx.flare else { return };
    previews_ui(ui, flare, preview);
    ui.separator();
    dirt_ui(ui, doc, flare, preview, actions);
}

/// The stop's mask and its starburst.
fn previews_ui(ui: &mut egui::Ui, flare: &flare_core::flare::PreparedFlare, preview: &mut AperturePreview) {
    let key = flare as *const _ as usize;
    if preview.key != key || preview.mask.is_none() {
        preview.key = key;
        preview.dirt = flare.dirt.as_ref().map(|d| {
            let grey = |values: &[f32], name: &str| {
                // Square-root scale: faint dirt shows.
                let peak = values.iter().copied().fold(1e-6, f32::max);
                let bytes: Vec<u8> = values.iter().map(|v| ((v / peak).sqrt() * 255.0) as u8).collect();
                let image = egui::ColorImage::from_gray([d.size, d.size], &bytes);
                ui.ctx().load_texture(name, image, egui::TextureOptions::LINEAR)
            };
            [grey(&d.share, "dirt"), grey(&d.map, "dirt seen through the stop")]
        });
        let m = flare.mask();
        let mask = egui::ColorImage::from_gray([m.size, m.size], &m.texels);
        preview.mask = Some(ui.ctx().load_texture("aperture mask", mask, egui::TextureOptions::LINEAR));
        // The far field on a log scale (six decades) shows the rays and the rings at once.
        let size = 128;
        let pixels: Vec<egui::Color32> = flare
            .starburst
            .preview(size)
            .iter()
            .map(|v| {
                let c = (v * 255.0) as u8;
                egui::Color32::from_rgb(c, c, c)
            })
            .collect();
        let image = egui::ColorImage::new([size, size], pixels);
        preview.starburst = Some(ui.ctx().load_texture("starburst", image, egui::TextureOptions::LINEAR));
    }
    ui.horizontal(|ui| {
        for (texture, caption) in [(&preview.mask, "stop"), (&preview.starburst, "starburst (log)")] {
            if let Some(t) = texture {
                ui.vertical(|ui| {
                    ui.add(egui::Image::from_texture((t.id(), egui::vec2(120.0, 120.0))));
                    ui.small(caption);
                });
            }
        }
    });
}

/// The front element's dirt: pattern, seed, amount, spread, image, previews and the share it takes.
fn dirt_ui(
    ui: &mut egui::Ui,
    doc: &mut Document,
    flare: &flare_core::flare::PreparedFlare,
    preview: &AperturePreview,
    actions: &mut Vec<Action>,
) {
    use flare_core::dirt::{DirtKind, SPREAD_RANGE_DEG};
    ui.strong("Front element dirt");
    let dirt = &mut doc.dirt;
    ui.horizontal(|ui| {
        let mut kind = dirt.pattern;
        egui::ComboBox::from_label("dirt").selected_text(kind.word()).show_ui(ui, |ui| {
            for k in DirtKind::ALL {
                ui.selectable_value(&mut kind, k, k.word());
            }
        });
        if kind != dirt.pattern {
            if kind == DirtKind::Image && dirt.image.is_none() {
                // An image pattern needs its file first: the pattern changes once one is read.
                actions.push(Action::OpenDirtImage);
            } else {
                dirt.pattern = kind;
            }
        }
        if ui.button("Dirt image…").on_hover_text("a grey image: white is dirt, black is clean glass").clicked() {
            actions.push(Action::OpenDirtImage);
        }
    });
    if dirt.pattern == DirtKind::None {
        ui.label("a clean lens: no glow");
        return;
    }
    if matches!(dirt.pattern, DirtKind::Dust | DirtKind::Smudges) {
        ui.horizontal(|ui| {
            ui.add(egui::DragValue::new(&mut dirt.seed).prefix("seed "));
            if ui.button("new").clicked() {
                dirt.seed = dirt.seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407) >> 1;
            }
        });
    }
    if dirt.pattern == DirtKind::Image
        && let Some(path) = &dirt.image
    {
        ui.small(path.as_str());
    }
    // Edited as a percentage; written back only when the slider moved (undo returns exactly what was there).
    let mut percent = dirt.amount * 100.0;
    let moved = ui
        .add(egui::Slider::new(&mut percent, 0.001..=100.0).logarithmic(true).suffix(" %").text("dirt amount"))
        .on_hover_text("the share of the light scattered where the dirt is densest")
        .changed();
    if moved {
        dirt.amount = (percent / 100.0).clamp(0.0, 1.0);
    }
    ui.add(
        egui::Slider::new(&mut dirt.spread_deg, SPREAD_RANGE_DEG.0..=SPREAD_RANGE_DEG.1)
            .logarithmic(true)
            .suffix(" deg")
            .text("dirt spread"),
    )
    .on_hover_text("the scattering lobe's half width at half peak: how far from the light the dirt lights up");
    if let Some(prepared) = &flare.dirt {
        let u = flare_core::ghost::light_slopes_for_frame_position(doc.light_deg[0], doc.light_deg[1]);
        let taken = prepared.taken_share(&flare.system, u, dirt.amount);
        ui.label(format!("takes {:.3}% of the light at its position into the glow", taken * 100.0));
    }
    ui.horizontal(|ui| {
        if let Some(textures) = &preview.dirt {
            for (texture, caption) in textures.iter().zip(["dirt", "seen through the stop"]) {
                ui.vertical(|ui| {
                    ui.add(egui::Image::from_texture((texture.id(), egui::vec2(120.0, 120.0))));
                    ui.small(caption);
                });
            }
        }
    });
}
