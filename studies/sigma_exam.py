"""The Tracker's σ on the exam's trials, an independent check never tuned on: the share of
scored frames whose true angle (torque) lies within ±1 σ of `ikid track --refiner none`'s
estimate, read from the `_sd` columns it wrote. The exam's subjects are other models
(OpenSim's, with their own joint axes, calibrated from markers), so the errors include what the
body model and the calibration get wrong, which no σ from the markers' noise can see.

    python -m studies.exam --quick --keep DIR   # the trials, the truth (truth.npz) and outputs
    python -m studies.sigma_exam DIR            # prints coverage per layout and artefact
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from ikid.io.storage import coordinate_names, moment_names, read_storage


def coverage(folder: Path) -> dict[str, float] | None:
    """Angles' and torques' coverage on one kept condition's scored frames (None without the
    bare filter's output or the truth)."""
    truth_file, mot, sto = folder / "truth.npz", folder / "track_none.mot", folder / "track_none.sto"
    if not (truth_file.exists() and mot.exists() and sto.exists()):
        return None
    truth = np.load(truth_file)
    start, rate = int(truth["scored_start"]), float(truth["rate_hz"])
    out = {}
    for path, names, true, scale in [
        (mot, coordinate_names(), truth["q"], np.radians),
        (sto, moment_names(), truth["tau"], lambda v: v),
    ]:
        table = read_storage(path)
        rows = np.rint(table.time * rate).astype(int)  # each written row's frame
        on = rows >= start
        est = scale(table.select(names)[on])
        sd = scale(table.select([f"{n}_sd" for n in names])[on])
        want = true[rows[on]] if len(true) > start else true[rows[on] - start]
        kind = "angles" if path.suffix == ".mot" else "torques"
        out[kind] = float(np.mean(np.abs(est - want) <= sd))
        out[f"{kind}_frames"] = float(on.sum())
    return out


def main(root: str) -> None:
    for folder in sorted(p for p in Path(root).glob("*/*") if p.is_dir()):
        c = coverage(folder)
        if c is not None:
            print(
                f"{folder.parent.name}/{folder.name}: angles {c['angles']:.3f}, torques {c['torques']:.3f} "
                f"({int(c['angles_frames'])} scored frames)"
            )


if __name__ == "__main__":
    main(sys.argv[1])
