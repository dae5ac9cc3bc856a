//! The house rules of ARCHITECTURE.md, checked on the source text: no import circle
//! between files, `error.rs` a leaf, each layer importing only what it may, no
//! source file of 600 lines or more.
//!
//! Imports are read from the text: `crate::`, `super::`, `self::` and `travmap::`
//! paths (`use` lists included) and paths through a module the file declares; tests
//! (`#[cfg(test)] mod tests`) are left out. A path is a dependency on the longest
//! module it names.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// Lines a source file must stay under.
const MAX_LINES: usize = 600;

/// A source file: its module path (the binary's files under `<bin>`) and its code.
struct SourceFile {
    relative: String,
    module: Vec<String>,
    code: String,
    lines: usize,
}

fn source_files() -> Vec<SourceFile> {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut paths = Vec::new();
    let mut pending = vec![src.clone()];
    while let Some(dir) = pending.pop() {
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                pending.push(path);
            } else if path.extension().is_some_and(|e| e == "rs") {
                paths.push(path);
            }
        }
    }
    paths.sort();
    paths
        .into_iter()
        .map(|path: PathBuf| {
            let relative = path
                .strip_prefix(&src)
                .unwrap()
                .to_str()
                .unwrap()
                .to_string();
            let mut module: Vec<String> = relative
                .trim_end_matches(".rs")
                .split('/')
                .map(str::to_string)
                .collect();
            if module.last().is_some_and(|m| m == "mod" || m == "lib") {
                module.pop();
            }
            if module.first().is_some_and(|m| m == "main" || m == "cli") {
                module.retain(|m| m != "main");
                module.insert(0, "<bin>".into());
            }
            let text = std::fs::read_to_string(&path).unwrap();
            SourceFile {
                lines: text.lines().count(),
                code: code_of(&text),
                relative,
                module,
            }
        })
        .collect()
}

/// The code without tests, comments and string contents.
fn code_of(text: &str) -> String {
    let text = match text.find("#[cfg(test)]\nmod tests") {
        Some(at) => &text[..at],
        None => text,
    };
    let mut code = String::with_capacity(text.len());
    for line in text.lines() {
        let mut in_string = false;
        let mut chars = line.chars().peekable();
        while let Some(c) = chars.next() {
            match c {
                '\\' if in_string => {
                    chars.next();
                }
                '"' => in_string = !in_string,
                '/' if !in_string && chars.peek() == Some(&'/') => break,
                _ if in_string => {}
                _ => code.push(c),
            }
        }
        code.push('\n');
    }
    code
}

fn is_ident(c: char) -> bool {
    c.is_ascii_alphanumeric() || c == '_'
}

/// Reads `a::b::{c, d::e}` from the start of `text`: each path it names.
fn read_paths(text: &str, prefix: Vec<String>, out: &mut Vec<Vec<String>>) {
    let mut path = prefix;
    let mut rest = text;
    loop {
        let rest_trimmed = rest.trim_start();
        if let Some(group) = rest_trimmed.strip_prefix('{') {
            // Each top-level item of the group, as a path of its own.
            let (mut depth, mut start) = (0, 0);
            for (i, c) in group.char_indices() {
                match c {
                    '{' => depth += 1,
                    '}' if depth == 0 => {
                        read_item(&group[start..i], &path, out);
                        return;
                    }
                    '}' => depth -= 1,
                    ',' if depth == 0 => {
                        read_item(&group[start..i], &path, out);
                        start = i + 1;
                    }
                    _ => {}
                }
            }
            return;
        }
        let end = rest_trimmed
            .find(|c| !is_ident(c))
            .unwrap_or(rest_trimmed.len());
        if end == 0 {
            break;
        }
        path.push(rest_trimmed[..end].to_string());
        match rest_trimmed[end..].strip_prefix("::") {
            Some(next) => rest = next,
            None => break,
        }
    }
    out.push(path);
}

fn read_item(item: &str, prefix: &[String], out: &mut Vec<Vec<String>>) {
    let item = item.trim();
    if item.is_empty() || item == "self" {
        out.push(prefix.to_vec());
    } else {
        read_paths(item, prefix.to_vec(), out);
    }
}

/// Every path the file's code names through `crate`, `super`, `self`, `travmap` or
/// a module it declares, made absolute.
fn imports(file: &SourceFile) -> Vec<Vec<String>> {
    let code = &file.code;
    let declared: BTreeSet<String> = code
        .lines()
        .filter_map(|line| {
            let line = line.trim();
            let line = line.strip_prefix("pub ").unwrap_or(line);
            let line = line.strip_prefix("pub(crate) ").unwrap_or(line);
            let name = line.strip_prefix("mod ")?.strip_suffix(';')?;
            Some(name.trim().to_string())
        })
        .collect();
    let crate_root: Vec<String> = match file.module.first().map(String::as_str) {
        Some("<bin>") => vec!["<bin>".into()],
        _ => Vec::new(),
    };
    let mut paths = Vec::new();
    for (at, _) in code.match_indices("::") {
        let before = &code[..at];
        let start = before.rfind(|c: char| !is_ident(c)).map_or(0, |i| i + 1);
        let head = &before[start..];
        if before[..start].ends_with("::") || head.is_empty() {
            continue;
        }
        let mut base = match head {
            "crate" => crate_root.clone(),
            "travmap" => Vec::new(),
            "self" => file.module.clone(),
            "super" => file.module[..file.module.len().saturating_sub(1)].to_vec(),
            name if declared.contains(name) => {
                let mut base = file.module.clone();
                base.push(name.to_string());
                base
            }
            _ => continue,
        };
        let mut rest = &code[at + 2..];
        // `super::super::x`
        while let Some(next) = rest.strip_prefix("super::") {
            base.pop();
            rest = next;
        }
        read_paths(rest, base, &mut paths);
    }
    paths
}

/// File -> the files it imports from (the crate roots left out: they only gather).
fn import_graph(files: &[SourceFile]) -> BTreeMap<&str, BTreeSet<&str>> {
    let by_module: BTreeMap<&[String], &str> = files
        .iter()
        .map(|f| (f.module.as_slice(), f.relative.as_str()))
        .collect();
    let mut graph = BTreeMap::new();
    for file in files {
        let mut targets = BTreeSet::new();
        for path in imports(file) {
            let target = (1..=path.len())
                .rev()
                .find_map(|n| by_module.get(&path[..n]).copied());
            if let Some(target) = target
                && target != file.relative
            {
                targets.insert(target);
            }
        }
        graph.insert(file.relative.as_str(), targets);
    }
    graph
}

/// A circle of imports, when there is one: the files in order.
fn find_circle<'a>(graph: &BTreeMap<&'a str, BTreeSet<&'a str>>) -> Option<Vec<&'a str>> {
    fn visit<'a>(
        file: &'a str,
        graph: &BTreeMap<&'a str, BTreeSet<&'a str>>,
        done: &mut BTreeSet<&'a str>,
        stack: &mut Vec<&'a str>,
    ) -> Option<Vec<&'a str>> {
        if let Some(at) = stack.iter().position(|f| *f == file) {
            let mut circle = stack[at..].to_vec();
            circle.push(file);
            return Some(circle);
        }
        if !done.insert(file) {
            return None;
        }
        stack.push(file);
        for next in graph.get(file).into_iter().flatten() {
            if let Some(circle) = visit(next, graph, done, stack) {
                return Some(circle);
            }
        }
        stack.pop();
        None
    }
    let mut done = BTreeSet::new();
    graph
        .keys()
        .find_map(|file| visit(file, graph, &mut done, &mut Vec::new()))
}

#[test]
fn no_file_imports_itself_through_others() {
    let files = source_files();
    let graph = import_graph(&files);
    if let Some(circle) = find_circle(&graph) {
        panic!("import circle: {}", circle.join(" -> "));
    }
}

#[test]
fn the_circle_finder_finds_a_circle() {
    let graph: BTreeMap<&str, BTreeSet<&str>> = [
        ("a.rs", ["b.rs"].into()),
        ("b.rs", ["c.rs"].into()),
        ("c.rs", ["a.rs"].into()),
        ("d.rs", ["a.rs"].into()),
    ]
    .into();
    let circle = find_circle(&graph).unwrap();
    assert_eq!(circle.first(), circle.last());
    assert_eq!(circle.len(), 4);
    let mut line = graph.clone();
    line.insert("c.rs", BTreeSet::new());
    assert_eq!(find_circle(&line), None);
}

#[test]
fn paths_are_read_from_use_lists_and_code() {
    let file = SourceFile {
        relative: "io/x.rs".into(),
        module: vec!["io".into(), "x".into()],
        code: code_of(
            "use super::{log::Log, ros::{A, B}};\nuse crate::error::Error; // crate::config\nfn f() { crate::geometry::rigid(); \"crate::frame\"; }\n",
        ),
        lines: 3,
    };
    let paths: BTreeSet<String> = imports(&file).iter().map(|p| p.join("::")).collect();
    let expected: BTreeSet<String> = [
        "io::log::Log",
        "io::ros::A",
        "io::ros::B",
        "error::Error",
        "geometry::rigid",
    ]
    .map(String::from)
    .into();
    assert_eq!(paths, expected);
}

/// The shared layer: what every layer may import.
const SHARED: &[&str] = &[
    "config",
    "error",
    "frame",
    "geometry",
    "lens",
    "posing",
    "random",
    "stopwatch",
];

/// Whether a file of `layer` may import from the top-level module `top`, by
/// ARCHITECTURE.md (None: the layer may import every layer above it).
fn may_import(layer: &str, top: &str) -> Option<bool> {
    match layer {
        _ if SHARED.contains(&layer) => Some(SHARED.contains(&top)),
        "io" | "method" => Some(SHARED.contains(&top) || top == layer),
        _ => None,
    }
}

#[test]
fn each_layer_imports_only_what_it_may() {
    let files = source_files();
    let mut broken = Vec::new();
    for file in &files {
        let Some(layer) = file.module.first() else {
            continue;
        };
        for path in imports(file) {
            let Some(top) = path.first() else { continue };
            if may_import(layer, top) == Some(false) {
                broken.push(format!("{} imports {}", file.relative, path.join("::")));
            }
        }
    }
    // error.rs is the leaf every layer stands on.
    let error = files.iter().find(|f| f.relative == "error.rs").unwrap();
    broken.extend(
        imports(error)
            .iter()
            .map(|p| format!("error.rs imports {}", p.join("::"))),
    );
    // The method knows no file format, command line or progress bar.
    for file in files.iter().filter(|f| f.relative.starts_with("method/")) {
        for outside in ["mcap::", "clap::", "indicatif::", "anyhow::", "std::fs::"] {
            if file.code.contains(outside) {
                broken.push(format!("{} uses {outside}", file.relative));
            }
        }
    }
    assert!(broken.is_empty(), "{}", broken.join("\n"));
}

#[test]
fn every_source_file_stays_under_600_lines() {
    let long: Vec<String> = source_files()
        .iter()
        .filter(|f| f.lines >= MAX_LINES)
        .map(|f| format!("{}: {} lines", f.relative, f.lines))
        .collect();
    assert!(long.is_empty(), "split along a seam: {}", long.join(", "));
}
