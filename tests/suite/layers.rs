//! The crate's shape (docs/architecture.md "Layers"): every top-level module of `src/`
//! belongs to one layer and uses only modules of its own layer or below, and no two
//! modules use each other, directly or through others. Test code is left out: a test may
//! use a synthetic body from `synth`.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// Core algorithms (0), the pipeline (1), the application (2).
const LAYERS: &[(&str, u8)] = &[
    ("error", 0),
    ("fsutil", 0),
    ("limits", 0),
    ("yaml", 0),
    ("shell", 0),
    ("rng", 0),
    ("text", 0),
    ("camera", 0),
    ("imageio", 0),
    ("video", 0),
    ("geometry", 0),
    ("photo", 0),
    ("maxflow", 0),
    ("skeleton", 0),
    ("fit", 0),
    ("tracked_surface", 0),
    ("recon", 0),
    ("person", 0),
    ("joints", 0),
    ("poses", 0),
    ("dataset", 1),
    ("artifacts", 1),
    ("config", 1),
    ("cache", 1),
    ("stages", 1),
    ("runner", 1),
    ("commands", 2),
    ("export", 2),
    ("report", 2),
    ("drawing", 2),
    ("eval", 2),
    ("bench", 2),
    ("slurm", 2),
    ("synth", 2),
    ("autoskeleton", 2),
    ("calib_import", 2),
    ("plot", 2),
];

/// The source of `text` without comments and without its `#[cfg(test)] mod tests`.
fn code_of(text: &str) -> String {
    let text = match text.find("#[cfg(test)]\nmod tests") {
        Some(i) => &text[..i],
        None => text,
    };
    text.lines()
        .filter(|l| !l.trim_start().starts_with("//"))
        .collect::<Vec<_>>()
        .join("\n")
}

/// The top-level modules `code` names as `crate::NAME`.
fn uses(code: &str) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    for (i, _) in code.match_indices("crate::") {
        let name: String = code[i + 7..]
            .chars()
            .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
            .collect();
        // `crate::Error` and the like are the root's re-exports, not modules.
        if name.starts_with(|c: char| c.is_ascii_lowercase()) {
            out.insert(name);
        }
    }
    out
}

fn walk(dir: &Path, files: &mut Vec<std::path::PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            walk(&path, files);
        } else if path.extension().is_some_and(|e| e == "rs") {
            files.push(path);
        }
    }
}

/// Each top-level module's uses of the others.
fn graph() -> BTreeMap<String, BTreeSet<String>> {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    walk(&src, &mut files);
    let mut graph: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for file in files {
        let rel = file.strip_prefix(&src).unwrap();
        let top = rel
            .components()
            .next()
            .unwrap()
            .as_os_str()
            .to_string_lossy();
        let top = top.trim_end_matches(".rs").to_string();
        if top == "main" || top == "lib" || rel.ends_with("tests.rs") {
            continue;
        }
        let code = code_of(&std::fs::read_to_string(&file).unwrap());
        let entry = graph.entry(top.clone()).or_default();
        entry.extend(uses(&code).into_iter().filter(|u| *u != top));
    }
    graph
}

#[test]
fn every_module_uses_only_its_layer_and_those_below() {
    let layer: BTreeMap<&str, u8> = LAYERS.iter().copied().collect();
    let graph = graph();
    let mut wrong = Vec::new();
    for (module, used) in &graph {
        let Some(&own) = layer.get(module.as_str()) else {
            wrong.push(format!("{module} has no layer in tests/layers.rs"));
            continue;
        };
        for u in used {
            match layer.get(u.as_str()) {
                Some(&l) if l > own => {
                    wrong.push(format!("{module} (layer {own}) uses {u} (layer {l})"))
                }
                None => wrong.push(format!("{module} uses {u}, which has no layer")),
                _ => {}
            }
        }
    }
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
    // The table names only modules that exist.
    for (name, _) in LAYERS {
        assert!(
            graph.contains_key(*name),
            "tests/layers.rs names '{name}', which is not in src/"
        );
    }
}

#[test]
fn no_module_uses_itself_through_others() {
    let graph = graph();
    // Depth-first search from each module for a path back to it.
    for start in graph.keys() {
        let mut stack: Vec<(String, Vec<String>)> = vec![(start.clone(), vec![start.clone()])];
        let mut seen = BTreeSet::new();
        while let Some((at, path)) = stack.pop() {
            for next in graph.get(&at).into_iter().flatten() {
                if next == start {
                    panic!("import cycle: {} -> {start}", path.join(" -> "));
                }
                if seen.insert(next.clone()) {
                    let mut p = path.clone();
                    p.push(next.clone());
                    stack.push((next.clone(), p));
                }
            }
        }
    }
}

#[test]
fn the_checker_sees_a_use() {
    let code = code_of("use crate::geometry::TriMesh;\n// crate::runner\nfn f() { crate::fit::x(); }\n#[cfg(test)]\nmod tests { use crate::synth; }");
    let found: Vec<String> = uses(&code).into_iter().collect();
    assert_eq!(found, ["fit", "geometry"]);
}
