"""A model file without a checksum of its weights is refused unless the caller opts in (issue #31,
"What to build" 5).

Such a file (written before model files carried ``tensor_sha256``) cannot be told from a
corrupted copy: the issue's case scaled the outputs by 30 behind a warning, every row up to 189°
off. The core refuses it (``missing_checksum``, a ``ModelFileError``), the message naming the
opt-in of the surface at hand (``allow_unchecked=True`` in Python, ``--allow-unchecked-model``
on the command line) and ``python -m ikid_training.export --restamp FILE``, which adds the
checksum; with the opt-in it loads, with a warning. C stays strict (``ikid_model_load``)."""

from __future__ import annotations

import importlib.util
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import ikid
from conftest import marker_frames

IKID = shutil.which("ikid", path=str(Path(sys.executable).parent)) or "ikid"
SHIPPED = Path(ikid.__file__).with_name("models")


def unchecked_copy(folder: Path, name: str = "wrist-ik", scale: float = 1.0) -> Path:
    """A shipped model with its card's checksum removed (and its output scale times
    ``scale``, as the issue's case did): what a file written before checksums looks like."""
    from safetensors.numpy import load_file, save_file

    path = folder / f"old-{name}.safetensors"
    tensors = load_file(str(SHIPPED / f"{name}.safetensors"))
    tensors["output.scale"] = tensors["output.scale"] * np.float32(scale)
    card = dict(ikid.load(name).card)
    card.pop("tensor_sha256")
    save_file(tensors, str(path), metadata={"ikid": json.dumps(card)})
    return path


def test_python_refuses_it_naming_the_opt_in_and_loads_it_with_the_opt_in(tmp_path):
    path = unchecked_copy(tmp_path)
    with pytest.raises(ikid.ModelFileError) as e:
        ikid.load(path)
    assert e.value.code == "missing_checksum" and e.value.kind == "model_file"
    message = str(e.value)
    assert message.startswith(f"model file {path}: "), message
    assert "allow_unchecked=True" in message and "--restamp" in message, message
    with pytest.raises(ikid.ModelFileError, match="restamp"):
        ikid._native.Model.load(path)  # the core's loader, strict too
    with pytest.warns(UserWarning, match="without a checksum"):
        model = ikid.load(path, allow_unchecked=True)
    assert not model.has_checksum
    frames = marker_frames(24)
    np.testing.assert_array_equal(model.predict(frames), ikid.load("wrist-ik").predict(frames))


def test_the_opt_in_does_not_excuse_a_wrong_checksum(tmp_path):
    path = tmp_path / "bad.safetensors"
    data = bytearray((SHIPPED / "wrist-ik.safetensors").read_bytes())
    data[-2] ^= 0x80  # a sign bit in the last tensor
    path.write_bytes(bytes(data))
    for allow in (False, True):
        with pytest.raises(ikid.ModelFileError) as e:
            ikid.load(path, allow_unchecked=allow)
        assert e.value.code == "checksum_mismatch"


def test_the_command_line_refuses_it_naming_its_flag_and_runs_with_it(tmp_path):
    """The issue's case: output scale x30 behind a warning. Refused, exit 2; with the flag the
    run goes ahead and says, on one line, that the file is unchecked."""
    path = unchecked_copy(tmp_path, scale=30.0)
    trial = ikid.simulate("random", seed=5, duration=0.3)
    trc = ikid.io.write_trc(tmp_path / "t.trc", trial.time, trial.markers, 1000.0)
    argv = [IKID, "ik", str(trc), "--model", str(path), "-o", str(tmp_path / "t.mot")]
    r = subprocess.run(argv, capture_output=True, text=True, timeout=120)
    assert r.returncode == 2, r.stderr
    assert "Traceback" not in r.stderr
    line = r.stderr.strip().splitlines()[-1]
    assert line.startswith(f"ikid: error: model file {path}: ") and "--allow-unchecked-model" in line, line
    assert "--restamp" in line and "allow_unchecked=True" not in line, line
    assert not (tmp_path / "t.mot").exists()
    r = subprocess.run([*argv, "--allow-unchecked-model"], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stderr.count(f"ikid: warning: {path}: loaded without a checksum") == 1, r.stderr
    assert "Traceback" not in r.stderr and (tmp_path / "t.mot").exists()


@pytest.mark.skipif(importlib.util.find_spec("ikid_training") is None, reason="needs ikid-training")
def test_restamp_gives_an_old_file_its_checksum(tmp_path):
    path = unchecked_copy(tmp_path, "wrist-chain")
    r = subprocess.run(
        [sys.executable, "-m", "ikid_training.export", "--restamp", str(path)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert r.returncode == 0, r.stderr
    assert "checksum True" in r.stdout, r.stdout
    model = ikid.load(path)  # no opt-in needed any more
    assert model.has_checksum
    frames = marker_frames(40)
    np.testing.assert_array_equal(model.predict(frames), ikid.load("wrist-chain").predict(frames))
