//! Aperture panel: blades (0 for a circle), their rotation and roundness, the f-number, a custom aperture
//! image; a live preview of the stop's mask and of its starburst (both from the prepared flare).

use eframe::egui;

use super::{Action, PanelContext};
use flare_core::preset::Document;

/// Preview textures, rebuilt when the prepared flare changes.
#[derive(Default)]
pub struct AperturePreview {
    key: usize,
    mask: Option<egui::TextureHandle>,
    starburst: Option<egui::TextureHandle>,
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
    let key = flare as *const _ as usize;
    if preview.key != key || preview.mask.is_none() {
        preview.key = key;
        let m = &flare.mask;
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
