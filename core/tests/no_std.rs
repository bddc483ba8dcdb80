//! The core is `no_std` without `alloc`: no source file of `core/src` brings `std` or `alloc`
//! back, so nothing in the step can allocate or do I/O. (The allocation counter in
//! `alloc_free.rs` checks the same at run time, for the paths it drives.)

use std::path::Path;

/// Every `.rs` file under `dir`, with its text.
fn sources(dir: &Path, out: &mut Vec<(String, String)>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            sources(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            let text = std::fs::read_to_string(&path).unwrap();
            out.push((path.display().to_string(), text));
        }
    }
}

/// The code of `text` without line comments, so a doc comment may name what the code may not.
fn code(text: &str) -> String {
    text.lines()
        .map(|l| l.split("//").next().unwrap_or(""))
        .collect::<Vec<_>>()
        .join("\n")
}

#[test]
fn the_core_is_no_std_without_alloc() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let lib = std::fs::read_to_string(src.join("lib.rs")).unwrap();
    assert!(
        lib.lines().any(|l| l.trim() == "#![no_std]"),
        "core/src/lib.rs lost #![no_std]"
    );
    let mut files = Vec::new();
    sources(&src, &mut files);
    assert!(files.len() >= 10, "{} source files", files.len());
    for (path, text) in &files {
        let code = code(text);
        for banned in ["extern crate std", "extern crate alloc", "std::", "alloc::"] {
            let found = code
                .match_indices(banned)
                .any(|(i, _)| !code[..i].ends_with(|c: char| c.is_alphanumeric() || c == '_'));
            assert!(!found, "{path} uses `{banned}`");
        }
    }
}
