//! What every subcommand shares: opening a lens by file or built-in name, and parsing the small value syntaxes
//! of the flags (pairs of numbers, coatings, apertures).

use std::path::Path;

use anyhow::{Context, Result, bail};
use flare_core::flare::PreparedFlare;
use flare_core::optics::formats::{LoadedLens, read_lens_file};
use flare_core::optics::library::builtin_lens;
use flare_core::optics::{Coating, CoatingLayer, Lens};
use flare_core::preset::{ApertureDoc, Document};

fn parse_pair<T: std::str::FromStr>(s: &str, what: &str) -> Result<(T, T), String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    match parts.as_slice() {
        [a, b] => match (a.parse(), b.parse()) {
            (Ok(a), Ok(b)) => Ok((a, b)),
            _ => Err(format!("`{s}` is not two {what} separated by a comma")),
        },
        _ => Err(format!("`{s}` is not two {what} separated by a comma")),
    }
}

pub fn parse_pair_f64(s: &str) -> Result<(f64, f64), String> {
    let (a, b) = parse_pair::<f64>(s, "numbers")?;
    if a.is_finite() && b.is_finite() { Ok((a, b)) } else { Err(format!("`{s}` is not finite")) }
}

pub fn parse_pair_u32(s: &str) -> Result<(u32, u32), String> {
    let (a, b) = s.split_once(',').ok_or_else(|| format!("`{s}`: give A,B"))?;
    let parse = |v: &str| v.trim().parse::<u32>().map_err(|_| format!("`{v}` is not a whole number"));
    Ok((parse(a)?, parse(b)?))
}

pub fn parse_pair_usize(s: &str) -> Result<(usize, usize), String> {
    parse_pair(s, "surface numbers")
}

/// Opens a lens: a file if the path exists, else a built-in lens by name. What loading had to decide (clipped
/// clear apertures, the system aperture) is said on stderr, once per warning.
pub fn open_lens(name: &str) -> Result<Lens> {
    let loaded = open_lens_checked(name)?;
    for warning in &loaded.warnings {
        eprintln!("warning: {name}: {warning}");
    }
    Ok(loaded.lens)
}

/// [`open_lens`] with the warnings returned instead of printed.
pub fn open_lens_checked(name: &str) -> Result<LoadedLens> {
    let path = Path::new(name);
    if path.exists() {
        return read_lens_file(path).with_context(|| name.to_string());
    }
    let looks_like_path = name.contains(['/', '\\']) || name.contains('.');
    match builtin_lens(name) {
        Ok(lens) => Ok(LoadedLens { lens, warnings: Vec::new() }),
        Err(_) if looks_like_path => bail!("{name}: no such file"),
        Err(e) => bail!("{name}: no such file, and {e}"),
    }
}

pub fn check_wavelength(nm: f64) -> Result<()> {
    use flare_core::spectrum::{MAX_WAVELENGTH_NM, MIN_WAVELENGTH_NM};
    if !(MIN_WAVELENGTH_NM..=MAX_WAVELENGTH_NM).contains(&nm) {
        bail!("--wavelength-nm {nm}: outside {MIN_WAVELENGTH_NM}-{MAX_WAVELENGTH_NM} nm");
    }
    Ok(())
}

/// Parses a coating override: `lens` (each surface's own: no override), `none`, `quarter-wave[:NM]`,
/// multilayer:INDEX/THICKNESS_NM,...
pub fn parse_coating_override(spec: &str) -> Result<Option<Coating>> {
    if spec == "lens" { Ok(None) } else { parse_coating(spec).map(Some) }
}

/// Parses a coating: `none`, `quarter-wave[:NM]`, `broadband` ([`Coating::broadband`]),
/// `multilayer:INDEX/THICKNESS_NM,...`
pub fn parse_coating(spec: &str) -> Result<Coating> {
    let (kind, rest) = spec.split_once(':').unwrap_or((spec, ""));
    let coating = match kind {
        "none" | "uncoated" => Coating::Uncoated,
        "broadband" => Coating::broadband(),
        "quarter-wave" | "qw" => Coating::QuarterWave {
            design_wavelength_nm: if rest.is_empty() {
                550.0
            } else {
                rest.parse().with_context(|| format!("--coating {spec}: `{rest}` is not a wavelength"))?
            },
            layer_index: None,
        },
        "multilayer" => {
            let mut layers = Vec::new();
            for layer in rest.split(',').filter(|l| !l.is_empty()) {
                let (n, t) = layer
                    .split_once('/')
                    .with_context(|| format!("--coating {spec}: layer `{layer}` is not INDEX/THICKNESS_NM"))?;
                let (index, thickness_nm) = (n.parse::<f64>(), t.parse::<f64>());
                let (Ok(index), Ok(thickness_nm)) = (index, thickness_nm) else {
                    bail!("--coating {spec}: layer `{layer}` is not two numbers")
                };
                layers.push(CoatingLayer { index, thickness_nm });
            }
            if layers.is_empty() {
                bail!("--coating {spec}: a multilayer needs at least one INDEX/THICKNESS_NM layer");
            }
            Coating::Multilayer { layers }
        }
        other => bail!("--coating {other}: use lens, none, quarter-wave[:NM], broadband or multilayer:N/T,..."),
    };
    // Validate through a lens surface so that the rules are the lens file's rules.
    let mut probe = flare_core::optics::library::default_lens();
    probe.surfaces[0].coating = coating.clone();
    probe.validate().map_err(|e| anyhow::anyhow!("--coating {spec}: {e}"))?;
    Ok(coating)
}

/// Parses a dirt pattern into `dirt`: `none`, `dust[:SEED]`, `smudges[:SEED]`, `haze` or `image:PATH` (the
/// amount and spread are kept).
pub fn parse_dirt(spec: &str, dirt: &mut flare_core::dirt::DirtDoc) -> Result<()> {
    use flare_core::dirt::DirtKind;
    let (kind, rest) = spec.split_once(':').map_or((spec, None), |(k, r)| (k, Some(r)));
    let seed = |rest: Option<&str>| -> Result<u64> {
        rest.map_or(Ok(dirt.seed), |r| r.parse().with_context(|| format!("--dirt {spec}: the seed is a whole number")))
    };
    match kind {
        "none" => dirt.pattern = DirtKind::None,
        "dust" => (dirt.pattern, dirt.seed) = (DirtKind::Dust, seed(rest)?),
        "smudges" => (dirt.pattern, dirt.seed) = (DirtKind::Smudges, seed(rest)?),
        "haze" => dirt.pattern = DirtKind::Haze,
        "image" => {
            let path = rest.filter(|p| !p.is_empty()).with_context(|| format!("--dirt {spec}: image:PATH"))?;
            if !std::path::Path::new(path).is_file() {
                bail!("--dirt {spec}: no such image file");
            }
            (dirt.pattern, dirt.image) = (DirtKind::Image, Some(path.to_owned()));
        }
        other => bail!("--dirt {other}: use none, dust[:SEED], smudges[:SEED], haze or image:PATH"),
    }
    Ok(())
}

/// Parses an aperture: `circle`, `blades:N[:ROTATION_DEG[:ROUNDNESS]]`, `image:PATH` (the f-number is kept).
pub fn parse_aperture(spec: &str, f_number: Option<f64>) -> Result<ApertureDoc> {
    let mut parts = spec.split(':');
    let mut doc = ApertureDoc { f_number, ..ApertureDoc::default() };
    match parts.next().unwrap_or("") {
        "circle" => doc.blades = 0,
        "blades" => {
            doc.blades =
                parts.next().unwrap_or("6").parse().with_context(|| format!("--aperture {spec}: blade count"))?;
            let mut optional = |what: &str| -> Result<f64> {
                let value = parts.next().map(str::parse::<f64>).transpose();
                Ok(value.with_context(|| format!("--aperture {spec}: {what}"))?.unwrap_or(0.0))
            };
            doc.rotation_deg = optional("rotation")?;
            doc.roundness = optional("roundness")?;
            if !(3..=32).contains(&doc.blades) {
                bail!("--aperture {spec}: 3 to {} blades", flare_core::aperture::MAX_BLADES);
            }
        }
        "image" => {
            let path = spec.split_once(':').map(|(_, p)| p).unwrap_or("");
            if !Path::new(path).is_file() {
                bail!("--aperture {spec}: no such image file");
            }
            doc.image = Some(path.to_owned());
        }
        other => bail!("--aperture {other}: use circle, blades:N[:ROTATION_DEG[:ROUNDNESS]] or image:PATH"),
    }
    Ok(doc)
}

/// The document a command works on: a preset (or the default document, the app's first frame) with LENS,
/// the coating and the f-number given replacing its fields. `render`, `classify` and `bake` all start here,
/// so a LUT's optics (and fingerprint) match the frames it is used in.
#[derive(clap::Args, Debug, Clone, Default)]
#[command(next_help_heading = "Optics")]
pub struct OpticsChoice {
    /// Lens file or built-in lens name (default: the preset's lens, else the default lens).
    #[arg(value_name = "LENS")]
    pub file: Option<String>,
    /// A preset: a .json file or the name of a shipped one (`flarelab preset list`).
    #[arg(long)]
    pub preset: Option<String>,
    /// Coating on every surface: lens (each surface's own), none, quarter-wave[:NM], broadband, multilayer:N/T,...
    /// (default: the preset's).
    #[arg(long)]
    pub coating: Option<String>,
    /// f-number (default: the preset's, else wide open).
    #[arg(long)]
    pub f_number: Option<f64>,
}

impl OpticsChoice {
    /// The document: the preset or the default, with these fields replaced (not yet checked).
    pub fn document(&self) -> Result<Document> {
        let mut doc = match &self.preset {
            Some(name) => Document::open_named(name).with_context(|| format!("--preset {name}"))?,
            None => Document::default(),
        };
        if let Some(file) = &self.file {
            doc.lens = open_lens(file)?;
        }
        if let Some(spec) = &self.coating {
            doc.coating_override = parse_coating_override(spec)?;
        }
        if let Some(f) = self.f_number {
            doc.aperture.f_number = Some(f);
        }
        Ok(doc)
    }

    /// The prepared flare of the checked document.
    pub fn flare(&self) -> Result<PreparedFlare> {
        let doc = self.document()?;
        doc.check().map_err(|e| anyhow::anyhow!("{e}"))?;
        let config = doc.flare_config().map_err(|e| anyhow::anyhow!("{e}"))?;
        PreparedFlare::new(&doc.lens, &config).with_context(|| doc.lens.id.clone())
    }
}

/// Where the frame is drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum DeviceArg {
    /// A GPU when wgpu finds an adapter, else the CPU twin (said on the terminal).
    Auto,
    /// wgpu (a software adapter such as lavapipe counts); refused when there is none.
    Gpu,
    /// The renderer's CPU twin.
    Cpu,
}

/// The depth of field's method (`dof --method`, `render --dof-method`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum MethodArg {
    Live,
    Reference,
}

impl From<MethodArg> for flare_core::dof::DofMethod {
    fn from(m: MethodArg) -> Self {
        match m {
            MethodArg::Live => Self::Live,
            MethodArg::Reference => Self::Reference,
        }
    }
}
