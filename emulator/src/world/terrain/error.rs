//! Typed errors of terrain specs and builds; each names what is wrong (and the file).

use std::path::PathBuf;

/// Why a terrain spec is invalid or a terrain could not be built.
#[derive(Debug, thiserror::Error)]
pub enum TerrainError {
    /// A spec field is out of its range or not finite.
    #[error("terrain spec: `{field}` {reason}")]
    InvalidSpec {
        /// The field's TOML key.
        field: &'static str,
        /// What is wrong with it.
        reason: String,
    },
    /// The site or reference radius is unusable.
    #[error("terrain site: {0}")]
    InvalidSite(String),
    /// The grid would be larger than the build accepts.
    #[error("terrain grid of {nodes} nodes exceeds the limit of {limit} (raise spacing_m or lower extent_m)")]
    GridTooLarge {
        /// Nodes the spec asks for.
        nodes: u64,
        /// The limit.
        limit: u64,
    },
    /// A built grid held a non-finite sample.
    #[error("terrain build produced a non-finite elevation")]
    NonFinite,
    /// The DEM file could not be opened or read.
    #[error("DEM {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The TIFF decoder refused the file (format, compression, corruption).
    #[error("DEM {path}: TIFF decoder: {source}")]
    Tiff {
        /// The file.
        path: PathBuf,
        /// The decoder's error.
        source: tiff::TiffError,
    },
    /// The file is a TIFF this reader does not support (what, in words).
    #[error("DEM {path}: unsupported: {what}")]
    Unsupported {
        /// The file.
        path: PathBuf,
        /// What is not supported.
        what: String,
    },
    /// The file lacks the georeference a DEM needs.
    #[error("DEM {path}: missing georeference: {what}")]
    MissingGeoreference {
        /// The file.
        path: PathBuf,
        /// Which tag or key is missing.
        what: String,
    },
    /// The site lies outside the file's raster, or on no-data.
    #[error("DEM {path}: site (lat {lat_deg:.6} deg, lon {lon_deg:.6} deg) {what}")]
    SiteNotCovered {
        /// The file.
        path: PathBuf,
        /// Site latitude, degrees.
        lat_deg: f64,
        /// Site east longitude, degrees.
        lon_deg: f64,
        /// "is outside the raster" or "falls on no-data".
        what: &'static str,
    },
}
