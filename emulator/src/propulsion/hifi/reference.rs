//! Frozen reference data used by the tests (not by the model).

/// Helium density `(pressure_pa, temperature_k, density_kg_m3)` from the reference
/// equation of state for helium (Ortiz-Vega et al.) as implemented in CoolProp 8.0.0,
/// `PropsSI('D', 'P', p, 'T', T, 'Helium')`. The first row is the bottle at its initial
/// state.
#[cfg(test)]
pub const HELIUM_DENSITY: &[(f64, f64, f64)] = &[
    (280.0e5, 293.15, 40.6139),
    (100.0e5, 293.15, 15.6679),
    (200.0e5, 250.00, 34.5987),
    (50.0e5, 250.00, 9.3588),
    (150.0e5, 200.00, 32.5844),
    (17.0e5, 200.00, 4.0417),
    (17.0e5, 275.00, 2.9498),
];
