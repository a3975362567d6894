//! `relevo prep --tiled` on the real Grenoble DEM (Copernicus, 1025² grid):
//! every level-0 vertex holds the single grid's heights, mask, errors and
//! radii bit for bit at any tile size, the mesh through the tiles is the
//! single grid's byte for byte (a window's, triangle for triangle), its
//! raycast reads coarser levels farther away and equals the single grid's
//! on level 0, a projected DEM is read window by window to the same
//! pyramid in a budget its grid exceeds, a killed build resumes to the
//! same bytes, the files match their golden hashes, and tampered pyramids
//! are refused by name. On the real Olinda region (SRTM, Landsat 7 and a
//! person's samples), a pyramid holds the single grid's vegetation and
//! clusters byte for byte.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use common::{
    grenoble_dem, khronos_validate, projected_dem, projected_dem_named, relevo, relevo_ok, repo,
    set_cells, sha256,
};
use relevo_core::bundle::Bundle;
use relevo_core::lp::window::Rect;
use relevo_core::pyramid::Pyramid;
use std::path::{Path, PathBuf};

/// `relevo prep --dem DEM --tiled --tile-size T EXTRA… --out DIR/NAME`.
fn tiled(dir: &Path, name: &str, tile: usize, extra: &[&str]) -> PathBuf {
    let out = dir.join(name);
    let mut args = vec![
        "prep".to_string(),
        "--dem".into(),
        grenoble_dem().display().to_string(),
        "--tiled".into(),
        "--tile-size".into(),
        tile.to_string(),
        "--out".into(),
        out.display().to_string(),
        "-q".into(),
    ];
    args.extend(extra.iter().map(|s| s.to_string()));
    relevo_ok(&args);
    out
}

fn tile_files(p: &Path) -> Vec<String> {
    ["height.f32", "mask.u8", "lp.f32x2", "drape.rgba8"]
        .iter()
        .map(|f| sha256(&p.join("tiles").join(f)))
        .collect()
}

/// `relevo prep --dem DEM --terrain-drape --out DIR/single.relevo`.
fn single_grid(dir: &Path, dem: &Path) -> PathBuf {
    let single = dir.join("single.relevo");
    relevo_ok([
        "prep".as_ref(),
        "--dem".as_ref(),
        dem.as_os_str(),
        "--terrain-drape".as_ref(),
        "--out".as_ref(),
        single.as_os_str(),
        "-q".as_ref(),
    ]);
    single
}

/// Every level-0 vertex of `pyramid` holds the single grid's heights, mask,
/// errors, radii and drape bit for bit, and the mesh through its tiles is
/// the single grid's byte for byte.
fn assert_same_as_single(single: &Path, pyramid: &Path, label: &str) {
    relevo_ok(["validate".as_ref(), pyramid.as_os_str()]);
    let bundle = Bundle::open(single).unwrap();
    let (heights, mask, lp) = (
        bundle.heights().unwrap(),
        bundle.mask().unwrap(),
        bundle.lp().unwrap(),
    );
    let h = lp.hierarchy();
    let drape = bundle.drape().unwrap().unwrap();
    let p = Pyramid::open(pyramid).unwrap();
    let w = p.level0_window(Rect::whole(p.layout.side)).unwrap();
    assert!(
        w.heights
            .iter()
            .zip(heights.iter())
            .all(|(a, b)| a.to_bits() == b.to_bits()),
        "{label}: heights"
    );
    assert!(w.mask[..] == mask[..], "{label}: mask");
    let differing =
        w.lp.iter()
            .zip(h.error_radius.iter())
            .filter(|(a, b)| a.map(f32::to_bits) != b.map(f32::to_bits))
            .count();
    assert_eq!(
        differing, 0,
        "{label}: {differing} vertices' errors or radii differ"
    );
    assert!(w.drape[..] == drape.rgba[..], "{label}: drape");
    // The mesh through the tiles, byte for byte the single grid's.
    let dir = pyramid.parent().unwrap();
    let (a, b) = (
        dir.join(format!("{label}.glb")),
        dir.join(format!("{label}.single.glb")),
    );
    for (bundle, out) in [(pyramid, &a), (single, &b)] {
        relevo_ok([
            "mesh".as_ref(),
            bundle.as_os_str(),
            "--max-error".as_ref(),
            "5".as_ref(),
            "--out".as_ref(),
            out.as_os_str(),
            "--force".as_ref(),
        ]);
    }
    assert_eq!(
        std::fs::read(&a).unwrap(),
        std::fs::read(&b).unwrap(),
        "{label}: meshes differ"
    );
}

#[test]
fn the_pyramid_holds_the_single_grid_at_any_tile_size_and_meshes_the_same() {
    let d = tempfile::tempdir().unwrap();
    let single = single_grid(d.path(), &grenoble_dem());
    for tile in [32, 128] {
        let p = tiled(d.path(), &format!("t{tile}.relevo"), tile, &[]);
        assert_same_as_single(&single, &p, &format!("t{tile}"));
    }
    // Golden hashes of the 64-cell pyramid's files.
    let p = tiled(d.path(), "t64.relevo", 64, &[]);
    let golden: Vec<String> = serde_json::from_str(
        &std::fs::read_to_string(repo("data/golden/grenoble_pyramid.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(tile_files(&p), golden, "data/golden/grenoble_pyramid.json");
}

/// `relevo mesh --window` through a pyramid of small tiles gives the
/// single grid's window mesh vertex for vertex and triangle for triangle
/// (the textures come from different crops), as valid glTF; a window off
/// the grid and a budget the mesh exceeds are refused by name.
#[test]
fn a_window_of_the_pyramid_meshes_as_the_single_grids_window() {
    let d = tempfile::tempdir().unwrap();
    let single = single_grid(d.path(), &grenoble_dem());
    let pyramid = tiled(d.path(), "t32.relevo", 32, &[]);
    let frame = Bundle::open(&single).unwrap().frame();
    // Corners between vertices, across several tiles' borders.
    let (x0, y0) = frame.world_from_vertex(300.3, 505.6);
    let (x1, y1) = frame.world_from_vertex(610.2, 200.1);
    let window = format!("{x0},{y0},{x1},{y1}");
    let mesh = |bundle: &Path, out: &Path, extra: &[&str]| {
        let mut args = vec![
            "mesh",
            bundle.to_str().unwrap(),
            "--max-error",
            "3",
            "--window",
            &window,
            "--out",
            out.to_str().unwrap(),
        ];
        args.extend(extra);
        relevo(args)
    };
    let geometry = |path: &Path| -> Vec<String> {
        std::fs::read_to_string(path)
            .unwrap()
            .lines()
            .filter(|l| l.starts_with("v ") || l.starts_with("vn ") || l.starts_with("f "))
            .map(str::to_string)
            .collect()
    };
    let (a, b) = (d.path().join("p.obj"), d.path().join("s.obj"));
    for (bundle, out) in [(&pyramid, &a), (&single, &b)] {
        let run = mesh(bundle, out, &[]);
        assert!(
            run.status.success(),
            "{}",
            String::from_utf8_lossy(&run.stderr)
        );
    }
    let (pa, sb) = (geometry(&a), geometry(&b));
    let faces = pa.iter().filter(|l| l.starts_with("f ")).count();
    assert!(faces > 1000, "{faces} triangles in the window");
    assert!(pa == sb, "the window meshes differ");
    // Fewer triangles than the whole region's.
    let whole = d.path().join("whole.obj");
    relevo_ok([
        "mesh".as_ref(),
        pyramid.as_os_str(),
        "--max-error".as_ref(),
        "3".as_ref(),
        "--out".as_ref(),
        whole.as_os_str(),
    ]);
    assert!(
        geometry(&whole)
            .iter()
            .filter(|l| l.starts_with("f "))
            .count()
            > 2 * faces
    );
    let glb = d.path().join("p.glb");
    assert!(mesh(&pyramid, &glb, &[]).status.success());
    let report = khronos_validate(&glb);
    assert_eq!(report["numErrors"], 0, "{report}");
    // A window off the grid, and a budget the mesh exceeds.
    let off = format!("{},{},{},{}", x0 - 1e6, y0, x1 - 1e6, y1);
    let run = relevo([
        "mesh",
        pyramid.to_str().unwrap(),
        "--max-error",
        "3",
        "--window",
        &off,
        "--out",
        d.path().join("off.glb").to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(
        !run.status.success() && err.contains("does not meet the grid"),
        "{err}"
    );
    let run = mesh(
        &pyramid,
        &d.path().join("tight.glb"),
        &["--max-memory", "200K"],
    );
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(
        !run.status.success() && err.contains("raise the tolerance"),
        "{err}"
    );
    assert!(!d.path().join("off.glb").exists() && !d.path().join("tight.glb").exists());
}

/// `relevo render` of a pyramid: with every band on level 0 it draws the
/// single grid's frame (the same depth at nearly every pixel); with the
/// default bands, farther slices read coarser levels and the frame stays
/// close to the single grid's; --bands is refused for a pyramid.
#[test]
fn a_pyramid_raycast_reads_coarser_levels_farther_away() {
    let d = tempfile::tempdir().unwrap();
    let single = single_grid(d.path(), &grenoble_dem());
    let pyramid = tiled(d.path(), "t32.relevo", 32, &[]);
    let frame = Bundle::open(&single).unwrap().frame();
    let (x, y) = frame.world_from_vertex(100.0, 550.0);
    let camera = format!("{x},{y},2500,45");
    let render = |bundle: &Path, name: &str, extra: &[&str]| {
        let (png, depth) = (
            d.path().join(format!("{name}.png")),
            d.path().join(format!("{name}.f32")),
        );
        let mut args = vec![
            "render",
            bundle.to_str().unwrap(),
            "--camera",
            &camera,
            "--size",
            "480x270",
            "--depth",
            depth.to_str().unwrap(),
            "--out",
            png.to_str().unwrap(),
        ];
        args.extend(extra);
        relevo_ok(args);
        let (rgba, _, _) =
            relevo_core::raster::png::decode_rgba(&std::fs::read(&png).unwrap()).unwrap();
        let depth: Vec<f32> = std::fs::read(&depth)
            .unwrap()
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
            .collect();
        (rgba, depth)
    };
    // PSNR of the colour channels, as the snapshot tests measure it.
    let psnr = |a: &[u8], b: &[u8]| {
        relevo_core::raster::compare::difference(a, b, 0)
            .expect("frames of one size")
            .psnr_db
    };
    let equal_depth = |a: &[f32], b: &[f32]| {
        a.iter().zip(b).filter(|(x, y)| x == y).count() as f64 / a.len() as f64
    };
    let (s_rgba, s_depth) = render(&single, "single", &[]);
    let terrain = s_depth.iter().filter(|&&z| z < 1.0).count() as f64 / s_depth.len() as f64;
    let (f_rgba, f_depth) = render(&pyramid, "finest", &["--max-cell-px", "1e-6"]);
    let (l_rgba, l_depth) = render(&pyramid, "levels", &["--max-cell-px", "8"]);
    assert!(terrain > 0.3, "the view shows terrain ({terrain:.3})");
    // Measured: exactly the single grid's frame (the same colour and depth
    // at every pixel).
    let (finest_psnr, finest_depth) = (psnr(&s_rgba, &f_rgba), equal_depth(&s_depth, &f_depth));
    assert!(
        finest_psnr > 60.0 && finest_depth > 0.999,
        "level 0 everywhere: {finest_psnr:.1} dB, depth equal at {finest_depth:.4}"
    );
    // Measured: 36.1 dB, depth equal at 88 % of the pixels (the near band
    // is level 0, farther ones coarser).
    let (levels_psnr, levels_depth) = (psnr(&s_rgba, &l_rgba), equal_depth(&s_depth, &l_depth));
    assert!(
        (32.0..60.0).contains(&levels_psnr) && (0.8..0.999).contains(&levels_depth),
        "coarser levels farther: {levels_psnr:.1} dB, depth equal at {levels_depth:.4}"
    );
    // It says which levels the bands read.
    let run = relevo([
        "render",
        pyramid.to_str().unwrap(),
        "--camera",
        &camera,
        "--max-cell-px",
        "8",
        "--out",
        d.path().join("said.png").to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(
        run.status.success()
            && err.contains("the bands read level 0 ")
            && err.contains(", level 1 "),
        "{err}"
    );
    let run = relevo([
        "render",
        pyramid.to_str().unwrap(),
        "--camera",
        &camera,
        "--bands",
        "3000:4,inf:1",
        "--out",
        d.path().join("bands.png").to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(
        !run.status.success() && err.contains("--max-cell-px"),
        "{err}"
    );
}

/// Holes in the projected DEM — small ones, one across a tile border, one
/// a single cell — are filled window by window exactly as the in-memory
/// fill stage fills them (the pyramid equals the single grid bit for bit
/// in a budget the grid exceeds); a void larger than the fill's limit
/// sends the build through the in-memory stages.
#[test]
fn a_dem_with_holes_is_filled_window_by_window_as_in_memory() {
    let d = tempfile::tempdir().unwrap();
    let nodata = ["-dstnodata", "-32768"];
    let dem = projected_dem_named(d.path(), "holes.tif", &nodata);
    for cells in [
        [100, 120, 6, 4],
        [250, 250, 10, 10],
        [497, 300, 30, 2],
        [640, 700, 1, 1],
    ] {
        set_cells(&dem, 32631, cells, -32768.0);
    }
    let single = single_grid(d.path(), &dem);
    let run = |dem: &Path, name: &str, budget: &str| {
        let out = d.path().join(name);
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_relevo"))
            .env("RAYON_NUM_THREADS", "2")
            .args(["prep", "--dem", dem.to_str().unwrap(), "--tiled"])
            .args(["--tile-size", "128", "--max-memory", budget, "--json", "-v"])
            .arg("--out")
            .arg(&out)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&o.stderr).to_string();
        assert!(o.status.success(), "{stderr}");
        let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        (out, summary, stderr)
    };
    let (p, summary, log) = run(&dem, "holes.relevo", "16M");
    assert_eq!(summary["read_by_windows"], true, "{summary}");
    assert!(log.contains("4 holes, filled window by window"), "{log}");
    assert_same_as_single(&single, &p, "holes");
    let big = projected_dem_named(d.path(), "big_void.tif", &nodata);
    set_cells(&big, 32631, [300, 600, 120, 100], -32768.0);
    let (_, summary, log) = run(&big, "big_void.relevo", "2G");
    assert_eq!(summary["read_by_windows"], false, "{summary}");
    assert!(log.contains("a void of 12000 cells"), "{log}");
}

#[test]
fn a_projected_dem_is_read_window_by_window_within_a_budget_the_grid_exceeds() {
    let d = tempfile::tempdir().unwrap();
    let dem = projected_dem(d.path());
    let single = single_grid(d.path(), &dem);
    // Two threads, so the tile work's budget is the same on any machine.
    let run = |name: &str, tile: &str, extra: &[&str]| {
        let out = d.path().join(name);
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_relevo"))
            .env("RAYON_NUM_THREADS", "2")
            .args(["prep", "--dem", dem.to_str().unwrap(), "--tiled"])
            .args(["--tile-size", tile, "--max-memory", "16M", "--json", "-q"])
            .args(extra)
            .arg("--out")
            .arg(&out)
            .output()
            .unwrap();
        (out, o)
    };
    // Window by window: the 1025² grid (23 MiB of heights alone) is never
    // held, so a 16 MiB budget suffices.
    let (p, o) = run("direct.relevo", "128", &[]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(summary["read_by_windows"], true, "{summary}");
    assert_same_as_single(&single, &p, "direct");
    // Through the in-memory stages (a resampling asked for), refused by name.
    let (p, o) = run("staged.relevo", "128", &["--cell-size", "30"]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("memory budget is 16.0 MiB") && !p.exists(),
        "{stderr}"
    );
    // Tiles too large for the budget are refused before anything is written.
    let (p, o) = run("wide.relevo", "1024", &[]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("building tiles of 1024 cells") && !p.exists(),
        "{stderr}"
    );
}

#[test]
fn a_killed_build_resumes_to_the_same_bytes() {
    let d = tempfile::tempdir().unwrap();
    // Small tiles and 41 m cells (a 4097² grid): a build of a few seconds.
    let whole = tiled(d.path(), "whole.relevo", 32, &["--cell-size", "41"]);
    let out = d.path().join("killed.relevo");
    for delay_ms in [1500, 2500, 3500] {
        let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_relevo"))
            .args([
                "prep".as_ref(),
                "--dem".as_ref(),
                grenoble_dem().as_os_str(),
            ])
            .args([
                "--tiled",
                "--tile-size",
                "32",
                "--cell-size",
                "41",
                "-q",
                "--force",
            ])
            .arg("--out")
            .arg(&out)
            .spawn()
            .unwrap();
        std::thread::sleep(std::time::Duration::from_millis(delay_ms));
        let _ = child.kill();
        let _ = child.wait();
        if !out.exists() {
            break;
        }
        std::fs::remove_dir_all(&out).unwrap();
    }
    let staging = d.path().join("killed.relevo.tmp");
    assert!(
        staging.exists() || out.exists(),
        "the build neither left its staging nor finished"
    );
    tiled(
        d.path(),
        "killed.relevo",
        32,
        &["--cell-size", "41", "--resume", "--force"],
    );
    assert_eq!(tile_files(&out), tile_files(&whole));
    assert!(!staging.exists());
}

#[test]
fn tampered_or_truncated_pyramids_are_refused_by_name() {
    let d = tempfile::tempdir().unwrap();
    let good = tiled(d.path(), "good.relevo", 64, &[]);
    let copy = |name: &str| {
        let to = d.path().join(name);
        let ok = std::process::Command::new("cp")
            .args(["-a".as_ref(), good.as_os_str(), to.as_os_str()])
            .status()
            .unwrap();
        assert!(ok.success());
        to
    };
    // Truncated heights.
    let truncated = copy("truncated.relevo");
    let f = std::fs::OpenOptions::new()
        .write(true)
        .open(truncated.join("tiles/height.f32"))
        .unwrap();
    f.set_len(1000).unwrap();
    // A manifest whose tiling disagrees with its grid.
    let tiling = copy("tiling.relevo");
    let path = tiling.join("manifest.json");
    let text = std::fs::read_to_string(&path)
        .unwrap()
        .replace("\"levels\": 5", "\"levels\": 9");
    std::fs::write(&path, text).unwrap();
    // A border sample changed in one tile, its hash fixed up.
    let border = copy("border.relevo");
    let heights = border.join("tiles/height.f32");
    let mut bytes = std::fs::read(&heights).unwrap();
    // Tile 0's last column, row 10: shared with tile 1's first column.
    let at = (10 * 65 + 64) * 4;
    bytes[at..at + 4].copy_from_slice(&1234.5f32.to_le_bytes());
    std::fs::write(&heights, bytes).unwrap();
    let path = border.join("manifest.json");
    let mut manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    manifest["files"]["height"]["sha256"] = sha256(&heights).into();
    std::fs::write(&path, serde_json::to_string_pretty(&manifest).unwrap()).unwrap();
    for (bundle, needles) in [
        (&truncated, vec!["height.f32", "is 1000 bytes"]),
        (&tiling, vec!["manifest.json", "tiling says 9 levels"]),
        (&border, vec!["disagree at their shared sample"]),
    ] {
        let out = relevo(["validate".as_ref(), bundle.as_os_str()]);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{stderr}");
        assert!(!stderr.contains("panicked"), "{stderr}");
        for n in needles {
            assert!(stderr.contains(n), "{}: {stderr}", bundle.display());
        }
    }
}

#[test]
fn commands_that_read_single_grids_refuse_a_pyramid_by_name() {
    let d = tempfile::tempdir().unwrap();
    let p = tiled(d.path(), "p.relevo", 128, &[]);
    let golden = d.path().join("golden.json");
    let p = p.to_str().unwrap();
    for (args, code) in [
        (
            vec!["check", p, "--golden", golden.to_str().unwrap(), "--bless"],
            2,
        ),
        (vec!["diff", p, p], 2),
    ] {
        let o = relevo(&args);
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(code), "{args:?}: {stderr}");
        assert!(stderr.contains("is a pyramid bundle"), "{args:?}: {stderr}");
        assert!(!golden.exists());
    }
    // `bake` reads pyramids; this one has no vegetation to cluster.
    let o = relevo(["bake", p]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("no vegetation database"), "{stderr}");
}

#[test]
fn a_grid_beyond_the_memory_budget_and_bad_tile_sizes_are_refused() {
    let d = tempfile::tempdir().unwrap();
    let dem_path = grenoble_dem().display().to_string();
    for (args, needle) in [
        (vec!["--tile-size", "100"], "a tile of 100 cells"),
        (
            vec!["--tile-size", "2048"],
            "cannot be cut into tiles of 2048 cells",
        ),
        (
            vec!["--cell-size", "10", "--max-memory", "256M"],
            "needs about",
        ),
        (
            vec!["--image", &dem_path, &dem_path],
            "make one VRT of them",
        ),
    ] {
        let dem = grenoble_dem();
        let mut all = vec!["prep", "--dem", dem.to_str().unwrap(), "--tiled", "--out"];
        let out = d.path().join("x.relevo");
        all.push(out.to_str().unwrap());
        all.extend(args);
        let o = relevo(&all);
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{stderr}");
        assert!(stderr.contains(needle) && !out.exists(), "{stderr}");
    }
}

/// `relevo prep data/olinda/REGION.toml --out OUT EXTRA…`; its output.
fn prep_olinda(out: &Path, extra: &[&str]) -> String {
    let region = repo("data/olinda/REGION.toml");
    let mut args = vec![
        "prep",
        region.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend(extra);
    relevo_ok(&args)
}

/// Olinda prepared as a pyramid of 32-cell tiles holds the vegetation
/// database, its samples and every cluster file of the single-grid bundle
/// byte for byte (the objects stand on the tiles' ground as on the whole
/// grid's), passes validation, and `info` shows them. Replacing it with
/// --force drops the old pyramid's files and keeps the user's; `bake`
/// re-bakes it in place as it re-bakes the single grid. Clusters that
/// disagree with the database are refused by name.
#[test]
fn a_pyramid_holds_the_single_grids_vegetation_and_clusters() {
    let d = tempfile::tempdir().unwrap();
    let (single, pyramid) = (d.path().join("s.relevo"), d.path().join("p.relevo"));
    let prep = prep_olinda;
    prep(&single, &["-q"]);
    let printed = prep(&pyramid, &["--tiled", "--tile-size", "32"]);
    assert!(printed.contains("vegetation: 11764 objects"), "{printed}");
    let s = Bundle::open(&single).unwrap();
    let p = Pyramid::open(&pyramid).unwrap();
    let vegetation: Vec<_> = s
        .manifest
        .artifacts
        .iter()
        .filter(|(key, _)| key.starts_with("vegetation") || key.starts_with("clusters"))
        .collect();
    assert!(vegetation.len() >= 7, "{vegetation:?}");
    for (key, a) in vegetation {
        let b = p.manifest.files.get(key).unwrap_or_else(|| panic!("{key}"));
        assert_eq!((&a.file, &a.sha256), (&b.file, &b.sha256), "{key}");
        assert_eq!(sha256(&pyramid.join(&b.file)), a.sha256, "{key}");
    }
    assert!(relevo_ok(["validate", pyramid.to_str().unwrap()]).contains("valid"));
    let info = relevo_ok(["info", pyramid.to_str().unwrap()]);
    assert!(info.contains("vegetation   11764 objects"), "{info}");
    assert!(
        info.contains("clusters     11764 objects (0 off the terrain)"),
        "{info}"
    );

    std::fs::write(pyramid.join("notes.txt"), "mine").unwrap();
    // Without --tile-size a grid smaller than the default tile (129² here)
    // is one tile.
    prep(&pyramid, &["--tiled", "--force", "-q"]);
    let replaced = Pyramid::open(&pyramid).unwrap();
    assert_eq!(
        (
            replaced.manifest.tiling.tile_cells,
            replaced.manifest.tiling.levels
        ),
        (128, 1)
    );
    assert_eq!(
        std::fs::read_to_string(pyramid.join("notes.txt")).unwrap(),
        "mine"
    );
    assert!(!d.path().join("p.relevo.old").exists());

    // Re-baked in place with a smaller budget: the single grid's new
    // clusters, byte for byte; the pages no longer listed are gone.
    for b in [&single, &pyramid] {
        relevo_ok(["bake", b.to_str().unwrap(), "--budget-mib", "16"]);
    }
    let (s, p) = (
        Bundle::open(&single).unwrap(),
        Pyramid::open(&pyramid).unwrap(),
    );
    let clusters = |files: &std::collections::BTreeMap<String, relevo_core::bundle::Artifact>| {
        files
            .iter()
            .filter(|(key, _)| key.starts_with("clusters"))
            .map(|(key, a)| (key.clone(), a.sha256.clone()))
            .collect::<Vec<_>>()
    };
    assert_eq!(clusters(&s.manifest.artifacts), clusters(&p.manifest.files));
    assert!(clusters(&p.manifest.files).len() < 7);
    assert!(!pyramid.join("clusters/atlas_002.png").exists());
    assert!(pyramid.join("notes.txt").exists());
    assert!(relevo_ok(["validate", pyramid.to_str().unwrap()]).contains("valid"));

    // A cluster object moved off its database row: refused by name.
    let objects = pyramid.join("clusters/objects.bin");
    let mut bytes = std::fs::read(&objects).unwrap();
    bytes[0] ^= 0x40;
    std::fs::write(&objects, bytes).unwrap();
    let o = relevo(["validate", pyramid.to_str().unwrap()]);
    let out = String::from_utf8_lossy(&o.stdout).to_string() + &String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{out}");
    assert!(out.contains("clusters/objects.bin"), "{out}");
}

/// Olinda's pyramid takes its drape from the Landsat image, tile by tile:
/// the same level-0 drape at tiles of 32 and 64 cells, and each vertex's
/// colour the image over its cell — registered: the single grid's drape
/// (the image at its own 28.5 m) averaged over each vertex's 90 m cell is
/// closest at no shift, closer than one vertex off in any direction.
#[test]
fn a_pyramids_drape_is_the_imagery_at_its_vertices() {
    let d = tempfile::tempdir().unwrap();
    let prep = |out: &Path, extra: &[&str]| {
        prep_olinda(out, &[extra, &["-q"]].concat());
    };
    let single = d.path().join("s.relevo");
    prep(&single, &[]);
    let drapes: Vec<Vec<u8>> = [32, 64]
        .iter()
        .map(|t| {
            let out = d.path().join(format!("p{t}.relevo"));
            prep(&out, &["--tiled", "--tile-size", &t.to_string()]);
            let p = Pyramid::open(&out).unwrap();
            p.level0_window(Rect::whole(p.layout.side)).unwrap().drape
        })
        .collect();
    assert!(drapes[0] == drapes[1], "the drape depends on the tile size");
    let b = Bundle::open(&single).unwrap();
    let image = b.drape().unwrap().unwrap();
    let (info, rgba) = (&image.info, &image.rgba);
    let side = b.manifest.grid.side;
    let grid = b.manifest.grid.geotransform;
    let cell = grid.cell_size().0;
    // The single grid's drape averaged over vertex (c, r)'s cell.
    let averaged = |c: usize, r: usize| -> Option<[f64; 3]> {
        let (x, y) = grid.apply(c as f64 + 0.5, r as f64 + 0.5);
        let pixel = |x: f64, y: f64| info.geotransform.invert(x, y).unwrap();
        let (c0, r0) = pixel(x - cell / 2.0, y + cell / 2.0);
        let (c1, r1) = pixel(x + cell / 2.0, y - cell / 2.0);
        let span = |a: f64, b: f64, n: usize| {
            a.max(0.0).round() as usize..b.min(n as f64).round() as usize
        };
        let (mut sum, mut n) = ([0.0; 3], 0.0);
        for py in span(r0, r1, info.height) {
            for px in span(c0, c1, info.width) {
                let k = 4 * (py * info.width + px);
                if rgba[k + 3] == 255 {
                    for ch in 0..3 {
                        sum[ch] += rgba[k + ch] as f64;
                    }
                    n += 1.0;
                }
            }
        }
        (n > 0.0).then(|| sum.map(|v| v / n))
    };
    let mean_difference = |dc: i64, dr: i64| -> f64 {
        let (mut total, mut n) = (0.0, 0.0);
        for r in 2..side - 2 {
            for c in 2..side - 2 {
                let k = 4 * (r * side + c);
                let (sc, sr) = ((c as i64 + dc) as usize, (r as i64 + dr) as usize);
                if let (255, Some(avg)) = (drapes[0][k + 3], averaged(sc, sr)) {
                    total += (0..3)
                        .map(|ch| (drapes[0][k + ch] as f64 - avg[ch]).abs())
                        .sum::<f64>()
                        / 3.0;
                    n += 1.0;
                }
            }
        }
        assert!(n > 1000.0, "{n} vertices compared");
        total / n
    };
    let here = mean_difference(0, 0);
    eprintln!("mean difference {here:.2}");
    assert!(here < 10.0, "{here}");
    for (dc, dr) in [(1, 0), (-1, 0), (0, 1), (0, -1)] {
        let off = mean_difference(dc, dr);
        eprintln!("shift ({dc}, {dr}): {off:.2}");
        assert!(here < off, "shifted by ({dc}, {dr}) {off} ≤ {here}");
    }
}
