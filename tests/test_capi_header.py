"""include/ikid.h as a host's compiler sees it: valid C99 and C++17 under -pedantic -Werror,
its deprecation attribute effective where the compiler has one (a call to an old name warns)
and absent, not an error, where it has none (GNU attributes unavailable: MSVC, a strict
compiler), and overridable by the host. Compile-only (no library needed): the fast tier."""

from __future__ import annotations

import re
import shutil
import subprocess

import pytest

from conftest import ROOT

INCLUDE = ROOT / "include"

# Every type, constant and a deprecated function of the header, used once.
SOURCE = """
#include "ikid.h"
int host(void) {
    ikid_model *model = 0;
    ikid_model_info info;
    ikid_tracker_settings settings = ikid_tracker_settings_default();
    ikid_tracker_flags flags;
    ikid_missing_markers policy = IKID_MISSING_MARKERS_FILL;
    enum ikid_status status = ikid_model_load("/nonexistent.safetensors", &model);
    (void)info; (void)flags; (void)policy;
    return (int)status + (int)(settings.rate_hz > 0) + IKID_FRAME_PER_FRAME
        + (int)ikid_predict_rows(model, 3);
}
"""


def compile_source(tmp_path, compiler: str, suffix: str, flags: list[str]) -> subprocess.CompletedProcess:
    if shutil.which(compiler) is None:
        pytest.skip(f"{compiler} is not installed")
    src = tmp_path / f"host{suffix}"
    src.write_text(SOURCE)
    cmd = [compiler, *flags, f"-I{INCLUDE}", "-c", str(src), "-o", str(tmp_path / "host.o")]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=60)


# (compiler, suffix, flags): the standards a host builds with, strict.
STRICT = {
    "c99": ("cc", ".c", ["-std=c99", "-pedantic", "-Wall", "-Wextra", "-Werror"]),
    "c11": ("cc", ".c", ["-std=c11", "-pedantic", "-Wall", "-Wextra", "-Werror"]),
    "c++17": ("c++", ".cpp", ["-std=c++17", "-pedantic", "-Wall", "-Wextra", "-Werror"]),
    "c++11": ("c++", ".cpp", ["-std=c++11", "-pedantic", "-Wall", "-Wextra", "-Werror"]),
}


@pytest.mark.parametrize("standard", STRICT)
def test_header_is_valid_strict_c_and_cpp(tmp_path, standard):
    compiler, suffix, flags = STRICT[standard]
    # Without the deprecation warning: only the header's own validity is under test here.
    result = compile_source(tmp_path, compiler, suffix, [*flags, "-Wno-deprecated-declarations"])
    assert result.returncode == 0, result.stderr


@pytest.mark.parametrize("standard", STRICT)
def test_a_deprecated_name_warns_at_compile_time(tmp_path, standard):
    compiler, suffix, flags = STRICT[standard]
    result = compile_source(tmp_path, compiler, suffix, flags)
    assert result.returncode != 0 and "renamed ikid_model_predict_rows" in result.stderr, result.stderr


@pytest.mark.parametrize("standard", ["c99", "c++17"])
def test_header_compiles_without_gnu_attributes(tmp_path, standard):
    """A compiler without GNU attributes (and without C23/C++14 standard ones): the macro's
    fallback is empty, so the old names compile and nothing unknown reaches the compiler."""
    compiler, suffix, flags = STRICT[standard]
    no_gnu = ["-U__GNUC__", "-U__clang__"] + (["-std=c++11"] if suffix == ".cpp" else [])
    result = compile_source(tmp_path, compiler, suffix, [*flags, *no_gnu])
    assert result.returncode == 0, result.stderr
    # What the declaration reads after preprocessing: no attribute of any spelling.
    src = tmp_path / f"host{suffix}"
    pre = subprocess.run(
        [compiler, *flags, *no_gnu, f"-I{INCLUDE}", "-E", str(src)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert pre.returncode == 0, pre.stderr
    for name in ("ikid_model_describe", "ikid_predict_rows", "ikid_predict"):
        at = re.search(rf"\b{name}\(", pre.stdout)
        assert at is not None, name
        decl = pre.stdout[: at.start()].rsplit(";", 1)[-1]
        assert not any(a in decl for a in ("deprecated", "__attribute__", "[[", "__declspec")), decl


def test_a_host_may_define_the_attribute_macro(tmp_path):
    """IKID_DEPRECATED defined empty by the host silences the warning (its documented use)."""
    compiler, suffix, flags = STRICT["c99"]
    result = compile_source(tmp_path, compiler, suffix, [*flags, "-DIKID_DEPRECATED(note)="])
    assert result.returncode == 0, result.stderr
