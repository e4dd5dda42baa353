//! The profile reader: any bytes give a profile that keeps the rules, or an error.
#![no_main]
use libfuzzer_sys::fuzz_target;
use oils_shared::profile::{ThrustProfile, MAX_PROFILE_END_S, RATED_THRUST_N};

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    match ThrustProfile::parse(text) {
        Ok(p) => {
            let rows = p.rows();
            assert!(!rows.is_empty());
            assert!(rows.windows(2).all(|w| w[0].t_ns < w[1].t_ns));
            for r in rows {
                assert!(r.t_ns >= 0 && r.t_ns as f64 <= MAX_PROFILE_END_S * 1e9);
                assert!(r
                    .thrust_cmd_n
                    .iter()
                    .all(|c| (0.0..=RATED_THRUST_N).contains(c)));
            }
            assert_eq!(ThrustProfile::parse(&p.to_csv()).unwrap(), p);
        }
        Err(e) => assert!(e.to_string().len() < 400),
    }
});
