"""Residual analysis: whether what a model leaves over the shot windows is noise, and if not, what."""

from .analyse import *  # noqa: F401,F403
from .analyse import __all__  # noqa: F401
