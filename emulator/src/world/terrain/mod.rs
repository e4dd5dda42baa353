//! Terrain about the landing site: a reference sphere plus a digital elevation model in
//! map coordinates, with the queries the plant's footpads and the altimeter beams need.
//!
//! Geometry (`docs/terrain.md`): points live in the [`SiteFrame`] (Moon-fixed
//! East-North-Up axes at the site, origin on the reference sphere). A point's map
//! coordinates `(e, n)` are those of its radial projection in the azimuthal equidistant
//! projection about the site ([`MapProjection`]); the surface is at radius `R + h(e, n)`.
//!
//! Modules: [`frame`] (site <-> `mcmf`), [`map`] (projection), [`grid`] (bilinear DEM),
//! [`surface`] (point queries), [`ray`] (beam casts), [`pyramid`] (height bounds for them), [`spec`] (configuration),
//! [`synthetic`] (seeded craters), [`detail`] (the sub-metre layer about the site), [`geotiff`] (DEM files) and [`cache`] (build once).

pub mod cache;
pub mod detail;
pub mod error;
pub mod frame;
pub mod geotiff;
pub mod grid;
pub mod map;
pub mod pyramid;
pub mod ray;
pub mod spec;
pub mod surface;
pub mod synthetic;

pub use cache::{build, TerrainCache, TerrainKey};
pub use error::TerrainError;
pub use frame::SiteFrame;
pub use grid::Grid;
pub use map::MapProjection;
pub use ray::Hit;
pub use spec::{BoulderSpec, DetailSpec, GeoTiffSpec, SmoothSpec, SyntheticSpec, TerrainSpec};
pub use surface::Terrain;
