//! GeoTIFF DEMs as lunar DEMs are distributed (LOLA/LRO products: float32 or int16
//! heights in metres, maybe scaled, on polar stereographic or equirectangular maps of a
//! 1 737 400 m sphere), read with the `tiff` crate and resampled about the site.
//!
//! Supported (`docs/terrain.md` has the matrix): one band of u8/i8/u16/i16/u32/i32/f32/
//! f64 samples, uncompressed, LZW or deflate, strips or tiles; georeference by
//! ModelTiepoint + ModelPixelScale or a ModelTransformation without rotation; models
//! geographic (lat/lon degrees) or projected (metres) with stereographic (polar or
//! oblique, ProjCoordTrans 14/15/16) or equirectangular (17) on a sphere; PixelIsArea or
//! PixelIsPoint; GDAL's no-data, scale and offset tags.

use super::frame::SiteFrame;
use super::grid::Grid;
use super::spec::{check_grid_size, nodes_per_side, GeoTiffSpec};
use super::TerrainError;
use nalgebra::Vector3;
use std::f64::consts::PI;
use std::fs::File;
use std::io::BufReader;
use std::path::{Path, PathBuf};
use tiff::decoder::{Decoder, DecodingResult, Limits};
use tiff::tags::Tag;

/// GDAL's XML metadata tag (scale and offset live there).
const TAG_GDAL_METADATA: u16 = 42112;
/// Largest raster read whole, bytes of decoded samples (4 GiB).
const MAX_DECODED_BYTES: usize = 1 << 32;

// GeoKey ids (GeoTIFF 1.1, OGC 19-008r4, section 7 and annex B).
const GT_MODEL_TYPE: u16 = 1024;
const GT_RASTER_TYPE: u16 = 1025;
const GEOG_ANGULAR_UNITS: u16 = 2054;
const GEOG_SEMI_MAJOR: u16 = 2057;
const GEOG_SEMI_MINOR: u16 = 2058;
const GEOG_INV_FLATTENING: u16 = 2059;
const PROJ_COORD_TRANS: u16 = 3075;
const PROJ_LINEAR_UNITS: u16 = 3076;
const PROJ_STD_PARALLEL1: u16 = 3078;
const PROJ_NAT_ORIGIN_LONG: u16 = 3080;
const PROJ_NAT_ORIGIN_LAT: u16 = 3081;
const PROJ_FALSE_EASTING: u16 = 3082;
const PROJ_FALSE_NORTHING: u16 = 3083;
const PROJ_CENTER_LONG: u16 = 3088;
const PROJ_CENTER_LAT: u16 = 3089;
const PROJ_SCALE_AT_NAT_ORIGIN: u16 = 3092;
const PROJ_STRAIGHT_VERT_POLE_LONG: u16 = 3095;

/// The map projection of a DEM file, on a sphere.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FileProjection {
    /// Model coordinates are east longitude and latitude, degrees.
    Geographic,
    /// Stereographic about `(lat0, lon0)` (polar when `lat0 = +-90 deg`) with scale `k0`.
    Stereographic {
        /// Sphere radius, m.
        radius_m: f64,
        /// Centre latitude, rad.
        lat0_rad: f64,
        /// Centre longitude, rad.
        lon0_rad: f64,
        /// Scale at the centre.
        k0: f64,
        /// False easting, m.
        false_easting_m: f64,
        /// False northing, m.
        false_northing_m: f64,
    },
    /// Equirectangular: `x = R (lon - lon0) cos(lat_ts)`, `y = R (lat - lat0)`.
    Equirectangular {
        /// Sphere radius, m.
        radius_m: f64,
        /// Latitude of true scale, rad.
        lat_ts_rad: f64,
        /// Origin latitude, rad.
        lat0_rad: f64,
        /// Central longitude, rad.
        lon0_rad: f64,
        /// False easting, m.
        false_easting_m: f64,
        /// False northing, m.
        false_northing_m: f64,
    },
}

/// Wraps an angle difference into (-pi, pi].
fn wrap_pi(a: f64) -> f64 {
    let w = (a + PI).rem_euclid(2.0 * PI) - PI;
    if w == -PI {
        PI
    } else {
        w
    }
}

impl FileProjection {
    /// Model coordinates (file units) of latitude, east longitude (rad); `None` where
    /// the projection is undefined (the stereographic antipode).
    pub fn forward(&self, lat_rad: f64, lon_rad: f64) -> Option<(f64, f64)> {
        match *self {
            FileProjection::Geographic => Some((lon_rad.to_degrees(), lat_rad.to_degrees())),
            FileProjection::Stereographic {
                radius_m,
                lat0_rad,
                lon0_rad,
                k0,
                false_easting_m,
                false_northing_m,
            } => {
                // Snyder (1987), Map Projections: A Working Manual, eqs. 21-2 to 21-4.
                let (s0, c0) = lat0_rad.sin_cos();
                let (s, c) = lat_rad.sin_cos();
                let (sd, cd) = wrap_pi(lon_rad - lon0_rad).sin_cos();
                let denom = 1.0 + s0 * s + c0 * c * cd;
                if denom <= 1e-12 {
                    return None;
                }
                let k = 2.0 * radius_m * k0 / denom;
                Some((
                    false_easting_m + k * c * sd,
                    false_northing_m + k * (c0 * s - s0 * c * cd),
                ))
            }
            FileProjection::Equirectangular {
                radius_m,
                lat_ts_rad,
                lat0_rad,
                lon0_rad,
                false_easting_m,
                false_northing_m,
            } => Some((
                false_easting_m + radius_m * wrap_pi(lon_rad - lon0_rad) * lat_ts_rad.cos(),
                false_northing_m + radius_m * (lat_rad - lat0_rad),
            )),
        }
    }
}

/// A DEM file read into memory: samples in metres (scale and offset applied; no-data
/// as NaN), the raster-to-model transform and the projection.
#[derive(Debug, Clone)]
pub struct GeoDem {
    path: PathBuf,
    width: usize,
    height: usize,
    h_m: Vec<f64>,
    /// Model coordinates of the centre of pixel (0, 0).
    x0: f64,
    y0: f64,
    /// Pixel size in model units (x to the right, y downward is `-sy`).
    sx: f64,
    sy: f64,
    projection: FileProjection,
}

fn unsupported(path: &Path, what: impl Into<String>) -> TerrainError {
    TerrainError::Unsupported {
        path: path.to_path_buf(),
        what: what.into(),
    }
}

fn missing(path: &Path, what: impl Into<String>) -> TerrainError {
    TerrainError::MissingGeoreference {
        path: path.to_path_buf(),
        what: what.into(),
    }
}

/// The GeoKey directory, resolved to numbers (short values and doubles).
struct GeoKeys {
    shorts: Vec<(u16, u16)>,
    doubles: Vec<(u16, f64)>,
}

impl GeoKeys {
    fn short(&self, id: u16) -> Option<u16> {
        self.shorts.iter().find(|(k, _)| *k == id).map(|(_, v)| *v)
    }
    fn double(&self, id: u16) -> Option<f64> {
        self.doubles.iter().find(|(k, _)| *k == id).map(|(_, v)| *v)
    }
}

fn read_geokeys(path: &Path, dir: &[u16], doubles: &[f64]) -> Result<GeoKeys, TerrainError> {
    if dir.len() < 4 {
        return Err(missing(path, "GeoKeyDirectory is shorter than its header"));
    }
    let count = dir[3] as usize;
    if dir.len() < 4 + 4 * count {
        return Err(missing(
            path,
            "GeoKeyDirectory is shorter than its key count",
        ));
    }
    let mut keys = GeoKeys {
        shorts: Vec::new(),
        doubles: Vec::new(),
    };
    for k in 0..count {
        let e = &dir[4 + 4 * k..8 + 4 * k];
        let (id, loc, n, off) = (e[0], e[1], e[2] as usize, e[3] as usize);
        match loc {
            0 => keys.shorts.push((id, off as u16)),
            34736 if n >= 1 => {
                let v = doubles.get(off).copied().ok_or_else(|| {
                    missing(path, format!("GeoKey {id} points past GeoDoubleParams"))
                })?;
                keys.doubles.push((id, v));
            }
            _ => {} // ASCII citations and other locations carry nothing we need.
        }
    }
    Ok(keys)
}

/// The first `<Item ... role="ROLE">VALUE</Item>` of GDAL's metadata XML, parsed.
fn gdal_metadata_number(xml: &str, role: &str) -> Option<f64> {
    let pat = format!("role=\"{role}\"");
    let at = xml.find(&pat)?;
    let rest = &xml[at..];
    let start = rest.find('>')? + 1;
    let end = rest[start..].find('<')? + start;
    rest[start..end].trim().parse().ok()
}

impl GeoDem {
    /// Reads `path`: samples, georeference and projection, with typed errors for what
    /// this reader does not support.
    pub fn open(path: &Path) -> Result<Self, TerrainError> {
        Self::open_with(path, None, None)
    }

    /// [`Self::open`] with the height scale and offset given (each overriding the
    /// file's GDAL metadata when `Some`).
    pub fn open_with(
        path: &Path,
        height_scale: Option<f64>,
        height_offset_m: Option<f64>,
    ) -> Result<Self, TerrainError> {
        let tiff_err = |source| TerrainError::Tiff {
            path: path.to_path_buf(),
            source,
        };
        let file = File::open(path).map_err(|source| TerrainError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let mut limits = Limits::default();
        limits.decoding_buffer_size = MAX_DECODED_BYTES;
        limits.intermediate_buffer_size = MAX_DECODED_BYTES;
        let mut dec = Decoder::new(BufReader::new(file))
            .map_err(tiff_err)?
            .with_limits(limits);
        let (w, h) = dec.dimensions().map_err(tiff_err)?;
        let (width, height) = (w as usize, h as usize);
        if width < 2 || height < 2 {
            return Err(unsupported(
                path,
                format!("raster {width} x {height} (need 2 x 2)"),
            ));
        }
        let spp = dec
            .find_tag_unsigned::<u16>(Tag::SamplesPerPixel)
            .map_err(tiff_err)?
            .unwrap_or(1);
        if spp != 1 {
            return Err(unsupported(
                path,
                format!("{spp} samples per pixel (need one band)"),
            ));
        }

        // Georeference.
        let scale = dec.find_tag(Tag::ModelPixelScaleTag).map_err(tiff_err)?;
        let tie = dec.find_tag(Tag::ModelTiepointTag).map_err(tiff_err)?;
        let xform = dec
            .find_tag(Tag::ModelTransformationTag)
            .map_err(tiff_err)?;
        let (corner_x, corner_y, sx, sy) = match (scale, tie, xform) {
            (Some(scale), Some(tie), _) => {
                let s = scale.into_f64_vec().map_err(tiff_err)?;
                let t = tie.into_f64_vec().map_err(tiff_err)?;
                if s.len() < 2 || t.len() < 6 {
                    return Err(missing(path, "ModelPixelScale or ModelTiepoint too short"));
                }
                if t.len() > 6 {
                    return Err(unsupported(
                        path,
                        "more than one tie point (a warped raster)",
                    ));
                }
                (t[3] - t[0] * s[0], t[4] + t[1] * s[1], s[0], s[1])
            }
            (_, _, Some(m)) => {
                let m = m.into_f64_vec().map_err(tiff_err)?;
                if m.len() < 16 {
                    return Err(missing(path, "ModelTransformation shorter than 16 values"));
                }
                if m[1] != 0.0 || m[4] != 0.0 {
                    return Err(unsupported(
                        path,
                        "a rotated raster (ModelTransformation shear terms)",
                    ));
                }
                (m[3], m[7], m[0], -m[5])
            }
            _ => {
                return Err(missing(
                    path,
                    "no ModelTiepoint + ModelPixelScale and no ModelTransformation",
                ))
            }
        };
        if !(sx.is_finite() && sy.is_finite() && sx > 0.0 && sy > 0.0) {
            return Err(unsupported(
                path,
                format!("pixel scale ({sx}, {sy}) (need positive; north-up rasters only)"),
            ));
        }

        let dir = dec
            .find_tag(Tag::GeoKeyDirectoryTag)
            .map_err(tiff_err)?
            .ok_or_else(|| missing(path, "no GeoKeyDirectory"))?
            .into_u16_vec()
            .map_err(tiff_err)?;
        let doubles = match dec.find_tag(Tag::GeoDoubleParamsTag).map_err(tiff_err)? {
            Some(v) => v.into_f64_vec().map_err(tiff_err)?,
            None => Vec::new(),
        };
        let keys = read_geokeys(path, &dir, &doubles)?;
        let projection = projection_of(path, &keys)?;
        // PixelIsArea (1, the default): the tie point is a pixel's corner.
        let centre_offset = if keys.short(GT_RASTER_TYPE) == Some(2) {
            0.0
        } else {
            0.5
        };
        let x0 = corner_x + centre_offset * sx;
        let y0 = corner_y - centre_offset * sy;

        // Samples in metres.
        let nodata: Option<f64> = match dec.find_tag(Tag::GdalNodata).map_err(tiff_err)? {
            Some(v) => {
                let s = v.into_string().map_err(tiff_err)?;
                let s = s.trim_matches(|c: char| c == '\0' || c.is_whitespace());
                match s.parse::<f64>() {
                    Ok(x) => Some(x),
                    Err(_) if s.eq_ignore_ascii_case("nan") => Some(f64::NAN),
                    Err(_) => return Err(unsupported(path, format!("GDAL_NODATA {s:?}"))),
                }
            }
            None => None,
        };
        let meta = dec
            .find_tag(Tag::Unknown(TAG_GDAL_METADATA))
            .map_err(tiff_err)?
            .and_then(|v| v.into_string().ok())
            .unwrap_or_default();
        let value_scale = height_scale
            .or(gdal_metadata_number(&meta, "scale"))
            .unwrap_or(1.0);
        let value_offset = height_offset_m
            .or(gdal_metadata_number(&meta, "offset"))
            .unwrap_or(0.0);
        if !(value_scale.is_finite() && value_offset.is_finite()) {
            return Err(unsupported(path, "non-finite scale or offset"));
        }
        let raw = dec.read_image().map_err(tiff_err)?;
        let to_m = |x: f64| -> f64 {
            let is_nodata = match nodata {
                Some(nd) if nd.is_nan() => x.is_nan(),
                Some(nd) => x == nd,
                None => false,
            };
            if is_nodata || !x.is_finite() {
                f64::NAN
            } else {
                x * value_scale + value_offset
            }
        };
        let h_m: Vec<f64> = match raw {
            DecodingResult::U8(v) => v.into_iter().map(|x| to_m(x as f64)).collect(),
            DecodingResult::I8(v) => v.into_iter().map(|x| to_m(x as f64)).collect(),
            DecodingResult::U16(v) => v.into_iter().map(|x| to_m(x as f64)).collect(),
            DecodingResult::I16(v) => v.into_iter().map(|x| to_m(x as f64)).collect(),
            DecodingResult::U32(v) => v.into_iter().map(|x| to_m(x as f64)).collect(),
            DecodingResult::I32(v) => v.into_iter().map(|x| to_m(x as f64)).collect(),
            DecodingResult::F32(v) => v.into_iter().map(|x| to_m(x as f64)).collect(),
            DecodingResult::F64(v) => v.into_iter().map(to_m).collect(),
            _ => {
                return Err(unsupported(
                    path,
                    "sample type (need 8/16/32-bit integers or f32/f64)",
                ))
            }
        };
        if h_m.len() != width * height {
            return Err(unsupported(
                path,
                format!("{} samples for a {width} x {height} raster", h_m.len()),
            ));
        }
        Ok(Self {
            path: path.to_path_buf(),
            width,
            height,
            h_m,
            x0,
            y0,
            sx,
            sy,
            projection,
        })
    }

    /// Raster size (columns, rows).
    pub fn size(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    /// The file's projection.
    pub fn projection(&self) -> &FileProjection {
        &self.projection
    }

    /// Model coordinates of the centre of pixel (0, 0) and the pixel size.
    pub fn transform(&self) -> (f64, f64, f64, f64) {
        (self.x0, self.y0, self.sx, self.sy)
    }

    /// Continuous pixel coordinates (column, row; pixel centres at integers) of model
    /// point `(x, y)`.
    pub fn pixel_of_model(&self, x: f64, y: f64) -> (f64, f64) {
        ((x - self.x0) / self.sx, (self.y0 - y) / self.sy)
    }

    /// Continuous pixel coordinates of latitude, east longitude (rad).
    pub fn pixel_of_lat_lon(&self, lat_rad: f64, lon_rad: f64) -> Option<(f64, f64)> {
        let (x, y) = self.projection.forward(lat_rad, lon_rad)?;
        Some(self.pixel_of_model(x, y))
    }

    /// True if continuous pixel `(c, r)` lies within the raster's pixel centres.
    pub fn covers(&self, c: f64, r: f64) -> bool {
        c >= 0.0 && r >= 0.0 && c <= (self.width - 1) as f64 && r <= (self.height - 1) as f64
    }

    /// Bilinear height (m) at continuous pixel `(c, r)`, clamped to the raster; no-data
    /// corners are left out and the rest re-weighted; `None` if all four are no-data.
    pub fn elevation_at_pixel(&self, c: f64, r: f64) -> Option<f64> {
        let c = c.clamp(0.0, (self.width - 1) as f64);
        let r = r.clamp(0.0, (self.height - 1) as f64);
        let i = (c.floor() as usize).min(self.width - 2);
        let j = (r.floor() as usize).min(self.height - 2);
        let (fx, fy) = (c - i as f64, r - j as f64);
        let corners = [
            (i, j, (1.0 - fx) * (1.0 - fy)),
            (i + 1, j, fx * (1.0 - fy)),
            (i, j + 1, (1.0 - fx) * fy),
            (i + 1, j + 1, fx * fy),
        ];
        let (mut acc, mut wsum) = (0.0, 0.0);
        for (ci, cj, w) in corners {
            let h = self.h_m[cj * self.width + ci];
            if h.is_finite() && w > 0.0 {
                acc += w * h;
                wsum += w;
            }
        }
        if wsum > 0.0 {
            Some(acc / wsum)
        } else {
            // On a node exactly: its own value, if valid.
            let h = self.h_m[(r.round() as usize) * self.width + c.round() as usize];
            h.is_finite().then_some(h)
        }
    }

    /// Bilinear height (m) at latitude, east longitude (rad), if covered and valid.
    pub fn elevation_at_lat_lon(&self, lat_rad: f64, lon_rad: f64) -> Option<f64> {
        let (c, r) = self.pixel_of_lat_lon(lat_rad, lon_rad)?;
        if !self.covers(c, r) {
            return None;
        }
        self.elevation_at_pixel(c, r)
    }

    /// The pixel's ground size at the site, m: the smaller of its east and north sizes
    /// (found by projecting points 1 m east and north of the site).
    pub fn ground_pixel_m(&self, site: &SiteFrame) -> Option<f64> {
        let px = |p: Vector3<f64>| {
            let (lat, lon) = site.lat_lon_of_site(&p);
            self.pixel_of_lat_lon(lat, lon)
        };
        let o = px(Vector3::zeros())?;
        let e = px(Vector3::x())?;
        let n = px(Vector3::y())?;
        let per_m_e = (e.0 - o.0).hypot(e.1 - o.1);
        let per_m_n = (n.0 - o.0).hypot(n.1 - o.1);
        let m = 1.0 / per_m_e.max(per_m_n);
        (m.is_finite() && m > 0.0).then_some(m)
    }

    /// Resamples the DEM onto a square grid of `extent_m` at `spacing_m` about `site`:
    /// each node's map point is taken to latitude/longitude, into the file's map, and
    /// interpolated bilinearly. Nodes outside the raster take the nearest edge value;
    /// nodes on no-data take the mean of the valid nodes. Returns the grid and the
    /// count of nodes filled either way.
    pub fn resample(
        &self,
        site: &SiteFrame,
        extent_m: f64,
        spacing_m: f64,
    ) -> Result<(Grid, usize), TerrainError> {
        let (lat_deg, lon_deg) = (site.lat_rad.to_degrees(), site.lon_rad.to_degrees());
        let not_covered = |what| TerrainError::SiteNotCovered {
            path: self.path.clone(),
            lat_deg,
            lon_deg,
            what,
        };
        let (c, r) = self
            .pixel_of_lat_lon(site.lat_rad, site.lon_rad)
            .ok_or_else(|| not_covered("is outside the raster"))?;
        if !self.covers(c, r) {
            return Err(not_covered("is outside the raster"));
        }
        if self.elevation_at_pixel(c, r).is_none() {
            return Err(not_covered("falls on no-data"));
        }
        check_grid_size(extent_m, spacing_m)?;
        let side = nodes_per_side(extent_m, spacing_m) as usize;
        let half = 0.5 * spacing_m * (side - 1) as f64;
        let map = super::map::MapProjection {
            radius_m: site.radius_m,
        };
        let mut h = vec![f64::NAN; side * side];
        let mut filled = 0usize;
        for j in 0..side {
            let n = -half + spacing_m * j as f64;
            for i in 0..side {
                let e = -half + spacing_m * i as f64;
                let (lat, lon) = site.lat_lon_of_site(&map.site_of_map(e, n, 0.0));
                let v = self.pixel_of_lat_lon(lat, lon).and_then(|(c, r)| {
                    if !self.covers(c, r) {
                        filled += 1;
                    }
                    self.elevation_at_pixel(c, r)
                });
                if let Some(v) = v {
                    h[j * side + i] = v;
                }
            }
        }
        let valid: Vec<f64> = h.iter().copied().filter(|x| x.is_finite()).collect();
        let mean = valid.iter().sum::<f64>() / valid.len().max(1) as f64;
        for x in h.iter_mut().filter(|x| !x.is_finite()) {
            *x = mean;
            filled += 1;
        }
        let grid =
            Grid::new(side, side, -half, -half, spacing_m, h).ok_or(TerrainError::NonFinite)?;
        Ok((grid, filled))
    }
}

fn projection_of(path: &Path, keys: &GeoKeys) -> Result<FileProjection, TerrainError> {
    let model = keys
        .short(GT_MODEL_TYPE)
        .ok_or_else(|| missing(path, "no GTModelTypeGeoKey"))?;
    if let Some(u) = keys.short(GEOG_ANGULAR_UNITS) {
        if u != 9102 {
            return Err(unsupported(
                path,
                format!("angular unit code {u} (need 9102, degree)"),
            ));
        }
    }
    if model == 2 {
        return Ok(FileProjection::Geographic);
    }
    if model != 1 {
        return Err(unsupported(
            path,
            format!("GTModelType {model} (need 1 projected or 2 geographic)"),
        ));
    }
    if let Some(u) = keys.short(PROJ_LINEAR_UNITS) {
        if u != 9001 {
            return Err(unsupported(
                path,
                format!("linear unit code {u} (need 9001, metre)"),
            ));
        }
    }
    let a = keys.double(GEOG_SEMI_MAJOR).ok_or_else(|| {
        missing(
            path,
            "no GeogSemiMajorAxisGeoKey (a user-defined sphere is expected for the Moon)",
        )
    })?;
    let spherical = match (
        keys.double(GEOG_SEMI_MINOR),
        keys.double(GEOG_INV_FLATTENING),
    ) {
        (Some(b), _) => (b - a).abs() <= 1e-9 * a,
        (None, Some(f)) => f == 0.0,
        (None, None) => true,
    };
    if !(spherical && a.is_finite() && a > 0.0) {
        return Err(unsupported(
            path,
            format!("ellipsoid with semi-major axis {a} m (need a sphere)"),
        ));
    }
    let d = |id| keys.double(id).unwrap_or(0.0);
    let fe = d(PROJ_FALSE_EASTING);
    let fn_ = d(PROJ_FALSE_NORTHING);
    let ct = keys.short(PROJ_COORD_TRANS).ok_or_else(|| {
        missing(
            path,
            "no ProjCoordTransGeoKey (EPSG-coded projections are not read)",
        )
    })?;
    match ct {
        // 14 Stereographic, 16 ObliqueStereographic (the same on a sphere).
        14 | 16 => Ok(FileProjection::Stereographic {
            radius_m: a,
            lat0_rad: keys
                .double(PROJ_CENTER_LAT)
                .or(keys.double(PROJ_NAT_ORIGIN_LAT))
                .unwrap_or(0.0)
                .to_radians(),
            lon0_rad: keys
                .double(PROJ_CENTER_LONG)
                .or(keys.double(PROJ_NAT_ORIGIN_LONG))
                .unwrap_or(0.0)
                .to_radians(),
            k0: keys.double(PROJ_SCALE_AT_NAT_ORIGIN).unwrap_or(1.0),
            false_easting_m: fe,
            false_northing_m: fn_,
        }),
        // 15 PolarStereographic: variant A (origin latitude +-90 and a scale) or B (a
        // standard parallel, whose sign picks the pole).
        15 => {
            let lon0 = keys
                .double(PROJ_STRAIGHT_VERT_POLE_LONG)
                .or(keys.double(PROJ_NAT_ORIGIN_LONG))
                .unwrap_or(0.0)
                .to_radians();
            let (lat0, k0) = match (keys.double(PROJ_NAT_ORIGIN_LAT), keys.double(PROJ_STD_PARALLEL1)) {
                (Some(lat), None) if lat.abs() == 90.0 => {
                    (lat.to_radians(), keys.double(PROJ_SCALE_AT_NAT_ORIGIN).unwrap_or(1.0))
                }
                (lat_origin, Some(ts)) => {
                    let pole = lat_origin.filter(|l| l.abs() == 90.0).unwrap_or(90f64.copysign(ts));
                    (pole.to_radians(), (1.0 + ts.to_radians().sin().abs()) / 2.0)
                }
                (other, None) => {
                    return Err(unsupported(
                        path,
                        format!("polar stereographic with origin latitude {other:?} (need +-90)"),
                    ))
                }
            };
            Ok(FileProjection::Stereographic {
                radius_m: a,
                lat0_rad: lat0,
                lon0_rad: lon0,
                k0,
                false_easting_m: fe,
                false_northing_m: fn_,
            })
        }
        // 17 Equirectangular.
        17 => Ok(FileProjection::Equirectangular {
            radius_m: a,
            lat_ts_rad: d(PROJ_STD_PARALLEL1).to_radians(),
            lat0_rad: keys
                .double(PROJ_CENTER_LAT)
                .or(keys.double(PROJ_NAT_ORIGIN_LAT))
                .unwrap_or(0.0)
                .to_radians(),
            lon0_rad: keys
                .double(PROJ_CENTER_LONG)
                .or(keys.double(PROJ_NAT_ORIGIN_LONG))
                .unwrap_or(0.0)
                .to_radians(),
            false_easting_m: fe,
            false_northing_m: fn_,
        }),
        other => Err(unsupported(
            path,
            format!("ProjCoordTrans {other} (supported: 14/16 stereographic, 15 polar stereographic, 17 equirectangular)"),
        )),
    }
}

/// Reads the spec's file and resamples it about `site` (spacing: the spec's, or the
/// file's ground pixel at the site).
pub fn build_grid(spec: &GeoTiffSpec, site: &SiteFrame) -> Result<Grid, TerrainError> {
    let dem = GeoDem::open_with(&spec.path, spec.height_scale, spec.height_offset_m)?;
    let spacing = match spec.spacing_m {
        Some(s) => s,
        None => dem
            .ground_pixel_m(site)
            .ok_or_else(|| TerrainError::SiteNotCovered {
                path: spec.path.clone(),
                lat_deg: site.lat_rad.to_degrees(),
                lon_deg: site.lon_rad.to_degrees(),
                what: "is where the file's projection is undefined",
            })?,
    };
    let (grid, _filled) = dem.resample(site, spec.extent_m, spacing)?;
    Ok(grid)
}
