//! The MCAP log reader (`mcap_log::parse_mcap`): any bytes give a log or an error, never a
//! panic, and what it accepts holds at most one record per message.
#![no_main]
use libfuzzer_sys::fuzz_target;
use oils_lab::mcap_log::parse_mcap;

fuzz_target!(|data: &[u8]| {
    if let Ok(log) = parse_mcap(std::path::Path::new("fuzz.mcap"), data) {
        assert!(log.damaged_records.is_empty());
        // Each record came from at least one message of at least a few bytes.
        assert!(log.records.len() <= data.len());
    }
});
