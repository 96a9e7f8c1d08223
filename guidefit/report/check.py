"""Tolerance checks of identify results for production lines and CI (``identify --check``).

A check spec is a TOML file::

    [parameters]                      # bands for any reported parameter (SI)
    K_V = { min = 0.9e9, max = 1.2e9 }
    f_H = { min = 900.0 }
    zeta_V = { max = 0.05 }

    [quality]
    min_coherence = 0.95              # coherence at the peak of the vertical and horizontal modes
    max_rejected_hits = 2             # per file
    max_relative_std = 0.02           # std / value of every checked parameter
    allow_warnings = true             # false: any warning is a violation

A parameter that was not identified (``null``) violates any band on it. A
result from an FRF file (``hits_checked: false``) violates
``max_rejected_hits`` (its hits could not be checked), and a joint mode
without a coherence (an FRF file without one) violates ``min_coherence``. A band
on a name that is not one of identify's eight parameters, a limit that is not a
finite number, or a quality limit out of its range (coherence 0-1, counts whole
and >= 0) makes the spec invalid (exit 2) rather than fail every file.
:func:`junit_xml` writes the outcome per file as JUnit XML for CI systems.

Examples
--------
>>> spec = parse_spec({"parameters": {"K_V": {"min": 0.9e9, "max": 1.2e9}}}, "spec")
>>> check_result({"file": "a.h5", "parameters": {"K_V": {"value": 1.3e9, "std": 1e6}}}, spec)
['a.h5: K_V = 1.3e+09 above max 1.2e+09']
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

from guidefit.errors import GuideError
from guidefit.model.vibration import JOINT_LABELS

_QUALITY = {"min_coherence": float, "max_rejected_hits": int, "max_relative_std": float, "allow_warnings": bool}
_PARAMETERS = ("f_V", "zeta_V", "K_V", "c_V", "f_H", "zeta_H", "K_H", "c_H")  # identify's parameters


class CheckSpecError(GuideError):
    """The check spec file is invalid (exit 2)."""


@dataclass(frozen=True)
class CheckSpec:
    """Parameter bands and quality limits."""

    bands: dict = field(default_factory=dict)  # name -> (min or None, max or None)
    quality: dict = field(default_factory=dict)


def load_spec(path) -> CheckSpec:
    """Read a check spec TOML file; one-line :class:`CheckSpecError` on any problem."""
    import tomllib

    try:
        with open(path, "rb") as handle:
            data = tomllib.load(handle)
    except OSError as exc:
        raise CheckSpecError(f"{path}: cannot read check spec ({exc.strerror})") from None
    except tomllib.TOMLDecodeError as exc:
        raise CheckSpecError(f"{path}: not valid TOML ({exc})") from None
    return parse_spec(data, str(path))


def parse_spec(data: dict, where: str) -> CheckSpec:
    """Validate a check spec given as a dict (the parsed TOML)."""
    unknown = set(data) - {"parameters", "quality"}
    if unknown:
        raise CheckSpecError(f"{where}: unknown section '{sorted(unknown)[0]}'; allowed: parameters, quality")
    bands = {}
    for name, band in data.get("parameters", {}).items():
        if name not in _PARAMETERS:  # a typo would otherwise fail every file as "not identified"
            raise CheckSpecError(f"{where}: unknown parameter 'parameters.{name}'; allowed: {', '.join(_PARAMETERS)}")
        if not isinstance(band, dict) or not band or set(band) - {"min", "max"}:
            raise CheckSpecError(f"{where}: parameters.{name} must be a table with 'min' and/or 'max'")
        lo, hi = band.get("min"), band.get("max")
        for key, value in (("min", lo), ("max", hi)):
            if value is not None and (isinstance(value, bool) or not isinstance(value, int | float)
                                      or not math.isfinite(value)):
                raise CheckSpecError(f"{where}: parameters.{name}.{key} must be a finite number, got {value!r}")
        if lo is not None and hi is not None and lo > hi:
            raise CheckSpecError(f"{where}: parameters.{name}: min {lo} is above max {hi}")
        bands[name] = (lo, hi)
    quality = {}
    for name, value in data.get("quality", {}).items():
        if name not in _QUALITY:
            raise CheckSpecError(f"{where}: unknown field 'quality.{name}'; allowed: {', '.join(_QUALITY)}")
        kind = _QUALITY[name]
        ok = isinstance(value, bool) if kind is bool else (isinstance(value, int | float)
                                                           and not isinstance(value, bool))
        if ok and kind is int:
            ok = float(value).is_integer() and value >= 0
        elif ok and kind is float:
            ok = math.isfinite(value) and value >= 0 and (name != "min_coherence" or value <= 1)
        if not ok:
            expected = {"min_coherence": "a number from 0 to 1", "max_rejected_hits": "an integer >= 0",
                        "max_relative_std": "a finite number >= 0", "allow_warnings": "true or false"}[name]
            raise CheckSpecError(f"{where}: quality.{name} must be {expected}, got {value!r}")
        quality[name] = value
    return CheckSpec(bands, quality)


def check_result(result: dict, spec: CheckSpec) -> list[str]:
    """Violations of one identify result (the ``to_dict()``/JSON form); empty when it passes."""
    where = result.get("file", "?")
    if "error" in result:
        return [f"{where}: {result['error']}"]
    out = []
    params = result.get("parameters", {})
    for name, (lo, hi) in spec.bands.items():
        p = params.get(name)
        value = None if p is None else p.get("value")
        if value is None:
            out.append(f"{where}: {name} not identified (band {lo} .. {hi})")
            continue
        if lo is not None and value < lo:
            out.append(f"{where}: {name} = {value:.4g} below min {lo:.4g}")
        if hi is not None and value > hi:
            out.append(f"{where}: {name} = {value:.4g} above max {hi:.4g}")
        limit = spec.quality.get("max_relative_std")
        std = p.get("std")
        if limit is not None and std is not None and value and abs(std / value) > limit:
            out.append(f"{where}: {name} relative std {abs(std / value):.3g} above {limit:.3g}")
    q = spec.quality
    if "min_coherence" in q:
        for mode in result.get("modes", []):
            coh = mode.get("coherence")
            if mode.get("label") in JOINT_LABELS.values() and (coh is None or coh != coh):  # an FRF file without coherence
                out.append(f"{where}: no coherence at the {mode['label']} peak to check against {q['min_coherence']}")
            elif mode.get("label") in JOINT_LABELS.values() and coh < q["min_coherence"]:
                out.append(f"{where}: coherence {coh:.3f} at the {mode['label']} peak below {q['min_coherence']}")
    if "max_rejected_hits" in q and result.get("hits_checked") is False:
        out.append(f"{where}: max_rejected_hits not checkable: no hit checks were possible (FRF input)")
    elif "max_rejected_hits" in q:
        rejected = sum(1 for h in result.get("hits", []) if not h.get("accepted", True))
        if rejected > q["max_rejected_hits"]:
            out.append(f"{where}: {rejected} rejected hits, more than {q['max_rejected_hits']}")
    if q.get("allow_warnings") is False:
        out += [f"{where}: warning: {w}" for w in result.get("warnings", [])]
    return out


#: characters XML 1.0 cannot hold, not even as character references (C0 controls other than
#: tab and line breaks, lone surrogates of undecodable file names, U+FFFE, U+FFFF)
_NOT_XML = re.compile("[^\t\n\r\x20-\ud7ff\ue000-\ufffd\U00010000-\U0010ffff]")


def xml_text(text: str) -> str:
    r"""``text`` with each character XML 1.0 cannot hold written as visible ``\xNN`` / ``\uNNNN``.

    >>> xml_text("rec\x01.h5"), xml_text("a\x1b[31m"), xml_text("caf\udce9.h5"), xml_text("tab\tok")
    ('rec\\x01.h5', 'a\\x1b[31m', 'caf\\udce9.h5', 'tab\tok')
    """
    def visible(match) -> str:
        code = ord(match.group())
        return f"\\x{code:02x}" if code < 0x100 else f"\\u{code:04x}"

    return _NOT_XML.sub(visible, text)


def junit_xml(outcomes: list[tuple[str, list[str], str | None]], path, elapsed_s: float = 0.0) -> None:
    """JUnit XML: one testcase per file; ``outcomes`` = (file, violations, error or None)."""
    import xml.etree.ElementTree as ET

    failures = sum(1 for _, v, e in outcomes if v and e is None)
    errors = sum(1 for _, _, e in outcomes if e is not None)
    suite = ET.Element("testsuite", name="guidefit", tests=str(len(outcomes)), failures=str(failures),
                       errors=str(errors), time=f"{elapsed_s:.3f}")
    for file, violations, error in outcomes:
        case = ET.SubElement(suite, "testcase", classname="guidefit.identify", name=xml_text(str(file)))
        if error is not None:
            ET.SubElement(case, "error", message=xml_text(error)).text = xml_text(error)
        elif violations:
            text = [xml_text(v) for v in violations]
            ET.SubElement(case, "failure", message=text[0]).text = "\n".join(text)
    root = ET.Element("testsuites", tests=str(len(outcomes)), failures=str(failures), errors=str(errors))
    root.append(suite)
    ET.indent(root)
    ET.ElementTree(root).write(path, encoding="utf-8", xml_declaration=True)
