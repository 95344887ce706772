//! Files written whole and read within bounds: every file FlareLab writes (images, presets, lenses, LUTs) goes
//! through [`write_atomic`], and every text file it reads (presets, tracks, glass catalogues, sidecars)
//! through `read_bounded`.
//!
//! # How it works
//! The bytes go to a temporary file in the target's folder, are flushed to disk, and the temporary file is
//! renamed over the target. A rename within one folder is atomic, so a reader (or a crash) sees the old file
//! or the new one, never half of one; on an error the temporary file is removed and the target is untouched.
//! A target that exists and is not a regular file (a FIFO, a device, a folder) is refused, never replaced; a
//! symbolic link is written through (its target replaced, the link kept). Temporary files are named
//! `.flarelab-tmp-PID-*`, so what a killed process left behind is recognised and removed (`remove_stale_temps`)
//! by the next write into that folder: at once when that process is gone, else once it is an hour old. A read takes at most `max_bytes + 1` bytes,
//! whatever the file claims to be (an endless FIFO or `/dev/zero` ends there with an error), and
//! [`shorten`] puts a token from a file into a message at most `TOKEN_CHARS` characters long, control
//! characters escaped.

use std::io::Write;
use std::path::Path;

/// Writes `contents` to `path` through a temporary file in the same folder and a rename: readers see the
/// old file or the new one, never half of one.
pub fn write_atomic(path: &Path, contents: &[u8]) -> std::io::Result<()> {
    // A link is written through: the file it names is replaced, the link stays.
    let resolved;
    let path = match std::fs::symlink_metadata(path) {
        Ok(meta) if meta.file_type().is_symlink() => {
            resolved = std::fs::canonicalize(path).or_else(|_| {
                // A dangling link: the file it names, made where the link points.
                let target = std::fs::read_link(path)?;
                Ok::<_, std::io::Error>(path.parent().map_or(target.clone(), |dir| dir.join(&target)))
            })?;
            resolved.as_path()
        }
        _ => path,
    };
    if let Ok(meta) = std::fs::metadata(path)
        && !meta.is_file()
    {
        // The caller names the file.
        return Err(std::io::Error::other(format!(
            "it exists and is not a regular file ({}): not replaced",
            kind_of(&meta)
        )));
    }
    let dir = folder_of(path);
    remove_stale_temps(dir, std::time::Duration::from_secs(3600));
    let prefix = format!("{TEMP_PREFIX}{}-", std::process::id());
    let mut tmp = tempfile::Builder::new().prefix(&prefix).tempfile_in(dir).map_err(plain)?;
    tmp.write_all(contents).map_err(plain)?;
    // The temporary file is private (0600); the result keeps the permissions of the file it replaces, or
    // gets the usual 0644 when it is new.
    let permissions = match std::fs::metadata(path) {
        Ok(existing) => existing.permissions(),
        Err(_) => default_permissions(tmp.as_file())?,
    };
    tmp.as_file().set_permissions(permissions).map_err(plain)?;
    tmp.as_file().sync_all().map_err(plain)?;
    tmp.persist(path).map_err(|e| plain(e.error))?;
    Ok(())
}

#[cfg(unix)]
fn default_permissions(_file: &std::fs::File) -> std::io::Result<std::fs::Permissions> {
    use std::os::unix::fs::PermissionsExt;
    Ok(std::fs::Permissions::from_mode(0o644))
}

#[cfg(not(unix))]
fn default_permissions(file: &std::fs::File) -> std::io::Result<std::fs::Permissions> {
    Ok(file.metadata()?.permissions())
}

/// The folder `path` is in (`.` for a bare name).
fn folder_of(path: &Path) -> &Path {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    }
}

/// Checks, before any work, that [`write_atomic`] could write `path`: its folder exists and a file can be made
/// in it (a temporary one, removed at once), and `path` is not there already as something other than a regular
/// file (what the write would refuse at the end of a long job). Issue 61: an unwritable folder was found only
/// after the whole bake (22 minutes for the Panavision look) or after every frame of a sequence.
pub fn check_target(path: &Path) -> Result<(), String> {
    let dir = folder_of(path);
    if !dir.is_dir() {
        return Err(format!("{}: the folder {} does not exist", path.display(), dir.display()));
    }
    if let Ok(meta) = std::fs::metadata(path)
        && !meta.is_file()
    {
        return Err(format!("{} exists and is not a regular file ({}): not replaced", path.display(), kind_of(&meta)));
    }
    probe_folder(path, dir)
}

/// Makes and removes a temporary file in `dir` as [`write_atomic`] would (`path`: what the caller will write,
/// named in the error).
fn probe_folder(path: &Path, dir: &Path) -> Result<(), String> {
    tempfile::Builder::new()
        .prefix(TEMP_PREFIX)
        .tempfile_in(dir)
        .map(drop)
        .map_err(|e| format!("{}: cannot write in the folder {}: {}", path.display(), dir.display(), plain(e)))
}

/// Checks, before any work, that the files of a sequence named like `path` can be written: the nearest folder
/// of its folder that exists (the sequence makes the rest) takes a file. See [`check_target`].
pub fn check_sequence_target(path: &Path) -> Result<(), String> {
    let mut dir = folder_of(path);
    while !dir.exists() {
        dir = folder_of(dir);
    }
    if !dir.is_dir() {
        return Err(format!("{}: {} is not a folder", path.display(), dir.display()));
    }
    probe_folder(path, dir)
}

/// `e` without the temporary file's path the `tempfile` crate appends (the caller names the target: the
/// temporary file is ours, not the user's, and named it twice).
fn plain(e: std::io::Error) -> std::io::Error {
    let text = e.to_string();
    match text.find(" at path ") {
        Some(at) => std::io::Error::new(e.kind(), text[..at].to_owned()),
        None => e,
    }
}

/// The name every temporary file of [`write_atomic`] starts with.
pub(crate) const TEMP_PREFIX: &str = ".flarelab-tmp-";

/// What a non-regular file is, in words.
fn kind_of(meta: &std::fs::Metadata) -> &'static str {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        let t = meta.file_type();
        if t.is_fifo() {
            return "a FIFO";
        }
        if t.is_char_device() || t.is_block_device() {
            return "a device";
        }
        if t.is_socket() {
            return "a socket";
        }
    }
    if meta.is_dir() { "a folder" } else { "not a plain file" }
}

/// Removes our own temporary files in `dir` left by a process that was killed while writing: at once when the
/// process named in the file (`.flarelab-tmp-PID-...`) is no longer running (Linux: no `/proc/PID`), else once
/// older than `age` (another system, or a process id used again). Returns how many. Anything else in the folder
/// is left alone, and a failure removes nothing more.
pub(crate) fn remove_stale_temps(dir: &Path, age: std::time::Duration) -> usize {
    let Ok(entries) = std::fs::read_dir(dir) else { return 0 };
    let now = std::time::SystemTime::now();
    let mut removed = 0;
    for entry in entries.flatten() {
        let name = entry.file_name();
        if !name.to_string_lossy().starts_with(TEMP_PREFIX) {
            continue;
        }
        let Ok(meta) = entry.metadata() else { continue };
        let old = meta.modified().ok().and_then(|m| now.duration_since(m).ok()).is_some_and(|d| d >= age);
        let writer = name.to_string_lossy()[TEMP_PREFIX.len()..].split('-').next().and_then(|p| p.parse::<u32>().ok());
        let writer_gone = cfg!(target_os = "linux")
            && writer.is_some_and(|pid| pid != std::process::id() && !Path::new(&format!("/proc/{pid}")).exists());
        if meta.is_file() && (old || writer_gone) && std::fs::remove_file(entry.path()).is_ok() {
            removed += 1;
        }
    }
    removed
}

/// The most bytes a text input (a preset, a track, a glass catalogue, a sidecar) may have: 64 MiB, far above
/// any real one (the largest shipped catalogue is under 1 MB).
pub(crate) const MAX_TEXT_BYTES: u64 = 64 * 1024 * 1024;

/// Opens `path` for reading if it is a regular file (links followed). A folder, a FIFO, a socket or a device is
/// refused before it is opened: opening a FIFO blocks until a writer comes, forever for a hostile input (issue
/// 61: a lens, a preset, a `.cube` or an OCIO config given as a FIFO hung the program in `open()`).
pub(crate) fn open_regular(path: &Path) -> Result<std::fs::File, String> {
    let fail = |e: std::io::Error| format!("cannot read {}: {e}", path.display());
    let meta = std::fs::metadata(path).map_err(fail)?;
    if meta.is_dir() {
        return Err(format!("{} is a folder, not a file", path.display()));
    }
    if !meta.is_file() {
        return Err(format!("{} is not a regular file (a FIFO, socket or device): give a file", path.display()));
    }
    std::fs::File::open(path).map_err(fail)
}

/// Reads `path` whole if it has at most `max_bytes`: at most `max_bytes + 1` bytes are ever read, whatever
/// the file claims (a FIFO or a device reports no length). The error is one line with the path.
pub(crate) fn read_bounded(path: &Path, max_bytes: u64) -> Result<Vec<u8>, String> {
    use std::io::Read;
    let fail = |e: std::io::Error| format!("cannot read {}: {e}", path.display());
    let file = open_regular(path)?;
    let meta = file.metadata().map_err(fail)?;
    if meta.len() > max_bytes {
        return Err(too_large(path, max_bytes));
    }
    let mut data = Vec::with_capacity(meta.len() as usize);
    file.take(max_bytes + 1).read_to_end(&mut data).map_err(fail)?;
    if data.len() as u64 > max_bytes {
        return Err(too_large(path, max_bytes));
    }
    Ok(data)
}

/// `read_bounded` as UTF-8 text.
pub fn read_text_bounded(path: &Path, max_bytes: u64) -> Result<String, String> {
    let bytes = read_bounded(path, max_bytes)?;
    String::from_utf8(bytes)
        .map_err(|e| format!("{}: not UTF-8 text (at byte {})", path.display(), e.utf8_error().valid_up_to()))
}

fn too_large(path: &Path, max_bytes: u64) -> String {
    format!("{} is larger than {} MiB, the most this file may be: not read", path.display(), max_bytes >> 20)
}

/// `text` with every number longer than `TOKEN_CHARS` characters written short (`1.000e302`, or cut as
/// [`shorten`] cuts): a value echoed from a file (a 302-digit `semi_aperture`, issue 61) keeps a message to a
/// line. Shorter numbers, paths and words are left as they are.
pub fn shorten_numbers(text: &str) -> String {
    let numeric = |c: char| c.is_ascii_digit() || matches!(c, '.' | 'e' | 'E' | '+' | '-');
    let mut out = String::with_capacity(text.len().min(1024));
    let mut run = String::new();
    let flush = |run: &mut String, out: &mut String| {
        if run.chars().count() > TOKEN_CHARS && run.chars().filter(char::is_ascii_digit).count() > TOKEN_CHARS / 2 {
            match run.parse::<f64>() {
                Ok(v) => out.push_str(&format!("{v:.3e}")),
                Err(_) => out.push_str(&shorten(run)),
            }
        } else {
            out.push_str(run);
        }
        run.clear();
    };
    for c in text.chars() {
        if numeric(c) {
            run.push(c);
        } else {
            flush(&mut run, &mut out);
            out.push(c);
        }
    }
    flush(&mut run, &mut out);
    out
}

/// A message about a file made safe to print: every `backquoted` token [`shorten`]ed, long numbers elsewhere
/// written short ([`shorten_numbers`]), control characters escaped.
pub fn clean(message: &str) -> String {
    let mut out = String::with_capacity(message.len().min(1024));
    for (k, part) in message.split('`').enumerate() {
        if k > 0 {
            out.push('`');
        }
        if k % 2 == 1 {
            out.push_str(&shorten(part));
        } else {
            out.extend(
                shorten_numbers(part)
                    .chars()
                    .flat_map(|c| if c.is_control() { c.escape_default().collect::<Vec<_>>() } else { vec![c] }),
            );
        }
    }
    out
}

/// [`clean`], then at most 400 characters (a parser's own message may quote a whole value).
pub(crate) fn one_line(message: &str) -> String {
    let cleaned = clean(message);
    match cleaned.char_indices().nth(400) {
        Some((at, _)) => format!("{}...", &cleaned[..at]),
        None => cleaned,
    }
}

/// The most characters of a token from a file that a message quotes.
pub(crate) const TOKEN_CHARS: usize = 40;

/// `token` for a message: at most `TOKEN_CHARS` characters (longer ones cut, saying how long they were),
/// control characters escaped, so a hostile file cannot flood or garble the terminal.
pub fn shorten(token: &str) -> String {
    let count = token.chars().count();
    let mut out: String = token.chars().take(TOKEN_CHARS).flat_map(char::escape_default).collect();
    if count > TOKEN_CHARS {
        out.push_str(&format!("... ({count} characters)"));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_long_token_is_cut_and_control_characters_escaped() {
        let long = "9".repeat(100_000);
        let s = shorten(&long);
        assert!(s.len() < 80 && s.ends_with("(100000 characters)"), "{s}");
        assert_eq!(shorten("a\u{1b}[2Jb"), "a\\u{1b}[2Jb");
        assert_eq!(shorten("a\u{7}b"), "a\\u{7}b");
    }

    #[cfg(unix)]
    #[test]
    fn an_endless_device_or_a_fifo_is_refused_before_it_is_opened() {
        let err = read_bounded(Path::new("/dev/zero"), 1 << 20).unwrap_err();
        assert!(err.contains("not a regular file"), "{err}");
        // Issue 61: a FIFO as an input (a lens, a preset, a .cube, an OCIO config) blocked forever in open().
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("in.json");
        if std::process::Command::new("mkfifo").arg(&fifo).status().is_ok_and(|s| s.success()) {
            let err = read_bounded(&fifo, 1 << 20).unwrap_err();
            assert!(err.contains("not a regular file"), "{err}");
            let err = crate::optics::formats::read_lens_file(&fifo).unwrap_err().to_string();
            assert!(err.contains("not a regular file"), "{err}");
            let err = crate::lut::format::read_lut(&fifo).unwrap_err().to_string();
            assert!(err.contains("not a regular file"), "{err}");
            let plate = dir.path().join("plate.exr");
            std::fs::rename(&fifo, &plate).unwrap();
            let err = crate::output::image_size(&plate, "plate").unwrap_err();
            assert!(err.contains("not a regular file"), "{err}");
        }
    }

    #[cfg(unix)]
    #[test]
    fn a_fifo_is_refused_and_a_link_is_written_through() {
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("out.png");
        assert!(std::process::Command::new("mkfifo").arg(&fifo).status().unwrap().success());
        let err = write_atomic(&fifo, b"x").unwrap_err().to_string();
        assert!(err.contains("a FIFO") && err.contains("not replaced") && !err.contains("out.png"), "{err}");
        let meta = std::fs::symlink_metadata(&fifo).unwrap();
        use std::os::unix::fs::FileTypeExt;
        assert!(meta.file_type().is_fifo(), "the FIFO is still there");
        let target = dir.path().join("real.json");
        std::fs::write(&target, b"old").unwrap();
        let link = dir.path().join("link.json");
        std::os::unix::fs::symlink(&target, &link).unwrap();
        write_atomic(&link, b"new").unwrap();
        assert!(std::fs::symlink_metadata(&link).unwrap().file_type().is_symlink(), "the link stays a link");
        assert_eq!(std::fs::read(&target).unwrap(), b"new");
    }

    #[test]
    fn stale_temporary_files_of_ours_are_removed_and_nothing_else() {
        let dir = tempfile::tempdir().unwrap();
        let ours = dir.path().join(format!("{TEMP_PREFIX}abc"));
        // A writer that is gone (no such process): removed at once, however young.
        let killed = dir.path().join(format!("{TEMP_PREFIX}4000000000-x"));
        std::fs::write(&killed, b"half").unwrap();
        let running = dir.path().join(format!("{TEMP_PREFIX}{}-y", std::process::id()));
        std::fs::write(&running, b"mine").unwrap();
        if cfg!(target_os = "linux") {
            assert_eq!(remove_stale_temps(dir.path(), std::time::Duration::from_secs(3600)), 1);
            assert!(!killed.exists() && running.exists(), "a live writer's file stays");
        }
        std::fs::remove_file(&running).unwrap();
        let _ = std::fs::remove_file(&killed);
        let theirs = dir.path().join(".other-tmp");
        std::fs::write(&ours, b"half").unwrap();
        std::fs::write(&theirs, b"keep").unwrap();
        assert_eq!(remove_stale_temps(dir.path(), std::time::Duration::from_secs(3600)), 0, "too young");
        assert_eq!(remove_stale_temps(dir.path(), std::time::Duration::ZERO), 1);
        assert!(!ours.exists() && theirs.exists());
    }
}
