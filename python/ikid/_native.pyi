"""Type stubs of the Rust extension (checked against it by ``python -m mypy.stubtest``)."""

import os
from collections.abc import Iterator, Sequence
from typing import Any, final

import numpy as np
import numpy.typing as npt

__all__ = [
    "__version__",
    "IkidError",
    "ModelFileError",
    "InputError",
    "ArgumentError",
    "ReadError",
    "NotFoundError",
    "COORDINATES",
    "MARKERS",
    "FEATURE_SETS",
    "feature_set_info",
    "fill_gaps",
    "LabelCheck",
    "compute_features",
    "Calibration",
    "Model",
    "Stream",
    "Tracker",
    "TrackerEstimate",
    "DEFAULT_JERK_NOISE",
    "GAP_PERIODS",
    "REFINER_OUTPUTS",
    "REFINER_GATE_NOISE",
    "REFINED_SD_SCALE_Q",
    "REFINED_SD_SCALE_TAU",
    "RIGID_TOLERANCE_M",
    "MAX_TIME_GAP_S",
    "RATE_TOLERANCE",
    "LOST_S",
    "RIGID_TOLERANCE_REL",
    "SD_SCALE_TAU",
    "build_model",
    "forward_markers",
    "body_model",
    "reference_ik",
    "reference_id",
    "joint_status",
    "SIMULATOR",
    "simulate",
    "noise_uniform",
    "noise_gaussian",
    "noise_drift",
    "noise_occlusion",
    "FRAME_STATUS",
    "MARKER_SPAN_M",
    "LENGTH_SCALE_RANGE",
    "MASS_SCALE_RANGE",
    "check_marker_units",
    "check_default_placement",
    "hand_from_one_marker",
    "one_marker_hand_landmarks",
    "learn_cluster_shape",
    "fit_cluster",
    "points_in_technical_frame",
    "points_from_technical_frame",
    "lab_turn",
    "lab_up_axis",
    "MAX_CLUSTER_FIT_RESIDUAL_M",
    "CLUSTER_SPREAD_FLOOR_M",
    "MIN_NEUTRAL_FRAMES",
    "HAND_POINT",
    "ONE_HAND_MARKER_UNDETERMINED",
]

__version__: str
FRAME_STATUS: dict[str, int]
COORDINATES: list[tuple[str, str, tuple[float, float]]]
MARKERS: list[tuple[str, str, str]]
FEATURE_SETS: list[str]
SIMULATOR: str

class IkidError(Exception):
    """Base of every ikid error. From the core: ``kind`` ("input", "argument", "model_file",
    "io"), ``code`` (stable reason), ``frame`` (or None), ``markers``, ``reason`` (the message
    without its ``frame N:`` prefix); None/empty when raised by Python code."""

    kind: str | None
    code: str | None
    frame: int | None
    markers: list[str] | tuple[()]
    reason: str | None

class ModelFileError(IkidError): ...
class InputError(IkidError, ValueError): ...
class ArgumentError(InputError): ...
class ReadError(IkidError, OSError): ...
class NotFoundError(ReadError, FileNotFoundError): ...

_Floats = npt.ArrayLike

def feature_set_info(name: str) -> dict[str, Any]: ...
def compute_features(frames: _Floats, feature_set: str) -> npt.NDArray[np.float32]: ...
def fill_gaps(
    frames: _Floats, unfillable: str = "raise", rate_hz: float = 1000.0
) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.uint8]]: ...

@final
class LabelCheck:
    def __new__(cls, rate_hz: float) -> LabelCheck: ...
    def labels(self, frames: _Floats) -> npt.NDArray[np.int8]: ...

def build_model(
    card_json: str,
    weights: list[_Floats],
    biases: list[_Floats],
    input_scale: _Floats,
    input_shift: _Floats,
    output_scale: _Floats,
    output_shift: _Floats,
) -> Model: ...

@final
class Calibration:
    LANDMARKS: list[tuple[str, str]]
    HAND_LANDMARKS: list[tuple[str, str]]
    @staticmethod
    def from_trials(static_frames: _Floats, movements: dict[str, _Floats]) -> Calibration: ...
    @staticmethod
    def from_neutral(
        neutral_frames: _Floats,
        landmarks: _Floats | None = None,
        landmark_frames: _Floats | None = None,
        side: str = "right",
        hand_landmarks: _Floats | None = None,
    ) -> Calibration: ...
    @staticmethod
    def functional(neutral_frames: _Floats, movement_frames: _Floats, side: str = "right") -> Calibration: ...
    @staticmethod
    def mirrored(
        other: Calibration,
        cluster: _Floats,
        other_landmarks: _Floats,
        neutral_frames: _Floats,
        landmarks: _Floats | None = None,
        landmark_frames: _Floats | None = None,
        side: str = "left",
    ) -> Calibration: ...
    @staticmethod
    def body_model() -> Calibration: ...
    @staticmethod
    def from_matrices(forearm: _Floats, hand: _Floats, side: str = "right") -> Calibration: ...
    @property
    def side(self) -> str: ...
    @property
    def method(self) -> str: ...
    @property
    def forearm(self) -> npt.NDArray[np.float64]: ...
    @property
    def hand(self) -> npt.NDArray[np.float64]: ...
    @property
    def report(self) -> dict[str, Any] | None: ...
    @property
    def marker_shapes(self) -> npt.NDArray[np.float64] | None: ...
    def with_shapes_of(self, frames: _Floats) -> Calibration: ...
    def with_marker_shapes(self, shapes: _Floats | None) -> Calibration: ...
    def apply(self, frames: _Floats) -> npt.NDArray[np.float32]: ...

@final
class Model:
    @staticmethod
    def load(path: str | os.PathLike[str], *, allow_unchecked: bool = False) -> Model: ...
    @staticmethod
    def from_bytes(data: bytes, *, allow_unchecked: bool = False) -> Model: ...
    @property
    def card(self) -> dict[str, Any]: ...
    @property
    def name(self) -> str: ...
    @property
    def task(self) -> str: ...
    @property
    def feature_set(self) -> str: ...
    @property
    def frame_kind(self) -> str: ...
    @property
    def window(self) -> int: ...
    @property
    def frame_len(self) -> int: ...
    @property
    def frame_names(self) -> list[str]: ...
    @property
    def n_outputs(self) -> int: ...
    @property
    def output_names(self) -> list[str]: ...
    @property
    def output_units(self) -> list[str]: ...
    @property
    def frame_rate_hz(self) -> float: ...
    @property
    def layer_widths(self) -> list[int]: ...
    @property
    def has_checksum(self) -> bool: ...
    def frame_status(self, features: _Floats, outputs: _Floats) -> npt.NDArray[np.uint16]: ...
    def predict(self, frames: _Floats, threads: int | None = None) -> npt.NDArray[np.float32]: ...
    @property
    def missing_markers(self) -> str: ...
    def stream(
        self,
        missing_markers: str | None = None,
        calibration: Calibration | str | os.PathLike[str] | None = None,
        early_outputs: bool = False,
        up: str | Sequence[float] | None = None,
    ) -> Stream: ...
    def with_uncertainty(self, uncertainty: str | None) -> Model: ...
    def save(self, path: str | os.PathLike[str]) -> None: ...
    def to_bytes(self) -> bytes: ...

@final
class Stream:
    def push(self, frame: _Floats, time: float | None = None) -> npt.NDArray[np.float32] | None: ...
    @property
    def gap_restarts(self) -> int: ...
    @property
    def time_reanchors(self) -> int: ...
    @property
    def reanchors(self) -> int: ...
    def push_many(self, frames: _Floats) -> npt.NDArray[np.float32]: ...
    def reset(self) -> None: ...
    @property
    def filled(self) -> int: ...
    @property
    def missing_markers(self) -> str: ...
    @property
    def filled_markers(self) -> list[str]: ...
    @property
    def status(self) -> int: ...
    @property
    def model(self) -> Model: ...
    @property
    def output_sd(self) -> npt.NDArray[np.float64] | None: ...
    @property
    def sd_terms(self) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]] | None: ...

DEFAULT_JERK_NOISE: float
GAP_PERIODS: float
SD_SCALE_TAU: float
REFINER_OUTPUTS: list[str]
REFINER_GATE_NOISE: float
REFINED_SD_SCALE_Q: float
REFINED_SD_SCALE_TAU: float
RIGID_TOLERANCE_M: float
MAX_TIME_GAP_S: float
RATE_TOLERANCE: float
LOST_S: float
RIGID_TOLERANCE_REL: float

@final
class Tracker:
    def __new__(
        cls,
        length_scale: float = 1.0,
        mass_scale: float = 1.0,
        marker_shift: _Floats | None = None,
        rate_hz: float | None = None,
        jerk_noise: float = 3000.0,
        noise_memory_s: float = 10.0,
        initial_marker_noise: float = 1e-3,
        refiner: Model | str | os.PathLike[str] | None = None,
        calibration: Calibration | str | os.PathLike[str] | None = None,
        relative_hand: bool = False,
        up: str | Sequence[float] | None = None,
    ) -> Tracker: ...
    @property
    def refiner(self) -> Model | None: ...
    @property
    def output_sd(self) -> npt.NDArray[np.float64] | None: ...
    def push(self, frame: _Floats, time: float | None = None) -> TrackerEstimate | None: ...
    def run(self, frames: _Floats, sd: bool = False, times: _Floats | None = None) -> dict[str, Any]: ...
    def reset(self) -> None: ...
    @property
    def restarts(self) -> int: ...
    @property
    def gap_restarts(self) -> int: ...
    @property
    def bridged_frames(self) -> int: ...
    @property
    def marker_noise(self) -> npt.NDArray[np.float64]: ...
    @property
    def settings(self) -> dict[str, Any]: ...

@final
class TrackerEstimate:
    @property
    def q(self) -> npt.NDArray[np.float64]: ...
    @property
    def qd(self) -> npt.NDArray[np.float64]: ...
    @property
    def qdd(self) -> npt.NDArray[np.float64]: ...
    @property
    def tau(self) -> npt.NDArray[np.float64]: ...
    @property
    def values(self) -> npt.NDArray[np.float64]: ...
    @property
    def status(self) -> int: ...
    @property
    def missing(self) -> int: ...
    @property
    def noise(self) -> float: ...
    @property
    def refined(self) -> bool: ...
    def __array__(self, dtype: Any = None, copy: bool | None = None) -> npt.NDArray[Any]: ...
    def __getitem__(self, key: Any, /) -> Any: ...
    def __len__(self) -> int: ...
    def __iter__(self) -> Iterator[npt.NDArray[np.float64]]: ...

def check_marker_units(frames: _Floats) -> None: ...
def check_default_placement(frames: _Floats, length_scale: float = 1.0, side: str = "right") -> None: ...
def hand_from_one_marker(frames: _Floats, left: bool = False) -> npt.NDArray[np.float64]: ...
def one_marker_hand_landmarks(frames: _Floats) -> npt.NDArray[np.float64]: ...
def learn_cluster_shape(frames: _Floats, n_markers: int) -> npt.NDArray[np.float64]: ...
def fit_cluster(frames: _Floats, shape: _Floats) -> tuple[npt.NDArray[np.float64], list[int], int]: ...
def points_in_technical_frame(
    markers: _Floats, points: _Floats, n_points: int
) -> npt.NDArray[np.float64]: ...
def points_from_technical_frame(markers: _Floats, local: _Floats) -> npt.NDArray[np.float64]: ...
def lab_turn(up: str | Sequence[float]) -> npt.NDArray[np.float64]: ...
def lab_up_axis(name: str) -> list[float]: ...

MAX_CLUSTER_FIT_RESIDUAL_M: float
CLUSTER_SPREAD_FLOOR_M: float
MIN_NEUTRAL_FRAMES: int

HAND_POINT: tuple[str, str, str]
ONE_HAND_MARKER_UNDETERMINED: str

MARKER_SPAN_M: tuple[float, float]
LENGTH_SCALE_RANGE: tuple[float, float]
MASS_SCALE_RANGE: tuple[float, float]

def body_model(
    length_scale: float = 1.0,
    mass_scale: float = 1.0,
    shoulder_flexion: float = 0.0,
    marker_shift: _Floats | None = None,
) -> dict[str, Any]: ...
def forward_markers(
    q: _Floats,
    shoulder_flexion: float = 0.0,
    length_scale: float = 1.0,
    mass_scale: float = 1.0,
    marker_shift: _Floats | None = None,
) -> npt.NDArray[np.float64]: ...
def reference_ik(
    markers: _Floats, length_scale: float = 1.0, mass_scale: float = 1.0
) -> npt.NDArray[np.float64]: ...
def reference_id(
    q: _Floats,
    qd: _Floats,
    qdd: _Floats,
    shoulder_flexion: float = 0.0,
    length_scale: float = 1.0,
    mass_scale: float = 1.0,
) -> npt.NDArray[np.float64]: ...
def joint_status(
    q: _Floats, tau: _Floats | None = None, mass_scale: float = 1.0
) -> npt.NDArray[np.uint16]: ...
def simulate(
    protocol: str = "random",
    seed: int = 0,
    duration: float = 10.0,
    shoulder_flexion: float = 0.0,
    length_scale: float = 1.0,
    mass_scale: float = 1.0,
    dt: float = 0.001,
    substeps: int = 1,
    output_every: int = 1,
    octants: list[str] | None = None,
) -> dict[str, Any]: ...
def noise_uniform(markers: _Floats, fraction: float, seed: int) -> npt.NDArray[np.float64]: ...
def noise_gaussian(markers: _Floats, sigma: float, seed: int) -> npt.NDArray[np.float64]: ...
def noise_drift(markers: _Floats, amplitude: float, rate_hz: float, seed: int) -> npt.NDArray[np.float64]: ...
def noise_occlusion(
    markers: _Floats,
    bursts_per_second: float,
    min_s: float,
    max_s: float,
    rate_hz: float,
    seed: int,
    markers_affected: list[int] = ...,
) -> npt.NDArray[np.float64]: ...
