//! Command-line interface: argument definitions and dispatch.

use crate::gdalio::{self, GridSpec, Resampling};
use crate::prep::prep;
use crate::region::{parse_nodata, DemSection, FillSection, GridSection, ImageSection, Region};
use crate::stitch::{stitch, StitchOptions};
use anyhow::{bail, Context, Result};
use clap::{Args, Parser, Subcommand};
use gdal::raster::GdalDataType;
use relevo_core::bundle::{validate, Bundle};
use relevo_core::grid::{HeightGrid, Squaring};
use relevo_core::raster::encoding::Encoding;
use relevo_core::raster::fill::fill_holes;
use relevo_core::raster::mosaic::Overlap;
use relevo_core::raster::Raster;
use std::path::{Path, PathBuf};

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
    Stitch(StitchArgs),
    /// Fill no-data holes by natural-neighbour interpolation.
    #[command(after_help = "Examples:
  relevo fill dem.tif --max-hole 5000 --out dem_filled.tif")]
    Fill(FillArgs),
    /// Pad (or resample) a heightfield to (2^n+1)² and write its data mask.
    #[command(after_help = "Examples:
  relevo pad dem.tif --out dem_1025.tif            # also writes dem_1025_mask.tif
  relevo pad dem.tif --resample --out dem_sq.tif --mask-out mask.tif")]
    Pad(PadArgs),
    /// Compute LP object-space errors and bounding-sphere radii of a (2^n+1)² heightfield.
    #[command(after_help = "Examples:
  relevo pad dem.tif --out dem_1025.tif && relevo hierarchy dem_1025.tif --out lp.tif
  relevo hierarchy fuji_513.tif --cell-size 30 --out lp.tif")]
    Hierarchy(HierarchyArgs),
    /// Build a bundle from a REGION.toml, or straight from rasters.
    #[command(after_help = "Examples:
  relevo prep data/olinda/REGION.toml --out olinda.relevo
  relevo prep --dem srtm_ref.tif --out turkey.relevo --json
  relevo prep --dem t1.tif t2.tif --image ortho.tif --bands 3,2,1 --crs EPSG:32633 --out r.relevo --force
  relevo prep --dem dem.tif --image ortho.tif --samples marks.csv --out r.relevo   # with vegetation")]
    Prep(PrepArgs),
    /// Export the mesh at an object-space tolerance as glTF (.glb) or OBJ.
    #[command(after_help = "Examples:
  relevo mesh olinda.relevo --max-error 2 --out olinda.glb
  relevo mesh olinda.relevo --max-error 0.5 --format obj --out olinda.obj   # also olinda.mtl, olinda.png
  relevo mesh fuji.relevo --max-error 5 --keep-padding --out fuji.glb")]
    Mesh(MeshArgs),
    /// Render a bundle with the CPU floating-horizon raycaster (PNG and depth).
    #[command(after_help = "Examples:
  relevo render olinda.relevo --camera 290000,9112000,400,45,300 --size 960x540 --out shot.png
  relevo render olinda.relevo --camera 290000,9112000,400,45,300 --depth depth.f32 --bands 2000:4:sub,inf:1 --out shot.png
  relevo render olinda.relevo --camera 290000,9112000,400,45,300 --mode distorted --out voxel_space.png")]
    Render(RenderArgs),
    /// Vegetation: detect objects in imagery from marked samples; score detections.
    #[command(subcommand)]
    Veg(VegCommand),
    /// Describe a bundle.
    #[command(after_help = "Examples:
  relevo info olinda.relevo
  relevo info olinda.relevo --json")]
    Info {
        /// The bundle to describe.
        bundle: PathBuf,
        /// Print the whole manifest as JSON.
        #[arg(long)]
        json: bool,
    },
    /// Measure performance against reference tools (release builds only).
    #[command(subcommand)]
    Bench(BenchCommand),
    /// Check a bundle's files, hashes, shapes and invariants; exit 1 on any problem.
    #[command(after_help = "Examples:
  relevo validate olinda.relevo")]
    Validate {
        /// The bundle to check.
        bundle: PathBuf,
    },
}

#[derive(Subcommand, Debug)]
pub enum VegCommand {
    /// Split-and-merge the image, learn Haar signatures from the samples,
    /// classify every region and write the vegetation objects.
    #[command(
        after_help = "Samples: a semicolon CSV `class;xmin;ymin;xmax;ymax` of pixel rectangles, or
GeoJSON polygons with a `class` property in the image CRS. Samples of the
negative class (default `other`) are counter-examples; every other class is
vegetation.

Examples:
  relevo veg detect ortho.tif --samples marks.csv --out trees.csv --gpkg trees.gpkg
  relevo veg detect crop.png --pixel-size 0.1 --samples marks.csv --out trees.csv --overlay check.png
  relevo veg detect landsat.tif --bands 3,2,1 --stretch 1,99 --samples forest.geojson \\
      --density 150 --labels regions.tif --out forest.csv"
    )]
    Detect(Box<VegDetectArgs>),
    /// Precision, recall and F1 of detections against truth boxes (pixels).
    #[command(
        after_help = "A detection is a true positive when its centre falls inside a truth box not
yet matched, taking detections from the highest score down.

Examples:
  relevo veg eval --detections trees.csv --truth crop.xml
  relevo veg eval --detections trees.csv --truth boxes.csv --json"
    )]
    Eval {
        /// Database written by `veg detect` (id;x;y;class;size;score).
        #[arg(long)]
        detections: PathBuf,
        /// Pascal VOC XML, or CSV lines xmin,ymin,xmax,ymax.
        #[arg(long)]
        truth: PathBuf,
        /// Print JSON.
        #[arg(long)]
        json: bool,
    },
}

#[derive(Args, Debug)]
pub struct VegDetectArgs {
    /// The image (anything GDAL reads).
    pub image: PathBuf,
    /// Marked samples: .csv (pixel rectangles) or .geojson (polygons).
    #[arg(long)]
    pub samples: PathBuf,
    /// Bands to analyse, 1-based (1 to 4), e.g. 3,2,1 or 1,2,3,4. Default: the first three.
    #[arg(long, value_delimiter = ',')]
    pub bands: Option<Vec<usize>>,
    /// Percentiles LOW,HIGH stretched to 0..255 (default: none for 8-bit, 2,98 otherwise).
    #[arg(long, value_name = "LOW,HIGH", value_parser = parse_percentiles)]
    pub stretch: Option<[f64; 2]>,
    /// Ground size of a pixel in metres, for images that are not georeferenced.
    #[arg(long, allow_negative_numbers = true)]
    pub pixel_size: Option<f64>,
    /// Largest brightness standard deviation in a region (8-bit units).
    #[arg(long, allow_negative_numbers = true)]
    pub brightness_std: Option<f32>,
    /// Largest chroma standard deviation in a region (8-bit units).
    #[arg(long, allow_negative_numbers = true)]
    pub chroma_std: Option<f32>,
    /// Regions smaller than this (pixels) join their most similar neighbour.
    #[arg(long)]
    pub min_region: Option<u32>,
    /// Side of the smallest split block, pixels (1, 2, 4, …, 64).
    #[arg(long)]
    pub min_block: Option<u32>,
    /// Smallest window side (pixels) a region's signature covers.
    #[arg(long)]
    pub window: Option<u32>,
    /// Nearest learnt signatures per class a region's distance averages.
    #[arg(long)]
    pub neighbours: Option<usize>,
    /// Class of counter-examples.
    #[arg(long)]
    pub negative: Option<String>,
    /// Crowns (fine imagery) or fill (coarse imagery); auto picks by pixel size.
    #[arg(long, value_enum)]
    pub mode: Option<crate::veg::Mode>,
    /// Smallest distance between crown centres, metres.
    #[arg(long, allow_negative_numbers = true)]
    pub crown_spacing: Option<f64>,
    /// Smallest crown radius kept, metres.
    #[arg(long, allow_negative_numbers = true)]
    pub crown_min_radius: Option<f64>,
    /// Fill mode: objects per hectare.
    #[arg(long, allow_negative_numbers = true)]
    pub density: Option<f64>,
    /// The database (semicolon CSV).
    #[arg(long, short)]
    pub out: PathBuf,
    /// Also write the objects as a GeoPackage.
    #[arg(long)]
    pub gpkg: Option<PathBuf>,
    /// Also write region and class labels as a GeoTIFF.
    #[arg(long)]
    pub labels: Option<PathBuf>,
    /// Also write a PNG of regions and objects over the image.
    #[arg(long)]
    pub overlay: Option<PathBuf>,
    /// Print a JSON report.
    #[arg(long)]
    pub json: bool,
    /// Replace existing outputs.
    #[arg(long)]
    pub force: bool,
}

impl VegDetectArgs {
    /// The flags given, over the defaults.
    pub fn options(&self) -> crate::veg::VegOptions {
        let mut o = crate::veg::VegOptions::default();
        macro_rules! set {
            ($($flag:ident => $field:ident),*) => {$(
                if let Some(v) = self.$flag.clone() { o.$field = v; }
            )*};
        }
        set!(brightness_std => brightness_std, chroma_std => chroma_std,
             min_region => min_region_px, min_block => min_block_px, window => window_px, neighbours => neighbours, negative => negative_class,
             mode => mode, crown_spacing => crown_spacing_m,
             crown_min_radius => crown_min_radius_m, density => density_per_ha);
        o
    }
}

#[derive(Subcommand, Debug)]
pub enum BenchCommand {
    /// `prep` on the sample region; `stitch` on the Landsat overlap beside gdalwarp.
    #[command(after_help = "Examples:
  relevo bench ingest
  relevo bench ingest --json --runs 7 --data ../shared/data")]
    Ingest(BenchArgs),
    /// LP errors and radii beside @mapbox/martini; view-dependent refinement.
    #[command(after_help = "Examples:
  relevo bench hierarchy --json
  relevo bench hierarchy --max-side 8193 --runs 3")]
    Hierarchy {
        #[command(flatten)]
        common: BenchArgs,
        /// Largest fractal grid side to run (257, 1025, 4097, 8193).
        #[arg(long, default_value_t = 4097)]
        max_side: usize,
    },
    /// The floating-horizon raycast: 1920×1080, far 1024, 8 headings, each configuration.
    #[command(after_help = "Examples:
  relevo bench render
  relevo bench render --json --runs 3")]
    Render(BenchArgs),
    /// Vegetation: F1 on the annotated crowns beside an excess-green baseline;
    /// split-and-merge and detection speed beside scikit-image's felzenszwalb.
    #[command(after_help = "Examples:
  relevo bench veg
  relevo bench veg --json --runs 3 --max-side 10000")]
    Veg {
        #[command(flatten)]
        common: BenchArgs,
        /// Side of the largest tiled test image (up to 10000).
        #[arg(long, default_value_t = 10000)]
        max_side: usize,
    },
}

#[derive(Args, Debug)]
pub struct BenchArgs {
    /// One JSON object per line instead of text.
    #[arg(long)]
    pub json: bool,
    /// Runs per figure; the median is reported.
    #[arg(long, default_value_t = 5)]
    pub runs: usize,
    /// The shared real-data folder (tiles/, dem/, …).
    #[arg(long, env = "RELEVO_SHARED_DATA", default_value = "../shared/data")]
    pub data: PathBuf,
    /// The Relevo repository (for data/olinda).
    #[arg(long, default_value = ".")]
    pub repo: PathBuf,
}

#[derive(Args, Debug)]
pub struct RenderArgs {
    /// The bundle to render.
    pub bundle: PathBuf,
    /// Eye easting, northing (bundle CRS), height (m), heading (° clockwise
    /// from north) and incl (projection-plane shift: the screen row, in pixels
    /// from the bottom, of the horizon; larger looks further down).
    #[arg(
        long,
        value_delimiter = ',',
        allow_negative_numbers = true,
        value_name = "X,Y,Z,HEADING[,INCL]",
        required = true
    )]
    pub camera: Vec<f64>,
    /// Horizontal field of view, degrees.
    #[arg(long, default_value_t = 60.0)]
    pub fov: f64,
    /// Image size, WIDTHxHEIGHT.
    #[arg(long, default_value = "960x540", value_parser = parse_size)]
    pub size: [u32; 2],
    /// Far plane, in grid cells.
    #[arg(long, default_value_t = 1024.0)]
    pub far: f64,
    /// Distortion-free raycast, or the voxel-space shortcuts as a baseline.
    #[arg(long, value_enum, default_value_t = RenderMode::Raycast)]
    pub mode: RenderMode,
    /// 16.16 fixed-point inner loop instead of floating point.
    #[arg(long)]
    pub fixed: bool,
    /// Distance bands UNTIL_M:SLICES_PER_CELL[:sub], e.g. 3000:4:sub,inf:1 (sub = sub-voxel bilinear).
    #[arg(long, value_parser = crate::render::parse_bands)]
    pub bands: Option<std::vec::Vec<relevo_core::horizon::Band>>,
    /// Sample prefiltered colour levels by slice footprint (anti-aliasing).
    #[arg(long)]
    pub prefilter: bool,
    /// Bake a hillshade: sun AZIMUTH,ELEVATION in degrees.
    #[arg(long, value_delimiter = ',', value_name = "AZIMUTH,ELEVATION")]
    pub hillshade: Option<Vec<f64>>,
    /// Also write the depth buffer: raw little-endian f32, row-major, top row first, [0, 1].
    #[arg(long)]
    pub depth: Option<PathBuf>,
    /// Output PNG.
    #[arg(long, short)]
    pub out: PathBuf,
    /// Replace existing outputs.
    #[arg(long)]
    pub force: bool,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum RenderMode {
    Raycast,
    Distorted,
}

/// `LOW,HIGH` percentiles with 0 ≤ LOW < HIGH ≤ 100.
fn parse_percentiles(text: &str) -> Result<[f64; 2], String> {
    let values: Vec<f64> = text
        .split(',')
        .map(|v| v.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("{text:?} is not two numbers"))?;
    match values[..] {
        [lo, hi] if (0.0..100.0).contains(&lo) && lo < hi && hi <= 100.0 => Ok([lo, hi]),
        _ => Err("--stretch takes LOW,HIGH percentiles with 0 <= LOW < HIGH <= 100".into()),
    }
}

fn parse_size(text: &str) -> Result<[u32; 2], String> {
    let (w, h) = text
        .split_once('x')
        .ok_or_else(|| format!("{text:?}: expected WIDTHxHEIGHT"))?;
    let parse = |v: &str| v.parse::<u32>().ok().filter(|&v| (1..=16384).contains(&v));
    match (parse(w), parse(h)) {
        (Some(w), Some(h)) => Ok([w, h]),
        _ => Err(format!("{text:?}: expected WIDTHxHEIGHT, each 1..=16384")),
    }
}

#[derive(Args, Debug)]
pub struct HierarchyArgs {
    /// Square (2^n+1)² heights in metres, e.g. from `relevo pad`.
    pub input: PathBuf,
    /// Output GeoTIFF: band 1 error δ, band 2 radius r, metres.
    #[arg(long, short)]
    pub out: PathBuf,
    /// Vertex spacing in metres; default: the input's cell size.
    #[arg(long)]
    pub cell_size: Option<f64>,
    /// Replace existing outputs.
    #[arg(long)]
    pub force: bool,
}

#[derive(Args, Debug)]
pub struct MeshArgs {
    /// The bundle to mesh.
    pub bundle: PathBuf,
    /// Largest vertical error left, metres.
    #[arg(long)]
    pub max_error: f32,
    /// Output format; default: from the output's extension.
    #[arg(long, value_enum)]
    pub format: Option<MeshFormat>,
    /// Output .glb or .obj (with .mtl and .png beside it).
    #[arg(long, short)]
    pub out: PathBuf,
    /// Mesh the padding and voids too (as martini does), ignoring the mask.
    #[arg(long)]
    pub keep_padding: bool,
    /// Replace existing outputs.
    #[arg(long)]
    pub force: bool,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq)]
pub enum MeshFormat {
    Glb,
    Obj,
}

#[derive(Args, Debug)]
pub struct StitchArgs {
    /// Input tiles, in priority order for --overlap first/last.
    #[arg(required = true)]
    pub tiles: Vec<PathBuf>,
    /// Output GeoTIFF.
    #[arg(long, short)]
    pub out: PathBuf,
    /// Target CRS (EPSG:n, WKT, PROJ); default: the first tile's.
    #[arg(long = "t-srs")]
    pub t_srs: Option<String>,
    /// Target cell size: one value for square cells, or X,Y.
    #[arg(long, value_delimiter = ',', value_name = "X[,Y]")]
    pub tr: Option<Vec<f64>>,
    /// Target extent in target CRS units.
    #[arg(long, num_args = 4, value_names = ["XMIN", "YMIN", "XMAX", "YMAX"], allow_negative_numbers = true)]
    pub te: Option<Vec<f64>>,
    #[command(flatten)]
    pub common: TileArgs,
    /// No-data value written to the output.
    #[arg(long, value_parser = parse_nodata, allow_negative_numbers = true)]
    pub dst_nodata: Option<f64>,
    /// Bands to keep, 1-based (e.g. 3,2,1).
    #[arg(long, value_delimiter = ',')]
    pub bands: Option<Vec<usize>>,
    /// Replace an existing output.
    #[arg(long)]
    pub force: bool,
}

/// Options shared by every command that reads tiles.
#[derive(Args, Debug, Clone)]
pub struct TileArgs {
    /// Resampling kernel when tiles are warped.
    #[arg(long, short = 'r', value_enum, default_value_t = Resampling::Nearest)]
    pub resampling: Resampling,
    /// Source no-data value (a number or nan), overriding the files'.
    #[arg(long, value_parser = parse_nodata, allow_negative_numbers = true)]
    pub src_nodata: Option<f64>,
    /// How overlapping tiles combine.
    #[arg(long, value_enum, default_value_t = OverlapArg::Blend)]
    pub overlap: OverlapArg,
    /// How tiles encode heights.
    #[arg(long, value_enum, default_value_t = EncodingArg::Plain)]
    pub encoding: EncodingArg,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum OverlapArg {
    First,
    Last,
    Blend,
}

impl From<OverlapArg> for Overlap {
    fn from(o: OverlapArg) -> Overlap {
        match o {
            OverlapArg::First => Overlap::First,
            OverlapArg::Last => Overlap::Last,
            OverlapArg::Blend => Overlap::Blend,
        }
    }
}

#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum EncodingArg {
    Plain,
    TerrainRgb,
    Terrarium,
}

impl From<EncodingArg> for Encoding {
    fn from(e: EncodingArg) -> Encoding {
        match e {
            EncodingArg::Plain => Encoding::Plain,
            EncodingArg::TerrainRgb => Encoding::TerrainRgb,
            EncodingArg::Terrarium => Encoding::Terrarium,
        }
    }
}

#[derive(Args, Debug)]
pub struct FillArgs {
    /// Heights with no-data holes (band 1 is used).
    pub input: PathBuf,
    /// Output GeoTIFF.
    #[arg(long, short)]
    pub out: PathBuf,
    /// Largest hole filled, in cells; larger holes stay no-data.
    #[arg(long, default_value_t = FillSection::default().max_hole_cells)]
    pub max_hole: usize,
    /// Source no-data value (a number or nan), overriding the file's.
    #[arg(long, value_parser = parse_nodata, allow_negative_numbers = true)]
    pub src_nodata: Option<f64>,
    /// Replace existing outputs.
    #[arg(long)]
    pub force: bool,
}

#[derive(Args, Debug)]
pub struct PadArgs {
    /// Heights to square (band 1 is used).
    pub input: PathBuf,
    /// Output heights, (2^n+1)², Float32.
    #[arg(long, short)]
    pub out: PathBuf,
    /// Output mask (1 = data, 0 = padding or no-data); default: OUT with _mask before the extension.
    #[arg(long)]
    pub mask_out: Option<PathBuf>,
    /// Resample to the nearest 2^n+1 instead of padding.
    #[arg(long)]
    pub resample: bool,
    /// Source no-data value (a number or nan), overriding the file's.
    #[arg(long, value_parser = parse_nodata, allow_negative_numbers = true)]
    pub src_nodata: Option<f64>,
    /// Replace existing outputs.
    #[arg(long)]
    pub force: bool,
}

#[derive(Args, Debug)]
pub struct PrepArgs {
    /// REGION.toml describing the inputs (or give --dem instead).
    #[arg(required_unless_present = "dem", conflicts_with_all = ["dem", "image"])]
    pub region: Option<PathBuf>,
    /// Output bundle directory, conventionally NAME.relevo.
    #[arg(long, short)]
    pub out: PathBuf,
    /// DEM tiles (quick form, without a REGION.toml).
    #[arg(long, num_args = 1..)]
    pub dem: Vec<PathBuf>,
    /// Imagery tiles to drape (quick form).
    #[arg(long, num_args = 1..)]
    pub image: Vec<PathBuf>,
    /// Image bands shown as red, green, blue (quick form), e.g. 3,2,1.
    #[arg(long, value_delimiter = ',', value_name = "R,G,B")]
    pub bands: Option<Vec<usize>>,
    /// Percentiles LOW,HIGH of each image band stretched to 0..255 (quick form).
    #[arg(long, value_name = "LOW,HIGH", value_parser = parse_percentiles, requires = "image")]
    pub stretch: Option<[f64; 2]>,
    /// Vegetation samples marked on the first image (quick form; see `veg detect`).
    #[arg(long, requires = "image")]
    pub samples: Option<PathBuf>,
    /// DEM encoding (quick form).
    #[arg(long, value_enum, default_value_t = EncodingArg::Plain)]
    pub encoding: EncodingArg,
    /// Bundle CRS (quick form).
    #[arg(long)]
    pub crs: Option<String>,
    /// Grid spacing in metres (quick form).
    #[arg(long)]
    pub cell_size: Option<f64>,
    /// Factor from the DEM's vertical unit to metres (quick form).
    #[arg(long, default_value_t = 1.0)]
    pub z_scale: f64,
    /// DEM no-data value, a number or nan (quick form).
    #[arg(long, value_parser = parse_nodata, allow_negative_numbers = true)]
    pub src_nodata: Option<f64>,
    /// Replace an existing bundle.
    #[arg(long)]
    pub force: bool,
    /// Print a JSON summary on stdout.
    #[arg(long)]
    pub json: bool,
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

pub fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Stitch(a) => run_stitch(a),
        Command::Fill(a) => run_fill(a),
        Command::Pad(a) => run_pad(a),
        Command::Prep(a) => run_prep(a),
        Command::Mesh(a) => run_mesh(a),
        Command::Render(a) => run_render(a),
        Command::Hierarchy(a) => run_hierarchy(a),
        Command::Info { bundle, json } => run_info(&bundle, json),
        Command::Veg(VegCommand::Detect(a)) => run_veg_detect(a),
        Command::Veg(VegCommand::Eval {
            detections,
            truth,
            json,
        }) => run_veg_eval(&detections, &truth, json),
        Command::Validate { bundle } => run_validate(&bundle),
        Command::Bench(BenchCommand::Ingest(a)) => {
            crate::bench::ingest(&a.repo, &a.data, a.runs.max(1), a.json)
        }
        Command::Bench(BenchCommand::Render(a)) => {
            crate::bench::render(&a.data, a.runs.max(1), a.json)
        }
        Command::Bench(BenchCommand::Veg {
            common: a,
            max_side,
        }) => crate::bench::veg(&a.repo, &a.data, a.runs.max(1), max_side, a.json),
        Command::Bench(BenchCommand::Hierarchy {
            common: a,
            max_side,
        }) => crate::bench::hierarchy(&a.repo, &a.data, a.runs.max(1), max_side, a.json),
    }
}

/// Refuse to overwrite `out` without `force`, and name an unwritable folder early.
fn check_output(out: &Path, force: bool) -> Result<()> {
    if out.exists() && !force {
        bail!(
            "{}: already exists (pass --force to replace it)",
            out.display()
        );
    }
    check_folder(out)
}

/// Name a missing output folder before any work is done.
fn check_folder(out: &Path) -> Result<()> {
    let parent = out
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    if !parent.is_dir() {
        bail!(
            "{}: cannot write, folder {} does not exist",
            out.display(),
            parent.display()
        );
    }
    Ok(())
}

fn run_stitch(a: StitchArgs) -> Result<()> {
    check_output(&a.out, a.force)?;
    if a.tr.as_ref().is_some_and(|v| v.len() > 2) {
        bail!("--tr takes X or X,Y");
    }
    let resolution = a.tr.map(|v| (v[0], *v.get(1).unwrap_or(&v[0])));
    let opts = StitchOptions {
        target_crs: a.t_srs,
        resolution,
        extent: a.te.map(|v| [v[0], v[1], v[2], v[3]]),
        resampling: a.common.resampling,
        src_nodata: a.common.src_nodata,
        dst_nodata: a.dst_nodata,
        overlap: a.common.overlap.into(),
        encoding: a.common.encoding.into(),
        bands: a.bands,
    };
    let m = stitch(&a.tiles, &opts)?;
    gdalio::write_geotiff(&a.out, &m.raster, &m.grid, m.band_type, Some(m.nodata))?;
    eprintln!(
        "{}: {}×{} cells, {} band(s), {} of {} cells with data",
        a.out.display(),
        m.grid.width,
        m.grid.height,
        m.raster.bands,
        m.raster.valid_count(),
        m.raster.cells()
    );
    Ok(())
}

/// Read a one-band raster with its grid.
fn read_single(
    path: &Path,
    src_nodata: Option<f64>,
) -> Result<(Raster, GridSpec, GdalDataType, Option<f64>)> {
    let source = gdalio::open(path)?;
    let nodata = src_nodata.or(source.nodata);
    let mut raster = source.read(nodata)?;
    if raster.bands > 1 {
        tracing::warn!("{}: using band 1 of {}", path.display(), raster.bands);
        raster = Raster::from_data(raster.width, raster.height, 1, raster.band(0).to_vec());
    }
    let grid = GridSpec {
        crs_wkt: source
            .srs
            .as_ref()
            .map(crate::crs::to_wkt)
            .transpose()?
            .unwrap_or_default(),
        geotransform: source
            .geotransform
            .unwrap_or(relevo_core::geo::GeoTransform::IDENTITY),
        width: source.width,
        height: source.height,
    };
    if raster.valid_count() == 0 {
        bail!("{}: no valid data (every cell is no-data)", path.display());
    }
    Ok((raster, grid, source.band_type, nodata))
}

fn run_fill(a: FillArgs) -> Result<()> {
    check_output(&a.out, a.force)?;
    let (mut raster, grid, band_type, nodata) = read_single(&a.input, a.src_nodata)?;
    let (w, h) = (raster.width, raster.height);
    let report = fill_holes(raster.band_mut(0), w, h, a.max_hole);
    let band_type = if gdalio::is_float(band_type) {
        band_type
    } else {
        GdalDataType::Float32
    };
    let nodata = nodata.unwrap_or_else(|| gdalio::default_nodata(band_type));
    gdalio::write_geotiff(&a.out, &raster, &grid, band_type, Some(nodata))?;
    eprintln!(
        "{}: filled {} hole(s), {} cells; left {} hole(s), {} cells (larger than {} cells or open to the edge)",
        a.out.display(),
        report.holes_filled,
        report.cells_filled,
        report.holes_left,
        report.cells_left,
        a.max_hole
    );
    Ok(())
}

fn run_pad(a: PadArgs) -> Result<()> {
    let mask_out = a.mask_out.clone().unwrap_or_else(|| {
        let stem = a
            .out
            .file_stem()
            .map(|s| s.to_string_lossy().to_string())
            .unwrap_or_default();
        a.out.with_file_name(format!("{stem}_mask.tif"))
    });
    check_output(&a.out, a.force)?;
    check_output(&mask_out, a.force)?;
    let (raster, grid, _, _) = read_single(&a.input, a.src_nodata)?;
    if raster.width < 2 || raster.height < 2 {
        bail!(
            "{}: {}×{} cells; a heightfield needs at least 2×2",
            a.input.display(),
            raster.width,
            raster.height
        );
    }
    let squaring = if a.resample {
        Squaring::Resample
    } else {
        Squaring::Pad
    };
    let g = HeightGrid::square(
        raster.band(0),
        raster.width,
        raster.height,
        grid.geotransform,
        squaring,
    );
    let spec = GridSpec {
        geotransform: g.geotransform,
        width: g.side,
        height: g.side,
        ..grid
    };
    let heights = Raster::from_data(
        g.side,
        g.side,
        1,
        g.heights.iter().map(|&h| h as f64).collect(),
    );
    let mask = Raster::from_data(
        g.side,
        g.side,
        1,
        g.mask.iter().map(|&m| m as f64).collect(),
    );
    gdalio::write_geotiff(&a.out, &heights, &spec, GdalDataType::Float32, None)?;
    gdalio::write_geotiff(&mask_out, &mask, &spec, GdalDataType::UInt8, None)?;
    eprintln!(
        "{}: {}×{} ({} of {} vertices with data); mask in {}",
        a.out.display(),
        g.side,
        g.side,
        g.valid_count(),
        g.side * g.side,
        mask_out.display()
    );
    Ok(())
}

fn run_prep(a: PrepArgs) -> Result<()> {
    if a.bands.as_ref().is_some_and(|b| b.len() != 3) {
        bail!("--bands takes three bands R,G,B, e.g. 3,2,1");
    }
    let region = match &a.region {
        Some(path) => Region::load(path)?,
        None => {
            let region = Region {
                name: None,
                crs: a.crs,
                cell_size_m: a.cell_size,
                z_scale: a.z_scale,
                dem: DemSection {
                    files: a.dem,
                    encoding: a.encoding.into(),
                    src_nodata: a.src_nodata.map(crate::region::NoData::Value),
                    overlap: Overlap::Blend,
                    resampling: Resampling::Bilinear,
                },
                fill: FillSection::default(),
                grid: GridSection::default(),
                image: (!a.image.is_empty()).then(|| ImageSection {
                    files: a.image,
                    bands: a.bands.map(|b| [b[0], b[1], b[2]]),
                    src_nodata: None,
                    overlap: Overlap::Blend,
                    resampling: Resampling::Bilinear,
                    stretch: a.stretch,
                }),
                vegetation: a.samples.map(|samples| crate::region::VegetationSection {
                    samples,
                    options: Default::default(),
                }),
            };
            region.check()?;
            region
        }
    };
    check_folder(&a.out)?;
    let summary = prep(&region, &a.out, a.force)?;
    if a.json {
        println!("{}", serde_json::to_string(&summary)?);
    } else {
        let total: f64 = summary.timings.iter().map(|t| t.ms).sum();
        println!(
            "{}: {}×{} grid, {:.2} m cells, {} vertices with data, heights {:.1}..{:.1} m, {:.0} ms",
            summary.bundle.display(),
            summary.side,
            summary.side,
            summary.cell_size_m,
            summary.valid_vertices,
            summary.height_range_m[0],
            summary.height_range_m[1],
            total
        );
    }
    Ok(())
}

fn run_render(a: RenderArgs) -> Result<()> {
    use crate::render;
    check_output(&a.out, a.force)?;
    if let Some(d) = &a.depth {
        check_output(d, a.force)?;
    }
    if !(a.fov > 0.0 && a.fov < 179.0) {
        bail!("--fov must be between 0 and 179 degrees, got {}", a.fov);
    }
    if a.far.is_nan() || a.far < 2.0 {
        bail!("--far must be at least 2 cells, got {}", a.far);
    }
    if !(4..=5).contains(&a.camera.len()) {
        bail!(
            "--camera takes X,Y,Z,HEADING[,INCL], got {} value(s)",
            a.camera.len()
        );
    }
    if a.hillshade.as_ref().is_some_and(|h| h.len() != 2) {
        bail!("--hillshade takes AZIMUTH,ELEVATION");
    }
    let bundle = Bundle::open(&a.bundle)?;
    let view = render::View {
        eye: [a.camera[0], a.camera[1], a.camera[2]],
        heading_deg: a.camera[3],
        incl_px: a.camera.get(4).copied(),
        fov_x_deg: a.fov,
        size: a.size,
        far_cells: a.far,
    };
    let mode = match a.mode {
        RenderMode::Raycast => relevo_core::horizon::Mode::Raycast,
        RenderMode::Distorted => relevo_core::horizon::Mode::Distorted,
    };
    let options = render::options(mode, a.fixed, a.bands, a.prefilter)?;
    let hillshade = a.hillshade.map(|v| [v[0], v[1]]);
    let frame = render::render_bundle(&bundle, &view, &options, hillshade)?;
    render::write_png(&a.out, &frame)?;
    if let Some(d) = &a.depth {
        crate::gdalio::write_atomic(d, bytemuck::cast_slice(&frame.depth))?;
    }
    let s = frame.steps;
    eprintln!(
        "{}: {}×{} in {:.1} ms (setup {:.1}, march {:.1}, output {:.1})",
        a.out.display(),
        frame.width,
        frame.height,
        s.setup_ms + s.march_ms + s.output_ms,
        s.setup_ms,
        s.march_ms,
        s.output_ms
    );
    Ok(())
}

fn run_hierarchy(a: HierarchyArgs) -> Result<()> {
    check_output(&a.out, a.force)?;
    let (raster, grid, _, _) = read_single(&a.input, None)?;
    let side = raster.width;
    if raster.height != side || side < 3 || !(side - 1).is_power_of_two() {
        bail!(
            "{}: {}×{} cells; the hierarchy needs a square (2^n+1)² grid (run `relevo pad` first)",
            a.input.display(),
            raster.width,
            raster.height
        );
    }
    if raster.valid_count() != raster.cells() {
        bail!(
            "{}: has no-data cells; fill or pad it first",
            a.input.display()
        );
    }
    let (cx, cy) = grid.geotransform.cell_size();
    let cell = match a.cell_size {
        Some(c) if c.is_finite() && c > 0.0 => c,
        Some(c) => bail!("--cell-size must be positive, got {c}"),
        None if (cx - cy).abs() <= 1e-9 * cx => cx,
        None => bail!(
            "{}: cells are {cx} × {cy}, not square; pass --cell-size",
            a.input.display()
        ),
    };
    let heights: Vec<f32> = raster.band(0).iter().map(|&v| v as f32).collect();
    let h = relevo_core::lp::Hierarchy::compute(&heights, side, cell);
    let data = h
        .error_radius
        .iter()
        .map(|e| e[0] as f64)
        .chain(h.error_radius.iter().map(|e| e[1] as f64))
        .collect();
    let out = Raster::from_data(side, side, 2, data);
    gdalio::write_geotiff(&a.out, &out, &grid, GdalDataType::Float32, None)?;
    let max_error = h.error_radius.iter().map(|e| e[0]).fold(0.0, f32::max);
    eprintln!(
        "{}: {side}×{side} vertices, largest error {max_error:.3} m",
        a.out.display()
    );
    Ok(())
}

fn run_mesh(a: MeshArgs) -> Result<()> {
    use crate::mesh;
    let format = match a.format {
        Some(f) => f,
        None => match a
            .out
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase)
            .as_deref()
        {
            Some("glb") => MeshFormat::Glb,
            Some("obj") => MeshFormat::Obj,
            _ => bail!(
                "{}: cannot tell the format from the extension; pass --format glb|obj",
                a.out.display()
            ),
        },
    };
    if !(a.max_error.is_finite() && a.max_error >= 0.0) {
        bail!(
            "--max-error must be a non-negative number of metres, got {}",
            a.max_error
        );
    }
    check_output(&a.out, a.force)?;
    let bundle = Bundle::open(&a.bundle)?;
    let m = mesh::build(&bundle, a.max_error, a.keep_padding)?;
    match format {
        MeshFormat::Glb => {
            gdalio::write_atomic(&a.out, &mesh::to_glb(&m, &bundle.manifest.crs.wkt)?)?
        }
        MeshFormat::Obj => {
            let stem = a
                .out
                .file_stem()
                .map(|s| s.to_string_lossy().to_string())
                .unwrap_or_else(|| "mesh".into());
            if let Some(png) = &m.texture_png {
                gdalio::write_atomic(&a.out.with_file_name(format!("{stem}.png")), png)?;
                let mtl = format!("newmtl drape\nKd 1 1 1\nmap_Kd {stem}.png\n");
                gdalio::write_atomic(&a.out.with_file_name(format!("{stem}.mtl")), mtl.as_bytes())?;
            }
            gdalio::write_atomic(
                &a.out,
                &mesh::to_obj(&m, m.texture_png.as_ref().map(|_| stem.as_str())),
            )?;
        }
    }
    eprintln!(
        "{}: {} vertices, {} triangles at {} m",
        a.out.display(),
        m.positions.len(),
        m.triangles.len(),
        a.max_error
    );
    Ok(())
}

fn run_veg_detect(a: Box<VegDetectArgs>) -> Result<()> {
    use crate::veg;
    let outputs: Vec<&PathBuf> = std::iter::once(&a.out)
        .chain(a.gpkg.iter())
        .chain(a.labels.iter())
        .chain(a.overlay.iter())
        .collect();
    for path in &outputs {
        if path.exists() && !a.force {
            bail!("{}: exists; pass --force to replace it", path.display());
        }
        check_folder(path)?;
    }
    let image = veg::VegImage::read(&a.image, a.bands.as_deref(), a.stretch, a.pixel_size)?;
    let samples = veg::read_samples(
        &a.samples,
        image.geotransform,
        image.image.width,
        image.image.height,
    )?;
    let options = a.options();
    let extraction = veg::extract(&image, &samples, &options)
        .with_context(|| format!("{}", a.image.display()))?;
    veg::write_csv(&a.out, &extraction.objects)?;
    if let Some(path) = &a.gpkg {
        veg::write_gpkg(path, &extraction.objects, &image.crs_wkt)?;
    }
    if let Some(path) = &a.labels {
        veg::write_labels(path, &image, &extraction)?;
    }
    if let Some(path) = &a.overlay {
        let rgba = veg::overlay(&image, &extraction, &options.negative_class);
        let png = gdalio::encode_png(&rgba, image.image.width, image.image.height)?;
        gdalio::write_atomic(path, &png)?;
    }
    let r = &extraction.report;
    if a.json {
        println!("{}", serde_json::to_string_pretty(r)?);
    } else {
        println!(
            "{}: {}×{} px of {:.2} m, {} leaves → {} regions, {} objects ({:.0} ms split-and-merge, {:.0} ms classify, {:.0} ms place)",
            a.image.display(), r.width, r.height, r.pixel_m, r.leaves, r.regions, r.objects,
            r.segment_ms, r.classify_ms, r.detect_ms
        );
        for c in &r.classes {
            println!(
                "  {:<12} {:>10} signatures {:>4}  regions {:>7}  pixels {:>10}  objects {:>7}",
                c.class,
                if c.vegetation {
                    "vegetation"
                } else {
                    "negative"
                },
                c.signatures,
                c.regions,
                c.pixels,
                c.objects
            );
        }
    }
    Ok(())
}

fn run_veg_eval(detections: &Path, truth: &Path, json: bool) -> Result<()> {
    use relevo_core::veg::{db, eval};
    let read = |p: &Path| {
        std::fs::read_to_string(p).with_context(|| format!("{}: cannot read", p.display()))
    };
    let objects = db::from_csv(&read(detections)?)
        .map_err(|e| anyhow::anyhow!("{}: {e}", detections.display()))?;
    let text = read(truth)?;
    let boxes = if text.trim_start().starts_with('<') {
        eval::parse_voc(&text)
    } else {
        eval::parse_box_csv(&text)
    }
    .map_err(|e| anyhow::anyhow!("{}: {e}", truth.display()))?;
    let points: Vec<(f64, f64, f32)> = objects.iter().map(|o| (o.x, o.y, o.score)).collect();
    let e = eval::evaluate(&points, &boxes);
    if json {
        println!("{}", serde_json::to_string_pretty(&e)?);
    } else {
        println!(
            "precision {:.3}  recall {:.3}  F1 {:.3}  (TP {}, FP {}, FN {}; {} detections, {} boxes)",
            e.precision, e.recall, e.f1, e.true_positives, e.false_positives,
            e.false_negatives, e.detections, e.truth
        );
    }
    Ok(())
}

fn run_info(path: &Path, json: bool) -> Result<()> {
    let bundle = Bundle::open(path)?;
    let m = &bundle.manifest;
    if json {
        println!("{}", serde_json::to_string_pretty(m)?);
        return Ok(());
    }
    println!(
        "{} — region {:?}, format {} v{}",
        path.display(),
        m.region,
        m.format,
        m.format_version
    );
    match m.crs.epsg {
        Some(code) => println!("  CRS          EPSG:{code}"),
        None if m.crs.wkt.is_empty() => println!("  CRS          none (grid units)"),
        None => println!("  CRS          custom (WKT in manifest)"),
    }
    let g = &m.grid;
    println!(
        "  grid         {0}×{0} vertices, {1:.3} m cells, z scale {2}",
        g.side, g.cell_size_m, g.z_scale
    );
    println!(
        "  data         {} vertices, heights {:.2}..{:.2} m",
        g.valid_vertices, g.height_range_m[0], g.height_range_m[1]
    );
    println!("  extent       {:?}", g.valid_extent);
    if let Some(c) = &m.color {
        println!(
            "  colour       {}×{} pixels, bands {:?}",
            c.width, c.height, c.bands
        );
    }
    if let Some(a) = m.artifacts.get("vegetation") {
        let path = bundle.dir.join(&a.file);
        let text = std::fs::read_to_string(&path)
            .with_context(|| format!("{}: cannot read", path.display()))?;
        let objects = relevo_core::veg::db::from_csv(&text)
            .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
        let mut per_class = std::collections::BTreeMap::new();
        for o in &objects {
            *per_class.entry(o.class.as_str()).or_insert(0usize) += 1;
        }
        println!("  vegetation   {} objects {per_class:?}", objects.len());
    }
    for (name, a) in m.artifacts.iter().chain(&m.exports) {
        println!(
            "  {name:<12} {} {:?} {:?} {} bytes",
            a.file, a.dtype, a.shape, a.bytes
        );
    }
    for t in &m.timings {
        println!("  stage {:<6} {:.1} ms", t.stage, t.ms);
    }
    Ok(())
}

fn run_validate(path: &Path) -> Result<()> {
    let bundle = Bundle::open(path)?;
    let problems = validate(&bundle);
    if problems.is_empty() {
        println!("{}: valid", path.display());
        Ok(())
    } else {
        for p in &problems {
            eprintln!("{}: {p}", path.display());
        }
        bail!("{}: {} problem(s)", path.display(), problems.len())
    }
}
