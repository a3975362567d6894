//! Several writers on one bundle at once — `bake`, `prep --force`, `prep`
//! into a path that does not exist yet — started together or staggered so
//! that they overlap at different stages. Whatever the interleaving, one
//! valid bundle remains, nothing the writers did not replace is lost, and
//! every exit code is honest: 0 for a run whose result is in place, non-zero
//! with the holder named for a run that was refused.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use common::{listing, relevo_ok, repo, sample_bundle, sha256};
use std::collections::BTreeMap;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::Duration;

/// Writers started per round.
const WRITERS: usize = 4;

/// How one writer ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Outcome {
    /// Exit 0: its result is the bundle, or was until a later writer's.
    Written,
    /// Refused at once because another writer held the bundle.
    RefusedLocked,
    /// `prep` without `--force` refused because the bundle existed (or
    /// appeared while it ran).
    RefusedExisting,
}

/// Start `WRITERS` commands, the k-th after `k * stagger`, and sort how
/// each ended; any other failure fails the test with its message.
fn run_together(commands: &[Vec<String>], stagger: Duration) -> Vec<Outcome> {
    let children: Vec<Child> = commands
        .iter()
        .map(|args| {
            std::thread::sleep(stagger);
            Command::new(env!("CARGO_BIN_EXE_relevo"))
                .args(args)
                .stdout(Stdio::null())
                .stderr(Stdio::piped())
                .spawn()
                .unwrap()
        })
        .collect();
    children
        .into_iter()
        .zip(commands)
        .map(|(child, args)| {
            let out = child.wait_with_output().unwrap();
            let stderr = String::from_utf8_lossy(&out.stderr);
            if out.status.success() {
                Outcome::Written
            } else if stderr.contains("is being written by another command (") {
                // "(pid …)", or, in the instant before the holder records
                // itself, "(its holder has not yet said who it is)".
                Outcome::RefusedLocked
            } else if stderr.contains("already exists") || stderr.contains("appeared while") {
                Outcome::RefusedExisting
            } else {
                panic!("{args:?} failed for another reason: {stderr}");
            }
        })
        .collect()
}

/// The bundle's terrain and vegetation files with their hashes: what a
/// re-bake must never lose or change.
fn terrain_files(bundle: &Path) -> BTreeMap<String, String> {
    [
        "height.f32",
        "mask.u8",
        "lp.f32x2",
        "color.rgba8",
        "vegetation.csv",
        "vegetation_samples.csv",
    ]
    .into_iter()
    .map(|name| (name.to_string(), sha256(&bundle.join(name))))
    .collect()
}

fn strings(args: &[&str]) -> Vec<String> {
    args.iter().map(|s| s.to_string()).collect()
}

#[test]
fn simultaneous_bakes_and_forced_preps_leave_one_valid_bundle_and_lose_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let bundle = sample_bundle(dir.path());
    let path = bundle.to_str().unwrap();
    let region = repo("data/olinda/REGION.toml");
    let region = region.to_str().unwrap();
    std::fs::write(bundle.join("notes.txt"), "the user's own file").unwrap();
    let terrain = terrain_files(&bundle);
    let writers = [
        strings(&["bake", path]),
        strings(&["bake", "--bands", "400:2,1600:8", path]),
        strings(&["prep", region, "--out", path, "--force"]),
        strings(&["bake", "--bands", "300:1,1200:4", path]),
    ];
    let mut tally: BTreeMap<Outcome, usize> = BTreeMap::new();
    // From all at once to one after another (a bake takes about a second).
    for round in 0..8u64 {
        let outcomes = run_together(&writers[..WRITERS], Duration::from_millis(round * 150));
        assert!(
            outcomes.contains(&Outcome::Written),
            "round {round}: no writer succeeded: {outcomes:?}"
        );
        assert!(!outcomes.contains(&Outcome::RefusedExisting));
        for o in outcomes {
            *tally.entry(o).or_default() += 1;
        }
        relevo_ok(["validate", path]);
        assert_eq!(terrain_files(&bundle), terrain, "round {round}");
        assert_eq!(
            std::fs::read_to_string(bundle.join("notes.txt")).unwrap(),
            "the user's own file",
            "round {round}"
        );
        assert_eq!(listing(dir.path()), ["olinda.relevo"], "round {round}");
    }
    eprintln!("bake/prep --force, 8 rounds x {WRITERS} writers: {tally:?}");
}

#[test]
fn simultaneous_preps_without_force_make_exactly_one_bundle() {
    let dir = tempfile::tempdir().unwrap();
    let region = repo("data/olinda/REGION.toml");
    let mut tally: BTreeMap<Outcome, usize> = BTreeMap::new();
    for round in 0..6u64 {
        let out = dir.path().join(format!("round{round}.relevo"));
        let prep = strings(&[
            "prep",
            region.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]);
        let commands = vec![prep; WRITERS];
        // From all at once to one after another (a prep takes about a second).
        let outcomes = run_together(&commands, Duration::from_millis(round * 150));
        let written = outcomes.iter().filter(|&&o| o == Outcome::Written).count();
        assert_eq!(written, 1, "round {round}: {outcomes:?}");
        for o in outcomes {
            *tally.entry(o).or_default() += 1;
        }
        relevo_ok(["validate", out.to_str().unwrap()]);
    }
    let expected: Vec<String> = (0..6).map(|r| format!("round{r}.relevo")).collect();
    assert_eq!(listing(dir.path()), expected);
    eprintln!("prep without --force, 6 rounds x {WRITERS} writers: {tally:?}");
}

#[test]
fn a_bundle_that_appears_while_prep_runs_is_never_replaced() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("olinda.relevo");
    let region = repo("data/olinda/REGION.toml");
    let prep = Command::new(env!("CARGO_BIN_EXE_relevo"))
        .args([
            "prep".as_ref(),
            region.as_os_str(),
            "--out".as_ref(),
            out.as_os_str(),
        ])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Another program (a copy, a sync) puts a folder there meanwhile.
    std::thread::sleep(Duration::from_millis(300));
    std::fs::create_dir(&out).unwrap();
    std::fs::write(out.join("theirs.txt"), "not Relevo's").unwrap();
    let ended = prep.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&ended.stderr);
    assert!(!ended.status.success());
    assert!(
        stderr.contains("appeared while this command ran") || stderr.contains("already exists"),
        "{stderr}"
    );
    assert_eq!(listing(&out), ["theirs.txt"]);
    assert_eq!(listing(dir.path()), ["olinda.relevo"]);
}
