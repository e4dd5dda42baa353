//! The OILSLOG3 log reader: any bytes give a log (records whose CRC matched, damaged
//! positions, trailing bytes) or an error.
#![no_main]
use libfuzzer_sys::fuzz_target;
use oils_emulator::recorder::{parse_log, RECORD_SIZE};

fuzz_target!(|data: &[u8]| {
    if let Ok(log) = parse_log(std::path::Path::new("fuzz.oilslog"), data) {
        assert!(log.trailing_bytes < RECORD_SIZE);
        assert!((log.records.len() + log.damaged_records.len()) * RECORD_SIZE <= data.len());
    }
});
