"""Errors are classified once, in the core: Python's exception class and attributes and C's
status code come from the same kind, for every kind, on the same bad inputs. C is called
through ctypes on the libikid built by `make c` (target/release/libikid.so)."""

from __future__ import annotations

import ctypes
import os

import numpy as np
import pytest

import ikid
import ikid.calibration
import ikid.sim
from conftest import ROOT, make_model, marker_frames

LIB = ROOT / "target" / "release" / "libikid.so"
# ikid_status values (include/ikid.h).
C_STATUS = {"argument": 2, "io": 3, "model_file": 4, "input": 5}
PY_CLASS = {
    "argument": ikid.ArgumentError,
    "io": ikid.ReadError,
    "model_file": ikid.ModelFileError,
    "input": ikid.InputError,
}


@pytest.fixture(scope="module")
def libikid():
    if not LIB.exists():
        pytest.fail(f"{LIB} is missing: run `make c` (make test does)")
    lib = ctypes.CDLL(str(LIB))
    lib.ikid_model_load.argtypes = [ctypes.c_char_p, ctypes.POINTER(ctypes.c_void_p)]
    lib.ikid_model_free.argtypes = [ctypes.c_void_p]
    lib.ikid_stream_new.argtypes = [ctypes.c_void_p, ctypes.POINTER(ctypes.c_void_p)]
    lib.ikid_stream_free.argtypes = [ctypes.c_void_p]
    f32p, f64p = ctypes.POINTER(ctypes.c_float), ctypes.POINTER(ctypes.c_double)
    lib.ikid_stream_push.argtypes = [
        ctypes.c_void_p,
        f32p,
        ctypes.c_size_t,
        f32p,
        ctypes.c_size_t,
        ctypes.POINTER(ctypes.c_bool),
    ]
    lib.ikid_stream_set_calibration.argtypes = [ctypes.c_void_p, f64p, f64p]
    lib.ikid_last_error.restype = ctypes.c_char_p
    return lib


def c_load(lib, path) -> tuple[int, str]:
    handle = ctypes.c_void_p()
    status = lib.ikid_model_load(os.fsencode(str(path)), ctypes.byref(handle))
    if status == 0:
        lib.ikid_model_free(handle)
        return 0, ""
    return status, lib.ikid_last_error().decode()


@pytest.fixture
def model_file(tmp_path):
    path = tmp_path / "model.safetensors"
    make_model(hidden=(16,)).save(path)
    return path


def agree(kind: str, py_error: ikid.IkidError, c_status: int, c_message: str) -> None:
    assert isinstance(py_error, PY_CLASS[kind]) and py_error.kind == kind, (type(py_error), py_error.kind)
    assert c_status == C_STATUS[kind], (kind, c_status, c_message)
    assert str(py_error) == c_message, "one message for both"


@pytest.mark.parametrize("case", ["missing", "directory", "dev_zero", "corrupt"])
def test_model_file_errors_agree(libikid, model_file, tmp_path, case):
    path = {
        "missing": tmp_path / "nope.safetensors",
        "directory": tmp_path,
        "dev_zero": "/dev/zero",
        "corrupt": tmp_path / "bad.safetensors",
    }[case]
    if case == "corrupt":
        path.write_bytes(model_file.read_bytes()[:100])
    kind = "model_file" if case == "corrupt" else "io"
    with pytest.raises(ikid.IkidError) as caught:
        ikid.Model.load(path)
    agree(kind, caught.value, *c_load(libikid, path))
    if case == "missing":
        assert (
            isinstance(caught.value, (ikid.NotFoundError, FileNotFoundError))
            and caught.value.code == "not_found"
        )
    else:
        assert not isinstance(caught.value, FileNotFoundError)
    assert str(path) in str(caught.value)


def test_input_and_argument_errors_agree(libikid, model_file):
    model = ikid.Model.load(model_file)
    frames = marker_frames(12, seed=3).astype(np.float32)
    frames[9, 13] = np.nan  # MC5.y
    handle, stream = ctypes.c_void_p(), ctypes.c_void_p()
    assert libikid.ikid_model_load(os.fsencode(str(model_file)), ctypes.byref(handle)) == 0
    assert libikid.ikid_stream_new(handle, ctypes.byref(stream)) == 0
    try:
        out, ready = (ctypes.c_float * 3)(), ctypes.c_bool()
        py_stream = model.stream()
        for i, frame in enumerate(frames):
            c_frame = frame.ctypes.data_as(ctypes.POINTER(ctypes.c_float))
            status = libikid.ikid_stream_push(stream, c_frame, 18, out, 3, ctypes.byref(ready))
            if i < 9:
                assert status == 0
                py_stream.push(frame)
                continue
            with pytest.raises(ikid.IkidError) as caught:
                py_stream.push(frame)
            agree("input", caught.value, status, libikid.ikid_last_error().decode())
            e = caught.value
            assert (e.code, e.frame, e.markers) == ("non_finite_input", 9, ["MC5"])
            assert e.reason == str(e).removeprefix("frame 9: ") and e.reason.startswith("value MC5.y is NaN")
            assert isinstance(e, ValueError)
            break
        # A calibration that is not a rotation: an argument error on both sides.
        reflection = np.diag([1.0, 1.0, -1.0])
        with pytest.raises(ikid.IkidError) as caught:
            ikid.Calibration.from_matrices(reflection, np.eye(3))
        m = np.ascontiguousarray(reflection).ctypes.data_as(ctypes.POINTER(ctypes.c_double))
        eye = np.eye(3).ctypes.data_as(ctypes.POINTER(ctypes.c_double))
        status = libikid.ikid_stream_set_calibration(stream, m, eye)
        agree("argument", caught.value, status, libikid.ikid_last_error().decode())
        assert caught.value.code == "bad_argument" and caught.value.frame is None
    finally:
        libikid.ikid_stream_free(stream)
        libikid.ikid_model_free(handle)


def test_errors_raised_by_python_code_have_the_class_defaults():
    e = ikid.InputError("made in Python")
    assert (e.kind, e.code, e.frame, tuple(e.markers), e.reason) == (None, None, None, (), None)
    assert issubclass(ikid.ArgumentError, ikid.InputError) and issubclass(ikid.InputError, ValueError)
    assert issubclass(ikid.NotFoundError, FileNotFoundError) and issubclass(ikid.ReadError, OSError)


# Every function that reads a file a user names: models (by path, by family at a rate, the
# class's own loader), the marker formats (each, and the reader that picks one by suffix),
# OpenSim storage, marker maps, calibrations (loaded, described, checked against a map) and
# simulated trials.
READERS = {
    "model": ikid.load,
    "model_at_rate": lambda path: ikid.load(path, rate_hz=1000.0),
    "model_class": ikid.Model.load,
    "trc": ikid.io.read_trc,
    "csv": ikid.io.read_csv_markers,
    "c3d": ikid.io.read_c3d,
    "markers_by_suffix": ikid.io.read_markers,
    "mot": ikid.io.read_mot,
    "sto": ikid.io.read_sto,
    "storage": ikid.io.read_storage,
    "map": ikid.io.MarkerMap.load,
    "calibration": ikid.load_calibration,
    "calibration_info": ikid.calibration.calibration_info,
    "calibration_map_check": lambda path: ikid.calibration.check_calibration_map(path, None),
    "trial": ikid.sim.Trial.load,
}


@pytest.fixture(scope="module")
def unbounded(tmp_path_factory):
    """A directory, /dev/zero, a named pipe (nothing writes to it: reading would block) and
    a 4 GB sparse file (4 GB of zeros to read)."""
    root = tmp_path_factory.mktemp("unbounded")
    fifo = root / "fifo.trc"
    os.mkfifo(fifo)
    sparse = root / "huge.trc"
    with open(sparse, "wb") as f:
        f.truncate(4 << 30)
    return {
        "directory": root / "dir.trc",
        "dev_zero": "/dev/zero",
        "fifo": fifo,
        "sparse_4gb": sparse,
        "root": root,
    }


@pytest.mark.parametrize("reader", sorted(READERS))
@pytest.mark.parametrize("case", ["directory", "dev_zero", "fifo", "sparse_4gb"])
def test_every_reader_refuses_what_it_cannot_bound_at_once(unbounded, reader, case):
    import resource
    import time

    path = unbounded[case]
    if case == "directory":
        path.mkdir(exist_ok=True)
    # /dev/zero has no suffix to pick a marker reader by: refused for that, before opening it.
    by_suffix = reader == "markers_by_suffix" and case == "dev_zero"
    peak_before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    started = time.monotonic()
    with pytest.raises(ikid.io.FileFormatError if by_suffix else ikid.ReadError) as caught:
        READERS[reader](path)
    assert time.monotonic() - started < 1.0
    growth_mb = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - peak_before) / 1024
    assert growth_mb < 50, f"peak memory grew {growth_mb:.0f} MB"
    message = str(caught.value)
    assert str(path) in message
    if by_suffix:
        assert "unknown marker file type" in message, message
        return
    assert "directory" in message or "not a regular file" in message or "4294967296 bytes" in message, message
