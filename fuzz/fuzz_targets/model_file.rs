//! The model loader (safetensors container + JSON model card + tensor checks) on arbitrary
//! bytes: it must return a model or an error, never panic, hang or read out of bounds; a
//! model it accepts must predict finite values or refuse.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(model) = ikid::Model::from_bytes(data) {
        ikid::testing::exercise(&model);
    }
});
