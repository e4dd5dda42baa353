//! The terrain configuration (TOML `[terrain]`, `kind = "smooth" | "synthetic" |
//! "geotiff"`), its validation and its hash (the cache key of built terrains).

pub use super::detail::DetailSpec;
use super::error::TerrainError;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// Where the terrain comes from. The default, `smooth`, is the bare sphere (`h = 0`).
/// Any kind may carry a `[terrain.detail]` table: a seeded sub-metre layer about the
/// site ([`DetailSpec`], `docs/terrain.md`), off unless given.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum TerrainSpec {
    /// The reference sphere, `h = 0`.
    Smooth(SmoothSpec),
    /// A seeded synthetic cratered surface.
    Synthetic(SyntheticSpec),
    /// A GeoTIFF DEM file, resampled about the site.
    Geotiff(GeoTiffSpec),
}

impl Default for TerrainSpec {
    fn default() -> Self {
        TerrainSpec::Smooth(SmoothSpec::default())
    }
}

/// The bare sphere; only a detail layer, if any, to configure.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(default, deny_unknown_fields)]
pub struct SmoothSpec {
    /// The seeded detail layer about the site, if any.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub detail: Option<DetailSpec>,
}

/// A seeded synthetic surface: craters from a power-law size-frequency distribution
/// with fresh-crater shapes, a regional slope and optional boulders (`docs/terrain.md`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SyntheticSpec {
    /// Seed of the surface's random streams.
    pub seed: u64,
    /// Side of the square grid centred on the site, m.
    pub extent_m: f64,
    /// Grid node spacing, m.
    pub spacing_m: f64,
    /// Crater density as a multiple of the lunar equilibrium `N(>D) = 0.079 D^-2` per m^2
    /// (Gault 1970); 1 is an equilibrium (old mare) surface.
    pub crater_density: f64,
    /// Exponent `b` of the cumulative distribution `N(>D) = c D^-b` (2: equilibrium).
    pub crater_sfd_exponent: f64,
    /// Smallest crater drawn, m (smaller ones are below the grid's resolution).
    pub crater_min_diameter_m: f64,
    /// Largest crater drawn, m.
    pub crater_max_diameter_m: f64,
    /// Depth (rim crest to floor) over diameter of a fresh crater (Pike 1977: ~0.2).
    pub depth_to_diameter: f64,
    /// Rim height above the surroundings over diameter (Pike 1977: ~0.04).
    pub rim_height_to_diameter: f64,
    /// Regional slope, degrees.
    pub regional_slope_deg: f64,
    /// Azimuth of the regional downhill direction, degrees clockwise from north.
    pub slope_azimuth_deg: f64,
    /// Boulders on the surface, if any.
    pub boulders: Option<BoulderSpec>,
    /// The seeded detail layer about the site, if any.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub detail: Option<DetailSpec>,
}

impl Default for SyntheticSpec {
    fn default() -> Self {
        Self {
            seed: 1,
            extent_m: 4000.0,
            spacing_m: 4.0,
            crater_density: 1.0,
            crater_sfd_exponent: 2.0,
            crater_min_diameter_m: 16.0,
            crater_max_diameter_m: 500.0,
            depth_to_diameter: 0.2,
            rim_height_to_diameter: 0.04,
            regional_slope_deg: 0.0,
            slope_azimuth_deg: 0.0,
            boulders: None,
            detail: None,
        }
    }
}

/// Boulders from the Golombek & Rapp (1997) rock model: cumulative fractional area
/// covered by rocks wider than D is `k exp(-q D)`, `q = 1.79 + 0.152 / k` (D in m).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BoulderSpec {
    /// Rock abundance `k`: the fractional area covered by all rocks (0..1).
    pub rock_abundance: f64,
    /// Smallest boulder drawn, m (at least two grid spacings to be resolved).
    pub min_diameter_m: f64,
    /// Largest boulder drawn, m.
    pub max_diameter_m: f64,
}

impl Default for BoulderSpec {
    fn default() -> Self {
        Self {
            rock_abundance: 0.05,
            min_diameter_m: 1.0,
            max_diameter_m: 8.0,
        }
    }
}

/// A GeoTIFF DEM: heights in metres (times the file's scale, plus its offset) above
/// the sphere, resampled onto a square grid about the site.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GeoTiffSpec {
    /// The file.
    pub path: PathBuf,
    /// Side of the resampled square about the site, m.
    #[serde(default = "default_geotiff_extent_m")]
    pub extent_m: f64,
    /// Resampled node spacing, m (default: the file's pixel size on the ground at the
    /// site).
    #[serde(default)]
    pub spacing_m: Option<f64>,
    /// Metres per stored unit, overriding the file's GDAL scale (e.g. 0.5 for LOLA's
    /// int16 half-metres when the file does not say so).
    #[serde(default)]
    pub height_scale: Option<f64>,
    /// Metres added after scaling, overriding the file's GDAL offset.
    #[serde(default)]
    pub height_offset_m: Option<f64>,
    /// The seeded detail layer about the site, if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub detail: Option<DetailSpec>,
}

fn default_geotiff_extent_m() -> f64 {
    10_000.0
}

/// Largest grid a build accepts (64 M nodes, 512 MB of f64).
pub const MAX_GRID_NODES: u64 = 1 << 26;

pub(super) fn positive(field: &'static str, v: f64) -> Result<(), TerrainError> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(TerrainError::InvalidSpec {
            field,
            reason: format!("must be positive and finite, got {v}"),
        })
    }
}

pub(super) fn in_range(field: &'static str, v: f64, lo: f64, hi: f64) -> Result<(), TerrainError> {
    if v.is_finite() && v >= lo && v <= hi {
        Ok(())
    } else {
        Err(TerrainError::InvalidSpec {
            field,
            reason: format!("must be within [{lo}, {hi}], got {v}"),
        })
    }
}

/// Nodes along one side of a square of `extent_m` at `spacing_m` (both validated).
pub(super) fn nodes_per_side(extent_m: f64, spacing_m: f64) -> u64 {
    (extent_m / spacing_m).ceil() as u64 + 1
}

pub(super) fn check_grid_size(extent_m: f64, spacing_m: f64) -> Result<(), TerrainError> {
    let side = nodes_per_side(extent_m, spacing_m);
    let nodes = side.saturating_mul(side);
    if nodes > MAX_GRID_NODES {
        return Err(TerrainError::GridTooLarge {
            nodes,
            limit: MAX_GRID_NODES,
        });
    }
    Ok(())
}

impl SyntheticSpec {
    /// Checks every field's range; run before tick 0.
    pub fn validate(&self) -> Result<(), TerrainError> {
        positive("extent_m", self.extent_m)?;
        positive("spacing_m", self.spacing_m)?;
        if self.spacing_m * 2.0 > self.extent_m {
            return Err(TerrainError::InvalidSpec {
                field: "spacing_m",
                reason: format!("must be at most half of extent_m, got {}", self.spacing_m),
            });
        }
        check_grid_size(self.extent_m, self.spacing_m)?;
        in_range("crater_density", self.crater_density, 0.0, 100.0)?;
        in_range("crater_sfd_exponent", self.crater_sfd_exponent, 0.5, 5.0)?;
        positive("crater_min_diameter_m", self.crater_min_diameter_m)?;
        positive("crater_max_diameter_m", self.crater_max_diameter_m)?;
        if self.crater_max_diameter_m < self.crater_min_diameter_m {
            return Err(TerrainError::InvalidSpec {
                field: "crater_max_diameter_m",
                reason: "must be at least crater_min_diameter_m".into(),
            });
        }
        // Keep the expected crater count bounded (and the build cheap).
        let expected = super::synthetic::expected_craters(self);
        if expected > 1e7 {
            return Err(TerrainError::InvalidSpec {
                field: "crater_min_diameter_m",
                reason: format!("gives {expected:.3e} expected craters (limit 1e7)"),
            });
        }
        in_range("depth_to_diameter", self.depth_to_diameter, 0.0, 1.0)?;
        in_range(
            "rim_height_to_diameter",
            self.rim_height_to_diameter,
            0.0,
            1.0,
        )?;
        in_range("regional_slope_deg", self.regional_slope_deg, 0.0, 60.0)?;
        in_range("slope_azimuth_deg", self.slope_azimuth_deg, -360.0, 360.0)?;
        if let Some(b) = &self.boulders {
            in_range("boulders.rock_abundance", b.rock_abundance, 1e-4, 0.5)?;
            positive("boulders.min_diameter_m", b.min_diameter_m)?;
            positive("boulders.max_diameter_m", b.max_diameter_m)?;
            if b.max_diameter_m < b.min_diameter_m {
                return Err(TerrainError::InvalidSpec {
                    field: "boulders.max_diameter_m",
                    reason: "must be at least boulders.min_diameter_m".into(),
                });
            }
            let expected = super::synthetic::expected_boulders(self, b);
            if expected > 1e7 {
                return Err(TerrainError::InvalidSpec {
                    field: "boulders.min_diameter_m",
                    reason: format!("gives {expected:.3e} expected boulders (limit 1e7)"),
                });
            }
        }
        Ok(())
    }
}

impl TerrainSpec {
    /// The bare sphere without detail: what the plant meets as an exact sphere.
    pub fn is_bare_sphere(&self) -> bool {
        matches!(self, TerrainSpec::Smooth(SmoothSpec { detail: None }))
    }

    /// The detail layer this spec asks for, if any.
    pub fn detail(&self) -> Option<&DetailSpec> {
        match self {
            TerrainSpec::Smooth(s) => s.detail.as_ref(),
            TerrainSpec::Synthetic(s) => s.detail.as_ref(),
            TerrainSpec::Geotiff(g) => g.detail.as_ref(),
        }
    }

    /// Checks the spec's numbers (a GeoTIFF file itself is checked when it is read).
    pub fn validate(&self) -> Result<(), TerrainError> {
        match self {
            TerrainSpec::Smooth(s) => s.detail.as_ref().map_or(Ok(()), DetailSpec::validate),
            TerrainSpec::Synthetic(s) => {
                s.validate()?;
                s.detail.as_ref().map_or(Ok(()), DetailSpec::validate)
            }
            TerrainSpec::Geotiff(g) => {
                if let Some(d) = &g.detail {
                    d.validate()?;
                }
                if g.path.as_os_str().is_empty() {
                    return Err(TerrainError::InvalidSpec {
                        field: "path",
                        reason: "is empty".into(),
                    });
                }
                positive("extent_m", g.extent_m)?;
                if let Some(s) = g.spacing_m {
                    positive("spacing_m", s)?;
                    check_grid_size(g.extent_m, s)?;
                }
                if let Some(s) = g.height_scale {
                    positive("height_scale", s)?;
                }
                if let Some(o) = g.height_offset_m {
                    in_range("height_offset_m", o, -1e7, 1e7)?;
                }
                Ok(())
            }
        }
    }

    /// A 64-bit hash of the spec (its canonical JSON through BLAKE3): equal specs hash
    /// equal. A GeoTIFF spec hashes its path, not the file's content.
    pub fn spec_hash(&self) -> u64 {
        // Only a non-UTF-8 path fails to serialise; its Debug text stands in.
        let json = serde_json::to_vec(self).unwrap_or_else(|_| format!("{self:?}").into_bytes());
        let h = blake3::hash(&json);
        let mut b = [0u8; 8];
        b.copy_from_slice(&h.as_bytes()[..8]);
        u64::from_le_bytes(b)
    }
}
