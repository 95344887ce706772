//! The README and the book (`docs/`): every relative link resolves (a file that exists, and where the link
//! names an anchor, a heading or an `<a id>` of that file), the README stays a front door (at most 300 lines,
//! the two commands on its first screen), and no user-facing page cites an issue number.
//!
//! Links are Markdown's inline form, `[text](target)` (an image too), outside fenced code blocks and inline
//! code. A heading's anchor is GitHub's: lower case, the characters that are not letters, digits, spaces,
//! hyphens or underscores dropped, spaces turned into hyphens.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// README.md and every page of the book.
fn pages() -> Vec<PathBuf> {
    let mut pages = vec![root().join("README.md")];
    let mut book: Vec<PathBuf> = std::fs::read_dir(root().join("docs"))
        .expect("docs/")
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "md"))
        .collect();
    book.sort();
    assert!(book.len() >= 10, "the book's pages: {book:?}");
    pages.extend(book);
    pages
}

/// The lines of `text` outside fenced code blocks, with their numbers (from 1).
fn outside_fences(text: &str) -> Vec<(usize, &str)> {
    let mut fenced = false;
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate() {
        if line.trim_start().starts_with("```") {
            fenced = !fenced;
        } else if !fenced {
            out.push((n + 1, line));
        }
    }
    out
}

/// The lines of `text` outside fenced code blocks, with their numbers (from 1) and inline code removed.
fn prose(text: &str) -> Vec<(usize, String)> {
    outside_fences(text).into_iter().map(|(n, line)| (n, line.split('`').step_by(2).collect::<String>())).collect()
}

/// GitHub's anchor for a heading's text.
fn slug(heading: &str) -> String {
    heading
        .trim()
        .to_lowercase()
        .chars()
        .filter(|c| c.is_alphanumeric() || matches!(c, ' ' | '-' | '_'))
        .map(|c| if c == ' ' { '-' } else { c })
        .collect()
}

/// Every anchor of a Markdown file: its headings' and its `<a id="...">`s.
fn anchors(text: &str) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    for (_, line) in outside_fences(text) {
        let hashes = line.chars().take_while(|&c| c == '#').count();
        if (1..=6).contains(&hashes) && line[hashes..].starts_with(' ') {
            out.insert(slug(&line[hashes..].replace('`', "")));
        }
        for tag in ["<a id=\"", "<a name=\""] {
            for (at, _) in line.match_indices(tag) {
                let rest = &line[at + tag.len()..];
                out.insert(rest[..rest.find('"').unwrap_or(rest.len())].to_owned());
            }
        }
    }
    out
}

/// The inline links' targets of a line: what follows `](` up to the closing parenthesis.
fn targets(line: &str) -> Vec<&str> {
    line.match_indices("](")
        .filter_map(|(at, _)| {
            let rest = &line[at + 2..];
            rest.find(')').map(|end| rest[..end].split_whitespace().next().unwrap_or(""))
        })
        .collect()
}

/// Every broken link of the page at `page` (given its text), said with its line.
fn broken_links(page: &Path, text: &str) -> Vec<String> {
    let mut broken = Vec::new();
    for (n, line) in prose(text) {
        for target in targets(&line) {
            if target.is_empty() || target.contains("://") || target.starts_with("mailto:") {
                continue;
            }
            let (file, anchor) = target.split_once('#').unwrap_or((target, ""));
            let path = if file.is_empty() { page.to_path_buf() } else { page.parent().unwrap().join(file) };
            let said = format!("{}:{n}: ({target})", page.strip_prefix(root()).unwrap_or(page).display());
            if !path.exists() {
                broken.push(format!("{said}: no file {}", path.display()));
                continue;
            }
            if !anchor.is_empty() && path.extension().is_some_and(|e| e == "md") {
                let linked = std::fs::read_to_string(&path).unwrap();
                if !anchors(&linked).contains(anchor) {
                    broken.push(format!("{said}: no heading or anchor `{anchor}` in {}", path.display()));
                }
            }
        }
    }
    broken
}

/// "issue 31", "Issue 62's", "issues 3 and 4", "(#12)": the numbers a user cannot look up.
fn issue_numbers(text: &str) -> Vec<(usize, String)> {
    let mut found = Vec::new();
    for (n, line) in prose(text) {
        let lower = line.to_lowercase();
        for word in ["issue ", "issues "] {
            for (at, _) in lower.match_indices(word) {
                let before_ok = at == 0 || !lower[..at].ends_with(|c: char| c.is_alphanumeric());
                if before_ok && lower[at + word.len()..].starts_with(|c: char| c.is_ascii_digit()) {
                    found.push((n, line[at..(at + word.len() + 3).min(line.len())].to_owned()));
                }
            }
        }
        for (at, _) in line.match_indices("(#") {
            if line[at + 2..].starts_with(|c: char| c.is_ascii_digit()) {
                found.push((n, line[at..(at + 5).min(line.len())].to_owned()));
            }
        }
    }
    found
}

#[test]
fn every_link_of_the_readme_and_the_book_resolves() {
    let mut broken = Vec::new();
    let mut links = 0;
    for page in pages() {
        let text = std::fs::read_to_string(&page).unwrap();
        links += prose(&text).iter().map(|(_, l)| targets(l).len()).sum::<usize>();
        broken.extend(broken_links(&page, &text));
    }
    assert!(links > 60, "links seen: {links}");
    assert!(broken.is_empty(), "broken links:\n{}", broken.join("\n"));
}

#[test]
fn the_link_check_finds_a_broken_link() {
    let page = root().join("docs").join("README.md");
    let text = "See [the app](app.md), [nowhere](nowhere.md), [a heading](app.md#no-such-heading), `[code](x.md)`,\n\
                [speed](speed.md#targets-where-they-stand) and [here](#the-flarelab-book).\n\
                ```\n[fenced](fenced.md)\n```\n# The FlareLab book\n";
    let broken = broken_links(&page, text);
    assert_eq!(broken.len(), 2, "{broken:?}");
    assert!(broken[0].contains("(nowhere.md): no file"), "{broken:?}");
    assert!(broken[1].contains("no heading or anchor `no-such-heading`"), "{broken:?}");
    assert_eq!(slug("Speed: the CPU twin, GPU ray grids, drafts"), "speed-the-cpu-twin-gpu-ray-grids-drafts");
    assert_eq!(slug("LUT ghosts (blended flares)"), "lut-ghosts-blended-flares");
}

#[test]
fn the_readme_is_a_front_door() {
    let text = std::fs::read_to_string(root().join("README.md")).unwrap();
    let lines = text.lines().count();
    assert!(lines <= 300, "README.md has {lines} lines: the rest belongs in docs/");
    // The two commands on the first screen (40 lines).
    let first: String = text.lines().take(40).collect::<Vec<_>>().join("\n");
    for command in ["`cargo run --release`", "`cargo test --workspace`"] {
        assert!(first.contains(command), "{command} is not on README.md's first screen");
    }
    // It points into every page of the book.
    for page in pages().iter().skip(1) {
        let name = format!("docs/{}", page.file_name().unwrap().to_string_lossy());
        assert!(text.contains(&format!("]({name}")), "README.md does not link {name}");
    }
}

#[test]
fn no_user_facing_page_cites_an_issue_number() {
    let mut found = Vec::new();
    for page in pages() {
        let text = std::fs::read_to_string(&page).unwrap();
        for (n, what) in issue_numbers(&text) {
            found.push(format!("{}:{n}: {what}", page.strip_prefix(root()).unwrap().display()));
        }
    }
    assert!(found.is_empty(), "issue numbers in user docs:\n{}", found.join("\n"));
    assert_eq!(issue_numbers("as issue 31 asked; (#12); tissue 4; issues are open").len(), 2);
}
