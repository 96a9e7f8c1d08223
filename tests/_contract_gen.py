"""An independent writer of contract recordings (shared/recording-format.md, version 1).

Written for the conformance audit from the contract and physics-notes only: it
does not import guidefit. The carriage is the pinned nominal MRB35 rigid body on
4 x 21 roller springs (physics-notes), its modes computed here from the roller
geometry; each hit is a half-sine force pulse, the responses the exact modal
superposition of the accelerations at the sensors (frequency domain, zero
padded so nothing wraps), with modal damping ratios chosen per mode.
"""

from __future__ import annotations

import numpy as np

G = 9.80665
M = 2.2
J = (3.927626e-3, 5.761594e-3, 2.467506e-3)
E, H1, H0, BETA, ZL, LL, KN = 0.032, 0.0235, 0.0107, np.radians(45.0), 21, 0.090, 2.5754e7
POINTS = {"A": (0.030, 0.0, 0.045), "B": (-0.030, 0.0, 0.045), "C": (-0.030, 0.0, -0.045),
          "D": (0.030, 0.0, -0.045)}
AXES = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}
# pinned nominal frequencies of physics-notes, Hz
NOMINAL = {"yaw": 1879.1, "pitch": 2275.9, "roll_low": 2496.4, "vertical": 3529.0, "roll_high": 5563.6}


def _g(r, n):
    """Generalised direction of a displacement along n at r for q = (u, v, theta, psi, phi)."""
    m = np.cross(r, n)
    return np.array([n[0], n[1], m[0], m[1], m[2]])


def stiffness(kn=KN):
    h3 = H1 + H0
    c, s = np.cos(BETA), np.sin(BETA)
    rows = [((-E, -H1), (c, s)), ((E, -H1), (-c, s)), ((-E, -h3), (c, -s)), ((E, -h3), (-c, -s))]
    K = np.zeros((5, 5))
    for (x, y), (nx, ny) in rows:
        for z in np.linspace(-LL / 2, LL / 2, ZL):
            g = _g(np.array([x, y, z]), np.array([nx, ny, 0.0]))
            K += kn * np.outer(g, g)
    return K


def modes(kn=KN, mass=M, k_support=None):
    """(frequencies Hz, mass-normalised shapes 5 x 5 columns), ascending."""
    m = np.array([mass, mass, *J])
    K = stiffness(kn) if k_support is None else stiffness_with_lateral_support(k_support, kn)
    Kt = K / np.sqrt(np.outer(m, m))
    w2, v = np.linalg.eigh(Kt)
    return np.sqrt(w2) / (2 * np.pi), v / np.sqrt(m)[:, None]


def sensor_row(position, direction):
    return _g(np.asarray(position, float), np.asarray(direction, float))


def accel_frf(freqs_hz, rows_out, row_in, zetas, kn=KN, mass=M, k_support=None, modal=None):
    """Acceleration per force FRF (m/s^2/N), one column per output row.

    ``modal`` = (frequencies, shapes) overrides the carriage's modes; shapes may have extra
    DOFs after the carriage's five (a base body), which no sensor or hammer touches.
    """
    f, phi = modes(kn, mass, k_support) if modal is None else modal
    pad = np.zeros(phi.shape[0] - 5)
    w = 2 * np.pi * np.asarray(freqs_hz)[:, None]
    out = np.zeros((len(freqs_hz), len(rows_out)), complex)
    for r in range(len(f)):
        wr = 2 * np.pi * f[r]
        a_in = np.append(row_in, pad) @ phi[:, r]
        a_out = np.array([np.append(ro, pad) @ phi[:, r] for ro in rows_out])
        out += (-(w ** 2) * a_in * a_out[None, :]) / (wr ** 2 - w ** 2 + 2j * zetas[r] * wr * w)
    return out


def half_sine(n, fs, width_s, peak, start):
    t = np.arange(n) / fs
    x = (t - start) / width_s
    return np.where((x >= 0) & (x <= 1), peak * np.sin(np.pi * np.clip(x, 0, 1)), 0.0)


def hit_record(n, fs, channels, hit_pos, hit_dir, peak=300.0, width_s=1e-4, pre=200, zetas=None,
               noise=0.0, rng=None, kn=KN, mass=M, k_support=None, modal=None):
    """One hit: (n, n_channels) in SI (N, m/s^2); channels = list of (name, position, direction)."""
    zetas = np.full(5 if modal is None else len(modal[0]), 0.02) if zetas is None else np.asarray(zetas)
    npad = 4 * n
    force = half_sine(npad, fs, width_s, peak, pre / fs)
    F = np.fft.rfft(force)
    freqs = np.fft.rfftfreq(npad, 1 / fs)
    outs = [(i, sensor_row(p, d)) for i, (name, p, d) in enumerate(channels) if name.startswith("acc")]
    H = accel_frf(freqs, [r for _, r in outs], sensor_row(hit_pos, hit_dir), zetas, kn, mass, k_support, modal)
    rec = np.zeros((n, len(channels)))
    for i, (name, _, _) in enumerate(channels):
        if name == "force":
            rec[:, i] = force[:n]
    for k, (i, _) in enumerate(outs):
        rec[:, i] = np.fft.irfft(F * H[:, k], npad)[:n]
    if noise and rng is not None:
        rec += noise * rng.standard_normal(rec.shape) * np.abs(rec).max(axis=0)
    return rec


def default_channels(axes="xy", points="ABCD"):
    chans = [("force", None, None)]
    for p in points:
        for a in axes:
            chans.append((f"acc_{p}_{a}", POINTS[p], AXES[a]))
    return chans


RUNS = {
    # hit position, direction: off centre so that several modes show
    "vertical": ((0.010, 0.0, 0.020), (0.0, -1.0, 0.0)),
    "lateral": ((0.035, -0.010, 0.015), (-1.0, 0.0, 0.0)),
}


def run_hits(run="vertical", n_hits=4, n=8000, fs=200_000.0, seed=0, axes="xy", zetas=None, noise=0.002,
             kn=KN, mass=M, peaks=None, channels=None, k_support=None, modal=None):
    rng = np.random.default_rng(seed)
    pos, d = RUNS[run]
    chans = channels or default_channels(axes)
    chans = [(name, pos if name == "force" else p, d if name == "force" else dd) for name, p, dd in chans]
    peaks = peaks if peaks is not None else rng.uniform(200, 400, n_hits)
    data = np.stack([hit_record(n, fs, chans, pos, d, peak=pk, zetas=zetas, noise=noise, rng=rng, kn=kn,
                                mass=mass, k_support=k_support, modal=modal) for pk in peaks])
    return chans, data


def write_run(group, chans, data, fs, direction, position=None, layout="hits", units=None, dtype=np.float64,
              pretrigger=None, str_kind="vlen", chunks=None, compression=None, names=None):
    """Write one run group. data in SI; a channel whose unit is 'g' is stored divided by G."""

    units = units or ["N" if c[0] == "force" else "m/s^2" for c in chans]
    arr = np.array(data, dtype=np.float64)
    for i, u in enumerate(units):
        if u == "g":
            arr[..., i] /= G
    if layout == "signals":
        arr = arr.reshape(-1, arr.shape[-1]) if arr.ndim == 3 else arr
    group.attrs["sample_rate_hz"] = fs
    group.attrs["excitation_direction"] = np.asarray(direction, float)
    if position is not None:
        group.attrs["excitation_position_m"] = np.asarray(position, float)
    ds = group.create_dataset(layout, data=arr.astype(dtype), chunks=chunks, compression=compression)
    names = names or [c[0] for c in chans]
    ds.attrs["channel_names"] = _strs(names, str_kind)
    ds.attrs["units"] = _strs(units, str_kind)
    ds.attrs["positions_m"] = np.array([c[1] for c in chans], float)
    ds.attrs["directions"] = np.array([c[2] for c in chans], float)
    if pretrigger is not None:
        ds.attrs["pretrigger_samples"] = pretrigger
    return ds


def _strs(values, kind):
    import h5py

    if kind == "vlen":
        return np.array(values, dtype=h5py.string_dtype())
    if kind == "fixed":
        return np.array([v.encode() for v in values])
    if kind == "list":
        return list(values)
    raise ValueError(kind)


def write_file(path, runs, guide="MRB35", description=None, version=1, fmt="guidefit-recording"):
    """runs: {name: kwargs for write_run}."""
    import h5py

    with h5py.File(path, "w") as f:
        if fmt is not None:
            f.attrs["format"] = fmt
        if version is not None:
            f.attrs["format_version"] = version
        if guide is not None:
            f.attrs["guide"] = guide
        if description is not None:
            f.attrs["description"] = description
        for name, kw in runs.items():
            write_run(f.create_group(f"runs/{name}"), **kw)
    return path


def standard_file(path, layout="hits", units_acc="m/s^2", runs=("vertical", "lateral"), seed=0, n_hits=4, n=8000,
                  fs=200_000.0, zetas=None, dtype=np.float64, noise=0.002, **kw):
    spec = {}
    for i, r in enumerate(runs):
        chans, data = run_hits(r, n_hits=n_hits, n=n, fs=fs, seed=seed + i, zetas=zetas, noise=noise)
        units = ["N" if c[0] == "force" else units_acc for c in chans]
        if layout == "signals":
            gap = np.zeros((n // 2, data.shape[-1]))
            data = np.concatenate([np.concatenate([gap, h]) for h in data] + [gap])
        spec[r] = dict(chans=chans, data=data, fs=fs, direction=RUNS[r][1], position=RUNS[r][0], layout=layout,
                       units=units, dtype=dtype, **({"pretrigger": 200} if layout == "hits" else {}))
    return write_file(path, spec, **kw)


def write_csv(path, chans, data, fs, direction, meta=None, time_col=True, units=None, newline="\n", bom=False,
              rate_line=True, positions=True):
    """One continuous record (n, n_ch) in SI as a contract CSV."""
    units = units or ["N" if c[0] == "force" else "m/s^2" for c in chans]
    arr = np.array(data, float)
    for i, u in enumerate(units):
        if u == "g":
            arr[:, i] /= G
    lines = []
    if meta is None:
        meta = {"guide": "MRB35"}
    for k, v in meta.items():
        lines.append(f"# {k}: {v}")
    if rate_line:
        lines.append(f"# sample_rate_hz: {float(fs)!r}")
    lines.append("# excitation_direction: " + " ".join(repr(float(x)) for x in direction))
    if positions:
        lines.append("# positions_m: " + "; ".join(" ".join(repr(float(x)) for x in c[1]) for c in chans))
        lines.append("# directions: " + "; ".join(" ".join(repr(float(x)) for x in c[2]) for c in chans))
    lines.append("# units: " + ("s " if time_col else "") + " ".join(units))
    names = (["time"] if time_col else []) + [c[0] for c in chans]
    lines.append(",".join(names))
    t = np.arange(len(arr)) / fs
    for i, row in enumerate(arr):
        vals = ([repr(float(t[i]))] if time_col else []) + [repr(float(x)) for x in row]
        lines.append(",".join(vals))
    text = newline.join(lines) + newline
    with open(path, "w", encoding="utf-8-sig" if bom else "utf-8", newline="") as fh:
        fh.write(text)
    return path


def _stiffness_with_rail(k_rail, rail_axis, kn=KN):
    """6x6 stiffness of the carriage (5 DOF) and a rigid rail moving along x (``rail_axis`` 0) or
    y (1) on a spring ``k_rail`` to ground; each roller spring acts on the normal component of
    carriage motion minus rail motion: g_c . q - n_axis r."""
    h3 = H1 + H0
    c, s = np.cos(BETA), np.sin(BETA)
    rows = [((-E, -H1), (c, s)), ((E, -H1), (-c, s)), ((-E, -h3), (c, -s)), ((E, -h3), (-c, -s))]
    K = np.zeros((6, 6))
    for (x, y), normal in rows:
        for z in np.linspace(-LL / 2, LL / 2, ZL):
            g = np.append(_g(np.array([x, y, z]), np.array([*normal, 0.0])), -normal[rail_axis])
            K += kn * np.outer(g, g)
    K[5, 5] += k_rail
    return K


def stiffness_with_lateral_support(k_support, kn=KN):
    """5x5 carriage stiffness with the rail on a lateral spring to ground (massless rail, condensed)."""
    K = _stiffness_with_rail(k_support, 0, kn)
    return K[:5, :5] - np.outer(K[:5, 5], K[5, :5]) / K[5, 5]


def modes_with_vertical_base(base_mass, k_base, kn=KN):
    """6-DOF modes: the carriage on its rollers on a rail body of mass ``base_mass`` that moves
    vertically on a spring ``k_base`` to ground (the rollers act on carriage minus rail motion)."""
    K = _stiffness_with_rail(k_base, 1, kn)
    m = np.array([M, M, *J, base_mass])
    w2, v = np.linalg.eigh(K / np.sqrt(np.outer(m, m)))
    return np.sqrt(w2) / (2 * np.pi), v / np.sqrt(m)[:, None]
