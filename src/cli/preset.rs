//! `flarelab preset new|list`: the document the app saves, written from the command line, and the presets
//! shipped in the binary.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Subcommand;
use flare_core::preset::{Document, shipped};

use super::common::open_lens;

#[derive(Subcommand, Debug)]
pub enum PresetCommand {
    /// Write the default document (on LENS, or on the default lens) as a preset file.
    New {
        /// Lens file or built-in lens name (default: the default lens).
        lens: Option<String>,
        /// The preset file to write (.json).
        #[arg(short = 'o', long = "out", alias = "output")]
        out: PathBuf,
    },
    /// The presets shipped in the binary (usable as `flarelab render --preset NAME`).
    List {
        #[arg(long)]
        json: bool,
    },
}

pub fn run(command: PresetCommand) -> Result<()> {
    match command {
        PresetCommand::New { lens, out } => {
            flare_core::files::check_target(&out).map_err(|e| anyhow::anyhow!("-o {e}"))?;
            let doc = match lens {
                Some(name) => Document::for_lens(open_lens(&name)?),
                None => Document::default(),
            };
            doc.check().with_context(|| "the new preset")?;
            // The write's error names the file once (its cause is its message, not a second line).
            doc.save(&out).map_err(|e| anyhow::anyhow!("writing {}: {e}", out.display()))?;
            eprintln!("wrote {} ({})", out.display(), doc.lens.id);
            Ok(())
        }
        PresetCommand::List { json } => {
            let mut rows = Vec::new();
            for p in shipped() {
                let doc = p.document().with_context(|| format!("shipped preset {}", p.name))?;
                rows.push((p, doc));
            }
            if json {
                let out: Vec<_> = rows
                    .iter()
                    .map(|(p, d)| serde_json::json!({"name": p.name, "title": p.title, "lens": d.lens.id}))
                    .collect();
                println!("{}", serde_json::to_string_pretty(&out)?);
            } else {
                for (p, d) in rows {
                    println!("{:<18} {:<32} {}", p.name, d.lens.id, p.title);
                }
            }
            Ok(())
        }
    }
}
