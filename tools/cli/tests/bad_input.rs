//! Bad input: every case must fail with a message naming the file and the
//! problem, exit non-zero, and leave no output behind.
// Test code: a failed unwrap is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;
use common::*;
use std::path::{Path, PathBuf};

/// Run `relevo ARGS` in `dir`, expecting failure; check stderr mentions every
/// needle and that `dir` holds only `keep` afterwards.
fn fails(dir: &Path, args: &[&str], needles: &[&str], keep: &[&str]) {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_relevo"))
        .args(args)
        .current_dir(dir)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{args:?} succeeded");
    assert!(!stderr.contains("panicked"), "{args:?} panicked: {stderr}");
    for n in needles {
        assert!(
            stderr.contains(n),
            "{args:?}: stderr lacks {n:?}:\n{stderr}"
        );
    }
    let mut expected: Vec<String> = keep.iter().map(|s| s.to_string()).collect();
    expected.sort();
    assert_eq!(listing(dir), expected, "{args:?} left files behind");
}

/// The sample region's bundle in a temporary folder, and an empty
/// `work` folder beside it to run commands in.
fn sample_bundle_and_workspace() -> (tempfile::TempDir, PathBuf, PathBuf) {
    let d = tempfile::tempdir().unwrap();
    let bundle = sample_bundle(d.path());
    let work = d.path().join("work");
    std::fs::create_dir(&work).unwrap();
    (d, bundle, work)
}

fn copy_in(dir: &Path, src: &Path, name: &str) -> PathBuf {
    let to = dir.join(name);
    std::fs::copy(src, &to).unwrap();
    to
}

#[test]
fn missing_file() {
    let d = tempfile::tempdir().unwrap();
    fails(
        d.path(),
        &["stitch", "nope.tif", "--out", "o.tif"],
        &["nope.tif", "no such file"],
        &[],
    );
    fails(
        d.path(),
        &["prep", "--dem", "nope.tif", "--out", "o.relevo"],
        &["nope.tif", "no such file"],
        &[],
    );
}

#[test]
fn not_a_raster() {
    let d = tempfile::tempdir().unwrap();
    std::fs::write(d.path().join("notes.tif"), "just some text\n").unwrap();
    fails(
        d.path(),
        &["prep", "--dem", "notes.tif", "--out", "o.relevo"],
        &["notes.tif", "not a raster GDAL can read"],
        &["notes.tif"],
    );
}

#[test]
fn truncated_tiff() {
    let d = tempfile::tempdir().unwrap();
    let full = std::fs::read(shared("dem/srtm_ref.tif")).unwrap();
    std::fs::write(d.path().join("cut.tif"), &full[..full.len() / 3]).unwrap();
    fails(
        d.path(),
        &["stitch", "cut.tif", "--out", "o.tif"],
        &["cut.tif"],
        &["cut.tif"],
    );
    fails(
        d.path(),
        &["prep", "--dem", "cut.tif", "--out", "o.relevo"],
        &["cut.tif"],
        &["cut.tif"],
    );
}

#[test]
fn tiles_with_different_band_counts() {
    let d = tempfile::tempdir().unwrap();
    copy_in(d.path(), &shared("tiles/rgbn_5m/rgbn_suba.tif"), "a.tif");
    copy_in(d.path(), &shared("dem/lidar_minnesota_1m.tif"), "b.tif");
    fails(
        d.path(),
        &["stitch", "a.tif", "b.tif", "--out", "o.tif"],
        &["b.tif", "has 1 band(s)", "a.tif", "has 4"],
        &["a.tif", "b.tif"],
    );
}

#[test]
fn all_nodata_input() {
    let d = tempfile::tempdir().unwrap();
    write_f32_tif(
        &d.path().join("empty.tif"),
        8,
        8,
        &[-9999.0; 64],
        Some(-9999.0),
    );
    fails(
        d.path(),
        &["prep", "--dem", "empty.tif", "--out", "o.relevo"],
        &["empty.tif", "no valid data"],
        &["empty.tif"],
    );
    fails(
        d.path(),
        &["fill", "empty.tif", "--out", "f.tif"],
        &["empty.tif", "no valid data"],
        &["empty.tif"],
    );
}

#[test]
fn nan_heights() {
    let d = tempfile::tempdir().unwrap();
    let mut v = vec![10.0f32; 64];
    v[27] = f32::NAN;
    write_f32_tif(&d.path().join("nan.tif"), 8, 8, &v, None);
    fails(
        d.path(),
        &["prep", "--dem", "nan.tif", "--out", "o.relevo"],
        &["nan.tif", "1 value(s) are NaN", "--src-nodata nan"],
        &["nan.tif"],
    );
    // Declared as holes, the same file goes through and the hole is filled.
    let (dem, out) = (d.path().join("nan.tif"), d.path().join("o.relevo"));
    let json = relevo_ok([
        "prep",
        "--dem",
        dem.to_str().unwrap(),
        "--src-nodata",
        "nan",
        "--out",
        out.to_str().unwrap(),
        "--json",
    ]);
    let summary: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert_eq!(summary["fill"]["cells_filled"], 1);
}

#[test]
fn one_cell_raster() {
    let d = tempfile::tempdir().unwrap();
    write_f32_tif(&d.path().join("dot.tif"), 1, 1, &[5.0], None);
    fails(
        d.path(),
        &["prep", "--dem", "dot.tif", "--out", "o.relevo"],
        &["dot.tif", "1×1", "at least 2×2"],
        &["dot.tif"],
    );
    fails(
        d.path(),
        &["pad", "dot.tif", "--out", "p.tif"],
        &["dot.tif", "at least 2×2"],
        &["dot.tif"],
    );
}

#[test]
fn region_file_errors() {
    let d = tempfile::tempdir().unwrap();
    let cases = [
        (
            "syntax.toml",
            "name = \"x\"\n[dem\nfiles = [\"a.tif\"]\n",
            "line 2",
        ),
        (
            "unknown.toml",
            "[dem]\nfiles = [\"a.tif\"]\nresolution = 5\n",
            "unknown field `resolution`",
        ),
        ("nodem.toml", "name = \"x\"\n", "missing field `dem`"),
        ("empty.toml", "[dem]\nfiles = []\n", "dem.files is empty"),
        (
            "stretch.toml",
            "[dem]\nfiles = [\"a.tif\"]\n[image]\nfiles = [\"b.tif\"]\nstretch = [90, 10]\n",
            "image.stretch",
        ),
        (
            "nodata.toml",
            "[dem]\nfiles = [\"a.tif\"]\nsrc_nodata = \"none\"\n",
            "src_nodata",
        ),
        (
            "vegnoimage.toml",
            "[dem]\nfiles = [\"a.tif\"]\n[vegetation]\nsamples = \"s.csv\"\n",
            "[vegetation] needs [image]",
        ),
        (
            "twodrapes.toml",
            "terrain_drape = true\n[dem]\nfiles = [\"a.tif\"]\n[image]\nfiles = [\"b.tif\"]\n",
            "terrain_drape and [image] both give the drape",
        ),
        (
            "vegoption.toml",
            "[dem]\nfiles = [\"a.tif\"]\n[image]\nfiles = [\"b.tif\"]\n[vegetation]\nsamples = \"s.csv\"\n[vegetation.options]\nthreshold = 3\n",
            "unknown field `threshold`",
        ),
    ];
    let names: Vec<&str> = cases.iter().map(|c| c.0).collect();
    for (name, text, _) in &cases {
        std::fs::write(d.path().join(name), text).unwrap();
    }
    for (name, _, needle) in &cases {
        fails(
            d.path(),
            &["prep", name, "--out", "o.relevo"],
            &[name, needle],
            &names,
        );
    }
}

#[test]
fn unwritable_or_existing_output() {
    let d = tempfile::tempdir().unwrap();
    let dem = copy_in(d.path(), &shared("dem/luxembourg_elev.tif"), "lux.tif");
    fails(
        d.path(),
        &["prep", "--dem", "lux.tif", "--out", "no/such/dir/x.relevo"],
        &["no/such/dir", "does not exist"],
        &["lux.tif"],
    );
    fails(
        d.path(),
        &["stitch", "lux.tif", "--out", "/proc/lux.tif"],
        &["/proc/lux.tif"],
        &["lux.tif"],
    );
    fails(
        d.path(),
        &["prep", "--dem", "lux.tif", "--out", "/proc/lux.relevo"],
        &["/proc/lux.relevo"],
        &["lux.tif"],
    );
    std::fs::write(d.path().join("taken.tif"), "keep me").unwrap();
    fails(
        d.path(),
        &["stitch", "lux.tif", "--out", "taken.tif"],
        &["taken.tif", "already exists", "--force"],
        &["lux.tif", "taken.tif"],
    );
    assert_eq!(
        std::fs::read_to_string(d.path().join("taken.tif")).unwrap(),
        "keep me"
    );
    let _ = dem;
}

#[test]
fn bands_and_encodings_that_do_not_exist() {
    let d = tempfile::tempdir().unwrap();
    copy_in(d.path(), &repo("data/olinda/L7_ETMs.tif"), "l7.tif");
    copy_in(d.path(), &shared("dem/luxembourg_elev.tif"), "lux.tif");
    fails(
        d.path(),
        &["stitch", "l7.tif", "--bands", "9,2,1", "--out", "o.tif"],
        &["l7.tif", "no band 9"],
        &["l7.tif", "lux.tif"],
    );
    fails(
        d.path(),
        &[
            "prep",
            "--dem",
            "lux.tif",
            "--encoding",
            "terrain-rgb",
            "--out",
            "o.relevo",
        ],
        &["lux.tif", "needs 3"],
        &["l7.tif", "lux.tif"],
    );
}

#[test]
fn ungeoreferenced_tiles_cannot_be_mosaicked() {
    let d = tempfile::tempdir().unwrap();
    copy_in(d.path(), &shared("terrain_rgb_martini/fuji.png"), "a.png");
    copy_in(d.path(), &shared("terrain_rgb_martini/fuji.png"), "b.png");
    fails(
        d.path(),
        &[
            "stitch",
            "a.png",
            "b.png",
            "--encoding",
            "terrain-rgb",
            "--out",
            "o.tif",
        ],
        &["a.png", "no georeferencing"],
        &["a.png", "b.png"],
    );
}

#[test]
fn broken_bundles_are_reported() {
    let d = tempfile::tempdir().unwrap();
    let bundle = d.path().join("lux.relevo");
    relevo_ok([
        "prep",
        "--dem",
        shared("dem/luxembourg_elev.tif").to_str().unwrap(),
        "--out",
        bundle.to_str().unwrap(),
    ]);
    relevo_ok(["validate", bundle.to_str().unwrap()]);

    // One flipped byte in the heights.
    let heights = bundle.join("height.f32");
    let mut bytes = std::fs::read(&heights).unwrap();
    bytes[100] ^= 0x40;
    std::fs::write(&heights, &bytes).unwrap();
    let out = relevo(["validate", bundle.to_str().unwrap()]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(stderr.contains("height.f32 has sha256"), "{stderr}");

    // A manifest that is not JSON.
    std::fs::write(bundle.join("manifest.json"), "{ nope").unwrap();
    for cmd in ["validate", "info"] {
        let out = relevo([cmd, bundle.to_str().unwrap()]);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success());
        assert!(
            stderr.contains("manifest.json") && stderr.contains("invalid manifest"),
            "{stderr}"
        );
    }
}

/// A change made to a manifest.
type Edit = dyn Fn(&mut serde_json::Value);

/// Hostile values at the edge: cameras and far planes that are not finite
/// numbers are refused by name; a huge far plane costs no more than the
/// terrain; a manifest with a zero cell size, a side that is not 2^n + 1
/// or a file outside the bundle is refused by every command before any
/// array is read.
#[test]
fn hostile_cameras_far_planes_and_manifests_are_refused() {
    let (_d, bundle, work) = sample_bundle_and_workspace();
    let b = bundle.to_str().unwrap();
    for camera in [
        "NaN,9112000,400,45,300",
        "290000,9112000,inf,45,300",
        "290000,9112000,400,-inf,300",
        "290000,9112000,400,45,NaN",
    ] {
        let arg = format!("--camera={camera}");
        fails(
            &work,
            &["render", b, &arg, "--out", "x.png"],
            &["finite"],
            &[],
        );
    }
    for far in ["inf", "NaN", "1"] {
        let arg = format!("--far={far}");
        fails(
            &work,
            &[
                "render",
                b,
                "--camera",
                "290000,9112000,400,45,300",
                &arg,
                "--out",
                "x.png",
            ],
            &["--far"],
            &[],
        );
    }
    // A far plane of 10¹² cells renders what the default does.
    let near = work.join("near.png");
    let far = work.join("far.png");
    let camera = "290000,9112000,400,45,300";
    relevo_ok([
        "render",
        b,
        "--camera",
        camera,
        "--out",
        near.to_str().unwrap(),
    ]);
    relevo_ok([
        "render",
        b,
        "--camera",
        camera,
        "--far",
        "1e12",
        "--out",
        far.to_str().unwrap(),
    ]);
    assert_eq!(std::fs::read(&near).unwrap(), std::fs::read(&far).unwrap());
    std::fs::remove_file(&near).unwrap();
    std::fs::remove_file(&far).unwrap();

    let manifest = bundle.join("manifest.json");
    let good: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&manifest).unwrap()).unwrap();
    let edits: [(&Edit, &str); 4] = [
        (&|m| m["grid"]["cell_size_m"] = 0.0.into(), "cell size 0"),
        (&|m| m["grid"]["side"] = 128.into(), "grid side 128"),
        (
            &|m| m["artifacts"]["height"]["file"] = "../../etc/passwd".into(),
            "not a relative path",
        ),
        (
            &|m| m["artifacts"]["height"]["file"] = "/etc/passwd".into(),
            "not a relative path",
        ),
    ];
    for (edit, needle) in edits {
        let mut m = good.clone();
        edit(&mut m);
        std::fs::write(&manifest, serde_json::to_string_pretty(&m).unwrap()).unwrap();
        for args in [
            vec!["info", b],
            vec!["validate", b],
            vec!["render", b, "--camera", camera, "--out", "x.png"],
            vec!["mesh", b, "--max-error", "5", "--out", "x.obj"],
        ] {
            fails(&work, &args, &["manifest.json", needle], &[]);
        }
    }
}

/// Never clobber: every file a command would write, side files included,
/// is checked before any work; `--force` replaces a Relevo bundle but
/// nothing else, and moving the old bundle aside touches nothing of the
/// user's.
#[test]
fn user_files_are_never_clobbered() {
    let (d, bundle, work) = sample_bundle_and_workspace();
    let b = bundle.to_str().unwrap();
    // The mesh's material and texture belong to the user here.
    std::fs::write(work.join("m.mtl"), "mine").unwrap();
    std::fs::write(work.join("m.png"), "mine too").unwrap();
    fails(
        &work,
        &["mesh", b, "--max-error", "5", "--out", "m.obj"],
        &["m.mtl", "already exists"],
        &["m.mtl", "m.png"],
    );
    assert_eq!(std::fs::read_to_string(work.join("m.mtl")).unwrap(), "mine");
    std::fs::remove_file(work.join("m.mtl")).unwrap();
    fails(
        &work,
        &["mesh", b, "--max-error", "5", "--out", "m.obj"],
        &["m.png", "already exists"],
        &["m.png"],
    );
    std::fs::remove_file(work.join("m.png")).unwrap();

    // --force on something that is not a bundle: refused, left as it was.
    let region = repo("data/olinda/REGION.toml");
    let r = region.to_str().unwrap();
    std::fs::create_dir(work.join("photos")).unwrap();
    std::fs::write(work.join("photos/holiday.jpg"), "precious").unwrap();
    std::fs::write(work.join("notes.txt"), "notes").unwrap();
    for target in ["photos", "notes.txt"] {
        fails(
            &work,
            &["prep", r, "--out", target, "--force"],
            &[target, "not a Relevo bundle"],
            &["notes.txt", "photos"],
        );
        assert_eq!(
            std::fs::read_to_string(work.join("photos/holiday.jpg")).unwrap(),
            "precious"
        );
    }
    // A bundle is replaced; a user's folder named like the aside path stays.
    std::fs::create_dir(d.path().join("olinda.relevo.old")).unwrap();
    std::fs::write(d.path().join("olinda.relevo.old/keep"), "keep").unwrap();
    relevo_ok(["prep", r, "--out", b, "--force"]);
    relevo_ok(["validate", b]);
    assert_eq!(
        std::fs::read_to_string(d.path().join("olinda.relevo.old/keep")).unwrap(),
        "keep"
    );
    assert_eq!(
        listing(d.path()),
        ["olinda.relevo", "olinda.relevo.old", "work"]
    );
}

/// Infinite heights, and heights far beyond any on Earth (an undeclared
/// no-data marker such as 3.4e38), are refused by every command that reads
/// a DEM, naming the file; declared as no-data they are holes.
#[test]
fn infinite_and_absurd_heights() {
    let d = tempfile::tempdir().unwrap();
    for (name, bad, needle) in [
        ("inf.tif", f32::INFINITY, "infinite"),
        ("minus_inf.tif", f32::NEG_INFINITY, "infinite"),
        ("max.tif", 3.0e38, "beyond ±100000 m"),
        ("huge.tif", 1.0e10, "the first, 1e10,"),
    ] {
        let mut v = vec![10.0f32; 64];
        v[27] = bad;
        write_f32_tif(&d.path().join(name), 8, 8, &v, None);
        let keep = listing(d.path());
        let keep: Vec<&str> = keep.iter().map(String::as_str).collect();
        for args in [
            vec!["prep", "--dem", name, "--out", "o.relevo"],
            vec!["stitch", name, "--out", "s.tif"],
            vec!["fill", name, "--out", "f.tif"],
            vec!["pad", name, "--out", "p.tif"],
        ] {
            fails(d.path(), &args, &[name, needle], &keep);
        }
    }
    // Declared as no-data, the marker is a hole that prep fills.
    let dem = d.path().join("huge.tif");
    let out = d.path().join("o.relevo");
    relevo_ok([
        "prep",
        "--dem",
        dem.to_str().unwrap(),
        "--src-nodata",
        "1e10",
        "--out",
        out.to_str().unwrap(),
    ]);
}

/// Work larger than the memory budget is refused before it allocates,
/// with the size, the budget and what to change: a 300000×300000 sparse
/// GeoTIFF (a few KB on disk) in every command that reads a DEM, and a
/// resampling of a real 30 km DEM to 1 m cells; under a 4 GB address-space
/// limit, or in a Slurm job's allocation, nothing reaches the allocator's
/// abort.
#[test]
fn work_beyond_the_memory_budget_is_refused_before_it_starts() {
    let d = tempfile::tempdir().unwrap();
    let sparse = d.path().join("sparse.tif");
    gdal_tool(
        "gdal_create",
        &[
            "-of",
            "GTiff",
            "-outsize",
            "300000",
            "300000",
            "-ot",
            "Float32",
            "-co",
            "SPARSE_OK=YES",
            "-co",
            "TILED=YES",
            "-a_srs",
            "EPSG:32632",
            "-a_ullr",
            "0",
            "9000000",
            "9000000",
            "0",
            sparse.to_str().unwrap(),
        ],
    );
    for args in [
        vec!["prep", "--dem", "sparse.tif", "--out", "o.relevo"],
        vec!["stitch", "sparse.tif", "--out", "s.tif"],
        vec!["fill", "sparse.tif", "--out", "f.tif"],
        vec!["pad", "sparse.tif", "--out", "p.tif"],
        vec!["hierarchy", "sparse.tif", "--out", "h.f32"],
        vec![
            "veg",
            "detect",
            "sparse.tif",
            "--samples",
            "s.csv",
            "--out",
            "v.csv",
        ],
    ] {
        let mut args = args;
        args.extend(["--max-memory", "2G"]);
        fails(
            d.path(),
            &args,
            &["needs about", "memory budget is 2.0 GiB", "--max-memory"],
            &["sparse.tif"],
        );
    }
    // The machine's own budget, under a 4 GB address-space limit.
    let out = std::process::Command::new("sh")
        .arg("-c")
        .arg(format!(
            "ulimit -v 4000000 && exec {} stitch sparse.tif --out s.tif",
            env!("CARGO_BIN_EXE_relevo")
        ))
        .current_dir(d.path())
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("needs about"), "{stderr}");
    // Inside a Slurm job given 1500 MB (--mem-per-cpu 750 on 2 CPUs).
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_relevo"))
        .args(["stitch", "sparse.tif", "--out", "s.tif"])
        .env("SLURM_MEM_PER_CPU", "750")
        .env("SLURM_CPUS_PER_TASK", "2")
        .current_dir(d.path())
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("memory budget is 1.5 GiB"), "{stderr}");
    assert!(!d.path().join("s.tif").exists());

    // A real 30 km DEM resampled to 1 m cells.
    let dem = shared("dem/luxembourg_elev.tif");
    fails(
        d.path(),
        &[
            "prep",
            "--dem",
            dem.to_str().unwrap(),
            "--cell-size",
            "0.1",
            "--out",
            "o.relevo",
            "--max-memory",
            "2G",
        ],
        &["stitched grid", "needs about", "coarser resolution"],
        &["sparse.tif"],
    );
    // At 20 m the stitched grid fits in 1 GiB, its (2^n+1)² square does not.
    fails(
        d.path(),
        &[
            "prep",
            "--dem",
            dem.to_str().unwrap(),
            "--cell-size",
            "20",
            "--out",
            "o.relevo",
            "--max-memory",
            "1G",
        ],
        &[
            "stage grid",
            "8193×8193 grid needs about 1.6 GiB",
            "coarser cell size",
        ],
        &["sparse.tif"],
    );
}

/// Tiles in far-apart CRSs (a Landsat scene in Paraguay's UTM zone, an
/// SRTM tile in eastern Turkey) and a world-sized `--te` would make grids
/// of billions of cells: refused before anything is allocated.
#[test]
fn far_apart_tiles_and_world_extents_are_refused() {
    let d = tempfile::tempdir().unwrap();
    let landsat = shared("tiles/landsat8_overlap/LC08_L1TP_224077_20200518_20200518_01_RT_B4.TIF");
    let srtm = shared("dem/srtm_ref.tif");
    fails(
        d.path(),
        &[
            "stitch",
            landsat.to_str().unwrap(),
            srtm.to_str().unwrap(),
            "--out",
            "s.tif",
            "--max-memory",
            "4G",
        ],
        &[
            "stitched grid of",
            "needs about",
            "memory budget is 4.0 GiB",
        ],
        &[],
    );
    fails(
        d.path(),
        &[
            "prep",
            "--dem",
            landsat.to_str().unwrap(),
            srtm.to_str().unwrap(),
            "--out",
            "o.relevo",
            "--max-memory",
            "4G",
        ],
        &["stitched grid of", "needs about"],
        &[],
    );
    fails(
        d.path(),
        &[
            "stitch",
            srtm.to_str().unwrap(),
            "--te",
            "-180",
            "-85",
            "180",
            "85",
            "--tr",
            "0.0001",
            "--out",
            "w.tif",
        ],
        &["stitched grid of", "needs about", "coarser resolution"],
        &[],
    );
}

/// The cluster bake's atlases are estimated from the atlas budget before
/// any is drawn: a 4 GiB atlas budget under a 1 GiB memory budget is
/// refused, and the bundle is left as it was.
#[test]
fn a_cluster_bake_beyond_the_memory_budget_is_refused() {
    let (_d, bundle, work) = sample_bundle_and_workspace();
    // Every file of the bundle and of its clusters/ folder, with its digest.
    let digests = || -> Vec<(String, String)> {
        [bundle.clone(), bundle.join("clusters")]
            .iter()
            .flat_map(|dir| listing(dir).into_iter().map(move |f| dir.join(f)))
            .filter(|p| p.is_file())
            .map(|p| (p.display().to_string(), sha256(&p)))
            .collect()
    };
    let before = digests();
    assert!(before.len() > 10, "{before:?}");
    fails(
        &work,
        &[
            "bake",
            bundle.to_str().unwrap(),
            "--budget-mib",
            "4096",
            "--max-memory",
            "1G",
        ],
        &[
            "cluster bake of",
            "4.0 GiB atlas budget needs about 6.0 GiB",
            "memory budget is 1.0 GiB",
            "--budget-mib",
        ],
        &[],
    );
    assert_eq!(before, digests(), "the bundle changed");
}

/// A DEM without georeferencing does not say how large its cells are:
/// `prep` refuses it unless told, and takes it when told.
#[test]
fn ungeoreferenced_dems_need_a_cell_size() {
    let d = tempfile::tempdir().unwrap();
    let png = shared("terrain_rgb_martini/fuji.png");
    let tile = copy_in(d.path(), &png, "tile.png");
    fails(
        d.path(),
        &[
            "prep",
            "--dem",
            "tile.png",
            "--encoding",
            "terrain-rgb",
            "--out",
            "o.relevo",
        ],
        &["tile.png", "not georeferenced", "--cell-size"],
        &["tile.png"],
    );
    let out = d.path().join("o.relevo");
    relevo_ok([
        "prep",
        "--dem",
        tile.to_str().unwrap(),
        "--encoding",
        "terrain-rgb",
        "--cell-size",
        "30",
        "--out",
        out.to_str().unwrap(),
    ]);
}

/// Exit 0 means the result is valid: a scaling that pushes heights out of
/// range is refused after the scaling (it used to write `null` into the
/// manifest and exit 0), two outputs on one path are refused, and a render
/// whose depth cannot be written leaves neither file (a full disk, made
/// here by a file-size limit).
#[test]
fn results_that_would_be_unusable_are_refused_and_leave_nothing() {
    let d = tempfile::tempdir().unwrap();
    write_f32_tif(&d.path().join("dem.tif"), 8, 8, &[10.0f32; 64], None);
    for scale in ["1e308", "1e5"] {
        fails(
            d.path(),
            &[
                "prep",
                "--dem",
                "dem.tif",
                "--z-scale",
                scale,
                "--out",
                "o.relevo",
            ],
            &["dem.tif", "z_scale", "beyond ±100000 m"],
            &["dem.tif"],
        );
    }

    // A negative scale used to reach the writer's own check, which named
    // the staging folder.
    fails(
        d.path(),
        &[
            "prep",
            "--dem",
            "dem.tif",
            "--z-scale=-1",
            "--out",
            "o.relevo",
        ],
        &["z_scale must be a finite, positive number, got -1"],
        &["dem.tif"],
    );

    let (_d, bundle, work) = sample_bundle_and_workspace();
    let bundle = bundle.to_str().unwrap();
    fails(
        &work,
        &[
            "render",
            bundle,
            "--camera",
            "290000,9112000,400,45,300",
            "--out",
            "x.png",
            "--depth",
            "x.png",
        ],
        &["x.png", "named twice"],
        &[],
    );
    // The PNG fits under the limit, the depth (320×200×4 bytes) does not.
    let out = std::process::Command::new("bash")
        .arg("-c")
        .arg(format!(
            "trap '' XFSZ; ulimit -f 200; exec '{}' render '{bundle}' --size 320x200 \
             --camera 290000,9112000,400,45,300 --out x.png --depth x.f32",
            env!("CARGO_BIN_EXE_relevo")
        ))
        .current_dir(&work)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("x.f32") && stderr.contains("cannot write"),
        "{stderr}"
    );
    assert_eq!(listing(&work), Vec::<String>::new(), "{stderr}");
}

/// What GDAL reads beside a file is named when it is the problem: a VRT
/// whose source is gone (the read used to fail with "read failed"), and a
/// world file that cannot be read (the image was taken as not
/// georeferenced).
#[test]
fn vrt_sources_and_world_files_are_named() {
    let d = tempfile::tempdir().unwrap();
    let dem = repo("data/grenoble/Copernicus_DSM_10_N45_00_E005_00_DEM.tif");
    let tile = d.path().join("tile.tif");
    gdal_tool(
        "gdal_translate",
        &[
            "-q",
            "-srcwin",
            "0",
            "0",
            "64",
            "64",
            dem.to_str().unwrap(),
            tile.to_str().unwrap(),
        ],
    );
    let vrt = d.path().join("mosaic.vrt");
    gdal_tool(
        "gdalbuildvrt",
        &["-q", vrt.to_str().unwrap(), tile.to_str().unwrap()],
    );
    std::fs::remove_file(&tile).unwrap();
    for args in [
        vec!["stitch", "mosaic.vrt", "--out", "s.tif"],
        vec!["fill", "mosaic.vrt", "--out", "f.tif"],
        vec!["prep", "--dem", "mosaic.vrt", "--out", "o.relevo"],
    ] {
        fails(
            d.path(),
            &args,
            &["mosaic.vrt", "tile.tif", "No such file"],
            &["mosaic.vrt"],
        );
    }
    std::fs::remove_file(&vrt).unwrap();

    let png = d.path().join("heights.png");
    gdal_tool(
        "gdal_translate",
        &[
            "-q",
            "-of",
            "PNG",
            "-ot",
            "UInt16",
            "-srcwin",
            "0",
            "0",
            "64",
            "64",
            dem.to_str().unwrap(),
            png.to_str().unwrap(),
        ],
    );
    let _ = std::fs::remove_file(d.path().join("heights.png.aux.xml"));
    std::fs::write(d.path().join("heights.pgw"), "10\n0\n0\n-10\n500000\n").unwrap();
    for args in [
        vec!["stitch", "heights.png", "--out", "s.tif"],
        vec!["prep", "--dem", "heights.png", "--out", "o.relevo"],
    ] {
        fails(
            d.path(),
            &args,
            &["heights.pgw", "heights.png", "world file", "six numbers"],
            &["heights.pgw", "heights.png"],
        );
    }
}
