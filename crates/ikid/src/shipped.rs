//! The models shipped with ikid (the Python package's `python/ikid/models/`), reachable from
//! Rust without copying them out of the source tree.
//!
//! [`load`] reads a shipped model by name. By default from [`MODELS_DIR`], the folder in the
//! source tree this crate was built from (a path or git dependency has it); with the cargo
//! feature `embedded-models` the files are compiled into the binary instead (about 1.4 MB),
//! for a host deployed without the source.
//!
//! ```
//! let model = ikid::shipped::load("wrist-ik")?;
//! assert_eq!(model.card().task, "ik");
//! assert!(ikid::shipped::NAMES.contains(&"wrist-track"));
//! # Ok::<(), ikid::Error>(())
//! ```

use crate::error::{Error, Result};
use crate::model::Model;
use std::path::PathBuf;

/// The folder holding the shipped model files in the source tree this crate was built from.
pub const MODELS_DIR: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../python/ikid/models");

/// The names of the shipped models (file stems in [`MODELS_DIR`]; a test checks they are the
/// folder's files).
pub const NAMES: [&str; 6] = ["wrist-chain", "wrist-id", "wrist-ik", "wrist-ik-100hz", "wrist-ik-250hz", "wrist-track"];

#[cfg(feature = "embedded-models")]
macro_rules! embedded {
    ($($name:literal),*) => {
        /// The bytes of the shipped model `name` compiled into this binary (feature
        /// `embedded-models`), or `None` for a name not shipped.
        pub fn bytes(name: &str) -> Option<&'static [u8]> {
            match name {
                $($name => Some(include_bytes!(concat!(env!("CARGO_MANIFEST_DIR"), "/../../python/ikid/models/", $name, ".safetensors"))),)*
                _ => None,
            }
        }
    };
}
#[cfg(feature = "embedded-models")]
embedded!("wrist-chain", "wrist-id", "wrist-ik", "wrist-ik-100hz", "wrist-ik-250hz", "wrist-track");

/// The file of the shipped model `name` in [`MODELS_DIR`] (it exists only where the source
/// tree does).
pub fn path(name: &str) -> PathBuf {
    PathBuf::from(MODELS_DIR).join(format!("{name}.safetensors"))
}

/// Loads and validates the shipped model `name` (one of [`NAMES`]): from the bytes compiled
/// in with the feature `embedded-models`, else from [`MODELS_DIR`]. A name not shipped is an
/// [`Error::BadArgument`] listing the names.
pub fn load(name: &str) -> Result<Model> {
    if !NAMES.contains(&name) {
        return Err(Error::BadArgument {
            what: "shipped model name",
            detail: format!("{name:?} is not shipped (shipped: {})", NAMES.join(", ")),
        });
    }
    #[cfg(feature = "embedded-models")]
    if let Some(bytes) = bytes(name) {
        return Model::from_bytes(bytes);
    }
    Model::load(path(name))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_names_are_the_folders_files_and_each_loads() {
        let mut files: Vec<String> = std::fs::read_dir(MODELS_DIR)
            .expect("the models folder")
            .filter_map(|e| e.ok()?.file_name().to_str()?.strip_suffix(".safetensors").map(String::from))
            .collect();
        files.sort();
        assert_eq!(files, NAMES);
        for name in NAMES {
            let model = load(name).unwrap_or_else(|e| panic!("{name}: {e}"));
            assert_eq!(model.card().name, name);
        }
        let err = load("wrist-xyz").unwrap_err().to_string();
        assert!(err.contains("\"wrist-xyz\" is not shipped") && err.contains("wrist-track"), "{err}");
    }

    #[cfg(feature = "embedded-models")]
    #[test]
    fn the_embedded_bytes_are_the_files() {
        for name in NAMES {
            assert_eq!(bytes(name).map(<[u8]>::to_vec), Some(std::fs::read(path(name)).unwrap()), "{name}");
        }
        assert!(bytes("wrist-xyz").is_none());
    }
}
