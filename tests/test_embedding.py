"""docs/embedding.md's three programs, built and run as a new user would, from outside the
repository: the Rust host as a new cargo crate with a path dependency, the C host linked
through pkg-config against `make install PREFIX=<tmp>` (shared without LD_LIBRARY_PATH, static,
and under valgrind's default leak check), the Python host in a fresh venv with the wheel.
What each prints is checked against ikid's Python API on the same frames. Slow tier (cargo and
pip builds)."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import venv
from pathlib import Path

import numpy as np
import pytest

import ikid
from conftest import ROOT

pytestmark = pytest.mark.slow

DOC = ROOT / "docs" / "embedding.md"
FILE_BLOCK = re.compile(r"<!-- file: (\S+) -->\n```\w*\n(.*?)```", re.S)


def write_programs(into: Path) -> dict[str, Path]:
    """Every `<!-- file: ... -->` block of the page, written under `into`."""
    written = {}
    for name, text in FILE_BLOCK.findall(DOC.read_text(encoding="utf-8")):
        path = into / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")
        written[name] = path
    assert {"rust/Cargo.toml", "rust/src/main.rs", "c/host.c", "python/host.py"} <= set(written), written
    return written


def run(cmd: list, **kw) -> subprocess.CompletedProcess:
    return subprocess.run([str(c) for c in cmd], capture_output=True, text=True, timeout=900, **kw)


def host_env() -> dict[str, str]:
    """The environment of a host that knows nothing of the repository."""
    env = {k: v for k, v in os.environ.items() if k not in ("LD_LIBRARY_PATH", "PYTHONPATH", "VIRTUAL_ENV")}
    return env


def expected() -> dict[str, object]:
    """What every host prints, from the Python API of the installed wheel (the oracle)."""
    model = ikid.load("wrist-ik")
    t = np.arange(1000) / model.frame_rate_hz
    q = np.stack([0.5 * np.sin(2 * t), -0.3 * np.sin(3 * t), np.full_like(t, 0.1)], axis=1)
    frames = ikid.forward_markers(q, 0.3).astype(np.float32)
    predicted = model.predict(frames)
    tracked = ikid.Tracker(rate_hz=model.frame_rate_hz).run(frames.astype(np.float64))
    stream = model.stream()
    for f in frames:
        stream.push(f)
    return {
        "stream_status": int(stream.status),
        "frames": frames,
        "predicted": len(predicted),
        "last": predicted[-1],
        "tracked": tracked["q"][-1],
        "status": int(tracked["status"][-1]),
    }


def numbers(line_start: str, text: str) -> np.ndarray:
    (line,) = [ln for ln in text.splitlines() if ln.startswith(line_start + " ")]
    return np.array([float(v) for v in line.split()[1:4]])


def check_output(stdout: str, want: dict[str, object]) -> None:
    assert f"predicted {want['predicted']}" in stdout, stdout
    np.testing.assert_allclose(numbers("last", stdout), want["last"], atol=2e-6)
    np.testing.assert_allclose(numbers("tracked", stdout), want["tracked"], atol=2e-6)
    assert re.search(rf"^tracked .* status {want['status']}$", stdout, re.M), stdout
    # The C host reads its last row with the row's status bits (review 5: it printed a flagged
    # row as any other); the other hosts print the angles alone.
    if re.search(r"^last .* status \d+$", stdout, re.M):
        assert re.search(rf"^last .* status {want['stream_status']}$", stdout, re.M), stdout


@pytest.mark.timeout(1200)  # a first build compiles ikid and nalgebra (~2 min on 2 cores)
def test_rust_host_from_a_new_crate(tmp_path):
    if shutil.which("cargo") is None:
        pytest.fail("cargo is not installed")
    files = write_programs(tmp_path)
    manifest = files["rust/Cargo.toml"]
    text = manifest.read_text()
    assert 'path = "../ikid/crates/ikid"' in text
    manifest.write_text(text.replace("../ikid/crates/ikid", str(ROOT / "crates" / "ikid")))
    # Its own target folder (kept between runs under target/, so a rerun only relinks).
    env = {**host_env(), "CARGO_TARGET_DIR": str(ROOT / "target" / "embedding-rust")}
    result = run(["cargo", "run", "--quiet", "--manifest-path", manifest], cwd=tmp_path, env=env)
    assert result.returncode == 0, result.stderr[-3000:]
    check_output(result.stdout, expected())
    assert "error frame has 17 values, expected 18: a marker frame" in result.stdout, result.stdout


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """libikid installed under a temporary prefix by `make install`."""
    prefix = tmp_path_factory.mktemp("prefix")
    result = run(["make", "-s", "-C", ROOT, "install", f"PREFIX={prefix}"])
    assert result.returncode == 0, result.stderr
    return prefix


@pytest.mark.parametrize("link", ["shared", "static"])
def test_c_host_through_pkg_config(tmp_path, installed, link):
    if shutil.which("pkg-config") is None:
        pytest.fail("pkg-config is not installed")
    files = write_programs(tmp_path)
    want = expected()
    np.savetxt(tmp_path / "frames.csv", want["frames"], fmt="%.9g", delimiter=",")
    env = {**host_env(), "PKG_CONFIG_PATH": str(installed / "lib" / "pkgconfig")}
    # The commands docs/embedding.md gives, with its /opt/ikid prefix replaced.
    doc = DOC.read_text(encoding="utf-8")
    commands = [ln for ln in doc.splitlines() if ln.startswith("cc -std=c99")]
    command = commands[0] if link == "shared" else commands[1]
    exe = tmp_path / ("host" if link == "shared" else "host-static")
    result = run(["sh", "-c", command], cwd=files["c/host.c"].parent, env=env)
    assert result.returncode == 0, result.stderr
    built = files["c/host.c"].parent / exe.name
    ldd = run(["ldd", built], env=env).stdout
    assert ("libikid" in ldd) == (link == "shared"), ldd
    model = ROOT / "python" / "ikid" / "models" / "wrist-ik.safetensors"
    result = run([built, model, tmp_path / "frames.csv"], env=env)  # no LD_LIBRARY_PATH
    assert result.returncode == 0, result.stderr
    assert "frames 1000" in result.stdout
    check_output(result.stdout, want)
    if shutil.which("valgrind") is None:
        pytest.skip("valgrind is not installed: the host ran, its memory check did not")
    result = run(
        ["valgrind", "--error-exitcode=1", "--leak-check=full", built, model, tmp_path / "frames.csv"],
        env=env,
    )
    assert result.returncode == 0 and "in use at exit: 0 bytes in 0 blocks" in result.stderr, result.stderr[
        -3000:
    ]
    check_output(result.stdout, want)


@pytest.mark.timeout(600)  # pip fetches or reuses numpy, ezc3d, tqdm
def test_python_host_in_a_fresh_venv(tmp_path):
    wheels = sorted((ROOT / "target" / "wheels").glob("ikid-*.whl"))
    if not wheels:
        pytest.fail("no wheel in target/wheels: run `make wheel`")
    files = write_programs(tmp_path)
    env_dir = tmp_path / "venv"
    venv.create(env_dir, with_pip=True)
    py = env_dir / "bin" / "python"
    result = run([py, "-m", "pip", "install", "--quiet", wheels[-1]], env=host_env())
    assert result.returncode == 0, result.stderr
    # Run from the temporary folder: the repository's python/ is nowhere on the path.
    result = run([py, files["python/host.py"]], cwd=tmp_path, env=host_env())
    assert result.returncode == 0, result.stderr
    check_output(result.stdout, expected())
    assert "error frame has 17 values, expected 18: a marker frame" in result.stdout, result.stdout
    where = run([py, "-c", "import ikid; print(ikid.__file__)"], cwd=tmp_path, env=host_env()).stdout
    assert str(env_dir) in where and str(ROOT) not in where, where
    assert sys.prefix not in where
