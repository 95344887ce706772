//! Depth of field in the app: the plate defocused on a thread through the flare's own lens and stop, the DoF
//! row under the view, and focus by click.
//!
//! # How it works
//! [`DofWork`] sits beside [`Derived`] (it reads the sharp plate and the flare there and puts the defocused plate
//! back): whenever what the defocused plate depends on changes (the document's depth
//! of field, its depth map, the prepared flare, the sensor, the sharp plate), a job reads the depth map, plans
//! the live method ([`flare_core::dof::live`]) and draws it on the app's own wgpu device
//! ([`flare_core::render::dof_gpu`]), or on its CPU twin where the adapter is a software one (lavapipe: the twin
//! is about twice as fast there) or the reference method is chosen. Until it is done the view shows the sharp
//! plate and the status says so; the result replaces the plate the view and exports use, and the flare is
//! drawn over it unblurred. A failure (a depth map of another size, a bad depth) is said once in the status bar
//! and the sharp plate stays. The DoF row and focus by click are in `dof_row.rs`.

use std::sync::{Arc, Mutex};
use std::time::Instant;

use eframe::egui_wgpu::RenderState;
use flare_core::dof::live::LivePlan;
use flare_core::dof::{self, DofMethod};
use flare_core::image::HdrImage;
use flare_core::preset::Document;
use flare_core::render::dof_gpu::GpuDof;

use super::job::{Job, Slot};
use crate::app::derived::{Derived, SyncEvent};

/// What a defocused plate was made from (a fingerprint).
type DofKey = u64;

/// The app's device for the live method: device, queue, adapter name, whether it is a software adapter.
type AppDevice = (wgpu::Device, wgpu::Queue, String, bool);

/// A finished job: the defocused plate and what to say about it.
type DofOutcome = Result<(HdrImage, String), String>;

/// The depth of field's work in progress and what the view shows (see the module documentation).
#[derive(Default)]
pub struct DofWork {
    /// The defocus running (or waiting for a cancelled one to stop), and what it is for.
    slot: Slot<DofKey, DofOutcome>,
    /// The key of the defocused plate shown (or of the failure said, or of the defocus cancelled), if any.
    shown: Option<DofKey>,
    /// Cancel was clicked: the next [`Self::sync`] stops the defocus and keeps the sharp plate.
    cancel_asked: bool,
    /// What the status bar says about the depth of field.
    pub status: String,
    /// The live method's pipelines on the app's device, made once.
    gpu: Arc<Mutex<Option<GpuDof>>>,
    /// Draw the live method on the app's device even when it is a software adapter (where the CPU twin is
    /// faster; the tests use it to run the GPU path on lavapipe).
    pub gpu_on_software: bool,
}

impl DofWork {
    /// True while a defocus is being computed, waits, or a cancelled one is still stopping.
    pub fn busy(&self) -> bool {
        self.slot.busy()
    }

    /// The running defocus's progress (`None` when none runs or waits).
    pub fn progress(&self) -> Option<(f32, String)> {
        self.slot.progress()
    }

    /// Stops the running defocus at its next check; the sharp plate stays until the depth of field changes.
    pub fn cancel(&mut self) {
        self.cancel_asked = true;
    }

    /// True when the plate shown is the defocused one for `key`.
    fn current(&self, key: DofKey) -> bool {
        self.shown == Some(key) && !self.slot.active()
    }
}

impl DofWork {
    /// The key of what the defocused plate depends on now; `None` when the depth of field is off or there is
    /// nothing to defocus.
    fn key(derived: &Derived, doc: &Document) -> Option<DofKey> {
        let flare = derived.flare().as_ref()?;
        derived.sharp_plate().as_ref()?;
        doc.dof.enabled.then(|| {
            flare_core::fingerprint::of(&(
                &doc.dof,
                doc.depth_at(derived.playhead()),
                flare.id,
                doc.sensor_width_mm.to_bits(),
                derived.sharp_generation(),
            ))
        })
    }

    /// True when the plate the view and exports use is what the document's depth of field asks for.
    pub fn ready(&self, derived: &Derived, doc: &Document) -> bool {
        match Self::key(derived, doc) {
            Some(key) => self.current(key),
            None => true,
        }
    }

    /// Starts, polls or undoes the defocus of `derived`'s plate (see the module documentation).
    pub fn sync(
        &mut self,
        derived: &mut Derived,
        doc: &Document,
        gpu: Option<&RenderState>,
        events: &mut Vec<SyncEvent>,
    ) {
        let finished = self.slot.poll();
        let show_sharp = |derived: &mut Derived| {
            let sharp = derived.sharp_plate().clone();
            derived.show_plate(sharp, gpu);
        };
        let Some(key) = Self::key(derived, doc) else {
            self.slot.cancel();
            self.cancel_asked = false;
            if self.shown.take().is_some() {
                show_sharp(derived);
            }
            self.status = if doc.dof.enabled && derived.sharp_plate().is_none() {
                "depth of field: on, but there is no plate to defocus (File > Background plate)".into()
            } else {
                String::new()
            };
            return;
        };
        if std::mem::take(&mut self.cancel_asked) && self.slot.cancel().is_some() {
            // Not started again until what it depends on changes.
            self.shown = Some(key);
            show_sharp(derived);
            self.status = "depth of field: cancelled (the sharp plate until the depth of field changes)".into();
            return;
        }
        if let Some(done) = finished.filter(|done| done.key == key) {
            self.shown = Some(key);
            match done.outcome {
                Ok((image, note)) => {
                    self.status = format!("depth of field: {note}");
                    derived.show_plate(Some(Arc::new(image)), gpu);
                }
                Err(e) => {
                    // Said once; the sharp plate stays until something changes.
                    self.status = format!("depth of field: {e}");
                    events.push(SyncEvent::Message(format!("depth of field: {e}")));
                    show_sharp(derived);
                }
            }
            return;
        }
        if self.shown == Some(key) {
            // Back to what is shown (an undo): a defocus for anything else stops.
            self.slot.cancel();
            return;
        }
        let start = self.start(derived, doc, gpu);
        self.slot.request(key, start);
        if let Some((_, text)) = self.slot.progress() {
            self.status = format!("depth of field: {text}");
        }
    }

    /// What starts a job defocusing the sharp plate as `doc` says, on the app's device or the CPU.
    fn start(
        &self,
        derived: &Derived,
        doc: &Document,
        gpu: Option<&RenderState>,
    ) -> impl FnOnce() -> Job<DofOutcome> + 'static {
        let (doc, flare, plate) = (doc.clone(), derived.flare().clone(), derived.sharp_plate().clone());
        let frame = derived.playhead();
        let device: Option<AppDevice> = gpu.map(|rs| {
            let info = rs.adapter.get_info();
            let software = info.device_type == wgpu::DeviceType::Cpu && !self.gpu_on_software;
            (rs.device.clone(), rs.queue.clone(), info.name, software)
        });
        let pipelines = self.gpu.clone();
        move || {
            Job::spawn("reading the depth map", move |cancel, report| {
                let (Some(flare), Some(plate)) = (flare, plate) else { return Err("no lens or no plate".into()) };
                let depth = doc.depth_at(frame).ok_or("no depth map (choose one in the DoF row)")?;
                let lens = flare_core::shot::plate::dof_lens(&doc, &flare);
                let started = Instant::now();
                let (models, depth_mm) =
                    dof::prepare(&doc.dof, lens, &depth, (plate.width, plate.height)).map_err(|e| e.to_string())?;
                if cancel.load(std::sync::atomic::Ordering::Relaxed) {
                    return Err("cancelled".into());
                }
                let model = &models[0];
                let colour = if models.len() == 3 { ", R, G, B each at its wavelength" } else { "" };
                let focus = format!(
                    "focus {:.2} m, far field {:.0} px{colour}",
                    model.focus_mm / 1000.0,
                    model.far_defocus_px()
                );
                if doc.dof.method == DofMethod::Reference {
                    report(0.2, "the reference method (every pixel's kernel, on the CPU)".into());
                    let image = dof::per_channel(&plate, &models, |plate, model| {
                        dof::reference::render_until(
                            plate,
                            &depth_mm,
                            model,
                            flare.mask(),
                            dof::reference::LAYER_PX,
                            cancel,
                        )
                        .map_err(|e| e.to_string())
                    })?;
                    return Ok((
                        image,
                        format!("reference on the CPU, {focus}, {:.2} s", started.elapsed().as_secs_f64()),
                    ));
                }
                report(0.2, "planning the layers".into());
                let mut held = pipelines.lock().map_err(|_| "the GPU pipelines are poisoned".to_string())?;
                let mut how = String::new();
                let image = dof::per_channel(&plate, &models, |plate, model| {
                    let plan = LivePlan::new(&depth_mm, model, flare.mask()).map_err(|e| e.to_string())?;
                    let layers = plan.layers.len();
                    if let Some((device, queue, adapter, false)) = &device {
                        report(0.4, format!("live on {adapter}"));
                        let dof_gpu = held.get_or_insert_with(|| GpuDof::new(device));
                        match dof_gpu.render_on(device, queue, &plan, plate) {
                            Ok(out) => {
                                how = format!(
                                    "live on {adapter}, {layers} layers{}",
                                    out.gpu_ms.map_or(String::new(), |ms| format!(" ({ms:.1} ms GPU time)"))
                                );
                                return Ok(out.image);
                            }
                            Err(e) => report(0.5, format!("the GPU failed ({e}): on the CPU twin")),
                        }
                    }
                    report(0.4, "live on the CPU twin".into());
                    let why = match &device {
                        Some((_, _, adapter, true)) => format!(" ({adapter} is a software adapter)"),
                        _ => String::new(),
                    };
                    how = format!("live on the CPU twin{why}, {layers} layers");
                    plan.render_cpu_until(plate, cancel).ok_or_else(|| "cancelled".to_string())
                })?;
                Ok((image, format!("{how}, {focus}, {:.0} ms", started.elapsed().as_secs_f64() * 1e3)))
            })
        }
    }
}
