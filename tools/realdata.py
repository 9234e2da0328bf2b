"""Real recordings through the documented CLI, scored against independent reference angles.

    make realdata                      # or: .venv/bin/python tools/realdata.py [--out DIR]

For each recording in ``$IKID_REALDATA`` (default ``../shared/realdata`` beside the repo; see
its README), as a lab would: write a marker map (``ikid map-template`` lists the labels),
``ikid calibrate`` from the recording itself (anatomical landmarks + the neutral frames its
reference names), ``ikid ik`` (the IK family picks its model for the rate; ``--resample`` only if it refuses)
and ``ikid track`` (``--calibration`` when it has one; the refiner only where its rate
allows). Scores: geodesic RMS between the hand-in-forearm rotations on the reference's
``valid`` frames (racing also on ``gimbal_ok``), per-angle RMS, outputs per valid frame.
Writes ``docs/realdata.md`` and ``docs/realdata/*.png``; the last line printed is

    realdata: pyomeca_ik=<deg> pyomeca_track=<deg> racing_ik=<deg> racing_track=<deg>
              left_in_range=<%|refused> left_r=<r|refused> pig_ik=<deg> pig_track=<deg> diverged=<count>

(racing on its gimbal_ok frames; left: the racing left arm, calibrated by the mirror method, the
smaller of ik's and track's share of frames within the coordinates' ranges ± 45° and of their e_f's
Pearson r against the right arm's; pig: the Plug-in Gait trial, both arms, e_f and ad_ab — what its one
hand marker determines — against Vicon's converted wrist angles, means removed, worst;
diverged = trials and probes whose track output is non-finite or
more than 100° off the reference anywhere, garbage frames included; the left arm if non-finite).
It also probes the tracker's promises (issue #19 item 3) through `ikid track`: 200 ms gaps of each
marker, no 360° jumps, garbage bursts flagged and recovered from within 100 ms, refusal when
uncalibrated, and the racing left arm (section 5 of the report). The recordings are read in place,
never copied.

Sign conventions (checked in ``check_conventions``): the reference is intrinsic Y-Z'-X'' of the
hand in the forearm (ISB axes: X volar, Y proximal, Z radial on a right arm), s_p positive in
pronation, e_f in flexion, ad_ab in ulnar deviation. ikid's body model (crates/ikid/src/body.rs)
has the same axes (x volar, y proximal, z radial) and order, with s_p about -y (supination
positive): the two describe the same rotation when ikid's s_p = -reference s_p.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
DEFAULT_DATA = REPO.parent / "shared" / "realdata"
DIVERGED_DEG = 100.0


@dataclass
class Recording:
    """One trial: its files, its marker map, how it is calibrated."""

    name: str
    trial: str  # the marker file scored
    reference: str  # reference/<reference>.csv and _meta.json
    markers: dict[str, str]
    landmarks: dict[str, str]
    calibration_file: str  # the file holding the landmarks and the neutral frames
    side: str = "right"
    notes: list[str] = field(default_factory=list)
    clusters: dict[str, list[str]] = field(default_factory=dict)  # segment -> its markers beyond three


RECORDINGS = [
    Recording(
        name="pyomeca",
        trial="pyomeca_markers_analogs.c3d",
        reference="pyomeca_markers_analogs_R",
        markers={
            "RSP": "Daphnee:LARM_ant",
            "USP": "Daphnee:STYLr_up",
            "FAP": "Daphnee:WRIST",
            "MC2": "Daphnee:INDEX",
            "MC5": "Daphnee:MEDH",
            "MCB": "Daphnee:LATH",
        },
        landmarks={
            "lateral_epicondyle": "Daphnee:EPICl",
            "medial_epicondyle": "Daphnee:EPICm",
            "radial_styloid": "Daphnee:STYLr",
            "ulnar_styloid": "Daphnee:STYLu",
        },
        calibration_file="pyomeca_markers_analogs.c3d",
    ),
    Recording(
        name="racing",
        trial="kinematics_racing_propulsion.c3d",
        reference="racing_propulsion_R",
        markers={
            "RSP": "ForearmR1",
            "USP": "ForearmR2",
            "FAP": "ForearmR3",
            "MC2": "GloveR1",
            "MC5": "GloveR2",
            "MCB": "GloveR3",
        },
        landmarks={
            "lateral_epicondyle": "LateralEpicondyleR",
            "medial_epicondyle": "MedialEpicondyleR",
            "radial_styloid": "RadialStyloidR",
            "ulnar_styloid": "UlnarStyloidR",
        },
        calibration_file="kinematics_racing_full.c3d",
    ),
]


def ikid_command() -> list[str]:
    """The installed `ikid` command (the venv's script beside this Python), else `python -m ikid`."""
    script = Path(sys.executable).parent / "ikid"
    return [str(script)] if script.exists() else [sys.executable, "-m", "ikid"]


def run(args: list[str], log: list[str]) -> subprocess.CompletedProcess:
    """Run one ikid command, keep its command line and its output for the report."""
    cmd = ikid_command() + args
    done = subprocess.run(cmd, capture_output=True, text=True, check=False)
    shown = " ".join(["ikid"] + [a if " " not in a else repr(a) for a in args])
    log.append(f"$ {shown}\n{(done.stdout + done.stderr).strip()}")
    return done


def map_toml(rec: Recording) -> str:
    lines = [f'side = "{rec.side}"', "[markers]"]
    lines += [f'{k} = "{v}"' for k, v in rec.markers.items()]
    lines += ["[landmarks]"] + [f'{k} = "{v}"' for k, v in rec.landmarks.items()]
    if rec.clusters:
        lines += ["[cluster]"] + [f"{k} = {json.dumps(v)}" for k, v in rec.clusters.items()]
    return "\n".join(lines) + "\n"


# --- rotations and scores ----------------------------------------------------------------------


def _rot(axis: int, angle: np.ndarray) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    r = np.zeros(angle.shape + (3, 3))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    r[..., axis, axis] = 1.0
    r[..., i, i] = c
    r[..., j, j] = c
    r[..., i, j] = -s
    r[..., j, i] = s
    return r


def reference_rotation(deg: np.ndarray) -> np.ndarray:
    """The reference's hand-in-forearm rotation: intrinsic Y-Z'-X'' of (s_p, e_f, ad_ab), degrees."""
    q = np.radians(deg)
    return _rot(1, q[:, 0]) @ _rot(2, q[:, 1]) @ _rot(0, q[:, 2])


def ikid_rotation(rad: np.ndarray) -> np.ndarray:
    """ikid's: Rot(-y, s_p) Rot(z, e_f) Rot(x, ad_ab) (crates/ikid/src/body.rs), radians."""
    return _rot(1, -rad[:, 0]) @ _rot(2, rad[:, 1]) @ _rot(0, rad[:, 2])


def geodesic_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    cos = (np.einsum("nij,nij->n", a, b) - 1.0) / 2.0
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def check_conventions() -> None:
    """ikid's documented angles and the reference's describe one rotation with s_p negated:
    checked here against the body model (``ikid.body_model``/``wrist_rotation`` semantics via
    ``ikid.forward_markers`` would need a fit; the axes are asserted directly instead)."""
    rng = np.random.default_rng(0)
    q = rng.uniform(-0.6, 0.6, (50, 3))
    ref = np.degrees(q) * np.array([-1.0, 1.0, 1.0])
    assert np.allclose(reference_rotation(ref), ikid_rotation(q), atol=1e-12)
    # ikid: flexion moves the distal hand (-y) volar (+x); ulnar deviation moves it ulnar (-z);
    # supination turns the palm normal (+x) radially (+z) (body.rs, positive_angles_move_the_hand_as_named).
    distal, palm = np.array([0.0, -1.0, 0.0]), np.array([1.0, 0.0, 0.0])
    one = np.array([0.3])
    assert (ikid_rotation(np.array([[0, 0.3, 0]]))[0] @ distal)[0] > 0.2
    assert (ikid_rotation(np.array([[0, 0, 0.3]]))[0] @ distal)[2] < -0.2
    assert (ikid_rotation(np.array([[0.3, 0, 0]]))[0] @ palm)[2] > 0.2
    # The reference (ISB, right arm): pronation turns the palm normal ulnarly (-z).
    assert (_rot(1, one)[0] @ palm)[2] < -0.2


def at_reference_times(t_out: np.ndarray, q_out: np.ndarray, t_ref: np.ndarray, tol: float) -> np.ndarray:
    """Outputs at the reference's frame times: linear between output rows at most ``tol`` s
    apart around the time (a row within ``tol``/2 is taken as it is); NaN where there is none."""
    out = np.full((len(t_ref), 3), np.nan)
    if len(t_out) == 0:
        return out
    k = np.clip(np.searchsorted(t_out, t_ref), 1, len(t_out) - 1)
    t0, t1 = t_out[k - 1], t_out[k]
    near = np.where(np.abs(t_ref - t0) <= np.abs(t1 - t_ref), k - 1, k)
    exact = np.abs(t_out[near] - t_ref) <= tol / 2
    out[exact] = q_out[near[exact]]
    between = ~exact & (t0 <= t_ref) & (t_ref <= t1) & (t1 - t0 <= tol)
    w = ((t_ref - t0) / np.where(t1 > t0, t1 - t0, 1.0))[between, None]
    out[between] = (1 - w) * q_out[k[between] - 1] + w * q_out[k[between]]
    return out


@dataclass
class Score:
    rms_valid: float = float("nan")
    rms_gimbal: float = float("nan")
    max_valid: float = float("nan")
    p95_gimbal: float = float("nan")
    coverage: float = 0.0  # valid frames with an output / valid frames
    per_angle_gimbal: tuple[float, float, float] = (float("nan"),) * 3
    finite: bool = True
    error: np.ndarray | None = None  # geodesic error per reference frame (NaN: no output/invalid)
    angles: np.ndarray | None = None  # ikid's angles at the reference frames, degrees, ikid signs
    lag_ms: float = float("nan")  # the delay of the outputs that fits the reference best


def score(t_out, q_out, ref: dict, tol: float) -> Score:
    q = at_reference_times(np.asarray(t_out), np.asarray(q_out), ref["time"], tol)
    s = Score(finite=bool(np.isfinite(q_out).all()), angles=np.degrees(q))
    err = geodesic_deg(ikid_rotation(np.nan_to_num(q)), reference_rotation(ref["angles"]))
    has = np.isfinite(q).all(axis=1)
    err[~has | ~ref["valid"]] = np.nan
    s.error = err
    valid, gimbal = ref["valid"] & has, ref["gimbal_ok"] & has
    s.coverage = float(valid.sum() / max(ref["valid"].sum(), 1))
    if valid.any():
        s.rms_valid = float(np.sqrt(np.mean(err[valid] ** 2)))
        s.max_valid = float(np.max(err[valid]))
    if gimbal.any():
        s.rms_gimbal = float(np.sqrt(np.mean(err[gimbal] ** 2)))
        s.p95_gimbal = float(np.percentile(err[gimbal], 95))
        ref_ikid = ref["angles"][gimbal] * np.array([-1.0, 1.0, 1.0])
        d = np.degrees(q[gimbal]) - ref_ikid
        s.per_angle_gimbal = tuple(float(v) for v in np.sqrt(np.mean(d**2, axis=0)))
    s.lag_ms = best_lag_ms(q, has, ref)
    return s


def best_lag_ms(q: np.ndarray, has: np.ndarray, ref: dict, most: int = 5) -> float:
    """The delay (ms; positive: the outputs come after the reference) among 0-``most`` frames
    either way whose geodesic RMS against the reference, on the valid frames both have, is
    least: how much a causal filter lags (the reference is per-frame and unfiltered)."""
    step = float(np.median(np.diff(ref["time"])))
    rot_q, rot_ref = ikid_rotation(np.nan_to_num(q)), reference_rotation(ref["angles"])
    best, lag = np.inf, float("nan")
    for k in range(-most, most + 1):
        # output frame i against reference frame i - k
        i = np.arange(max(k, 0), len(q) + min(k, 0))
        ok = has[i] & ref["valid"][i] & ref["valid"][i - k]
        if ok.sum() < 10:
            continue
        rms = float(np.sqrt(np.mean(geodesic_deg(rot_q[i][ok], rot_ref[i - k][ok]) ** 2)))
        if rms < best:
            best, lag = rms, 1e3 * k * step
    return lag


def read_reference(folder: Path, name: str) -> dict:
    table = np.genfromtxt(folder / "reference" / f"{name}.csv", delimiter=",", names=True)
    meta = json.loads((folder / "reference" / f"{name}_meta.json").read_text())
    return {
        "time": np.asarray(table["time"], float),
        "angles": np.stack([table["s_p"], table["e_f"], table["ad_ab"]], axis=1),
        "valid": table["valid"].astype(bool),
        "gimbal_ok": table["gimbal_ok"].astype(bool),
        "meta": meta,
    }


# --- one recording -----------------------------------------------------------------------------


def process(rec: Recording, folder: Path, work: Path, log: list[str]) -> dict:
    from ikid.io import read_mot

    ref = read_reference(folder, rec.reference)
    neutral = ref["meta"]["neutral_frames"]
    trial = folder / rec.trial
    mapping = work / f"{rec.name}.toml"
    run(["map-template", str(trial)], log)  # the labels, as a user would list them
    mapping.write_text(map_toml(rec))
    cal = work / f"{rec.name}.json"
    frames = ",".join(str(i) for i in neutral)
    done = run(
        [
            "calibrate",
            "--static",
            str(folder / rec.calibration_file),
            "--frames",
            frames,
            "--map",
            str(mapping),
        ]
        + ["-o", str(cal)],
        log,
    )
    calibrated = done.returncode == 0
    result: dict = {
        "rec": rec,
        "ref": ref,
        "calibrated": calibrated,
        "calibrate_out": (done.stdout + done.stderr).strip(),
        "cal_path": cal,
    }
    rate = float(ref["meta"]["rate_hz"])

    def ik(calibration: Path | None, tag: str) -> tuple[Score | None, str]:
        out = work / f"{rec.name}_{tag}.mot"
        base = ["ik", str(trial), "-o", str(out), "--map", str(mapping)]
        base += ["--calibration", str(calibration)] if calibration else []
        done = run(base, log)
        # What ik's summary says it ran: the member at the file's rate, or the 1 kHz member on the
        # file resampled with outputs at the file's own frames.
        how = (
            "1 kHz model at the recording's frames"
            if "outputs at the recording's frames" in done.stdout
            else "model at the recording's rate"
        )
        if done.returncode != 0 and "--resample" in done.stderr:
            done = run(base + ["--resample"], log)
            how = "--resample"
        if done.returncode != 0:
            return None, f"failed: {done.stderr.strip().splitlines()[-1] if done.stderr.strip() else ''}"
        if tag == "ik":
            result["ik_per_frame"] = per_frame_rows(done.stdout)
        t, q = read_mot(out)
        step = np.median(np.diff(t)) if len(t) > 1 else 1.0 / rate
        return score(t, q, ref, tol=max(1.5 * step, 1e-6)), how

    result["geometry"] = geometry_check(trial, mapping, cal, ref) if calibrated else None
    result["ik"], result["ik_how"] = ik(cal if calibrated else None, "ik")
    # Uncalibrated: the body model's placement cannot read these markers; ik says so and refuses.
    result["ik_raw"], result["ik_raw_how"] = ik(None, "ik_uncalibrated")

    help_text = run(["track", "--help"], [])
    track_has_calibration = "--calibration" in help_text.stdout
    stem = work / f"{rec.name}_track"
    base = ["track", str(trial), "-o", str(stem), "--map", str(mapping)]
    tracked_with = "uncalibrated"
    if track_has_calibration and calibrated:
        base += ["--calibration", str(cal)]
        tracked_with = "calibrated"
    done = run(base, log)
    refined = re.search(r"refined by (\S+);", done.stdout)
    refiner = refined[1] if refined else "none (auto: no shipped refiner at this rate)"
    result["track_how"] = f"{tracked_with}, refiner {refiner}"
    if done.returncode == 0:
        t, q = read_mot(stem.with_suffix(".mot"))
        result["track"] = score(t, q, ref, tol=1.5 / rate)
    else:
        result["track"] = None
        result["track_how"] += (
            f"; failed: {done.stderr.strip().splitlines()[-1] if done.stderr.strip() else ''}"
        )
    return result


def per_frame_rows(summary: str) -> tuple[int, int]:
    """From `ikid ik`'s summary: the rows that are the per-frame fallback because the window's
    posture or speed lay beyond the network's training (the window's filling excepted), and the
    rows written."""
    rows = re.search(r"(\d+)/\d+ frames with output", summary)
    beyond = re.search(r"(\d+) where the window's posture or speed was beyond training", summary)
    return (int(beyond[1]) if beyond else 0), (int(rows[1]) if rows else 0)


def geometry_check(trial: Path, mapping: Path, cal: Path, ref: dict) -> Score:
    """A check of the calibration itself, not a CLI path: the frames with all six markers, moved
    by the calibration file to the body model's placement, read as angles by the core's
    per-frame geometry (the ``angles`` feature set: no network, no filter, no filling)."""
    import ikid
    from ikid import _native
    from ikid.io import MarkerMap, read_markers

    data = read_markers(trial)
    frames = data.frames(MarkerMap.load(mapping))
    ok = np.isfinite(frames).all(axis=1)
    q = np.full((len(frames), 3), np.nan)
    q[ok] = _native.compute_features(ikid.load_calibration(cal).apply(frames[ok]), "angles")
    return score(data.time[ok], q[ok], ref, tol=1e-6)


def diverged(s: Score | None) -> bool:
    if s is None:
        return False
    return (not s.finite) or bool(np.nanmax(np.nan_to_num(s.error, nan=0.0)) > DIVERGED_DEG)


def headline(r: dict, key: str) -> float:
    """The number the last line gives: pyomeca on valid frames, racing on gimbal_ok frames."""
    s = r.get(key)
    if s is None:
        return float("nan")
    return s.rms_gimbal if r["rec"].name == "racing" else s.rms_valid


# --- the tracker's promises (issue #19 item 3), probed through `ikid track` ----------------------

GAP_S = 0.2  # each artificial gap
GAP_EVERY_S = 2.0  # one every 2 s, from 1 s
GAP_COST_MAX = 2.0  # x the gap-free error on the same frames
RECOVERY_S = 0.1  # back within GARBAGE_COST_MAX x the gap-free error this long after a burst
RECOVERY_WINDOW_S = 0.5  # ... judged over this long
GARBAGE_COST_MAX = 2.0
JUMP_MAX_DEG = 180.0  # consecutive output angles never differ by more (no 360° jumps)
RANGE_MARGIN_DEG = 45.0  # the left arm: angles within the coordinates' ranges ± this ...
IN_RANGE_MIN = 0.99  # ... on at least this share of frames
LEFT_MARKERS = {
    "RSP": "ForearmL1",
    "USP": "ForearmL2",
    "FAP": "ForearmL3",
    "MC2": "GloveL1",
    "MC5": "GloveL2",
    "MCB": "GloveL3",
}
# The left arm's one landmark: with the plates' shape it says how they pair with the right arm's.
LEFT_LANDMARKS = {"lateral_epicondyle": "LateralEpicondyleL"}


@dataclass
class Run:
    """One `ikid track` output at the recording's frames: angles (rad, NaN where no row was
    written), the ikid_status column (-1 where no row), and the command's exit status."""

    q: np.ndarray
    status: np.ndarray
    returncode: int
    message: str = ""


def track_file(path: Path, mapping: Path, cal: Path | None, out: Path, n: int, log: list[str] | None) -> Run:
    """`ikid track` one marker file; its rows placed at frame numbers (time x rate)."""
    from ikid.io import read_markers
    from ikid.io.storage import read_storage

    args = ["track", str(path), "-o", str(out), "--map", str(mapping)]
    args += ["--calibration", str(cal)] if cal else []
    done = run(args, log if log is not None else [])
    q = np.full((n, 3), np.nan)
    status = np.full(n, -1, np.int64)
    if done.returncode != 0:
        return Run(q, status, done.returncode, (done.stdout + done.stderr).strip())
    rate = read_markers(path).rate_hz
    table = read_storage(out.with_suffix(".mot"))
    rows = np.rint(table.time * rate).astype(int)
    angles = table.select(["ra_wr_s_p", "ra_wr_e_f", "ra_wr_ad_ab"])
    q[rows] = np.radians(angles) if table.in_degrees else angles
    status[rows] = table.column("ikid_status").astype(np.int64)
    return Run(q, status, 0, (done.stdout + done.stderr).strip())


def write_probe(data, rec: Recording, frames: np.ndarray, path: Path) -> Path:
    """The recording with its six mapped markers replaced by `frames` ((n, 18), metres)."""
    from ikid.io import write_c3d
    from ikid.io.markers import MarkerData

    positions = data.positions.copy()
    for j, label in enumerate(rec.markers.values()):
        positions[:, data.labels.index(label)] = frames[:, 3 * j : 3 * j + 3]
    return write_c3d(path, MarkerData(data.labels, data.time, positions, data.rate_hz, str(path)))


def frame_errors(q: np.ndarray, ref: dict) -> np.ndarray:
    """Geodesic error per frame, degrees; NaN where no output or the reference is not valid."""
    e = geodesic_deg(ikid_rotation(np.nan_to_num(q)), reference_rotation(ref["angles"]))
    e[~np.isfinite(q).all(axis=1) | ~ref["valid"]] = np.nan
    return e


def jumps(q: np.ndarray) -> tuple[float, float]:
    """(largest change of any angle between consecutive rows, degrees; largest geodesic angle
    between consecutive rows' rotations, degrees): rows of consecutive frames both written."""
    both = np.isfinite(q[1:]).all(axis=1) & np.isfinite(q[:-1]).all(axis=1)
    if not both.any():
        return 0.0, 0.0
    step = np.degrees(np.abs(np.diff(q, axis=0)[both])).max()
    turn = geodesic_deg(ikid_rotation(q[1:][both]), ikid_rotation(q[:-1][both])).max()
    return float(step), float(turn)


def rms(x: np.ndarray) -> float:
    x = x[np.isfinite(x)]
    return float(np.sqrt(np.mean(x**2))) if len(x) else float("nan")


def probes(r: dict, folder: Path, work: Path, log: list[str]) -> dict:
    """Gaps, garbage bursts and the uncalibrated run for one recording (see the module doc)."""
    from ikid.io import MarkerMap, read_markers

    rec, ref = r["rec"], r["ref"]
    trial = folder / rec.trial
    mapping = work / f"{rec.name}.toml"
    data = read_markers(trial)
    frames = data.frames(MarkerMap.load(mapping))
    n, rate = len(frames), data.rate_hz
    scored = ref["gimbal_ok"] if rec.name == "racing" else ref["valid"]
    cal = r["cal_path"] if r["calibrated"] else None
    base = track_file(trial, mapping, cal, work / f"{rec.name}_probe_base", n, None)
    e0 = frame_errors(base.q, ref)
    out: dict = {"base": base, "runs": {}, "gaps": {}, "garbage": {}}
    out["runs"]["gap-free"] = base

    # 1. Gaps: each marker missing for 200 ms every 2 s.
    length = int(round(GAP_S * rate))
    starts = np.arange(int(round(1.0 * rate)), n - length, int(round(GAP_EVERY_S * rate)))
    in_gap = np.zeros(n, bool)
    for s in starts:
        in_gap[s : s + length] = True
    for j, name in enumerate(rec.markers):
        f = frames.copy()
        f[in_gap, 3 * j : 3 * j + 3] = np.nan
        probe = write_probe(data, rec, f, work / f"{rec.name}_gap_{name}.c3d")
        got = track_file(probe, mapping, cal, work / f"{rec.name}_gap_{name}", n, None)
        e = frame_errors(got.q, ref)
        both = scored & np.isfinite(e0) & np.isfinite(e)
        lost = scored & np.isfinite(e0) & ~np.isfinite(e)
        out["runs"][f"gap {name}"] = got
        out["gaps"][name] = {
            "rms": rms(e[both]),
            "base": rms(e0[both]),
            "cost": rms(e[both]) / rms(e0[both]),
            "in_gaps": rms(e[both & in_gap]),
            "max": float(np.nanmax(e[both])) if both.any() else float("nan"),
            "no_output": int(lost.sum()),
            "gaps": len(starts),
        }

    # 3. Garbage: bursts of 1, 5 and 20 frames (random frames, shifted by 1 km, one marker 10 cm
    # off), and two labels swapped for 0.5 s; each kind in its own file, bursts 1.5 s apart.
    rng = np.random.default_rng(19)
    centre = np.nanmedian(frames.reshape(n, 6, 3), axis=(0, 1))
    swap_len = int(round(0.5 * rate))
    kinds = {
        "random frames": [1, 5, 20],
        "shifted by 1 km": [1, 5, 20],
        "one marker 10 cm off": [1, 5, 20],
        "two labels swapped": [swap_len, swap_len],
    }
    spacing = int(round(1.5 * rate))
    for kind, lengths in kinds.items():
        f = frames.copy()
        bursts = []
        for b, k in enumerate(lengths):
            s = int(round(1.0 * rate)) + b * spacing
            if s + k + int((RECOVERY_S + RECOVERY_WINDOW_S) * rate) >= n:
                break
            sl = slice(s, s + k)
            if kind == "random frames":
                f[sl] = centre[None].repeat(6, 0).reshape(-1) + rng.uniform(-0.5, 0.5, (k, 18))
            elif kind == "shifted by 1 km":
                f[sl] += 1000.0
            elif kind == "one marker 10 cm off":
                m = [4, 1, 3][b % 3]  # MC5, USP, MC2
                d = rng.normal(size=3)
                f[sl, 3 * m : 3 * m + 3] += 0.1 * d / np.linalg.norm(d)
            else:
                a, c = [(3, 4), (0, 1)][b % 2]  # MC2<->MC5, then RSP<->USP
                f[sl, 3 * a : 3 * a + 3], f[sl, 3 * c : 3 * c + 3] = (
                    frames[sl, 3 * c : 3 * c + 3].copy(),
                    frames[sl, 3 * a : 3 * a + 3].copy(),
                )
            bursts.append((s, k))
        tag = kind.split()[0] + kind.split()[-1]
        probe = write_probe(data, rec, f, work / f"{rec.name}_garbage_{tag}.c3d")
        got = track_file(probe, mapping, cal, work / f"{rec.name}_garbage_{tag}", n, None)
        out["runs"][kind] = got
        e = frame_errors(got.q, ref)
        results = []
        wait, window = int(np.ceil(RECOVERY_S * rate)), int(round(RECOVERY_WINDOW_S * rate))
        for s, k in bursts:
            bad = np.arange(s, s + k)
            unflagged = int(np.sum(got.status[bad] == 0))  # written with status 0
            end = s + k

            def cost(d: int, end: int = end, e: np.ndarray = e, window: int = window) -> float:
                w = np.arange(end + d, min(end + d + window, n))
                w = w[scored[w] & np.isfinite(e0[w])]
                after = e[w]
                if not np.isfinite(after).all():  # no output on a scored frame there
                    return float("inf")
                return rms(after) / rms(e0[w])

            recovery = next((d for d in range(0, 3 * wait + 1) if cost(d) <= GARBAGE_COST_MAX), None)
            results.append(
                {
                    "frames": k,
                    "unflagged": unflagged,
                    "cost": cost(wait),
                    "recovery_ms": float("inf") if recovery is None else 1e3 * recovery / rate,
                }
            )
        out["garbage"][kind] = results

    # 4. Uncalibrated: refused, saying to calibrate.
    out["uncalibrated"] = track_file(trial, mapping, None, work / f"{rec.name}_probe_uncal", n, log)
    # 2. No 360° jumps in any of these runs.
    out["jumps"] = {name: jumps(got.q) for name, got in out["runs"].items()}
    out["diverged"] = [
        name
        for name, got in out["runs"].items()
        if got.returncode != 0
        or not np.isfinite(got.q[np.isfinite(got.q).all(axis=1)]).all()
        or np.nanmax(np.nan_to_num(frame_errors(got.q, ref), nan=0.0)) > DIVERGED_DEG
    ]
    return out


def median_posture_frames(data, markers: dict[str, str], k: int = 10) -> list[int]:
    """The `k` frames whose hand-in-forearm rotation (technical frames of the two clusters) is
    closest to the median posture: the rule the racing reference chose its neutral frames by."""
    xyz = np.stack([data.marker(markers[m]) for m in ("RSP", "USP", "FAP", "MC2", "MC5", "MCB")], axis=1)
    whole = np.flatnonzero(np.isfinite(xyz).all(axis=(1, 2)))

    def frames_of(p: np.ndarray) -> np.ndarray:  # Gram-Schmidt on three markers, (n, 3, 3) columns
        x = p[:, 1] - p[:, 0]
        x /= np.linalg.norm(x, axis=1, keepdims=True)
        z = np.cross(x, p[:, 2] - p[:, 0])
        z /= np.linalg.norm(z, axis=1, keepdims=True)
        return np.stack([x, np.cross(z, x), z], axis=2)

    rel = np.einsum("nji,njk->nik", frames_of(xyz[whole, :3]), frames_of(xyz[whole, 3:]))
    u, _, vt = np.linalg.svd(rel.mean(axis=0))  # chordal mean
    mean = u @ np.diag([1.0, 1.0, np.linalg.det(u @ vt)]) @ vt
    off = geodesic_deg(rel, np.broadcast_to(mean, rel.shape))
    # Of the 50 frames nearest that posture, the k nearest one another (the tightest cluster).
    near = np.argsort(off)[:50]
    best, chosen = np.inf, near[:k]
    for c in near:
        d = geodesic_deg(rel[near], np.broadcast_to(rel[c], (len(near), 3, 3)))
        group = near[np.argsort(d)[:k]]
        spread = max(geodesic_deg(rel[group], np.broadcast_to(rel[g], (k, 3, 3))).max() for g in group)
        if spread < best:
            best, chosen = spread, group
    return sorted(int(i) for i in whole[chosen])


def left_arm(folder: Path, work: Path, right: dict, log: list[str]) -> dict:
    """The racing recording's left arm: plates and a lateral epicondyle only. Calibrated as a lab
    would (docs/markersets.md): `ikid calibrate --method mirror --from <the right arm's calibration>`
    with the left's lateral epicondyle in the map, the hand at the 10 frames nearest one another
    near the left arm's median posture (the rule the reference chose the right arm's neutral frames
    by); the map first names the plates' markers in label order and, if the calibration says they
    pair the other way, as it says. Then `ik` and `track`; no reference there, so: finite, no 360°
    jumps, in range (both paths), and e_f against the right arm's (ik against ik, track against
    track). Refused (what to record said): nothing is tracked."""
    import ikid
    from ikid.io import read_markers

    rec = next(r for r in RECORDINGS if r.name == "racing")
    trial = folder / rec.trial
    mapping = work / "racing_left.toml"
    cal = work / "racing_left.json"
    out: dict = {"attempts": []}
    data = read_markers(trial)
    n = len(data)
    chosen = median_posture_frames(data, LEFT_MARKERS)
    neutral = ",".join(str(i) for i in chosen)
    markers = dict(LEFT_MARKERS)
    for _ in range(2):
        mapping.write_text(
            map_toml(Recording("racing_left", rec.trial, rec.reference, markers, LEFT_LANDMARKS, "", "left"))
        )
        forearm = ", ".join(f"{m}={markers[m]}" for m in ("RSP", "USP", "FAP"))
        cmd = ["calibrate", "--static", str(trial), "--frames", neutral, "--map", str(mapping)]
        cmd += ["--method", "mirror", "--from", str(right["cal_path"]), "-o", str(cal)]
        done = run(cmd, log)
        message = (done.stdout + done.stderr).strip()
        out["attempts"].append((forearm, neutral, message))
        # What the refusal says to change in the map: "give RSP the label now given to FAP, ...".
        moves = re.findall(r"give (\w+) the label now given to (\w+)", message)
        if done.returncode == 0 or not moves:
            break
        markers = {**markers, **{a: markers[b] for a, b in moves}}
    out["calibrate_out"] = message
    out["calibrated"] = done.returncode == 0
    out["markers"] = markers
    nan = float("nan")
    if not out["calibrated"]:
        out.update(run=None, ik=None, in_range=nan, in_range_by={}, written=0.0, jumps=(nan, nan))
        out.update(diverged=False, ef_correlation=nan, ef_by={}, ef_frames=0)
        return out
    got = track_file(trial, mapping, cal, work / "racing_left_track", n, log)
    out["run"] = got
    out["ik"] = ik_file(trial, mapping, cal, work / "racing_left_ik.mot", n, log)
    lo = np.array([c[2][0] for c in ikid._native.COORDINATES]) - np.radians(RANGE_MARGIN_DEG)
    hi = np.array([c[2][1] for c in ikid._native.COORDINATES]) + np.radians(RANGE_MARGIN_DEG)
    right_by = {
        "ik": np.radians(right["ik"].angles) if right["ik"] else None,
        "track": right["probes"]["base"].q,
    }
    out["in_range_by"], out["ef_by"], out["written_by"] = {}, {}, {}
    for path, q in (("ik", out["ik"].q), ("track", got.q)):
        written = np.isfinite(q).all(axis=1)
        inside = written & np.all((q >= lo) & (q <= hi), axis=1)
        out["in_range_by"][path] = float(inside.sum() / n)  # rows not written count as outside
        out["written_by"][path] = float(written.sum() / n)
        right_q = right_by[path]
        both = written & np.isfinite(right_q).all(axis=1) if right_q is not None else np.zeros(n, bool)
        out["ef_by"][path] = float(np.corrcoef(q[both, 1], right_q[both, 1])[0, 1]) if both.sum() > 2 else nan
        if path == "track":
            out["ef_frames"] = int(both.sum())
    out["in_range"] = min(out["in_range_by"].values())
    out["ef_correlation"] = min(out["ef_by"].values())
    out["written"] = min(out["written_by"].values())
    out["jumps"] = jumps(got.q)
    out["diverged"] = got.returncode != 0 or not np.isfinite(got.q[np.isfinite(got.q).all(axis=1)]).all()
    return out


def ik_file(path: Path, mapping: Path, cal: Path, out: Path, n: int, log: list[str]) -> Run:
    """`ikid ik` one marker file (``--resample`` if it refuses the rate); rows placed at frame
    numbers (time x rate), NaN where none."""
    from ikid.io import read_markers
    from ikid.io.storage import read_storage

    args = ["ik", str(path), "-o", str(out), "--map", str(mapping), "--calibration", str(cal)]
    done = run(args, log)
    if done.returncode != 0 and "--resample" in done.stderr:
        done = run(args + ["--resample"], log)
    q = np.full((n, 3), np.nan)
    status = np.full(n, -1, np.int64)
    if done.returncode != 0:
        return Run(q, status, done.returncode, (done.stdout + done.stderr).strip())
    rate = read_markers(path).rate_hz
    table = read_storage(out)
    rows = np.rint(table.time * rate).astype(int)
    keep = (rows >= 0) & (rows < n) & (np.abs(table.time * rate - rows) < 0.25)
    angles = table.select(["ra_wr_s_p", "ra_wr_e_f", "ra_wr_ad_ab"])
    q[rows[keep]] = (np.radians(angles) if table.in_degrees else angles)[keep]
    return Run(q, status, 0, (done.stdout + done.stderr).strip())


# --- Plug-in Gait: one hand marker, against Vicon's own wrist angles ---------------------------

PIG_TRIAL, PIG_STATIC = "pycgm_movement.c3d", "pycgm_static.c3d"


def pig_map(side: str) -> str:
    """Plug-in Gait's arm as ikid ships it (``MarkerMap.plug_in_gait``, what ``ikid map-template``
    writes for these labels): the wrist bar on the styloids, ELB, FIN the hand's one marker."""
    from ikid.io import MarkerMap

    return MarkerMap.plug_in_gait(side).to_toml()


def vicon_wrist(folder: Path, trial: str, side: str) -> np.ndarray:
    """Vicon's wrist angles of ``trial`` (pycgm_movement or pycgm_static) converted as the data's
    README says: R = Ry(X)·Rx(Y)·Rz(Z) (left: Y and Z negated) decomposed Z-Y'-X'' gives
    (pronation, flexion, -ulnar deviation) (left: -pronation, flexion, ulnar deviation).
    Returns (pronation, flexion, ulnar deviation) in degrees: the reference's s_p/e_f/ad_ab."""
    t = np.genfromtxt(folder / "reference" / f"{trial}_vicon_wrist.csv", delimiter=",", names=True)
    p = side[0].upper()
    x, y, z = (np.radians(t[f"{p}_{k}"]) for k in ("flex", "dev", "rot"))
    sign = 1.0 if p == "R" else -1.0
    r = _rot(1, x) @ _rot(0, sign * y) @ _rot(2, sign * z)
    a1 = np.arctan2(r[:, 1, 0], r[:, 0, 0])
    a2 = -np.arcsin(np.clip(r[:, 2, 0], -1.0, 1.0))
    a3 = np.arctan2(r[:, 2, 1], r[:, 2, 2])
    return np.degrees(np.stack([sign * a1, a2, -sign * a3], axis=1))


def pig(folder: Path, work: Path, log: list[str]) -> dict:
    """Both arms of the Plug-in Gait trial: calibrated from the static trial, `ik` and `track`,
    e_f and ad_ab (the coordinates one hand marker determines) against Vicon's converted wrist
    angles, each trial's mean removed (the two models place their axes differently)."""
    from ikid.io.storage import not_determined, read_storage

    trial = folder / PIG_TRIAL
    out: dict = {"arms": {}}
    for side in ("right", "left"):
        mapping = work / f"pig_{side}.toml"
        mapping.write_text(pig_map(side))
        cal = work / f"pig_{side}.json"
        done = run(
            ["calibrate", "--static", str(folder / PIG_STATIC), "--map", str(mapping), "-o", str(cal)], log
        )
        arm: dict = {"calibrate_out": (done.stdout + done.stderr).strip(), "calibrated": done.returncode == 0}
        vicon = vicon_wrist(folder, "pycgm_movement", side)
        for path in ("ik", "track"):
            stem = work / f"pig_{side}_{path}"
            args = [path, str(trial), "-o", str(stem.with_suffix(".mot") if path == "ik" else stem)]
            done = run(args + ["--map", str(mapping), "--calibration", str(cal)], log)
            arm[f"{path}_out"] = (done.stdout + done.stderr).strip()
            if done.returncode != 0 or not arm["calibrated"]:
                arm[path] = None
                continue
            table = read_storage(stem.with_suffix(".mot"))
            rows = np.rint(table.time * 120.0).astype(int)
            q = np.full((len(vicon), 3), np.nan)
            q[rows, 1] = table.column("ra_wr_e_f")
            q[rows, 2] = table.column("ra_wr_ad_ab")
            arm[path] = _pig_score(q, vicon, list(table.columns), not_determined(table))
        done, q, columns = _pig_live(trial, side, mapping, cal, log)
        arm["stream_out"] = done.stderr.strip()
        ok = done.returncode == 0 and arm["calibrated"]
        written = [c for c in ("ra_wr_s_p", "ra_wr_e_f", "ra_wr_ad_ab") if c in columns]
        not_written = [c for c in ("ra_wr_s_p", "ra_wr_e_f", "ra_wr_ad_ab") if c not in written]
        arm["stream"] = _pig_score(q, vicon, columns, not_written) if ok else None
        out["arms"][side] = arm
    for path in ("ik", "track"):
        scores = [a[path] for a in out["arms"].values()]
        out[path] = float("nan") if any(s is None for s in scores) else max(max(s["rms"]) for s in scores)
    return out


def _pig_score(q: np.ndarray, vicon: np.ndarray, columns: list[str], not_written: list[str]) -> dict:
    """e_f and ad_ab of ``q`` (``(n, 3)`` degrees at the trial's frames, NaN where no row)
    against Vicon's, each mean removed."""
    has = np.isfinite(q[:, 1:]).all(axis=1)
    rms_by = []
    for k in (1, 2):
        a, b = q[has, k] - q[has, k].mean(), vicon[has, k] - vicon[has, k].mean()
        rms_by.append(float(np.sqrt(np.mean((a - b) ** 2))))
    return {
        "rms": rms_by,
        "r": [float(np.corrcoef(q[has, k], vicon[has, k])[0, 1]) for k in (1, 2)],
        "rows": int(has.sum()),
        "frames": len(vicon),
        "columns": columns,
        "not_determined": not_written,
    }


def _pig_live(trial: Path, side: str, mapping: Path, cal: Path, log: list[str]):
    """The trial's four markers of ``side`` sent live by a fake Qualisys QTM server on
    127.0.0.1 (the tests' ``live_peers.FakeQtm``: QTM's protocol, float32 mm, the C3D's own up
    as its AxisUpwards), read by ``ikid stream --tracker``: its exit, the ``(n, 3)`` angles in
    degrees of its ``ok`` lines (NaN elsewhere) and its CSV columns."""
    peers = str(Path(__file__).resolve().parent.parent / "tests")
    if peers not in sys.path:
        sys.path.insert(0, peers)
    from ikid.io import MarkerMap, read_markers
    from live_peers import FakeQtm

    data = read_markers(trial)
    plug_in_gait = MarkerMap.plug_in_gait(side)
    labels = [plug_in_gait.labels[m] for m in plug_in_gait.marker_names()]
    up = data.lab_up()[0]
    raw = np.concatenate([data.marker(label, "+y") for label in labels], axis=1)  # the file's lab
    server = FakeQtm(raw, rate=data.rate_hz, labels=labels, up=up.upper(), burst=True)
    args = ["stream", "--source", "qtm:127.0.0.1:PORT", "--map", str(mapping), "--calibration", str(cal),
            "--tracker", "--idle", "3", "--max-lag", "1000", "--count", str(len(raw))]  # fmt: skip
    try:
        done = run([a.replace("PORT", str(server.port)) for a in args], [])
    finally:
        server.close()
    said = done.stderr.strip().replace(f"127.0.0.1:{server.port}", "127.0.0.1:PORT")
    log.append(f"$ ikid {' '.join(args)}  # a fake QTM on the loopback sends {trial.name}\n{said}")
    lines = done.stdout.strip().splitlines()
    columns = lines[0].split(",") if lines else []
    q = np.full((len(raw), 3), np.nan)
    for k, line in enumerate(lines[1:]):
        row = line.split(",")
        if row[2] == "ok":
            q[k, 1:] = np.degrees([float(row[columns.index(c)]) for c in ("ra_wr_e_f", "ra_wr_ad_ab")])
    return done, q, columns


def pig_summary(p: dict) -> list[str]:
    lines = []
    for side, arm in p["arms"].items():
        for path in ("ik", "track", "stream"):
            s = arm[path]
            if s is None:
                why = arm[f"{path}_out"].splitlines()[-1] if arm[f"{path}_out"] else ""
                lines.append(f"pig {side} {path}: FAILED: {why or arm['calibrate_out']}")
                continue
            lines.append(
                f"pig {side} {path}: e_f {s['rms'][0]:.2f}° ad_ab {s['rms'][1]:.2f}° RMS against Vicon, "
                "means "
                f"removed (r {s['r'][0]:.3f}, {s['r'][1]:.3f}); {s['rows']}/{s['frames']} rows; not written: "
                f"{', '.join(s['not_determined']) or 'none'}"
            )
    return lines


# --- styloid markers that are also landmarks -----------------------------------------------------

# Two of pyomeca's maps whose markers are also landmarks: the styloid markers both in the forearm's
# cluster (STYLr/STYLu as RSP/USP), and STYLr alone there with two markers on the radius. The ulna stays
# while the radius turns about it in pronation, and the reference's forearm is the radius: the first
# read 12.8° off (ik 12.7°, track 4.1°; any cluster holding STYLu 7.8-17°) and is refused by the marker
# map, saying what to map instead; the second reads 1.55° (the reference's own cluster 1.96°).
PYOMECA_STYLOIDS = {
    "both styloids as RSP/USP": {
        "RSP": "Daphnee:STYLr",
        "USP": "Daphnee:STYLu",
        "FAP": "Daphnee:LARM_ant",
    },
    "radial styloid as RSP": {
        "RSP": "Daphnee:STYLr",
        "USP": "Daphnee:LARM_ant",
        "FAP": "Daphnee:WRIST",
    },
}


def pyomeca_styloids(folder: Path, work: Path, log: list[str]) -> dict:
    """pyomeca with styloid markers in the forearm's cluster that are also its styloid landmarks
    (one label for a marker and a landmark), calibrated and scored as `process` does, per map."""
    base = next(r for r in RECORDINGS if r.name == "pyomeca")
    out = {}
    for k, (name, forearm) in enumerate(PYOMECA_STYLOIDS.items()):
        markers = {**base.markers, **forearm}
        rec = Recording(
            f"pyomeca_styloids{k}", base.trial, base.reference, markers, base.landmarks, base.trial
        )
        r = process(rec, folder, work, log)
        out[name] = {key: r[key] for key in ("calibrated", "calibrate_out", "ik", "track", "geometry")}
        out[name]["markers"] = forearm
    return out


# pyomeca with more than three markers on a segment ([cluster], docs/markersets.md): the forearm's
# radius markers with the radial styloid, the hand's with LASTC. Skin markers: the fourth slides
# otherwise than the three, stays out of the cluster's rigid core and stands in for a missing one.
PYOMECA_CLUSTERS = {
    "forearm of four (+STYLr)": {"forearm": ["Daphnee:STYLr"]},
    "hand of four (+LASTC)": {"hand": ["Daphnee:LASTC"]},
    "both": {"forearm": ["Daphnee:STYLr"], "hand": ["Daphnee:LASTC"]},
}


def pyomeca_clusters(folder: Path, work: Path, log: list[str]) -> dict:
    """pyomeca with a segment of four markers (``[cluster]``), calibrated and scored as `process`
    does, per map; with the rows `ik` wrote."""
    base = next(r for r in RECORDINGS if r.name == "pyomeca")
    out = {}
    for k, (name, clusters) in enumerate(PYOMECA_CLUSTERS.items()):
        rec = Recording(
            f"pyomeca_clusters{k}",
            base.trial,
            base.reference,
            base.markers,
            base.landmarks,
            base.trial,
            clusters=clusters,
        )
        r = process(rec, folder, work, log)
        out[name] = {
            key: r.get(key) for key in ("calibrated", "calibrate_out", "ik", "track", "ik_per_frame")
        }
    return out


def cluster_line(clusters: dict) -> str:
    parts = []
    for name, c in clusters.items():
        ik, tr = c["ik"], c["track"]
        rows = c["ik_per_frame"][1] if c["ik_per_frame"] else 0
        parts.append(
            f"{name}: ik {fmt(ik.rms_valid if ik else np.nan)}° ({rows} rows), track "
            f"{fmt(tr.rms_valid if tr else np.nan)}°"
        )
    return "pyomeca, four-marker segments ([cluster]; geodesic RMS, valid frames): " + "; ".join(parts)


def racing_one_hand(folder: Path, work: Path, log: list[str]) -> dict:
    """The racing right arm as a lab with a forearm plate and one marker on the hand would mark
    it: `ForearmR1-3` as the forearm's cluster, `GloveR2` alone on the hand, calibrated from the
    probed landmarks at the reference's neutral frames. Scored against the hand marker's
    direction from the mid-styloids in the forearm's ISB frame built anew each frame from the
    four landmarks (`_full`'s, as the reference builds it): flexion/extension and deviation RMS,
    degrees, per path."""
    from ikid.io import read_markers, read_mot

    base = next(r for r in RECORDINGS if r.name == "racing")
    ref = read_reference(folder, base.reference)
    markers = {"RSP": "ForearmR1", "USP": "ForearmR2", "FAP": "ForearmR3", "HND": "GloveR2"}
    mapping = work / "racing_one_hand.toml"
    mapping.write_text(
        map_toml(Recording("racing_one_hand", base.trial, base.reference, markers, base.landmarks, ""))
    )
    cal = work / "racing_one_hand.json"
    frames = ",".join(str(i) for i in ref["meta"]["neutral_frames"])
    done = run(
        [
            "calibrate",
            "--static",
            str(folder / base.calibration_file),
            "--frames",
            frames,
            "--map",
            str(mapping),
            "-o",
            str(cal),
        ],
        log,
    )
    out: dict = {"calibrated": done.returncode == 0, "calibrate_out": (done.stdout + done.stderr).strip()}
    if not out["calibrated"]:
        # Expected: the glove's marker is off the hand's axis (it reads the hand about 64° from
        # zero at the reference's neutral frames), and every angle would carry that.
        return out
    full = read_markers(folder / base.calibration_file)
    lm = {k: full.marker(v) for k, v in base.landmarks.items()}
    wrist = (lm["radial_styloid"] + lm["ulnar_styloid"]) / 2
    y = (lm["lateral_epicondyle"] + lm["medial_epicondyle"]) / 2 - wrist
    y /= np.linalg.norm(y, axis=1, keepdims=True)
    x = np.cross(y, lm["radial_styloid"] - lm["ulnar_styloid"])
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    z = np.cross(x, y)
    d = full.marker("GloveR2") - wrist
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    dx, dy, dz = (np.sum(d * axis, axis=1) for axis in (x, y, z))
    truth = np.degrees(np.stack([np.arctan2(dx, -dy), -np.arcsin(np.clip(dz, -1, 1))], axis=1))
    for path in ("ik", "track"):
        stem = work / f"racing_one_hand_{path}"
        target = str(stem.with_suffix(".mot")) if path == "ik" else str(stem)
        args = [
            path,
            str(folder / base.trial),
            "-o",
            target,
            "--map",
            str(mapping),
            "--calibration",
            str(cal),
        ]
        done = run(args, log) if out["calibrated"] else None
        if done is None or done.returncode != 0:
            out[path] = None
            continue
        t, q = read_mot(stem.with_suffix(".mot"))
        rows = np.rint(t * full.rate_hz).astype(int)
        err = np.degrees(q[:, 1:]) - truth[rows]
        ok = np.isfinite(err).all(axis=1)
        out[path] = {
            "rows": int(len(t)),
            "rms": np.sqrt(np.mean(err[ok] ** 2, axis=0)).tolist(),
            "said": done.stdout,
        }
    return out


def one_hand_line(r: dict) -> str:
    head = "racing right arm, forearm plate + one glove marker (GloveR2)"
    if not r["calibrated"]:
        said = r["calibrate_out"].removeprefix("ikid: error: ")
        reason = said.split(": ", 1)[-1].split(": its angles")[0]
        return f"{head}: calibration refused, as it should be: {reason} (the marker is off the hand's axis)"
    parts = []
    for path in ("ik", "track"):
        s = r.get(path)
        parts.append(
            f"{path} flexion {fmt(s['rms'][0])}°, deviation {fmt(s['rms'][1])}° ({s['rows']} rows)"
            if s
            else f"{path} failed"
        )
    return (
        f"{head}: calibrated, though the marker reads the hand far from zero at the neutral frames "
        "(RMS against its direction in the landmarks' forearm frame): " + "; ".join(parts)
    )


def styloid_line(styloids: dict) -> str:
    parts = []
    for name, st in styloids.items():
        used = ", ".join(f"{m}={lab.split(':')[-1]}" for m, lab in st["markers"].items())
        if not st["calibrated"]:
            why = st["calibrate_out"].splitlines()[-1] if st["calibrate_out"] else ""
            parts.append(f"{name} ({used}): refused: {why}")
            continue
        ik, tr, ge = st["ik"], st["track"], st["geometry"]
        parts.append(
            f"{name} ({used}): ik {fmt(ik.rms_valid if ik else np.nan)}°, track "
            f"{fmt(tr.rms_valid if tr else np.nan)}°, calibration check "
            f"{fmt(ge.rms_valid if ge else np.nan)}°"
        )
    return "pyomeca, styloid markers that are also landmarks (geodesic RMS, valid frames): " + "; ".join(
        parts
    )


# --- report ------------------------------------------------------------------------------------


def plot(r: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ref = r["ref"]
    t = ref["time"]
    ref_ikid = np.where(ref["valid"][:, None], ref["angles"] * np.array([-1.0, 1.0, 1.0]), np.nan)
    fig, axes = plt.subplots(4, 1, figsize=(10, 10), sharex=True)
    names = ["s_p (supination +)", "e_f (flexion +)", "ad_ab (ulnar deviation +)"]
    for k, ax in enumerate(axes[:3]):
        ax.plot(t, ref_ikid[:, k], "k", lw=1.5, label="reference")
        for key, style, label in (("ik", "C0", "ikid ik"), ("track", "C1", "ikid track")):
            s = r.get(key)
            if s is not None:
                ax.plot(t, np.clip(s.angles[:, k], -200, 200), style, lw=1, label=label)
        ax.set_ylabel(f"{names[k]}, °")
        ax.grid(alpha=0.3)
    axes[0].legend(loc="upper right", fontsize=8)
    if not ref["gimbal_ok"].all():
        for ax in axes:
            lo = np.ma.clump_masked(np.ma.masked_array(t, ~ref["gimbal_ok"] & ref["valid"]))
            for sl in lo:
                ax.axvspan(t[sl.start], t[sl.stop - 1], color="0.85", lw=0)
    for key, style, label in (("ik", "C0", "ik"), ("track", "C1", "track")):
        s = r.get(key)
        if s is not None:
            axes[3].plot(t, np.clip(s.error, 0, 180), style, lw=1, label=label)
    axes[3].set_ylabel("geodesic error, °")
    axes[3].set_xlabel("time, s")
    axes[3].grid(alpha=0.3)
    axes[3].legend(loc="upper right", fontsize=8)
    fig.suptitle(
        f"{r['rec'].name}: ikid (calibrated from the recording) vs the reference (grey: |e_f| > 60°)"
    )
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    plt.close(fig)


def plot_left(left: dict, right: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = right["ref"]["time"]
    fig, axes = plt.subplots(3, 1, figsize=(10, 7), sharex=True)
    names = ["s_p (supination +)", "e_f (flexion +)", "ad_ab (ulnar deviation +)"]
    for k, ax in enumerate(axes):
        ax.plot(t, np.degrees(right["probes"]["base"].q[:, k]), "C1", lw=1, label="right arm (ikid track)")
        ax.plot(t, np.degrees(left["run"].q[:, k]), "C2", lw=1, label="left arm (ikid track)")
        ax.plot(t, np.degrees(left["ik"].q[:, k]), "C2", lw=1, ls=":", label="left arm (ikid ik)")
        ax.set_ylabel(f"{names[k]}, °")
        ax.grid(alpha=0.3)
    axes[0].legend(loc="upper right", fontsize=8)
    axes[-1].set_xlabel("time, s")
    fig.suptitle(
        f"racing: left arm (mirror calibration) vs right arm, e_f correlation ik {left['ef_by']['ik']:.2f}, "
        f"track {left['ef_by']['track']:.2f}"
    )
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    plt.close(fig)


def fmt(x: float) -> str:
    return "–" if not np.isfinite(x) else f"{x:.2f}"


def probe_report(results: list[dict], left: dict) -> list[str]:
    """The tracker's promises (issue #19 item 3) as report sections."""
    lines = [
        "## The tracker's promises, probed through `ikid track`",
        "",
        "Each probe is a copy of the recording with its six mapped markers changed (written to a "
        "temporary C3D with `ikid.io.write_c3d`), tracked by `ikid track --calibration` as above and "
        "scored on the same frames as the gap-free run (pyomeca: valid frames; racing: gimbal_ok).",
        "",
        f"### 1. 200 ms gaps of any one marker (bound: ≤ {GAP_COST_MAX:g}× the gap-free error)",
        "",
        f"Gaps of {GAP_S * 1e3:.0f} ms every {GAP_EVERY_S:g} s from 1 s (pyomeca 3, racing 5). "
        "Cost = geodesic RMS with the gaps / without, over the same frames.",
        "",
        "| trial | marker | RMS with gaps | gap-free | cost | RMS inside the gaps | max "
        "| scored frames without output |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in results:
        for m, g in r["probes"]["gaps"].items():
            lines.append(
                f"| {r['rec'].name} | {m} ({r['rec'].markers[m]}) | {fmt(g['rms'])} | {fmt(g['base'])} | "
                f"**{g['cost']:.2f}×** | {fmt(g['in_gaps'])} | {fmt(g['max'])} | {g['no_output']} |"
            )
    lines += [
        "",
        f"### 2. No 360° jumps (bound: consecutive outputs ≤ {JUMP_MAX_DEG:g}° apart per angle)",
        "",
        "Over every run above and below (gap-free, each gap and garbage probe): the largest change of "
        "any angle between consecutive written frames, and the largest geodesic angle between "
        "consecutive rotations (a flip of Euler triple near gimbal lock changes angles, not the rotation).",
        "",
        "| trial | runs | largest step of an angle, ° | largest geodesic step, ° |",
        "|---|---|---|---|",
    ]
    for r in results:
        j = r["probes"]["jumps"]
        lines.append(
            f"| {r['rec'].name} | {len(j)} | {max(v[0] for v in j.values()):.1f} | "
            f"{max(v[1] for v in j.values()):.1f} |"
        )
    lines += [
        "",
        f"### 3. Garbage frames (bounds: every garbage row flagged or absent; ≤ {GARBAGE_COST_MAX:g}× the "
        f"gap-free error {RECOVERY_S * 1e3:.0f} ms after a burst)",
        "",
        f"Bursts 1.5 s apart from 1 s; after each, the error over the {RECOVERY_WINDOW_S * 1e3:.0f} ms "
        f"starting {RECOVERY_S * 1e3:.0f} ms after its last frame against the gap-free run's on the same "
        "frames; recovery = the shortest wait after the burst for which that holds. Random frames: "
        "uniform within ±0.5 m of the markers' median; one marker 10 cm off: MC5, USP, MC2 in turn; "
        "two labels swapped for 0.5 s: MC2↔MC5, then RSP↔USP.",
        "",
        "| trial | garbage | burst frames | garbage rows written unflagged | cost 100 ms after "
        "| recovery, ms |",
        "|---|---|---|---|---|---|",
    ]
    for r in results:
        for kind, bursts in r["probes"]["garbage"].items():
            for b in bursts:
                lines.append(
                    f"| {r['rec'].name} | {kind} | {b['frames']} | {b['unflagged']} | {b['cost']:.2f}× | "
                    f"{b['recovery_ms']:.0f} |"
                )
    lines += [
        "",
        "### 4. Uncalibrated, `ikid track` refuses",
        "",
        "| trial | exit status | message |",
        "|---|---|---|",
    ]
    for r in results:
        u = r["probes"]["uncalibrated"]
        msg = u.message.splitlines()[-1] if u.message else ""
        lines.append(f"| {r['rec'].name} | {u.returncode} | {msg.replace(str(REPO) + '/', '')} |")
    lines += [
        "",
        "### 5. The racing left arm (`ForearmL1-3`, `GloveL1-3`, `LateralEpicondyleL`; no reference angles)",
        "",
        "Calibrated by `ikid calibrate --method mirror --from <the right arm's calibration above>` "
        '(`side = "left"`, the lateral epicondyle in the map\'s `[landmarks]`; docs/markersets.md): the '
        "right forearm's anatomical frame in its plate, taken to the left plate, checked by the plates' "
        "shape and by where the left epicondyle lies against where the right arm's frame puts it (which "
        "also tells how the equilateral plates' markers pair); the hand at the 10 frames nearest one another "
        "near the left arm's median posture (the rule the reference chose the right arm's by). The map names "
        "the plate's markers in label order first and, when the calibration says they pair the other way, as "
        "it says. Tracked by `ikid track` and `ikid ik`. Bounds: no divergence, no 360° jumps, angles "
        f"within the coordinates' ranges ± {RANGE_MARGIN_DEG:g}° on ≥ {100 * IN_RANGE_MIN:g} % of frames "
        "(a row not written counts as outside); e_f against the right arm's (ik against ik, track "
        "against track).",
        "",
        *[
            f"- calibration with {forearm} (frames {frames}): {msg.splitlines()[-1] if msg else ''}"
            for forearm, frames, msg in left["attempts"]
        ],
    ]
    if left["run"] is None:
        return lines + ["- **refused**: nothing is tracked and nothing written.", ""]
    return lines + [
        *[
            f"- `{path}`: written rows {100 * left['written_by'][path]:.1f} % of frames; within range "
            f"± {RANGE_MARGIN_DEG:g}°: {100 * left['in_range_by'][path]:.1f} %; e_f left vs right (Pearson): "
            f"**{left['ef_by'][path]:.2f}**"
            for path in ("ik", "track")
        ],
        f"- largest step between consecutive `track` outputs: {left['jumps'][0]:.1f}° per angle, "
        f"{left['jumps'][1]:.1f}° geodesic; diverged: {'yes' if left['diverged'] else 'no'}",
        "",
        "![racing left arm](realdata/racing_left.png)",
        "",
    ]


def count_diverged(results: list[dict], left: dict) -> int:
    """Trials and probes whose track output is non-finite or > DIVERGED_DEG off the reference
    anywhere (the left arm, without a reference: non-finite or failed)."""
    n = sum(diverged(r["track"]) for r in results)
    n += sum(len(r["probes"]["diverged"]) for r in results)
    return n + int(left["diverged"])


def probe_summary(results: list[dict], left: dict) -> list[str]:
    """One line per requirement, as printed and as the report's summary."""
    lines = []
    for r in results:
        pr, name = r["probes"], r["rec"].name
        gaps = ", ".join(f"{m} {g['cost']:.2f}x" for m, g in pr["gaps"].items())
        worst = max(g["cost"] for g in pr["gaps"].values())
        lines.append(
            f"{name}: 200 ms gaps, cost vs gap-free (<= {GAP_COST_MAX:g}x): {gaps}; worst {worst:.2f}x"
        )
        step = max(j[0] for j in pr["jumps"].values())
        turn = max(j[1] for j in pr["jumps"].values())
        lines.append(
            f"{name}: largest step between consecutive outputs over {len(pr['jumps'])} runs: "
            f"{step:.1f}° per angle (<= {JUMP_MAX_DEG:g}), {turn:.1f}° geodesic"
        )
        g = [b for bursts in pr["garbage"].values() for b in bursts]
        lines.append(
            f"{name}: garbage bursts: {sum(b['unflagged'] for b in g)} garbage frames written unflagged; "
            f"worst cost {RECOVERY_S * 1e3:.0f} ms after a burst {max(b['cost'] for b in g):.2f}x "
            f"(<= {GARBAGE_COST_MAX:g}x); slowest recovery {max(b['recovery_ms'] for b in g):.0f} ms"
        )
        u = pr["uncalibrated"]
        lines.append(
            f"{name}: track uncalibrated: exit {u.returncode}"
            f"{', says to calibrate' if 'calibrate' in u.message else ', NO calibrate message'}"
        )
    if left["run"] is None:
        why = left["calibrate_out"].splitlines()[-1]
        lines.append(f"racing left arm: calibration refused, nothing written: {why}")
        return lines
    forearm = ", ".join(f"{m}={left['markers'][m]}" for m in ("RSP", "USP", "FAP"))
    lines.append(
        f"racing left arm: calibrated (mirror, {forearm}); "
        f"in range ±{RANGE_MARGIN_DEG:g}° ik {100 * left['in_range_by']['ik']:.1f} % / track "
        f"{100 * left['in_range_by']['track']:.1f} % of frames; largest step {left['jumps'][0]:.1f}°; e_f "
        f"correlation with the right arm ik {left['ef_by']['ik']:.2f} / track {left['ef_by']['track']:.2f} "
        f"({left['ef_frames']} frames); diverged {int(left['diverged'])}"
    )
    return lines


def fallback(r: dict) -> str:
    """`ik`'s per-frame fallback rows (beyond training, the window's filling aside) of its rows."""
    beyond, rows = r.get("ik_per_frame", (0, 0))
    return f"{beyond}/{rows} ({100 * beyond / rows:.1f} %)" if rows else "-"


def write_report(
    results: list[dict],
    left: dict,
    log: list[str],
    path: Path,
    seconds: float,
    plug_in_gait: dict,
    styloids: dict,
    clusters: dict,
    one_hand: dict,
) -> None:
    lines = [
        "# ikid on real recordings",
        "",
        "Written by `make realdata` (`tools/realdata.py`); do not edit by hand. The recordings and their",
        "independent reference angles are in `../shared/realdata/` (read its README; never copied here).",
        "Everything below goes through the documented CLI: a marker map, `ikid calibrate` from the",
        "recording itself (epicondyle and styloid landmarks + the neutral frames the reference names),",
        "`ikid ik`, `ikid track`. Error = geodesic angle between ikid's and the reference's",
        "hand-in-forearm rotation (the reference's s_p is pronation-positive, ikid's supination-positive;",
        "same axes and Y-Z-X order otherwise). The reference's own spread (Kabsch vs Gram-Schmidt",
        "clusters): pyomeca 1.96°, racing 0.35°.",
        "",
        "| trial | frames scored | ik RMS (valid) | ik RMS (gimbal_ok) | ik p95 / max | ik outputs | "
        "ik per-frame fallback (window filling aside) | "
        "ik uncalibrated RMS | track RMS (valid) | track RMS (gimbal_ok) | track max | track outputs | "
        "lag ik / track (ms) | calibration check | how |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in results:
        ref, ik, raw, tr = r["ref"], r["ik"], r["ik_raw"], r["track"]
        n = f"{int(ref['valid'].sum())} valid, {int(ref['gimbal_ok'].sum())} gimbal_ok"
        lines.append(
            f"| {r['rec'].name} | {n} | {fmt(ik.rms_valid if ik else np.nan)} | "
            f"{fmt(ik.rms_gimbal if ik else np.nan)} | "
            f"{fmt(ik.p95_gimbal if ik else np.nan)} / {fmt(ik.max_valid if ik else np.nan)} | "
            f"{100 * ik.coverage if ik else 0:.1f} % | {fallback(r)} | "
            f"{fmt(raw.rms_valid) if raw else 'refused'} | "
            f"{fmt(tr.rms_valid if tr else np.nan)} | {fmt(tr.rms_gimbal if tr else np.nan)} | "
            f"{fmt(tr.max_valid if tr else np.nan)} | {100 * tr.coverage if tr else 0:.1f} % | "
            f"{ik.lag_ms if ik else np.nan:.0f} / {tr.lag_ms if tr else np.nan:.0f} | "
            f"{fmt(r['geometry'].rms_valid if r['geometry'] else np.nan)} | "
            f"ik {r['ik_how']}; track {r['track_how']} |"
        )
    lines += ["", "Per-angle RMS on gimbal_ok frames (ikid's signs), degrees:", ""]
    lines += ["| trial | path | s_p | e_f | ad_ab |", "|---|---|---|---|---|"]
    for r in results:
        for key in ("geometry", "ik", "track"):
            s = r[key]
            if s is not None:
                a = s.per_angle_gimbal
                lines.append(f"| {r['rec'].name} | {key} | {fmt(a[0])} | {fmt(a[1])} | {fmt(a[2])} |")
    lines += [""]
    for r in results:
        lines += [f"![{r['rec'].name}](realdata/{r['rec'].name}.png)", ""]
    lines += probe_report(results, left)
    lines += [
        "## Plug-in Gait: one hand marker, against Vicon's wrist angles",
        "",
        "`pycgm_movement.c3d`, both arms, as ikid's one-hand-marker set (`docs/markersets.md`): `WRA`/`WRB` "
        "as RSP/USP and the styloid landmarks, `ELB` as FAP and the elbow landmark, `FIN` as HND; calibrated "
        "from `pycgm_static.c3d`. ikid writes e_f and ad_ab and not s_p (the hand's roll is not observed); "
        "Vicon's angles converted as the data's README says, each trial's mean removed (the two models place "
        "their axes differently). `pig_ik`/`pig_track` on the last line: the worst of these. `stream`: "
        "`ikid stream --tracker` reading the trial live from a fake Qualisys QTM server on the loopback "
        "(QTM's protocol, float32 mm, the C3D's +Z up as QTM's AxisUpwards); rows: its `ok` lines (the "
        "filter's first ones are flagged `restarted`).",
        "",
        "| arm | path | e_f RMS, ° | ad_ab RMS, ° | r e_f / ad_ab | rows | columns not written |",
        "|---|---|---|---|---|---|---|",
    ]
    for side, arm in plug_in_gait["arms"].items():
        for key in ("ik", "track", "stream"):
            sc = arm[key]
            if sc is None:
                lines.append(f"| {side} | {key} | failed | | | | |")
                continue
            lines.append(
                f"| {side} | {key} | {sc['rms'][0]:.2f} | {sc['rms'][1]:.2f} | {sc['r'][0]:.3f} / "
                f"{sc['r'][1]:.3f} | {sc['rows']}/{sc['frames']} | {', '.join(sc['not_determined'])} |"
            )
    lines += [
        "",
        f"- {styloid_line(styloids)}",
        f"- {cluster_line(clusters)}",
        f"- {one_hand_line(one_hand)}",
        "",
    ]
    lines += [
        "## Notes",
        "",
        "- Calibration: `ikid calibrate --static <file> --frames <the reference's neutral frames> "
        "--map <map>` "
        "with the map's `[landmarks]` (method `landmarks`): the forearm's ISB frame from the epicondyles and "
        "styloids averaged in the forearm cluster's frame over those frames, the hand's frame equal to the "
        "forearm's there. Racing takes its landmarks from `kinematics_racing_full.c3d` (virtual points from "
        "probing) and is scored on `kinematics_racing_propulsion.c3d`; its angles are relative to the median "
        "propulsion posture, as the reference's are.",
        "- Calibration check: not a CLI path but a check of the calibration file itself: the frames with "
        "all six markers moved by it to the body model's placement and read by the core's per-frame "
        "geometry (the `angles` feature set: no network, no filter). It equals the reference's own spread "
        "(its Kabsch vs Gram-Schmidt clusters; ikid's technical frame is Gram-Schmidt-like), so what "
        "`ik` and `track` add beyond it is theirs, not the calibration's.",
        "- `ik` runs the IK family (`ikid.pipeline.pick_model`): the member at the recording's rate "
        "(pyomeca: `wrist-ik-100hz`), else the 1 kHz member on the recording resampled, outputs at the "
        "recording's own frames (racing, 70 Hz); they are compared at the reference's frame times.",
        "- `track`: calibrated when `ikid track` has `--calibration`, else uncalibrated (the body model's "
        "placement), as the table says; the shipped refiner only where its rate allows. `track outputs`: "
        "the valid frames with a row; `track` writes none for an estimate flagged implausible (a torque or "
        "speed no wrist gives; its summary counts them, in the commands below).",
        f"- diverged (last line): trials and probes whose track output is non-finite or more than "
        f"{DIVERGED_DEG:.0f}° off the reference on some valid frame (garbage frames included), and the "
        "left arm if non-finite.",
        f"- {seconds:.0f} s on this machine.",
        "",
        "## Commands and their output",
        "",
        "```",
        *[entry.replace(str(REPO) + "/", "") for entry in log],
        "```",
        "",
    ]
    path.write_text("\n".join(lines))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default=os.environ.get("IKID_REALDATA", str(DEFAULT_DATA)))
    ap.add_argument("--doc", default=str(REPO / "docs" / "realdata.md"), help="report to write ('' for none)")
    ap.add_argument("--keep", metavar="DIR", help="keep the maps, calibrations and outputs in DIR")
    args = ap.parse_args(argv)
    folder = Path(args.data)
    if not (folder / "reference").is_dir():
        print(f"realdata: no recordings at {folder} (set IKID_REALDATA)", file=sys.stderr)
        return 2
    check_conventions()
    t0 = time.perf_counter()
    log: list[str] = []
    with tempfile.TemporaryDirectory(prefix="ikid-realdata-") as tmp:
        work = Path(args.keep) if args.keep else Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        results = [process(rec, folder, work, log) for rec in RECORDINGS]
        for r in results:
            r["probes"] = probes(r, folder, work, log)
        left = left_arm(folder, work, next(r for r in results if r["rec"].name == "racing"), log)
        plug_in_gait = pig(folder, work, log)
        styloids = pyomeca_styloids(folder, work, log)
        clusters = pyomeca_clusters(folder, work, log)
        one_hand = racing_one_hand(folder, work, log)
        log = [entry.replace(str(work), "$WORK").replace(str(folder), "$REALDATA") for entry in log]
        for r in results:
            u = r["probes"]["uncalibrated"]
            u.message = u.message.replace(str(work), "$WORK").replace(str(folder), "$REALDATA")
        for st in [*styloids.values(), *clusters.values()]:
            st["calibrate_out"] = (
                st["calibrate_out"].replace(str(work), "$WORK").replace(str(folder), "$REALDATA")
            )
        left["attempts"] = [
            (h, f, m.replace(str(work), "$WORK").replace(str(folder), "$REALDATA"))
            for h, f, m in left["attempts"]
        ]
    for r in results:
        ik, tr = r["ik"], r["track"]
        print(
            f"{r['rec'].name}: calibrate {'ok' if r['calibrated'] else 'FAILED'}; "
            f"ik {fmt(headline(r, 'ik'))}° (valid {fmt(ik.rms_valid if ik else np.nan)}, max "
            f"{fmt(ik.max_valid if ik else np.nan)}, per-frame fallback {fallback(r)}, {r['ik_how']}); "
            f"track {fmt(headline(r, 'track'))}° "
            f"(valid {fmt(tr.rms_valid if tr else np.nan)}; {r['track_how']})"
        )
    for line in probe_summary(results, left):
        print(line)
    for line in pig_summary(plug_in_gait):
        print(line)
    print(styloid_line(styloids))
    print(cluster_line(clusters))
    print(one_hand_line(one_hand))
    if args.doc:
        doc = Path(args.doc)
        for r in results:
            plot(r, doc.parent / "realdata" / f"{r['rec'].name}.png")
        if left["run"] is not None:
            plot_left(
                left,
                next(r for r in results if r["rec"].name == "racing"),
                doc.parent / "realdata" / "racing_left.png",
            )
        write_report(
            results, left, log, doc, time.perf_counter() - t0, plug_in_gait, styloids, clusters, one_hand
        )
    by = {r["rec"].name: r for r in results}
    n_div = count_diverged(results, left)
    last = " ".join(
        f"{name}_{key}={headline(by[name], key):.2f}"
        for name in ("pyomeca", "racing")
        for key in ("ik", "track")
    )
    # The racing left arm: the smaller of ik's and track's share in range and e_f correlation;
    # refused (nothing written) if the mirror calibration is.
    left_last = (
        "left_in_range=refused left_r=refused"
        if left["run"] is None
        else f"left_in_range={100 * left['in_range']:.1f} left_r={left['ef_correlation']:.2f}"
    )
    pig_last = f"pig_ik={plug_in_gait['ik']:.2f} pig_track={plug_in_gait['track']:.2f}"
    print(f"realdata: {last} {left_last} {pig_last} diverged={n_div}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
