"""Which way is up: torques depend on gravity's direction in the lab, angles do not.

ikid's own lab is +Y up (its simulator, body model and torque networks, as OpenSim's); Vicon and
Qualisys labs are usually +Z up. A file's lab is turned into ikid's before its frames reach the
core, by the map's ``up``, else the file's declaration (a C3D's ``POINT:Y_SCREEN``), else +Y,
said to be assumed. The oracle throughout: the same simulated trial in ikid's own lab, and the
simulator's torques.
"""

from __future__ import annotations

import io as text_io
import subprocess
import sys

import numpy as np
import pytest

import ikid
from ikid import io
from ikid.cli import main as cli
from ikid.io.storage import moment_names


def _z_up(markers: np.ndarray) -> np.ndarray:
    """ikid-lab (+Y up) positions ``(n, 18)`` as a +Z-up lab records them: its z is ikid's y
    (up), its y is ikid's −z (so the axes stay right-handed), its x ikid's x."""
    p = np.asarray(markers, np.float64).reshape(len(markers), 6, 3)
    return np.stack([p[..., 0], -p[..., 2], p[..., 1]], axis=-1).reshape(len(markers), 18)


@pytest.fixture(scope="module")
def trial():
    return ikid.simulate("random", seed=7011, duration=3.0)


def _map(tmp_path, up: str | None) -> str:
    lines = ([f'up = "{up}"'] if up else []) + ["[markers]"] + [f'{m} = "{m}"' for m in ikid.marker_names()]
    path = tmp_path / f"map_{up or 'none'}.toml"
    path.write_text("\n".join(lines) + "\n")
    return str(path)


def _track(tmp_path, capsys, path, name, *extra) -> tuple[np.ndarray, np.ndarray, str]:
    assert cli(["track", str(path), "-o", str(tmp_path / name), *extra]) == 0
    out = capsys.readouterr().out
    q = io.read_storage(tmp_path / f"{name}.mot").select(ikid.coordinate_names())
    tau = io.read_storage(tmp_path / f"{name}.sto").select(moment_names())
    return q, tau, out


def test_a_z_up_lab_declared_by_its_map_or_its_c3d_gives_the_torques_of_ikids_own_lab(
    trial, tmp_path, capsys
):
    y_up = io.write_trc(tmp_path / "y.trc", trial.time, trial.markers, trial.rate_hz)
    z_markers = _z_up(trial.markers)
    z_trc = io.write_trc(tmp_path / "z.trc", trial.time, z_markers, trial.rate_hz)
    z_c3d = tmp_path / "z.c3d"
    positions = z_markers.reshape(len(z_markers), 6, 3)
    io.write_c3d(
        z_c3d,
        io.MarkerData(
            tuple(ikid.marker_names()), trial.time, positions, trial.rate_hz, "z", "m", {"up": "+z"}
        ),
    )
    q_y, tau_y, out_y = _track(tmp_path, capsys, y_up, "y")
    assert "lab up +y (assumed" in out_y
    # The simulator's torques: ikid's own lab is tracked to them.
    assert np.sqrt(np.mean((tau_y[500:] - trial.tau[500:]) ** 2)) < 0.01

    q_map, tau_map, out_map = _track(tmp_path, capsys, z_trc, "zmap", "--map", _map(tmp_path, "+z"))
    assert "lab up +z (the map's up)" in out_map
    q_c3d, tau_c3d, out_c3d = _track(tmp_path, capsys, z_c3d, "zc3d")
    assert "lab up +z (the C3D's POINT:Y_SCREEN = '+Z')" in out_c3d
    for q, tau in ((q_map, tau_map), (q_c3d, tau_c3d)):
        np.testing.assert_allclose(q, q_y, atol=1e-4)  # degrees; the C3D's float32 positions
        np.testing.assert_allclose(tau, tau_y, atol=2e-4)

    # Undeclared, the same markers are read as a +Y-up lab: the angles are the same, the torques
    # are not (gravity along the forearm's other axis), and the summary says +Y was assumed.
    q_none, tau_none, out_none = _track(tmp_path, capsys, z_trc, "znone")
    assert "lab up +y (assumed" in out_none
    np.testing.assert_allclose(q_none, q_y, atol=1e-6)
    assert np.sqrt(np.mean((tau_none - tau_y) ** 2)) > 0.05


def test_a_torque_model_on_a_z_up_lab_reads_gravity_where_the_map_puts_it(trial, tmp_path, capsys):
    y_up = io.write_trc(tmp_path / "y.trc", trial.time, trial.markers, trial.rate_hz)
    z_trc = io.write_trc(tmp_path / "z.trc", trial.time, _z_up(trial.markers), trial.rate_hz)
    runs = {}
    for name, path, extra in (("y", y_up, []), ("z", z_trc, ["--map", _map(tmp_path, "+z")])):
        assert cli(["run", str(path), "-o", str(tmp_path / name), *extra]) == 0
        runs[name] = capsys.readouterr().out
        assert "torques with lab up" in runs[name]
    assert "torques with lab up +z (the map's up)" in runs["z"]
    tau = {k: io.read_storage(tmp_path / f"{k}.sto") for k in runs}
    np.testing.assert_allclose(tau["z"].select(moment_names()), tau["y"].select(moment_names()), atol=1e-4)
    np.testing.assert_array_equal(tau["z"].column("ikid_status"), tau["y"].column("ikid_status"))


def _csv(frames: np.ndarray) -> str:
    return "".join(",".join(f"{v:.9g}" for v in row) + "\n" for row in frames)


def _stream(monkeypatch, capsys, frames, *args) -> tuple[np.ndarray, str]:
    monkeypatch.setattr(sys, "stdin", text_io.StringIO(_csv(frames)))
    assert cli(["stream", "--rate", "1000", "--tracker", *args]) == 0
    captured = capsys.readouterr()
    lines = captured.out.strip().splitlines()[1:]
    return np.array(
        [[float(v) if v else np.nan for v in line.split(",")[2:]] for line in lines]
    ), captured.err


def test_the_live_stream_turns_a_z_up_lab_given_by_up(trial, monkeypatch, capsys):
    frames = np.asarray(trial.markers[:600], np.float64)
    y, err_y = _stream(monkeypatch, capsys, frames)
    assert "lab up +y (assumed" in err_y
    z, err_z = _stream(monkeypatch, capsys, _z_up(frames), "--up", "+z")
    assert "lab up +z" in err_z and "assumed" not in err_z
    np.testing.assert_allclose(z, y, atol=1e-6, equal_nan=True)


def _qtm_tracker(tmp_path, frames: np.ndarray, up: str, *extra: str) -> tuple[np.ndarray, str]:
    from live_peers import FakeQtm, map_toml

    (tmp_path / "lab.toml").write_text(map_toml())
    server = FakeQtm(frames, rate=1000.0, up=up, burst=True)
    try:
        r = subprocess.run(
            [sys.executable, "-m", "ikid", "stream", "--source", f"qtm:127.0.0.1:{server.port}",
             "--map", str(tmp_path / "lab.toml"), "--tracker", "--idle", "3", "--max-lag", "10",
             "--count", str(len(frames)), *extra],
            capture_output=True, text=True, timeout=120,
        )  # fmt: skip
    finally:
        server.close()
    assert r.returncode == 0, r.stderr
    lines = r.stdout.strip().splitlines()[1:]
    return np.array([[float(v) if v else np.nan for v in line.split(",")[3:]] for line in lines]), r.stderr


def test_a_qtm_source_is_turned_by_the_axis_upwards_it_declares(trial, tmp_path):
    # QTM's 3D data is +Z up by default and its parameters say so (AxisUpwards); read as +Y,
    # gravity pulled the hand sideways and every torque line was "ok".
    frames = np.asarray(trial.markers[:600], np.float64)
    y, _ = _qtm_tracker(tmp_path, frames, "+Y")
    z, err = _qtm_tracker(tmp_path, _z_up(frames), "+Z")
    assert "lab up +z (QTM's AxisUpwards)" in err, err
    # Sent as float32 millimetres: equal to what the same frames in ikid's lab give.
    np.testing.assert_allclose(z, y, atol=2e-4, equal_nan=True)
    # An --up of the lab's own is taken over QTM's word, and the difference said.
    _, err = _qtm_tracker(tmp_path, _z_up(frames), "+Z", "--up", "+y")
    assert "taken as +y (--up), where QTM says its AxisUpwards is +z" in err, err


def test_up_must_name_a_lab_axis(tmp_path):
    with pytest.raises(ikid.InputError, match=r"up = 'w'.*one of \+x, -x"):
        io.MarkerMap.load(_map(tmp_path, "w"))
    assert io.MarkerMap.load(_map(tmp_path, "Z")).up == "+z"


@pytest.mark.parametrize("up", ["+x", "-x", "+y", "-y", "+z", "-z"])
def test_each_up_axis_is_turned_to_ikids_up_by_a_proper_rotation(up):
    # Oracle: the axis itself, and a rotation's determinant (a mirror would make a right arm left).
    axis = {"x": 0, "y": 1, "z": 2}[up[1]]
    points = np.eye(3) * (1.0 if up[0] == "+" else -1.0)
    turned = io.to_ikid_lab(points, up)
    np.testing.assert_allclose(turned[axis], [0.0, 1.0, 0.0])
    rotation = io.to_ikid_lab(np.eye(3), up).T  # columns: where each lab axis goes
    np.testing.assert_allclose(rotation.T @ rotation, np.eye(3), atol=1e-12)
    assert np.linalg.det(rotation) == pytest.approx(1.0)


def test_a_map_that_overrides_the_files_declared_up_says_so(trial, tmp_path, capsys):
    positions = _z_up(trial.markers).reshape(len(trial.markers), 6, 3)
    z_c3d = tmp_path / "z.c3d"
    data = io.MarkerData(
        tuple(ikid.marker_names()), trial.time, positions, trial.rate_hz, "z", "m", {"up": "+z"}
    )
    io.write_c3d(z_c3d, data)
    _, _, out = _track(tmp_path, capsys, z_c3d, "over", "--map", _map(tmp_path, "+y"))
    assert "lab up +y (the map's up, over the C3D's POINT:Y_SCREEN = '+Z')" in out, out


def test_the_trackers_up_gives_a_z_up_labs_frames_the_torques_of_ikids_lab(trial):
    """The API, not the CLI: ``ikid.Tracker(up=...)`` on a Z-up lab's raw frames. Oracle: the
    simulator's torques (and the same trial in ikid's own lab)."""
    frames, truth = trial.markers, trial.tau
    own = ikid.Tracker(rate_hz=trial.rate_hz).run(frames)["tau"]
    raw = _z_up(frames)
    told = ikid.Tracker(rate_hz=trial.rate_hz, up="+z").run(raw)["tau"]
    as_vector = ikid.Tracker(rate_hz=trial.rate_hz, up=[0.0, 0.0, 2.0]).run(raw)["tau"]
    untold = ikid.Tracker(rate_hz=trial.rate_hz).run(raw)["tau"]
    scored = slice(500, None)
    err = lambda tau: float(np.sqrt(np.mean((tau[scored] - truth[scored]) ** 2)))  # noqa: E731
    np.testing.assert_allclose(told, own, atol=1e-9)
    np.testing.assert_allclose(as_vector, own, atol=1e-9)
    assert err(told) < 0.01 and err(untold) > 10 * err(told), (err(told), err(untold))
    for bad in ("up", "+w", [0.0, 0.0, 0.0], [1.0, 2.0]):
        with pytest.raises(ikid.IkidError, match="up"):
            ikid.Tracker(rate_hz=trial.rate_hz, up=bad)  # type: ignore[arg-type]


def test_a_stream_told_its_labs_up_gives_wrist_chain_the_torques_of_ikids_lab(trial):
    """The API: ``model.stream(up=...)`` on a Z-up lab's raw frames. The shipped torque model
    reads gravity's direction from the frames; told the lab's up, its torques are those of the
    same trial in ikid's own lab (the oracle); not told, they are not."""
    model = ikid.load("wrist-chain")

    def torques(frames, **kw):
        return model.stream(**kw).push_many(np.asarray(frames, np.float32))

    own = torques(trial.markers)
    raw = _z_up(trial.markers)
    np.testing.assert_allclose(torques(raw, up="+z"), own, atol=1e-3)
    np.testing.assert_allclose(torques(raw, up=(0.0, 0.0, 5.0)), own, atol=1e-3)
    assert np.abs(torques(raw) - own).max() > 0.05
    with pytest.raises(ikid.IkidError, match="up"):
        model.stream(up="w")
