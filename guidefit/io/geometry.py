"""Default sensor geometry of a recording that gives channel names but no positions.

The CSV and UFF readers (and DAQ setups) place ``acc_<point>_<axis>`` at the
guide's measuring point and along +axis; the points come from the guide
catalogue (:func:`guidefit.model.guides.load_guide`), MRB35 by default.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from guidefit.errors import RecordingError

__all__ = ["default_channel_geometry", "default_points"]

_ACC_RE = re.compile(r"^acc_([A-Za-z0-9]+)_([xyz])\Z")
_AXES = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}

# Measuring points A-D of the MRB35 nominal model (physics notes, paper Figure 7).
_MRB35_POINTS_M = {
    "A": (0.030, 0.0, 0.045),
    "B": (-0.030, 0.0, 0.045),
    "C": (-0.030, 0.0, -0.045),
    "D": (0.030, 0.0, -0.045),
}

def default_points(guide_name: str | None = None) -> dict[str, np.ndarray]:
    """Default measuring points of a guide, for recordings that give no positions.

    Uses ``measuring_points_m`` of :func:`guidefit.model.guides.load_guide`
    when the guide defines points; otherwise the MRB35 layout of the nominal model:
    A (+0.030, 0, +0.045), B (-0.030, 0, +0.045), C (-0.030, 0, -0.045),
    D (+0.030, 0, -0.045) m.

    Parameters
    ----------
    guide_name : str or None
        Catalogue name (``"MRB35"``) or guide TOML path; None means MRB35.

    Returns
    -------
    dict of str to ndarray, shape (3,)
        Point name -> position in the carriage frame, m.

    Raises
    ------
    GuideError
        The guide catalogue exists but does not know ``guide_name``.

    Examples
    --------
    >>> pts = default_points()
    >>> sorted(pts), pts["A"].tolist()
    (['A', 'B', 'C', 'D'], [0.03, 0.0, 0.045])
    """
    from guidefit.model.guides import load_guide

    guide = load_guide(guide_name or "MRB35")
    points = getattr(guide, "measuring_points_m", None)
    if points:
        return {str(k): np.asarray(v, dtype=np.float64).reshape(3) for k, v in points.items()}
    return {k: np.array(v) for k, v in _MRB35_POINTS_M.items()}


def default_channel_geometry(
    channel_names: Sequence[str],
    excitation_direction,
    excitation_position_m=None,
    guide: str | None = None,
    points: Mapping[str, Any] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Positions and directions of channels from their names (the CSV defaults).

    ``acc_<point>_<axis>`` sits at the guide's default point (see
    :func:`default_points`) and points along +axis; ``force`` sits at
    ``excitation_position_m`` (the origin if None) and points along
    ``excitation_direction``.

    Parameters
    ----------
    channel_names : sequence of str
    excitation_direction : array_like, shape (3,)
    excitation_position_m : array_like, shape (3,), optional
    guide : str, optional
        Guide whose default points to use (None: MRB35).
    points : mapping, optional
        Point name -> position, m; overrides the guide's points.

    Returns
    -------
    positions_m, directions : ndarray, shape (n_channels, 3)

    Raises
    ------
    RecordingError
        A channel name does not follow the convention or names an unknown point.

    Examples
    --------
    >>> pos, dirs = default_channel_geometry(["force", "acc_B_x"], [0, -1, 0])
    >>> pos.tolist(), dirs.tolist()
    ([[0.0, 0.0, 0.0], [-0.03, 0.0, 0.045]], [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0]])
    """
    pts = (
        None if points is None else {k: np.asarray(v, float).reshape(3) for k, v in points.items()}
    )
    positions, directions = [], []
    for name in channel_names:
        if name == "force":
            pos = (
                np.zeros(3)
                if excitation_position_m is None
                else np.asarray(excitation_position_m, float)
            )
            positions.append(pos.reshape(3))
            directions.append(np.asarray(excitation_direction, float).reshape(3))
            continue
        match = _ACC_RE.match(name)
        if not match:
            raise RecordingError(
                f"channel '{name}' not recognised; expected 'force' or 'acc_<point>_<axis>' with axis x, y or z"
            )
        if pts is None:
            pts = default_points(guide)
        point, axis = match.groups()
        if point not in pts:
            raise RecordingError(
                f"channel '{name}': point '{point}' has no default position for guide "
                f"{guide or 'MRB35'} (known: {', '.join(sorted(pts))}); give positions_m"
            )
        positions.append(pts[point])
        directions.append(np.array(_AXES[axis]))
    return np.array(positions, dtype=float).reshape(-1, 3), np.array(
        directions, dtype=float
    ).reshape(-1, 3)


# --------------------------------------------------------------------- reading

