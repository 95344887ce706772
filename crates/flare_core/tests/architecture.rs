//! The shape of the house: no import cycle between the modules of the core or of the app, and the core's
//! rooms (its top-level files and folders) in strict layers.
//!
//! Each source file is a module (`a/b.rs` and `a/b/mod.rs` are `a::b`). A module depends on every module its
//! code (not its comments, not its `#[cfg(test)]` test module) names through `crate::...` or `super::...`, resolved
//! to the longest module path that exists, and every child module it names by a relative path (`plot::Row` in
//! the module that declares `mod plot`). A depth-first search then looks for a cycle; the first one found
//! is printed in full.
//!
//! The layers are the numbered list under "# Layers" in the core's `lib.rs` (its docs are the map): a room may
//! import from its own layer and the layers below, never from one above, and the rooms' graph (every module's
//! imports, gathered by room) has no cycle either, so no two rooms of a layer import each other.
//!
//! No function of the core, its examples or the app is longer than 120 lines, counted from its `fn` line to
//! the closing brace at the same indentation.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

type Graph = BTreeMap<String, BTreeSet<String>>;

/// The code of a source file before its tests: up to a `#[cfg(test)]` that opens a module (a `cfg(test)`
/// function or struct among the code is code too).
fn before_tests(text: &str) -> &str {
    let mut at = 0;
    let mut lines = text.split_inclusive('\n').peekable();
    while let Some(line) = lines.next() {
        let next = lines.peek().map_or("", |l| l.trim_start_matches("pub(crate) ").trim_start_matches("pub "));
        if line.trim_end() == "#[cfg(test)]" && next.starts_with("mod ") {
            return &text[..at];
        }
        at += line.len();
    }
    text
}

/// Every module of the crate rooted at `src` with its source (the part before its tests, [`before_tests`]).
fn modules(src: &Path) -> BTreeMap<String, String> {
    let mut out = BTreeMap::new();
    for (path, code) in sources(src) {
        let relative = path.strip_prefix(src).unwrap().with_extension("");
        let mut parts: Vec<String> = relative.iter().map(|p| p.to_string_lossy().into_owned()).collect();
        if parts.last().is_some_and(|p| p == "mod" || p == "lib" || p == "main") {
            parts.pop();
        }
        let name = if parts.is_empty() { "crate".to_owned() } else { parts.join("::") };
        out.insert(name, code);
    }
    out
}

/// The longest module named by the path segments `segments` (under `base`), if any.
fn resolve(known: &BTreeMap<String, String>, base: &[String], segments: &[&str]) -> Option<String> {
    (0..=segments.len()).rev().find_map(|n| {
        let mut path = base.to_vec();
        path.extend(segments[..n].iter().map(|s| s.to_string()));
        let name = if path.is_empty() { "crate".to_owned() } else { path.join("::") };
        known.contains_key(&name).then_some(name)
    })
}

fn graph(src: &Path) -> Graph {
    let known = modules(src);
    let mut graph = Graph::new();
    for (name, code) in &known {
        let here: Vec<String> =
            if name == "crate" { Vec::new() } else { name.split("::").map(str::to_owned).collect() };
        let mut deps = BTreeSet::new();
        for line in code.lines().map(str::trim).filter(|l| !l.starts_with("//")) {
            for (prefix, base) in [("crate::", Vec::new()), ("super::", here[..here.len().saturating_sub(1)].to_vec())]
            {
                let mut rest = line;
                while let Some(at) = rest.find(prefix) {
                    // Not the tail of a longer path (`flare_core::crate::` never occurs; `x.super::` neither).
                    let tail = &rest[at + prefix.len()..];
                    let path: String =
                        tail.chars().take_while(|c| c.is_ascii_alphanumeric() || *c == '_' || *c == ':').collect();
                    let segments: Vec<&str> = path.split("::").filter(|s| !s.is_empty()).collect();
                    let mut targets = vec![resolve(&known, &base, &segments)];
                    // `use super::{a, b}` / `use crate::{a, b}`: each name that is a module.
                    if tail[path.len()..].starts_with('{')
                        || path.ends_with("::") && tail[path.len()..].starts_with('{')
                    {
                        let inner = &tail[path.len() + 1..];
                        let inner = &inner[..inner.find('}').unwrap_or(inner.len())];
                        for item in inner.split(',').map(str::trim) {
                            let mut segs = segments.clone();
                            segs.extend(item.split("::").filter(|s| !s.is_empty()));
                            targets.push(resolve(&known, &base, &segs));
                        }
                    }
                    for target in targets.into_iter().flatten() {
                        // A module's own parent (through `super::`) or itself is not an edge that can close a cycle
                        // by declaration; its items are.
                        if target != *name {
                            deps.insert(target);
                        }
                    }
                    rest = &tail[path.len()..];
                }
            }
        }
        // A child module named by a relative path (`plot::Row` in the module that declares `mod plot`).
        let prefix = if name == "crate" { String::new() } else { format!("{name}::") };
        for child in known.keys().filter_map(|k| k.strip_prefix(&prefix)).filter(|c| !c.contains("::")) {
            let needle = format!("{child}::");
            let used = code.lines().map(str::trim).filter(|l| !l.starts_with("//")).any(|l| {
                l.match_indices(&needle)
                    .any(|(at, _)| !l[..at].ends_with(|c: char| c.is_ascii_alphanumeric() || c == '_' || c == ':'))
            });
            if used {
                deps.insert(format!("{prefix}{child}"));
            }
        }
        graph.insert(name.clone(), deps);
    }
    graph
}

/// A cycle of `graph`, if it has one.
fn find_cycle(graph: &Graph) -> Option<Vec<String>> {
    fn visit(
        node: &str,
        graph: &Graph,
        state: &mut BTreeMap<String, u8>,
        path: &mut Vec<String>,
    ) -> Option<Vec<String>> {
        state.insert(node.to_owned(), 1);
        path.push(node.to_owned());
        for next in graph.get(node).into_iter().flatten() {
            match state.get(next.as_str()).copied().unwrap_or(0) {
                1 => {
                    let start = path.iter().position(|p| p == next).unwrap();
                    let mut cycle = path[start..].to_vec();
                    cycle.push(next.clone());
                    return Some(cycle);
                }
                0 => {
                    if let Some(c) = visit(next, graph, state, path) {
                        return Some(c);
                    }
                }
                _ => {}
            }
        }
        path.pop();
        state.insert(node.to_owned(), 2);
        None
    }
    let mut state = BTreeMap::new();
    for node in graph.keys() {
        if state.get(node.as_str()).copied().unwrap_or(0) == 0
            && let Some(c) = visit(node, graph, &mut state, &mut Vec::new())
        {
            return Some(c);
        }
    }
    None
}

#[test]
fn no_module_of_the_core_or_the_app_imports_in_a_cycle() {
    let core = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let app = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../src");
    for (what, src) in [("flare_core", core), ("flarelab", app)] {
        let graph = graph(&src);
        assert!(graph.len() > 5, "{what}: modules found in {}", src.display());
        // The graph sees real edges (the test can fail).
        let edge = |a: &str, b: &str| graph.get(a).is_some_and(|d| d.contains(b));
        if what == "flare_core" {
            // The reference ray tracer depends only on the optics, the coatings and the aperture (and the small
            // shared pieces: spectrum, images, colour, the timing spans, which import nothing of the crate),
            // never on the paraxial ghosts, the renderer or the LUTs.
            let allowed = ["raytrace", "optics", "coating", "aperture", "spectrum", "image", "color", "timing"];
            for (module, deps) in graph.iter().filter(|(m, _)| m.starts_with("raytrace")) {
                for dep in deps {
                    let root = dep.split("::").next().unwrap_or("");
                    assert!(allowed.contains(&root), "{module} depends on {dep}");
                }
            }
        }
        match what {
            "flare_core" => assert!(edge("frame", "render::gpu") && edge("render::gpu", "lut::blend"), "{graph:?}"),
            _ => assert!(edge("app", "viewport") && edge("cli::bench", "cli::bench::plot"), "{graph:?}"),
        }
        let mut g = graph.clone();
        let mut all = Vec::new();
        while let Some(cycle) = find_cycle(&g) {
            all.push(cycle.join(" -> "));
            let n = cycle.len();
            g.get_mut(&cycle[n - 2]).unwrap().remove(&cycle[n - 1]);
        }
        assert!(all.is_empty(), "{what}: import cycles:\n{}", all.join("\n"));
    }
}

/// The layers of the core, bottom first, as the "# Layers" list of `lib.rs` names them (each room in
/// backticks, as an intra-doc link).
fn layers_of(lib_rs: &str) -> Vec<Vec<String>> {
    let mut layers: Vec<Vec<String>> = Vec::new();
    let mut inside = false;
    for line in lib_rs.lines().map(|l| l.trim_start_matches("//!")) {
        if line.starts_with(" # ") {
            inside = line.trim() == "# Layers";
            continue;
        }
        if !inside {
            continue;
        }
        let item = line.trim_start();
        let numbered =
            item.split_once(". ").is_some_and(|(n, _)| !n.is_empty() && n.chars().all(|c| c.is_ascii_digit()));
        if numbered {
            layers.push(Vec::new());
        } else if !line.starts_with("    ") {
            continue; // the prose before and after the list
        }
        let Some(layer) = layers.last_mut() else { continue };
        // The rooms are the links' names: "[`render`]".
        layer.extend(item.split("[`").skip(1).filter_map(|r| r.split_once("`]")).map(|(room, _)| room.to_owned()));
    }
    layers
}

/// The room of a module: its first segment.
fn room(module: &str) -> &str {
    module.split("::").next().unwrap_or(module)
}

/// Every import of `graph` that breaks `layers`: one that goes up a layer, a room no layer names, and the rooms'
/// cycles, each said with the modules that make it.
fn layer_breaks(graph: &Graph, layers: &[Vec<String>]) -> Vec<String> {
    let layer_of = |r: &str| layers.iter().position(|l| l.iter().any(|x| x == r));
    let mut breaks = Vec::new();
    let mut rooms = Graph::new();
    let mut why: BTreeMap<(String, String), String> = BTreeMap::new();
    for (module, deps) in graph.iter().filter(|(m, _)| *m != "crate") {
        let from = room(module);
        rooms.entry(from.to_owned()).or_default();
        if layer_of(from).is_none() {
            breaks.push(format!("the room {from} is in no layer of lib.rs's \"# Layers\""));
        }
        for dep in deps.iter().filter(|d| room(d) != from && *d != "crate") {
            let to = room(dep);
            rooms.get_mut(from).unwrap().insert(to.to_owned());
            why.entry((from.to_owned(), to.to_owned())).or_insert_with(|| format!("{module} -> {dep}"));
            if let (Some(a), Some(b)) = (layer_of(from), layer_of(to))
                && b > a
            {
                breaks.push(format!("{module} -> {dep}: layer {} imports from layer {} above it", a + 1, b + 1));
            }
        }
    }
    let mut g = rooms;
    while let Some(cycle) = find_cycle(&g) {
        let said: Vec<&str> = cycle.windows(2).map(|w| why[&(w[0].clone(), w[1].clone())].as_str()).collect();
        breaks.push(format!("rooms in a cycle: {} ({})", cycle.join(" -> "), said.join(", ")));
        let n = cycle.len();
        g.get_mut(&cycle[n - 2]).unwrap().remove(&cycle[n - 1]);
    }
    breaks.sort();
    breaks.dedup();
    breaks
}

fn core_layers() -> (Graph, Vec<Vec<String>>) {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let lib_rs = std::fs::read_to_string(src.join("lib.rs")).unwrap();
    (graph(&src), layers_of(&lib_rs))
}

#[test]
fn the_core_s_rooms_import_only_from_their_layer_and_below() {
    let (graph, layers) = core_layers();
    assert!(layers.len() >= 5, "the layers read from lib.rs: {layers:?}");
    let named: Vec<&String> = layers.iter().flatten().collect();
    let unique: BTreeSet<&String> = named.iter().copied().collect();
    assert_eq!(named.len(), unique.len(), "a room in two layers: {layers:?}");
    for r in &named {
        assert!(graph.keys().any(|m| room(m) == r.as_str()), "lib.rs's layers name {r}, which is no module");
    }
    let breaks = layer_breaks(&graph, &layers);
    assert!(breaks.is_empty(), "the core's layers are broken:\n{}", breaks.join("\n"));
}

/// The check fails on a back-import: the real graph with one import added from a low layer to a high one
/// (the LUTs' blend naming the shot's plan), and with two rooms of a layer importing each other.
#[test]
fn a_back_import_breaks_the_layers() {
    let (graph, layers) = core_layers();
    let mut up = graph.clone();
    up.get_mut("lut::blend").expect("lut::blend").insert("shot::plan".to_owned());
    let breaks = layer_breaks(&up, &layers);
    assert!(
        breaks.iter().any(|b| b.starts_with("lut::blend -> shot::plan: layer 3 imports from layer 6")),
        "{breaks:?}"
    );
    assert!(
        breaks.iter().any(|b| b.starts_with("rooms in a cycle") && b.contains("lut::blend -> shot::plan")),
        "{breaks:?}"
    );
    let mut across = graph.clone();
    across.get_mut("ghost").expect("ghost").insert("dirt".to_owned());
    let breaks = layer_breaks(&across, &layers);
    assert!(breaks.iter().any(|b| b.starts_with("rooms in a cycle") && b.contains("ghost -> dirt")), "{breaks:?}");
    let mut unnamed = graph;
    unnamed.insert("attic::junk".to_owned(), BTreeSet::new());
    assert!(layer_breaks(&unnamed, &layers).iter().any(|b| b.contains("attic is in no layer")));
}

#[test]
fn the_cycle_finder_finds_a_cycle() {
    let mut graph = Graph::new();
    graph.insert("a".into(), ["b".to_owned()].into());
    graph.insert("b".into(), ["c".to_owned()].into());
    graph.insert("c".into(), ["a".to_owned()].into());
    assert_eq!(find_cycle(&graph).unwrap(), ["a", "b", "c", "a"]);
    graph.get_mut("c").unwrap().clear();
    assert!(find_cycle(&graph).is_none());
}

/// The longest a function may be, in lines from its `fn` to its closing brace.
const MOST_LINES: usize = 120;

/// Each function of `code` (the part before its test module) as (name, first line, lines): from its
/// `fn` line to the closing brace at the `fn`'s indentation. A function on one line and a declaration without
/// a body (a trait's `fn f();`) are not counted.
fn function_lengths(code: &str) -> Vec<(String, usize, usize)> {
    let lines: Vec<&str> = code.lines().collect();
    let mut out = Vec::new();
    for (i, line) in lines.iter().enumerate() {
        let trimmed = line.trim_start();
        let indent = line.len() - trimmed.len();
        let mut rest = trimmed;
        for word in ["pub(crate) ", "pub(super) ", "pub ", "const ", "async ", "unsafe "] {
            rest = rest.strip_prefix(word).unwrap_or(rest);
        }
        let Some(name) = rest.strip_prefix("fn ") else { continue };
        let name: String = name.chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect();
        // The line that opens the body, unless a `;` ends the declaration first.
        let Some(open) = (i..lines.len()).find(|&j| lines[j].contains('{') || lines[j].trim_end().ends_with(';'))
        else {
            continue;
        };
        let opening = lines[open];
        if !opening.contains('{') || opening.matches('{').count() == opening.matches('}').count() {
            continue;
        }
        let close = (open + 1..lines.len()).find(|&k| {
            let l = lines[k];
            l.len() - l.trim_start().len() == indent && l.trim_start().starts_with('}')
        });
        if let Some(close) = close {
            out.push((name, i + 1, close - i + 1));
        }
    }
    out
}

/// Every `.rs` file under `dir`, with its code before its tests ([`before_tests`]).
fn sources(dir: &Path) -> Vec<(std::path::PathBuf, String)> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else if path.extension().and_then(|e| e.to_str()) == Some("rs") {
                let text = std::fs::read_to_string(&path).unwrap();
                out.push((path, before_tests(&text).to_owned()));
            }
        }
    }
    out
}

#[test]
fn no_function_of_the_core_or_the_app_is_longer_than_120_lines() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dirs = [root.join("src"), root.join("examples"), root.join("benches"), root.join("../../src")];
    let mut all = Vec::new();
    for dir in dirs.iter().filter(|d| d.is_dir()) {
        for (path, code) in sources(dir) {
            for (name, line, lines) in function_lengths(&code) {
                all.push((lines, format!("{}:{line} {name}", path.display())));
            }
        }
    }
    all.sort_by(|a, b| b.0.cmp(&a.0));
    // The scanner sees the functions (the test can fail): hundreds of them, the longest near the bound.
    assert!(all.len() > 500 && all[0].0 > 60, "functions found: {}", all.len());
    let long: Vec<String> =
        all.iter().filter(|(n, _)| *n > MOST_LINES).map(|(n, at)| format!("{n} lines: {at}")).collect();
    assert!(long.is_empty(), "functions over {MOST_LINES} lines (split them into their steps):\n{}", long.join("\n"));
}

#[test]
fn the_function_scanner_counts_a_long_function() {
    let body = "    let x = 1;\n".repeat(130);
    let code = format!(
        "fn short() {{ 1 }}\ntrait T {{\n    fn declared(&self);\n}}\npub(crate) fn long(\n    a: u32,\n) -> u32 {{\n{body}    if a > 0 {{\n        a\n    }} else {{ 0 }}\n}}\n"
    );
    let found = function_lengths(&code);
    assert_eq!(found, vec![("long".to_owned(), 5, 137)], "{found:?}");
    // A `cfg(test)` function is code; a `cfg(test)` module is where the tests start.
    let text = "fn a() {}\n#[cfg(test)]\nfn oracle() {}\nfn b() {}\n#[cfg(test)]\nmod tests {\n}\n";
    assert_eq!(before_tests(text), "fn a() {}\n#[cfg(test)]\nfn oracle() {}\nfn b() {}\n");
}
