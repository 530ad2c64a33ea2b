//! Issue 34 (the `cargo install` row): every place the README or the docs tell a user to install says `--locked`,
//! so the tools are built with the versions of `Cargo.lock` the tests ran with; and the README's two commands for a
//! fresh machine are still there.

use std::path::{Path, PathBuf};

/// README.md and every Markdown file under docs/.
fn documents() -> Vec<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut files = vec![root.join("README.md"), root.join("ARCHITECTURE.md")];
    let mut dirs = vec![root.join("docs")];
    while let Some(dir) = dirs.pop() {
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                dirs.push(path);
            } else if path.extension().is_some_and(|e| e == "md") {
                files.push(path);
            }
        }
    }
    files
}

/// The commands in `text` that start with `cargo install`: up to the end of the line or of the inline code span.
fn installs(text: &str) -> Vec<&str> {
    let mut found = Vec::new();
    for line in text.lines() {
        let mut rest = line;
        while let Some(at) = rest.find("cargo install") {
            let command = &rest[at..];
            let end = command.find('`').unwrap_or(command.len());
            found.push(&command[..end]);
            rest = &command["cargo install".len()..];
        }
    }
    found
}

#[test]
fn every_install_command_is_locked() {
    let mut seen = 0;
    for file in documents() {
        let text = std::fs::read_to_string(&file).unwrap();
        for command in installs(&text) {
            seen += 1;
            assert!(
                command.split_whitespace().any(|w| w == "--locked"),
                "{}: {command:?} without --locked builds versions the tests never ran",
                file.display()
            );
        }
    }
    assert!(seen >= 2, "the README's install commands were not found");
}

#[test]
fn the_readme_installs_the_workspace_locked_and_keeps_its_two_first_commands() {
    let readme =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("README.md")).unwrap();
    let blocks: Vec<&str> = readme
        .split("```sh\n")
        .skip(1)
        .map(|b| b.split("```").next().unwrap().trim())
        .collect();
    for command in [
        "cargo run --release",
        "cargo test --workspace",
        "cargo install --locked --path .",
    ] {
        assert!(
            blocks.contains(&command),
            "the README has no block of its own for {command:?}: {blocks:?}"
        );
    }
    // The build times are the ones measured on a 2-core machine (issue 34), not the older, shorter ones.
    assert!(
        readme.contains("about 9 minutes to build and 2.5 minutes to run"),
        "the README's test times"
    );
}

#[test]
fn an_install_without_locked_is_caught() {
    assert_eq!(
        installs("run `cargo install --path .` then `cargo install --locked x`"),
        ["cargo install --path .", "cargo install --locked x"]
    );
}
