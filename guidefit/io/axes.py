"""Axis maps: a file's (machine) axes X, Y, Z and guidefit's carriage axes x, y, z.

One syntax, one meaning, for ``export --axis-map`` (output) and the input
``--axis-map`` of identify, explain, report, frf and plan:
``x=X,y=Z,z=-Y`` says that guidefit's x (lateral) is the other frame's +X, its
y (vertical) the other frame's +Z and its z (along the rail) the other
frame's -Y. It must be a proper rotation (no mirror image).

:func:`parse_axis_map` gives R with ``other = R @ guidefit``. On input
(:func:`input_axes`), every position, sensor direction and hammer direction
a reader gives is turned into guidefit's frame (``guidefit = R.T @ file``)
and each ``acc_<point>_<axis>`` channel is renamed after its new axis
(``acc_A_z`` of a z-up file becomes ``acc_A_y``).
"""

from __future__ import annotations

import contextlib
import re
from dataclasses import replace

import numpy as np

from guidefit.errors import RecordingError

__all__ = ["MACHINE_FRAME_HINT", "frame_hint", "input_axes", "map_frf_file", "map_recording", "parse_axis_map"]

#: the map of the usual machine frame (z up), suggested when a file's data fit it
MACHINE_FRAME_MAP = "x=X,y=Z,z=-Y"
MACHINE_FRAME_HINT = (f"the file's axes may be a machine frame (z up); try --axis-map {MACHINE_FRAME_MAP} "
                      "(guidefit: x lateral, y vertical, z along the rail)")
_ACC_RE = re.compile(r"^(acc_[A-Za-z0-9]+_)([xyz])\Z")
_current: list = [None]  # the input axis map in force (a module global: forked --jobs workers inherit it)
_active: list = [None]  # the map of the top-level read in progress (readers that apply it themselves)
#: suffixes whose readers apply the map themselves (they know which positions the file gives)
SELF_MAPPING = (".uff", ".unv")
#: suffixes whose every position and direction is in the file (the map turns them all)
EXPLICIT = (".h5", ".hdf5")


def _safe(text: str, n: int) -> str:
    shown = "".join(c if c.isprintable() else "?" for c in str(text))
    return shown if len(shown) <= n else shown[: n - 3] + "..."


def parse_axis_map(text: str | None, error=RecordingError, option: str = "--axis-map") -> np.ndarray:
    """``"x=X,y=Z,z=-Y"`` -> R (3x3) with other-frame vector = R @ guidefit vector; a proper rotation.

    Parameters
    ----------
    text : str or None
        None or empty: the identity.
    error : type
        The exception class raised (a :class:`~guidefit.errors.GuidefitError`: exit 2).
    option : str
        The option name that starts the message.

    Examples
    --------
    >>> parse_axis_map("x=X,y=Z,z=-Y") @ [0.0, 1.0, 0.0]   # guidefit's vertical is the other frame's +Z
    array([0., 0., 1.])
    """
    if text is None or not text.strip():
        return np.eye(3)
    rot = np.zeros((3, 3))
    seen = set()
    for item in text.split(","):
        key, eq, target = (s.strip() for s in item.partition("="))
        key, target_up = key.lower(), target.upper()
        sign = -1.0 if target_up.startswith("-") else 1.0
        axis = target_up.lstrip("+-")
        if not eq or key not in ("x", "y", "z") or axis not in ("X", "Y", "Z") or len(target_up.lstrip("+-")) != 1 \
                or len(target_up) - len(axis) > 1 or key in seen:
            raise error(f"{option}: '{_safe(item, 40)}': use x=AXIS,y=AXIS,z=AXIS with AXIS one of "
                        "X, Y, Z, -X, -Y, -Z (e.g. x=X,y=Z,z=-Y)")
        seen.add(key)
        rot["XYZ".index(axis), "xyz".index(key)] = sign
    if len(seen) != 3 or not np.allclose(rot @ rot.T, np.eye(3)):
        raise error(f"{option} '{_safe(text, 40)}': give each of x, y, z exactly one distinct machine axis")
    if np.linalg.det(rot) < 0:
        raise error(f"{option} '{_safe(text, 40)}' is a mirror image (left-handed); flip the sign of one axis")
    return rot


@contextlib.contextmanager
def input_axes(rot):
    """Within the block, :func:`guidefit.io.read_recording` and
    :func:`guidefit.io.frf_files.read_input` turn what they read into guidefit's
    frame with ``rot`` (from :func:`parse_axis_map`; None or the identity: as read)."""
    rot = None if rot is None or np.allclose(rot, np.eye(3)) else np.asarray(rot, float)
    before = _current[0]
    _current[0] = rot
    try:
        yield
    finally:
        _current[0] = before


@contextlib.contextmanager
def reading():
    """The input map in force for a top-level read (None inside: a reader that reads another file
    through the registry gets it as it is, and the top-level call turns it once)."""
    rot = _current[0]
    active = _active[0]
    _current[0] = None
    _active[0] = rot
    try:
        yield rot
    finally:
        _current[0] = rot
        _active[0] = active


def active() -> np.ndarray | None:
    """The input axis map of the top-level read in progress (for the UFF readers), None if none."""
    return _active[0]


def in_force() -> bool:
    """Whether an input axis map is in force (:func:`input_axes`)."""
    return _current[0] is not None or _active[0] is not None


def map_input(obj, rot, display: str):
    """A read recording or FRF file in guidefit's frame: UFF readers have turned it already, HDF5
    (every position and direction in the file) is turned here, other formats are refused.

    Raises
    ------
    RecordingError
        ``rot`` given for a CSV, a test setup or a DAQ file: their positions may be the guide's
        defaults, already in guidefit's frame (a setup gives its channels' directions itself).
    """
    if rot is None:
        return obj
    from pathlib import Path

    suffix = Path(display).suffix.lower()
    if suffix in SELF_MAPPING:
        return obj
    if suffix not in EXPLICIT:
        raise RecordingError(f"{display}: --axis-map applies to UFF, frf.h5 and HDF5 recordings; a CSV, a test "
                             "setup or a DAQ file gives its channels' directions itself (a setup's [channels] "
                             "direction, a CSV's '# directions:' line)")
    return map_frf_file(obj, rot) if hasattr(obj, "frfsets") else map_recording(obj, rot)


def turn_code(code: int, rot: np.ndarray | None) -> int:
    """A direction code (+-1..3) of the file's axes as guidefit's (``guidefit = R.T @ file``); 0 as is."""
    if rot is None or abs(int(code)) not in (1, 2, 3):
        return int(code)
    vec = rot.T[:, abs(int(code)) - 1] * np.sign(code)
    k = int(np.argmax(np.abs(vec)))
    return (k + 1) * int(np.sign(vec[k]))


def renamed(name: str, rot: np.ndarray) -> str:
    """``acc_<point>_<axis>`` after the file's axis letter, turned into guidefit's (``force`` as is)."""
    match = _ACC_RE.match(name)
    if not match:
        return name
    file_axis = np.zeros(3)
    file_axis["xyz".index(match.group(2))] = 1.0
    return match.group(1) + "xyz"[int(np.argmax(np.abs(rot.T @ file_axis)))]


def _run(run, rot: np.ndarray):
    def turn(v):
        if v is None:
            return None
        out = rot.T @ np.asarray(v, float)
        out.flags.writeable = False
        return out

    channels = tuple(replace(ch, name=renamed(ch.name, rot), position_m=turn(ch.position_m),
                             direction=turn(ch.direction)) for ch in run.channels)
    return replace(run, channels=channels, excitation_direction=turn(run.excitation_direction),
                   excitation_position_m=turn(run.excitation_position_m))


def map_recording(recording, rot):
    """The recording (metadata: channels, hit points, directions) in guidefit's frame; samples as they are."""
    if rot is None:
        return recording
    return replace(recording, runs=tuple(_run(run, rot) for run in recording.runs))


def map_frf_file(frf_file, rot):
    """An :class:`~guidefit.io.frf_files.FrfFile` in guidefit's frame: its runs and its FRFs' channel names."""
    if rot is None:
        return frf_file
    sets = tuple(replace(s, channels=tuple(renamed(c, rot) for c in s.channels)) for s in frf_file.frfsets)
    notes = (*frf_file.notes, "axes mapped into guidefit's frame by --axis-map")
    return replace(frf_file, recording=map_recording(frf_file.recording, rot), frfsets=sets, notes=notes)


#: a direction counts as along an axis when its component there exceeds this
ALONG_AXIS = 0.9


def frame_hint(recording) -> str:
    """``"; the file's axes may be a machine frame ..."`` when the joint modes were not found and the
    file looks like one (z up): a hammer along z, or most sensors along z (guidefit's rail axis, along
    which a carriage's joint modes are barely read); "" otherwise, and when an axis map is in force."""
    if in_force():
        return ""
    sensors = [abs(float(ch.direction[2])) > ALONG_AXIS for r in recording.runs
               for i, ch in enumerate(r.channels) if i != r.force_index]
    hammer = any(abs(float(r.excitation_direction[2])) > ALONG_AXIS for r in recording.runs)
    return f"; {MACHINE_FRAME_HINT}" if hammer or 2 * sum(sensors) > len(sensors) else ""
