//! Marker noise models as seeded data transforms on recordings (`n` frames of
//! [`MARKER_FRAME_LEN`] values, metres). The simulator's datasets and training's
//! augmentation both use these, so "1 % noise" means the same everywhere.
//!
//! * [`uniform_range`]: the thesis' noise, uniform in ±p × (max − min) of each coordinate
//!   column over the recording.
//! * [`gaussian`]: independent Gaussian noise of σ metres on every value.
//! * [`drift`]: a slow sinusoidal offset per coordinate (0.05–0.2 Hz, random phase), the
//!   look of a marker sliding on skin.
//! * [`occlusion`]: bursts in which a marker is missing (all three coordinates NaN).
//!
//! The same seed gives the same noise, bit for bit.

use crate::body::{MARKER_FRAME_LEN, N_MARKERS};
use crate::error::{Error, Result};
use crate::rng::SplitMix;

fn frames_of(markers: &[f64]) -> Result<usize> {
    if !markers.len().is_multiple_of(MARKER_FRAME_LEN) {
        return Err(Error::BadArgument {
            what: "markers",
            detail: format!("{} values is not a whole number of 18-value frames", markers.len()),
        });
    }
    Ok(markers.len() / MARKER_FRAME_LEN)
}

fn parameter(what: &'static str, value: f64, ok: bool, expected: &str) -> Result<()> {
    if ok && value.is_finite() {
        Ok(())
    } else {
        Err(Error::BadArgument { what, detail: format!("is {value}, expected {expected}") })
    }
}

/// Adds uniform noise in ±`fraction` × (range of each coordinate column) — the thesis'
/// "1 %" is `fraction = 0.01`. Missing (NaN) values stay missing and do not count in ranges.
pub fn uniform_range(markers: &mut [f64], fraction: f64, seed: u64) -> Result<()> {
    parameter("fraction", fraction, fraction >= 0.0, "≥ 0")?;
    frames_of(markers)?;
    let mut span = [0.0; MARKER_FRAME_LEN];
    for (c, s) in span.iter_mut().enumerate() {
        let column = markers.iter().skip(c).step_by(MARKER_FRAME_LEN).filter(|v| v.is_finite());
        let (lo, hi) = column.fold((f64::MAX, f64::MIN), |(lo, hi), &v| (lo.min(v), hi.max(v)));
        *s = if hi >= lo { hi - lo } else { 0.0 };
    }
    let mut rng = SplitMix::new(seed);
    for (i, v) in markers.iter_mut().enumerate() {
        let amplitude = fraction * span[i % MARKER_FRAME_LEN];
        *v += rng.uniform(-amplitude, amplitude);
    }
    Ok(())
}

/// Adds Gaussian noise of standard deviation `sigma` metres to every value.
pub fn gaussian(markers: &mut [f64], sigma: f64, seed: u64) -> Result<()> {
    parameter("sigma", sigma, sigma >= 0.0, "≥ 0 (metres)")?;
    frames_of(markers)?;
    let mut rng = SplitMix::new(seed);
    for v in markers.iter_mut() {
        *v += sigma * rng.normal();
    }
    Ok(())
}

/// Adds a slow drift of peak `amplitude` metres per coordinate: `A sin(2π f t + φ)` with
/// `f` uniform in 0.05–0.2 Hz and random phase; `rate_hz` is the frame rate.
pub fn drift(markers: &mut [f64], amplitude: f64, rate_hz: f64, seed: u64) -> Result<()> {
    parameter("amplitude", amplitude, amplitude >= 0.0, "≥ 0 (metres)")?;
    parameter("rate_hz", rate_hz, rate_hz > 0.0, "> 0 (Hz)")?;
    frames_of(markers)?;
    let mut rng = SplitMix::new(seed);
    let waves: [(f64, f64, f64); MARKER_FRAME_LEN] = std::array::from_fn(|_| {
        (
            amplitude * rng.uniform(0.5, 1.0),
            std::f64::consts::TAU * rng.uniform(0.05, 0.2),
            rng.uniform(0.0, std::f64::consts::TAU),
        )
    });
    for (n, frame) in markers.chunks_exact_mut(MARKER_FRAME_LEN).enumerate() {
        let t = n as f64 / rate_hz;
        for (v, (a, w, phase)) in frame.iter_mut().zip(&waves) {
            *v += a * (w * t + phase).sin();
        }
    }
    Ok(())
}

/// Makes markers disappear in bursts: each frame starts a burst on a given marker with
/// probability `bursts_per_second / rate_hz`; a burst lasts `min_s`–`max_s` seconds.
/// `markers_affected` lists the marker indices that may disappear (all if empty).
/// Returns the number of values set to NaN.
pub fn occlusion(
    markers: &mut [f64],
    bursts_per_second: f64,
    min_s: f64,
    max_s: f64,
    rate_hz: f64,
    markers_affected: &[usize],
    seed: u64,
) -> Result<usize> {
    parameter("bursts_per_second", bursts_per_second, bursts_per_second >= 0.0, "≥ 0")?;
    parameter("rate_hz", rate_hz, rate_hz > 0.0, "> 0 (Hz)")?;
    parameter("min_s", min_s, min_s >= 0.0 && min_s <= max_s, "0 ≤ min_s ≤ max_s")?;
    parameter("max_s", max_s, max_s >= 0.0, "≥ 0")?;
    if let Some(&bad) = markers_affected.iter().find(|&&m| m >= N_MARKERS) {
        return Err(Error::BadArgument {
            what: "markers_affected",
            detail: format!("marker index {bad} is not below {N_MARKERS}"),
        });
    }
    let n = frames_of(markers)?;
    let all: Vec<usize> = (0..N_MARKERS).collect();
    let affected = if markers_affected.is_empty() { &all[..] } else { markers_affected };
    let mut rng = SplitMix::new(seed);
    let p = bursts_per_second / rate_hz;
    let mut removed = 0;
    for &m in affected {
        let mut f = 0;
        while f < n {
            if rng.uniform(0.0, 1.0) < p {
                let len = ((rng.uniform(min_s, max_s) * rate_hz).round() as usize).max(1);
                for frame in f..(f + len).min(n) {
                    for v in &mut markers[frame * MARKER_FRAME_LEN + 3 * m..frame * MARKER_FRAME_LEN + 3 * m + 3] {
                        removed += usize::from(!v.is_nan());
                        *v = f64::NAN;
                    }
                }
                f += len;
            } else {
                f += 1;
            }
        }
    }
    Ok(removed)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn recording(n: usize) -> Vec<f64> {
        (0..n * MARKER_FRAME_LEN)
            .map(|i| ((i % MARKER_FRAME_LEN) as f64 * 0.01) + ((i / MARKER_FRAME_LEN) as f64 * 0.001).sin())
            .collect()
    }

    #[test]
    fn uniform_noise_stays_within_its_bound_and_is_seeded() {
        let clean = recording(2000);
        let mut a = clean.clone();
        uniform_range(&mut a, 0.05, 1).unwrap();
        let mut b = clean.clone();
        uniform_range(&mut b, 0.05, 1).unwrap();
        assert_eq!(a, b);
        let column0 = clean.iter().step_by(MARKER_FRAME_LEN);
        let span = column0.clone().fold(f64::MIN, |m, &v| m.max(v)) - column0.fold(f64::MAX, |m, &v| m.min(v));
        let max = a.iter().zip(&clean).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max);
        assert!(max <= 0.05 * span && max > 0.04 * span, "{max}");
    }

    #[test]
    fn gaussian_noise_has_its_sigma() {
        let clean = recording(5000);
        let mut a = clean.clone();
        gaussian(&mut a, 0.002, 3).unwrap();
        let var = a.iter().zip(&clean).map(|(x, y)| (x - y).powi(2)).sum::<f64>() / a.len() as f64;
        assert!((var.sqrt() - 0.002).abs() < 0.0001, "{}", var.sqrt());
    }

    #[test]
    fn drift_is_slow_and_bounded() {
        let clean = recording(3000);
        let mut a = clean.clone();
        drift(&mut a, 0.005, 1000.0, 4).unwrap();
        let d: Vec<f64> = a.iter().zip(&clean).map(|(x, y)| x - y).collect();
        assert!(d.iter().all(|v| v.abs() <= 0.005 + 1e-15));
        // Frame-to-frame change ≤ 2π · 0.2 Hz · A / 1 kHz.
        let step = d
            .chunks(MARKER_FRAME_LEN)
            .zip(d.chunks(MARKER_FRAME_LEN).skip(1))
            .flat_map(|(p, q)| p.iter().zip(q).map(|(x, y)| (x - y).abs()))
            .fold(0.0, f64::max);
        assert!(step <= std::f64::consts::TAU * 0.2 * 0.005 / 1000.0 + 1e-15);
    }

    #[test]
    fn occlusion_removes_whole_markers_in_bursts() {
        let mut a = recording(10_000);
        let removed = occlusion(&mut a, 0.5, 0.05, 0.2, 1000.0, &[3], 5).unwrap();
        assert!(removed > 0 && removed.is_multiple_of(3));
        for frame in a.chunks(MARKER_FRAME_LEN) {
            let nan: Vec<bool> = frame.iter().map(|v| v.is_nan()).collect();
            assert!(nan[9..12].iter().all(|&x| x == nan[9]), "a marker goes missing whole");
            assert!(!nan[..9].iter().chain(&nan[12..]).any(|&x| x), "only marker 3");
        }
        assert!(occlusion(&mut a, 1.0, 0.1, 0.05, 1000.0, &[], 1).unwrap_err().to_string().contains("min_s"));
        assert!(occlusion(&mut a, 1.0, 0.1, 0.2, 1000.0, &[6], 1).unwrap_err().to_string().contains("marker index 6"));
    }
}
