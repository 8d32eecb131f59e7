//! Every library crate is a package of its own: both licence files (the root's, byte for
//! byte), a README its manifest names, and a README example that is the crate's front-page
//! doc example (so the doctests run what a reader of crates.io sees).

use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The library crates (the Python crate is built by maturin, not published).
fn packages() -> Vec<PathBuf> {
    let mut dirs: Vec<PathBuf> = std::fs::read_dir(root().join("crates"))
        .expect("crates/")
        .map(|e| e.expect("entry").path())
        .filter(|p| !p.ends_with("streamcert-python"))
        .collect();
    dirs.sort();
    dirs
}

/// The first fenced Rust block of `text` (fence ```` ```rust ````, ```` ```no_run ```` or a
/// bare ```` ``` ````), without rustdoc's hidden lines.
fn rust_block(text: &str) -> Option<Vec<String>> {
    let mut open: Option<(String, Vec<String>)> = None;
    for line in text.lines() {
        match (&mut open, line.strip_prefix("```")) {
            (None, Some(lang)) => open = Some((lang.to_string(), Vec::new())),
            (Some((lang, body)), Some("")) => {
                if lang.is_empty() || lang == "rust" || lang == "no_run" {
                    return Some(std::mem::take(body));
                }
                open = None;
            }
            (Some((_, body)), _) => {
                if !line.starts_with("# ") && line != "#" {
                    body.push(line.to_string());
                }
            }
            (None, None) => {}
        }
    }
    None
}

/// The crate docs of `lib.rs` (its `//!` lines), as text.
fn crate_docs(lib: &Path) -> String {
    let text = std::fs::read_to_string(lib).expect("lib.rs");
    let lines = text.lines().map_while(|l| {
        l.strip_prefix("//! ").or_else(|| (l == "//!").then_some("")).map(String::from)
    });
    lines.collect::<Vec<_>>().join("\n")
}

#[test]
fn every_package_holds_both_licences_and_its_readme() {
    let mit = std::fs::read(root().join("LICENSE-MIT")).expect("root LICENSE-MIT");
    let apache = std::fs::read(root().join("LICENSE-APACHE")).expect("root LICENSE-APACHE");
    let dirs = packages();
    assert!(dirs.len() >= 12, "{dirs:?}");
    for dir in dirs {
        let name = dir.display();
        assert_eq!(std::fs::read(dir.join("LICENSE-MIT")).ok().as_ref(), Some(&mit), "{name}");
        assert_eq!(
            std::fs::read(dir.join("LICENSE-APACHE")).ok().as_ref(),
            Some(&apache),
            "{name}"
        );
        let manifest = std::fs::read_to_string(dir.join("Cargo.toml")).expect("manifest");
        assert!(manifest.contains("readme = \"README.md\""), "{name}: no readme");
        let readme = std::fs::read_to_string(dir.join("README.md")).expect("README.md");
        assert!(readme.contains("MIT OR Apache-2.0"), "{name}: no licence line");
    }
}

#[test]
fn every_readme_example_is_the_crates_doctested_front_page_example() {
    let mut checked = 0;
    for dir in packages() {
        let readme = std::fs::read_to_string(dir.join("README.md")).expect("README.md");
        let Some(example) = rust_block(&readme) else { continue };
        let docs = crate_docs(&dir.join("src/lib.rs"));
        let doc = rust_block(&docs).unwrap_or_else(|| panic!("{}: no doc example", dir.display()));
        assert_eq!(example, doc, "{}: README and front page differ", dir.display());
        checked += 1;
    }
    assert!(checked >= 8, "{checked} crates with a Rust example");
}
