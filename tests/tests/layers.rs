//! The core's layer rule (`core/src/lib.rs`, "Layers"): a top-level module refers only to
//! modules below it, so there is no import cycle between them and the wire protocol
//! depends on nothing above it.
//!
//! ```text
//! controller → wire → registration | acquisition → math → config → error → limits
//! ```
//!
//! Every `crate::<module>` path in the code of `core/src` (comments and doc links
//! excluded, tests included) is checked against that order.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

/// Rank of each top-level module: a module may use only strictly lower ranks (and
/// itself). `registration` and `acquisition` share a rank, so neither may use the other.
fn rank(module: &str) -> Option<u8> {
    Some(match module {
        "limits" => 0,
        "error" => 1,
        "config" => 2,
        "math" => 3,
        "registration" | "acquisition" => 4,
        "wire" => 5,
        "controller" => 6,
        _ => return None,
    })
}

/// Items of the crate root and the module that defines them.
fn root_item(name: &str) -> Option<&'static str> {
    match name {
        "Vec3" => Some("limits"),
        "Error" | "Result" | "Stream" => Some("error"),
        _ => None,
    }
}

fn core_src() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../core/src")
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

/// The top-level module a file belongs to (`math/som.rs` → `math`, `config.rs` →
/// `config`); `None` for `lib.rs`.
fn owner(src: &Path, file: &Path) -> Option<String> {
    let rel = file.strip_prefix(src).unwrap();
    let first = rel.components().next()?.as_os_str().to_str()?.to_string();
    let name = first.trim_end_matches(".rs").to_string();
    (name != "lib").then_some(name)
}

/// `(line, module)` for every `crate::module` in code (not in comments).
fn references(text: &str) -> Vec<(usize, String)> {
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let code = match line.find("//") {
            Some(i) => &line[..i],
            None => line,
        };
        let mut rest = code;
        while let Some(i) = rest.find("crate::") {
            rest = &rest[i + "crate::".len()..];
            if rest.starts_with('{') {
                // `use crate::{a, b::c}`: every name in the braces.
                let end = rest.find('}').unwrap_or(rest.len());
                for part in rest[1..end].split(',') {
                    let name = part.trim().split("::").next().unwrap_or("").trim();
                    if !name.is_empty() {
                        out.push((n + 1, name.to_string()));
                    }
                }
                continue;
            }
            let name: String = rest
                .chars()
                .take_while(|c| c.is_alphanumeric() || *c == '_')
                .collect();
            out.push((n + 1, name));
        }
    }
    out
}

#[test]
fn core_modules_import_downward_only() {
    let src = core_src();
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    files.sort();
    assert!(files.len() > 20, "core/src not found at {}", src.display());
    let mut seen = BTreeSet::new();
    let mut violations = Vec::new();
    for file in &files {
        let Some(from) = owner(&src, file) else {
            continue;
        };
        let from_rank = rank(&from)
            .unwrap_or_else(|| panic!("{}: module `{from}` has no layer", file.display()));
        let text = std::fs::read_to_string(file).unwrap();
        for (line, name) in references(&text) {
            let to = match root_item(&name) {
                Some(m) => m.to_string(),
                None => name.clone(),
            };
            let Some(to_rank) = rank(&to) else {
                violations.push(format!(
                    "{}:{line}: unknown crate item `{name}`",
                    file.display()
                ));
                continue;
            };
            seen.insert((from.clone(), to.clone()));
            if to != from && to_rank >= from_rank {
                violations.push(format!(
                    "{}:{line}: `{from}` (layer {from_rank}) uses `{to}` (layer {to_rank})",
                    file.display()
                ));
            }
        }
    }
    assert!(
        violations.is_empty(),
        "layer rule broken:\n{}",
        violations.join("\n")
    );
    // The check sees real edges (a parser that found nothing would pass vacuously).
    for edge in [
        ("controller", "wire"),
        ("registration", "math"),
        ("wire", "acquisition"),
    ] {
        assert!(
            seen.contains(&(edge.0.to_string(), edge.1.to_string())),
            "expected edge {edge:?} not found"
        );
    }
}

#[test]
fn the_check_catches_an_upward_edge() {
    let refs = references(
        "use crate::controller::Controller; // crate::wire\nlet x = crate::{math::geom, wire};",
    );
    let names: Vec<&str> = refs.iter().map(|(_, n)| n.as_str()).collect();
    assert_eq!(names, ["controller", "math", "wire"]);
    assert!(rank("wire") < rank("controller"));
    assert_eq!(rank("registration"), rank("acquisition"));
}
