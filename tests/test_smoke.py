"""First look: the package imports without torch and exposes the body model's names."""

import subprocess
import sys

import ikid


def test_import_does_not_pull_in_torch():
    code = "import sys, ikid; ikid.load; print('torch' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_names_come_from_the_core():
    assert ikid.coordinate_names() == ["ra_wr_s_p", "ra_wr_e_f", "ra_wr_ad_ab"]
    assert ikid.marker_names() == ["RSP", "USP", "FAP", "MC2", "MC5", "MCB"]
    assert ikid.FEATURE_SETS == [
        "markers",
        "basis",
        "relative",
        "relative_gravity",
        "angles",
        "angles_gravity",
        "joint_state",
        "tracker_state",
    ]
    assert ikid.__version__.count(".") == 2


def test_exceptions_form_one_hierarchy():
    assert issubclass(ikid.ModelFileError, ikid.IkidError)
    assert issubclass(ikid.InputError, ikid.IkidError)
    assert issubclass(ikid.InputError, ValueError)
