"""UFF-58 codes and numbering shared by the UFF writer and readers.

The function and specific-data-type codes of dataset 58, guidefit's node and
direction numbering (:func:`point_nodes`, :func:`direction_code`,
:func:`direction_vector`; described in the docstring of
:mod:`guidefit.io.uff`), the channel-label tables, and the helpers every UFF
module needs (the lazy ``pyuff`` import, the suffix check). They are separate
so that the writer (:mod:`guidefit.io.uff_write`) and the readers
(:mod:`guidefit.io.uff`, :mod:`guidefit.io.uff_frf`) share one definition
without importing each other. Every public name stays importable from
:mod:`guidefit.io.uff`.
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from guidefit.errors import RecordingError, first_line
from guidefit.io.uff_geometry import DIRECTION_TOLERANCE

UFF_SUFFIXES = (".uff", ".unv")

FUNCTION_TIME = 1
"""UFF-58 function type of a time response."""
FUNCTION_FRF = 4
"""UFF-58 function type of a frequency response function."""
FUNCTION_COHERENCE = 6
"""UFF-58 function type of an (ordinary) coherence."""

SPEC_UNKNOWN = 0
SPEC_GENERAL = 1
SPEC_ACCELERATION = 12
SPEC_FORCE = 13
SPEC_TIME = 17
SPEC_FREQUENCY = 18

POINT_NODES = {"A": 1, "B": 2, "C": 3, "D": 4}
"""Response node of the paper's measuring points A-D."""
OTHER_POINT_NODE_BASE = 10
"""Node of the k-th other point name (k = 1, 2, ...) is this + k."""
REFERENCE_NODE_BASE = 100
"""Reference (hammer) node of the i-th run (i = 1, 2, ...) is this + i."""

_AXIS_CODES = {"x": 1, "y": 2, "z": 3}
_FUNCTION_NAMES = {
    0: "general",
    1: "time response",
    2: "auto spectrum",
    3: "cross spectrum",
    4: "FRF",
    5: "transmissibility",
    6: "coherence",
    9: "PSD",
    12: "spectrum",
}
_SPEC_NAMES = {
    0: "unknown",
    1: "general",
    2: "stress",
    3: "strain",
    5: "temperature",
    6: "heat flux",
    8: "displacement",
    9: "reaction force",
    11: "velocity",
    12: "acceleration",
    13: "excitation force",
    15: "pressure",
    16: "mass",
    17: "time",
    18: "frequency",
    19: "rpm",
    20: "order",
}
_ACC_RE = re.compile(r"^acc_([A-Za-z0-9]+)_([xyz])$")
_ID_WIDTH = 80
_MARK = "guidefit"
_E13_5 = 5.000001e-6  # largest relative rounding error of an E13.5 field
_ACC_LABELS = {
    "": "m/s^2",
    "none": "m/s^2",
    "m/s^2": "m/s^2",
    "m/s2": "m/s^2",
    "m/s**2": "m/s^2",
    "m/s/s": "m/s^2",
    "ms^-2": "m/s^2",
    "g": "g",
}
_REFERENCE_FORCE_SPECS = (SPEC_UNKNOWN, SPEC_GENERAL, 9)  # unknown, general, reaction force
_FORCE_LABELS = {"": "N", "none": "N", "n": "N"}
_INSTALL_HINT = "needs the optional extra: pip install 'guidefit[uff]'"


# ----------------------------------------------------------------- numbering


def point_nodes(points: Iterable[str]) -> dict[str, int]:
    """UFF node of each measuring point name.

    A, B, C, D are nodes 1-4 (:data:`POINT_NODES`); the k-th other name
    (k = 1, 2, ..., in order of first appearance) is node 10 + k.

    Parameters
    ----------
    points : iterable of str
        Point names, repeats allowed (e.g. one per channel).

    Returns
    -------
    dict of str to int

    Raises
    ------
    RecordingError
        More than 89 other names (their nodes would reach the hammer's 101).

    Examples
    --------
    >>> point_nodes(["A", "C", "E", "A", "top"])
    {'A': 1, 'C': 3, 'E': 11, 'top': 12}
    """
    nodes: dict[str, int] = {}
    others = 0
    for point in points:
        if point in nodes:
            continue
        if point in POINT_NODES:
            nodes[point] = POINT_NODES[point]
            continue
        others += 1
        node = OTHER_POINT_NODE_BASE + others
        if node > REFERENCE_NODE_BASE:
            raise RecordingError(
                f"point '{point}': more than {REFERENCE_NODE_BASE - OTHER_POINT_NODE_BASE} "
                "point names besides A-D; their nodes would collide with the hammer's"
            )
        nodes[point] = node
    return nodes


def direction_code(direction, axis: str | None = None, where: str = "direction") -> int:
    """UFF direction code (+-1, +-2, +-3 for +-X, +-Y, +-Z) of a unit vector.

    Parameters
    ----------
    direction : array_like, shape (3,)
        Unit vector in the carriage frame.
    axis : {"x", "y", "z"}, optional
        The axis the vector must lie along (a channel's axis letter); by
        default its largest component.
    where : str
        Start of the error message (file, run, channel).

    Returns
    -------
    int

    Raises
    ------
    RecordingError
        The vector is not along ``axis`` (or any axis) within
        :data:`DIRECTION_TOLERANCE`.

    Examples
    --------
    >>> direction_code([0, -1, 0]), direction_code([1, 0, 0], "x"), direction_code([0, 0, -1], "z")
    (-2, 1, -3)
    """
    vec = np.asarray(direction, dtype=np.float64).reshape(3)
    k = "xyz".index(axis) if axis else int(np.argmax(np.abs(vec)))
    component = float(vec[k])
    if not abs(component) >= 1.0 - DIRECTION_TOLERANCE:
        along = f"the {axis} axis" if axis else "an axis"
        shown = ", ".join(f"{v:.6g}" for v in vec)
        raise RecordingError(
            f"{where}: ({shown}) is not along {along}; UFF-58 directions are +-X, +-Y, +-Z "
            f"(tolerance {DIRECTION_TOLERANCE:g})"
        )
    return (k + 1) if component > 0 else -(k + 1)


def direction_vector(code: int) -> np.ndarray:
    """Unit vector of a UFF translation direction code (inverse of :func:`direction_code`).

    Examples
    --------
    >>> direction_vector(-2).tolist()
    [0.0, -1.0, 0.0]
    """
    code = int(code)
    if abs(code) not in (1, 2, 3):
        raise ValueError(f"code={code}: expected a translation +-1, +-2 or +-3")
    vec = np.zeros(3)
    vec[abs(code) - 1] = 1.0 if code > 0 else -1.0
    return vec


def _pyuff(display: str):
    try:
        import pyuff
    except ImportError:
        raise RecordingError(f"{display}: UFF {_INSTALL_HINT}") from None
    return pyuff


_first_line = first_line  # the one helper, in guidefit.errors


def _check_suffix(display: str) -> None:
    suffix = Path(display).suffix.lower()
    if suffix not in UFF_SUFFIXES:
        raise RecordingError(
            f"{display}: unknown file type '{Path(display).suffix}'; a UFF file ends in .uff or .unv"
        )
