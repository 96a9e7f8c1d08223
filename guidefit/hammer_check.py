r"""Whether a run's modes are ones its declared hammer direction can excite.

A hit drives mode ``i`` in proportion to ``g . phi_i`` (``g``: the hammer's
direction through the rigid-body map at the hit point,
:func:`guidefit.modes.labels.driving_row`), and its sensors read it as
``S phi_i`` whatever the hammer. So a run's strong measured mode whose shape
at its sensors is model mode ``i``'s (MAC >= :data:`~guidefit.modes.labels.SCALE_MAC`,
every model mode tied with it on MAC included), while the declared hammer
drives mode ``i`` with less than :data:`MAX_DRIVE` of the run's best-driven
mode's predicted readings, is one the declared excitation cannot give. When
such modes carry most of the run (:data:`CONTRADICTED_SHARE`) and a hit
along one of the carriage's axes at the same point would excite nearly all
of it (:data:`OTHER_AXIS_SHARE`), the data say the hammer hit along another
axis (a test setup's ``excitation_direction`` entered as x for a vertical
hit); a few such modes beside the run's own are a rig effect (a corner mass
makes a lateral hit drive the vertical mode too), not a wrong direction. The labeller and the set-up's expected
modes (:func:`guidefit.consistency.observable_modes`) both trust the
declared direction, so without this the vertical mode of a vertical run
declared along x is "not excited on this layout", K_V null and exit 0.

A reversed sign (``-y`` entered as ``+y``) changes no mode's drive, only the
sign of every modal constant of the run: the labeller reads each run at its
own sign and the run-scale warning names it; K and c do not depend on it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

#: a model mode whose predicted readings in a run are below this fraction of the run's best-driven mode's is
#: one the declared hammer cannot excite
MAX_DRIVE = 0.01
#: a measured mode at least this fraction of its run's strongest (modal-constant norm) is strong
STRONG = 0.1
#: the declared direction is contradicted when modes it cannot excite carry more than this share of the run's
#: strong, model-like modes (sum of squared modal-constant norms) ...
CONTRADICTED_SHARE = 0.5
#: ... while a hit along one of the carriage axes at the same point leaves less than this share unexplained
#: (a rig effect, a corner mass, makes a lateral hit drive the vertical mode too: a minority of the run)
OTHER_AXIS_SHARE = 0.1


def contradicted_modes(s, model, driving=None) -> tuple[list[tuple[float, tuple]], float]:
    """The strong modes of run ``s`` (a :class:`guidefit.consistency.ShapeSet`) whose shape at its sensors
    is a model mode the hammer row ``driving`` (default: the declared one, ``s.driving``) cannot excite,
    as (frequency, model labels), and their share of the run's strong model-like modes (0 when there are
    none, or the hit point is unknown)."""
    from guidefit.modes.labels import SCALE_MAC, SCALE_MAC_TIE

    driving = s.driving if driving is None else driving
    if driving is None or not s.shapes.size:
        return [], 0.0
    phi = np.asarray(model.shapes)[:5]
    P = (s.sensors @ phi).T  # (model modes, channels): what the sensors read of each mode, any hammer
    pp = np.einsum("ij,ij->i", P, P)
    seen = pp > 1e-6 * float(pp.max(initial=0.0))
    drive = np.sqrt(pp) * np.abs(driving @ phi)  # size of each mode's predicted constants in this run
    top_drive = float(drive[seen].max(initial=0.0))
    norms = np.linalg.norm(s.shapes, axis=1)
    out, bad, total = [], 0.0, 0.0
    for f, m, size in zip(s.frequencies_hz, s.shapes, norms):
        if size < STRONG * float(norms.max()) or not np.any(seen):
            continue
        mac = np.where(seen, (P @ m) ** 2 / (np.where(seen, pp, 1.0) * size**2), 0.0)
        best = float(mac.max())
        if best < SCALE_MAC:
            continue
        total += float(size) ** 2
        tied = np.flatnonzero(mac >= best - SCALE_MAC_TIE)
        if np.all(drive[tied] <= MAX_DRIVE * top_drive):
            out.append((float(f), tuple(model.labels[i] for i in tied)))
            bad += float(size) ** 2
    return out, (bad / total if total > 0 else 0.0)


def hammer_lines(sets, model, recording=None) -> tuple[dict, dict]:
    """(contradicted, any): run name -> one line for each run whose strong modes contradict its declared
    hammer direction (:func:`contradicted_modes`: more than :data:`CONTRADICTED_SHARE` of them, while a hit
    along a carriage axis at the same point leaves less than :data:`OTHER_AXIS_SHARE`), and the same line for
    every run with any such mode that a hit along another axis would explain better (added to a rejected or
    incomplete identification's line: a hint, not a verdict)."""
    from guidefit.consistency import vector_text
    from guidefit.modes.labels import driving_row

    runs = {r.name: r for r in getattr(recording, "runs", ())}
    setup = str(getattr(recording, "path", "")).lower().endswith(".toml")
    strong, weak = {}, {}
    for s in sets:
        bad, share = contradicted_modes(s, model)
        if not bad:
            continue
        run = runs.get(s.run)
        hit = getattr(run, "hit_position_m", None)
        others = [contradicted_modes(s, model, driving_row(axis, hit))[1] for axis in np.eye(3)] if hit is not None else []
        direction = vector_text(run.excitation_direction) if run is not None else "?"
        where = (f"runs.{s.run}.excitation_direction in {Path(recording.path).name}" if setup
                 else f"the excitation_direction of run '{s.run}'")
        modes = ", ".join(f"{f:.0f} Hz ({'/'.join(labels)})" for f, labels in bad)
        line = (f"run '{s.run}': its strong modes at {modes} by their shape at its sensors are modes a hit "
                f"along the declared excitation_direction {direction} cannot excite: the hammer direction may "
                f"be entered wrong ({where})")
        if others and min(others) < share - 1e-9:  # a hit along another axis explains the run better
            weak[s.run] = line
            if share > CONTRADICTED_SHARE and min(others) < OTHER_AXIS_SHARE:
                strong[s.run] = line
    return strong, weak

