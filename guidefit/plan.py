"""Pre-test planning: the model's modes as a planned hammer test will see them (``guidefit plan``).

For a layout (a test setup, a recording's geometry, or a ``--sensors`` layout
with ``--hit`` points) :func:`make_plan` reports, from
:func:`guidefit.modes.labels.layout_view` (the labeller's own computation, not a
copy of it):

* per run, how strongly its hit excites each model mode (``|g . phi|``, the
  participation of the mass-normalised mode at the hit point) and how large
  the readings of its sensors are;
* the auto-MAC of the model modes on these sensors (all runs stacked): two
  modes with a MAC near 1 look alike to this test;
* per label, what will decide it: ``shape``, ``frequency`` only,
  ``shape+frequency``, ``ambiguous`` or ``not seen``;
* the best hit points and sensor layout among the guide's points for telling
  all five modes apart by shape (:func:`best_layout`).

Examples
--------
>>> from guidefit.model.guides import load_guide
>>> p = make_plan(load_guide("MRB35"), layout_runs(load_guide("MRB35"), "default"))
>>> p.basis["vertical"]
'shape'
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from guidefit.modes import labels as lab_mod


@dataclass(frozen=True)
class PlanRun:
    """A planned run: its accelerometers (guidefit.modes.labels.Sensor) and its hit."""

    name: str
    sensors: tuple
    excitation_direction: tuple
    excitation_position_m: tuple | None

    def view(self) -> lab_mod.RunView:
        return lab_mod.RunView(self.sensors, self.excitation_direction, self.excitation_position_m)


@dataclass(frozen=True)
class Plan:
    """What a layout will tell (see the module docstring)."""

    guide: str
    runs: tuple  # PlanRun
    view: lab_mod.LayoutView
    basis: dict  # label -> "shape" | "frequency" | "shape+frequency" | "ambiguous" | "not seen"
    notes: dict  # label -> sentence
    best: dict | None  # {"layout", "hits", "decided_by_shape", "basis"} or None

    def to_dict(self) -> dict:
        v = self.view
        return {
            "guide": self.guide,
            "runs": [{"name": r.name, "excitation_direction": list(r.excitation_direction),
                      "excitation_position_m": None if r.excitation_position_m is None
                      else list(r.excitation_position_m),
                      "sensors": [{"name": s.name, "position_m": list(s.position_m), "direction": list(s.direction)}
                                  for s in r.sensors]} for r in self.runs],
            "modes": [{"label": lab, "frequency_hz": v.frequencies_hz[i], "visible": v.visible[i],
                       "label_basis": self.basis[lab], "note": self.notes[lab],
                       "participation": {r: None if p is None else float(p[i]) for r, p in v.participation.items()},
                       "readings": {r: float(x[i]) for r, x in v.readings.items()}}
                      for i, lab in enumerate(v.labels)],
            "auto_mac": {"labels": list(v.labels), "matrix": [[float(x) for x in row] for row in v.auto_mac]},
            "decided_by_shape": [lab for i, lab in enumerate(v.labels) if _by_shape(v, i)],
            "best": self.best,
        }


def _basis_and_notes(view: lab_mod.LayoutView) -> tuple[dict, dict]:
    basis, notes = {}, {}
    for i, lab in enumerate(view.labels):
        d = view.decided[i]
        if d is None:
            basis[lab] = "not seen"
            notes[lab] = "no run both excites it at its hit point and reads it at its sensors"
        elif d.label != lab:
            basis[lab] = "ambiguous"
            notes[lab] = d.note
        else:
            basis[lab] = d.basis
            notes[lab] = d.note
    return basis, notes


def make_plan(guide, runs: list[PlanRun], search: bool = False) -> Plan:
    """The plan of a layout (``search``: also look for the best layout among the guide's points)."""
    from guidefit.model import vibration as vib

    model = vib.solve_modes(vib.model_from_guide(guide))
    view = lab_mod.layout_view(model, {r.name: r.view() for r in runs})
    basis, notes = _basis_and_notes(view)
    best = best_layout(guide, runs, model) if search else None
    return Plan(guide.name, tuple(runs), view, basis, notes, best)


def _by_shape(view: lab_mod.LayoutView, i: int) -> bool:
    d = view.decided[i]
    return d is not None and d.label == view.labels[i] and d.by_shape


def shape_score(view: lab_mod.LayoutView) -> tuple:
    """Ranks layouts: labels the shape alone decides, then labels seen, then the smallest shape margin."""
    shaped = [view.decided[i] for i in range(len(view.labels)) if _by_shape(view, i)]
    margin = min((min(d.shape_margin, 50.0) for d in shaped), default=0.0)
    return (len(shaped), sum(view.visible), margin)


# --------------------------------------------------------------------------- layouts


def layout_runs(guide, layout: str = "default", hits: dict | None = None, run_names=None) -> list[PlanRun]:
    """PlanRuns of a ``--sensors`` layout (:func:`guidefit.simulate.layouts.resolve_layout`) on the simulator's
    default runs, hit points moved by ``hits`` (run -> (x, y, z))."""
    from guidefit.simulate import layouts

    runs = [r for r in layouts.DEFAULT_RUNS if run_names is None or r.name in run_names]
    if hits:
        runs = list(layouts.apply_hits(tuple(runs), list(hits.items())))
    sensors = layouts.resolve_layout(guide, layout, tuple(runs))
    return [PlanRun(r.name, tuple(lab_mod.Sensor(s.name, tuple(s.position_m), tuple(s.direction))
                                  for s in sensors[r.name]),
                    tuple(r.direction), tuple(r.position_m)) for r in runs]


def setup_runs(path) -> tuple[str | None, list[PlanRun]]:
    """The guide name and PlanRuns of a test setup TOML (its DAQ files need not exist yet)."""
    from guidefit.io import setup as setup_mod

    s = setup_mod.load_setup(path, planning=True)
    out = []
    for run in s.runs:
        names = run.channels or tuple(n for n in s.channels if n != "force")
        chans = [s.channels[n] for n in names if n != "force"]
        positions, directions = setup_mod._geometry(s, run, chans)
        out.append(PlanRun(run.name, tuple(lab_mod.Sensor(c.name, tuple(map(float, p)), tuple(map(float, d)))
                                           for c, p, d in zip(chans, positions, directions)),
                           tuple(map(float, run.excitation_direction)),
                           None if run.excitation_position_m is None else tuple(map(float, run.excitation_position_m))))
    return s.guide, out


def recording_runs(recording) -> list[PlanRun]:
    """PlanRuns of a recording's geometry (no samples are used).

    The hit point is the run's ``hit_position_m`` (``excitation_position_m``, else the force channel's
    position), as identify's labels use it: a file without ``excitation_position_m`` was planned with
    the hit point unknown (no participation) though its force channel gives it.
    """
    out = []
    for run in recording.runs:
        accs = [ch for ch in run.channels if ch.name != "force"]
        hit = run.hit_position_m
        out.append(PlanRun(run.name, tuple(lab_mod.Sensor(c.name, tuple(map(float, c.position_m)),
                                                          tuple(map(float, c.direction))) for c in accs),
                           tuple(map(float, run.excitation_direction)),
                           None if hit is None else tuple(map(float, hit))))
    return out


#: layouts tried by :func:`best_layout` (guidefit.simulate.layouts names)
SEARCH_LAYOUTS = ("default", "pair", "side", "both", "triax:A,C")


def _hit_candidates(guide, run: PlanRun) -> list[tuple]:
    """Hit points on the run's face: its own, and the guide's points moved onto that face."""
    d = np.asarray(run.excitation_direction, float)
    axis = int(np.argmax(np.abs(d)))
    here = run.excitation_position_m
    face = 0.0 if here is None else float(here[axis])
    out = [] if here is None else [tuple(float(x) for x in here)]
    for p in guide.measuring_points_m.values():
        q = [float(x) for x in p]
        q[axis] = face
        if here is not None and axis == 0:
            q[1] = float(here[1])  # a side face: keep the hit's height below the top face
        t = tuple(round(x, 6) for x in q)
        if t not in out:
            out.append(t)
    return out


def best_layout(guide, runs: list[PlanRun], model) -> dict:
    """The hit points (per run, among :func:`_hit_candidates`) and the layout (among
    :data:`SEARCH_LAYOUTS`) that decide most labels by shape: each run's hit chosen with the current
    sensors, then each layout with those hits."""
    import itertools

    from guidefit.errors import GuidefitError

    names = [r.name for r in runs]
    cands = [_hit_candidates(guide, r) for r in runs]
    best_hits, best_score = None, None
    for combo in itertools.product(*cands):
        trial = [PlanRun(r.name, r.sensors, r.excitation_direction, h) for r, h in zip(runs, combo)]
        score = shape_score(lab_mod.layout_view(model, {t.name: t.view() for t in trial}))
        if best_score is None or score > best_score:
            best_hits, best_score = combo, score
    hits = dict(zip(names, best_hits))
    budget = max((len(r.sensors) for r in runs), default=0)  # the DAQ's accelerometer channels per run
    rows = []
    for layout in SEARCH_LAYOUTS:
        try:
            trial = layout_runs(guide, layout, hits=None, run_names=names)
        except GuidefitError:  # a layout the guide cannot give (no side points, say)
            continue
        trial = [PlanRun(t.name, t.sensors, r.excitation_direction, hits[r.name]) for t, r in zip(trial, runs)]
        view = lab_mod.layout_view(model, {t.name: t.view() for t in trial})
        rows.append((shape_score(view), layout, max(len(t.sensors) for t in trial)))
    own = [PlanRun(r.name, r.sensors, r.excitation_direction, hits[r.name]) for r in runs]
    rows.append((shape_score(lab_mod.layout_view(model, {r.name: r.view() for r in own})), "(as planned)", budget))
    rows.sort(key=lambda t: (-t[0][0], -t[0][1], -t[0][2], t[2]))
    fits = [r for r in rows if r[2] <= budget] or rows
    score, layout, width = fits[0]
    return {"layout": layout, "hits": {k: list(v) for k, v in hits.items()}, "decided_by_shape": int(score[0]),
            "seen": int(score[1]), "sensors_per_run": int(width), "budget_sensors_per_run": int(budget),
            "layouts": [{"layout": lay, "decided_by_shape": int(sc[0]), "seen": int(sc[1]), "sensors_per_run": int(w)}
                        for sc, lay, w in rows]}


def plan(source=None, guide=None, layout: str | None = None, hits: dict | None = None, search: bool = True) -> Plan:
    """The plan of a test setup TOML, of a recording's geometry, or of a ``--sensors`` layout.

    Parameters
    ----------
    source : path, optional
        A test setup ``.toml`` (its DAQ files need not exist) or a recording;
        None: the ``layout`` on the simulator's default runs.
    guide : str, Path or Guide, optional
        Default: the one the source names, else MRB35.
    layout : str, optional
        A :mod:`guidefit.simulate.layouts` layout (``default``, ``both``, ``triax:A,C``,
        ``side``, ``pair``, ``single`` or a TOML file); not with ``source``.
    hits : dict, optional
        run -> hit point (m) moved from the default (``--hit``).
    search : bool
        Also search the best hit points and layout (:func:`best_layout`).
    """
    from guidefit.errors import ModelError
    from guidefit.model.guides import Guide, load_guide

    named = None
    if source is not None:
        if layout is not None:
            raise ModelError("plan: give a setup or recording, or --sensors, not both")
        if str(source).lower().endswith(".toml"):
            named, runs = setup_runs(source)
        else:
            from guidefit.io.registry import read_recording

            rec = read_recording(source)
            named, runs = rec.guide, recording_runs(rec)
        if hits:
            unknown = [r for r in hits if r not in {x.name for x in runs}]
            if unknown:
                raise ModelError(f"--hit: run '{unknown[0]}' not in {source} (have "
                                 f"{', '.join(x.name for x in runs)})")
            runs = [PlanRun(r.name, r.sensors, r.excitation_direction, tuple(hits.get(r.name, r.excitation_position_m)))
                    if r.name in hits else r for r in runs]
    if not isinstance(guide, Guide):
        guide = load_guide(guide or named or "MRB35")
    if source is None:
        runs = layout_runs(guide, layout or "default", hits)
    return make_plan(guide, runs, search=search)
