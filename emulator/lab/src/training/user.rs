//! Training on the user's own propulsion model rather than the bench's hifi: recorded
//! time series ([`train_on_data`], `oils train --data`) or a model the caller built and
//! hands in, driven by the excitation ([`train_on_model`], `oils train --truth fmu:`).
//! The cross-validation, the fits and the model file are [`super::train`]'s.
//!
//! Nothing can be derived from hifi here (the valve's stroke table, the ignition clock):
//! the configuration must give its valve filter plainly, as
//! `emulator/config/train-user.toml` ([`USER_CONFIG`]) does.

use super::dataset::Dataset;
use super::excitation::{Excitation, Segment};
use super::recorded::{self, RecordedRun};
use super::{train_recorded, Progress, ReferenceInfo, TrainConfig, TrainConfigError, TrainOutcome};
use oils_emulator::propulsion::surrogate::model_file::ReferenceOutput;
use oils_emulator::propulsion::Propulsion;

/// The committed configuration for a user's model (`emulator/config/train-user.toml`).
pub const USER_CONFIG: &str = include_str!("../../../config/train-user.toml");

/// The configuration resolved without hifi: an error that says what to change when it
/// asks for something derived from hifi.
fn resolve_plain(cfg: &TrainConfig) -> Result<TrainConfig, TrainConfigError> {
    cfg.validate()?;
    cfg.resolve(None).map(|(c, _)| c).map_err(|e| {
        TrainConfigError(format!(
            "{}; recorded data or an FMU have no hifi to derive them from: use a configuration without [variants.engine_valve.stroke] and [variants.engine_valve.ignition] (emulator/config/train-user.toml, the default with --data and --truth fmu:)",
            e.0
        ))
    })
}

/// Fewest samples cross-validation takes with `cfg` (what [`TrainConfig::validate`]
/// asks of the excitation).
pub fn min_samples(cfg: &TrainConfig) -> usize {
    20 * cfg.cv.folds * (cfg.cv.history_max + 2)
}

/// Trains on recorded runs (read by [`recorded::load`] at `cfg.sample_time_ns`), joined
/// in order ([`recorded::join`]). `info` names the data for the provenance (see
/// [`data_info`]).
pub fn train_on_data(
    cfg: &TrainConfig,
    runs: &[RecordedRun],
    info: &ReferenceInfo,
    progress: &dyn Progress,
) -> Result<TrainOutcome, TrainConfigError> {
    let cfg = resolve_plain(cfg)?;
    if let Some(r) = runs
        .iter()
        .find(|r| r.dataset.sample_time_ns != cfg.sample_time_ns)
    {
        return Err(TrainConfigError(format!(
            "{} was resampled to {} ns, the configuration's sample time is {} ns",
            r.path.display(),
            r.dataset.sample_time_ns,
            cfg.sample_time_ns
        )));
    }
    let (data, held) =
        recorded::join(runs).ok_or_else(|| TrainConfigError("no recorded data given".into()))?;
    let need = min_samples(&cfg);
    if data.len() < need {
        return Err(TrainConfigError(format!(
            "the recorded data hold {} samples ({:.2} s at {} s); {} folds with histories up to {} need at least {need} ({:.2} s)",
            data.len(),
            data.len() as f64 * cfg.sample_time_ns as f64 / 1e9,
            cfg.sample_time_ns as f64 / 1e9,
            cfg.cv.folds,
            cfg.cv.history_max,
            need as f64 * cfg.sample_time_ns as f64 / 1e9
        )));
    }
    let excitation = Excitation {
        sample_time_ns: cfg.sample_time_ns,
        inputs: data.inputs.clone(),
        segments: vec![Segment::Recorded; data.len()],
    };
    train_recorded(&cfg, excitation, data, held, info, progress)
}

/// Trains on `model` (the user's, built by the caller) driven by the configured
/// excitation at the sample time: what [`super::train_configured`] does with hifi.
pub fn train_on_model(
    cfg: &TrainConfig,
    model: &mut dyn Propulsion,
    info: &ReferenceInfo,
    progress: &dyn Progress,
) -> Result<TrainOutcome, TrainConfigError> {
    let cfg = resolve_plain(cfg)?;
    let held = ReferenceOutput::of(&model.output());
    let excitation = cfg.excitation.generate(cfg.sample_time_ns);
    progress.begin("data", excitation.inputs.len() as u64);
    let recorded = Dataset::record(model, &excitation, || progress.tick());
    progress.finish();
    if let Some(why) = model.failure() {
        return Err(TrainConfigError(format!(
            "the {} model failed while the excitation ran: {why}",
            model.name()
        )));
    }
    train_recorded(&cfg, excitation, recorded, held, info, progress)
}

/// Provenance of recorded files: reference `data`, the hash of the files' bytes.
pub fn data_info(paths: &[std::path::PathBuf]) -> Result<ReferenceInfo, recorded::DataError> {
    Ok(ReferenceInfo {
        name: "data".into(),
        param_hash: recorded::hash_files(paths)?,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::training::excitation::ExcitationConfig;
    use crate::training::{cv::CvConfig, Quiet};
    use oils_emulator::config::PropulsionConfig;
    use oils_emulator::propulsion::ideal::IdealPropulsion;

    fn small() -> TrainConfig {
        let mut cfg = TrainConfig::from_toml(USER_CONFIG).unwrap();
        cfg.excitation = ExcitationConfig {
            levels: 2,
            burn_s: 0.0,
            starts: 0,
            cycles: 2,
            ..Default::default()
        };
        cfg.cv = CvConfig {
            history_max: 2,
            mu_count: 3,
            ..cfg.cv
        };
        cfg
    }

    #[test]
    fn the_committed_user_config_derives_nothing_and_the_hifi_one_is_refused() {
        let cfg = TrainConfig::from_toml(USER_CONFIG).unwrap();
        assert!(resolve_plain(&cfg).is_ok());
        let hifi = TrainConfig::from_toml(include_str!("../../../config/train.toml")).unwrap();
        let e = resolve_plain(&hifi).unwrap_err().to_string();
        assert!(e.contains("train-user.toml"), "{e}");
    }

    #[test]
    fn recorded_data_train_like_the_model_that_made_them() {
        // The excitation through the ideal model, written as a recording, trains the
        // same model file as the ideal model driven directly (but for the provenance).
        let cfg = small();
        let info = ReferenceInfo {
            name: "ideal".into(),
            param_hash: "x".into(),
        };
        let mut m = IdealPropulsion::new(&PropulsionConfig::default());
        let direct = train_on_model(&cfg, &mut m, &info, &Quiet).unwrap();
        let d = &direct.dataset;
        let mut csv = recorded::REQUIRED_COLUMNS.join(",") + "\n";
        let row = |t: usize, i: &[f64], s: &[f64]| {
            let mut l = format!("{}", t as f64 * 0.01);
            for v in i.iter().chain(s) {
                l.push_str(&format!(",{v}"));
            }
            l + "\n"
        };
        csv.push_str(&row(0, &d.inputs[0], &d.initial));
        for k in 0..d.len() {
            csv.push_str(&row(k + 1, &d.inputs[k], &d.states[k]));
        }
        let run = recorded::read(csv.as_bytes(), "x.csv".as_ref(), cfg.sample_time_ns).unwrap();
        let from_data = train_on_data(&cfg, &[run], &info, &Quiet).unwrap();
        assert_eq!(from_data.dataset.states, d.states);
        assert_eq!(from_data.dataset.inputs, d.inputs);
        assert_eq!(
            from_data.deployed_model().model,
            direct.deployed_model().model
        );
    }

    #[test]
    fn too_little_data_is_refused_with_the_numbers() {
        let cfg = small();
        let csv = format!(
            "{}\n0,0,0,0,0,0,0,0,0,0,0,0,0,1,0,0\n0.01,0,0,0,0,0,0,0,0,0,0,0,0,1,0,0\n",
            recorded::REQUIRED_COLUMNS.join(",")
        );
        let run = recorded::read(csv.as_bytes(), "x.csv".as_ref(), cfg.sample_time_ns).unwrap();
        let info = ReferenceInfo {
            name: "data".into(),
            param_hash: String::new(),
        };
        let e = train_on_data(&cfg, &[run], &info, &Quiet).unwrap_err();
        assert!(e.to_string().contains("hold 1 samples"), "{e}");
    }
}
