//! `relevo-view`: fly over a Relevo bundle as a view-dependent refined mesh
//! or a CPU floating-horizon raycast; `relevo-view render` draws the same
//! frames headless to PNG. Depends on relevo-core only: every terrain
//! computation is core's; this crate owns GPU resources, input and UI.

use clap::{Parser, Subcommand};
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Parser, Debug)]
#[command(
    name = "relevo-view",
    version,
    about = "Fly over a Relevo bundle (refined mesh or floating-horizon raycast); render it headless to PNG.",
    args_conflicts_with_subcommands = true,
    after_help = "Examples:
  relevo-view olinda.relevo
  relevo-view olinda.relevo --objects data/olinda/objects.geojson --camera 290963,9112753,100,35
  relevo-view olinda.relevo --tour 90 --screenshot window.png   # scripted flight, screenshot, exit
  relevo-view region.relevo --tile-cache 256M   # a pyramid (prep --tiled): tiles paged as you fly
  relevo-view region.relevo --mode raycast      # start in raycast mode
  relevo-view render olinda.relevo --mode raycast --size 1920x1080 --out shot.png
  relevo-view render olinda.relevo --mode mesh --tau 1 --wireframe --camera 289000,9111000,400,40,420 --out mesh.png
  relevo-view render alps.relevo --size 7680x4320 --depth depth.f32 --stats stats.json --out big.png
  relevo-view render alps.relevo --max-memory 2G --size 3840x2160 --out shot.png   # refuse what needs more
  relevo-view bench olinda.relevo --size 1920x1080 --json > gpu.jsonl    # frame times on this machine's GPU"
)]
struct Cli {
    /// The bundle or pyramid to open in the window.
    bundle: Option<PathBuf>,
    /// Objects to composite: a GeoJSON placement file (see docs/formats.md).
    #[arg(long, requires = "bundle")]
    objects: Option<PathBuf>,
    /// Start at this camera, X,Y,Z,HEADING[,PITCHdeg][,INCL] (default: the home view).
    #[arg(long, requires = "bundle", allow_hyphen_values = true)]
    camera: Option<String>,
    /// Draw the terrain as mesh, raycast, or a Z-buffer baseline
    /// zbuffer:a … zbuffer:g at first (the M key and the side panel
    /// switch).
    #[arg(long, default_value = "mesh", value_parser = relevo_view::settings::TerrainMode::parse)]
    mode: relevo_view::settings::TerrainMode,
    /// Fly a scripted tour of this many frames (forward, turning), then
    /// save a screenshot of the window to --screenshot and close.
    #[arg(long, requires = "screenshot", value_name = "FRAMES")]
    tour: Option<u32>,
    /// Where the tour's screenshot goes (PNG).
    #[arg(long, requires = "tour")]
    screenshot: Option<PathBuf>,
    /// Most memory the viewer may plan to use, e.g. 512M or 8G (default:
    /// the memory the machine has available, within the process's limits).
    /// A bundle or frame estimated larger is refused before it is loaded.
    #[arg(long, global = true, value_parser = relevo_core::memory::parse_size)]
    max_memory: Option<u64>,
    /// Memory a pyramid's tile cache may hold, e.g. 256M (default 1G): the
    /// least recently used tiles are dropped above it and read again when
    /// needed; the tiles the view needs are kept even above it.
    #[arg(long, global = true, value_parser = relevo_core::memory::parse_size)]
    tile_cache: Option<u64>,
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Render one frame without a window (PNG, depth, figures).
    #[command(after_help = "Examples:
  relevo-view render olinda.relevo --mode raycast --size 1920x1080 --out shot.png
  relevo-view render olinda.relevo --mode mesh --tau 1 --wireframe --camera 289000,9111000,400,40,420 --out mesh.png
  relevo-view render olinda.relevo --objects data/olinda/objects.geojson --hud --stats stats.json --out hud.png
  relevo-view render olinda.relevo --tab samples --samples marks.csv --out samples.png")]
    Render(Box<relevo_view::headless::RenderArgs>),
    /// Time a scripted flight (takeoff, low pass, turn, climb) mode by mode
    /// on this machine's GPU: frame-time percentiles, triangles, impostors,
    /// uploads, the adapter.
    #[command(after_help = "Examples:
  relevo-view bench olinda.relevo                                  # text, 1280×720, 60 frames a leg
  relevo-view bench olinda.relevo --objects data/olinda/objects.geojson --size 1920x1080 --json > gpu.jsonl
  relevo-view bench region.pyramid.relevo --in-flight 2           # the next frame refined while the GPU draws
  relevo-view bench --fractal 16385 --size 1920x1080 --json       # the pyramid benchmark's input, made here without GDAL
  VK_ICD_FILENAMES=/usr/share/vulkan/icd.d/lvp_icd.x86_64.json relevo-view bench alps.relevo --frames 20   # on lavapipe")]
    Bench(relevo_view::bench::BenchArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let _ = tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn")),
        )
        .with_writer(std::io::stderr)
        .try_init();
    if let Some(bytes) = cli.max_memory {
        relevo_core::memory::set_budget(bytes);
    }
    if let Some(bytes) = cli.tile_cache {
        relevo_view::scene::set_tile_cache(bytes);
    }
    let result = match cli.command {
        Some(Command::Render(args)) => relevo_view::headless::run(*args),
        Some(Command::Bench(args)) => relevo_view::bench::run(args),
        None => {
            let tour = cli
                .tour
                .zip(cli.screenshot)
                .map(|(frames, path)| relevo_view::app::Tour::new(frames, path));
            let start = relevo_view::app::Start {
                bundle: cli.bundle,
                objects: cli.objects,
                camera: cli.camera,
                mode: cli.mode,
                tour,
            };
            relevo_view::app::run(start)
        }
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("error: {error:#}");
            ExitCode::FAILURE
        }
    }
}
