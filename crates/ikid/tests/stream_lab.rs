//! A stream told its lab's up direction reads a turned lab's frames as the body model's lab:
//! a model that reads gravity (wrist-chain's `angles_gravity`) gives the same outputs.

use ikid::FeatureSet;
use ikid::testing::{random_frames, random_model};
use nalgebra::{Rotation3, Unit, Vector3};

/// Every marker of `frames` turned by `turn` (a lab whose up is `turn * +Y`).
fn turned(frames: &[f32], turn: &Rotation3<f64>) -> Vec<f32> {
    frames
        .chunks_exact(3)
        .flat_map(|m| {
            let v = turn * Vector3::new(f64::from(m[0]), f64::from(m[1]), f64::from(m[2]));
            [v.x as f32, v.y as f32, v.z as f32]
        })
        .collect()
}

fn outputs(model: &ikid::Model, frames: &[f32], up: Option<[f64; 3]>) -> Vec<f32> {
    let mut stream = model.stream();
    if let Some(up) = up {
        stream.set_lab_up(up).unwrap();
    }
    let mut out = vec![0.0; stream.rows_for(frames.len() / 18) * model.n_outputs()];
    let rows = stream.push_many(frames, &mut out).unwrap();
    out.truncate(rows * model.n_outputs());
    out
}

#[test]
fn a_model_that_reads_gravity_gives_the_body_models_lab_outputs_in_a_turned_lab() {
    let model = random_model(FeatureSet::AnglesGravity, 5, &[16], 3, 8);
    let frames = random_frames(FeatureSet::AnglesGravity, 200, 5);
    let own = outputs(&model, &frames, None);
    let axis = |v: [f64; 3]| Unit::new_normalize(Vector3::from(v));
    for (name, turn) in [
        ("Z up", Rotation3::from_axis_angle(&axis([1.0, 0.0, 0.0]), std::f64::consts::FRAC_PI_2)),
        ("Y down", Rotation3::from_axis_angle(&axis([0.0, 0.0, 1.0]), std::f64::consts::PI)),
        ("tilted", Rotation3::from_axis_angle(&axis([0.3, -0.5, 0.8]), 2.1)),
    ] {
        let lab = turned(&frames, &turn);
        let up: [f64; 3] = (3.0 * (turn * Vector3::y())).into();
        let told = outputs(&model, &lab, Some(up));
        let untold = outputs(&model, &lab, None);
        let worst = |a: &[f32]| a.iter().zip(&own).map(|(x, y)| (x - y).abs()).fold(0.0, f32::max);
        // f32 frames turned twice: rounding, not gravity.
        assert!(worst(&told) < 1e-3, "{name}: {}", worst(&told));
        assert!(worst(&untold) > 100.0 * worst(&told).max(1e-5), "{name}: untold {}", worst(&untold));
    }
    // An angles-only model does not depend on it.
    let angles = random_model(FeatureSet::Angles, 5, &[16], 3, 8);
    let lab = turned(&frames, &Rotation3::from_axis_angle(&axis([1.0, 0.0, 0.0]), 1.0));
    let a = outputs(&angles, &frames, None);
    let b = outputs(&angles, &lab, None);
    assert!(a.iter().zip(&b).all(|(x, y)| (x - y).abs() < 1e-3));
    // A bad up is refused, naming it.
    let e = model.stream().set_lab_up([0.0; 3]).unwrap_err().to_string();
    assert!(e.contains("up") && e.contains("non-zero"), "{e}");
}
