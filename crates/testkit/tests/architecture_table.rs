//! `ARCHITECTURE.md`'s layer table stays true to the `Cargo.toml` files: every crate has a
//! row, every volmorph crate a crate depends on is listed above it (the one stated
//! exception: `testkit`), and its "depends on" column names exactly what it reaches, directly
//! or through the crates it names.
//!
//! The column may name indirect dependencies (`scene` names `warp`, which it also reaches
//! through `register`), so the check is on reach: the closure of the listed crates (through
//! their own rows) must equal the closure of the `[dependencies]` tables, and every listed
//! crate must be reached.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The workspace root (two levels above this crate).
fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// One row of the table: the crate's short name and the names its column lists (`None` for
/// "everything": every crate listed above it).
struct Row {
    name: String,
    listed: Option<Vec<String>>,
}

/// Remove parenthesised remarks (one level deep, as the table writes them).
fn without_remarks(text: &str) -> String {
    let mut depth = 0usize;
    let mut out = String::new();
    for c in text.chars() {
        match c {
            '(' => depth += 1,
            ')' => depth = depth.saturating_sub(1),
            _ if depth == 0 => out.push(c),
            _ => {}
        }
    }
    out
}

/// The rows of the layer table (the section "## Layers" where there is one), in order.
fn rows(text: &str) -> Vec<Row> {
    let section = match text.split_once("## Layers") {
        Some((_, rest)) => rest.split("\n## ").next().unwrap_or(rest),
        None => text,
    };
    let mut rows = Vec::new();
    for line in section.lines() {
        let cells: Vec<&str> = line.split(" | ").collect();
        if !line.starts_with("| ") || cells.len() != 4 || cells[1].trim() == "crate" {
            continue;
        }
        let Some(name) = cells[1].split('`').nth(1) else {
            continue;
        };
        let column = without_remarks(cells[3].trim_end_matches('|').trim());
        let listed = if column.trim().starts_with("everything") {
            None
        } else {
            Some(
                column
                    .split(',')
                    .map(|s| s.trim().trim_matches('`').to_string())
                    .filter(|s| !s.is_empty() && s != "—")
                    .collect(),
            )
        };
        rows.push(Row {
            name: name.to_string(),
            listed,
        });
    }
    rows
}

/// The volmorph crates (short names) of a manifest's `[dependencies]` table.
fn direct_dependencies(manifest: &Path) -> BTreeSet<String> {
    let text =
        std::fs::read_to_string(manifest).unwrap_or_else(|e| panic!("{}: {e}", manifest.display()));
    let mut section = String::new();
    let mut deps = BTreeSet::new();
    for line in text.lines() {
        let line = line.trim();
        if line.starts_with('[') {
            section = line.to_string();
            continue;
        }
        if section != "[dependencies]" {
            continue;
        }
        if let Some(rest) = line.strip_prefix("volmorph-") {
            let name: String = rest
                .chars()
                .take_while(|c| c.is_ascii_alphanumeric() || *c == '-')
                .collect();
            deps.insert(name);
        }
    }
    deps
}

/// Everything `name` reaches through `edges`.
fn closure(name: &str, edges: &BTreeMap<String, BTreeSet<String>>) -> BTreeSet<String> {
    let mut seen = BTreeSet::new();
    let mut todo: Vec<String> = edges.get(name).into_iter().flatten().cloned().collect();
    while let Some(n) = todo.pop() {
        if seen.insert(n.clone()) {
            todo.extend(edges.get(&n).into_iter().flatten().cloned());
        }
    }
    seen
}

/// The manifest of a crate named in the table.
fn manifest_of(name: &str) -> PathBuf {
    if name == "python" {
        root().join("python/Cargo.toml")
    } else {
        root().join("crates").join(name).join("Cargo.toml")
    }
}

#[test]
fn architecture_table_matches_the_manifests() {
    let path = root().join("ARCHITECTURE.md");
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let rows = rows(&text);
    let order: BTreeMap<&str, usize> = rows
        .iter()
        .enumerate()
        .map(|(i, r)| (r.name.as_str(), i))
        .collect();
    assert_eq!(order.len(), rows.len(), "a crate has two rows");

    // Every crate of `crates/` has a row.
    let mut dirs: Vec<String> = std::fs::read_dir(root().join("crates"))
        .expect("crates/")
        .filter_map(|e| e.ok())
        .filter(|e| e.path().join("Cargo.toml").is_file())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    dirs.sort();
    for d in &dirs {
        assert!(
            order.contains_key(d.as_str()),
            "crate {d} has no row in ARCHITECTURE.md"
        );
    }

    // The graph by the manifests, and by the table.
    let actual: BTreeMap<String, BTreeSet<String>> = rows
        .iter()
        .map(|r| (r.name.clone(), direct_dependencies(&manifest_of(&r.name))))
        .collect();
    let stated: BTreeMap<String, BTreeSet<String>> = rows
        .iter()
        .enumerate()
        .map(|(i, r)| {
            let set = match &r.listed {
                Some(l) => l.iter().cloned().collect(),
                // "Everything": what it depends on, all of it listed above.
                None => actual[&r.name]
                    .iter()
                    .filter(|d| order.get(d.as_str()).is_some_and(|&j| j < i))
                    .cloned()
                    .collect(),
            };
            (r.name.clone(), set)
        })
        .collect();

    let mut faults = Vec::new();
    for (i, r) in rows.iter().enumerate() {
        for d in &actual[&r.name] {
            match order.get(d.as_str()) {
                None => faults.push(format!("{}: depends on {d}, which has no row", r.name)),
                Some(&j) if j > i && d != "testkit" => {
                    faults.push(format!("{}: depends on {d}, listed below it", r.name));
                }
                _ => {}
            }
        }
        let (reach, says) = (closure(&r.name, &actual), closure(&r.name, &stated));
        if reach != says {
            faults.push(format!(
                "{}: reaches {:?} by its manifests, the table says {:?}",
                r.name, reach, says
            ));
        }
        for l in &stated[&r.name] {
            if !reach.contains(l) {
                faults.push(format!(
                    "{}: lists {l}, which it does not depend on",
                    r.name
                ));
            }
        }
    }
    assert!(
        faults.is_empty(),
        "ARCHITECTURE.md is out of date:\n{}",
        faults.join("\n")
    );
}

/// The parser reads a row's name and column, drops remarks in parentheses and reads
/// "everything" as every crate above (regression guard for the checker itself).
#[test]
fn rows_are_parsed_with_remarks_dropped() {
    let text = "| layer | crate | owns | depends on (volmorph crates) |\n\
                | --- | --- | --- | --- |\n\
                | 0 | `io` | atomic writes (and more, with commas) | — |\n\
                | 3 | `warp` | warps | deform, io (for the `Progress`, trait) |\n\
                | 8 | `cli` | the binary | everything |\n";
    let r = rows(text);
    assert_eq!(r.len(), 3);
    assert_eq!(r[0].name, "io");
    assert_eq!(r[0].listed.as_deref(), Some(&[][..]));
    assert_eq!(
        r[1].listed.as_deref(),
        Some(&["deform".to_string(), "io".to_string()][..])
    );
    assert!(r[2].listed.is_none());
}
