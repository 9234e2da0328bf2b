"""The source distribution builds where cargo is: `maturin sdist`, then pip builds and installs
it in a fresh venv (no repository on the path) and the installed package runs. Slow tier: pip
compiles ikid's crates from the sdist's sources (~1-2 min; the registry dependencies come from
target/, shared with `make wheel`)."""

from __future__ import annotations

import os
import shutil
import subprocess
import tarfile
import venv

import pytest

import ikid
from conftest import ROOT

pytestmark = pytest.mark.slow


def run(cmd: list, **kw) -> subprocess.CompletedProcess:
    return subprocess.run([str(c) for c in cmd], capture_output=True, text=True, timeout=1500, **kw)


@pytest.mark.timeout(1800)
def test_the_sdist_builds_and_installs_in_a_fresh_venv(tmp_path):
    if shutil.which("cargo") is None:
        pytest.fail("cargo is not installed")
    maturin = ROOT / ".venv" / "bin" / "maturin"
    result = run([maturin, "sdist", "--out", tmp_path / "sdist"], cwd=ROOT)
    assert result.returncode == 0, result.stderr
    (sdist,) = (tmp_path / "sdist").glob("ikid-*.tar.gz")
    with tarfile.open(sdist) as tar:
        names = tar.getnames()
    root = f"ikid-{ikid.__version__}"
    # The workspace the extension needs, the models, and no build output.
    for needed in (
        "Cargo.toml",
        "Cargo.lock",
        "crates/ikid/src/lib.rs",
        "crates/ikid-py/src/lib.rs",
        "pyproject.toml",
    ):
        assert f"{root}/{needed}" in names, needed
    assert f"{root}/python/ikid/models/wrist-ik.safetensors" in names
    assert not any("/target/" in n for n in names)

    env_dir = tmp_path / "venv"
    venv.create(env_dir, with_pip=True)
    py = env_dir / "bin" / "python"
    version = run([maturin, "--version"]).stdout.split()[1]
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    env["CARGO_TARGET_DIR"] = str(ROOT / "target")
    result = run([py, "-m", "pip", "install", "--quiet", f"maturin=={version}"], env=env)
    assert result.returncode == 0, result.stderr
    # The sdist's files keep their mtimes, so cargo would take the repository's own artifacts
    # in target/ as up to date: unpacked and touched, its crates are compiled from its sources
    # (the registry dependencies still come from target/).
    with tarfile.open(sdist) as tar:
        tar.extractall(tmp_path / "unpacked", filter="data")
    source = tmp_path / "unpacked" / root
    for path in source.rglob("*"):
        os.utime(path)
    result = run(
        [py, "-m", "pip", "install", "--quiet", "--no-build-isolation", source], env=env, cwd=tmp_path
    )
    assert result.returncode == 0, result.stderr[-3000:]
    check = (
        "import ikid, numpy as np; m = ikid.load('wrist-ik'); "
        "f = ikid.forward_markers(np.zeros((80, 3)), 0.3); "
        "print(ikid.__file__, ikid.__version__, m.predict(f).shape)"
    )
    result = run([py, "-c", check], env=env, cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    where, version_installed, shape = result.stdout.split(maxsplit=2)
    assert where.startswith(str(env_dir)) and version_installed == ikid.__version__, result.stdout
    assert shape.strip() == f"({80 - ikid.load('wrist-ik').window + 1}, 3)"
