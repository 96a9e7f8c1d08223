"""Make a module callable, so that ``guidefit.identify(path)`` works although
``guidefit.identify`` is also the module of that name.

Python sets a package attribute to the submodule when the submodule is
imported, which would shadow a function of the same name in ``__init__``;
giving the module a ``__call__`` keeps both ``guidefit.identify(path)`` and
``from guidefit.identify import Identification`` working.
"""

import sys
import types


def make_callable(module_name: str, function_name: str) -> None:
    """Let calling module ``module_name`` call its function ``function_name``."""
    module = sys.modules[module_name]

    class _CallableModule(types.ModuleType):
        def __call__(self, *args, **kwargs):
            return getattr(self, function_name)(*args, **kwargs)

    _CallableModule.__doc__ = module.__doc__
    module.__class__ = _CallableModule
