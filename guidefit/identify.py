r"""From a hammer recording to K_V, K_H, c_V, c_H (the paper's Eq. 24-29).

Pipeline (:func:`identify`), one straight sequence of stages that take
values and return values, warnings inside their results:

1. recording -> hits -> FRFs (:func:`frf_stage`): per run, hits
   (:mod:`guidefit.hits`) streamed into averaged FRFs of every response
   channel (:mod:`guidefit.frf`), up to :func:`frf_top_hz`; or the FRFs of
   an FRF file.
2. modal fit, shapes and labels (:func:`modal_fit`): one modal model of all
   runs (:func:`guidefit.modal_stage.identify_frfs`: poly-reference LSCF
   stabilisation diagram, pole selection by stability, global
   variable-projection fit with shared poles, :mod:`guidefit.modes.globalfit`),
   each mode's modal constants of every run assembled into one rigid-body
   motion of the carriage and labelled (:mod:`guidefit.modes.labels`); ambiguous
   labels are reported, not assigned; every run's own estimate is kept
   (``estimates``). Declared refit: harder force levels whose modes move
   are fitted apart.
3. sensor check (:func:`sensor_check`, :mod:`guidefit.consistency`): a
   channel that does not fit rigid motion is named; declared refit: the
   corrected FRFs re-enter at the FRF stage (:func:`corrected_frfs`) and
   the fit is made again.
4. run results and force levels (:func:`run_results`).
5. parameters, gate, result (:func:`conclude`).

:func:`per_run_fits` is a diagnostic beside the pipeline: each run's FRFs
fitted on their own (the per-run curve fits identify used before the
global fit).

The joint parameters follow the paper's single-DOF reading of the vertical
and horizontal (``roll_low``) modes, with M the carriage mass of the guide:

* Eq. (24), (25): ``K = 4 pi^2 M f^2`` (:func:`stiffness_from_frequency`)
* Eq. (26), (28): ``xi = (f2 - f1) / (2 f)`` (:func:`guidefit.modes.half_power`)
* Eq. (27), (29): ``c = 4 pi M f xi`` (:func:`damping_from_frequency`)

``f`` is the undamped natural frequency |p|/2pi of the fit and ``xi``
its viscous damping ratio; the half-power values are reported beside them.
Uncertainties (one standard deviation) combine the fit's own standard error,
the delete-a-group jackknife over hits and (global fit) the spread over
pole selection.

Examples
--------
>>> round(stiffness_from_frequency(2.2, 3450.0) / 1e9, 3)
1.034
>>> round(damping_from_frequency(2.2, 3450.0, 0.0288))
2747
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from guidefit.errors import IdentificationError, identification_failure
from guidefit.identify_runs import (
    _excitation_warnings,
    _force_levels,
    _frequency_scale_warnings,
    _hit_row,
    _quality_warnings,
    amplitude_dependence,
    dead_channel_warnings,
    frf_channels,
)
from guidefit.model.vibration import JOINT_LABELS, UNNAMED_LABELS  # noqa: F401 - guidefit.identify.UNNAMED_LABELS
from guidefit.modes.shapes import IdentifiedMode  # noqa: F401 - guidefit.identify.IdentifiedMode

# --------------------------------------------------------------------------- Eq. (24)-(29)


def stiffness_from_frequency(mass_kg: float, frequency_hz: float) -> float:
    """Joint stiffness K = 4 pi^2 M f^2 (N/m), Eq. (24) vertical and Eq. (25) horizontal."""
    return 4.0 * math.pi**2 * mass_kg * frequency_hz**2


def damping_from_frequency(mass_kg: float, frequency_hz: float, damping_ratio: float) -> float:
    """Joint damping c = 4 pi M f xi (N s/m), Eq. (27) vertical and Eq. (29) horizontal."""
    return 4.0 * math.pi * mass_kg * frequency_hz * damping_ratio


def joint_parameters(mass_kg: float, modes: dict) -> dict:
    """The contract's ``parameters`` from the vertical and roll_low modes.

    ``modes`` maps "V"/"H" to an :class:`IdentifiedMode` (or None). Standard
    deviations propagate linearly: std_K = 2 K std_f / f;
    std_c / c = sqrt((std_f/f)^2 + (std_xi/xi)^2).
    """
    out: dict = {}
    for key in ("V", "H"):
        mode = modes.get(key)
        if mode is None:
            for name, unit in ((f"f_{key}", "Hz"), (f"zeta_{key}", "1"), (f"K_{key}", "N/m"), (f"c_{key}", "N*s/m")):
                out[name] = {"value": None, "unit": unit, "std": None}
            continue
        f, zeta = mode.frequency_hz, mode.damping_ratio
        sf, sz = mode.frequency_std_hz, mode.damping_std
        k = stiffness_from_frequency(mass_kg, f)
        c = damping_from_frequency(mass_kg, f, zeta)
        rel_f = sf / f if sf is not None else None
        rel_z = sz / zeta if (sz is not None and zeta > 0) else None
        out[f"f_{key}"] = {"value": f, "unit": "Hz", "std": sf}
        out[f"zeta_{key}"] = {"value": zeta, "unit": "1", "std": sz}
        out[f"K_{key}"] = {"value": k, "unit": "N/m", "std": None if rel_f is None else 2 * k * rel_f}
        std_c = None
        if rel_f is not None and rel_z is not None:
            std_c = c * math.hypot(rel_f, rel_z)
        out[f"c_{key}"] = {"value": c, "unit": "N*s/m", "std": std_c}
    return out


# --------------------------------------------------------------------------- results


@dataclass(frozen=True)
class IdentifySettings:
    """Options of :func:`identify`; ``None`` means chosen from the data."""

    estimator: str = "H1"
    window: object = None  # guidefit.frf.WindowSettings
    fft_precision: str = "auto"  # "auto" (that of the stored samples), "single" or "double"
    hits: object = None  # guidefit.hits.HitSettings
    f_min_hz: float | None = None
    f_max_hz: float | None = None
    min_coherence: float = 0.9
    min_accepted_hits: int = 3
    jackknife: bool = True
    force_levels: bool = False  # per force-level frequencies (for explain's amplitude_dependence)
    force_bins: int = 3
    min_force_ratio: float = 1.5
    method: str = "global"  # one modal model of all runs (guidefit.modes.globalfit); the only method

    def __post_init__(self):
        if self.method == "per_run":
            raise ValueError("IdentifySettings(method='per_run') is gone: identify fits one modal model of all "
                             "runs; the per-run fits are the diagnostic guidefit.identify.per_run_fits(path)")
        if self.method != "global":
            raise ValueError(f"IdentifySettings.method must be 'global', got {self.method!r}")


@dataclass(frozen=True)
class RunResult:
    """One run's FRFs, hit table and fitted modes."""

    name: str
    frf: object  # guidefit.frf.FrfSet
    hits: list
    modes: list
    excitation_direction: tuple
    channels: list  # guidefit.io.Channel of the responses, in FRF order
    force_levels: list = field(default_factory=list)


@dataclass(frozen=True)
class Identification:
    """The result of :func:`identify` for one recording."""

    file: str
    guide: object
    runs: tuple
    modes: tuple
    parameters: dict
    warnings: tuple
    extra_modes: tuple = ()
    missing_modes: tuple = ()
    failed_run_hits: tuple = ()  # hit rows of runs that gave no FRF (every hit rejected)
    hits_checked: bool = True  # False: identified from an FRF file (no time data, no hit checks)
    modal: object = field(default=None, repr=False, compare=False)  # guidefit.modal_stage.ModalResult
    gate: str | None = None  # why the modes are not those of a carriage on this guide (no joint parameters)
    sensor_faults: tuple = ()  # guidefit.consistency.SensorFault of channels that do not fit rigid motion
    #: why a joint parameter the set-up should have given is missing (its mode excited and seen, yet not found
    #: or not told apart): the identification is incomplete (exit 1), the parameters found are still given
    unidentified: tuple = ()
    #: the Recording identify read (None from FRFs): explain iterates its hits again without reading the file
    recording: object = field(default=None, repr=False, compare=False)

    def hit_rows(self) -> list[dict]:
        """Every hit of every run, accepted or rejected, including runs that gave no FRF."""
        return [row for run in self.runs for row in run.hits] + list(self.failed_run_hits)

    def to_dict(self) -> dict:
        """The contract's JSON object (``identify --json``), with optional extra fields."""
        return {
            "file": self.file,
            "guide": self.guide.name,
            "parameters": self.parameters,
            "modes": [m.to_dict() for m in self.modes],
            "warnings": list(self.warnings),
            "extra_modes": [m.to_dict() for m in self.extra_modes],
            "missing_modes": list(self.missing_modes),
            "hits": self.hit_rows(),
            "hits_checked": self.hits_checked,
            "sensors": [
                {"name": ch.name, "position_m": [float(x) for x in ch.position_m],
                 "direction": [float(x) for x in ch.direction]}
                for ch in self._sensor_channels()
            ],
            "force_levels": [lvl for run in self.runs for lvl in run.force_levels],
            "run_modes": self.run_modes(),
            "method": "global_fit",
            "gate": self.gate,
            "unidentified": list(self.unidentified),
            "sensor_faults": [{"channel": f.channel, "kind": f.kind, "factor": f.factor, "axis": f.axis,
                               "alternatives": list(f.alternatives), "message": f.message}
                              for f in self.sensor_faults],
        }

    def run_modes(self) -> list[dict]:
        """Every run's own all-hits f and zeta of each mode (``level`` None: all hits; nothing dropped).

        The force bins within a run are the ``force_levels`` entries (each
        with its ``level`` index, 0 = softest hits, frequency and damping).
        """
        return [{"label": m.label, **e} for m in list(self.modes) + list(self.extra_modes) for e in m.estimates]

    def _sensor_channels(self):
        seen = {}
        for run in self.runs:
            for ch in run.channels:
                seen.setdefault(ch.name, ch)
        return list(seen.values())

    def to_frame(self):
        """One row per parameter: name, value, unit, std."""
        import pandas as pd

        return pd.DataFrame(
            [{"parameter": k, **v} for k, v in self.parameters.items()],
            columns=["parameter", "value", "unit", "std"],
        )

    def summary_row(self) -> dict:
        """One flat row for ``--csv``/``--summary`` (units in the column names)."""
        units = {"Hz": "hz", "1": "1", "N/m": "n_per_m", "N*s/m": "ns_per_m"}
        row = {"file": self.file, "guide": self.guide.name}
        for name, p in self.parameters.items():
            suffix = units.get(p["unit"], p["unit"])
            row[f"{name}_{suffix}"] = p["value"]
            row[f"{name}_std_{suffix}"] = p["std"]
        row["n_warnings"] = len(self.warnings)
        row["hits_checked"] = self.hits_checked  # False: from an FRF file
        row["gate"] = self.gate
        return row


# --------------------------------------------------------------------------- stage results


@dataclass(frozen=True)
class FrfStage:
    """What the FRF stage gives (:func:`frf_stage`): the runs' FRFs and the warnings of their hits."""

    collected: tuple  # (Run, FrfSet, hit rows) of every run that gave FRFs, in the file's order
    failed_rows: tuple = ()  # the hit rows of the runs that gave none (every hit rejected)
    warnings: tuple = ()


@dataclass(frozen=True)
class ModalPass:
    """One global fit of the collected FRFs (:func:`_global_pass`)."""

    modal: object  # guidefit.modal_stage.ModalResult; None when the fit failed (the reason in warnings)
    runs: tuple  # RunResult of every collected run, its modes the run's views of the shared modes
    warnings: tuple = ()


@dataclass(frozen=True)
class ModalFit:
    """The modal fit stage (:func:`modal_fit`, then :func:`sensor_check`) and what its declared refits did.

    ``collected`` are the FRFs of the final fit (sensor faults corrected),
    ``levels_only`` the harder force levels fitted apart, ``notes`` the
    sentences that say so, ``check`` the sensor check of the final fit.
    """

    collected: tuple
    levels_only: tuple
    passed: ModalPass
    notes: tuple = ()
    check: object = None  # guidefit.consistency.SensorCheck

    @property
    def warnings(self) -> tuple:
        """The stage's warnings in the order identify reports them: refits, the final fit, the faults."""
        faults = self.check.warnings if self.check is not None else ()
        return (*self.notes, *self.passed.warnings, *faults)


# --------------------------------------------------------------------------- the pipeline


def identify(path, guide=None, settings: IdentifySettings | None = None) -> Identification:
    """Identify the joint modes and K_V, K_H, c_V, c_H of one recording (or of FRFs measured from one).

    One sequence of stages, each taking values and returning them (warnings
    inside): recording -> hits -> FRFs (:func:`frf_stage`) -> modal fit,
    shapes and labels (:func:`modal_fit`) -> sensor check (:func:`sensor_check`,
    a fault corrected re-enters at the FRF stage: :func:`corrected_frfs`)
    -> force levels (:func:`run_results`) -> parameters and gate (:func:`conclude`).

    Parameters
    ----------
    path : str or Path
        A recording in any registered format, or FRFs: guidefit's ``frf.h5``
        or UFF-58 FRFs (:func:`guidefit.io.frf_files.read_input`). From FRFs the
        pipeline starts at the modal fit: no hit checks (``hits_checked``
        False), and without jackknife sums in the file the std is the fit's own.
    guide : str, Path or Guide, optional
        Overrides the file's ``guide`` attribute (default MRB35 when neither is given).
    settings : IdentifySettings, optional

    Raises
    ------
    RecordingError
        Malformed file (exit 2).
    IdentificationError
        Valid file, but no result can be trusted: every hit rejected, no joint mode found (exit 1).
    """
    from guidefit.io.frf_files import FrfFile, read_input

    settings = settings or IdentifySettings()
    source = read_input(path)
    from_frfs = isinstance(source, FrfFile)
    recording = source.recording if from_frfs else source
    guide, model = guide_and_model(recording, guide)
    frfs = frf_stage(source, settings, frf_top_hz(model, settings))
    recording = _as_computed(recording, frfs)
    if not frfs.collected:
        raise identification_failure(f"{path}: no run gave an FRF", frfs.warnings)
    fit = modal_fit(frfs.collected, guide, model, settings)
    fit = sensor_check(fit, recording, guide, model, settings, recompute=not from_frfs)
    runs, level_warnings = run_results(fit, [run.name for run, _, _ in frfs.collected], settings)
    warnings = (*frfs.warnings, *fit.warnings, *level_warnings)
    return conclude(path, recording, guide, model, settings, fit, runs, warnings,
                    failed_rows=frfs.failed_rows, hits_checked=not from_frfs)


def _as_computed(recording, frfs: FrfStage):
    """``recording`` with its runs as the FRF stage read them (a run read with the hammer's sign turned:
    :func:`_pushed_against`), so that every later stage sees one geometry."""
    from dataclasses import replace

    read = {run.name: run for run, _, _ in frfs.collected}
    if all(read.get(run.name, run) is run for run in recording.runs):
        return recording
    return replace(recording, runs=tuple(read.get(run.name, run) for run in recording.runs))


def guide_and_model(recording, guide=None):
    """The guide (``guide``, else the recording's, else MRB35) and its nominal modal solution."""
    from guidefit.model import vibration as vib
    from guidefit.model.guides import Guide, load_guide

    if not isinstance(guide, Guide):
        guide = load_guide(guide or recording.guide or "MRB35")
    return guide, vib.solve_modes(vib.model_from_guide(guide))


#: identify's FRFs end at this multiple of the band's nominal top (:func:`frf_top_hz`)
FRF_TOP_FACTOR = 3.0


def frf_top_hz(model, settings) -> float:
    """The highest frequency identify's FRFs need: :data:`FRF_TOP_FACTOR` x the band's nominal
    top (``settings.f_max_hz``, else 1.3 x the model's highest carriage mode).

    A decision of the pipeline from the model and the settings, made before
    any FRF exists. The modal stage's band
    (:func:`guidefit.modal_stage.global_band`) is widened to at most twice
    that top and never past 0.8 x the last bin, the per-mode checks look
    below it, so FRFs to 3x the top give every decision the bins it has with
    every bin; the bins above (at 200 kHz, about 70 % of them) are not summed
    (the spectral sums of every hit cost more than its FFT).
    """
    nominal = settings.f_max_hz or 1.3 * float(np.max(model.frequencies_hz))
    return FRF_TOP_FACTOR * float(nominal)


# --------------------------------------------------------------------------- stage: FRFs


def frf_stage(source, settings: IdentifySettings, max_frequency_hz: float | None = None) -> FrfStage:
    """The FRFs of every run: from a recording's hits (:func:`run_frfs`, up to ``max_frequency_hz``) or
    as an FRF file holds them (:func:`file_frfs`)."""
    from guidefit.io.frf_files import FrfFile

    if isinstance(source, FrfFile):
        return file_frfs(source, settings)
    return run_frfs(source, settings, max_frequency_hz)


def run_frfs(recording, settings: IdentifySettings, max_frequency_hz: float | None = None) -> FrfStage:
    """The FRFs of every run of a recording that gives them, with the warnings of its hits.

    Hits stream from the file into the spectral sums (bounded memory); each
    rejected hit is listed with its reason. ``max_frequency_hz``: the FRFs
    end there (:func:`guidefit.frf.compute_frf`). The hit rows of a run that
    gives no FRF are in ``failed_rows``. Runs recorded with another record
    length or sample rate are put on one frequency grid (:func:`_on_common_grid`).
    """
    from guidefit.errors import RecordingError

    collected, failed, warnings = [], [], []
    for run in recording.runs:
        if not run.response_indices:
            raise RecordingError(f"{run.file}: run '{run.name}': no acceleration channel; an FRF needs "
                                 "'force' and at least one 'acc_<point>_<axis>'")
        frf, rows, notes = _run_frf(run, settings, max_frequency_hz)
        run, frf, rows, notes = _pushed_against(run, frf, rows, notes, settings, max_frequency_hz)
        warnings.extend(notes)
        if frf is None:
            failed.extend(rows)
        else:
            collected.append((run, frf, rows))
    return FrfStage(_on_common_grid(tuple(collected), settings, max_frequency_hz), tuple(failed), tuple(warnings))


def _on_common_grid(collected: tuple, settings: IdentifySettings, max_frequency_hz) -> tuple:
    """The FRF stage's runs on one frequency grid (:func:`guidefit.frf.common_grid`), as the global fit
    needs them: a run with shorter records (or another sample rate) has its FRFs computed again from its
    hits with each windowed record zero-padded to the longest record's duration; a run whose FRFs reach
    higher (a higher sample rate) is cut to the common top. Runs that share one grid already: unchanged,
    nothing computed again."""
    from guidefit.frf import common_grid, fft_length, first_bins
    from guidefit.hits import HitSettings, iter_hits

    plan = common_grid([frf for _, frf, _ in collected], max_frequency_hz)
    if plan is None:
        return collected
    out = []
    for (run, frf, rows), (n_fft, bins) in zip(collected, plan):
        if n_fft != fft_length(frf):
            top = float((bins - 0.5) * frf.sample_rate_hz / n_fft)  # between the last bin kept and the next
            frf = _compute_frf(run, iter_hits(run, settings.hits or HitSettings()), settings, top, n_fft)
        out.append((run, first_bins(frf, bins), rows))
    return tuple(out)


def _run_frf(run, settings: IdentifySettings, max_frequency_hz):
    """One run's (FrfSet or None, hit rows, warnings): each rejected hit, a run without an FRF, too few hits."""
    from guidefit.hits import HitSettings, iter_hits

    rows: list[dict] = []
    notes: list[str] = []

    def tapped(it):
        for hit in it:
            rows.append(_hit_row(run.name, hit))
            if not hit.accepted:
                notes.append(f"run '{run.name}' hit {hit.index}: rejected: {hit.reason}")
            yield hit

    try:
        frf = _compute_frf(run, tapped(iter_hits(run, settings.hits or HitSettings())), settings,
                           max_frequency_hz)
    except IdentificationError as exc:
        text = str(exc)
        notes.append(text if text.startswith(f"run '{run.name}'") else f"run '{run.name}': {text}")
        return None, rows, notes
    notes.extend(dead_channel_warnings(run.name, frf))
    n_ok = sum(r["accepted"] for r in rows)
    if n_ok < settings.min_accepted_hits:
        notes.append(f"run '{run.name}': only {n_ok} accepted hit(s); uncertainties are unreliable")
    return frf, rows, notes


def _pushed_against(run, frf, rows, notes, settings: IdentifySettings, max_frequency_hz):
    """A run whose force pulses are mostly negative, read as the same test with the hammer's sign turned.

    The contract's sign: a positive force sample is a force on the carriage
    along ``excitation_direction``. A writer that declares the axis the
    other way round (the hammer pushing along -excitation_direction) gives
    negative pulses: the same physics as the direction and the samples both
    turned, which a hammer (it can only push) makes positive. When more of
    the run's hits are rejected as ``negative`` than accepted, the run is
    read again so (:func:`hammer_turned`), and kept so if more hits are
    accepted, with a line that says it; a run with a few negative pulses
    among positive ones keeps them rejected. Returns ``(run, frf, rows,
    notes)``, the run as its FRFs were computed.
    """
    negative = sum(1 for r in rows if str(r.get("reason") or "").startswith("negative"))
    accepted = sum(1 for r in rows if r["accepted"])
    if negative <= accepted:
        return run, frf, rows, notes
    turned = hammer_turned(run)
    frf_t, rows_t, notes_t = _run_frf(turned, settings, max_frequency_hz)
    if sum(1 for r in rows_t if r["accepted"]) <= accepted:
        return run, frf, rows, notes
    from guidefit.consistency import vector_text

    line = (f"run '{run.name}': {negative} of {len(rows)} force pulses are negative: the hammer pushes against "
            f"excitation_direction {vector_text(run.excitation_direction)}; read as pushed along "
            f"{vector_text(turned.excitation_direction)} with the force's sign turned (the same test: a positive force "
            "sample is a force along excitation_direction)")
    return turned, frf_t, rows_t, [line, *notes_t]


def hammer_turned(run):
    """``run`` with its excitation direction and its force channel (direction and sign) turned: the same
    test written with the other sign convention (:func:`_pushed_against`)."""
    from dataclasses import replace

    fi = run.force_index
    force = run.channels[fi]
    force = replace(force, direction=-np.asarray(force.direction, dtype=float), scale_to_si=-force.scale_to_si)
    channels = tuple(force if i == fi else ch for i, ch in enumerate(run.channels))
    return replace(run, excitation_direction=-np.asarray(run.excitation_direction, dtype=float), channels=channels)


def _compute_frf(run, hits, settings: IdentifySettings, max_frequency_hz, n_fft=None):
    """:func:`guidefit.frf.compute_frf` with identify's estimator, windows and FFT precision (``n_fft``:
    zero-padded to that length, a common grid)."""
    from guidefit.frf import WindowSettings, compute_frf

    return compute_frf(run, hits, estimator=settings.estimator, window=settings.window or WindowSettings(),
                       precision=settings.fft_precision, max_frequency_hz=max_frequency_hz, n_fft=n_fft)


def file_frfs(frf_file, settings: IdentifySettings) -> FrfStage:
    """The FRFs of every run of an FRF file (no hit rows); what the file lacks is in ``warnings``.

    The modal stage then runs on them as on :func:`run_frfs`' FRFs. Another
    estimator than the file's is used where its jackknife sums allow.
    """
    warnings = list(frf_file.notes)
    if settings.window is not None:
        warnings.append("the window settings do not apply: the file holds FRFs already computed")
    collected = []
    for run, frf in zip(frf_file.recording.runs, frf_file.frfsets):
        if settings.estimator != frf.estimator and frf.estimator in ("H1", "H2", "Hv"):  # else: not said
            if frf.n_groups >= 1:
                frf = frf.with_estimator(settings.estimator)
            else:
                warnings.append(f"run '{run.name}': the file holds {frf.estimator} FRFs; estimator "
                                f"{settings.estimator} needs the spectral sums (not in the file)")
        collected.append((run, frf, []))
    return FrfStage(tuple(collected), (), tuple(warnings))


@dataclass(frozen=True)
class RunChannels:
    """A run read with only some of its channels: what :func:`guidefit.frf.compute_frf` reads of a run
    (name, rate, channels, force column, record layout, sample dtype), and its hits with the other
    columns left out (:meth:`hits`). How a sensor-fault correction computes a run's FRFs again without
    a channel that reads another axis (:func:`corrected_frfs`)."""

    run: object  # guidefit.io.Run
    keep: tuple  # column indices kept, in order; the force column among them

    @classmethod
    def without(cls, run, names) -> RunChannels:
        """``run`` without the channels named in ``names``."""
        return cls(run, tuple(i for i, ch in enumerate(run.channels) if ch.name not in names))

    @property
    def name(self) -> str:
        return self.run.name

    @property
    def channels(self) -> tuple:
        return tuple(self.run.channels[i] for i in self.keep)

    @property
    def force_index(self) -> int:
        return self.keep.index(self.run.force_index)

    @property
    def sample_rate_hz(self) -> float:
        return self.run.sample_rate_hz

    @property
    def pretrigger_samples(self) -> int | None:
        return self.run.pretrigger_samples

    @property
    def layout(self) -> str:
        return self.run.layout

    @property
    def n_samples(self) -> int:
        return self.run.n_samples

    @property
    def n_hits_stored(self) -> int:
        return self.run.n_hits_stored

    @property
    def sample_dtype(self):
        return self.run.sample_dtype

    def hits(self, settings: IdentifySettings):
        """The run's hits (:func:`guidefit.hits.iter_hits`), each accepted one with the kept columns only."""
        from guidefit.hits import HitSettings, iter_hits

        keep = list(self.keep)
        for hit in iter_hits(self.run, settings.hits or HitSettings()):
            yield hit if hit.data is None else replace(hit, data=hit.data[:, keep])


def corrected_frfs(collected, faults, settings: IdentifySettings, recompute: bool = True) -> tuple:
    """The declared step by which a sensor-fault correction re-enters the pipeline at the FRF stage.

    Takes the FRF stage's (run, FrfSet, hit rows) and the faults
    (:class:`guidefit.consistency.SensorFault`) and returns them corrected
    (:func:`guidefit.consistency.corrected_frf`: a scale divided out, a
    wrong-axis channel left out). With ``recompute`` (time data) a run with
    a wrong-axis channel has its FRFs computed again without it
    (:class:`RunChannels`), so that channel no longer pulls the automatic
    exponential window (chosen from every response's decay) either.
    """
    from guidefit import consistency
    from guidefit.frf import top_of

    out = []
    for run, frf, rows in collected:
        if not any(f.channel in {ch.name for ch in run.channels} for f in faults):
            out.append((run, frf, rows))
            continue
        drop = consistency.axis_fault_channels(faults, run.channels)
        if drop and recompute:
            view = RunChannels.without(run, drop)
            frf = _compute_frf(view, view.hits(settings), settings, top_of(frf), frf.n_fft)
        out.append((run, consistency.corrected_frf(frf, faults), rows))
    return tuple(out)


# --------------------------------------------------------------------------- stage: modal fit, shapes, labels


def modal_fit(collected, guide, model, settings: IdentifySettings) -> ModalFit:
    """One modal model of all runs (:func:`_global_pass`), with its declared refit for force levels.

    Runs that are harder force levels of another run (:func:`_force_level_runs`)
    whose modes move with the force (:func:`_levels_agree`: contacts soften
    with amplitude) are left out of the shared-pole fit, which is made again
    without them; a note says so for each.
    """
    first = _global_pass(collected, guide, model, settings)
    harder = _force_level_runs(collected)
    if not harder or _levels_agree(first.modal, harder):
        return ModalFit(tuple(collected), (), first)
    notes = tuple(f"run '{name}': the same hit point and direction as a softer run at {ratio:.1f}x its mean hit "
                  "force, and its modes move with the force (contacts soften with amplitude): a force level, left "
                  "out of the shared-pole fit; explain compares it through the force-level model"
                  for name, ratio in harder.items())
    kept = tuple(item for item in collected if item[0].name not in harder)
    levels_only = tuple(item for item in collected if item[0].name in harder)
    return ModalFit(kept, levels_only, _global_pass(kept, guide, model, settings), notes)


def _global_pass(collected, guide, model, settings) -> ModalPass:
    """One global fit of the (run, FrfSet, hit rows) triples: the ModalResult (None when it failed, the
    reason in the warnings) and each run's RunResult with its views of the shared modes (force levels
    are added by :func:`run_results`, on the final fit)."""
    from guidefit import modal_stage

    frf_by_run = {run.name: frf for run, frf, _ in collected}
    geometry = {run.name: modal_stage.geometry_of(run, frf) for run, frf, _ in collected}
    try:
        res = modal_stage.identify_frfs(frf_by_run, geometry, guide, settings, model=model)
        warnings = res.warnings
    except IdentificationError as exc:
        res, warnings = None, (str(exc),)
    runs = []
    for run, frf, rows in collected:
        views = []
        if res is not None:
            for m in res.modes + res.extras:
                k = m.global_index
                if run.name in res.fit.runs and res.per_run.get(run.name, [None] * (k + 1))[k] is not None:
                    views.append(replace(m, run=run.name, fit=res.fit.run_mode(k, run.name),
                                         shape=m.shapes.get(run.name, m.shape)))
        runs.append(RunResult(run.name, frf, rows, views, tuple(run.excitation_direction),
                              frf_channels(run, frf)))
    return ModalPass(res, tuple(runs), tuple(warnings))


# --------------------------------------------------------------------------- stage: sensor check


def sensor_check(fit: ModalFit, recording, guide, model, settings: IdentifySettings, recompute=True) -> ModalFit:
    """The global shapes checked for sensors that do not fit rigid carriage motion
    (:func:`guidefit.consistency.check_global`).

    A faulty channel is named, its FRFs corrected (:func:`corrected_frfs`,
    ``recompute``: from the hits again where a channel is left out) and the
    global fit made again; the first fit's warnings go with it. ``check``
    of the result holds the faults and the shape sets behind the gate.
    """
    from guidefit import consistency

    check = consistency.check_global(fit.passed.runs, recording, guide, settings, model=model)
    if not check.faults:
        return replace(fit, check=check)
    collected = corrected_frfs(fit.collected, check.faults, settings, recompute)
    again = _global_pass(collected, guide, model, settings)
    check = consistency.check_global(again.runs, recording, guide, settings, faults=check.faults)
    return replace(fit, collected=collected, passed=again, check=check)


# --------------------------------------------------------------------------- stage: run results, force levels


def run_results(fit: ModalFit, order, settings: IdentifySettings) -> tuple[list, tuple]:
    """Every run's RunResult in the file's ``order`` (run names), the force levels fitted apart among
    them (no modes), with their per-force-bin frequencies when ``settings.force_levels``
    (:func:`guidefit.identify_runs._force_levels`, on the final fit), and the warnings of those refits."""
    runs = list(fit.passed.runs)
    runs += [RunResult(run.name, frf, rows, [], tuple(run.excitation_direction), frf_channels(run, frf), [])
             for run, frf, rows in fit.levels_only]
    rank = {name: i for i, name in enumerate(order)}
    runs.sort(key=lambda r: rank[r.name])
    if not settings.force_levels:
        return runs, ()
    run_of = {run.name: run for run, _, _ in (*fit.collected, *fit.levels_only)}
    out, warnings = [], []
    for r in runs:
        if r.modes:
            levels, notes = _force_levels(run_of[r.name], r.frf, r.hits, r.modes, settings)
            warnings.extend(notes)
            r = replace(r, force_levels=levels)
        out.append(r)
    return out, tuple(warnings)


# --------------------------------------------------------------------------- stage: parameters and gate


def conclude(path, recording, guide, model, settings: IdentifySettings, fit: ModalFit, runs, warnings,
             failed_rows=(), hits_checked: bool = True) -> Identification:
    """Joint parameters (Eq. 24-29), the plausibility gate and the result, from the final fit.

    ``warnings`` are those of the stages before; the quality, excitation,
    hit-point and modal-mass warnings follow them.

    Raises
    ------
    IdentificationError
        No mode at all was found, nor the vertical or horizontal joint mode.
    """
    from guidefit import consistency
    from guidefit.hammer_check import hammer_lines
    from guidefit.io.axes import frame_hint

    res = fit.passed.modal
    modes = res.modes if res is not None else []
    joint = {k: next((m for m in modes if m.label == lab), None) for k, lab in JOINT_LABELS.items()}
    neither = joint["V"] is None and joint["H"] is None
    if neither and (res is None or not (res.modes or res.extras)):
        raise identification_failure(f"{path}: neither the vertical nor the horizontal joint mode was found", warnings,
                                     hint=frame_hint(recording))
    sets = fit.check.sets
    warnings = (*warnings, *_quality_warnings(modes, settings),
                *_excitation_warnings(modes, {r.name: r.frf for r in runs}),
                *_frequency_scale_warnings(modes, recording),
                *consistency.unknown_hit_warnings(recording))
    params = joint_parameters(guide.mass_kg, joint)
    # modes that are found but not named (ambiguous) count as missing for the gate
    not_named = [lab for lab in model.labels if lab not in {m.label for m in modes} and not lab.startswith("support")]
    gate = fit.check.unresolved or consistency.plausibility(modes, not_named, sets, model)
    amplitude = _amplitude_lines(fit, runs, settings, gate is not None)
    warnings = (*amplitude, *warnings)
    if gate is not None and amplitude:
        gate = f"{amplitude[0]}; {gate}"
    if gate is None and neither:  # modes found, none of them the vertical or the horizontal joint mode
        gate = (f"neither the vertical nor the horizontal joint mode was found among the {len(res.modes)} "
                f"labelled and {len(res.extras)} other modes: the recording does not look like a carriage on "
                "this guide, or its sensors cannot tell its modes apart (guidefit plan shows what they can)")
    hammer, hints = (tuple(d.values()) for d in hammer_lines(sets, model, recording))
    warnings = (*warnings, *consistency.global_mass_warnings(runs, sets, guide, model), *hammer)
    if gate is not None:
        gate += "".join(f"; {line}" for line in hints) + frame_hint(recording)
        params = joint_parameters(guide.mass_kg, {})
    fitted = {run.name for run, _, _ in (*fit.collected, *fit.levels_only)}
    lost = consistency.recorded_sets([r for r in recording.runs if r.name not in fitted],
                                     consistency.hit_points_of(recording), (settings.f_min_hz, settings.f_max_hz))
    unidentified = () if gate is not None else _unidentified(joint, model, sets, [*modes, *res.extras], lost)
    unidentified = tuple(line + "".join(f"; {h}" for h in hints) for line in unidentified)
    if gate is None and hammer:  # a joint mode the declared hammer "cannot excite" is missing: not the layout's
        said = {line.split(",")[0] for line in unidentified}
        unidentified += tuple(f"f_{key}, K_{key}, c_{key} not identified: {'; '.join(hammer)}"
                              for key in JOINT_LABELS if joint[key] is None and f"f_{key}" not in said)
    return Identification(str(path), guide, tuple(runs), tuple(modes), params, tuple(warnings),
                          tuple(res.extras), tuple(res.missing), tuple(failed_rows), hits_checked=hits_checked,
                          modal=res, gate=gate, sensor_faults=fit.check.faults, unidentified=unidentified,
                          recording=recording if hits_checked else None)


def _amplitude_lines(fit: ModalFit, runs, settings: IdentifySettings, rejected: bool) -> tuple:
    """Amplitude dependence (:func:`guidefit.identify_runs.amplitude_dependence`) of each fitted run, looked
    for only when the fit failed its gate or the labeller found the modes in antiphase with the model's
    while the driving points are signed right: one linear model does not fit, and this says why."""
    from guidefit.hammer_check import STRONG

    res = fit.passed.modal
    if not rejected and (res is None or not res.antiphase_signed_right):
        return ()
    run_of = {run.name: run for run, _, _ in fit.collected}
    out = []
    for r in runs:
        if r.name not in run_of or res is None or r.name not in res.fit.runs:
            continue
        views = [replace(m, run=r.name, fit=res.fit.run_mode(m.global_index, r.name)) for m in res.modes + res.extras]
        size = {id(v): float(np.linalg.norm(list(m.shapes.get(r.name, {}).values()) or [0.0]))
                for v, m in zip(views, res.modes + res.extras)}
        top = max(size.values(), default=0.0)
        strong = [v for v in views if top > 0 and size[id(v)] >= STRONG * top]  # the modes this run's hammer drives
        line = amplitude_dependence(run_of[r.name], r, strong, settings)
        if line is not None:
            out.append(line)
    return tuple(out)


def _unidentified(joint: dict, model, sets, modes, lost=()) -> tuple:  # modes: the named ones and the extras
    """One sentence per joint parameter pair (f_V..c_V, f_H..c_H) left out although the set-up excites and
    sees its mode (:func:`guidefit.consistency.observable_modes`): not found, or found and not told apart
    (``ambiguous``), or only a run that gave no FRF (every hit rejected; ``lost``, its
    :func:`guidefit.consistency.recorded_sets`) excites and sees it. A layout that cannot see the mode is
    not a failure (the result says what it cannot tell)."""
    from guidefit import consistency

    observable = consistency.observable_modes(model, sets)
    ambiguous = any(getattr(m, "label", None) == "ambiguous" for m in modes)
    out = []
    for key, label in JOINT_LABELS.items():
        if joint.get(key) is not None:
            continue
        if label in observable:
            why = "found but not told apart from another mode" if ambiguous else "not found"
            out.append(f"f_{key}, K_{key}, c_{key} not identified: the {label} mode this set-up excites and sees "
                       f"was {why} (the warnings say why)")
            continue
        failed = [s.run for s in lost if label in consistency.observable_modes(model, [s])]
        if failed:
            out.append(f"f_{key}, K_{key}, c_{key} not identified: run '{failed[0]}', which excites and sees the "
                       f"{label} mode, gave no FRF (every hit rejected; the warnings say why)")
            continue
        unexplained = _strong_extras(modes)
        if unexplained:
            runs = "; ".join(f"run '{r}': {', '.join(f'{f:.0f}' for f in fs)} Hz" for r, fs in unexplained.items())
            out.append(f"f_{key}, K_{key}, c_{key} not identified: the layout as declared cannot see the {label} "
                       f"mode, but strong modes the model does not predict are there ({runs}): a sensor's "
                       "direction or position, or the hammer's, may be entered wrong")
    return tuple(out)


def _strong_extras(modes) -> dict:
    """Run -> frequencies of its strong modes (modal-constant norm in that run at least
    :data:`guidefit.hammer_check.STRONG` of its strongest mode's) that the model does not predict
    (``extra``). On a set-up as declared, a run's strong modes are carriage modes; when one is not, a
    joint mode the declared layout "cannot see" may be that mode (a vertical run's sensors declared along x
    show the vertical mode as a lateral shape at the vertical mode's frequency)."""
    from guidefit.hammer_check import STRONG

    sizes: dict = {}
    for m in modes:
        for run, shape in (getattr(m, "shapes", None) or {}).items():
            size = float(np.linalg.norm(list(shape.values()))) if shape else 0.0
            sizes.setdefault(run, []).append((size, m))
    out: dict = {}
    for run, entries in sizes.items():
        top = max(size for size, _ in entries)
        found = sorted(m.frequency_hz for size, m in entries
                       if top > 0 and size >= STRONG * top and getattr(m, "label", None) == "extra")
        if found:
            out[run] = found
    return out


# --------------------------------------------------------------------------- force levels fitted apart

#: runs of one hit point and direction whose mean peak forces differ by this factor are force levels
LEVEL_FORCE_RATIO = 1.5


def _force_level_runs(collected) -> dict:
    """Runs that are only harder force levels of another run: name -> mean force ratio to the softest.

    Runs with the same hit point, hit direction, channels, sample rate and
    record length whose mean accepted peak forces differ by
    :data:`LEVEL_FORCE_RATIO` are levels of one test.
    """
    from guidefit.io.records import hit_point_of

    groups: dict = {}
    for run, frf, rows in collected:
        pos = hit_point_of(run)
        key = (None if pos is None else tuple(np.round(np.asarray(pos, float), 4)),
               tuple(np.round(np.asarray(run.excitation_direction, float), 3)), tuple(frf.channels),
               float(run.sample_rate_hz), int(getattr(run, "n_samples", 0) or 0))
        forces = [r["peak_force_n"] for r in rows if r.get("accepted")]
        if forces:
            groups.setdefault(key, []).append((float(np.mean(forces)), run.name))
    out = {}
    for members in groups.values():
        low = min(f for f, _ in members)
        out.update({name: f / low for f, name in members if low > 0 and f >= LEVEL_FORCE_RATIO * low})
    return out


def _levels_agree(res, harder: dict) -> bool:
    """Whether the harder force levels share the softer run's poles (linear contacts).

    Preloaded Hertz contacts soften with amplitude (rollers unload), so a
    harder level's modes move (on MRB35 f_V -0.3 % at 1 kN, -18 % at 5 kN):
    then a shared-pole fit would average levels that differ. They agree when
    the global fit found modes and each harder run's own estimate of every
    mode lies within max(3 std, 0.1 %) of the shared frequency, and no harder
    run has lost most of the modes a softer run shows (modes that moved far
    leave a shared-pole fit without them: no estimate is no agreement).
    """
    if res is None or not res.modes:
        return False
    soft_modes, shown = 0, dict.fromkeys(harder, 0)
    for m in res.modes:
        seen = {e.get("run") for e in m.estimates if e.get("level") is None and e.get("frequency_hz") is not None}
        if seen - set(harder):
            soft_modes += 1
            for h in seen & set(harder):
                shown[h] += 1
    if any(2 * n < soft_modes for n in shown.values()):  # a harder run lost most of the softer run's modes: moved
        return False
    for m in res.modes:
        for e in m.estimates:
            if e.get("run") not in harder or e.get("level") is not None or e.get("frequency_hz") is None:
                continue
            std = e.get("frequency_std_hz") or 0.0
            if abs(e["frequency_hz"] - m.frequency_hz) > max(3.0 * std, 1e-3 * m.frequency_hz):
                return False
    return True


def frf_of_recording(path, settings: IdentifySettings | None = None):
    """FRF sets of every run of any recording (guideway or not) and the warnings.

    Raises :class:`IdentificationError` when no run gives an FRF.
    """
    from guidefit.io.frf_files import read_input

    settings = settings or IdentifySettings()
    frfs = frf_stage(read_input(path), settings)
    if not frfs.collected:
        raise identification_failure(f"{path}: no run gave an FRF", frfs.warnings)
    return [frf for _run, frf, _rows in frfs.collected], list(frfs.warnings)


# --------------------------------------------------------------------------- diagnostics


def per_run_fits(path, guide=None, settings: IdentifySettings | None = None):
    """The per-run diagnostic: each run's FRFs (every bin) fitted on their own, one estimate per label.

    What identify did before the global fit (:func:`guidefit.identify_runs.fit_runs`:
    per-run curve fits, labels from each run alone, the estimate with the
    smallest frequency uncertainty per label); for comparison with
    :func:`identify` (``benchmarks/bench_global.py``). No sensor check, gate
    or joint parameters.

    Returns
    -------
    guidefit.identify_runs.RunFits
        ``modes``, ``extras``, ``missing`` and ``warnings`` (the FRF stage's first).
    """
    from guidefit.identify_runs import fit_runs
    from guidefit.io.frf_files import FrfFile, read_input

    settings = settings or IdentifySettings()
    source = read_input(path)
    guide, model = guide_and_model(source.recording if isinstance(source, FrfFile) else source, guide)
    frfs = frf_stage(source, settings)
    if not frfs.collected:
        raise identification_failure(f"{path}: no run gave an FRF", frfs.warnings)
    fits = fit_runs(frfs.collected, guide, model, settings)
    return replace(fits, warnings=frfs.warnings + fits.warnings)


from guidefit._api import make_callable  # noqa: E402

make_callable(__name__, "identify")
