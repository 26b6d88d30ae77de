//! ARCHITECTURE.md's rooms table is true of the code: each room's "may import" cell lists
//! exactly the rooms its files import (`crate::ROOM` paths, `use crate::{…}` groups), test
//! modules left out; every room may import `error`, which the table does not repeat. On a mismatch the test prints the cell the code implies, so the table is
//! regenerated from the code rather than edited by hand.

use std::collections::{BTreeMap, BTreeSet};
use std::fs;
use std::path::{Path, PathBuf};

const PUBLIC_API: &str = "the public API";

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let mut entries: Vec<_> = fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|e| e == "rs") {
            out.push(p);
        }
    }
}

/// The room a file of `src/` belongs to, as the table names it (`codec/`, `metrics.rs`);
/// `None` for the binary, the crate root and the test helpers.
fn room_of(rel: &Path) -> Option<String> {
    let mut parts = rel
        .components()
        .map(|c| c.as_os_str().to_string_lossy().into_owned());
    let first = parts.next()?;
    let rest = parts.next();
    match (first.as_str(), rest) {
        ("bin", _) | ("lib.rs", None) | ("testutil.rs", None) => None,
        (f, None) => Some(f.to_string()),
        (d, Some(_)) => Some(format!("{d}/")),
    }
}

/// The code of a file without its test modules (a `#[cfg(test)]` item and everything after
/// it: the crate puts its unit tests last) and without line comments.
fn code_of(text: &str) -> String {
    let mut out = String::new();
    for line in text.lines() {
        let t = line.trim_start();
        if t.starts_with("#[cfg(test)]") {
            break;
        }
        if t.starts_with("//") {
            continue;
        }
        out.push_str(line);
        out.push('\n');
    }
    out
}

/// The first path segments after `crate::`, including each top-level name of a
/// `use crate::{a::b, c, d::{e, f}}` group.
fn crate_paths(code: &str) -> BTreeSet<String> {
    let mut names = BTreeSet::new();
    let mut rest = code;
    while let Some(i) = rest.find("crate::") {
        let preceded = rest[..i].chars().next_back();
        rest = &rest[i + "crate::".len()..];
        if preceded.is_some_and(|c| c.is_alphanumeric() || c == '_' || c == '$') {
            continue; // `$crate::`, `mycrate::`
        }
        if let Some(group) = rest.strip_prefix('{') {
            let mut depth = 0usize;
            let mut item = String::new();
            let mut at_start = true;
            for c in group.chars() {
                match c {
                    '{' => depth += 1,
                    '}' if depth == 0 => break,
                    '}' => depth -= 1,
                    ',' if depth == 0 => {
                        if at_start && !item.is_empty() {
                            names.insert(std::mem::take(&mut item));
                        }
                        at_start = true;
                        item.clear();
                        continue;
                    }
                    _ => {}
                }
                if depth == 0 && at_start {
                    if c.is_alphanumeric() || c == '_' {
                        item.push(c);
                    } else if !item.is_empty() {
                        names.insert(std::mem::take(&mut item));
                        at_start = false;
                    }
                }
            }
            if at_start && !item.is_empty() {
                names.insert(item);
            }
        } else {
            let name: String = rest
                .chars()
                .take_while(|c| c.is_alphanumeric() || *c == '_')
                .collect();
            if !name.is_empty() {
                names.insert(name);
            }
        }
    }
    names
}

/// Each room's imports of other rooms, from the code.
fn imports() -> BTreeMap<String, BTreeSet<String>> {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    // Module names at the crate root → their rooms.
    let mut rooms = BTreeMap::new();
    for f in &files {
        if let Some(room) = room_of(f.strip_prefix(&src).unwrap()) {
            let module = room
                .trim_end_matches('/')
                .trim_end_matches(".rs")
                .to_string();
            rooms.insert(module, room);
        }
    }
    let mut out: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for f in &files {
        let Some(room) = room_of(f.strip_prefix(&src).unwrap()) else {
            continue;
        };
        let entry = out.entry(room.clone()).or_default();
        for name in crate_paths(&code_of(&fs::read_to_string(f).unwrap())) {
            let target = match name.as_str() {
                // Every room may use the error enum (the table's heading says so), also
                // through its re-export at the root.
                "testutil" | "self" | "super" | "error" | "Error" | "Result" => continue,
                n => match rooms.get(n) {
                    Some(r) => r.clone(),
                    None if n == "internals" => continue,
                    // Any other root name is a re-export: the public API.
                    None => PUBLIC_API.to_string(),
                },
            };
            if target != room {
                entry.insert(target);
            }
        }
    }
    out
}

/// The rooms a "may import" cell names: the text before its first " — ", parentheses
/// removed, the words that are room names or "the public API".
fn listed(cell: &str, rooms: &BTreeSet<String>) -> BTreeSet<String> {
    let head = cell.split(" — ").next().unwrap();
    let mut flat = String::new();
    let mut depth = 0usize;
    for c in head.chars() {
        match c {
            '(' => depth += 1,
            ')' => depth = depth.saturating_sub(1),
            _ if depth == 0 => flat.push(c),
            _ => {}
        }
    }
    let mut out = BTreeSet::new();
    if flat.contains(PUBLIC_API) {
        out.insert(PUBLIC_API.to_string());
    }
    for word in flat.split(|c: char| !(c.is_alphanumeric() || c == '_' || c == '.')) {
        let word = word.trim_end_matches('.');
        for room in rooms {
            if room.trim_end_matches('/').trim_end_matches(".rs") == word
                || room.trim_end_matches('/') == word
            {
                out.insert(room.clone());
            }
        }
    }
    out
}

fn cell_of(set: &BTreeSet<String>) -> String {
    if set.is_empty() {
        return "—".to_string();
    }
    let names: Vec<String> = set
        .iter()
        .map(|r| {
            if r == PUBLIC_API {
                r.clone()
            } else {
                r.trim_end_matches('/').trim_end_matches(".rs").to_string()
            }
        })
        .collect();
    names.join(", ")
}

#[test]
fn the_rooms_table_lists_what_each_room_imports() {
    let code = imports();
    let rooms: BTreeSet<String> = code.keys().cloned().collect();
    let doc =
        fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("ARCHITECTURE.md")).unwrap();
    let mut table: BTreeMap<String, String> = BTreeMap::new();
    for line in doc.lines() {
        let cells: Vec<&str> = line.split(" | ").collect();
        if !line.starts_with("| `") || cells.len() < 3 {
            continue;
        }
        let room = cells[0]
            .trim_start_matches("| ")
            .trim_matches('`')
            .to_string();
        let last = cells[cells.len() - 1]
            .trim_end_matches(" |")
            .trim_end_matches('|')
            .trim();
        table.insert(room, last.to_string());
    }
    let mut wrong = Vec::new();
    for (room, imports) in &code {
        match table.get(room) {
            None => wrong.push(format!(
                "`{room}` has no row (it imports: {})",
                cell_of(imports)
            )),
            Some(cell) => {
                let said = listed(cell, &rooms);
                if &said != imports {
                    wrong.push(format!(
                        "`{room}`: the table says {}, the code imports {}",
                        cell_of(&said),
                        cell_of(imports)
                    ));
                }
            }
        }
    }
    for room in table.keys() {
        if !code.contains_key(room) && room != "lib.rs" && room != "bin/vtz/" {
            wrong.push(format!("`{room}` has a row but no file in src/"));
        }
    }
    assert!(
        wrong.is_empty(),
        "ARCHITECTURE.md's rooms table is not the code's:\n{}",
        wrong.join("\n")
    );
}

/// The parser itself, on the shapes the crate writes.
#[test]
fn crate_paths_reads_groups_and_nested_groups() {
    let code = "use crate::{model::{Raster, Window}, quant, error::Error};\nlet x = crate::codec::decode(b);\nmacro_rules! m { () => { $crate::source::X } }";
    let got: Vec<String> = crate_paths(code).into_iter().collect();
    assert_eq!(got, ["codec", "error", "model", "quant"]);
    assert_eq!(
        code_of("use a;\n// crate::x\n#[cfg(test)]\nmod tests { use crate::y; }"),
        "use a;\n"
    );
}
