//! No import loops inside the crate: the graph of its top-level modules, with an edge
//! `a → b` wherever a file of `a` names `crate::b` (in a `use` or a path, test code
//! included; comments are skipped), has no cycle. Names the crate root re-exports
//! (`crate::Trainer`) count as their defining module. `super::` paths stay inside a
//! module and are not followed.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

type Graph = BTreeMap<String, BTreeSet<String>>;

fn src() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("src")
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// The text without `//` and `/* */` comments (string contents are kept: no file of the
/// crate writes `crate::` inside a string).
fn strip_comments(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while !rest.is_empty() {
        if let Some(r) = rest.strip_prefix("//") {
            rest = r.find('\n').map_or("", |i| &r[i..]);
        } else if let Some(r) = rest.strip_prefix("/*") {
            rest = r.find("*/").map_or("", |i| &r[i + 2..]);
        } else {
            let c = rest.chars().next().unwrap();
            out.push(c);
            rest = &rest[c.len_utf8()..];
        }
    }
    out
}

fn ident_at(s: &str) -> &str {
    let end = s
        .find(|c: char| !(c.is_alphanumeric() || c == '_'))
        .unwrap_or(s.len());
    &s[..end]
}

/// The first-level names a file reaches through `crate::`: `crate::a::…`, and every
/// top-level entry of `crate::{a::…, b, …}`.
fn crate_names(text: &str) -> Vec<String> {
    let mut names = Vec::new();
    for (i, _) in text.match_indices("crate::") {
        let before = text[..i].chars().next_back();
        if before.is_some_and(|c| c.is_alphanumeric() || c == '_') {
            continue; // `foo_crate::`, not ours
        }
        let after = &text[i + "crate::".len()..];
        match after.strip_prefix('{') {
            Some(group) => names.extend(group_heads(group)),
            None => names.push(ident_at(after).to_string()),
        }
    }
    names
}

/// The names at depth 0 of a `{…}` group, up to its closing brace.
fn group_heads(group: &str) -> Vec<String> {
    let (mut depth, mut heads, mut start) = (0usize, Vec::new(), true);
    for (i, c) in group.char_indices() {
        match c {
            '{' => depth += 1,
            '}' if depth == 0 => break,
            '}' => depth -= 1,
            ',' if depth == 0 => start = true,
            c if start && (c.is_alphanumeric() || c == '_') && depth == 0 => {
                heads.push(ident_at(&group[i..]).to_string());
                start = false;
            }
            _ => {}
        }
    }
    heads
}

/// `pub use m::{A, B};` and `pub use m::A;` of the crate root: item → module.
fn reexports(lib: &str) -> BTreeMap<String, String> {
    let mut map = BTreeMap::new();
    for line in lib.lines() {
        let Some(path) = line.trim().strip_prefix("pub use ") else {
            continue;
        };
        let path = path.trim_end_matches(';');
        let Some((module, items)) = path.split_once("::") else {
            continue;
        };
        let items = items.trim_start_matches('{').trim_end_matches('}');
        for item in items.split(',').map(str::trim).filter(|s| !s.is_empty()) {
            map.insert(item.to_string(), module.to_string());
        }
    }
    map
}

/// The top-level module a file belongs to (None: the crate root).
fn module_of(root: &Path, file: &Path) -> Option<String> {
    let rel = file.strip_prefix(root).unwrap();
    let first = rel.components().next()?.as_os_str().to_str()?.to_string();
    match first.strip_suffix(".rs") {
        Some("lib") => None,
        Some(stem) => Some(stem.to_string()),
        None => Some(first),
    }
}

fn graph() -> Graph {
    let root = src();
    let lib = std::fs::read_to_string(root.join("lib.rs")).unwrap();
    let reexported = reexports(&strip_comments(&lib));
    let mut files = Vec::new();
    rust_files(&root, &mut files);
    let mut g = Graph::new();
    for f in files {
        let Some(from) = module_of(&root, &f) else {
            continue;
        };
        let text = strip_comments(&std::fs::read_to_string(&f).unwrap());
        let edges = g.entry(from.clone()).or_default();
        for name in crate_names(&text) {
            let to = reexported.get(&name).cloned().unwrap_or(name);
            if to != from && !to.is_empty() {
                edges.insert(to);
            }
        }
    }
    g
}

/// A cycle of `g` as the list of its modules (first repeated at the end), if any.
fn find_cycle(g: &Graph) -> Option<Vec<String>> {
    // 0 unvisited, 1 on the current path, 2 done.
    fn visit(
        g: &Graph,
        v: &str,
        state: &mut BTreeMap<String, u8>,
        path: &mut Vec<String>,
    ) -> Option<Vec<String>> {
        state.insert(v.to_string(), 1);
        path.push(v.to_string());
        for w in g.get(v).into_iter().flatten() {
            match state.get(w.as_str()).copied().unwrap_or(0) {
                1 => {
                    let start = path.iter().position(|p| p == w).unwrap();
                    let mut cycle = path[start..].to_vec();
                    cycle.push(w.clone());
                    return Some(cycle);
                }
                0 => {
                    if let Some(c) = visit(g, w, state, path) {
                        return Some(c);
                    }
                }
                _ => {}
            }
        }
        path.pop();
        state.insert(v.to_string(), 2);
        None
    }
    let mut state = BTreeMap::new();
    for v in g.keys() {
        if state.get(v.as_str()).copied().unwrap_or(0) == 0 {
            if let Some(c) = visit(g, v, &mut state, &mut Vec::new()) {
                return Some(c);
            }
        }
    }
    None
}

#[test]
fn top_level_modules_import_each_other_in_one_direction_only() {
    let g = graph();
    assert!(g.len() > 20, "read the crate's modules: {:?}", g.keys());
    if let Some(cycle) = find_cycle(&g) {
        panic!(
            "import loop between modules of `train`: {}",
            cycle.join(" → ")
        );
    }
}

#[test]
fn the_checker_reads_paths_groups_and_reexports_and_finds_a_loop() {
    let text = strip_comments(
        "use crate::{a::X, b, c::{D, E}};\n// crate::commented\nlet x = crate::d::f();\n\
         /* crate::blocked */ my_crate::no;",
    );
    assert_eq!(crate_names(&text), ["a", "b", "c", "d"]);
    let map = reexports("pub use config::TrainConfig;\npub use error::{Result, TrainError};");
    assert_eq!(map["TrainError"], "error");
    assert_eq!(map["TrainConfig"], "config");
    let mut g = Graph::new();
    for (a, b) in [("x", "y"), ("y", "z"), ("z", "x"), ("z", "w")] {
        g.entry(a.to_string()).or_default().insert(b.to_string());
    }
    assert_eq!(find_cycle(&g).unwrap(), ["x", "y", "z", "x"]);
    g.get_mut("z").unwrap().remove("x");
    assert_eq!(find_cycle(&g), None);
}
