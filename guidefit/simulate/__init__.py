r"""Synthetic impact-hammer tests of a guideway carriage with known truth.

A recording made here goes through the same chain as a real one: hammer
pulse -> carriage (+ support body) -> accelerometers -> anti-alias filter ->
sensor noise -> ADC. Its truth (effects, modal table, K_V/K_H/c_V/c_H)
goes to a separate JSON file that ``identify`` never reads.

Forward model
-------------
*Structure.* The model of :mod:`guidefit.model.vibration` with any effects of
:mod:`guidefit.model.effects`: mass-normalised modes ``phi_k`` (support-body
DOFs included), natural frequencies ``w_k`` and a viscous modal damping ratio
``zeta_k`` per mode label (:data:`DEFAULT_DAMPING`: vertical 2.9 % and
roll_low 10.5 %, the paper's identified values; pitch, yaw, roll_high and any
support-body mode 2 %).

*Hammer.* Each hit is a half-sine force pulse
``F(t) = F0 sin(pi t / T)`` for ``0 <= t <= T``; ``T = 0.1 ms`` (steel tip)
puts the first zero of its spectrum at ``1.5 / T = 15 kHz`` and its -3 dB
point at about ``0.6 / T = 6 kHz``, above every carriage mode. The hit point and direction are
those of the run; the peak force of each hit is drawn uniformly from
``SimulationConfig.force_n`` (None: 200-500 N, or less for a carriage whose
accelerometers would pass half their range, :mod:`guidefit.simulate.levels`);
the onset lies at a random sub-sample instant just before the trigger sample.

*Linear response (exact).* Each mode obeys
``eta'' + 2 zeta w eta' + w^2 eta = b_k F(t)`` with ``b_k = d . R(p) phi_k``
(hammer direction ``d`` at hit point ``p``; ``R`` is
:func:`~guidefit.model.vibration.rigid_body_map`). Its response to a half-sine
is a closed form: with the pole ``lambda = -zeta w + j w_d`` and the Duhamel
integral ``J(t) = int_0^min(t,T) exp(lambda (t - s)) sin(Omega s) ds``
(``Omega = pi / T``, evaluated analytically),
``eta'' = b_k [F(t)/F0 + Im(lambda^2 J) / w_d] F0``. This is sampled at the
internal (oversampled) instants: no time stepping, no FFT wrap-around. The
acceleration of sensor ``r`` (point ``p_r``, axis ``d_r``) is
``sum_k (d_r . R(p_r) phi_k) eta_k''``.

*Nonlinear contacts* (effect ``amplitude_dependence``). Every roller is a
preloaded Hertz line contact, ``Q_i = C_i delta_i^(10/9)`` for
``delta_i > 0`` and 0 otherwise (Palmgren, Eq. 4; two contacts in series keep
the exponent), every ball of a ball guide a Hertz point contact,
``Q_i = C_i delta_i^(3/2)`` (Eq. 3; :func:`guidefit.model.static.exponent`), with ``delta_i = Delta' - g_i . q``, ``Delta'`` the guide's
preload times ``preload_factor`` and ``C_i`` calibrated so that at the
nominal preload the tangent stiffness is roller i's K_n of the linear model
(:func:`guidefit.model.static.contact_constant`, calibration 'nominal': the
same law as the static model).
The static equilibrium is found by Newton's method; the damping matrix
``C = M Phi diag(2 zeta_k w_k) Phi^T M`` is the modal damping of the model
linearised there. The equations of motion are integrated by the classical
4th-order Runge-Kutta method with a fixed step equal to the internal sample
interval divided by ``substeps`` and extra step boundaries at every pulse
start and end (the force is smooth inside each step). Once the pulses are
over and the energy bound on every roller's excursion
``|g_i . (q - q0)| <= sqrt(2 E g_i^T K^-1 g_i)`` falls below
``nonlinear_tolerance * Delta'``, the remaining free decay is the exact
linear one from that state. While every roller stays in contact, halving the
step divides the error by 16 (4th order); across lift-off the law is not
smooth at ``delta = 0`` and the order drops, the error staying below 2e-5 of
the peak at the default step (tests: step convergence, energy conservation,
agreement with the linear solution at small force).

Measurement chain
-----------------
1. *Anti-alias filter and decimation*: the internal signals (``oversample``
   times the sample rate) pass a linear-phase Kaiser FIR low-pass (passband
   to 0.4 fs, > 90 dB stopband from 0.6 fs, delay compensated), as in the
   decimation filter of a sigma-delta DAQ, then every ``oversample``-th sample
   is kept. The same filter acts on force and response channels, so the FRF is
   unchanged; its pre-ringing (about 0.1 ms) lies inside the pretrigger.
2. *Sensor noise*: white Gaussian, RMS ``noise_fraction`` times the channel's
   range, independent per channel and sample.
3. *ADC*: ``adc_bits`` (16) bipolar converter with range ``+/- range``
   (force 2048 N, acceleration 1024 m/s^2: LSB 1/16 N and 1/32 m/s^2,
   exact in float32 and short in CSV): values are rounded to the LSB
   ``2 range / 2^bits`` and clipped to the lowest and highest code
   (:func:`adc`). Stored as float32 in SI units.

Faults (:data:`FAULTS`, ``--fault NAME[:param=value,...]``): ``double_hit``
(a rebound pulse after ``delay_s`` with ``ratio`` of the force),
``overload`` (one hit ``factor`` times harder: channels clip at their
range), ``loose_sensor`` (a rattling sensor: extra noise ``noise_factor``
times the channel noise plus multiplicative rattle ``rattle`` times the
signal), ``dropped_hit`` (the DAQ loses a block of samples in one hit: zeros).

Examples
--------
>>> from guidefit.simulate import SimulationConfig, simulate
>>> cfg = SimulationConfig(hits=2, record_s=0.01)
>>> data, truth = simulate("MRB35", config=cfg, seed=1)
>>> [r.name for r in data.runs]
['vertical', 'lateral']
>>> round(truth["parameters"]["f_V"]["value"], 1)
3529.0
"""

from __future__ import annotations

import math
import os
import zlib
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from guidefit.errors import ModelError
from guidefit.model.guides import as_guide, guide_reference
from guidefit.progress import progress_bar
from guidefit.simulate.layouts import DEFAULT_RUNS, HammerRun

# the physics moved to sim_physics (issue 22); its public names stay importable from here
from guidefit.simulate.physics import (  # noqa: F401
    DEFAULT_DAMPING,
    PALMGREN_EXPONENT,
    SUPPORT_DAMPING,
    _decimate,
    _Model,
    adc,
    anti_alias_filter,
    build_model,
    half_sine_modal_acceleration,
    hit_response,
    integrate_contacts,
    modal_damping,
)

TRUTH_FORMAT = "guidefit-simulation-truth"


@dataclass(frozen=True)
class Fault:
    """A measurement fault: name and parameters (see :data:`FAULTS`)."""

    name: str
    parameters: dict = field(default_factory=dict)

    def __str__(self) -> str:
        body = ",".join(f"{k}={v}" for k, v in self.parameters.items())
        return f"{self.name}:{body}" if body else self.name


#: Faults of a real test: parameter -> default. ``hit`` is the 0-based hit index
#: (default: the given index, or the last hit when the run has fewer); ``run`` a
#: run name or ``all``.
FAULTS = {
    "double_hit": {"hit": 1, "delay_s": 1.5e-3, "ratio": 0.4, "run": "all"},
    "overload": {"hit": 2, "factor": 8.0, "run": "all"},
    "loose_sensor": {"channel": "acc_C_y", "noise_factor": 30.0, "rattle": 0.3, "run": "all"},
    "dropped_hit": {"hit": 3, "start_s": 2e-4, "duration_s": 2e-3, "run": "all"},
}
_FAULT_TEXT = {"channel", "run"}


def parse_fault(text: str) -> Fault:
    """Parse ``NAME[:param=value,...]`` (the ``--fault`` syntax) into a checked :class:`Fault`.

    >>> parse_fault("double_hit:delay_s=0.002")
    Fault(name='double_hit', parameters={'hit': 1, 'delay_s': 0.002, 'ratio': 0.4, 'run': 'all'})
    """
    from guidefit.model.effects import split_named_parameters

    return make_fault(*split_named_parameters(text, "fault"))


def make_fault(name: str, parameters: dict | None = None) -> Fault:
    """Validate a fault's name and parameters and fill the defaults."""
    if name not in FAULTS:
        raise ModelError(f"unknown fault '{name}'; have {', '.join(FAULTS)}")
    parameters = dict(parameters or {})
    out = {}
    for key in parameters:
        if key not in FAULTS[name]:
            raise ModelError(f"fault {name}: unknown parameter '{key}'; have {', '.join(FAULTS[name])}")
    for key, default in FAULTS[name].items():
        value = parameters.get(key, default)
        if key in _FAULT_TEXT:
            out[key] = str(value)
            continue
        try:
            number = float(value)
        except (TypeError, ValueError):
            raise ModelError(f"fault {name}: parameter '{key}' must be a number, got {value!r}") from None
        if not math.isfinite(number) or number < 0:
            raise ModelError(f"fault {name}: parameter '{key}' must be finite and >= 0, got {value!r}")
        out[key] = int(number) if key == "hit" else number
    return Fault(name, out)


@dataclass(frozen=True)
class SimulationConfig:
    """How the hammer test is run and recorded (SI units; names say the unit).

    Parameters
    ----------
    runs : tuple of HammerRun
        Excitation set-ups; default :data:`DEFAULT_RUNS` (vertical, lateral).
    hits : int
        Hits per run.
    force_n : (float, float) or None
        Range of the hits' peak forces (N), drawn uniformly per hit. None (the
        default): chosen for the carriage (:mod:`guidefit.simulate.levels`):
        200-500 N unless that would drive an accelerometer past half its
        range, then less (and ``force_range_n`` scaled with it).
    pulse_s : float
        Half-sine pulse duration T (s); 0.1 ms is a steel tip.
    sample_rate_hz, record_s, pretrigger_s : float
        Sample rate, record length per hit and pretrigger.
    layout : {'hits', 'signals'}
        One pre-triggered record per hit, or one continuous record (the hit
        records back to back, ``gap_s`` of quiet noise between them). CSV
        output is always continuous.
    damping : dict
        Modal damping ratio per mode label, overriding :data:`DEFAULT_DAMPING`
        (key ``support`` for extra modes).
    sensors, axes : str
        Measuring points (guide point names) and axes of the accelerometers,
        the same in every run (used when ``sensor_layout`` is None).
    sensor_layout : str or None
        Each run's accelerometers from a layout of :mod:`guidefit.simulate.layouts`
        (``default``, ``both``, ``pair``, ``single``, ``side``,
        ``triax:A,C`` or a layout TOML file); None: ``sensors`` x ``axes``.
    adc_bits : int or None
        ADC resolution; None: no quantisation and no clipping (ideal chain).
    force_range_n, acc_range_m_s2 : float
        ADC range (+/-) of the force and acceleration channels.
    noise_fraction : float
        Sensor noise RMS relative to the channel's range.
    oversample : int
        Internal rate / sample rate (anti-alias filter design, nonlinear step).
    anti_alias : bool
        Apply the anti-alias FIR before decimation (else plain subsampling).
    faults : tuple of Fault or str
        Measurement faults (:data:`FAULTS`).
    nonlinear_tolerance : float
        Nonlinear contacts: switch to the exact linear decay once every
        roller's excursion is below this fraction of the preload.
    substeps : int
        Nonlinear contacts: RK4 steps per internal sample.
    """

    runs: tuple = DEFAULT_RUNS
    hits: int = 8
    force_n: tuple[float, float] | None = None
    pulse_s: float = 1.0e-4
    sample_rate_hz: float = 200_000.0
    record_s: float = 0.1
    pretrigger_s: float = 1.0e-3
    layout: str = "hits"
    gap_s: float = 0.0
    damping: dict = field(default_factory=dict)
    sensors: str = "ABCD"
    axes: str = "xy"
    sensor_layout: str | None = None
    adc_bits: int | None = 16
    force_range_n: float = 2048.0
    acc_range_m_s2: float = 1024.0
    noise_fraction: float = 1.0e-4
    oversample: int = 4
    anti_alias: bool = True
    faults: tuple = ()
    nonlinear_tolerance: float = 1.0e-2
    substeps: int = 1

    def ideal(self) -> SimulationConfig:
        """The same test with a perfect chain: no noise, no quantisation, no clipping."""
        return replace(self, noise_fraction=0.0, adc_bits=None)

    def to_dict(self) -> dict:
        """JSON-ready dictionary (used in the truth file)."""
        out = asdict(self)
        out["runs"] = [asdict(r) for r in self.runs]
        out["faults"] = [{"name": f.name, "parameters": dict(f.parameters)} for f in _faults(self)]
        if self.sensor_layout is not None:
            out["sensor_layout"] = os.fspath(self.sensor_layout)  # a layout file given as a Path
        return out


def config_from_options(runs=None, hits=None, record_s=None, force_n=None, layout=None, faults=(),
                        ideal: bool = False, base: SimulationConfig | None = None, sensor_layout=None,
                        hit_points=()) -> SimulationConfig:
    """A :class:`SimulationConfig` from command-line style options (None keeps the default).

    ``runs`` names runs of :data:`DEFAULT_RUNS` (a list or ``"vertical,lateral"``);
    ``force_n`` is ``(min, max)`` or ``"min,max"`` in N; ``faults`` are
    ``NAME[:param=value,...]`` texts; ``sensor_layout`` a layout of
    :mod:`guidefit.simulate.layouts`; ``hit_points`` ``RUN:x,y,z`` texts that move a
    run's hammer point (:func:`guidefit.simulate.layouts.apply_hits`).

    >>> cfg = config_from_options(runs="vertical", hits=3, force_n="100,150")
    >>> [r.name for r in cfg.runs], cfg.hits, cfg.force_n
    (['vertical'], 3, (100.0, 150.0))
    """
    cfg = SimulationConfig() if base is None else base
    changes: dict = {}
    if runs is not None:
        names = [r.strip() for r in runs.split(",")] if isinstance(runs, str) else list(runs)
        known = {r.name: r for r in DEFAULT_RUNS}
        for name in names:
            if name not in known:
                raise ModelError(f"run '{name}' unknown; have {', '.join(known)}")
        changes["runs"] = tuple(known[name] for name in names)
    if hits is not None:
        changes["hits"] = int(hits)
    if record_s is not None:
        changes["record_s"] = float(record_s)
    if force_n is not None:
        parts = force_n.split(",") if isinstance(force_n, str) else list(force_n)
        try:
            values = tuple(float(x) for x in parts)
        except ValueError:
            values = ()
        if len(values) == 1:
            values = values * 2
        if len(values) != 2:
            raise ModelError(f"force: expected MIN,MAX in N, got '{force_n}'")
        changes["force_n"] = values
    if layout is not None:
        changes["layout"] = layout
    if faults:
        changes["faults"] = tuple(parse_fault(f) if isinstance(f, str) else f for f in faults)
    if sensor_layout is not None:
        changes["sensor_layout"] = str(sensor_layout)
    if hit_points:
        from guidefit.simulate.layouts import apply_hits

        changes["runs"] = apply_hits(changes.get("runs", cfg.runs), hit_points)
    cfg = replace(cfg, **changes)
    return cfg.ideal() if ideal else cfg


# --------------------------------------------------------------------------- simulation


def _faults(config) -> tuple:
    out = []
    for f in config.faults:
        if isinstance(f, str):
            out.append(parse_fault(f))
        elif isinstance(f, Fault):
            out.append(make_fault(f.name, f.parameters))
        else:
            raise ModelError(f"fault: expected 'NAME:param=value' or a Fault, got {f!r}")
    return tuple(out)


def _check_config(config: SimulationConfig, guide) -> None:
    def bad(name, value, allowed):
        raise ModelError(f"simulation config: {name} = {value!r}; {allowed}")

    if not isinstance(config.hits, int) or config.hits < 1:
        bad("hits", config.hits, "must be a positive integer")
    if config.force_n is not None:
        lo, hi = config.force_n
        if not 0 < lo <= hi:
            bad("force_n", config.force_n, "must be (min, max) with 0 < min <= max")
    for name in ("pulse_s", "sample_rate_hz", "record_s", "force_range_n", "acc_range_m_s2"):
        value = getattr(config, name)
        if not (math.isfinite(value) and value > 0):
            bad(name, value, "must be positive")
    for name in ("pretrigger_s", "gap_s", "noise_fraction", "nonlinear_tolerance"):
        value = getattr(config, name)
        if not (math.isfinite(value) and value >= 0):
            bad(name, value, "must be >= 0")
    if config.pretrigger_s >= config.record_s:
        bad("pretrigger_s", config.pretrigger_s, f"must be shorter than record_s = {config.record_s}")
    if config.layout not in ("hits", "signals"):
        bad("layout", config.layout, "allowed: hits, signals")
    if config.adc_bits is not None and not (isinstance(config.adc_bits, int) and 2 <= config.adc_bits <= 32):
        bad("adc_bits", config.adc_bits, "must be an integer 2-32 or None")
    if not isinstance(config.oversample, int) or config.oversample < 1:
        bad("oversample", config.oversample, "must be a positive integer")
    if not isinstance(config.substeps, int) or config.substeps < 1:
        bad("substeps", config.substeps, "must be a positive integer")
    if not config.runs:
        bad("runs", config.runs, "needs at least one run")
    names = [r.name for r in config.runs]
    if len(set(names)) != len(names):
        bad("runs", names, "run names must be unique")
    for r in config.runs:
        d = np.asarray(r.direction, float)
        if d.shape != (3,) or not np.all(np.isfinite(d)) or np.linalg.norm(d) == 0:
            bad(f"runs[{r.name}].direction", r.direction, "must be a non-zero 3-vector")
        p = np.asarray(r.position_m, float)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            bad(f"runs[{r.name}].position_m", r.position_m, "must be a finite 3-vector")
    if config.sensor_layout is not None:
        if not isinstance(config.sensor_layout, str | os.PathLike):
            bad("sensor_layout", config.sensor_layout, "must be a layout name or a layout file path")
        _layout(config, guide)  # a bad layout raises ModelError naming the layout
    else:
        for p in config.sensors:
            if p not in guide.measuring_points_m:
                bad("sensors", config.sensors, f"point '{p}' not defined by guide {guide.name} "
                    f"(have {''.join(guide.measuring_points_m)})")
        if not config.axes or any(a not in "xyz" for a in config.axes):
            bad("axes", config.axes, "letters from 'xyz'")
    if config.pulse_s * config.sample_rate_hz * config.oversample < 2:
        bad("pulse_s", config.pulse_s, "shorter than two internal samples; raise oversample")


def _layout(config, guide) -> dict:
    """Run name -> tuple of SensorSpec: the resolved ``sensor_layout``, or ``sensors`` x ``axes`` in every run."""
    from guidefit.simulate.layouts import AXES, SensorSpec, resolve_layout

    if config.sensor_layout is not None:
        return resolve_layout(guide, config.sensor_layout, config.runs)
    specs = tuple(SensorSpec(f"acc_{p}_{a}", tuple(guide.measuring_points_m[p]), AXES[a])
                  for p in config.sensors for a in config.axes)
    return {r.name: specs for r in config.runs}


def _channels(config, guide, run: HammerRun):
    names, units, positions, directions = ["force"], ["N"], [tuple(run.position_m)], []
    d = np.asarray(run.direction, float)
    directions.append(d / np.linalg.norm(d))
    for spec in _layout(config, guide)[run.name]:
        names.append(spec.name)
        units.append("m/s^2")
        positions.append(tuple(spec.position_m))
        directions.append(np.array(spec.direction))
    return tuple(names), tuple(units), np.array(positions, float), np.array(directions, float)


def _rng(seed: int, run_name: str, hit: int, stream: int = 0):
    key = (zlib.crc32(run_name.encode("utf-8")), hit, stream)
    return np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=key))


def _hit_faults(faults, run_name: str, hit: int, n_hits: int) -> list:
    out = []
    for f in faults:
        p = f.parameters
        if p.get("run", "all") not in ("all", run_name):
            continue
        if "hit" in p and min(p["hit"], n_hits - 1) != hit:
            continue
        out.append(f)
    return out


def _simulate_hit(model: _Model, config, run: HammerRun, channels, hit: int, seed: int, faults):
    """One hit record: (data (n_samples, n_ch) as stored, hit truth dict)."""
    names, _units, positions, directions = channels
    fs = config.sample_rate_hz
    n_rec = round(config.record_s * fs)
    n_pre = round(config.pretrigger_s * fs)
    os_ = config.oversample
    rng = _rng(seed, run.name, hit)
    lo, hi = config.force_n
    peak = float(rng.uniform(lo, hi))
    onset = (n_pre - 1 + float(rng.uniform(0.0, 1.0))) / fs
    noise = rng.standard_normal((n_rec, len(names)))
    truth = {"index": hit, "peak_force_n": peak, "onset_s": onset, "faults": []}
    for f in faults:
        truth["faults"].append({"name": f.name, "parameters": dict(f.parameters)})
        if f.name == "overload":
            peak *= f.parameters["factor"]
            truth["peak_force_n"] = peak
    pulses = [(peak, onset, config.pulse_s)]
    for f in faults:
        if f.name == "double_hit":
            pulses.append((peak * f.parameters["ratio"], onset + f.parameters["delay_s"], config.pulse_s))
    truth["pulses"] = [{"peak_force_n": p[0], "onset_s": p[1], "duration_s": p[2]} for p in pulses]

    t_int = np.arange(n_rec * os_) / (fs * os_)
    force, acc = hit_response(model, run.position_m, run.direction, pulses, t_int, positions[1:], directions[1:],
                              substeps=config.substeps, tolerance=config.nonlinear_tolerance)
    signals = _decimate(np.column_stack([force, acc]), os_, config.anti_alias)
    return _measure(signals, config, names, noise, faults, rng_loose=_rng(seed, run.name, hit, 2)), truth



def _ranges(config, names) -> np.ndarray:
    return np.array([config.force_range_n if n == "force" else config.acc_range_m_s2 for n in names])


def _measure(signals, config, names, noise, faults, rng_loose=None) -> np.ndarray:
    """Sensor noise, loose-sensor rattle, ADC and dropped samples on one record (n, n_ch)."""
    ranges = _ranges(config, names)
    sigma = config.noise_fraction * ranges
    out = signals + noise * sigma
    fs = config.sample_rate_hz
    n_pre = round(config.pretrigger_s * fs)
    for f in faults:
        if f.name == "loose_sensor":
            if f.parameters["channel"] not in names:
                raise ModelError(f"fault loose_sensor: channel '{f.parameters['channel']}' not recorded; "
                                 f"have {', '.join(names)}")
            j = names.index(f.parameters["channel"])
            extra = rng_loose.standard_normal((2, out.shape[0]))
            out[:, j] += (f.parameters["noise_factor"] * max(sigma[j], 1e-6 * ranges[j]) * extra[0]
                          + f.parameters["rattle"] * np.abs(signals[:, j]) * extra[1])
    if config.adc_bits is not None:
        out = adc(out, ranges[None, :], config.adc_bits)
    for f in faults:
        if f.name == "dropped_hit":
            a = n_pre + round(f.parameters["start_s"] * fs)
            b = a + max(round(f.parameters["duration_s"] * fs), 1)
            out[a:b] = 0.0
    return out


def _quiet(config, names, n: int, seed: int, run_name: str, hit: int) -> np.ndarray:
    """A gap of noise only (signals layout)."""
    noise = _rng(seed, run_name, hit, 1).standard_normal((n, len(names)))
    return _measure(np.zeros((n, len(names))), config, names, noise, ())


def simulate(guide, effects=(), config: SimulationConfig | None = None, seed: int = 0,
             progress: bool = False):
    """Simulate a hammer test of ``guide`` with ``effects``; return (recording, truth).

    Parameters
    ----------
    guide : Guide or str
        A guide or the name / TOML path of one.
    effects : iterable of Effect or str
        Effects (``"NAME:param=value,..."``) the model of the test object has
        and the nominal model lacks (:data:`guidefit.model.effects.EFFECTS`).
    config : SimulationConfig
        Test set-up and measurement chain.
    seed : int
        Seed of every random draw (hit forces, onsets, noise); the same seed
        gives the same recording. Each hit has its own stream, so the first
        hits of a run do not depend on the number of hits or on the layout.
    progress : bool
        Show a progress bar on stderr (for the command line; :func:`guidefit.progress.progress_bar`).

    Returns
    -------
    recording : guidefit.io.RecordingData
        What an experimenter's DAQ would have stored (float32, SI units);
        write it with :func:`guidefit.io.write_recording`.
    truth : dict
        Effects, true modal table, K/c truth, hits; JSON-ready
        (:func:`truth_json`).

    Examples
    --------
    >>> data, truth = simulate("MRB35", ["added_mass:mass_kg=0.1"], SimulationConfig(hits=1, record_s=0.005))
    >>> data.runs[0].data.shape
    (1, 1000, 9)
    >>> truth["parameters"]["f_V"]["value"] < truth["nominal_modes"][3]["frequency_hz"]
    True
    """
    from guidefit.io import RecordingData

    guide, config, faults, model, choice = _prepare(guide, effects, config)
    runs, runs_truth = [], {}
    with progress_bar("simulating hits", len(config.runs) * config.hits, enabled=progress) as bar:
        for run in config.runs:
            hits_truth: list = []
            blocks = list(_iter_run(model, config, run, seed, faults, hits_truth, bar.advance))
            data = np.stack(blocks) if config.layout == "hits" else np.concatenate(blocks)
            runs.append(_run_data(config, model.guide, run, data))
            runs_truth[run.name] = _run_truth(run, hits_truth)
    recording = RecordingData(runs=tuple(runs), guide=guide_reference(guide), description=_description(seed))
    return recording, _truth(model, config, seed, runs_truth, faults, choice)


def _description(seed: int) -> str:
    return f"guidefit simulate, seed {seed}"


def _prepare(guide, effects, config):
    config = SimulationConfig() if config is None else config
    guide = as_guide(guide)
    _check_config(config, guide)
    faults = _faults(config)
    for f in faults:
        if f.parameters["run"] not in ("all", *(r.name for r in config.runs)):
            raise ModelError(f"fault {f.name}: run '{f.parameters['run']}' not simulated; "
                             f"have {', '.join(r.name for r in config.runs)}")
    _check_loose_sensors(faults, _layout(config, guide))
    model = build_model(guide, effects, config.damping)
    config, choice = _choose_forces(config, model)
    return guide, config, faults, model, choice


def _choose_forces(config, model):
    """``(config, ForceChoice or None)``: the hit forces chosen for the carriage when none are
    given (:func:`guidefit.simulate.levels.choose_forces`)."""
    from guidefit.simulate.levels import choose_forces

    sensors = {}
    for run in config.runs:
        _names, _units, positions, directions = _channels(config, model.guide, run)
        sensors[run.name] = (positions[1:], directions[1:])
    return choose_forces(config, model, sensors)


def _check_loose_sensors(faults, layout: dict) -> None:
    """A loose sensor must be a channel of a run it applies to (``run=all``: of any run)."""
    for f in faults:
        if f.name != "loose_sensor":
            continue
        channel, run = f.parameters["channel"], f.parameters["run"]
        targets = list(layout) if run == "all" else [run]
        if not any(channel in (s.name for s in layout[t]) for t in targets):
            have = sorted({s.name for t in targets for s in layout[t]})
            where = "any run" if run == "all" else f"run '{run}'"
            raise ModelError(f"fault loose_sensor: channel '{channel}' not recorded in {where}; "
                             f"have {', '.join(have)}")


def _run_faults(faults, names) -> tuple:
    """The faults of one run: a loose sensor only where its channel is recorded (a layout may
    record it in one run only; :func:`_check_loose_sensors` made sure some run does)."""
    return tuple(f for f in faults if f.name != "loose_sensor" or f.parameters["channel"] in names)


def _iter_run(model: _Model, config, run: HammerRun, seed: int, faults, hits_truth: list, tick):
    """Blocks of one run in stored order (float32); appends each hit's truth to ``hits_truth``.

    ``hits`` layout: one (n_samples, n_ch) record per hit. ``signals``: the records
    back to back, with ``gap_s`` of noise between them.
    """
    fs = config.sample_rate_hz
    n_rec, n_pre, n_gap = round(config.record_s * fs), round(config.pretrigger_s * fs), round(config.gap_s * fs)
    channels = _channels(config, model.guide, run)
    faults = _run_faults(faults, channels[0])
    start = 0
    for i in range(config.hits):
        hit_faults = _hit_faults(faults, run.name, i, config.hits)
        record, t = _simulate_hit(model, config, run, channels, i, seed, hit_faults)
        if config.layout == "hits":
            t["trigger_sample"] = n_pre
        else:
            if i > 0 and n_gap:
                yield _quiet(config, channels[0], n_gap, seed, run.name, i).astype(np.float32)
                start += n_gap
            t["record_start_sample"] = start
            t["trigger_sample"] = start + n_pre
            t["onset_s"] += start / fs
            for p in t["pulses"]:
                p["onset_s"] += start / fs
            start += n_rec
        hits_truth.append(t)
        tick()
        yield record.astype(np.float32)


def _run_data(config, guide, run: HammerRun, data=None):
    from guidefit.io import RunData

    names, units, positions, directions = _channels(config, guide, run)
    d = np.asarray(run.direction, float)
    return RunData(
        name=run.name, sample_rate_hz=float(config.sample_rate_hz), excitation_direction=d / np.linalg.norm(d),
        channel_names=names, units=units, positions_m=positions, directions=directions, data=data,
        layout=config.layout, excitation_position_m=np.asarray(run.position_m, float),
        pretrigger_samples=round(config.pretrigger_s * config.sample_rate_hz) if config.layout == "hits" else None,
    )


def _run_truth(run: HammerRun, hits_truth: list) -> dict:
    d = np.asarray(run.direction, float)
    return {
        "excitation_position_m": [float(x) for x in run.position_m],
        "excitation_direction": [float(x) for x in d / np.linalg.norm(d)],
        "hits": hits_truth,
    }


def _stream_h5(path: Path, guide, effects, config, seed: int, progress: bool) -> dict:
    """Write a ``signals`` simulation to HDF5 block by block (bounded memory); return the truth."""
    from guidefit.io import open_signals_writer

    guide, config, faults, model, choice = _prepare(guide, effects, config)
    runs_truth = {}
    with progress_bar("simulating hits", len(config.runs) * config.hits, enabled=progress) as bar:
        for k, run in enumerate(config.runs):
            hits_truth: list = []
            with open_signals_writer(path, _run_data(config, guide, run), guide=guide_reference(guide),
                                     description=_description(seed), mode="w" if k == 0 else "a",
                                     dtype=np.float32, compression="gzip") as writer:
                for block in _iter_run(model, config, run, seed, faults, hits_truth, bar.advance):
                    writer.append(block)
            runs_truth[run.name] = _run_truth(run, hits_truth)
    return _truth(model, config, seed, runs_truth, faults, choice)


def _truth(model: _Model, config, seed, runs_truth, faults, choice=None) -> dict:
    from guidefit import __version__

    sol, zeta, mass = model.solution, model.damping, model.guide.mass_kg
    order = np.argsort(sol.frequencies_hz)
    modes = [{"label": sol.labels[i], "frequency_hz": float(sol.frequencies_hz[i]),
              "damping_ratio": float(zeta[i])} for i in order]
    nom = model.nominal
    nominal = [{"label": nom.labels[i], "frequency_hz": float(nom.frequencies_hz[i])}
               for i in np.argsort(nom.frequencies_hz)]
    params = {}
    for key, label in (("V", "vertical"), ("H", "roll_low")):
        if label not in sol.labels:
            continue
        i = sol.labels.index(label)
        f, z = float(sol.frequencies_hz[i]), float(zeta[i])
        params[f"f_{key}"] = {"value": f, "unit": "Hz"}
        params[f"zeta_{key}"] = {"value": z, "unit": "1"}
        params[f"K_{key}"] = {"value": 4 * math.pi**2 * mass * f**2, "unit": "N/m"}
        params[f"c_{key}"] = {"value": 4 * math.pi * mass * f * z, "unit": "N*s/m"}
    notes = [("frequencies are undamped natural frequencies of the model with effects; "
             "K = 4 pi^2 M f^2, c = 4 pi M f zeta (Eq. 24-29) with M the guide's carriage mass")]
    if model.contacts is not None:
        notes.append("amplitude_dependence: modes are the small-amplitude linearisation at the static "
                     "equilibrium; harder hits soften the contacts and lower the frequencies")
    truth = {
        "format": TRUTH_FORMAT,
        "format_version": 1,
        "guidefit_version": __version__,
        "guide": model.guide.name,
        "seed": int(seed),
        "effects": [{"name": e.name, "parameters": dict(e.parameters)} for e in model.effects],
        "faults": [{"name": f.name, "parameters": dict(f.parameters)} for f in faults],
        "modes": modes,
        "nominal_modes": nominal,
        "parameters": params,
        "mass_kg": mass,
        "runs": _runs_truth_sensors(runs_truth, config, model.guide),
        "config": config.to_dict(),
        "notes": notes,
    }
    if choice is not None:  # only when the default forces would have clipped: MRB35's truth is unchanged
        truth["force_choice"] = {"message": choice.message(), "force_n": list(choice.force_n),
                                 "force_range_n": choice.force_range_n,
                                 "default_peak_m_s2": choice.default_peak_m_s2, "peak_m_s2": choice.peak_m_s2}
    if model.contacts is not None:
        truth["static_equilibrium_q"] = [float(x) for x in model.contacts.q0]
        truth["preload_m"] = model.contacts.preload_m
    return _jsonable(truth)


def _runs_truth_sensors(runs_truth: dict, config, guide) -> dict:
    """With a ``sensor_layout``, each run's truth lists its resolved sensors (name, position, direction)."""
    if config.sensor_layout is None:
        return runs_truth
    layout = _layout(config, guide)
    return {name: {**t, "sensors": [s.to_dict() for s in layout[name]]} for name, t in runs_truth.items()}


def _jsonable(obj):
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, float | np.floating):
        value = float(obj)
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return value
    return obj


def truth_json(truth: dict) -> str:
    """The truth dictionary as JSON text (sorted keys, stable across runs)."""
    import json

    return json.dumps(truth, indent=1, sort_keys=True) + "\n"


def truth_path(path) -> Path:
    """Where the truth of a recording goes: ``FILE.h5`` -> ``FILE.truth.json``.

    >>> truth_path("data/test.h5").name
    'test.truth.json'
    """
    path = Path(path)
    return path.with_name(path.stem + ".truth.json")


@dataclass(frozen=True)
class SimulationFiles:
    """What :func:`write_simulation` wrote: recording file(s), truth file and the truth itself."""

    recordings: tuple[Path, ...]
    truth_path: Path
    truth: dict


def write_simulation(path, guide, effects=(), config: SimulationConfig | None = None, seed: int = 0,
                     file_format: str | None = None, progress: bool = False) -> SimulationFiles:
    """Simulate a hammer test and write it in the contract format, its truth beside it.

    Parameters
    ----------
    path : str or Path
        Recording to write. HDF5 (``.h5``, gzip-compressed float32) holds every
        run; a continuous (``signals``) HDF5 recording is written block by block
        in bounded memory. CSV holds one run per file, so with several runs ``FILE.csv``
        becomes ``FILE_<run>.csv`` per run. The truth goes to
        ``FILE.truth.json`` (:func:`truth_path`).
    guide, effects, config, seed, progress
        As for :func:`simulate`.
    file_format : {'h5', 'csv'}, optional
        Default from the suffix of ``path``. CSV records are continuous
        (``layout='signals'``).

    Returns
    -------
    SimulationFiles

    Examples
    --------
    >>> import tempfile, pathlib
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     out = write_simulation(pathlib.Path(folder) / "test.h5", "MRB35",
    ...                            config=SimulationConfig(hits=1, record_s=0.005))
    ...     [p.name for p in out.recordings], out.truth_path.name
    (['test.h5'], 'test.truth.json')
    """
    from guidefit.io import RecordingData, write_recording

    path = Path(path)
    suffix = path.suffix.lower().lstrip(".")
    fmt = (file_format or {"hdf5": "h5"}.get(suffix, suffix)).lower()
    if fmt not in ("h5", "csv"):
        raise ModelError(f"output format '{fmt}' unknown; allowed: h5, csv (from --format or the file suffix)")
    config = SimulationConfig() if config is None else config
    if fmt == "csv":
        config = replace(config, layout="signals")
        if suffix != "csv":
            path = path.with_suffix(".csv")
    elif suffix not in ("h5", "hdf5"):
        path = path.with_suffix(".h5")
    from guidefit.outputs import refuse_inputs, replacing, write_text

    runs = list(config.runs)
    if fmt == "csv" and len(runs) > 1:
        written = [path.with_name(f"{path.stem}_{run.name}.csv") for run in runs]
    else:
        written = [path]
    target = truth_path(path)
    # every output is written whole (temporary file + rename) and never onto an input
    refuse_inputs([*written, target], [guide if isinstance(guide, (str, os.PathLike)) else None])
    if fmt == "h5" and config.layout == "signals":
        with replacing(path) as tmp:  # the runs are appended block by block: renamed when all are in
            truth = _stream_h5(tmp, guide, effects, config, seed, progress)
    else:
        recording, truth = simulate(guide, effects, config, seed, progress=progress)
        if fmt == "h5":
            write_recording(path, recording, compression="gzip")
        elif len(recording.runs) == 1:
            write_recording(path, recording)
        else:
            for out, run in zip(written, recording.runs):
                write_recording(out, RecordingData((run,), recording.guide, recording.description))
    truth = {**truth, "recordings": [p.name for p in written]}
    write_text(target, truth_json(truth))
    return SimulationFiles(tuple(written), target, truth)
