"""Features from Python are the core's: known geometry, shapes, invariance, errors."""

import numpy as np
import pytest

import ikid
from conftest import marker_frames


def test_feature_set_info_sizes():
    sizes = {
        name: (ikid.feature_set_info(name)["frame_len"], ikid.feature_set_info(name)["feature_len"])
        for name in ikid.FEATURE_SETS
    }
    assert sizes == {
        "markers": (18, 18),
        "basis": (18, 24),
        "relative": (18, 12),
        "relative_gravity": (18, 15),
        "angles": (18, 3),
        "angles_gravity": (18, 6),
        "joint_state": (9, 9),
        "tracker_state": (10, 7),
    }
    with pytest.raises(ikid.InputError, match="unknown feature set"):
        ikid.feature_set_info("pixels")


def test_tracker_state_drops_the_angles():
    frames = np.arange(30, dtype=np.float32).reshape(3, 10)
    np.testing.assert_array_equal(ikid.compute_features(frames, "tracker_state"), frames[:, 3:])
    assert ikid.feature_set_info("tracker_state")["feature_names"][0] == "qd.ra_wr_s_p"


def test_markers_are_passed_through():
    frames = marker_frames(10)
    np.testing.assert_array_equal(ikid.compute_features(frames, "markers"), frames)


def test_basis_of_a_known_triangle():
    frame = np.zeros((1, 18), np.float32)
    frame[0, :9] = [0, 0, 0, 2, 0, 0, 0, 3, 0]
    frame[0, 9:] = [1, 1, 1, 1, 2, 1, 0, 1, 1]
    got = ikid.compute_features(frame, "basis")[0]
    want = [2 / 3, 1, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 2 / 3, 4 / 3, 1, 0, 1, 0, -1, 0, 0, 0, 0, 1]
    np.testing.assert_allclose(got, want, atol=1e-6)


def test_relative_features_ignore_a_rigid_motion_of_the_whole_arm():
    frames = marker_frames(20).astype(np.float64).reshape(20, 6, 3)
    angle = 0.7
    rot = np.array([[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]])
    moved = frames @ rot.T + np.array([0.3, -0.2, 1.0])
    a = ikid.compute_features(frames.reshape(20, 18), "relative")
    b = ikid.compute_features(moved.reshape(20, 18), "relative")
    np.testing.assert_allclose(a, b, atol=1e-5)
    assert not np.allclose(
        ikid.compute_features(frames.reshape(20, 18), "basis"),
        ikid.compute_features(moved.reshape(20, 18), "basis"),
    )


def test_degenerate_markers_and_nan_are_named():
    frames = marker_frames(3)
    frames[1, 9:] = [0, 0, 0, 1, 0, 0, 2, 0, 0]
    with pytest.raises(ikid.InputError, match="frame 1: the hand markers are collinear"):
        ikid.compute_features(frames, "relative")
    frames = marker_frames(3)
    frames[2, 0] = np.inf
    with pytest.raises(ikid.InputError, match="frame 2: value RSP.x is inf"):
        ikid.compute_features(frames, "basis")
