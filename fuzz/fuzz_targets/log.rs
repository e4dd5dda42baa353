//! The OILSLOG7 (and OILSLOG6) log reader: any bytes give a log (records whose CRC
//! matched, damaged positions, trailing bytes) or an error.
#![no_main]
use libfuzzer_sys::fuzz_target;
use oils_emulator::recorder::{parse_log, FRAME_HEADER_SIZE, FRAME_RECORDS};

fuzz_target!(|data: &[u8]| {
    if let Ok(log) = parse_log(std::path::Path::new("fuzz.oilslog"), data) {
        assert!(log.trailing_bytes <= data.len());
        // Every record read or counted damaged comes from a frame header of its own.
        let frames = data.len() / FRAME_HEADER_SIZE + 1;
        assert!(log.records.len() + log.damaged_records.len() <= frames * FRAME_RECORDS);
    }
});
