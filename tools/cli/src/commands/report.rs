//! The reports `relevo check` writes for CI systems: JUnit XML (one test
//! case per artifact and render; GitHub, GitLab and Jenkins show it),
//! Markdown (a pull-request comment or a job summary) and plain text.

use relevo_core::golden::{CheckReport, Finding, Outcome, Place};
use std::fmt::Write;

/// One place in words: the block, its cells and its extent in the CRS.
pub fn place_words(p: &Place) -> String {
    let [c0, r0, c1, r1] = p.cells;
    let [w, s, e, n] = p.bounds;
    if c1 == c0 + 1 && r1 == r0 + 1 {
        return format!(
            "column {c0}, row {r0} (E {:.1}, N {:.1}): {}",
            (w + e) / 2.0,
            (s + n) / 2.0,
            p.what
        );
    }
    format!(
        "block ({}, {}): columns {c0}–{}, rows {r0}–{}, E {w:.1}–{e:.1}, N {s:.1}–{n:.1}: {}",
        p.block[0],
        p.block[1],
        c1.saturating_sub(1),
        r1.saturating_sub(1),
        p.what
    )
}

fn verdict(f: &Finding) -> &'static str {
    match f.outcome {
        Outcome::Unchanged => "unchanged",
        Outcome::WithinTolerance => "within tolerance",
        Outcome::Changed => "CHANGED",
        Outcome::Skipped => "skipped",
    }
}

/// The report as text, a line per artifact and a line per place.
pub fn text(report: &CheckReport) -> String {
    let mut out = String::new();
    for f in &report.findings {
        let _ = writeln!(
            out,
            "{:<5} {}: {} — {} (tolerance: {})",
            if f.outcome == Outcome::Changed {
                "FAIL"
            } else {
                "ok"
            },
            f.artifact,
            verdict(f),
            f.figure,
            f.tolerance
        );
        for p in &f.places {
            let _ = writeln!(out, "        at {}", place_words(p));
        }
    }
    out
}

/// Escape `text` for XML attributes and text.
fn xml(text: &str) -> String {
    text.chars()
        .filter(|&c| c == '\n' || c == '\t' || c >= ' ')
        .fold(String::new(), |mut s, c| {
            match c {
                '&' => s.push_str("&amp;"),
                '<' => s.push_str("&lt;"),
                '>' => s.push_str("&gt;"),
                '"' => s.push_str("&quot;"),
                '\'' => s.push_str("&apos;"),
                c => s.push(c),
            }
            s
        })
}

/// The report as JUnit XML: a suite named after the region, a test case
/// per artifact and render, a `<failure>` with the figures for each change
/// beyond tolerance.
pub fn junit(report: &CheckReport, bundle: &str) -> String {
    let failures = report
        .findings
        .iter()
        .filter(|f| f.outcome == Outcome::Changed)
        .count();
    let tests = report.findings.len();
    let skipped = report
        .findings
        .iter()
        .filter(|f| f.outcome == Outcome::Skipped)
        .count();
    let suite = format!("relevo check {}", report.region);
    let mut out = String::new();
    let _ = writeln!(out, r#"<?xml version="1.0" encoding="UTF-8"?>"#);
    let _ = writeln!(
        out,
        r#"<testsuites name="relevo check" tests="{tests}" failures="{failures}" errors="0">"#
    );
    let _ = writeln!(
        out,
        r#"  <testsuite name="{}" tests="{tests}" failures="{failures}" errors="0" skipped="{skipped}">"#,
        xml(&suite)
    );
    let _ = writeln!(
        out,
        r#"    <properties><property name="bundle" value="{}"/></properties>"#,
        xml(bundle)
    );
    for f in &report.findings {
        let _ = write!(
            out,
            r#"    <testcase classname="{}" name="{}" time="0""#,
            xml(&format!("relevo.check.{}", report.region)),
            xml(&f.artifact)
        );
        if f.outcome == Outcome::Changed {
            let mut body = format!("{}\ntolerance: {}\n", f.figure, f.tolerance);
            for p in &f.places {
                let _ = writeln!(body, "at {}", place_words(p));
            }
            let _ = writeln!(out, ">");
            let _ = writeln!(
                out,
                r#"      <failure message="{}" type="changed">{}</failure>"#,
                xml(&format!(
                    "{}: {} (tolerance: {})",
                    f.artifact, f.figure, f.tolerance
                )),
                xml(&body)
            );
            let _ = writeln!(out, "    </testcase>");
        } else if f.outcome == Outcome::Skipped {
            let _ = writeln!(out, ">");
            let _ = writeln!(out, r#"      <skipped message="--skip"/>"#);
            let _ = writeln!(out, "    </testcase>");
        } else {
            let _ = writeln!(out, ">");
            let _ = writeln!(
                out,
                "      <system-out>{}</system-out>",
                xml(&format!("{}: {}", verdict(f), f.figure))
            );
            let _ = writeln!(out, "    </testcase>");
        }
    }
    let _ = writeln!(out, "  </testsuite>");
    let _ = writeln!(out, "</testsuites>");
    out
}

/// Escape a Markdown table cell.
fn cell(text: &str) -> String {
    text.replace('|', "\\|").replace('\n', " ")
}

/// The report as Markdown: a headline and a table, places under it.
pub fn markdown(report: &CheckReport, bundle: &str) -> String {
    let failures: Vec<&Finding> = report
        .findings
        .iter()
        .filter(|f| f.outcome == Outcome::Changed)
        .collect();
    let mut out = String::new();
    let _ = writeln!(
        out,
        "### relevo check — region `{}`: {}\n",
        report.region,
        if failures.is_empty() {
            "every artifact within tolerance ✅".to_string()
        } else {
            format!("{} artifact(s) changed beyond tolerance ❌", failures.len())
        }
    );
    let _ = writeln!(out, "Bundle `{bundle}`.\n");
    let _ = writeln!(out, "| artifact | result | figure | tolerance |");
    let _ = writeln!(out, "|---|---|---|---|");
    for f in &report.findings {
        let _ = writeln!(
            out,
            "| `{}` | {} | {} | {} |",
            f.artifact,
            verdict(f),
            cell(&f.figure),
            cell(&f.tolerance)
        );
    }
    for f in failures.iter().filter(|f| !f.places.is_empty()) {
        let _ = writeln!(out, "\n**`{}`** changed at:\n", f.artifact);
        for p in &f.places {
            let _ = writeln!(out, "- {}", place_words(p));
        }
    }
    out
}
