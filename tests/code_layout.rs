//! The code's shape holds: no two sibling modules (files beside each other, or a directory
//! module's files) import each other, in any crate of the workspace. A cycle between siblings
//! means neither can be read, moved or tested without the other.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// A module's path inside its crate (`["ppo", "host"]` for `ppo/host.rs`; empty: the root).
type ModPath = Vec<String>;

/// The crates' source roots, relative to the workspace root.
const SOURCE_ROOTS: [&str; 7] = [
    "src",
    "crates/sim/src",
    "crates/envs/src",
    "crates/rl/src",
    "crates/run/src",
    "crates/deploy/src",
    "crates/python/src",
];

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

/// The module a file holds: `a/b.rs` and `a/b/mod.rs` are `a::b`; `lib.rs` and `main.rs` the
/// root (binaries under `bin/` are roots of their own and are left out).
fn module_of(root: &Path, file: &Path) -> Option<ModPath> {
    let rel = file.strip_prefix(root).ok()?.with_extension("");
    let mut parts: ModPath = rel.iter().map(|s| s.to_string_lossy().into_owned()).collect();
    if parts.first().is_some_and(|p| p == "bin") {
        return None;
    }
    if parts.last().is_some_and(|p| p == "mod" || p == "lib" || p == "main") {
        parts.pop();
    }
    Some(parts)
}

/// The code of a file without comments and without its trailing `#[cfg(test)] mod tests`
/// (test modules may reach anywhere).
fn code_of(text: &str) -> String {
    let text = text.split("#[cfg(test)]\nmod tests").next().unwrap_or(text);
    text.lines()
        .map(|l| l.split("//").next().unwrap_or(""))
        .collect::<Vec<_>>()
        .join("\n")
}

fn ident_at(s: &str) -> &str {
    let end = s.find(|c: char| !(c.is_alphanumeric() || c == '_')).unwrap_or(s.len());
    &s[..end]
}

/// The first names after `prefix` at `rest`: one ident, or each item of a `{...}` group.
fn first_names(rest: &str) -> Vec<String> {
    if let Some(group) = rest.strip_prefix('{') {
        let body = &group[..group.find('}').unwrap_or(group.len())];
        return body
            .split(',')
            .map(|item| ident_at(item.trim()).to_string())
            .filter(|n| !n.is_empty())
            .collect();
    }
    let n = ident_at(rest);
    if n.is_empty() { vec![] } else { vec![n.to_string()] }
}

/// Every module path `code` (in module `me`) names through `super::` or `crate::`, as far as
/// its first segment below the prefix's module (enough to tell which sibling it reaches).
fn referenced(me: &ModPath, code: &str) -> BTreeSet<ModPath> {
    let mut out = BTreeSet::new();
    for (prefix, base) in [
        ("super::", me[..me.len().saturating_sub(1)].to_vec()),
        ("crate::", vec![]),
    ] {
        let mut from = 0;
        while let Some(k) = code[from..].find(prefix) {
            let at = from + k;
            from = at + prefix.len();
            let before = code[..at].chars().next_back();
            if before.is_some_and(|c| c.is_alphanumeric() || c == '_' || c == ':') {
                continue;
            }
            // Walk `a::b::c` to its end, then read the last segment's names (or a group).
            let mut path = base.clone();
            let mut rest = &code[from..];
            loop {
                let n = ident_at(rest);
                if n.is_empty() || !rest[n.len()..].starts_with("::") {
                    break;
                }
                path.push(n.to_string());
                out.insert(path.clone());
                rest = &rest[n.len() + 2..];
            }
            for n in first_names(rest) {
                let mut p = path.clone();
                p.push(n);
                out.insert(p);
            }
        }
    }
    out
}

/// Pairs of sibling modules that import each other (`root: a <-> b`), per crate source root.
fn sibling_cycles(roots: &[PathBuf]) -> Vec<String> {
    let mut found = Vec::new();
    for root in roots {
        let mut files = Vec::new();
        rust_files(root, &mut files);
        let mut refs: BTreeMap<ModPath, BTreeSet<ModPath>> = BTreeMap::new();
        for f in &files {
            if let Some(m) = module_of(root, f) {
                let code = code_of(&std::fs::read_to_string(f).unwrap());
                refs.insert(m.clone(), referenced(&m, &code));
            }
        }
        let mods: Vec<&ModPath> = refs.keys().collect();
        for (i, a) in mods.iter().enumerate() {
            for b in &mods[i + 1..] {
                let siblings = !a.is_empty() && a.len() == b.len() && a[..a.len() - 1] == b[..b.len() - 1];
                if siblings && refs[*a].contains(*b) && refs[*b].contains(*a) {
                    found.push(format!("{}: {} <-> {}", root.display(), a.join("::"), b.join("::")));
                }
            }
        }
    }
    found
}

#[test]
fn no_two_sibling_modules_import_each_other() {
    let workspace = Path::new(env!("CARGO_MANIFEST_DIR"));
    let roots: Vec<PathBuf> = SOURCE_ROOTS.iter().map(|r| workspace.join(r)).collect();
    let cycles = sibling_cycles(&roots);
    assert!(
        cycles.is_empty(),
        "sibling modules that import each other:\n{}",
        cycles.join("\n")
    );
}

/// The check sees a cycle through `super::` groups and through `crate::` paths, and leaves
/// comments and test modules alone.
#[test]
fn a_planted_sibling_cycle_is_found() {
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path().join("src");
    std::fs::create_dir_all(src.join("net")).unwrap();
    let write = |p: &str, text: &str| std::fs::write(src.join(p), text).unwrap();
    write("lib.rs", "mod a;\nmod b;\nmod c;\nmod net;\n");
    write("a.rs", "use crate::b::Thing;\nuse crate::c;\n");
    write("b.rs", "use super::{c, a};\n");
    write(
        "c.rs",
        "// crate::a::X is only a comment\n#[cfg(test)]\nmod tests {\n    use crate::a::X;\n}\n",
    );
    write("net/mod.rs", "mod host;\nmod layout;\n");
    write("net/host.rs", "use super::layout::Layout;\n");
    write("net/layout.rs", "pub fn f() { super::host::g() }\n");
    let found = sibling_cycles(std::slice::from_ref(&src));
    let pairs: Vec<&str> = found.iter().map(|f| f.rsplit(": ").next().unwrap()).collect();
    assert_eq!(pairs, ["a <-> b", "net::host <-> net::layout"]);
}
