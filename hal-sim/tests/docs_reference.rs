//! The guide's reference pages (`docs/src/reference/`) are what the code renders
//! (`hal_sim::docs`): the CLI from the `piezo` binary's own clap definition, the settings
//! table, the controller registry, the serial commands and the error codes. A page that
//! differs fails here; `UPDATE_DOCS=1 cargo test -p hal-sim --test docs_reference` rewrites
//! them.

// The binary's source, for its `Cli` (the subcommands other modules add come along).
#[allow(dead_code)]
#[path = "../src/bin/piezo.rs"]
mod piezo_bin;

use clap::CommandFactory;
use std::path::{Path, PathBuf};

fn book_src() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/src")
}

#[test]
fn reference_pages_match_the_code() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let command_rs = std::fs::read_to_string(root.join("src/command.rs")).unwrap();
    let pages = hal_sim::docs::pages(&piezo_bin::Cli::command(), &command_rs).unwrap();
    let update = std::env::var_os("UPDATE_DOCS").is_some_and(|v| v == "1");
    let mut stale = Vec::new();
    for p in &pages {
        let path = book_src().join(p.path);
        let old = std::fs::read_to_string(&path).unwrap_or_default();
        if old == p.text {
            continue;
        }
        if update {
            std::fs::create_dir_all(path.parent().unwrap()).unwrap();
            std::fs::write(&path, &p.text).unwrap();
            eprintln!("rewrote docs/src/{}", p.path);
        } else {
            let line = old
                .lines()
                .zip(p.text.lines())
                .position(|(a, b)| a != b)
                .unwrap_or(old.lines().count().min(p.text.lines().count()));
            stale.push(format!(
                "docs/src/{} differs from the code from line {}:\n  committed: {:?}\n  rendered:  {:?}",
                p.path,
                line + 1,
                old.lines().nth(line).unwrap_or("<end of file>"),
                p.text.lines().nth(line).unwrap_or("<end of file>"),
            ));
        }
    }
    assert!(
        stale.is_empty(),
        "{}\n\nThe reference pages are generated from the code; regenerate them with\n  {}\nand commit the result.",
        stale.join("\n"),
        hal_sim::docs::REGENERATE
    );
}

#[test]
fn every_subcommand_is_in_the_cli_page() {
    let cli = piezo_bin::Cli::command();
    let page = hal_sim::docs::cli_page(&cli);
    for s in cli.get_subcommands() {
        assert!(
            page.contains(&format!("## `piezo {}`", s.get_name())),
            "{} missing",
            s.get_name()
        );
    }
}
