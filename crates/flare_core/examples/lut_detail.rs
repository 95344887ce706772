//! Per entry of a LUT, the detail each halving loses (`LutEntry::detail_lost`, relative L1 of luminance against
//! the halved image's bilinear upsample), from the entry's own size down to 64 texels across: what the bake's
//! `detail_tolerance` decides on. The README's figures for the Heliar's two ghosts and the Nikon zoom's large
//! entries came from it.
//!
//! `cargo run --release -p flare_core --example lut_detail -- LUT.flut`

use flare_core::lut::format::read_lut;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let path = std::env::args().nth(1).ok_or("usage: lut_detail LUT.flut")?;
    let lut = read_lut(std::path::Path::new(&path))?;
    for ghost in &lut.ghosts {
        for e in ghost.entries.iter().filter(|e| !e.is_empty()) {
            let mut level = e.clone();
            let mut chain = Vec::new();
            while level.width.max(level.height) > 64 {
                let halved = level.halved();
                chain.push(format!("{}:{:.3}", level.width.max(level.height), level.detail_lost(&halved)));
                level = halved;
            }
            println!("ghost {} theta {:.2} phi {:.1}: {}", ghost.ghost, e.theta_deg, e.phi_deg, chain.join(" "));
        }
    }
    println!("{} texels in {} entries", lut.texel_count(), lut.entry_count());
    Ok(())
}
