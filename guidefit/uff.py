"""Compatibility: UFF-58 reading and writing now live in :mod:`guidefit.io.uff`.

``from guidefit.uff import write_frf_uff`` (and every other public name) keeps working.
"""

from guidefit.io.uff import *  # noqa: F403
from guidefit.io.uff import __all__  # noqa: F401
