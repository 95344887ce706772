//! Light paths: the ordered surface interactions a ray makes, for the image and for every ghost.
//!
//! # How it works
//! The image-forming path refracts at surfaces 0, 1, ..., N-1. A two-reflection ghost (i, j), i < j,
//! goes forward to j and reflects there, travels back refracting at j-1 ... i+1, reflects at i, then goes
//! forward again through i+1 ... N-1: the sequence `[0..=j, j-1..=i, i+1..N]` of the reference figures.
//! A [`LightPath`] lists those [`Step`]s with the travel direction *arriving* at each one and the media on
//! both sides, so that the exact tracer ([`crate::optics::trace`]) and the paraxial matrices
//! ([`crate::optics::paraxial`]) walk one and the same description of the path and cannot disagree on it.
//! A ghost whose reflections lie on both sides of the stop crosses the stop three times; the path records
//! every crossing ([`LightPath::stop_crossings`]).

use super::lens::Lens;

/// What the light does at a surface.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Interaction {
    Refract,
    Reflect,
}

/// One interaction of a path.
#[derive(Clone, Debug, PartialEq)]
pub struct Step {
    /// The surface, numbered from 0 in file order.
    pub surface: usize,
    pub interaction: Interaction,
    /// +1 when the light arrives travelling towards +z, -1 when it arrives travelling back.
    pub arriving_direction: f64,
    /// Medium the light arrives in, as a slot of [`Lens::media_indices_at`]: 0 is object-space air,
    /// k + 1 the medium after surface k.
    pub medium_in: usize,
    /// Medium the light leaves in (the same as `medium_in` for a reflection).
    pub medium_out: usize,
}

impl Step {
    /// Travel direction after the step.
    pub fn leaving_direction(&self) -> f64 {
        match self.interaction {
            Interaction::Refract => self.arriving_direction,
            Interaction::Reflect => -self.arriving_direction,
        }
    }
}

/// Which path: the image, or the ghost reflected at `j` then at `i` (i < j).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum PathKind {
    Image,
    Ghost { i: usize, j: usize },
}

/// Why a path cannot be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PathError {
    #[error("ghost ({i}, {j}): needs i < j")]
    Order { i: usize, j: usize },
    #[error("ghost ({i}, {j}): the lens has only {surfaces} surfaces (numbered 0..{last})", last = .surfaces - 1)]
    OutOfRange { i: usize, j: usize, surfaces: usize },
    #[error("ghost ({i}, {j}): surface {k} does not reflect ({why})")]
    NotReflecting { i: usize, j: usize, k: usize, why: &'static str },
}

/// The steps of one path through a lens.
#[derive(Clone, Debug, PartialEq)]
pub struct LightPath {
    pub kind: PathKind,
    pub steps: Vec<Step>,
}

impl LightPath {
    /// The image-forming path: refraction at every surface in order.
    pub fn image(lens: &Lens) -> Self {
        let steps = (0..lens.surfaces.len()).map(|k| refract(k, 1.0)).collect();
        Self { kind: PathKind::Image, steps }
    }

    /// The ghost reflected at `j`, then at `i`. Both must be reflecting surfaces (the media on their two sides
    /// differ; a stop on a lens surface reflects, an iris does not).
    pub fn ghost(lens: &Lens, i: usize, j: usize) -> Result<Self, PathError> {
        let n = lens.surfaces.len();
        if i >= j {
            return Err(PathError::Order { i, j });
        }
        if j >= n {
            return Err(PathError::OutOfRange { i, j, surfaces: n });
        }
        for k in [i, j] {
            if !lens.medium_before(k).differs_from(&lens.surfaces[k].medium) {
                let why = if lens.surfaces[k].stop {
                    "it is the aperture stop, an iris with the same medium on both sides"
                } else {
                    "the same medium lies on both sides"
                };
                return Err(PathError::NotReflecting { i, j, k, why });
            }
        }
        let mut steps = Vec::with_capacity(j + 1 + (j - i) + (n - i - 1));
        steps.extend((0..j).map(|k| refract(k, 1.0)));
        steps.push(reflect(j, 1.0));
        steps.extend((i + 1..j).rev().map(|k| refract(k, -1.0)));
        steps.push(reflect(i, -1.0));
        steps.extend((i + 1..n).map(|k| refract(k, 1.0)));
        Ok(Self { kind: PathKind::Ghost { i, j }, steps })
    }

    /// Builds the path of `kind`.
    pub fn new(lens: &Lens, kind: PathKind) -> Result<Self, PathError> {
        match kind {
            PathKind::Image => Ok(Self::image(lens)),
            PathKind::Ghost { i, j } => Self::ghost(lens, i, j),
        }
    }

    /// Positions (in `steps`) at which the path crosses the aperture stop: one for most paths, three for a
    /// ghost whose two reflections lie on opposite sides of the stop, two for a ghost that reflects at a stop
    /// on a lens surface.
    pub fn stop_crossings(&self, lens: &Lens) -> Vec<usize> {
        let stop = lens.stop_index();
        self.steps.iter().enumerate().filter(|(_, s)| s.surface == stop).map(|(k, _)| k).collect()
    }

    /// True for a ghost whose reflections lie on opposite sides of the stop (it crosses the stop three times).
    pub fn straddles_stop(&self, lens: &Lens) -> bool {
        self.stop_crossings(lens).len() == 3
    }
}

fn refract(k: usize, direction: f64) -> Step {
    let (medium_in, medium_out) = if direction > 0.0 { (k, k + 1) } else { (k + 1, k) };
    Step { surface: k, interaction: Interaction::Refract, arriving_direction: direction, medium_in, medium_out }
}

fn reflect(k: usize, direction: f64) -> Step {
    let medium = if direction > 0.0 { k } else { k + 1 };
    Step {
        surface: k,
        interaction: Interaction::Reflect,
        arriving_direction: direction,
        medium_in: medium,
        medium_out: medium,
    }
}
