//! File names of a sequence: `shot.####.exr` (as many `#` as digits) or `shot.%04d.exr` (printf style;
//! `%d` is no padding), the frame number substituted.
//!
//! # How it works
//! [`FramePattern::parse`] splits the name at its one frame field into a prefix, a width and a suffix; a
//! name with no field is not a pattern (`None`), one with two fields or wider than `MAX_FRAME_DIGITS` is
//! refused. [`FramePattern::path`]
//! writes the frame zero-padded to the width (a negative frame keeps its minus sign).
//! [`FramePattern::existing_frames`] lists the frames present on disk: the files of the pattern's folder
//! whose names are the prefix, digits (at least the width, or exactly it when padded numbers are longer
//! than needed) and the suffix.

use std::path::{Path, PathBuf};

/// The widest frame field (digits): an `i64` frame has at most 19 digits and a sign. Wider fields are refused
/// (`%070000d` once reached the formatter's limit of 65535 and panicked).
pub(crate) const MAX_FRAME_DIGITS: usize = 20;

/// A sequence's file name with its frame field (see the module documentation).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FramePattern {
    /// The pattern as given.
    pub text: String,
    prefix: String,
    width: usize,
    suffix: String,
}

impl FramePattern {
    /// The pattern in `text`, `Ok(None)` when it has no frame field, an error when it has two.
    pub fn parse(text: &str) -> Result<Option<Self>, String> {
        let hashes = find_hashes(text);
        let printf = find_printf(text);
        let (start, end, width) = match (hashes, printf) {
            (None, None) => return Ok(None),
            (Some(_), Some(_)) => return Err(format!("`{text}` has both a #### and a %d frame field: use one")),
            (Some(h), None) | (None, Some(h)) => h,
        };
        if find_hashes(&text[end..]).is_some() || find_printf(&text[end..]).is_some() {
            return Err(format!("`{text}` has two frame fields: use one"));
        }
        if width > MAX_FRAME_DIGITS {
            let field = crate::files::shorten(&text[start..end]);
            return Err(format!(
                "the frame field `{field}` pads to {} digits: at most {MAX_FRAME_DIGITS} (a frame number has at most 19 and a sign)",
                if width == usize::MAX { "too many".to_string() } else { width.to_string() }
            ));
        }
        Ok(Some(Self { text: text.to_string(), prefix: text[..start].into(), width, suffix: text[end..].into() }))
    }

    /// True when `text` names a sequence (has a frame field).
    pub fn is_pattern(text: &str) -> bool {
        find_hashes(text).is_some() || find_printf(text).is_some()
    }

    /// The file of frame `frame`.
    pub fn path(&self, frame: i64) -> PathBuf {
        PathBuf::from(format!("{}{:0width$}{}", self.prefix, frame, self.suffix, width = self.width))
    }

    /// The frames of this pattern that exist on disk, sorted.
    pub fn existing_frames(&self) -> Vec<i64> {
        let full = Path::new(&self.prefix);
        let (dir, name_prefix) = if self.prefix.ends_with('/') || self.prefix.is_empty() {
            (PathBuf::from(if self.prefix.is_empty() { "." } else { &self.prefix }), String::new())
        } else {
            let dir = full.parent().map(Path::to_path_buf).filter(|p| !p.as_os_str().is_empty());
            let name = full.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
            (dir.unwrap_or_else(|| PathBuf::from(".")), name)
        };
        let Ok(entries) = std::fs::read_dir(&dir) else { return Vec::new() };
        let mut frames: Vec<i64> = entries
            .filter_map(|e| e.ok())
            .filter_map(|e| {
                let name = e.file_name().to_string_lossy().into_owned();
                let digits = name.strip_prefix(&name_prefix)?.strip_suffix(&self.suffix)?;
                let unsigned = digits.strip_prefix('-').unwrap_or(digits);
                let ok = !unsigned.is_empty()
                    && unsigned.bytes().all(|b| b.is_ascii_digit())
                    && digits.len() >= self.width.max(1);
                ok.then(|| digits.parse().ok()).flatten()
            })
            .filter(|&f| self.path(f).exists())
            .collect();
        frames.sort_unstable();
        frames.dedup();
        frames
    }
}

/// The sequence a numbered file belongs to: `shot.0001.exr` with `shot.0002.exr` beside it is the pattern
/// `shot.####.exr` and its frames on disk. `None` when the name has no number before its extension or no
/// other file of the sequence exists.
pub fn sequence_of(path: &Path) -> Option<(FramePattern, Vec<i64>)> {
    let text = path.to_str()?;
    let name_start = text.len() - path.file_name()?.len();
    let stem_end = text.rfind('.').filter(|&d| d > name_start).unwrap_or(text.len());
    let digits_end = stem_end;
    let digits_start = text[name_start..digits_end]
        .char_indices()
        .rev()
        .take_while(|(_, c)| c.is_ascii_digit())
        .last()
        .map(|(i, _)| name_start + i)?;
    let width = digits_end - digits_start;
    let pattern_text = format!("{}{}{}", &text[..digits_start], "#".repeat(width), &text[digits_end..]);
    let pattern = FramePattern::parse(&pattern_text).ok()??;
    let frames = pattern.existing_frames();
    (frames.len() >= 2).then_some((pattern, frames))
}

/// The first run of `#` in `text`: (start, end, width).
fn find_hashes(text: &str) -> Option<(usize, usize, usize)> {
    let start = text.find('#')?;
    let end = start + text[start..].bytes().take_while(|&b| b == b'#').count();
    Some((start, end, end - start))
}

/// The first `%d` or `%0Nd` in `text`: (start, end, width; `usize::MAX` when the width cannot be read).
fn find_printf(text: &str) -> Option<(usize, usize, usize)> {
    let bytes = text.as_bytes();
    let mut from = 0;
    while let Some(offset) = text[from..].find('%') {
        let start = from + offset;
        let digits = bytes[start + 1..].iter().take_while(|b| b.is_ascii_digit()).count();
        let end = start + 1 + digits;
        if bytes.get(end) == Some(&b'd') {
            // A width too large to read is a field all the same (refused by `parse`), not literal text.
            let width = if digits == 0 { 0 } else { text[start + 1..end].parse().unwrap_or(usize::MAX) };
            return Some((start, end + 1, width));
        }
        from = start + 1;
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hashes_and_printf_fields_substitute_the_frame() {
        let p = FramePattern::parse("plates/shot.####.exr").unwrap().unwrap();
        assert_eq!(p.path(7), PathBuf::from("plates/shot.0007.exr"));
        assert_eq!(p.path(12345), PathBuf::from("plates/shot.12345.exr"));
        let p = FramePattern::parse("out/f.%04d.png").unwrap().unwrap();
        assert_eq!(p.path(42), PathBuf::from("out/f.0042.png"));
        let p = FramePattern::parse("f%d.png").unwrap().unwrap();
        assert_eq!(p.path(42), PathBuf::from("f42.png"));
        assert!(FramePattern::parse("still.exr").unwrap().is_none());
        assert!(FramePattern::parse("a.##.b.##.exr").is_err());
        assert!(FramePattern::parse("a.##.%04d.exr").is_err());
        assert!(!FramePattern::is_pattern("100%.png"));
    }

    /// Issue 61: `%070000d` passed the formatter's limit (65535) and panicked when a frame's name was made.
    #[test]
    fn a_frame_field_wider_than_a_frame_number_is_refused() {
        let p = FramePattern::parse("f.%020d.exr").unwrap().unwrap();
        assert_eq!(p.path(-1), PathBuf::from(format!("f.-{}1.exr", "0".repeat(18))));
        for text in ["f.%021d.exr", "f.%070000d.exr", "f.%099999999999999999999999999d.exr"] {
            let e = FramePattern::parse(text).unwrap_err();
            assert!(e.contains("at most 20"), "{e}");
            assert!(e.len() < 200, "{e}");
        }
        let hashes = format!("f.{}.exr", "#".repeat(70_000));
        let e = FramePattern::parse(&hashes).unwrap_err();
        assert!(e.contains("70000 digits") && e.len() < 200, "{e}");
        // The message quotes at most 40 characters of the name, whatever its length.
        assert!(!e.contains(&"#".repeat(41)), "{e}");
    }

    #[test]
    fn the_frames_on_disk_are_listed() {
        let dir = tempfile::tempdir().unwrap();
        for f in [3, 1, 2, 10] {
            std::fs::write(dir.path().join(format!("shot.{f:04}.exr")), b"x").unwrap();
        }
        std::fs::write(dir.path().join("shot.abcd.exr"), b"x").unwrap();
        std::fs::write(dir.path().join("other.0005.exr"), b"x").unwrap();
        let p = FramePattern::parse(&format!("{}/shot.####.exr", dir.path().display())).unwrap().unwrap();
        assert_eq!(p.existing_frames(), vec![1, 2, 3, 10]);
        let (found, frames) = sequence_of(&dir.path().join("shot.0002.exr")).unwrap();
        assert_eq!(found, p);
        assert_eq!(frames, vec![1, 2, 3, 10]);
        assert!(sequence_of(&dir.path().join("other.0005.exr")).is_none(), "a lone numbered file");
    }
}
