//! The `relevo` command line: the argument tree and the dispatch. Each
//! subcommand is one module holding its clap arguments and its `run`.

mod args;
pub mod bake;
mod check;
mod diff;
pub mod export;
mod fill;
mod hierarchy;
mod info;
mod mesh;
mod pad;
mod prep;
mod render;
mod report;
mod stitch;
mod validate;
mod veg;

use anyhow::Result;
use clap::{Parser, Subcommand};

#[derive(Parser, Debug)]
#[command(
    name = "relevo",
    version,
    about = "Terrain data preparation: tiles and imagery in, a self-describing bundle out."
)]
#[command(after_help = "Examples:
  relevo prep data/olinda/REGION.toml --out olinda.relevo
  relevo prep --dem n45e005.tif --image ortho.jpg --out alps.relevo
  relevo stitch a.tif b.tif --overlap blend --out mosaic.tif
  relevo validate olinda.relevo")]
pub struct Cli {
    /// More log output (-v info, -vv debug); RUST_LOG overrides.
    #[arg(short, long, global = true, action = clap::ArgAction::Count)]
    pub verbose: u8,
    /// Only errors.
    #[arg(short, long, global = true)]
    pub quiet: bool,
    /// Most memory a command may plan to use, e.g. 512M or 8G (default:
    /// the memory the machine has available). Work estimated larger is
    /// refused before it starts.
    #[arg(long, global = true, value_parser = relevo_core::memory::parse_size)]
    pub max_memory: Option<u64>,
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Mosaic georeferenced tiles (any GDAL raster, world files, Terrain-RGB) into one GeoTIFF.
    #[command(after_help = "Examples:
  relevo stitch LC08_*_B4.TIF --src-nodata 0 --out red.tif
  relevo stitch n45e005.tif n45e006.tif --t-srs EPSG:32631 --tr 30 -r bilinear --out dem.tif
  relevo stitch fuji.png --encoding terrain-rgb --out fuji.tif
  relevo stitch a.tif b.tif --te 500000 4980000 520000 5000000 --overlap first --out crop.tif")]
    Stitch(stitch::StitchArgs),
    /// Fill no-data holes by natural-neighbour interpolation.
    #[command(after_help = "Examples:
  relevo fill dem.tif --max-hole 5000 --out dem_filled.tif")]
    Fill(fill::FillArgs),
    /// Pad (or resample) a heightfield to (2^n+1)² and write its data mask.
    #[command(after_help = "Examples:
  relevo pad dem.tif --out dem_1025.tif            # also writes dem_1025_mask.tif
  relevo pad dem.tif --resample --out dem_sq.tif --mask-out mask.tif")]
    Pad(pad::PadArgs),
    /// Compute LP object-space errors and bounding-sphere radii of a (2^n+1)² heightfield.
    #[command(after_help = "Examples:
  relevo pad dem.tif --out dem_1025.tif && relevo hierarchy dem_1025.tif --out lp.tif
  relevo hierarchy fuji_513.tif --cell-size 30 --out lp.tif")]
    Hierarchy(hierarchy::HierarchyArgs),
    /// Build a bundle from a REGION.toml, or straight from rasters.
    #[command(after_help = "Examples:
  relevo prep data/olinda/REGION.toml --out olinda.relevo
  relevo prep --dem srtm_ref.tif --out turkey.relevo --json
  relevo prep --dem t1.tif t2.tif --image ortho.tif --bands 3,2,1 --crs EPSG:32633 --out r.relevo --force
  relevo prep --dem dem.tif --image ortho.tif --samples marks.csv --out r.relevo   # with vegetation
  relevo prep --dem alps.tif --terrain-drape --out alps.relevo   # drape tinted and lit from the heights
  relevo prep --dem country.vrt --tiled --out country.relevo      # a pyramid of 513² tiles
  relevo prep --dem county_utm.tif --tiled --out county.relevo    # a projected DEM, read window by window
  relevo prep data/olinda/REGION.toml --tiled --tile-size 32 --out olinda.relevo   # a pyramid with its vegetation and clusters
  relevo prep --dem country.vrt --tiled --resume --out country.relevo   # go on after a kill
  relevo prep --dem county_utm.tif --tiled --plan /shared/plan --jobs 16 --out /shared/county.relevo
  relevo prep --plan /shared/plan --job 3        # one job of the plan, on any machine
  relevo prep --plan /shared/plan --submit slurm --mem 4G --cpus-per-task 4 --time 1:00:00
  relevo prep --plan /shared/plan --status       # each step's jobs done
  relevo prep --plan /shared/plan --finish       # check every job, move the pyramid into place")]
    Prep(prep::PrepArgs),
    /// Export the mesh at an object-space tolerance as glTF (.glb) or OBJ,
    /// of the whole region or a window of it (single grid or pyramid).
    #[command(after_help = "Examples:
  relevo mesh olinda.relevo --max-error 2 --out olinda.glb
  relevo mesh olinda.relevo --max-error 0.5 --format obj --out olinda.obj   # also olinda.mtl, olinda.png
  relevo mesh fuji.relevo --max-error 5 --keep-padding --out fuji.glb
  relevo mesh country.relevo --max-error 1 --window 712000,5000000,716000,5004000 --out part.glb   # a window of a pyramid")]
    Mesh(mesh::MeshArgs),
    /// Export a bundle in formats other clients read: Cesium quantized-mesh terrain.
    #[command(subcommand)]
    Export(export::ExportCommand),
    /// Render a bundle with the CPU floating-horizon raycaster (PNG and depth);
    /// a pyramid's distance bands read its coarser levels farther away.
    #[command(after_help = "Examples:
  relevo render olinda.relevo --camera 290000,9112000,400,45,300 --size 960x540 --out shot.png
  relevo render olinda.relevo --camera 290000,9112000,400,45,300 --depth depth.f32 --bands 2000:4:sub,inf:1 --out shot.png
  relevo render olinda.relevo --camera 290000,9112000,900,45,-35deg --size 1920x1080 --out looking_down.png
  relevo render olinda.relevo --camera 290000,9112000,400,45,300 --mode distorted --out voxel_space.png
  relevo render county.relevo --camera 705000,5020000,3000,60,-10deg --far 8192 --max-cell-px 2 --out far.png   # a pyramid

The pitch (PITCHdeg) tilts the camera for real; the raycaster draws pitches
while every screen row looks forward and needs at most 4 marched lines per
column — about -60deg..60deg at a 60° field of view and 16:9 — and refuses
others, naming the range for that size and field of view. INCL (a bare
number) shifts the projection plane instead, as before pitches existed.")]
    Render(render::RenderArgs),
    /// Vegetation: detect objects in imagery from marked samples; score detections.
    #[command(subcommand)]
    Veg(veg::VegCommand),
    /// (Re)bake a bundle's vegetation clusters: impostors, quadtree views, atlases.
    #[command(after_help = "Examples:
  relevo bake olinda.relevo
  relevo bake olinda.relevo --model forest=conifer --budget-mib 64
  relevo bake olinda.relevo --model forest=models/palm.obj --bands 300:1,1000:4,4000:32
  relevo bake olinda.relevo --json   # the bake report: counts and atlas bytes per depth
  relevo bake county.relevo --budget-mib 128   # a pyramid (prep --tiled): its clusters replaced in place")]
    Bake(bake::BakeArgs),
    /// Describe a bundle.
    #[command(after_help = "Examples:
  relevo info olinda.relevo
  relevo info olinda.relevo --json")]
    Info(info::InfoArgs),
    /// Check a bundle's files, hashes, shapes and invariants; exit 1 on any problem.
    #[command(after_help = "Examples:
  relevo validate olinda.relevo")]
    Validate(validate::ValidateArgs),
    /// Check a bundle against a golden record (exit 0 within tolerance, 1 changed, 2 unusable); --bless writes the record.
    #[command(after_help = "Examples:
  relevo check olinda.relevo --golden golden/olinda.json --bless      # write the record (and golden/olinda.home.png)
  relevo check olinda.relevo --golden golden/olinda.json --junit check.xml --markdown check.md
  relevo check olinda.relevo --golden golden/olinda.json --height-m 0.01 --render-pixels-off 0.01
  relevo check olinda.relevo --golden golden/olinda.json --bless --camera harbour=290963,9112753,300,35,-20deg

Exact by default for everything but renders (see docs/guide.md, \"Testing your region in CI\").")]
    Check(check::CheckArgs),
    /// Compare two bundles: what changed, where and by how much (exit 0 identical, 1 different, 2 unusable).
    #[command(after_help = "Examples:
  relevo diff before.relevo after.relevo
  relevo diff before.relevo after.relevo --threshold-m 1 --images diff/
  relevo diff before.relevo after.relevo --json --camera home=290000,9112000,400,45,300")]
    Diff(diff::DiffArgs),
}

/// A command's own exit status besides 0 and 1 (`relevo check` and `relevo
/// diff`: 1 a difference, 2 inputs that cannot be compared), with its
/// message.
#[derive(Debug)]
pub struct Exit {
    pub code: u8,
    pub message: String,
}

impl Exit {
    pub fn with(code: u8, message: String) -> Exit {
        Exit { code, message }
    }
}

impl std::fmt::Display for Exit {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.message)
    }
}

impl std::error::Error for Exit {}

/// Run the parsed command.
pub fn run(cli: Cli) -> Result<()> {
    if let Some(bytes) = cli.max_memory {
        relevo_core::memory::set_budget(bytes);
    }
    match cli.command {
        Command::Stitch(a) => stitch::run(a),
        Command::Fill(a) => fill::run(a),
        Command::Pad(a) => pad::run(a),
        Command::Hierarchy(a) => hierarchy::run(a),
        Command::Prep(a) => prep::run(a),
        Command::Mesh(a) => mesh::run(a),
        Command::Export(a) => export::run(a),
        Command::Render(a) => render::run(a),
        Command::Veg(a) => veg::run(a),
        Command::Bake(a) => bake::run(a),
        Command::Info(a) => info::run(a),
        Command::Validate(a) => validate::run(a),
        Command::Check(a) => check::run(a),
        Command::Diff(a) => diff::run(a),
    }
}

/// Set up tracing on stderr.
pub fn init_logging(verbose: u8, quiet: bool) {
    let level = match (quiet, verbose) {
        (true, _) => "error",
        (false, 0) => "warn",
        (false, 1) => "info",
        _ => "debug",
    };
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(level));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .try_init();
}
