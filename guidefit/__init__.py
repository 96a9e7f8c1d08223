"""guidefit: joint stiffness and damping of linear rolling guideways from impact-hammer tests.

Everything the command line does is one call away; the package imports
nothing heavy until a function is used::

    import guidefit
    result = guidefit.identify("sample_data/mrb35_sample.h5")   # Identification
    result.to_frame()                                            # parameters as a table
    guidefit.predict(guidefit.load_guide("MRB35")).modes.to_frame()

``guidefit.identify``, ``guidefit.predict``, ``guidefit.simulate`` and
``guidefit.explain`` are modules that can be called like their main function.
"""

import importlib

__version__ = "0.1.0"

_LAZY = {
    "identify": "guidefit.identify",
    "predict": "guidefit.predict",
    "simulate": "guidefit.simulate",
    "explain": "guidefit.explain",
    "load_guide": ("guidefit.model.guides", "load_guide"),
    "read_recording": ("guidefit.io", "read_recording"),
}


def __getattr__(name):
    target = _LAZY.get(name)
    if target is None:
        raise AttributeError(f"module 'guidefit' has no attribute '{name}'")
    if isinstance(target, tuple):
        return getattr(importlib.import_module(target[0]), target[1])
    return importlib.import_module(target)


def __dir__():
    return sorted(list(globals()) + list(_LAZY))
