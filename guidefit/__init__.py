"""guidefit: joint stiffness and damping of linear rolling guideways from impact-hammer tests.

The package imports nothing heavy at start-up; the public functions are
reached lazily (``guidefit.identify``, ``guidefit.predict``, ...).
"""

__version__ = "0.1.0"
