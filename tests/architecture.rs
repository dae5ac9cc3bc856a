//! The house rules of ARCHITECTURE.md that crate boundaries cannot express,
//! checked on the source text: no import circle between the files of a crate,
//! `error.rs` a leaf, the method free of file access, each crate depending only on
//! the crates below it (so that no `Cargo.toml` edit quietly adds an arrow up), and no
//! source folder of more than 25 files. That the method cannot import a reader is
//! the compiler's to keep: `travmap-method` does not depend on `travmap-io`.
//!
//! Imports are read from the text: `crate::`, `super::` and `self::` paths (`use`
//! lists included) and paths through a module the file declares; tests (`#[cfg(test)]
//! mod tests`) are left out. A path is a dependency on the longest module it names.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// `.rs` files a source folder may hold: more, and it wants rooms of its own.
const MAX_FILES_PER_FOLDER: usize = 25;

/// The workspace's crates, bottom up: the folder of each, its package name and the
/// crates of the workspace it may depend on.
const CRATES: &[(&str, &str, &[&str])] = &[
    ("crates/core", "travmap-core", &[]),
    ("crates/formats", "travmap-formats", &["travmap-core"]),
    (
        "crates/io",
        "travmap-io",
        &["travmap-core", "travmap-formats"],
    ),
    ("crates/method", "travmap-method", &["travmap-core"]),
    (
        "crates/run",
        "travmap-run",
        &["travmap-core", "travmap-io", "travmap-method"],
    ),
    (
        "crates/training",
        "travmap-training",
        &["travmap-core", "travmap-run", "travmap-method"],
    ),
    (
        "crates/outputs",
        "travmap-outputs",
        &[
            "travmap-core",
            "travmap-formats",
            "travmap-io",
            "travmap-method",
            "travmap-run",
        ],
    ),
    (
        "crates/label",
        "travmap-label",
        &[
            "travmap-core",
            "travmap-method",
            "travmap-run",
            "travmap-outputs",
        ],
    ),
    (
        "crates/bench",
        "travmap-bench",
        &["travmap-core", "travmap-run"],
    ),
    (
        "crates/fuzzing",
        "travmap-fuzzing",
        &[
            "travmap-core",
            "travmap-io",
            "travmap-method",
            "travmap-outputs",
        ],
    ),
    (
        "crates/python",
        "travmap-python",
        &[
            "travmap-core",
            "travmap-io",
            "travmap-method",
            "travmap-run",
        ],
    ),
    (
        ".",
        "travmap",
        &[
            "travmap-core",
            "travmap-formats",
            "travmap-io",
            "travmap-method",
            "travmap-run",
            "travmap-training",
            "travmap-outputs",
            "travmap-label",
            "travmap-bench",
        ],
    ),
];

/// A source file: its crate's folder, its path from the repository, its module path
/// in its crate, and its code.
struct SourceFile {
    krate: &'static str,
    relative: String,
    module: Vec<String>,
    code: String,
}

fn repository() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// Every source file of every crate.
fn source_files() -> Vec<SourceFile> {
    CRATES
        .iter()
        .flat_map(|(dir, _, _)| crate_files(dir))
        .collect()
}

fn rust_files_under(src: &Path) -> Vec<PathBuf> {
    let mut paths = Vec::new();
    let mut pending = vec![src.to_path_buf()];
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
}

/// The source files of the crate in `dir`, each with its module path.
fn crate_files(dir: &'static str) -> Vec<SourceFile> {
    let src = repository().join(dir).join("src");
    rust_files_under(&src)
        .into_iter()
        .map(|path| {
            let in_crate = path.strip_prefix(&src).unwrap().to_str().unwrap();
            let mut module: Vec<String> = in_crate
                .trim_end_matches(".rs")
                .split('/')
                .map(str::to_string)
                .collect();
            if module
                .last()
                .is_some_and(|m| m == "mod" || m == "lib" || m == "main")
            {
                module.pop();
            }
            let text = std::fs::read_to_string(&path).unwrap();
            SourceFile {
                krate: dir,
                relative: Path::new(dir)
                    .join("src")
                    .join(in_crate)
                    .to_str()
                    .unwrap()
                    .trim_start_matches("./")
                    .to_string(),
                code: code_of(&text),
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
    let mut paths = Vec::new();
    for (at, _) in code.match_indices("::") {
        let before = &code[..at];
        let start = before.rfind(|c: char| !is_ident(c)).map_or(0, |i| i + 1);
        let head = &before[start..];
        if before[..start].ends_with("::") || head.is_empty() {
            continue;
        }
        let mut base = match head {
            "crate" => Vec::new(),
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

/// File -> the files of its crate it imports from (the crate roots left out: they
/// only gather).
fn import_graph(files: &[SourceFile]) -> BTreeMap<&str, BTreeSet<&str>> {
    let by_module: BTreeMap<(&str, &[String]), &str> = files
        .iter()
        .map(|f| ((f.krate, f.module.as_slice()), f.relative.as_str()))
        .collect();
    let mut graph = BTreeMap::new();
    for file in files {
        let mut targets = BTreeSet::new();
        for path in imports(file) {
            let target = (1..=path.len())
                .rev()
                .find_map(|n| by_module.get(&(file.krate, &path[..n])).copied());
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
        krate: "crates/io",
        relative: "crates/io/src/io/x.rs".into(),
        module: vec!["io".into(), "x".into()],
        code: code_of(
            "use super::{log::Log, ros::{A, B}};\nuse crate::error::Error; // crate::config\nfn f() { crate::geometry::rigid(); \"crate::frame\"; }\n",
        ),
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

/// The `travmap-*` crates a manifest's `[dependencies]` name.
fn workspace_dependencies(manifest: &str) -> BTreeSet<String> {
    let mut names = BTreeSet::new();
    let mut in_dependencies = false;
    for line in manifest.lines() {
        let line = line.trim();
        if line.starts_with('[') {
            in_dependencies = line == "[dependencies]";
            continue;
        }
        let name = line.split(['.', '=', ' ']).next().unwrap_or_default();
        if in_dependencies && (name == "travmap" || name.starts_with("travmap-")) {
            names.insert(name.to_string());
        }
    }
    names
}

#[test]
fn each_crate_depends_only_on_the_crates_below_it() {
    let mut broken = Vec::new();
    for (dir, name, allowed) in CRATES {
        let manifest = std::fs::read_to_string(repository().join(dir).join("Cargo.toml")).unwrap();
        let manifest = match *dir {
            // The root manifest is the workspace's too: its package section on.
            "." => manifest[manifest.find("[package]").unwrap()..].to_string(),
            _ => manifest,
        };
        for dependency in workspace_dependencies(&manifest) {
            if !allowed.contains(&dependency.as_str()) {
                broken.push(format!("{name} depends on {dependency}"));
            }
        }
    }
    assert!(broken.is_empty(), "{}", broken.join("\n"));
    // The method's crate reaches no reader, not even through another crate.
    let method = CRATES.iter().find(|c| c.1 == "travmap-method").unwrap();
    assert!(method.2.iter().all(|d| *d == "travmap-core"));
}

#[test]
fn error_rs_is_a_leaf_and_the_method_reads_no_file() {
    let files = source_files();
    let mut broken = Vec::new();
    // error.rs is the leaf every crate stands on.
    let error = files
        .iter()
        .find(|f| f.relative == "crates/core/src/error.rs")
        .unwrap();
    broken.extend(
        imports(error)
            .iter()
            .map(|p| format!("error.rs imports {}", p.join("::"))),
    );
    // The method knows no file: what it needs is handed to it.
    for file in files.iter().filter(|f| f.krate == "crates/method") {
        if file.code.contains("std::fs::") {
            broken.push(format!("{} uses std::fs", file.relative));
        }
    }
    assert!(broken.is_empty(), "{}", broken.join("\n"));
}

#[test]
fn no_source_folder_holds_more_than_25_files() {
    let mut by_folder: BTreeMap<PathBuf, usize> = BTreeMap::new();
    for (dir, _, _) in CRATES {
        for path in rust_files_under(&repository().join(dir).join("src")) {
            *by_folder
                .entry(path.parent().unwrap().to_path_buf())
                .or_default() += 1;
        }
    }
    let crowded: Vec<String> = by_folder
        .iter()
        .filter(|(_, files)| **files > MAX_FILES_PER_FOLDER)
        .map(|(folder, files)| format!("{}: {files} files", folder.display()))
        .collect();
    assert!(
        crowded.is_empty(),
        "give them rooms: {}",
        crowded.join(", ")
    );
}
