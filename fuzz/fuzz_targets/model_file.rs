//! The surrogate model file loader: any text gives a checked model or an error.
#![no_main]
use libfuzzer_sys::fuzz_target;
use oils_emulator::propulsion::surrogate::model_file::ModelFile;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(f) = ModelFile::parse(text) {
        assert!(f.model.check().is_ok());
    }
});
