//! Prescribed wrist motions with analytic angles, velocities and accelerations.
//!
//! A protocol is a sequence of minimum-jerk (quintic) transitions, each a sigmoid from one
//! posture to the next with zero velocity and acceleration at both ends, and holds between
//! them. Targets stay within 95 % of each coordinate's anatomical range
//! (`ikid::body::COORDINATES`).

use ikid::body::{COORDINATES, N_COORDINATES};
use ikid::reference::JointState;
use ikid::rng::SplitMix;

/// Fraction of the anatomical range targets may use.
const RANGE_USE: f64 = 0.95;

/// The protocols [`Protocol::from_name`] makes, by name.
pub const PROTOCOLS: [&str; 2] = ["thesis", "random"];

/// Longest random protocol [`Protocol::from_name`] makes, s (ten hours).
pub const MAX_DURATION_S: f64 = 36_000.0;

/// One transition from `from` to `to` starting at `start` (s) and lasting `duration` (s).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Movement {
    /// Start time, s.
    pub start: f64,
    /// Duration, s (a hold when `from == to`).
    pub duration: f64,
    /// Posture at the start, rad.
    pub from: [f64; N_COORDINATES],
    /// Posture at the end, rad.
    pub to: [f64; N_COORDINATES],
}

/// A set of joint-sign octants: octant `k` has bit `i` set when coordinate `i` is negative
/// (coordinate order s_p, e_f, ad_ab; zero counts as positive). Written as sign strings,
/// e.g. `"+-+"` = supinated, extended, adducted.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Octants(pub u8);

impl Octants {
    /// Every octant.
    pub const ALL: Octants = Octants(0xFF);

    /// The octant index of a joint position.
    pub fn of(q: &[f64; N_COORDINATES]) -> usize {
        (0..N_COORDINATES).filter(|&i| q[i] < 0.0).map(|i| 1 << i).sum()
    }

    /// Whether octant `k` is in the set (the neutral pose is always allowed).
    pub fn contains(self, k: usize) -> bool {
        self.0 & (1 << k) != 0
    }

    /// True when no octant is allowed.
    pub fn is_empty(self) -> bool {
        self.0 == 0
    }

    /// Parses sign strings such as `["+-+", "---"]`.
    pub fn parse<S: AsRef<str>>(signs: &[S]) -> Result<Octants, String> {
        let mut mask = 0u8;
        for s in signs {
            let s = s.as_ref();
            let chars: Vec<char> = s.chars().collect();
            if chars.len() != N_COORDINATES || chars.iter().any(|c| *c != '+' && *c != '-') {
                return Err(format!(
                    "octant {s:?} must be {N_COORDINATES} signs ('+' or '-') for s_p, e_f, ad_ab, e.g. \"+-+\""
                ));
            }
            let k: usize = chars.iter().enumerate().filter(|(_, c)| **c == '-').map(|(i, _)| 1 << i).sum();
            mask |= 1 << k;
        }
        if mask == 0 {
            return Err("no octant given".into());
        }
        Ok(Octants(mask))
    }
}

/// A named sequence of movements (back to back, starting at t = 0 from neutral).
#[derive(Debug, Clone, PartialEq)]
pub struct Protocol {
    /// E.g. `"thesis"` or `"random"`.
    pub name: String,
    /// Movements in time order.
    pub movements: Vec<Movement>,
}

impl Protocol {
    fn build(name: &str, steps: impl IntoIterator<Item = ([f64; N_COORDINATES], f64)>) -> Self {
        let mut movements = Vec::new();
        let (mut t, mut at) = (0.0, [0.0; N_COORDINATES]);
        for (to, duration) in steps {
            movements.push(Movement { start: t, duration, from: at, to });
            t += duration;
            at = to;
        }
        Protocol { name: name.into(), movements }
    }

    /// The thesis' protocol for one shoulder pose: 42 single-DoF sigmoid movements, 14 per
    /// coordinate, alternating 250 ms and 500 ms, out to ±30/60/90/50 % of the range side and
    /// back to neutral, with 200 ms rests between movements.
    pub fn thesis() -> Self {
        let fractions = [0.3, -0.3, 0.6, -0.6, 0.9, -0.9, 0.5];
        let mut steps = Vec::new();
        for (dof, c) in COORDINATES.iter().enumerate() {
            for (k, f) in fractions.iter().enumerate() {
                let mut target = [0.0; N_COORDINATES];
                target[dof] = if *f > 0.0 { f * c.range.1 } else { -f * c.range.0 };
                let (out, back) = if k % 2 == 0 { (0.25, 0.5) } else { (0.5, 0.25) };
                steps.push((target, out));
                steps.push((target, 0.2));
                steps.push(([0.0; N_COORDINATES], back));
                steps.push(([0.0; N_COORDINATES], 0.2));
            }
        }
        Self::build("thesis", steps)
    }

    /// Random smooth multi-DoF reaching lasting at least `seconds`: each movement takes
    /// 0.25–1.0 s (speeds vary with distance and duration), moves each coordinate to a
    /// random target with probability 0.8 (holds it otherwise), returns to neutral 15 % of
    /// the time, and is followed by a hold of 0–0.4 s a third of the time.
    pub fn random(seed: u64, seconds: f64) -> Self {
        Self::random_in(seed, seconds, Octants::ALL)
    }

    /// [`random`](Self::random) whose targets lie only in the allowed joint-sign octants
    /// (returns to neutral stay allowed). Holding out octants in training and testing on
    /// them measures generalisation to movement types a network never saw. With
    /// [`Octants::ALL`] it is exactly `random` (same draws, same trajectory).
    pub fn random_in(seed: u64, seconds: f64, allowed: Octants) -> Self {
        assert!(!allowed.is_empty(), "at least one octant must be allowed");
        let mut rng = SplitMix::new(seed);
        let mut steps = Vec::new();
        let (mut t, mut at) = (0.0, [0.0; N_COORDINATES]);
        while t < seconds {
            let duration = rng.uniform(0.25, 1.0);
            let to: [f64; N_COORDINATES] = if rng.uniform(0.0, 1.0) < 0.15 {
                [0.0; N_COORDINATES]
            } else {
                // Rejection sampling; with every octant allowed the first draw is kept, so
                // `random` is unchanged. A held coordinate keeps its sign, so a draw can
                // fail forever only if no allowed octant shares it: then all move.
                let mut draw = 0;
                loop {
                    let keep_all = draw >= 64;
                    let to: [f64; N_COORDINATES] = std::array::from_fn(|i| {
                        let (lo, hi) = COORDINATES[i].range;
                        let moves = rng.uniform(0.0, 1.0) < 0.8 || keep_all;
                        if moves { rng.uniform(RANGE_USE * lo, RANGE_USE * hi) } else { at[i] }
                    });
                    draw += 1;
                    if allowed.contains(Octants::of(&to)) {
                        break to;
                    }
                }
            };
            steps.push((to, duration));
            t += duration;
            if rng.uniform(0.0, 1.0) < 1.0 / 3.0 {
                let hold = rng.uniform(0.0, 0.4);
                steps.push((to, hold));
                t += hold;
            }
            at = to;
        }
        Self::build("random", steps)
    }

    /// The protocol called `name` (one of [`PROTOCOLS`]), as a caller names it: `"thesis"`
    /// ([`thesis`](Self::thesis); `seed` and `duration` unused) or `"random"`
    /// ([`random_in`](Self::random_in) lasting at least `duration` s, 0 < `duration` ≤
    /// [`MAX_DURATION_S`], its targets in the joint-sign `octants` when given, sign strings
    /// such as `"+-+"`, see [`Octants::parse`]). Refused, naming the fault: another name, a
    /// duration out of range, octants that do not parse or given to `"thesis"`.
    pub fn from_name<S: AsRef<str>>(
        name: &str,
        seed: u64,
        duration: f64,
        octants: Option<&[S]>,
    ) -> crate::Result<Protocol> {
        match name {
            "thesis" if octants.is_some() => Err(crate::Error::Octants("apply to the \"random\" protocol only".into())),
            "thesis" => Ok(Self::thesis()),
            "random" => {
                crate::check(
                    "duration",
                    duration,
                    duration > 0.0 && duration <= MAX_DURATION_S,
                    &format!("expected 0 < duration ≤ {MAX_DURATION_S} s"),
                )?;
                let allowed = match octants {
                    Some(signs) => Octants::parse(signs).map_err(crate::Error::Octants)?,
                    None => Octants::ALL,
                };
                Ok(Self::random_in(seed, duration, allowed))
            }
            other => Err(crate::Error::UnknownProtocol {
                name: other.into(),
                known: PROTOCOLS.map(|p| format!("{p:?}")).join(", "),
            }),
        }
    }

    /// Total duration, s.
    pub fn duration(&self) -> f64 {
        self.movements.last().map_or(0.0, |m| m.start + m.duration)
    }

    /// Angles, velocities and accelerations at time `t` (s); holds the last posture after
    /// the end.
    pub fn sample(&self, t: f64) -> JointState {
        let i = self.movements.partition_point(|m| m.start <= t).saturating_sub(1);
        let Some(m) = self.movements.get(i) else { return JointState::default() };
        let s = ((t - m.start) / m.duration).clamp(0.0, 1.0);
        let moving = t < m.start + m.duration && m.duration > 0.0;
        // Minimum-jerk profile p(s) = 10s³ − 15s⁴ + 6s⁵ and its time derivatives.
        let p = s * s * s * (10.0 - 15.0 * s + 6.0 * s * s);
        let (dp, ddp) = if moving {
            let d = m.duration;
            (30.0 * s * s * (1.0 - s) * (1.0 - s) / d, 60.0 * s * (1.0 - s) * (1.0 - 2.0 * s) / (d * d))
        } else {
            (0.0, 0.0)
        };
        let delta: [f64; N_COORDINATES] = std::array::from_fn(|k| m.to[k] - m.from[k]);
        JointState {
            q: std::array::from_fn(|k| m.from[k] + delta[k] * p),
            qd: std::array::from_fn(|k| delta[k] * dp),
            qdd: std::array::from_fn(|k| delta[k] * ddp),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thesis_protocol_has_42_movements_within_range() {
        let p = Protocol::thesis();
        let moves = p.movements.iter().filter(|m| m.from != m.to).count();
        assert_eq!(moves, 42);
        let durations: Vec<f64> = p.movements.iter().filter(|m| m.from != m.to).map(|m| m.duration).collect();
        assert!(durations.iter().all(|d| *d == 0.25 || *d == 0.5));
        for m in &p.movements {
            for (k, c) in COORDINATES.iter().enumerate() {
                assert!(m.to[k] >= c.range.0 && m.to[k] <= c.range.1);
            }
        }
    }

    #[test]
    fn derivatives_match_finite_differences() {
        let p = Protocol::random(3, 5.0);
        let h = 1e-6;
        for k in 1..400 {
            let t = k as f64 * 0.0123;
            let (a, b, c) = (p.sample(t - h), p.sample(t), p.sample(t + h));
            for i in 0..3 {
                assert!(((c.q[i] - a.q[i]) / (2.0 * h) - b.qd[i]).abs() < 1e-5, "qd at {t}");
                assert!(((c.qd[i] - a.qd[i]) / (2.0 * h) - b.qdd[i]).abs() < 1e-3, "qdd at {t}");
            }
        }
    }

    #[test]
    fn octant_restricted_targets_stay_in_their_octants() {
        assert_eq!(Protocol::random_in(5, 20.0, Octants::ALL), Protocol::random(5, 20.0));
        let held_out = Octants::parse(&["+-+"]).unwrap();
        let rest = Octants(!held_out.0);
        for (allowed, seed) in [(held_out, 1), (rest, 2)] {
            let p = Protocol::random_in(seed, 30.0, allowed);
            let targets: Vec<_> = p.movements.iter().map(|m| m.to).filter(|to| *to != [0.0; 3]).collect();
            assert!(targets.len() > 10);
            assert!(targets.iter().all(|to| allowed.contains(Octants::of(to))), "{allowed:?}");
        }
        assert!(Octants::parse(&["+-"]).is_err());
        assert!(Octants::parse(&["+x+"]).is_err());
        assert_eq!(Octants::parse(&["+++", "---"]).unwrap(), Octants(1 | 1 << 7));
    }

    #[test]
    fn protocols_are_made_by_name_within_limits() {
        let none: Option<&[&str]> = None;
        assert_eq!(Protocol::from_name("thesis", 0, 0.0, none).unwrap(), Protocol::thesis());
        assert_eq!(Protocol::from_name("random", 5, 10.0, none).unwrap(), Protocol::random(5, 10.0));
        let held_out = Protocol::from_name("random", 1, 30.0, Some(&["+-+"])).unwrap();
        assert_eq!(held_out, Protocol::random_in(1, 30.0, Octants::parse(&["+-+"]).unwrap()));
        let message = |r: crate::Result<Protocol>| r.unwrap_err().to_string();
        assert_eq!(
            message(Protocol::from_name("dance", 0, 1.0, none)),
            "unknown protocol \"dance\" (known: \"thesis\", \"random\")"
        );
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY, MAX_DURATION_S + 1.0] {
            assert!(message(Protocol::from_name("random", 0, bad, none)).starts_with("duration is"), "{bad}");
        }
        assert!(Protocol::from_name("random", 0, MAX_DURATION_S, none).is_ok());
        assert!(message(Protocol::from_name("random", 0, 1.0, Some(&["+x+"]))).starts_with("octants: octant"));
        let empty: &[&str] = &[];
        assert_eq!(message(Protocol::from_name("random", 0, 1.0, Some(empty))), "octants: no octant given");
        assert_eq!(
            message(Protocol::from_name("thesis", 0, 1.0, Some(&["+++"]))),
            "octants: apply to the \"random\" protocol only"
        );
    }

    #[test]
    fn random_protocol_is_seeded_and_within_range() {
        assert_eq!(Protocol::random(5, 10.0), Protocol::random(5, 10.0));
        assert_ne!(Protocol::random(5, 10.0), Protocol::random(6, 10.0));
        let p = Protocol::random(5, 30.0);
        assert!(p.duration() >= 30.0);
        for m in &p.movements {
            for (k, c) in COORDINATES.iter().enumerate() {
                assert!(m.to[k] >= RANGE_USE * c.range.0 - 1e-12 && m.to[k] <= RANGE_USE * c.range.1 + 1e-12);
            }
        }
    }
}
