//! Python bindings of the ikid core (`ikid._native`): registration only.
//!
//! Each core module has one binding file here holding conversion and nothing else; NumPy
//! conversion lives in `conv.rs`, the exception hierarchy in `errors.rs`.
//!
//! Threading: every class is safe to share between threads. Array work (`predict`,
//! `compute_features`, `Stream.push_many`, `Model.load`) releases the GIL; a single-frame
//! `Stream.push` keeps it (its few microseconds cost less than releasing it). A `Stream` is
//! used by one thread at a time (concurrent calls on one stream raise `RuntimeError`,
//! "already borrowed").

mod body;
mod calibration;
mod conv;
mod errors;
mod features;
mod model;
mod reference;
mod sim;
mod tracker;

use pyo3::prelude::*;

#[pymodule(gil_used = false)]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", ikid::VERSION)?;
    errors::register(m)?;
    body::register(m)?;
    calibration::register(m)?;
    features::register(m)?;
    model::register(m)?;
    reference::register(m)?;
    sim::register(m)?;
    tracker::register(m)?;
    // Per-frame status bits, by name (`ikid.FRAME_STATUS`): one table, the core's.
    let bits = pyo3::types::PyDict::new(m.py());
    for (bit, name) in ikid::status::ALL {
        bits.set_item(name, bit)?;
    }
    m.add("FRAME_STATUS", bits)?;
    // A live stream's largest step in time taken as frames lost (a file's longer gaps restart it).
    m.add("MAX_TIME_GAP_S", ikid::stream::MAX_TIME_GAP_S)?;
    // How far a source's mean step may be off the rate before it is said to run at another.
    m.add("RATE_TOLERANCE", ikid::stream::RATE_TOLERANCE)?;
    // How long a tracker's first estimates are flagged restarted while its rates settle.
    m.add("LOST_S", ikid::tracker::LOST_S)?;
    Ok(())
}
