//! The configuration loaders (scenario, run configuration, hifi parameters): any text
//! parses and validates, or is refused; nothing accepted is non-finite.
#![no_main]
use libfuzzer_sys::fuzz_target;
use oils_emulator::config::ScenarioConfig;
use oils_emulator::propulsion::hifi::HifiParams;
use oils_emulator::run_config::RunConfig;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(c) = toml::from_str::<ScenarioConfig>(text) {
        if c.validate().is_ok() {
            assert!(c.nav_noise.position_m.is_finite() && c.touchdown.stability_factor.is_finite());
        }
    }
    if let Ok(c) = toml::from_str::<RunConfig>(text) {
        if c.validate().is_ok() {
            assert!(c.duration_s.is_finite() && c.speed.is_finite());
            let _ = c.to_toml();
        }
    }
    if let Ok(p) = toml::from_str::<HifiParams>(text) {
        if p.validate().is_ok() {
            assert!(p.bottle.initial_pressure_pa <= 1e8);
        }
    }
});
