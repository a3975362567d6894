//! `relevo-bench`: Relevo's measured figures beside reference tools, run
//! from the repository root as `cargo run --release -p relevo-bench -- …`.
//! It starts node (martini), python (scikit-image) and gdalwarp from
//! repository paths, so it is a development tool, not part of the shipped
//! `relevo` binary.

mod bench;
mod check;
mod clusters;
mod measure;
mod pyramid;
mod render;
mod slurm;
mod veg_protocol;
mod view;
mod view_inputs;
mod view_vegetation;

use clap::{Args, Parser, Subcommand};
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Parser, Debug)]
#[command(
    name = "relevo-bench",
    version,
    about = "Measure Relevo against reference tools (release builds only).",
    after_help = "Examples:
  cargo run --release -p relevo-bench -- ingest --json
  cargo run --release -p relevo-bench -- hierarchy --max-side 8193 --runs 3
  cargo run --release -p relevo-bench -- render --json --runs 10
  cargo run --release -p relevo-bench -- veg --json --runs 3 --max-side 10000
  cargo run --release -p relevo-bench -- veg-protocol --json
  cargo run --release -p relevo-bench -- view --json --runs 3
  cargo run --release -p relevo-bench -- view-inputs --out gpu-inputs
  cargo run --release -p relevo-bench -- clusters --json --runs 5
  cargo run --release -p relevo-bench -- check --json --runs 5
  cargo build --release -p relevo -p relevo-view && cargo run --release -p relevo-bench -- pyramid --json --max-side 32769"
)]
struct Cli {
    #[command(subcommand)]
    command: BenchCommand,
}

#[derive(Subcommand, Debug)]
enum BenchCommand {
    /// A pyramid (the real 8193² Grenoble input of `pyramid`) built as
    /// Slurm array jobs on a single-node cluster it starts, beside `prep
    /// --tiled`; Slurm's cost per task. Needs Slurm and munge
    /// (scripts/setup-test) and the `relevo` binary built beside this one.
    #[command(after_help = "Examples:
  cargo build --release -p relevo
  relevo-bench slurm --json
  relevo-bench slurm --jobs 16")]
    Slurm {
        #[command(flatten)]
        common: BenchArgs,
        /// Most jobs a step.
        #[arg(long, default_value_t = 8)]
        jobs: usize,
    },
    /// `prep` on the sample region; `stitch` on the Landsat overlap beside gdalwarp.
    #[command(after_help = "Examples:
  relevo-bench ingest
  relevo-bench ingest --json --runs 7")]
    Ingest(BenchArgs),
    /// The pyramid at scale: `relevo prep --tiled` on a real 8193² DEM and
    /// the fractal at 16385² and 32769², wall time and peak memory, beside
    /// gdaladdo and a COG of the same file; then the readers and the viewer
    /// (`relevo-view bench`) over each pyramid. Needs the `relevo` and
    /// `relevo-view` binaries built beside this one.
    #[command(after_help = "Examples:
  cargo build --release -p relevo -p relevo-view
  relevo-bench pyramid --json
  relevo-bench pyramid --json --max-side 32769
  relevo-bench pyramid --pictures docs/images")]
    Pyramid {
        #[command(flatten)]
        common: BenchArgs,
        /// Largest fractal side (16385 or 32769; 8193 runs the real DEM alone).
        #[arg(long, default_value_t = 16385)]
        max_side: usize,
        /// Write docs/images' picture of the pyramid's levels to this
        /// folder instead of measuring.
        #[arg(long)]
        pictures: Option<PathBuf>,
    },
    /// LP errors and radii beside @mapbox/martini; view-dependent refinement.
    #[command(after_help = "Examples:
  relevo-bench hierarchy --json
  relevo-bench hierarchy --max-side 8193 --runs 3")]
    Hierarchy {
        #[command(flatten)]
        common: BenchArgs,
        /// Largest fractal grid side to run (257, 1025, 4097, 8193).
        #[arg(long, default_value_t = 4097)]
        max_side: usize,
    },
    /// The floating-horizon raycast: each configuration, level and pitched,
    /// at 1920×1080 and 1280×720, far 1024, 8 headings, each a flight of
    /// `--runs` frames turning 0.5° a frame, with its PSNR against the
    /// full-resolution render, beside the classic voxel-space loop and the
    /// time to merely write a frame (the memory floor).
    #[command(after_help = "Examples:
  relevo-bench render
  relevo-bench render --json --runs 10
  relevo-bench render --grid srtm --size 1920x1080 --mode growing
  relevo-bench render --grid grenoble --bundle out/grenoble.relevo --size 1920x1080
  RAYON_NUM_THREADS=1 perf record -- relevo-bench render --grid srtm --size 1920x1080 --mode raycast --runs 50")]
    Render {
        #[command(flatten)]
        common: BenchArgs,
        /// Only the grids whose name contains this (`fractal`, `srtm`, or
        /// the bundle's name).
        #[arg(long)]
        grid: Option<String>,
        /// Only this frame size, WIDTHxHEIGHT (1920x1080 or 1280x720).
        #[arg(long)]
        size: Option<String>,
        /// Only the configuration of this name (`raycast`), or those whose
        /// name contains it (`growing`, `pitch`, `classic`, `floor`, …); a reference
        /// left out is still rendered for the others' PSNR, untimed.
        #[arg(long)]
        mode: Option<String>,
        /// Also a bundle's terrain with its drape, as `relevo render` and the
        /// viewer draw it (e.g. out/grenoble.relevo from `scripts/demo`).
        #[arg(long)]
        bundle: Option<PathBuf>,
    },
    /// Vegetation: F1 on the annotated crowns beside an excess-green baseline;
    /// split-and-merge and detection speed beside scikit-image's felzenszwalb.
    #[command(after_help = "Examples:
  relevo-bench veg
  relevo-bench veg --json --runs 3 --max-side 10000")]
    Veg {
        #[command(flatten)]
        common: BenchArgs,
        /// Side of the largest tiled test image (up to 10000).
        #[arg(long, default_value_t = 10000)]
        max_side: usize,
    },
    /// Vegetation on images it was not tuned on: leave each annotated crop
    /// out, choose the options on the others and score it (IoU 0.4 and
    /// 0.5), beside the defaults and the excess-green + local-maximum
    /// baseline; the simulated user's correction loop; the defaults with
    /// marks drawn at random from the truth; the defaults on
    /// contrast-changed copies.
    #[command(after_help = "Examples:
  relevo-bench veg-protocol
  relevo-bench veg-protocol --json
  relevo-bench veg-protocol --rounds-dir rounds   # each round's and drawn set's marks as samples CSV")]
    VegProtocol {
        #[command(flatten)]
        common: BenchArgs,
        /// Write the marks of each crop's correction rounds and drawn sets
        /// there, as samples CSV (`{crop}_round{k}.csv`,
        /// `{crop}_drawn{seed}.csv`), to look at or detect with.
        #[arg(long, value_name = "DIR")]
        rounds_dir: Option<PathBuf>,
    },
    /// The viewer's vegetation on the GPU found (lavapipe without one), at
    /// 1280×720: the seed's tables 4.1–4.5 (billboards against sprites,
    /// culling along a flight, texture sizes, list/blobs/quadtree, large
    /// scenes) beside its figures, and frame time for 1k–1M objects.
    #[command(after_help = "Examples:
  relevo-bench view-vegetation --json --runs 2
  relevo-bench view-vegetation --max-objects 100000")]
    ViewVegetation {
        #[command(flatten)]
        common: BenchArgs,
        /// Largest object count (1k, 10k, 100k, 1M).
        #[arg(long, default_value_t = 1_000_000)]
        max_objects: usize,
    },
    /// Vegetation clusters: draws per frame of the list, blobs and quadtree
    /// (the seed's table 4.4, then 10k–1M objects), selection and bake time.
    #[command(after_help = "Examples:
  relevo-bench clusters
  relevo-bench clusters --json --runs 5 --max-objects 1000000
  relevo-bench clusters --pictures docs/images")]
    Clusters {
        #[command(flatten)]
        common: BenchArgs,
        /// Largest object count of the large-scale runs (10k, 100k, 1M).
        #[arg(long, default_value_t = 1_000_000)]
        max_objects: usize,
        /// Atlas budget of the large-scale bakes, MiB.
        #[arg(long, default_value_t = 256)]
        budget_mib: u64,
        /// Instead of measuring, write the documentation's pictures here.
        #[arg(long, value_name = "DIR")]
        pictures: Option<PathBuf>,
    },
    /// Regression checks on the sample region and Grenoble: bless, check
    /// (unchanged; every grid compared with its reference), diff, beside
    /// `relevo validate` on the same bundle.
    #[command(after_help = "Examples:
  relevo-bench check
  relevo-bench check --json --runs 5")]
    Check(BenchArgs),
    /// The viewer's renderer: frame time of every mode at 1280×720 and
    /// 1920×1080 on the GPU found (lavapipe without one).
    #[command(after_help = "Examples:
  VK_ICD_FILENAMES=/usr/share/vulkan/icd.d/lvp_icd.x86_64.json relevo-bench view --json --runs 3
  relevo-bench view --max-side 2049")]
    View(ViewArgs),
    /// Write the bundles of the viewer's figures (the sample regions, the
    /// 4097² fractal, the sample region with --objects objects) to a
    /// folder, for `relevo-view bench` on a machine with a GPU and no
    /// GDAL; prints the commands to run there.
    #[command(after_help = "Examples:
  relevo-bench view-inputs --out gpu-inputs
  relevo-bench view-inputs --out gpu-inputs --objects 100000")]
    ViewInputs {
        #[command(flatten)]
        common: BenchArgs,
        /// The folder to write.
        #[arg(long)]
        out: PathBuf,
        /// Objects in the dense vegetation scene.
        #[arg(long, default_value_t = 1_000_000)]
        objects: usize,
    },
}

#[derive(Args, Debug)]
struct ViewArgs {
    #[command(flatten)]
    common: BenchArgs,
    /// Largest grid side: 4097 adds a fractal 4097² terrain.
    #[arg(long, default_value_t = 4097)]
    max_side: usize,
}

#[derive(Args, Debug)]
struct BenchArgs {
    /// One JSON object per line instead of text.
    #[arg(long)]
    json: bool,
    /// Runs per figure; the median is reported.
    #[arg(long, default_value_t = 5)]
    runs: usize,
    /// The real inputs (tiles/, dem/, …) that scripts/fetch-data extracts
    /// from their registry packages.
    #[arg(long, env = "RELEVO_SHARED_DATA", default_value_os_t = fetched_data())]
    data: PathBuf,
    /// The Relevo repository (for data/olinda).
    #[arg(long, default_value = ".")]
    repo: PathBuf,
}

/// Where scripts/fetch-data puts the real inputs: `~/.cache/relevo/data`.
fn fetched_data() -> PathBuf {
    std::env::var_os("HOME")
        .map(PathBuf::from)
        .unwrap_or_default()
        .join(".cache/relevo/data")
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    relevo::commands::init_logging(0, false);
    relevo::ingest::gdalio::init();
    let result = match cli.command {
        BenchCommand::View(a) => view::view(
            &a.common.repo,
            &a.common.data,
            a.common.runs.max(1),
            a.max_side,
            a.common.json,
        ),
        BenchCommand::ViewInputs {
            common: a,
            out,
            objects,
        } => view_inputs::run(&a.repo, &a.data, &out, objects),
        BenchCommand::ViewVegetation {
            common: a,
            max_objects,
        } => view_vegetation::run(&a.repo, a.runs.max(1), max_objects, a.json),
        BenchCommand::Clusters {
            common: a,
            max_objects,
            budget_mib,
            pictures,
        } => match pictures {
            Some(dir) => clusters::pictures(&a.repo, &dir),
            None => clusters::clusters(&a.repo, a.runs.max(1), max_objects, budget_mib, a.json),
        },
        BenchCommand::Ingest(a) => bench::ingest(&a.repo, &a.data, a.runs.max(1), a.json),
        BenchCommand::Pyramid {
            common: a,
            max_side,
            pictures,
        } => match pictures {
            Some(dir) => pyramid::picture(&a.repo, &dir),
            None => pyramid::run(&a.repo, a.runs.max(1), max_side, a.json),
        },
        BenchCommand::Slurm { common: a, jobs } => slurm::run(&a.repo, jobs, a.json),
        BenchCommand::Check(a) => check::run(&a.repo, a.runs.max(1), a.json),
        BenchCommand::Render {
            common: a,
            grid,
            size,
            mode,
            bundle,
        } => render::render(
            &a.data,
            a.runs.max(1),
            a.json,
            grid.as_deref(),
            size.as_deref(),
            mode.as_deref(),
            bundle.as_deref(),
        ),
        BenchCommand::Veg {
            common: a,
            max_side,
        } => bench::veg(&a.repo, &a.data, a.runs.max(1), max_side, a.json),
        BenchCommand::VegProtocol {
            common: a,
            rounds_dir,
        } => veg_protocol::run(&a.repo, &a.data, rounds_dir.as_deref(), a.json),
        BenchCommand::Hierarchy {
            common: a,
            max_side,
        } => bench::hierarchy(&a.repo, &a.data, a.runs.max(1), max_side, a.json),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("error: {error:#}");
            ExitCode::FAILURE
        }
    }
}
