//! The onboard terrain map: what the flight software knows of the ground it navigates
//! by, loaded from a file before the descent (never the emulator's terrain).
//!
//! A map is a stack of levels, each a square grid of cells in map coordinates `(e, n)`
//! about the landing site (the azimuthal equidistant projection on the reference sphere,
//! [`MapFrame`]: distance and azimuth from the site kept exactly), holding the rendered
//! reflectance (I/F under the map's sun) and the terrain height above the sphere of
//! each cell. Levels are finest first; each coarser level covers a wider area. The
//! bench renders one with `oils map` (`docs/gnc.md`, "Terrain-relative navigation").
//! The file also carries the calibration of the camera the map is for (a terrain
//! navigation data load, as a mission uplinks map and camera model together).
//!
//! File layout (`OILSMAP1`, little-endian), written and read here so the format has
//! one owner:
//! ```text
//! magic        8 bytes "OILSMAP1"
//! levels u32 | reserved u32
//! site_lat_deg f64 | site_lon_deg f64 | radius_m f64 | sun_azimuth_deg f64 | sun_elevation_deg f64
//! camera:      width u32 | height u32 | fov_deg f64 | k1 f64 | k2 f64 | boresight_body 3 f64
//!              | image_right_body 3 f64 | position_body_m 3 f64 | full_scale_dn u32 | reserved u32
//! per level:   spacing_m f64 | e0_m f64 | n0_m f64 | width u32 | height u32
//! per level:   width*height f32 I/F, then width*height f32 height_m (row i: n = n0 + i s,
//!              column j: e = e0 + j s; row 0 is the southernmost)
//! hash         32 bytes: BLAKE3 of every byte before it
//! ```

use super::terrain_nav::CameraModel;
use nalgebra::Vector3;
use std::path::Path;

/// File magic of this format.
pub const MAP_MAGIC: &[u8; 8] = b"OILSMAP1";
/// Largest map file read, bytes (a map of six 2048² levels is 200 MB).
pub const MAX_MAP_BYTES: u64 = 1 << 30;
/// Most levels in a map.
pub const MAX_LEVELS: usize = 12;
/// Largest level side, cells.
pub const MAX_SIDE: u32 = 8192;

/// Why a map could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum MapError {
    /// The file could not be opened, read or written.
    #[error("terrain map {path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// What the OS said.
        source: std::io::Error,
    },
    /// The bytes are not a map this version reads.
    #[error("terrain map {path}: {why}")]
    Format {
        /// The file.
        path: String,
        /// What is wrong.
        why: String,
    },
}

/// The map projection about the site: azimuthal equidistant on the sphere of
/// `radius_m`, Moon-fixed. The same projection as the emulator's terrain grid
/// (`emulator/src/world/terrain/map.rs`; `tests/fsw_models.rs` holds the two together).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MapFrame {
    /// Site latitude, degrees.
    pub lat_deg: f64,
    /// Site east longitude, degrees.
    pub lon_deg: f64,
    /// Reference sphere radius, m.
    pub radius_m: f64,
    east: Vector3<f64>,
    north: Vector3<f64>,
    up: Vector3<f64>,
}

impl MapFrame {
    /// The projection about the site at `lat_deg`, `lon_deg` on a sphere of `radius_m`.
    pub fn new(lat_deg: f64, lon_deg: f64, radius_m: f64) -> Self {
        let (sl, cl) = lat_deg.to_radians().sin_cos();
        let (so, co) = lon_deg.to_radians().sin_cos();
        Self {
            lat_deg,
            lon_deg,
            radius_m,
            east: Vector3::new(-so, co, 0.0),
            north: Vector3::new(-sl * co, -sl * so, cl),
            up: Vector3::new(cl * co, cl * so, sl),
        }
    }

    /// Unit East, North and Up at the site, `mcmf`.
    pub fn axes_mcmf(&self) -> [Vector3<f64>; 3] {
        [self.east, self.north, self.up]
    }

    /// The `mcmf` point at map `(e, n)` and radial height `height_m` above the sphere.
    pub fn mcmf_of_map(&self, e_m: f64, n_m: f64, height_m: f64) -> Vector3<f64> {
        let s = e_m.hypot(n_m);
        let theta = s / self.radius_m;
        let (st, ct) = theta.sin_cos();
        let dir = if s > 0.0 {
            (self.east * e_m + self.north * n_m) / s
        } else {
            Vector3::zeros()
        };
        (self.radius_m + height_m) * (self.up * ct + dir * st)
    }

    /// Map `(e, n)` and radial height of the `mcmf` point `p`.
    pub fn map_of_mcmf(&self, p: &Vector3<f64>) -> (f64, f64, f64) {
        let (x, y, z) = (p.dot(&self.east), p.dot(&self.north), p.dot(&self.up));
        let hor = x.hypot(y);
        let h = p.norm() - self.radius_m;
        if hor == 0.0 {
            return (0.0, 0.0, h);
        }
        let s = self.radius_m * hor.atan2(z);
        (s * x / hor, s * y / hor, h)
    }
}

/// One level of the map: a grid of `width x height` cells `spacing_m` apart.
#[derive(Debug, Clone, PartialEq)]
pub struct MapLevel {
    /// Cell spacing, m.
    pub spacing_m: f64,
    /// Map east of column 0, m.
    pub e0_m: f64,
    /// Map north of row 0, m.
    pub n0_m: f64,
    /// Columns.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// Rendered I/F per cell, row-major from row 0 (south).
    pub iof: Vec<f32>,
    /// Terrain height above the sphere per cell, m.
    pub height_m: Vec<f32>,
}

impl MapLevel {
    /// Fractional (column, row) of map `(e, n)`.
    #[inline]
    pub fn cell_of(&self, e_m: f64, n_m: f64) -> (f64, f64) {
        (
            (e_m - self.e0_m) / self.spacing_m,
            (n_m - self.n0_m) / self.spacing_m,
        )
    }

    /// Whether the cell window `[c0, c0 + w) x [r0, r0 + h)` lies inside the level.
    pub fn contains_window(&self, c0: i64, r0: i64, w: i64, h: i64) -> bool {
        c0 >= 0 && r0 >= 0 && c0 + w <= self.width as i64 && r0 + h <= self.height as i64
    }

    /// The I/F of cell (column, row); the caller keeps it inside.
    #[inline]
    pub fn iof_at(&self, col: usize, row: usize) -> f32 {
        self.iof[row * self.width as usize + col]
    }

    /// Terrain height at map `(e, n)`, bilinear between cells; `None` outside.
    pub fn height_at(&self, e_m: f64, n_m: f64) -> Option<f64> {
        let (c, r) = self.cell_of(e_m, n_m);
        let (w, h) = (self.width as f64, self.height as f64);
        if !(c >= 0.0 && r >= 0.0 && c <= w - 1.0 && r <= h - 1.0) {
            return None;
        }
        let (c0, r0) = (
            (c.floor() as usize).min(self.width as usize - 2),
            (r.floor() as usize).min(self.height as usize - 2),
        );
        let (fc, fr) = (c - c0 as f64, r - r0 as f64);
        let at = |cc: usize, rr: usize| self.height_m[rr * self.width as usize + cc] as f64;
        let lo = at(c0, r0) * (1.0 - fc) + at(c0 + 1, r0) * fc;
        let hi = at(c0, r0 + 1) * (1.0 - fc) + at(c0 + 1, r0 + 1) * fc;
        Some(lo * (1.0 - fr) + hi * fr)
    }

    fn cells(&self) -> usize {
        self.width as usize * self.height as usize
    }
}

/// The onboard terrain map.
#[derive(Debug, Clone, PartialEq)]
pub struct TerrainMap {
    /// The projection (the site the map is about).
    pub frame: MapFrame,
    /// The sun the map was rendered under: azimuth from north through east, degrees.
    pub sun_azimuth_deg: f64,
    /// The sun's elevation above the site's horizon, degrees.
    pub sun_elevation_deg: f64,
    /// The camera the map is for.
    pub camera: CameraModel,
    /// Levels, finest first.
    pub levels: Vec<MapLevel>,
}

impl TerrainMap {
    /// The finest level that holds map `(e, n)` with `margin_cells` to spare and whose
    /// spacing is at least `min_spacing_m`, or the coarsest that holds it at all.
    pub fn level_for(&self, e_m: f64, n_m: f64, min_spacing_m: f64) -> Option<usize> {
        self.levels
            .iter()
            .position(|l| l.spacing_m >= min_spacing_m && l.height_at(e_m, n_m).is_some())
    }

    /// Terrain height at `(e, n)` from the finest level that holds it.
    pub fn height_at(&self, e_m: f64, n_m: f64) -> Option<f64> {
        self.levels.iter().find_map(|l| l.height_at(e_m, n_m))
    }

    /// Checks what a reader relies on: sizes, finite values, spacings.
    pub fn validate(&self) -> Result<(), String> {
        let f = &self.frame;
        if !(f.lat_deg.abs() <= 90.0 && f.lon_deg.is_finite() && f.radius_m > 0.0) {
            return Err("site latitude within +-90 deg, finite longitude, radius > 0".into());
        }
        if !(self.sun_azimuth_deg.is_finite() && self.sun_elevation_deg.abs() <= 90.0) {
            return Err("a finite sun azimuth and an elevation within +-90 deg".into());
        }
        let c = &self.camera;
        let mount_finite = c
            .boresight_body
            .iter()
            .chain(&c.image_right_body)
            .chain(&c.position_body_m)
            .all(|v| v.is_finite());
        let sized = (8..=MAX_SIDE).contains(&c.width_px)
            && (8..=MAX_SIDE).contains(&c.height_px)
            && c.fov_deg > 0.0
            && c.fov_deg < 170.0;
        let camera_ok = sized
            && c.k1.is_finite()
            && c.k2.is_finite()
            && mount_finite
            && Vector3::from(c.boresight_body).norm() > 0.0
            && c.full_scale_dn > 0;
        if !camera_ok {
            return Err(format!(
                "camera: sides of 8 to {MAX_SIDE} px, a field of view in (0, 170) deg, finite distortion and mounting, a boresight, a full scale"
            ));
        }
        if self.levels.is_empty() || self.levels.len() > MAX_LEVELS {
            return Err(format!(
                "1 to {MAX_LEVELS} levels, not {}",
                self.levels.len()
            ));
        }
        for (k, l) in self.levels.iter().enumerate() {
            if !(l.spacing_m.is_finite() && l.spacing_m > 0.0) {
                return Err(format!("level {k}: spacing must be finite and > 0"));
            }
            if !(l.e0_m.is_finite() && l.n0_m.is_finite()) {
                return Err(format!("level {k}: a finite origin"));
            }
            if !(2..=MAX_SIDE).contains(&l.width) || !(2..=MAX_SIDE).contains(&l.height) {
                return Err(format!("level {k}: sides of 2 to {MAX_SIDE} cells"));
            }
            if l.iof.len() != l.cells() || l.height_m.len() != l.cells() {
                return Err(format!("level {k}: width * height values of each kind"));
            }
            if l.iof
                .iter()
                .chain(l.height_m.iter())
                .any(|v| !v.is_finite())
            {
                return Err(format!("level {k}: a value that is not finite"));
            }
        }
        Ok(())
    }

    /// Writes the map to `path` (created or replaced).
    pub fn write(&self, path: &Path) -> Result<(), MapError> {
        let name = path.display().to_string();
        self.validate().map_err(|why| MapError::Format {
            path: name.clone(),
            why,
        })?;
        let mut b = Vec::new();
        b.extend_from_slice(MAP_MAGIC);
        b.extend_from_slice(&(self.levels.len() as u32).to_le_bytes());
        b.extend_from_slice(&0u32.to_le_bytes());
        for v in [
            self.frame.lat_deg,
            self.frame.lon_deg,
            self.frame.radius_m,
            self.sun_azimuth_deg,
            self.sun_elevation_deg,
        ] {
            b.extend_from_slice(&v.to_le_bytes());
        }
        let c = &self.camera;
        b.extend_from_slice(&c.width_px.to_le_bytes());
        b.extend_from_slice(&c.height_px.to_le_bytes());
        for v in [c.fov_deg, c.k1, c.k2]
            .iter()
            .chain(&c.boresight_body)
            .chain(&c.image_right_body)
            .chain(&c.position_body_m)
        {
            b.extend_from_slice(&v.to_le_bytes());
        }
        b.extend_from_slice(&u32::from(c.full_scale_dn).to_le_bytes());
        b.extend_from_slice(&0u32.to_le_bytes());
        for l in &self.levels {
            for v in [l.spacing_m, l.e0_m, l.n0_m] {
                b.extend_from_slice(&v.to_le_bytes());
            }
            b.extend_from_slice(&l.width.to_le_bytes());
            b.extend_from_slice(&l.height.to_le_bytes());
        }
        for l in &self.levels {
            for v in l.iof.iter().chain(l.height_m.iter()) {
                b.extend_from_slice(&v.to_le_bytes());
            }
        }
        let hash = blake3::hash(&b);
        b.extend_from_slice(hash.as_bytes());
        std::fs::write(path, &b).map_err(|source| MapError::Io { path: name, source })
    }

    /// Reads a map written by [`TerrainMap::write`]; a damaged or foreign file is refused
    /// with what is wrong.
    pub fn load(path: &Path) -> Result<Self, MapError> {
        use std::io::Read;
        let name = path.display().to_string();
        let io = |source| MapError::Io {
            path: name.clone(),
            source,
        };
        let bad = |why: String| MapError::Format {
            path: name.clone(),
            why,
        };
        let mut bytes = Vec::new();
        std::fs::File::open(path)
            .map_err(io)?
            .take(MAX_MAP_BYTES + 1)
            .read_to_end(&mut bytes)
            .map_err(io)?;
        if bytes.len() as u64 > MAX_MAP_BYTES {
            return Err(bad(format!("larger than {MAX_MAP_BYTES} bytes")));
        }
        if bytes.len() < 8 + 8 + 40 + 112 + 32 || &bytes[..8] != MAP_MAGIC {
            return Err(bad(
                "not an OILSMAP1 terrain map (make one with `oils map`)".into(),
            ));
        }
        let (body, hash) = bytes.split_at(bytes.len() - 32);
        if blake3::hash(body).as_bytes() != hash {
            return Err(bad(
                "its hash does not match its contents (damaged or cut)".into()
            ));
        }
        let mut r = Reader { b: body, at: 8 };
        let levels = r.u32().ok_or_else(|| bad("cut short".into()))? as usize;
        r.u32();
        if levels == 0 || levels > MAX_LEVELS {
            return Err(bad(format!("1 to {MAX_LEVELS} levels, not {levels}")));
        }
        let head: Option<[f64; 5]> =
            (|| Some([r.f64()?, r.f64()?, r.f64()?, r.f64()?, r.f64()?]))();
        let [lat, lon, radius, az, el] = head.ok_or_else(|| bad("cut short".into()))?;
        let camera: Option<CameraModel> = (|| {
            let (width_px, height_px) = (r.u32()?, r.u32()?);
            let mut v = [0.0f64; 12];
            for x in &mut v {
                *x = r.f64()?;
            }
            let full = r.u32()?;
            r.u32()?;
            Some(CameraModel {
                width_px,
                height_px,
                fov_deg: v[0],
                k1: v[1],
                k2: v[2],
                boresight_body: [v[3], v[4], v[5]],
                image_right_body: [v[6], v[7], v[8]],
                position_body_m: [v[9], v[10], v[11]],
                full_scale_dn: u16::try_from(full).unwrap_or(0),
            })
        })();
        let camera = camera.ok_or_else(|| bad("cut short".into()))?;
        let mut out = Vec::with_capacity(levels);
        for _ in 0..levels {
            let l: Option<MapLevel> = (|| {
                Some(MapLevel {
                    spacing_m: r.f64()?,
                    e0_m: r.f64()?,
                    n0_m: r.f64()?,
                    width: r.u32()?,
                    height: r.u32()?,
                    iof: Vec::new(),
                    height_m: Vec::new(),
                })
            })();
            let l = l.ok_or_else(|| bad("cut short".into()))?;
            if !(2..=MAX_SIDE).contains(&l.width) || !(2..=MAX_SIDE).contains(&l.height) {
                return Err(bad(format!("a level side outside 2 to {MAX_SIDE} cells")));
            }
            out.push(l);
        }
        let need: usize = out.iter().map(|l| l.cells() * 8).sum();
        if body.len() - r.at != need {
            return Err(bad(format!(
                "{} bytes of cells where its levels need {need}",
                body.len() - r.at
            )));
        }
        for l in &mut out {
            let n = l.cells();
            l.iof = r.f32s(n);
            l.height_m = r.f32s(n);
        }
        let map = TerrainMap {
            frame: MapFrame::new(lat, lon, radius),
            sun_azimuth_deg: az,
            sun_elevation_deg: el,
            camera,
            levels: out,
        };
        map.validate().map_err(bad)?;
        Ok(map)
    }
}

/// Little-endian fields from a byte slice.
struct Reader<'a> {
    b: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    fn take<const K: usize>(&mut self) -> Option<[u8; K]> {
        let s = self.b.get(self.at..self.at + K)?;
        self.at += K;
        s.try_into().ok()
    }
    fn u32(&mut self) -> Option<u32> {
        self.take::<4>().map(u32::from_le_bytes)
    }
    fn f64(&mut self) -> Option<f64> {
        self.take::<8>().map(f64::from_le_bytes)
    }
    /// `n` f32s; the caller checked that they are there.
    fn f32s(&mut self, n: usize) -> Vec<f32> {
        let s = &self.b[self.at..self.at + 4 * n];
        self.at += 4 * n;
        s.chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn small_map() -> TerrainMap {
        let (w, h) = (8u32, 6u32);
        let n = (w * h) as usize;
        TerrainMap {
            frame: MapFrame::new(-69.373, 32.319, 1_737_400.0),
            sun_azimuth_deg: 100.0,
            sun_elevation_deg: 8.6,
            camera: CameraModel::default(),
            levels: vec![MapLevel {
                spacing_m: 2.0,
                e0_m: -7.0,
                n0_m: -5.0,
                width: w,
                height: h,
                iof: (0..n).map(|i| i as f32 * 0.01).collect(),
                height_m: (0..n).map(|i| (i % w as usize) as f32).collect(),
            }],
        }
    }

    #[test]
    fn a_map_reads_back_as_written_and_a_damaged_one_is_refused() {
        let dir = std::env::temp_dir().join(format!("oils-map-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("m.oilsmap");
        let map = small_map();
        map.write(&path).unwrap();
        assert_eq!(TerrainMap::load(&path).unwrap(), map);
        let mut bytes = std::fs::read(&path).unwrap();
        bytes[100] ^= 1;
        std::fs::write(&path, &bytes).unwrap();
        let e = TerrainMap::load(&path).unwrap_err().to_string();
        assert!(e.contains("hash does not match"), "{e}");
        std::fs::write(
            &path,
            b"OILSLOG8 and more bytes than a header holds, but not a map at all......",
        )
        .unwrap();
        let e = TerrainMap::load(&path).unwrap_err().to_string();
        assert!(e.contains("not an OILSMAP1"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn heights_are_bilinear_and_none_outside() {
        let map = small_map();
        let l = &map.levels[0];
        // Column c holds height c; e = -7 + 2 c.
        assert!((l.height_at(-6.0, -3.0).unwrap() - 0.5).abs() < 1e-12);
        assert!((l.height_at(7.0, 5.0).unwrap() - 7.0).abs() < 1e-12);
        assert!(l.height_at(7.5, 0.0).is_none());
        assert!(l.height_at(0.0, -5.5).is_none());
    }

    #[test]
    fn the_projection_keeps_distance_and_azimuth_and_inverts() {
        let f = MapFrame::new(-69.373, 32.319, 1_737_400.0);
        for (e, n, h) in [
            (0.0, 0.0, 0.0),
            (1000.0, -2000.0, 35.0),
            (-8000.0, 3000.0, -120.0),
        ] {
            let p = f.mcmf_of_map(e, n, h);
            let (e2, n2, h2) = f.map_of_mcmf(&p);
            assert!((e - e2).abs() < 1e-6 && (n - n2).abs() < 1e-6 && (h - h2).abs() < 1e-6);
            // The great-circle distance from the site is hypot(e, n).
            let ang = p.normalize().dot(&f.axes_mcmf()[2]).clamp(-1.0, 1.0).acos();
            assert!((ang * f.radius_m - e.hypot(n)).abs() < 1e-6);
        }
    }
}
