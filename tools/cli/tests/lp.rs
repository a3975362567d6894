//! Lindstrom–Pascucci hierarchy on real terrain: conformance with
//! @mapbox/martini and the nesting invariants.

mod common;
use common::*;
use relevo_core::bundle::{sha256_bytes, Bundle};
use relevo_core::lp::extract::extract;
use relevo_core::lp::Hierarchy;

#[test]
fn errors_and_meshes_match_martini() {
    let reference = martini_reference();
    let d = tempfile::tempdir().unwrap();
    for (name, file, encoding) in MARTINI_TILES {
        let bundle = Bundle::open(&prep_martini_tile(d.path(), file, encoding)).unwrap();
        let r = &reference[name];
        let heights = bundle.array::<f32>("height").unwrap();
        let side = bundle.manifest.grid.side;
        let h = Hierarchy::compute(&heights, side, 1.0);
        let errors: Vec<f32> = h.error_radius.iter().map(|e| e[0]).collect();
        assert_eq!(
            sha256_bytes(bytemuck::cast_slice(&errors)),
            r["errors"]["sha256"],
            "{name}: errors"
        );
        // The bundle stores the same errors beside the radii.
        let lp = bundle.array::<f32>("lp").unwrap();
        assert!(lp.chunks(2).zip(&errors).all(|(p, e)| p[0] == *e));

        for (max_error, mesh) in r["meshes"].as_object().unwrap() {
            let m = extract(&h, max_error.parse().unwrap(), None);
            let vertices: Vec<u16> = m.vertices.iter().flatten().copied().collect();
            let triangles: Vec<u32> = m.triangles.iter().flatten().copied().collect();
            assert_eq!(
                vertices.len() as u64,
                mesh["vertices"]["length"],
                "{name} @ {max_error}: vertex count"
            );
            assert_eq!(
                triangles.len() as u64,
                mesh["triangles"]["length"],
                "{name} @ {max_error}: triangle count"
            );
            assert_eq!(
                sha256_bytes(bytemuck::cast_slice(&vertices)),
                mesh["vertices"]["sha256"],
                "{name} @ {max_error}"
            );
            assert_eq!(
                sha256_bytes(bytemuck::cast_slice(&triangles)),
                mesh["triangles"]["sha256"],
                "{name} @ {max_error}"
            );
        }
    }
}

#[test]
fn hierarchy_is_nested_on_real_dems() {
    let d = tempfile::tempdir().unwrap();
    for dem in [
        "dem/srtm_ref.tif",
        "dem/Copernicus_DSM_10_N45_00_E005_00_DEM.tif",
        "dem/Gironde.tif",
    ] {
        let out = d.path().join("dem.relevo");
        let path = shared(dem);
        relevo_ok([
            "prep".as_ref(),
            "--dem".as_ref(),
            path.as_os_str(),
            "--force".as_ref(),
            "--out".as_ref(),
            out.as_os_str(),
        ]);
        let bundle = Bundle::open(&out).unwrap();
        let heights = bundle.array::<f32>("height").unwrap();
        let lp = bundle.lp().unwrap();
        let h = lp.hierarchy().into_owned();
        assert_eq!(
            h.nesting_violations(&heights, 10),
            Vec::<String>::new(),
            "{dem}"
        );
        assert!(
            h.error_radius.iter().any(|e| e[0] > 1.0),
            "{dem}: no relief?"
        );
        // validate runs the same check on the stored file.
        relevo_ok(["validate".as_ref(), out.as_os_str()]);
    }
}

mod refinement {
    use super::*;
    use glam::DVec3;
    use relevo_core::camera::Camera;
    use relevo_core::lp::hierarchy::visit_bottom_up;
    use relevo_core::lp::refine::{RefineParams, Refiner, Strip};
    use relevo_core::lp::terrain_position;
    use std::collections::HashMap;

    struct Terrain {
        name: String,
        heights: Vec<f32>,
        h: Hierarchy<'static>,
    }

    /// Real DEMs prepared into bundles (reprojected, filled, padded).
    fn terrains() -> Vec<Terrain> {
        let d = tempfile::tempdir().unwrap();
        let mut out = Vec::new();
        for (dem, extra) in [
            ("dem/srtm_ref.tif", vec![]),
            ("dem/Copernicus_DSM_10_N45_00_E005_00_DEM.tif", vec![]),
            ("dem/Gironde.tif", vec![]),
            (
                "terrain_rgb_martini/fuji.png",
                vec!["--encoding", "terrain-rgb", "--cell-size", "30"],
            ),
        ] {
            let path = d.path().join("t.relevo");
            let src = shared(dem);
            let mut args = vec![
                "prep",
                "--dem",
                src.to_str().unwrap(),
                "--force",
                "--out",
                path.to_str().unwrap(),
            ];
            args.extend(extra);
            relevo_ok(args);
            let b = Bundle::open(&path).unwrap();
            let heights = b.array::<f32>("height").unwrap().to_vec();
            let lp = b.lp().unwrap();
            let h = lp.hierarchy().into_owned();
            out.push(Terrain {
                name: dem.into(),
                heights,
                h,
            });
        }
        out
    }

    /// A deterministic pseudo-random sequence in [0, 1).
    struct Lcg(u64);
    impl Lcg {
        fn next(&mut self) -> f64 {
            self.0 = self
                .0
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (self.0 >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    /// Cameras inside, above and beside the terrain, looking anywhere.
    fn cameras(t: &Terrain, count: usize, seed: u64) -> Vec<Camera> {
        let mut rng = Lcg(seed);
        let extent = (t.h.side - 1) as f64 * t.h.cell_size_m;
        let top = t.heights.iter().cloned().fold(f32::MIN, f32::max) as f64;
        (0..count)
            .map(|k| {
                let (x, y) = match k % 3 {
                    0 => (rng.next() * extent, rng.next() * extent), // over the terrain
                    1 => (
                        -0.5 * extent + rng.next() * 0.4 * extent,
                        rng.next() * extent,
                    ), // beside it
                    _ => (rng.next() * extent, 1.1 * extent + rng.next() * extent),
                };
                let z = top + 50.0 + rng.next() * extent * 0.3 * (k % 2) as f64;
                Camera {
                    position: DVec3::new(x, y, z),
                    heading_deg: rng.next() * 360.0,
                    pitch_deg: -89.0 + rng.next() * 120.0,
                    incl_px: 540.0,
                    fov_x_deg: 30.0 + rng.next() * 60.0,
                    width: 1920,
                    height: 1080,
                    near_m: 1.0,
                    far_m: extent * 3.0,
                }
            })
            .collect()
    }

    fn parents(side: usize) -> HashMap<usize, Vec<usize>> {
        let mut map = HashMap::new();
        visit_bottom_up(side, |d| {
            map.insert(d.vertex, d.parents.iter().flatten().copied().collect());
        });
        map
    }

    /// Every edge used once lies on the grid border, every other edge twice,
    /// and the triangles' areas add up to the whole grid.
    fn assert_watertight(strip: &Strip, side: usize, what: &str) {
        let mut edges: HashMap<(u32, u32), u32> = HashMap::new();
        let mut area2 = 0i64;
        let xy = |v: u32| ((v as usize % side) as i64, (v as usize / side) as i64);
        let mut orientation = 0i64;
        for t in strip.triangles() {
            let (a, b, c) = (xy(t[0]), xy(t[1]), xy(t[2]));
            let cross = (b.0 - a.0) * (c.1 - a.1) - (b.1 - a.1) * (c.0 - a.0);
            assert!(cross != 0, "{what}: flat triangle");
            if orientation == 0 {
                orientation = cross.signum();
            }
            assert_eq!(
                cross.signum(),
                orientation,
                "{what}: triangles wound both ways"
            );
            area2 += cross.abs();
            for (p, q) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
                *edges.entry((p.min(q), p.max(q))).or_default() += 1;
            }
        }
        let m = (side - 1) as i64;
        assert_eq!(
            area2,
            2 * m * m,
            "{what}: triangles do not tile the grid exactly"
        );
        for ((p, q), n) in edges {
            let (a, b) = (xy(p), xy(q));
            let on_border =
                (a.0 == b.0 && (a.0 == 0 || a.0 == m)) || (a.1 == b.1 && (a.1 == 0 || a.1 == m));
            match n {
                1 => assert!(on_border, "{what}: open edge {a:?}-{b:?} inside the grid"),
                2 => {}
                _ => panic!("{what}: edge {a:?}-{b:?} used {n} times"),
            }
        }
    }

    #[test]
    fn random_cameras_give_crack_free_meshes_closed_under_parents() {
        let mut refiner = Refiner::new();
        for t in terrains() {
            let side = t.h.side;
            let parents = parents(side);
            for (k, cam) in cameras(&t, 24, 7).iter().enumerate() {
                for (tau, cull) in [(1.0, true), (4.0, false), (0.5, true)] {
                    let p = RefineParams::for_camera(cam, tau, None, cull);
                    let strip = refiner.refine(&t.h, &t.heights, &p).clone();
                    let what = format!("{} camera {k} τ={tau} cull={cull}", t.name);
                    assert_watertight(&strip, side, &what);
                    let active: std::collections::HashSet<usize> =
                        strip.indices.iter().map(|&v| v as usize).collect();
                    for &v in &active {
                        for &parent in parents.get(&v).map(|p| p.as_slice()).unwrap_or(&[]) {
                            assert!(
                                active.contains(&parent),
                                "{what}: vertex {v} active without parent {parent}"
                            );
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn zero_tolerance_keeps_every_vertex_and_culling_keeps_what_is_visible() {
        let mut refiner = Refiner::new();
        for t in terrains().into_iter().take(2) {
            let side = t.h.side;
            let cam = &cameras(&t, 1, 3)[0];
            let all = refiner
                .refine(
                    &t.h,
                    &t.heights,
                    &RefineParams::for_camera(cam, 0.0, None, false),
                )
                .clone();
            let used: std::collections::HashSet<u32> = all.indices.iter().copied().collect();
            assert_eq!(
                used.len(),
                side * side,
                "{}: τ = 0 must keep every vertex",
                t.name
            );

            // With culling, every vertex active without it whose sphere is not
            // wholly outside the frustum stays active; none is added.
            for cam in cameras(&t, 12, 11) {
                let free: std::collections::HashSet<u32> = refiner
                    .refine(
                        &t.h,
                        &t.heights,
                        &RefineParams::for_camera(&cam, 1.0, None, false),
                    )
                    .indices
                    .iter()
                    .copied()
                    .collect();
                let culled: std::collections::HashSet<u32> = refiner
                    .refine(
                        &t.h,
                        &t.heights,
                        &RefineParams::for_camera(&cam, 1.0, None, true),
                    )
                    .indices
                    .iter()
                    .copied()
                    .collect();
                assert!(culled.is_subset(&free));
                let planes = cam.frustum_planes();
                for &v in &free {
                    let (c, r) = (v as usize % side, v as usize / side);
                    let p =
                        terrain_position(c, r, side, t.h.cell_size_m, t.heights[v as usize] as f64);
                    let radius = t.h.radius(v as usize) as f64;
                    let outside = planes
                        .iter()
                        .any(|q| q[0] * p[0] + q[1] * p[1] + q[2] * p[2] + q[3] < -radius);
                    if !outside {
                        assert!(
                            culled.contains(&v),
                            "{}: visible vertex ({c}, {r}) culled",
                            t.name
                        );
                    }
                }
            }
        }
    }

    /// Per drawn vertex: its drawn height, and the height of the edge it
    /// splits (average of its hypotenuse end points as drawn).
    fn drawn(
        strip: &Strip,
        heights: &[f32],
        ends: &HashMap<usize, [usize; 2]>,
    ) -> HashMap<u32, (f64, f64)> {
        let z: HashMap<u32, f64> = if strip.morphed_z.is_empty() {
            strip
                .indices
                .iter()
                .map(|&v| (v, heights[v as usize] as f64))
                .collect()
        } else {
            strip
                .indices
                .iter()
                .copied()
                .zip(strip.morphed_z.iter().map(|&z| z as f64))
                .collect()
        };
        z.iter()
            .map(|(&v, &zv)| {
                let edge = ends
                    .get(&(v as usize))
                    .map_or(zv, |[a, b]| (z[&(*a as u32)] + z[&(*b as u32)]) / 2.0);
                (v, (zv, edge))
            })
            .collect()
    }

    /// The surface jumps when a vertex appears or vanishes away from the
    /// edge it splits, or when a drawn height moves: measure the largest such
    /// change per small camera step, with and without geomorphing.
    #[test]
    fn geomorphing_keeps_the_surface_continuous_as_the_camera_moves() {
        let t = terrains().remove(3); // fuji, 513², 30 m cells
        let side = t.h.side;
        let extent = (side - 1) as f64 * t.h.cell_size_m;
        let mut ends = HashMap::new();
        visit_bottom_up(side, |d| {
            ends.insert(d.vertex, d.hypotenuse);
        });
        let mut refiner = Refiner::new();
        let mut worst = [0.0f64; 2];
        for (k, morph) in [Some(6.0), None].into_iter().enumerate() {
            let mut previous: Option<HashMap<u32, (f64, f64)>> = None;
            for step in 0..80 {
                let cam = Camera {
                    position: DVec3::new(0.2 * extent + step as f64 * 5.0, 0.5 * extent, 4500.0),
                    heading_deg: 80.0,
                    pitch_deg: -25.0,
                    incl_px: 540.0,
                    fov_x_deg: 60.0,
                    width: 1920,
                    height: 1080,
                    near_m: 1.0,
                    far_m: 1e6,
                };
                let strip = refiner.refine(
                    &t.h,
                    &t.heights,
                    &RefineParams::for_camera(&cam, 2.0, morph, false),
                );
                let now = drawn(strip, &t.heights, &ends);
                if let Some(prev) = &previous {
                    for (v, &(z, edge)) in &now {
                        let change = match prev.get(v) {
                            Some(&(z0, _)) => (z - z0).abs(),
                            None => (z - edge).abs(), // appeared
                        };
                        worst[k] = worst[k].max(change);
                    }
                    for (v, &(z0, edge0)) in prev {
                        if !now.contains_key(v) {
                            worst[k] = worst[k].max((z0 - edge0).abs()); // vanished
                        }
                    }
                }
                previous = Some(now);
            }
        }
        eprintln!(
            "largest surface change per 5 m camera step: morphing {:.3} m, without {:.3} m",
            worst[0], worst[1]
        );
        assert!(
            worst[1] > 1.0,
            "the path should cross refinement thresholds"
        );
        assert!(
            worst[0] < worst[1] / 5.0,
            "morphing {} vs popping {}",
            worst[0],
            worst[1]
        );
    }
}

#[test]
fn hierarchy_command_matches_the_bundle_and_refuses_non_square_input() {
    let d = tempfile::tempdir().unwrap();
    let dem = shared("dem/luxembourg_elev.tif");
    let padded = d.path().join("lux_129.tif");
    relevo_ok([
        "pad".as_ref(),
        dem.as_os_str(),
        "--out".as_ref(),
        padded.as_os_str(),
    ]);
    let lp = d.path().join("lp.tif");
    relevo_ok([
        "hierarchy".as_ref(),
        padded.as_os_str(),
        "--cell-size".as_ref(),
        "30".as_ref(),
        "--out".as_ref(),
        lp.as_os_str(),
    ]);
    let r = read(&lp);
    assert_eq!((r.width, r.height, r.bands.len()), (129, 129, 2));
    let heights: Vec<f32> = read(&padded).bands[0].iter().map(|&v| v as f32).collect();
    let h = Hierarchy::compute(&heights, 129, 30.0);
    for (i, e) in h.error_radius.iter().enumerate() {
        assert_eq!((r.bands[0][i] as f32, r.bands[1][i] as f32), (e[0], e[1]));
    }
    let out = relevo([
        "hierarchy".as_ref(),
        dem.as_os_str(),
        "--out".as_ref(),
        d.path().join("x.tif").as_os_str(),
    ]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("(2^n+1)²"));
}
