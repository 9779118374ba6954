//! The repository's maps stay true: docs/STRUCTURE.md names every module of every crate and
//! of the training package, and the copies in docs/reference/ of what the project's shared
//! folder fixes (the design contracts, the architecture) are the shared folder's text,
//! where that folder sits beside the checkout (CI has it; a lone clone reads the copies).

use std::fs;
use std::path::{Path, PathBuf};

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// The map's sections: heading prefix -> the folder whose modules it lists.
const SECTIONS: [(&str, &str); 4] = [
    ("## `color/`", "color/src"),
    ("## `src/`", "src"),
    ("## `render/`", "render/src"),
    ("## `training/temc_train/`", "training/temc_train"),
];

/// Files that are a folder's entry, not a module of their own.
const ENTRY_FILES: [&str; 4] = ["mod.rs", "lib.rs", "main.rs", "__init__.py"];

/// The text of the section that starts with `heading`, up to the next `## `.
fn section<'a>(map: &'a str, heading: &str) -> &'a str {
    let start = map
        .find(heading)
        .unwrap_or_else(|| panic!("docs/STRUCTURE.md has no section {heading:?}"));
    let body = &map[start + heading.len()..];
    &body[..body.find("\n## ").unwrap_or(body.len())]
}

/// Whether `word` occurs in `text` with no identifier character on either side.
fn names_word(text: &str, word: &str) -> bool {
    let ident = |c: char| c.is_ascii_alphanumeric() || c == '_' || c == '-';
    text.match_indices(word).any(|(i, _)| {
        let before = text[..i].chars().next_back();
        let after = text[i + word.len()..].chars().next();
        !before.is_some_and(ident) && !after.is_some_and(ident)
    })
}

/// Every module (file stem) and folder under `dir`, as paths relative to it.
fn modules(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in fs::read_dir(&d).unwrap().map(Result::unwrap) {
            let path = entry.path();
            let name = entry.file_name().to_string_lossy().into_owned();
            if path.is_dir() && name != "__pycache__" {
                out.push(path.clone());
                stack.push(path);
            } else if (name.ends_with(".rs") || name.ends_with(".py"))
                && !ENTRY_FILES.contains(&name.as_str())
            {
                out.push(path);
            }
        }
    }
    out.into_iter()
        .map(|p| p.strip_prefix(dir).unwrap().to_path_buf())
        .collect()
}

#[test]
fn the_structure_map_names_every_module() {
    let map = fs::read_to_string(root().join("docs/STRUCTURE.md")).unwrap();
    let mut missing = Vec::new();
    for (heading, dir) in SECTIONS {
        let text = section(&map, heading);
        for module in modules(&root().join(dir)) {
            let stem = module.file_stem().unwrap().to_string_lossy();
            if !names_word(text, &stem) {
                missing.push(format!("{dir}/{}", module.display()));
            }
        }
    }
    assert!(
        missing.is_empty(),
        "docs/STRUCTURE.md does not name these modules in their section: {missing:?}"
    );
}

#[test]
fn the_word_check_needs_whole_names() {
    assert!(names_word("| `keep_mean.rs` | ...", "keep_mean"));
    assert!(!names_word("| `keep_mean_probe.py` |", "keep_mean"));
    assert!(!names_word("| `reconstruction` |", "reconstruct"));
}

/// docs/reference/NAME -> the shared folder's file it copies.
const COPIES: [(&str, &str); 2] = [
    ("DESIGN.md", "DESIGN.md"),
    ("temc-architecture.md", "reference/temc-architecture.md"),
];

#[test]
fn reference_copies_match_the_shared_folder() {
    let shared = root().join("../shared");
    for (copy, original) in COPIES {
        let ours = fs::read_to_string(root().join("docs/reference").join(copy))
            .unwrap_or_else(|e| panic!("docs/reference/{copy}: {e}"));
        let Ok(theirs) = fs::read_to_string(shared.join(original)) else {
            eprintln!("no ../shared/{original} beside the checkout: the copy stands alone");
            continue;
        };
        assert!(
            ours == theirs,
            "docs/reference/{copy} differs from ../shared/{original}: copy it again"
        );
    }
}
