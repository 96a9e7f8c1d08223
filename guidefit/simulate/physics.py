"""The simulator's physics: forward model, hit responses and measurement chain.

Everything :mod:`guidefit.simulate` computes for one hit, as pure functions
of the model and the pulses: the modal model of a guide with its effects and
damping (:func:`build_model`, :func:`modal_damping`), the exact linear
half-sine response (:func:`half_sine_modal_acceleration`), the nonlinear Hertz
contacts integrated by RK4 (:func:`integrate_contacts`), the response of one
hit at the sensors (:func:`hit_response`) and the measurement chain (anti-alias
filter and decimation, :func:`adc`). The equations are described in the
docstring of :mod:`guidefit.simulate`.

It is separate from :mod:`guidefit.simulate`, which holds the configuration
(:class:`~guidefit.simulate.SimulationConfig`, faults), the loop over runs and
hits and the writing of recordings and truth files, so that the physics can
be read and reused (:mod:`guidefit.nonlinear` runs :func:`hit_response`)
without the file and configuration code. Every name here stays importable
from :mod:`guidefit.simulate` as before.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, replace

import numpy as np

from guidefit.errors import ModelError

#: Modal damping ratio per mode label: the paper's identified values (Eq. 26, 28:
#: c_V = 2750 N s/m and c_H = 3109 N s/m give 2.88 % and 10.5 %) for the vertical
#: and horizontal (roll_low) modes; 2 % for pitch, yaw, roll_high.
DEFAULT_DAMPING = {"vertical": 0.029, "roll_low": 0.105, "pitch": 0.02, "yaw": 0.02, "roll_high": 0.02}
#: Damping ratio of any extra (support-body) mode.
SUPPORT_DAMPING = 0.02

PALMGREN_EXPONENT = 10.0 / 9.0


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
    from guidefit.model.guides import as_guide

    guide = as_guide(guide)
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
    t_int = np.asarray(t_s, float)
    if model.contacts is None:
        acc = linear_acceleration(model, position_m, direction, pulses, t_int, sensor_positions_m, sensor_directions)
    else:
        b_q, sensor_rows = _hammer_and_sensors(model, position_m, direction, sensor_positions_m, sensor_directions)
        q_dd = integrate_contacts(model.contacts, b_q, pulses, t_int, substeps=substeps,
                                  tolerance=tolerance, solution=model.solution, damping=model.damping)
        acc = q_dd[:, :5] @ sensor_rows.T
    force = np.zeros(len(t_int))
    for f0, t0, dur in pulses:
        tau = t_int - t0
        inside = (tau > 0) & (tau < dur)
        force[inside] += f0 * np.sin(math.pi * tau[inside] / dur)
    return force, acc


def _hammer_and_sensors(model: _Model, position_m, direction, sensor_positions_m, sensor_directions):
    """Generalised force per newton of hammer force (n_dof,) and the sensors' rows (n_s, 5)."""
    from guidefit.model import vibration as vib
    from guidefit.modes.labels import Sensor, sensor_matrix

    d = np.asarray(direction, float)
    d = d / np.linalg.norm(d)
    sensor_rows = sensor_matrix([Sensor("", p, dr) for p, dr in zip(sensor_positions_m, sensor_directions)])
    b_q = np.zeros(model.solution.shapes.shape[0])
    b_q[:5] = d @ vib.rigid_body_map(position_m)
    return b_q, sensor_rows


def linear_acceleration(model: _Model, position_m, direction, pulses, t_s, sensor_positions_m,
                        sensor_directions) -> np.ndarray:
    """Sensor accelerations (n_t, n_s) of the linear (small-amplitude) model under half-sine pulses.

    The exact modal response of :func:`half_sine_modal_acceleration`; for a
    model with nonlinear contacts, that of its linearisation at the static
    equilibrium (what :func:`hit_response` gives for a vanishing hit).

    Examples
    --------
    >>> import numpy as np
    >>> model = build_model("MRB35")
    >>> t = np.arange(400) / 200e3
    >>> a = linear_acceleration(model, (0, 0, 0), (0, -1, 0), [(100.0, 1e-4, 1e-4)], t, [(0.03, 0, 0.045)], [(0, 1, 0)])
    >>> a.shape, bool(np.abs(a).max() > 10)
    ((400, 1), True)
    """
    sol = model.solution
    b_q, sensor_rows = _hammer_and_sensors(model, position_m, direction, sensor_positions_m, sensor_directions)
    b = b_q @ sol.shapes  # modal participation of the hammer
    eta_dd = half_sine_modal_acceleration(np.asarray(t_s, float), sol.frequencies_hz, model.damping, pulses) * b
    return eta_dd @ (sensor_rows @ sol.shapes[:5]).T
