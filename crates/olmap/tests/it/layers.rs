//! The layer order of ARCHITECTURE.md, checked on the source: a module imports only from
//! layers below it (or its own), and no two sibling modules of one subsystem import each
//! other in a cycle. Paths are read from `crate::` and `super::` references outside
//! comments and before a file's `#[cfg(test)]` part (tests may use anything).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The layers, bottom first; modules in one layer may not import each other.
const LAYERS: &[&[&str]] = &[
    &["error", "progress", "guard"],
    &["file", "limits"],
    &["geometry"],
    &["cloud"],
    &["io"],
    &["occupancy"],
    &["scanner", "beacon", "grid2d", "graph"],
    &["align"],
    &["render"],
    &["report"],
    &["mapping"],
    &["team"],
    &["sim"],
    &["fixtures", "test_data"],
    &["bench", "fuzz"],
];

fn rank(module: &str) -> Option<usize> {
    LAYERS.iter().position(|l| l.contains(&module))
}

fn src() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("src")
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// The module path of a source file: `align/bnb/mod.rs` -> `[align, bnb]`.
fn module_of(file: &Path) -> Vec<String> {
    let rel = file.strip_prefix(src()).unwrap();
    let mut parts: Vec<String> = rel
        .iter()
        .map(|p| p.to_string_lossy().trim_end_matches(".rs").to_string())
        .collect();
    if matches!(parts.last().map(String::as_str), Some("mod" | "lib")) {
        parts.pop();
    }
    parts
}

/// The path at the start of `code` (just after `crate::` or `super::`): `a::b` ->
/// `[a, b]`; a group
/// `{a, b::c}` gives one path per item (only its first segment).
fn paths_after(code: &str) -> Vec<Vec<String>> {
    let ident = |s: &str| -> (String, usize) {
        let n = s
            .find(|c: char| !(c.is_alphanumeric() || c == '_'))
            .unwrap_or(s.len());
        (s[..n].to_string(), n)
    };
    if let Some(group) = code.strip_prefix('{') {
        let end = group.find('}').unwrap_or(group.len());
        return group[..end]
            .split(',')
            .map(|item| vec![ident(item.trim()).0])
            .filter(|p| !p[0].is_empty() && p[0] != "self")
            .collect();
    }
    let mut path = Vec::new();
    let mut rest = code;
    loop {
        let (id, n) = ident(rest);
        if id.is_empty() {
            break;
        }
        path.push(id);
        rest = &rest[n..];
        match rest.strip_prefix("::") {
            Some(r) if !r.starts_with('{') => rest = r,
            _ => break,
        }
    }
    vec![path]
}

/// Every crate path a file refers to, resolved to absolute module paths.
fn references(file: &Path) -> Vec<Vec<String>> {
    let text = std::fs::read_to_string(file).unwrap();
    let here = module_of(file);
    let mut out = Vec::new();
    for line in text.lines() {
        let line = line.trim();
        if line.starts_with("#[cfg(test)]") {
            break;
        }
        if line.starts_with("//") {
            continue;
        }
        let code = line.split("//").next().unwrap_or("");
        for (i, _) in code.match_indices("crate::") {
            // `$crate::` in macros is not a module path of ours.
            if code[..i].ends_with('$') {
                continue;
            }
            for p in paths_after(&code[i + "crate::".len()..]) {
                out.push(p);
            }
        }
        let mut from = 0;
        while let Some(i) = code[from..].find("super::") {
            let start = from + i;
            if start > 0 && code[..start].ends_with(|c: char| c.is_alphanumeric() || c == ':') {
                from = start + 1;
                continue;
            }
            let mut rest = &code[start..];
            // `here` names the file's module (a folder's for `mod.rs`): `super` is its
            // parent.
            let mut base = here.clone();
            while let Some(r) = rest.strip_prefix("super::") {
                base.pop();
                rest = r;
            }
            for p in paths_after(rest) {
                let mut abs = base.clone();
                abs.extend(p);
                out.push(abs);
            }
            from = start + "super::".len();
        }
    }
    out
}

fn is_module(path: &[String]) -> bool {
    let mut p = src();
    for s in path {
        p.push(s);
    }
    p.is_dir() || p.with_extension("rs").is_file()
}

#[test]
fn modules_import_only_from_lower_layers() {
    let mut files = Vec::new();
    rust_files(&src(), &mut files);
    let mut wrong = Vec::new();
    for f in &files {
        let here = module_of(f);
        let Some(top) = here.first() else { continue };
        let Some(mine) = rank(top) else {
            wrong.push(format!("{}: module {top} is in no layer", f.display()));
            continue;
        };
        for r in references(f) {
            let Some(other) = r.first() else { continue };
            if other == top || !is_module(&r[..1]) {
                continue;
            }
            match rank(other) {
                Some(theirs) if theirs < mine => {}
                _ => wrong.push(format!(
                    "{}: {top} imports {} from the same or a higher layer",
                    f.strip_prefix(src()).unwrap().display(),
                    r.join("::")
                )),
            }
        }
    }
    wrong.sort();
    wrong.dedup();
    assert!(wrong.is_empty(), "layer violations:\n{}", wrong.join("\n"));
}

#[test]
fn no_import_cycle_between_sibling_modules() {
    let mut files = Vec::new();
    rust_files(&src(), &mut files);
    // Edges between the second-level modules of one subsystem: align::bnb -> align::search.
    let mut edges: BTreeMap<(String, String), BTreeSet<String>> = BTreeMap::new();
    for f in &files {
        let here = module_of(f);
        if here.len() < 2 {
            continue;
        }
        for r in references(f) {
            if r.len() >= 2 && r[0] == here[0] && r[1] != here[1] && is_module(&r[..2]) {
                edges
                    .entry((here[0].clone(), here[1].clone()))
                    .or_default()
                    .insert(r[1].clone());
            }
        }
    }
    let mut cycles = Vec::new();
    for ((top, a), targets) in &edges {
        for b in targets {
            // a -> b and b ->* a.
            let mut seen = BTreeSet::new();
            let mut stack = vec![b.clone()];
            while let Some(m) = stack.pop() {
                if &m == a {
                    cycles.push(format!("{top}::{a} -> {top}::{b} -> ... -> {top}::{a}"));
                    break;
                }
                if seen.insert(m.clone()) {
                    if let Some(next) = edges.get(&(top.clone(), m)) {
                        stack.extend(next.iter().cloned());
                    }
                }
            }
        }
    }
    assert!(cycles.is_empty(), "import cycles:\n{}", cycles.join("\n"));
}
