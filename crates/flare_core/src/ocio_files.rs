//! An OCIO config read within bounds before OCIO reads it: its YAML's aliases, the files it names, and
//! `.ocioz` archives.
//!
//! # How it works
//! OCIO (the `ocio` crate) builds a config's YAML tree by cloning every alias, reads every LUT file a
//! transform names whole, and extracts a `.ocioz` archive into a shared temporary folder that it never
//! removes. Before it does any of that, [`load`] reads the config itself:
//! - **The YAML as events** ([`check_config_text`], `yaml-rust2`'s parser, which never expands an alias): the
//!   nodes the tree would have once every alias is expanded are counted (an anchor's subtree counted once, each
//!   alias adding that count) and a config past `MAX_YAML_NODES` is refused. A 1.2 KB "billion laughs"
//!   config once expanded to 5.7 GB and aborted the process.
//! - **The files it names**: every `src` (a FileTransform's file) is resolved as OCIO resolves it, absolute, or
//!   relative to each `search_path` entry (itself relative to the config's folder), and every such file that
//!   exists must be a regular file (a FIFO would block OCIO's read forever) of at most `MAX_LUT_FILE_BYTES`
//!   (a 3 GB sparse `.cube` once aborted the process). At most `MAX_NAMED_FILES` files are named. A name
//!   holding a context variable (`$SHOT`) cannot be resolved here and is refused.
//! - **Archives**: a `.ocioz` is extracted by [`load`] itself into a private folder ([`tempfile::TempDir`]):
//!   at most `MAX_ARCHIVE_ENTRIES` entries, each at most `MAX_LUT_FILE_BYTES` and all together at most
//!   `MAX_ARCHIVE_BYTES` as read (the sizes an archive declares are not trusted), names that would leave the
//!   folder refused; its `config.ocio` is then checked as above and loaded from there. The folder lives as
//!   long as the [`LoadedConfig`] and is removed with it (an 816 KB archive once left 800 MB in `$TMPDIR` per
//!   use).

use std::collections::HashMap;
use std::io::Read;
use std::path::{Component, Path, PathBuf};
use std::sync::Arc;

use yaml_rust2::parser::{Event, Parser};

/// The most nodes a config's YAML may have once its aliases are expanded: far above any real config (the
/// ACES studio config has about 20,000).
pub(crate) const MAX_YAML_NODES: u64 = 1_000_000;
/// The most bytes of one file a config names (a LUT, a CLF), and of one archive entry.
pub(crate) const MAX_LUT_FILE_BYTES: u64 = crate::files::MAX_TEXT_BYTES;
/// The most files a config may name (`src` entries).
pub(crate) const MAX_NAMED_FILES: usize = 4096;
/// The most entries of a `.ocioz` archive.
pub(crate) const MAX_ARCHIVE_ENTRIES: usize = 4096;
/// The most bytes a `.ocioz` archive may extract to, all entries together.
pub(crate) const MAX_ARCHIVE_BYTES: u64 = 256 * 1024 * 1024;

/// A config loaded within bounds, with the private folder its archive was extracted to (removed when the
/// last clone is dropped).
#[derive(Clone)]
pub struct LoadedConfig {
    pub config: ocio::Config,
    pub extracted: Option<Arc<tempfile::TempDir>>,
}

impl std::fmt::Debug for LoadedConfig {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LoadedConfig").field("extracted", &self.extracted).finish_non_exhaustive()
    }
}

/// What the YAML of a config names: `src` files and `search_path` entries.
#[derive(Debug, Default, PartialEq)]
pub struct Named {
    pub srcs: Vec<String>,
    pub search_paths: Vec<String>,
}

/// One open mapping or sequence while reading the events.
struct Open {
    mapping: bool,
    /// In a mapping: the next node is a key.
    expect_key: bool,
    key: Option<String>,
    anchor: usize,
    /// Nodes inside, aliases expanded.
    nodes: u64,
    /// A sequence that is a `search_path`'s value.
    search_path: bool,
}

/// The YAML `text` read as events: refused (with the line) when it does not parse or expands past
/// `MAX_YAML_NODES` nodes; otherwise what it names.
pub fn check_config_text(text: &str) -> Result<Named, String> {
    let mut parser = Parser::new_from_str(text);
    let mut stack: Vec<Open> = Vec::new();
    let mut anchors: HashMap<usize, u64> = HashMap::new();
    let mut expanded: u64 = 0;
    let mut named = Named::default();
    loop {
        let (event, mark) = parser.next_token().map_err(|e| format!("not YAML: {e}"))?;
        let done = match event {
            Event::StreamEnd => break,
            Event::Scalar(value, _, anchor, _) => {
                if anchor > 0 {
                    anchors.insert(anchor, 1);
                }
                Some((1, Some(value)))
            }
            Event::Alias(id) => Some((anchors.get(&id).copied().unwrap_or(1), None)),
            Event::SequenceStart(anchor, _) | Event::MappingStart(anchor, _) => {
                let mapping = matches!(event, Event::MappingStart(..));
                let search_path =
                    stack.last().is_some_and(|p| p.mapping && !p.expect_key && p.key.as_deref() == Some("search_path"));
                stack.push(Open { mapping, expect_key: true, key: None, anchor, nodes: 1, search_path });
                expanded = expanded.saturating_add(1);
                None
            }
            Event::SequenceEnd | Event::MappingEnd => {
                let open = stack.pop().ok_or("unbalanced YAML")?;
                if open.anchor > 0 {
                    anchors.insert(open.anchor, open.nodes);
                }
                // The container's nodes were counted as they came.
                add_to_parent(&mut stack, open.nodes, None, &mut named);
                None
            }
            _ => None,
        };
        if let Some((nodes, scalar)) = done {
            expanded = expanded.saturating_add(nodes);
            add_to_parent(&mut stack, nodes, scalar, &mut named);
        }
        if expanded > MAX_YAML_NODES {
            return Err(format!(
                "line {}: its aliases expand to more than {MAX_YAML_NODES} YAML nodes (an alias bomb?)",
                mark.line()
            ));
        }
        if named.srcs.len() > MAX_NAMED_FILES {
            return Err(format!("line {}: it names more than {MAX_NAMED_FILES} files", mark.line()));
        }
    }
    Ok(named)
}

/// A node of `nodes` (its scalar text, if it is one) completed inside the innermost open container: counted
/// there, and noted when it is a `src` or `search_path` value.
fn add_to_parent(stack: &mut [Open], nodes: u64, scalar: Option<String>, named: &mut Named) {
    let Some(top) = stack.last_mut() else { return };
    top.nodes = top.nodes.saturating_add(nodes);
    if !top.mapping {
        if top.search_path
            && let Some(s) = scalar
        {
            named.search_paths.push(s);
        }
        return;
    }
    if top.expect_key {
        top.key = scalar;
        top.expect_key = false;
        return;
    }
    if let Some(s) = scalar {
        match top.key.as_deref() {
            Some("src") => named.srcs.push(s),
            Some("search_path") => named.search_paths.extend(s.split(':').map(str::to_owned)),
            _ => {}
        }
    }
    top.expect_key = true;
}

/// Checks every file `named` names as OCIO would find it from the config's folder `dir` (see the module
/// documentation).
pub(crate) fn check_named_files(named: &Named, dir: &Path) -> Result<(), String> {
    let search: Vec<PathBuf> = if named.search_paths.is_empty() {
        vec![dir.to_path_buf()]
    } else {
        named.search_paths.iter().filter(|s| !s.trim().is_empty()).map(|s| dir.join(s.trim())).collect()
    };
    for src in &named.srcs {
        let shown = crate::files::shorten(src);
        if src.contains('$') || named.search_paths.iter().any(|s| s.contains('$')) {
            return Err(format!(
                "`{shown}`: a file named through a context variable cannot be checked before OCIO reads it; name it \
                 by its path"
            ));
        }
        let candidates: Vec<PathBuf> = if Path::new(src).is_absolute() {
            vec![PathBuf::from(src)]
        } else {
            search.iter().map(|d| d.join(src)).collect()
        };
        for path in candidates {
            // `metadata` follows links and never opens the file: a FIFO is seen, not waited on.
            let Ok(meta) = std::fs::metadata(&path) else { continue };
            if !meta.is_file() {
                return Err(format!("{}: not a regular file (a folder, FIFO or device)", path.display()));
            }
            if meta.len() > MAX_LUT_FILE_BYTES {
                return Err(format!(
                    "{}: {} bytes, more than the {} MiB a LUT file may have",
                    path.display(),
                    meta.len(),
                    MAX_LUT_FILE_BYTES >> 20
                ));
            }
        }
    }
    Ok(())
}

/// Extracts the `.ocioz` archive `path` into a private folder within bounds (see the module documentation).
pub fn extract_archive(path: &Path) -> Result<tempfile::TempDir, String> {
    let file = crate::files::open_regular(path)?;
    let mut zip = zip::ZipArchive::new(file).map_err(|e| format!("not a .ocioz archive: {e}"))?;
    if zip.len() > MAX_ARCHIVE_ENTRIES {
        return Err(format!("{} entries, more than {MAX_ARCHIVE_ENTRIES}", zip.len()));
    }
    let dir = tempfile::Builder::new().prefix("flarelab-ocioz-").tempdir().map_err(|e| e.to_string())?;
    let mut total: u64 = 0;
    for k in 0..zip.len() {
        let mut entry = zip.by_index(k).map_err(|e| format!("entry {k}: {e}"))?;
        let name = entry.name().map_err(|e| format!("entry {k}: {e}"))?.into_owned();
        let shown = crate::files::shorten(&name);
        let relative = Path::new(&name);
        if relative.components().any(|c| !matches!(c, Component::Normal(_))) {
            return Err(format!("entry `{shown}` would leave the archive's folder"));
        }
        let target = dir.path().join(relative);
        if entry.is_dir() {
            std::fs::create_dir_all(&target).map_err(|e| format!("{}: {e}", target.display()))?;
            continue;
        }
        if let Some(parent) = target.parent() {
            std::fs::create_dir_all(parent).map_err(|e| format!("{}: {e}", parent.display()))?;
        }
        let mut data = Vec::new();
        (&mut entry)
            .take(MAX_LUT_FILE_BYTES + 1)
            .read_to_end(&mut data)
            .map_err(|e| format!("entry `{shown}`: {e}"))?;
        if data.len() as u64 > MAX_LUT_FILE_BYTES {
            return Err(format!("entry `{shown}` holds more than {} MiB", MAX_LUT_FILE_BYTES >> 20));
        }
        total += data.len() as u64;
        if total > MAX_ARCHIVE_BYTES {
            return Err(format!("its entries hold more than {} MiB", MAX_ARCHIVE_BYTES >> 20));
        }
        std::fs::write(&target, &data).map_err(|e| format!("{}: {e}", target.display()))?;
    }
    Ok(dir)
}

/// Loads the config `name`: an `ocio://` built-in as it is, a file checked first (see the module
/// documentation). Errors are one line without the config's name (the caller says it).
pub fn load(name: &str) -> Result<LoadedConfig, String> {
    if name.trim_start().starts_with("ocio://") {
        let config = ocio::Config::create_from_file(name).map_err(|e| crate::files::one_line(&e.to_string()))?;
        return Ok(LoadedConfig { config, extracted: None });
    }
    let path = Path::new(name);
    let (file, extracted) = if name.to_ascii_lowercase().ends_with(".ocioz") {
        let dir = extract_archive(path)?;
        (dir.path().join("config.ocio"), Some(Arc::new(dir)))
    } else {
        (path.to_path_buf(), None)
    };
    let bytes = crate::files::read_bounded(&file, crate::files::MAX_TEXT_BYTES)?;
    let text = String::from_utf8_lossy(&bytes);
    let named = check_config_text(&text)?;
    let dir = file.parent().map_or_else(|| PathBuf::from("."), Path::to_path_buf);
    check_named_files(&named, &dir)?;
    let file_name = file.to_string_lossy().into_owned();
    let config = ocio::Config::create_from_file(&file_name).map_err(|e| crate::files::one_line(&e.to_string()))?;
    Ok(LoadedConfig { config, extracted })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Issue 61: a 1.2 KB config of nested aliases expanded by cloning to 5.7 GB and aborted the process.
    #[test]
    fn an_alias_bomb_is_refused_before_it_expands() {
        let mut text = String::from("ocio_profile_version: 2\na0: &a0 [x, x, x, x, x, x, x, x, x, x]\n");
        for k in 1..12 {
            let refs = vec![format!("*a{}", k - 1); 10].join(", ");
            text.push_str(&format!("a{k}: &a{k} [{refs}]\n"));
        }
        assert!(text.len() < 1500, "{}", text.len());
        let e = check_config_text(&text).unwrap_err();
        assert!(e.contains("alias") && e.contains("line"), "{e}");
        // A few aliases, as real configs use them, pass.
        let fine = "a: &x {k: 1}\nb: *x\nc: [*x, *x]\nsearch_path: luts:more\n";
        let named = check_config_text(fine).unwrap();
        assert_eq!(named.search_paths, vec!["luts", "more"]);
    }

    /// The files a config names are checked where OCIO would look: over the bound, or a FIFO, refused.
    #[test]
    fn the_files_a_config_names_are_checked_before_ocio_reads_them() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir(dir.path().join("luts")).unwrap();
        let text = "search_path:\n  - luts\ncolorspaces:\n  - !<ColorSpace>\n    name: a\n    from_scene_reference: \
                    !<FileTransform> {src: big.cube}\n";
        let named = check_config_text(text).unwrap();
        assert_eq!(named, Named { srcs: vec!["big.cube".into()], search_paths: vec!["luts".into()] });
        // Absent: OCIO says so itself.
        check_named_files(&named, dir.path()).unwrap();
        // A sparse file over the bound: refused by its size, never read.
        let big = std::fs::File::create(dir.path().join("luts/big.cube")).unwrap();
        big.set_len(MAX_LUT_FILE_BYTES + 1).unwrap();
        let e = check_named_files(&named, dir.path()).unwrap_err();
        assert!(e.contains("more than the 64 MiB"), "{e}");
        std::fs::remove_file(dir.path().join("luts/big.cube")).unwrap();
        #[cfg(unix)]
        {
            let fifo = dir.path().join("luts/big.cube");
            let made = std::process::Command::new("mkfifo").arg(&fifo).status();
            if made.is_ok_and(|s| s.success()) {
                let e = check_named_files(&named, dir.path()).unwrap_err();
                assert!(e.contains("not a regular file"), "{e}");
            }
        }
        let vars = check_config_text("colorspaces: [{t: !<FileTransform> {src: $SHOT.cube}}]\n").unwrap();
        assert!(check_named_files(&vars, dir.path()).unwrap_err().contains("context variable"));
    }

    /// Issue 61: a `.ocioz` went to a shared temporary folder that was never removed; its entries were not
    /// bounded. Now: a private folder, removed with the config; entries bounded as read; no way out of it.
    #[test]
    fn an_archive_is_extracted_within_bounds_to_a_private_folder_that_goes_with_the_config() {
        use std::io::Write;
        let dir = tempfile::tempdir().unwrap();
        let write = |name: &str, entries: &[(&str, &[u8])]| {
            let path = dir.path().join(name);
            let mut zip = zip::ZipWriter::new(std::fs::File::create(&path).unwrap());
            let options = zip::write::SimpleFileOptions::default();
            for (entry, data) in entries {
                zip.start_file(*entry, options).unwrap();
                zip.write_all(data).unwrap();
            }
            zip.finish().unwrap();
            path
        };
        let config = ocio::Config::create_from_file(crate::view_transform::DEFAULT_CONFIG).unwrap();
        let text = config.serialize().unwrap();
        let good = write("good.ocioz", &[("config.ocio", text.as_bytes())]);
        let loaded = load(good.to_str().unwrap()).unwrap();
        let extracted = loaded.extracted.clone().unwrap().path().to_path_buf();
        assert!(extracted.join("config.ocio").is_file());
        drop(loaded);
        assert!(!extracted.exists(), "the private folder goes with the config");
        let escape = write("escape.ocioz", &[("../evil.cube", b"x")]);
        assert!(load(escape.to_str().unwrap()).unwrap_err().contains("would leave"));
        // An entry of 65 MiB of zeros (a small archive): refused as it is read.
        let zeros = vec![0u8; (MAX_LUT_FILE_BYTES + 1) as usize];
        let bomb = write("bomb.ocioz", &[("config.ocio", text.as_bytes()), ("luts/zero.cube", &zeros)]);
        assert!(std::fs::metadata(&bomb).unwrap().len() < 1 << 20);
        assert!(load(bomb.to_str().unwrap()).unwrap_err().contains("more than 64 MiB"));
    }
}
