"""CLI probes: every ``ikid`` command with bad option values (0, negative, NaN, inf, huge),
missing and corrupted inputs, output to a read-only folder, ``-o existing_folder/``, a full
disk (a file size limit, with a good output already in place), corrupted model weights, and
the stream's stdin and UDP faults; plus a night's batch with broken trials among good ones.

On exit 0 an output is compared with the clean run's (angles within 5°, torques within a
quarter of their range, on rows not flagged by a status column); a failed run must name the
file or option and leave every file it found as it was."""

from __future__ import annotations

import math
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from faults.corpus import MARKER_KINDS, Corpus
from faults.framework import IKID, PYTHON, Cli, Run, Verdict

BAD_VALUES = ("0", "-1", "nan", "inf", "1e308")
BAD_NONNEG = ("nan", "inf", "1e308")
ANGLE_TOL_DEG = 5.0
STANDARD = {
    "ra_wr_s_p",
    "ra_wr_e_f",
    "ra_wr_ad_ab",
    "ra_wr_s_p_moment",
    "ra_wr_e_f_moment",
    "ra_wr_ad_ab_moment",
}


# --- output checks -------------------------------------------------------------------------------


def compare_storage(v: Verdict, got: Path, ref: Path, time_scale: float = 1.0, not_excusing: int = 0) -> None:
    """``got`` (a .mot or .sto written by a run that succeeded) against the clean run's; its
    row at time ``t`` is the clean run's at ``t * time_scale`` (a file whose header states
    another rate than its data's: its times are the header's). A row flagged only with bits
    in ``not_excusing`` (e.g. ``filled`` where nothing was missing) must be right all the same."""
    from ikid.io import read_storage

    if not got.exists():
        v.silent(f"exit 0 but {got.name} was not written")
        return
    a, b = read_storage(got), read_storage(ref)
    names = [c for c in b.columns if c in STANDARD]
    missing = [c for c in names if c not in a.columns]
    if missing:
        v.silent(f"{got.name} lacks columns {missing}")
        return
    flags = [c for c in a.columns if c not in STANDARD]
    flagged = np.zeros(len(a.time), bool)
    for c in flags:
        flagged |= (a.column(c).astype(np.int64) & ~not_excusing) != 0
    ref_rows = {int(round(t * 1e6)): k for k, t in enumerate(b.time)}
    x, y = a.select(names), b.select(names)
    if a.in_degrees != b.in_degrees:
        v.silent(f"{got.name}: inDegrees differs from the clean output's")
        return
    if got.suffix == ".mot":
        tol = np.full(len(names), ANGLE_TOL_DEG if a.in_degrees else math.radians(ANGLE_TOL_DEG))
    else:
        tol = 0.25 * (np.ptp(y, axis=0) + 1e-3)
    count, worst, at = 0, 0.0, 0.0
    for i, t in enumerate(a.time):
        k = ref_rows.get(int(round(t * time_scale * 1e6)))
        if k is None or flagged[i]:
            continue
        excess = np.abs(x[i] - y[k]) / tol
        if not np.all(excess <= 1):
            count += 1
            if float(np.max(excess)) > worst:
                worst, at = float(np.max(excess)), t
    if count:
        v.silent(
            f"exit 0 but {got.name} has {count} unflagged rows off the clean run's "
            f"(worst {worst:.3g}× the tolerance, t={at:.3f} s)"
        )


def readable_outputs(paths: list[Path]) -> callable:
    def check(r: Run, v: Verdict) -> None:
        import ikid

        for p in paths:
            if not p.exists():
                v.silent(f"exit 0 but {p.name} was not written")
                continue
            if p.suffix in (".mot", ".sto"):
                t = ikid.io.read_storage(p)
                if not (np.isfinite(t.values).all() and len(t.time)):
                    v.silent(f"{p.name}: empty or non-finite")
            elif p.suffix == ".trc":
                d = ikid.io.read_trc(p)
                d.frames()

    return check


def compare(pairs: list[tuple[Path, Path]], time_scale: float = 1.0):
    def check(r: Run, v: Verdict) -> None:
        for got, ref in pairs:
            compare_storage(v, got, ref, time_scale)

    return check


def nothing_beside(folder: Path):
    """``-o folder/``: nothing may appear next to the folder (``folder.mot``)."""

    def check(r: Run, v: Verdict) -> None:
        beside = sorted(p.name for p in folder.parent.iterdir() if p.name.startswith(folder.name + "."))
        if beside:
            v.silent(f"-o {folder.name}/ wrote {', '.join(beside)} beside the folder")
        if r.returncode == 0 and not any(folder.iterdir()):
            v.silent(f"exit 0 but nothing written in {folder.name}/")

    return check


# --- probe builders ------------------------------------------------------------------------------


class Builder:
    def __init__(self, corpus: Corpus) -> None:
        self.c = corpus
        self.out: list[Cli] = []

    def dir(self, name: str) -> Path:
        return self.c.probe_dir(name)

    def add(self, name: str, argv: list, d: Path, **kw) -> None:
        self.out.append(Cli(name=f"cli/{name}", argv=[str(a) for a in argv], cwd=d, **kw))

    def seed(self, d: Path, files: dict[str, Path]) -> None:
        """Pre-existing good outputs in the probe's folder."""
        for name, src in files.items():
            shutil.copyfile(src, d / name)
            (d / name).chmod(0o644)


def trial_inputs(c: Corpus, kind: str) -> list[Path]:
    """The mutated marker files a processing command is run on."""
    keep = []
    for p in c.mutations(kind):
        m = p.stem
        if m.startswith(("flip-", "trunc-")):
            continue
        if m.startswith("junk-") and m != "junk-middle":
            continue
        keep.append(p)
    byte_picks = [p for p in c.mutations(kind) if p.stem.startswith(("trunc-", "flip-"))]
    keep += byte_picks[len(byte_picks) // 2 :: max(1, len(byte_picks) // 4)][:3]
    return keep


def must_fail(mutation: str) -> bool:
    return mutation.startswith(("special-", "empty", "marker-missing", "label-renamed", "missing-column"))


def processing(b: Builder) -> None:
    c = b.c
    ref = c.ref
    for kind in MARKER_KINDS:
        for src in trial_inputs(c, kind):
            m = src.stem
            expect = "error" if must_fail(m) else "either"
            names = [str(src)]
            d = b.dir(f"ik-{kind}-{m}")
            b.seed(d, {"out.mot": ref / "ik.mot"})
            # A header stating half the data's rate: every command runs at the rate it is told,
            # which no marker can contradict. Angles must still be right (at the file's times);
            # velocities, so torques, follow the stated rate, a documented limit
            # (docs/RELIABILITY.md), so no .sto is compared for it.
            wrong_rate = m == "rate-500-data-at-1000"
            b.add(
                f"ik/{kind}/{m}",
                ["ik", src, "-o", d / "out.mot"],
                d,
                expect=expect,
                names=names,
                check=compare([(d / "out.mot", ref / "ik.mot")], time_scale=0.5 if wrong_rate else 1.0),
            )
            if m.startswith(("special-", "flip-", "trunc-", "junk-")):
                continue
            d = b.dir(f"track-{kind}-{m}")
            b.seed(d, {"out.mot": ref / "track.mot", "out.sto": ref / "track.sto"})
            b.add(
                f"track/{kind}/{m}",
                ["track", src, "-o", d / "out"],
                d,
                expect=expect,
                names=names,
                check=(
                    compare([(d / "out.mot", ref / "track.mot")], time_scale=0.5)
                    if wrong_rate
                    else compare([(d / "out.mot", ref / "track.mot"), (d / "out.sto", ref / "track.sto")])
                ),
            )
            if kind != "trc":
                continue
            d = b.dir(f"run-{kind}-{m}")
            b.seed(d, {"out.mot": ref / "run.mot", "out.sto": ref / "run.sto"})
            b.add(
                f"run/{kind}/{m}",
                ["run", src, "-o", d / "out"],
                d,
                expect=expect,
                names=names,
                check=(
                    compare([(d / "out.mot", ref / "run.mot")], time_scale=0.5)
                    if wrong_rate
                    else compare([(d / "out.mot", ref / "run.mot"), (d / "out.sto", ref / "run.sto")])
                ),
            )
    for src in c.mutations("mot"):
        m = src.stem
        if m.startswith(("flip-", "trunc-")) and m not in ("trunc-0029311",):
            continue
        d = b.dir(f"id-{m}")
        b.seed(d, {"out.sto": ref / "id.sto"})
        expect = (
            "error"
            if must_fail(m) or m.startswith(("time-", "value-literal", "value-not-a-number", "nRows"))
            else "either"
        )
        b.add(
            f"id/mot/{m}",
            ["id", src, "-o", d / "out.sto"],
            d,
            expect=expect,
            names=[str(src)],
            check=compare([(d / "out.sto", ref / "id.sto")]),
        )


def options(b: Builder) -> None:
    c, ref, base = b.c, b.c.ref, b.c.base
    trc = base / "trial.trc"

    def sim(opt: str, value: str, expect: str = "error") -> None:
        d = b.dir(f"simulate{opt}={value}")
        b.seed(d, {f"t{s}": base / f"trial{s}" for s in (".npz", ".trc", ".mot", ".sto")})
        b.add(
            f"simulate/{opt}={value}",
            ["simulate", "--seed", "3", "--duration", "1", opt, value, "-o", d / "t"],
            d,
            expect=expect,
            names=[opt, opt.lstrip("-"), opt.lstrip("-").replace("-", " ")],
            check=readable_outputs([d / "t.trc", d / "t.mot", d / "t.sto"]),
            timeout=20.0,
        )

    for opt in ("--duration", "--length-scale", "--mass-scale", "--rate"):
        for value in BAD_VALUES:
            sim(opt, value)
    for value in BAD_NONNEG:
        sim("--shoulder-deg", value)
    sim("--seed", "-1", "either")
    sim("--seed", "1e308")
    for spec in ("uniform:-1", "uniform:nan", "gaussian:inf", "bogus:1", "uniform", "occlusion:1e308"):
        sim("--noise", spec)

    for opt, values in (
        ("--random-trials", ("-1",)),
        ("--duration", BAD_VALUES),
        ("--jobs", ("0", "-1")),
    ):
        for value in values:
            d = b.dir(f"dataset{opt}={value}")
            b.add(
                f"dataset/{opt}={value}",
                ["dataset", "-o", d / "data", "--random-trials", "1", "--duration", "1", opt, value],
                d,
                expect="error",
                names=[opt, opt.lstrip("-"), opt.lstrip("-").replace("-", " ")],
                timeout=25.0,
            )

    lab = c.probes / "shared-lab"
    lab.mkdir()
    shutil.copyfile(base / "trial.trc", lab / "a.trc")
    shutil.copyfile(base / "trial.trc", lab / "b.trc")
    shutil.copyfile(base / "trial.mot", lab / "a.mot")
    shutil.copyfile(base / "trial.mot", lab / "b.mot")
    for cmd in ("ik", "run"):
        for value in ("0", "-1"):
            d = b.dir(f"{cmd}-jobs={value}")
            b.add(
                f"{cmd}/--jobs={value}",
                [cmd, lab, "-o", d / "out", "--jobs", value],
                d,
                expect="error",
                names=["--jobs", "jobs"],
            )
        for flag, value, needle in (
            ("--model", "no-such-model", "no-such-model"),
            ("--model", c.mut / "safetensors" / "special-fifo.safetensors", "special-fifo"),
            ("--model", c.mut / "safetensors" / "junk-middle.safetensors", "junk-middle"),
            ("--map", c.root / "no-such.toml", "no-such.toml"),
            ("--map", c.mut / "toml" / "junk-middle.toml", "junk-middle.toml"),
            ("--map", c.mut / "toml" / "special-fifo.toml", "special-fifo.toml"),
            ("--calibration", c.root / "no-such.json", "no-such.json"),
            ("--calibration", c.mut / "json" / "not-a-rotation.json", "not-a-rotation.json"),
            ("--missing-markers", "bogus", "--missing-markers"),
        ):
            d = b.dir(f"{cmd}{flag}={Path(str(value)).name}")
            b.seed(d, {"out.mot": ref / f"{cmd}.mot"})
            b.add(
                f"{cmd}/{flag}={Path(str(value)).name}",
                [cmd, trc, "-o", d / "out.mot", flag, value],
                d,
                expect="error",
                names=[needle],
            )
    # Marker maps with a [cluster] or a one-marker hand on a forearm cluster: refused, naming
    # what is wrong, nothing written.
    six = '[markers]\nRSP="RSP"\nUSP="USP"\nFAP="FAP"\n'
    for name, text, needle in (
        ("cluster-absent", six + 'MC2="MC2"\nMC5="MC5"\nMCB="MCB"\n[cluster]\nforearm=["NOPE"]\n', "NOPE"),
        ("cluster-reused", six + 'MC2="MC2"\nMC5="MC5"\nMCB="MCB"\n[cluster]\nhand=["RSP"]\n', "RSP"),
        ("cluster-on-hnd", six + 'HND="MC2"\n[cluster]\nhand=["MC5"]\n', "[cluster]"),
        (
            "hnd-forearm-cluster",
            six
            + 'HND="MC2"\n[landmarks]\nlateral_epicondyle="MC5"\nmedial_epicondyle="MC5"\n'
            + 'radial_styloid="MCB"\nulnar_styloid="MC5"\n',
            "--calibration",
        ),
    ):
        d = b.dir(f"ik-map-{name}")
        (d / f"{name}.toml").write_text(text)
        b.seed(d, {"out.mot": ref / "ik.mot"})
        b.add(
            f"ik/--map={name}",
            ["ik", trc, "-o", d / "out.mot", "--map", d / f"{name}.toml"],
            d,
            expect="error",
            names=[needle],
        )
    # Case 3: the task is not checked; a file named like a shipped model shadows it.
    d = b.dir("ik-model-wrist-chain")
    b.seed(d, {"out.mot": ref / "ik.mot"})
    b.add(
        "ik/--model=wrist-chain",
        ["ik", trc, "-o", d / "out.mot", "--model", "wrist-chain"],
        d,
        expect="error",
        names=["wrist-chain"],
    )
    d = b.dir("run-torque-model-wrist-ik")
    b.seed(d, {"out.mot": ref / "run.mot", "out.sto": ref / "run.sto"})
    b.add(
        "run/--torque-model=wrist-ik",
        ["run", trc, "-o", d / "out", "--torque-model", "wrist-ik"],
        d,
        expect="error",
        names=["wrist-ik"],
    )
    d = b.dir("ik-folder-named-wrist-ik")
    (d / "wrist-ik").mkdir()
    b.add(
        "ik/a-folder-named-wrist-ik-in-cwd",
        ["ik", trc, "-o", d / "out.mot"],
        d,
        names=["wrist-ik"],
        check=compare([(d / "out.mot", ref / "ik.mot")]),
        new_files_ok=True,
    )
    d = b.dir("ik-file-named-wrist-ik")
    shutil.copyfile(c.model("wrist-chain"), d / "wrist-ik")
    b.add(
        "ik/a-file-named-wrist-ik-in-cwd",
        ["ik", trc, "-o", d / "out.mot"],
        d,
        names=["wrist-ik"],
        check=compare([(d / "out.mot", ref / "ik.mot")]),
        new_files_ok=True,
    )

    for opt in ("--length-scale", "--mass-scale", "--jerk-noise"):
        for value in BAD_VALUES:
            d = b.dir(f"track{opt}={value}")
            b.seed(d, {"out.mot": ref / "track.mot", "out.sto": ref / "track.sto"})
            b.add(
                f"track/{opt}={value}",
                ["track", trc, "-o", d / "out", opt, value],
                d,
                expect="error",
                names=[opt, opt.lstrip("-").replace("-", "_"), opt.lstrip("-").replace("-", " ")],
            )
    for value, needle in (
        ("no-such-model", "no-such-model"),
        ("wrist-ik", "wrist-ik"),
        (c.mut / "safetensors" / "empty.safetensors", "empty.safetensors"),
    ):
        d = b.dir(f"track-refiner={Path(str(value)).name}")
        b.seed(d, {"out.mot": ref / "track.mot", "out.sto": ref / "track.sto"})
        b.add(
            f"track/--refiner={Path(str(value)).name}",
            ["track", trc, "-o", d / "out", "--refiner", value],
            d,
            expect="error",
            names=[needle],
        )

    mot = base / "trial.mot"
    for opt in ("--length-scale", "--mass-scale"):
        for value in BAD_VALUES:
            d = b.dir(f"id-reference{opt}={value}")
            b.seed(d, {"out.sto": ref / "id.sto"})
            b.add(
                f"id/--reference{opt}={value}",
                ["id", mot, "-o", d / "out.sto", "--reference", opt, value],
                d,
                expect="error",
                names=[opt, opt.lstrip("-").replace("-", "_"), opt.lstrip("-").replace("-", " ")],
            )
    for value in BAD_NONNEG:
        d = b.dir(f"id-reference-shoulder={value}")
        b.seed(d, {"out.sto": ref / "id.sto"})
        b.add(
            f"id/--reference--shoulder-deg={value}",
            ["id", mot, "-o", d / "out.sto", "--reference", "--shoulder-deg", value],
            d,
            expect="error",
            names=["--shoulder-deg", "shoulder"],
        )
    for model in ("wrist-ik", "wrist-chain", "wrist-track", "no-such-model"):
        d = b.dir(f"id-model={model}")
        b.seed(d, {"out.sto": ref / "id.sto"})
        b.add(
            f"id/--model={model}",
            ["id", mot, "-o", d / "out.sto", "--model", model],
            d,
            expect="error",
            names=[model],
        )

    for value in BAD_VALUES:
        d = b.dir(f"bench-frames={value}")
        b.add(
            f"bench/--frames={value}",
            ["bench", "--frames", value],
            d,
            expect="error",
            names=["--frames", "frames"],
        )
    for value in ("10000000000", "1000000000000"):
        d = b.dir(f"bench-frames={value}")
        b.add(
            f"bench/--frames={value}",
            ["bench", "--frames", value],
            d,
            expect="error",
            names=["--frames", "frames"],
            timeout=25.0,
        )
    for value, needle in (
        ("no-such-model", "no-such-model"),
        (c.mut / "safetensors" / "special-devzero.safetensors", "special-devzero"),
    ):
        d = b.dir(f"bench-model={Path(str(value)).name}")
        b.add(
            f"bench/--model={Path(str(value)).name}",
            ["bench", "--model", value, "--frames", "2000"],
            d,
            expect="error",
            names=[needle],
        )

    for opt, value in (
        ("--window", "0"),
        ("--window", "-1"),
        ("--hidden", "0"),
        ("--hidden", "-5"),
        ("--hidden", "abc"),
        ("--minutes", "-1"),
        ("--minutes", "nan"),
        ("--rate", "0"),
        ("--rate", "-1"),
        ("--rate", "nan"),
    ):
        d = b.dir(f"train{opt}={value}")
        b.add(
            f"train/{opt}={value}",
            ["train", "--data", lab, "--task", "ik", "--no-onnx", "-o", d / "m.safetensors", opt, value],
            d,
            expect="error",
            names=[opt, opt.lstrip("-")],
            timeout=40.0,
        )
    for flag, value in (("--data", c.root / "no-such-folder"), ("--config", c.root / "no-such.toml")):
        d = b.dir(f"train{flag}-missing")
        b.add(
            f"train/{flag}=missing",
            ["train", flag, value, "-o", d / "m.safetensors"],
            d,
            expect="error",
            names=[Path(value).name],
            timeout=40.0,
        )
    d = b.dir("report-data-missing")
    b.add(
        "report/--data=missing",
        ["report", "--data", c.root / "no-such-folder"],
        d,
        expect="error",
        names=["no-such-folder"],
        timeout=40.0,
    )
    broken_lab = c.probes / "shared-broken-lab"
    broken_lab.mkdir()
    shutil.copyfile(c.mut / "trc" / "junk-middle.trc", broken_lab / "a.trc")
    shutil.copyfile(base / "trial.mot", broken_lab / "a.mot")
    d = b.dir("report-data-broken")
    b.add(
        "report/--data=broken-trial",
        ["report", "--data", broken_lab, "--clean-only"],
        d,
        expect="error",
        names=["a.trc"],
        timeout=40.0,
    )

    for opt in ("--seconds", "--noise"):
        for value in BAD_VALUES if opt == "--seconds" else ("-1", "nan", "inf"):
            d = b.dir(f"demo{opt}={value}")
            b.add(
                f"demo/{opt}={value}",
                ["demo", opt, value, "--plot", d / "demo.png"],
                d,
                expect="error",
                names=[opt, opt.lstrip("-")],
                timeout=25.0,
            )

    for spec, needle in (
        ("bogus=" + str(base / "move_e_f.trc"), "bogus"),
        ("ra_wr_e_f", "ra_wr_e_f"),
        ("ra_wr_e_f=" + str(c.root / "no-such.trc"), "no-such.trc"),
        ("ra_wr_e_f=" + str(c.mut / "trc" / "junk-middle.trc"), "junk-middle.trc"),
        ("ra_wr_e_f=" + str(c.mut / "trc" / "special-fifo.trc"), "special-fifo.trc"),
        ("ra_wr_e_f=" + str(base / "static.trc"), "ra_wr_e_f"),
    ):
        d = b.dir(f"calibrate-movement-{Path(spec).name}")
        b.seed(d, {"cal.json": ref / "cal.json"})
        b.add(
            f"calibrate/--movement={Path(spec).name}",
            [
                "calibrate",
                "--static",
                base / "static.trc",
                "--movement",
                spec,
                "--movement",
                f"ra_wr_s_p={base / 'move_s_p.trc'}",
                "-o",
                d / "cal.json",
            ],
            d,
            expect="error",
            names=[needle],
        )
    for static in (
        c.root / "no-such.trc",
        c.mut / "trc" / "special-directory.trc",
        c.mut / "trc" / "units-cm-numbers-in-mm.trc",
    ):
        d = b.dir(f"calibrate-static-{static.name}")
        b.seed(d, {"cal.json": ref / "cal.json"})
        b.add(
            f"calibrate/--static={static.name}",
            [
                "calibrate",
                "--static",
                static,
                "--movement",
                f"ra_wr_e_f={base / 'move_e_f.trc'}",
                "--movement",
                f"ra_wr_s_p={base / 'move_s_p.trc'}",
                "-o",
                d / "cal.json",
            ],
            d,
            expect="error",
            names=[static.name],
        )
    for src in (
        c.root / "no-such.c3d",
        c.mut / "c3d" / "special-directory.c3d",
        c.mut / "c3d" / "special-fifo.c3d",
        c.mut / "c3d" / "special-devzero.c3d",
        c.mut / "c3d" / "empty.c3d",
        next(p for p in c.mutations("c3d") if p.stem.startswith("trunc-") and int(p.stem[6:]) > 10000),
        c.mut / "trc" / "empty.trc",
    ):
        d = b.dir(f"map-template-{src.parent.name}-{src.name}")
        b.add(
            f"map-template/{src.parent.name}-{src.name}",
            ["map-template", src],
            d,
            expect="error",
            names=[src.name],
        )


def outputs(b: Builder) -> None:
    """Read-only folders, ``-o existing_folder/`` and a full disk, for every writing command."""
    c, ref, base = b.c, b.c.ref, b.c.base
    trc, mot = base / "trial.trc", base / "trial.mot"
    sizes = c.info["sizes"]
    cal_args = [
        "--static",
        base / "static.trc",
        "--movement",
        f"ra_wr_e_f={base / 'move_e_f.trc'}",
        "--movement",
        f"ra_wr_s_p={base / 'move_s_p.trc'}",
    ]
    commands = {
        # name: (argv before -o, the -o target in the folder, the outputs it writes: their clean copies)
        "simulate": (
            ["simulate", "--seed", "3", "--duration", "1"],
            "t",
            {f"t{s}": base / f"trial{s}" for s in (".npz", ".trc", ".mot", ".sto")},
        ),
        "ik": (["ik", trc], "out.mot", {"out.mot": ref / "ik.mot"}),
        "run": (["run", trc], "out", {"out.mot": ref / "run.mot", "out.sto": ref / "run.sto"}),
        "track": (["track", trc], "out", {"out.mot": ref / "track.mot", "out.sto": ref / "track.sto"}),
        "id": (["id", mot], "out.sto", {"out.sto": ref / "id.sto"}),
        "calibrate": (["calibrate", *cal_args], "cal.json", {"cal.json": ref / "cal.json"}),
    }
    for name, (argv, target, seeded) in commands.items():
        # A read-only folder (as an unprivileged user when running as root).
        d = b.dir(f"{name}-read-only")
        ro = d / "ro"
        ro.mkdir()
        b.seed(ro, seeded)
        ro.chmod(0o555)
        b.add(
            f"{name}/output-to-read-only-folder",
            [*argv, "-o", ro / target],
            d,
            expect="error",
            names=[str(ro)],
            as_nobody=True,
        )
        # -o existing_folder/
        d = b.dir(f"{name}-existing-folder")
        (d / "existing").mkdir()
        (d / "existing").chmod(0o777)
        b.add(
            f"{name}/-o-existing-folder-slash",
            [*argv, "-o", str(d / "existing") + "/"],
            d,
            names=["existing"],
            check_any=nothing_beside(d / "existing"),
            new_files_ok=True,
        )
        # A full disk: the file size limit below the outputs' sizes, good outputs in place.
        limits = {
            "simulate": [16 << 10, 250 << 10],
            "calibrate": [500],
            "ik": [sizes["ik.mot"] // 3],
            "id": [sizes["id.sto"] // 3],
        }
        if name in ("run", "track"):
            small, large = sorted((sizes[f"{name}.mot"], sizes[f"{name}.sto"]))
            limits[name] = [small // 3, (small + large) // 2]
        for limit in limits[name]:
            d = b.dir(f"{name}-full-disk-{limit}")
            b.seed(d, seeded)
            b.add(
                f"{name}/full-disk-at-{limit}-bytes",
                [*argv, "-o", d / target],
                d,
                expect="error",
                names=[str(d)],
                fsize=limit,
            )

    # Writers through the API under a full disk (issue case 5: write_c3d), each over a good file.
    snippets = {
        "write_c3d": ("trial.c3d", "ikid.io.write_c3d(OUT, ikid.io.read_trc(BASE / 'trial.trc'))"),
        "write_trc": (
            "trial.trc",
            "d = ikid.io.read_trc(BASE / 'trial.trc'); "
            "ikid.io.write_trc(OUT, d.time, d.positions.reshape(len(d), -1))",
        ),
        "write_csv_markers": (
            "trial.csv",
            "d = ikid.io.read_trc(BASE / 'trial.trc'); "
            "ikid.io.write_csv_markers(OUT, d.time, d.positions.reshape(len(d), -1), units='mm')",
        ),
        "write_mot": (
            "trial.mot",
            "t, q = ikid.io.read_mot(BASE / 'trial.mot'); ikid.io.write_mot(OUT, t, q)",
        ),
        "write_sto": (
            "trial.sto",
            "t, x = ikid.io.read_sto(BASE / 'trial.sto'); ikid.io.write_sto(OUT, t, x)",
        ),
        "save_calibration": (
            "cal.json",
            "ikid.save_calibration(ikid.load_calibration(BASE / 'cal.json'), OUT)",
        ),
        "Model.save": ("wrist-ik.safetensors", "ikid.load('wrist-ik').save(OUT)"),
        "Trial.save": (
            "trial.npz",
            "ikid.simulate('random', seed=3, duration=1.0).save(OUT.with_suffix(''))",
        ),
    }
    for name, (file, code) in snippets.items():
        d = b.dir(f"api-{name}-full-disk")
        b.seed(d, {file: base / file})
        out = d / file
        limit = max(200, out.stat().st_size // 3)
        script = (
            "import sys; from pathlib import Path; import ikid, ikid.io\n"
            f"BASE, OUT = Path({str(base)!r}), Path({str(out)!r})\n"
            "try:\n"
            f"    {code}\n"
            "except (ikid.IkidError, OSError) as e:\n"
            "    print(f'error: {e}', file=sys.stderr); sys.exit(2)\n"
        )
        b.add(
            f"api/{name}/full-disk-at-{limit}-bytes",
            [PYTHON, "-c", script],
            d,
            expect="error",
            names=[str(out), out.name],
            fsize=limit,
            raw=True,
        )


def weights(b: Builder) -> None:
    """Issue case 8 from the command line: a model with one flipped sign bit."""
    from faults.live import flip_sign, weight_targets

    c, ref, base = b.c, b.c.ref, b.c.base
    trc = base / "trial.trc"
    bad = {}
    for model in ("wrist-ik", "wrist-chain", "wrist-id", "wrist-track"):
        tensor, element = weight_targets(c.model(model))[0]
        path = c.probes / f"corrupt-{model}.safetensors"
        flip_sign(c.model(model), path, tensor, element)
        bad[model] = path
    cases = {
        "ik": (["ik", trc, "--model", bad["wrist-ik"]], "out.mot", {"out.mot": ref / "ik.mot"}, "wrist-ik"),
        "run": (
            ["run", trc, "--torque-model", bad["wrist-chain"]],
            "out",
            {"out.mot": ref / "run.mot", "out.sto": ref / "run.sto"},
            "wrist-chain",
        ),
        "track": (
            ["track", trc, "--refiner", bad["wrist-track"]],
            "out",
            {"out.mot": ref / "track.mot", "out.sto": ref / "track.sto"},
            "wrist-track",
        ),
        "id": (
            ["id", base / "trial.mot", "--model", bad["wrist-id"]],
            "out.sto",
            {"out.sto": ref / "id.sto"},
            "wrist-id",
        ),
        "bench": (["bench", "--frames", "1000", "--model", bad["wrist-ik"]], None, {}, "wrist-ik"),
        "stream": (
            ["stream", "--rate", "1000", "--model", bad["wrist-ik"], "--count", "10"],
            None,
            {},
            "wrist-ik",
        ),
    }
    for name, (argv, target, seeded, model) in cases.items():
        d = b.dir(f"{name}-corrupt-weights")
        b.seed(d, seeded)
        full = argv + (["-o", d / target] if target else [])
        stdin = (c.ref / "long_frames.csv").read_bytes()[:20000] if name == "stream" else None
        b.add(
            f"{name}/corrupt-weights-{model}", full, d, expect="error", names=[bad[model].name], stdin=stdin
        )


def unchecked(b: Builder) -> None:
    """A model file without a checksum (written before checksums; here with its output scale
    x30, as the issue's case): refused naming the opt-in, and with the opt-in the clean run's
    angles (its weights are the shipped ones) with a warning."""
    import json

    from safetensors.numpy import load_file, save_file

    import ikid

    c, ref = b.c, b.c.ref
    trc = c.base / "trial.trc"
    for scale, tag in ((1.0, ""), (30.0, "-scaled-x30")):
        path = c.probes / f"unchecked{tag}-wrist-ik.safetensors"
        tensors = load_file(str(c.model("wrist-ik")))
        tensors["output.scale"] = tensors["output.scale"] * np.float32(scale)
        card = dict(ikid.load("wrist-ik").card)
        card.pop("tensor_sha256")
        save_file(tensors, str(path), metadata={"ikid": json.dumps(card)})
        for cmd, target, seeded in (
            ("ik", "out.mot", {"out.mot": ref / "ik.mot"}),
            ("run", "out", {"out.mot": ref / "run.mot", "out.sto": ref / "run.sto"}),
        ):
            d = b.dir(f"{cmd}-model-without-checksum{tag}")
            b.seed(d, seeded)
            b.add(
                f"{cmd}/model-without-checksum{tag}",
                [cmd, trc, "--model", path, "-o", d / target],
                d,
                expect="error",
                names=["--allow-unchecked-model"],
            )
    d = b.dir("ik-model-without-checksum-allowed")
    b.add(
        "ik/model-without-checksum-allowed",
        [
            "ik",
            trc,
            "--model",
            c.probes / "unchecked-wrist-ik.safetensors",
            "--allow-unchecked-model",
            "-o",
            d / "out.mot",
        ],
        d,
        check=compare([(d / "out.mot", ref / "ik.mot")]),
        check_any=lambda r, v: (
            None if "ikid: warning:" in r.stderr else v.silent("no warning for an unchecked model")
        ),
    )


# --- stream: stdin and UDP -----------------------------------------------------------------------


def stream_lines(c: Corpus) -> list[str]:
    return (c.ref / "long_frames.csv").read_text().splitlines()


def clean_stream(c: Corpus) -> dict[int, np.ndarray]:
    rows = {}
    for line in (c.ref / "stream.csv").read_text().splitlines()[1:]:
        parts = line.split(",")
        if parts[1] == "ok":
            rows[int(parts[0])] = np.array([float(x) for x in parts[2:5]])
    return rows


def stream_check(c: Corpus, index: list[int | None], end: int | None = None):
    """One output line per input frame, each with a known status; ok rows within 5° of the
    clean run's at the same trial frame; after the fault, under 5 % refused."""
    clean = clean_stream(c)

    def check(r: Run, v: Verdict) -> None:
        lines = [line for line in r.stdout.splitlines() if line.strip()]
        if r.returncode != 0 and not lines:
            return  # refused before the first frame (the error is judged by the runner)
        if not lines or not lines[0].startswith("frame,status"):
            v.silent(f"no header line on stdout (exit {r.returncode})")
            return
        rows = lines[1:]
        if r.returncode == 0 and len(rows) != len(index):
            v.silent(f"{len(index)} frames in, {len(rows)} lines out: frames skipped without a word")
        off, refused_after, after = 0, 0, 0
        for line in rows:
            parts = line.split(",")
            k, status = int(parts[0]), parts[1]
            if not status.startswith(("ok", "filled", "filling", "refused")):
                v.silent(f"line {k}: unknown status {status!r}")
                continue
            trial_frame = index[k] if k < len(index) else None
            if end is not None and trial_frame is not None and trial_frame >= end:
                after += 1
                refused_after += status.startswith("refused")
            if status == "ok" and trial_frame in clean:
                d = np.degrees(np.max(np.abs(np.array([float(x) for x in parts[2:5]]) - clean[trial_frame])))
                if not d <= ANGLE_TOL_DEG:
                    off += 1
        if off:
            v.silent(f"{off} 'ok' lines over {ANGLE_TOL_DEG:g}° from the clean stream's")
        if after and refused_after > 0.05 * after:
            v.silent(f"{refused_after} of {after} frames after the fault refused (over 5 %)")

    return check


def stream(b: Builder) -> None:
    c = b.c
    lines = stream_lines(c)
    n = len(lines)
    k0 = 1500
    t = c.long["time"]

    def add(
        name: str, body: list[str], index: list[int | None], end: int | None = None, args=(), **kw
    ) -> None:
        d = b.dir(f"stream-{name}")
        b.add(
            f"stream/{name}",
            # The corpus is at 1 kHz; a probe of --rate gives its own.
            ["stream", *(() if "--rate" in args else ("--rate", "1000")), *args],
            d,
            stdin=("\n".join(body) + "\n").encode("utf-8", "surrogateescape"),
            check_any=stream_check(c, index, end),
            **kw,
        )

    idx = list(range(n))

    def replaced(k: int, text: str) -> list[str]:
        out = list(lines)
        out[k] = text
        return out

    add("garbage-text-line", replaced(k0, "abc,def"), idx, k0 + 1)
    add("17-values", replaced(k0, ",".join(lines[k0].split(",")[:17])), idx, k0 + 1)
    add("19-values", replaced(k0, lines[k0] + ",1.0"), idx, k0 + 1)
    add("all-nan", replaced(k0, ",".join(["nan"] * 18)), idx, k0 + 1)
    add("inf-value", replaced(k0, ",".join(["inf"] + lines[k0].split(",")[1:])), idx, k0 + 1)
    add("1km-off", replaced(k0, ",".join(str(float(x) + 1000) for x in lines[k0].split(","))), idx, k0 + 1)
    add("huge-1e308", replaced(k0, ",".join(["1e308"] * 18)), idx, k0 + 1)
    add("binary-junk", replaced(k0, "\udcff\udcfe\x00\x01junk"), idx, k0 + 1)
    keep = list(range(k0)) + list(range(k0 + 100, n))
    add("lost-100-frames-unstamped", [lines[k] for k in keep], keep, k0 + 100)
    keep5 = list(range(k0)) + list(range(k0 + 500, n))
    add("lost-500-frames-unstamped", [lines[k] for k in keep5], keep5, k0 + 500)
    burst = list(lines)
    rng = np.random.default_rng(5)
    for k in range(k0, k0 + 50):
        burst[k] = ",".join(f"{x:.6g}" for x in rng.uniform(-2, 2, 18))
    add("burst-50-garbage-frames", burst, idx, k0 + 50)
    stamped = [f"{t[k]:.6f},{lines[k]}" for k in range(n)]
    add("stamped-clean", stamped, idx, None, args=("--time",))
    add("stamped-lost-100-frames", [stamped[k] for k in keep], keep, k0 + 100, args=("--time",))
    back = list(stamped)
    back[k0] = f"{t[k0 - 2]:.6f},{lines[k0]}"
    add("stamped-time-backwards", back, idx, k0 + 1, args=("--time",))
    dup = list(stamped)
    dup[k0] = f"{t[k0 - 1]:.6f},{lines[k0]}"
    add("stamped-time-duplicated", dup, idx, k0 + 1, args=("--time",))
    nant = list(stamped)
    nant[k0] = f"nan,{lines[k0]}"
    add("stamped-time-nan", nant, idx, k0 + 1, args=("--time",))
    short = [lines[k] for k in range(300)]
    add(
        "strict-garbage",
        replaced(100, "abc")[:300],
        list(range(300)),
        None,
        args=("--strict",),
        expect="error",
        names=["frame 100"],
    )
    del short
    for opt, values in (("--rate", BAD_VALUES), ("--count", ("-1",))):
        for value in values:
            add(
                f"{opt}={value}",
                lines[:300],
                list(range(300)),
                None,
                args=(opt, value),
                expect="error",
                names=[opt, opt.lstrip("-")],
            )
    for flag, value in (
        ("--calibration", c.root / "no-such.json"),
        ("--model", "no-such-model"),
        ("--model", c.mut / "safetensors" / "special-fifo.safetensors"),
    ):
        add(
            f"{flag}={Path(str(value)).name}",
            lines[:300],
            list(range(300)),
            None,
            args=(flag, str(value)),
            expect="error",
            names=[Path(str(value)).name],
        )

    # UDP: a burst as fast as the socket takes it, and a dropout.
    for name, frames, idle in (
        ("udp-burst-3000", list(range(3000)), "2"),
        ("udp-dropout", list(range(1000)) + list(range(1200, 2000)), "2"),
    ):
        d = b.dir(f"stream-{name}")

        def interact(proc: subprocess.Popen, frames=frames) -> None:
            port = _read_port(proc)
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
                for k in frames:
                    s.sendto(lines[k].encode(), ("127.0.0.1", port))
                time.sleep(0.2)
                s.sendto(b"END", ("127.0.0.1", port))

        def udp_check(r: Run, v: Verdict, frames=frames) -> None:
            body = [line for line in r.stdout.splitlines()[1:] if line.strip()]
            if len(body) < len(frames):
                lost = len(frames) - len(body)
                said = "lost" in r.stderr or "dropped" in r.stderr
                if not said:
                    v.silent(
                        f"{len(frames)} datagrams sent, {len(body)} lines out, "
                        f"the summary does not say {lost} were lost"
                    )
            stream_check(c, frames, None)(r, v)

        b.out.append(
            Cli(
                name=f"cli/stream/{name}",
                argv=["stream", "--rate", "1000", "--udp", "0", "--idle", idle, "--flush"],
                cwd=d,
                interact=interact,
                check_any=udp_check,
                timeout=30.0,
            )
        )


def _read_port(proc: subprocess.Popen) -> int:
    """The port from ``ikid stream: listening on udp 127.0.0.1:PORT`` (its first stderr line)."""
    buf = b""
    deadline = time.monotonic() + 20
    fd = proc.stderr.fileno()
    import select

    while b"\n" not in buf and time.monotonic() < deadline:
        ready, _, _ = select.select([fd], [], [], 1.0)
        if ready:
            chunk = os.read(fd, 1)
            if not chunk:
                break
            buf += chunk
    line = buf.decode(errors="replace")
    return int(line.strip().rsplit(":", 1)[1])


# --- outputs over inputs (issue #31 item 1) ------------------------------------------------------


def over_inputs(b: Builder) -> None:
    """Every writing command with an output that is one of its inputs: the same name, a
    symbolic link to it, a hard link to it. Each must fail naming that input (the runner checks
    that every file in the probe's folder, the input first, is byte for byte as it was)."""
    c, base = b.c, b.c.base
    inputs = ("trial.trc", "trial.mot", "static.trc", "map.toml", "cal.json")
    commands = {
        # name: (argv, the input it must not replace, the output's name as the command derives it)
        "id": (["id", "trial.mot", "-o", "OUT"], "trial.mot", "out.sto"),
        "calibrate": (
            ["calibrate", "--static", "static.trc", "--method", "neutral", "-o", "OUT"],
            "static.trc",
            "c.json",
        ),
        "calibrate-map": (
            ["calibrate", "--static", "static.trc", "--map", "map.toml", "-o", "OUT"],
            "map.toml",
            "c.json",
        ),
        "ik": (["ik", "trial.trc", "-o", "OUT"], "trial.trc", "out.mot"),
        "ik-calibration": (
            ["ik", "trial.trc", "--calibration", "cal.json", "-o", "OUT"],
            "cal.json",
            "out.mot",
        ),
        "run": (["run", "trial.trc", "-o", "out"], "trial.trc", "out.sto"),
        "track": (["track", "trial.trc", "-o", "out"], "trial.trc", "out.mot"),
        "report": (["report", "--data", "lab", "--clean-only", "-o", "OUT"], "lab/a.mot", "out.md"),
        "train": (
            ["train", "--data", "lab", "--map", "map.toml", "--no-onnx", "-o", "OUT"],
            "map.toml",
            "m.safetensors",
        ),
    }
    same_name = {"id", "calibrate", "calibrate-map"}
    for name, (argv, target, derived) in commands.items():
        for how in ("same", "symlink", "hardlink"):
            if how == "same" and name not in same_name:
                continue
            d = b.dir(f"over-input-{name}-{how}")
            for f in inputs:
                shutil.copyfile(base / f, d / f)
            (d / "lab").mkdir()
            shutil.copyfile(base / "trial.trc", d / "lab" / "a.trc")
            shutil.copyfile(base / "trial.mot", d / "lab" / "a.mot")
            out = target
            if how == "symlink":
                (d / derived).symlink_to(target)
                out = derived
            elif how == "hardlink":
                os.link(d / target, d / derived)
                out = derived
            b.add(
                f"{name}/output-over-input-{how}",
                [out if a == "OUT" else a for a in argv],
                d,
                expect="error",
                names=[f"is the input {target}"],
                new_files_ok=False,
                timeout=40.0,
            )
    # Standard output into the input: `ikid map-template t.trc >> t.trc`, `ikid stream < f >> f`.
    ikid = " ".join(f"'{a}'" for a in map(str, IKID))
    for name, shell in (
        ("map-template", f"{ikid} map-template trial.trc >> trial.trc"),
        ("stream", f"{ikid} stream < trial.csv >> trial.csv"),
    ):
        d = b.dir(f"over-input-{name}-stdout")
        shutil.copyfile(base / "trial.trc", d / "trial.trc")
        shutil.copyfile(c.ref / "long_frames.csv", d / "trial.csv")
        b.add(
            f"{name}/stdout-into-its-input",
            ["sh", "-c", shell],
            d,
            expect="error",
            names=["standard output is the input"],
            new_files_ok=False,
            raw=True,
        )


# --- a night's batch -----------------------------------------------------------------------------


def batch(b: Builder) -> None:
    """`ikid run` over a folder of good trials and broken ones (truncated, wrong units, a
    marker missing throughout, junk bytes, a folder named like a trial): the good ones
    written, each broken one named, a non-zero exit, the broken ones' old outputs untouched."""
    c = b.c
    d = b.dir("run-night-batch")
    src = d / "in"
    src.mkdir()
    good = [f"good{k}" for k in range(4)]
    for g in good:
        shutil.copyfile(c.base / "trial.trc", src / f"{g}.trc")
    broken = {
        "truncated": c.mut / "trc" / "trunc-0137416.trc",
        "units": c.mut / "trc" / "units-cm-numbers-in-mm.trc",
        "missing": c.mut / "trc" / "marker-missing-throughout.trc",
        "junk": c.mut / "trc" / "junk-middle.trc",
    }
    for name, p in broken.items():
        if p.exists():
            shutil.copyfile(p, src / f"{name}.trc")
    (src / "folder.trc").mkdir()
    out = d / "out"
    out.mkdir()
    for name in [*broken, "folder"]:
        shutil.copyfile(c.ref / "run.mot", out / f"{name}.mot")
        shutil.copyfile(c.ref / "run.sto", out / f"{name}.sto")

    def check(r: Run, v: Verdict) -> None:
        for name in broken:
            if f"{name}.trc" not in r.stderr:
                v.silent(f"broken trial {name}.trc not named on stderr")
        for g in good:
            for s in (".mot", ".sto"):
                if not (out / f"{g}{s}").exists():
                    v.silent(f"good trial {g}: {g}{s} not written")
        if r.returncode == 0:
            v.silent("exit 0 although trials were lost")

    b.out.append(
        Cli(
            name="cli/run/night-batch-with-broken-trials",
            argv=["run", str(src), "-o", str(out), "--jobs", "2"],
            cwd=d,
            expect="error",
            names=["truncated.trc"],
            check_any=check,
            new_files_ok=True,
            may_change=[out / f"{g}{s}" for g in good for s in (".mot", ".sto")],
            timeout=60.0,
        )
    )


# --- a batch stopped by a signal, or losing a worker (issue #31 item 2) -----------------------------


def _children(pid: int) -> list[int]:
    """The processes whose parent is ``pid`` (from /proc)."""
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / "stat").read_text()
            except OSError:
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                found.append(int(entry.name))
    return found


def _until(what, timeout: float = 300.0) -> None:
    # Generous: on a loaded 2-core machine (probes in parallel, a build beside) the batch's first
    # file took over 30 s, and the probe failed as "no worker was running".
    deadline = time.monotonic() + timeout
    while not what():
        if time.monotonic() > deadline:
            raise TimeoutError("the batch never got there")
        time.sleep(0.02)


def stopped_batches(b: Builder) -> None:
    """`ikid run DIR -o OUT --jobs 2` over 4 s trials (24; 8 for the lost worker), stopped by
    Ctrl-C (SIGINT to the group) or `kill` (SIGTERM to the parent) after its first file, or with
    one worker killed
    by SIGKILL (the out-of-memory killer). Each must end with a named status (130, 143, 2), no
    traceback, no process of the batch left once it exits, no temporary file (the runner's
    snapshot), and say which files were done, which not, and how to resume; a lost worker
    fails its own file only."""
    import ikid.io

    long = b.c.long
    for case in ("SIGINT", "SIGTERM", "worker-SIGKILL"):
        d = b.dir(f"run-batch-{case}")
        (d / "in").mkdir()
        # Stopped ones get 24 files: on a quiet machine eight were all done before the signal
        # (the harness saw no worker left to stop).
        for k in range(8 if case == "worker-SIGKILL" else 24):
            ikid.io.write_trc(d / "in" / f"t{k}.trc", long["time"], long["markers"], 1000.0)
        out = d / "out"
        seen: dict = {}

        def written(out: Path = out) -> int:
            return sum(not p.name.startswith(".") for p in out.glob("*.sto")) if out.is_dir() else 0

        def interact(proc: subprocess.Popen, case=case, seen=seen, written=written) -> None:
            found: list[int] = []

            def workers_or_end() -> bool:
                # One look at /proc, kept: a second look may fall between two files, when the
                # batch has no worker for a moment (the probe then failed as a harness error).
                found[:] = _children(proc.pid)
                return bool(found) or proc.poll() is not None

            if case == "worker-SIGKILL":
                _until(workers_or_end)
                seen["workers"] = list(found)
                if found:
                    try:
                        os.kill(found[0], signal.SIGKILL)
                    except ProcessLookupError:  # it ended just now: its file is done
                        seen["workers"] = []
            else:
                _until(lambda: written() > 0 or proc.poll() is not None)
                _until(workers_or_end)
                seen["workers"] = list(found)
                if case == "SIGINT":
                    os.killpg(proc.pid, signal.SIGINT)  # a terminal's Ctrl-C: the whole group
                else:
                    proc.send_signal(signal.SIGTERM)  # `kill PID`: the parent alone
            try:
                proc.wait(timeout=120)
            except subprocess.TimeoutExpired:
                return  # the runner reports the hang
            try:
                os.killpg(proc.pid, 0)
                seen["left"] = True
            except ProcessLookupError:
                seen["left"] = False

        def check(r: Run, v: Verdict, case=case, seen=seen, written=written) -> None:
            if not seen.get("workers"):
                v.add("harness", "no worker was running when the signal was to be sent")
            if seen.get("left", True):
                v.traceback("a process of the batch outlived it (orphaned workers)")
            if case == "worker-SIGKILL":
                died = [line for line in r.stderr.splitlines() if "died (killed by SIGKILL" in line]
                if r.returncode != 2 or len(died) != 1:
                    v.silent(
                        f"exit {r.returncode}, {len(died)} files named as lost with their worker (want 2, 1)"
                    )
                if written() != 7:
                    v.silent(f"{written()} of the 7 other files written")
                return
            want = 130 if case == "SIGINT" else 143
            if r.returncode != want:
                v.silent(f"exit {r.returncode} after {case}, expected {want}")
            for needle in ("  done: ", "  not done: ", "  to resume: ikid run "):
                if needle not in r.stderr:
                    v.silent(f"after {case} the summary lacks {needle.strip()!r}")

        b.out.append(
            Cli(
                name=f"cli/run/batch-{case}",
                argv=["run", "in", "-o", "out", "--jobs", "2"],
                cwd=d,
                expect="error",
                names=["died (killed by SIGKILL" if case == "worker-SIGKILL" else f"stopped by {case}"],
                interact=interact,
                check_any=check,
                timeout=600.0,
            )
        )


# --- labels swapped mid-trial, files longer than a block (issue #31 items 3 and 4) -----------------


def swapped_labels(b: Builder) -> None:
    """The clean trial with two labels exchanged for its last quarter (two hand markers, two
    forearm markers, one of each): `ik` and `run` put them right (every row as the clean run's,
    or flagged with more than ``filled``: nothing was missing) and say so; `track` writes no
    row off the clean run's unflagged."""
    import ikid
    from ikid.io import read_trc, write_trc

    c = b.c
    data = read_trc(c.base / "trial.trc")
    frames = data.positions.reshape(len(data), -1)
    # From three quarters on: the median posture (what an uncalibrated run checks the body
    # model's placement against) is the true labels'.
    half = 3 * len(data) // 4
    filled = ikid.FRAME_STATUS["filled"]
    for name, (i, j) in {"MC2-MC5": (3, 4), "RSP-USP": (0, 1), "MC2-RSP": (3, 0)}.items():
        f = frames.copy()
        f[half:, 3 * i : 3 * i + 3], f[half:, 3 * j : 3 * j + 3] = (
            frames[half:, 3 * j : 3 * j + 3],
            frames[half:, 3 * i : 3 * i + 3],
        )
        for cmd, outs in (
            ("ik", ["ik.mot"]),
            ("run", ["run.mot", "run.sto"]),
            ("track", ["track.mot", "track.sto"]),
        ):
            d = b.dir(f"swap-{name}-{cmd}")
            src = d / "swapped.trc"
            write_trc(src, data.time, f, data.rate_hz)
            pairs = [(d / f"out{Path(o).suffix}", c.ref / o) for o in outs]

            def check(r: Run, v: Verdict, pairs=pairs, cmd=cmd) -> None:
                for got, ref in pairs:
                    compare_storage(v, got, ref, not_excusing=filled)
                if cmd != "track" and "swapped labels" not in r.stdout:
                    v.silent("the summary does not say labels were swapped")

            b.add(
                f"swap/{name}/{cmd}",
                [cmd, src, "-o", d / ("out.mot" if cmd == "ik" else "out")],
                d,
                expect="either",
                names=[str(src)],
                check=check,
                timeout=60.0,
            )


#: Frames of the long probe file: more than one block of the TRC reader and of the writers.
LONG_FRAMES = 70_000


def long_files(b: Builder) -> None:
    """A 70 s TRC (several blocks): whole, `ik` writes every row; with a bad cell near its end
    (read after earlier blocks were run and written), a row missing (NumFrames says more) or
    a marker missing throughout, `ik` and `run` fail naming the file and leave the old outputs
    as they were: nothing is written a block at a time where a user would see it."""
    from ikid.io import read_trc, write_trc

    c = b.c
    data = read_trc(c.base / "trial.trc")
    frames = data.positions.reshape(len(data), -1)
    # The trial forward then backward, again and again: continuous at every turn.
    reps = -(-LONG_FRAMES // len(frames))
    tiled = np.concatenate([frames if k % 2 == 0 else frames[::-1] for k in range(reps)])[:LONG_FRAMES]
    time_s = np.arange(LONG_FRAMES) / data.rate_hz
    src_dir = b.dir("long-inputs")
    clean = write_trc(src_dir / "long.trc", time_s, tiled, data.rate_hz)
    lines = clean.read_text().splitlines()
    bad = list(lines)
    cells = bad[65_000].split("\t")
    cells[4] = "1.2.3"
    bad[65_000] = "\t".join(cells)
    (src_dir / "bad-cell-late.trc").write_text("\n".join(bad) + "\n")
    (src_dir / "truncated.trc").write_text("\n".join(lines[:-1000]) + "\n")
    gone = tiled.copy()
    gone[:, 6:9] = np.nan  # FAP never seen: known only once the last block is read
    write_trc(src_dir / "marker-never-seen.trc", time_s, gone, data.rate_hz)
    for p in src_dir.iterdir():
        p.chmod(0o644)

    d = b.dir("long-ik-clean")

    def complete(r: Run, v: Verdict, d=d) -> None:
        from ikid.io import read_storage

        t = read_storage(d / "out.mot")
        if len(t.time) != LONG_FRAMES:
            v.silent(f"exit 0 but out.mot has {len(t.time)} of {LONG_FRAMES} rows")
        if not np.isfinite(t.values).all():
            v.silent("out.mot holds non-finite values")

    b.add(
        "long/ik/clean", ["ik", clean, "-o", d / "out.mot"], d, expect="either", check=complete, timeout=180.0
    )
    for name, needle in (
        ("bad-cell-late", "bad-cell-late.trc:65001"),
        ("truncated", "truncated.trc"),
        ("marker-never-seen", "FAP"),
    ):
        for cmd in ("ik", "run"):
            d = b.dir(f"long-{cmd}-{name}")
            seeded = {"out.mot": c.ref / f"{cmd}.mot"} | (
                {"out.sto": c.ref / "run.sto"} if cmd == "run" else {}
            )
            b.seed(d, seeded)
            b.add(
                f"long/{cmd}/{name}",
                [cmd, src_dir / f"{name}.trc", "-o", d / ("out.mot" if cmd == "ik" else "out")],
                d,
                expect="error",
                names=[needle],
                timeout=180.0,
            )


def long_angles(b: Builder) -> None:
    """A 70 s `.mot` at 1 kHz (two blocks of the storage reader, the low-pass given in pieces):
    whole, `id` writes a torque for every frame past its window; with a bad cell or a time step
    backwards near its end (read after earlier blocks were filtered and written), or rows
    missing (nRows says more), `id` fails naming the file (and the line) and leaves the old
    output as it was."""
    import ikid
    from ikid.io import write_mot

    c = b.c
    time_s = np.arange(LONG_FRAMES) / 1000.0
    w = 2 * np.pi * np.array([0.7, 1.1, 0.4])
    q = np.array([0.4, 0.3, 0.15]) * np.sin(w * time_s[:, None] + np.array([0.0, 1.0, 2.0]))
    src_dir = b.dir("long-angles")
    clean = write_mot(src_dir / "long.mot", time_s, q)
    lines = clean.read_text().splitlines()
    head = lines.index("endheader") + 2  # the first row's index in lines
    bad = list(lines)
    bad[head + 66_000] = bad[head + 66_000].replace("\t", "\t1.2.3", 1)
    (src_dir / "bad-cell-late.mot").write_text("\n".join(bad) + "\n")
    back = list(lines)
    back[head + 67_000] = "66.5" + back[head + 67_000][back[head + 67_000].index("\t") :]
    (src_dir / "time-backwards-late.mot").write_text("\n".join(back) + "\n")
    (src_dir / "truncated.mot").write_text("\n".join(lines[:-1000]) + "\n")
    for p in src_dir.iterdir():
        p.chmod(0o644)

    d = b.dir("long-id-clean")
    rows = LONG_FRAMES - ikid.load("wrist-id").window + 1

    def complete(r: Run, v: Verdict, d=d) -> None:
        from ikid.io import read_storage

        t = read_storage(d / "out.sto")
        if len(t.time) != rows:
            v.silent(f"exit 0 but out.sto has {len(t.time)} of {rows} rows")
        if not np.isfinite(t.values).all():
            v.silent("out.sto holds non-finite values")

    b.add(
        "long/id/clean", ["id", clean, "-o", d / "out.sto"], d, expect="either", check=complete, timeout=180.0
    )
    for name, needle in (
        ("bad-cell-late", f"bad-cell-late.mot:{head + 66_001}"),
        ("time-backwards-late", f"time-backwards-late.mot:{head + 67_001}"),
        ("truncated", "truncated.mot"),
    ):
        d = b.dir(f"long-id-{name}")
        b.seed(d, {"out.sto": c.ref / "id.sto"})
        b.add(
            f"long/id/{name}",
            ["id", src_dir / f"{name}.mot", "-o", d / "out.sto"],
            d,
            expect="error",
            names=[needle],
            timeout=180.0,
        )


def probes(corpus: Corpus) -> list[Cli]:
    b = Builder(corpus)
    for part in (
        processing,
        options,
        outputs,
        weights,
        unchecked,
        stream,
        batch,
        over_inputs,
        stopped_batches,
        swapped_labels,
        long_files,
        long_angles,
    ):
        part(b)
    return b.out


if __name__ == "__main__":  # pragma: no cover - a quick count
    print(len(probes(Corpus(Path(sys.argv[1])))))
