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
``SimulationConfig.force_n``; the onset lies at a random sub-sample instant
just before the trigger sample.

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

import itertools
import math
import os
import zlib
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from guidefit.errors import ModelError
from guidefit.layouts import DEFAULT_RUNS, HammerRun
from guidefit.model.guides import guide_reference

#: Modal damping ratio per mode label: the paper's identified values (Eq. 26, 28:
#: c_V = 2750 N s/m and c_H = 3109 N s/m give 2.88 % and 10.5 %) for the vertical
#: and horizontal (roll_low) modes; 2 % for pitch, yaw, roll_high.
DEFAULT_DAMPING = {"vertical": 0.029, "roll_low": 0.105, "pitch": 0.02, "yaw": 0.02, "roll_high": 0.02}
#: Damping ratio of any extra (support-body) mode.
SUPPORT_DAMPING = 0.02

TRUTH_FORMAT = "guidefit-simulation-truth"
PALMGREN_EXPONENT = 10.0 / 9.0


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
    force_n : (float, float)
        Range of the hits' peak forces (N), drawn uniformly per hit.
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
        Each run's accelerometers from a layout of :mod:`guidefit.layouts`
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
    force_n: tuple[float, float] = (200.0, 500.0)
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
    :mod:`guidefit.layouts`; ``hit_points`` ``RUN:x,y,z`` texts that move a
    run's hammer point (:func:`guidefit.layouts.apply_hits`).

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
        from guidefit.layouts import apply_hits

        changes["runs"] = apply_hits(changes.get("runs", cfg.runs), hit_points)
    cfg = replace(cfg, **changes)
    return cfg.ideal() if ideal else cfg


# --------------------------------------------------------------------------- model


@dataclass(frozen=True)
class _Model:
    """Everything the forward model needs for one guide and set of effects."""

    guide: object
    effects: tuple
    spec: object  # linear (small-amplitude) ModelSpec
    solution: object  # ModalSolution of spec
    damping: np.ndarray  # (n_modes,)
    nominal: object  # ModalSolution of the nominal guide
    contacts: _Contacts | None  # nonlinear contacts, or None


@dataclass(frozen=True)
class _Contacts:
    """Nonlinear preloaded Hertz contacts (rollers or balls) around the static equilibrium q0."""

    G: np.ndarray  # (N, n) roller gradients over the model DOFs
    C: np.ndarray  # (N,) law constants, Q = C delta^e (e = exponent)
    delta0: np.ndarray  # (N,) roller approach at q = 0
    K_ground: np.ndarray  # (n, n) linear springs of the support body to ground
    M: np.ndarray
    M_inv: np.ndarray
    C_damp: np.ndarray  # (n, n) modal damping matrix
    K_lin: np.ndarray  # (n, n) tangent stiffness at q0
    q0: np.ndarray  # (n,) static equilibrium
    preload_m: float  # Delta'
    exponent: float = PALMGREN_EXPONENT  # the guide's, static.exponent: 10/9 rollers, 3/2 balls

    def force(self, q: np.ndarray) -> np.ndarray:
        """Generalised restoring force of rollers and ground springs at q (N, N m)."""
        d = self.delta0 - self.G @ q
        return self.G.T @ (self.C * np.maximum(d, 0.0) ** self.exponent) - self.K_ground @ q

    def potential(self, q: np.ndarray) -> float:
        """Elastic energy at q (J): sum of int Q d(delta) over rollers plus ground springs."""
        d = np.maximum(self.delta0 - self.G @ q, 0.0)
        e = self.exponent + 1.0
        return float(np.sum(self.C * d**e / e) + 0.5 * q @ self.K_ground @ q)

    def tangent(self, q: np.ndarray) -> np.ndarray:
        """Tangent stiffness -dF/dq at q."""
        d = np.maximum(self.delta0 - self.G @ q, 0.0)
        k = self.exponent * self.C * d ** (self.exponent - 1.0)
        return (self.G * k[:, None]).T @ self.G + self.K_ground


def modal_damping(labels, overrides=None) -> np.ndarray:
    """Damping ratio per mode from its label: :data:`DEFAULT_DAMPING`, overridden by ``overrides``.

    >>> modal_damping(("yaw", "vertical", "support_1")).tolist()
    [0.02, 0.029, 0.02]
    """
    table = {**DEFAULT_DAMPING, **(overrides or {})}
    support = table.get("support", SUPPORT_DAMPING)
    out = []
    for label in labels:
        zeta = float(table.get(label, support))
        if not 0.0 <= zeta < 1.0:
            raise ModelError(f"damping of mode '{label}': must be in [0, 1), got {zeta}")
        out.append(zeta)
    return np.array(out)


def _as_guide(guide):
    from guidefit.model.guides import load_guide

    return load_guide(guide) if isinstance(guide, str | Path) else guide


def _as_effects(effects) -> tuple:
    from guidefit.model.effects import Effect, make_effect, parse_effect

    out = []
    for e in effects:
        if isinstance(e, str):
            out.append(parse_effect(e))
        elif isinstance(e, Effect):
            out.append(make_effect(e.name, e.parameters))
        else:
            raise ModelError(f"effect: expected 'NAME:param=value' or an Effect, got {e!r}")
    return tuple(out)


def build_model(guide, effects=(), damping=None) -> _Model:
    """The linear model (and nonlinear contacts if any effect needs them) of a simulation.

    >>> model = build_model("MRB35", ["added_mass:mass_kg=0.1"])
    >>> round(model.solution.frequency_hz("vertical"), 1), model.contacts is None
    (3451.5, True)
    """
    from guidefit.model import vibration as vib
    from guidefit.model.effects import apply_effects

    guide = _as_guide(guide)
    effects = _as_effects(effects)
    nominal_spec = vib.model_from_guide(guide)
    amplitude = [e for e in effects if e.name == "amplitude_dependence"]
    if len(amplitude) > 1:
        raise ModelError("effect amplitude_dependence given more than once")
    linear_effects = [e for e in effects if e.name != "amplitude_dependence"]
    base = apply_effects(nominal_spec, guide, linear_effects)
    contacts = None
    if amplitude:
        contacts, spec = _nonlinear_contacts(base, guide, amplitude[0].parameters["preload_factor"])
    else:
        spec = base
    solution = vib.solve_modes(spec)
    zeta = modal_damping(solution.labels, damping)
    if contacts is not None:
        phi = solution.shapes
        c_damp = contacts.M @ phi @ np.diag(2 * zeta * 2 * math.pi * solution.frequencies_hz) @ phi.T @ contacts.M
        contacts = replace(contacts, C_damp=c_damp)
    return _Model(guide, effects, spec, solution, zeta, vib.solve_modes(nominal_spec), contacts)


def _nonlinear_contacts(base, guide, preload_factor: float):
    """Nonlinear contacts built on the linear spec ``base``; returns (contacts, linearised spec)."""
    from guidefit.model import static
    from guidefit.model import vibration as vib

    if guide.preload_m <= 0:
        raise ModelError(f"effect amplitude_dependence: guide {guide.name} has no preload (contact.preload_m)")
    k_lin, m, _names = vib.assemble(base)
    if np.any(np.all(np.isclose(m, 0.0), axis=1)):
        raise ModelError(
            "effect amplitude_dependence: cannot be combined with a massless support coordinate "
            "(give the support a mass, e.g. base_mode)"
        )
    rollers = base.rollers
    g = vib.roller_gradients(rollers)
    if base.support is not None:
        rel = rollers.position_m - np.asarray(base.support.reference_m, float)
        g_body = vib.roller_gradients(replace(rollers, position_m=rel))
        free = np.isfinite(np.asarray(base.support.stiffness_to_ground, float))
        g = np.hstack([g, -g_body[:, free]])
    k_r = rollers.stiffness_n_per_m
    k_ground = k_lin - (g * k_r[:, None]).T @ g
    # the element law of the static model, Q = C delta^e (e = 10/9 rollers, 3/2 balls), calibrated ('nominal') so that
    # dQ/ddelta = K_n at the guide's preload; each roller scaled to its own linear stiffness
    k_nominal = guide.roller_stiffness_n_per_m * guide.effective_roller_fraction
    c = static.contact_constant(guide, "nominal") * k_r / k_nominal
    preload = preload_factor * guide.preload_m
    n = m.shape[0]
    contacts = _Contacts(
        G=g, C=c, delta0=np.full(len(k_r), preload), K_ground=k_ground, M=m, M_inv=np.linalg.inv(m),
        C_damp=np.zeros((n, n)), K_lin=np.zeros((n, n)), q0=np.zeros(n), preload_m=preload,
        exponent=static.exponent(guide),
    )
    q0 = _static_equilibrium(contacts)
    d0 = contacts.delta0 - g @ q0
    e = static.exponent(guide)
    k_tan = e * c * np.maximum(d0, 0.0) ** (e - 1.0)
    spec = vib.with_roller_stiffness(base, k_tan)
    contacts = replace(contacts, q0=q0, K_lin=contacts.tangent(q0))
    return contacts, spec


def _static_equilibrium(contacts: _Contacts) -> np.ndarray:
    q = np.zeros(contacts.M.shape[0])
    for _ in range(50):
        r = contacts.force(q)
        scale = np.abs(contacts.G.T @ (contacts.C * contacts.delta0**contacts.exponent)).max() + 1.0
        if np.abs(r).max() < 1e-12 * max(scale, float(np.sum(contacts.C * contacts.delta0**contacts.exponent))):
            return q
        q = q + np.linalg.solve(contacts.tangent(q), r)
    raise ModelError("effect amplitude_dependence: no static equilibrium found (rows lifted off)")


# --------------------------------------------------------------------------- responses


def half_sine_modal_acceleration(t_s, frequency_hz, damping_ratio, pulses) -> np.ndarray:
    """Exact modal accelerations of unit-participation modes under half-sine pulses.

    Solves ``eta'' + 2 zeta w eta' + w^2 eta = F(t)`` from rest, with
    ``F = sum_j F0_j sin(pi (t - t0_j) / T_j)`` on ``[t0_j, t0_j + T_j]``, by the
    closed-form Duhamel integral (module docstring).

    Parameters
    ----------
    t_s : array (n_t,)
        Sample instants (s).
    frequency_hz, damping_ratio : array (n_modes,)
        Undamped natural frequencies (Hz) and viscous damping ratios (< 1).
    pulses : iterable of (F0_n, t0_s, T_s)

    Returns
    -------
    ndarray (n_t, n_modes)
        eta'' in (m/s^2) per (kg^-1/2 ...) unit modal participation: multiply by
        ``b_k`` and the sensor's modal displacement.

    Examples
    --------
    A quasi-static check: a 1 Hz oscillator under a 0.1 ms pulse is a free mass,
    so its velocity after the pulse is the impulse ``2 F0 T / pi``.

    >>> import numpy as np
    >>> t = np.linspace(0, 1e-4, 2001)
    >>> a = half_sine_modal_acceleration(t, [1.0], [0.0], [(1.0, 0.0, 1e-4)])
    >>> bool(np.allclose(a[:, 0], np.sin(np.pi * t / 1e-4), atol=1e-6))
    True
    """
    t = np.asarray(t_s, dtype=float)[:, None]
    w = 2 * math.pi * np.asarray(frequency_hz, dtype=float)[None, :]
    zeta = np.asarray(damping_ratio, dtype=float)[None, :]
    wd = w * np.sqrt(1.0 - zeta**2)
    lam = -zeta * w + 1j * wd
    out = np.zeros((t.shape[0], w.shape[1]))
    flat = t[:, 0]
    for f0, t0, duration in pulses:
        if f0 == 0:
            continue
        om = math.pi / duration
        plus, minus = 1.0 / (1j * om - lam), 1.0 / (-1j * om - lam)
        # during the pulse: the full Duhamel integral
        during = (flat > t0) & (flat < t0 + duration)
        tau = t[during] - t0
        e2 = np.exp(lam * tau)
        j_int = ((np.exp(1j * om * tau) - e2) * plus - (np.exp(-1j * om * tau) - e2) * minus) / 2j
        out[during] += f0 * (np.imag(lam**2 * j_int) / wd + np.sin(om * tau))
        # after it: J = exp(lambda (t - t0 - T)) J(T), a free decay
        after = flat >= t0 + duration
        j_end = -(1.0 + np.exp(lam * duration)) * (plus - minus) / 2j
        decay = np.exp(lam * (t[after] - t0 - duration))
        out[after] += f0 * np.imag(lam**2 * j_end * decay) / wd
    return out


def _force(t: float, pulses) -> float:
    f = 0.0
    for f0, t0, duration in pulses:
        if t0 <= t <= t0 + duration:
            f += f0 * math.sin(math.pi * (t - t0) / duration)
    return f


def integrate_contacts(contacts: _Contacts, b: np.ndarray, pulses, t_s: np.ndarray, substeps: int = 1,
                       tolerance: float = 1e-2, solution=None, damping=None, q_init=None, v_init=None,
                       return_states: bool = False):
    """Carriage response with nonlinear contacts by fixed-step RK4 (module docstring).

    Parameters
    ----------
    contacts : nonlinear contact model (:func:`build_model`)
    b : array (n,)
        Generalised force per newton of hammer force.
    pulses : iterable of (F0_n, t0_s, T_s)
    t_s : array (n_t,)
        Equidistant output instants starting at 0; the RK4 step is their
        spacing divided by ``substeps``.
    tolerance : float
        Switch to the exact linear free decay once every roller's excursion is
        below ``tolerance * preload`` (needs ``solution`` and ``damping``; 0
        integrates to the end).
    q_init, v_init : array (n,), optional
        Initial displacement from equilibrium and velocity (default rest).

    Returns
    -------
    ndarray (n_t, n)
        Generalised accelerations; with ``return_states`` also (q - q0, v).
    """
    n_t = len(t_s)
    h = float(t_s[1] - t_s[0])
    n = contacts.M.shape[0]
    acc = np.zeros((n_t, n))
    pulses = list(pulses)
    breaks = sorted({p[1] for p in pulses} | {p[1] + p[2] for p in pulses})
    t_end_force = max((p[1] + p[2] for p in pulses), default=0.0)
    q0 = contacts.q0
    y = np.concatenate([q0 + (np.zeros(n) if q_init is None else np.asarray(q_init, float)),
                        np.zeros(n) if v_init is None else np.asarray(v_init, float)])
    if q_init is None and v_init is None and pulses:
        start = max(math.floor(min(p[1] for p in pulses) / h), 0)
    else:
        start = 0
    # y' = (v, M^-1 (Q(q) - K_ground q - C v + b F(t))), with M^-1 folded into the matrices
    g, g_t, c_law, d0, ex = contacts.G, contacts.M_inv @ contacts.G.T, contacts.C, contacts.delta0, contacts.exponent
    k_v = contacts.M_inv @ np.hstack([contacts.K_ground, contacts.C_damp])
    m_b = contacts.M_inv @ b

    def deriv(t, y):
        d = d0 - g @ y[:n]
        np.maximum(d, 0.0, out=d)
        out = np.empty(2 * n)
        out[:n] = y[n:]
        out[n:] = g_t @ (c_law * d**ex) - k_v @ y
        if t <= t_end_force:
            out[n:] += m_b * _force(t, pulses)
        return out

    states = np.zeros((n_t, 2 * n)) if return_states else None
    f = deriv(t_s[start], y)
    acc[start] = f[n:]
    if return_states:
        states[start] = y
    check_every = 32
    if tolerance > 0:
        flex = np.einsum("ij,ji->i", contacts.G, np.linalg.solve(contacts.K_lin, contacts.G.T))
    for i in range(start, n_t - 1):
        t0, t1 = t_s[i], t_s[i + 1]
        marks = [t0] + [x for x in breaks if t0 < x < t1] + [t1]
        first = True
        for ta, tb in itertools.pairwise(marks):
            hh = (tb - ta) / substeps
            for k in range(substeps):
                ts = ta + k * hh
                k1 = f if first else deriv(ts, y)
                first = False
                k2 = deriv(ts + hh / 2, y + (hh / 2) * k1)
                k3 = deriv(ts + hh / 2, y + (hh / 2) * k2)
                k4 = deriv(ts + hh, y + hh * k3)
                y = y + (hh / 6) * (k1 + 2 * (k2 + k3) + k4)
        f = deriv(t1, y)
        acc[i + 1] = f[n:]
        if return_states:
            states[i + 1] = y
        if tolerance > 0 and solution is not None and t1 > t_end_force and (i - start) % check_every == 0:
            dq, v = y[:n] - q0, y[n:]
            energy = 0.5 * v @ contacts.M @ v + 0.5 * dq @ contacts.K_lin @ dq
            if math.sqrt(2 * energy * flex.max()) < tolerance * contacts.preload_m:
                acc[i + 1:] = _free_decay(solution, damping, contacts.M, dq, v, t_s[i + 1:] - t1)
                break
    if return_states:
        return acc, states[:, :n] - q0, states[:, n:]
    return acc


def _free_decay(solution, damping, m, dq, v, tau) -> np.ndarray:
    """Generalised accelerations of the linear model's free decay from (dq, v) at tau = 0."""
    phi = solution.shapes
    eta0 = phi.T @ m @ dq
    deta0 = phi.T @ m @ v
    w = 2 * math.pi * solution.frequencies_hz
    wd = w * np.sqrt(1 - damping**2)
    lam = -damping * w + 1j * wd
    c = eta0 - 1j * (deta0 + damping * w * eta0) / wd
    eta_dd = np.real(c * lam**2 * np.exp(np.outer(tau, lam)))
    return eta_dd @ phi.T


# --------------------------------------------------------------------------- measurement chain


def adc(x, full_scale: float, bits: int = 16) -> np.ndarray:
    """A bipolar ADC: round to the LSB ``2 full_scale / 2^bits`` and clip to the code range.

    The codes run from ``-2^(bits-1)`` to ``2^(bits-1) - 1``: a signal beyond the
    range reads ``-full_scale`` or ``full_scale - LSB`` (flat-topped clipping).

    >>> adc([0.26, -3.0, 3.0], full_scale=2.0, bits=3)
    array([ 0.5, -2. ,  1.5])
    """
    lsb = 2.0 * full_scale / 2**bits
    codes = np.clip(np.round(np.asarray(x, dtype=float) / lsb), -(2 ** (bits - 1)), 2 ** (bits - 1) - 1)
    return codes * lsb + 0.0  # + 0.0: no negative zeros


def anti_alias_filter(oversample: int) -> np.ndarray:
    """Taps of the linear-phase anti-alias FIR at the internal rate (``oversample`` x fs).

    Kaiser window design: passband to 0.4 fs, stopband (> 90 dB) from 0.6 fs,
    so nothing aliases into 0-0.4 fs after decimation; the -6 dB point is fs/2.

    >>> taps = anti_alias_filter(4)
    >>> len(taps) % 2, round(float(taps.sum()), 6)
    (1, 1.0)
    """
    from scipy import signal

    nyq_internal = oversample / 2.0  # in units of fs
    numtaps, beta = signal.kaiserord(90.0, 0.2 / nyq_internal)
    numtaps += 1 - numtaps % 2
    return signal.firwin(numtaps, 0.5 / nyq_internal, window=("kaiser", beta))


def _decimate(x: np.ndarray, oversample: int, anti_alias: bool) -> np.ndarray:
    if oversample == 1:
        return x
    if not anti_alias:
        return x[::oversample]
    from scipy import signal

    return signal.resample_poly(x, 1, oversample, axis=0, window=anti_alias_filter(oversample))


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
    from guidefit.layouts import AXES, SensorSpec, resolve_layout

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


def hit_response(model: _Model, position_m, direction, pulses, t_s, sensor_positions_m, sensor_directions,
                 substeps: int = 1, tolerance: float = 1.0e-2):
    """Hammer force and sensor accelerations of one hit, before the measurement chain.

    The forward model of the module docstring: the exact modal response of a
    linear model, or the RK4 integration of the preloaded Hertz contacts
    (:func:`integrate_contacts`) when ``model`` has nonlinear contacts. Used by
    :func:`simulate` (at the oversampled internal rate) and by
    :mod:`guidefit.nonlinear` (the forward model of measured force levels).

    Parameters
    ----------
    model : the result of :func:`build_model`
    position_m, direction : (3,)
        Hit point (m, carriage frame) and force direction (any length).
    pulses : iterable of (F0_n, t0_s, T_s)
        Half-sine pulses: peak force (N), onset (s), duration (s).
    t_s : array (n_t,)
        Equidistant instants from 0 (s).
    sensor_positions_m, sensor_directions : (n_s, 3)
        Accelerometer points and unit measuring axes.
    substeps, tolerance
        As for :func:`integrate_contacts` (nonlinear contacts only).

    Returns
    -------
    force_n : ndarray (n_t,)
    acceleration_m_s2 : ndarray (n_t, n_s)

    Examples
    --------
    >>> import numpy as np
    >>> model = build_model("MRB35")
    >>> t = np.arange(400) / 200e3
    >>> f, a = hit_response(model, (0, 0, 0), (0, -1, 0), [(100.0, 1e-4, 1e-4)], t, [(0.03, 0, 0.045)], [(0, 1, 0)])
    >>> f.shape, a.shape, round(float(f.max()), 1)
    ((400,), (400, 1), 100.0)
    """
    from guidefit.model import vibration as vib

    t_int = np.asarray(t_s, float)
    d = np.asarray(direction, float)
    d = d / np.linalg.norm(d)
    sol = model.solution
    from guidefit.labels import Sensor, sensor_matrix

    sensor_rows = sensor_matrix([Sensor("", p, dr) for p, dr in zip(sensor_positions_m, sensor_directions)])
    b_q = np.zeros(sol.shapes.shape[0])
    b_q[:5] = d @ vib.rigid_body_map(position_m)
    if model.contacts is None:
        b = b_q @ sol.shapes  # modal participation of the hammer
        eta_dd = half_sine_modal_acceleration(t_int, sol.frequencies_hz, model.damping, pulses) * b
        acc = eta_dd @ (sensor_rows @ sol.shapes[:5]).T
    else:
        q_dd = integrate_contacts(model.contacts, b_q, pulses, t_int, substeps=substeps,
                                  tolerance=tolerance, solution=sol, damping=model.damping)
        acc = q_dd[:, :5] @ sensor_rows.T
    force = np.zeros(len(t_int))
    for f0, t0, dur in pulses:
        tau = t_int - t0
        inside = (tau > 0) & (tau < dur)
        force[inside] += f0 * np.sin(math.pi * tau[inside] / dur)
    return force, acc


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
        Show a rich progress bar (for the command line).

    Returns
    -------
    recording : guidefit.recording.RecordingData
        What an experimenter's DAQ would have stored (float32, SI units);
        write it with :func:`guidefit.recording.write_recording`.
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
    from guidefit.recording import RecordingData

    guide, config, faults, model = _prepare(guide, effects, config)
    runs, runs_truth = [], {}
    with _progress(progress, len(config.runs) * config.hits) as tick:
        for run in config.runs:
            hits_truth: list = []
            blocks = list(_iter_run(model, config, run, seed, faults, hits_truth, tick))
            data = np.stack(blocks) if config.layout == "hits" else np.concatenate(blocks)
            runs.append(_run_data(config, model.guide, run, data))
            runs_truth[run.name] = _run_truth(run, hits_truth)
    recording = RecordingData(runs=tuple(runs), guide=guide_reference(guide), description=_description(seed))
    return recording, _truth(model, config, seed, runs_truth, faults)


def _description(seed: int) -> str:
    return f"guidefit simulate, seed {seed}"


def _prepare(guide, effects, config):
    config = SimulationConfig() if config is None else config
    guide = _as_guide(guide)
    _check_config(config, guide)
    faults = _faults(config)
    for f in faults:
        if f.parameters["run"] not in ("all", *(r.name for r in config.runs)):
            raise ModelError(f"fault {f.name}: run '{f.parameters['run']}' not simulated; "
                             f"have {', '.join(r.name for r in config.runs)}")
    _check_loose_sensors(faults, _layout(config, guide))
    return guide, config, faults, build_model(guide, effects, config.damping)


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


class _progress:
    """Context manager yielding a tick() callable; a rich bar on stderr when enabled."""

    def __init__(self, enabled: bool, total: int):
        self.enabled, self.total, self.bar = enabled, total, None

    def __enter__(self):
        if not self.enabled:
            return lambda: None
        from rich.console import Console
        from rich.progress import Progress

        console = Console(stderr=True)
        if not console.is_terminal:  # a log or a pipe gets no bar (nor the blank line it leaves)
            return lambda: None
        self.bar = Progress(console=console, transient=True)
        self.bar.__enter__()
        task = self.bar.add_task("simulating hits", total=self.total)
        return lambda: self.bar.advance(task)

    def __exit__(self, *exc):
        if self.bar is not None:
            self.bar.__exit__(*exc)
        return False


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
    from guidefit.recording import RunData

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
    from guidefit.recording import open_signals_writer

    guide, config, faults, model = _prepare(guide, effects, config)
    runs_truth = {}
    with _progress(progress, len(config.runs) * config.hits) as tick:
        for k, run in enumerate(config.runs):
            hits_truth: list = []
            with open_signals_writer(path, _run_data(config, guide, run), guide=guide_reference(guide),
                                     description=_description(seed), mode="w" if k == 0 else "a",
                                     dtype=np.float32, compression="gzip") as writer:
                for block in _iter_run(model, config, run, seed, faults, hits_truth, tick):
                    writer.append(block)
            runs_truth[run.name] = _run_truth(run, hits_truth)
    return _truth(model, config, seed, runs_truth, faults)


def _truth(model: _Model, config, seed, runs_truth, faults) -> dict:
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
    from guidefit.recording import RecordingData, write_recording

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
