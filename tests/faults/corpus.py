"""The fault suite's corpus, generated at test time into a temporary folder (nothing here is
committed): a small simulated trial in every format ikid reads, clean reference outputs of
every command, and the mutated copies the reader probes read.

    ROOT/base/     trial.{npz,trc,mot,sto,c3d,csv}, map.toml, cal.json, the shipped models,
                   the calibration trials, a 4 s trial for the streams (long.npz)
    ROOT/ref/      each command's output on the clean files (what a bad run is compared with)
    ROOT/mut/KIND/ one file per mutation of base's KIND file (name = the mutation)
    ROOT/probes/   one folder per CLI probe (its pre-existing outputs live there)
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import zlib
from functools import cached_property
from pathlib import Path

import numpy as np

from faults.framework import IKID

#: The files the readers are probed with, by kind.
KINDS = {
    "c3d": "trial.c3d",
    "trc": "trial.trc",
    "csv": "trial.csv",
    "mot": "trial.mot",
    "sto": "trial.sto",
    "toml": "map.toml",
    "json": "cal.json",
    "safetensors": "wrist-ik.safetensors",
}
MARKER_KINDS = ("c3d", "trc", "csv")
SHIPPED = ("wrist-ik", "wrist-chain", "wrist-id", "wrist-track")
#: Where a mutation that touches one frame touches it (and a block starts).
FRAME = 600


def _rng(kind: str, salt: str = "") -> np.random.Generator:
    return np.random.default_rng(zlib.crc32(f"{kind}/{salt}".encode()))


def header_end(kind: str, data: bytes) -> int:
    """Offset of the first byte after the file's header (where the values start)."""
    if kind == "trc":
        return _after_lines(data, 6)
    if kind == "csv":
        return _after_lines(data, 2)
    if kind in ("mot", "sto"):
        k = data.find(b"endheader\n") + len(b"endheader\n")
        return data.find(b"\n", k) + 1
    if kind == "c3d":
        return (data[0] - 1) * 512 + 512 * data[512 + 2] if len(data) > 515 else 512
    if kind == "safetensors":
        return 8 + int.from_bytes(data[:8], "little")
    return len(data) // 2


def _after_lines(data: bytes, n: int) -> int:
    k = 0
    for _ in range(n):
        k = data.find(b"\n", k) + 1
    return k


def byte_mutations(kind: str, data: bytes) -> dict[str, bytes]:
    """Truncations, single bit flips, junk bytes and the empty file, by name."""
    n, h = len(data), header_end(kind, data)
    rng = _rng(kind)
    out: dict[str, bytes] = {"empty": b""}
    cuts = {1, 8, 64, 300, h - 1, h, h + 1, n - 1}
    cuts |= {int(n * f) for f in (0.1, 0.25, 0.5, 0.75, 0.9, 0.999)}
    for cut in sorted(c for c in cuts if 0 < c < n):
        out[f"trunc-{cut:07d}"] = data[:cut]
    flips = set(rng.integers(0, h, 8).tolist()) | set(rng.integers(h, n, 8).tolist())
    for k, off in enumerate(sorted(flips)):
        bit = (k * 3) % 8
        b = bytearray(data)
        b[off] ^= 1 << bit
        out[f"flip-{off:07d}-bit{bit}"] = bytes(b)
    junk = rng.integers(0, 256, 64, dtype=np.uint8).tobytes()
    out["junk-prepend"] = junk + data
    out["junk-middle"] = data[: n // 2] + junk + data[n // 2 :]
    out["junk-overwrite"] = data[:h] + junk + data[h + 64 :]
    return out


#: Mutations that are not a file's bytes: each reader must refuse them at once.
SPECIAL = ("special-directory", "special-fifo", "special-devzero", "special-sparse4g")


class Corpus:
    """Paths and clean references of a built corpus (``build`` makes one)."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self.base = root / "base"
        self.ref = root / "ref"
        self.mut = root / "mut"
        self.probes = root / "probes"

    def path(self, kind: str) -> Path:
        return self.base / KINDS[kind]

    def model(self, name: str) -> Path:
        return self.base / f"{name}.safetensors"

    def mutations(self, kind: str) -> list[Path]:
        return sorted((self.mut / kind).iterdir())

    def probe_dir(self, name: str) -> Path:
        d = self.probes / name.replace("/", "__")
        d.mkdir(parents=True, exist_ok=False)
        d.chmod(0o777)  # probes run as nobody write here
        return d

    @cached_property
    def trial(self) -> dict:
        with np.load(self.base / "trial.npz") as z:
            return {k: z[k] for k in z.files}

    @cached_property
    def long(self) -> dict:
        with np.load(self.base / "long.npz") as z:
            return {k: z[k] for k in z.files}

    @cached_property
    def info(self) -> dict:
        return json.loads((self.root / "info.json").read_text())


def _ikid(*args: str, cwd: Path) -> None:
    subprocess.run([*map(str, IKID), *args], cwd=cwd, check=True, capture_output=True, timeout=120)


def _text_rows(kind: str, text: str) -> tuple[list[str], int]:
    """The lines of a text file and the index of its first data row."""
    lines = text.split("\n")
    if kind == "trc":
        return lines, 6
    if kind == "csv":
        return lines, 2
    end = lines.index("endheader")
    return lines, end + 2


def _edit_rows(kind: str, text: str, edit) -> str:
    lines, first = _text_rows(kind, text)
    sep = "," if kind == "csv" else "\t"
    rows = [line.split(sep) for line in lines[first:] if line]
    rows = edit(rows)
    return "\n".join(lines[:first] + [sep.join(r) for r in rows]) + "\n"


def semantic_mutations(kind: str, corpus: Corpus) -> dict[str, bytes]:
    """Files that parse but say something wrong: units, labels, time, values, columns."""
    import ikid
    from ikid.io import MarkerData, write_c3d, write_csv_markers, write_trc

    out: dict[str, bytes] = {}
    tmp = corpus.root / "tmp"
    tmp.mkdir(exist_ok=True)
    text = corpus.path(kind).read_text() if kind not in ("c3d", "safetensors") else ""
    time_col = 0 if kind in ("csv", "mot", "sto") else 1
    if kind in MARKER_KINDS:
        clean = ikid.io.read_trc(corpus.path("trc"))
        names = ikid.marker_names() if hasattr(ikid, "marker_names") else [m[0] for m in ikid.MARKERS]

        def write(name: str, data: MarkerData, units: str = "mm") -> None:
            p = tmp / f"{name}.{kind}"
            if kind == "c3d":
                write_c3d(p, data, units=units)
            elif kind == "trc":
                write_trc(
                    p, data.time, data.positions.reshape(len(data), -1), data.rate_hz, data.labels, units
                )
            else:
                write_csv_markers(
                    p, data.time, data.positions.reshape(len(data), -1), list(data.labels), units
                )
            out[name] = p.read_bytes()

        def variant(positions=None, labels=None, rate=None) -> MarkerData:
            return MarkerData(
                tuple(labels or clean.labels),
                clean.time if rate is None else np.arange(len(clean)) / rate,
                clean.positions if positions is None else positions,
                clean.rate_hz if rate is None else rate,
            )

        write("units-cm-numbers-in-mm", variant(clean.positions * 10), "cm")
        write("units-m-numbers-in-mm", variant(clean.positions * 1000), "m")
        write("units-mm-numbers-in-m", variant(clean.positions / 1000), "mm")
        labels = list(clean.labels)
        i2, i5 = labels.index("MC2"), labels.index("MC5")
        labels[i2], labels[i5] = labels[i5], labels[i2]
        write("swapped-labels-MC2-MC5", variant(labels=labels))
        p = clean.positions.copy()
        p[FRAME:, [i2, i5]] = p[FRAME:, [i5, i2]]
        write("swapped-markers-from-frame-600", variant(p))
        p = clean.positions.copy()
        p[:, i5] = np.nan
        write("marker-missing-throughout", variant(p))
        p = clean.positions.copy()
        p[FRAME, i5] = np.nan
        write("nan-one-marker-one-frame", variant(p))
        p = clean.positions.copy()
        p[FRAME : FRAME + 100, i5] = np.nan
        write("nan-one-marker-100-frames", variant(p))
        p = clean.positions.copy()
        p[FRAME : FRAME + 100] = np.nan
        write("nan-all-markers-100-frames", variant(p))
        p = clean.positions.copy()
        p[FRAME, i5] += 1000.0
        write("one-frame-shifted-1km", variant(p))
        p = clean.positions.copy()
        p[FRAME:] += 0.2
        write("whole-body-jumps-20cm", variant(p))
        labels = list(clean.labels)
        labels[i5] = "R_MCP5"
        write("label-renamed", variant(labels=labels))
        write("rate-500-data-at-1000", variant(rate=500.0))
        del names
    if kind in ("trc", "csv", "mot", "sto"):
        k = FRAME

        def backwards(rows):
            times = [r[time_col] for r in rows[k : k + 100]]
            for r, t in zip(rows[k : k + 100], reversed(times), strict=True):
                r[time_col] = t
            return rows

        def duplicate(rows):
            rows[k + 1][time_col] = rows[k][time_col]
            return rows

        def cell(value: str, col: int):
            def edit(rows):
                rows[k][col] = value
                return rows

            return edit

        value_col = time_col + 1 + (12 if kind in MARKER_KINDS else 1)
        out["time-backwards-100-rows"] = _edit_rows(kind, text, backwards).encode()
        out["time-duplicated"] = _edit_rows(kind, text, duplicate).encode()
        out["value-literal-nan"] = _edit_rows(kind, text, cell("nan", value_col)).encode()
        out["value-literal-inf"] = _edit_rows(kind, text, cell("inf", value_col)).encode()
        out["value-huge-1e300"] = _edit_rows(kind, text, cell("1e300", value_col)).encode()
        out["value-not-a-number"] = _edit_rows(kind, text, cell("12.3.4", value_col)).encode()
        if kind == "trc":
            # The last marker's z gone from every row: MCB is missing throughout.
            out["missing-last-column"] = _edit_rows(kind, text, lambda rows: [r[:-1] for r in rows]).encode()
            # A middle cell gone from every row: every later value shifts one column left.
            out["missing-middle-column"] = _edit_rows(
                kind, text, lambda rows: [r[:4] + r[5:] for r in rows]
            ).encode()
        elif kind == "csv":
            lines = text.split("\n")
            cols = lines[1].split(",")
            keep = [j for j in range(len(cols)) if cols[j] != "MCB.z"]
            out["missing-column"] = (
                "\n".join(
                    lines[:1]
                    + [",".join(line.split(",")[j] for j in keep) if line else "" for line in lines[1:]]
                )
            ).encode()
            out["missing-middle-column"] = _edit_rows(
                kind, text, lambda rows: [r[:4] + r[5:] for r in rows]
            ).encode()
        else:
            out["missing-column"] = _edit_rows(kind, text, lambda rows: [r[:-1] for r in rows]).encode()
            lines = text.split("\n")
            end = lines.index("endheader")
            lines[end + 1] = "\t".join(lines[end + 1].split("\t")[:-1])
            out["missing-column-header-and-rows"] = _edit_rows(
                kind, "\n".join(lines), lambda rows: [r[:-1] for r in rows]
            ).encode()
        if kind == "mot":
            out["degrees-marked-radians"] = text.replace("inDegrees=yes", "inDegrees=no").encode()
            out["s_p-times-1e8"] = _edit_rows(
                kind, text, lambda rows: [[r[0], f"{float(r[1]) * 1e8:.10g}", *r[2:]] for r in rows]
            ).encode()
        if kind in ("trc", "mot", "sto"):
            key = "NumFrames" if kind == "trc" else "nRows"
            if kind == "trc":
                lines = text.split("\n")
                vals = lines[2].split("\t")
                vals[2] = str(int(vals[2]) + 5)
                lines[2] = "\t".join(vals)
                out[f"{key}-lies"] = "\n".join(lines).encode()
            else:
                n = int(text.split("nRows=")[1].split("\n")[0])
                out[f"{key}-lies"] = text.replace(f"nRows={n}", f"nRows={n + 5}").encode()
    if kind == "toml":
        out["label-twice"] = text.replace('MC5 = "MC5"', 'MC5 = "MC2"').encode()
        out["unknown-marker"] = (text + 'XYZ = "abc"\n').encode()
        out["marker-absent"] = "\n".join(
            line for line in text.split("\n") if not line.startswith("MCB")
        ).encode()
        out["label-not-a-string"] = text.replace('MC5 = "MC5"', "MC5 = 5").encode()
        out["no-markers-table"] = text.replace("[markers]", "[marker]").encode()
    if kind == "json":
        doc = json.loads(text)

        def variant_doc(change) -> bytes:
            d = json.loads(json.dumps(doc))
            change(d)
            return json.dumps(d).encode()

        out["not-a-rotation"] = variant_doc(lambda d: d["forearm"][0].__setitem__(0, 2.0))
        out["reflection"] = variant_doc(lambda d: d.__setitem__("hand", [[1, 0, 0], [0, 1, 0], [0, 0, -1]]))
        out["nan-in-matrix"] = text.replace(str(doc["hand"][1][1]), "NaN", 1).encode()
        out["wrong-shape"] = variant_doc(lambda d: d.__setitem__("hand", [[1, 0], [0, 1]]))
        out["no-hand"] = variant_doc(lambda d: d.pop("hand"))
        out["format-version-99"] = variant_doc(lambda d: d.__setitem__("format_version", 99))
        out["matrix-is-string"] = variant_doc(lambda d: d.__setitem__("forearm", "eye(3)"))
        out["top-level-list"] = b"[1, 2, 3]"
    return out


def build(root: Path) -> Corpus:
    """The whole corpus under ``root`` (a fresh temporary folder)."""
    import ikid
    from ikid.io import read_trc, write_c3d, write_csv_markers

    c = Corpus(root)
    root.mkdir(parents=True, exist_ok=True)
    root.chmod(0o755)
    for d in (c.base, c.ref, c.mut, c.probes):
        d.mkdir(parents=True)
        d.chmod(0o755)
    _ikid("simulate", "--seed", "3", "--duration", "1", "-o", "trial", cwd=c.base)
    data = read_trc(c.base / "trial.trc")
    write_c3d(c.base / "trial.c3d", data)
    write_csv_markers(c.base / "trial.csv", data.time, data.positions.reshape(len(data), -1), units="mm")
    (c.base / "map.toml").write_text(ikid.io.MarkerMap.identity().to_toml())
    cz, sz = np.cos(np.radians(10)), np.sin(np.radians(10))
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    ikid.save_calibration(ikid.Calibration.from_matrices(rz, rz), c.base / "cal.json")
    for name in SHIPPED:
        ikid.load(name).save(c.model(name))
    # Calibration trials: a neutral static trial and two single-coordinate movements.
    n = 2000
    ikid.io.write_trc(
        c.base / "static.trc", np.arange(1500) / 1000, ikid.forward_markers(np.zeros((1500, 3)), 0.0)
    )
    for j, coord in enumerate(("s_p", "e_f")):
        q = np.zeros((n, 3))
        q[:, j] = 0.6 * np.sin(np.linspace(0, 2 * np.pi, n))
        ikid.io.write_trc(c.base / f"move_{coord}.trc", np.arange(n) / 1000, ikid.forward_markers(q, 0.0))
    long = ikid.simulate("random", seed=3, duration=4.0)
    np.savez(c.base / "long.npz", markers=long.markers, time=long.time, q=long.q)
    for f in c.base.iterdir():
        f.chmod(0o644)

    # Clean references.
    base = c.base
    _ikid("ik", str(base / "trial.trc"), "-o", str(c.ref / "ik.mot"), cwd=c.ref)
    _ikid("run", str(base / "trial.trc"), "-o", str(c.ref / "run"), cwd=c.ref)
    _ikid("track", str(base / "trial.trc"), "-o", str(c.ref / "track"), cwd=c.ref)
    _ikid("id", str(base / "trial.mot"), "-o", str(c.ref / "id.sto"), cwd=c.ref)
    _ikid(
        "calibrate",
        "--static",
        str(base / "static.trc"),
        "--movement",
        f"ra_wr_s_p={base / 'move_s_p.trc'}",
        "--movement",
        f"ra_wr_e_f={base / 'move_e_f.trc'}",
        "-o",
        str(c.ref / "cal.json"),
        cwd=c.ref,
    )
    np.savetxt(c.ref / "long_frames.csv", long.markers, fmt="%.9g", delimiter=",")
    lines = (c.ref / "long_frames.csv").read_bytes()
    run = subprocess.run(
        [*map(str, IKID), "stream", "--rate", "1000"],
        input=lines,
        capture_output=True,
        cwd=c.ref,
        timeout=120,
        check=True,
    )
    (c.ref / "stream.csv").write_bytes(run.stdout)
    sizes = {f.name: f.stat().st_size for f in c.ref.iterdir()}
    (root / "info.json").write_text(json.dumps({"sizes": sizes}))

    # Mutated files, by kind.
    for kind, name in KINDS.items():
        d = c.mut / kind
        d.mkdir()
        ext = Path(name).suffix
        original = (c.base / name).read_bytes()
        for mname, content in {**byte_mutations(kind, original), **semantic_mutations(kind, c)}.items():
            (d / f"{mname}{ext}").write_bytes(content)
        (d / f"special-directory{ext}").mkdir()
        os.mkfifo(d / f"special-fifo{ext}")
        os.symlink("/dev/zero", d / f"special-devzero{ext}")
        with open(d / f"special-sparse4g{ext}", "wb") as f:
            f.truncate(4 << 30)
    shutil.rmtree(root / "tmp", ignore_errors=True)
    return c
