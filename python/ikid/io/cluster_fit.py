"""A segment marked by more than three markers (``[cluster]`` of a marker map): each frame the
cluster's rigid shape, learned from the recording, is fitted to every one of its markers seen
(core ``cluster``), and the segment's three named markers take the places the fit gives them.
:meth:`ikid.io.mapping.MarkerMap.fit_clusters` delegates here."""

from __future__ import annotations

import warnings
from typing import TYPE_CHECKING

import numpy as np

from ikid import _native
from ikid.io._common import MarkerMapWarning

if TYPE_CHECKING:
    from ikid.io.mapping import MarkerMap
    from ikid.io.markers import MarkerData


#: (file, segment) -> the cluster's shape learned from that file's first block (None: it could
#: not be learned), kept by the map so that every block of a file is fitted with one shape.
Shapes = dict[tuple[str, str], np.ndarray | None]


def fit_clusters(mapping: MarkerMap, data: MarkerData, columns: np.ndarray, shapes: Shapes) -> np.ndarray:
    """``columns`` (``labels_in_ikid_order``'s, ``(n, 3m)``) with each segment that has a
    ``[cluster]`` given its three markers where the cluster's rigid shape, fitted to every
    marker of it seen, puts them (core ``cluster``); a frame with fewer than three of its
    markers seen (or whose markers break the shape) keeps the three as they are. The shape
    is learned from the first block of ``data``'s file that is fitted and kept for the
    rest. A marker of the cluster
    often left out of the fit (it leaves its place), or frames whose markers break the
    shape, are said as a :class:`MarkerMapWarning`."""
    if not mapping.clusters:
        return columns
    source = data.source or "markers"
    columns = np.array(columns, np.float64)
    for segment, extra in mapping.clusters.items():
        first = {"forearm": 0, "hand": 9}[segment]  # the columns' order: forearm's three, hand's three
        names = mapping.marker_names()[first // 3 : first // 3 + 3]
        labels = [mapping.labels[m] for m in names] + list(extra)
        absent = [lab for lab in extra if lab not in data.labels]
        if absent:
            raise _native.InputError(
                f"{source}: the {segment}'s cluster label(s) {', '.join(absent)} not found; the file has "
                f"{', '.join(data.labels)}"
            )
        cluster = np.concatenate(
            [columns[:, first : first + 9]] + [data.marker(lab, mapping.up) for lab in extra], axis=1
        )
        key = (source, segment)
        named = (
            ", ".join(f"{n} {lab!r}" for n, lab in zip(names, labels, strict=False))
            + ", "
            + ", ".join(repr(lab) for lab in extra)
        )
        if key not in shapes:
            shapes[key] = _learn_shape(cluster, labels, segment, named, source)
        shape = shapes[key]
        if shape is None:
            continue
        placed, left_out, undetermined = _native.fit_cluster(cluster, shape)
        # A frame the cluster does not determine keeps its three markers as seen (ikid's gap
        # filling and marker checks take it from there, as for a three-marker segment).
        fitted = np.isfinite(placed[:, :9]).all(axis=1)
        columns[fitted, first : first + 9] = placed[fitted, :9]
        seen = np.isfinite(cluster.reshape(len(cluster), -1, 3)).all(axis=2).sum(axis=0)
        margin = 1e3 * _native.MAX_CLUSTER_FIT_RESIDUAL_M
        for label, out, n_seen in zip(labels, left_out, seen, strict=True):
            if out > max(1, 0.01 * n_seen):
                warnings.warn(
                    f"{source}: marker {label!r} of the {segment}'s cluster is more than {margin:.0f} mm "
                    f"from where the cluster's other markers put it in {out} of the {n_seen} frames it "
                    "is seen in, and is left out of those frames' fit: it does not keep its place on the "
                    "cluster; check its label, or that it is on the same rigid cluster",
                    MarkerMapWarning,
                    stacklevel=4,
                )
        if undetermined:
            warnings.warn(
                f"{source}: in {undetermined} frame(s) the {segment}'s cluster markers seen do not keep "
                f"its shape (within {margin:.0f} mm) or lie on a line: those frames read its three "
                "markers as they are",
                MarkerMapWarning,
                stacklevel=4,
            )
    return columns


def _learn_shape(
    cluster: np.ndarray, labels: list[str], segment: str, named: str, source: str
) -> np.ndarray | None:
    """A cluster's shape (core ``cluster::ClusterShape``, ``(k, 4)``), its markers that
    stray from it said; None, said, when these frames cannot give one (the segment's three
    are then read as they are)."""
    try:
        shape = _native.learn_cluster_shape(cluster, len(labels))
    except _native.IkidError as e:
        warnings.warn(
            f"{source}: the {segment}'s cluster ({named}) is not used: {e.reason or e} (in the "
            f"{len(cluster)} frames its shape is learned from: the file's first block); the "
            f"{segment}'s three [markers] are read as they are",
            MarkerMapWarning,
            stacklevel=5,
        )
        return None
    spread, core = shape[:, 3], shape[:, 4] >= 1.0
    kept = ", ".join(repr(lab) for lab, c in zip(labels, core, strict=True) if c)
    for label, stray, in_core in zip(labels, spread, core, strict=True):
        if not in_core:
            warnings.warn(
                f"{source}: marker {label!r} of the {segment}'s cluster does not keep its distances to "
                f"the markers that keep theirs together ({kept}): they change by {1e3 * stray:.1f} mm "
                f"(standard deviation), theirs by {1e3 * float(np.min(spread[core])):.1f}-"
                f"{1e3 * float(np.max(spread[core])):.1f} mm. It is on another segment, moved on "
                "its plate part-way, or slides on the skin: it counts for almost nothing in the "
                "cluster's fit (only where fewer than three of those are seen); check its label, or "
                "leave it out of [cluster]",
                MarkerMapWarning,
                stacklevel=5,
            )
    return shape
