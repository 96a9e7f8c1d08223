"""Every exception class of guidefit: a GuidefitError and a builtin, listed in errors.py's table."""

from __future__ import annotations

import builtins
import importlib
import inspect
import pkgutil

import guidefit
from guidefit import errors
from guidefit.errors import GuidefitError


def _exception_classes() -> dict[str, type]:
    """Every exception class (warnings aside) defined in a module of guidefit, by qualified name."""
    found = {}
    for info in pkgutil.walk_packages(guidefit.__path__, "guidefit."):
        if info.name == "guidefit.__main__":
            continue
        module = importlib.import_module(info.name)
        for _, cls in inspect.getmembers(module, inspect.isclass):
            if (issubclass(cls, BaseException) and not issubclass(cls, Warning)
                    and cls.__module__ == info.name):
                found[f"{info.name}.{cls.__qualname__}"] = cls
    return found


def _builtin_bases(cls: type) -> list[type]:
    return [c for c in cls.__mro__ if c.__module__ == "builtins"
            and c not in (BaseException, Exception, object)]


def test_every_exception_class_is_a_guidefit_error_and_a_builtin():
    classes = _exception_classes()
    assert "guidefit.machine.update.UpdateError" in classes and "guidefit.io.setup.SetupError" in classes
    for name, cls in classes.items():
        assert issubclass(cls, GuidefitError), name
        if cls is not GuidefitError:
            assert _builtin_bases(cls), f"{name}: no builtin base in {[c.__name__ for c in cls.__mro__]}"
        assert cls.exit_code in (1, 2), name


def test_every_exception_class_is_in_the_table_of_errors_py():
    doc = errors.__doc__
    for name, cls in _exception_classes().items():
        module = name.rsplit(".", 1)[0]
        row = next((line for line in doc.splitlines() if line.startswith(f"``{cls.__name__}``")), None)
        assert row is not None, f"{name} is missing from errors.py's table"
        assert f"``{module}``" in row and row.split()[-1] == str(cls.exit_code), row


def test_the_check_sees_a_class_without_builtin():
    class Bare(GuidefitError):
        pass

    assert _builtin_bases(Bare) == [] and _builtin_bases(errors.IdentificationError) == [RuntimeError]
    assert builtins.ValueError in _builtin_bases(errors.RecordingError)
