//! Per-frame status bits: what was unusual about an output that is still written.
//!
//! Every path that gives outputs frame by frame (the [`Stream`](crate::Stream), the
//! [`Tracker`](crate::Tracker), their C and Python bindings, the CLI's `status` column) reports
//! the same bits, defined once here. Zero means nothing unusual. A frame that could not be given
//! an output at all is not a status: it is an error (or, for the tracker, no estimate).
//!
//! What the bits promise (docs/RELIABILITY.md): an output is either plausible or carries a bit
//! saying why it may not be; [`IMPLAUSIBLE`] marks one no wrist can give, which writers put
//! down as NaN rather than as a number.

/// A missing marker was filled (stream) or the estimate was made without it (tracker).
pub const FILLED: u16 = 1;
/// A present marker was rejected as implausible (it broke its segment's rigid shape, or it
/// was too far from where the wrist could have moved it) and was not used (a stream fills its
/// place from the other markers, as a missing one's; [`FILLED`] is for markers missing in the
/// recording).
pub const REJECTED_MARKER: u16 = 2;
/// The tracker lost the wrist (its markers agreed with one another but not with it) and
/// restarted from its own solution at this frame — or did so, started, or held through a long
/// gap, within the last [`LOST_S`](crate::tracker::LOST_S): its velocities and accelerations
/// (so the torques) are still settling. `ikid id` sets it on the rows next to a time gap or a
/// file's ends, where its low-pass sees one side only.
pub const RESTARTED: u16 = 4;
/// A segment was not measured in this frame (its markers missing or rejected): its last pose
/// was held, or the estimate was carried forward without a correction.
pub const HELD: u16 = 8;
/// The model's inputs for this frame lie outside the range it was trained on (its card's
/// envelope): the output is an extrapolation.
pub const OUTSIDE_TRAINING: u16 = 16;
/// An output no wrist can give (an angle beyond its coordinate's range by more than
/// [`RANGE_MARGIN_RAD`], a torque beyond [`torque_limit`], or outside the model's output
/// envelope by more than its own width).
pub const IMPLAUSIBLE: u16 = 32;

/// A correcting model's correction was not applied: the output is the per-frame solution (the
/// newest frame's own features, e.g. its angles read from the markers alone), because the
/// window's posture or its speed lies beyond what the model was trained on, or (a stream with
/// [`early outputs`](crate::Stream::set_early_outputs)) the window is still filling.
pub const PER_FRAME: u16 = 64;

/// A marker was found where another marker of the frame belongs (labels swapped in the
/// recording, a labelling error): the markers were used under their right labels.
pub const SWAPPED: u16 = 128;

/// The stream took its source's new clock ([`TIME_REANCHOR_FRAMES`](crate::stream::TIME_REANCHOR_FRAMES)
/// stamps in a row that jumped: the source was restarted) and this is its first output since:
/// frames were lost before it, and its window holds the new clock's frames only.
pub const RESYNCED: u16 = 256;

/// The hand reads turned further from its neutral posture on the forearm than any wrist turns
/// (see [`TurnedOverWatch`]). It is what two markers under each other's labels throughout,
/// or a cluster mapped or calibrated the other way round, read as (the hand or the forearm
/// half a turn off): the labels or the calibration are wrong, not the wrist. Always set with
/// [`IMPLAUSIBLE`], so writers leave the frame out; this bit says why.
pub const TURNED_OVER: u16 = 512;

/// Every bit with its name (the CLI's legend and the bindings' constant tables).
pub const ALL: [(u16, &str); 10] = [
    (FILLED, "filled"),
    (REJECTED_MARKER, "rejected_marker"),
    (RESTARTED, "restarted"),
    (HELD, "held"),
    (OUTSIDE_TRAINING, "outside_training"),
    (IMPLAUSIBLE, "implausible"),
    (PER_FRAME, "per_frame"),
    (SWAPPED, "swapped"),
    (RESYNCED, "resynced"),
    (TURNED_OVER, "turned_over"),
];

/// How far beyond a coordinate's anatomical range ([`crate::body::COORDINATES`]) an angle may
/// go before it is [`IMPLAUSIBLE`], rad (45°: ranges are typical active ones; passive motion
/// and marker error go past them, a wrist does not go 45° past them).
pub const RANGE_MARGIN_RAD: f64 = std::f64::consts::FRAC_PI_4;

/// True if the angle `q` (rad) of coordinate `c` is beyond its range by more than
/// [`RANGE_MARGIN_RAD`] (or not finite).
pub fn angle_implausible(c: usize, q: f64) -> bool {
    let (lo, hi) = crate::body::COORDINATES[c].range;
    !(q >= lo - RANGE_MARGIN_RAD && q <= hi + RANGE_MARGIN_RAD)
}

/// How far from its neutral posture the hand may read turned on the forearm (the angle of
/// its rotation there, whatever its axis), degrees, before it is [`TURNED_OVER`]. Every
/// coordinate at the end of its range at once turns the hand 125° at most (the body model's
/// ranges, [`crate::body::COORDINATES`]); real wheelchair racing, the farthest-turning recording
/// ikid was tried on (its independent reference), turns it 96°. Two hand markers under each
/// other's labels read as the hand half a turn off, so as 180° less its true turn or more:
/// 130° is passed as soon as the true turn is under 50°, as it is at rest.
pub const TURNED_OVER_DEG: f64 = 130.0;
/// Once turned over, the hand reads upright again only when turned less than this, degrees. A
/// hand read through swapped labels turns about 180° less its true turn, so more than 60°
/// while the true turn is under 120° (every posture of the body model's ranges but their
/// farthest corners), and stays flagged while the wrist goes far; a tracker that lost such a
/// hand and restarted read it 88° turned where its true turn was 101°. A real wrist comes
/// back under 60° whenever it comes near rest.
pub const UPRIGHT_DEG: f64 = 60.0;

/// The angle, degrees, by which wrist angles `q` (rad) turn the hand from its neutral posture
/// on the forearm: the rotation angle of [`wrist_rotation`](crate::body::wrist_rotation),
/// whatever its axis (near gimbal lock the angles are not defined, this is).
///
/// From the scalar part of the chain's quaternion, without building the rotation (it runs on
/// every push): for three mutually orthogonal axes `a₁, a₂, a₃` and half-angles `hᵢ`,
/// `w = cos h₁ cos h₂ cos h₃ − ((a₁ × a₂)·a₃) sin h₁ sin h₂ sin h₃`, and the angle is
/// `2 acos |w|`.
pub fn hand_turn_deg(q: &[f64; 3]) -> f64 {
    (2.0 * turn_cos_half(q).clamp(0.0, 1.0).acos()).to_degrees() // clamp keeps a NaN a NaN
}

/// `|w|`, the cosine of half the hand's turn ([`hand_turn_deg`]).
fn turn_cos_half(q: &[f64; 3]) -> f64 {
    use crate::body::COORDINATES;
    let [a1, a2, a3] = COORDINATES.map(|c| nalgebra::Vector3::from(c.axis));
    let handedness = a1.cross(&a2).dot(&a3);
    let (s1, c1) = (0.5 * q[0]).sin_cos();
    let (s2, c2) = (0.5 * q[1]).sin_cos();
    let (s3, c3) = (0.5 * q[2]).sin_cos();
    (c1 * c2 * c3 - handedness * s1 * s2 * s3).abs()
}

/// cos(½ [`TURNED_OVER_DEG`]) and cos(½ [`UPRIGHT_DEG`]): the watch compares `|w|` with them
/// instead of taking an arccosine on every push (checked in the tests).
const TURNED_OVER_COS_HALF: f64 = 0.42261826174069944;
const UPRIGHT_COS_HALF: f64 = 0.8660254037844387;

/// [`TURNED_OVER_DEG`] and [`UPRIGHT_DEG`] in radians, for [`turn_bound_rad`].
const TURNED_OVER_RAD: f64 = TURNED_OVER_DEG * (std::f64::consts::PI / 180.0);
const UPRIGHT_RAD: f64 = UPRIGHT_DEG * (std::f64::consts::PI / 180.0);

/// `|q₁| + |q₂| + |q₃|`, rad: the hand's turn is at most this. A rotation's angle is a
/// distance between rotations, so along the chain's three turns the triangle inequality holds.
/// A wrist near rest, nearly every frame, is decided by it without trigonometry.
fn turn_bound_rad(q: &[f64; 3]) -> f64 {
    q[0].abs() + q[1].abs() + q[2].abs()
}

/// True if wrist angles `q` (rad) turn the hand past [`TURNED_OVER_DEG`]: the stateless check
/// of one frame (a [`TurnedOverWatch`] also keeps the flag until the hand reads upright).
pub fn turned_over(q: &[f64; 3]) -> bool {
    turn_bound_rad(q) > TURNED_OVER_RAD && turn_cos_half(q) < TURNED_OVER_COS_HALF
}

/// Whether a stream's or a tracker's hand reads turned over ([`TURNED_OVER`]), frame after
/// frame: on when turned past [`TURNED_OVER_DEG`], off again only under [`UPRIGHT_DEG`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct TurnedOverWatch {
    turned: bool,
}

impl TurnedOverWatch {
    /// A watch that has seen nothing (upright).
    pub fn new() -> Self {
        Self::default()
    }

    /// Takes the next frame's wrist angles `q` (rad) and returns its bits: [`TURNED_OVER`] |
    /// [`IMPLAUSIBLE`] while the hand reads turned over, else 0. Angles that are not finite
    /// change nothing.
    pub fn update(&mut self, q: &[f64; 3]) -> u16 {
        let bound = turn_bound_rad(q);
        if bound < UPRIGHT_RAD {
            self.turned = false; // turned less than the bound: upright
        } else if self.turned || bound > TURNED_OVER_RAD {
            let cos_half = turn_cos_half(q); // smaller: turned further
            if cos_half < TURNED_OVER_COS_HALF {
                self.turned = true;
            } else if cos_half > UPRIGHT_COS_HALF {
                self.turned = false;
            }
        } // else not turned over, and within the bound it cannot have turned over
        self.bits()
    }

    /// The bits of the last frame ([`update`](Self::update)).
    pub fn bits(&self) -> u16 {
        if self.turned { TURNED_OVER | IMPLAUSIBLE } else { 0 }
    }
}

/// Largest joint torque about any wrist coordinate a wrist of the default subject
/// ([`BodyModel::default`](crate::body::BodyModel::default), a 73 kg adult male) can take, N·m;
/// a torque beyond it ([`torque_limit`] for another subject) is [`IMPLAUSIBLE`]. The strongest
/// maximal isometric wrist moments measured in adult men are about 12 N·m (flexion; extension
/// about 7, radial and ulnar deviation 9–11: Delp, Grierson & Buchanan 1996, J. Biomech.
/// 29(10), 1371–1375; forearm rotation about 10). The bound is 2.5 times that, leaving room
/// for strong subjects and for passive and impact loads: a tracker's torque beyond it is its
/// own error (q̈ from marker jitter), not a wrist's.
pub const TORQUE_LIMIT_NM: f64 = 30.0;

/// [`TORQUE_LIMIT_NM`] for a subject whose masses are `mass_scale` times the default's: a
/// muscle's force scales with its cross-section (its mass over its length) and its moment arm
/// with length, so its moment with the mass alone (the length scale cancels).
pub fn torque_limit(mass_scale: f64) -> f64 {
    TORQUE_LIMIT_NM * mass_scale
}

/// True if the torque `tau` (N·m) is beyond `limit` ([`torque_limit`]) or not finite.
pub fn torque_implausible(tau: f64, limit: f64) -> bool {
    !tau.is_finite() || tau.abs() > limit
}

/// The bits of one joint state a writer did not make itself (angles read from a file, torques
/// computed from them), taken alone: [`IMPLAUSIBLE`] for an angle `q` (rad) beyond its range by
/// more than [`RANGE_MARGIN_RAD`] or a torque `tau` (N·m, when given) beyond `torque_limit`
/// ([`torque_limit`]), and [`TURNED_OVER`] with it for angles that turn the hand over
/// ([`turned_over`]). A stream and the tracker check their own frames as they go.
pub fn joint_status(q: &[f64; 3], tau: Option<&[f64; 3]>, torque_limit: f64) -> u16 {
    let mut bits = 0;
    if (0..3).any(|c| angle_implausible(c, q[c])) {
        bits |= IMPLAUSIBLE;
    }
    if turned_over(q) {
        bits |= TURNED_OVER | IMPLAUSIBLE;
    }
    if tau.is_some_and(|t| t.iter().any(|&t| torque_implausible(t, torque_limit))) {
        bits |= IMPLAUSIBLE;
    }
    bits
}

/// The names of the bits set in `status`, comma-separated ("" for 0).
pub fn describe(status: u16) -> String {
    ALL.iter().filter(|(bit, _)| status & bit != 0).map(|(_, name)| *name).collect::<Vec<_>>().join(",")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bits_are_distinct_single_bits_and_named() {
        let mut seen = 0u16;
        for (bit, name) in ALL {
            assert_eq!(bit.count_ones(), 1, "{name}");
            assert_eq!(seen & bit, 0, "{name} reuses a bit");
            seen |= bit;
        }
        assert_eq!(describe(FILLED | HELD), "filled,held");
        assert_eq!(describe(0), "");
    }

    #[test]
    fn angles_are_implausible_only_well_beyond_their_range() {
        // s_p's range is ±80°: 120° is within the 45° margin, 130° is not.
        assert!(!angle_implausible(0, 120f64.to_radians()));
        assert!(!angle_implausible(0, -120f64.to_radians()));
        assert!(angle_implausible(0, 130f64.to_radians()));
        assert!(angle_implausible(0, -130f64.to_radians()));
        // e_f's is -70°..80°: the margin is added on each side of its own range.
        assert!(!angle_implausible(1, -110f64.to_radians()));
        assert!(angle_implausible(1, -120f64.to_radians()));
        assert!(!angle_implausible(1, 120f64.to_radians()));
        assert!(angle_implausible(1, 130f64.to_radians()));
        assert!(angle_implausible(1, f64::NAN));
        assert!(!angle_implausible(2, 0.0));
    }

    #[test]
    fn the_hands_turn_is_its_rotation_angle_whatever_the_axis() {
        // Oracle: one coordinate alone turns the hand by its own angle; at gimbal lock
        // (e_f = 90°) s_p and ad_ab turn it about one axis, so opposite equal values cancel
        // (axes -y and x both land on that axis with e_f's quarter turn about z).
        for deg in [-170.0f64, -95.0, 0.0, 45.0, 129.0, 131.0] {
            for c in 0..3 {
                let mut q = [0.0; 3];
                q[c] = deg.to_radians();
                assert!((hand_turn_deg(&q) - deg.abs()).abs() < 1e-9, "{c} {deg}");
            }
        }
        let locked = hand_turn_deg(&[1.0, std::f64::consts::FRAC_PI_2, 1.0]);
        assert!((locked - 90.0).abs() < 1e-9, "{locked}");
        // Any angles: the rotation angle nalgebra finds in the chain's matrix.
        let mut rng = crate::rng::SplitMix::new(7);
        for _ in 0..1000 {
            let q = [rng.uniform(-3.5, 3.5), rng.uniform(-3.5, 3.5), rng.uniform(-3.5, 3.5)];
            let oracle = crate::body::wrist_rotation(&q).angle().to_degrees();
            assert!((hand_turn_deg(&q) - oracle).abs() < 1e-6, "{q:?}: {} vs {oracle}", hand_turn_deg(&q));
        }
    }

    #[test]
    fn the_watchs_thresholds_are_its_angles() {
        assert!((TURNED_OVER_COS_HALF - (0.5 * TURNED_OVER_DEG).to_radians().cos()).abs() < 1e-15);
        assert!((UPRIGHT_COS_HALF - (0.5 * UPRIGHT_DEG).to_radians().cos()).abs() < 1e-15);
    }

    #[test]
    fn a_hand_turned_over_stays_flagged_until_it_reads_upright() {
        let at = |deg: f64| [deg.to_radians(), 0.0, 0.0];
        let mut watch = TurnedOverWatch::new();
        assert_eq!(watch.update(&at(60.0)), 0);
        assert_eq!(watch.update(&at(-125.0)), 0, "as far as every range at once reaches");
        // Past 130°: turned over, and implausible with it so that writers leave the frame out.
        assert_eq!(watch.update(&at(135.0)), TURNED_OVER | IMPLAUSIBLE);
        // Back under 130° but not yet under 60°: still turned over.
        assert_eq!(watch.update(&at(95.0)), TURNED_OVER | IMPLAUSIBLE);
        assert_eq!(watch.update(&at(-62.0)), TURNED_OVER | IMPLAUSIBLE);
        assert_eq!(watch.update(&at(f64::NAN)), TURNED_OVER | IMPLAUSIBLE, "NaN changes nothing");
        assert_eq!(watch.update(&at(-58.0)), 0);
        assert_eq!(watch.bits(), 0);
    }

    #[test]
    fn the_watch_and_the_one_frame_check_agree_with_the_rotation_angle_on_random_walks() {
        // Oracle: the hysteresis written on nalgebra's rotation angle of the chain. The walks
        // reach postures where |q₁|+|q₂|+|q₃| passes 130° long before the hand does (the
        // bound's shortcut must not decide those) and cross both thresholds many times.
        let mut rng = crate::rng::SplitMix::new(11);
        let (mut crossings, mut bound_only) = (0, 0);
        for walk in 0..40 {
            let mut watch = TurnedOverWatch::new();
            let mut oracle = false;
            let reach = if walk % 2 == 0 { 1.6 } else { 3.4 };
            let mut q = [0.0f64; 3];
            for _ in 0..500 {
                for qc in &mut q {
                    *qc = (*qc + rng.uniform(-0.25, 0.25)).clamp(-reach, reach);
                }
                let turn = crate::body::wrist_rotation(&q).angle().to_degrees();
                let was = oracle;
                if turn > TURNED_OVER_DEG {
                    oracle = true;
                } else if turn < UPRIGHT_DEG {
                    oracle = false;
                }
                crossings += usize::from(was != oracle);
                bound_only += usize::from(turn_bound_rad(&q) > TURNED_OVER_RAD && turn <= TURNED_OVER_DEG);
                let expected = if oracle { TURNED_OVER | IMPLAUSIBLE } else { 0 };
                assert_eq!(watch.update(&q), expected, "{q:?}: turned {turn}°");
                assert_eq!(turned_over(&q), turn > TURNED_OVER_DEG, "{q:?}: turned {turn}°");
            }
        }
        assert!(crossings > 50 && bound_only > 1000, "the walks test little: {crossings} {bound_only}");
    }

    #[test]
    fn a_joint_state_read_from_elsewhere_is_checked_angle_by_angle_turn_and_torque() {
        let limit = torque_limit(1.0);
        assert_eq!(joint_status(&[0.3, -0.2, 0.1], Some(&[1.0, -2.0, 0.5]), limit), 0);
        assert_eq!(joint_status(&[0.3, -0.2, 0.1], None, limit), 0);
        // e_f's range ends at -70°: -120° is past the 45° margin, the hand turned 120° only.
        assert_eq!(joint_status(&[0.0, (-120f64).to_radians(), 0.0], None, limit), IMPLAUSIBLE);
        // 3 rad of supination alone: past its range, and the hand turned 172°. (100 "rad", degrees
        // read as radians, turns it 30°: past the range is what tells then.)
        assert_eq!(joint_status(&[3.0, 0.0, 0.0], None, limit), TURNED_OVER | IMPLAUSIBLE);
        assert_eq!(joint_status(&[100.0, 0.0, 0.0], None, limit), IMPLAUSIBLE);
        // Each angle within its margin (s_p 124° of 125°, ad_ab 70° of 75°), the two together
        // turning the hand 134.8° (cos ½θ = cos 62° cos 35°): turned over.
        let (s_p, ad_ab) = (124f64.to_radians(), 70f64.to_radians());
        assert_eq!(joint_status(&[s_p, 0.0, ad_ab], None, limit), TURNED_OVER | IMPLAUSIBLE);
        assert_eq!(joint_status(&[s_p, 0.0, 0.0], None, limit), 0);
        // A torque past the limit, or not finite.
        assert_eq!(joint_status(&[0.0, 0.0, 0.0], Some(&[0.0, limit * 1.01, 0.0]), limit), IMPLAUSIBLE);
        assert_eq!(joint_status(&[0.0, 0.0, 0.0], Some(&[0.0, f64::NAN, 0.0]), limit), IMPLAUSIBLE);
        assert_eq!(joint_status(&[f64::NAN, 0.0, 0.0], None, limit), IMPLAUSIBLE);
    }

    #[test]
    fn torques_are_implausible_beyond_the_limit_scaled_by_mass() {
        assert!(!torque_implausible(-29.0, torque_limit(1.0)));
        assert!(torque_implausible(31.0, torque_limit(1.0)));
        assert!(!torque_implausible(31.0, torque_limit(1.5)));
        assert!(torque_implausible(f64::NAN, torque_limit(1.0)));
    }
}
