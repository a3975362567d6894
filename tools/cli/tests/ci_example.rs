//! The CI example of docs/guide.md ("Testing your region in CI") run as
//! written: the `relevo` lines of its bless block, then those of its
//! GitHub Actions job (the GitLab job must hold the same ones), on a copy
//! of the sample region. Unchanged inputs pass; a DEM edited by 5 m over
//! 2 × 2 cells fails with `height` and the vertex named; restored, it
//! passes again. So the example cannot rot.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use common::repo;
use std::path::Path;
use std::process::{Command, Output};

/// The commands of the block after `<!-- ci-example:NAME -->` in the guide
/// that run `mkdir` or `relevo` (YAML `run:` and list items unwrapped).
fn commands(guide: &str, name: &str) -> Vec<String> {
    let marker = format!("<!-- ci-example:{name} -->");
    let start = guide
        .find(&marker)
        .unwrap_or_else(|| panic!("no {marker} in the guide"));
    let block = guide[start..].split("```").nth(1).unwrap();
    block
        .lines()
        .map(|l| {
            l.trim()
                .trim_start_matches("- ")
                .trim_start_matches("run: ")
                .trim()
                .to_string()
        })
        .filter(|l| l.starts_with("relevo ") || l.starts_with("mkdir "))
        .collect()
}

/// Run `line` with bash in `dir`, `relevo` being this build's.
fn run(dir: &Path, line: &str) -> Output {
    let bin = Path::new(env!("CARGO_BIN_EXE_relevo")).parent().unwrap();
    let path = format!(
        "{}:{}",
        bin.display(),
        std::env::var("PATH").unwrap_or_default()
    );
    Command::new("bash")
        .args(["-c", line])
        .current_dir(dir)
        .env("PATH", path)
        .output()
        .unwrap()
}

/// The CI job's commands in `dir`: the exit status of the last one
/// (`relevo check`) and its output.
fn ci_job(dir: &Path, job: &[String]) -> Output {
    let (last, before) = job.split_last().unwrap();
    for line in before {
        let o = run(dir, line);
        assert!(
            o.status.success(),
            "{line}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
    }
    run(dir, last)
}

#[test]
fn the_guides_ci_example_passes_unchanged_inputs_and_names_an_edit() {
    let guide = std::fs::read_to_string(repo("docs/guide.md")).unwrap();
    let bless = commands(&guide, "bless");
    let github = commands(&guide, "github");
    let gitlab = commands(&guide, "gitlab");
    assert_eq!(
        github, gitlab,
        "the GitHub and GitLab jobs run different commands"
    );
    assert!(github.last().unwrap().starts_with("relevo check ") && bless.len() >= 3);

    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    common::region_copy(d);
    for line in &bless {
        let o = run(d, line);
        assert!(
            o.status.success(),
            "{line}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
    }
    let o = ci_job(d, &github);
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stdout)
    );
    assert!(d.join("relevo-check.xml").is_file() && d.join("relevo-check.md").is_file());

    // A DEM edited by +5 m over the 2×2 cells from column 60, row 40.
    let dem = d.join("region/olinda_dem_utm25s.tif");
    let original = std::fs::read(&dem).unwrap();
    common::burn(&dem, 32725, [60, 40, 2, 2], 5.0, None);
    let o = ci_job(d, &github);
    let report = String::from_utf8_lossy(&o.stdout);
    assert_eq!(o.status.code(), Some(1), "{report}");
    assert!(
        report.contains("FAIL  height: CHANGED — 4 of 16641 cells beyond tolerance")
            && report.contains("at column 60, row 40"),
        "{report}"
    );
    let markdown = std::fs::read_to_string(d.join("relevo-check.md")).unwrap();
    assert!(markdown.contains("| `height` | CHANGED |") && markdown.contains("column 60, row 40"));

    std::fs::write(&dem, original).unwrap();
    let o = ci_job(d, &github);
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stdout)
    );
}
