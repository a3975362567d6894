//! A bundle as something to look at: cameras given in world (CRS)
//! coordinates, the text syntax both programs accept for them, and the
//! raycast of a bundle. The conversions between world and terrain frame are
//! [`TerrainFrame`]'s; everything here goes through them.

use crate::bundle::{Bundle, GridInfo};
use crate::camera::Camera;
use crate::geo::TerrainFrame;
use crate::horizon::{render, DistanceBand, RaycastFrame, RenderOptions, Terrain};
use crate::{Error, Result};
use glam::DVec3;

/// A camera given in the bundle's world coordinates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct View {
    /// Easting, northing (CRS units), height (metres).
    pub eye: [f64; 3],
    /// Degrees clockwise from north.
    pub heading_deg: f64,
    /// Tilt of the view above the horizon, degrees (negative looks down).
    pub pitch_deg: f64,
    /// Projection-plane shift: the screen row, in pixels from the bottom,
    /// the view axis passes through; `None` centres it.
    pub incl_px: Option<f64>,
    /// Horizontal field of view, degrees.
    pub fov_x_deg: f64,
    /// Image width and height, pixels.
    pub size: [u32; 2],
    /// Far plane in grid cells.
    pub far_cells: f64,
}

impl View {
    /// Where the camera is and where it looks, as the camera string has it.
    pub fn pose(&self) -> CameraPose {
        CameraPose {
            eye: self.eye,
            heading_deg: self.heading_deg,
            pitch_deg: self.pitch_deg,
            incl_px: self.incl_px,
        }
    }

    /// The home view of a grid: from the south-west quarter of its data,
    /// 150 m above its highest point, looking north-east (35°), the horizon
    /// three quarters up a `size` image, far plane 1024 cells.
    pub fn home(grid: &GridInfo, size: [u32; 2]) -> View {
        let [x0, y0, x1, y1] = grid.valid_extent;
        let top = grid.height_range_m[1] as f64;
        View {
            eye: [x0 + 0.15 * (x1 - x0), y0 + 0.1 * (y1 - y0), top + 150.0],
            heading_deg: 35.0,
            pitch_deg: 0.0,
            incl_px: Some(size[1] as f64 * 0.75),
            fov_x_deg: 60.0,
            size,
            far_cells: 1024.0,
        }
    }
}

/// The position and direction part of a camera, as typed on the command line
/// and copied from the viewer: `X,Y,Z,HEADING[,PITCHdeg][,INCL]` — the eye,
/// the heading, an optional pitch in degrees (written with its `deg` unit,
/// negative looks down) and an optional projection-plane shift in pixels
/// (the seed's `incl`, a bare number as before pitches existed).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraPose {
    /// Easting, northing (CRS units), height (metres).
    pub eye: [f64; 3],
    /// Degrees clockwise from north.
    pub heading_deg: f64,
    /// Degrees above the horizon (0 when the string has none).
    pub pitch_deg: f64,
    /// Projection-plane shift in pixels from the bottom (see [`View`]).
    pub incl_px: Option<f64>,
}

/// The camera string's syntax, for messages.
const POSE_SYNTAX: &str = "X,Y,Z,HEADING[,PITCHdeg][,INCL]";

impl CameraPose {
    /// Parse `X,Y,Z,HEADING[,PITCHdeg][,INCL]`.
    pub fn parse(text: &str) -> Result<CameraPose, String> {
        let fields: Vec<&str> = text.split(',').map(str::trim).collect();
        if !(4..=6).contains(&fields.len()) {
            return Err(format!(
                "{text:?}: expected {POSE_SYNTAX}, got {} value(s)",
                fields.len()
            ));
        }
        let number = |field: &str| -> Result<f64, String> {
            let value: f64 = field
                .parse()
                .map_err(|_| format!("{text:?}: {field:?} is not a number ({POSE_SYNTAX})"))?;
            if value.is_finite() {
                Ok(value)
            } else {
                Err(format!("{text:?}: {field:?} is not a finite number"))
            }
        };
        let mut pose = CameraPose {
            eye: [number(fields[0])?, number(fields[1])?, number(fields[2])?],
            heading_deg: number(fields[3])?,
            pitch_deg: 0.0,
            incl_px: None,
        };
        let mut rest = &fields[4..];
        if let Some(pitch) = rest.first().and_then(|f| f.strip_suffix("deg")) {
            pose.pitch_deg = number(pitch)?;
            if !(-90.0..=90.0).contains(&pose.pitch_deg) {
                return Err(format!("{text:?}: the pitch must lie in -90deg..90deg"));
            }
            rest = &rest[1..];
        }
        match rest {
            [] => {}
            [incl] => pose.incl_px = Some(number(incl)?),
            _ => return Err(format!("{text:?}: expected {POSE_SYNTAX}")),
        }
        Ok(pose)
    }
}

impl std::fmt::Display for CameraPose {
    /// The same `X,Y,Z,HEADING[,PITCHdeg][,INCL]` syntax [`CameraPose::parse`]
    /// reads, each number in its shortest form that reads back exactly; a
    /// level camera's pitch is left out.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let [x, y, z] = self.eye;
        write!(f, "{x},{y},{z},{}", self.heading_deg)?;
        if self.pitch_deg != 0.0 {
            write!(f, ",{}deg", self.pitch_deg)?;
        }
        if let Some(incl) = self.incl_px {
            write!(f, ",{incl}")?;
        }
        Ok(())
    }
}

/// The camera of `view` in the terrain frame of `frame` (near plane one
/// cell ahead).
pub fn camera(frame: &TerrainFrame, view: &View) -> Result<Camera> {
    let (x, y) = frame
        .terrain_from_world(view.eye[0], view.eye[1])
        .ok_or_else(|| Error::Input("the bundle's geotransform cannot be inverted".into()))?;
    let cell = frame.cell_size_m;
    Ok(Camera {
        position: DVec3::new(x, y, view.eye[2]),
        heading_deg: view.heading_deg,
        pitch_deg: view.pitch_deg,
        incl_px: view.incl_px.unwrap_or(view.size[1] as f64 / 2.0),
        fov_x_deg: view.fov_x_deg,
        width: view.size[0],
        height: view.size[1],
        near_m: cell,
        far_m: view.far_cells * cell,
    })
}

/// Refuse a field of view or far plane no renderer can use, in the words
/// both programs print: the field of view (degrees) lies in (0, 179), the
/// far plane (grid cells) is finite and at least 2.
///
/// ```
/// use relevo_core::scene::check_view_limits;
/// assert!(check_view_limits(60.0, 1024.0).is_ok());
/// assert!(check_view_limits(180.0, 1024.0).unwrap_err().to_string().contains("--fov"));
/// assert!(check_view_limits(60.0, f64::INFINITY).is_err());
/// ```
pub fn check_view_limits(fov_x_deg: f64, far_cells: f64) -> Result<()> {
    if !(fov_x_deg > 0.0 && fov_x_deg < 179.0) {
        return Err(Error::Input(format!(
            "--fov must be between 0 and 179 degrees, got {fov_x_deg}"
        )));
    }
    if !(far_cells.is_finite() && far_cells >= 2.0) {
        return Err(Error::Input(format!(
            "--far must be a finite number of at least 2 cells, got {far_cells}"
        )));
    }
    Ok(())
}

/// Parse an image size `WIDTHxHEIGHT`, each 1 to 16384 pixels.
pub fn parse_size(text: &str) -> Result<[u32; 2], String> {
    let (w, h) = text
        .split_once('x')
        .ok_or_else(|| format!("{text:?}: expected WIDTHxHEIGHT"))?;
    let parse = |v: &str| v.parse::<u32>().ok().filter(|&v| (1..=16384).contains(&v));
    match (parse(w), parse(h)) {
        (Some(w), Some(h)) => Ok([w, h]),
        _ => Err(format!("{text:?}: expected WIDTHxHEIGHT, each 1..=16384")),
    }
}

/// Parse `UNTIL_M:SLICES_PER_CELL[:sub]` bands, comma-separated, e.g.
/// `3000:4:sub,10000:2:sub,inf:1`.
pub fn parse_bands(text: &str) -> Result<Vec<DistanceBand>, String> {
    text.split(',')
        .map(|band| {
            let parts: Vec<&str> = band.split(':').collect();
            let bad = || format!("{band:?}: expected UNTIL_M:SLICES_PER_CELL[:sub]");
            if !(2..=3).contains(&parts.len()) {
                return Err(bad());
            }
            let until_m = if parts[0] == "inf" {
                f64::INFINITY
            } else {
                parts[0].parse().map_err(|_| bad())?
            };
            let slices_per_cell: f64 = parts[1].parse().map_err(|_| bad())?;
            if !(slices_per_cell > 0.0 && slices_per_cell <= 64.0) {
                return Err(format!("{band:?}: slices per cell must be in (0, 64]"));
            }
            let subvoxel = match parts.get(2) {
                None => false,
                Some(&"sub") => true,
                Some(_) => return Err(bad()),
            };
            Ok(DistanceBand {
                until_m,
                slices_per_cell,
                subvoxel,
            })
        })
        .collect()
}

/// Raycast options with `bands` when given (at least one), the options'
/// own otherwise: what `--bands` sets.
///
/// ```
/// use relevo_core::horizon::RenderOptions;
/// use relevo_core::scene::{parse_bands, with_bands};
/// let options = with_bands(RenderOptions::default(), Some(parse_bands("3000:4:sub,inf:1").unwrap()));
/// assert_eq!(options.unwrap().bands.len(), 2);
/// assert!(with_bands(RenderOptions::default(), Some(Vec::new())).is_err());
/// ```
pub fn with_bands(
    options: RenderOptions,
    bands: Option<Vec<DistanceBand>>,
) -> Result<RenderOptions> {
    match bands {
        Some(b) if b.is_empty() => Err(Error::Input("--bands needs at least one band".into())),
        Some(bands) => Ok(RenderOptions { bands, ..options }),
        None => Ok(options),
    }
}

/// Raycast `bundle` for `view`, with a baked hillshade (sun azimuth and
/// elevation in degrees) when asked.
pub fn render_bundle(
    bundle: &Bundle,
    view: &View,
    options: &RenderOptions,
    hillshade: Option<[f64; 2]>,
) -> Result<RaycastFrame> {
    let frame = bundle.frame();
    let drape_pixels = bundle
        .manifest
        .color
        .as_ref()
        .map_or(0, |c| c.width as u64 * c.height as u64);
    Terrain::check_size(frame.side, drape_pixels)?;
    let heights = bundle.heights()?;
    let mask = bundle.mask()?;
    let color = match bundle.drape()? {
        Some(drape) => drape.color_source(&frame),
        None => None,
    };
    let mut terrain = Terrain::new(frame.side, frame.cell_size_m, &heights, &mask, color);
    if let Some([az, el]) = hillshade {
        terrain = terrain.with_hillshade(az, el);
    }
    let cam = camera(&frame, view)?;
    render(&terrain, &cam, options)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn camera_strings_round_trip() {
        let pose = CameraPose::parse("289000,9111000,400,40,420").unwrap();
        assert_eq!(pose.eye, [289000.0, 9111000.0, 400.0]);
        assert_eq!((pose.pitch_deg, pose.incl_px), (0.0, Some(420.0)));
        assert_eq!(CameraPose::parse(&pose.to_string()).unwrap(), pose);
        let exact = CameraPose {
            eye: [289000.125, 9111000.3, 412.7],
            heading_deg: 33.333,
            pitch_deg: -27.25,
            incl_px: None,
        };
        assert_eq!(
            exact.to_string(),
            "289000.125,9111000.3,412.7,33.333,-27.25deg"
        );
        assert_eq!(CameraPose::parse(&exact.to_string()).unwrap(), exact);
        let both = CameraPose::parse("1,2,3,4, -10deg ,300").unwrap();
        assert_eq!((both.pitch_deg, both.incl_px), (-10.0, Some(300.0)));
        assert_eq!(CameraPose::parse(&both.to_string()).unwrap(), both);
        for bad in [
            "1,2,3",
            "1,2,x,4",
            "1,2,3,4,5,6",
            "1,2,3,4,300,-10deg",
            "1,2,3,4,-95deg",
            "1,2,3,4,NaNdeg",
            "1,2,3,inf",
        ] {
            assert!(CameraPose::parse(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn bands_parse_and_refuse_nonsense() {
        let b = parse_bands("3000:4:sub,inf:1").unwrap();
        assert_eq!(b.len(), 2);
        assert!(b[0].subvoxel && b[1].until_m.is_infinite());
        assert!(parse_bands("3000:0").is_err());
        assert!(parse_bands("3000:4:super").is_err());
        assert!(parse_bands("x:4").is_err());
        assert_eq!(parse_size("960x540"), Ok([960, 540]));
        assert!(parse_size("0x540").is_err() && parse_size("960").is_err());
    }
}
