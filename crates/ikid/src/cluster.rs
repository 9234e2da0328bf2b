//! Segments marked by more than three markers: a four-marker plate, a cluster of skin markers.
//!
//! ikid's frames hold three markers per segment ([`crate::body::MARKERS`]). A lab that puts
//! more on a segment names three of them as that segment's markers and the rest as the same
//! rigid cluster; each frame, the cluster's shape (learned from the recording) is fitted to
//! every marker of it that is seen, and the three take the places the fit gives them. So a
//! frame missing one of the three still has them (from any three markers of the cluster), the
//! noise is averaged over every marker, and a marker that leaves its place in a frame (a
//! swapped label, a marker knocked off) is left out of that frame's fit rather than bending it.
//!
//! The three keep their physical meaning (the fit puts the markers themselves, not new points),
//! so a calibration measured with the cluster holds for the three alone and the reverse.

use nalgebra::{Matrix3, SymmetricEigen, Vector3};

/// Fewest frames with every marker of the cluster seen that its shape is learned from.
pub const MIN_WHOLE_FRAMES: usize = 10;
/// Farthest a marker may lie from where the frame's fit of the rest puts it, m: beyond it the
/// marker is left out of that frame's fit (and, when no more than three are left, the frame
/// has no cluster). The same margin as a segment's markers may stretch over a recording
/// (skin markers move up to 12 mm on the real recordings; a marker on another segment 18 mm
/// and more).
pub const MAX_FIT_RESIDUAL_M: f64 = 0.015;
/// Narrowest spread of the markers a frame is fitted to, m (the RMS distance from their best
/// line): below it their roll about that line is the markers' noise.
pub const MIN_CLUSTER_WIDTH_M: f64 = 0.003;
/// Most frames the shape is learned from (evenly spaced over the whole ones): more average
/// nothing further and cost time.
pub const MAX_SHAPE_FRAMES: usize = 2000;
/// Least spread a marker is given for its weight in a fit, m: the markers of a rigid plate
/// (0.1-0.5 mm of noise) count alike.
pub const SPREAD_FLOOR_M: f64 = 0.0005;

/// How many times the core's seed's largest distance change a marker's distances to the core
/// may change before it is left out of the core (`rigid_core`).
pub const STRAY_FACTOR: f64 = 2.0;
/// Least that limit is, m.
pub const RIGID_FLOOR_M: f64 = 0.001;
/// Most that limit is, m: the change, beyond noise, of a rigid plate's distances is its
/// markers' placement wobble (racing's plates: under 0.5 mm); skin markers slide by more
/// (pyomeca's forearm: 1.5-2.2 mm among the radius' three, 2.7-10 mm to the others).
pub const RIGID_LIMIT_M: f64 = 0.0015;
/// The weight of a marker outside the rigid core (at the limit; less beyond it), against 1 for
/// the core's markers.
pub const STRAYING_WEIGHT: f64 = 1e-4;

/// A cluster's rigid shape: each marker's place in the cluster's own frame (centroid at the
/// origin), metres, how much it strays as the cluster moves (its spread), and its weight in a
/// fit: a marker that moved on the plate part-way through, or one on another segment, counts
/// for almost nothing against the markers that keep their distances together (the rigid core).
#[derive(Debug, Clone, PartialEq)]
pub struct ClusterShape {
    points: Vec<Vector3<f64>>,
    spread: Vec<f64>,
    weight: Vec<f64>,
}

/// One frame of [`ClusterShape::fit`]: every marker where the fitted shape puts it.
#[derive(Debug, Clone, PartialEq)]
pub struct ClusterFit {
    /// `(n, 3k)`: each frame's markers as the fitted shape places them, metres; NaN in a frame
    /// the cluster is not determined in (under three usable markers, or too narrow).
    pub placed: Vec<f64>,
    /// Per marker: frames it was seen in but left out of the fit (beyond
    /// [`MAX_FIT_RESIDUAL_M`] from where the others put it).
    pub left_out: Vec<usize>,
    /// Frames with three or more markers seen whose cluster is still not determined (the seen
    /// markers too narrow, or three that do not keep the shape).
    pub undetermined: usize,
}

impl ClusterShape {
    /// The shape of a cluster of `n_markers` from frames `(n, 3·n_markers)` (metres, NaN =
    /// missing; the first three markers the segment's own, which the rigid core starts from):
    /// over the frames with every marker seen (at most [`MAX_SHAPE_FRAMES`], evenly spaced),
    /// each turned onto the first by a least-squares fit weighed as `rigid_core` finds, each
    /// marker's median place.
    pub fn learn(frames: &[f64], n_markers: usize) -> crate::Result<Self> {
        let width = 3 * n_markers;
        if n_markers < 3 || !frames.len().is_multiple_of(width) {
            return Err(bad(format!(
                "{} values is not whole frames of {n_markers} markers (a cluster has three or more)",
                frames.len()
            )));
        }
        let whole: Vec<&[f64]> = frames.chunks_exact(width).filter(|f| f.iter().all(|v| v.is_finite())).collect();
        if whole.len() < MIN_WHOLE_FRAMES {
            return Err(bad(format!(
                "the cluster's {n_markers} markers are all seen in {} of {} frames; its shape is learned from at \
                 least {MIN_WHOLE_FRAMES} frames with every one of them",
                whole.len(),
                frames.len() / width
            )));
        }
        let step = whole.len().div_ceil(MAX_SHAPE_FRAMES);
        let samples: Vec<Vec<Vector3<f64>>> = whole.iter().step_by(step).map(|f| centred(&points(f))).collect();
        // Which markers move as one body, and each marker's weight ([`rigid_core`]); then each
        // frame turned onto the first by those weights, and each marker's median place: robust
        // to frames with a marker off its place (a swapped label, a marker knocked), and to
        // markers outside the core, which would turn a plain fit by their lever arm.
        let (spread, weight) = rigid_core(&whole);
        let aligned: Vec<Vec<Vector3<f64>>> = samples
            .iter()
            .map(|sample| {
                let (rot, _) = kabsch(sample, &samples[0], &weight);
                sample.iter().map(|p| rot * p).collect()
            })
            .collect();
        let shape = Self {
            points: centred(&(0..n_markers).map(|m| median_point(aligned.iter().map(|a| a[m]))).collect::<Vec<_>>()),
            spread,
            weight,
        };
        if width_of(&shape.points, &vec![true; n_markers]) < MIN_CLUSTER_WIDTH_M {
            return Err(bad(format!(
                "the cluster's markers lie on a line (within {:.1} mm): they do not give its orientation",
                1e3 * MIN_CLUSTER_WIDTH_M
            )));
        }
        Ok(shape)
    }

    /// A shape from its markers' places `(k, 3)`, spreads and weights `(k,)` (as
    /// [`Self::points`], [`Self::spread`] and [`Self::weight`] give them).
    pub fn from_points(flat: &[f64], spread: &[f64], weight: &[f64]) -> crate::Result<Self> {
        if flat.len() < 9 || !flat.len().is_multiple_of(3) || !flat.iter().all(|v| v.is_finite()) {
            return Err(bad(format!("{} values are not three or more finite points", flat.len())));
        }
        if spread.len() != flat.len() / 3 || !spread.iter().all(|&s| s > 0.0) {
            return Err(bad(format!(
                "{} spreads for {} points: one positive spread per point",
                spread.len(),
                flat.len() / 3
            )));
        }
        if weight.len() != spread.len() || !weight.iter().all(|&w| w > 0.0 && w <= 1.0) {
            return Err(bad(format!("{} weights for {} points: one in (0, 1] per point", weight.len(), spread.len())));
        }
        Ok(Self { points: centred(&points(flat)), spread: spread.to_vec(), weight: weight.to_vec() })
    }

    /// Each marker's weight in a fit: 1 for the markers of the cluster's rigid core (the
    /// largest set that keeps its distances together, [`Self::learn`]); a marker outside it
    /// counts [`STRAYING_WEIGHT`] or less: far from the others (an epicondyle with a wrist
    /// cluster) it would turn the fit by its lever arm, so it only fixes what the core leaves
    /// open (a frame with two of the core's markers).
    pub fn weight(&self) -> &[f64] {
        &self.weight
    }

    /// Each marker's spread, m: how much its distances to the rigid core's markers change as
    /// the cluster moves (the median over them of each distance's standard deviation, at least
    /// [`SPREAD_FLOOR_M`]).
    pub fn spread(&self) -> &[f64] {
        &self.spread
    }

    /// Number of markers in the cluster.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// Always false: a cluster has three or more markers.
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// Each marker's place in the cluster's frame, `(k, 3)` flattened, metres.
    pub fn points(&self) -> Vec<f64> {
        self.points.iter().flat_map(|p| [p.x, p.y, p.z]).collect()
    }

    /// Fits the shape to each frame `(n, 3k)` (metres, NaN = missing): a least-squares rigid
    /// fit (Kabsch) to the markers seen, the one farthest from the fit left out while more
    /// than [`MAX_FIT_RESIDUAL_M`] off and more than three remain.
    pub fn fit(&self, frames: &[f64]) -> crate::Result<ClusterFit> {
        let k = self.points.len();
        if !frames.len().is_multiple_of(3 * k) {
            return Err(bad(format!("{} values is not whole frames of the cluster's {k} markers", frames.len())));
        }
        let mut placed = Vec::with_capacity(frames.len());
        let mut left_out = vec![0; k];
        let mut undetermined = 0;
        for f in frames.chunks_exact(3 * k) {
            let lab = points(f);
            let seen: Vec<bool> = lab.iter().map(|p| p.iter().all(|v| v.is_finite())).collect();
            match self.fit_frame(&lab, seen.clone()) {
                Some((used, rot, shift)) => {
                    for (i, p) in self.points.iter().enumerate() {
                        let q = rot * p + shift;
                        placed.extend_from_slice(&[q.x, q.y, q.z]);
                        left_out[i] += usize::from(seen[i] && !used[i]);
                    }
                }
                None => {
                    undetermined += usize::from(seen.iter().filter(|&&s| s).count() >= 3);
                    placed.extend(std::iter::repeat_n(f64::NAN, 3 * k));
                }
            }
        }
        Ok(ClusterFit { placed, left_out, undetermined })
    }

    /// The frame's fit: the markers used, the rotation and translation from the shape's frame
    /// to the lab. None when fewer than three usable markers are left or they are too narrow.
    fn fit_frame(&self, lab: &[Vector3<f64>], mut used: Vec<bool>) -> Option<(Vec<bool>, Matrix3<f64>, Vector3<f64>)> {
        loop {
            let count = used.iter().filter(|&&u| u).count();
            if count < 3 || width_of(&self.points, &used) < MIN_CLUSTER_WIDTH_M {
                return None;
            }
            let weight: Vec<f64> = used.iter().zip(&self.weight).map(|(&u, &w)| if u { w } else { 0.0 }).collect();
            let (rot, shift) = kabsch(&self.points, lab, &weight);
            let (worst, residual) = (0..lab.len())
                .filter(|&i| used[i])
                .map(|i| (i, (rot * self.points[i] + shift - lab[i]).norm()))
                .max_by(|a, b| a.1.total_cmp(&b.1))?;
            if residual <= MAX_FIT_RESIDUAL_M {
                return Some((used, rot, shift));
            }
            if count == 3 {
                return None;
            }
            used[worst] = false;
        }
    }
}

/// Narrowest the triangle of three markers may be for their technical frame, m (the distance of
/// the third from the line of the first two): below it the frame's roll is their noise.
pub const MIN_FRAME_WIDTH_M: f64 = 0.005;

/// A segment's technical frame from three of its markers: origin the first, `x` towards the
/// second, `z` normal to the three (`x × (third − first)`), `y = z × x`; the axes are the
/// rotation's columns. None when a marker is missing or the three are nearly collinear
/// ([`MIN_FRAME_WIDTH_M`]).
pub fn technical_frame(markers: &[f64]) -> Option<(Matrix3<f64>, Vector3<f64>)> {
    let [a, b, c] = [0, 1, 2].map(|m| Vector3::new(markers[3 * m], markers[3 * m + 1], markers[3 * m + 2]));
    let x = (b - a).try_normalize(1e-9)?;
    let across = c - a - x * x.dot(&(c - a));
    if !across.iter().all(|v| v.is_finite()) || across.norm() < MIN_FRAME_WIDTH_M {
        return None;
    }
    let z = x.cross(&across).normalize();
    Some((Matrix3::from_columns(&[x, z.cross(&x), z]), a))
}

/// Points `(n, 3k)` (metres, lab) expressed in each frame's [`technical_frame`] of three
/// markers `(n, 9)`: NaN where the point or the frame is missing.
pub fn points_in_technical_frame(markers: &[f64], points: &[f64]) -> crate::Result<Vec<f64>> {
    let n = markers.len() / 9;
    if !markers.len().is_multiple_of(9) || n == 0 || !points.len().is_multiple_of(3 * n) {
        return Err(bad(format!(
            "{} marker values and {} point values are not the same frames of three markers and of points",
            markers.len(),
            points.len()
        )));
    }
    let width = points.len() / n;
    let mut out = Vec::with_capacity(points.len());
    for (m, p) in markers.chunks_exact(9).zip(points.chunks_exact(width)) {
        let frame = technical_frame(m);
        for q in p.chunks_exact(3) {
            let local = frame.map_or(Vector3::repeat(f64::NAN), |(rot, origin)| {
                rot.transpose() * (Vector3::new(q[0], q[1], q[2]) - origin)
            });
            out.extend_from_slice(local.as_slice());
        }
    }
    Ok(out)
}

/// Points fixed in the [`technical_frame`] of three markers (`local`, `(k, 3)`), placed in the
/// lab for each frame of the markers `(n, 9)`: `(n, 3k)`, NaN where the frame is missing.
pub fn points_from_technical_frame(markers: &[f64], local: &[f64]) -> crate::Result<Vec<f64>> {
    if !markers.len().is_multiple_of(9) || !local.len().is_multiple_of(3) || !local.iter().all(|v| v.is_finite()) {
        return Err(bad(format!(
            "{} marker values are not frames of three markers, or {} point values not finite points",
            markers.len(),
            local.len()
        )));
    }
    let mut out = Vec::with_capacity(markers.len() / 9 * local.len());
    for m in markers.chunks_exact(9) {
        let frame = technical_frame(m);
        for q in local.chunks_exact(3) {
            let lab =
                frame.map_or(Vector3::repeat(f64::NAN), |(rot, origin)| rot * Vector3::new(q[0], q[1], q[2]) + origin);
            out.extend_from_slice(lab.as_slice());
        }
    }
    Ok(out)
}

fn bad(detail: String) -> crate::Error {
    crate::Error::BadArgument { what: "cluster", detail }
}

fn points(f: &[f64]) -> Vec<Vector3<f64>> {
    f.chunks_exact(3).map(|p| Vector3::new(p[0], p[1], p[2])).collect()
}

/// How much the distance between each two markers changes over `frames` (in time order, every
/// marker seen) beyond the markers' own noise: its variance less the noise's (from consecutive
/// frames; the median of a χ²(1) is 0.4549), as a standard deviation, m. Skin that slides or a
/// marker moved on its plate changes a distance slowly; white noise does not count.
fn distance_changes(frames: &[&[f64]]) -> Vec<Vec<f64>> {
    let k = frames[0].len() / 3;
    let markers: Vec<Vec<Vector3<f64>>> = frames.iter().map(|f| points(f)).collect();
    let beyond_noise = |a: usize, b: usize| {
        if a == b {
            return 0.0;
        }
        let d: Vec<f64> = markers.iter().map(|m| (m[a] - m[b]).norm()).collect();
        let n = d.len() as f64;
        let mean = d.iter().sum::<f64>() / n;
        let variance = d.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n;
        let mut steps: Vec<f64> = d.windows(2).map(|w| (w[1] - w[0]).powi(2)).collect();
        steps.sort_by(f64::total_cmp);
        let noise = if steps.is_empty() { 0.0 } else { steps[steps.len() / 2] / 2.0 / 0.4549 };
        (variance - noise).max(0.0).sqrt()
    };
    (0..k).map(|a| (0..k).map(|b| beyond_noise(a, b)).collect()).collect()
}

/// The cluster's rigid core, and each marker's spread and weight, from how much the distance
/// between each two markers changes beyond noise ([`distance_changes`]). The core starts from
/// the segment's three markers (the cluster's first three), unless they change their distances
/// more than [`STRAY_FACTOR`] times the steadiest three (and [`RIGID_LIMIT_M`]): then from
/// those. It takes in, one at a time, the marker whose largest change to the core's markers is
/// least, while that stays within [`STRAY_FACTOR`] times the seed's, clamped to
/// [[`RIGID_FLOOR_M`], [`RIGID_LIMIT_M`]]: a rigid plate's markers join, skin markers that slide
/// do not (the segment's three define it; the others stand in for a missing one), nor does a
/// marker on another segment or one that moved on its plate, however many such markers there
/// are. Spread: the median change of a marker's distances to the core's other markers; weight:
/// 1 in the core, [`STRAYING_WEIGHT`] × (limit / spread)² (at most [`STRAYING_WEIGHT`]) outside.
fn rigid_core(frames: &[&[f64]]) -> (Vec<f64>, Vec<f64>) {
    let change = distance_changes(frames);
    let k = change.len();
    let worst_of = |set: &[usize]| {
        set.iter().flat_map(|&a| set.iter().map(move |&b| (a, b))).map(|(a, b)| change[a][b]).fold(0.0, f64::max)
    };
    let mut steadiest = (f64::INFINITY, vec![0, 1, 2]);
    for a in 0..k {
        for b in a + 1..k {
            for c in b + 1..k {
                let worst = worst_of(&[a, b, c]);
                if worst < steadiest.0 {
                    steadiest = (worst, vec![a, b, c]);
                }
            }
        }
    }
    let three = worst_of(&[0, 1, 2]);
    let (seed_worst, mut core) =
        if three <= (STRAY_FACTOR * steadiest.0).max(RIGID_LIMIT_M) { (three, vec![0, 1, 2]) } else { steadiest };
    let limit = (STRAY_FACTOR * seed_worst).clamp(RIGID_FLOOR_M, RIGID_LIMIT_M);
    let worst_to = |m: usize, set: &[usize]| set.iter().map(|&j| change[m][j]).fold(0.0, f64::max);
    while let Some((m, worst)) =
        (0..k).filter(|m| !core.contains(m)).map(|m| (m, worst_to(m, &core))).min_by(|a, b| a.1.total_cmp(&b.1))
    {
        if worst > limit {
            break;
        }
        core.push(m);
    }
    let spread: Vec<f64> = (0..k)
        .map(|m| {
            let mut to_core: Vec<f64> = core.iter().filter(|&&j| j != m).map(|&j| change[m][j]).collect();
            to_core.sort_by(f64::total_cmp);
            to_core[to_core.len() / 2].max(SPREAD_FLOOR_M)
        })
        .collect();
    let weight = (0..k)
        .map(|m| if core.contains(&m) { 1.0 } else { STRAYING_WEIGHT * (limit / spread[m]).powi(2).min(1.0) })
        .collect();
    (spread, weight)
}

/// Each coordinate's median of `points`.
fn median_point(points: impl Iterator<Item = Vector3<f64>>) -> Vector3<f64> {
    let points: Vec<Vector3<f64>> = points.collect();
    Vector3::from_fn(|axis, _| {
        let mut values: Vec<f64> = points.iter().map(|p| p[axis]).collect();
        values.sort_by(f64::total_cmp);
        let half = values.len() / 2;
        if values.len() % 2 == 1 { values[half] } else { (values[half - 1] + values[half]) / 2.0 }
    })
}

fn centred(points: &[Vector3<f64>]) -> Vec<Vector3<f64>> {
    let c = points.iter().sum::<Vector3<f64>>() / points.len() as f64;
    points.iter().map(|p| p - c).collect()
}

/// RMS distance of the `used` points from their best line: the second principal spread.
fn width_of(points: &[Vector3<f64>], used: &[bool]) -> f64 {
    let chosen: Vec<Vector3<f64>> = points.iter().zip(used).filter(|&(_, &u)| u).map(|(p, _)| *p).collect();
    let centred = centred(&chosen);
    let scatter: Matrix3<f64> = centred.iter().map(|p| p * p.transpose()).sum::<Matrix3<f64>>() / chosen.len() as f64;
    let mut eigen = SymmetricEigen::new(scatter).eigenvalues;
    eigen.as_mut_slice().sort_by(|a, b| b.total_cmp(a));
    eigen[1].max(0.0).sqrt()
}

/// Rotation and translation taking the `local` points onto the `lab` ones, least squares with
/// a weight per point (0: not used; Kabsch, a reflection excluded).
pub(crate) fn kabsch(local: &[Vector3<f64>], lab: &[Vector3<f64>], weight: &[f64]) -> (Matrix3<f64>, Vector3<f64>) {
    let total: f64 = weight.iter().sum();
    let lc = local.iter().zip(weight).map(|(p, w)| p * *w).sum::<Vector3<f64>>() / total;
    let gc = lab.iter().zip(weight).filter(|(_, w)| **w > 0.0).map(|(p, w)| p * *w).sum::<Vector3<f64>>() / total;
    let h: Matrix3<f64> = local
        .iter()
        .zip(lab)
        .zip(weight)
        .filter(|(_, w)| **w > 0.0)
        .map(|((a, b), w)| (a - lc) * (b - gc).transpose() * *w)
        .sum();
    let svd = h.svd(true, true);
    let (u, v_t) = (svd.u.expect("requested"), svd.v_t.expect("requested"));
    let mut fix = Matrix3::identity();
    fix[(2, 2)] = (v_t.transpose() * u.transpose()).determinant().signum();
    let rot = v_t.transpose() * fix * u.transpose();
    (rot, gc - rot * lc)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix as Rng;
    use nalgebra::{Rotation3, Vector3};

    /// A four-marker plate (not symmetric), in its own frame, m.
    const PLATE: [[f64; 3]; 4] = [[0.0, 0.0, 0.0], [0.045, 0.0, 0.0], [0.01, 0.04, 0.0], [0.03, 0.025, 0.02]];

    /// Frames of the plate turning and moving: each frame's pose, and its markers (`noise`:
    /// Gaussian per coordinate, m).
    /// The plate's pose in a frame: rotation, then translation.
    type Pose = (Rotation3<f64>, Vector3<f64>);

    fn moving(n: usize, noise: f64, rng: &mut Rng) -> (Vec<Pose>, Vec<f64>) {
        let mut poses = Vec::new();
        let mut frames = Vec::new();
        for i in 0..n {
            let t = i as f64 * 0.01;
            let rot = Rotation3::from_euler_angles(0.9 * (1.1 * t).sin(), 0.5 * (0.7 * t).cos(), 1.3 * t);
            let shift = Vector3::new(0.3 + 0.1 * t.sin(), 1.1, -0.2 * t.cos());
            for p in PLATE {
                let q = rot * Vector3::from(p) + shift;
                frames.extend(q.iter().map(|v| v + noise * rng.normal()));
            }
            poses.push((rot, shift));
        }
        (poses, frames)
    }

    /// Where a pose puts the plate's marker `m` (the oracle: the plate's own geometry).
    fn truth(pose: &Pose, m: usize) -> Vector3<f64> {
        pose.0 * Vector3::from(PLATE[m]) + pose.1
    }

    fn placed(fit: &ClusterFit, frame: usize, m: usize) -> Vector3<f64> {
        let i = 12 * frame + 3 * m;
        Vector3::new(fit.placed[i], fit.placed[i + 1], fit.placed[i + 2])
    }

    #[test]
    fn learns_the_plates_shape_from_noisy_frames() {
        let mut rng = Rng::new(1);
        let (n, noise) = (2000, 0.001);
        let (_, frames) = moving(n, noise, &mut rng);
        let shape = ClusterShape::learn(&frames, 4).unwrap();
        // Every distance between two markers as the plate has it (distances do not depend on
        // the shape's frame), within five standard errors of the difference of two means.
        let tolerance = 5.0 * noise * (2.0 / n as f64).sqrt();
        let learned = shape.points();
        for a in 0..4 {
            for b in a + 1..4 {
                let d = (Vector3::from(PLATE[a]) - Vector3::from(PLATE[b])).norm();
                let e = (Vector3::from_row_slice(&learned[3 * a..3 * a + 3])
                    - Vector3::from_row_slice(&learned[3 * b..3 * b + 3]))
                .norm();
                assert!((d - e).abs() < tolerance, "{a}-{b}: {d} learned {e}");
            }
        }
    }

    #[test]
    fn places_a_missing_marker_where_the_plate_holds_it() {
        let mut rng = Rng::new(2);
        let (poses, mut frames) = moving(300, 0.0, &mut rng);
        let shape = ClusterShape::learn(&frames, 4).unwrap();
        // Frames 100-199 lose marker 0, frames 200-249 marker 3.
        for f in 100..200 {
            frames[12 * f..12 * f + 3].fill(f64::NAN);
        }
        for f in 200..250 {
            frames[12 * f + 9..12 * f + 12].fill(f64::NAN);
        }
        let fit = shape.fit(&frames).unwrap();
        for f in [0, 150, 220, 299] {
            for m in 0..4 {
                let err = (placed(&fit, f, m) - truth(&poses[f], m)).norm();
                assert!(err < 1e-9, "frame {f} marker {m}: {err} m");
            }
        }
        assert_eq!(fit.left_out, vec![0; 4]);
        assert_eq!(fit.undetermined, 0);
    }

    #[test]
    fn averages_the_noise_of_every_marker() {
        // Four markers' fit places each marker nearer its true place than its own noisy reading.
        let mut rng = Rng::new(3);
        let (poses, frames) = moving(2000, 0.002, &mut rng);
        let shape = ClusterShape::learn(&frames, 4).unwrap();
        let fit = shape.fit(&frames).unwrap();
        let (mut raw, mut fitted) = (0.0, 0.0);
        for (f, pose) in poses.iter().enumerate() {
            for m in 0..3 {
                let i = 12 * f + 3 * m;
                raw += (Vector3::new(frames[i], frames[i + 1], frames[i + 2]) - truth(pose, m)).norm_squared();
                fitted += (placed(&fit, f, m) - truth(pose, m)).norm_squared();
            }
        }
        // Least squares over 4 markers leaves 3·4 - 6 = 6 of 12 noise dimensions in the 4
        // markers: each marker's error variance falls to about half.
        let ratio = fitted / raw;
        assert!((0.35..0.65).contains(&ratio), "fitted/raw error variance {ratio}");
    }

    #[test]
    fn leaves_out_a_marker_that_jumps_off_the_plate() {
        let mut rng = Rng::new(4);
        let (poses, mut frames) = moving(200, 0.0, &mut rng);
        let shape = ClusterShape::learn(&frames, 4).unwrap();
        // In frame 50 marker 1 is read 40 mm away (a swapped label for one frame).
        frames[12 * 50 + 3 + 1] += 0.04;
        let fit = shape.fit(&frames).unwrap();
        assert_eq!(fit.left_out, vec![0, 1, 0, 0]);
        for m in 0..4 {
            assert!((placed(&fit, 50, m) - truth(&poses[50], m)).norm() < 1e-9, "marker {m}");
        }
    }

    #[test]
    fn learns_the_shape_past_frames_with_a_marker_off_its_place() {
        // A fifth of the frames read marker 3 40 mm off (its label swapped with a neighbour's):
        // the shape is the plate's, and those frames are fitted to the other three.
        let mut rng = Rng::new(8);
        let (poses, mut frames) = moving(500, 0.0, &mut rng);
        for f in 100..200 {
            frames[12 * f + 10] += 0.04;
        }
        let shape = ClusterShape::learn(&frames, 4).unwrap();
        let fit = shape.fit(&frames).unwrap();
        assert_eq!(fit.left_out, vec![0, 0, 0, 100]);
        for f in [0, 150, 499] {
            for m in 0..4 {
                assert!((placed(&fit, f, m) - truth(&poses[f], m)).norm() < 1e-9, "frame {f} marker {m}");
            }
        }
    }

    #[test]
    fn a_marker_that_moves_on_the_plate_part_way_counts_for_little() {
        // Marker 3 moves 20 mm on the plate half-way through (knocked, stuck back): within the
        // 15 mm a frame's fit tolerates either side of its average place. Its spread says so,
        // and the other markers' places hold in every frame, before the knock and after.
        let mut rng = Rng::new(10);
        let (poses, mut frames) = moving(500, 0.0002, &mut rng);
        for (f, pose) in poses.iter().enumerate().skip(250) {
            let moved = pose.0 * Vector3::new(0.02, 0.0, 0.0);
            for i in 0..3 {
                frames[12 * f + 9 + i] += moved[i];
            }
        }
        let shape = ClusterShape::learn(&frames, 4).unwrap();
        assert!(shape.spread()[3] > 0.005, "{:?}", shape.spread());
        assert!(shape.spread()[..3].iter().all(|&s| s < 0.001), "{:?}", shape.spread());
        let fit = shape.fit(&frames).unwrap();
        let worst = (0..500)
            .flat_map(|f| (0..3).map(move |m| (f, m)))
            .map(|(f, m)| (placed(&fit, f, m) - truth(&poses[f], m)).norm())
            .fold(0.0, f64::max);
        // The fourth marker at a ten-thousandth of the others' weight or less.
        assert!(worst < 0.001, "{worst} m");
    }

    #[test]
    fn two_straying_markers_are_left_out_of_the_core_together() {
        // Five markers: the plate's first three, marker 3 moving 14 mm on it half-way through,
        // and a fifth on another segment (swinging 25 mm about the plate). A median over the
        // five would count them in; the core of the three that keep their distances does not.
        let mut rng = Rng::new(11);
        let (poses, four) = moving(600, 0.0002, &mut rng);
        let mut frames = Vec::new();
        for (f, pose) in poses.iter().enumerate() {
            let mut frame = four[12 * f..12 * f + 12].to_vec();
            if f >= 300 {
                let moved = pose.0 * Vector3::new(0.0, 0.014, 0.0);
                (0..3).for_each(|i| frame[9 + i] += moved[i]);
            }
            let swing = Vector3::new(0.06 + 0.025 * (0.05 * f as f64).sin(), 0.02, 0.01);
            frame.extend_from_slice((pose.0 * swing + pose.1).as_slice());
            frames.extend(frame);
        }
        let shape = ClusterShape::learn(&frames, 5).unwrap();
        assert_eq!(&shape.weight()[..3], &[1.0; 3], "{:?}", shape.weight());
        assert!(shape.weight()[3..].iter().all(|&w| w <= STRAYING_WEIGHT), "{:?}", shape.weight());
        let fit = shape.fit(&frames).unwrap();
        let worst = (0..600)
            .flat_map(|f| (0..3).map(move |m| (f, m)))
            .map(|(f, m)| {
                let i = 15 * f + 3 * m;
                (Vector3::new(fit.placed[i], fit.placed[i + 1], fit.placed[i + 2]) - truth(&poses[f], m)).norm()
            })
            .fold(0.0, f64::max);
        assert!(worst < 0.001, "{worst} m");
    }

    #[test]
    fn a_frame_whose_three_markers_break_the_shape_has_no_cluster() {
        let mut rng = Rng::new(5);
        let (_, mut frames) = moving(100, 0.0, &mut rng);
        let shape = ClusterShape::learn(&frames, 4).unwrap();
        frames[12 * 10..12 * 10 + 3].fill(f64::NAN);
        frames[12 * 10 + 3] += 0.05;
        // Two markers only in frames 20 and 21.
        frames[12 * 20..12 * 20 + 6].fill(f64::NAN);
        frames[12 * 21..12 * 21 + 6].fill(f64::NAN);
        let fit = shape.fit(&frames).unwrap();
        assert!(fit.placed[12 * 10..12 * 11].iter().all(|v| v.is_nan()));
        assert!(fit.placed[12 * 20..12 * 21].iter().all(|v| v.is_nan()));
        assert!(fit.placed[12 * 11..12 * 12].iter().all(|v| v.is_finite()));
        assert_eq!(fit.undetermined, 1, "frame 10 had three markers seen, frames 20 and 21 two");
    }

    #[test]
    fn refuses_what_gives_no_shape() {
        let mut rng = Rng::new(6);
        let (_, mut frames) = moving(30, 0.0, &mut rng);
        // Marker 2 seen in 9 frames only.
        for f in 9..30 {
            frames[12 * f + 6..12 * f + 9].fill(f64::NAN);
        }
        let err = ClusterShape::learn(&frames, 4).unwrap_err().to_string();
        assert!(err.contains("all seen in 9 of 30 frames"), "{err}");
        // Four markers on a line.
        let line: Vec<f64> = (0..20).flat_map(|_| (0..4).flat_map(|m| [0.01 * m as f64, 0.0, 0.0])).collect();
        assert!(ClusterShape::learn(&line, 4).unwrap_err().to_string().contains("on a line"));
        assert!(ClusterShape::learn(&frames[..11], 4).is_err());
        assert!(ClusterShape::learn(&frames, 2).is_err());
        assert!(ClusterShape::from_points(&[0.0; 6], &[0.001; 2], &[1.0; 2]).is_err());
        assert!(ClusterShape::from_points(&[f64::NAN; 9], &[0.001; 3], &[1.0; 3]).is_err());
        assert!(ClusterShape::from_points(&[0.0; 9], &[0.001; 2], &[1.0; 2]).is_err());
        assert!(ClusterShape::from_points(&[0.0; 9], &[0.0; 3], &[1.0; 3]).is_err());
        assert!(ClusterShape::from_points(&[0.0; 9], &[0.001; 3], &[0.0; 3]).is_err());
    }

    #[test]
    fn points_ride_with_the_technical_frame_of_three_markers() {
        // A point fixed to the plate: expressed in the frame of its first three markers at one
        // pose, put back at every other pose it is where the plate's geometry puts it.
        let mut rng = Rng::new(9);
        let (poses, frames) = moving(100, 0.0, &mut rng);
        let three: Vec<f64> = frames.chunks_exact(12).flat_map(|f| f[..9].to_vec()).collect();
        let fixed = Vector3::new(-0.02, 0.11, 0.03);
        let points: Vec<f64> = poses.iter().flat_map(|(r, t)| (r * fixed + t).as_slice().to_vec()).collect();
        let local = points_in_technical_frame(&three, &points).unwrap();
        for f in 1..100 {
            for i in 0..3 {
                assert!((local[3 * f + i] - local[i]).abs() < 1e-12, "frame {f}");
            }
        }
        let back = points_from_technical_frame(&three, &local[..3]).unwrap();
        for (f, pose) in poses.iter().enumerate() {
            let want = pose.0 * fixed + pose.1;
            assert!((Vector3::from_row_slice(&back[3 * f..3 * f + 3]) - want).norm() < 1e-12, "frame {f}");
        }
        // A frame of three markers on a line has no technical frame, wherever the line lies.
        let line = [0.0, 0.0, 0.0, 0.05, 0.0, 0.0, 0.1, 0.001, 0.0];
        assert!(technical_frame(&line).is_none());
        let shifted: Vec<f64> = line.iter().zip([0.2, 1.0, -0.3].iter().cycle()).map(|(v, o)| v + o).collect();
        assert!(technical_frame(&shifted).is_none());
        assert!(points_in_technical_frame(&[0.0; 10], &[0.0; 3]).is_err());
        assert!(points_from_technical_frame(&[0.0; 10], &[0.0; 3]).is_err());
        assert!(points_from_technical_frame(&line, &[0.0; 3]).unwrap().iter().all(|v| v.is_nan()));
        assert!(points_in_technical_frame(&line, &[0.0; 6]).unwrap().iter().all(|v| v.is_nan()));
        assert!(points_from_technical_frame(&line, &[f64::NAN; 3]).is_err());
        assert!(points_in_technical_frame(&line, &[0.0; 4]).is_err());
    }

    #[test]
    fn ten_whole_frames_are_enough_and_three_points_a_shape() {
        let mut rng = Rng::new(12);
        let (_, frames) = moving(MIN_WHOLE_FRAMES, 0.0, &mut rng);
        let shape = ClusterShape::learn(&frames, 4).unwrap();
        let three = ClusterShape::from_points(&shape.points()[..9], &shape.spread()[..3], &[1.0; 3]).unwrap();
        assert_eq!(three.len(), 3);
        // A cluster of three markers is one too (a segment whose [cluster] is its three).
        let only_three: Vec<f64> = frames.chunks_exact(12).flat_map(|f| f[..9].to_vec()).collect();
        assert_eq!(ClusterShape::learn(&only_three, 3).unwrap().len(), 3);
    }

    #[test]
    fn a_first_frame_with_a_marker_off_its_place_teaches_no_wrong_shape() {
        // The frames are turned onto the first: its marker 1, read 30 mm off, must not bend the
        // shape (the median over the frames, the core's weights).
        let mut rng = Rng::new(13);
        let (poses, mut frames) = moving(300, 0.0, &mut rng);
        frames[4] += 0.03;
        let shape = ClusterShape::learn(&frames, 4).unwrap();
        let fit = shape.fit(&frames).unwrap();
        for f in [1, 150, 299] {
            for m in 0..4 {
                assert!((placed(&fit, f, m) - truth(&poses[f], m)).norm() < 1e-6, "frame {f} marker {m}");
            }
        }
    }

    #[test]
    fn three_markers_of_a_cluster_on_a_line_do_not_fix_it() {
        // A plate whose first three markers lie nearly on a line (1 mm off it) and a fourth off
        // it: with the fourth missing, the three leave the roll about their line open.
        let plate = [[0.0, 0.0, 0.0], [0.03, 0.0, 0.0], [0.06, 0.001, 0.0], [0.02, 0.04, 0.01]];
        let mut frames = Vec::new();
        for i in 0..50 {
            let rot = Rotation3::from_euler_angles(0.02 * i as f64, 0.5, -0.01 * i as f64);
            for p in plate {
                frames.extend_from_slice((rot * Vector3::from(p)).as_slice());
            }
        }
        let shape = ClusterShape::learn(&frames, 4).unwrap();
        assert!(!shape.is_empty());
        frames[12 * 30 + 9..12 * 31].fill(f64::NAN);
        let fit = shape.fit(&frames).unwrap();
        assert!(fit.placed[12 * 30..12 * 31].iter().all(|v| v.is_nan()));
        assert!(fit.placed[12 * 29..12 * 30].iter().all(|v| v.is_finite()));
        assert_eq!(fit.undetermined, 1);
    }

    #[test]
    fn white_noise_keeps_a_plate_whole_and_a_slow_slide_does_not() {
        // Every marker with 1 mm of white noise; marker 3 also slides 3 mm to and fro, slowly
        // (skin). The noise alone changes each distance by about 1.4 mm, beyond the rigid limit:
        // taken out, the plate's three stay one body and the sliding marker does not.
        let mut rng = Rng::new(14);
        let (poses, mut frames) = moving(3000, 0.001, &mut rng);
        for (f, pose) in poses.iter().enumerate() {
            let slide = pose.0 * Vector3::new(0.003 * (0.004 * f as f64).sin(), 0.0, 0.0);
            (0..3).for_each(|i| frames[12 * f + 9 + i] += slide[i]);
        }
        let shape = ClusterShape::learn(&frames, 4).unwrap();
        assert_eq!(&shape.weight()[..3], &[1.0; 3], "{:?} {:?}", shape.weight(), shape.spread());
        assert!(shape.weight()[3] <= STRAYING_WEIGHT, "{:?} {:?}", shape.weight(), shape.spread());
        // Without the slide, 1.5 mm of noise (distances changing by 2 mm) leaves all four one body.
        let (_, noisy) = moving(3000, 0.0015, &mut rng);
        let shape = ClusterShape::learn(&noisy, 4).unwrap();
        assert_eq!(shape.weight(), &[1.0; 4], "{:?}", shape.spread());
    }

    #[test]
    fn a_knocked_segment_marker_leaves_the_core_to_the_steadiest_three() {
        // Six markers: the segment's three (0-2), of which marker 0 is moved 12 mm on the plate
        // half-way through, two more plate markers (3, 4) and a sixth (5) sliding 1.8 mm slowly.
        // The core is then seeded by the steadiest three, not the segment's, and keeps out both
        // marker 0 and the slider (its change beyond the plate's 1 mm limit).
        let mut rng = Rng::new(15);
        let (poses, four) = moving(2000, 0.0001, &mut rng);
        let extra = [Vector3::new(0.05, 0.03, -0.01), Vector3::new(0.02, -0.03, 0.02)];
        let mut frames = Vec::new();
        for (f, pose) in poses.iter().enumerate() {
            let mut frame = four[12 * f..12 * f + 12].to_vec();
            if f >= 1000 {
                let moved = pose.0 * Vector3::new(0.012, 0.0, 0.0);
                (0..3).for_each(|i| frame[i] += moved[i]);
            }
            let slide = Vector3::new(0.0018 * (0.003 * f as f64).sin(), 0.0018 * (0.003 * f as f64).cos(), 0.0);
            for (j, e) in extra.iter().enumerate() {
                let p = pose.0 * (e + if j == 1 { slide } else { Vector3::zeros() }) + pose.1;
                frame.extend_from_slice(p.as_slice());
            }
            frames.extend(frame);
        }
        let shape = ClusterShape::learn(&frames, 6).unwrap();
        let w = shape.weight();
        assert_eq!([w[1], w[2], w[3], w[4]], [1.0; 4], "{w:?} {:?}", shape.spread());
        assert!(w[0] <= STRAYING_WEIGHT && w[5] <= STRAYING_WEIGHT, "{w:?} {:?}", shape.spread());
    }

    #[test]
    fn the_median_point_is_each_coordinates_middle_value() {
        let odd = [Vector3::new(3.0, 0.0, 1.0), Vector3::new(1.0, 5.0, 1.0), Vector3::new(2.0, 4.0, 7.0)];
        assert_eq!(median_point(odd.into_iter()), Vector3::new(2.0, 4.0, 1.0));
        let even = [
            Vector3::new(1.0, 0.0, 0.0),
            Vector3::new(2.0, 0.0, 0.0),
            Vector3::new(4.0, 0.0, 0.0),
            Vector3::new(8.0, 0.0, 0.0),
        ];
        assert_eq!(median_point(even.into_iter()).x, 3.0);
    }

    #[test]
    fn a_shape_round_trips_through_its_points() {
        let mut rng = Rng::new(7);
        let (_, frames) = moving(50, 0.0, &mut rng);
        let shape = ClusterShape::learn(&frames, 4).unwrap();
        let again = ClusterShape::from_points(&shape.points(), shape.spread(), shape.weight()).unwrap();
        assert_eq!((again.spread(), again.weight()), (shape.spread(), shape.weight()));
        assert_eq!(again.len(), 4);
        for (a, b) in shape.points().iter().zip(again.points()) {
            assert!((a - b).abs() < 1e-15);
        }
    }
}
