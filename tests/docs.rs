//! The manual holds: every relative link resolves (file and heading), and every flag a documented
//! `agvrl` or `agvrl-drive` command uses exists in that command's `--help`.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::Command;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// README.md, ARCHITECTURE.md, python/README.md and every page under docs/.
fn pages() -> Vec<PathBuf> {
    let mut out: Vec<PathBuf> = ["README.md", "ARCHITECTURE.md", "python/README.md"]
        .iter()
        .map(|p| root().join(p))
        .collect();
    let mut dirs = vec![root().join("docs")];
    while let Some(d) = dirs.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                dirs.push(p);
            } else if p.extension().is_some_and(|x| x == "md") {
                out.push(p);
            }
        }
    }
    out.sort();
    out
}

/// GitHub's anchor of a heading: lower case, punctuation dropped but `-` and `_`, spaces as `-`.
fn slug(heading: &str) -> String {
    heading
        .trim()
        .to_lowercase()
        .chars()
        .filter(|c| c.is_alphanumeric() || matches!(c, ' ' | '-' | '_'))
        .map(|c| if c == ' ' { '-' } else { c })
        .collect()
}

/// The anchors of a page's headings (outside code blocks), numbered as GitHub numbers repeats.
fn anchors(text: &str) -> BTreeSet<String> {
    let mut seen: BTreeMap<String, usize> = BTreeMap::new();
    let mut out = BTreeSet::new();
    for line in prose_lines(text) {
        let Some(h) = line.strip_prefix('#') else { continue };
        let h = h.trim_start_matches('#');
        if !h.starts_with(' ') {
            continue;
        }
        let s = slug(h);
        let n = seen.entry(s.clone()).or_insert(0);
        out.insert(if *n == 0 { s.clone() } else { format!("{s}-{n}") });
        *n += 1;
    }
    out
}

/// Lines outside fenced code blocks.
fn prose_lines(text: &str) -> impl Iterator<Item = &str> {
    let mut fenced = false;
    text.lines().filter(move |l| {
        if l.trim_start().starts_with("```") {
            fenced = !fenced;
            return false;
        }
        !fenced
    })
}

/// The targets of the inline links `[text](target)` in the prose of `text`.
fn link_targets(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    for line in prose_lines(text) {
        let mut rest = line;
        while let Some(i) = rest.find("](") {
            rest = &rest[i + 2..];
            let Some(j) = rest.find(')') else { break };
            out.push(rest[..j].to_string());
            rest = &rest[j..];
        }
    }
    out
}

#[test]
fn every_relative_link_in_the_docs_resolves_to_a_file_and_heading() {
    let mut broken = Vec::new();
    let mut checked = 0;
    for page in pages() {
        let text = std::fs::read_to_string(&page).unwrap();
        for target in link_targets(&text) {
            if target.contains("://") || target.starts_with("mailto:") {
                continue;
            }
            checked += 1;
            let (file, anchor) = target.split_once('#').unwrap_or((&target, ""));
            let dest = if file.is_empty() {
                page.clone()
            } else {
                page.parent().unwrap().join(file)
            };
            let shown = format!("{}: ({target})", page.strip_prefix(root()).unwrap().display());
            if !dest.exists() {
                broken.push(format!("{shown}: no such file"));
            } else if !anchor.is_empty() {
                let dest_text = std::fs::read_to_string(&dest).unwrap_or_default();
                if !anchors(&dest_text).contains(anchor) {
                    broken.push(format!("{shown}: no heading with that anchor"));
                }
            }
        }
    }
    assert!(
        checked > 100,
        "only {checked} relative links found: is the link parser broken?"
    );
    assert!(
        broken.is_empty(),
        "{} broken links:\n{}",
        broken.len(),
        broken.join("\n")
    );
}

/// Each documented command line of `bin` (`agvrl ...`, `cargo run --release -- ...`, or
/// `agvrl-drive ...`, with `\` continuations joined): its subcommand (None for agvrl-drive) and
/// the `--flags` it uses.
fn documented_commands(text: &str) -> Vec<(String, Option<String>, Vec<String>)> {
    let mut out = Vec::new();
    let mut joined = String::new();
    for raw in text.lines() {
        // Inline code spans and code-block lines alike; a trailing `\` continues the line.
        if let Some(stripped) = raw.trim_end().strip_suffix('\\') {
            joined.push_str(stripped);
            joined.push(' ');
            continue;
        }
        joined.push_str(raw);
        let line = std::mem::take(&mut joined);
        for segment in line.split('`') {
            let words: Vec<&str> = segment.split_whitespace().collect();
            for (i, w) in words.iter().enumerate() {
                let bin = match *w {
                    "agvrl" | "target/release/agvrl" => "agvrl",
                    "agvrl-drive" | "target/release/agvrl-drive" => "agvrl-drive",
                    "--" if i >= 3 && words[i - 3..i] == ["cargo", "run", "--release"] => "agvrl",
                    _ => continue,
                };
                let args = &words[i + 1..];
                let (sub, args) = if bin == "agvrl" {
                    match args.first() {
                        Some(s) if s.chars().all(|c| c.is_ascii_lowercase() || c == '-') && !s.is_empty() => {
                            (Some(s.to_string()), &args[1..])
                        }
                        _ => continue,
                    }
                } else {
                    (None, args)
                };
                let flags = args
                    .iter()
                    .take_while(|a| !matches!(**a, "|" | "&&" | ";" | "#" | ">" | "2>"))
                    .filter(|a| a.starts_with("--") && a.len() > 2)
                    .map(|a| {
                        a.split(['=', ',', ')', '`', '.', ';', ':'])
                            .next()
                            .unwrap()
                            .trim_end_matches(['[', ']'])
                            .to_string()
                    })
                    .filter(|f| f.len() > 2 && f[2..].chars().all(|c| c.is_ascii_lowercase() || c == '-'))
                    .collect();
                out.push((bin.to_string(), sub, flags));
            }
        }
    }
    out
}

fn help(bin: &Path, sub: Option<&str>) -> String {
    let mut c = Command::new(bin);
    if let Some(s) = sub {
        c.arg(s);
    }
    let o = c.arg("--help").output().unwrap();
    assert!(o.status.success(), "{} {sub:?} --help failed", bin.display());
    String::from_utf8_lossy(&o.stdout).into_owned()
}

#[test]
fn every_flag_of_a_documented_command_exists() {
    let agvrl = PathBuf::from(env!("CARGO_BIN_EXE_agvrl"));
    // agvrl-drive is built beside agvrl by `cargo test --workspace` and `cargo build --release`.
    let drive = agvrl.with_file_name("agvrl-drive");
    assert!(
        drive.exists(),
        "{} not built: cargo build --release -p agvrl-deploy",
        drive.display()
    );
    let subcommands = help(&agvrl, None);
    let mut helps: BTreeMap<(String, Option<String>), String> = BTreeMap::new();
    let (mut missing, mut commands) = (BTreeSet::new(), 0);
    for page in pages() {
        let text = std::fs::read_to_string(&page).unwrap();
        let shown = page.strip_prefix(root()).unwrap().display().to_string();
        for (bin, sub, flags) in documented_commands(&text) {
            if let Some(s) = &sub
                && !subcommands.contains(&format!("  {s} "))
                && !subcommands.contains(&format!("  {s}\n"))
            {
                // A word after `agvrl` that is no subcommand is prose ("agvrl and ...").
                continue;
            }
            commands += 1;
            let key = (bin.clone(), sub.clone());
            let text = helps
                .entry(key)
                .or_insert_with(|| help(if bin == "agvrl" { &agvrl } else { &drive }, sub.as_deref()));
            for f in flags {
                if f != "--help" && !text.contains(&format!("{f} ")) && !text.contains(&format!("{f}\n")) {
                    let cmd = sub.as_deref().map_or(bin.clone(), |s| format!("{bin} {s}"));
                    missing.insert(format!("{shown}: {cmd} {f}"));
                }
            }
        }
    }
    assert!(
        commands > 100,
        "only {commands} documented commands found: is the parser broken?"
    );
    assert!(
        missing.is_empty(),
        "{} documented flags that the command does not have:\n{}",
        missing.len(),
        missing.into_iter().collect::<Vec<_>>().join("\n")
    );
}
