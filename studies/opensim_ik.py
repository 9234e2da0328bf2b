"""OpenSim's inverse kinematics beside ikid on the same held-out trials (`make compare-opensim`).

Trials training never saw (random protocol, seeds 9300+, shoulder 0°, 45°, −20°, 1000 Hz,
~10 s each), with the thesis' uniform noise (0, 1 %, 5 % of each marker coordinate's range).
On the very same frames, per noise level:

* OpenSim's ``InverseKinematicsTool`` on the ``.osim`` ikid writes for the trial's subject and
  shoulder pose and the trial's ``.trc``, all markers weighted 1, at its default accuracy
  (1e-5) and at 1e-8 (converged);
* ikid's shipped ``wrist-ik``, as a batch (``Model.predict``) and frame by frame
  (``Stream.push`` from Python);
* ``ikid.reference_ik`` (per-frame least-squares segment fit);
* the closed-form least squares of OpenSim's own problem (forearm known, hand rotating about
  the known wrist centre), to show which problem OpenSim's IK solves.

Scores: angle MSE (rad²) and RMSE per coordinate (deg) on all frames every method answers
(from the network's first full window on) and on the last 10 % of each trial; ms per frame.
Writes the section "OpenSim IK vs ikid" of docs/opensim.md and target/opensim_ik.json, and
prints the table.
"""

from __future__ import annotations

import json
import os
import sys
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np

import ikid
from ikid import io
from ikid.evaluate import EVAL_SEED
from ikid.interop import opensim as ios
from ikid_training import data as D

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from studies.common import machine  # noqa: E402

DOC = ROOT / "docs" / "opensim.md"
JSON_OUT = ROOT / "target" / "opensim_ik.json"
SECTION = "## OpenSim IK vs ikid on the same trials"
NOISE = {"clean": 0.0, "1%": 0.01, "5%": 0.05}
SHOULDERS_DEG = [0.0, 45.0, -20.0]
DURATION = 10.0
CONVERGED_ACCURACY = 1e-8

METHODS = {
    "opensim": "OpenSim IK tool (accuracy 1e-5, default)",
    "opensim_converged": "OpenSim IK tool (accuracy 1e-8)",
    "ikid_predict": "ikid wrist-ik, Model.predict",
    "ikid_stream": "ikid wrist-ik, Stream.push",
    "reference_ik": "ikid.reference_ik",
    "known_forearm_ls": "least squares, forearm known (closed form)",
}


def main() -> None:
    osim = ios.require_opensim()
    osim.Logger.removeFileSink()  # no opensim.log in the working directory
    osim.Logger.setLevelString("warn")
    model = ikid.load("wrist-ik")
    load_before = os.getloadavg()[0]
    specs = D.recording_set(
        "random", seeds=[9300], shoulders_deg=SHOULDERS_DEG, length_scales=[1.0], duration=DURATION
    )
    clean = D.simulate_all(specs)
    results: dict[str, dict] = {}
    with tempfile.TemporaryDirectory(prefix="ikid-opensim-") as tmp:
        work = Path(tmp)
        for label, level in NOISE.items():
            # Same noise seeds as the evaluation report's (never used in training).
            recs = [D.add_noise(r, "uniform", level, EVAL_SEED + i) for i, r in enumerate(clean)]
            results[label] = evaluate(model, recs, work / label.replace("%", "pct"))
            print(f"{label}: done", file=sys.stderr)
    report = {
        "generated": time.strftime("%Y-%m-%d %H:%M"),
        "machine": machine(),
        # Other work on the (shared) machine inflates every time in the table alike.
        "load_average_1min": [load_before, os.getloadavg()[0]],
        "opensim": osim.GetVersionAndDate(),
        "ikid": ikid.__version__,
        "model": {"name": model.name, "window": model.window, "feature_set": model.feature_set},
        "trials": [
            {"name": r.name, "frames": len(r), "shoulder_deg": s["shoulder_deg"], "seed": s["seed"]}
            for r, s in zip(clean, specs, strict=True)
        ],
        "methods": METHODS,
        "results": results,
    }
    JSON_OUT.parent.mkdir(parents=True, exist_ok=True)
    JSON_OUT.write_text(json.dumps(report, indent=1))
    section = render(report)
    print(section)
    write_section(section)


def evaluate(model: ikid.Model, recs: list[D.Recording], work: Path) -> dict:
    """Every method on every trial of one noise level; errors stacked over the trials."""
    work.mkdir(parents=True)
    w = model.window
    errs: dict[str, list] = {k: [] for k in METHODS}
    tails: dict[str, list] = {k: [] for k in METHODS}
    seconds: dict[str, float] = dict.fromkeys(METHODS, 0.0)
    frames = 0
    for rec in recs:
        shoulder, ls, ms, rate = (
            rec.meta[k] for k in ("shoulder_flexion_rad", "length_scale", "mass_scale", "rate_hz")
        )
        n = len(rec)
        trc = io.write_trc(work / f"{rec.name}.trc", np.arange(n) / rate, rec.markers, rate_hz=rate)
        osim_path = ios.write_osim(
            work / f"{rec.name}.osim", length_scale=ls, mass_scale=ms, shoulder_flexion=shoulder
        )
        out: dict[str, np.ndarray] = {}

        for key, acc in (("opensim", None), ("opensim_converged", CONVERGED_ACCURACY)):
            with quiet_stdout():
                res = ios.inverse_kinematics(osim_path, trc, work / f"{rec.name}.{key}.mot", accuracy=acc)
            if len(res.q) != n:
                raise RuntimeError(f"{rec.name}: OpenSim IK gave {len(res.q)} frames for {n}")
            out[key] = res.q
            seconds[key] += res.seconds

        frames32 = np.ascontiguousarray(rec.markers, np.float32)
        start = time.perf_counter()
        pred = model.predict(frames32)
        seconds["ikid_predict"] += time.perf_counter() - start
        out["ikid_predict"] = np.vstack([np.full((w - 1, 3), np.nan), pred.astype(np.float64)])

        stream = model.stream()
        rows = np.full((n, 3), np.nan)
        push = stream.push
        start = time.perf_counter()
        for i, frame in enumerate(frames32):
            y = push(frame)
            if y is not None:
                rows[i] = y
        seconds["ikid_stream"] += time.perf_counter() - start
        out["ikid_stream"] = rows

        start = time.perf_counter()
        out["reference_ik"] = ikid.reference_ik(rec.markers, ls, ms)
        seconds["reference_ik"] += time.perf_counter() - start

        start = time.perf_counter()
        out["known_forearm_ls"] = known_forearm_least_squares(rec.markers, shoulder, ls, ms)
        seconds["known_forearm_ls"] += time.perf_counter() - start

        # Score every method on the frames all of them answer (the network's first full window on).
        answered = np.isfinite(out["ikid_stream"]).all(axis=1) & np.isfinite(out["ikid_predict"]).all(axis=1)
        if not answered[w - 1 :].all():
            print(
                f"{rec.name}: the stream gave no output for {int((~answered[w - 1 :]).sum())} frames",
                file=sys.stderr,
            )
        tail = np.zeros(n, bool)
        tail[int(round(0.9 * n)) :] = True
        for key, q in out.items():
            e = q - rec.q
            errs[key].append(e[answered])
            tails[key].append(e[answered & tail])
        frames += n

    summary: dict = {"frames": frames, "methods": {}}
    for key in METHODS:
        e, et = np.concatenate(errs[key]), np.concatenate(tails[key])
        summary["methods"][key] = {
            "mse": float(np.mean(e**2)),
            "rmse_deg": np.degrees(np.sqrt(np.mean(e**2, axis=0))).tolist(),
            "mse_last10": float(np.mean(et**2)),
            "rmse_deg_last10": np.degrees(np.sqrt(np.mean(et**2, axis=0))).tolist(),
            "ms_per_frame": 1e3 * seconds[key] / frames,
            "scored_frames": len(e),
        }
    # How far apart the two least-squares answers are (rad, worst frame): OpenSim's converged
    # IK against the closed form of the same problem, and against ikid's segment fit.
    conv = {
        k: np.concatenate([x for x in errs[k]])
        for k in ("opensim_converged", "known_forearm_ls", "reference_ik")
    }
    summary["max_abs_diff_rad"] = {
        "opensim_converged_vs_known_forearm_ls": float(
            np.abs(conv["opensim_converged"] - conv["known_forearm_ls"]).max()
        ),
        "opensim_converged_vs_reference_ik": float(
            np.abs(conv["opensim_converged"] - conv["reference_ik"]).max()
        ),
    }
    return summary


@contextmanager
def quiet_stdout():
    """The IK tool prints the model's summary with C++ ``std::cout`` whatever the log level:
    send file descriptor 1 to /dev/null while it runs, so the table stays readable."""
    sys.stdout.flush()
    saved = os.dup(1)
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 1)
        yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)
        os.close(devnull)


def known_forearm_least_squares(
    markers: np.ndarray, shoulder: float, length_scale: float, mass_scale: float
) -> np.ndarray:
    """The problem OpenSim's IK solves on ikid's ``.osim``, in closed form: the forearm is
    welded at its known pose and the hand only rotates about the known wrist centre, so each
    frame is a Procrustes fit of the hand markers without translation, then the wrist angles
    of that rotation (ikid's decomposition, with the axes read from the body model)."""
    body = ikid.body_model(length_scale, mass_scale, shoulder)
    rf = np.array(body["forearm_pose"]["rotation"])
    tf = np.array(body["forearm_pose"]["translation"])
    hand = [i for i, m in enumerate(body["markers"]) if m["segment"] == "hand"]
    offsets = np.array([body["markers"][i]["offset"] for i in hand])  # (k, 3) hand frame
    pos = markers.reshape(len(markers), -1, 3)[:, hand]  # (n, k, 3) lab
    y = (pos - tf) @ rf  # in the forearm frame: rfᵀ (p - t), row-wise
    h = np.einsum("ki,nkj->nij", offsets, y)  # Σ o yᵀ
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(np.transpose(vt, (0, 2, 1)) @ np.transpose(u, (0, 2, 1))))
    fix = np.ones((len(markers), 3))
    fix[:, 2] = d
    r = np.transpose(vt, (0, 2, 1)) @ (fix[:, :, None] * np.transpose(u, (0, 2, 1)))  # hand in forearm
    a1, a2, a3 = (np.array(c["axis"], float) for c in body["coordinates"])
    s = np.sign(np.cross(a1, a2) @ a3)
    ra1, ra2, ra3 = r @ a1, r @ a2, r @ a3
    q2 = np.arcsin(np.clip(s * ra3 @ a1, -1, 1))
    q1 = np.arctan2(-s * ra3 @ a2, ra3 @ a3)
    q3 = np.arctan2(-s * ra2 @ a1, ra1 @ a1)
    return np.column_stack([q1, q2, q3])


def render(report: dict) -> str:
    res = report["results"]
    names = ikid.coordinate_names()
    short = [n.replace("ra_wr_", "") for n in names]
    lines = [
        SECTION,
        "",
        f"Generated by `make compare-opensim` on {report['generated']} — {report['machine']}; "
        f"OpenSim {report['opensim']}, ikid {report['ikid']}. Load average "
        f"{report['load_average_1min'][0]:.1f} before, {report['load_average_1min'][1]:.1f} after (2 cores, "
        "shared: compare times within one run).",
        "",
        "Trials training never saw: random protocol, seeds "
        f"{', '.join(str(t['seed']) for t in report['trials'])} (shoulder "
        f"{', '.join(str(t['shoulder_deg']) + '°' for t in report['trials'])}), default subject, 1000 Hz, "
        f"{sum(t['frames'] for t in report['trials'])} frames in all; uniform noise ± the level of each "
        "marker coordinate's range (the thesis' definition). Every method sees the very same frames. "
        "Scored on the frames every method answers (from the network's first full window of "
        f"{report['model']['window']} frames on) and on the last 10 % of each trial. MSE in rad², "
        f"RMSE per coordinate in degrees ({', '.join(short)}).",
        "",
        "| noise | method | MSE | RMSE ° | MSE last 10 % | RMSE ° last 10 % | ms/frame |",
        "|---|---|---|---|---|---|---|",
    ]
    for label, r in res.items():
        for key, title in report["methods"].items():
            m = r["methods"][key]
            rmse = " / ".join(f"{v:.3f}" for v in m["rmse_deg"])
            rmse_t = " / ".join(f"{v:.3f}" for v in m["rmse_deg_last10"])
            lines.append(
                f"| {label} | {title} | {m['mse']:.2e} | {rmse} | {m['mse_last10']:.2e} | "
                f"{rmse_t} | {m['ms_per_frame']:.4f} |"
            )
    diffs = "; ".join(
        f"{label}: {r['max_abs_diff_rad']['opensim_converged_vs_known_forearm_ls']:.1e} rad vs the closed "
        f"form, {r['max_abs_diff_rad']['opensim_converged_vs_reference_ik']:.1e} rad vs reference_ik"
        for label, r in res.items()
    )
    lines += [
        "",
        "What the times include: *OpenSim IK tool* is the wall time of `InverseKinematicsTool.run()` divided "
        "by the frames: reading the `.trc`, building the system, solving every frame (tracking from the "
        "previous one), writing the `.mot`; loading the `.osim` is left out. *Model.predict* is one call "
        "on the whole trial (the core's batch path, both cores). *Stream.push* is a Python loop pushing one "
        "frame at a time (what a live display does). *reference_ik* is one call on the whole trial (Rust, "
        "one thread); the closed form is NumPy, vectorised over the trial.",
        "",
        f"Largest difference between the least-squares answers, any frame: {diffs}.",
    ]
    return "\n".join(lines) + "\n"


def write_section(section: str) -> None:
    """Replace (or append) the generated section of docs/opensim.md, keeping the rest."""
    text = DOC.read_text() if DOC.exists() else "# OpenSim\n"
    start = text.find(SECTION)
    if start < 0:
        text = text.rstrip("\n") + "\n\n" + section
    else:
        end = text.find("\n## ", start + len(SECTION))
        rest = text[end + 1 :] if end >= 0 else ""
        text = text[:start] + section + ("\n" + rest if rest else "")
    from ikid.io._atomic import write_text_atomic

    write_text_atomic(DOC, text)


if __name__ == "__main__":
    main()
