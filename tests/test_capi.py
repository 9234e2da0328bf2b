"""libikid from C: the C test program (tests/c/test_capi.c) and the example host program,
built by `make c` with plain cc against include/ikid.h, run under valgrind, checked against
the Python API on the same model and frames; and a host build through pkg-config."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

import ikid
from conftest import ROOT, make_model, marker_frames

BIN = ROOT / "target" / "c"
# valgrind as its manual gives it, no other flags: any leak kind (possibly lost and still
# reachable included) is an error a host running it would see.
VALGRIND = ["valgrind", "--error-exitcode=99", "--leak-check=full"]


def built(name: str) -> Path:
    path = BIN / name
    if not path.exists():
        pytest.fail(f"{path} is missing: run `make c` (make test does)")
    return path


@pytest.fixture
def fixtures(tmp_path):
    model = make_model(hidden=(64, 64))
    model_path = tmp_path / "model.safetensors"
    model.save(model_path)
    frames = marker_frames(120, seed=7)
    expected = model.predict(frames)
    np.savetxt(tmp_path / "frames.csv", frames, fmt="%.9g", delimiter=",")
    np.savetxt(tmp_path / "expected.csv", expected, fmt="%.9g", delimiter=",")
    corrupt = tmp_path / "corrupt.safetensors"
    corrupt.write_bytes(model_path.read_bytes()[:100])
    # The same frames through a stream calibrated with 10° about z for both segments (the C
    # test sets the same matrices).
    c, s = np.cos(np.radians(10)), np.sin(np.radians(10))
    rz = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    stream = model.stream(calibration=ikid.Calibration.from_matrices(rz, rz))
    as_read = np.loadtxt(tmp_path / "frames.csv", delimiter=",", dtype=np.float32)
    calibrated = [out for out in (stream.push(f) for f in as_read) if out is not None]
    np.savetxt(tmp_path / "expected_calibrated.csv", np.array(calibrated), fmt="%.9g", delimiter=",")
    return tmp_path, model, frames, expected


def run(cmd: list, **kw) -> subprocess.CompletedProcess:
    return subprocess.run([str(c) for c in cmd], capture_output=True, text=True, timeout=300, **kw)


def in_ci() -> bool:
    return os.environ.get("CI", "").strip().lower() not in ("", "0", "false", "no")


def run_checked(cmd: list, check) -> None:
    """Runs `cmd` and `check(result)` on it natively, then under valgrind (no invalid access,
    no leak) and checks again. Without valgrind: a failure in CI (CI set), elsewhere a skip
    once the native run passed."""
    check(run(cmd))
    if shutil.which("valgrind") is None:
        if in_ci():
            pytest.fail(
                "valgrind is not installed, and CI is set: in CI the C programs must run under "
                "valgrind (apt-get install valgrind)"
            )
        pytest.skip(
            "valgrind is not installed: the program passed natively, but its memory checks did not run "
            "(in CI, with CI set, this is a failure)"
        )
    check(run(VALGRIND + cmd))


HEADER_FUNCTIONS = re.compile(r"^[^/#\s][^;()]*?\b(ikid_\w+)\(", re.MULTILINE)


def test_a_program_calling_every_function_is_clean_under_default_valgrind(tmp_path):
    """tests/c/every_call.c calls every function the header declares (read from the header
    here), ikid_model_predict on enough frames for several threads; `valgrind
    --error-exitcode=1 --leak-check=full` with no other flags exits 0 (nothing lost, nothing
    still reachable: predict's threads are started and joined within the call)."""
    declared = set(HEADER_FUNCTIONS.findall((ROOT / "include" / "ikid.h").read_text()))
    assert {"ikid_model_predict", "ikid_tracker_set_calibration", "ikid_version"} <= declared, declared
    called = set(re.findall(r"\b(ikid_\w+)\(", (ROOT / "tests" / "c" / "every_call.c").read_text()))
    assert declared - called == set(), f"every_call.c does not call {sorted(declared - called)}"
    frames = tmp_path / "frames.csv"
    np.savetxt(frames, marker_frames(2400, seed=3).astype(np.float64), fmt="%.9g", delimiter=",")
    models = ROOT / "python" / "ikid" / "models"
    cmd = [built("every_call"), models / "wrist-ik.safetensors", models / "wrist-track.safetensors", frames]
    n_checks = (ROOT / "tests" / "c" / "every_call.c").read_text().count("CHECK(")

    def check(result):
        assert result.returncode == 0, result.stdout + result.stderr
        passed, failed = map(int, re.findall(r"^(\d+) passed, (\d+) failed$", result.stdout, re.M)[0])
        assert failed == 0 and passed >= n_checks, result.stdout

    check(run(cmd))
    if shutil.which("valgrind") is None:
        if in_ci():
            pytest.fail("valgrind is not installed, and CI is set: apt-get install valgrind")
        pytest.skip("valgrind is not installed: the program passed natively, its memory check did not run")
    result = run(["valgrind", "--error-exitcode=1", "--leak-check=full", *cmd])
    check(result)
    assert "in use at exit: 0 bytes in 0 blocks" in result.stderr, result.stderr[-2000:]


def test_libikid_has_a_soname_and_versioned_names(tmp_path):
    """The library names its ABI (SONAME libikid.so.<major>); `make install` lays out the
    versioned file, its SONAME link and the development link."""
    if shutil.which("readelf") is None:
        pytest.skip("readelf (binutils) is not installed")
    major = ikid.__version__.split(".")[0]
    dynamic = run(["readelf", "-d", ROOT / "target" / "release" / "libikid.so"]).stdout
    assert f"Library soname: [libikid.so.{major}]" in dynamic, dynamic
    prefix = tmp_path / "prefix"
    result = run(["make", "-s", "-C", ROOT, "install", f"PREFIX={prefix}"])
    assert result.returncode == 0, result.stderr
    lib = prefix / "lib"
    real = lib / f"libikid.so.{ikid.__version__}"
    assert real.is_file() and not real.is_symlink()
    assert os.readlink(lib / f"libikid.so.{major}") == real.name
    assert os.readlink(lib / "libikid.so") == f"libikid.so.{major}"
    assert (lib / "libikid.a").is_file() and (prefix / "include" / "ikid.h").is_file()
    # The host records the SONAME, not the development link.
    needed = run(["readelf", "-d", built("every_call")]).stdout
    assert f"Shared library: [libikid.so.{major}]" in needed, needed


def test_c_test_program_passes_under_valgrind(fixtures):
    d = fixtures[0]
    cmd = [
        built("test_capi"),
        d / "model.safetensors",
        d / "frames.csv",
        d / "expected.csv",
        d / "corrupt.safetensors",
        d / "expected_calibrated.csv",
    ]

    def check(result):
        assert result.returncode == 0, result.stdout + result.stderr
        last = result.stdout.strip().splitlines()[-1]
        passed, failed = int(last.split()[0]), int(last.split()[2])
        # Every CHECK in the source ran (none skipped by an early exit); tests/c/check.h defines it.
        n_checks = (ROOT / "tests" / "c" / "test_capi.c").read_text().count("CHECK(")
        assert failed == 0 and passed == n_checks, last

    run_checked(cmd, check)


LATENCY = re.compile(r"^(\d+) frames; ikid_stream_push latency p50 (\S+) us, p99 (\S+) us$", re.MULTILINE)


def test_example_host_program_matches_python(fixtures):
    d, model, frames, expected = fixtures
    cmd = [built("stream_csv"), d / "model.safetensors", d / "frames.csv", "--every", "1"]

    def check(result):
        assert result.returncode == 0, result.stderr
        lines = result.stdout.strip().splitlines()
        assert lines[0] == "frame," + ",".join(model.output_names)
        rows = np.array([[float(v) for v in ln.split(",")] for ln in lines[1:]])
        np.testing.assert_array_equal(rows[:, 0], np.arange(model.window - 1, len(frames)))
        np.testing.assert_allclose(rows[:, 1:], expected, atol=1e-6)  # printed with 6 decimals
        # The latency line: every frame counted, percentiles of real time (not timing targets).
        ((n, p50, p99),) = LATENCY.findall(result.stderr)
        p50, p99 = float(p50), float(p99)
        assert int(n) == len(frames) and np.isfinite([p50, p99]).all() and 0 < p50 <= p99, result.stderr

    run_checked(cmd, check)


def test_example_reports_a_bad_frame(fixtures):
    d = fixtures[0]
    frames = np.loadtxt(d / "frames.csv", delimiter=",")
    frames[9, 4] = np.nan
    np.savetxt(d / "bad.csv", frames, fmt="%.9g", delimiter=",")
    result = run([built("stream_csv"), d / "model.safetensors", d / "bad.csv"])
    assert result.returncode == 1 and "frame 9" in result.stderr and "USP.y" in result.stderr, result.stderr


@pytest.mark.skipif(shutil.which("pkg-config") is None, reason="pkg-config not installed")
@pytest.mark.parametrize("link", ["shared", "static"])
def test_host_build_through_pkg_config(fixtures, tmp_path, link):
    d = fixtures[0]
    prefix = tmp_path / "prefix"
    result = run(["make", "-s", "-C", ROOT, "install", f"PREFIX={prefix}"])
    assert result.returncode == 0, result.stderr
    env = {**os.environ, "PKG_CONFIG_PATH": str(prefix / "lib" / "pkgconfig")}
    flags = ["--cflags", "--libs"] + (["--static"] if link == "static" else [])
    pc = run(["pkg-config", *flags, "ikid"], env=env)
    assert pc.returncode == 0, pc.stderr
    args = pc.stdout.split()
    if link == "static":  # prefer the archive over the shared library
        args = (
            [a for a in args if a != "-likid"]
            + [str(prefix / "lib" / "libikid.a")]
            + [a for a in args if a.startswith("-l") and a != "-likid"]
        )
    exe = tmp_path / f"host_{link}"
    cc = run(
        [
            "cc",
            "-std=c11",
            "-O2",
            "-Wall",
            "-Wextra",
            "-Werror",
            ROOT / "examples" / "c" / "stream_csv.c",
            "-o",
            exe,
            *args,
        ]
    )
    assert cc.returncode == 0, cc.stderr
    # Started as a host would be: no LD_LIBRARY_PATH (ikid.pc's rpath finds the library).
    run_env = {k: v for k, v in os.environ.items() if k != "LD_LIBRARY_PATH"}
    result = run([exe, d / "model.safetensors", d / "frames.csv"], env=run_env)
    assert result.returncode == 0 and result.stdout.startswith("frame,ra_wr_s_p"), result.stderr
    ldd = run(["ldd", exe], env=run_env)
    if link == "static":
        assert "libikid" not in ldd.stdout
    else:
        major = ikid.__version__.split(".")[0]
        assert f"libikid.so.{major} => {prefix / 'lib'}/libikid.so.{major}" in ldd.stdout, ldd.stdout


@pytest.mark.skipif(shutil.which("c++") is None, reason="no C++ compiler")
def test_header_compiles_and_links_as_cpp(tmp_path):
    src = tmp_path / "host.cpp"
    src.write_text(
        '#include "ikid.h"\n#include <cstdio>\n'
        "int main() {\n"
        "  ikid_model *m = nullptr;\n"
        '  ikid_status s = ikid_model_load("/nonexistent.safetensors", &m);\n'
        '  std::printf("%s|%d|%s\\n", ikid_version(), int(s), ikid_last_error());\n'
        "  return m != nullptr;\n}\n"
    )
    exe = tmp_path / "host"
    lib = ROOT / "target" / "release"
    cc = run(
        [
            "c++",
            "-std=c++17",
            "-Wall",
            "-Wextra",
            "-Werror",
            f"-I{ROOT / 'include'}",
            src,
            "-o",
            exe,
            f"-L{lib}",
            "-likid",
            f"-Wl,-rpath,{lib}",
        ]
    )
    assert cc.returncode == 0, cc.stderr
    out = run([exe]).stdout.strip().split("|")
    assert out[1] == "3" and "/nonexistent.safetensors" in out[2], out
