//! `relevo check` and `relevo diff` on the sample region: a blessed record
//! passes, every kind of change (a DEM edited by 5 m over 2×2 cells, a
//! sample rectangle moved, the drape edited, the clusters rebaked with
//! another budget) is found, named and placed, each passes under a
//! tolerance that covers it, the JUnit report reads back with a JUnit
//! reader, and unusable inputs exit 2 leaving the record as it was.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use common::{burn, region_copy, relevo, relevo_ok, repo};
use std::path::{Path, PathBuf};
use std::process::Output;

fn prep(region: &Path, out: &Path) {
    relevo_ok([
        "prep".as_ref(),
        region.join("REGION.toml").as_os_str(),
        "--out".as_ref(),
        out.as_os_str(),
        "--force".as_ref(),
        "-q".as_ref(),
    ]);
}

/// `relevo check BUNDLE --golden RECORD EXTRA…`.
fn check(bundle: &Path, record: &Path, extra: &[&str]) -> Output {
    let mut args = vec![
        "check".to_string(),
        bundle.display().to_string(),
        "--golden".into(),
        record.display().to_string(),
    ];
    args.extend(extra.iter().map(|s| s.to_string()));
    relevo(&args)
}

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).to_string()
}

/// The line of `relevo check`'s text for `artifact`, and the lines under it.
fn finding(o: &Output, artifact: &str) -> String {
    let text = stdout(o);
    let mut lines = text
        .lines()
        .skip_while(|l| !l.contains(&format!(" {artifact}: ")));
    let first = lines
        .next()
        .unwrap_or_else(|| panic!("no {artifact} in:\n{text}"));
    std::iter::once(first)
        .chain(lines.take_while(|l| l.starts_with("        at ")))
        .collect::<Vec<_>>()
        .join("\n")
}

/// `picture` has the pixels of the reviewed one the guide shows (`docs`,
/// relative to the repository); `RELEVO_BLESS=1` replaces the reviewed one.
fn same_picture(picture: &Path, docs: &str) {
    let reference = repo(docs);
    if std::env::var_os("RELEVO_BLESS").is_some() {
        std::fs::copy(picture, &reference).unwrap();
    }
    let decode =
        |p: &Path| relevo_core::raster::png::decode_rgba(&std::fs::read(p).unwrap()).unwrap();
    let ((a, aw, ah), (b, bw, bh)) = (decode(picture), decode(&reference));
    assert_eq!((aw, ah), (bw, bh), "{docs}: size");
    let d = relevo_core::raster::compare::difference(&a, &b, 0).unwrap();
    assert_eq!(
        d.pixels_off,
        0,
        "{docs} differs from {} ({d:?})",
        picture.display()
    );
}

/// The sample region copied into a temporary folder, its bundle, and the
/// golden record blessed from it (checked to pass on a second prep).
struct Fixture {
    dir: tempfile::TempDir,
    region: PathBuf,
    base: PathBuf,
    record: PathBuf,
}

fn blessed_region() -> Fixture {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let region = region_copy(d);
    let (base, record) = (d.join("base.relevo"), d.join("golden/olinda.json"));
    std::fs::create_dir(d.join("golden")).unwrap();
    prep(&region, &base);
    let blessed = relevo_ok([
        "check".as_ref(),
        base.as_os_str(),
        "--golden".as_ref(),
        record.as_os_str(),
        "--bless".as_ref(),
    ]);
    assert!(blessed.contains("1 render(s)"), "{blessed}");
    assert!(d.join("golden/olinda.home.png").is_file());

    // The same inputs again: the same bundle, so the record passes.
    let again = d.join("again.relevo");
    prep(&region, &again);
    let o = check(&again, &record, &[]);
    assert_eq!(o.status.code(), Some(0), "{}", stdout(&o));
    assert!(!stdout(&o).contains("FAIL"));

    Fixture {
        region,
        base,
        record,
        dir,
    }
}

#[test]
fn a_dem_edited_by_5_m_is_found_to_the_vertex_and_passes_a_6_m_tolerance() {
    let Fixture {
        dir,
        region,
        base,
        record,
    } = blessed_region();
    let d = dir.path();
    // A DEM edited by +5 m over 2×2 cells at column 60, row 40.
    let dem = region.join("olinda_dem_utm25s.tif");
    let original_dem = std::fs::read(&dem).unwrap();
    burn(&dem, 32725, [60, 40, 2, 2], 5.0, None);
    let raised = d.join("raised.relevo");
    prep(&region, &raised);
    std::fs::write(&dem, &original_dem).unwrap();
    let o = check(
        &raised,
        &record,
        &["--junit", d.join("check.xml").to_str().unwrap()],
    );
    assert_eq!(o.status.code(), Some(1), "{}", stdout(&o));
    let height = finding(&o, "height");
    // The reference heights beside the record place it to the vertex (the
    // edit's four lie in one block, which names the first of them).
    assert!(
        height.starts_with("FAIL")
            && height.contains("4 of 16641 cells beyond tolerance, largest change 5.00")
            && height.contains("at column 60, row 40"),
        "{height}"
    );
    assert!(finding(&o, "mask").contains("unchanged"));
    assert!(finding(&o, "color").contains("unchanged"));
    // diff places it to the cell.
    let diff = relevo([
        "diff".as_ref(),
        base.as_os_str(),
        raised.as_os_str(),
        "--images".as_ref(),
        d.join("pictures").as_os_str(),
    ]);
    assert_eq!(diff.status.code(), Some(1));
    let text = stdout(&diff);
    assert!(
        text.contains("heights: 4 vertices changed, largest 5.000 m")
            && text.contains("(column 60, row 40): 30.000 → 35.000 m"),
        "{text}"
    );
    same_picture(
        &d.join("pictures/height_change.png"),
        "docs/images/diff_height_change.png",
    );
    // Within a 6 m tolerance (and the files derived from the heights skipped).
    let o = check(
        &raised,
        &record,
        &[
            "--height-m",
            "6",
            "--lp-error-m",
            "6",
            "--skip",
            "clusters*",
            "--skip",
            "height_geotiff",
        ],
    );
    assert_eq!(o.status.code(), Some(0), "{}", stdout(&o));
    assert!(finding(&o, "height").contains("within tolerance"));
    let o = check(
        &raised,
        &record,
        &[
            "--height-m",
            "4",
            "--lp-error-m",
            "6",
            "--skip",
            "clusters*",
            "--skip",
            "height_geotiff",
        ],
    );
    assert_eq!(
        o.status.code(),
        Some(1),
        "a 4 m tolerance lets a 5 m edit through"
    );

    // The JUnit report, read back by a JUnit reader.
    let xml = std::fs::read(d.join("check.xml")).unwrap();
    let suites = junit_parser::from_reader(std::io::Cursor::new(xml)).unwrap();
    let suite = &suites.suites[0];
    assert_eq!(suite.cases.len(), 18);
    let case = |name: &str| {
        let case = suite
            .cases
            .iter()
            .find(|c| c.original_name == name)
            .unwrap();
        assert_eq!(case.classname.as_deref(), Some("relevo.check.olinda"));
        case
    };
    assert!(case("height").status.is_failure());
    assert!(case("lp").status.is_failure());
    assert!(case("color").status.is_success());
    assert!(case("render:home").status.is_success());
    assert_eq!(
        suite.failures as usize,
        suite.cases.iter().filter(|c| c.status.is_failure()).count()
    );
}

#[test]
fn a_moved_sample_rectangle_changes_the_vegetation_and_is_placed() {
    let Fixture {
        dir,
        region,
        base,
        record,
    } = blessed_region();
    let d = dir.path();
    // A sample rectangle moved by 10 pixels.
    let samples = region.join("samples.csv");
    let original_samples = std::fs::read_to_string(&samples).unwrap();
    std::fs::write(
        &samples,
        original_samples.replace("forest;60;60;120;110", "forest;70;70;130;120"),
    )
    .unwrap();
    let moved = d.join("moved.relevo");
    prep(&region, &moved);
    std::fs::write(&samples, &original_samples).unwrap();
    let o = check(&moved, &record, &[]);
    assert_eq!(o.status.code(), Some(1));
    let vegetation = finding(&o, "vegetation");
    assert!(
        vegetation.contains("forest: 11764 →") && vegetation.contains("        at block"),
        "{vegetation}"
    );
    assert!(finding(&o, "height").contains("unchanged"));
    let loose = [
        "--vegetation-count",
        "100000",
        "--vegetation-position-m",
        "100000",
        "--skip",
        "clusters*",
        "--skip",
        "vegetation_*",
    ];
    assert_eq!(check(&moved, &record, &loose).status.code(), Some(0));
    let diff = stdout(&relevo([
        "diff".as_ref(),
        base.as_os_str(),
        moved.as_os_str(),
        "--images".as_ref(),
        d.join("pictures").as_os_str(),
    ]));
    same_picture(
        &d.join("pictures/vegetation_change.png"),
        "docs/images/diff_vegetation_change.png",
    );
    assert!(
        diff.contains("vegetation forest: 11764 →") && diff.contains("clusters: baked again"),
        "{diff}"
    );
}

#[test]
fn an_edited_drape_is_found_to_the_pixel() {
    let Fixture {
        dir,
        region,
        record,
        ..
    } = blessed_region();
    let d = dir.path();
    // The drape: Landsat's bands raised by 40 over 3×3 pixels.
    let image = region.join("L7_ETMs.tif");
    for band in 1..=3 {
        burn(&image, 32725, [150, 150, 3, 3], 40.0, Some(band));
    }
    let tinted = d.join("tinted.relevo");
    prep(&region, &tinted);
    let o = check(&tinted, &record, &[]);
    assert_eq!(o.status.code(), Some(1));
    let color = finding(&o, "color");
    assert!(
        color.starts_with("FAIL") && color.contains("at column 150, row 150"),
        "{color}"
    );
    let o = check(
        &tinted,
        &record,
        &[
            "--drape-levels",
            "200",
            "--skip",
            "clusters*",
            "--skip",
            "vegetation*",
            "--skip",
            "color_geotiff",
        ],
    );
    assert_eq!(o.status.code(), Some(0), "{}", stdout(&o));
}

#[test]
fn clusters_baked_with_another_budget_are_the_only_change() {
    let Fixture {
        dir, base, record, ..
    } = blessed_region();
    let d = dir.path();
    // The clusters baked again with a smaller atlas budget.
    let rebaked = d.join("rebaked.relevo");
    std::process::Command::new("cp")
        .args(["-a".as_ref(), base.as_os_str(), rebaked.as_os_str()])
        .status()
        .unwrap();
    relevo_ok([
        "bake".as_ref(),
        rebaked.as_os_str(),
        "--budget-mib".as_ref(),
        "16".as_ref(),
    ]);
    let o = check(&rebaked, &record, &[]);
    assert_eq!(o.status.code(), Some(1));
    let failed: Vec<String> = stdout(&o)
        .lines()
        .filter(|l| l.starts_with("FAIL"))
        .map(|l| {
            l.split(':')
                .next()
                .unwrap()
                .trim_start_matches("FAIL")
                .trim()
                .to_string()
        })
        .collect();
    assert!(
        !failed.is_empty() && failed.iter().all(|k| k.starts_with("clusters_")),
        "{failed:?}"
    );
}

#[test]
fn unusable_records_and_bundles_exit_2_and_a_failed_bless_keeps_the_record() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let bundle = common::sample_bundle(d);
    let record = d.join("olinda.json");
    relevo_ok([
        "check".as_ref(),
        bundle.as_os_str(),
        "--golden".as_ref(),
        record.as_os_str(),
        "--bless".as_ref(),
        "--no-renders".as_ref(),
    ]);
    let blessed = std::fs::read(&record).unwrap();
    let text = String::from_utf8(blessed.clone()).unwrap();
    let write = |name: &str, content: &str| {
        let p = d.join(name);
        std::fs::write(&p, content).unwrap();
        p
    };
    let cases = [
        (write("other.json", &text.replace("\"region\": \"olinda\"", "\"region\": \"grenoble\"")), "of region \"grenoble\""),
        (write("truncated.json", &text[..text.len() / 2]), "not a golden record"),
        (write("future.json", &text.replace("\"format_version\": 1", "\"format_version\": 9")), "format version 9"),
        (
            write("extra.json", &text.replacen("\"artifacts\": {", "\"artifacts\": {\n    \"dem_contours\": {\"file\": \"exports/contours.gpkg\", \"bytes\": 1, \"sha256\": \"00\"},", 1)),
            "has no artifact \"dem_contours\"",
        ),
        (
            write("rows.json", &{
                let mut v: serde_json::Value = serde_json::from_str(&text).unwrap();
                let row = &mut v["artifacts"]["height"]["blocks"]["hashes"][0];
                *row = format!("zz {}", row.as_str().unwrap()).into();
                v.to_string()
            }),
            "expected 26 blocks",
        ),
    ];
    for (path, needle) in &cases {
        let o = check(
            &bundle,
            path,
            &["--junit", d.join("j.xml").to_str().unwrap()],
        );
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{}: {stderr}", path.display());
        assert!(
            stderr.contains(needle) && !stderr.contains("panicked"),
            "{}: {stderr}",
            path.display()
        );
        assert!(
            !d.join("j.xml").exists(),
            "a report was written for an unusable input"
        );
    }
    // A bless that fails (its render over the memory budget) leaves the
    // old record as it was, and no render beside it.
    let o = relevo([
        "check".as_ref(),
        bundle.as_os_str(),
        "--golden".as_ref(),
        record.as_os_str(),
        "--bless".as_ref(),
        "--render-size".as_ref(),
        "16384x16384".as_ref(),
        "--max-memory".as_ref(),
        "64M".as_ref(),
    ]);
    assert_eq!(
        o.status.code(),
        Some(2),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert_eq!(std::fs::read(&record).unwrap(), blessed);
    assert!(!d.join("olinda.home.png").exists());
}
