//! ikid: real-time inverse kinematics and dynamics of the human wrist from motion-capture
//! markers.
//!
//! A small MLP over a short window of marker frames predicts the wrist's three angles (or
//! torques). This crate is the pure core: the [`body`] model and its conventions, the
//! [`features`] a network sees, the allocation-free [`net`] kernels, [`model`] files and the
//! frame-by-frame [`stream`]; the classical [`reference`](mod@reference) solvers (IK by segment
//! fitting, ID by Newton–Euler) the networks are measured against; and the [`tracker`], a
//! Kalman filter over the body model giving angles, velocities, accelerations and torques per
//! frame, optionally refined by a network.
//!
//! Every type a caller passes is this crate's or std's: frames are slices of `f32` (or `f64`
//! for the [`Tracker`]), and the [`nalgebra`] version the crate uses (for
//! [`Calibration::from_matrices`]'s rotation matrices) is re-exported as `ikid::nalgebra`, so a
//! host needs no nalgebra of its own. The shipped models are reachable by name through
//! [`shipped`] (from the source tree, or compiled in with the feature `embedded-models`).
//!
//! # A model, frame by frame
//!
//! A [`Stream`] predicts once its window is full; [`Model::predict`] does a whole recording.
//!
//! ```
//! use ikid::body::BodyModel;
//!
//! let model = ikid::shipped::load("wrist-ik")?;
//! // Two seconds of a slow wrist movement at the model's rate, as the body model's markers
//! // (six markers × x, y, z in metres, one frame after another).
//! let rate = model.card().frame_rate_hz;
//! let q: Vec<f64> = (0..2000).flat_map(|i| {
//!     let t = i as f64 / rate;
//!     [0.5 * (1.1 * t).sin(), -0.4 * (0.7 * t).sin(), 0.15 * (1.9 * t).cos()]
//! }).collect();
//! let frames: Vec<f32> = BodyModel::default().marker_frames(&q, 0.3)?.iter().map(|&v| v as f32).collect();
//!
//! let mut stream = model.stream();
//! let mut last = None;
//! for frame in frames.chunks_exact(model.frame_len()) {
//!     if let Some(angles) = stream.push(frame)? {
//!         last = Some([angles[0], angles[1], angles[2]]); // s_p, e_f, ad_ab, rad
//!     }
//! }
//! let last = last.expect("a prediction once the window is full");
//! assert!((f64::from(last[0]) - q[q.len() - 3]).abs() < 0.1, "s_p {last:?}");
//! # Ok::<(), ikid::Error>(())
//! ```
//!
//! # The tracker: angles, velocities, accelerations and torques
//!
//! A [`Tracker`] takes the same `f32` frames (or `f64`) and gives q, q̇, q̈ and τ for every
//! frame once one with every marker has started it, with [`status`] bits saying what it did.
//!
//! ```
//! use ikid::body::BodyModel;
//! use ikid::{Tracker, TrackerSettings};
//!
//! let settings = TrackerSettings::new(1000.0);
//! let mut tracker = Tracker::new(BodyModel::default(), settings)?;
//! tracker.set_refiner(Some(ikid::shipped::load("wrist-track")?))?; // optional
//! let q: Vec<f64> = (0..500).flat_map(|i| [0.3, -0.2 * (i as f64 / 200.0).sin(), 0.1]).collect();
//! let frames = BodyModel::default().marker_frames(&q, 0.3)?;
//! let mut estimate = None;
//! for frame in frames.chunks_exact(ikid::body::MARKER_FRAME_LEN) {
//!     estimate = tracker.push(frame)?;
//! }
//! let out = estimate.expect("started on the first frame: every marker present");
//! assert!((out.state.q[0] - 0.3).abs() < 0.05, "s_p {:?}", out.state.q);
//! assert_eq!(out.status & ikid::status::IMPLAUSIBLE, 0);
//! println!("tau {:?} N·m, status bits {:#x}", out.tau, out.status);
//! # Ok::<(), ikid::Error>(())
//! ```
//!
//! # Calibration
//!
//! A subject's marker placement, as two rotation matrices (e.g. the `"forearm"` and `"hand"`
//! arrays of a file written by `ikid calibrate`), built with the re-exported nalgebra; a
//! matrix that is not a rotation is refused.
//!
//! ```
//! use ikid::nalgebra::{Matrix3, Rotation3, Vector3};
//! use ikid::{Calibration, ErrorKind};
//!
//! let tilt = Rotation3::from_axis_angle(&Vector3::z_axis(), 10f64.to_radians()).into_inner();
//! let calibration = Calibration::from_matrices(tilt, Matrix3::identity())?;
//! let model = ikid::shipped::load("wrist-ik")?;
//! let mut stream = model.stream();
//! stream.set_calibration(Some(calibration))?;
//!
//! let sheared = Matrix3::new(1.0, 0.5, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0);
//! let err = Calibration::from_matrices(sheared, Matrix3::identity()).unwrap_err();
//! assert_eq!(err.kind(), ErrorKind::Argument);
//! # Ok::<(), ikid::Error>(())
//! ```
//!
//! # Errors
//!
//! Every fallible call returns an [`Error`]; [`Error::kind`] sorts it into four
//! [`ErrorKind`]s (what the C ABI's status codes and Python's exception classes are),
//! [`Error::code`] gives a stable reason and [`Error::frame`] the frame it is about.
//!
//! ```
//! use ikid::ErrorKind;
//!
//! let model = ikid::shipped::load("wrist-ik")?;
//! let mut stream = model.stream();
//! let err = stream.push(&[0.0; 17]).unwrap_err();
//! assert_eq!((err.kind(), err.code()), (ErrorKind::Input, "frame_length"));
//! assert!(err.to_string().contains("a marker frame"), "{err}");
//!
//! let err = ikid::Model::load("/nonexistent/wrist-ik.safetensors").unwrap_err();
//! assert_eq!(err.kind(), ErrorKind::Io);
//! let err = ikid::Model::from_bytes(b"not a model").unwrap_err();
//! assert_eq!(err.kind(), ErrorKind::ModelFile);
//! let err = ikid::shipped::load("wrist-xyz").unwrap_err();
//! assert_eq!(err.kind(), ErrorKind::Argument);
//! # Ok::<(), ikid::Error>(())
//! ```

#![deny(missing_docs)]

pub mod body;
pub mod calibration;
pub mod cluster;
pub mod error;
pub mod features;
pub mod gaps;
pub mod model;
pub mod net;
pub mod noise;
pub mod reference;
pub mod rng;
pub mod shipped;
pub mod status;
pub mod stream;
pub mod testing;
pub mod tracker;

pub use calibration::{Calibration, MarkerShapes, SegmentShapes, marker_shapes};
pub use error::{Error, ErrorKind, Result};
pub use features::{FeatureSet, FrameKind};
pub use gaps::{GapFiller, MissingMarkers};
pub use model::{Model, ModelCard, OutputSpec};
pub use stream::Stream;
pub use tracker::{Tracker, TrackerOutput, TrackerSettings};

/// The linear algebra crate of ikid's API, at the version ikid uses (for
/// [`Calibration::from_matrices`]).
pub use nalgebra;

/// This crate's version.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");

#[cfg(test)]
mod module_graph {
    //! No module cycles in the core (docs/ARCHITECTURE.md, "Dependency rules"): the top-level
    //! modules' dependencies, read from their sources, form a directed acyclic graph.

    use std::collections::{BTreeMap, BTreeSet};
    use std::path::Path;

    /// A file's code without its comments and without its trailing test module(s): what the
    /// crate itself is built from (tests may use anything, `testing` included).
    fn code(text: &str) -> String {
        let lines: Vec<&str> = text.lines().collect();
        let mut end = lines.len();
        for (i, line) in lines.iter().enumerate() {
            if line.trim() == "#[cfg(test)]" {
                let next = lines[i + 1..].iter().find(|l| !l.trim_start().starts_with("#[")).unwrap_or(&"");
                let next = next.trim_start().trim_start_matches("pub ").trim_start_matches("pub(crate) ");
                if next.starts_with("mod ") {
                    end = i;
                    break;
                }
            }
        }
        lines[..end].iter().map(|l| l.split("//").next().unwrap_or("")).collect::<Vec<_>>().join("\n")
    }

    /// The first path segment of every `crate::…` path in `code`, braces expanded
    /// (`crate::{a::X, b}` gives `a` and `b`).
    fn crate_paths(code: &str) -> BTreeSet<String> {
        let ident = |s: &str| s.chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect::<String>();
        let mut out = BTreeSet::new();
        for (at, _) in code.match_indices("crate::") {
            let rest = &code[at + "crate::".len()..];
            match rest.strip_prefix('{') {
                Some(group) => {
                    // The items at the group's own level: each starts the text, or follows a
                    // comma outside nested braces.
                    let (mut depth, mut start) = (0, true);
                    for (i, c) in group.char_indices() {
                        match c {
                            '{' => depth += 1,
                            '}' if depth == 0 => break,
                            '}' => depth -= 1,
                            ',' if depth == 0 => start = true,
                            c if start && !c.is_whitespace() => {
                                out.insert(ident(&group[i..]));
                                start = false;
                            }
                            _ => {}
                        }
                    }
                }
                None => {
                    out.insert(ident(rest));
                }
            }
        }
        out.retain(|s| !s.is_empty() && s != "self");
        out
    }

    /// Top-level module → the top-level modules its code names (crate-root re-exports such as
    /// `crate::Model` resolved to the module they come from).
    fn graph() -> BTreeMap<String, BTreeSet<String>> {
        let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
        let lib = std::fs::read_to_string(src.join("lib.rs")).expect("lib.rs");
        let lib = code(&lib);
        let mut reexports = BTreeMap::new();
        for line in lib.lines().filter_map(|l| l.trim().strip_prefix("pub use ")) {
            // `pub use nalgebra;` re-exports a crate, not one of the modules.
            let Some((module, names)) = line.trim_end_matches(';').split_once("::") else { continue };
            for name in names.trim_matches(|c| c == '{' || c == '}').split(',') {
                reexports.insert(name.trim().to_string(), module.to_string());
            }
        }
        let modules: Vec<String> = lib
            .lines()
            .filter_map(|l| l.trim().strip_prefix("pub mod ").or_else(|| l.trim().strip_prefix("mod ")))
            .map(|m| m.trim_end_matches(';').to_string())
            .collect();
        let mut graph = BTreeMap::new();
        for module in &modules {
            // The module's own file, or every file of its folder; `super::` in a top-level file
            // (or `super::super::` one level down) is the crate root.
            let mut files = vec![(src.join(format!("{module}.rs")), "super::")];
            if let Ok(dir) = std::fs::read_dir(src.join(module)) {
                for entry in dir.flatten() {
                    let path = entry.path();
                    let root = if path.ends_with("mod.rs") { "super::" } else { "super::super::" };
                    files.push((path, root));
                }
            }
            let mut deps = BTreeSet::new();
            for (path, root) in files.iter().filter(|(p, _)| p.is_file()) {
                let text = code(&std::fs::read_to_string(path).expect("source file"));
                let text = text.replace(root, "crate::");
                for name in crate_paths(&text) {
                    let target = reexports.get(&name).cloned().unwrap_or(name);
                    if modules.contains(&target) && &target != module {
                        deps.insert(target);
                    }
                }
            }
            graph.insert(module.clone(), deps);
        }
        graph
    }

    /// A cycle through the graph, as a path `a -> b -> … -> a`, if there is one.
    fn cycle(graph: &BTreeMap<String, BTreeSet<String>>) -> Option<Vec<String>> {
        fn visit(
            node: &str,
            graph: &BTreeMap<String, BTreeSet<String>>,
            path: &mut Vec<String>,
            done: &mut BTreeSet<String>,
        ) -> Option<Vec<String>> {
            if let Some(i) = path.iter().position(|p| p == node) {
                let mut found = path[i..].to_vec();
                found.push(node.to_string());
                return Some(found);
            }
            if done.contains(node) {
                return None;
            }
            path.push(node.to_string());
            for next in &graph[node] {
                if let Some(found) = visit(next, graph, path, done) {
                    return Some(found);
                }
            }
            path.pop();
            done.insert(node.to_string());
            None
        }
        let mut done = BTreeSet::new();
        graph.keys().find_map(|node| visit(node, graph, &mut Vec::new(), &mut done))
    }

    #[test]
    fn the_reader_sees_paths_braces_and_tests() {
        let text = "use crate::{body::X, error::{Error, Result}};\nuse super::net;\n// crate::tracker\n\
                    fn f() { crate::Model::load(\"\"); }\n#[cfg(test)]\n#[allow(x)]\nmod tests { use crate::testing; }";
        let names = crate_paths(&code(text).replace("super::", "crate::"));
        let want = ["Model", "body", "error", "net"].map(String::from);
        assert_eq!(names, BTreeSet::from(want));
        let looped = BTreeMap::from([
            ("a".to_string(), BTreeSet::from(["b".to_string()])),
            ("b".to_string(), BTreeSet::from(["a".to_string()])),
        ]);
        assert_eq!(cycle(&looped).map(|c| c.join(" -> ")), Some("a -> b -> a".into()));
    }

    #[test]
    fn the_core_has_no_module_cycles() {
        let graph = graph();
        // The reading found the modules and the edges everyone relies on.
        for (from, to) in [("stream", "model"), ("model", "net"), ("tracker", "stream"), ("features", "body")] {
            assert!(graph[from].contains(to), "{from} should depend on {to}: {graph:?}");
        }
        assert!(graph["net"].iter().all(|d| d == "error"), "net depends only on error: {:?}", graph["net"]);
        assert!(graph["error"].is_empty(), "error is the bottom layer: {:?}", graph["error"]);
        if let Some(found) = cycle(&graph) {
            panic!("module cycle in the core: {}", found.join(" -> "));
        }
    }
}
