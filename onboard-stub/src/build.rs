//! The flight software a run names ([`FswSpec`]), built as a value: the reference GNC,
//! profile playback or a C library. The stub process and the emulator's in-process link
//! both start from here; nothing here parses a command line.

use crate::c_library::{CLibraryError, CLibraryFsw};
use crate::fsw::{FlightSoftware, FswSpec, GncOptions};
use crate::gnc::{GncConfig, GncConfigError, ReferenceGnc, SiteTarget};
use crate::playback::ProfilePlayback;
use oils_shared::profile::{ProfileError, ProfileRules, ThrustProfile};
use std::path::Path;

/// Why the flight software asked for could not be built.
#[derive(Debug, thiserror::Error)]
pub enum FswBuildError {
    /// Bad argument.
    #[error("{0}")]
    Argument(String),
    /// Profile unreadable.
    #[error(transparent)]
    Profile(#[from] ProfileError),
    /// GNC configuration invalid.
    #[error(transparent)]
    Gnc(#[from] GncConfigError),
    /// C flight software could not be loaded.
    #[error(transparent)]
    CLibrary(#[from] CLibraryError),
    /// The terrain navigation data could not be read.
    #[error(transparent)]
    Map(#[from] crate::gnc::terrain_map::MapError),
}

/// Largest `--fsw-params` file, bytes.
pub const MAX_FSW_PARAMS_BYTES: u64 = 1 << 20;

/// Builds the flight software asked for (allocation happens here, before tick 0).
/// `profile` is for playback (the file and the rules it is read with, see
/// `oils_shared::profile`); `fsw_params` (a text file of at most
/// [`MAX_FSW_PARAMS_BYTES`]) and `run_id` are handed to a C library's `oils_fsw_init`.
/// `site`: the scenario's landing site, which the reference GNC flies to (`None`: the
/// default scenario's, [`SiteTarget::CHANDRAYAAN_3`]); a C library is not told it.
/// `gnc`: what the reference GNC navigates from and turns the vehicle with.
pub fn build_fsw(
    spec: &FswSpec,
    profile: Option<(&Path, &ProfileRules)>,
    fsw_params: Option<&Path>,
    run_id: u64,
    site: Option<SiteTarget>,
    gnc: GncOptions,
) -> Result<Box<dyn FlightSoftware>, FswBuildError> {
    build_fsw_expecting(spec, profile, fsw_params, run_id, None, site, gnc)
}

/// The reference GNC's configuration for a run whose scenario names `site`, with the
/// run's `options`: the terrain navigation data `options.map` names is read here
/// (refused: a damaged file, or a map without sensor navigation to use it).
pub fn gnc_config(
    site: Option<SiteTarget>,
    options: &GncOptions,
) -> Result<GncConfig, FswBuildError> {
    let mut cfg = GncConfig::default();
    if let Some(site) = site {
        cfg.site = Some(site);
    }
    cfg.navigation = options.navigation;
    cfg.attitude_actuator = options.attitude;
    if options.hazard_avoidance {
        if options.navigation != crate::fsw::GncNavigation::Sensors {
            return Err(FswBuildError::Argument(
                "hazard avoidance is part of the sensor navigation: add --gnc-nav sensors".into(),
            ));
        }
        cfg.hazard.enabled = true;
    }
    if let Some(path) = &options.map {
        if options.navigation != crate::fsw::GncNavigation::Sensors {
            return Err(FswBuildError::Argument(format!(
                "the terrain map {} is for sensor navigation: add --gnc-nav sensors (gnc.navigation = \"sensors\")",
                path.display()
            )));
        }
        let map = crate::gnc::terrain_map::TerrainMap::load(path)?;
        cfg.sensor_nav.terrain.camera = map.camera.clone();
        cfg.sensor_nav.terrain.map = Some(std::sync::Arc::new(map));
    }
    Ok(cfg)
}

/// [`build_fsw`]; a C library must also have the BLAKE3 `c_blake3` when given (see
/// [`CLibraryFsw::load_expecting`]); `site` and `gnc` as for [`build_fsw`].
pub fn build_fsw_expecting(
    spec: &FswSpec,
    profile: Option<(&Path, &ProfileRules)>,
    fsw_params: Option<&Path>,
    run_id: u64,
    c_blake3: Option<&str>,
    site: Option<SiteTarget>,
    gnc: GncOptions,
) -> Result<Box<dyn FlightSoftware>, FswBuildError> {
    match spec {
        FswSpec::Gnc => Ok(Box::new(ReferenceGnc::new(gnc_config(site, &gnc)?)?)),
        FswSpec::CLibrary(path) => {
            let params = match fsw_params {
                Some(p) => read_params(p)?,
                None => String::new(),
            };
            Ok(Box::new(CLibraryFsw::load_expecting(
                path, run_id, &params, c_blake3,
            )?))
        }
        FswSpec::External => Err(FswBuildError::Argument(
            "--fsw external is flown by a client started by hand, not by this stub".into(),
        )),
        FswSpec::Playback => {
            let (path, rules) = profile.ok_or_else(|| {
                FswBuildError::Argument("--fsw playback needs --profile CSV".into())
            })?;
            Ok(Box::new(ProfilePlayback::new(ThrustProfile::load_with(
                path, rules,
            )?)))
        }
    }
}

/// A flight software parameter file: text of at most [`MAX_FSW_PARAMS_BYTES`].
fn read_params(p: &Path) -> Result<String, FswBuildError> {
    use std::io::Read;
    let bad = |why: String| FswBuildError::Argument(format!("--fsw-params {}: {why}", p.display()));
    let file = std::fs::File::open(p).map_err(|e| bad(e.to_string()))?;
    let mut bytes = Vec::new();
    file.take(MAX_FSW_PARAMS_BYTES + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| bad(e.to_string()))?;
    if bytes.len() as u64 > MAX_FSW_PARAMS_BYTES {
        return Err(bad(format!(
            "larger than {MAX_FSW_PARAMS_BYTES} bytes, the largest parameter file"
        )));
    }
    String::from_utf8(bytes).map_err(|_| bad("not UTF-8 text".into()))
}
