//! Simulation speed (× real time, one core) against rapier substeps, and the torque-truth
//! residual for each: the trade-off behind `SimConfig::default().substeps`.
//!
//! ```text
//! cargo run --release -p ikid-sim --example sim_speed
//! ```

use ikid::reference::{JointState, inverse_dynamics};
use ikid_sim::protocol::Protocol;
use ikid_sim::{SimConfig, simulate};
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let protocol = Protocol::thesis();
    println!("thesis protocol: {:.1} s of motion per shoulder pose", protocol.duration());
    for substeps in [1, 2, 4] {
        let config = SimConfig { substeps, shoulder_flexion: 45f64.to_radians(), ..Default::default() };
        let mut best = f64::MAX;
        let mut trial = None;
        for _ in 0..3 {
            let t = Instant::now();
            trial = Some(simulate(&config, &protocol)?);
            best = best.min(t.elapsed().as_secs_f64());
        }
        let trial = trial.expect("ran");
        let mut worst = 0.0f64;
        for i in 0..3 {
            let (lo, hi) = trial.tau.iter().fold((f64::MAX, f64::MIN), |(lo, hi), t| (lo.min(t[i]), hi.max(t[i])));
            let mut sq = 0.0;
            for n in 0..trial.time.len() {
                let s = JointState { q: trial.q[n], qd: trial.qd[n], qdd: trial.qdd[n] };
                sq += (inverse_dynamics(&config.body, config.shoulder_flexion, &s)?[i] - trial.tau[n][i]).powi(2);
            }
            worst = worst.max((sq / trial.time.len() as f64).sqrt() / (hi - lo));
        }
        println!(
            "substeps {substeps}: {:.1} µs/step, {:.0}x real time, worst RNEA residual {:.3} % of a DoF's torque range",
            best / trial.time.len() as f64 * 1e6,
            protocol.duration() / best,
            100.0 * worst
        );
    }
    Ok(())
}
