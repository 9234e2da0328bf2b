//! Reference inverse dynamics: recursive Newton–Euler over the wrist's joint chain.
//!
//! The three revolute joints share the wrist centre `O`, with two tiny links between them
//! ([`VIRTUAL_LINK`], as in the simulator) and the hand last. The forearm carries `O`: fixed
//! in the lab ([`inverse_dynamics_at`]) or moving ([`inverse_dynamics_moving`]: its angular
//! velocity `ω_0` and acceleration `α_0`, and `O`'s linear acceleration `a_O`). Forward pass:
//! link angular velocities and accelerations (`ω_i = ω_{i-1} + z_i q̇_i`,
//! `α_i = α_{i-1} + z_i q̈_i + ω_{i-1} × z_i q̇_i`). Backward pass: the moment about `O` each
//! link needs, `n_i = n_{i+1} + I_i α_i + ω_i × I_i ω_i + c_i × m_i (a_ci − g)` with
//! `a_ci = a_O + α_i × c_i + ω_i × (ω_i × c_i)`, and the joint torque is its component along
//! the joint axis, `τ_i = z_i · n_i` (N·m, in coordinate order).

use crate::body::{BodyModel, COORDINATES, GRAVITY, N_COORDINATES, VIRTUAL_LINK};
use crate::error::{Error, Result};
use nalgebra::{Matrix3, Rotation3, Unit, Vector3};

/// Joint angles, velocities and accelerations (rad, rad/s, rad/s²), coordinate order.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct JointState {
    /// Angles.
    pub q: [f64; N_COORDINATES],
    /// Angular velocities.
    pub qd: [f64; N_COORDINATES],
    /// Angular accelerations.
    pub qdd: [f64; N_COORDINATES],
}

/// The forearm's motion in the lab, lab frame (the body model's: gravity along −Y): what the
/// hand's joints carry besides their own motion. Zero: the forearm at rest.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ForearmMotion {
    /// Its angular velocity, rad/s ...
    pub omega: [f64; 3],
    /// ... its angular acceleration, rad/s² ...
    pub alpha: [f64; 3],
    /// ... and the linear acceleration of the wrist centre it carries, m/s².
    pub accel: [f64; 3],
}

/// Joint torques `(s_p, e_f, ad_ab)` in N·m that produce `state` for the subject `body`
/// with the forearm at `shoulder_flexion` (radians), under gravity.
pub fn inverse_dynamics(body: &BodyModel, shoulder_flexion: f64, state: &JointState) -> Result<[f64; N_COORDINATES]> {
    if !shoulder_flexion.is_finite() {
        return Err(Error::BadArgument { what: "shoulder_flexion", detail: format!("is {shoulder_flexion}") });
    }
    let forearm = body.forearm_pose(shoulder_flexion).rotation.to_rotation_matrix();
    inverse_dynamics_at(body, &forearm, state)
}

/// [`inverse_dynamics`] with the forearm's orientation in the lab given directly (e.g. fitted
/// to its markers): the forearm is taken to be at rest; only gravity's direction in the
/// forearm frame depends on it.
pub fn inverse_dynamics_at(
    body: &BodyModel,
    forearm: &Rotation3<f64>,
    state: &JointState,
) -> Result<[f64; N_COORDINATES]> {
    inverse_dynamics_moving(body, forearm, &ForearmMotion::default(), state)
}

/// [`inverse_dynamics_at`] on a forearm moving as `motion` says (a forearm swung through a
/// reach or a push accelerates the hand it carries: 30 m/s² at the wrist is three times
/// gravity's pull on the hand).
pub fn inverse_dynamics_moving(
    body: &BodyModel,
    forearm: &Rotation3<f64>,
    motion: &ForearmMotion,
    state: &JointState,
) -> Result<[f64; N_COORDINATES]> {
    let carried = motion.omega.iter().chain(&motion.alpha).chain(&motion.accel);
    if let Some(i) = carried.clone().position(|v| !v.is_finite()) {
        return Err(Error::BadArgument {
            what: "forearm motion",
            detail: format!("{}[{}] is {}", ["omega", "alpha", "accel"][i / 3], i % 3, carried.clone().nth(i).unwrap()),
        });
    }
    let values = state.q.iter().chain(&state.qd).chain(&state.qdd);
    if let Some(i) = values.clone().position(|v| !v.is_finite()) {
        let kind = ["q", "qd", "qdd"][i / N_COORDINATES];
        return Err(Error::BadArgument {
            what: "joint state",
            detail: format!("{kind}.{} is {}", COORDINATES[i % N_COORDINATES].name, values.clone().nth(i).unwrap()),
        });
    }
    let links = [VIRTUAL_LINK, VIRTUAL_LINK, body.hand];

    // Forward: orientation, axis, angular velocity and acceleration of each link (lab frame).
    let mut rotation = *forearm;
    let (mut omega, mut alpha) = (Vector3::from(motion.omega), Vector3::from(motion.alpha));
    let mut axes = [Vector3::zeros(); N_COORDINATES];
    let mut kin = [(Rotation3::identity(), Vector3::zeros(), Vector3::zeros()); N_COORDINATES];
    for i in 0..N_COORDINATES {
        let local = Unit::new_normalize(Vector3::from(COORDINATES[i].axis));
        let z = rotation * local.into_inner();
        let spin = z * state.qd[i];
        alpha += z * state.qdd[i] + omega.cross(&spin);
        omega += spin;
        rotation *= Rotation3::from_axis_angle(&local, state.q[i]);
        axes[i] = z;
        kin[i] = (rotation, omega, alpha);
    }

    // Backward: moment about the wrist centre needed by links i.. (lab frame).
    let g = Vector3::from(GRAVITY);
    let a_centre = Vector3::from(motion.accel);
    let mut moment = Vector3::zeros();
    let mut tau = [0.0; N_COORDINATES];
    for i in (0..N_COORDINATES).rev() {
        let (r, w, a) = kin[i];
        let link = &links[i];
        let c = r * Vector3::from(link.com);
        let inertia = r.matrix() * Matrix3::from_diagonal(&Vector3::from(link.inertia)) * r.matrix().transpose();
        let a_com = a_centre + a.cross(&c) + w.cross(&w.cross(&c));
        moment += inertia * a + w.cross(&(inertia * w)) + c.cross(&(link.mass * (a_com - g)));
        tau[i] = axes[i].dot(&moment);
    }
    if let Some(i) = tau.iter().position(|t| !t.is_finite()) {
        return Err(Error::BadArgument {
            what: "joint state",
            detail: format!(
                "gives a non-finite {} torque (velocities or accelerations too large?)",
                COORDINATES[i].name
            ),
        });
    }
    Ok(tau)
}

/// Torques for many joint states: `q`, `qd`, `qdd` hold `n` rows of [`N_COORDINATES`] each,
/// `out` receives `n` rows of torques. Errors name the row.
pub fn inverse_dynamics_rows(
    body: &BodyModel,
    shoulder_flexion: f64,
    q: &[f64],
    qd: &[f64],
    qdd: &[f64],
    out: &mut [f64],
) -> Result<()> {
    let n = q.len() / N_COORDINATES;
    if [q.len(), qd.len(), qdd.len(), out.len()].iter().any(|&l| l != n * N_COORDINATES)
        || !q.len().is_multiple_of(N_COORDINATES)
    {
        return Err(Error::BadArgument {
            what: "joint states",
            detail: format!(
                "q, qd, qdd and out have {}, {}, {} and {} values; expected equal whole rows of 3",
                q.len(),
                qd.len(),
                qdd.len(),
                out.len()
            ),
        });
    }
    if !shoulder_flexion.is_finite() {
        return Err(Error::BadArgument { what: "shoulder_flexion", detail: format!("is {shoulder_flexion}") });
    }
    for i in 0..n {
        let row = |v: &[f64]| [v[3 * i], v[3 * i + 1], v[3 * i + 2]];
        let state = JointState { q: row(q), qd: row(qd), qdd: row(qdd) };
        let tau = inverse_dynamics(body, shoulder_flexion, &state).map_err(|e| match e {
            Error::BadArgument { what, detail } => Error::BadArgument { what, detail: format!("row {i}: {detail}") },
            other => other,
        })?;
        out[3 * i..3 * i + 3].copy_from_slice(&tau);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Lagrangian of the hand: kinetic energy about the fixed wrist centre minus potential.
    fn lagrangian(body: &BodyModel, shoulder: f64, q: [f64; 3], qd: [f64; 3]) -> f64 {
        let forearm = body.forearm_pose(shoulder).rotation.to_rotation_matrix();
        let hand = forearm * crate::body::wrist_rotation(&q);
        // Angular velocity by finite difference of the orientation (independent of the RNEA's
        // recursion): ω× ≈ (R(q + h q̇) − R(q − h q̇)) Rᵀ / 2h.
        let h = 1e-6;
        let step = |s: f64| forearm * crate::body::wrist_rotation(&std::array::from_fn(|i| q[i] + s * qd[i]));
        let dr = (step(h).matrix() - step(-h).matrix()) / (2.0 * h);
        let w_hat = dr * hand.matrix().transpose();
        let omega = Vector3::new(w_hat[(2, 1)], w_hat[(0, 2)], w_hat[(1, 0)]);
        let c = hand * Vector3::from(body.hand.com);
        let i_com =
            hand.matrix() * Matrix3::from_diagonal(&Vector3::from(body.hand.inertia)) * hand.matrix().transpose();
        let v = omega.cross(&c);
        let kinetic = 0.5 * body.hand.mass * v.dot(&v) + 0.5 * omega.dot(&(i_com * omega));
        let potential = -body.hand.mass * Vector3::from(GRAVITY).dot(&c);
        kinetic - potential
    }

    /// τ = d/dt ∂L/∂q̇ − ∂L/∂q by central differences along q(t) = q + q̇ t + ½ q̈ t².
    fn lagrange_torques(body: &BodyModel, shoulder: f64, s: &JointState) -> [f64; 3] {
        let at = |t: f64| -> ([f64; 3], [f64; 3]) {
            (
                std::array::from_fn(|i| s.q[i] + s.qd[i] * t + 0.5 * s.qdd[i] * t * t),
                std::array::from_fn(|i| s.qd[i] + s.qdd[i] * t),
            )
        };
        let dl_dqd = |q: [f64; 3], qd: [f64; 3], i: usize| {
            let e = 1e-4;
            let (mut up, mut dn) = (qd, qd);
            up[i] += e;
            dn[i] -= e;
            (lagrangian(body, shoulder, q, up) - lagrangian(body, shoulder, q, dn)) / (2.0 * e)
        };
        let dt = 1e-4;
        std::array::from_fn(|i| {
            let (qa, va) = at(dt);
            let (qb, vb) = at(-dt);
            let ddt = (dl_dqd(qa, va, i) - dl_dqd(qb, vb, i)) / (2.0 * dt);
            let e = 1e-5;
            let (mut up, mut dn) = (s.q, s.q);
            up[i] += e;
            dn[i] -= e;
            let dl_dq = (lagrangian(body, shoulder, up, s.qd) - lagrangian(body, shoulder, dn, s.qd)) / (2.0 * e);
            ddt - dl_dq
        })
    }

    #[test]
    fn rnea_agrees_with_the_lagrangian() {
        let body = BodyModel::scaled(1.1, 0.9);
        for (shoulder, state) in [
            (0.0, JointState { q: [0.3, -0.5, 0.2], qd: [4.0, -6.0, 2.0], qdd: [120.0, -80.0, 40.0] }),
            (0.8, JointState { q: [-1.0, 0.9, -0.3], qd: [-10.0, 3.0, -1.0], qdd: [-150.0, 200.0, 60.0] }),
            (-0.35, JointState { q: [0.0, 0.0, 0.0], qd: [0.0; 3], qdd: [0.0; 3] }),
        ] {
            let rnea = inverse_dynamics(&body, shoulder, &state).unwrap();
            let lag = lagrange_torques(&body, shoulder, &state);
            for i in 0..3 {
                assert!((rnea[i] - lag[i]).abs() < 2e-4 * (1.0 + lag[i].abs()), "{state:?}: {rnea:?} vs {lag:?}");
            }
        }
    }

    #[test]
    fn static_torque_is_the_gravity_moment() {
        // Arm hanging, wrist straight: the hand's centre of mass is straight below the wrist,
        // so gravity has no moment; flexed 90°, the flexion joint holds m g d.
        let body = BodyModel::default();
        let hanging = inverse_dynamics(&body, 0.0, &JointState::default()).unwrap();
        assert!(hanging.iter().all(|t| t.abs() < 1e-12), "{hanging:?}");
        let flexed = JointState { q: [0.0, std::f64::consts::FRAC_PI_2, 0.0], ..Default::default() };
        let tau = inverse_dynamics(&body, 0.0, &flexed).unwrap();
        let expect = body.hand.mass * 9.81 * body.hand.com[1].abs();
        assert!((tau[1].abs() - expect).abs() < 1e-9, "{tau:?} vs {expect}");
    }

    /// The forearm's pose at time `t` for a forearm that, at t = 0, is at `forearm` with the
    /// wrist centre at the origin and moves as `m`: turned by exp(ω t + ½ α t²) in the lab
    /// (lab angular velocity ω and acceleration α at t = 0), the centre at ½ a t².
    fn forearm_at(forearm: &Rotation3<f64>, m: &ForearmMotion, t: f64) -> (Rotation3<f64>, Vector3<f64>) {
        let turn = Vector3::from(m.omega) * t + Vector3::from(m.alpha) * (0.5 * t * t);
        (Rotation3::new(turn) * forearm, Vector3::from(m.accel) * (0.5 * t * t))
    }

    /// Lagrangian of the hand on a moving forearm, L(q, q̇, t): the hand's absolute velocities
    /// by central differences along (q + s q̇, t + s), the motion's own, explicit in t.
    fn moving_lagrangian(
        body: &BodyModel,
        forearm: &Rotation3<f64>,
        m: &ForearmMotion,
        q: [f64; 3],
        qd: [f64; 3],
        t: f64,
    ) -> f64 {
        let pose = |s: f64| {
            let (r, o) = forearm_at(forearm, m, t + s);
            let hand = r * crate::body::wrist_rotation(&std::array::from_fn(|i| q[i] + s * qd[i]));
            (hand, o + hand * Vector3::from(body.hand.com))
        };
        let h = 1e-6;
        let ((r_up, c_up), (r_dn, c_dn), (hand, c)) = (pose(h), pose(-h), pose(0.0));
        let w_hat = (r_up.matrix() - r_dn.matrix()) / (2.0 * h) * hand.matrix().transpose();
        let omega = Vector3::new(w_hat[(2, 1)], w_hat[(0, 2)], w_hat[(1, 0)]);
        let v = (c_up - c_dn) / (2.0 * h);
        let i_com =
            hand.matrix() * Matrix3::from_diagonal(&Vector3::from(body.hand.inertia)) * hand.matrix().transpose();
        let kinetic = 0.5 * body.hand.mass * v.dot(&v) + 0.5 * omega.dot(&(i_com * omega));
        kinetic + body.hand.mass * Vector3::from(GRAVITY).dot(&c)
    }

    #[test]
    fn on_a_moving_forearm_the_rnea_agrees_with_the_lagrangian_of_the_carried_hand() {
        // τ = d/dt ∂L/∂q̇ − ∂L/∂q along q(t) = q + q̇ t + ½ q̈ t² with the forearm's motion
        // explicit in L: an oracle that never writes ω_0, α_0 or a_O into a recursion.
        let body = BodyModel::scaled(1.1, 0.9);
        let forearm = body.forearm_pose(0.4).rotation.to_rotation_matrix();
        let motion = ForearmMotion { omega: [2.0, -5.0, 3.0], alpha: [-40.0, 25.0, 60.0], accel: [12.0, -30.0, 8.0] };
        for state in [
            JointState { q: [0.3, -0.5, 0.2], qd: [4.0, -6.0, 2.0], qdd: [120.0, -80.0, 40.0] },
            JointState { q: [-1.0, 0.9, -0.3], qd: [0.0; 3], qdd: [0.0; 3] },
        ] {
            let along = |t: f64| -> ([f64; 3], [f64; 3]) {
                (
                    std::array::from_fn(|i| state.q[i] + state.qd[i] * t + 0.5 * state.qdd[i] * t * t),
                    std::array::from_fn(|i| state.qd[i] + state.qdd[i] * t),
                )
            };
            let dl_dqd = |t: f64, i: usize| {
                let (q, qd) = along(t);
                let e = 1e-4;
                let (mut up, mut dn) = (qd, qd);
                up[i] += e;
                dn[i] -= e;
                (moving_lagrangian(&body, &forearm, &motion, q, up, t)
                    - moving_lagrangian(&body, &forearm, &motion, q, dn, t))
                    / (2.0 * e)
            };
            let lagrange: [f64; 3] = std::array::from_fn(|i| {
                let dt = 1e-4;
                let ddt = (dl_dqd(dt, i) - dl_dqd(-dt, i)) / (2.0 * dt);
                let e = 1e-5;
                let (mut up, mut dn) = (state.q, state.q);
                up[i] += e;
                dn[i] -= e;
                let dl_dq = (moving_lagrangian(&body, &forearm, &motion, up, state.qd, 0.0)
                    - moving_lagrangian(&body, &forearm, &motion, dn, state.qd, 0.0))
                    / (2.0 * e);
                ddt - dl_dq
            });
            let rnea = inverse_dynamics_moving(&body, &forearm, &motion, &state).unwrap();
            let at_rest = inverse_dynamics_at(&body, &forearm, &state).unwrap();
            for i in 0..3 {
                assert!(
                    (rnea[i] - lagrange[i]).abs() < 5e-4 * (1.0 + lagrange[i].abs()),
                    "{state:?}: {rnea:?} vs {lagrange:?}"
                );
            }
            // The motion matters here: the forearm at rest is far off.
            assert!((0..3).any(|i| (at_rest[i] - lagrange[i]).abs() > 0.05), "{at_rest:?} vs {lagrange:?}");
        }
    }

    #[test]
    fn a_non_finite_forearm_motion_is_named() {
        let m = ForearmMotion { accel: [0.0, f64::NAN, 0.0], ..Default::default() };
        let forearm = Rotation3::identity();
        let err = inverse_dynamics_moving(&BodyModel::default(), &forearm, &m, &JointState::default()).unwrap_err();
        assert!(err.to_string().contains("accel[1]"), "{err}");
    }

    #[test]
    fn non_finite_state_is_named() {
        let s = JointState { qd: [0.0, f64::NAN, 0.0], ..Default::default() };
        let err = inverse_dynamics(&BodyModel::default(), 0.0, &s).unwrap_err();
        assert!(err.to_string().contains("qd.ra_wr_e_f"), "{err}");
    }
}
