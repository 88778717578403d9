//! Keeps the documentation honest:
//! - `docs/cli.md` is what `kumi <command> --help` prints, for every command
//!   (`KUMI_BLESS_DOCS=1 cargo test -p kumi --test docs` rewrites it);
//! - every relative link in `README.md`, `docs/`, the model cards and the reports resolves to a
//!   file, and its `#anchor`, where it has one, to a heading of that file;
//! - every `kumi` subcommand named in code in `README.md`, `docs/` and the model cards exists;
//! - no reference text tells the history of how it was found (the word stop and a number):
//!   that belongs in `docs/notebook/` and in version control.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::Command;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// `kumi <path> --help`.
fn help(path: &[String]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_kumi"))
        .args(path)
        .arg("--help")
        .output()
        .expect("running kumi");
    assert!(
        out.status.success(),
        "kumi {} --help failed",
        path.join(" ")
    );
    String::from_utf8(out.stdout).expect("help is UTF-8")
}

/// The subcommands a help text lists under `Commands:` (clap's own `help` left out).
fn subcommands(help: &str) -> Vec<String> {
    help.lines()
        .skip_while(|line| line.trim() != "Commands:")
        .skip(1)
        .take_while(|line| !line.trim().is_empty())
        .filter(|line| line.starts_with("  ") && !line.starts_with("   "))
        .filter_map(|line| line.split_whitespace().next().map(str::to_string))
        .filter(|name| name != "help")
        .collect()
}

/// Every command path (`[]`, `["train"]`, `["train", "arm"]`, ...) with its help, depth first.
fn command_tree() -> Vec<(Vec<String>, String)> {
    fn walk(path: Vec<String>, out: &mut Vec<(Vec<String>, String)>) {
        let text = help(&path);
        let children = subcommands(&text);
        out.push((path.clone(), text));
        for child in children {
            let mut next = path.clone();
            next.push(child);
            walk(next, out);
        }
    }
    let mut out = Vec::new();
    walk(Vec::new(), &mut out);
    out
}

fn cli_markdown(tree: &[(Vec<String>, String)]) -> String {
    let mut md = String::from(
        "# Command reference\n\n\
         Every `kumi` command and flag, as `kumi <command> --help` prints it. This file is \
         generated: `KUMI_BLESS_DOCS=1 cargo test -p kumi --test docs` rewrites it, and the \
         test fails when it differs from the built command. For what the commands are for and \
         how they fit together, start at the [README](../README.md) and the [docs \
         index](README.md). Errors are one line on stderr (`error: file: field: problem`) \
         and a non-zero exit code.\n\n## Commands\n\n",
    );
    for (path, _) in tree.iter().skip(1) {
        let name = path.join(" ");
        md += &format!("- [`kumi {name}`](#kumi-{})\n", name.replace(' ', "-"));
    }
    for (path, text) in tree {
        let name = if path.is_empty() {
            "kumi".to_string()
        } else {
            format!("kumi {}", path.join(" "))
        };
        md += &format!("\n## {name}\n\n```text\n{}\n```\n", text.trim_end());
    }
    md
}

#[test]
fn docs_cli_md_is_what_the_command_prints() {
    let tree = command_tree();
    assert!(
        tree.len() > 15,
        "only {} commands found: is the help parser broken?",
        tree.len()
    );
    let expected = cli_markdown(&tree);
    let file = root().join("docs/cli.md");
    if std::env::var_os("KUMI_BLESS_DOCS").is_some() {
        std::fs::write(&file, &expected).unwrap();
        return;
    }
    let actual = std::fs::read_to_string(&file).unwrap_or_default();
    assert!(
        actual == expected,
        "docs/cli.md is out of date with the command's help: run \
         `KUMI_BLESS_DOCS=1 cargo test -p kumi --test docs` and commit it"
    );
}

/// Appends every file under `dir` whose extension is one of `exts`, leaving out build output
/// (`target`) and hidden folders.
fn files_under(dir: &Path, exts: &[&str], out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let path = entry.path();
        let name = path.file_name().unwrap().to_string_lossy().to_string();
        if path.is_dir() && name != "target" && !name.starts_with('.') {
            files_under(&path, exts, out);
        } else if path
            .extension()
            .is_some_and(|e| exts.iter().any(|x| e == *x))
        {
            out.push(path);
        }
    }
}

/// Markdown files a reader is pointed to: the README, `docs/`, the model cards, the reports and
/// the examples.
fn markdown_files(with_notebook: bool) -> Vec<PathBuf> {
    let root = root();
    let mut files = vec![root.join("README.md")];
    for dir in ["docs", "policies", "reports", "examples"] {
        files_under(&root.join(dir), &["md"], &mut files);
    }
    files.retain(|f| with_notebook || !f.starts_with(root.join("docs/notebook")));
    files.sort();
    files
}

/// `(line number from 1, line, inside a fenced code block)` for every line of a markdown text
/// but the fences themselves.
fn markdown_lines(text: &str) -> impl Iterator<Item = (usize, &str, bool)> {
    let mut fenced = false;
    text.lines().enumerate().filter_map(move |(n, line)| {
        if line.trim_start().starts_with("```") {
            fenced = !fenced;
            None
        } else {
            Some((n + 1, line, fenced))
        }
    })
}

/// `(target, line)` of every inline markdown link `[text](target)` outside code.
fn links(text: &str) -> Vec<(String, usize)> {
    let mut out = Vec::new();
    for (n, line, fenced) in markdown_lines(text) {
        if fenced {
            continue;
        }
        let outside_code: String = line.split('`').step_by(2).collect::<Vec<_>>().join(" ");
        let mut rest = outside_code.as_str();
        while let Some(at) = rest.find("](") {
            let after = &rest[at + 2..];
            let Some(end) = after.find(')') else { break };
            out.push((after[..end].trim().to_string(), n));
            rest = &after[end..];
        }
    }
    out
}

/// GitHub's anchor of a heading: lower case, punctuation dropped, spaces as hyphens.
fn anchor(heading: &str) -> String {
    heading
        .trim()
        .to_lowercase()
        .chars()
        .filter(|c| c.is_alphanumeric() || *c == ' ' || *c == '-' || *c == '_')
        .map(|c| if c == ' ' { '-' } else { c })
        .collect()
}

fn anchors(text: &str) -> BTreeSet<String> {
    markdown_lines(text)
        .filter(|(_, line, fenced)| !fenced && line.starts_with('#'))
        .map(|(_, line, _)| anchor(line.trim_start_matches('#')))
        .collect()
}

#[test]
fn every_relative_link_in_the_docs_resolves() {
    let mut broken = Vec::new();
    for file in markdown_files(true) {
        let text = std::fs::read_to_string(&file).unwrap();
        for (target, line) in links(&text) {
            if target.contains("://") || target.starts_with("mailto:") {
                continue;
            }
            let (path, fragment) = match target.split_once('#') {
                Some((path, fragment)) => (path, Some(fragment)),
                None => (target.as_str(), None),
            };
            let resolved = if path.is_empty() {
                file.clone()
            } else {
                file.parent().unwrap().join(path)
            };
            let label = format!(
                "{}:{line}: {target}",
                file.strip_prefix(root()).unwrap().display()
            );
            if !resolved.exists() {
                broken.push(format!("{label} (no such file)"));
                continue;
            }
            if let Some(fragment) = fragment {
                let heading_text = std::fs::read_to_string(&resolved).unwrap_or_default();
                if !anchors(&heading_text).contains(fragment) {
                    broken.push(format!("{label} (no heading with that anchor)"));
                }
            }
        }
    }
    assert!(broken.is_empty(), "broken links:\n{}", broken.join("\n"));
}

/// `kumi <words>` as named in code (inline code and fenced blocks), with `cargo run ... --bin
/// kumi -- <words>` read the same way: the first two words after `kumi` that look like
/// command names.
fn kumi_invocations(text: &str) -> Vec<(Vec<String>, usize)> {
    let mut out = Vec::new();
    for (n, line, fenced) in markdown_lines(text) {
        let code: Vec<&str> = if fenced {
            vec![line]
        } else {
            line.split('`').skip(1).step_by(2).collect()
        };
        for span in code {
            let words: Vec<&str> = span.split_whitespace().collect();
            for (i, word) in words.iter().enumerate() {
                if *word != "kumi" {
                    continue;
                }
                let mut rest = words[i + 1..].iter().copied().skip_while(|w| *w == "--");
                let path: Vec<String> = rest
                    .by_ref()
                    .take(2)
                    .take_while(|w| {
                        w.chars().all(|c| c.is_ascii_lowercase() || c == '-') && !w.starts_with('-')
                    })
                    .map(str::to_string)
                    .collect();
                if !path.is_empty() {
                    out.push((path, n));
                }
            }
        }
    }
    out
}

#[test]
fn every_kumi_command_named_in_the_docs_exists() {
    let tree = command_tree();
    let commands: BTreeSet<Vec<String>> = tree.iter().map(|(path, _)| path.clone()).collect();
    let has_children = |path: &[String]| {
        commands
            .iter()
            .any(|c| c.len() == path.len() + 1 && c.starts_with(path))
    };
    let mut unknown = Vec::new();
    for file in markdown_files(false) {
        let text = std::fs::read_to_string(&file).unwrap();
        for (words, line) in kumi_invocations(&text) {
            // `kumi train` names a command that has subcommands; `kumi train arm` one of them;
            // `kumi demo minimal` a command and its argument.
            let first = vec![words[0].clone()];
            let known = commands.contains(&first)
                && (words.len() == 1 || !has_children(&first) || commands.contains(&words));
            if !known {
                unknown.push(format!(
                    "{}:{line}: kumi {}",
                    file.strip_prefix(root()).unwrap().display(),
                    words.join(" ")
                ));
            }
        }
    }
    assert!(
        unknown.is_empty(),
        "commands that kumi does not have:\n{}",
        unknown.join("\n")
    );
}

/// Whether `text` names a stop of the project's history: the word stop (or stops), a space and
/// a digit, in any case.
fn names_a_stop(text: &str) -> bool {
    let lower = text.to_lowercase();
    lower.match_indices("stop").any(|(at, _)| {
        let rest = lower[at + 4..]
            .strip_prefix('s')
            .unwrap_or(&lower[at + 4..]);
        rest.strip_prefix(' ')
            .is_some_and(|r| r.starts_with(|c: char| c.is_ascii_digit()))
    })
}

#[test]
fn reference_text_tells_no_history() {
    let root = root();
    let mut files = markdown_files(false);
    files_under(&root.join("train/configs"), &["toml"], &mut files);
    files_under(&root.join("urdf"), &["toml", "urdf"], &mut files);
    files_under(&root.join("examples"), &["toml"], &mut files);
    for dir in [
        "urdf",
        "sim_bridge",
        "msgs",
        "nodes",
        "policies",
        "train",
        "cli",
        "tests",
        "scripts",
    ] {
        files_under(&root.join(dir), &["rs", "py", "sh"], &mut files);
    }
    let mut found = Vec::new();
    for file in files {
        let text = std::fs::read_to_string(&file).unwrap_or_default();
        for (n, line) in text.lines().enumerate() {
            if names_a_stop(line) {
                found.push(format!(
                    "{}:{}: {}",
                    file.strip_prefix(&root).unwrap().display(),
                    n + 1,
                    line.trim()
                ));
            }
        }
    }
    assert!(
        found.is_empty(),
        "history in reference text (it belongs in docs/notebook/ or a commit message):\n{}",
        found.join("\n")
    );
}

#[test]
fn the_checks_catch_what_they_look_for() {
    // Built at run time, so that this file itself holds no such text.
    let (stop, stops) = ("stop", "Stops");
    assert!(
        names_a_stop(&format!("as {stop} 66 found")) && names_a_stop(&format!("{stops} 34-65"))
    );
    assert!(!names_a_stop("a non-stop run, stopping at 3"));
    assert_eq!(
        links("see [a](x.md#b) and `[c](not)`"),
        vec![("x.md#b".to_string(), 1)]
    );
    assert_eq!(
        anchor("## The upper level (in progress)".trim_start_matches('#')),
        "the-upper-level-in-progress"
    );
    let named = kumi_invocations("run `cargo run --release --bin kumi -- train arm --out x`");
    assert_eq!(
        named,
        vec![(vec!["train".to_string(), "arm".to_string()], 1)]
    );
    let named = kumi_invocations("```sh\nkumi demo minimal\n```");
    assert_eq!(named[0].0, vec!["demo".to_string(), "minimal".to_string()]);
    let tree = vec![
        (
            vec![],
            "Commands:\n  train  Train\n  help   Print\n\nOptions:\n".to_string(),
        ),
        (vec!["train".to_string()], String::new()),
    ];
    assert_eq!(subcommands(&tree[0].1), vec!["train".to_string()]);
    assert!(cli_markdown(&tree).contains("## kumi train"));
}
