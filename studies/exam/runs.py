"""Every method on one exam condition's files, each run as its own users run it.

* ikid, through its CLI: ``ikid calibrate`` from the condition's own static (landmarks probed
  there) and functional trials, then ``ikid track`` (default refiner and ``--refiner none``)
  and ``ikid ik``; the subject's size and hand mass passed as a lab knows them.
* biorbd's EKF (``KalmanReconsMarkers``, biorbd's default tuning, the data's frame rate) and
  biorbd's inverse dynamics on its state, on the ``.bioMod`` of the exam model with the
  layout's nominal marker placement.
* OpenSim's ``InverseKinematicsTool`` on the scored frames (plus 1 s before, for the filter)
  and its inverse dynamics on coordinates low-passed at 6 Hz (OpenSim's ID tool's default
  filter: a zero-lag 4th-order Butterworth), velocities and accelerations by splines.

Each returns estimates on every frame (NaN where a method gave no output) and its wall time.
"""

from __future__ import annotations

import contextlib
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from ikid.io import read_storage
from ikid.io.storage import coordinate_names, moment_names

IKID = [sys.executable, "-m", "ikid"]


def ikid_cmd(args: list[str]) -> tuple[subprocess.CompletedProcess, float]:
    start = time.perf_counter()
    done = subprocess.run(IKID + args, capture_output=True, text=True, encoding="utf-8", errors="replace")
    return done, time.perf_counter() - start


def read_rows(path: Path, names: list[str], n: int, rate: float, degrees_ok: bool = True) -> dict:
    """A MOT/STO's named columns on the trial's frames (NaN where no row) and its status."""
    table = read_storage(path)
    values = table.select(names)
    if table.in_degrees and degrees_ok:
        values = np.radians(values)
    idx = np.rint(table.time * rate).astype(int)
    out = np.full((n, len(names)), np.nan)
    status = np.zeros(n, np.int64)
    ok = (idx >= 0) & (idx < n)
    out[idx[ok]] = values[ok]
    if "ikid_status" in table.columns:
        status[idx[ok]] = table.column("ikid_status")[ok].astype(np.int64)
    return {"values": out, "status": status}


def run_ikid(
    folder: Path,
    n: int,
    rate: float,
    scales: tuple[float, float],
    methods: tuple[str, ...] = ("landmarks",),
    neutral_frames: str = "0-999",
) -> dict:
    """Calibrate with each of ``methods`` (the first one feeds every run), then track, track
    --refiner none and ik with it. ``folder`` holds task.trc, static.trc, functional.trc, map.toml;
    ``neutral_frames``: the static trial's frames the functional method takes as neutral."""
    f = folder
    out: dict = {"calibrations": {}}
    common = ["--map", str(f / "map.toml")]
    for method in methods:
        args = [
            "calibrate",
            "--static",
            str(f / "static.trc"),
            "--method",
            method,
            "-o",
            str(f / f"cal_{method}.json"),
        ]
        if method == "functional":
            args += ["--motion", str(f / "functional.trc"), "--frames", neutral_frames]
        done, secs = ikid_cmd(args + common)
        out["calibrations"][method] = {
            "accepted": done.returncode == 0,
            "message": (done.stderr or done.stdout).strip().splitlines()[-1:] if done.returncode else [],
            "seconds": secs,
        }
    cal = f / f"cal_{methods[0]}.json"
    length_scale, mass_scale = scales
    runs = {
        "track": ["track", "--length-scale", f"{length_scale:.6f}", "--mass-scale", f"{mass_scale:.6f}"],
        "track_none": [
            "track",
            "--refiner",
            "none",
            "--length-scale",
            f"{length_scale:.6f}",
            "--mass-scale",
            f"{mass_scale:.6f}",
        ],
        "ik": ["ik"],
    }
    for key, args in runs.items():
        if not out["calibrations"][methods[0]]["accepted"]:
            out[key] = {"error": "calibration refused"}
            continue
        stem = f / key
        target = str(stem) + (".mot" if key == "ik" else "")
        done, secs = ikid_cmd(
            [args[0], str(f / "task.trc"), "-o", target, "--calibration", str(cal), *args[1:], *common]
        )
        if done.returncode not in (0, 3):
            out[key] = {"error": (done.stderr or done.stdout).strip()[-400:]}
            continue
        res = {"seconds": secs, "summary": done.stdout.strip()[-400:]}
        if not Path(target if key == "ik" else str(stem) + ".mot").exists():  # no frame had an output
            out[key] = {"error": f"no output written: {(done.stdout + done.stderr).strip()[-400:]}"}
            continue
        mot = read_rows(Path(str(stem) + ".mot"), coordinate_names(), n, rate)
        res["q"], res["status"] = mot["values"], mot["status"]
        if key != "ik":
            res["tau"] = read_rows(Path(str(stem) + ".sto"), moment_names(), n, rate)["values"]
        out[key] = res
    # The other calibrations, each with the bare filter: what the method costs.
    for method in methods[1:]:
        if out["calibrations"][method]["accepted"]:
            cal_file = f / f"cal_{method}.json"
            q = track_bare(f, f / "task.trc", cal_file, rate, scales, n)
            if q is not None:
                out["calibrations"][method]["q"] = q
    return out


def run_ekf(biomod: Path, markers: np.ndarray, rate: float, id_from: int = 0) -> dict:
    """biorbd's EKF, frame by frame, and its inverse dynamics on the frames from ``id_from`` (the
    scored ones: the rest would only cost time); NaN markers are occluded. Every coordinate of
    the model, in its order."""
    import biorbd

    model = biorbd.Model(str(biomod))
    kalman = biorbd.KalmanReconsMarkers(model, biorbd.KalmanParam(rate))
    q, qd, qdd = (
        biorbd.GeneralizedCoordinates(model),
        biorbd.GeneralizedVelocity(model),
        biorbd.GeneralizedAcceleration(model),
    )
    n, dof = len(markers), model.nbQ()
    out = {k: np.empty((n, dof)) for k in ("q", "tau")}
    start = time.perf_counter()
    for i in range(n):
        kalman.reconstructFrame(model, markers[i], q, qd, qdd)
        out["q"][i] = q.to_array()
        out["tau"][i] = model.InverseDynamics(q, qd, qdd).to_array() if i >= id_from else np.nan
    out["seconds"] = time.perf_counter() - start
    return out


@contextlib.contextmanager
def _quiet():
    """OpenSim's tools print with C++ std::cout: silence file descriptor 1 while they run."""
    sys.stdout.flush()
    saved = os.dup(1)
    with open(os.devnull, "w") as null:
        os.dup2(null.fileno(), 1)
        try:
            yield
        finally:
            os.dup2(saved, 1)
            os.close(saved)


def write_trc_opensim(
    path: Path, time_s: np.ndarray, markers: np.ndarray, rate: float, labels: list[str]
) -> Path:
    """A TRC written by OpenSim's own ``TRCFileAdapter`` (mm; a missing marker is ``nan``, which
    its IK leaves out). Not ikid's ``write_trc``: OpenSim 4.6 refuses ikid's file when the last
    marker of a row is missing (its empty trailing cells read as a short row)."""
    import opensim as osim

    table = osim.TimeSeriesTableVec3()
    table.setColumnLabels(labels)
    for t, frame in zip(time_s, markers, strict=True):
        row = osim.RowVectorVec3(len(labels))
        for k in range(len(labels)):
            row[k] = osim.Vec3(*(1000.0 * float(v) for v in frame[3 * k : 3 * k + 3]))
        table.appendRow(float(t), row)
    table.addTableMetaDataString("DataRate", f"{rate:g}")
    table.addTableMetaDataString("Units", "mm")
    osim.TRCFileAdapter().write(table, str(path))
    return path


def run_opensim(osim: Path, trc: Path, n: int, rate: float, first: int) -> dict:
    """OpenSim IK on frames ``first``.. of the trial file, then ID on the 6 Hz low-passed result."""
    from scipy.interpolate import CubicSpline
    from scipy.signal import butter, filtfilt

    from ikid.interop.opensim import inverse_dynamics, inverse_kinematics

    with _quiet():
        res = inverse_kinematics(osim, trc, trc.with_suffix(".osim_ik.mot"))
    q = np.full((n, 3), np.nan)
    idx = np.rint(res.time * rate).astype(int)
    q[idx] = res.q
    seg = q[first:]
    ok = np.isfinite(seg).all(axis=1)
    tau = np.full((n, 3), np.nan)
    id_seconds = 0.0
    if ok.all():
        b, a = butter(4, 6.0 / (rate / 2))
        qf = filtfilt(b, a, seg, axis=0)
        t = np.arange(len(qf)) / rate
        spline = CubicSpline(t, qf, axis=0)
        start = time.perf_counter()
        tau[first:] = inverse_dynamics(osim, qf, spline(t, 1), spline(t, 2))
        id_seconds = time.perf_counter() - start
    return {"q": q, "tau": tau, "seconds": res.seconds, "id_seconds": id_seconds, "frames": len(res.q)}


def track_bare(
    folder: Path, task: Path, calibration: Path, rate: float, scales: tuple[float, float], n: int
) -> np.ndarray | None:
    """``ikid track --refiner none`` on ``task`` with ``calibration``: its angles on every frame
    (NaN where none), or None when the command wrote nothing."""
    stem = folder / f"bare_{calibration.stem}_{task.stem}"
    done, _ = ikid_cmd(
        [
            "track",
            str(task),
            "-o",
            str(stem),
            "--calibration",
            str(calibration),
            "--refiner",
            "none",
            "--length-scale",
            f"{scales[0]:.6f}",
            "--mass-scale",
            f"{scales[1]:.6f}",
            "--map",
            str(folder / "map.toml"),
        ]
    )
    mot = Path(str(stem) + ".mot")
    if done.returncode not in (0, 3) or not mot.exists():
        return None
    return read_rows(mot, coordinate_names(), n, rate)["values"]
