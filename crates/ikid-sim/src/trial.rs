//! Running a protocol through the rapier model and recording the ground truth.
//!
//! Control is computed torque on the simulated state: `τ = ID(q, q̇, q̈_ref + Kp e + Kd ė)`
//! with `e = q_ref − q`, so the arm follows the protocol while rapier integrates the
//! dynamics. What is recorded is what happened: rapier's `q`, `q̇`, the acceleration it
//! integrated (`(q̇_{n+1} − q̇_n)/dt`), the torque applied over that step, and the markers
//! on the simulated segments.

use crate::protocol::Protocol;
use crate::world::WristWorld;
use crate::{Result, check};
use ikid::body::{BodyModel, MARKER_FRAME_LEN, MARKERS, N_COORDINATES, Segment};
use ikid::reference::{JointState, inverse_dynamics};
use nalgebra::Point3;

/// How to simulate.
#[derive(Debug, Clone, PartialEq)]
pub struct SimConfig {
    /// The subject.
    pub body: BodyModel,
    /// Shoulder flexion, rad (the thesis used 0°, 45° and −20°).
    pub shoulder_flexion: f64,
    /// Physics step, s.
    pub dt: f64,
    /// Rapier solver iterations (substeps) per step.
    pub substeps: usize,
    /// Record every n-th step (output rate = 1 / (dt · n)).
    pub output_every: usize,
    /// Controller stiffness, 1/s² (natural frequency squared).
    pub kp: f64,
    /// Controller damping, 1/s.
    pub kd: f64,
}

impl Default for SimConfig {
    fn default() -> Self {
        SimConfig {
            body: BodyModel::default(),
            shoulder_flexion: 0.0,
            dt: 1e-3,
            substeps: 1,
            output_every: 1,
            kp: 400.0,
            kd: 40.0,
        }
    }
}

/// A simulated trial: per recorded frame, time and ground truth.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Trial {
    /// Time of each frame, s.
    pub time: Vec<f64>,
    /// Joint angles, rad.
    pub q: Vec<[f64; N_COORDINATES]>,
    /// Joint velocities, rad/s.
    pub qd: Vec<[f64; N_COORDINATES]>,
    /// Joint accelerations, rad/s².
    pub qdd: Vec<[f64; N_COORDINATES]>,
    /// Joint torques that produced the motion, N·m.
    pub tau: Vec<[f64; N_COORDINATES]>,
    /// Marker positions (lab, m), `MARKERS` order.
    pub markers: Vec<[f64; MARKER_FRAME_LEN]>,
    /// The prescribed angles the controller followed, rad.
    pub q_ref: Vec<[f64; N_COORDINATES]>,
}

/// Simulates `protocol` under `config`.
pub fn simulate(config: &SimConfig, protocol: &Protocol) -> Result<Trial> {
    check("dt", config.dt, config.dt > 0.0 && config.dt <= 0.01, "a step between 0 and 0.01 s")?;
    check("substeps", config.substeps as f64, (1..=64).contains(&config.substeps), "1..=64")?;
    check("output_every", config.output_every as f64, config.output_every >= 1, "at least 1")?;
    check(
        "shoulder_flexion",
        config.shoulder_flexion,
        config.shoulder_flexion.abs() <= std::f64::consts::PI,
        "within ±π rad",
    )?;
    check("kp", config.kp, config.kp >= 0.0, "non-negative")?;
    check("kd", config.kd, config.kd >= 0.0, "non-negative")?;
    check_body(&config.body)?;

    let steps = (protocol.duration() / config.dt).round() as usize;
    let mut world = WristWorld::new(&config.body, config.shoulder_flexion, config.dt, config.substeps);
    let frames = steps / config.output_every + 1;
    let mut trial = Trial::default();
    for v in [&mut trial.q, &mut trial.qd, &mut trial.qdd, &mut trial.tau, &mut trial.q_ref] {
        v.reserve(frames);
    }
    trial.markers.reserve(frames);
    let (mut q, mut qd) = world.state();
    for n in 0..steps {
        let t = n as f64 * config.dt;
        let reference = protocol.sample(t);
        let command: [f64; N_COORDINATES] = std::array::from_fn(|i| {
            reference.qdd[i] + config.kp * (reference.q[i] - q[i]) + config.kd * (reference.qd[i] - qd[i])
        });
        let tau = inverse_dynamics(&config.body, config.shoulder_flexion, &JointState { q, qd, qdd: command })?;
        let hand = world.hand_pose();
        world.step(&tau);
        let (q_next, qd_next) = world.state();
        if n % config.output_every == 0 {
            trial.time.push(t);
            trial.q.push(q);
            trial.qd.push(qd);
            trial.qdd.push(std::array::from_fn(|i| (qd_next[i] - qd[i]) / config.dt));
            trial.tau.push(tau);
            trial.q_ref.push(reference.q);
            trial.markers.push(markers(&config.body, world.forearm_pose(), &hand));
        }
        (q, qd) = (q_next, qd_next);
    }
    Ok(trial)
}

/// Marker positions from the simulated segment poses.
fn markers(
    body: &BodyModel,
    forearm: &nalgebra::Isometry3<f64>,
    hand: &nalgebra::Isometry3<f64>,
) -> [f64; MARKER_FRAME_LEN] {
    let mut frame = [0.0; MARKER_FRAME_LEN];
    for (i, m) in MARKERS.iter().enumerate() {
        let pose = if m.segment == Segment::Forearm { forearm } else { hand };
        let p = pose * Point3::from(body.marker_offsets[i]);
        frame[3 * i..3 * i + 3].copy_from_slice(p.coords.as_slice());
    }
    frame
}

fn check_body(body: &BodyModel) -> Result<()> {
    for seg in [&body.forearm, &body.hand] {
        check("segment mass", seg.mass, seg.mass > 0.0, "positive (kg)")?;
        check("segment length", seg.length, seg.length > 0.0, "positive (m)")?;
        for &i in &seg.inertia {
            check("segment inertia", i, i > 0.0, "positive (kg·m²)")?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rms(v: impl Iterator<Item = f64>) -> f64 {
        let (s, n) = v.fold((0.0, 0usize), |(s, n), x| (s + x * x, n + 1));
        (s / n as f64).sqrt()
    }

    #[test]
    fn rnea_reproduces_the_recorded_torques() {
        let config = SimConfig { shoulder_flexion: 0.4, ..Default::default() };
        let trial = simulate(&config, &Protocol::random(1, 3.0)).unwrap();
        for i in 0..N_COORDINATES {
            let (lo, hi) = trial.tau.iter().fold((f64::MAX, f64::MIN), |(lo, hi), t| (lo.min(t[i]), hi.max(t[i])));
            let err = rms((0..trial.time.len()).map(|n| {
                let s = JointState { q: trial.q[n], qd: trial.qd[n], qdd: trial.qdd[n] };
                inverse_dynamics(&config.body, config.shoulder_flexion, &s).unwrap()[i] - trial.tau[n][i]
            }));
            println!("dof {i}: torque range {lo:.3}..{hi:.3} N·m, RNEA residual RMS {err:.2e} N·m");
            assert!(err <= 0.01 * (hi - lo), "dof {i}: residual {err} vs range {}", hi - lo);
        }
    }

    #[test]
    fn simulated_motion_follows_the_protocol_and_the_markers_match_kinematics() {
        let config = SimConfig::default();
        let trial = simulate(&config, &Protocol::thesis()).unwrap();
        let err = rms(trial.q.iter().zip(&trial.q_ref).flat_map(|(q, r)| (0..3).map(move |i| q[i] - r[i])));
        assert!(err < 1e-3, "tracking RMS {err} rad");
        let pose = config.body.forearm_pose(0.0);
        for n in (0..trial.time.len()).step_by(97) {
            let fk = config.body.marker_frame(&trial.q[n], &pose);
            for (a, b) in fk.iter().zip(&trial.markers[n]) {
                assert!((a - b).abs() < 1e-9, "frame {n}: {a} vs {b}");
            }
        }
    }

    #[test]
    fn same_config_gives_identical_bits() {
        let p = Protocol::random(9, 1.0);
        let a = simulate(&SimConfig::default(), &p).unwrap();
        let b = simulate(&SimConfig::default(), &p).unwrap();
        assert_eq!(a, b);
    }

    #[test]
    fn bad_parameters_are_named() {
        let p = Protocol::random(1, 0.1);
        let bad = |c: SimConfig| simulate(&c, &p).unwrap_err().to_string();
        assert!(bad(SimConfig { dt: -1.0, ..Default::default() }).contains("dt is -1"));
        assert!(
            bad(SimConfig { shoulder_flexion: f64::NAN, ..Default::default() }).contains("shoulder_flexion is NaN")
        );
        let mut body = BodyModel::default();
        body.hand.mass = -0.4;
        assert!(bad(SimConfig { body, ..Default::default() }).contains("segment mass is -0.4"));
    }
}
