//! The shape of the house: no import cycle between the modules of the core or of the app.
//!
//! Each source file is a module (`a/b.rs` and `a/b/mod.rs` are `a::b`). A module depends on every module its
//! code (not its comments, not its `#[cfg(test)]` tests) names through `crate::...` or `super::...`, resolved
//! to the longest module path that exists, and every child module it names by a relative path (`plot::Row` in
//! the module that declares `mod plot`). A depth-first search then looks for a cycle; the first one found
//! is printed in full.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

type Graph = BTreeMap<String, BTreeSet<String>>;

/// Every module of the crate rooted at `src` with its source (the part before `#[cfg(test)]`).
fn modules(src: &Path) -> BTreeMap<String, String> {
    let mut out = BTreeMap::new();
    let mut stack = vec![src.to_path_buf()];
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
                continue;
            }
            if path.extension().and_then(|e| e.to_str()) != Some("rs") {
                continue;
            }
            let relative = path.strip_prefix(src).unwrap().with_extension("");
            let mut parts: Vec<String> = relative.iter().map(|p| p.to_string_lossy().into_owned()).collect();
            if parts.last().is_some_and(|p| p == "mod" || p == "lib" || p == "main") {
                parts.pop();
            }
            let name = if parts.is_empty() { "crate".to_owned() } else { parts.join("::") };
            let text = std::fs::read_to_string(&path).unwrap();
            let code = text.split("#[cfg(test)]").next().unwrap_or("").to_owned();
            out.insert(name, code);
        }
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
